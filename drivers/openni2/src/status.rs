//! OpenNI2's `OniStatus` codes (`OniCEnums.h`), the crate's error type, and how both become a
//! [`SourceError`] the daemon understands.

use tacmesh_source::SourceError;

/// A non-OK `OniStatus`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OniStatus {
    /// `ONI_STATUS_ERROR` (1): a generic failure; the extended error says more.
    Error,
    /// `ONI_STATUS_NOT_IMPLEMENTED` (2).
    NotImplemented,
    /// `ONI_STATUS_NOT_SUPPORTED` (3).
    NotSupported,
    /// `ONI_STATUS_BAD_PARAMETER` (4).
    BadParameter,
    /// `ONI_STATUS_OUT_OF_FLOW` (5): a call in the wrong state (e.g. a stream not started).
    OutOfFlow,
    /// `ONI_STATUS_NO_DEVICE` (6).
    NoDevice,
    /// `ONI_STATUS_TIME_OUT` (102).
    TimeOut,
    /// A code this crate does not know.
    Unknown(i32),
}

impl OniStatus {
    /// `Ok(())` for `ONI_STATUS_OK` (0), the failure otherwise.
    pub fn check(code: i32) -> Result<(), OniStatus> {
        Err(match code {
            0 => return Ok(()),
            1 => Self::Error,
            2 => Self::NotImplemented,
            3 => Self::NotSupported,
            4 => Self::BadParameter,
            5 => Self::OutOfFlow,
            6 => Self::NoDevice,
            102 => Self::TimeOut,
            other => Self::Unknown(other),
        })
    }

    /// The C name of the code.
    pub fn c_name(self) -> &'static str {
        match self {
            Self::Error => "ONI_STATUS_ERROR",
            Self::NotImplemented => "ONI_STATUS_NOT_IMPLEMENTED",
            Self::NotSupported => "ONI_STATUS_NOT_SUPPORTED",
            Self::BadParameter => "ONI_STATUS_BAD_PARAMETER",
            Self::OutOfFlow => "ONI_STATUS_OUT_OF_FLOW",
            Self::NoDevice => "ONI_STATUS_NO_DEVICE",
            Self::TimeOut => "ONI_STATUS_TIME_OUT",
            Self::Unknown(_) => "unknown OniStatus",
        }
    }

    /// The numeric code.
    pub fn code(self) -> i32 {
        match self {
            Self::Error => 1,
            Self::NotImplemented => 2,
            Self::NotSupported => 3,
            Self::BadParameter => 4,
            Self::OutOfFlow => 5,
            Self::NoDevice => 6,
            Self::TimeOut => 102,
            Self::Unknown(code) => code,
        }
    }
}

impl std::fmt::Display for OniStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({})", self.c_name(), self.code())
    }
}

/// What went wrong talking to OpenNI2.
#[derive(Debug, thiserror::Error)]
pub enum OpenNi2Error {
    /// A C call returned a non-OK status; `detail` is `oniGetExtendedError()` read right after.
    #[error("{call} returned {status}{}", detail_suffix(.detail))]
    Call {
        call: &'static str,
        status: OniStatus,
        detail: String,
    },
    /// A frame whose fields do not describe its buffer.
    #[error("malformed OpenNI2 frame: {0}")]
    MalformedFrame(String),
    /// A depth pixel format other than DEPTH_1_MM (100) and DEPTH_100_UM (101), e.g. the
    /// shifted disparity formats 102/103, which this crate does not convert.
    #[error("unsupported depth pixel format {0}: choose a DEPTH_1_MM or DEPTH_100_UM video mode")]
    UnsupportedPixelFormat(i32),
    /// The device reports no usable field of view and no fallback was configured.
    #[error(
        "the device reports no field of view ({0}); set a fallback field of view in the options"
    )]
    NoFieldOfView(String),
    /// A URI OpenNI2 cannot be given (it contains a NUL byte).
    #[error("URI {0:?} contains a NUL byte")]
    BadUri(String),
}

fn detail_suffix(detail: &str) -> String {
    let detail = detail.trim();
    if detail.is_empty() {
        String::new()
    } else {
        format!(": {detail}")
    }
}

impl OpenNi2Error {
    /// The status of a failed C call, if this is one.
    pub fn status(&self) -> Option<OniStatus> {
        match self {
            Self::Call { status, .. } => Some(*status),
            _ => None,
        }
    }
}

/// Maps a failure while opening `device` (initialising, opening, creating or starting the
/// stream): whatever it was, the device is not usable, so [`SourceError::DeviceMissing`], with
/// a hint on what to check.
pub fn open_error(device: &str, error: OpenNi2Error) -> SourceError {
    let hint = match error.status() {
        Some(OniStatus::NoDevice) | Some(OniStatus::Error) => format!(
            "{error}; is the camera plugged in, and may this user open it (udev rules of \
             libopenni2-0, or of the vendor's OpenNI2 package)?"
        ),
        _ => error.to_string(),
    };
    SourceError::DeviceMissing {
        device: device.to_owned(),
        hint,
    }
}

/// Maps a failure while waiting for or reading a frame of `device`: a timeout or any failed
/// call means the device stopped delivering ([`SourceError::Disconnected`]); a frame that does
/// not describe its buffer is [`SourceError::Malformed`].
pub fn read_error(device: &str, error: OpenNi2Error, timeout_ms: u32) -> SourceError {
    let device = device.to_owned();
    match error {
        OpenNi2Error::Call {
            status: OniStatus::TimeOut,
            ..
        } => SourceError::Disconnected {
            device,
            reason: format!("no frame within {timeout_ms} ms; is the camera still plugged in?"),
        },
        OpenNi2Error::MalformedFrame(_)
        | OpenNi2Error::UnsupportedPixelFormat(_)
        | OpenNi2Error::NoFieldOfView(_) => SourceError::Malformed {
            device,
            reason: error.to_string(),
        },
        other => SourceError::Disconnected {
            device,
            reason: other.to_string(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn call(status: OniStatus, detail: &str) -> OpenNi2Error {
        OpenNi2Error::Call {
            call: "oniDeviceOpen",
            status,
            detail: detail.into(),
        }
    }

    #[test]
    fn status_check_maps_every_documented_code() {
        assert_eq!(OniStatus::check(0), Ok(()));
        let codes = [1, 2, 3, 4, 5, 6, 102];
        for code in codes {
            let status = OniStatus::check(code).unwrap_err();
            assert_eq!(status.code(), code);
            assert!(status.c_name().starts_with("ONI_STATUS_"), "{status}");
        }
        assert_eq!(OniStatus::check(6), Err(OniStatus::NoDevice));
        assert_eq!(OniStatus::check(102), Err(OniStatus::TimeOut));
        assert_eq!(OniStatus::check(-7), Err(OniStatus::Unknown(-7)));
    }

    #[test]
    fn call_error_message_carries_status_and_extended_error() {
        let msg = call(
            OniStatus::NoDevice,
            "\tDeviceOpen using default: no devices found\n",
        )
        .to_string();
        assert_eq!(
            msg,
            "oniDeviceOpen returned ONI_STATUS_NO_DEVICE (6): DeviceOpen using default: no devices found"
        );
        assert_eq!(
            call(OniStatus::Error, "  ").to_string(),
            "oniDeviceOpen returned ONI_STATUS_ERROR (1)"
        );
    }

    #[test]
    fn open_failure_is_device_missing_naming_the_uri() {
        let err = open_error(
            "openni2:Dummy",
            call(OniStatus::Error, "Could not open \"Dummy\""),
        );
        match err {
            SourceError::DeviceMissing { device, hint } => {
                assert_eq!(device, "openni2:Dummy");
                assert!(hint.contains("Could not open \"Dummy\""), "{hint}");
                assert!(hint.contains("plugged in"), "{hint}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn read_timeout_is_disconnected_with_the_timeout() {
        let err = read_error("openni2:x", call(OniStatus::TimeOut, ""), 2000);
        match err {
            SourceError::Disconnected { reason, .. } => {
                assert!(reason.contains("2000 ms"), "{reason}")
            }
            other => panic!("{other:?}"),
        }
        let err = read_error("openni2:x", call(OniStatus::Error, "stream stopped"), 2000);
        assert!(matches!(err, SourceError::Disconnected { .. }), "{err:?}");
    }

    #[test]
    fn malformed_frame_stays_malformed() {
        let err = read_error("openni2:x", OpenNi2Error::UnsupportedPixelFormat(102), 2000);
        assert!(matches!(err, SourceError::Malformed { .. }), "{err:?}");
    }
}
