//! Greedy edge collapse ranked by quadrics and stopped by the maximum residual.
//!
//! Follows Garland & Heckbert 1997 (quadric ranking and placement, boundary constraint planes),
//! Hoppe 1996 / Hoppe et al. 1993 (support points reassigned to their nearest face, spring
//! energy) and Dey et al. 1999 (link condition); see the crate docs for the full references and
//! the exact residual definition.
//!
//! The stages run in this order, and the file is laid out in the same order:
//! validate → adjacency (corner lists, classify vertices, components) → quadrics and support
//! points → rank (edge queue) → collapse checks (topology, geometry, residual) → update →
//! compact. The public entry point [`simplify`] is last.
//!
//! Collapse rules, checked cheapest first when an edge is popped:
//!
//! | rule | refuses when |
//! |------|--------------|
//! | locked | either end is on a non-manifold edge or is a non-manifold (bow-tie) vertex: such edges are never queued |
//! | topology | edge has more than 2 faces; interior edge joining two boundary vertices; `a` and `b` share a neighbour that is not the apex of a face on `ab` (link condition); a face would be duplicated; the component would drop below 4 faces (closed) or 1 face (open) |
//! | geometry | a surviving face around `a` or `b` turns by more than 60° (`MIN_NORMAL_COS`), degenerates (`DEGENERATE_QUALITY`) or becomes a needle (`MIN_QUALITY`); or, after reassignment, a face's normal disagrees with the summed input normals of its support points |
//! | residual | a support point of a face around `a` or `b` would end farther than `max_residual_m` from every face around `v*`, or `v*` is farther than that from the faces around `a` and `b` |
//!
//! Placement of `v*`: two boundary vertices (a boundary edge) collapse onto whichever endpoint
//! costs less, and a boundary vertex never moves, so output boundary vertices are input boundary
//! vertices; two interior vertices go to the quadric minimiser, regularised toward the edge
//! midpoint, unless that is ill-conditioned or leaves the edge's bounding box grown by the edge
//! length, in which case the cheapest of `a`, `b` and the midpoint.
//!
//! Queue: edges are ranked lazily. A collapse bumps the stamp of the surviving vertex instead of
//! re-ranking its edges at once; a popped edge with an old stamp is re-ranked then, and queued
//! again unless it is still the cheapest. A refused edge is parked on both its vertices and queued
//! again only when a collapse changes the neighbourhood of one of them. Each edge has at most one
//! queue entry or one parked record at a time; entries of a vertex merged away are dropped when
//! popped, or all at once when they outnumber the live edges, and its edges to vertices new to
//! the survivor are queued afresh.

use glam::{DVec3, Vec3};
use tacmesh_source::TriMesh;

use crate::min_heap::MinHeap;
use crate::point_triangle::TriangleQuery;
use crate::quadric::Quadric;
use crate::triangle_grid::PointCells;
use crate::{SimplifyConfig, SimplifyError, SimplifyReport};

/// Weight of a boundary constraint plane per square metre of its edge, relative to face planes
/// weighted by their area (Garland & Heckbert §6.1, "preserving boundaries").
const BOUNDARY_WEIGHT: f64 = 100.0;
/// Spring constant per square metre of quadric face area (Hoppe 1996 §4.2 `E_spring`), kept tiny:
/// it breaks ties in flat regions toward short edges and keeps triangles well shaped.
const SPRING_WEIGHT: f64 = 1e-3;
/// A surviving face may turn by at most 60° in one collapse (cos 60°).
const MIN_NORMAL_COS: f32 = 0.5;
/// Triangle quality `4√3·area / Σ edge²` (1 equilateral, 0 degenerate) below which a triangle is
/// a needle: about a 3–5° smallest angle. A collapse may not turn a face that was above it into
/// one below it (marching-cubes slivers that start below may stay, and usually collapse away).
const MIN_QUALITY: f32 = 0.1;
/// Quality below which a triangle counts as degenerate (its normal is not trusted), and which no
/// face around `v*` may end below.
const DEGENERATE_QUALITY: f32 = 1e-4;
/// A support point within this fraction of `max_residual_m` of its own face, when that face
/// survives a collapse, stays on it instead of moving to the nearest face around `v*`: the
/// search over those faces is most of the cost of the residual check, and on the test shapes
/// skipping it for such points changes no face count.
const SETTLED_FRACTION: f32 = 0.5;

const NONE: u32 = u32::MAX;

/// Vertex flags.
const ALIVE: u8 = 1;
const BOUNDARY: u8 = 2;
const LOCKED: u8 = 4;

// ---------------------------------------------------------------------------------------------
// Validate

/// The non-degenerate triangles of `mesh` (those with three distinct indices), in input order.
fn validate(mesh: &TriMesh) -> Result<Vec<[u32; 3]>, SimplifyError> {
    let vertex_count = mesh.vertices.len();
    if vertex_count >= NONE as usize || mesh.triangles.len() >= (NONE / 3) as usize {
        return Err(SimplifyError::TooLarge {
            triangles: mesh.triangles.len(),
            vertices: vertex_count,
        });
    }
    let mut kept = Vec::with_capacity(mesh.triangles.len());
    for (triangle, tri) in mesh.triangles.iter().enumerate() {
        for &index in tri {
            let position =
                mesh.vertices
                    .get(index as usize)
                    .ok_or(SimplifyError::IndexOutOfRange {
                        triangle,
                        index,
                        vertex_count,
                    })?;
            if !position.is_finite() {
                return Err(SimplifyError::NonFiniteVertex {
                    index: index as usize,
                    position: *position,
                });
            }
        }
        let [x, y, z] = *tri;
        if x != y && y != z && z != x {
            kept.push(*tri);
        }
    }
    Ok(kept)
}

/// The square of the triangle quality `4√3·area / Σ edge²` (1 equilateral, 0 degenerate), from
/// the corners and their cross product `(p1 − p0) × (p2 − p0)`.
fn quality_sq(p: [Vec3; 3], cross: Vec3) -> f32 {
    let sum_sq = (p[1] - p[0]).length_squared()
        + (p[2] - p[1]).length_squared()
        + (p[0] - p[2]).length_squared();
    if sum_sq > 0.0 {
        12.0 * cross.length_squared() / (sum_sq * sum_sq)
    } else {
        0.0
    }
}

fn cross_of(p: [Vec3; 3]) -> Vec3 {
    (p[1] - p[0]).cross(p[2] - p[0])
}

/// The bits of a non-negative `f32` order like the number.
fn cost_bits(cost: f64) -> u32 {
    let cost = cost as f32;
    if cost > 0.0 {
        cost.to_bits()
    } else {
        0
    }
}

/// One queued edge, ranked while both vertices had these stamps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Entry {
    a: u32,
    b: u32,
    /// `stamp[a] << 16 | stamp[b]`. Stamps wrap: a stale entry taken for fresh after 65536
    /// changes of one vertex only costs an evaluation out of order; every check runs on the
    /// current mesh.
    stamps: u32,
}

/// The edge queue: a min-heap of 16-byte keys `cost_bits, a, b, stamps` (the bits of a
/// non-negative `f32` order like the number; equal costs pop by vertex ids). Most popped entries
/// are stale or dead, so a pop reads nothing but the heap and the small status array.
struct EdgeQueue {
    heap: MinHeap<u128>,
}

impl EdgeQueue {
    fn with_capacity(capacity: usize) -> Self {
        Self {
            heap: MinHeap::with_capacity(capacity),
        }
    }

    fn push(&mut self, cost_bits: u32, entry: Entry) {
        self.heap.push(
            u128::from(cost_bits) << 96
                | u128::from(entry.a) << 64
                | u128::from(entry.b) << 32
                | u128::from(entry.stamps),
        );
    }

    fn pop(&mut self) -> Option<Entry> {
        let key = self.heap.pop()?;
        Some(Entry {
            a: (key >> 64) as u32,
            b: (key >> 32) as u32,
            stamps: key as u32,
        })
    }

    fn len(&self) -> usize {
        self.heap.len()
    }

    /// Drops the entries for which `keep(a, b)` is false.
    fn retain(&mut self, mut keep: impl FnMut(u32, u32) -> bool) {
        self.heap
            .retain(|&key| keep((key >> 64) as u32, (key >> 32) as u32));
    }

    /// Cost bits of the cheapest queued entry.
    fn peek_cost_bits(&self) -> Option<u32> {
        self.heap.peek().map(|key| (key >> 96) as u32)
    }
}

/// A refused edge waiting for its neighbourhood to change, linked into the lists of both ends.
#[derive(Debug, Clone, Copy)]
struct Parked {
    a: u32,
    b: u32,
    next_a: u32,
    next_b: u32,
    live: bool,
}

/// A vertex of the current mesh, by input vertex id; the fields a collapse reads together.
#[derive(Debug, Clone, Copy)]
struct Vertex {
    pos: Vec3,
    /// A corner `3f + k` with `tris[f][k]` this vertex; `corner_next` chains the others.
    head: u32,
    component: u32,
    quadric: Quadric,
}

/// What every popped queue entry checks, kept apart from [`Vertex`] so that the whole array
/// stays in cache.
#[derive(Debug, Clone, Copy, Default)]
struct Status {
    /// Bumped when the vertex moves or its quadric changes.
    stamp: u16,
    flags: u8,
}

/// An input vertex as a support point of the residual: the fields the residual check walks.
/// Its normal lives apart in `Simplifier::support_normal`, read only by collapses that pass,
/// so that this array (walked in linked-list order, mostly cache misses) stays small.
#[derive(Debug, Clone, Copy)]
struct Support {
    position: Vec3,
    /// Barycentric weights `[wb, wc]`, on the assigned face, of the point that was closest when
    /// last measured: the distance to that point as the face moves bounds the distance to the
    /// face.
    weights: [f32; 2],
    /// Assigned face, and the next support point on it.
    face: u32,
    next: u32,
}

/// What became of a popped edge.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Verdict {
    Collapse,
    Topology,
    Geometry,
    Residual,
    /// Would go below `min_faces`, or the edge is gone: dropped, not counted, not retried.
    Drop,
}

/// Buffers reused by every collapse evaluation; allocated once per call.
#[derive(Default)]
struct Scratch {
    ring: Vec<u32>,
    /// Per vertex: the epoch in which a neighbour walk last saw it (see `next_seen_epoch`).
    seen: Vec<u32>,
    seen_epoch: u32,
    /// Faces containing both `a` and `b`, only `a`, only `b`.
    faces_ab: Vec<u32>,
    faces_a: Vec<u32>,
    faces_b: Vec<u32>,
    /// The faces around `v*` after the collapse: face id, prepared triangle, unnormalised normal.
    new_face: Vec<u32>,
    new_tri: Vec<TriangleQuery>,
    new_cross: Vec<Vec3>,
    /// Sum of the input normals of the support points each new face would receive.
    new_support_normal: Vec<Vec3>,
    /// Per face id: its index in `new_face` while evaluating, `NONE` for faces on `ab`.
    slot_of_face: Vec<u32>,
    /// Support points to reassign: point, `new_face` index, weights of its closest point.
    moves: Vec<(u32, u32, [f32; 2])>,
    /// Neighbours of `b` that are not neighbours of `a`: new edges of `a` after the collapse.
    new_neighbours: Vec<u32>,
    /// `(neighbour, outgoing, incoming, face of the outgoing use)` while classifying one vertex.
    fan: Vec<(u32, u8, u8, u32)>,
}

struct Simplifier<'m> {
    input: &'m [Vec3],
    threshold_m: f32,
    threshold_sq: f32,
    settled_sq: f32,
    min_faces: usize,

    // Current mesh: positions per input vertex id, faces per kept input triangle.
    vertex: Vec<Vertex>,
    status: Vec<Status>,
    tris: Vec<[u32; 3]>,
    face_alive: Vec<bool>,
    faces_alive: usize,
    /// `corner_next` chains the corners of each vertex after `Vertex::head`.
    corner_next: Vec<u32>,
    component_faces: Vec<u32>,
    component_closed: Vec<bool>,

    /// Support points: first by input vertex id (unused entries have `face == NONE`), then the
    /// caller's extra points.
    support: Vec<Support>,
    /// Per support point: the area-weighted input vertex normal, unit length.
    support_normal: Vec<Vec3>,
    /// Per face: its first support point (they chain through `Support::next`).
    face_support: Vec<u32>,
    /// Per vertex: a support point that made the last residual check at this vertex fail.
    fail_hint: Vec<u32>,

    queue: EdgeQueue,
    parked: Vec<Parked>,
    parked_head: Vec<u32>,
    report: SimplifyReport,
    scratch: Scratch,
}

impl<'m> Simplifier<'m> {
    // -----------------------------------------------------------------------------------------
    // Adjacency

    fn new(
        mesh: &'m TriMesh,
        tris: Vec<[u32; 3]>,
        config: &SimplifyConfig,
        extra_points: usize,
    ) -> Self {
        let n = mesh.vertices.len();
        let f = tris.len();
        let threshold_m = config.max_residual_m;
        let mut s = Self {
            input: &mesh.vertices,
            threshold_m,
            threshold_sq: threshold_m * threshold_m,
            settled_sq: (SETTLED_FRACTION * threshold_m).powi(2),
            min_faces: config.min_faces,
            vertex: mesh
                .vertices
                .iter()
                .map(|&pos| Vertex {
                    pos,
                    head: NONE,
                    component: NONE,
                    quadric: Quadric::default(),
                })
                .collect(),
            status: vec![Status::default(); n],
            face_alive: vec![true; f],
            faces_alive: f,
            corner_next: vec![NONE; 3 * f],
            component_faces: vec![0; n],
            component_closed: vec![true; n],
            support: vec![
                Support {
                    position: Vec3::ZERO,
                    weights: [0.0; 2],
                    face: NONE,
                    next: NONE,
                };
                n + extra_points
            ],
            support_normal: vec![Vec3::ZERO; n + extra_points],
            face_support: vec![NONE; f],
            fail_hint: vec![NONE; n],
            queue: EdgeQueue::with_capacity(3 * f / 2 + 16),
            parked: Vec::new(),
            parked_head: vec![NONE; n],
            report: SimplifyReport {
                faces_in: mesh.triangles.len(),
                ..SimplifyReport::default()
            },
            scratch: Scratch {
                slot_of_face: vec![NONE; f],
                seen: vec![0; n],
                ..Scratch::default()
            },
            tris,
        };
        // Build corner lists back to front so that each list runs in increasing face order.
        for corner in (0..3 * f).rev() {
            let v = s.tris[corner / 3][corner % 3] as usize;
            s.corner_next[corner] = s.vertex[v].head;
            s.vertex[v].head = corner as u32;
            s.status[v].flags = ALIVE;
        }
        s.classify_vertices();
        s.find_components();
        s
    }

    /// Marks boundary vertices (on an edge used by one face), and locks vertices on a
    /// non-manifold edge (used by more than two faces, or twice in the same direction) and
    /// bow-tie vertices (faces around them form more than one fan).
    fn classify_vertices(&mut self) {
        let mut fan = std::mem::take(&mut self.scratch.fan);
        let mut fan_slot = vec![0u32; self.vertex.len()];
        for v in 0..self.vertex.len() {
            if self.status[v].flags & ALIVE == 0 {
                continue;
            }
            fan.clear();
            let epoch = self.next_seen_epoch();
            let mut face_count = 0usize;
            let mut corner = self.vertex[v].head;
            while corner != NONE {
                let f = corner / 3;
                let k = (corner % 3) as usize;
                let t = self.tris[f as usize];
                face_count += 1;
                for (neighbour, outgoing) in [(t[(k + 1) % 3], true), (t[(k + 2) % 3], false)] {
                    let n = neighbour as usize;
                    if self.scratch.seen[n] != epoch {
                        self.scratch.seen[n] = epoch;
                        fan_slot[n] = fan.len() as u32;
                        fan.push((neighbour, 0, 0, NONE));
                    }
                    let e = &mut fan[fan_slot[n] as usize];
                    if outgoing {
                        e.1 = e.1.saturating_add(1);
                        e.3 = f;
                    } else {
                        e.2 = e.2.saturating_add(1);
                    }
                }
                corner = self.corner_next[corner as usize];
            }
            let (mut boundary_edges, mut manifold) = (0, true);
            let mut chain_start = self.vertex[v].head / 3;
            for &(_, out, inc, f) in &fan {
                match (out, inc) {
                    (1, 1) => {}
                    (1, 0) => {
                        boundary_edges += 1;
                        chain_start = f; // the first face of an open fan
                    }
                    (0, 1) => boundary_edges += 1,
                    _ => manifold = false,
                }
            }
            if boundary_edges > 0 {
                self.status[v].flags |= BOUNDARY;
            }
            let one_fan = manifold
                && boundary_edges <= 2
                && self.fan_walk_len(v, chain_start, &fan, &fan_slot) == face_count;
            if !one_fan {
                self.status[v].flags |= LOCKED;
            }
        }
        self.scratch.fan = fan;
    }

    /// How many faces a walk around `v` from face `start` visits, crossing from each face to the
    /// one that shares its incoming edge, until it returns to `start` or reaches the boundary.
    /// All edges at `v` must be manifold; `fan_slot` indexes `fan` by neighbour.
    fn fan_walk_len(
        &self,
        v: usize,
        start: u32,
        fan: &[(u32, u8, u8, u32)],
        fan_slot: &[u32],
    ) -> usize {
        let mut face = start;
        let mut visited = 0;
        while visited <= fan.len() {
            visited += 1;
            let t = self.tris[face as usize];
            let k = t.iter().position(|&w| w as usize == v).unwrap_or(0);
            let incoming = t[(k + 2) % 3];
            let entry = fan[fan_slot[incoming as usize] as usize];
            if entry.1 == 0 {
                break; // reached the other end of an open fan
            }
            face = entry.3;
            if face == start {
                break;
            }
        }
        visited
    }

    /// Connected components (union-find over faces), their face counts and whether they are
    /// closed (no boundary and no locked vertex).
    fn find_components(&mut self) {
        let n = self.vertex.len();
        let mut parent: Vec<u32> = (0..n as u32).collect();
        fn root(parent: &mut [u32], mut v: u32) -> u32 {
            while parent[v as usize] != v {
                let up = parent[parent[v as usize] as usize];
                parent[v as usize] = up;
                v = up;
            }
            v
        }
        for t in &self.tris {
            for &v in &t[1..] {
                // Both roots afresh for every pair: the first union may have hung `t[0]`'s
                // root under another, and linking a non-root would cut its tree off.
                let (r0, r) = (root(&mut parent, t[0]), root(&mut parent, v));
                let (lo, hi) = (r0.min(r), r0.max(r));
                parent[hi as usize] = lo;
            }
        }
        for v in 0..n {
            if self.status[v].flags & ALIVE == 0 {
                continue;
            }
            let r = root(&mut parent, v as u32);
            self.vertex[v].component = r;
            if self.status[v].flags & (BOUNDARY | LOCKED) != 0 {
                self.component_closed[r as usize] = false;
            }
        }
        for t in &self.tris {
            self.component_faces[self.vertex[t[0] as usize].component as usize] += 1;
        }
    }

    // -----------------------------------------------------------------------------------------
    // Quadrics and support points

    /// Per vertex: the area-weighted face planes around it plus, on boundary edges, a plane
    /// through the edge perpendicular to its face. Per input vertex: a support point with the
    /// area-weighted vertex normal, assigned to its largest incident face at distance 0.
    fn init_quadrics_and_support(&mut self) {
        let mut largest_face = vec![(NONE, -1.0f32); self.vertex.len()];
        for (f, t) in self.tris.iter().enumerate() {
            let p = t.map(|v| self.vertex[v as usize].pos);
            let cross = cross_of(p);
            let double_area = cross.length();
            for &v in t {
                self.support_normal[v as usize] += cross;
                let best = &mut largest_face[v as usize];
                if double_area > best.1 {
                    *best = (f as u32, double_area);
                }
            }
            let pd = p.map(|x| x.as_dvec3());
            let cross_d = (pd[1] - pd[0]).cross(pd[2] - pd[0]);
            let len = cross_d.length();
            if len > 0.0 {
                let q = Quadric::from_face(cross_d / len, pd[0], 0.5 * len);
                for &v in t {
                    self.vertex[v as usize].quadric += q;
                }
            }
        }
        // Boundary constraint planes, once per boundary edge, from the face that owns it.
        for v in 0..self.vertex.len() {
            if self.status[v].flags & BOUNDARY == 0 {
                continue;
            }
            let mut corner = self.vertex[v].head;
            while corner != NONE {
                let t = self.tris[(corner / 3) as usize];
                let next = t[(corner as usize % 3 + 1) % 3];
                if !self.has_directed_edge(next, v as u32) {
                    let p = t.map(|x| self.vertex[x as usize].pos.as_dvec3());
                    let normal = (p[1] - p[0]).cross(p[2] - p[0]);
                    let edge =
                        self.vertex[next as usize].pos.as_dvec3() - self.vertex[v].pos.as_dvec3();
                    let plane = edge.cross(normal).normalize_or_zero();
                    if plane != DVec3::ZERO {
                        let q = Quadric::from_plane(
                            plane,
                            self.vertex[v].pos.as_dvec3(),
                            edge.length_squared() * BOUNDARY_WEIGHT,
                        );
                        self.vertex[v].quadric += q;
                        self.vertex[next as usize].quadric += q;
                    }
                }
                corner = self.corner_next[corner as usize];
            }
        }
        for (v, &(f, _)) in largest_face.iter().enumerate() {
            if f != NONE {
                let corner = self.tris[f as usize].iter().position(|&w| w as usize == v);
                let support = &mut self.support[v];
                support.position = self.input[v];
                support.weights = match corner {
                    Some(1) => [1.0, 0.0],
                    Some(2) => [0.0, 1.0],
                    _ => [0.0, 0.0],
                };
                support.face = f;
                support.next = self.face_support[f as usize];
                self.face_support[f as usize] = v as u32;
                self.support_normal[v] = self.support_normal[v].normalize_or_zero();
            }
        }
    }

    /// Makes each of the held points a support point (after the input vertices' own),
    /// assigned to its nearest face with no normal (it never vetoes a face's orientation). A
    /// point farther than the threshold from every face cannot be held to it and is left out,
    /// counted in the report. The faces within the threshold of a point come from a grid of
    /// threshold-sized cells (without it, every face was tried per point: 8 ms of a 9 ms second
    /// pass for 10,000 points over 60 faces); with a zero or infinite threshold every face is
    /// tried.
    fn add_extra_support(&mut self, held: &HeldPoints) {
        let points = held.points;
        if points.is_empty() {
            return;
        }
        let corners = |t: &[u32; 3]| t.map(|v| self.vertex[v as usize].pos);
        let faces: Vec<TriangleQuery> = self
            .tris
            .iter()
            .map(|t| {
                let [a, b, c] = corners(t);
                TriangleQuery::new(a, b, c)
            })
            .collect();
        let made_here;
        let cells = if held.cell_m == self.threshold_m {
            held.cells.as_ref()
        } else {
            made_here = point_cells(points, self.threshold_m);
            made_here.as_ref()
        };
        let lists = cells.map(|cells| cells.bucket(self.tris.iter().map(corners)));
        let every_face: Vec<u32> = match cells {
            Some(_) => Vec::new(),
            None => (0..faces.len() as u32).collect(),
        };
        let first = self.input.len();
        for (i, &x) in points.iter().enumerate() {
            let candidates = match (cells, &lists) {
                (Some(cells), Some(lists)) => cells.near_point(lists, i),
                _ => every_face.as_slice(),
            };
            let mut best = (f32::INFINITY, NONE, [0.0; 2]);
            for &f in candidates {
                let tri = &faces[f as usize];
                let h = tri.plane_distance(x);
                if h * h >= best.0 {
                    continue;
                }
                let (d, weights) = tri.closest(x);
                if d < best.0 {
                    best = (d, f, weights);
                }
            }
            let (d, f, weights) = best;
            if f == NONE || !x.is_finite() || d > self.threshold_sq {
                self.report.points_beyond_bound += 1;
                continue;
            }
            let p = first + i;
            self.support[p] = Support {
                position: x,
                weights,
                face: f,
                next: self.face_support[f as usize],
            };
            self.face_support[f as usize] = p as u32;
        }
    }

    /// Whether some face has the directed edge `from → to`.
    fn has_directed_edge(&self, from: u32, to: u32) -> bool {
        let mut corner = self.vertex[from as usize].head;
        while corner != NONE {
            let t = self.tris[(corner / 3) as usize];
            if t[(corner as usize % 3 + 1) % 3] == to {
                return true;
            }
            corner = self.corner_next[corner as usize];
        }
        false
    }

    // -----------------------------------------------------------------------------------------
    // Rank

    /// A fresh value for the `seen` marks.
    fn next_seen_epoch(&mut self) -> u32 {
        let sc = &mut self.scratch;
        sc.seen_epoch = sc.seen_epoch.wrapping_add(1);
        if sc.seen_epoch == 0 {
            sc.seen.fill(0);
            sc.seen_epoch = 1;
        }
        sc.seen_epoch
    }

    /// Marks every neighbour of `v` as seen in `epoch`.
    fn mark_neighbours(&mut self, v: u32, epoch: u32) {
        let mut corner = self.vertex[v as usize].head;
        while corner != NONE {
            let t = self.tris[(corner / 3) as usize];
            let k = corner as usize % 3;
            self.scratch.seen[t[(k + 1) % 3] as usize] = epoch;
            self.scratch.seen[t[(k + 2) % 3] as usize] = epoch;
            corner = self.corner_next[corner as usize];
        }
    }

    /// The distinct neighbours of `v` not seen in `skip_epoch` (0 skips none), in corner-list
    /// order.
    fn neighbours_into(&mut self, v: u32, skip_epoch: u32, out: &mut Vec<u32>) {
        out.clear();
        let epoch = self.next_seen_epoch();
        let mut corner = self.vertex[v as usize].head;
        while corner != NONE {
            let t = self.tris[(corner / 3) as usize];
            let k = corner as usize % 3;
            for w in [t[(k + 1) % 3], t[(k + 2) % 3]] {
                let seen = &mut self.scratch.seen[w as usize];
                if *seen != epoch && (skip_epoch == 0 || *seen != skip_epoch) {
                    *seen = epoch;
                    out.push(w);
                }
            }
            corner = self.corner_next[corner as usize];
        }
    }

    /// How many neighbours `a` and `b` share, besides each other.
    fn common_neighbours(&mut self, a: u32, b: u32) -> usize {
        let of_a = self.next_seen_epoch();
        self.mark_neighbours(a, of_a);
        let counted = self.next_seen_epoch();
        let mut common = 0;
        let mut corner = self.vertex[b as usize].head;
        while corner != NONE {
            let t = self.tris[(corner / 3) as usize];
            let k = corner as usize % 3;
            for w in [t[(k + 1) % 3], t[(k + 2) % 3]] {
                let seen = &mut self.scratch.seen[w as usize];
                if w != a && *seen == of_a {
                    *seen = counted;
                    common += 1;
                }
            }
            corner = self.corner_next[corner as usize];
        }
        common
    }

    /// Where edge `ab` would collapse to and what it costs: the quadric error of `Qa + Qb` plus
    /// the spring energy `κ (|v−a|² + |v−b|²)` with `κ` = `SPRING_WEIGHT` × quadric area.
    fn placement(&self, a: u32, b: u32) -> (f64, Vec3) {
        let q = self.vertex[a as usize].quadric + self.vertex[b as usize].quadric;
        let pa = self.vertex[a as usize].pos.as_dvec3();
        let pb = self.vertex[b as usize].pos.as_dvec3();
        let kappa = SPRING_WEIGHT * q.area_m2();
        let cost_at =
            |p: DVec3| q.error(p) + kappa * (p.distance_squared(pa) + p.distance_squared(pb));
        let cheapest = |candidates: &[DVec3]| {
            candidates
                .iter()
                .map(|&p| (cost_at(p), p))
                .min_by(|x, y| x.0.total_cmp(&y.0))
                .unwrap_or((0.0, pa))
        };
        let boundary_a = self.status[a as usize].flags & BOUNDARY != 0;
        let boundary_b = self.status[b as usize].flags & BOUNDARY != 0;
        let (cost, target) = match (boundary_a, boundary_b) {
            (true, true) => cheapest(&[pa, pb]),
            (true, false) => (cost_at(pa), pa),
            (false, true) => (cost_at(pb), pb),
            (false, false) => {
                let mid = (pa + pb) * 0.5;
                let grow = DVec3::splat(pa.distance(pb));
                let (lo, hi) = (pa.min(pb) - grow, pa.max(pb) + grow);
                match q.minimiser(mid, 2.0 * kappa) {
                    Some(p) if p.cmple(hi).all() && p.cmpge(lo).all() => (cost_at(p), p),
                    _ => cheapest(&[mid, pa, pb]),
                }
            }
        };
        (cost, target.as_vec3())
    }

    fn stamps(&self, a: u32, b: u32) -> u32 {
        u32::from(self.status[a as usize].stamp) << 16 | u32::from(self.status[b as usize].stamp)
    }

    /// Queues edge `ab` at its current cost, unless an end is locked.
    fn push_edge(&mut self, a: u32, b: u32) {
        if (self.status[a as usize].flags | self.status[b as usize].flags) & LOCKED != 0 {
            return;
        }
        let cost = self.placement(a, b).0;
        let stamps = self.stamps(a, b);
        self.queue.push(cost_bits(cost), Entry { a, b, stamps });
    }

    /// Queues every edge once.
    fn rank_all(&mut self) {
        let mut ring = std::mem::take(&mut self.scratch.ring);
        for a in 0..self.vertex.len() as u32 {
            if self.status[a as usize].flags & (ALIVE | LOCKED) != ALIVE {
                continue;
            }
            self.neighbours_into(a, 0, &mut ring);
            for &b in ring.iter().filter(|&&b| b > a) {
                self.push_edge(a, b);
            }
        }
        self.scratch.ring = ring;
    }

    // -----------------------------------------------------------------------------------------
    // Collapse checks

    fn gather_faces(&mut self, a: u32, b: u32) {
        let sc = &mut self.scratch;
        sc.faces_ab.clear();
        sc.faces_a.clear();
        sc.faces_b.clear();
        let mut corner = self.vertex[a as usize].head;
        while corner != NONE {
            let f = corner / 3;
            if self.tris[f as usize].contains(&b) {
                sc.faces_ab.push(f);
            } else {
                sc.faces_a.push(f);
            }
            corner = self.corner_next[corner as usize];
        }
        let mut corner = self.vertex[b as usize].head;
        while corner != NONE {
            let f = corner / 3;
            if !self.tris[f as usize].contains(&a) {
                sc.faces_b.push(f);
            }
            corner = self.corner_next[corner as usize];
        }
    }

    /// Topology rules (see the table in the module docs), after [`Self::gather_faces`].
    fn check_topology(&mut self, a: u32, b: u32) -> Verdict {
        let on_edge = self.scratch.faces_ab.len();
        if on_edge == 0 {
            return Verdict::Drop;
        }
        if on_edge > 2 || self.scratch.faces_a.is_empty() && self.scratch.faces_b.is_empty() {
            return Verdict::Topology; // non-manifold edge, or v* would be left without faces
        }
        let both_boundary =
            self.status[a as usize].flags & self.status[b as usize].flags & BOUNDARY != 0;
        if on_edge == 2 && both_boundary {
            return Verdict::Topology;
        }
        let component = self.vertex[a as usize].component as usize;
        let left = self.component_faces[component] as usize - on_edge;
        let floor = if self.component_closed[component] {
            4
        } else {
            1
        };
        if left < floor {
            return Verdict::Topology;
        }
        if self.faces_alive - on_edge < self.min_faces {
            return Verdict::Drop;
        }
        // Link condition: the only shared neighbours are the apexes of the faces on ab.
        if self.common_neighbours(a, b) != on_edge {
            return Verdict::Topology;
        }
        // No face around b may become a copy of a face around a.
        let sc = &self.scratch;
        for &fb in &sc.faces_b {
            let tb = self.tris[fb as usize];
            for &fa in &sc.faces_a {
                let ta = self.tris[fa as usize];
                if tb.iter().all(|&v| v == b || ta.contains(&v)) {
                    return Verdict::Topology;
                }
            }
        }
        Verdict::Collapse
    }

    /// Geometry rules, after [`Self::check_topology`]; fills the `new_*` scratch with the faces
    /// around `v*`. Qualities and angles are compared squared, without roots.
    fn check_geometry(&mut self, a: u32, b: u32, target: Vec3) -> Verdict {
        let sc = &mut self.scratch;
        sc.new_face.clear();
        sc.new_tri.clear();
        sc.new_cross.clear();
        let mut without_normal = false;
        for &f in sc.faces_a.iter().chain(&sc.faces_b) {
            let t = self.tris[f as usize];
            let before = t.map(|v| self.vertex[v as usize].pos);
            let mut after = before;
            for (corner, &v) in after.iter_mut().zip(&t) {
                if v == a || v == b {
                    *corner = target;
                }
            }
            let cross_before = cross_of(before);
            let cross_after = cross_of(after);
            let q_before = quality_sq(before, cross_before);
            let q_after = quality_sq(after, cross_after);
            if q_after < DEGENERATE_QUALITY * DEGENERATE_QUALITY {
                return Verdict::Geometry;
            }
            if q_before >= MIN_QUALITY * MIN_QUALITY && q_after < MIN_QUALITY * MIN_QUALITY {
                return Verdict::Geometry; // would become a needle
            }
            if q_before >= DEGENERATE_QUALITY * DEGENERATE_QUALITY {
                let dot = cross_after.dot(cross_before);
                let limit = MIN_NORMAL_COS
                    * MIN_NORMAL_COS
                    * cross_after.length_squared()
                    * cross_before.length_squared();
                if dot <= 0.0 || dot * dot < limit {
                    return Verdict::Geometry; // flips or folds
                }
            } else {
                without_normal = true;
            }
            sc.slot_of_face[f as usize] = sc.new_face.len() as u32;
            sc.new_face.push(f);
            sc.new_tri
                .push(TriangleQuery::new(after[0], after[1], after[2]));
            sc.new_cross.push(cross_after);
        }
        if without_normal {
            // A face that was degenerate has no normal of its own to keep: it must face the same
            // side as the surface around a and b.
            let mut local_normal = Vec3::ZERO;
            for &f in sc.faces_ab.iter().chain(&sc.faces_a).chain(&sc.faces_b) {
                local_normal +=
                    cross_of(self.tris[f as usize].map(|v| self.vertex[v as usize].pos));
            }
            if sc.new_cross.iter().any(|n| n.dot(local_normal) <= 0.0) {
                return Verdict::Geometry;
            }
        }
        Verdict::Collapse
    }

    /// The `new_face` slot nearest to support point `p` and the weights of the closest point on
    /// it, or `None` when no face around `v*` is within the threshold. A point settled on its own
    /// surviving face stays there.
    fn nearest_new_face(&mut self, p: u32) -> Option<(u32, [f32; 2])> {
        let sc = &self.scratch;
        let support = &self.support[p as usize];
        let x = support.position;
        let own = sc.slot_of_face[support.face as usize];
        let (mut best_slot, (mut best, mut best_weights)) = if own != NONE {
            (own, sc.new_tri[own as usize].closest(x))
        } else {
            (NONE, (f32::INFINITY, [0.0; 2]))
        };
        let search = own == NONE || best > self.settled_sq;
        if search {
            for (slot, tri) in sc.new_tri.iter().enumerate() {
                let h = tri.plane_distance(x);
                if h * h >= best || slot as u32 == own {
                    continue;
                }
                let (d, weights) = tri.closest(x);
                if d < best {
                    (best, best_weights, best_slot) = (d, weights, slot as u32);
                }
            }
        }
        self.report.work.support_searches += usize::from(search);
        (best_slot != NONE && best <= self.threshold_sq).then_some((best_slot, best_weights))
    }

    /// The residual rule: `v*` within the threshold of the faces around `a` and `b`, and every
    /// support point of those faces within the threshold of a face around `v*`. Fills
    /// `scratch.moves`. A support point keeps its own surviving face without a search when the
    /// point it tracks on that face (same barycentric weights, corners moved) is within the
    /// settled distance. Also checks each new face against the summed input normals of the
    /// points it receives (a geometry refusal).
    fn check_residual(&mut self, a: u32, b: u32, target: Vec3) -> Verdict {
        if target != self.vertex[a as usize].pos && target != self.vertex[b as usize].pos {
            let sc = &self.scratch;
            let near = sc
                .faces_ab
                .iter()
                .chain(&sc.faces_a)
                .chain(&sc.faces_b)
                .any(|&f| {
                    let p = self.tris[f as usize].map(|v| self.vertex[v as usize].pos);
                    TriangleQuery::new(p[0], p[1], p[2]).distance_sq(target) <= self.threshold_sq
                });
            if !near {
                return Verdict::Residual;
            }
        }
        for i in 0..self.scratch.faces_ab.len() {
            let f = self.scratch.faces_ab[i];
            self.scratch.slot_of_face[f as usize] = NONE;
        }
        // A point that failed here before goes first: a refusal then costs one point, not all.
        for hint in [self.fail_hint[a as usize], self.fail_hint[b as usize]] {
            if hint != NONE {
                self.report.work.support_checks += 1;
                let t = self.tris[self.support[hint as usize].face as usize];
                if (t.contains(&a) || t.contains(&b)) && self.nearest_new_face(hint).is_none() {
                    return Verdict::Residual;
                }
            }
        }
        let mut moves = std::mem::take(&mut self.scratch.moves);
        moves.clear();
        let mut verdict = Verdict::Collapse;
        // Faces on ab first: their points must move, and are the likeliest to fail.
        let faces =
            self.scratch.faces_ab.len() + self.scratch.faces_a.len() + self.scratch.faces_b.len();
        'faces: for i in 0..faces {
            let f = self.face_around(i);
            let own = self.scratch.slot_of_face[f as usize];
            let mut p = self.face_support[f as usize];
            while p != NONE {
                self.report.work.support_checks += 1;
                let support = &self.support[p as usize];
                let (weights, next) = (support.weights, support.next);
                let tracked = if own != NONE {
                    let q = self.scratch.new_tri[own as usize].point_at(weights);
                    q.distance_squared(support.position)
                } else {
                    f32::INFINITY
                };
                if own != NONE && tracked <= self.settled_sq {
                    moves.push((p, own, weights));
                } else if let Some((slot, weights)) = self.nearest_new_face(p) {
                    moves.push((p, slot, weights));
                } else {
                    self.fail_hint[a as usize] = p;
                    self.fail_hint[b as usize] = p;
                    verdict = Verdict::Residual;
                    break 'faces;
                }
                p = next;
            }
        }
        if verdict == Verdict::Collapse {
            let sc = &mut self.scratch;
            sc.new_support_normal.clear();
            sc.new_support_normal.resize(sc.new_face.len(), Vec3::ZERO);
            for &(p, slot, _) in &moves {
                sc.new_support_normal[slot as usize] += self.support_normal[p as usize];
            }
            let disagrees = sc
                .new_support_normal
                .iter()
                .zip(&sc.new_cross)
                .any(|(sum, cross)| *sum != Vec3::ZERO && sum.dot(*cross) <= 0.0);
            if disagrees {
                verdict = Verdict::Geometry;
            }
        }
        self.scratch.moves = moves;
        verdict
    }

    /// The `i`-th face around `a` or `b`: faces on `ab` first, then around `a`, then around `b`.
    fn face_around(&self, i: usize) -> u32 {
        let sc = &self.scratch;
        let (ab, fa) = (sc.faces_ab.len(), sc.faces_a.len());
        if i < ab {
            sc.faces_ab[i]
        } else if i < ab + fa {
            sc.faces_a[i - ab]
        } else {
            sc.faces_b[i - ab - fa]
        }
    }

    /// Runs the checks for collapsing edge `ab` to `target`. The endpoint with fewer faces is
    /// the one that goes (fewer faces to relink and edges to queue again): returns the pair as
    /// `(survivor, removed)` with the verdict.
    fn evaluate(&mut self, a: u32, b: u32, target: Vec3) -> (Verdict, u32, u32) {
        self.gather_faces(a, b);
        let (a, b) = if self.scratch.faces_b.len() > self.scratch.faces_a.len() {
            let sc = &mut self.scratch;
            std::mem::swap(&mut sc.faces_a, &mut sc.faces_b);
            (b, a)
        } else {
            (a, b)
        };
        let verdict = match self.check_topology(a, b) {
            Verdict::Collapse => match self.check_geometry(a, b, target) {
                Verdict::Collapse => self.check_residual(a, b, target),
                other => other,
            },
            other => other,
        };
        (verdict, a, b)
    }

    // -----------------------------------------------------------------------------------------
    // Update

    /// Removes corner `corner` from the corner list of vertex `v`.
    fn unlink_corner(&mut self, v: u32, corner: u32) {
        let mut at = self.vertex[v as usize].head;
        if at == corner {
            self.vertex[v as usize].head = self.corner_next[corner as usize];
            return;
        }
        while at != NONE {
            let next = self.corner_next[at as usize];
            if next == corner {
                self.corner_next[at as usize] = self.corner_next[corner as usize];
                return;
            }
            at = next;
        }
    }

    /// Parks refused edge `ab` on both its vertices.
    fn park(&mut self, a: u32, b: u32) {
        let id = self.parked.len() as u32;
        self.parked.push(Parked {
            a,
            b,
            next_a: self.parked_head[a as usize],
            next_b: self.parked_head[b as usize],
            live: true,
        });
        self.parked_head[a as usize] = id;
        self.parked_head[b as usize] = id;
    }

    /// Queues again the edges parked on `v` whose ends are both alive.
    fn unpark(&mut self, v: u32) {
        let mut id = self.parked_head[v as usize];
        self.parked_head[v as usize] = NONE;
        while id != NONE {
            let record = self.parked[id as usize];
            self.parked[id as usize].live = false;
            if record.live
                && self.status[record.a as usize].flags
                    & self.status[record.b as usize].flags
                    & ALIVE
                    != 0
            {
                self.push_edge(record.a, record.b);
            }
            id = if record.a == v {
                record.next_a
            } else {
                record.next_b
            };
        }
    }

    /// Merges `b` into `a` at `target` after a successful [`Self::evaluate`].
    fn collapse(&mut self, a: u32, b: u32, target: Vec3) {
        // Reassign the support points as the residual check decided.
        let faces =
            self.scratch.faces_ab.len() + self.scratch.faces_a.len() + self.scratch.faces_b.len();
        for i in 0..faces {
            let f = self.face_around(i);
            self.face_support[f as usize] = NONE;
        }
        for i in 0..self.scratch.moves.len() {
            let (p, slot, weights) = self.scratch.moves[i];
            let f = self.scratch.new_face[slot as usize];
            let support = &mut self.support[p as usize];
            support.next = self.face_support[f as usize];
            support.face = f;
            support.weights = weights;
            self.face_support[f as usize] = p;
        }
        // Neighbours of b that a lacks: their edges become new edges of a.
        let of_a = self.next_seen_epoch();
        self.mark_neighbours(a, of_a);
        let mut new_neighbours = std::mem::take(&mut self.scratch.new_neighbours);
        self.neighbours_into(b, of_a, &mut new_neighbours);
        // Remove the faces on ab.
        let removed = self.scratch.faces_ab.len();
        for i in 0..removed {
            let f = self.scratch.faces_ab[i];
            let t = self.tris[f as usize];
            for (k, &v) in t.iter().enumerate() {
                self.unlink_corner(v, 3 * f + k as u32);
            }
            self.face_alive[f as usize] = false;
        }
        // Relabel b's corners and splice its list in front of a's.
        let mut corner = self.vertex[b as usize].head;
        let mut last = NONE;
        while corner != NONE {
            self.tris[(corner / 3) as usize][corner as usize % 3] = a;
            last = corner;
            corner = self.corner_next[corner as usize];
        }
        if last != NONE {
            self.corner_next[last as usize] = self.vertex[a as usize].head;
            self.vertex[a as usize].head = self.vertex[b as usize].head;
        }
        self.vertex[b as usize].head = NONE;
        self.vertex[a as usize].pos = target;
        let qb = self.vertex[b as usize].quadric;
        self.vertex[a as usize].quadric += qb;
        self.status[a as usize].flags |= self.status[b as usize].flags & BOUNDARY;
        self.status[b as usize].flags = 0;
        self.status[a as usize].stamp = self.status[a as usize].stamp.wrapping_add(1);
        let component = self.vertex[a as usize].component as usize;
        self.component_faces[component] -= removed as u32;
        self.faces_alive -= removed;
        self.report.collapses += 1;
        // a's old edges stay queued and are re-ranked when popped (their stamp moved); b's
        // edges to a's old neighbours merge into those; b's other edges are new.
        for &x in &new_neighbours {
            if x != a {
                self.push_edge(a, x);
            }
        }
        self.scratch.new_neighbours = new_neighbours;
        // Refusals around a may no longer hold.
        let mut ring = std::mem::take(&mut self.scratch.ring);
        self.neighbours_into(a, 0, &mut ring);
        self.unpark(a);
        for &x in &ring {
            self.unpark(x);
        }
        self.scratch.ring = ring;
    }

    /// Drops the queue entries of merged-away vertices once they outnumber the live edges
    /// (about `1.5 × faces_alive`). Left in, each would cost a full pop: they were over half
    /// of all pops. Which entries are dead does not change, so neither does the order in which
    /// live entries pop; only [`EdgeQueue::peek_cost_bits`] now sees a live cost more often.
    fn purge_dead_entries(&mut self) {
        if self.queue.len() <= 2 * self.faces_alive + 64 {
            return;
        }
        let status = &self.status;
        self.queue
            .retain(|a, b| status[a as usize].flags & status[b as usize].flags & ALIVE != 0);
    }

    fn run(&mut self) {
        while let Some(entry) = self.queue.pop() {
            self.report.work.queue_pops += 1;
            if self.faces_alive <= self.min_faces {
                break;
            }
            let (a, b) = (entry.a, entry.b);
            if self.status[a as usize].flags & self.status[b as usize].flags & ALIVE == 0 {
                continue; // b's old edges after it merged into a
            }
            let (cost, target) = self.placement(a, b);
            let stamps = self.stamps(a, b);
            if entry.stamps != stamps {
                // Ranked before a collapse moved an end: wait if no longer the cheapest.
                let bits = cost_bits(cost);
                if self.queue.peek_cost_bits().is_some_and(|next| next < bits) {
                    self.queue.push(bits, Entry { a, b, stamps });
                    continue;
                }
            }
            self.report.work.evaluations += 1;
            let (verdict, a, b) = self.evaluate(a, b, target);
            match verdict {
                Verdict::Collapse => {
                    self.collapse(a, b, target);
                    self.purge_dead_entries();
                    continue;
                }
                Verdict::Drop => continue,
                Verdict::Topology => self.report.rejected_by_topology += 1,
                Verdict::Geometry => self.report.rejected_by_geometry += 1,
                Verdict::Residual => self.report.rejected_by_residual += 1,
            }
            self.park(a, b);
        }
    }

    // -----------------------------------------------------------------------------------------
    // Compact

    /// The surviving faces in input order over the surviving vertices in input order, and the
    /// report with the residual actually reached (exact distances to the assigned faces).
    fn finish(mut self) -> (TriMesh, SimplifyReport) {
        let mut max_sq = 0.0f32;
        for support in &self.support {
            let f = support.face;
            if f != NONE {
                let c = self.tris[f as usize].map(|v| self.vertex[v as usize].pos);
                let d = TriangleQuery::new(c[0], c[1], c[2]).distance_sq(support.position);
                max_sq = max_sq.max(d);
            }
        }
        let mut remap = vec![NONE; self.vertex.len()];
        let mut triangles = Vec::with_capacity(self.faces_alive);
        for (f, t) in self.tris.iter().enumerate() {
            if self.face_alive[f] {
                triangles.push(*t);
                for &v in t {
                    remap[v as usize] = 0; // used; numbered below in vertex order
                }
            }
        }
        let mut vertices = Vec::new();
        for (v, slot) in remap.iter_mut().enumerate() {
            if *slot != NONE {
                *slot = vertices.len() as u32;
                vertices.push(self.vertex[v].pos);
            }
        }
        for t in &mut triangles {
            *t = t.map(|v| remap[v as usize]);
        }
        self.report.faces_out = triangles.len();
        self.report.vertices_out = vertices.len();
        // f32 rounding may put the measured value a hair above the threshold it was checked
        // against; the documented bound is the threshold.
        self.report.max_residual_m = max_sq.sqrt().min(self.threshold_m);
        (TriMesh::new(vertices, triangles), self.report)
    }
}

/// Simplifies `mesh` by edge collapse until no further collapse keeps every input vertex within
/// `config.max_residual_m` (metres) of the output, or `config.min_faces` is reached.
///
/// The output is a 2-manifold wherever the input was (non-manifold parts are left untouched),
/// with no degenerate or duplicate triangles created, no triangle flipped against the input, the
/// same boundary loops (closed input stays closed; boundary vertices are a subset of the
/// input's), only referenced vertices, and faces and vertices in input order. Triangles with a
/// repeated index are dropped. The result is deterministic. Scratch memory is allocated once per
/// call, proportional to the input.
///
/// Errors: an index out of range, a non-finite vertex used by a triangle, a negative or NaN
/// `max_residual_m`, more than `u32` indices can address.
pub fn simplify(
    mesh: &TriMesh,
    config: &SimplifyConfig,
) -> Result<(TriMesh, SimplifyReport), SimplifyError> {
    simplify_near_points(mesh, &[], config)
}

/// As [`simplify`], with `points` held to the output as well: no collapse may leave one of them
/// farther than `config.max_residual_m` from the surface, besides the input vertices. A point
/// already farther than that from the input mesh is left out (counted in
/// [`SimplifyReport::points_beyond_bound`]). Meant for a second pass over a mesh that is
/// already small, held to the data it was fitted to (each point is matched at the start
/// against the faces within the bound of it, found through a grid of bound-sized cells).
pub fn simplify_near_points(
    mesh: &TriMesh,
    points: &[Vec3],
    config: &SimplifyConfig,
) -> Result<(TriMesh, SimplifyReport), SimplifyError> {
    simplify_near_held_points(
        mesh,
        &HeldPoints::new(points, config.max_residual_m),
        config,
    )
}

/// Points to hold a mesh to over several passes under the same bound (see
/// [`simplify_near_held_points`]), with the cells of the grid that matches them to faces found
/// once: for the 2,000-20,000 marching-cubes vertices of one object that was a third of each
/// pass after the first.
pub struct HeldPoints<'p> {
    points: &'p [Vec3],
    /// The bound the cells were made for.
    cell_m: f32,
    /// The points' cells, `cell_m` wide; `None` for a zero or infinite bound.
    cells: Option<PointCells>,
}

impl<'p> HeldPoints<'p> {
    /// `points` to be held within `max_residual_m` (a pass under another bound finds their
    /// cells again).
    pub fn new(points: &'p [Vec3], max_residual_m: f32) -> Self {
        Self {
            points,
            cell_m: max_residual_m,
            cells: point_cells(points, max_residual_m),
        }
    }
}

/// The cells of `points` in a grid `reach` wide, or `None` when `reach` is zero, negative,
/// NaN or infinite (every face is then tried).
fn point_cells(points: &[Vec3], reach: f32) -> Option<PointCells> {
    (!points.is_empty() && reach.is_finite() && reach > 0.0)
        .then(|| PointCells::new(points.iter().copied(), reach))
}

/// [`simplify_near_points`] with the points' grid cells found beforehand.
pub fn simplify_near_held_points(
    mesh: &TriMesh,
    held: &HeldPoints,
    config: &SimplifyConfig,
) -> Result<(TriMesh, SimplifyReport), SimplifyError> {
    let points = held.points;
    // NaN is neither below nor at or above zero.
    if config.max_residual_m.is_nan() || config.max_residual_m < 0.0 {
        return Err(SimplifyError::InvalidMaxResidual {
            value: config.max_residual_m,
        });
    }
    let tris = validate(mesh)?;
    if mesh.vertices.len() + points.len() > NONE as usize {
        return Err(SimplifyError::TooLarge {
            triangles: tris.len(),
            vertices: mesh.vertices.len() + points.len(),
        });
    }
    let mut s = Simplifier::new(mesh, tris, config, points.len());
    s.init_quadrics_and_support();
    s.add_extra_support(held);
    s.rank_all();
    s.run();
    let (out, report) = s.finish();
    tracing::trace!(
        faces_in = report.faces_in,
        faces_out = report.faces_out,
        collapses = report.collapses,
        rejected_by_residual = report.rejected_by_residual,
        rejected_by_topology = report.rejected_by_topology,
        rejected_by_geometry = report.rejected_by_geometry,
        max_residual_m = report.max_residual_m,
        "simplified"
    );
    Ok((out, report))
}
