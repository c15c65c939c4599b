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
//! subscriber saw (shapes, poses, removes and their bytes, data age at arrival; collision
//! bodies, their bytes and how long after its shape each came). With
//! `BENCH_ENCODING=compact` in the environment the subscriber asks for compact shapes, with
//! `BENCH_MAX_RATE_HZ=N` for at most N updates a second per object, with `BENCH_EXTRAPOLATE=1`
//! for only the poses a client extrapolating by velocity needs.
//! Prints a Markdown table for BENCHMARKS.md. Not a test: nothing here asserts a time.

mod support;

use std::time::{Duration, Instant};

use tacmesh::protocol::{encode, Encoding, Message, Stats, Subscribe};
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

    let encoding = match std::env::var("BENCH_ENCODING").as_deref() {
        Ok("compact") => Encoding::Compact,
        _ => Encoding::Full,
    };
    let max_rate_hz: f32 = std::env::var("BENCH_MAX_RATE_HZ")
        .ok()
        .and_then(|rate| rate.parse().ok())
        .unwrap_or(0.0);
    let extrapolate = std::env::var("BENCH_EXTRAPOLATE").is_ok_and(|v| v == "1");
    let options =
        (encoding == Encoding::Compact || max_rate_hz > 0.0 || extrapolate).then(|| Subscribe {
            encoding,
            resend: true,
            extrapolate,
            max_rate_hz,
            ..Subscribe::default()
        });
    let mut subscription =
        Subscription::connect_with(&socket, Some(Duration::from_secs(5)), options)
            .expect("subscribes");

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
    let (mut shapes, mut poses, mut removes) = (0u64, 0u64, 0u64);
    // Bytes on the wire by kind (a frame's size is that of the message encoded again) and
    // the faces of the shapes, for bytes per face.
    let (mut shape_bytes, mut pose_bytes, mut other_bytes, mut faces) = (0u64, 0u64, 0u64, 0u64);
    let mut ages_ms: Vec<f64> = Vec::new();
    // Their ages differ: a move or a sighting (a Pose) is published by the frame path, a new
    // shape by the mesher.
    let (mut moved_ages_ms, mut mesh_ages_ms): (Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new());
    let age_ms = |capture_ns: u64| {
        monotonic_now()
            .as_nanos()
            .saturating_sub(u128::from(capture_ns)) as f64
            / 1e6
    };
    // Collision bodies (protocol 3): their count and bytes, and when each object's shapes
    // arrived, for how long after its shape a body comes.
    let (mut bodies, mut body_bytes) = (0u64, 0u64);
    let mut shape_arrivals: std::collections::HashMap<(u64, u64), Instant> =
        std::collections::HashMap::new();
    let mut body_lags_ms: Vec<f64> = Vec::new();
    // Per object: when its first shape came, and from then to its first body.
    let mut first_shape_at: std::collections::HashMap<u64, Instant> =
        std::collections::HashMap::new();
    let mut first_body_lags_ms: std::collections::HashMap<u64, f64> =
        std::collections::HashMap::new();
    let mut frame = Vec::new();
    loop {
        let message = subscription.next_message();
        if let Ok(message) = &message {
            frame.clear();
            let mut again = message.clone();
            if let Message::Shape(shape) = &mut again {
                // Encoding adds the quantisation bound again; the size is the same.
                shape.encoding = encoding;
            }
            if let Message::Body(body) = &mut again {
                body.encoding = encoding;
            }
            encode(&again, &mut frame).expect("a decoded message encodes");
            match message {
                Message::Shape(_) => shape_bytes += frame.len() as u64,
                Message::Pose(_) => pose_bytes += frame.len() as u64,
                Message::Body(_) => body_bytes += frame.len() as u64,
                _ => other_bytes += frame.len() as u64,
            }
        }
        match message {
            Ok(Message::Shape(shape)) => {
                shape_arrivals.insert((shape.object_id(), shape.version()), Instant::now());
                first_shape_at
                    .entry(shape.object_id())
                    .or_insert_with(Instant::now);
                shapes += 1;
                faces += shape.mesh.triangles.len() as u64;
                let age = age_ms(shape.shape_time_ns);
                ages_ms.push(age);
                mesh_ages_ms.push(age);
            }
            Ok(Message::Pose(pose)) => {
                poses += 1;
                let age = age_ms(pose.last_seen_ns);
                ages_ms.push(age);
                moved_ages_ms.push(age);
            }
            Ok(Message::Body(body)) => {
                bodies += 1;
                // How long after its shape the body came (its shape arrived on this
                // connection, unless it was made from an older version held over).
                if let Some(at) = shape_arrivals.get(&(body.object_id, body.shape_version)) {
                    body_lags_ms.push(at.elapsed().as_secs_f64() * 1e3);
                }
                if let Some(at) = first_shape_at.get(&body.object_id) {
                    first_body_lags_ms
                        .entry(body.object_id)
                        .or_insert_with(|| at.elapsed().as_secs_f64() * 1e3);
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
    for ages in [
        &mut ages_ms,
        &mut moved_ages_ms,
        &mut mesh_ages_ms,
        &mut body_lags_ms,
    ] {
        ages.sort_by(f64::total_cmp);
    }
    let pct_of = |ages: &[f64], q: f64| {
        ages.get(((ages.len() as f64 * q).ceil() as usize).saturating_sub(1))
            .copied()
            .unwrap_or(0.0)
    };
    let pct = |q: f64| pct_of(&ages_ms, q);

    println!(
        "\n## tacmesh run, {sensor}, {seconds:.0} s, {encoding:?} encoding, rate cap {max_rate_hz} Hz, \
         extrapolating {extrapolate} (exit {status})\n"
    );
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
    println!(
        "| shapes / poses published | {} / {} |",
        s1.shapes_published, s1.poses_published
    );
    println!("| socket bytes / s (1 subscriber) | {:.0} |", bytes_per_s);
    println!("| peak RSS | {:.1} MiB |", peak_rss_kib as f64 / 1024.0);
    println!("| subscriber: shapes / poses / removes | {shapes} / {poses} / {removes} |");
    let run_s = seconds.max(1e-9);
    println!(
        "| subscriber: bytes of shapes / poses / the rest | {shape_bytes} / {pose_bytes} / \
         {other_bytes} ({:.0} B/s in all) |",
        (shape_bytes + pose_bytes + other_bytes) as f64 / run_s
    );
    println!(
        "| subscriber: bodies, bytes | {bodies}, {body_bytes} ({:.0} B/s; {:.0} B a body) |",
        body_bytes as f64 / run_s,
        body_bytes as f64 / bodies.max(1) as f64
    );
    println!(
        "| subscriber: a body after its shape p50 / p99 ({} matched) | {:.1} / {:.1} ms |",
        body_lags_ms.len(),
        pct_of(&body_lags_ms, 0.5),
        pct_of(&body_lags_ms, 0.99)
    );
    let mut first_body_lags_ms: Vec<f64> = first_body_lags_ms.into_values().collect();
    first_body_lags_ms.sort_by(f64::total_cmp);
    println!(
        "| subscriber: an object's first body after its first shape p50 / max ({} of {} \
         objects got one) | {:.1} / {:.1} ms |",
        first_body_lags_ms.len(),
        first_shape_at
            .keys()
            .filter(|&&id| id < tacmesh::protocol::FIRST_SUPPORT_ID)
            .count(),
        pct_of(&first_body_lags_ms, 0.5),
        first_body_lags_ms.last().copied().unwrap_or(0.0)
    );
    println!(
        "| subscriber: bytes per shape face / per pose | {:.1} / {:.0} |",
        shape_bytes as f64 / faces.max(1) as f64,
        pose_bytes as f64 / poses.max(1) as f64
    );
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
        "| — of {} poses (moves and sightings, by last seen) p50 / p99 | {:.1} / {:.1} ms |",
        moved_ages_ms.len(),
        pct_of(&moved_ages_ms, 0.5),
        pct_of(&moved_ages_ms, 0.99)
    );
}
