//! Injected sensor faults: the simulated camera can misbehave like real hardware on a script,
//! so that the daemon's supervision (bad frames counted and skipped, a lost device reopened,
//! the last meshes kept) is tested end to end without a flaky USB cable.
//!
//! Entry points: [`Fault`] (a [`FaultKind`] over a window of frame indices), given to the camera
//! with [`SimulatedDepthCamera::set_faults`](crate::SimulatedDepthCamera::set_faults) or by a
//! scene file's `[[fault]]` tables (documented in `scenes/demo.toml`); [`check_faults`].
//!
//! Faults are keyed by the camera's frame index (the k-th frame it delivers, from 0), not by
//! wall-clock time, so a run is reproducible at any pace. A camera that is rebuilt (the daemon
//! reopens a disconnected source from its spec) starts again at frame 0 and so replays its
//! faults: a disconnect at frame 240 recurs every 240 frames plus the reopen backoff.

use std::ops::Range;

/// What goes wrong.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// The read fails with [`SourceError::Malformed`](tacmesh_source::SourceError::Malformed)
    /// (a corrupt transfer): the frame is lost, the device stays open.
    Error,
    /// The read fails with
    /// [`SourceError::Disconnected`](tacmesh_source::SourceError::Disconnected): the device is
    /// gone until it is reopened.
    Disconnect,
    /// A frame whose depth buffer has half the pixels its intrinsics say.
    WrongSize,
    /// A frame of all zeros (no return anywhere: a covered lens).
    Zeros,
    /// A frame of all NaN.
    Nan,
    /// A frame with a zero horizontal and a NaN vertical focal length (a corrupt calibration);
    /// the depth buffer is the true image.
    AbsurdIntrinsics,
    /// The read of the window's first frame blocks for as long as the window's frames would
    /// take at `fps` (a hung transfer), then the camera delivers the frame after the window:
    /// `frames = 300` at 30 fps hangs the source for ten seconds.
    Stall,
}

impl FaultKind {
    /// Every kind, in the order above.
    pub const ALL: [FaultKind; 7] = [
        FaultKind::Error,
        FaultKind::Disconnect,
        FaultKind::WrongSize,
        FaultKind::Zeros,
        FaultKind::Nan,
        FaultKind::AbsurdIntrinsics,
        FaultKind::Stall,
    ];

    /// The name scene files use (`kind = "wrong_size"`).
    pub fn name(self) -> &'static str {
        match self {
            FaultKind::Error => "error",
            FaultKind::Disconnect => "disconnect",
            FaultKind::WrongSize => "wrong_size",
            FaultKind::Zeros => "zeros",
            FaultKind::Nan => "nan",
            FaultKind::AbsurdIntrinsics => "absurd_intrinsics",
            FaultKind::Stall => "stall",
        }
    }

    pub fn from_name(name: &str) -> Option<FaultKind> {
        FaultKind::ALL.into_iter().find(|kind| kind.name() == name)
    }
}

/// A fault over frames `at_frame .. at_frame + frames` of one camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fault {
    pub kind: FaultKind,
    /// The first frame index affected.
    pub at_frame: u64,
    /// How many consecutive frames are affected, at least 1.
    pub frames: u64,
}

impl Fault {
    /// The frame indices affected.
    pub fn frames(&self) -> Range<u64> {
        self.at_frame..self.at_frame.saturating_add(self.frames)
    }
}

/// Checks that every fault covers at least one frame and that no two overlap (a frame has one
/// fault or none). On failure, says which faults by their index in `faults`.
pub fn check_faults(faults: &[Fault]) -> Result<(), String> {
    for (i, fault) in faults.iter().enumerate() {
        if fault.frames == 0 {
            return Err(format!(
                "fault {i} ({}) covers no frames: frames must be at least 1",
                fault.kind.name()
            ));
        }
        for (j, other) in faults.iter().enumerate().skip(i + 1) {
            let (a, b) = (fault.frames(), other.frames());
            if a.start < b.end && b.start < a.end {
                return Err(format!(
                    "faults {i} ({}, frames {a:?}) and {j} ({}, frames {b:?}) overlap: a frame \
                     has one fault at most",
                    fault.kind.name(),
                    other.kind.name()
                ));
            }
        }
    }
    Ok(())
}

/// The fault whose window holds frame `frame_index`, if any.
pub(crate) fn fault_at(faults: &[Fault], frame_index: u64) -> Option<&Fault> {
    faults
        .iter()
        .find(|fault| fault.frames().contains(&frame_index))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fault(kind: FaultKind, at_frame: u64, frames: u64) -> Fault {
        Fault {
            kind,
            at_frame,
            frames,
        }
    }

    #[test]
    fn fault_at_finds_the_window_of_a_frame() {
        let faults = [
            fault(FaultKind::Zeros, 2, 3),
            fault(FaultKind::Disconnect, 10, 1),
        ];
        let kinds: Vec<_> = (0..12)
            .map(|k| fault_at(&faults, k).map(|f| f.kind))
            .collect();
        let z = Some(FaultKind::Zeros);
        assert_eq!(
            kinds,
            [
                None,
                None,
                z,
                z,
                z,
                None,
                None,
                None,
                None,
                None,
                Some(FaultKind::Disconnect),
                None
            ]
        );
    }

    #[test]
    fn check_faults_refuses_empty_and_overlapping_windows() {
        assert!(check_faults(&[fault(FaultKind::Nan, 0, 1)]).is_ok());
        let empty = check_faults(&[fault(FaultKind::Nan, 5, 0)]).unwrap_err();
        assert!(empty.contains("at least 1"), "{empty}");
        let overlap = check_faults(&[
            fault(FaultKind::Nan, 5, 10),
            fault(FaultKind::Error, 0, 1),
            fault(FaultKind::Zeros, 14, 2),
        ])
        .unwrap_err();
        assert!(overlap.contains("faults 0 (nan") && overlap.contains("2 (zeros"));
    }

    #[test]
    fn kinds_round_trip_through_their_names() {
        for kind in FaultKind::ALL {
            assert_eq!(FaultKind::from_name(kind.name()), Some(kind));
        }
        assert_eq!(FaultKind::from_name("hang"), None);
    }
}
