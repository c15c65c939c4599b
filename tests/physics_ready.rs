//! Issue 13, meshes a physics engine can use. No output mesh is inside out. A sweep over the paper's shapes, noise levels,
//! densities and seeds (the settings where inverted meshes were seen: the cone at 20 mm and
//! 40,000 points, cone and cylinder at 20,000, the sphere at 40 mm), judged against the true
//! shape: each face's normal must point out of the true solid (its winding number), not only
//! agree with the volume sign the pipeline itself checks. And a one-view shell's collision
//! proxy is closed and holds the true object.

use parry3d::query::PointQuery;
use parry3d::shape::TriMesh as ParryTriMesh;
use rayon::prelude::*;
use tacmesh::glam::{DVec3, Vec3};
use tacmesh::physics::orientation::{orientation, signed_volume_m3};
use tacmesh::physics::proxy::{collision_proxy, ProxyConfig, ProxyKind, SupportPlane};
use tacmesh::pipeline::{mesh_cloud, MeshConfig, MeshReport};
use tacmesh::sim::{contact_fidelity, sample_cloud, ContactConfig, SampleConfig, Shape};
use tacmesh::{PointCloud, TriMesh};

/// The generalised winding number of a closed mesh at `p` (Jacobson et al. 2013): 1 inside,
/// 0 outside, from the solid angles of its triangles (Van Oosterom and Strackee 1983).
fn winding_number(mesh: &TriMesh, p: DVec3) -> f64 {
    let mut total = 0.0;
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize].as_dvec3() - p);
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let numerator = a.dot(b.cross(c));
        let denominator = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
        total += 2.0 * numerator.atan2(denominator);
    }
    total / (4.0 * std::f64::consts::PI)
}

/// The area-weighted share of `mesh`'s faces whose normal points out of the true solid: a step
/// of `step_m` along the normal from the face's centre leaves the truth's inside, or a step
/// against it enters. 1 for a mesh that faces out everywhere, about −1 for one inside out.
fn outward_agreement(truth: &TriMesh, mesh: &TriMesh, step_m: f64) -> f64 {
    let (mut agree, mut area) = (0.0, 0.0);
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize].as_dvec3());
        let normal = (b - a).cross(c - a);
        let weight = normal.length();
        if weight == 0.0 {
            continue;
        }
        let centre = (a + b + c) / 3.0;
        let step = normal / weight * step_m;
        let outside_ahead = winding_number(truth, centre + step);
        let inside_behind = winding_number(truth, centre - step);
        agree += weight * (inside_behind - outside_ahead).clamp(-1.0, 1.0);
        area += weight;
    }
    agree / area
}

struct Case {
    shape: Shape,
    noise_mm: f32,
    points: usize,
    seed: u64,
    /// Keep only the points on the side facing this sensor position (a one-view shell).
    viewpoint: Option<Vec3>,
}

impl Case {
    fn name(&self) -> String {
        format!(
            "{:?} at {} mm, {} points, seed {}{}",
            self.shape,
            self.noise_mm,
            self.points,
            self.seed,
            match self.viewpoint {
                Some(v) => format!(", seen from {v}"),
                None => String::new(),
            }
        )
    }
}

/// What a camera at `eye` sees of `truth`, roughly: points drawn uniformly by area on the faces
/// that face it (occlusion is left out: it only removes more of the far side), with Gaussian
/// noise. A cut of the cloud by a plane would keep points past the silhouette, which no camera
/// sees and whose normals turn away from it.
fn front_facing_cloud(truth: &TriMesh, eye: Vec3, case: &Case) -> PointCloud {
    let faces: Vec<(Vec3, Vec3, Vec3)> = truth
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| truth.vertices[i as usize]);
            (a, b, c)
        })
        .filter(|&(a, b, c)| (b - a).cross(c - a).dot(eye - a) > 0.0)
        .collect();
    let mut cumulative = Vec::with_capacity(faces.len());
    let mut area = 0.0f64;
    for &(a, b, c) in &faces {
        area += f64::from((b - a).cross(c - a).length());
        cumulative.push(area);
    }
    // SplitMix64: a few lines of seeded randomness, enough for test data.
    let mut state = case.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x5EED;
    let mut uniform = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let sigma = f64::from(case.noise_mm) / 1000.0;
    let points = (0..case.points)
        .map(|_| {
            let pick = uniform() * area;
            let f = cumulative
                .partition_point(|&c| c < pick)
                .min(faces.len() - 1);
            let (a, b, c) = faces[f];
            let (mut u, mut v) = (uniform() as f32, uniform() as f32);
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let on_surface = a + (b - a) * u + (c - a) * v;
            // Box–Muller, three normal deviates.
            let noise = Vec3::from_array([0, 1, 2].map(|_| {
                let (r, theta) = (uniform().max(1e-12), uniform());
                ((-2.0 * r.ln()).sqrt() * (std::f64::consts::TAU * theta).cos() * sigma) as f32
            }));
            on_surface + noise
        })
        .collect();
    PointCloud::new(points)
}

/// Meshes the case and returns why it fails, if it does.
fn check(case: &Case) -> Option<String> {
    let truth = case.shape.mesh();
    let cloud = match case.viewpoint {
        Some(eye) => front_facing_cloud(&truth, eye, case),
        None => sample_cloud(
            &truth,
            &SampleConfig {
                points: case.points,
                noise_sigma_m: case.noise_mm / 1000.0,
                seed: case.seed,
            },
        )
        .expect("sampling a built-in shape"),
    };
    let config = MeshConfig {
        viewpoint: case.viewpoint,
        ..MeshConfig::default()
    };
    let (mesh, report) = match mesh_cloud(&cloud, &config) {
        Ok(meshed) => meshed,
        Err(err) => return Some(format!("{}: not meshed: {err}", case.name())),
    };
    let faced = orientation(&mesh);
    if faced.is_closed() && faced.signed_volume_m3 <= 0.0 {
        return Some(format!(
            "{}: closed with volume {} m³",
            case.name(),
            faced.signed_volume_m3
        ));
    }
    // 5 cm: past the noise of the surface, within the thinnest parts (Suzanne's ears, 3 cm,
    // only count for a few faces). A mesh that faces out scores above 0.4 even where 40 mm of
    // noise crumples its surface into folds; one inside out scores below zero, about −1 when its surface is clean.
    let agreement = outward_agreement(&truth, &mesh, 0.05);
    (agreement < 0.1).then(|| {
        format!(
            "{}: {:.2} of the area faces out of the true shape ({} faces, {} pieces, {} open, \
             {} turned by the check, volume {:.4} m³)",
            case.name(),
            agreement,
            report.faces,
            report.pieces,
            report.open_pieces,
            report.pieces_flipped,
            faced.signed_volume_m3
        )
    })
}

#[test]
fn no_closed_shape_comes_out_inside_out() {
    let mut cases = Vec::new();
    for shape in Shape::ALL {
        for noise_mm in [0.0, 20.0, 40.0] {
            for points in [20_000, 40_000] {
                for seed in [101, 102] {
                    cases.push(Case {
                        shape,
                        noise_mm,
                        points,
                        seed,
                        viewpoint: None,
                    });
                }
            }
        }
    }
    let failures: Vec<String> = cases.par_iter().filter_map(check).collect();
    assert!(
        failures.is_empty(),
        "{} of {} meshes face inwards:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

#[test]
fn one_view_shells_face_the_sensor() {
    let mut cases = Vec::new();
    for shape in Shape::ALL {
        for (noise_mm, seed) in [(20.0, 201), (40.0, 202)] {
            cases.push(Case {
                shape,
                noise_mm,
                points: 20_000,
                seed,
                viewpoint: Some(Vec3::new(1.5, -2.0, 1.0)),
            });
        }
    }
    let failures: Vec<String> = cases.par_iter().filter_map(check).collect();
    assert!(
        failures.is_empty(),
        "{} of {} shells face away:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

/// Thin parts of a sampled closed shape stay closed: Suzanne's ears (3 cm, thinner than the
/// box a tangent plane is fitted over, so one plane stands for both sides) and the cone's rim
/// and apex. The reconstruction decides this (the marching-cubes mesh was open at the ears),
/// so the simplified mesh is judged as the pipeline returns it.
#[test]
fn thin_parts_of_closed_shapes_stay_closed() {
    let mut cases = Vec::new();
    for seed in 1..=3 {
        cases.push((Shape::Monkey, 20.0, seed));
        cases.push((Shape::Cone, 20.0, seed));
    }
    // The noise-free cone was open at its rim on these seeds, and closed on 1–4.
    for seed in 1..=6 {
        cases.push((Shape::Cone, 0.0, seed));
    }
    let open: Vec<String> = cases
        .par_iter()
        .filter_map(|&(shape, noise_mm, seed)| {
            let cloud = sample_cloud(
                &shape.mesh(),
                &SampleConfig {
                    points: 40_000,
                    noise_sigma_m: noise_mm / 1000.0,
                    seed,
                },
            )
            .expect("sampling a built-in shape");
            let (mesh, report) = match mesh_cloud(&cloud, &MeshConfig::default()) {
                Ok(meshed) => meshed,
                Err(err) => return Some(format!("{shape:?} at {noise_mm} mm, seed {seed}: {err}")),
            };
            (!orientation(&mesh).is_closed()).then(|| {
                format!(
                    "{shape:?} at {noise_mm} mm, seed {seed}: open ({} faces, {} open pieces)",
                    report.faces, report.open_pieces
                )
            })
        })
        .collect();
    assert!(
        open.is_empty(),
        "{} of {} meshes are open:\n{}",
        open.len(),
        cases.len(),
        open.join("\n")
    );
}

/// The judge itself: a true shape agrees with itself, and turned inside out it disagrees.
#[test]
fn the_outward_judge_tells_an_inverted_mesh() {
    let truth = Shape::Cone.mesh();
    assert!(outward_agreement(&truth, &truth, 0.02) > 0.95);
    let mut inverted = truth.clone();
    for t in &mut inverted.triangles {
        t.swap(1, 2);
    }
    assert!(outward_agreement(&truth, &inverted, 0.02) < -0.95);
    assert!((winding_number(&truth, DVec3::ZERO) - 1.0).abs() < 1e-6);
}

/// One of the six shapes standing on a table, seen once by a camera at `eye`.
struct OnTable {
    truth: TriMesh,
    /// The table: the plane under the shape's bottom.
    table: SupportPlane,
    /// What the camera sees: 30,000 points on the faces turned to it, none on the underside.
    cloud: PointCloud,
    /// The cloud meshed by the default pipeline.
    shell: TriMesh,
    report: MeshReport,
}

fn seen_on_a_table(shape: Shape, noise_mm: f32, seed: u64, eye: Vec3) -> OnTable {
    let truth = shape.mesh();
    // The shapes fit a 1 m box centred on the origin: the table is its bottom.
    let bottom = truth
        .vertices
        .iter()
        .map(|v| v.z)
        .fold(f32::INFINITY, f32::min);
    let case = Case {
        shape,
        noise_mm,
        points: 30_000,
        seed,
        viewpoint: Some(eye),
    };
    // The table hides the shape's underside from any camera: no points there.
    let mut cloud = front_facing_cloud(&truth, eye, &case);
    cloud.points.retain(|p| p.z > bottom + 0.01);
    let config = MeshConfig {
        viewpoint: Some(eye),
        ..MeshConfig::default()
    };
    let (shell, report) = mesh_cloud(&cloud, &config).expect("meshing a one-view shell");
    OnTable {
        truth,
        table: SupportPlane {
            normal: Vec3::Z,
            offset: bottom,
        },
        cloud,
        shell,
        report,
    }
}

/// The one-view shells of the six shapes standing on a table, seen from 20° above it: each
/// proxy is closed, holds the true object (probes from any side stop at or before it), and is
/// not absurdly larger. `cargo test --release --test tests -- physics_ready::proxies
/// --nocapture` prints the figures BENCHMARKS.md quotes.
#[test]
fn proxies_of_one_view_shells_are_closed_and_hold_the_object() {
    let eye = Vec3::new(1.5, -2.0, 1.0);
    let mut failures = Vec::new();
    const TOLERANCE_M: f32 = 0.02;
    eprintln!(
        "| shape | proxy faces | closed | proxy volume / true volume | true surface inside the \
         proxy | inside or within {TOLERANCE_M} m of its surface | 10 mm probes, shell from the \
         sensor's side: first contact mm / normal p95 ° | 10 mm probes, proxy from all sides: \
         passing through it where the object is / stopped by it where there is none / first \
         contact mm |"
    );
    eprintln!("|---|---:|---|---:|---:|---:|---|---|");
    for shape in Shape::ALL {
        let OnTable {
            truth,
            table,
            shell,
            report,
            ..
        } = seen_on_a_table(shape, 10.0, 301, eye);
        let bottom = table.offset;
        // The daemon's margin: the residual bound the shell was simplified to.
        let config = ProxyConfig {
            margin_m: report.max_residual_bound_m,
            ..ProxyConfig::default()
        };
        let proxy = collision_proxy(&shell, Some(eye), Some(table), &config);
        // Points on the true surface, off its bottom (which stands on the table, where the
        // proxy's cap is too), are inside the proxy when its winding number there is ½ or more.
        let samples = sample_cloud(
            &truth,
            &SampleConfig {
                points: 4_000,
                noise_sigma_m: 0.0,
                seed: 302,
            },
        )
        .expect("sampling a built-in shape");
        let off_bottom: Vec<Vec3> = samples
            .points
            .into_iter()
            .filter(|p| p.z > bottom + 0.005)
            .collect();
        // The visible surface is the reconstruction's, within its error of the truth on
        // either side: a true point just in front of it is "inside up to the mesh's error".
        let surface = ParryTriMesh::new(proxy.mesh.vertices.clone(), proxy.mesh.triangles.clone())
            .expect("a proxy has faces");
        let (inside, within) = off_bottom
            .par_iter()
            .map(|p| {
                let inside = winding_number(&proxy.mesh, p.as_dvec3()) >= 0.5;
                let near = surface.project_local_point(*p, false).point.distance(*p) <= TOLERANCE_M;
                (usize::from(inside), usize::from(inside || near))
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        let share = |n: usize| n as f64 / off_bottom.len() as f64;
        let (inside, within) = (share(inside), share(within));
        // Suzanne's own mesh is not closed: its volume is not a measure.
        let ratio = (shape != Shape::Monkey).then(|| proxy.volume_m3 / signed_volume_m3(&truth));
        // Contact with 10 mm probes: the visual shell from the sensor's side (the one-sided
        // metric), and the proxy from every side, where a conservative proxy lets no probe
        // through that the object would stop.
        let probes = |viewpoint_m| ContactConfig {
            probe_radii_m: vec![0.01],
            probe_lines: 2_000,
            viewpoint_m,
            ..ContactConfig::default()
        };
        let seen = contact_fidelity(&truth, &shell, &probes(Some(eye)))
            .expect("contact with the shell")
            .overall;
        let all_round = contact_fidelity(&truth, &proxy.mesh, &probes(None))
            .expect("contact with the proxy")
            .overall;
        let through = all_round.missed_by_candidate as f64 / all_round.probes as f64;
        eprintln!(
            "| {shape:?} | {} | {} | {} | {:.1} % | {:.1} % | {:.1} / {:.0} | {:.1} % / {:.1} % / {:.1} |",
            proxy.mesh.triangles.len(),
            proxy.closed,
            ratio.map_or("–".to_owned(), |r| format!("{r:.2}")),
            inside * 100.0,
            within * 100.0,
            seen.first_contact_m.mean * 1e3,
            seen.normal_deg.p95,
            through * 100.0,
            all_round.extra_in_candidate as f64 / all_round.probes as f64 * 100.0,
            all_round.first_contact_m.mean * 1e3,
        );
        if proxy.kind != ProxyKind::ShadowVolume
            || !proxy.closed
            || inside < 0.9
            || within < 0.97
            || through > 0.02
            || ratio.is_some_and(|r| !(1.0..6.0).contains(&r))
        {
            failures.push(format!(
                "{shape:?}: {:?}, closed {}, {:.1} % inside, {:.1} % within {TOLERANCE_M} m, \
                 volume ratio {ratio:?}, {:.1} % of the probes through it",
                proxy.kind,
                proxy.closed,
                inside * 100.0,
                within * 100.0,
                through * 100.0
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Mass and contact from every side against what an engine collides with for a one-view
/// object: the daemon's own body of each of the six shapes (1 m) standing on a table, seen
/// once from 20° above it at 20 mm noise, its primitive fitted to the cloud fused into voxels
/// as the daemon's grid fuses it. The body is the primitive the object is, its completion by
/// turning about an axis, or (flagged) its shadow volume; the engine collides the primitive,
/// else the convex hulls. `cargo test --release --test tests -- physics_ready::one_view_bodies
/// --nocapture` prints the figures BENCHMARKS.md quotes.
#[test]
fn one_view_bodies_complete_the_object_for_mass_and_contact() {
    use tacmesh::daemon::{make_body, BodyJob};
    use tacmesh::physics::split_part_points;
    use tacmesh::physics::MassProperties;
    use tacmesh::physics_scene::physics_primitive;
    use tacmesh::protocol::BodySolid;

    let eye = Vec3::new(1.5, -2.0, 1.0);
    eprintln!(
        "| shape | body | volume ÷ true | centre of mass off, mm | principal inertia ÷ true | \
         contact from every side, p95: first contact mm / normal ° | probes through it |"
    );
    eprintln!("|---|---|---:|---:|---|---|---:|");
    let mut failures = Vec::new();
    for shape in Shape::ALL {
        let OnTable {
            truth,
            table,
            cloud,
            shell,
            report,
        } = seen_on_a_table(shape, 20.0, 311, eye);
        let mut grid = tacmesh::reconstruct::moment_grid::MomentGrid::new(report.voxel_size_m);
        grid.integrate(&cloud.points);
        let fused = grid.surface_means(4096);
        let job = BodyJob {
            object_id: 1,
            shape_version: 1,
            mesh_in_object: shell,
            viewpoint_in_object: Some(eye),
            support: Some(table),
            margin_m: report.max_residual_bound_m,
            // What the daemon fits a primitive to: the cloud fused into voxels, their means.
            fused_points: fused.points,
            fused_roughness_m: fused.roughness_m,
        };
        let body = make_body(&job, None, |mesh, config| {
            Ok(split_part_points(mesh, config))
        })
        .expect("a one-view shell on a table has a body");
        // What the engine collides with: the primitive exactly (finely tessellated here), or
        // the union of the hulls.
        let surface = match &body.primitive {
            Some(primitive) => physics_primitive(primitive).mesh_with(128, 64),
            None => TriMesh::concatenated(&body.hulls.iter().map(|h| h.mesh()).collect::<Vec<_>>()),
        };
        let contact = contact_fidelity(&truth, &surface, &ContactConfig::default())
            .expect("contact with the body")
            .overall;
        let through = contact.missed_by_candidate as f64 / contact.probes.max(1) as f64;
        // Suzanne's own mesh is not closed: no volume or centre to compare with.
        let true_mass = (shape != Shape::Monkey)
            .then(|| MassProperties::of_closed_mesh(&truth).expect("a closed true shape"));
        let ratio = true_mass
            .as_ref()
            .map(|m| f64::from(body.volume_m3) / f64::from(m.volume_m3));
        let off_mm = true_mass
            .as_ref()
            .map(|m| f64::from(body.centre_of_mass.distance(m.centre_of_mass)) * 1e3);
        // The principal moments, smallest first, each over the truth's: the lowest and the
        // highest of the three ratios.
        let inertia = true_mass.as_ref().map(|m| {
            let got = MassProperties {
                volume_m3: body.volume_m3,
                centre_of_mass: body.centre_of_mass,
                inertia: body.inertia,
            }
            .principal_moments();
            let ratios = got
                .iter()
                .zip(m.principal_moments())
                .map(|(g, t)| f64::from(g / t));
            (
                ratios.clone().fold(f64::INFINITY, f64::min),
                ratios.fold(0.0, f64::max),
            )
        });
        let what = match &body.primitive {
            Some(p) => physics_primitive(p).shape.name().to_owned(),
            None => format!("{} ({} hulls)", body.solid.as_str(), body.hulls.len()),
        };
        eprintln!(
            "| {shape:?} | {what} | {} | {} | {} | {:.1} / {:.1} | {:.1} % |",
            ratio.map_or("–".to_owned(), |r| format!("{r:.2}")),
            off_mm.map_or("–".to_owned(), |m| format!("{m:.0}")),
            inertia.map_or("–".to_owned(), |(lo, hi)| format!("{lo:.2}–{hi:.2}")),
            contact.first_contact_m.p95 * 1e3,
            contact.normal_deg.p95,
            through * 100.0,
        );
        // A primitive where the shape is one, to issue 40's targets: 0.8–1.25× the volume,
        // the centre of mass within 15 mm, contact p95 within 10 mm and 10°. The cone and the
        // torus turned about their axes, to the targets for shapes that are no primitive:
        // 0.7–1.5× and 20 mm (their contact is not at the target yet). Suzanne, neither: a
        // fallback, closed, holding the object.
        let primitive = match shape {
            Shape::Cube => Some("box"),
            Shape::Cylinder => Some("cylinder"),
            Shape::Sphere => Some("sphere"),
            Shape::Cone | Shape::Torus | Shape::Monkey => None,
        };
        let on_target = match (primitive, shape) {
            (Some(kind), _) => {
                what == kind
                    && ratio.is_some_and(|r| (0.8..=1.25).contains(&r))
                    && off_mm.is_some_and(|m| m <= 15.0)
                    && inertia.is_some_and(|(lo, hi)| lo >= 0.7 && hi <= 1.4)
                    && contact.first_contact_m.p95 <= 0.010
                    && contact.normal_deg.p95 <= 10.0
            }
            (None, Shape::Cone | Shape::Torus) => {
                body.solid == BodySolid::Completed
                    && ratio.is_some_and(|r| (0.7..=1.5).contains(&r))
                    && off_mm.is_some_and(|m| m <= 20.0)
                    && inertia.is_some_and(|(lo, hi)| lo >= 0.7 && hi <= 1.5)
            }
            (None, _) => body.solid.is_fallback(),
        };
        if !on_target || through > 0.05 {
            failures.push(format!(
                "{shape:?}: {what}, {ratio:?}× its volume, centre {off_mm:?} mm off, inertia \
                 {inertia:?}×, contact \
                 p95 {:.1} mm / {:.1}°, {:.1} % of the probes through it",
                contact.first_contact_m.p95 * 1e3,
                contact.normal_deg.p95,
                through * 100.0
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
