//! The soak benchmark: `cargo bench --bench soak [-- SECONDS [CSV]]` (default one hour, CSV
//! `target/soak.csv`). Not a test: it asserts nothing, it records.
//!
//! Runs the real `tacmesh run` on the demo scene (objects coming and going: the cylinder leaves
//! and comes back, the cone slides, the whole scene loops every 36 s) with one subscriber, and
//! every 10 s samples the daemon's resident memory (VmRSS), the frames in and dropped since
//! the last sample, the objects tracked, shapes published, the subscriber's updates (shapes, poses) and
//! removes, and the daemon's frame-to-publish p50/p99 (over its last 90 s). Writes one CSV row
//! per sample and prints a summary table; `python3 benches/plot_soak.py CSV PNG` draws it.

mod support;

use std::io::Write;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tacmesh::protocol::{Message, Stats};
use tacmesh::subscriber::Subscription;

const SAMPLE_EVERY: Duration = Duration::from_secs(10);

#[derive(Default)]
struct Seen {
    stats: Option<Stats>,
    updates: u64,
    removes: u64,
}

fn main() {
    let mut args = std::env::args().skip(1).filter(|a| a != "--bench");
    let seconds: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(3600);
    let csv_path = args
        .next()
        .unwrap_or_else(|| concat!(env!("CARGO_MANIFEST_DIR"), "/target/soak.csv").to_string());
    let duration = seconds.to_string();
    let support::RunningDaemon {
        child: mut daemon,
        socket,
        dir: _dir,
    } = support::start_daemon("sim", &["--duration-s", &duration]);
    let pid = daemon.id();

    let seen = Arc::new(Mutex::new(Seen::default()));
    let reader = {
        let seen = Arc::clone(&seen);
        let mut subscription =
            Subscription::connect(&socket, Some(Duration::from_secs(5))).expect("subscribes");
        std::thread::spawn(move || loop {
            let message = subscription.next_message();
            let mut seen = seen.lock().unwrap_or_else(|e| e.into_inner());
            match message {
                Ok(Message::Shape(_) | Message::Pose(_)) => seen.updates += 1,
                Ok(Message::Remove { .. }) => seen.removes += 1,
                Ok(Message::Stats(stats)) => seen.stats = Some(stats),
                Ok(Message::Goodbye { .. }) | Err(_) => return,
                Ok(_) => {}
            }
        })
    };

    let mut csv = std::fs::File::create(&csv_path).expect("the CSV can be written");
    writeln!(
        csv,
        "elapsed_s,rss_mib,frames_in,frames_dropped,objects,shapes_published,updates,removes,\
         f2p_p50_ms,f2p_p99_ms"
    )
    .expect("writes");
    let started = Instant::now();
    let mut rows: Vec<[f64; 10]> = Vec::new();
    let mut previous = (0u64, 0u64);
    while let Some(rss_kib) = support::proc_status_kib(pid, "VmRSS") {
        std::thread::sleep(SAMPLE_EVERY);
        let seen = seen.lock().unwrap_or_else(|e| e.into_inner());
        let Some(stats) = seen.stats.clone() else {
            continue;
        };
        let row = [
            started.elapsed().as_secs_f64(),
            rss_kib as f64 / 1024.0,
            (stats.frames_in - previous.0) as f64,
            (stats.frames_dropped - previous.1) as f64,
            stats.objects_tracked as f64,
            stats.shapes_published as f64,
            seen.updates as f64,
            seen.removes as f64,
            f64::from(stats.frame_to_publish_p50_ms),
            f64::from(stats.frame_to_publish_p99_ms),
        ];
        previous = (stats.frames_in, stats.frames_dropped);
        let line: Vec<String> = row.iter().map(|v| format!("{v:.2}")).collect();
        writeln!(csv, "{}", line.join(",")).expect("writes");
        csv.flush().ok();
        eprintln!("soak: {}", line.join(" "));
        rows.push(row);
    }
    let status = daemon.wait().expect("daemon exits");
    let _ = reader.join();

    let column = |i: usize| rows.iter().map(move |r| r[i]);
    let max = |i: usize| column(i).fold(0.0, f64::max);
    let first_minute_rss = rows.iter().find(|r| r[0] >= 60.0).map_or(0.0, |r| r[1]);
    let last_rss = rows.last().map_or(0.0, |r| r[1]);
    let frames: f64 = column(2).sum();
    let dropped: f64 = column(3).sum();
    println!("\n## Soak: tacmesh run, demo scene, {seconds} s (exit {status})\n");
    println!("| measure | value |\n|---|---|");
    println!("| samples | {} (every {:?}) |", rows.len(), SAMPLE_EVERY);
    println!(
        "| RSS after 1 min / at end / max | {first_minute_rss:.1} / {last_rss:.1} / {:.1} MiB |",
        max(1)
    );
    println!(
        "| frames / dropped | {frames:.0} / {dropped:.0} ({:.2} %) |",
        100.0 * dropped / frames.max(1.0)
    );
    println!(
        "| worst 10-s drop rate | {:.1} % |",
        rows.iter()
            .map(|r| 100.0 * r[3] / r[2].max(1.0))
            .fold(0.0, f64::max)
    );
    println!(
        "| frame-to-publish p99: median of samples / worst | {:.1} / {:.1} ms |",
        median(column(9).collect()),
        max(9)
    );
    println!(
        "| objects tracked: min / max | {:.0} / {:.0} |",
        column(4).fold(f64::INFINITY, f64::min),
        max(4)
    );
    println!(
        "| subscriber updates (shapes and poses) / removes | {:.0} / {:.0} |",
        rows.last().map_or(0.0, |r| r[6]),
        rows.last().map_or(0.0, |r| r[7])
    );
    println!("| CSV | {csv_path} |");
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values.get(values.len() / 2).copied().unwrap_or(0.0)
}
