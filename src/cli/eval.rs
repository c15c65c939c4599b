use anyhow::Context;
use clap::Args;
use serde::Serialize;
use tacmesh::glam::Vec3;
use tacmesh::sim::{
    contact_fidelity, mesh_distance, ContactConfig, ContactErrors, ContactFidelity, ErrorSummary,
    DEFAULT_PROBE_LINES, PAPER_SAMPLES,
};

/// Compare a mesh with a reference: mean Hausdorff error (the paper's metric) and friends, and
/// with --contact how a physics simulation touching it would differ.
///
/// Samples points uniformly by area on each surface and measures exact point-to-triangle
/// distances to the other; MHE is the mean of the two one-sided means. All values in metres.
///
/// --contact moves probe balls (5 to 50 mm) toward both meshes along the same lines and
/// reports, per radius, the errors of the first contact (millimetres, along the contact normal
/// and along the approach), of the contact normal (degrees) and of the penetration depth at a
/// fixed push (millimetres), as mean, p95 and max, with the probes that touched only one mesh.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Reference: a shape name (cone, cube, cylinder, monkey, torus, sphere; 1 m as in the
    /// paper) or a mesh file
    reference: String,
    /// Candidate mesh file (or shape name)
    candidate: String,
    /// Samples on each surface
    #[arg(long, default_value_t = PAPER_SAMPLES)]
    samples: usize,
    /// Seed of the sampling (and of the contact probes)
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print one JSON object
    #[arg(long)]
    json: bool,
    /// Also measure contact fidelity with probe balls
    #[arg(long)]
    contact: bool,
    /// Probe ball radii in millimetres, comma-separated
    #[arg(
        long,
        value_name = "MM,...",
        value_delimiter = ',',
        value_parser = parse_radius_mm,
        default_value = "5,10,20,50",
        allow_hyphen_values = true,
        requires = "contact"
    )]
    probe_radii_mm: Vec<f32>,
    /// How far past its first contact with the reference each probe is pushed to compare
    /// penetration depths, millimetres
    #[arg(long, value_name = "MM", value_parser = parse_push_mm, default_value_t = 10.0, allow_hyphen_values = true, requires = "contact")]
    push_mm: f32,
    /// Probe lines, each run with every radius (a third to four fifths of them touch a compact
    /// object)
    #[arg(
        long,
        value_name = "N",
        default_value_t = DEFAULT_PROBE_LINES as u32,
        value_parser = clap::value_parser!(u32).range(1..),
        requires = "contact"
    )]
    probes: u32,
    /// The sensor's position x,y,z in metres, in the meshes' frame: use only probes from its
    /// side that touch surfaces facing it (for the open mesh of a one-view scan)
    #[arg(long, value_name = "X,Y,Z", value_parser = super::parse_vec3, allow_hyphen_values = true, requires = "contact")]
    viewpoint: Option<Vec3>,
    /// Also measure contact, from every side, against the body an engine would collide with
    /// instead of the candidate mesh: the box, cylinder or sphere the candidate is when one
    /// explains it (in any orientation for a closed candidate; an open one only as a sphere:
    /// offline there is no support to stand it on), else the convex hulls of its closed proxy
    /// (an open one-view mesh closed along the rays from --viewpoint)
    #[arg(long, requires = "contact")]
    body: bool,
}

fn parse_radius_mm(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(mm) if mm.is_finite() && mm > 0.0 => Ok(mm),
        _ => Err("expected a probe radius in millimetres > 0, e.g. 5,10,20,50".into()),
    }
}

fn parse_push_mm(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(mm) if mm.is_finite() && mm >= 0.0 => Ok(mm),
        _ => Err("expected a push in millimetres >= 0, e.g. 10".into()),
    }
}

#[derive(Debug, Serialize)]
struct EvalReport {
    mhe: f64,
    mean_reference_to_candidate: f64,
    mean_candidate_to_reference: f64,
    hausdorff: f64,
    max_reference_to_candidate: f64,
    max_candidate_to_reference: f64,
    rms: f64,
    faces: usize,
    reference_faces: usize,
    samples_per_side: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    contact: Option<ContactReport>,
    /// What the body is (`sphere`, `3 hulls of the shadow volume`…), with --body.
    #[serde(skip_serializing_if = "Option::is_none")]
    body: Option<String>,
    /// Contact against the body, from every side, with --body.
    #[serde(skip_serializing_if = "Option::is_none")]
    body_contact: Option<ContactReport>,
}

/// The surface an engine collides with for `candidate` (see `EvalArgs::body`), and what it is.
fn body_surface(
    candidate: &tacmesh::TriMesh,
    viewpoint: Option<Vec3>,
) -> anyhow::Result<(tacmesh::TriMesh, String)> {
    use tacmesh::physics::{
        collision_proxy, convex_parts, fit_closed_primitive, fit_primitive, surface_points,
        ConvexConfig, ProxyConfig,
    };
    let extent = candidate
        .bounds()
        .map_or(0.0, |(lo, hi)| (hi - lo).max_element());
    // The pipeline's default residual bound, 2.5 % of the extent, and the same 3 mm of noise
    // the subscriber allows a primitive.
    let bound_m = 0.025 * extent + 0.003;
    let points = surface_points(candidate);
    let primitive = if candidate.is_closed() {
        fit_closed_primitive(&points, bound_m)
    } else {
        fit_primitive(&points, None, bound_m)
    };
    if let Some(primitive) = primitive {
        return Ok((
            primitive.mesh_with(128, 64),
            primitive.shape.name().to_owned(),
        ));
    }
    let proxy = collision_proxy(candidate, viewpoint, None, &ProxyConfig::default());
    anyhow::ensure!(
        proxy.closed,
        "the candidate has no body: it is open and no --viewpoint closes it"
    );
    let parts = convex_parts(&proxy.mesh, &ConvexConfig::default())?;
    Ok((
        tacmesh::TriMesh::concatenated(&parts.hulls),
        format!("{} hulls of the {}", parts.hulls.len(), proxy.kind.as_str()),
    ))
}

/// `--contact` in the JSON: lengths in millimetres, angles in degrees.
#[derive(Debug, Serialize)]
struct ContactReport {
    push_mm: f64,
    probe_lines: usize,
    viewpoint_m: Option<[f32; 3]>,
    per_radius: Vec<RadiusReport>,
    overall: ErrorsReport,
}

#[derive(Debug, Serialize)]
struct RadiusReport {
    probe_radius_mm: f64,
    #[serde(flatten)]
    errors: ErrorsReport,
}

#[derive(Debug, Serialize)]
struct ErrorsReport {
    probes: usize,
    missed_by_candidate: usize,
    extra_in_candidate: usize,
    first_contact_mm: SummaryReport,
    first_contact_along_approach_mm: SummaryReport,
    normal_deg: SummaryReport,
    penetration_mm: SummaryReport,
}

#[derive(Debug, Serialize)]
struct SummaryReport {
    mean: f64,
    p50: f64,
    p95: f64,
    max: f64,
}

impl SummaryReport {
    fn scaled(s: ErrorSummary, factor: f64) -> Self {
        Self {
            mean: s.mean * factor,
            p50: s.p50 * factor,
            p95: s.p95 * factor,
            max: s.max * factor,
        }
    }
}

impl From<&ContactErrors> for ErrorsReport {
    fn from(e: &ContactErrors) -> Self {
        Self {
            probes: e.probes,
            missed_by_candidate: e.missed_by_candidate,
            extra_in_candidate: e.extra_in_candidate,
            first_contact_mm: SummaryReport::scaled(e.first_contact_m, 1e3),
            first_contact_along_approach_mm: SummaryReport::scaled(
                e.first_contact_along_approach_m,
                1e3,
            ),
            normal_deg: SummaryReport::scaled(e.normal_deg, 1.0),
            penetration_mm: SummaryReport::scaled(e.penetration_m, 1e3),
        }
    }
}

impl ContactReport {
    fn new(f: &ContactFidelity, viewpoint: Option<Vec3>) -> Self {
        Self {
            push_mm: f64::from(f.push_m * 1e3),
            probe_lines: f.probe_lines,
            viewpoint_m: viewpoint.map(|v| v.to_array()),
            per_radius: f
                .per_radius
                .iter()
                .map(|r| RadiusReport {
                    probe_radius_mm: f64::from(r.probe_radius_m * 1e3),
                    errors: ErrorsReport::from(&r.errors),
                })
                .collect(),
            overall: ErrorsReport::from(&f.overall),
        }
    }

    /// A readable table: one row per radius and one over all of them.
    fn table(&self) -> String {
        let mut out = format!(
            "contact: {} probe lines, push {} mm{}; errors as mean / p95 / max\n",
            self.probe_lines,
            self.push_mm,
            match self.viewpoint_m {
                Some([x, y, z]) => format!(", one-sided from {x},{y},{z}"),
                None => String::new(),
            }
        );
        out += &format!(
            "{:>9} {:>6} {:>6} {:>5}  {:>22}  {:>22}  {:>20}  {:>22}\n",
            "radius mm",
            "probes",
            "missed",
            "extra",
            "first contact mm",
            "along approach mm",
            "normal deg",
            "penetration mm"
        );
        let row = |label: String, e: &ErrorsReport| {
            let cell = |s: &SummaryReport| format!("{:.2} / {:.2} / {:.2}", s.mean, s.p95, s.max);
            format!(
                "{label:>9} {:>6} {:>6} {:>5}  {:>22}  {:>22}  {:>20}  {:>22}\n",
                e.probes,
                e.missed_by_candidate,
                e.extra_in_candidate,
                cell(&e.first_contact_mm),
                cell(&e.first_contact_along_approach_mm),
                cell(&e.normal_deg),
                cell(&e.penetration_mm)
            )
        };
        for r in &self.per_radius {
            out += &row(format!("{}", r.probe_radius_mm), &r.errors);
        }
        out += &row("all".into(), &self.overall);
        out.trim_end().to_owned()
    }
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    let reference = super::shape_or_mesh_file(&args.reference)?;
    let candidate = super::shape_or_mesh_file(&args.candidate)?;
    let comparing = || format!("comparing {} with {}", args.candidate, args.reference);
    let d =
        mesh_distance(&reference, &candidate, args.samples, args.seed).with_context(comparing)?;
    let contact = if args.contact {
        let config = ContactConfig {
            probe_radii_m: args.probe_radii_mm.iter().map(|mm| mm / 1e3).collect(),
            push_m: args.push_mm / 1e3,
            probe_lines: args.probes as usize,
            seed: args.seed,
            viewpoint_m: args.viewpoint,
            ..ContactConfig::default()
        };
        let fidelity = contact_fidelity(&reference, &candidate, &config).with_context(comparing)?;
        Some(ContactReport::new(&fidelity, args.viewpoint))
    } else {
        None
    };
    let (body, body_contact) = if args.body {
        let (surface, what) = body_surface(&candidate, args.viewpoint).with_context(comparing)?;
        let config = ContactConfig {
            probe_radii_m: args.probe_radii_mm.iter().map(|mm| mm / 1e3).collect(),
            push_m: args.push_mm / 1e3,
            probe_lines: args.probes as usize,
            seed: args.seed,
            viewpoint_m: None,
            ..ContactConfig::default()
        };
        let fidelity = contact_fidelity(&reference, &surface, &config).with_context(comparing)?;
        (Some(what), Some(ContactReport::new(&fidelity, None)))
    } else {
        (None, None)
    };
    let report = EvalReport {
        mhe: d.mhe_m,
        mean_reference_to_candidate: d.mean_reference_to_candidate_m,
        mean_candidate_to_reference: d.mean_candidate_to_reference_m,
        hausdorff: d.hausdorff_m,
        max_reference_to_candidate: d.max_reference_to_candidate_m,
        max_candidate_to_reference: d.max_candidate_to_reference_m,
        rms: d.rms_m,
        faces: candidate.triangles.len(),
        reference_faces: reference.triangles.len(),
        samples_per_side: d.samples_per_side,
        contact,
        body,
        body_contact,
    };
    if args.json {
        return super::print_json(&report);
    }
    super::print_line(&format!(
        "mhe {:.5} m  hausdorff {:.5} m  rms {:.5} m  faces {} (reference {})",
        report.mhe, report.hausdorff, report.rms, report.faces, report.reference_faces
    ))?;
    if let Some(contact) = &report.contact {
        super::print_line(&contact.table())?;
    }
    if let (Some(what), Some(contact)) = (&report.body, &report.body_contact) {
        super::print_line(&format!("body: {what}, probed from every side"))?;
        super::print_line(&contact.table())?;
    }
    Ok(())
}
