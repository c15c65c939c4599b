//! Scripted rigid motion of a scene object: a fixed pose, or waypoints interpolated in time.
//!
//! Entry points:
//! - [`Motion`]: [`Motion::Fixed`] (any invertible affine pose) or [`Motion::Path`]
//!   ([`Waypoint`]s played [`PathMode::Once`], [`PathMode::Loop`] or [`PathMode::PingPong`]);
//!   [`Motion::world_from_object_at`] is the pose at a scene time.
//!
//! A path pose is rigid: a translation to the waypoint's position after a rotation of
//! `yaw_deg` about the object's +Z axis (world +Z, since paths do not tilt). Between two
//! waypoints the position and the yaw (in degrees, so 0 → 360 is one full turn) are linearly
//! interpolated. Before its first waypoint an object holds the first pose.
//!
//! Layout: the types, then path time (mode → time along the path), then the pose at that time.

use glam::{Affine3A, Vec3};

/// One scripted pose: at scene time `time_s` the object's origin is at `position` (world
/// metres) and it is turned by `yaw_deg` about +Z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Waypoint {
    pub time_s: f32,
    pub position: Vec3,
    pub yaw_deg: f32,
}

impl Waypoint {
    /// `world_from_object` of this waypoint: rotate by the yaw, then translate.
    pub fn world_from_object(&self) -> Affine3A {
        Affine3A::from_translation(self.position)
            * Affine3A::from_rotation_z(self.yaw_deg.to_radians())
    }
}

/// What a path does after its last waypoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PathMode {
    /// Stop and hold the last pose.
    #[default]
    Once,
    /// Jump back to the first waypoint and play again (make the last waypoint equal the first
    /// for a closed loop without a jump).
    Loop,
    /// Play backwards to the first waypoint, then forwards again, for ever.
    PingPong,
}

impl PathMode {
    /// The mode's name in scene files: `once`, `loop` or `pingpong`.
    pub fn name(self) -> &'static str {
        match self {
            PathMode::Once => "once",
            PathMode::Loop => "loop",
            PathMode::PingPong => "pingpong",
        }
    }
}

/// How an object is placed over time.
#[derive(Debug, Clone, PartialEq)]
pub enum Motion {
    /// Always at this pose. Any finite, invertible affine map; ray casting bakes it into the
    /// mesh once.
    Fixed(Affine3A),
    /// Along scripted waypoints, whose times must be finite and strictly increasing.
    Path {
        waypoints: Vec<Waypoint>,
        mode: PathMode,
    },
}

impl Motion {
    /// Whether the pose never changes.
    pub fn is_fixed(&self) -> bool {
        match self {
            Motion::Fixed(_) => true,
            Motion::Path { waypoints, .. } => waypoints.len() <= 1,
        }
    }

    /// The object's pose at scene time `t_s` (see the module docs for the interpolation).
    /// A path without waypoints, which [`Motion::check`] rejects, stays at the origin.
    pub fn world_from_object_at(&self, t_s: f32) -> Affine3A {
        match self {
            Motion::Fixed(pose) => *pose,
            Motion::Path { waypoints, mode } => match interpolate(waypoints, *mode, t_s) {
                Some(waypoint) => waypoint.world_from_object(),
                None => Affine3A::IDENTITY,
            },
        }
    }

    /// Why this motion cannot be played, if it cannot: a non-finite or singular fixed pose, a
    /// path without waypoints, a non-finite waypoint or waypoint times not strictly increasing.
    pub fn check(&self) -> Result<(), String> {
        match self {
            Motion::Fixed(pose) => {
                if pose.is_finite() && pose.matrix3.determinant() != 0.0 {
                    Ok(())
                } else {
                    Err(format!(
                        "the fixed pose must be finite and invertible, got {pose:?}"
                    ))
                }
            }
            Motion::Path { waypoints, .. } => {
                if waypoints.is_empty() {
                    return Err("a path needs at least one waypoint".into());
                }
                for (i, w) in waypoints.iter().enumerate() {
                    if !(w.time_s.is_finite() && w.position.is_finite() && w.yaw_deg.is_finite()) {
                        return Err(format!("waypoint {i} is not finite: {w:?}"));
                    }
                }
                for (i, pair) in waypoints.windows(2).enumerate() {
                    if pair[1].time_s <= pair[0].time_s {
                        return Err(format!(
                            "waypoint times must strictly increase, but waypoint {} is at {} s after waypoint {i} at {} s",
                            i + 1,
                            pair[1].time_s,
                            pair[0].time_s
                        ));
                    }
                }
                Ok(())
            }
        }
    }
}

// -- path time: where along the path the object is at scene time t ----------------------------

/// The time along the path (between the first and last waypoint times) that `mode` plays at
/// scene time `t_s`.
fn path_time_s(first_s: f32, last_s: f32, mode: PathMode, t_s: f32) -> f32 {
    let span_s = last_s - first_s;
    let since_s = t_s - first_s;
    if span_s <= 0.0 || since_s <= 0.0 {
        return first_s;
    }
    match mode {
        PathMode::Once => t_s.min(last_s),
        PathMode::Loop => first_s + since_s.rem_euclid(span_s),
        PathMode::PingPong => {
            let phase_s = since_s.rem_euclid(2.0 * span_s);
            first_s + span_s - (phase_s - span_s).abs()
        }
    }
}

// -- the pose at that time ----------------------------------------------------------------------

/// The interpolated waypoint at scene time `t_s`, or `None` without waypoints. Waypoint times
/// must increase (unchecked here; [`Motion::check`] does).
fn interpolate(waypoints: &[Waypoint], mode: PathMode, t_s: f32) -> Option<Waypoint> {
    let (first, last) = (waypoints.first()?, waypoints.last()?);
    let path_t_s = path_time_s(first.time_s, last.time_s, mode, t_s);
    // The first waypoint after `path_t_s`; the segment is [next - 1, next].
    let next = waypoints.partition_point(|w| w.time_s <= path_t_s);
    if next == 0 {
        return Some(*first);
    }
    if next == waypoints.len() {
        return Some(*last);
    }
    let (a, b) = (waypoints[next - 1], waypoints[next]);
    let f = (path_t_s - a.time_s) / (b.time_s - a.time_s);
    Some(Waypoint {
        time_s: t_s,
        position: a.position.lerp(b.position, f),
        yaw_deg: a.yaw_deg + f * (b.yaw_deg - a.yaw_deg),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn waypoint(time_s: f32, x: f32, yaw_deg: f32) -> Waypoint {
        Waypoint {
            time_s,
            position: Vec3::new(x, 0.0, 0.0),
            yaw_deg,
        }
    }

    /// A path from x = 0 at 1 s to x = 2 at 3 s, turning 0 → 90°.
    fn path(mode: PathMode) -> Motion {
        Motion::Path {
            waypoints: vec![waypoint(1.0, 0.0, 0.0), waypoint(3.0, 2.0, 90.0)],
            mode,
        }
    }

    fn x_at(motion: &Motion, t_s: f32) -> f32 {
        motion.world_from_object_at(t_s).translation.x
    }

    #[test]
    fn once_interpolates_then_holds_both_ends() {
        let motion = path(PathMode::Once);
        assert_eq!(x_at(&motion, 0.0), 0.0);
        assert_eq!(x_at(&motion, 1.0), 0.0);
        assert!((x_at(&motion, 1.5) - 0.5).abs() < 1e-6);
        assert!((x_at(&motion, 2.0) - 1.0).abs() < 1e-6);
        assert_eq!(x_at(&motion, 3.0), 2.0);
        assert_eq!(x_at(&motion, 100.0), 2.0);
    }

    #[test]
    fn loop_restarts_from_the_first_waypoint() {
        let motion = path(PathMode::Loop);
        assert!((x_at(&motion, 2.0) - 1.0).abs() < 1e-6);
        // Period 2 s: 3.5 s is 0.5 s into the second lap.
        assert!((x_at(&motion, 3.5) - 0.5).abs() < 1e-6);
        assert!((x_at(&motion, 10.0) - 1.0).abs() < 1e-5);
    }

    #[test]
    fn pingpong_plays_back_and_forth() {
        let motion = path(PathMode::PingPong);
        assert!((x_at(&motion, 2.0) - 1.0).abs() < 1e-6);
        assert!((x_at(&motion, 3.0) - 2.0).abs() < 1e-6);
        // On the way back: 3.5 s mirrors 2.5 s.
        assert!((x_at(&motion, 3.5) - 1.5).abs() < 1e-6);
        assert!((x_at(&motion, 5.0) - 0.0).abs() < 1e-6);
        // Period 4 s.
        assert!((x_at(&motion, 6.5) - 1.5).abs() < 1e-5);
    }

    #[test]
    fn yaw_turns_about_world_z() {
        let motion = path(PathMode::Once);
        // Halfway: 45°, at x = 1. The object's +X axis points between world +X and +Y.
        let pose = motion.world_from_object_at(2.0);
        let x_axis = pose.transform_vector3(Vec3::X);
        let half = std::f32::consts::FRAC_1_SQRT_2;
        assert!(
            x_axis.distance(Vec3::new(half, half, 0.0)) < 1e-6,
            "{x_axis}"
        );
        assert!(pose.transform_vector3(Vec3::Z).distance(Vec3::Z) < 1e-6);
        let p = pose.transform_point3(Vec3::new(0.0, 0.0, 0.3));
        assert!(p.distance(Vec3::new(1.0, 0.0, 0.3)) < 1e-6, "{p}");
    }

    #[test]
    fn single_waypoint_and_fixed_motions_do_not_move() {
        let still = Motion::Path {
            waypoints: vec![waypoint(2.0, 1.0, 0.0)],
            mode: PathMode::Loop,
        };
        assert!(still.is_fixed());
        assert_eq!(x_at(&still, 0.0), 1.0);
        assert_eq!(x_at(&still, 9.0), 1.0);
        let pose = Affine3A::from_translation(Vec3::Y);
        assert_eq!(Motion::Fixed(pose).world_from_object_at(5.0), pose);
        assert!(!path(PathMode::Once).is_fixed());
    }

    #[test]
    fn check_rejects_unordered_or_empty_paths() {
        assert!(path(PathMode::Loop).check().is_ok());
        let empty = Motion::Path {
            waypoints: vec![],
            mode: PathMode::Once,
        };
        assert!(empty.check().is_err());
        let backwards = Motion::Path {
            waypoints: vec![waypoint(1.0, 0.0, 0.0), waypoint(1.0, 1.0, 0.0)],
            mode: PathMode::Once,
        };
        let reason = backwards.check().unwrap_err();
        assert!(reason.contains("strictly increase"), "{reason}");
        assert!(Motion::Fixed(Affine3A::ZERO).check().is_err());
    }
}
