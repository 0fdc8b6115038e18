//! The Embree peer: Sun et al. 2025 Algorithm 1 (`stochastic`), exact compositing (Eq. 3) and
//! the opaque closest-ellipsoid ray on Embree 3 user geometry, with one intersection callback
//! per particle, as Sun et al. ran their CPU numbers (§5). It is the baseline that
//! `cargo xtask bench` measures splat-core's CPU tracer against, in the same run.
//!
//! The peer makes splat-core's decisions: the same hit test (kernel degree 2, mean hit
//! distance, cutoff, clamp, cull), the same xxhash32/PCG keys per pixel, frame and particle, the
//! same tie-break by particle id, and the same bounding ellipsoid for the opaque ray, so the
//! same seed gives the same image; the `embree-peer` binary checks that beside every time. A peer that computed something else would be no
//! baseline.
//!
//! The C++ (`cpp/peer.cpp`) is compiled only where Embree 3's headers are installed (Debian:
//! `libembree-dev`); elsewhere [`EmbreePeer::build`] returns an error that says so.

use splat_core::hit::{HitDistance, PreparedParticle};
use splat_core::trace::bounding_radius;
use splat_core::{Camera, RenderSettings, Scene};

/// What the peer traces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PeerMethod {
    /// Closest entry into a cutoff ellipsoid (splat's `opaque`).
    Opaque = 0,
    /// Algorithm 1 (splat's `stochastic`).
    Stochastic = 1,
    /// Every hit, sorted, Eq. 3 (splat's `exact`).
    Exact = 2,
}

/// Floats per particle handed to the peer: mean, canonical transform (column-major), opacity,
/// padded box, squared radius of the bounding ellipsoid.
const PARTICLE_FLOATS: usize = 20;

/// The boxes Embree builds its BVH over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PeerBounds {
    /// The box of each particle's cutoff ellipsoid (Eq. 2), as Sun et al. bound particles.
    Cutoff,
    /// splat's boxes: each particle's visible extent
    /// ([`splat_core::trace::bounding_radius`]), so that both BVHs bound the same volumes.
    Splat,
}

/// An Embree scene over a splat scene.
pub struct EmbreePeer {
    #[cfg(embree)]
    handle: ffi::Handle,
}

impl EmbreePeer {
    /// Build the Embree BVH over the scene's particles on `threads` threads (what Embree calls
    /// the commit). Errors when Embree is not compiled in, or the settings ask for what the peer
    /// does not implement.
    pub fn build(scene: &Scene, settings: &RenderSettings, bounds: PeerBounds, threads: usize) -> Result<Self, String> {
        if settings.kernel.degree != 2 || settings.hit_distance != HitDistance::Mean {
            return Err("the Embree peer implements kernel degree 2 with the mean hit distance only".into());
        }
        let particles = pack_particles(scene, settings, bounds);
        let sh: Vec<f32> =
            scene.particles.iter().flat_map(|p| p.sh.to_array().into_iter().flat_map(|c| c.to_array())).collect();
        let k = &settings.kernel;
        let b = settings.background;
        let packed_settings = [k.cutoff, k.alpha_clamp, k.alpha_cull, settings.t_min, settings.t_max, b.x, b.y, b.z];
        Self::build_packed(&particles, &sh, &packed_settings, u32::from(scene.sh_degree), threads)
    }

    #[cfg(embree)]
    fn build_packed(
        particles: &[f32],
        sh: &[f32],
        settings: &[f32; 8],
        degree: u32,
        threads: usize,
    ) -> Result<Self, String> {
        let handle = ffi::Handle::build(particles, sh, settings, degree, threads as u32)
            .ok_or("Embree failed to build the scene (rtcGetDeviceError)")?;
        Ok(Self { handle })
    }

    #[cfg(not(embree))]
    fn build_packed(_: &[f32], _: &[f32], _: &[f32; 8], _: u32, _: usize) -> Result<Self, String> {
        Err(NOT_BUILT.into())
    }

    /// One frame of `method` through the pixel centres of `camera` (frame key as
    /// [`splat_core::rng::frame_key`]), on `threads` threads: RGB, row-major.
    pub fn render(&self, camera: &Camera, method: PeerMethod, frame_key: u32, threads: usize) -> Vec<f32> {
        let rays: Vec<f32> = (0..camera.height)
            .flat_map(|y| (0..camera.width).map(move |x| (x, y)))
            .flat_map(|(x, y)| {
                let r = camera.pixel_ray(x, y);
                [r.origin.x, r.origin.y, r.origin.z, r.dir.x, r.dir.y, r.dir.z]
            })
            .collect();
        self.render_rays(&rays, camera.width, camera.height, method, frame_key, threads)
    }

    #[cfg(embree)]
    fn render_rays(&self, rays: &[f32], w: u32, h: u32, method: PeerMethod, key: u32, threads: usize) -> Vec<f32> {
        self.handle.render(rays, w, h, method as u32, key, threads as u32)
    }

    #[cfg(not(embree))]
    fn render_rays(&self, _: &[f32], _: u32, _: u32, _: PeerMethod, _: u32, _: usize) -> Vec<f32> {
        unreachable!("an EmbreePeer cannot be built without Embree")
    }
}

/// Why the peer is absent from this build.
pub const NOT_BUILT: &str = "the Embree peer was not compiled: Embree 3's headers were not found \
     (/usr/include/embree3/rtcore.h; Debian: `apt-get install libembree-dev`, which `cargo xtask bench` \
     does as root); rebuild after installing";

/// How far two RGB images (row-major, 3 floats a pixel) are apart: the largest channel
/// difference, and the number of pixels with a channel more than 1e-4 apart (a different
/// decision, not float noise).
pub fn difference(a: &[f32], b: &[f32]) -> (f32, usize) {
    let max = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max);
    let apart =
        a.chunks(3).zip(b.chunks(3)).filter(|(p, q)| p.iter().zip(*q).any(|(x, y)| (x - y).abs() > 1e-4)).count();
    (max, apart)
}

/// Whether the C++ peer is compiled into this build.
pub const fn available() -> bool {
    cfg!(embree)
}

fn pack_particles(scene: &Scene, settings: &RenderSettings, bounds: PeerBounds) -> Vec<f32> {
    let mut out = Vec::with_capacity(scene.particles.len() * PARTICLE_FLOATS);
    for p in &scene.particles {
        let prepared = PreparedParticle::new(p);
        let radius = bounding_radius(settings, p.opacity);
        let b = match bounds {
            PeerBounds::Cutoff => p.aabb(settings.kernel.cutoff),
            PeerBounds::Splat => p.aabb(radius),
        }
        .padded();
        out.extend(prepared.mean.to_array());
        out.extend(prepared.canonical.to_cols_array());
        out.push(prepared.opacity);
        out.extend(b.min.to_array());
        out.extend(b.max.to_array());
        out.push(radius * radius);
    }
    out
}

/// The C ABI of `cpp/peer.cpp`, behind a safe handle.
#[cfg(embree)]
#[allow(unsafe_code)]
mod ffi {
    use std::ffi::c_void;
    use std::ptr::NonNull;

    unsafe extern "C" {
        fn splat_peer_build(
            particles: *const f32,
            sh: *const f32,
            n: u32,
            settings: *const f32,
            sh_degree: u32,
            threads: u32,
        ) -> *mut c_void;
        fn splat_peer_render(
            handle: *const c_void,
            method: u32,
            frame_key: u32,
            rays: *const f32,
            width: u32,
            height: u32,
            threads: u32,
            out: *mut f32,
        );
        fn splat_peer_free(handle: *mut c_void);
    }

    /// An owned Embree scene (device, scene and the copied particle arrays).
    pub struct Handle(NonNull<c_void>);

    impl Handle {
        pub fn build(particles: &[f32], sh: &[f32], settings: &[f32; 8], degree: u32, threads: u32) -> Option<Self> {
            let n = particles.len() / super::PARTICLE_FLOATS;
            assert_eq!(particles.len(), n * super::PARTICLE_FLOATS);
            assert_eq!(sh.len(), n * 48);
            let n = u32::try_from(n).ok()?;
            // SAFETY: the arrays hold n particles and n × 48 SH floats and 8 settings, as
            // `splat_peer_build` reads them; it copies them and returns an owned pointer or null.
            let raw =
                unsafe { splat_peer_build(particles.as_ptr(), sh.as_ptr(), n, settings.as_ptr(), degree, threads) };
            NonNull::new(raw).map(Self)
        }

        pub fn render(&self, rays: &[f32], width: u32, height: u32, method: u32, key: u32, threads: u32) -> Vec<f32> {
            let pixels = width as usize * height as usize;
            assert_eq!(rays.len(), 6 * pixels);
            assert!(method <= 2 && threads >= 1);
            let mut out = vec![0.0f32; 3 * pixels];
            // SAFETY: the handle is live; `rays` holds 6 floats and `out` 3 per pixel of the
            // width × height image, as `splat_peer_render` reads and writes them; it joins its
            // threads before returning.
            unsafe {
                splat_peer_render(self.0.as_ptr(), method, key, rays.as_ptr(), width, height, threads, out.as_mut_ptr())
            };
            out
        }
    }

    impl Drop for Handle {
        fn drop(&mut self) {
            // SAFETY: the pointer came from `splat_peer_build` and is freed once, here.
            unsafe { splat_peer_free(self.0.as_ptr()) }
        }
    }
}
