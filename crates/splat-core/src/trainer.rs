//! The trainers whose captures splat renders as they render them, and what each one's renderer
//! assumes of a capture that the file does not say: one home for a trainer's conventions (the
//! CLI's `--preset`, `splat info`).
//!
//! | preset | screen filter | splat extent | splat response | kernel | its renderer |
//! |---|---|---|---|---|---|
//! | `3dgs` | 0.3 px² dilation | 3DGS tiles | projected | degree 2 | the INRIA rasterizer |
//! | `gsplat` | 0.3 px² dilation | alpha cull | projected | degree 2 | gsplat, `rasterize_mode="classic"` (its default; splatfacto's too) |
//! | `gsplat-antialiased` | antialiased | alpha cull | projected | degree 2 | gsplat, `rasterize_mode="antialiased"` |
//! | `mip-splatting` | 2D Mip filter | 3DGS tiles | projected | degree 2 | Mip-Splatting's rasterizer (its 3D filter is in the file) |
//! | `3dgrt` | the file's | 3DGUT's tiles | along the ray | degree 4: exp(−4.5 (d/3)⁴) | 3DGRT's ray tracer (3dgrut `configs/render/3dgrt.yaml`) |
//! | `3dgut` | the file's | 3DGUT's tiles | along the ray | degree 2 | 3DGUT (3dgrut `configs/render/3dgut.yaml`): particles evaluated in 3D along each ray, in global depth order |
//! | `2dgs` | the file's | 3DGUT's tiles | along the ray | degree 2, no cutoff | 2DGS's rasterizer (diff-surfel-rasterization): the ray–splat intersection and its low-pass |
//!
//! gsplat's rasterizer also culls centres nearer than 0.01 ([`Preset::near`]), where the 3DGS
//! rasterizer culls at 0.2. Its classic mode filters as 3DGS does; its footprint and near plane
//! are its own in both modes.
//!
//! 3DGRT and 3DGUT evaluate each particle in 3D along the pixel's ray (their response at its
//! maximum, alpha clamped to 0.99 and cut below 1/255, as here), but drop a hit whose response
//! is below [`GRUT_MIN_RESPONSE`] (0.0113, just above e^−4.5 ≈ 0.0111): their presets set the
//! cutoff to the Mahalanobis radius of that response ([`Preset::cutoff`], 2.994σ for degree 2,
//! 2.997σ for 4). Their captures render faithfully with the ray-tracing methods, through any
//! lens ([`crate::camera::Lens`]), and 3DGUT's with splatting too ([`Response::AlongRay`]); the
//! screen filter of 3DGUT's projector only culls, so the file's stays.

use crate::filter::ScreenFilter;
use crate::kernel::KernelParams;
use crate::raster::{Response, SplatExtent};

/// gsplat's default near plane (`rasterization(near_plane=0.01)`).
pub const GSPLAT_NEAR: f32 = 0.01;

/// The smallest kernel response 3DGRT and 3DGUT keep (`particle_kernel_min_response`).
pub const GRUT_MIN_RESPONSE: f32 = 0.0113;

/// A trainer's preset (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Preset {
    /// 3DGS (Kerbl et al. 2023), the INRIA trainer.
    ThreeDgs,
    /// gsplat (and Nerfstudio's splatfacto, which rasterizes through it) in its default
    /// `rasterize_mode="classic"`.
    Gsplat,
    /// gsplat with `rasterize_mode="antialiased"`.
    GsplatAntialiased,
    /// Mip-Splatting (Yu et al. 2024).
    MipSplatting,
    /// 3DGRT (Moenne-Loccoz et al. 2024).
    ThreeDgrt,
    /// 3DGUT (Wu et al. 2025).
    ThreeDgut,
    /// 2DGS (Huang et al. 2024): surfels.
    TwoDgs,
}

impl Preset {
    /// Every preset.
    pub const ALL: [Preset; 7] = [
        Preset::ThreeDgs,
        Preset::Gsplat,
        Preset::GsplatAntialiased,
        Preset::MipSplatting,
        Preset::ThreeDgrt,
        Preset::ThreeDgut,
        Preset::TwoDgs,
    ];

    /// Its name on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            Preset::ThreeDgs => "3dgs",
            Preset::Gsplat => "gsplat",
            Preset::GsplatAntialiased => "gsplat-antialiased",
            Preset::MipSplatting => "mip-splatting",
            Preset::ThreeDgrt => "3dgrt",
            Preset::ThreeDgut => "3dgut",
            Preset::TwoDgs => "2dgs",
        }
    }

    /// What it sets, in words.
    pub const fn describe(self) -> &'static str {
        match self {
            Preset::ThreeDgs => "3DGS: the 0.3 px² dilation, Gaussian kernel",
            Preset::Gsplat => {
                "gsplat classic (and splatfacto): the 3DGS dilation over gsplat's footprint and near plane"
            }
            Preset::GsplatAntialiased => "gsplat antialiased: the antialiased screen filter, Gaussian kernel",
            Preset::MipSplatting => "Mip-Splatting: its 2D Mip filter, Gaussian kernel",
            Preset::ThreeDgrt => "3DGRT: kernel degree 4; render with a ray-tracing method",
            Preset::ThreeDgut => {
                "3DGUT: Gaussian kernel, its minimum response; splatting evaluates each particle along the pixel's ray"
            }
            Preset::TwoDgs => "2DGS: surfels evaluated at their ray–splat intersection with 2DGS's low-pass, no cutoff",
        }
    }

    /// The screen filter its rasterizer applies, or `None` where its renderer has none of its
    /// own and the file's stays.
    pub const fn screen_filter(self) -> Option<ScreenFilter> {
        match self {
            Preset::ThreeDgs | Preset::Gsplat => Some(ScreenFilter::Dilation),
            Preset::GsplatAntialiased => Some(ScreenFilter::Antialiased),
            Preset::MipSplatting => Some(ScreenFilter::Mip),
            Preset::ThreeDgrt | Preset::ThreeDgut | Preset::TwoDgs => None,
        }
    }

    /// The rasterizing trainer whose screen filter `filter` is: the one a capture that names
    /// its filter (and no preset) is rendered as.
    pub const fn of_filter(filter: ScreenFilter) -> Preset {
        match filter {
            ScreenFilter::Dilation => Preset::ThreeDgs,
            ScreenFilter::Antialiased => Preset::GsplatAntialiased,
            ScreenFilter::Mip => Preset::MipSplatting,
        }
    }

    /// Which pixels its rasterizer lets a splat touch: gsplat's opacity-aware bounds (in both
    /// modes), else the 3DGS rasterizer's tiles (Mip-Splatting's rasterizer is a fork of it;
    /// 3DGRT and 3DGUT render with rays, where no extent applies).
    pub const fn extent(self) -> SplatExtent {
        match self {
            Preset::Gsplat | Preset::GsplatAntialiased => SplatExtent::AlphaCull,
            _ => SplatExtent::ThreeDgs,
        }
    }

    /// How its rasterizer evaluates a fragment: along the pixel's ray for 3DGUT and 2DGS (and
    /// 3DGRT, whose renderer is a ray tracer), else the projected 2D Gaussian.
    pub const fn response(self) -> Response {
        match self {
            Preset::ThreeDgrt | Preset::ThreeDgut | Preset::TwoDgs => Response::AlongRay,
            _ => Response::Projected,
        }
    }

    /// The near plane of its rasterizer ([`crate::RenderSettings::near`]): gsplat's `near_plane`
    /// 0.01, else the 3DGS rasterizer's 0.2 (Mip-Splatting's fork keeps it).
    pub const fn near(self) -> f32 {
        match self {
            Preset::Gsplat | Preset::GsplatAntialiased => GSPLAT_NEAR,
            _ => crate::raster::project::NEAR,
        }
    }

    /// The degree n of its particles' kernel exp(−4.5 (d/3)ⁿ) ([`crate::kernel`]).
    pub const fn kernel_degree(self) -> u32 {
        match self {
            Preset::ThreeDgrt => 4,
            _ => crate::kernel::DEFAULT_DEGREE,
        }
    }

    /// The cutoff in standard deviations: 3 (3DGS's 3σ), or for 3DGRT and 3DGUT the radius where
    /// the response falls to [`GRUT_MIN_RESPONSE`], 3 (ln(1 / r_min) / 4.5)^(1/n).
    pub fn cutoff(self) -> f32 {
        match self {
            Preset::ThreeDgrt | Preset::ThreeDgut => min_response_cutoff(GRUT_MIN_RESPONSE, self.kernel_degree()),
            // 2DGS's rasterizer has no cutoff: only the alpha cull, which takes even an opaque
            // surfel's response beyond its visible radius.
            Preset::TwoDgs => KernelParams::default().visible_radius(1.0),
            _ => crate::kernel::DEFAULT_CUTOFF,
        }
    }
}

/// The splat extent and response a capture is drawn with where no option says: those of the
/// renderer its file names ([`crate::Scene::trained`]); else the extent of the rasterizing
/// trainer whose screen filter it names ([`Preset::of_filter`]: a gsplat-antialiased capture is
/// drawn with gsplat's bounds), and along the rays for a capture of 2D Gaussians, as 2DGS
/// evaluates them, else projected.
pub fn capture_splatting(scene: &crate::Scene) -> (SplatExtent, Response) {
    let trained = scene.trained.map(|t| t.preset);
    let extent = trained.unwrap_or(Preset::of_filter(scene.screen_filter)).extent();
    let surfels = scene.is_surfels().then_some(Preset::TwoDgs);
    let response = trained.or(surfels).map_or(Response::Projected, Preset::response);
    (extent, response)
}

/// The cutoff, in standard deviations, where the kernel of degree n falls to the response
/// `min_response` (3DGRT's and 3DGUT's `particle_kernel_min_response`): 3 (ln(1 / r_min) /
/// 4.5)^(1/n), from exp(−4.5 (d/3)ⁿ) = r_min.
pub fn min_response_cutoff(min_response: f32, degree: u32) -> f32 {
    3.0 * ((1.0 / min_response).ln() / 4.5).powf(1.0 / degree as f32)
}

/// What a capture's file or its run's folder says of the renderer its trainer drew it through,
/// beyond its screen filter ([`crate::Scene::screen_filter`]): a trainer's checkpoint is gsplat's
/// rasterizer's (gsplat's, splatfacto's) or names its renderer and kernel (a 3DGRUT config's),
/// and a run may name the background its evaluation composites over and the near plane its
/// rasterizer culled at. Front ends render such a capture so where the user chose no preset,
/// kernel, near plane or background, as they apply a file's screen filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trained {
    /// The preset of its renderer.
    pub preset: Preset,
    /// The degree n of the kernel exp(−4.5 (d/3)ⁿ) it trained with: its preset's, unless the
    /// run set another.
    pub kernel_degree: u32,
    /// The cutoff, in standard deviations, of that kernel: its preset's, unless the run set
    /// another degree or minimum response ([`min_response_cutoff`]).
    pub cutoff: f32,
    /// The colour its trainer's evaluation composites its renders over, where the run says
    /// (3DGS's `white_background`, splatfacto's `background_color`, 3DGRUT's
    /// `model.background.color`); `None`: black, the default.
    pub background: Option<glam::Vec3>,
    /// The near plane its rasterizer culled at ([`crate::RenderSettings::near`]): its preset's,
    /// unless the run set another (gsplat's `near_plane`).
    pub near: f32,
}

impl Trained {
    /// Trained as `preset` renders, with its kernel.
    pub fn of(preset: Preset) -> Self {
        let (kernel_degree, cutoff, near) = (preset.kernel_degree(), preset.cutoff(), preset.near());
        Self { preset, kernel_degree, cutoff, background: None, near }
    }

    /// `preset`'s renderer, kernel and near plane in place of those `trained` names (a run's
    /// word, or none), keeping the background its run composites over, of which a preset says
    /// nothing.
    pub fn instead(trained: Option<Trained>, preset: Preset) -> Self {
        Self { background: trained.and_then(|t| t.background), ..Self::of(preset) }
    }

    /// The kernel it trained with: `base` with its degree and cutoff.
    pub fn kernel(&self, base: KernelParams) -> KernelParams {
        KernelParams { degree: self.kernel_degree, cutoff: self.cutoff, ..base }
    }

    /// `base` as its renderer draws: its kernel, its near plane, its background.
    pub fn settings(&self, base: crate::RenderSettings) -> crate::RenderSettings {
        crate::RenderSettings {
            kernel: self.kernel(base.kernel),
            near: self.near,
            background: self.background.unwrap_or(base.background),
            ..base
        }
    }

    /// Whether its kernel is its preset's own (its degree and cutoff).
    pub fn has_presets_kernel(&self) -> bool {
        (self.kernel_degree, self.cutoff) == (self.preset.kernel_degree(), self.preset.cutoff())
    }

    /// Whether its near plane is its preset's own.
    pub fn has_presets_near(&self) -> bool {
        self.near == self.preset.near()
    }

    /// What it is, in words: "3DGRT's ray tracer, kernel degree 4, cutoff 2.9972σ"; "gsplat's
    /// rasterizer (classic mode), kernel degree 2, cutoff 3.0000σ, near plane 0.2" where its near
    /// plane is not its preset's.
    pub fn describe(&self) -> String {
        let renderer = match self.preset {
            Preset::ThreeDgs => "the INRIA rasterizer",
            Preset::Gsplat => "gsplat's rasterizer (classic mode)",
            Preset::GsplatAntialiased => "gsplat's rasterizer (antialiased mode)",
            Preset::MipSplatting => "Mip-Splatting's rasterizer",
            Preset::ThreeDgrt => "3DGRT's ray tracer",
            Preset::ThreeDgut => "3DGUT's renderer",
            Preset::TwoDgs => "2DGS's rasterizer",
        };
        let background =
            self.background.map_or(String::new(), |b| format!(", over the background {},{},{}", b.x, b.y, b.z));
        let near = if self.has_presets_near() { String::new() } else { format!(", near plane {}", self.near) };
        format!("{renderer}, kernel degree {}, cutoff {:.4}σ{near}{background}", self.kernel_degree, self.cutoff)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::response;

    /// The 3DGRT and 3DGUT cutoffs are where the response is the trainers' minimum.
    #[test]
    fn the_grut_cutoff_is_the_minimum_response() {
        for preset in [Preset::ThreeDgrt, Preset::ThreeDgut] {
            let c = preset.cutoff();
            let r = response(c * c, preset.kernel_degree());
            assert!((r - GRUT_MIN_RESPONSE).abs() < 1e-6, "{preset:?}: {r} at {c}");
        }
        assert_eq!(Preset::ThreeDgs.cutoff(), 3.0);
    }

    /// A capture is splatted as the renderer its file names draws it, else as its screen
    /// filter's trainer and its surfels say.
    #[test]
    fn a_capture_is_splatted_as_its_trainer_draws_it() {
        use crate::Scene;
        use crate::particle::{Particle, surfel_thickness};
        use glam::{Quat, Vec3};
        let splat = |s: Vec3| Particle::with_rgb(Vec3::ZERO, s, Quat::IDENTITY, 0.5, Vec3::ONE);
        let plain = Scene::new(vec![splat(Vec3::splat(0.1))], 0);
        let surfels = Scene::new(vec![splat(Vec3::new(0.1, 0.2, surfel_thickness(0.1, 0.2)))], 0);
        let with = |scene: &Scene, filter, trained: Option<Preset>| Scene {
            screen_filter: filter,
            trained: trained.map(Trained::of),
            ..scene.clone()
        };
        let (dilation, antialiased) = (ScreenFilter::Dilation, ScreenFilter::Antialiased);
        for (scene, expected) in [
            (with(&plain, dilation, None), (SplatExtent::ThreeDgs, Response::Projected)),
            (with(&plain, antialiased, None), (SplatExtent::AlphaCull, Response::Projected)),
            (with(&plain, dilation, Some(Preset::Gsplat)), (SplatExtent::AlphaCull, Response::Projected)),
            (with(&plain, dilation, Some(Preset::ThreeDgut)), (SplatExtent::ThreeDgs, Response::AlongRay)),
            (with(&surfels, dilation, None), (SplatExtent::ThreeDgs, Response::AlongRay)),
        ] {
            assert_eq!(capture_splatting(&scene), expected, "{:?} {:?}", scene.screen_filter, scene.trained);
        }
    }

    /// A capture trained as a preset renders has the preset's kernel; a run's own minimum
    /// response at another degree is that degree's cutoff.
    #[test]
    fn a_trained_kernel_is_its_presets_unless_the_run_changed_it() {
        for preset in Preset::ALL {
            let k = Trained::of(preset).kernel(KernelParams::default());
            assert_eq!((k.degree, k.cutoff), (preset.kernel_degree(), preset.cutoff()), "{preset:?}");
        }
        let c = min_response_cutoff(GRUT_MIN_RESPONSE, 8);
        assert!((response(c * c, 8) - GRUT_MIN_RESPONSE).abs() < 1e-6);
        assert!(!Trained { kernel_degree: 8, cutoff: c, ..Trained::of(Preset::ThreeDgrt) }.has_presets_kernel());
    }

    /// A trained near plane is its preset's unless the run set another; the settings take it,
    /// `describe` names it only then, and a preset put in place of the run's brings its own.
    #[test]
    fn a_trained_near_plane_is_its_presets_unless_the_run_changed_it() {
        for preset in Preset::ALL {
            let trained = Trained::of(preset);
            assert!(trained.has_presets_near() && !trained.describe().contains("near plane"), "{preset:?}");
            assert_eq!(trained.settings(crate::RenderSettings::default()).near, preset.near(), "{preset:?}");
        }
        let run = Trained { near: 0.5, background: Some(glam::Vec3::ONE), ..Trained::of(Preset::Gsplat) };
        assert!(!run.has_presets_near() && run.describe().contains(", near plane 0.5"), "{}", run.describe());
        assert_eq!(run.settings(crate::RenderSettings::default()).near, 0.5);
        let instead = Trained::instead(Some(run), Preset::ThreeDgs);
        assert_eq!((instead.near, instead.background), (Preset::ThreeDgs.near(), run.background));
    }
}
