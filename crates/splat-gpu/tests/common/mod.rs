//! Shared helpers of the GPU test binaries.
#![allow(dead_code)]

use splat_core::{Camera, Scene};
use splat_gpu::GpuContext;
use std::sync::OnceLock;

/// The shared context; `None` (with the reason printed) when there is no adapter, except under
/// `CI=true`, where a missing adapter fails the test.
pub fn context() -> Option<&'static GpuContext> {
    static CTX: OnceLock<Result<GpuContext, String>> = OnceLock::new();
    match CTX.get_or_init(|| GpuContext::new().map_err(|e| e.to_string())) {
        Ok(ctx) => Some(ctx),
        Err(e) => {
            assert!(std::env::var("CI").is_err(), "CI=true and no GPU adapter: {e}");
            eprintln!("skipping GPU test: {e}");
            None
        }
    }
}

pub fn fixture(name: &str, width: u32, height: u32) -> (Scene, Camera) {
    let (scene, camera) = splat_core::scenes::by_name(name).unwrap();
    (scene, camera.rescaled(width, height).unwrap())
}

/// Read an antimatter15 `.splat` (32-byte records) without depending on splat-io, which sits
/// above this crate: position, scale, RGBA8, quaternion bytes (w, x, y, z).
pub fn splat_io_free_load(path: &std::path::Path) -> Scene {
    let bytes = std::fs::read(path).unwrap();
    let f = |r: &[u8], i: usize| f32::from_le_bytes([r[4 * i], r[4 * i + 1], r[4 * i + 2], r[4 * i + 3]]);
    let particles = bytes
        .chunks_exact(32)
        .map(|r| {
            let q: Vec<f32> = r[28..32].iter().map(|&b| (f32::from(b) - 128.0) / 128.0).collect();
            let rgb = glam::Vec3::new(f32::from(r[24]), f32::from(r[25]), f32::from(r[26])) / 255.0;
            splat_core::Particle::with_rgb(
                glam::Vec3::new(f(r, 0), f(r, 1), f(r, 2)),
                glam::Vec3::new(f(r, 3), f(r, 4), f(r, 5)),
                glam::Quat::from_xyzw(q[1], q[2], q[3], q[0]).normalize(),
                f32::from(r[27]) / 255.0,
                rgb,
            )
        })
        .collect();
    Scene { particles, sh_degree: 0 }
}
