//! An independent forward pass of the INRIA 3DGS rasterizer (Kerbl et al. 2023,
//! diff-gaussian-rasterization: `preprocessCUDA`, `computeCov2D`, `computeColorFromSH` and
//! `renderCUDA`), written from the published algorithm in the rasterizer's own precision (f32),
//! sharing no code with `splat-core`'s splatting path. It is what `raster-sorted` with the
//! default `3dgs` extent must reproduce.
//!
//! gsplat's `classic` mode (its default, and splatfacto's) filters as 3DGS does (+ 0.3 px²,
//! `eps2d`) but bounds and culls splats its own way (below). Two trainers change
//! `computeCov2D`'s low-pass ([`Forward`]): gsplat's `antialiased`
//! mode (`add_blur`: + 0.3 px², opacity × √max(0, det_orig / det_blur)) and Mip-Splatting's 2D
//! Mip filter (its rasterizer fork: + `kernel_size` 0.1 px², opacity × `coef`, with that fork's
//! 1e-6 guards). Mip-Splatting's 3D smoothing filter is applied here from the raw `filter_3D`
//! values, as its `GaussianModel` does (`get_scaling_with_3D_filter`,
//! `get_opacity_with_3D_filter`), when [`Options::filter_3d`] gives them.
//!
//! Pixel coordinates follow this workspace (pixel i covers [i, i + 1), centre i + 0.5; 3DGS
//! puts the centre at i and shifts the projected mean by −½ with it, so every offset d is the
//! same). A splat reaches every pixel of the 16 × 16 tiles its bounds touch (`renderCUDA`
//! tests a pixel against nothing but α ≥ 1/255): the INRIA rasterizer and Mip-Splatting's fork
//! bound it by the ⌈3 √λ_max⌉ square and `getRect`; gsplat by its opacity-aware half-widths
//! ⌈extend √Σ′_ii⌉, extend = min(3.33, √(2 ln(255 o))), and the tile range of `isect_tiles`
//! (its AABB path; its AccuTile ellipse test drops only tiles where no pixel passes the cull).

use splat_core::{Camera, Scene};

/// Whose forward pass: the trainers differ in `computeCov2D`'s screen-space low-pass.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Forward {
    /// diff-gaussian-rasterization: Σ₂ + 0.3 I.
    #[default]
    Inria,
    /// gsplat with `rasterize_mode="classic"`: Σ₂ + `eps2d` I (0.3), the opacity as it is.
    GsplatClassic {
        /// `eps2d`, px² (0.3 in gsplat).
        eps2d: f32,
    },
    /// gsplat with `rasterize_mode="antialiased"`: Σ₂ + `eps2d` I (0.3) with the opacity
    /// compensated.
    GsplatAntialiased {
        /// `eps2d`, px² (0.3 in gsplat; other values make the tests' controls).
        eps2d: f32,
    },
    /// Mip-Splatting's rasterizer: Σ₂ + `kernel_size` I (0.1) with the opacity × `coef`.
    MipSplatting {
        /// `kernel_size`, px² (0.1 in every published run).
        kernel_size: f32,
    },
}

impl Forward {
    /// gsplat's classic mode as published.
    pub const GSPLAT_CLASSIC: Forward = Forward::GsplatClassic { eps2d: 0.3 };
    /// gsplat's antialiased mode as published.
    pub const GSPLAT_ANTIALIASED: Forward = Forward::GsplatAntialiased { eps2d: 0.3 };
    /// Mip-Splatting as published.
    pub const MIP_SPLATTING: Forward = Forward::MipSplatting { kernel_size: 0.1 };

    /// The filtered covariance (a, b, c) and the opacity factor, from Σ₂'s (a, b, c).
    fn low_pass(self, a: f32, b: f32, c: f32) -> ([f32; 3], f32) {
        match self {
            Forward::Inria => ([a + 0.3, b, c + 0.3], 1.0),
            Forward::GsplatClassic { eps2d } => ([a + eps2d, b, c + eps2d], 1.0),
            Forward::GsplatAntialiased { eps2d } => {
                let det_orig = a * c - b * b;
                let (a, c) = (a + eps2d, c + eps2d);
                let det_blur = a * c - b * b;
                ([a, b, c], (det_orig / det_blur).max(0.0).sqrt())
            }
            Forward::MipSplatting { kernel_size } => {
                let det_0 = (a * c - b * b).max(1e-6);
                let det_1 = ((a + kernel_size) * (c + kernel_size) - b * b).max(1e-6);
                let mut coef = (det_0 / (det_1 + 1e-6) + 1e-6).sqrt();
                if det_0 <= 1e-6 || det_1 <= 1e-6 {
                    coef = 0.0;
                }
                ([a + kernel_size, b, c + kernel_size], coef)
            }
        }
    }
}

/// What the forward pass takes besides the scene and camera.
#[derive(Clone, Copy, Debug, Default)]
pub struct Options<'a> {
    /// Background colour.
    pub background: [f32; 3],
    /// Stop a pixel before the splat that would take T below 1e-4 (`renderCUDA`'s `done`).
    pub early_stop: bool,
    /// Whose `computeCov2D`.
    pub forward: Forward,
    /// Mip-Splatting's `filter_3D` of each particle (σ_f, world units), applied to the scene's
    /// raw scales and opacities; `None` for a scene without it.
    pub filter_3d: Option<&'a [f32]>,
}

/// A splat after `preprocessCUDA`.
struct Projected {
    depth: f32,
    id: usize,
    mean: [f32; 2],
    conic: [f32; 3],
    /// The tiles [x0, x1) × [y0, y1) the splat is drawn in.
    tiles: [i32; 4],
    opacity: f32,
    rgb: [f32; 3],
}

/// The image (row-major RGB) that the reference renders.
pub fn render(scene: &Scene, camera: &Camera, options: &Options) -> Vec<[f32; 3]> {
    let mut splats: Vec<Projected> =
        scene.particles.iter().enumerate().filter_map(|(id, _)| preprocess(scene, id, camera, options)).collect();
    // The (tile | depth) radix sort is stable over the splat index: depth, then id.
    splats.sort_by(|a, b| a.depth.total_cmp(&b.depth).then(a.id.cmp(&b.id)));
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut out = vec![[0.0f32; 3]; w * h];
    for (i, pixel) in out.iter_mut().enumerate() {
        *pixel = render_pixel(&splats, (i % w) as i32, (i / w) as i32, options);
    }
    out
}

/// `renderCUDA` for pixel (x, y): the splats of its tile front to back, α = min(0.99, o e^power),
/// skip α < 1/255.
fn render_pixel(splats: &[Projected], x: i32, y: i32, options: &Options) -> [f32; 3] {
    let pixf = [x as f32 + 0.5, y as f32 + 0.5];
    let (tx, ty) = (x / 16, y / 16);
    let mut t = 1.0f32;
    let mut c = [0.0f32; 3];
    for s in splats {
        let [x0, y0, x1, y1] = s.tiles;
        if tx < x0 || tx >= x1 || ty < y0 || ty >= y1 {
            continue;
        }
        let d = [s.mean[0] - pixf[0], s.mean[1] - pixf[1]];
        let power = -0.5 * (s.conic[0] * d[0] * d[0] + s.conic[2] * d[1] * d[1]) - s.conic[1] * d[0] * d[1];
        if power > 0.0 {
            continue;
        }
        let alpha = (s.opacity * power.exp()).min(0.99);
        if alpha < 1.0 / 255.0 {
            continue;
        }
        let test_t = t * (1.0 - alpha);
        if options.early_stop && test_t < 0.0001 {
            break;
        }
        for (ck, rk) in c.iter_mut().zip(s.rgb) {
            *ck += rk * alpha * t;
        }
        t = test_t;
    }
    [0, 1, 2].map(|k| c[k] + t * options.background[k])
}

type M3 = [[f32; 3]; 3];

fn mat_mul(a: &M3, b: &M3) -> M3 {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

fn transpose(a: &M3) -> M3 {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = a[j][i];
        }
    }
    m
}

/// `preprocessCUDA` for particle `id`: near-plane cull, Σ from scale and rotation, the EWA 2D
/// covariance with the trainer's low-pass, conic, the tiles it is drawn in, SH colour.
fn preprocess(scene: &Scene, id: usize, camera: &Camera, options: &Options) -> Option<Projected> {
    let p = &scene.particles[id];
    let r_view = camera.rotation.to_cols_array_2d(); // columns
    let view = |i: usize, j: usize| r_view[j][i];
    let world = p.mean.to_array();
    let center = camera.center().to_array();
    let rel = [0, 1, 2].map(|k| world[k] - center[k]);
    let t: [f32; 3] = [0, 1, 2].map(|i| (0..3).map(|j| view(i, j) * rel[j]).sum());
    // `in_frustum` culls p_view.z <= 0.2; gsplat culls mean_c.z < near_plane (0.01).
    let culled = match options.forward {
        Forward::GsplatClassic { .. } | Forward::GsplatAntialiased { .. } => t[2] < 0.01,
        Forward::Inria | Forward::MipSplatting { .. } => t[2] <= 0.2,
    };
    if culled {
        return None;
    }
    // computeCov3D: Σ = Mᵀ M with M = S R (glm's layout), i.e. R S² Rᵀ.
    let q = p.rotation.normalize();
    let (r, x, y, z) = (q.w, q.x, q.y, q.z);
    let rot: M3 = [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - r * z), 2.0 * (x * z + r * y)],
        [2.0 * (x * y + r * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - r * x)],
        [2.0 * (x * z - r * y), 2.0 * (y * z + r * x), 1.0 - 2.0 * (x * x + y * y)],
    ];
    let mut s = p.scale.to_array();
    let mut opacity = p.opacity;
    if let Some(filter_3d) = options.filter_3d {
        // get_scaling_with_3D_filter and get_opacity_with_3D_filter.
        let f2 = filter_3d[id] * filter_3d[id];
        let det1: f32 = s.iter().map(|v| v * v).product();
        let det2: f32 = s.iter().map(|v| v * v + f2).product();
        opacity *= (det1 / det2).sqrt();
        s = s.map(|v| (v * v + f2).sqrt());
    }
    let rs: M3 = [0, 1, 2].map(|i| [0, 1, 2].map(|j| rot[i][j] * s[j]));
    let sigma = mat_mul(&rs, &transpose(&rs));
    // computeCov2D, with 3DGS's clamp of x/z and y/z to 1.3 tan(fov / 2).
    let (fx, fy) = (camera.fx, camera.fy);
    let lim_x = 1.3 * (0.5 * camera.width as f32) / fx;
    let lim_y = 1.3 * (0.5 * camera.height as f32) / fy;
    let tx = (t[0] / t[2]).clamp(-lim_x, lim_x) * t[2];
    let ty = (t[1] / t[2]).clamp(-lim_y, lim_y) * t[2];
    let j: M3 = [[fx / t[2], 0.0, -(fx * tx) / (t[2] * t[2])], [0.0, fy / t[2], -(fy * ty) / (t[2] * t[2])], [0.0; 3]];
    let w: M3 = [0, 1, 2].map(|i| [0, 1, 2].map(|k| view(i, k)));
    let jw = mat_mul(&j, &w);
    let cov = mat_mul(&mat_mul(&jw, &sigma), &transpose(&jw));
    let ([a, b, c], coef) = options.forward.low_pass(cov[0][0], cov[0][1], cov[1][1]);
    let det = a * c - b * b;
    if det == 0.0 {
        return None;
    }
    let conic = [c / det, -b / det, a / det];
    let mean = [fx * t[0] / t[2] + camera.cx, fy * t[1] / t[2] + camera.cy];
    let opacity = opacity * coef;
    let grid = [camera.width.div_ceil(16) as i32, camera.height.div_ceil(16) as i32];
    let tiles = match options.forward {
        Forward::GsplatClassic { .. } | Forward::GsplatAntialiased { .. } => gsplat_tiles(mean, [a, c], opacity, grid)?,
        Forward::Inria | Forward::MipSplatting { .. } => get_rect(mean, [a, b, c], grid)?,
    };
    let dir = normalize(rel);
    let rgb = color_from_sh(&p.sh.to_array().map(|v| v.to_array()), scene.sh_degree, dir);
    Some(Projected { depth: t[2], id, mean, conic, tiles, opacity, rgb })
}

/// `preprocessCUDA`'s radius ⌈3 √max(λ₁, λ₂)⌉ and `getRect`'s tiles around the mean in 3DGS's
/// pixel coordinates (centre at i, so mean − ½ here), with its integer arithmetic; `None` when
/// it touches no tile.
fn get_rect(mean: [f32; 2], [a, b, c]: [f32; 3], grid: [i32; 2]) -> Option<[i32; 4]> {
    let det = a * c - b * b;
    let mid = 0.5 * (a + c);
    let lambda1 = mid + (mid * mid - det).max(0.1).sqrt();
    let lambda2 = mid - (mid * mid - det).max(0.1).sqrt();
    let radius = (3.0 * lambda1.max(lambda2).sqrt()).ceil() as i32;
    let p = [mean[0] - 0.5, mean[1] - 0.5];
    let lo = |k: usize| (((p[k] - radius as f32) / 16.0) as i32).clamp(0, grid[k]);
    let hi = |k: usize| (((p[k] + radius as f32 + 15.0) / 16.0) as i32).clamp(0, grid[k]);
    let rect = [lo(0), lo(1), hi(0), hi(1)];
    ((rect[2] - rect[0]) * (rect[3] - rect[1]) != 0).then_some(rect)
}

/// gsplat's `projection_ewa_3dgs_fused` bounds (radius ⌈extend √Σ′_ii⌉ per axis) and
/// `isect_tiles`' AABB tile range [⌊m/16 − r/16⌋, ⌈m/16 + r/16⌉); `None` when the splat is
/// culled (opacity below 1/255, no tile).
fn gsplat_tiles(mean: [f32; 2], [a, c]: [f32; 2], opacity: f32, grid: [i32; 2]) -> Option<[i32; 4]> {
    const ALPHA_THRESHOLD: f32 = 1.0 / 255.0;
    if opacity < ALPHA_THRESHOLD {
        return None;
    }
    let extend = 3.33f32.min((2.0 * (opacity / ALPHA_THRESHOLD).ln()).sqrt());
    let radius = [(extend * a.sqrt()).ceil(), (extend * c.sqrt()).ceil()];
    let lo = |k: usize| ((mean[k] / 16.0 - radius[k] / 16.0).floor() as i32).clamp(0, grid[k]);
    let hi = |k: usize| ((mean[k] / 16.0 + radius[k] / 16.0).ceil() as i32).clamp(0, grid[k]);
    let rect = [lo(0), lo(1), hi(0), hi(1)];
    (rect[0] < rect[2] && rect[1] < rect[3]).then_some(rect)
}

fn normalize(v: [f32; 3]) -> [f32; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / n)
}

/// `computeColorFromSH`: the real SH basis of degrees 0–3 along the direction from the camera
/// centre to the mean, + 0.5, clamped at 0. The constants are written with the digits 3DGS
/// publishes (`SH_C0` … `SH_C3`); f32 rounds them.
#[allow(clippy::excessive_precision)]
fn color_from_sh(sh: &[[f32; 3]; 16], degree: u8, dir: [f32; 3]) -> [f32; 3] {
    const C0: f32 = 0.28209479177387814;
    const C1: f32 = 0.4886025119029199;
    const C2: [f32; 5] =
        [1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396];
    const C3: [f32; 7] = [
        -0.5900435899266435,
        2.890611442640554,
        -0.4570457994644658,
        0.3731763325901154,
        -0.4570457994644658,
        1.445305721320277,
        -0.5900435899266435,
    ];
    let [x, y, z] = dir;
    let (xx, yy, zz, xy, yz, xz) = (x * x, y * y, z * z, x * y, y * z, x * z);
    let mut basis = vec![C0];
    if degree >= 1 {
        basis.extend([-C1 * y, C1 * z, -C1 * x]);
    }
    if degree >= 2 {
        basis.extend([C2[0] * xy, C2[1] * yz, C2[2] * (2.0 * zz - xx - yy), C2[3] * xz, C2[4] * (xx - yy)]);
    }
    if degree >= 3 {
        basis.extend([
            C3[0] * y * (3.0 * xx - yy),
            C3[1] * xy * z,
            C3[2] * y * (4.0 * zz - xx - yy),
            C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
            C3[4] * x * (4.0 * zz - xx - yy),
            C3[5] * z * (xx - yy),
            C3[6] * x * (xx - 3.0 * yy),
        ]);
    }
    [0, 1, 2].map(|k| (basis.iter().zip(sh).map(|(b, c)| b * c[k]).sum::<f32>() + 0.5).max(0.0))
}
