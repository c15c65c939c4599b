//! Closes the surface where the band of known corners ends on its inside: thin parts.
//!
//! One plane per voxel cannot hold both sides of a part thinner than the plane fit's box
//! (Suzanne's ears, 3 cm, against a box 4 voxels wide): the two sides' points give one plane in
//! the middle, the signed distance is negative on one side of it and positive on the other, and
//! the zero set is a single sheet whose rim ends where the band of known corners ends: a hole
//! the size of the ear. A sampled closed object is known everywhere on its surface, so its band
//! encloses the unknown inside, and unknown corners reachable from far away are outside.
//! Here the unknown corners next to the band get that sign, found by a flood fill from the box
//! around the band: a negative known corner next to an outside unknown one then closes the
//! surface there, and the enclosed inside gets a surface nowhere. The band reaches about as far
//! past the middle plane as its width, so the negative corners next to the outside are peeled
//! off that many layers deep first: the thin part becomes a slab about as thick as the data
//! says (on Suzanne at 20 mm this leaves the faces and the mean Hausdorff error as they were
//! with the holes, and the volume within 3 % instead of 6 %).
//!
//! This is only right for a surface that encloses a volume: an open shell (one view, no
//! viewpoint) has no inside, and closing its inner side would turn it into a slab. So the fill
//! runs only when the band encloses an inside and the negative corners that face the outside
//! are a small share of the band's outer edge (a thin part, not a whole side).
//!
//! Entry point: [`close_where_band_ends`].

use glam::IVec3;

use crate::cell_index::FACE_STEPS;
use crate::sparse_sdf::{local_index, SparseSdf, BLOCK_EDGE};

/// Largest box of corners the fill walks (512³; two bytes each, a corner's state and its
/// neighbourhood's flags); a larger grid is left as it is.
const MAX_CORNERS: usize = 1 << 27;

/// Largest share of the band's outward edge (known corners next to outside unknown ones) that
/// may be negative for the fill to run: a thin part's rim, not a whole open side.
const MAX_NEGATIVE_EDGE_SHARE: f64 = 0.2;

const UNKNOWN: u8 = 0;
const NEGATIVE: u8 = 1;
const POSITIVE: u8 = 2;
const OUTSIDE: u8 = 3;

/// What [`close_where_band_ends`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BandClosure {
    /// Unknown corners given a positive value (outside, next to a negative known one).
    pub closed_corners: usize,
    /// Unknown corners given a negative value (enclosed, next to the band).
    pub filled_corners: usize,
    /// Negative corners of thin parts turned positive (peeled off from the outside).
    pub eroded_corners: usize,
}

/// Gives the unknown corners next to the band of `sdf` the sign of where they are (outside when
/// reachable from beyond the band, inside when enclosed by it), so marching cubes closes the
/// surface where the band ends in a thin part. Does nothing to a band that encloses nothing or
/// whose outward edge is largely negative (an open shell). Values given are half a voxel;
/// `erode_layers` layers of negative corners next to the outside are turned positive first
/// (the signed distance's band, in voxels).
pub fn close_where_band_ends(sdf: &mut SparseSdf, erode_layers: i32) -> BandClosure {
    let none = BandClosure::default();
    let Some(lo_block) = sdf.blocks.keys().copied().reduce(IVec3::min) else {
        return none;
    };
    let hi_block = sdf.blocks.keys().copied().fold(lo_block, IVec3::max);
    // Two layers of corners around the blocks, all unknown: the fill starts on the outer one,
    // and the inner one holds the corners next to the band's outermost known ones.
    let lo = lo_block * BLOCK_EDGE - IVec3::splat(2);
    let size = (hi_block - lo_block + IVec3::ONE) * BLOCK_EDGE + IVec3::splat(4);
    let total = size.x as usize * size.y as usize * size.z as usize;
    if total > MAX_CORNERS {
        return none;
    }
    let at = |p: IVec3| (p.x + size.x * (p.y + size.y * p.z)) as usize;
    let mut state = vec![UNKNOWN; total];
    for (key, block) in &sdf.blocks {
        for z in 0..BLOCK_EDGE {
            for y in 0..BLOCK_EDGE {
                for x in 0..BLOCK_EDGE {
                    let local = IVec3::new(x, y, z);
                    let v = block.values_m[local_index(local)];
                    if v.is_finite() {
                        state[at(*key * BLOCK_EDGE + local - lo)] =
                            if v < 0.0 { NEGATIVE } else { POSITIVE };
                    }
                }
            }
        }
    }

    // Flood the unknown corners reachable from the box's faces (6-connected). The outermost
    // layer is all unknown: mark it outside, and flood from the unknown corners of the layer
    // inside it, whose neighbours are all in the box (no bounds to check). Corners are
    // addressed by index: a step is a fixed offset.
    let (sx, sxy) = (size.x as usize, size.x as usize * size.y as usize);
    let steps = [1, sx, sxy];
    let mut queue: Vec<u32> = Vec::new();
    for z in 0..size.z {
        for y in 0..size.y {
            for x in 0..size.x {
                let p = IVec3::new(x, y, z);
                // Corners from the box's faces: 0 on the outermost layer.
                let layer = p.min(size - IVec3::ONE - p).min_element();
                if layer == 0 {
                    state[at(p)] = OUTSIDE;
                } else if layer == 1 && state[at(p)] == UNKNOWN {
                    state[at(p)] = OUTSIDE;
                    queue.push(at(p) as u32);
                }
            }
        }
    }
    while let Some(i) = queue.pop() {
        let i = i as usize;
        for step in steps {
            for q in [i - step, i + step] {
                if state[q] == UNKNOWN {
                    state[q] = OUTSIDE;
                    queue.push(q as u32);
                }
            }
        }
    }

    // Per corner, whether a negative corner and whether any known corner is in its 3 × 3 × 3
    // neighbourhood (every cell marching cubes could mesh): one bit each, spread one corner
    // along x, then y, then z, instead of reading 27 neighbours per corner.
    const NEAR_NEGATIVE: u8 = 1;
    const NEAR_KNOWN: u8 = 2;
    let mut near: Vec<u8> = state
        .iter()
        .map(|&s| match s {
            NEGATIVE => NEAR_NEGATIVE | NEAR_KNOWN,
            POSITIVE => NEAR_KNOWN,
            _ => 0,
        })
        .collect();
    for step in steps {
        spread_along(&mut near, step);
    }

    // The unknown corners next to a known one, and the band's outward edge by sign.
    let mut to_close = Vec::new();
    let mut to_fill = Vec::new();
    let (mut negative_edge, mut edge) = (0usize, 0usize);
    for z in 1..size.z - 1 {
        for y in 1..size.y - 1 {
            for x in 1..size.x - 1 {
                let p = IVec3::new(x, y, z);
                let here = state[at(p)];
                if here == NEGATIVE || here == POSITIVE {
                    continue;
                }
                let next_to_negative = near[at(p)] & NEAR_NEGATIVE != 0;
                let next_to_known = near[at(p)] & NEAR_KNOWN != 0;
                if here == OUTSIDE {
                    if next_to_known {
                        edge += 1;
                    }
                    if next_to_negative {
                        negative_edge += 1;
                        to_close.push(p + lo);
                    }
                } else if next_to_known {
                    to_fill.push(p + lo);
                }
            }
        }
    }
    let encloses = !to_fill.is_empty();
    let thin_parts_only = (negative_edge as f64) <= MAX_NEGATIVE_EDGE_SHARE * edge as f64;
    if !(encloses && thin_parts_only) {
        return none;
    }
    // The band reaches about `band_voxels` past the plane in the middle of a thin part; peel
    // that many layers of its negative corners off from the outside, so the slab ends about
    // where the part's far side is rather than a band's width behind it.
    let voxel = sdf.voxel_size_m;
    let mut front = to_close.clone();
    let mut eroded_corners = 0;
    for _ in 0..erode_layers {
        let mut eroded = Vec::new();
        for &ijk in &front {
            for step in FACE_STEPS {
                let q = ijk - lo + step;
                if state[at(q)] == NEGATIVE {
                    state[at(q)] = OUTSIDE;
                    eroded.push(q + lo);
                }
            }
        }
        for &ijk in &eroded {
            set(sdf, ijk, 0.1 * voxel);
        }
        eroded_corners += eroded.len();
        front = eroded;
    }
    for &ijk in &to_close {
        set(sdf, ijk, 0.5 * voxel);
    }
    for &ijk in &to_fill {
        set(sdf, ijk, -0.5 * voxel);
    }
    BandClosure {
        closed_corners: to_close.len(),
        filled_corners: to_fill.len(),
        eroded_corners,
    }
}

/// `values[i] | values[i - step] | values[i + step]` (the values as they were) into every
/// `values[i]` with both neighbours in the slice, in place, a block at a time: the block's
/// values as they were, with `step` more on either side, are copied first, so the extra memory
/// is a block and two steps (at most a few slices of the box), not another box.
fn spread_along(values: &mut [u8], step: usize) {
    const BLOCK: usize = 1 << 14;
    let len = values.len();
    if step == 0 || len <= 2 * step {
        return;
    }
    let block = BLOCK.max(step);
    // `was[k]` is the value at `start - step + k` before this pass.
    let mut was = vec![0u8; block + 2 * step];
    was[..step].copy_from_slice(&values[..step]);
    let mut start = step;
    while start < len - step {
        let end = (start + block).min(len - step);
        let n = end - start;
        was[step..n + 2 * step].copy_from_slice(&values[start..end + step]);
        let back = &was[..n];
        let here = &was[step..step + n];
        let ahead = &was[2 * step..2 * step + n];
        for (((value, &b), &h), &a) in values[start..end].iter_mut().zip(back).zip(here).zip(ahead)
        {
            *value = b | h | a;
        }
        was.copy_within(n..n + step, 0);
        start = end;
    }
}

fn set(sdf: &mut SparseSdf, ijk: IVec3, value_m: f32) {
    let (block, local) = SparseSdf::split(ijk);
    sdf.blocks.entry(block).or_default().values_m[local_index(local)] = value_m;
}

#[cfg(test)]
mod tests {
    use std::collections::{HashMap, VecDeque};

    use glam::Vec3;
    use tacmesh_source::TriMesh;

    use super::*;
    use crate::marching_cubes::marching_cubes;

    const VOXEL_M: f32 = 0.01;

    /// Edges used by other than two triangles: the mesh's holes (and non-manifold edges).
    fn open_edges(mesh: &TriMesh) -> usize {
        let mut uses: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &mesh.triangles {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                *uses.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        uses.values().filter(|&&n| n != 2).count()
    }

    /// A sphere's band of known distances, with a fin sticking out of it (+x) that is known only
    /// as one plane in its middle: the signed distance of a part too thin for its two sides.
    fn sphere_with_thin_fin() -> SparseSdf {
        let mut sdf = SparseSdf::new(VOXEL_M, Vec3::ZERO);
        let radius_m = 0.1;
        for z in -20..=20 {
            for y in -20..=20 {
                for x in -20..=30 {
                    let ijk = IVec3::new(x, y, z);
                    let p = sdf.position(ijk);
                    let sphere = p.length() - radius_m;
                    let in_fin = p.x > 0.05 && p.x < 0.2 && p.z.abs() < 0.04;
                    if in_fin && sphere > 0.0 && p.y.abs() <= 2.0 * VOXEL_M {
                        set(&mut sdf, ijk, p.y);
                    } else if sphere.abs() <= 2.5 * VOXEL_M {
                        set(&mut sdf, ijk, sphere);
                    }
                }
            }
        }
        sdf
    }

    #[test]
    fn thin_fin_of_a_closed_surface_comes_out_closed() {
        let mut sdf = sphere_with_thin_fin();
        assert!(
            open_edges(&marching_cubes(&sdf)) > 0,
            "the fin alone is open"
        );
        let closure = close_where_band_ends(&mut sdf, 1);
        assert!(closure.closed_corners > 0 && closure.filled_corners > 0);
        let mesh = marching_cubes(&sdf);
        assert_eq!(open_edges(&mesh), 0);
        // The fin is still there: the mesh reaches out along +x past the sphere.
        let reach_m = mesh.vertices.iter().map(|v| v.x).fold(f32::MIN, f32::max);
        assert!(reach_m > 0.18, "{reach_m}");
    }

    /// The corners to close and to fill counted the plain way: a breadth-first flood from the
    /// box's faces with every bound checked, and all 27 neighbours read per corner.
    fn corners_next_to_the_band(sdf: &SparseSdf) -> (usize, usize) {
        let lo_block = sdf.blocks.keys().copied().reduce(IVec3::min).unwrap();
        let hi_block = sdf.blocks.keys().copied().reduce(IVec3::max).unwrap();
        let lo = lo_block * BLOCK_EDGE - IVec3::splat(2);
        let size = (hi_block - lo_block + IVec3::ONE) * BLOCK_EDGE + IVec3::splat(4);
        let known = |p: IVec3| {
            let (block, local) = SparseSdf::split(p + lo);
            let v = sdf
                .blocks
                .get(&block)
                .map(|b| b.values_m[local_index(local)]);
            v.filter(|v| v.is_finite())
        };
        let mut outside = HashMap::new();
        let mut queue = VecDeque::new();
        for z in 0..size.z {
            for y in 0..size.y {
                for x in 0..size.x {
                    let p = IVec3::new(x, y, z);
                    if p.min(size - IVec3::ONE - p).min_element() == 0 {
                        outside.insert(p, ());
                        queue.push_back(p);
                    }
                }
            }
        }
        while let Some(p) = queue.pop_front() {
            for d in [IVec3::X, IVec3::Y, IVec3::Z] {
                for q in [p - d, p + d] {
                    let in_box = q.cmpge(IVec3::ZERO).all() && q.cmplt(size).all();
                    if in_box && known(q).is_none() && outside.insert(q, ()).is_none() {
                        queue.push_back(q);
                    }
                }
            }
        }
        let (mut close, mut fill) = (0, 0);
        for z in 1..size.z - 1 {
            for y in 1..size.y - 1 {
                for x in 1..size.x - 1 {
                    let p = IVec3::new(x, y, z);
                    if known(p).is_some() {
                        continue;
                    }
                    let (mut negative, mut any) = (false, false);
                    for dz in -1..=1 {
                        for dy in -1..=1 {
                            for dx in -1..=1 {
                                if let Some(v) = known(p + IVec3::new(dx, dy, dz)) {
                                    any = true;
                                    negative |= v < 0.0;
                                }
                            }
                        }
                    }
                    match outside.contains_key(&p) {
                        true if negative => close += 1,
                        false if any => fill += 1,
                        _ => {}
                    }
                }
            }
        }
        (close, fill)
    }

    /// The flood runs over corner indices and the neighbourhoods are read per axis (see
    /// [`close_where_band_ends`]): it must find the very corners the plain way finds.
    #[test]
    fn closes_and_fills_the_corners_the_plain_way_finds() {
        let mut sdf = sphere_with_thin_fin();
        let expected = corners_next_to_the_band(&sdf);
        let closure = close_where_band_ends(&mut sdf, 1);
        assert_eq!((closure.closed_corners, closure.filled_corners), expected);
        assert!(expected.0 > 0 && expected.1 > 0);
    }

    /// In place and a block at a time, as if every value were read before any was written;
    /// the first and last `step` values stay as they were.
    #[test]
    fn spreading_in_blocks_reads_the_values_as_they_were() {
        for (len, step) in [
            (40_000usize, 1usize),
            (40_000, 37),
            (70_001, 20_000),
            (5, 2),
            (4, 2),
        ] {
            let values: Vec<u8> = (0..len).map(|i| ((i * 7919) % 13 == 0) as u8).collect();
            let mut expected = values.clone();
            for i in step..len.saturating_sub(step) {
                expected[i] = values[i - step] | values[i] | values[i + step];
            }
            let mut spread = values;
            spread_along(&mut spread, step);
            assert_eq!(spread, expected, "{len} values, step {step}");
        }
    }

    #[test]
    fn open_shell_is_left_open() {
        let mut sdf = SparseSdf::new(VOXEL_M, Vec3::ZERO);
        for z in -2..=2 {
            for y in 0..20 {
                for x in 0..20 {
                    let ijk = IVec3::new(x, y, z);
                    let z_m = sdf.position(ijk).z;
                    set(&mut sdf, ijk, z_m);
                }
            }
        }
        let before = marching_cubes(&sdf);
        assert_eq!(close_where_band_ends(&mut sdf, 2), BandClosure::default());
        assert_eq!(marching_cubes(&sdf), before);
    }
}
