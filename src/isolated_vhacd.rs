//! parry3d's V-HACD in a child process (`tacmesh __vhacd`), so that a panic inside it cannot
//! take the daemon down: V-HACD calls `convex_hull(..).unwrap()` on the voxel clusters it cuts,
//! which fails on degenerate geometry, and the release build aborts on a panic (so that
//! systemd restarts a clean daemon rather than keep one with a dead thread). A failed, crashed
//! or overdue child costs one object its decomposition: the caller falls back to the proxy's
//! convex hull (see [`tacmesh_physics::convex_parts_with`]).
//!
//! The exchange is by hand, because both ends are this binary of the same build: the proxy
//! goes to the child's standard input as OBJ (the `formats` crate's writer and reader), the
//! parts come back on its standard output as lines `x y z`, a blank line after each part
//! (floats in Rust's shortest round-trip form, so they read back exactly).

use std::io::{Read, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use glam::Vec3;
use tacmesh_physics::{vhacd_part_points, ConvexConfig};
use tacmesh_source::TriMesh;

/// The hidden subcommand the child is run as.
pub const SUBCOMMAND: &str = "__vhacd";

/// How long a child may take before it is killed (V-HACD at 64 voxels takes 0.2–0.3 s on the
/// concave shapes of BENCHMARKS.md on this machine).
pub const CHILD_TIMEOUT: Duration = Duration::from_secs(10);

/// How much the child lowers its own scheduling priority (`nice`): a body can wait, the next
/// frame should not (on a saturated machine the frame path keeps its share of the cores).
pub const CHILD_NICENESS: i32 = 10;

/// The child's side, as the `__vhacd` subcommand runs it: lowers its own priority by
/// [`CHILD_NICENESS`], then [`serve`]s standard input to standard output.
pub fn serve_as_child(config: &ConvexConfig) -> Result<(), String> {
    if let Err(err) = rustix::process::nice(CHILD_NICENESS) {
        // Not fatal: the parts are the same at any priority.
        tracing::debug!("cannot lower the V-HACD child's priority: {err}");
    }
    serve(&mut std::io::stdin(), &mut std::io::stdout(), config)
}

/// The child's side: reads the proxy from `input`, writes each part's points to `output`.
pub fn serve(
    input: &mut impl Read,
    output: &mut impl Write,
    config: &ConvexConfig,
) -> Result<(), String> {
    let mut bytes = Vec::new();
    input
        .read_to_end(&mut bytes)
        .map_err(|e| format!("reading the mesh: {e}"))?;
    let mesh = tacmesh_formats::obj::parse(&bytes, "standard input").map_err(|e| e.to_string())?;
    let mut text = String::new();
    for part in vhacd_part_points(&mesh, config) {
        for p in part {
            text.push_str(&format!("{} {} {}\n", p.x, p.y, p.z));
        }
        text.push('\n');
    }
    output
        .write_all(text.as_bytes())
        .map_err(|e| format!("writing the parts: {e}"))
}

/// The parent's side: runs `exe __vhacd` on `mesh` and reads the parts back; an error says
/// what went wrong (the child crashed, took longer than `timeout`, or wrote nonsense).
pub fn decompose(
    exe: &Path,
    mesh: &TriMesh,
    config: &ConvexConfig,
    timeout: Duration,
) -> Result<Vec<Vec<Vec3>>, String> {
    let mut child = Command::new(exe)
        .arg(SUBCOMMAND)
        .args(["--resolution", &config.resolution.to_string()])
        .args(["--concavity", &config.concavity.to_string()])
        .args(["--max-hulls", &config.max_hulls.to_string()])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| format!("cannot start {} {SUBCOMMAND}: {e}", exe.display()))?;
    let mut obj = Vec::new();
    tacmesh_formats::obj::write(&mut obj, mesh).map_err(|e| e.to_string())?;
    // The child reads all of its input before it writes, so writing first cannot deadlock;
    // its output is read on a thread so that the wait below can time out.
    let written = child
        .stdin
        .take()
        .map(|mut stdin| stdin.write_all(&obj))
        .unwrap_or(Ok(()));
    let mut stdout = child.stdout.take();
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        stdout
            .as_mut()
            .map(|out| out.read_to_string(&mut text))
            .transpose()
            .map(|_| text)
    });
    let deadline = Instant::now() + timeout;
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(2)),
            Ok(None) => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!("it took longer than {} s", timeout.as_secs_f32()));
            }
            Err(e) => return Err(format!("cannot wait for it: {e}")),
        }
    };
    let text = reader
        .join()
        .map_err(|_| "its output reader panicked".to_owned())?
        .map_err(|e| format!("reading its output: {e}"))?;
    if !status.success() {
        return Err(format!("it ended with {status}"));
    }
    written.map_err(|e| format!("writing the mesh to it: {e}"))?;
    parse_parts(&text)
}

/// Parts from the child's output: `x y z` lines, a blank line after each part.
fn parse_parts(text: &str) -> Result<Vec<Vec<Vec3>>, String> {
    let mut parts = Vec::new();
    let mut part = Vec::new();
    for (number, line) in text.lines().enumerate() {
        if line.is_empty() {
            parts.push(std::mem::take(&mut part));
            continue;
        }
        let values: Vec<f32> = line
            .split(' ')
            .map(str::parse)
            .collect::<Result<_, _>>()
            .map_err(|e| format!("line {}: {e}", number + 1))?;
        match values[..] {
            [x, y, z] if x.is_finite() && y.is_finite() && z.is_finite() => {
                part.push(Vec3::new(x, y, z))
            }
            _ => return Err(format!("line {} is not three finite numbers", number + 1)),
        }
    }
    if !part.is_empty() {
        return Err("the last part is cut off".into());
    }
    Ok(parts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_child_writes_what_the_parent_reads() {
        let torus = tacmesh_sim::torus(24, 12, 0.4, 0.1);
        let config = ConvexConfig::default();
        let mut input = Vec::new();
        tacmesh_formats::obj::write(&mut input, &torus).unwrap();
        let mut output = Vec::new();
        serve(&mut input.as_slice(), &mut output, &config).expect("serves");
        let parts = parse_parts(&String::from_utf8(output).unwrap()).expect("parses");
        assert_eq!(parts, vhacd_part_points(&torus, &config));
        assert!(parts.len() >= 3, "{} parts", parts.len());
    }

    #[test]
    fn nonsense_output_is_an_error() {
        assert!(parse_parts("1 2\n\n").is_err());
        assert!(parse_parts("1 2 NaN\n\n").is_err());
        assert!(parse_parts("1 2 3\n").is_err());
        assert_eq!(parse_parts(""), Ok(vec![]));
    }

    /// A program that is not tacmesh (here `true`, which prints nothing and succeeds, or
    /// `false`) gives no parts or an error, never a hang.
    #[test]
    fn a_child_that_is_not_tacmesh_gives_nothing_or_an_error() {
        let mesh = tacmesh_sim::cube(0.1);
        let config = ConvexConfig::default();
        if let Ok(parts) = decompose(Path::new("/bin/true"), &mesh, &config, CHILD_TIMEOUT) {
            assert!(parts.is_empty());
        }
        let failed = decompose(Path::new("/bin/false"), &mesh, &config, CHILD_TIMEOUT);
        assert!(failed.is_err_and(|why| why.contains("ended with")));
        let missing = decompose(Path::new("/nonexistent"), &mesh, &config, CHILD_TIMEOUT);
        assert!(missing.is_err_and(|why| why.contains("cannot start")));
        let slow = decompose(
            Path::new("/bin/sleep"),
            &mesh,
            &config,
            Duration::from_millis(50),
        );
        assert!(
            slow.is_err(),
            "sleep without an argument fails or times out"
        );
    }
}
