//! What Zenoh adds on loopback: `cargo bench --features zenoh --bench zenoh [-- SECONDS]`.
//!
//! Starts the real `tacmesh run` on the demo scene with a `[zenoh]` section listening on
//! 127.0.0.1 (multicast scouting off), reads it at the same time over its Unix socket and over
//! Zenoh (this process joins as a peer), and reports: for every update both saw (a Shape by
//! object and version, a Pose by object and pose time), how much later it arrived over Zenoh
//! (p50 / p99 / max); the data's age at arrival over Zenoh; the payload bytes each way got; and
//! the bytes that crossed the loopback interface (`/proc/net/dev`, both directions, IP and TCP
//! headers and Zenoh's framing included; nothing else should use loopback meanwhile); and the
//! daemon's peak resident memory. Prints a Markdown table for BENCHMARKS.md. Not a test:
//! nothing here asserts a time.

mod support;

use std::collections::HashMap;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use tacmesh::protocol::{encode, Message};
use tacmesh::source::monotonic_now;
use tacmesh::subscriber::Subscription;
use tacmesh::zenoh::{ZenohSettings, ZenohSubscription};

/// What identifies one update in both streams.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Update {
    Shape {
        object: u64,
        version: u64,
    },
    Pose {
        object: u64,
        pose_time: u64,
        last_seen: u64,
    },
}

fn identify(message: &Message) -> Option<Update> {
    match message {
        Message::Shape(s) => Some(Update::Shape {
            object: s.object_id(),
            version: s.version(),
        }),
        Message::Pose(p) => Some(Update::Pose {
            object: p.object_id,
            pose_time: p.pose_time_ns,
            last_seen: p.last_seen_ns,
        }),
        _ => None,
    }
}

/// Bytes received on the loopback interface so far.
fn loopback_bytes() -> u64 {
    let dev = std::fs::read_to_string("/proc/net/dev").unwrap_or_default();
    dev.lines()
        .find_map(|line| line.trim_start().strip_prefix("lo:"))
        .and_then(|counters| counters.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
}

fn main() {
    let mut args = std::env::args().skip(1).filter(|a| a != "--bench");
    let seconds: f64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(20.0);
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let config_dir = tempfile::tempdir().expect("a temporary folder");
    let config = config_dir.path().join("zenoh.toml");
    std::fs::write(
        &config,
        format!("[zenoh]\nrobot = \"bench\"\nlisten = [\"tcp/127.0.0.1:{port}\"]\n"),
    )
    .expect("writes the config");
    let duration = (seconds + 5.0).to_string();
    let support::RunningDaemon {
        child: mut daemon,
        socket,
        dir: _dir,
    } = support::start_daemon(
        "sim",
        &[
            "--duration-s",
            &duration,
            "--config",
            config.to_str().expect("UTF-8"),
        ],
    );
    std::thread::sleep(Duration::from_secs(2));

    let settings = ZenohSettings {
        robot: "bench".into(),
        connect: vec![format!("tcp/127.0.0.1:{port}")],
        ..ZenohSettings::default()
    };
    let lo_before = loopback_bytes();
    let until = Instant::now() + Duration::from_secs_f64(seconds);
    let (tx, rx) = mpsc::channel::<(bool, Instant, Update, usize, u64)>();
    let over_socket = {
        let tx = tx.clone();
        let mut subscription =
            Subscription::connect(&socket, Some(Duration::from_secs(5))).expect("subscribes");
        std::thread::spawn(move || {
            let mut frame = Vec::new();
            while Instant::now() < until {
                let Ok(message) = subscription.next_message() else {
                    break;
                };
                frame.clear();
                let _ = encode(&message, &mut frame);
                if let Some(update) = identify(&message) {
                    let _ = tx.send((false, Instant::now(), update, frame.len(), 0));
                }
            }
        })
    };
    let over_zenoh = {
        let mut subscription =
            ZenohSubscription::connect(&settings, Duration::from_secs(5)).expect("joins Zenoh");
        std::thread::spawn(move || {
            let mut frame = Vec::new();
            while Instant::now() < until {
                let Ok(Some(message)) = subscription.next_message(Duration::from_secs(1)) else {
                    continue;
                };
                frame.clear();
                let _ = encode(&message, &mut frame);
                let newest = match &message {
                    Message::Shape(s) => s.shape_time_ns,
                    Message::Pose(p) => p.last_seen_ns,
                    _ => 0,
                };
                if let Some(update) = identify(&message) {
                    let _ = tx.send((true, Instant::now(), update, frame.len(), newest));
                }
            }
        })
    };
    let (mut socket_at, mut zenoh_at) = (HashMap::new(), HashMap::new());
    let (mut socket_bytes, mut zenoh_bytes) = (0usize, 0usize);
    let mut ages_ms = Vec::new();
    for (zenoh, at, update, bytes, newest) in rx {
        if zenoh {
            zenoh_bytes += bytes;
            zenoh_at.entry(update).or_insert(at);
            if newest > 0 {
                let age = monotonic_now()
                    .as_nanos()
                    .saturating_sub(u128::from(newest));
                ages_ms.push(age as f64 / 1e6);
            }
        } else {
            socket_bytes += bytes;
            socket_at.entry(update).or_insert(at);
        }
    }
    let _ = over_socket.join();
    let _ = over_zenoh.join();
    let lo_bytes = loopback_bytes().saturating_sub(lo_before);
    let peak_rss_kib = support::proc_status_kib(daemon.id(), "VmHWM").unwrap_or(0);
    let _ = daemon.kill();
    let _ = daemon.wait();

    let mut added_ms: Vec<f64> = zenoh_at
        .iter()
        .filter_map(|(update, &z)| {
            let s = *socket_at.get(update)?;
            Some(if z >= s {
                (z - s).as_secs_f64() * 1e3
            } else {
                -((s - z).as_secs_f64() * 1e3)
            })
        })
        .collect();
    added_ms.sort_by(f64::total_cmp);
    ages_ms.sort_by(f64::total_cmp);
    let q = |values: &[f64], q: f64| {
        values
            .get(((values.len() as f64 * q).ceil() as usize).saturating_sub(1))
            .copied()
            .unwrap_or(0.0)
    };
    println!("\n## tacmesh over Zenoh on loopback, demo scene, {seconds:.0} s\n");
    println!("| measure | value |\n|---|---|");
    println!(
        "| updates seen over the socket / over Zenoh / both | {} / {} / {} |",
        socket_at.len(),
        zenoh_at.len(),
        added_ms.len()
    );
    println!(
        "| Zenoh's arrival after the socket's, p50 / p99 / max | {:.2} / {:.2} / {:.2} ms |",
        q(&added_ms, 0.5),
        q(&added_ms, 0.99),
        q(&added_ms, 1.0)
    );
    println!(
        "| data age at arrival over Zenoh, p50 / p99 | {:.1} / {:.1} ms |",
        q(&ages_ms, 0.5),
        q(&ages_ms, 0.99)
    );
    println!(
        "| payload bytes: socket (full shapes) / Zenoh (compact shapes) | {socket_bytes} / {zenoh_bytes} ({:.0} / {:.0} B/s) |",
        socket_bytes as f64 / seconds,
        zenoh_bytes as f64 / seconds
    );
    println!(
        "| bytes through the loopback interface (Zenoh's TCP, both ways, headers included) | {lo_bytes} ({:.0} B/s) |",
        lo_bytes as f64 / seconds
    );
    println!(
        "| the daemon's peak RSS, publishing over Zenoh | {:.1} MiB |",
        peak_rss_kib as f64 / 1024.0
    );
}
