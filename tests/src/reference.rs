//! Independent reference of the exact renderer, in f64, for SH degree 0 scenes.
//!
//! It shares no code with `splat-core`'s math: Σ is built from the quaternion with the 3DGS
//! formula, inverted with the adjugate, and the hit is found by minimising the quadratic
//! (x − μ)ᵀ Σ⁻¹ (x − μ) along the ray directly in world space.

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
