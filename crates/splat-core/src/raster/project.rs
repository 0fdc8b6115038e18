//! EWA splatting: each particle projected to a 2D Gaussian on the image (Zwicker et al. 2002,
//! as the 3DGS rasterizer does it), with view-dependent colour and frustum and alpha culling.

use super::{Response, SURFEL_LOW_PASS};
use crate::camera::Camera;
use crate::kernel::KernelParams;
use crate::particle::{Particle, Scene};
use crate::settings::RenderSettings;
use crate::sh;
use glam::{Mat3, Vec2, Vec3};

/// The `Sqrt8` extent reaches √8 σ: fragments whose Mahalanobis term A exceeds 8 are discarded.
pub const EXTENT_SQ: f32 = 8.0;
/// The `ThreeDgs` extent starts from a square of half-width ⌈3 √λ_max⌉ px around the centre
/// (λ_max the larger eigenvalue of Σ′), as the 3DGS rasterizer's `preprocessCUDA` computes its
/// radius.
pub const BOX_SIGMAS: f32 = 3.0;
/// 3DGS takes λ = mid ± √max(0.1, mid² − det): the floor under the discriminant.
pub const EIGEN_FLOOR: f32 = 0.1;
/// The side of the 3DGS rasterizer's tiles (`BLOCK_X`, `BLOCK_Y`), px: its footprint is made
/// of whole tiles.
pub const BLOCK: f32 = 16.0;

/// Which pixels a splat can touch; within it, the alpha cull (1/255) decides.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum SplatExtent {
    /// The reference 3DGS rasterizer (diff-gaussian-rasterization): every pixel of the 16 × 16
    /// tiles that the ⌈3 √λ_max⌉ box around the centre touches (`getRect`; `renderCUDA` tests
    /// no pixel against the box), so an opaque splat reaches past 3σ along its major axis
    /// wherever its tiles do and α ≥ 1/255. What trained captures were optimised with: the
    /// default. Cut to the visible radius ([`KernelParams::visible_radius`]), which changes no
    /// pixel centre's alpha and covers a sample of a multisampled pixel where it is visible.
    #[default]
    ThreeDgs = 0,
    /// The √8σ ellipse (A ≤ 8) of vk_gaussian_splatting and StochasticSplats' quads.
    Sqrt8 = 1,
    /// Every pixel whose alpha passes the cull: gsplat's footprint, whose opacity-aware bounds
    /// (`extend` = √(2 ln(o / (1/255))) standard deviations, and its tile–ellipse test) hold
    /// exactly those pixels.
    AlphaCull = 2,
}

impl SplatExtent {
    /// Every extent.
    pub const ALL: [SplatExtent; 3] = [SplatExtent::ThreeDgs, SplatExtent::Sqrt8, SplatExtent::AlphaCull];

    /// Its name on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            SplatExtent::ThreeDgs => "3dgs",
            SplatExtent::Sqrt8 => "sqrt8",
            SplatExtent::AlphaCull => "alpha-cull",
        }
    }

    /// The footprint in words.
    pub const fn describe(self) -> &'static str {
        match self {
            SplatExtent::ThreeDgs => "the 3DGS rasterizer's tiles around its ⌈3√λmax⌉ box",
            SplatExtent::Sqrt8 => "the √8σ ellipse of vk_gaussian_splatting and StochasticSplats",
            SplatExtent::AlphaCull => "every pixel above the 1/255 alpha cull, as gsplat",
        }
    }
}

/// The 3DGS rasterizer's near plane (`in_frustum`): particles whose centre is nearer along the
/// view axis are culled. The default of [`crate::RenderSettings::near`].
pub const NEAR: f32 = 0.2;
/// 3DGS clamps x/z and y/z of a centre to 1.3 × the image's half-extent before the Jacobian,
/// so that splats far outside the frustum do not get absurd footprints.
pub const FRUSTUM_GUARD: f32 = 1.3;

/// A particle projected to the image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Splat {
    /// Scene index of the particle (the splat id of the hashes).
    pub id: u32,
    /// Projected centre, pixels (pixel i covers [i, i + 1)).
    pub mean: Vec2,
    /// Inverse of the filtered 2D covariance Σ′ as (a, b, c): A = a dx² + 2 b dx dy + c dy².
    pub conic: Vec3,
    /// Depth of the centre: the billboard depth and the global sort key; view-space z through
    /// the pinhole, the distance from the camera through another lens.
    pub depth: f32,
    /// The splat's opacity: the particle's, times the screen filter's compensation ρ.
    pub opacity: f32,
    /// SH colour seen along the direction from the camera centre to the particle centre.
    pub color: Vec3,
    /// The largest Mahalanobis term A the footprint holds: 8 for the √8σ ellipse, else the
    /// visible radius² ([`KernelParams::visible_radius`]), beyond which the cull takes every
    /// alpha anyway.
    pub bound: f32,
    /// Pixel range [x0, x1) × [y0, y1) of the footprint, clipped to the image: the box of the
    /// bounding ellipse, within the 3DGS tiles for that extent.
    pub rect: [u32; 4],
}

impl Splat {
    /// The Mahalanobis term A = dᵀ Σ′⁻¹ d at continuous pixel position `p`.
    #[inline]
    pub fn mahalanobis(&self, p: Vec2) -> f32 {
        let d = p - self.mean;
        self.conic.x * d.x * d.x + 2.0 * self.conic.y * d.x * d.y + self.conic.z * d.y * d.y
    }

    /// Whether continuous pixel position `p` lies in the splat's footprint: in its rect and
    /// within its bounding ellipse.
    #[inline]
    pub fn covers(&self, p: Vec2) -> bool {
        let [x0, y0, x1, y1] = self.rect.map(|v| v as f32);
        p.x >= x0 && p.x < x1 && p.y >= y0 && p.y < y1 && self.mahalanobis(p) <= self.bound
    }

    /// alpha = opacity × response(A) at `p` (exp(−½A) for the degree-2 kernel), `None` outside
    /// the footprint or below the alpha cull; clamped like every particle alpha.
    #[inline]
    pub fn alpha(&self, p: Vec2, kernel: &KernelParams) -> Option<f32> {
        if !self.covers(p) {
            return None;
        }
        kernel.alpha(self.opacity, kernel.response(self.mahalanobis(p)))
    }
}

/// Project particle `index` of `scene` for `camera`; `None` when it is culled (behind the near
/// plane, outside the image, or unable to reach the alpha cull anywhere).
///
/// Σ₂ = J W Σ Wᵀ Jᵀ, with W the world-to-camera rotation and J the Jacobian of the
/// perspective projection at the centre t = (x, y, z): J = [[f_x/z, 0, −f_x x/z²],
/// [0, f_y/z, −f_y y/z²]]; then the scene's screen filter: Σ′ = Σ₂ + s I and the opacity
/// ρ o ([`crate::ScreenFilter`]; s = 0.3 px² and ρ = 1 for 3DGS).
///
/// Through any other lens ([`crate::camera::Lens`]) the mean and Σ₂ come from 3DGUT's
/// unscented transform instead ([`unscented`]), and the depth is the distance of the centre
/// from the camera.
///
/// With [`Response::AlongRay`] the projection only bounds the particle: its footprint is
/// every pixel of the 16 × 16 tiles around its visible region (the alpha-cull ellipse, or a
/// surfel's projected disc widened by 2DGS's low-pass) whatever `extent`, and its opacity its
/// own, uncompensated.
pub fn project(
    scene: &Scene,
    index: u32,
    camera: &Camera,
    settings: &RenderSettings,
    extent: SplatExtent,
    response: Response,
) -> Option<Splat> {
    let (p, kernel) = (&scene.particles[index as usize], &settings.kernel);
    // ρ ≤ 1, so a particle below the cull stays below it.
    if p.opacity < kernel.alpha_cull {
        return None;
    }
    let near = settings.near;
    let (mean, [a2, b2, c2], depth) =
        if camera.is_pinhole() { ewa(p, camera, near)? } else { unscented(p, camera, near)? };
    let ([a, b, c], rho) = scene.screen_filter.apply(a2, b2, c2);
    let det = a * c - b * b;
    if det.is_nan() || det <= 0.0 || !det.is_finite() {
        return None;
    }
    let opacity = match response {
        Response::Projected => rho * p.opacity,
        Response::AlongRay => p.opacity,
    };
    if opacity < kernel.alpha_cull {
        return None;
    }
    let conic = Vec3::new(c / det, -b / det, a / det);
    let (w, h) = (camera.width, camera.height);
    let r2 = kernel.visible_radius(opacity).powi(2);
    let (bound, rect) = match (response, extent) {
        (Response::AlongRay, _) => (f32::MAX, along_ray_tiles(p, mean, a, c, r2, camera)?),
        (Response::Projected, SplatExtent::ThreeDgs) => {
            // Within the tiles the alpha cull alone decides, and it takes every pixel beyond the
            // visible radius: cutting the footprint to it tests fewer pixels, keeps the same.
            let [x0, y0, x1, y1] = inria_tiles(mean, a, c, det, w, h)?;
            let [u0, v0, u1, v1] = ellipse_box(mean, a, c, r2, w, h)?;
            let rect = [x0.max(u0), y0.max(v0), x1.min(u1), y1.min(v1)];
            (r2, (rect[0] < rect[2] && rect[1] < rect[3]).then_some(rect)?)
        }
        (Response::Projected, SplatExtent::Sqrt8) => (EXTENT_SQ, ellipse_box(mean, a, c, EXTENT_SQ, w, h)?),
        (Response::Projected, SplatExtent::AlphaCull) => (r2, ellipse_box(mean, a, c, r2, w, h)?),
    };
    let dir = (p.mean - camera.center()).normalize_or_zero();
    let color = sh::eval_stored(p.sh.as_slice(), scene.sh_degree, dir, settings.sh_storage);
    Some(Splat { id: index, mean, conic, depth, opacity, color, bound, rect })
}

/// The pixels of the 3DGS rasterizer's footprint: its radius r = ⌈3 √λ_max⌉ with
/// λ_max = mid + √max(0.1, mid² − det), and the tiles `getRect` gives the box around the centre
/// p (in its pixel coordinates, where pixel i's centre is i: p = mean − ½),
/// [⌊(p − r) / 16⌋, ⌊(p + r + 15) / 16⌋) clamped to the grid; `None` when that is empty (the
/// rasterizer culls the splat).
fn inria_tiles(mean: Vec2, a: f32, c: f32, det: f32, w: u32, h: u32) -> Option<[u32; 4]> {
    let mid = 0.5 * (a + c);
    let lambda_max = mid + (mid * mid - det).max(EIGEN_FLOOR).sqrt();
    let r = (BOX_SIGMAS * lambda_max.sqrt()).ceil();
    let p = mean - Vec2::splat(0.5);
    let tiles = |p: f32, size: u32| -> (u32, u32) {
        let grid = size.div_ceil(BLOCK as u32) as f32;
        let lo = ((p - r) / BLOCK).floor().clamp(0.0, grid);
        let hi = ((p + r + BLOCK - 1.0) / BLOCK).floor().clamp(0.0, grid);
        ((lo * BLOCK) as u32, ((hi * BLOCK) as u32).min(size))
    };
    let ((x0, x1), (y0, y1)) = (tiles(p.x, w), tiles(p.y, h));
    (x0 < x1 && y0 < y1).then_some([x0, y0, x1, y1])
}

/// The footprint of a particle evaluated along rays ([`Response::AlongRay`]): every pixel of
/// the 16 × 16 tiles that the box of its visible region touches, within which the alpha alone
/// decides. A Gaussian's box is that of its projection's alpha-cull ellipse A ≤ `r2` on
/// Σ′ = [[a, ·], [·, c]] (3DGUT's tight opacity bounds on the 0.3 px²-dilated projection); a
/// surfel's is the box of its visible disc projected through the lens (as 2DGS bounds the exact
/// conic, here from 64 points of the rim), widened by 2DGS's low-pass.
fn along_ray_tiles(p: &Particle, mean: Vec2, a: f32, c: f32, r2: f32, camera: &Camera) -> Option<[u32; 4]> {
    let (lo, hi) = if p.is_surfel() {
        let low_pass = Vec2::splat((r2 * SURFEL_LOW_PASS).sqrt());
        let (lo, hi) = surfel_box(p, r2.sqrt(), camera);
        (lo - low_pass, hi + low_pass)
    } else {
        let half = Vec2::new((r2 * a).sqrt(), (r2 * c).sqrt());
        (mean - half, mean + half)
    };
    let size = Vec2::new(camera.width as f32, camera.height as f32);
    let lo = ((lo / BLOCK).floor() * BLOCK).max(Vec2::ZERO);
    let hi = ((hi / BLOCK).ceil() * BLOCK).min(size);
    (lo.x < hi.x && lo.y < hi.y).then_some([lo.x as u32, lo.y as u32, hi.x as u32, hi.y as u32])
}

/// The image box of a surfel's disc of `r` standard deviations: 64 points of its rim projected
/// through the camera's lens, padded by 1 % of the box and a pixel for the chords between them;
/// the whole image when a point has no projection (behind a perspective lens).
fn surfel_box(p: &Particle, r: f32, camera: &Camera) -> (Vec2, Vec2) {
    const RIM: usize = 64;
    let axes = glam::DMat3::from_quat(p.rotation.as_dquat());
    let (tu, tv) = (axes.x_axis * f64::from(p.scale.x * r), axes.y_axis * f64::from(p.scale.y * r));
    let (rotation, translation) = (camera.rotation.as_dmat3(), camera.translation.as_dvec3());
    let whole = (Vec2::ZERO, Vec2::new(camera.width as f32, camera.height as f32));
    let (mut lo, mut hi) = (Vec2::INFINITY, Vec2::NEG_INFINITY);
    for i in 0..RIM {
        let theta = std::f64::consts::TAU * i as f64 / RIM as f64;
        let x = p.mean.as_dvec3() + theta.cos() * tu + theta.sin() * tv;
        let Some(q) = camera.project(rotation * x + translation) else { return whole };
        (lo, hi) = (lo.min(q.as_vec2()), hi.max(q.as_vec2()));
    }
    let pad = 0.01 * (hi - lo) + Vec2::ONE;
    (lo - pad, hi + pad)
}

/// The pixels [x0, x1) × [y0, y1) around the ellipse A ≤ `bound` of Σ′ = [[a, b], [b, c]]
/// (half-widths √(bound a) and √(bound c)), clipped to the image; `None` when empty.
fn ellipse_box(mean: Vec2, a: f32, c: f32, bound: f32, w: u32, h: u32) -> Option<[u32; 4]> {
    let clip = |lo: f32, hi: f32, max: u32| -> Option<(u32, u32)> {
        let lo = lo.floor().max(0.0);
        let hi = hi.ceil().min(max as f32);
        (lo < hi).then_some((lo as u32, hi as u32))
    };
    let (rx, ry) = ((bound * a).sqrt(), (bound * c).sqrt());
    let (x0, x1) = clip(mean.x - rx, mean.x + rx, w)?;
    let (y0, y1) = clip(mean.y - ry, mean.y + ry, h)?;
    Some([x0, y0, x1, y1])
}

/// EWA through the pinhole: the projected centre, Σ₂ = J W Σ Wᵀ Jᵀ as (a, b, c) and the view
/// depth z; `None` behind the near plane `near`.
fn ewa(p: &Particle, camera: &Camera, near: f32) -> Option<(Vec2, [f32; 3], f32)> {
    let t = camera.to_camera(p.mean);
    if t.z.is_nan() || t.z <= near {
        return None;
    }
    let (w, h) = (camera.width as f32, camera.height as f32);
    let lim_x = FRUSTUM_GUARD * camera.cx.max(w - camera.cx) / camera.fx;
    let lim_y = FRUSTUM_GUARD * camera.cy.max(h - camera.cy) / camera.fy;
    let tx = (t.x / t.z).clamp(-lim_x, lim_x) * t.z;
    let ty = (t.y / t.z).clamp(-lim_y, lim_y) * t.z;
    let j = Mat3::from_cols(
        Vec3::new(camera.fx / t.z, 0.0, 0.0),
        Vec3::new(0.0, camera.fy / t.z, 0.0),
        Vec3::new(-camera.fx * tx / (t.z * t.z), -camera.fy * ty / (t.z * t.z), 0.0),
    );
    let jw = j * camera.rotation;
    let cov = jw * p.covariance() * jw.transpose();
    Some((camera.project_camera(t), [cov.x_axis.x, cov.y_axis.x, cov.y_axis.y], t.z))
}

/// 3DGUT's unscented-transform parameters (Wu et al. 2025; 3dgrut `configs/render/3dgut.yaml`):
/// α, β, κ for D = 3.
pub const UT_ALPHA: f64 = 1.0;
/// β (2: optimal for Gaussians).
pub const UT_BETA: f64 = 2.0;
/// κ.
pub const UT_KAPPA: f64 = 0.0;

/// The unscented transform of a particle through the camera's lens (3DGUT's
/// `unscentedParticleProjection`): the 2D + 1 sigma points μ and μ ± √(D + λ) s_i r_i (r_i the
/// columns of its rotation, λ = α² (D + κ) − D) projected by [`Camera::project`], their weighted
/// mean (weights λ / (D + λ) and 1 / (2 (D + λ))) and covariance (the centre's weight plus
/// 1 − α² + β), and the distance of the centre as depth. `None` nearer than the near plane or
/// when a sigma point falls where the lens sees nothing (behind a perspective lens), where 3DGUT
/// would still use the points it could project.
pub fn unscented(p: &Particle, camera: &Camera, near: f32) -> Option<(Vec2, [f32; 3], f32)> {
    let depth = camera.to_camera(p.mean).length();
    if depth.is_nan() || depth <= near {
        return None;
    }
    let d = 3.0;
    let lambda = UT_ALPHA * UT_ALPHA * (d + UT_KAPPA) - d;
    let delta = (d + lambda).sqrt();
    let axes = glam::DMat3::from_quat(p.rotation.as_dquat());
    let (rotation, translation) = (camera.rotation.as_dmat3(), camera.translation.as_dvec3());
    let project = |x: glam::DVec3| camera.project(rotation * x + translation);
    let mu = p.mean.as_dvec3();
    let mut points = vec![project(mu)?];
    for i in 0..3 {
        let step = delta * f64::from(p.scale[i]) * axes.col(i);
        points.push(project(mu + step)?);
        points.push(project(mu - step)?);
    }
    let (w0, wi) = (lambda / (d + lambda), 1.0 / (2.0 * (d + lambda)));
    let mean = w0 * points[0] + wi * points[1..].iter().sum::<glam::DVec2>();
    let outer = |q: glam::DVec2| {
        let e = q - mean;
        glam::DVec3::new(e.x * e.x, e.x * e.y, e.y * e.y)
    };
    let cov = (w0 + 1.0 - UT_ALPHA * UT_ALPHA + UT_BETA) * outer(points[0])
        + wi * points[1..].iter().map(|&q| outer(q)).sum::<glam::DVec3>();
    Some((mean.as_vec2(), cov.as_vec3().to_array(), depth))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ScreenFilter;
    use crate::filter::DILATION;
    use crate::particle::Particle;
    use approx::assert_relative_eq;
    use glam::Quat;

    fn camera() -> Camera {
        Camera::look_at(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, Vec3::Y, 50.0, 64, 48).unwrap()
    }

    /// An isotropic particle on the axis projects to a circle of σ′² = (f σ / z)² + 0.3 px².
    #[test]
    fn isotropic_particle_projects_to_the_expected_circle() {
        let cam = camera();
        let p = Particle::with_rgb(Vec3::ZERO, Vec3::splat(0.1), Quat::IDENTITY, 0.8, Vec3::ONE);
        let scene = Scene::new(vec![p], 0);
        let s = project(&scene, 0, &cam, &RenderSettings::default(), SplatExtent::Sqrt8, Response::Projected).unwrap();
        let sigma2 = (cam.fx * 0.1 / 4.0).powi(2) + DILATION;
        assert_relative_eq!(s.conic.x, 1.0 / sigma2, max_relative = 1e-4);
        assert_relative_eq!(s.conic.z, 1.0 / sigma2, max_relative = 1e-4);
        assert_relative_eq!(s.conic.y, 0.0, epsilon = 1e-7);
        assert_relative_eq!(s.mean.x, 32.0, epsilon = 1e-4);
        assert_relative_eq!(s.depth, 4.0, epsilon = 1e-5);
        // exp(−½A): at one σ′ from the centre the alpha is opacity × e^−½.
        let a = s.alpha(s.mean + Vec2::new(sigma2.sqrt(), 0.0), &KernelParams::default()).unwrap();
        assert_relative_eq!(a, 0.8 * (-0.5f32).exp(), max_relative = 1e-4);
        assert!(s.alpha(s.mean + Vec2::new(2.9 * sigma2.sqrt(), 0.0), &KernelParams::default()).is_none());
    }

    /// Each screen filter on a round splat of σ² px²: σ′² = σ² + s, and where the filter
    /// compensates, opacity × √(det Σ₂ / det Σ′) = σ² / (σ² + s).
    #[test]
    fn each_screen_filter_widens_and_compensates_as_its_trainer() {
        let cam = camera();
        let p = Particle::with_rgb(Vec3::ZERO, Vec3::splat(0.02), Quat::IDENTITY, 0.8, Vec3::ONE);
        let sigma2 = (cam.fx * 0.02 / 4.0).powi(2);
        for (filter, s, rho) in [
            (ScreenFilter::Dilation, 0.3, 1.0),
            (ScreenFilter::Antialiased, 0.3, sigma2 / (sigma2 + 0.3)),
            (ScreenFilter::Mip, 0.1, sigma2 / (sigma2 + 0.1)),
        ] {
            let scene = Scene { screen_filter: filter, ..Scene::new(vec![p.clone()], 0) };
            let splat =
                project(&scene, 0, &cam, &RenderSettings::default(), SplatExtent::ThreeDgs, Response::Projected)
                    .unwrap();
            assert_relative_eq!(splat.conic.x, 1.0 / (sigma2 + s), max_relative = 1e-4);
            assert_relative_eq!(splat.opacity, 0.8 * rho, max_relative = 1e-4);
        }
    }

    /// The 2D covariance matches the finite-difference Jacobian of the projection applied to
    /// Σ (the linearisation EWA makes), for an anisotropic, rotated, off-axis particle.
    #[test]
    fn covariance_matches_the_numerical_jacobian() {
        let cam = camera();
        let rot = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1);
        let p = Particle::with_rgb(Vec3::new(0.4, -0.3, 0.5), Vec3::new(0.2, 0.05, 0.1), rot, 0.5, Vec3::ONE);
        let scene = Scene::new(vec![p.clone()], 0);
        let s = project(&scene, 0, &cam, &RenderSettings::default(), SplatExtent::Sqrt8, Response::Projected).unwrap();
        let f = |x: Vec3| cam.project_camera(cam.to_camera(x));
        let eps = 1e-3;
        let cols: Vec<Vec2> = [Vec3::X, Vec3::Y, Vec3::Z]
            .iter()
            .map(|&e| (f(p.mean + eps * e) - f(p.mean - eps * e)) / (2.0 * eps))
            .collect();
        let sigma = p.covariance();
        let cov = |i: usize, k: usize| -> f32 {
            let g = |v: Vec2, i: usize| if i == 0 { v.x } else { v.y };
            (0..3).map(|r| (0..3).map(|q| g(cols[r], i) * sigma.col(q)[r] * g(cols[q], k)).sum::<f32>()).sum()
        };
        let (a, b, c) = (cov(0, 0) + DILATION, cov(0, 1), cov(1, 1) + DILATION);
        let det = a * c - b * b;
        assert_relative_eq!(s.conic.x, c / det, max_relative = 2e-3);
        assert_relative_eq!(s.conic.y, -b / det, max_relative = 2e-3, epsilon = 1e-4);
        assert_relative_eq!(s.conic.z, a / det, max_relative = 2e-3);
    }

    /// Behind the camera, outside the image or nearer than the near plane: culled; a particle
    /// 0.1 in front of the camera is culled at 3DGS's 0.2 and kept at gsplat's 0.01.
    #[test]
    fn particles_behind_outside_or_too_near_are_culled() {
        let cam = camera();
        let at = |m: Vec3| Particle::with_rgb(m, Vec3::splat(0.001), Quat::IDENTITY, 0.8, Vec3::ONE);
        let scene = Scene::new(
            vec![
                at(Vec3::new(0.0, 0.0, 5.0)),
                at(Vec3::new(30.0, 0.0, 0.0)),
                at(Vec3::ZERO),
                at(Vec3::new(0.0, 0.0, 3.9)),
            ],
            0,
        );
        let settings = RenderSettings::default();
        assert!(
            project(&scene, 0, &cam, &settings, SplatExtent::ThreeDgs, Response::Projected).is_none(),
            "behind the camera"
        );
        assert!(
            project(&scene, 1, &cam, &settings, SplatExtent::ThreeDgs, Response::Projected).is_none(),
            "outside the image"
        );
        assert!(project(&scene, 2, &cam, &settings, SplatExtent::ThreeDgs, Response::Projected).is_some());
        assert!(
            project(&scene, 3, &cam, &settings, SplatExtent::ThreeDgs, Response::Projected).is_none(),
            "nearer than 0.2"
        );
        let gsplat = RenderSettings { near: crate::trainer::GSPLAT_NEAR, ..settings };
        assert!(
            project(&scene, 3, &cam, &gsplat, SplatExtent::ThreeDgs, Response::Projected).is_some(),
            "farther than 0.01"
        );
    }

    /// The 3DGS footprint is whole 16 × 16 tiles: a pixel beyond the ⌈3 √λ_max⌉ box in a tile
    /// the box touches is covered (and visible while α ≥ 1/255), a pixel of the next tile is
    /// not, whatever its alpha. The controls, the box itself and the √8σ ellipse, are narrower.
    #[test]
    fn the_3dgs_footprint_is_the_tiles_its_box_touches() {
        let cam = Camera::look_at(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, Vec3::Y, 50.0, 128, 96).unwrap();
        let p = Particle::with_rgb(Vec3::ZERO, Vec3::splat(0.6), Quat::IDENTITY, 0.99, Vec3::ONE);
        let scene = Scene::new(vec![p], 0);
        let (settings, k) = (RenderSettings::default(), KernelParams::default());
        let s = project(&scene, 0, &cam, &settings, SplatExtent::ThreeDgs, Response::Projected).unwrap();
        let sigma = (1.0 / s.conic.x).sqrt();
        let r = (3.0 * sigma).ceil();
        // The fixture: centre (64, 48), r = 47; in 3DGS's coordinates p = 63.5, so the tiles
        // are ⌊(63.5 − 47) / 16⌋ = 1 to ⌊(63.5 + 47 + 15) / 16⌋ = 7 (exclusive), pixels [16, 112).
        assert_eq!((s.mean, r), (Vec2::new(64.0, 48.0), 47.0), "the fixture's geometry");
        assert_eq!(s.rect[0..3], [16, 0, 112]);
        let at = |x: f32| Vec2::new(x, s.mean.y + 0.5);
        for x in [111.5, 16.5] {
            assert!((at(x) - s.mean).abs().x > r, "{x} lies past the box");
            assert!(s.alpha(at(x), &k).is_some(), "{x}: in a tile the box touches, above the cull");
        }
        for x in [112.5, 15.5] {
            assert!(k.alpha(s.opacity, k.response(s.mahalanobis(at(x)))).is_some(), "{x}: above the cull");
            assert!(s.alpha(at(x), &k).is_none(), "{x}: a tile the box does not touch");
        }
        let sqrt8 = project(&scene, 0, &cam, &settings, SplatExtent::Sqrt8, Response::Projected).unwrap();
        assert!(sqrt8.alpha(at(111.5), &k).is_none(), "past √8σ");
    }

    /// The alpha-cull extent (gsplat) covers exactly the pixels whose alpha passes the cull:
    /// for opacities from faint to opaque, along both axes of a rotated anisotropic splat.
    #[test]
    fn the_alpha_cull_extent_is_where_alpha_passes() {
        let cam = Camera::look_at(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, Vec3::Y, 50.0, 128, 96).unwrap();
        let (settings, k) = (RenderSettings::default(), KernelParams::default());
        for opacity in [0.01, 0.05, 0.3, 0.99] {
            let rot = Quat::from_rotation_z(0.6);
            let p = Particle::with_rgb(Vec3::ZERO, Vec3::new(0.3, 0.1, 0.1), rot, opacity, Vec3::ONE);
            let scene = Scene::new(vec![p], 0);
            let s = project(&scene, 0, &cam, &settings, SplatExtent::AlphaCull, Response::Projected).unwrap();
            let mut covered = 0;
            for y in 0..96 {
                for x in 0..128 {
                    let q = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                    let passes = k.alpha(s.opacity, k.response(s.mahalanobis(q))).is_some();
                    assert_eq!(s.alpha(q, &k).is_some(), passes, "opacity {opacity} at {q}");
                    covered += usize::from(passes);
                }
            }
            assert!(covered > 10, "opacity {opacity}: {covered} pixels");
        }
    }
}
