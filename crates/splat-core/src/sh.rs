//! View-dependent colour from spherical harmonics, degrees 0–3, exactly as 3DGS evaluates it
//! (`eval_sh` with its constants, then +0.5 and a clamp at 0).

use glam::Vec3;

/// Band 0 constant Y₀⁰ = 1 / (2√π).
pub const SH_C0: f32 = 0.282_094_8;
/// Band 1 constant.
pub const SH_C1: f32 = 0.488_602_52;
/// Band 2 constants.
pub const SH_C2: [f32; 5] = [1.092_548_4, -1.092_548_4, 0.315_391_57, -1.092_548_4, 0.546_274_2];
/// Band 3 constants.
pub const SH_C3: [f32; 7] =
    [-0.590_043_6, 2.890_611_4, -0.457_045_8, 0.373_176_34, -0.457_045_8, 1.445_305_7, -0.590_043_6];

/// How a renderer stores the SH coefficients: f32 as read (the default), IEEE half precision
/// rounded to nearest even (vk_gaussian_splatting's fp16 SH format), or 8 bits a channel
/// (vk_gaussian_splatting's uint8 formats): a half or a quarter of the memory of the GPU's
/// largest scene array, and a colour error the README measures. The CPU reads the same stored
/// values ([`eval_stored`]), so both backends render the same image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum ShStorage {
    /// 32-bit floats.
    #[default]
    F32,
    /// 16-bit floats.
    F16,
    /// 8-bit fixed point ([`u8_quantize`]).
    U8,
}

impl ShStorage {
    /// Every storage, by name.
    pub const ALL: [ShStorage; 3] = [ShStorage::F32, ShStorage::F16, ShStorage::U8];

    /// Its name on the command line and from Python.
    pub fn name(self) -> &'static str {
        match self {
            ShStorage::F32 => "f32",
            ShStorage::F16 => "f16",
            ShStorage::U8 => "u8",
        }
    }

    /// One line on what it stores.
    pub fn describe(self) -> &'static str {
        match self {
            ShStorage::F32 => "32-bit floats, as read",
            ShStorage::F16 => "16-bit floats: half the GPU's SH memory, the colours rounded",
            ShStorage::U8 => {
                "8 bits a channel (vk_gaussian_splatting's uint8): a quarter of the GPU's SH memory, the base colour clamped to [0, 1] and higher coefficients to [-1, 1]"
            }
        }
    }

    /// The storage named `name`.
    pub fn parse(name: &str) -> Option<ShStorage> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// Coefficient `k` (0 the DC term) as stored and read back: `c` itself in f32, each channel
    /// rounded to the nearest half (ties to even; beyond ±65504, ±∞) in f16, quantized to 8 bits
    /// and decoded in u8 ([`u8_quantize`], [`u8_decode`]).
    pub fn load(self, c: Vec3, k: usize) -> Vec3 {
        match self {
            ShStorage::F32 => c,
            ShStorage::F16 => c.to_array().map(|x| half::f16::from_f32(x).to_f32()).into(),
            ShStorage::U8 => u8_decode(u8_quantize(c, k), k),
        }
    }
}

/// The 8-bit channels of coefficient `k` as vk_gaussian_splatting's uint8 formats store them
/// (`toUint8` in its splat_set_vk.cpp: round(clamp(255 (v − lo) / (hi − lo), 0, 255))): the DC
/// term as the base colour 0.5 + C₀ c in [0, 1] (its RGBA buffer), the higher coefficients in
/// [−1, 1] (its SH buffer).
pub fn u8_quantize(c: Vec3, k: usize) -> [u8; 3] {
    let normalized = if k == 0 { Vec3::splat(0.5) + SH_C0 * c } else { 0.5 * (c + Vec3::ONE) };
    normalized.to_array().map(|x| (x * 255.0).round().clamp(0.0, 255.0) as u8)
}

/// The scale of an 8-bit channel q: the coefficient is (2q − 255) × this, one rounding, so the
/// CPU and the GPU decode it to the same float (vk divides by 255 and subtracts, which a GPU may
/// fuse): 1 / (510 C₀) for the DC term, 1 / 255 for the others.
pub fn u8_scale(k: usize) -> f32 {
    if k == 0 { (1.0 / (510.0 * f64::from(SH_C0))) as f32 } else { (1.0f64 / 255.0) as f32 }
}

/// Coefficient `k` of its 8-bit channels `q` ([`u8_quantize`]): (2q − 255) [`u8_scale`]`(k)`.
pub fn u8_decode(q: [u8; 3], k: usize) -> Vec3 {
    Vec3::from(q.map(|q| (2.0 * f32::from(q) - 255.0) * u8_scale(k)))
}

/// [`eval`] of the coefficients as `storage` holds them ([`ShStorage::load`]).
pub fn eval_stored(sh: &[Vec3], degree: u8, dir: Vec3, storage: ShStorage) -> Vec3 {
    match storage {
        ShStorage::F32 => eval(sh, degree, dir),
        ShStorage::F16 | ShStorage::U8 => {
            let mut stored = [Vec3::ZERO; 16];
            let n = sh.len().min(16);
            for (k, (s, &c)) in stored.iter_mut().zip(&sh[..n]).enumerate() {
                *s = storage.load(c, k);
            }
            eval(&stored[..n], degree, dir)
        }
    }
}

/// Colour of a particle seen along the unit direction `dir` (from the viewer toward the
/// particle): Σ SH basis × coefficients + 0.5, clamped at 0. Coefficients past `degree` are
/// ignored, and so are bands that `sh` does not hold (a DC-only [`crate::particle::Sh`] is one
/// coefficient long: its higher bands are zero).
pub fn eval(sh: &[Vec3], degree: u8, dir: Vec3) -> Vec3 {
    let held = match sh.len() {
        0 => return Vec3::splat(0.5),
        1..=3 => 0,
        4..=8 => 1,
        9..=15 => 2,
        _ => 3,
    };
    let degree = degree.min(held);
    let mut c = SH_C0 * sh[0];
    if degree >= 1 {
        let (x, y, z) = (dir.x, dir.y, dir.z);
        c += -SH_C1 * y * sh[1] + SH_C1 * z * sh[2] - SH_C1 * x * sh[3];
        if degree >= 2 {
            let (xx, yy, zz) = (x * x, y * y, z * z);
            let (xy, yz, xz) = (x * y, y * z, x * z);
            c += SH_C2[0] * xy * sh[4]
                + SH_C2[1] * yz * sh[5]
                + SH_C2[2] * (2.0 * zz - xx - yy) * sh[6]
                + SH_C2[3] * xz * sh[7]
                + SH_C2[4] * (xx - yy) * sh[8];
            if degree >= 3 {
                c += SH_C3[0] * y * (3.0 * xx - yy) * sh[9]
                    + SH_C3[1] * xy * z * sh[10]
                    + SH_C3[2] * y * (4.0 * zz - xx - yy) * sh[11]
                    + SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * sh[12]
                    + SH_C3[4] * x * (4.0 * zz - xx - yy) * sh[13]
                    + SH_C3[5] * z * (xx - yy) * sh[14]
                    + SH_C3[6] * x * (xx - 3.0 * yy) * sh[15];
            }
        }
    }
    (c + Vec3::splat(0.5)).max(Vec3::ZERO)
}

/// DC coefficient whose degree-0 colour is `rgb`: (rgb − 0.5) / C₀.
pub fn rgb_to_dc(rgb: Vec3) -> Vec3 {
    (rgb - Vec3::splat(0.5)) / SH_C0
}

/// The 16 real SH basis functions of [`eval`] at unit direction `d` (with 3DGS's signs), in f64.
fn basis(d: glam::DVec3) -> [f64; 16] {
    let (x, y, z) = (d.x, d.y, d.z);
    let (c1, c2, c3) = (f64::from(SH_C1), SH_C2.map(f64::from), SH_C3.map(f64::from));
    let (xx, yy, zz) = (x * x, y * y, z * z);
    [
        f64::from(SH_C0),
        -c1 * y,
        c1 * z,
        -c1 * x,
        c2[0] * x * y,
        c2[1] * y * z,
        c2[2] * (2.0 * zz - xx - yy),
        c2[3] * x * z,
        c2[4] * (xx - yy),
        c3[0] * y * (3.0 * xx - yy),
        c3[1] * x * y * z,
        c3[2] * y * (4.0 * zz - xx - yy),
        c3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
        c3[4] * x * (4.0 * zz - xx - yy),
        c3[5] * z * (xx - yy),
        c3[6] * x * (xx - 3.0 * yy),
    ]
}

/// The linear map of SH coefficients under a rotation R of the particle: the rotated
/// coefficients c' give the colour c'(d) = c(R⁻¹ d) in every direction d.
///
/// Each band is closed under rotation, so c' is found exactly by least squares on sampled
/// directions: with Y(d) the basis row, Y(dᵢ) c' = Y(R⁻¹ dᵢ) c for 64 spiral directions, solved
/// once per rotation through the normal equations.
#[derive(Clone, Debug, PartialEq)]
pub struct Rotation {
    m: [[f64; 16]; 16],
}

impl Rotation {
    /// The map for rotation `r`.
    pub fn new(r: glam::Quat) -> Self {
        let inv = r.as_dquat().inverse();
        let n = 64;
        let dirs = (0..n).map(|i| {
            // A Fibonacci spiral: directions spread over the sphere.
            let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
            let phi = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
            let r = (1.0 - z * z).sqrt();
            glam::DVec3::new(r * phi.cos(), r * phi.sin(), z)
        });
        let mut ata = [[0.0f64; 16]; 16];
        let mut atb = [[0.0f64; 16]; 16];
        for d in dirs {
            let (a, b) = (basis(d), basis(inv * d));
            for i in 0..16 {
                for j in 0..16 {
                    ata[i][j] += a[i] * a[j];
                    atb[i][j] += a[i] * b[j];
                }
            }
        }
        Self { m: solve(ata, atb) }
    }

    /// The rotated coefficients of `sh`.
    pub fn apply(&self, sh: &[Vec3; 16]) -> [Vec3; 16] {
        std::array::from_fn(|i| {
            let c = (0..16).fold(glam::DVec3::ZERO, |acc, j| acc + self.m[i][j] * sh[j].as_dvec3());
            c.as_vec3()
        })
    }
}

/// X with A X = B for a symmetric positive definite A, by Gauss–Jordan elimination with
/// partial pivoting.
fn solve(mut a: [[f64; 16]; 16], mut b: [[f64; 16]; 16]) -> [[f64; 16]; 16] {
    for col in 0..16 {
        let pivot = (col..16).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs())).unwrap_or(col);
        a.swap(col, pivot);
        b.swap(col, pivot);
        let p = a[col][col];
        for k in 0..16 {
            a[col][k] /= p;
            b[col][k] /= p;
        }
        for row in 0..16 {
            if row != col {
                let f = a[row][col];
                for k in 0..16 {
                    a[row][k] -= f * a[col][k];
                    b[row][k] -= f * b[col][k];
                }
            }
        }
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// f16 storage rounds each channel to the nearest half, ties to even (IEEE 754's binary16,
    /// written out here: 11 significant bits), and evaluates the rounded coefficients; f32 is the
    /// plain evaluation.
    #[test]
    fn f16_storage_rounds_each_coefficient_to_the_nearest_half() {
        // 1 + 2⁻¹¹ is halfway between 1 and 1 + 2⁻¹⁰: to even (1); 1 + 3·2⁻¹¹ up to 1 + 2⁻⁹.
        let c = Vec3::new(1.0 + 2f32.powi(-11), 1.0 + 3.0 * 2f32.powi(-11), -0.1);
        let stored = ShStorage::F16.load(c, 1);
        assert_eq!((stored.x, stored.y), (1.0, 1.0 + 2f32.powi(-9)));
        // 0.1 in binary16: 1638 / 2¹⁴ (0.0999755…), the nearest of its neighbours.
        assert_eq!(stored.z, -1638.0 / 16384.0);
        assert_eq!(ShStorage::F32.load(c, 1), c);
        let sh: Vec<Vec3> = (0..16).map(|k| Vec3::new(0.3, -0.2, 0.1) * (k as f32 + 1.0).recip()).collect();
        let dir = Vec3::new(0.48, -0.6, 0.64);
        assert_eq!(eval_stored(&sh, 3, dir, ShStorage::F32), eval(&sh, 3, dir));
        let rounded: Vec<Vec3> = sh.iter().enumerate().map(|(k, &c)| ShStorage::F16.load(c, k)).collect();
        let half = eval_stored(&sh, 3, dir, ShStorage::F16);
        assert_eq!(half, eval(&rounded, 3, dir));
        let error = (half - eval(&sh, 3, dir)).abs().max_element();
        assert!(error > 0.0 && error < 1e-3, "the f16 colour differs by {error}");
        assert_eq!(ShStorage::parse("f16"), Some(ShStorage::F16));
    }

    /// vk_gaussian_splatting's uint8 rule, by hand: a higher coefficient v is round(127.5 (v + 1))
    /// clamped to 0..=255, decoded as (2q − 255) / 255; the DC term goes through the base colour
    /// 0.5 + C₀ c, so 0 stores as 128 and a colour of 1 as 255, decoded to 0.5 / C₀.
    #[test]
    fn u8_storage_quantizes_as_vk_and_decodes_in_one_rounding() {
        let rest = |v: f32| u8_quantize(Vec3::new(v, -v, 2.0 * v), 1);
        assert_eq!(rest(0.0), [128, 128, 128]);
        assert_eq!(rest(1.0), [255, 0, 255]);
        assert_eq!(rest(0.6), [204, 51, 255]); // 203.99…, 51.0…, clamped
        assert_eq!(u8_decode([255, 0, 128], 1), Vec3::new(1.0, -1.0, f32::from_bits(0x3b80_8081)));
        assert_eq!(u8_scale(1).to_bits(), 0x3b80_8081, "1/255 rounded once");
        assert_eq!(u8_quantize(Vec3::ZERO, 0), [128; 3]);
        let white = Vec3::splat(0.5 / SH_C0);
        assert_eq!(u8_quantize(white, 0), [255; 3]);
        assert_eq!(u8_quantize(-white, 0), [0; 3]);
        let stored = ShStorage::U8.load(white, 0);
        assert!((stored - white).abs().max_element() < 1e-6, "{stored}");
        let sh: Vec<Vec3> = (0..16).map(|k| Vec3::new(0.3, -0.2, 0.1) * (k as f32 + 1.0).recip()).collect();
        let dir = Vec3::new(0.48, -0.6, 0.64);
        let loaded: Vec<Vec3> = sh.iter().enumerate().map(|(k, &c)| ShStorage::U8.load(c, k)).collect();
        let byte = eval_stored(&sh, 3, dir, ShStorage::U8);
        assert_eq!(byte, eval(&loaded, 3, dir));
        let error = (byte - eval(&sh, 3, dir)).abs().max_element();
        assert!(error > 0.0 && error < 0.02, "the u8 colour differs by {error}");
        assert_eq!(ShStorage::parse("u8"), Some(ShStorage::U8));
    }

    #[test]
    fn degree_zero_is_dc_plus_half() {
        let mut sh = [Vec3::ZERO; 16];
        sh[0] = Vec3::new(1.0, -0.5, -10.0);
        sh[5] = Vec3::ONE; // ignored at degree 0
        let c = eval(&sh, 0, Vec3::Z);
        assert_relative_eq!(c.x, 0.5 + SH_C0, epsilon = 1e-6);
        assert_relative_eq!(c.y, 0.5 - 0.5 * SH_C0, epsilon = 1e-6);
        assert_eq!(c.z, 0.0, "clamped at 0");
    }

    #[test]
    fn rgb_round_trips_through_dc() {
        let rgb = Vec3::new(0.1, 0.7, 0.95);
        let mut sh = [Vec3::ZERO; 16];
        sh[0] = rgb_to_dc(rgb);
        assert_relative_eq!(eval(&sh, 3, Vec3::X).x, rgb.x, epsilon = 1e-6);
    }

    #[test]
    fn band_one_is_odd_in_direction() {
        let mut sh = [Vec3::ZERO; 16];
        sh[1] = Vec3::splat(0.3);
        sh[2] = Vec3::splat(-0.2);
        sh[3] = Vec3::splat(0.1);
        let d = Vec3::new(0.3, -0.5, 0.8).normalize();
        let a = eval(&sh, 1, d) - Vec3::splat(0.5);
        let b = eval(&sh, 1, -d) - Vec3::splat(0.5);
        assert_relative_eq!(a.x, -b.x, epsilon = 1e-6);
    }

    #[test]
    fn rotated_coefficients_give_the_colour_of_the_rotated_direction() {
        let mut sh = [Vec3::ZERO; 16];
        for (i, c) in sh.iter_mut().enumerate() {
            *c = Vec3::new(0.3 * (i as f32).sin(), 0.2 * (i as f32 * 0.7).cos(), 0.1 * i as f32 / 16.0);
        }
        let r = glam::Quat::from_euler(glam::EulerRot::XYZ, 0.4, -1.1, 2.3);
        let rotated = Rotation::new(r).apply(&sh);
        for d in [Vec3::X, Vec3::new(0.3, -0.5, 0.8).normalize(), Vec3::new(-0.9, 0.1, 0.2).normalize()] {
            let want = eval(&sh, 3, r.inverse() * d);
            let got = eval(&rotated, 3, d);
            assert_relative_eq!(got.x, want.x, epsilon = 1e-5);
            assert_relative_eq!(got.y, want.y, epsilon = 1e-5);
            assert_relative_eq!(got.z, want.z, epsilon = 1e-5);
        }
        // The identity changes nothing, and band 0 never moves.
        let same = Rotation::new(glam::Quat::IDENTITY).apply(&sh);
        assert_relative_eq!(same[7].x, sh[7].x, epsilon = 1e-6);
        assert_relative_eq!(rotated[0].y, sh[0].y, epsilon = 1e-6);
    }

    #[test]
    fn band_three_matches_direct_formula() {
        // Y_3^{-3} term only: C3[0] y (3x² − y²).
        let mut sh = [Vec3::ZERO; 16];
        sh[9] = Vec3::ONE;
        let d = Vec3::new(0.6, 0.0, 0.8);
        assert_relative_eq!(eval(&sh, 3, d).x, 0.5, epsilon = 1e-6);
        let d = Vec3::new(0.0, 1.0, 0.0);
        assert_relative_eq!(eval(&sh, 3, d).x, 0.5 - SH_C3[0], epsilon = 1e-6);
    }
}
