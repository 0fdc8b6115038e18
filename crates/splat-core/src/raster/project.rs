//! EWA splatting: each particle projected to a 2D Gaussian on the image (Zwicker et al. 2002,
//! as the 3DGS rasterizer does it), with view-dependent colour and frustum and alpha culling.

use crate::camera::Camera;
use crate::kernel::KernelParams;
use crate::particle::Scene;
use crate::sh;
use glam::{Mat3, Vec2, Vec3};

/// The `Sqrt8` extent reaches √8 σ: fragments whose Mahalanobis term A exceeds 8 are discarded.
pub const EXTENT_SQ: f32 = 8.0;
/// The `ThreeDgs` extent is a square of half-width ⌈3 √λ_max⌉ px around the centre (λ_max the
/// larger eigenvalue of Σ′), as the 3DGS rasterizer's `preprocessCUDA` computes its radius.
pub const BOX_SIGMAS: f32 = 3.0;
/// 3DGS takes λ = mid ± √max(0.1, mid² − det): the floor under the discriminant.
pub const EIGEN_FLOOR: f32 = 0.1;

/// Which pixels a splat can touch; within it, the alpha cull (1/255) decides.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum SplatExtent {
    /// The reference 3DGS rasterizer (diff-gaussian-rasterization): every pixel within the
    /// ⌈3 √λ_max⌉ box, so an opaque splat reaches 3.33σ along its minor axis where α ≥ 1/255.
    /// What trained captures were optimised with: the default.
    #[default]
    ThreeDgs = 0,
    /// The √8σ ellipse (A ≤ 8) of vk_gaussian_splatting and StochasticSplats' quads.
    Sqrt8 = 1,
}
/// Particles whose centre is nearer than this along the view axis are culled (3DGS).
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
    /// Half-width ⌈3 √λ_max⌉ of the 3DGS box, px.
    pub radius: f32,
    /// The footprint: the 3DGS box or the √8σ ellipse.
    pub extent: SplatExtent,
    /// Pixel range [x0, x1) × [y0, y1) of the footprint, clipped to the image.
    pub rect: [u32; 4],
}

impl Splat {
    /// The Mahalanobis term A = dᵀ Σ′⁻¹ d at continuous pixel position `p`.
    #[inline]
    pub fn mahalanobis(&self, p: Vec2) -> f32 {
        let d = p - self.mean;
        self.conic.x * d.x * d.x + 2.0 * self.conic.y * d.x * d.y + self.conic.z * d.y * d.y
    }

    /// Whether continuous pixel position `p` lies in the splat's footprint.
    #[inline]
    pub fn covers(&self, p: Vec2) -> bool {
        match self.extent {
            SplatExtent::ThreeDgs => {
                let d = (p - self.mean).abs();
                d.x <= self.radius && d.y <= self.radius
            }
            SplatExtent::Sqrt8 => self.mahalanobis(p) <= EXTENT_SQ,
        }
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
pub fn project(
    scene: &Scene,
    index: u32,
    camera: &Camera,
    kernel: &KernelParams,
    extent: SplatExtent,
) -> Option<Splat> {
    let p = &scene.particles[index as usize];
    // ρ ≤ 1, so a particle below the cull stays below it.
    if p.opacity < kernel.alpha_cull {
        return None;
    }
    let (mean, [a2, b2, c2], depth) = if camera.is_pinhole() { ewa(p, camera)? } else { unscented(p, camera)? };
    let (w, h) = (camera.width as f32, camera.height as f32);
    let ([a, b, c], rho) = scene.screen_filter.apply(a2, b2, c2);
    let det = a * c - b * b;
    if det.is_nan() || det <= 0.0 || !det.is_finite() {
        return None;
    }
    let opacity = rho * p.opacity;
    if opacity < kernel.alpha_cull {
        return None;
    }
    let conic = Vec3::new(c / det, -b / det, a / det);
    let mid = 0.5 * (a + c);
    let lambda_max = mid + (mid * mid - det).max(EIGEN_FLOOR).sqrt();
    let radius = (BOX_SIGMAS * lambda_max.sqrt()).ceil();
    let (rx, ry) = match extent {
        SplatExtent::ThreeDgs => (radius, radius),
        SplatExtent::Sqrt8 => ((EXTENT_SQ * a).sqrt(), (EXTENT_SQ * c).sqrt()),
    };
    let clip = |lo: f32, hi: f32, max: f32| -> Option<(u32, u32)> {
        let lo = lo.floor().max(0.0);
        let hi = hi.ceil().min(max);
        (lo < hi).then_some((lo as u32, hi as u32))
    };
    let (x0, x1) = clip(mean.x - rx, mean.x + rx, w)?;
    let (y0, y1) = clip(mean.y - ry, mean.y + ry, h)?;
    let color = sh::eval(p.sh.as_slice(), scene.sh_degree, (p.mean - camera.center()).normalize_or_zero());
    let rect = [x0, y0, x1, y1];
    Some(Splat { id: index, mean, conic, depth, opacity, color, radius, extent, rect })
}

/// EWA through the pinhole: the projected centre, Σ₂ = J W Σ Wᵀ Jᵀ as (a, b, c) and the view
/// depth z; `None` behind the near plane.
fn ewa(p: &crate::particle::Particle, camera: &Camera) -> Option<(Vec2, [f32; 3], f32)> {
    let t = camera.to_camera(p.mean);
    if t.z.is_nan() || t.z <= NEAR {
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
pub fn unscented(p: &crate::particle::Particle, camera: &Camera) -> Option<(Vec2, [f32; 3], f32)> {
    let depth = camera.to_camera(p.mean).length();
    if depth.is_nan() || depth <= NEAR {
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
        let s = project(&scene, 0, &cam, &KernelParams::default(), SplatExtent::Sqrt8).unwrap();
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
            let splat = project(&scene, 0, &cam, &KernelParams::default(), SplatExtent::ThreeDgs).unwrap();
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
        let s = project(&scene, 0, &cam, &KernelParams::default(), SplatExtent::Sqrt8).unwrap();
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

    #[test]
    fn particles_behind_or_outside_are_culled() {
        let cam = camera();
        let at = |m: Vec3| Particle::with_rgb(m, Vec3::splat(0.05), Quat::IDENTITY, 0.8, Vec3::ONE);
        let scene = Scene::new(vec![at(Vec3::new(0.0, 0.0, 5.0)), at(Vec3::new(30.0, 0.0, 0.0)), at(Vec3::ZERO)], 0);
        let k = KernelParams::default();
        assert!(project(&scene, 0, &cam, &k, SplatExtent::ThreeDgs).is_none(), "behind the camera");
        assert!(project(&scene, 1, &cam, &k, SplatExtent::ThreeDgs).is_none(), "outside the image");
        assert!(project(&scene, 2, &cam, &k, SplatExtent::ThreeDgs).is_some());
    }

    /// The 3DGS box: half-width ⌈3 √λ_max⌉; a point inside the box beyond √8σ is covered (and
    /// visible while α ≥ 1/255), a point outside the box is not, whatever its alpha.
    #[test]
    fn the_3dgs_box_reaches_past_sqrt8_sigma() {
        let cam = camera();
        let p = Particle::with_rgb(Vec3::ZERO, Vec3::splat(0.1), Quat::IDENTITY, 0.99, Vec3::ONE);
        let scene = Scene::new(vec![p], 0);
        let k = KernelParams::default();
        let s = project(&scene, 0, &cam, &k, SplatExtent::ThreeDgs).unwrap();
        let sigma = (1.0 / s.conic.x).sqrt();
        assert_relative_eq!(s.radius, (3.0 * sigma).ceil(), epsilon = 1e-4);
        let at = |d: f32| s.mean + Vec2::new(d * sigma, 0.0);
        assert!(s.alpha(at(3.0), &k).is_some(), "3σ is inside the box and above the cull");
        let sqrt8 = project(&scene, 0, &cam, &k, SplatExtent::Sqrt8).unwrap();
        assert!(sqrt8.alpha(at(3.0), &k).is_none(), "3σ is outside √8σ");
        assert!(s.alpha(s.mean + Vec2::new(s.radius + 0.01, 0.0), &k).is_none(), "outside the box");
        assert!(s.rect[2] - s.rect[0] > sqrt8.rect[2] - sqrt8.rect[0]);
    }
}
