//! The simplifier on arbitrary meshes: `tacmesh_simplify::simplify` must return an error or a
//! valid result for any vertex and index buffers, then `fit_to_samples` runs on that result as
//! the pipeline runs it.
//!
//! Input layout: byte 0 picks how the mesh is built, byte 1 the residual bound, byte 2 the
//! minimum face count; the rest builds the mesh:
//! - `0`: OBJ text (the seeds are real meshes, so mutations stay close to closed manifolds);
//! - `1`: a height field: a width byte, then one height byte per grid vertex (an open manifold
//!   the simplifier can actually collapse);
//! - otherwise: a triangle soup built with `arbitrary`: raw `f32` triples (NaN and infinities
//!   included) and index triples of which some fall outside the vertices.
//!
//! Properties beyond "no panic", on success: every index is in range, no triangle repeats a
//! corner, every output vertex is used and finite, the report's counts match the output and
//! `faces_out ≤ faces_in`, and the reported residual is within the bound.

#![no_main]

use arbitrary::{Arbitrary, Unstructured};
use glam::Vec3;
use libfuzzer_sys::fuzz_target;
use tacmesh_simplify::{
    fit_to_samples, simplify, FitConfig, FitSamples, SimplifyConfig, WeightedSample,
};
use tacmesh_source::TriMesh;

/// Bounds that keep one input to milliseconds; meshes this size already hold every local case.
const MAX_VERTICES: usize = 512;
const MAX_TRIANGLES: usize = 1024;
const MAX_HEIGHT_FIELD_SIDE: usize = 24;

fuzz_target!(|data: &[u8]| {
    let Some(([mode, residual, min_faces], rest)) = data.split_first_chunk::<3>() else {
        return;
    };
    let Some(mesh) = build_mesh(*mode, rest) else {
        return;
    };
    let config = SimplifyConfig {
        max_residual_m: residual_m(*residual),
        min_faces: usize::from(*min_faces),
    };
    let Ok((mut out, report)) = simplify(&mesh, &config) else {
        return;
    };
    check_output(&mesh, &config, &out, &report);

    if config.max_residual_m > 0.0 && config.max_residual_m.is_finite() {
        let samples: Vec<WeightedSample> = mesh
            .vertices
            .iter()
            .map(|&point| WeightedSample { point, weight: 1.0 })
            .collect();
        let fit = FitConfig {
            iterations: 3,
            max_move_m: config.max_residual_m,
            stiffness: 1e-3,
            measure_after: true,
        };
        let triangles = out.triangles.clone();
        let data = FitSamples::new(&samples, 2.5 * config.max_residual_m);
        fit_to_samples(&mut out, &data, &fit);
        assert_eq!(out.triangles, triangles, "the fit changed connectivity");
        assert!(out.vertices.iter().all(|v| v.is_finite()));
    }
});

/// 0 to 0.252 m in millimetres, and the three values the config check must refuse or accept.
fn residual_m(byte: u8) -> f32 {
    match byte {
        255 => f32::INFINITY,
        254 => f32::NAN,
        253 => -0.001,
        mm => f32::from(mm) * 1e-3,
    }
}

fn build_mesh(mode: u8, bytes: &[u8]) -> Option<TriMesh> {
    let mesh = match mode {
        0 => tacmesh_formats::obj::parse(bytes, "fuzz.obj").ok()?,
        1 => height_field(bytes)?,
        _ => soup(bytes).ok()?,
    };
    (mesh.vertices.len() <= MAX_VERTICES && mesh.triangles.len() <= MAX_TRIANGLES).then_some(mesh)
}

/// A grid 1 cm apart with heights in millimetres, two triangles per cell.
fn height_field(bytes: &[u8]) -> Option<TriMesh> {
    let (&width, heights) = bytes.split_first()?;
    let width = usize::from(width) % (MAX_HEIGHT_FIELD_SIDE - 1) + 2;
    let height = (heights.len() / width).min(MAX_HEIGHT_FIELD_SIDE);
    if height < 2 {
        return None;
    }
    let vertices = heights[..width * height]
        .iter()
        .enumerate()
        .map(|(i, &h)| {
            let (x, y) = (i % width, i / width);
            Vec3::new(x as f32 * 0.01, y as f32 * 0.01, f32::from(h as i8) * 1e-3)
        })
        .collect();
    let mut triangles = Vec::new();
    for y in 0..height - 1 {
        for x in 0..width - 1 {
            let at = |dx: usize, dy: usize| ((y + dy) * width + x + dx) as u32;
            triangles.push([at(0, 0), at(1, 0), at(1, 1)]);
            triangles.push([at(0, 0), at(1, 1), at(0, 1)]);
        }
    }
    Some(TriMesh::new(vertices, triangles))
}

/// Raw vertices and index triples; an index byte counts modulo a little more than the vertex
/// count, so most triangles are valid and some point just past the end, and an optional
/// arbitrary `u32` replaces one index anywhere.
fn soup(bytes: &[u8]) -> arbitrary::Result<TriMesh> {
    let mut u = Unstructured::new(bytes);
    let vertices: Vec<Vec3> = Vec::<[f32; 3]>::arbitrary(&mut u)?
        .into_iter()
        .map(Vec3::from_array)
        .collect();
    let modulus = vertices.len() as u32 + 2;
    let mut triangles: Vec<[u32; 3]> = Vec::<[u8; 3]>::arbitrary(&mut u)?
        .into_iter()
        .map(|t| t.map(|i| u32::from(i) % modulus))
        .collect();
    if let Some((at, index)) = Option::<(usize, u32)>::arbitrary(&mut u)? {
        if !triangles.is_empty() {
            let at = at % (3 * triangles.len());
            triangles[at / 3][at % 3] = index;
        }
    }
    Ok(TriMesh::new(vertices, triangles))
}

fn check_output(
    input: &TriMesh,
    config: &SimplifyConfig,
    out: &TriMesh,
    report: &tacmesh_simplify::SimplifyReport,
) {
    assert_eq!(out.first_bad_index(), None, "output index out of range");
    assert!(out.vertices.iter().all(|v| v.is_finite()));
    let mut used = vec![false; out.vertices.len()];
    for &[a, b, c] in &out.triangles {
        assert!(a != b && b != c && c != a, "degenerate output triangle");
        for v in [a, b, c] {
            used[v as usize] = true;
        }
    }
    assert!(used.iter().all(|&u| u), "unused output vertex");
    assert_eq!(report.faces_in, input.triangles.len());
    assert_eq!(report.faces_out, out.triangles.len());
    assert_eq!(report.vertices_out, out.vertices.len());
    assert!(report.faces_out <= report.faces_in);
    assert!(
        report.max_residual_m <= config.max_residual_m,
        "residual {} above the bound {}",
        report.max_residual_m,
        config.max_residual_m
    );
}
