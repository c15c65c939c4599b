//! The live daemon under its default load: `cargo bench --bench daemon [-- SECONDS [SPEC
//! [paced|unpaced [ARGS…]]]]` (ARGS go to `tacmesh run`, such as `--config FILE`). A
//! `replay:` SPEC is played looped at maximum rate (`--unpaced --loop`), the recordings'
//! throughput benchmark; with `paced` after it, at its recorded rate, as a camera
//! would deliver it (frames the pipeline cannot take are dropped, as live). The daemon's last
//! counter line (standard error) gives object births and removals.
//!
//! Starts the real `tacmesh run` (this profile's build) on the default demo scene (640×480 at
//! 30 fps, paced) for 60 s, subscribes over its socket, and reports: sustained frame rate,
//! frames dropped, frame-to-publish latency p50/p99, per-stage p50/p99 (from the daemon's last
//! Stats message), peak RSS (VmHWM from /proc), bytes per second on the socket, and what one
//! subscriber saw (upserts, removes, data age at arrival). Prints a Markdown table for
//! BENCHMARKS.md. Not a test: nothing here asserts a time.

mod support;

use std::time::{Duration, Instant};

use tacmesh::protocol::{Message, Stats};
use tacmesh::source::monotonic_now;
use tacmesh::subscriber::Subscription;

fn main() {
    let mut args = std::env::args().skip(1).filter(|a| a != "--bench");
    let seconds: f64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(60.0);
    let sensor = args.next().unwrap_or_else(|| "sim".into());
    // A recording plays as fast as the pipeline takes it, unless `paced` follows the spec:
    // then at its recorded rate, as a live camera would deliver it.
    let paced = args.next().is_some_and(|a| a == "paced");
    // Anything after goes to `tacmesh run` as it is (`--config FILE` to compare settings).
    let passed: Vec<String> = args.collect();
    let replay = sensor.starts_with("replay:");
    let duration = seconds.to_string();
    let mut extra = vec!["--duration-s", duration.as_str()];
    extra.extend(passed.iter().map(String::as_str));
    if replay {
        extra.push("--loop");
        if !paced {
            extra.push("--unpaced");
        }
    }
    let support::RunningDaemon {
        child: mut daemon,
        socket,
        dir: _dir,
    } = support::start_daemon(&sensor, &extra);
    let pid = daemon.id();

    let mut subscription =
        Subscription::connect(&socket, Some(Duration::from_secs(5))).expect("subscribes");

    // RSS sampler: the daemon's peak resident set, from its own high-water mark.
    let rss = std::thread::spawn(move || {
        let mut peak_kib = 0u64;
        while let Some(kib) = support::proc_status_kib(pid, "VmHWM") {
            peak_kib = peak_kib.max(kib);
            std::thread::sleep(Duration::from_millis(200));
        }
        peak_kib
    });

    let mut last_stats: Option<(Instant, Stats)> = None;
    let mut first_stats: Option<(Instant, Stats)> = None;
    let (mut upserts, mut removes) = (0u64, 0u64);
    let mut ages_ms: Vec<f64> = Vec::new();
    // A moved object is republished with the same triangles and report; anything else is a
    // new mesh. Their ages differ: a move is published by the frame path, a mesh by the mesher.
    let mut last_report: std::collections::HashMap<u64, (usize, tacmesh::protocol::SimplifyStats)> =
        std::collections::HashMap::new();
    let (mut moved_ages_ms, mut mesh_ages_ms): (Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new());
    loop {
        match subscription.next_message() {
            Ok(Message::Upsert(upsert)) => {
                upserts += 1;
                let age = monotonic_now()
                    .as_nanos()
                    .saturating_sub(upsert.capture_time_ns as u128);
                ages_ms.push(age as f64 / 1e6);
                let key = (upsert.mesh.triangles.len(), upsert.report);
                if last_report.insert(upsert.object_id, key) == Some(key) {
                    moved_ages_ms.push(age as f64 / 1e6);
                } else {
                    mesh_ages_ms.push(age as f64 / 1e6);
                }
            }
            Ok(Message::Remove { .. }) => removes += 1,
            Ok(Message::Stats(stats)) => {
                if first_stats.is_none() {
                    first_stats = Some((Instant::now(), stats.clone()));
                }
                last_stats = Some((Instant::now(), stats));
            }
            Ok(Message::Goodbye { .. }) => break,
            Ok(_) => {}
            Err(err) => {
                eprintln!("subscription ended: {err}");
                break;
            }
        }
    }
    let status = daemon.wait().expect("daemon exits");
    let peak_rss_kib = rss.join().unwrap_or(0);
    let (Some((t0, s0)), Some((t1, s1))) = (first_stats, last_stats) else {
        panic!("no stats received");
    };
    let span_s = (t1 - t0).as_secs_f64().max(1e-9);
    let fps = (s1.frames_in - s0.frames_in) as f64 / span_s;
    let processed_fps =
        ((s1.frames_in - s1.frames_dropped) - (s0.frames_in - s0.frames_dropped)) as f64 / span_s;
    let bytes_per_s = (s1.bytes_sent - s0.bytes_sent) as f64 / span_s;
    for ages in [&mut ages_ms, &mut moved_ages_ms, &mut mesh_ages_ms] {
        ages.sort_by(f64::total_cmp);
    }
    let pct_of = |ages: &[f64], q: f64| {
        ages.get(((ages.len() as f64 * q).ceil() as usize).saturating_sub(1))
            .copied()
            .unwrap_or(0.0)
    };
    let pct = |q: f64| pct_of(&ages_ms, q);

    println!("\n## tacmesh run, {sensor}, {seconds:.0} s (exit {status})\n");
    println!("| measure | value |\n|---|---|");
    println!("| frames from sensor | {} ({fps:.1} fps) |", s1.frames_in);
    println!("| frames processed | {:.1} fps |", processed_fps);
    println!(
        "| frames dropped | {} ({:.1} %) |",
        s1.frames_dropped,
        100.0 * s1.frames_dropped as f64 / s1.frames_in.max(1) as f64
    );
    println!(
        "| frame-to-publish p50 / p99 | {:.1} / {:.1} ms |",
        s1.frame_to_publish_p50_ms, s1.frame_to_publish_p99_ms
    );
    for stage in &s1.stage_latencies {
        println!(
            "| stage {} p50 / p99 | {:.1} / {:.1} ms |",
            stage.stage, stage.p50_ms, stage.p99_ms
        );
    }
    println!("| objects tracked at end | {} |", s1.objects_tracked);
    println!("| meshing runs | {} |", s1.meshing_runs);
    println!("| meshes published | {} |", s1.meshes_published);
    println!("| socket bytes / s (1 subscriber) | {:.0} |", bytes_per_s);
    println!("| peak RSS | {:.1} MiB |", peak_rss_kib as f64 / 1024.0);
    println!("| subscriber: upserts / removes | {upserts} / {removes} |");
    println!(
        "| subscriber: data age at arrival p50 / p99 | {:.1} / {:.1} ms |",
        pct(0.5),
        pct(0.99)
    );
    println!(
        "| — of {} new meshes (mesher) p50 / p99 | {:.1} / {:.1} ms |",
        mesh_ages_ms.len(),
        pct_of(&mesh_ages_ms, 0.5),
        pct_of(&mesh_ages_ms, 0.99)
    );
    println!(
        "| — of {} moves (same mesh, new pose) p50 / p99 | {:.1} / {:.1} ms |",
        moved_ages_ms.len(),
        pct_of(&moved_ages_ms, 0.5),
        pct_of(&moved_ages_ms, 0.99)
    );
}
