//! The PCD reader over bytes held in memory: `tacmesh_formats::pcd::parse` (what `read_pcd` and
//! `read_cloud` call for a `.pcd` file), then `into_cloud` and `retain_finite` as `read_cloud`
//! does.
//!
//! Properties beyond "no panic": `width × height` points, and every per-point column (normals,
//! labels, colours) has one entry per point.

#![no_main]

use libfuzzer_sys::fuzz_target;
use tacmesh_formats::pcd;

fuzz_target!(|data: &[u8]| {
    let Ok(cloud) = pcd::parse(data, "fuzz.pcd") else {
        return;
    };
    let n = cloud.points.len();
    assert_eq!(n as u64, u64::from(cloud.width) * u64::from(cloud.height));
    assert!(cloud.normals.as_ref().is_none_or(|c| c.len() == n));
    assert!(cloud.labels.as_ref().is_none_or(|c| c.len() == n));
    assert!(cloud.rgba.as_ref().is_none_or(|c| c.len() == n));
    let mut points = cloud.into_cloud();
    points.retain_finite();
    assert!(points.points.iter().all(|p| p.is_finite()));
});
