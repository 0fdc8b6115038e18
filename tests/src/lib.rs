//! Shared helpers of the end-to-end tests: an independent f64 implementation of the exact
//! render (Eq. 3), written from the formulas rather than from `splat-core`, and golden-image
//! comparison.

pub mod inria;

use std::path::{Path, PathBuf};

/// The workspace root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("tests/ is in the workspace").to_path_buf()
}

/// Independent reference of the exact renderer, in f64, for SH degree 0 scenes.
///
/// It shares no code with `splat-core`'s math: Σ is built from the quaternion with the 3DGS
/// formula, inverted with the adjugate, and the hit is found by minimising the quadratic
/// (x − μ)ᵀ Σ⁻¹ (x − μ) along the ray directly in world space.
#[allow(clippy::needless_range_loop)] // matrix algebra reads best with explicit indices
pub mod reference {
    type V3 = [f64; 3];
    type M3 = [[f64; 3]; 3];

    fn sub(a: V3, b: V3) -> V3 {
        [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
    }
    fn dot(a: V3, b: V3) -> f64 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }
    fn mul(m: &M3, v: V3) -> V3 {
        [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
    }

    /// A particle as stored in a 3DGS file, after activations.
    #[derive(Clone, Copy, Debug)]
    pub struct Gaussian {
        /// Mean.
        pub mean: V3,
        /// Linear scale.
        pub scale: V3,
        /// Quaternion (w, x, y, z), unit.
        pub q: [f64; 4],
        /// Opacity.
        pub opacity: f64,
        /// Degree-0 colour 0.5 + C₀ f_dc, clamped at 0.
        pub rgb: V3,
    }

    /// Σ⁻¹ for R from the quaternion as 3DGS's `build_rotation` writes it, Σ = R S² Rᵀ.
    fn inverse_covariance(g: &Gaussian) -> M3 {
        let [r, x, y, z] = g.q;
        let rot = [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - r * z), 2.0 * (x * z + r * y)],
            [2.0 * (x * y + r * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - r * x)],
            [2.0 * (x * z - r * y), 2.0 * (y * z + r * x), 1.0 - 2.0 * (x * x + y * y)],
        ];
        let mut cov = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] = (0..3).map(|k| rot[i][k] * g.scale[k] * g.scale[k] * rot[j][k]).sum();
            }
        }
        // Adjugate / determinant.
        let c = |i: usize, j: usize| {
            let (a, b) = ((i + 1) % 3, (i + 2) % 3);
            let (p, q) = ((j + 1) % 3, (j + 2) % 3);
            cov[a][p] * cov[b][q] - cov[a][q] * cov[b][p]
        };
        let det: f64 = (0..3).map(|j| cov[0][j] * c(0, j)).sum();
        let mut inv = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                inv[j][i] = c(i, j) / det;
            }
        }
        inv
    }

    /// Colour of one ray over `background`, Eq. 3 with the defaults of `splat-core`
    /// (max-density hit, cutoff 3σ, alpha clamp 0.99, cull 1/255, t in (0.001, 10000)).
    pub fn trace(gaussians: &[Gaussian], origin: V3, dir: V3, background: V3) -> V3 {
        let mut hits: Vec<(f64, f64, V3)> = Vec::new();
        for g in gaussians {
            let a = inverse_covariance(g);
            let m = sub(origin, g.mean);
            // q(t) = (m + t d)ᵀ A (m + t d) is minimal at t = −mᵀ A d / dᵀ A d.
            let ad = mul(&a, dir);
            let dad = dot(dir, ad);
            let t = -dot(m, ad) / dad;
            let d2 = dot(m, mul(&a, m)) - t * t * dad;
            if d2 > 9.0 || t <= 0.001 || t >= 10_000.0 {
                continue;
            }
            let alpha = g.opacity * (-0.5 * d2).exp();
            if alpha < 1.0 / 255.0 {
                continue;
            }
            hits.push((t, alpha.min(0.99), g.rgb));
        }
        hits.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut out = [0.0; 3];
        let mut transmittance = 1.0;
        for (_, alpha, rgb) in hits {
            for k in 0..3 {
                out[k] += transmittance * alpha * rgb[k];
            }
            transmittance *= 1.0 - alpha;
        }
        [0, 1, 2].map(|k| out[k] + transmittance * background[k])
    }
}

/// Compare an 8-bit rendering with a committed golden PNG: every channel within `tolerance`
/// units. On mismatch (or a missing golden) write `NAME-actual.png` and `NAME-diff.png` beside
/// the golden and return a message naming them.
pub fn compare_golden(golden: &Path, actual: &image::RgbImage, tolerance: u8) -> Result<(), String> {
    let stem = golden.with_extension("");
    let actual_path = PathBuf::from(format!("{}-actual.png", stem.display()));
    let diff_path = PathBuf::from(format!("{}-diff.png", stem.display()));
    let expected = match image::open(golden) {
        Ok(img) => img.to_rgb8(),
        Err(e) => {
            actual.save(&actual_path).map_err(|e| e.to_string())?;
            return Err(format!(
                "cannot read {}: {e}; wrote {} (run `cargo xtask bless`)",
                golden.display(),
                actual_path.display()
            ));
        }
    };
    if expected.dimensions() != actual.dimensions() {
        actual.save(&actual_path).map_err(|e| e.to_string())?;
        return Err(format!(
            "{}: size {:?}, rendered {:?}",
            golden.display(),
            expected.dimensions(),
            actual.dimensions()
        ));
    }
    let mut worst = 0u8;
    let mut bad = 0usize;
    let diff = image::RgbImage::from_fn(actual.width(), actual.height(), |x, y| {
        let (a, e) = (actual.get_pixel(x, y), expected.get_pixel(x, y));
        let d = [0, 1, 2].map(|k| a[k].abs_diff(e[k]));
        let m = d.into_iter().max().unwrap_or(0);
        worst = worst.max(m);
        bad += usize::from(m > tolerance);
        image::Rgb(d.map(|v| v.saturating_mul(16)))
    });
    if bad == 0 {
        return Ok(());
    }
    actual.save(&actual_path).map_err(|e| e.to_string())?;
    diff.save(&diff_path).map_err(|e| e.to_string())?;
    Err(format!(
        "{}: {bad} pixels differ by more than {tolerance} (worst {worst}); wrote {} and {}",
        golden.display(),
        actual_path.display(),
        diff_path.display()
    ))
}

/// The statistical method of docs/architecture.md ("How correctness is proven") as one object,
/// after Mitsuba 3's `ChiSquareTest`: a [`harness::StatTest`] is an oracle image and a sampler
/// of frames (any estimator, CPU or GPU, ray or raster); every statistical suite is a few lines
/// on it.
pub mod harness {
    use splat_core::frame::{Frames, RenderOutput};
    use splat_core::raster::{Blend, RasterMethod, Rasterizer, render_raster};
    use splat_core::stats::{ZTest, log_log_slope, rmse};
    use splat_core::trace::{Method, TraceScene, render_frames};
    use splat_core::{Camera, Scene};
    use std::ops::RangeInclusive;

    /// The log–log RMSE slope of an unbiased Monte Carlo estimator: −1/2 within the sampling
    /// error of a 3-seed, 9-level fit.
    pub const MONTE_CARLO_SLOPE: RangeInclusive<f64> = -0.58..=-0.42;

    /// A built-in fixture scene and its camera at `width` × `height`.
    pub fn fixture(name: &str, width: u32, height: u32) -> (Scene, Camera) {
        let (scene, camera) = splat_core::scenes::by_name(name).expect("a built-in scene");
        (scene, camera.rescaled(width, height).expect("a valid size"))
    }

    /// One estimator against its oracle.
    pub struct StatTest<'a> {
        name: String,
        oracle: RenderOutput,
        sampler: Box<dyn Fn(Frames) -> RenderOutput + 'a>,
    }

    impl<'a> StatTest<'a> {
        /// `sampler(frames)` renders the mean and variance of `frames` of the estimator;
        /// `oracle` is the image it must equal in expectation; `name` labels reports and the
        /// z-map written on failure.
        pub fn new(
            name: impl Into<String>,
            oracle: RenderOutput,
            sampler: impl Fn(Frames) -> RenderOutput + 'a,
        ) -> Self {
            Self { name: name.into(), oracle, sampler: Box::new(sampler) }
        }

        /// The CPU ray-tracing `method` against `exact` (equal to the oracle, proven in
        /// `tracer.rs`).
        pub fn trace(name: impl Into<String>, trace: &'a TraceScene<'a>, camera: &'a Camera, method: Method) -> Self {
            let run = move |m: &Method, f: Frames| render_frames(trace, camera, m, &f, &|_| {}).expect("render");
            Self::new(name, run(&Method::Exact, Frames::default()), move |f| run(&method, f))
        }

        /// The CPU raster `method` against sorted splatting with the same samples (the raster
        /// oracle).
        pub fn raster(name: impl Into<String>, r: &'a Rasterizer<'a>, method: RasterMethod) -> Self {
            let run = move |m: &RasterMethod, f: Frames| render_raster(r, m, &f, &|_| {}).expect("render");
            let sorted = RasterMethod::Sorted { blend: Blend::Under };
            Self::new(name, run(&sorted, Frames::default()), move |f| run(&method, f))
        }

        /// The z-test over the oracle's covered pixel-channels: the mean from `base.count`
        /// frames with seed `base.seed`, the per-frame variance from an independent run of
        /// 4 × as many frames with seed `base.seed + 1`.
        pub fn z_test(&self, base: Frames) -> ZTest {
            self.z_test_and_map(base).0
        }

        fn z_test_and_map(&self, base: Frames) -> (ZTest, image::RgbImage) {
            let mask: Vec<bool> = self.oracle.alpha.data().iter().flat_map(|&a| [a > 1e-4; 3]).collect();
            let keep = |v: &[f32]| v.iter().zip(&mask).filter(|(_, m)| **m).map(|(v, _)| *v).collect::<Vec<_>>();
            let mean = (self.sampler)(base);
            let var = (self.sampler)(Frames { count: 4 * base.count, seed: base.seed + 1, ..base });
            let (m, r, v) = (mean.mean.data(), self.oracle.mean.data(), var.variance.data());
            let z = ZTest::new(&keep(m), &keep(r), &keep(v), base.count, 3);
            (z, z_map(&self.oracle, m, v, base.count, &mask))
        }

        /// Assert that the estimator passes the z-test; on failure write the z-map.
        pub fn assert_unbiased(&self, base: Frames) -> ZTest {
            let (z, map) = self.z_test_and_map(base);
            eprintln!("{}: {z:?}", self.name);
            if !z.passes() {
                panic!("{} fails the z-test: {z:?}; z-map: {}", self.name, self.write_map(&map));
            }
            z
        }

        /// Assert that the z-test rejects the estimator (a biased control).
        pub fn assert_rejected(&self, base: Frames) -> ZTest {
            let z = self.z_test(base);
            eprintln!("{} (control): {z:?}", self.name);
            assert!(!z.passes(), "the biased control {} passes the z-test: {z:?}", self.name);
            z
        }

        /// RMSE against the oracle at spp = 1, 2, 4, … `max_spp`, averaged over `seeds` seeds
        /// (seed 1000 × spp + s), and the least-squares log–log slope.
        pub fn convergence(&self, max_spp: u32, seeds: u32) -> (f64, Vec<(u32, f64)>) {
            let levels: Vec<u32> = (0..).map(|i| 1u32 << i).take_while(|&s| s <= max_spp).collect();
            let table: Vec<(u32, f64)> = levels
                .iter()
                .map(|&spp| {
                    let sum: f64 = (0..seeds)
                        .map(|s| {
                            let frames = Frames { count: spp, seed: 1000 * spp + s, ..Frames::default() };
                            rmse((self.sampler)(frames).mean.data(), self.oracle.mean.data())
                        })
                        .sum();
                    (spp, sum / f64::from(seeds))
                })
                .collect();
            let (x, y): (Vec<f64>, Vec<f64>) = table.iter().map(|&(s, r)| (f64::from(s), r)).unzip();
            let slope = log_log_slope(&x, &y);
            eprintln!("{}: slope {slope:.3} {table:?}", self.name);
            (slope, table)
        }

        /// Assert that the RMSE falls at the Monte Carlo rate ([`MONTE_CARLO_SLOPE`]).
        pub fn assert_converges(&self, max_spp: u32, seeds: u32) -> f64 {
            let (slope, table) = self.convergence(max_spp, seeds);
            assert!(MONTE_CARLO_SLOPE.contains(&slope), "{}: slope {slope} {table:?}", self.name);
            slope
        }

        /// Write the z-map as `fixtures/NAME-zmap.png` (beside the fixtures, as the goldens
        /// write their diffs) and return its path.
        fn write_map(&self, map: &image::RgbImage) -> String {
            let file: String =
                self.name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect();
            let path = super::root().join("fixtures").join(format!("{file}-zmap.png"));
            match map.save(&path) {
                Ok(()) => path.display().to_string(),
                Err(e) => format!("{} not written: {e}", path.display()),
            }
        }
    }

    /// Per-pixel z = (mean − oracle) / max(√(var / F), 1 / F) of each channel as an image:
    /// grey 128 is z = 0, 32 levels per unit of z (brighter: too bright), black outside the
    /// oracle's coverage.
    fn z_map(oracle: &RenderOutput, mean: &[f32], var: &[f32], frames: u32, mask: &[bool]) -> image::RgbImage {
        let f = f64::from(frames);
        let reference = oracle.mean.data();
        image::RgbImage::from_fn(oracle.mean.width(), oracle.mean.height(), |x, y| {
            let i = 3 * (y * oracle.mean.width() + x) as usize;
            image::Rgb([0, 1, 2].map(|c| {
                if !mask[i + c] {
                    return 0;
                }
                let se = (f64::from(var[i + c]) / f).sqrt().max(1.0 / f);
                let z = (f64::from(mean[i + c]) - f64::from(reference[i + c])) / se;
                (128.0 + 32.0 * z).clamp(0.0, 255.0) as u8
            }))
        })
    }
}

/// The bonsai capture fetched by `cargo xtask assets`, if present (tests skip without it,
/// saying why; with `CI=true` they fail instead).
pub fn bonsai() -> Option<splat_core::Scene> {
    let path = root().join("target/assets/bonsai-7k-mini.splat");
    if !path.exists() {
        let msg = format!("{} is absent: run `cargo xtask assets`", path.display());
        assert!(std::env::var("CI").is_err(), "{msg} (CI must fetch it)");
        eprintln!("skipping: {msg}");
        return None;
    }
    Some(splat_io::read_scene(&path).expect("the verified bonsai capture loads"))
}

/// The standard bonsai view (the capture's world up is −y): 1200 × 800 from (0, −1.5, 4)
/// looking at (0, 0.5, 0), 50° vertical field of view.
pub fn bonsai_camera() -> splat_core::Camera {
    splat_core::Camera::look_at(
        glam::Vec3::new(0.0, -1.5, 4.0),
        glam::Vec3::new(0.0, 0.5, 0.0),
        glam::Vec3::new(0.0, -1.0, 0.0),
        50.0,
        1200,
        800,
    )
    .expect("valid camera")
}

/// Golden images: what `cargo xtask bless` renders and the golden test compares.
pub mod golden {
    use splat_core::raster::{Blend, RasterMethod, RasterSettings};
    use splat_core::trace::Method;
    use splat_core::{Algorithm, Frames, RenderSettings};

    /// Fixtures with golden images.
    pub const FIXTURES: [&str; 3] = ["layers", "ramp", "cloud"];
    /// Fixtures of the stratification report (`splat stratify`), rendered with kernel degree
    /// [`splat_core::scenes::PLATE_KERNEL_DEGREE`].
    pub const STRATIFICATION_FIXTURES: [&str; 2] = ["plates", "cloth"];

    /// The methods rendered for every fixture: (file suffix, case, frames), stochastic ones
    /// with seed 1.
    pub fn cases() -> Vec<(&'static str, Algorithm, Frames)> {
        let f = |count| Frames { count, seed: 1, ..Frames::default() };
        let s4 = RasterSettings { samples: 4, ..RasterSettings::default() };
        vec![
            ("oracle", Algorithm::Oracle, f(1)),
            ("kbuffer", Algorithm::Trace(Method::KBUFFER), f(1)),
            ("stochastic", Algorithm::Trace(Method::Stochastic), f(4)),
            ("stochastic-n", Algorithm::Trace(Method::StochasticN { m: 1, n: 4 }), f(1)),
            ("stochastic-pass", Algorithm::Trace(Method::STOCHASTIC_PASS), f(4)),
            ("depth-sampling-k", Algorithm::Trace(Method::DepthSampling { k: 2 }), f(4)),
            (
                "raster-sorted",
                Algorithm::Raster(RasterMethod::Sorted { blend: Blend::Over }, RasterSettings::default()),
                f(1),
            ),
            ("stochastic-splat", Algorithm::Raster(RasterMethod::StochasticSplat, s4), f(2)),
            ("enderton", Algorithm::Raster(RasterMethod::Enderton, s4), f(2)),
            ("stratified", Algorithm::Raster(RasterMethod::Stratified { scramble: true }, s4), f(2)),
        ]
    }

    /// Render one golden case of one fixture, read through the file formats, as 8-bit RGB.
    pub fn render(fixture: &str, algorithm: &Algorithm, frames: &Frames) -> image::RgbImage {
        let dir = super::root().join("fixtures");
        let scene = splat_io::ply::read_ply(&dir.join(format!("{fixture}.ply"))).expect("fixture");
        let camera = splat_io::cameras::read_cameras(&dir.join(format!("{fixture}.cameras.json"))).expect("camera")[0];
        let out = algorithm.render(&scene, &camera, &RenderSettings::default(), frames, &|_| {}).expect("render");
        splat_io::image::to_rgba8(&out.mean).to_rgb8()
    }

    /// Path of a golden image.
    pub fn path(fixture: &str, suffix: &str) -> std::path::PathBuf {
        super::root().join("fixtures/golden").join(format!("{fixture}-{suffix}.png"))
    }
}
