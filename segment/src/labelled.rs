//! Scoring a segmentation against a scan's per-point labels, in the scheme of the labelled
//! mOSD scans (Richtsfeld et al.'s Object Segmentation Database as modified for PCL): label 0
//! for no reading, 1–9 for the table, and `10 k + j` for the `j`-th visible piece of the
//! `k`-th object (k ≥ 2). An object cut in two by an occluder is one object of two pieces:
//! it is scored as one, so a segmentation must join the pieces to score fully.
//!
//! The measure is the per-object IoU of the issue-41 evaluation: each labelled object's points
//! against the segment that overlaps them best (intersection over union of point sets). Beside
//! it, the segments that hold more than one object (merged) and the objects spread over more
//! than one segment (split), which say why an IoU is low.
//!
//! Entry points: [`score`], [`MosdKind::of_scan`].

use rustc_hash::FxHashMap;

/// The kind of scene a mOSD scan shows, from its name (`learnN` or `testN`, with any prefix),
/// by the dataset's README.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MosdKind {
    Boxes,
    Stacked,
    Occluded,
    Cylinders,
    Mixed,
    Complex,
}

impl MosdKind {
    /// Every kind, in the README's order.
    pub const ALL: [MosdKind; 6] = [
        MosdKind::Boxes,
        MosdKind::Stacked,
        MosdKind::Occluded,
        MosdKind::Cylinders,
        MosdKind::Mixed,
        MosdKind::Complex,
    ];

    /// The kind of the scan named `name` (a file stem such as `learn17` or `osd_test57`), or
    /// `None` for a name that is neither set's.
    pub fn of_scan(name: &str) -> Option<MosdKind> {
        let digits_at = name.rfind(|c: char| !c.is_ascii_digit())? + 1;
        let number: u32 = name[digits_at..].parse().ok()?;
        let stem = &name[..digits_at];
        if stem.ends_with("learn") {
            Some(match number {
                0..=16 => MosdKind::Boxes,
                17..=24 => MosdKind::Stacked,
                25..=32 => MosdKind::Occluded,
                33..=44 => MosdKind::Cylinders,
                _ => return None,
            })
        } else if stem.ends_with("test") {
            Some(match number {
                0..=15 => MosdKind::Boxes,
                16..=23 => MosdKind::Stacked,
                24..=30 => MosdKind::Occluded,
                31..=42 => MosdKind::Cylinders,
                43..=54 => MosdKind::Mixed,
                55..=65 => MosdKind::Complex,
                _ => return None,
            })
        } else {
            None
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            MosdKind::Boxes => "boxes",
            MosdKind::Stacked => "stacked",
            MosdKind::Occluded => "occluded",
            MosdKind::Cylinders => "cylinders",
            MosdKind::Mixed => "mixed",
            MosdKind::Complex => "complex",
        }
    }
}

/// How one labelled object scores.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectScore {
    /// The object's number (`label / 10`).
    pub object: u32,
    /// Its labelled points.
    pub points: usize,
    /// IoU with the segment that overlaps it best.
    pub iou: f64,
    /// Segments holding at least a fifth of its points: more than one is a split object.
    pub pieces: usize,
    /// Its best segment holds at least half of another labelled object too.
    pub merged: bool,
}

/// How one segmentation of one labelled scan scores.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanScore {
    /// Each labelled object, by object number.
    pub objects: Vec<ObjectScore>,
    /// Segments predicted (distinct non-zero predicted labels).
    pub segments: usize,
    /// Segments of which no labelled object is the larger part: table, background or noise
    /// published as an object.
    pub spurious: usize,
}

impl ScanScore {
    /// The mean IoU of the scan's objects (0 for a scan without objects).
    pub fn mean_iou(&self) -> f64 {
        if self.objects.is_empty() {
            return 0.0;
        }
        self.objects.iter().map(|o| o.iou).sum::<f64>() / self.objects.len() as f64
    }
}

/// Scores `predicted` (one label per point, 0 for no object, `k` for the `k`-th segment)
/// against `truth` (mOSD labels, one per point). Points beyond the shorter of the two are not
/// looked at.
pub fn score(truth: &[u32], predicted: &[u32]) -> ScanScore {
    let mut object_sizes: FxHashMap<u32, usize> = FxHashMap::default();
    let mut segment_sizes: FxHashMap<u32, usize> = FxHashMap::default();
    let mut overlaps: FxHashMap<(u32, u32), usize> = FxHashMap::default();
    for (&t, &p) in truth.iter().zip(predicted) {
        if p > 0 {
            *segment_sizes.entry(p).or_default() += 1;
        }
        if t >= 20 {
            *object_sizes.entry(t / 10).or_default() += 1;
            if p > 0 {
                *overlaps.entry((t / 10, p)).or_default() += 1;
            }
        }
    }
    // Per object, each segment's overlap; per segment, the objects it holds half of.
    let mut by_object: FxHashMap<u32, Vec<(u32, usize)>> = FxHashMap::default();
    let mut holds_half: FxHashMap<u32, usize> = FxHashMap::default();
    let mut largest_part: FxHashMap<u32, usize> = FxHashMap::default();
    for (&(object, segment), &n) in &overlaps {
        by_object.entry(object).or_default().push((segment, n));
        if 2 * n >= object_sizes[&object] {
            *holds_half.entry(segment).or_default() += 1;
        }
        let part = largest_part.entry(segment).or_default();
        *part = (*part).max(n);
    }
    let mut ids: Vec<u32> = object_sizes.keys().copied().collect();
    ids.sort_unstable();
    let objects = ids
        .into_iter()
        .map(|object| {
            let size = object_sizes[&object];
            let parts = by_object.remove(&object).unwrap_or_default();
            let best = parts
                .iter()
                .map(|&(segment, n)| {
                    let union = size + segment_sizes[&segment] - n;
                    (n as f64 / union.max(1) as f64, segment)
                })
                .max_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)));
            ObjectScore {
                object,
                points: size,
                iou: best.map_or(0.0, |(iou, _)| iou),
                pieces: parts.iter().filter(|&&(_, n)| 5 * n >= size).count(),
                merged: best
                    .is_some_and(|(_, segment)| holds_half.get(&segment).copied().unwrap_or(0) > 1),
            }
        })
        .collect();
    let spurious = segment_sizes
        .iter()
        .filter(|&(segment, &size)| 2 * largest_part.get(segment).copied().unwrap_or(0) < size)
        .count();
    ScanScore {
        objects,
        segments: segment_sizes.len(),
        spurious,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_follow_the_readme() {
        assert_eq!(MosdKind::of_scan("learn0"), Some(MosdKind::Boxes));
        assert_eq!(MosdKind::of_scan("learn24"), Some(MosdKind::Stacked));
        assert_eq!(MosdKind::of_scan("learn44"), Some(MosdKind::Cylinders));
        assert_eq!(MosdKind::of_scan("learn45"), None);
        assert_eq!(MosdKind::of_scan("osd_test26"), Some(MosdKind::Occluded));
        assert_eq!(MosdKind::of_scan("test57"), Some(MosdKind::Complex));
        assert_eq!(MosdKind::of_scan("test"), None);
        assert_eq!(MosdKind::of_scan("bunny3"), None);
    }

    #[test]
    fn a_perfect_segmentation_scores_one_and_pieces_count_as_one_object() {
        // Table, object 2 in two pieces (20, 21), object 3.
        let truth = [1, 1, 20, 20, 21, 21, 30, 30, 0];
        let predicted = [0, 0, 1, 1, 1, 1, 2, 2, 0];
        let score = score(&truth, &predicted);
        assert_eq!(score.objects.len(), 2);
        assert!(score.objects.iter().all(|o| o.iou == 1.0 && o.pieces == 1));
        assert_eq!((score.segments, score.spurious), (2, 0));
    }

    #[test]
    fn split_merged_and_spurious_segments_are_named() {
        let truth = [1, 1, 1, 20, 20, 20, 20, 30, 30, 30, 30];
        // Object 2 split in halves; object 3 merged with half of object 2; the table's
        // points a segment of their own.
        let predicted = [3, 3, 3, 1, 1, 2, 2, 2, 2, 2, 2];
        let score = score(&truth, &predicted);
        let two = &score.objects[0];
        assert_eq!((two.pieces, two.iou), (2, 0.5));
        let three = &score.objects[1];
        assert!(three.merged);
        assert!((three.iou - 4.0 / 6.0).abs() < 1e-12);
        assert_eq!((score.segments, score.spurious), (3, 1));
    }
}
