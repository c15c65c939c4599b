//! Flooring to grid indices without a library call.
//!
//! Why by hand: on the baseline x86-64 target (no SSE4.1, so no rounding instruction) `f32::floor`
//! is a call to `floorf`, and every grid of the pipeline (voxels, range-image bins, fit cells,
//! segmentation cells) floors three coordinates of every point it keys; the call was 3 % of the
//! live daemon's CPU time. A truncating cast and one comparison give the same integer.

use glam::{IVec3, Vec3};

/// `x.floor() as i32`, saturating as that cast does (NaN to 0).
#[inline]
pub fn floor_i32(x: f32) -> i32 {
    let truncated = x as i32;
    // Truncation rounds negative non-integers up; beyond ±2^31 both saturate alike. Without a
    // branch: on a cloud around the origin the sign is a coin flip from point to point, and a
    // branch on it made voxel keying slower than the `floorf` call it replaces.
    truncated.saturating_sub(i32::from(x < truncated as f32))
}

/// `q.floor().as_ivec3()`: the integer cell of `q` in cell units.
#[inline]
pub fn floor_ivec3(q: Vec3) -> IVec3 {
    IVec3::new(floor_i32(q.x), floor_i32(q.y), floor_i32(q.z))
}

#[cfg(test)]
mod tests {
    use super::*;

    const VALUES: [f32; 20] = [
        0.0,
        -0.0,
        0.5,
        -0.5,
        1.0,
        -1.0,
        -1.5,
        2.999_999_8,
        -2.999_999_8,
        8_388_607.5,
        -8_388_607.5,
        2_147_483_520.0,
        -2_147_483_648.0,
        3e9,
        -3e9,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        f32::MIN_POSITIVE,
        -f32::MIN_POSITIVE,
    ];

    #[test]
    fn floor_i32_is_floor_then_a_saturating_cast() {
        for x in VALUES {
            assert_eq!(floor_i32(x), x.floor() as i32, "{x}");
        }
    }

    #[test]
    fn floor_ivec3_is_glams_floor_then_cast() {
        for (i, &x) in VALUES.iter().enumerate() {
            let q = Vec3::new(x, VALUES[(i + 7) % VALUES.len()], -x);
            assert_eq!(floor_ivec3(q), q.floor().as_ivec3(), "{q}");
        }
    }
}
