//! The camera's own error: one rigid correction of each frame, estimated from the objects that
//! stand still and applied to the whole frame before any object is aligned.
//!
//! Why: a camera pose from SLAM or odometry is off by centimetres and a degree, and a camera
//! with no pose at all (a hand-held one, or one on a moving base) moves every frame. Aligned
//! one by one, each object then "moves" by the camera's error, is predicted there, and the
//! next view's cluster of it (from a pose off the other way) lies beyond the match distance
//! and is born again: two posed Kinect views 4 cm and 1.1° off each other made a new pair of
//! objects every two frames. The error is shared by every still object; each object alone
//! cannot tell it from its own motion, and its surface alone leaves directions free (a
//! sphere's turns, a box face's slide), but all of them together fix it in every direction.
//! Object-level SLAM tracks the camera against its objects the same way (SLAM++,
//! Salas-Moreno et al. 2013); here the map's objects are the model and the frame is aligned
//! to them, frame to model, so the correction does not drift.
//!
//! Each frame ([`CameraError::estimate`]):
//! 1. Guesses: the last correction, then the other corrections of the last frames (a camera
//!    that goes back and forth between viewpoints returns to an earlier one), then none. The
//!    clusters, moved by each, are associated with all the objects (where they are predicted;
//!    one moving on its own is outvoted below) by centroid; at least [`MIN_AGREEING`] must
//!    match.
//! 2. A guess under which most matched clusters (more than half) already lie on their models
//!    ([`FITS_SHARE`] of their points) stands as it is: the others moved on their own.
//!    Otherwise, from the guess that fits best: all matched clusters are aligned to their
//!    objects' models at once ([`align_jointly`]); the objects whose cluster then lands on its
//!    model (at least [`AGREE_SHARE`] of its points) agree. The correction stands if at least
//!    [`MIN_AGREEING`] objects and at least half of those matched agree; it is refitted on
//!    the agreeing ones alone.
//! 3. If no guess stands, a guess from the clusters' and objects' centroids: RANSAC over
//!    triples of (cluster, object) pairs whose mutual distances agree (a rigid motion keeps
//!    them; the triples are grown from seed pairs through such pairs only), each triple giving
//!    a motion in closed form; the motion that brings most
//!    centroids onto their objects' is tried as in step 2. This reaches a camera that moved
//!    far beyond the match distance (15° at 2 m is half a metre).
//! 4. A dead band as for objects: a correction that differs from the last by less than half
//!    the move thresholds keeps the last, so noise never accumulates.
//!
//! With no guess standing (a new scene, a single object) the last correction is kept.

use std::collections::BTreeMap;
use std::time::Duration;

use glam::{Affine3A, Mat3, Quat, Vec3};
use tracing::debug;

use crate::associate::associate_greedy;
use crate::config::TrackConfig;
use crate::icp::{align_jointly, joint_shares, JointAlignment, JointPart};
use crate::object::TrackedObject;

/// A matched object agrees with a correction when this share of its cluster's points lies
/// on its model (within the fine level's rejection distance) under it.
pub const AGREE_SHARE: f32 = 0.6;

/// A guess under which most matched clusters have this share of their points on their
/// models stands without being refined (see `Trial::fits`).
pub const FITS_SHARE: f32 = 0.9;

/// Fewest agreeing objects for a correction: one object cannot tell the camera's motion from
/// its own.
pub const MIN_AGREEING: usize = 3;

/// At most this many points of each cluster take part in the joint alignment (an even
/// stride), so that each object counts about the same, however large.
const POINTS_PER_PART: usize = 300;

/// At most this many objects (the largest clusters) take part.
const MAX_PARTS: usize = 16;

/// Corrections kept as guesses, newest first.
const RECENT: usize = 4;

/// RANSAC over centroid pairs: pairs farther apart than this (after the last correction) are
/// not considered, metres.
const RANSAC_REACH_M: f32 = 0.6;
/// A cluster's centroid within this of its object's (partial views move centroids by a few
/// centimetres) is an inlier; also the slack on the mutual distances of a triple, metres.
const RANSAC_INLIER_M: f32 = 0.04;
/// Seed pairs tried (an even stride through all pairs), and triples tried per seed.
const RANSAC_SEEDS: usize = 64;
const RANSAC_TRIPLES_PER_SEED: usize = 16;
/// Fewest inliers for a RANSAC motion to be tried.
const RANSAC_MIN_INLIERS: usize = 3;

/// The correction of the camera, carried from frame to frame.
#[derive(Debug, Clone)]
pub struct CameraError {
    /// Maps a frame's world (as its pose put it) onto the map's world.
    correction: Affine3A,
    /// Recently accepted corrections, newest first, each distinct from the others.
    recent: Vec<Affine3A>,
}

impl Default for CameraError {
    fn default() -> Self {
        Self {
            correction: Affine3A::IDENTITY,
            recent: Vec::new(),
        }
    }
}

/// One cluster as the estimate sees it: finite points and their centroid, world frame as
/// the frame's pose put them.
pub type Cluster = (Vec<Vec3>, Vec3);

/// A correction that stood: it, how many objects agreed, and their mean centroid.
struct Standing {
    correction: Affine3A,
    agreeing: usize,
    centre: Vec3,
}

impl CameraError {
    /// Estimates this frame's correction from its clusters and the map's objects, where they
    /// are predicted (see the module doc), keeps it for the next frame, and returns it.
    pub fn estimate(
        &mut self,
        clusters: &[Option<Cluster>],
        objects: &BTreeMap<u64, TrackedObject>,
        now: Duration,
        config: &TrackConfig,
    ) -> Affine3A {
        // Every object takes part, where it is predicted: one that moves on its own disagrees
        // and is outvoted, and leaving out the ones a wrong correction set moving would keep
        // the estimate from ever seeing them again.
        let objects: Vec<&TrackedObject> = objects.values().collect();
        if objects.len() < MIN_AGREEING || clusters.iter().flatten().count() < MIN_AGREEING {
            return self.correction;
        }
        let centroids: Vec<Vec3> = objects.iter().map(|o| o.predicted_centroid(now)).collect();
        let mut guesses = vec![self.correction];
        for &recent in self.recent.iter().chain([&Affine3A::IDENTITY]) {
            if !guesses
                .iter()
                .any(|g| close(g, &recent, Vec3::ZERO, config))
            {
                guesses.push(recent);
            }
        }
        let mut trials: Vec<Trial> = guesses
            .into_iter()
            .filter_map(|guess| Trial::new(guess, now, clusters, &objects, &centroids, config))
            .collect();
        // A guess that already lands most clusters on their models stands as it is: refined
        // anew each frame, the correction would carry the joint alignment's noise (two
        // objects, one a sphere, turned it by up to a degree from frame to frame) into every
        // object.
        for t in &trials {
            tracing::trace!(pairs = t.pairs.len(), shares = ?t.shares, "camera correction: a guess as it is");
        }
        let mut standing = trials.iter().find_map(|t| t.standing_as_is(&centroids));
        if standing.is_none() {
            trials.sort_by(|a, b| b.mean_share().total_cmp(&a.mean_share()));
            standing = trials
                .into_iter()
                .find_map(|trial| trial.refine(&centroids, config));
        }
        if standing.is_none() {
            let ransac = centroid_ransac(self.correction, clusters, &centroids);
            tracing::trace!(
                found = ransac.is_some(),
                "camera correction: RANSAC on centroids"
            );
            standing = ransac
                .and_then(|guess| Trial::new(guess, now, clusters, &objects, &centroids, config))
                .and_then(|trial| {
                    trial
                        .standing_as_is(&centroids)
                        .or_else(|| trial.refine(&centroids, config))
                });
        }
        let Some(standing) = standing else {
            tracing::trace!("camera correction: no guess stands; the last one is kept");
            return self.correction;
        };
        tracing::trace!(agreeing = standing.agreeing, "camera correction stands");
        if !close(
            &standing.correction,
            &self.correction,
            standing.centre,
            config,
        ) {
            debug!(
                agreeing = standing.agreeing,
                shift_mm = 1e3
                    * (standing.correction.transform_point3(standing.centre)
                        - self.correction.transform_point3(standing.centre))
                    .length(),
                "camera correction changed"
            );
            self.correction = standing.correction;
        }
        self.remember(self.correction, standing.centre, config);
        self.correction
    }

    /// Puts `correction` first among the recent ones, dropping any close to it.
    fn remember(&mut self, correction: Affine3A, centre: Vec3, config: &TrackConfig) {
        self.recent
            .retain(|r| !close(r, &correction, centre, config));
        self.recent.insert(0, correction);
        self.recent.truncate(RECENT);
    }
}

/// Whether two corrections differ by less than half the move thresholds, measured at
/// `centre` (where the objects are: a turn about a far origin shifts them more).
fn close(a: &Affine3A, b: &Affine3A, centre: Vec3, config: &TrackConfig) -> bool {
    let delta = *a * b.inverse();
    let at = b.transform_point3(centre);
    let shift = (delta.transform_point3(at) - at).length();
    let turn = Quat::from_mat3a(&delta.matrix3).angle_between(Quat::IDENTITY);
    shift < 0.5 * config.move_threshold_m && turn < 0.5 * config.move_threshold_rad
}

/// One guess's association, ready to be judged and refined (step 2 of the module doc).
struct Trial<'a> {
    guess: Affine3A,
    /// (cluster index, object index) per part.
    pairs: Vec<(usize, usize)>,
    parts: Vec<JointPart<'a>>,
    /// Per part, the share of its points on its model under the guess as it is.
    shares: Vec<f32>,
    /// Where the objects' clusters are, moved by the guess, against where the objects are:
    /// the mean offset, a start for a guess whose rotation is right but shift is not.
    offset: Vec3,
}

impl<'a> Trial<'a> {
    /// Associates the clusters moved by `guess` with the objects; `None` below
    /// [`MIN_AGREEING`] pairs.
    fn new(
        guess: Affine3A,
        now: Duration,
        clusters: &[Option<Cluster>],
        objects: &[&'a TrackedObject],
        centroids: &[Vec3],
        config: &TrackConfig,
    ) -> Option<Self> {
        let moved: Vec<Option<Vec3>> = clusters
            .iter()
            .map(|c| {
                c.as_ref()
                    .map(|(_, centroid)| guess.transform_point3(*centroid))
            })
            .collect();
        let mut pairs = associate_greedy(&moved, centroids, config.match_distance_m);
        if pairs.len() < MIN_AGREEING {
            return None;
        }
        pairs.sort_by_key(|&(ci, _)| {
            std::cmp::Reverse(clusters[ci].as_ref().map_or(0, |c| c.0.len()))
        });
        pairs.truncate(MAX_PARTS);
        let mut offset = Vec3::ZERO;
        let parts: Vec<JointPart> = pairs
            .iter()
            .filter_map(|&(ci, ti)| {
                let (points, _) = clusters[ci].as_ref()?;
                offset += centroids[ti] - moved[ci]?;
                let stride = points.len().div_ceil(POINTS_PER_PART).max(1);
                Some(JointPart {
                    levels: objects[ti].icp_levels(config),
                    object_from_world: objects[ti].predicted_world_from_object(now).inverse(),
                    points_in_world: points.iter().step_by(stride).copied().collect(),
                })
            })
            .collect();
        let shares = joint_shares(&parts, &guess);
        Some(Self {
            guess,
            offset: offset / pairs.len() as f32,
            pairs,
            parts,
            shares,
        })
    }

    /// Whether the guess as it is lands most clusters (more than half) on their models:
    /// keeping a correction needs less evidence than changing it, and the others moved on
    /// their own (refined, the joint alignment would find a compromise that a hand moving one
    /// of three objects 1 cm made a 1.7° turn of the camera).
    fn fits(&self) -> bool {
        let fitting = self.shares.iter().filter(|&&s| s >= FITS_SHARE).count();
        2 * fitting > self.shares.len()
    }

    fn mean_share(&self) -> f32 {
        self.shares.iter().sum::<f32>() / self.shares.len().max(1) as f32
    }

    /// The mean centroid of the objects of parts `which`.
    fn centre(&self, which: &[usize], centroids: &[Vec3]) -> Vec3 {
        which
            .iter()
            .map(|&i| centroids[self.pairs[i].1])
            .sum::<Vec3>()
            / which.len().max(1) as f32
    }

    /// The guess as it is, if it fits.
    fn standing_as_is(&self, centroids: &[Vec3]) -> Option<Standing> {
        self.fits().then(|| {
            let all: Vec<usize> = (0..self.parts.len()).collect();
            Standing {
                correction: self.guess,
                agreeing: all.len(),
                centre: self.centre(&all, centroids),
            }
        })
    }

    /// The joint alignment from the guess, and from the guess shifted by the centroids'
    /// offset (the better of the two), then the vote: it stands if at least
    /// [`MIN_AGREEING`] parts and half of them agree, refitted on the agreeing ones.
    fn refine(self, centroids: &[Vec3], config: &TrackConfig) -> Option<Standing> {
        let settings = config.icp_settings();
        let shifted = Affine3A::from_translation(self.offset) * self.guess;
        let total = |j: &JointAlignment| j.shares.iter().sum::<f32>();
        let joint = [self.guess, shifted]
            .into_iter()
            .filter_map(|start| align_jointly(&self.parts, start, &settings).ok())
            .max_by(|a, b| total(a).total_cmp(&total(b)))?;
        tracing::trace!(shares = ?joint.shares, "camera correction: refined");
        let agreeing: Vec<usize> = (0..self.parts.len())
            .filter(|&i| joint.shares[i] >= AGREE_SHARE)
            .collect();
        if agreeing.len() < MIN_AGREEING || 2 * agreeing.len() < self.parts.len() {
            return None;
        }
        let centre = self.centre(&agreeing, centroids);
        let correction = if agreeing.len() < self.parts.len() {
            let parts: Vec<JointPart> = self
                .parts
                .into_iter()
                .enumerate()
                .filter(|(i, _)| agreeing.contains(i))
                .map(|(_, p)| p)
                .collect();
            let refit = align_jointly(&parts, joint.corrected_from_world, &settings).ok()?;
            if refit.shares.iter().any(|&s| s < AGREE_SHARE) {
                return None;
            }
            refit.corrected_from_world
        } else {
            joint.corrected_from_world
        };
        Some(Standing {
            correction,
            agreeing: agreeing.len(),
            centre,
        })
    }
}

/// Step 3 of the module doc: the rigid motion (after `start`) that brings the most cluster
/// centroids within [`RANSAC_INLIER_M`] of an object's, if it brings at least
/// [`RANSAC_MIN_INLIERS`]. Deterministic: the same frame gives the same guess.
fn centroid_ransac(
    start: Affine3A,
    clusters: &[Option<Cluster>],
    centroids: &[Vec3],
) -> Option<Affine3A> {
    let from: Vec<Vec3> = clusters
        .iter()
        .flatten()
        .map(|(_, c)| start.transform_point3(*c))
        .collect();
    let pairs: Vec<(usize, usize)> = from
        .iter()
        .enumerate()
        .flat_map(|(ci, c)| {
            centroids
                .iter()
                .enumerate()
                .filter(move |(_, o)| c.distance(**o) <= RANSAC_REACH_M)
                .map(move |(oi, _)| (ci, oi))
        })
        .collect();
    if pairs.len() < RANSAC_MIN_INLIERS {
        return None;
    }
    // Guided rather than blind sampling: a triple is right only if all three pairs are, and
    // with ten objects in reach of each cluster a blind draw is right once in a thousand. Each
    // seed pair keeps only the pairs whose distance to it the motion would keep (and no
    // cluster or object twice); the triple's other two are drawn from those and checked
    // against each other.
    let consistent = |p: (usize, usize), q: (usize, usize)| {
        p.0 != q.0
            && p.1 != q.1
            && (from[p.0].distance(from[q.0]) - centroids[p.1].distance(centroids[q.1])).abs()
                <= RANSAC_INLIER_M
    };
    let mut best: Option<(usize, Affine3A)> = None;
    let seed_stride = pairs.len().div_ceil(RANSAC_SEEDS).max(1);
    for &seed in pairs.iter().step_by(seed_stride) {
        let around: Vec<(usize, usize)> = pairs
            .iter()
            .copied()
            .filter(|&q| consistent(seed, q))
            .collect();
        let mut tried = 0;
        'seed: for (i, &second) in around.iter().enumerate() {
            for &third in &around[i + 1..] {
                if !consistent(second, third) {
                    continue;
                }
                tried += 1;
                if tried > RANSAC_TRIPLES_PER_SEED {
                    break 'seed;
                }
                let triple = [seed, second, third];
                let a = triple.map(|(ci, _)| from[ci]);
                let b = triple.map(|(_, oi)| centroids[oi]);
                let Some(motion) = triad(a, b) else { continue };
                let inliers = count_inliers(&motion, &from, centroids);
                if inliers >= RANSAC_MIN_INLIERS && best.is_none_or(|(n, _)| inliers > n) {
                    best = Some((inliers, motion));
                }
            }
        }
    }
    best.map(|(_, motion)| motion * start)
}

/// Clusters whose centroid `motion` brings within [`RANSAC_INLIER_M`] of some object's, each
/// object counted once.
fn count_inliers(motion: &Affine3A, from: &[Vec3], centroids: &[Vec3]) -> usize {
    let moved: Vec<Option<Vec3>> = from
        .iter()
        .map(|c| Some(motion.transform_point3(*c)))
        .collect();
    associate_greedy(&moved, centroids, RANSAC_INLIER_M).len()
}

/// The rigid motion taking triangle `a` onto triangle `b`, from the orthonormal frame each
/// spans (first side, normal, their cross product) and their centroids; `None` for a
/// triangle too thin to span a frame. The minimal solver of the RANSAC: the joint alignment
/// refines what it gives.
fn triad(a: [Vec3; 3], b: [Vec3; 3]) -> Option<Affine3A> {
    let frame = |t: [Vec3; 3]| -> Option<Mat3> {
        let x = (t[1] - t[0]).try_normalize()?;
        let z = x.cross(t[2] - t[0]);
        // |z| is the third corner's distance from the first side's line: under 5 mm (a
        // centroid's noise) the normal is noise.
        if z.length() < 0.005 {
            return None;
        }
        let z = z.normalize();
        Some(Mat3::from_cols(x, z.cross(x), z))
    };
    let rotation = frame(b)? * frame(a)?.transpose();
    let centre_a = (a[0] + a[1] + a[2]) / 3.0;
    let centre_b = (b[0] + b[1] + b[2]) / 3.0;
    Some(Affine3A::from_mat3_translation(
        rotation,
        centre_b - rotation * centre_a,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_triad_recovers_a_rigid_motion() {
        let motion = Affine3A::from_rotation_translation(
            Quat::from_rotation_y(0.26) * Quat::from_rotation_x(-0.1),
            Vec3::new(0.07, -0.02, 0.03),
        );
        let a = [
            Vec3::new(-0.3, 0.1, 1.2),
            Vec3::new(0.2, 0.0, 1.5),
            Vec3::new(0.0, -0.2, 2.0),
        ];
        let b = a.map(|p| motion.transform_point3(p));
        let found = triad(a, b).expect("a triangle");
        for p in [Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0)] {
            assert!(
                found
                    .transform_point3(p)
                    .distance(motion.transform_point3(p))
                    < 1e-4
            );
        }
        let thin = [a[0], a[1], (a[0] + a[1]) * 0.5];
        assert!(triad(thin, thin).is_none());
    }

    #[test]
    fn ransac_finds_the_motion_that_moves_most_centroids_together() {
        let motion = Affine3A::from_rotation_translation(
            Quat::from_rotation_y(-15f32.to_radians()),
            Vec3::new(0.07, 0.0, 0.03),
        );
        let objects: Vec<Vec3> = (0..8)
            .map(|i| {
                let i = i as f32;
                Vec3::new(
                    -0.6 + 0.17 * i,
                    0.1 * (i * 1.7).sin(),
                    1.2 + 0.1 * (i * 2.3).cos(),
                )
            })
            .collect();
        // The frame's clusters: every object seen through the inverse motion, and two
        // clusters no object explains.
        let mut clusters: Vec<Option<Cluster>> = objects
            .iter()
            .map(|o| Some((Vec::new(), motion.inverse().transform_point3(*o))))
            .collect();
        clusters.push(Some((Vec::new(), Vec3::new(0.0, 0.5, 1.0))));
        clusters.push(None);
        let found = centroid_ransac(Affine3A::IDENTITY, &clusters, &objects).expect("found");
        for o in &objects {
            let c = motion.inverse().transform_point3(*o);
            assert!(found.transform_point3(c).distance(*o) < 1e-3);
        }
    }
}
