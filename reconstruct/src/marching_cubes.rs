//! Marching cubes over a sparse signed distance: the zero level set as an indexed triangle mesh,
//! following W. E. Lorensen and H. E. Cline, "Marching cubes: a high resolution 3D surface
//! construction algorithm" (SIGGRAPH 1987), with case tables in the numbering of Paul Bourke's
//! tabulation (see `marching_cubes/tables.rs` for the numbering and how ambiguous faces are cut).
//!
//! Entry point: [`marching_cubes`].
//!
//! A cell is the cube between grid corner `ijk` and `ijk + (1, 1, 1)`; it is meshed only when all
//! eight corners are known, so the mesh stops where the data stops instead of closing over the
//! unknown. Every vertex lies on one grid edge and is shared by all cells around that edge, so
//! the mesh is watertight wherever the known region encloses the surface.
//!
//! The stages, in the order they run (each block in parallel, merged in sorted block order so the
//! output does not depend on thread count or hash-map order):
//! 1. gather a block's 9³ window of corner values (its own and the first layer of its +x, +y, +z
//!    neighbours), and record which corners are known and which inside as bit rows along x;
//! 2. place a vertex on every grid edge the block owns (the edge's lower corner lies in the block)
//!    whose two corners are known and of opposite sign;
//! 3. number the vertices block after block;
//! 4. triangulate every cell whose min corner lies in the block, looking each edge's vertex up in
//!    the block that owns the edge;
//! 5. concatenate, and drop vertices that no cell used (crossed edges whose every neighbouring
//!    cell has an unknown corner).

mod tables;

use glam::{IVec3, Vec3};
use rayon::prelude::*;
use tacmesh_source::TriMesh;

use crate::sparse_sdf::{local_index, SparseSdf, BLOCK_EDGE, BLOCK_VOXELS};
use tables::{CORNER_OFFSETS, EDGE_ORIGIN_AXIS, EDGE_TABLE, TRIANGLE_TABLE};

/// Closest a vertex may come to either end of its edge, as a fraction of the edge.
///
/// A corner value of exactly zero, or within rounding of it, would put the vertices of all edges
/// meeting at that corner on one point: coincident vertices and needle triangles. Clamping the
/// interpolation parameter to `[EDGE_PARAM_MARGIN, 1 − EDGE_PARAM_MARGIN]` keeps them apart
/// while moving a vertex by at most 1/1000 of a voxel, well below the error of the linear
/// interpolation itself.
const EDGE_PARAM_MARGIN: f32 = 1e-3;

/// Corners per axis of the window a block reads: its own eight plus one from the next block.
const WINDOW_EDGE: i32 = BLOCK_EDGE + 1;
const WINDOW_CORNERS: usize = (WINDOW_EDGE * WINDOW_EDGE * WINDOW_EDGE) as usize;
/// Rows of corners along x in a window, one per `(y, z)`.
const WINDOW_ROWS: usize = (WINDOW_EDGE * WINDOW_EDGE) as usize;
/// Bits `0..BLOCK_EDGE` of a row: the corners (or cells, or edges) that belong to the block.
const BLOCK_ROW: u16 = (1 << BLOCK_EDGE) - 1;
const _: () = assert!(WINDOW_EDGE <= 16, "a window row must fit a u16 mask");

/// Grid edges a block owns: the +x, +y and +z edge of each of its corners.
const OWNED_EDGES: usize = 3 * BLOCK_VOXELS;
/// Marks an owned edge with no vertex.
const NO_VERTEX: u16 = u16::MAX;
const _: () = assert!(
    OWNED_EDGES < NO_VERTEX as usize,
    "vertex numbers in a block fit u16"
);

/// Corner values of one block's window in metres, `NaN` where unknown.
type Window = [f32; WINDOW_CORNERS];

fn window_index(local: IVec3) -> usize {
    (local.x + WINDOW_EDGE * (local.y + WINDOW_EDGE * local.z)) as usize
}

/// Index of the row of window corners at `(y, z)`: the next row in y is `+ 1`, in z
/// `+ WINDOW_EDGE`.
fn row_index(y: i32, z: i32) -> usize {
    (y + WINDOW_EDGE * z) as usize
}

/// Which of the eight blocks `key + {0,1}³` holds window corner `local`: bit 0 for +x, bit 1 for
/// +y, bit 2 for +z.
fn neighbour_slot(local: IVec3) -> usize {
    let step = local / BLOCK_EDGE;
    (step.x | step.y << 1 | step.z << 2) as usize
}

fn slot_step(slot: usize) -> IVec3 {
    IVec3::new(
        slot as i32 & 1,
        (slot as i32 >> 1) & 1,
        (slot as i32 >> 2) & 1,
    )
}

/// Index of the grid edge along `axis` from corner `local` among the edges a block owns; the
/// block's vertices are numbered in this order.
fn owned_edge(local: IVec3, axis: usize) -> usize {
    3 * local_index(local) + axis
}

/// Iterates the set bits of `mask`, lowest first.
fn set_bits(mut mask: u16) -> impl Iterator<Item = i32> {
    std::iter::from_fn(move || {
        let bit = mask.trailing_zeros() as i32;
        mask &= mask.wrapping_sub(1);
        (bit < 16).then_some(bit)
    })
}

// ---- 1. gather --------------------------------------------------------------------------------

/// Fills `window` with the corner values block `key` reads: all of the block itself, and the
/// first layer of the next block along each axis.
fn gather_window(sdf: &SparseSdf, key: IVec3, window: &mut Window) {
    window.fill(f32::NAN);
    let span = |step: i32| {
        if step == 0 {
            0..BLOCK_EDGE
        } else {
            BLOCK_EDGE..WINDOW_EDGE
        }
    };
    for slot in 0..8 {
        let step = slot_step(slot);
        let Some(block) = sdf.blocks.get(&(key + step)) else {
            continue;
        };
        for z in span(step.z) {
            for y in span(step.y) {
                let row = IVec3::new(BLOCK_EDGE * step.x, y, z);
                let from = local_index(row - step * BLOCK_EDGE);
                let to = window_index(row);
                if step.x == 0 {
                    // A whole row; the fixed length lets the copy inline.
                    const ROW: usize = BLOCK_EDGE as usize;
                    window[to..to + ROW].copy_from_slice(&block.values_m[from..from + ROW]);
                } else {
                    window[to] = block.values_m[from];
                }
            }
        }
    }
}

/// Signs of a window's corners as bit rows along x (bit `x` of row `row_index(y, z)`), so that
/// whole rows of edges and cells are classified with a few bit operations.
struct SignRows {
    known: [u16; WINDOW_ROWS],
    /// Set only where known.
    inside: [u16; WINDOW_ROWS],
}

/// The sign rows of `window`, or `None` when it holds no sign change (no vertex, no triangle).
fn sign_rows(window: &Window) -> Option<SignRows> {
    let mut rows = SignRows {
        known: [0; WINDOW_ROWS],
        inside: [0; WINDOW_ROWS],
    };
    for (row, values) in window.chunks_exact(WINDOW_EDGE as usize).enumerate() {
        for (x, &value) in values.iter().enumerate() {
            // `SparseSdf::get` treats every non-finite value as unknown; so do we.
            rows.known[row] |= u16::from(value.is_finite()) << x;
            rows.inside[row] |= u16::from(value < 0.0 && value.is_finite()) << x;
        }
    }
    let any_inside = rows.inside.iter().any(|&r| r != 0);
    let any_outside = rows
        .known
        .iter()
        .zip(&rows.inside)
        .any(|(k, i)| k & !i != 0);
    (any_inside && any_outside).then_some(rows)
}

// ---- 2. place vertices ------------------------------------------------------------------------

/// What stage 2 leaves for stage 4 about one block.
struct BlockVertices {
    /// `None` when the block's window has no sign change.
    rows: Option<SignRows>,
    /// For each owned edge, the number of its vertex within the block, or `NO_VERTEX`; empty
    /// when the block has no vertex.
    vertex_of_edge: Vec<u16>,
    /// One vertex per crossed owned edge, in owned-edge order.
    vertices: Vec<Vec3>,
}

/// Places a vertex on every owned edge of block `key` whose corners are known and of opposite
/// sign, by linear interpolation of the two values.
fn place_vertices(sdf: &SparseSdf, key: IVec3, window: &mut Window) -> BlockVertices {
    gather_window(sdf, key, window);
    let Some(rows) = sign_rows(window) else {
        return BlockVertices {
            rows: None,
            vertex_of_edge: Vec::new(),
            vertices: Vec::new(),
        };
    };
    let mut vertex_of_edge = vec![NO_VERTEX; OWNED_EDGES];
    let mut vertices = Vec::new();
    let block_min = key * BLOCK_EDGE;
    let (known, inside) = (&rows.known, &rows.inside);
    for z in 0..BLOCK_EDGE {
        for y in 0..BLOCK_EDGE {
            let r = row_index(y, z);
            // Bit x set when the edge from corner (x, y, z) along the axis is crossed.
            let crossed_along = |next: usize, shift: u32| {
                known[r] & known[next] >> shift & (inside[r] ^ inside[next] >> shift) & BLOCK_ROW
            };
            let crossed = [
                crossed_along(r, 1),
                crossed_along(r + 1, 0),
                crossed_along(r + WINDOW_EDGE as usize, 0),
            ];
            for x in set_bits(crossed[0] | crossed[1] | crossed[2]) {
                let local = IVec3::new(x, y, z);
                for (axis, step) in IVec3::AXES.into_iter().enumerate() {
                    if crossed[axis] >> x & 1 == 0 {
                        continue;
                    }
                    let low = window[window_index(local)];
                    let high = window[window_index(local + step)];
                    // Opposite signs, so `low - high` is not zero.
                    let t = (low / (low - high)).clamp(EDGE_PARAM_MARGIN, 1.0 - EDGE_PARAM_MARGIN);
                    let mut p = sdf.position(block_min + local);
                    p[axis] += t * sdf.voxel_size_m;
                    // At most OWNED_EDGES vertices, which fits (checked at compile time above).
                    vertex_of_edge[owned_edge(local, axis)] = vertices.len() as u16;
                    vertices.push(p);
                }
            }
        }
    }
    BlockVertices {
        rows: Some(rows),
        vertex_of_edge,
        vertices,
    }
}

// ---- 3. number vertices -----------------------------------------------------------------------

/// The global number of each block's first vertex, and the total.
fn number_vertices(blocks: &[BlockVertices]) -> (Vec<u32>, usize) {
    let mut first = Vec::with_capacity(blocks.len());
    let mut total = 0usize;
    for block in blocks {
        // Invariant: u32 indices cover any mesh that fits in memory here (4 G vertices would
        // need 48 GB for positions alone).
        first.push(u32::try_from(total).expect("more than u32::MAX mesh vertices"));
        total += block.vertices.len();
    }
    (first, total)
}

// ---- 4. triangulate ---------------------------------------------------------------------------

/// Triangles of every cell whose min corner lies in block `index` of the sorted `keys`.
fn triangulate_cells(
    index: usize,
    keys: &[IVec3],
    blocks: &[BlockVertices],
    first_vertex: &[u32],
) -> Vec<[u32; 3]> {
    let Some(rows) = &blocks[index].rows else {
        return Vec::new();
    };
    // The vertex numbers on the edges owned by each of the eight blocks this block's cells
    // touch (empty for a block without vertices), with the number of the block's first vertex.
    let owners: [(&[u16], u32); 8] = std::array::from_fn(|slot| {
        let neighbour = (keys[index] + slot_step(slot)).to_array();
        match keys.binary_search_by_key(&neighbour, |k| k.to_array()) {
            Ok(owner) => (&blocks[owner].vertex_of_edge[..], first_vertex[owner]),
            Err(_) => (&[][..], 0),
        }
    });
    // Where the vertex on `edge` of `cell` is numbered: the owning block's vertex numbers, its
    // first vertex, and the edge's index among its owned edges.
    let owner_of = |cell: IVec3, edge: usize| {
        let (origin, axis) = EDGE_ORIGIN_AXIS[edge];
        let low = cell + IVec3::from_array(origin);
        let slot = neighbour_slot(low);
        let (numbers, first) = owners[slot];
        (
            numbers,
            first,
            owned_edge(low - slot_step(slot) * BLOCK_EDGE, axis),
        )
    };
    let (own_numbers, own_first) = owners[0];
    let edge_step =
        EDGE_ORIGIN_AXIS.map(|(origin, axis)| owned_edge(IVec3::from_array(origin), axis));

    // About two triangles per vertex on a closed surface.
    let mut triangles = Vec::with_capacity(2 * blocks[index].vertices.len());
    for z in 0..BLOCK_EDGE {
        for y in 0..BLOCK_EDGE {
            // A cell at (x, y, z) is worth a look when its corners, in the four rows at
            // (y or y + 1, z or z + 1) and columns x and x + 1, are all known and of both signs.
            let r = row_index(y, z);
            let (mut all_known, mut any_inside, mut all_inside) = (BLOCK_ROW, 0, BLOCK_ROW);
            for q in [
                r,
                r + row_index(1, 0),
                r + row_index(0, 1),
                r + row_index(1, 1),
            ] {
                let (k, i) = (rows.known[q], rows.inside[q]);
                all_known &= k & k >> 1;
                any_inside |= i | i >> 1;
                all_inside &= i & i >> 1;
            }
            for x in set_bits(all_known & any_inside & !all_inside) {
                let case = CORNER_OFFSETS
                    .iter()
                    .enumerate()
                    .map(|(corner, &[dx, dy, dz])| {
                        let row = rows.inside[r + row_index(dy, dz)];
                        usize::from(row >> (x + dx) & 1) << corner
                    })
                    .fold(0, |case, bit| case | bit);
                let cell = IVec3::new(x, y, z);
                let inner = cell.cmplt(IVec3::splat(BLOCK_EDGE - 1)).all();
                let cell_edge = owned_edge(cell, 0);
                let mut vertex_of_edge = [0u32; 12];
                for edge in set_bits(EDGE_TABLE[case]) {
                    let edge = edge as usize;
                    let (numbers, first, owned) = if inner {
                        // All twelve edges are the block's own (the common case, 343 cells of
                        // 512): their owned-edge indices are the cell's plus a constant.
                        (own_numbers, own_first, cell_edge + edge_step[edge])
                    } else {
                        owner_of(cell, edge)
                    };
                    // Invariant: the edge is crossed and both its corners are known, so the block
                    // holding its lower corner is stored and placed a vertex on it (a missing
                    // block would leave `numbers` empty and this index would panic).
                    let number = numbers[owned];
                    debug_assert_ne!(number, NO_VERTEX, "crossed edge without a vertex");
                    vertex_of_edge[edge] = first + u32::from(number);
                }
                for edges in TRIANGLE_TABLE[case] {
                    let [a, b, c] = edges.map(|edge| vertex_of_edge[usize::from(edge)]);
                    if a != b && b != c && c != a {
                        triangles.push([a, b, c]);
                    }
                }
            }
        }
    }
    triangles
}

// ---- 5. merge ---------------------------------------------------------------------------------

/// Removes vertices no triangle uses, keeping the order of the rest.
fn drop_unused_vertices(mesh: &mut TriMesh) {
    let mut used = vec![false; mesh.vertices.len()];
    for &i in mesh.triangles.iter().flatten() {
        used[i as usize] = true;
    }
    if used.iter().all(|&u| u) {
        return;
    }
    let mut new_index = vec![u32::MAX; used.len()];
    let mut kept = 0;
    for (old, &keep) in used.iter().enumerate() {
        if keep {
            mesh.vertices[kept] = mesh.vertices[old];
            new_index[old] = kept as u32;
            kept += 1;
        }
    }
    mesh.vertices.truncate(kept);
    for i in mesh.triangles.iter_mut().flatten() {
        *i = new_index[*i as usize];
    }
}

/// The zero level set of `sdf` as an indexed triangle mesh, in the SDF's frame and metres.
///
/// Inside is `value < 0`. Triangles wind counter-clockwise seen from the positive side: the
/// face normal `(b − a) × (c − a)` points toward increasing distance. Cells with an unknown
/// corner emit nothing, so a surface seen from one side stays open at the edge of the data. The
/// output is the same for the same field, whatever the thread count or hash-map order.
pub fn marching_cubes(sdf: &SparseSdf) -> TriMesh {
    let mut keys: Vec<IVec3> = sdf.blocks.keys().copied().collect();
    keys.sort_unstable_by_key(|key| key.to_array());

    let blocks: Vec<BlockVertices> = keys
        .par_iter()
        .map_init(
            || Box::new([f32::NAN; WINDOW_CORNERS]),
            |window, &key| place_vertices(sdf, key, window),
        )
        .collect();
    let (first_vertex, vertex_count) = number_vertices(&blocks);
    let triangles: Vec<Vec<[u32; 3]>> = (0..keys.len())
        .into_par_iter()
        .map(|index| triangulate_cells(index, &keys, &blocks, &first_vertex))
        .collect();

    let mut vertices = Vec::with_capacity(vertex_count);
    for block in &blocks {
        vertices.extend_from_slice(&block.vertices);
    }
    let mut mesh = TriMesh::new(vertices, triangles.concat());
    drop_unused_vertices(&mut mesh);
    tracing::trace!(
        blocks = keys.len(),
        vertices = mesh.vertices.len(),
        triangles = mesh.triangles.len(),
        "marching cubes"
    );
    mesh
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use glam::DVec3;

    use super::*;
    use crate::sparse_sdf::SdfBlock;

    // ---- building fields ----

    fn set(sdf: &mut SparseSdf, ijk: IVec3, value_m: f32) {
        let (block, local) = SparseSdf::split(ijk);
        sdf.blocks.entry(block).or_default().values_m[local_index(local)] = value_m;
    }

    /// `distance_m` sampled on the grid corners in `lo..=hi` where it is within `band_m` of
    /// zero, unknown elsewhere.
    fn sampled(
        voxel_size_m: f32,
        origin: Vec3,
        (lo, hi): (IVec3, IVec3),
        band_m: f64,
        distance_m: impl Fn(DVec3) -> f64,
    ) -> SparseSdf {
        let mut sdf = SparseSdf::new(voxel_size_m, origin);
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    let ijk = IVec3::new(x, y, z);
                    let d = distance_m(sdf.position(ijk).as_dvec3());
                    if d.abs() <= band_m {
                        set(&mut sdf, ijk, d as f32);
                    }
                }
            }
        }
        sdf
    }

    /// The grid corners `lo..=hi` with the given values (unit voxels, origin at zero).
    fn grid(lo: IVec3, size: i32, mut value: impl FnMut(IVec3) -> f32) -> SparseSdf {
        let mut sdf = SparseSdf::new(1.0, Vec3::ZERO);
        for z in 0..size {
            for y in 0..size {
                for x in 0..size {
                    let ijk = lo + IVec3::new(x, y, z);
                    set(&mut sdf, ijk, value(ijk));
                }
            }
        }
        sdf
    }

    /// A 64-bit LCG (Knuth's MMIX constants): enough randomness for sign patterns, no new deps.
    struct Lcg(u64);

    impl Lcg {
        fn unit(&mut self) -> f32 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (self.0 >> 40) as f32 / (1u64 << 24) as f32
        }

        /// Uniform in `[-1, 1)`, exactly zero one time in ten.
        fn value(&mut self) -> f32 {
            if self.unit() < 0.1 {
                0.0
            } else {
                2.0 * self.unit() - 1.0
            }
        }
    }

    fn sphere(centre: DVec3, radius_m: f64) -> impl Fn(DVec3) -> f64 {
        move |p| (p - centre).length() - radius_m
    }

    // ---- checking meshes ----

    /// For each undirected edge `(low, high)`, how many triangles run it `low → high` and
    /// `high → low`.
    fn edge_uses(mesh: &TriMesh) -> HashMap<(u32, u32), [u32; 2]> {
        let mut uses = HashMap::new();
        for &[a, b, c] in &mesh.triangles {
            for (p, q) in [(a, b), (b, c), (c, a)] {
                let entry = uses.entry((p.min(q), p.max(q))).or_insert([0, 0]);
                entry[usize::from(p > q)] += 1;
            }
        }
        uses
    }

    fn assert_indices_sound(mesh: &TriMesh) {
        assert_eq!(mesh.first_bad_index(), None);
        let mut used = vec![false; mesh.vertices.len()];
        for &[a, b, c] in &mesh.triangles {
            assert!(
                a != b && b != c && c != a,
                "degenerate triangle {a} {b} {c}"
            );
            for i in [a, b, c] {
                used[i as usize] = true;
            }
        }
        assert!(used.iter().all(|&u| u), "unreferenced vertex");
    }

    /// Every edge in exactly two triangles, once in each direction (consistent winding).
    fn assert_closed_and_oriented(mesh: &TriMesh) {
        for (edge, uses) in edge_uses(mesh) {
            assert_eq!(uses, [1, 1], "edge {edge:?}");
        }
    }

    fn euler_characteristic(mesh: &TriMesh) -> i64 {
        mesh.vertices.len() as i64 - edge_uses(mesh).len() as i64 + mesh.triangles.len() as i64
    }

    fn signed_volume(mesh: &TriMesh) -> f64 {
        (0..mesh.triangles.len())
            .map(|t| {
                let [a, b, c] = mesh.corners(t).map(Vec3::as_dvec3);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// On a fully known grid spanning `lo..=hi` corners: every edge inside the grid is in two
    /// triangles with opposite directions, and none is in more than two. Edges on the grid's
    /// outer faces (both ends on one face; unit voxels make those coordinates exact) may be
    /// in one.
    fn assert_manifold_inside(mesh: &TriMesh, lo: IVec3, hi: IVec3) {
        assert_indices_sound(mesh);
        let (lo, hi) = (lo.as_vec3(), hi.as_vec3());
        for ((p, q), uses) in edge_uses(mesh) {
            let (p, q) = (mesh.vertices[p as usize], mesh.vertices[q as usize]);
            let on_outer_face = (0..3)
                .any(|k| (p[k] == lo[k] && q[k] == lo[k]) || (p[k] == hi[k] && q[k] == hi[k]));
            if on_outer_face {
                assert!(uses[0] <= 1 && uses[1] <= 1, "outer edge {p} {q}: {uses:?}");
            } else {
                assert_eq!(uses, [1, 1], "inner edge {p} {q}");
            }
        }
    }

    // ---- tests ----

    #[test]
    fn sphere_exact_sdf_is_watertight_and_close() {
        let (radius_m, voxel_m) = (0.25, 0.01);
        let centre = DVec3::new(0.0031, -0.0017, 0.0023);
        // Every corner of a cell the surface passes through is within √3 voxels of it, so a
        // band of 2.5 voxels leaves no surface cell with an unknown corner.
        let sdf = sampled(
            voxel_m as f32,
            Vec3::new(-0.0004, 0.0007, 0.0002),
            (IVec3::splat(-30), IVec3::splat(30)),
            2.5 * voxel_m,
            sphere(centre, radius_m),
        );
        let mesh = marching_cubes(&sdf);

        assert!(
            mesh.triangles.len() > 5_000,
            "{} triangles",
            mesh.triangles.len()
        );
        assert_indices_sound(&mesh);
        assert_closed_and_oriented(&mesh);
        assert_eq!(euler_characteristic(&mesh), 2);

        // Along a cell edge the exact distance f(s) = √(d² + s²) − r has f'' ≤ 1/ρ, ρ the
        // distance from the centre, and ρ ≥ r − h on a crossed edge (f is 1-Lipschitz, so both
        // ends are within one voxel h of the surface). Linear interpolation over an edge of
        // length h is off by at most h²·max f''/8, and at the interpolated root that error is
        // the distance to the sphere: ≤ h²/(8(r − h)) ≈ 0.005 h here. The clamp moves a vertex
        // at most EDGE_PARAM_MARGIN·h further; 1 µm covers f32 rounding.
        let bound_m = voxel_m * voxel_m / (8.0 * (radius_m - voxel_m))
            + f64::from(EDGE_PARAM_MARGIN) * voxel_m
            + 1e-6;
        assert!(bound_m < 0.02 * voxel_m);
        let worst_m = mesh
            .vertices
            .iter()
            .map(|v| sphere(centre, radius_m)(v.as_dvec3()).abs())
            .fold(0.0, f64::max);
        assert!(
            worst_m <= bound_m,
            "vertex {worst_m} m off the sphere, bound {bound_m} m"
        );

        // Positive volume: normals point outward.
        let exact = 4.0 / 3.0 * std::f64::consts::PI * radius_m.powi(3);
        let volume = signed_volume(&mesh);
        assert!(
            (volume / exact - 1.0).abs() < 0.01,
            "volume {volume}, sphere {exact}"
        );
    }

    #[test]
    fn torus_has_genus_one() {
        let (major_m, minor_m, voxel_m) = (0.2, 0.07, 0.01);
        let centre = DVec3::new(0.0013, 0.0029, -0.0041);
        let torus = move |p: DVec3| {
            let q = p - centre;
            let ring = (q.x.hypot(q.y) - major_m).hypot(q.z);
            ring - minor_m
        };
        let sdf = sampled(
            voxel_m as f32,
            Vec3::ZERO,
            (IVec3::new(-30, -30, -10), IVec3::new(30, 30, 10)),
            2.5 * voxel_m,
            torus,
        );
        let mesh = marching_cubes(&sdf);

        assert!(!mesh.is_empty());
        assert_indices_sound(&mesh);
        assert_closed_and_oriented(&mesh);
        assert_eq!(euler_characteristic(&mesh), 0);
        let exact = 2.0 * std::f64::consts::PI.powi(2) * major_m * minor_m * minor_m;
        assert!((signed_volume(&mesh) / exact - 1.0).abs() < 0.02);
    }

    #[test]
    fn unknown_corners_emit_nothing() {
        // A tilted plane, known only for grid x ≤ 3: block x = 0 holds unknown corners for
        // x = 4..8 and block x = 1 is not stored at all.
        let normal = DVec3::new(0.1, 0.2, 1.0).normalize();
        let mut sdf = SparseSdf::new(1.0, Vec3::ZERO);
        for z in -8..8 {
            for y in -8..16 {
                for x in -8..=3 {
                    let ijk = IVec3::new(x, y, z);
                    set(&mut sdf, ijk, (normal.dot(ijk.as_dvec3()) - 0.37) as f32);
                }
            }
        }
        let mesh = marching_cubes(&sdf);

        assert!(!mesh.is_empty());
        assert_indices_sound(&mesh);
        let last_known_x = 3.0;
        assert!(mesh.vertices.iter().all(|v| v.x <= last_known_x));
        // Open: some edges are in one triangle only, and all of those lie on the border of the
        // known region; every other edge is in two.
        let (lo, hi) = (Vec3::new(-8.0, -8.0, -8.0), Vec3::new(3.0, 15.0, 7.0));
        let uses = edge_uses(&mesh);
        assert!(uses.values().any(|&u| u[0] + u[1] == 1));
        assert_manifold_inside(&mesh, lo.as_ivec3(), hi.as_ivec3());
        // No closing residue: every triangle lies in the plane and faces along its normal.
        for t in 0..mesh.triangles.len() {
            let [a, b, c] = mesh.corners(t).map(Vec3::as_dvec3);
            assert!(
                (b - a).cross(c - a).dot(normal) > 0.0,
                "triangle {t} faces away"
            );
        }
    }

    #[test]
    fn random_fields_give_manifold_edges() {
        let mut rng = Lcg(0x7ac_5eed);
        // The grid straddles block boundaries at 0 and 8 on every axis.
        let (lo, size) = (IVec3::new(5, -3, 6), 6);
        let mut triangles = 0;
        for _ in 0..300 {
            let sdf = grid(lo, size, |_| rng.value());
            let mesh = marching_cubes(&sdf);
            assert_manifold_inside(&mesh, lo, lo + (size - 1));
            triangles += mesh.triangles.len();
        }
        assert!(triangles > 10_000);
    }

    #[test]
    fn every_sign_case_is_manifold_among_random_neighbours() {
        let mut rng = Lcg(256);
        // A 3³-cell grid whose centre cell (min corner 7, 7, 7) takes each case in turn.
        let (lo, size, centre) = (IVec3::splat(6), 4, IVec3::splat(7));
        for case in 0..256 {
            for _ in 0..8 {
                let sdf = grid(lo, size, |ijk| {
                    let Some(corner) = CORNER_OFFSETS
                        .iter()
                        .position(|&o| ijk == centre + IVec3::from_array(o))
                    else {
                        return rng.value();
                    };
                    let magnitude = 0.05 + rng.unit();
                    if case >> corner & 1 == 1 {
                        -magnitude
                    } else {
                        magnitude
                    }
                });
                assert_manifold_inside(&marching_cubes(&sdf), lo, lo + (size - 1));
            }
        }
    }

    #[test]
    fn every_sign_case_faces_from_inside_to_outside() {
        for case in 0..256usize {
            let inside = |ijk: IVec3| {
                let corner = CORNER_OFFSETS
                    .iter()
                    .position(|&o| ijk == IVec3::from_array(o))
                    .expect("corner of the unit cell");
                case >> corner & 1 == 1
            };
            let sdf = grid(IVec3::ZERO, 2, |ijk| if inside(ijk) { -1.0 } else { 1.0 });
            let mesh = marching_cubes(&sdf);
            assert_indices_sound(&mesh);
            assert_eq!(
                mesh.triangles.len(),
                TRIANGLE_TABLE[case].len(),
                "case {case:#010b}"
            );
            assert_eq!(mesh.vertices.len() as u32, EDGE_TABLE[case].count_ones());
            for t in 0..mesh.triangles.len() {
                let [a, b, c] = mesh.corners(t);
                let normal = (b - a).cross(c - a);
                // With values ±1 each vertex is an edge midpoint; its edge runs along the axis
                // where its coordinate is one half.
                let outward: f32 = [a, b, c]
                    .iter()
                    .map(|&v| {
                        let axis = (0..3).find(|&k| v[k] == 0.5).expect("edge midpoint");
                        let step = IVec3::AXES[axis];
                        let low = (v - 0.5 * step.as_vec3()).as_ivec3();
                        let toward_outside = if inside(low) { 1.0 } else { -1.0 };
                        toward_outside * normal[axis]
                    })
                    .sum();
                assert!(outward > 0.0, "case {case:#010b}, triangle {t}");
            }
        }
    }

    #[test]
    fn empty_field_gives_empty_mesh() {
        assert_eq!(
            marching_cubes(&SparseSdf::new(0.01, Vec3::ZERO)),
            TriMesh::default()
        );
        let mut unknown = SparseSdf::new(0.01, Vec3::ZERO);
        unknown.blocks.insert(IVec3::ZERO, SdfBlock::default());
        assert_eq!(marching_cubes(&unknown), TriMesh::default());
        let outside = grid(IVec3::splat(-4), 9, |_| 0.5);
        assert_eq!(marching_cubes(&outside), TriMesh::default());
    }

    #[test]
    fn output_is_deterministic() {
        let field = sphere(DVec3::new(0.01, 0.02, -0.015), 0.12);
        let bounds = (IVec3::splat(-20), IVec3::splat(20));
        let sdf = sampled(0.01, Vec3::ZERO, bounds, 0.03, &field);
        // The same blocks inserted in reverse order into a map with its own hasher seed.
        let mut keys: Vec<IVec3> = sdf.blocks.keys().copied().collect();
        keys.sort_unstable_by_key(|k| std::cmp::Reverse(k.to_array()));
        let mut shuffled = SparseSdf::new(sdf.voxel_size_m, sdf.origin);
        for key in keys {
            shuffled.blocks.insert(key, sdf.blocks[&key].clone());
        }

        let in_pool = |threads: usize, sdf: &SparseSdf| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a thread pool for the test")
                .install(|| marching_cubes(sdf))
        };
        let reference = in_pool(1, &sdf);
        assert!(!reference.is_empty());
        assert_eq!(in_pool(4, &sdf), reference);
        assert_eq!(in_pool(3, &shuffled), reference);
        assert_eq!(marching_cubes(&shuffled), reference);
    }

    /// Speed report, not a check: `cargo test --release -p tacmesh-reconstruct
    /// sphere_meshing_speed -- --ignored --nocapture`. Other load on the machine only ever adds
    /// to a run, so the minimum is the figure to quote.
    #[test]
    #[ignore = "timing report; run in release"]
    fn sphere_meshing_speed_report() {
        let voxel_m = 0.01;
        let sdf = sampled(
            voxel_m as f32,
            Vec3::ZERO,
            (IVec3::splat(-56), IVec3::splat(56)),
            3.0 * voxel_m,
            sphere(DVec3::new(0.0021, -0.0013, 0.0007), 0.5),
        );
        let mesh = marching_cubes(&sdf);
        println!(
            "sphere r = 0.5 m at 1 cm, band ±3 voxels: {} blocks, {} vertices, {} triangles",
            sdf.blocks.len(),
            mesh.vertices.len(),
            mesh.triangles.len()
        );
        for threads in [1, 2, 4] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a thread pool for the report");
            let mut times_ms: Vec<f64> = (0..51)
                .map(|_| {
                    let start = std::time::Instant::now();
                    std::hint::black_box(pool.install(|| marching_cubes(&sdf)));
                    start.elapsed().as_secs_f64() * 1e3
                })
                .collect();
            times_ms.sort_by(f64::total_cmp);
            println!(
                "{threads} thread(s): min {:.2} ms, median {:.2} ms",
                times_ms[0],
                times_ms[times_ms.len() / 2]
            );
        }
    }
}
