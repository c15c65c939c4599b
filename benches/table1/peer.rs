//! The peer run of `cargo bench --bench table1`: Open3D's Poisson reconstruction and quadric
//! decimation (`benches/table1/peer.py`) on the same clouds as ours, judged by the same metric.
//!
//! Runs when the Python named by `--peer-python PATH` or `TACMESH_PEER_PYTHON` (else
//! `python3`) imports `open3d`; says why and skips otherwise. For each shape at 20 mm noise and
//! each seed: our pipeline on one thread (faces, MHE, ms); Open3D's Poisson mesh decimated to a
//! ladder of face counts from ours upwards, each judged by MHE over 50,000 samples; *faces at
//! our MHE* is the smallest count on the ladder whose MHE is no worse than ours (none when even
//! the undecimated Poisson mesh is worse), and its time is normals + Poisson + that
//! decimation, on one thread too.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

use tacmesh::pipeline::{mesh_cloud, MeshConfig};
use tacmesh::sim::{mesh_distance, PAPER_SAMPLES};

use super::{cloud_for, median, PAPER_TABLE1};

/// Multiples of our face count the peer's mesh is decimated to.
const LADDER: [f64; 11] = [1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 32.0, 64.0];
const NOISE_MM: f32 = 20.0;

#[derive(serde::Deserialize)]
struct PeerTimings {
    normals_s: f64,
    poisson_s: f64,
    poisson_faces: usize,
    decimate_s: BTreeMap<String, f64>,
}

/// One cloud's figures, ours and the peer's.
struct Comparison {
    ours_faces: f64,
    ours_mhe: f64,
    ours_ms: f64,
    /// The peer's MHE at our face count.
    peer_mhe_at_our_faces: f64,
    /// The peer's faces and ms at our MHE, when it gets there.
    peer_at_our_mhe: Option<(f64, f64)>,
    peer_poisson_faces: f64,
    peer_poisson_mhe: f64,
    /// Normals + Poisson, the part that does not depend on the face count.
    peer_reconstruct_ms: f64,
}

pub fn python_from(args: &[String]) -> String {
    args.windows(2)
        .find(|w| w[0] == "--peer-python")
        .map(|w| w[1].clone())
        .or_else(|| std::env::var("TACMESH_PEER_PYTHON").ok())
        .unwrap_or_else(|| "python3".into())
}

fn open3d_available(python: &str) -> bool {
    Command::new(python)
        .args(["-c", "import open3d"])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Writes every cloud, asks the peer for its meshes, judges both.
pub fn peer_run(python: &str, seeds: u64, points: usize, one_thread: &rayon::ThreadPool) {
    println!(
        "\n### Peer run: Open3D 0.20 Poisson (depth 8) + quadric decimation on the same clouds \
         ({NOISE_MM} mm, {points} points, median of {seeds} seeds, one thread each)\n"
    );
    if !open3d_available(python) {
        println!(
            "Skipped: `{python}` cannot import open3d (set TACMESH_PEER_PYTHON to a Python \
             with `open3d==0.20.0`).\n"
        );
        return;
    }
    let work = tempfile::tempdir().expect("a temporary folder");
    let mut ours = BTreeMap::new();
    let mut manifest = Vec::new();
    for (shape, ..) in PAPER_TABLE1 {
        for seed in 1..=seeds {
            let name = format!("{}-{seed}", shape.name());
            let cloud = cloud_for(shape, NOISE_MM, seed, points);
            let path = work.path().join(format!("{name}.ply"));
            tacmesh::formats::write_cloud(&path, &cloud).expect("the cloud is written");
            let start = Instant::now();
            let (mesh, report) = one_thread
                .install(|| mesh_cloud(&cloud, &MeshConfig::default()))
                .expect("pipeline runs on sampled shapes");
            let ms = start.elapsed().as_secs_f64() * 1e3;
            let mhe = mesh_distance(&shape.mesh(), &mesh, PAPER_SAMPLES, seed)
                .expect("meshes compare")
                .mhe_m;
            let ladder: Vec<usize> = LADDER
                .iter()
                .map(|k| (k * report.faces as f64).round() as usize)
                .collect();
            manifest.push(serde_json::json!({"name": name, "cloud": path, "faces": ladder}));
            ours.insert(name, (shape, seed, report.faces, mhe, ms, ladder));
        }
    }
    let manifest_path = work.path().join("manifest.json");
    let manifest = serde_json::json!({"clouds": manifest, "out": work.path()});
    std::fs::write(&manifest_path, manifest.to_string()).expect("the manifest is written");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/table1/peer.py");
    let status = Command::new(python)
        .arg(script)
        .arg(&manifest_path)
        .env("OMP_NUM_THREADS", "1")
        .status()
        .expect("the peer starts");
    assert!(status.success(), "benches/table1/peer.py failed: {status}");
    let timings: BTreeMap<String, PeerTimings> = serde_json::from_str(
        &std::fs::read_to_string(work.path().join("timings.json")).expect("the peer timed"),
    )
    .expect("the peer's timings parse");

    let mut by_shape: BTreeMap<&'static str, Vec<Comparison>> = BTreeMap::new();
    for (name, (shape, seed, faces, mhe, ms, ladder)) in &ours {
        let peer = &timings[name];
        let judge = |file: &Path| -> (f64, f64) {
            let mesh = tacmesh::formats::read_mesh(file).expect("the peer's mesh reads");
            let d =
                mesh_distance(&shape.mesh(), &mesh, PAPER_SAMPLES, *seed).expect("meshes compare");
            (mesh.triangles.len() as f64, d.mhe_m)
        };
        let reconstruct_ms = (peer.normals_s + peer.poisson_s) * 1e3;
        let mut at_our_faces = f64::NAN;
        let mut at_our_mhe = None;
        for (k, target) in ladder.iter().enumerate() {
            let (peer_faces, peer_mhe) = judge(&work.path().join(format!("{name}-{target}.ply")));
            if k == 0 {
                at_our_faces = peer_mhe;
            }
            if at_our_mhe.is_none() && peer_mhe <= *mhe {
                let decimate_ms = peer.decimate_s[&target.to_string()] * 1e3;
                at_our_mhe = Some((peer_faces, reconstruct_ms + decimate_ms));
            }
        }
        let (poisson_faces, poisson_mhe) = judge(&work.path().join(format!("{name}-poisson.ply")));
        debug_assert_eq!(poisson_faces as usize, peer.poisson_faces);
        eprintln!(
            "peer {name}: ours {faces} faces {mhe:.5} m {ms:.0} ms; Open3D at our faces {at_our_faces:.5} m, \
             at our MHE {at_our_mhe:?}, Poisson {poisson_faces} faces {poisson_mhe:.5} m {reconstruct_ms:.0} ms"
        );
        by_shape.entry(shape.name()).or_default().push(Comparison {
            ours_faces: *faces as f64,
            ours_mhe: *mhe,
            ours_ms: *ms,
            peer_mhe_at_our_faces: at_our_faces,
            peer_at_our_mhe: at_our_mhe,
            peer_poisson_faces: poisson_faces,
            peer_poisson_mhe: poisson_mhe,
            peer_reconstruct_ms: reconstruct_ms,
        });
    }

    println!("| shape | ours: faces / MHE (mm) / ms | Open3D at our faces: MHE (mm) | Open3D at our MHE: faces / ms (seeds that got there) | **faces ratio** Open3D/ours | **time ratio** Open3D/ours | Open3D Poisson: faces / MHE (mm) |");
    println!("|---|---|---|---|---|---|---|");
    for (shape, ..) in PAPER_TABLE1 {
        let Some(runs) = by_shape.get(shape.name()) else {
            continue;
        };
        let m = |f: &dyn Fn(&Comparison) -> f64| median(runs.iter().map(f).collect());
        let reached: Vec<&Comparison> = runs
            .iter()
            .filter(|c| c.peer_at_our_mhe.is_some())
            .collect();
        let reach = |f: &dyn Fn(&Comparison) -> f64| median(reached.iter().map(|c| f(c)).collect());
        let (peer_faces, peer_ms) = (
            reach(&|c| c.peer_at_our_mhe.map_or(f64::NAN, |p| p.0)),
            reach(&|c| c.peer_at_our_mhe.map_or(f64::NAN, |p| p.1)),
        );
        let at_mhe = if reached.is_empty() {
            "not reached (0)".to_string()
        } else {
            format!("{peer_faces:.0} / {peer_ms:.0} ({})", reached.len())
        };
        let (faces_ratio, time_ratio) = if reached.is_empty() {
            (
                "–".to_string(),
                format!("≥ {:.0}", m(&|c| c.peer_reconstruct_ms) / m(&|c| c.ours_ms)),
            )
        } else {
            (
                format!(
                    "{:.1}",
                    reach(&|c| c.peer_at_our_mhe.map_or(f64::NAN, |p| p.0) / c.ours_faces)
                ),
                format!(
                    "{:.0}",
                    reach(&|c| c.peer_at_our_mhe.map_or(f64::NAN, |p| p.1) / c.ours_ms)
                ),
            )
        };
        println!(
            "| {} | {:.0} / {:.2} / {:.0} | {:.2} | {at_mhe} | **{faces_ratio}** | **{time_ratio}** | {:.0} / {:.2} |",
            shape.name(),
            m(&|c| c.ours_faces),
            m(&|c| c.ours_mhe * 1e3),
            m(&|c| c.ours_ms),
            m(&|c| c.peer_mhe_at_our_faces * 1e3),
            m(&|c| c.peer_poisson_faces),
            m(&|c| c.peer_poisson_mhe * 1e3),
        );
    }
}
