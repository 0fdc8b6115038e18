//! Arrays in and out: shapes checked with messages that name the array, images to and from
//! numpy.

use crate::SplatError;
use glam::Vec3;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use splat_core::particle::{SH_MAX_COEFFS, sh_coeff_count};
use splat_core::undistort::Photo;
use splat_core::{Image, Particle};

/// A shape as Python prints it: `(5, 3)`.
fn shape_text(shape: &[usize]) -> String {
    match shape {
        [one] => format!("({one},)"),
        _ => format!("({})", shape.iter().map(usize::to_string).collect::<Vec<_>>().join(", ")),
    }
}

/// Refuse `name` unless its shape is `expected`.
pub fn check_shape(name: &str, shape: &[usize], expected: &[usize]) -> PyResult<()> {
    if shape == expected {
        return Ok(());
    }
    Err(SplatError::new_err(format!("{name} has shape {}; expected {}", shape_text(shape), shape_text(expected))))
}

/// K of an SH array of shape (N, K, 3): 1, 4, 9 or 16 (degrees 0 to 3).
pub fn sh_coefficients(shape: &[usize], n: usize) -> PyResult<usize> {
    let k = match shape {
        [rows, k, 3] if *rows == n => *k,
        _ => {
            return Err(SplatError::new_err(format!(
                "sh has shape {}; expected ({n}, K, 3) with K = (degree + 1)² = 1, 4, 9 or 16",
                shape_text(shape)
            )));
        }
    };
    if !(0..=3).any(|d| sh_coeff_count(d) == k) {
        return Err(SplatError::new_err(format!(
            "sh has {k} coefficients a colour channel; expected 1, 4, 9 or 16 (SH degree 0 to 3; degree 4's 25 \
             are not rendered: drop the last band, sh[:, :16])"
        )));
    }
    Ok(k)
}

/// The columns of N splats as the Python layer passes them (float32, contiguous, shapes
/// checked): means (N, 3), scales (N, 3), rotations (N, 4) w, x, y, z, opacities (N,), sh
/// (N, k, 3); scales logarithmic and opacities logits where the flags say so.
pub struct Splats<'a> {
    pub means: &'a [f32],
    pub scales: &'a [f32],
    pub rotations: &'a [f32],
    pub opacities: &'a [f32],
    pub sh: &'a [f32],
    pub k: usize,
    pub log_scales: bool,
    pub logit_opacities: bool,
}

impl Splats<'_> {
    /// Splat `i` as the `.ply` reader makes a particle (its activations, in f64), validated;
    /// an error names the splat and what is wrong with it.
    pub fn particle(&self, i: usize) -> Result<Particle, String> {
        let v3 = |a: &[f32]| Vec3::new(a[3 * i], a[3 * i + 1], a[3 * i + 2]);
        let q = &self.rotations[4 * i..4 * i + 4];
        let mean = v3(self.means);
        let bad = |what: String| format!("splat {i}: {what} (mean {mean}, rotation w, x, y, z {q:?})");
        let scale = if self.log_scales {
            let raw = v3(self.scales).to_array().map(f64::from);
            match raw.map(splat_io::ply::scale_from_log) {
                [Some(x), Some(y), Some(z)] => Vec3::new(x, y, z),
                _ => return Err(bad(format!("log scale {raw:?} gives no usable positive scale"))),
            }
        } else {
            v3(self.scales)
        };
        let wxyz = [q[0], q[1], q[2], q[3]].map(f64::from);
        let rotation = splat_io::ply::unit_quaternion(wxyz)
            .ok_or_else(|| bad("the rotation quaternion has zero length".into()))?;
        let o = self.opacities[i];
        let opacity = if self.logit_opacities { splat_io::ply::opacity_from_logit(f64::from(o)) as f32 } else { o };
        let mut coefficients = [Vec3::ZERO; SH_MAX_COEFFS];
        for (j, c) in coefficients.iter_mut().enumerate().take(self.k) {
            let at = 3 * (i * self.k + j);
            *c = Vec3::new(self.sh[at], self.sh[at + 1], self.sh[at + 2]);
        }
        Particle::new(mean, scale, rotation, opacity, coefficients).map_err(|e| bad(e.to_string()))
    }
}

/// The number of rows of a 2-D array `name` of `columns` columns.
pub fn rows(name: &str, shape: &[usize], columns: usize) -> PyResult<usize> {
    match shape {
        [n, c] if *c == columns => Ok(*n),
        shape => Err(SplatError::new_err(format!("{name} has shape {}; expected (N, {columns})", shape_text(shape)))),
    }
}

/// A square matrix of side `N`, rows first, from any nested sequence of numbers (a numpy
/// array of any float dtype, a list of lists, a CPU tensor).
pub fn matrix<const N: usize>(name: &str, value: &Bound<'_, PyAny>) -> PyResult<[[f32; N]; N]> {
    let wrong = || SplatError::new_err(format!("{name}: expected a {N} × {N} matrix of numbers"));
    let rows: Vec<Vec<f64>> = value.extract().map_err(|_| wrong())?;
    let shape: Vec<usize> = std::iter::once(rows.len()).chain(rows.first().map(Vec::len)).collect();
    if rows.len() != N || rows.iter().any(|r| r.len() != N) {
        return Err(SplatError::new_err(format!("{name} has shape {}; expected ({N}, {N})", shape_text(&shape))));
    }
    let mut m = [[0.0; N]; N];
    for (r, row) in rows.iter().enumerate() {
        for (c, &v) in row.iter().enumerate() {
            if !v.is_finite() {
                return Err(SplatError::new_err(format!("{name}[{r}, {c}] is {v}: expected a finite value")));
            }
            m[r][c] = v as f32;
        }
    }
    Ok(m)
}

/// An image from an array of shape (H, W) or (H, W, C) with 1 to 4 channels.
pub fn image_from_array(name: &str, array: &PyReadonlyArrayDyn<'_, f32>) -> PyResult<Image> {
    let (w, h, c) = image_size(name, array.shape())?;
    Image::from_data(w, h, c, array.as_slice()?.to_vec())
        .ok_or_else(|| SplatError::new_err(format!("{name}: the data does not fill {w}×{h}×{c}")))
}

/// An 8-bit photograph from a uint8 array (H, W) or (H, W, C) with 1 to 4 channels, in any
/// memory order (a view such as `image[..., :3]` included).
pub fn photo_from_array(name: &str, value: &Bound<'_, PyAny>) -> PyResult<Photo> {
    let array: PyReadonlyArrayDyn<'_, u8> = value.extract().map_err(|_| {
        SplatError::new_err(format!(
            "{name}: expected a numpy array of uint8 (an 8-bit photograph, (H, W) or (H, W, C)), got {}",
            value.getattr("dtype").map_or_else(|_| value.get_type().to_string(), |d| format!("dtype {d}"))
        ))
    })?;
    let (width, height, channels) = image_size(name, array.shape())?;
    Ok(Photo { width, height, channels, data: array.as_array().iter().copied().collect() })
}

/// Width, height and channels of an image array of `shape`: (H, W) or (H, W, C), 1 to 4
/// channels, none empty.
fn image_size(name: &str, shape: &[usize]) -> PyResult<(u32, u32, u32)> {
    let (h, w, c) = match shape {
        &[h, w] => (h, w, 1),
        &[h, w, c] if (1..=4).contains(&c) => (h, w, c),
        shape => {
            return Err(SplatError::new_err(format!(
                "{name} has shape {}; expected an image (H, W) or (H, W, C) with 1 to 4 channels",
                shape_text(shape)
            )));
        }
    };
    let side = |v: usize| u32::try_from(v).ok().filter(|&v| v > 0);
    let (Some(w), Some(h), Some(c)) = (side(w), side(h), side(c)) else {
        return Err(SplatError::new_err(format!("{name} is empty (shape {})", shape_text(shape))));
    };
    Ok((w, h, c))
}

/// An image as an array (H, W) for one channel, else (H, W, C), without a copy.
pub fn image_to_array(py: Python<'_>, image: Image) -> PyResult<Bound<'_, PyUntypedArray>> {
    let shape = array_shape(image.width(), image.height(), image.channels());
    shaped(py, image.into_data(), &shape)
}

/// A photograph as a uint8 array (H, W) for one channel, else (H, W, C), without a copy.
pub fn photo_to_array(py: Python<'_>, photo: Photo) -> PyResult<Bound<'_, PyUntypedArray>> {
    shaped(py, photo.data, &array_shape(photo.width, photo.height, photo.channels))
}

/// The array shape of a `w` × `h` image of `c` channels: (H, W) for one channel, else (H, W, C).
fn array_shape(w: u32, h: u32, c: u32) -> Vec<usize> {
    let (w, h, c) = (w as usize, h as usize, c as usize);
    if c == 1 { vec![h, w] } else { vec![h, w, c] }
}

/// `data` as an array of `shape` (row-major), without a copy.
pub fn shaped<'py, T: numpy::Element>(
    py: Python<'py>,
    data: Vec<T>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyUntypedArray>> {
    Ok(PyArray1::from_vec(py, data).reshape(shape)?.as_untyped().clone())
}
