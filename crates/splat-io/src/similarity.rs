//! Similarities between worlds: the one home of a map x ↦ s R x + t, how it moves a camera, and
//! how it is read from a file.
//!
//! A trainer may train its splats in a world of its own, which its exported splats keep, while
//! the capture's cameras stay in the world they were reconstructed in. Nerfstudio saves its map
//! (`dataparser_transforms.json`, [`crate::transforms::Dataparser`]); gsplat saves none
//! ([`crate::gsplat_world`] finds it from the capture). Any other map between a camera file's
//! world and the splats' can be given as a 4 × 4 (or 3 × 4) matrix [s R | t] ([`read`]), such as
//! gsplat's `parser.transform` saved with `numpy.save` or `numpy.savetxt`.

use glam::{DMat3, DVec3};
use splat_core::Camera;
use std::path::Path;

/// A similarity x ↦ s R x + t.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Similarity {
    /// s > 0.
    pub scale: f64,
    /// R, a rotation.
    pub rotation: DMat3,
    /// t.
    pub translation: DVec3,
}

/// A camera's pose: camera-to-world rotation and centre.
pub type Pose = (DMat3, DVec3);

/// How far from orthonormal a rotation read from a file may be: ‖R Rᵀ − I‖∞ (files hold
/// rotations rounded to f32 or printed to 8 digits).
const ORTHONORMAL: f64 = 1e-5;

impl Similarity {
    /// x ↦ x.
    pub const IDENTITY: Self = Self { scale: 1.0, rotation: DMat3::IDENTITY, translation: DVec3::ZERO };

    /// A rotation about the origin.
    pub fn rotation(rotation: DMat3) -> Self {
        Self { scale: 1.0, rotation, translation: DVec3::ZERO }
    }

    /// The image of the point `x`.
    pub fn point(&self, x: DVec3) -> DVec3 {
        self.scale * (self.rotation * x) + self.translation
    }

    /// `next` applied after `self`.
    pub fn then(self, next: Self) -> Self {
        Self {
            scale: next.scale * self.scale,
            rotation: next.rotation * self.rotation,
            translation: next.point(self.translation),
        }
    }

    /// The map back: x ↦ s⁻¹ Rᵀ (x − t).
    pub fn inverse(self) -> Self {
        let rotation = self.rotation.transpose();
        Self { scale: 1.0 / self.scale, rotation, translation: -(rotation * self.translation) / self.scale }
    }

    /// A camera's pose moved: the centre mapped, the axes turned (the scale divided out of the
    /// rotation, as gsplat's `transform_cameras` and Nerfstudio's dataparser do).
    pub fn pose(&self, (world_from_camera, centre): Pose) -> Pose {
        (self.rotation * world_from_camera, self.point(centre))
    }

    /// `camera` (its intrinsics and lens kept) at the pose `pose` moved by this map, checked as a
    /// camera.
    pub fn camera(&self, camera: &Camera, pose: Pose) -> Result<Camera, splat_core::camera::CameraError> {
        let (world_from_camera, centre) = self.pose(pose);
        let camera_from_world = world_from_camera.transpose();
        let rotation = camera_from_world.as_mat3();
        let moved = Camera { rotation, translation: (-(camera_from_world * centre)).as_vec3(), ..*camera };
        moved.validate().map(|()| moved)
    }

    /// The map of a 3 × 4 or 4 × 4 matrix `m` (its last row 0, 0, 0, 1) named `name`: [R | t]
    /// where `rigid`, else [s R | t] with s the cube root of the 3 × 3 part's determinant.
    /// Anything else (a reflection, a shear, unequal scales along the axes) is refused.
    pub fn from_rows(m: &[Vec<f64>], name: &str, rigid: bool) -> Result<Self, String> {
        let (linear, translation) = affine_rows(m, name)?;
        let determinant = linear.determinant();
        if !(determinant.is_finite() && determinant > 0.0) {
            let what = if determinant < 0.0 { "a mirror" } else { "flat" };
            return Err(format!("{name}'s 3 × 3 part has determinant {determinant:.3e}: it is {what}, not a turn"));
        }
        let scale = if rigid { 1.0 } else { determinant.cbrt() };
        let rotation = linear / scale;
        let off = (rotation * rotation.transpose() - DMat3::IDENTITY)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |a, v| a.max(v.abs()));
        if off > ORTHONORMAL || rotation.determinant() < 0.0 {
            let what = if rigid { String::new() } else { format!(" times one scale (R = the part / {scale:.6})") };
            return Err(format!("{name}'s 3 × 3 part is not a rotation{what}: ‖R Rᵀ − I‖∞ = {off:.1e}"));
        }
        Ok(Self { scale, rotation, translation })
    }
}

/// The pose of `camera`: its camera-to-world rotation Rᵀ and its centre −Rᵀ t, in f64.
pub fn pose_of(camera: &Camera) -> Pose {
    let world_from_camera = camera.rotation.as_dmat3().transpose();
    (world_from_camera, -(world_from_camera * camera.translation.as_dvec3()))
}

/// The 3 × 3 part and the last column of a 3 × 4 or 4 × 4 matrix `m` named `name` (its last
/// row 0, 0, 0, 1), every value finite.
pub(crate) fn affine_rows(m: &[Vec<f64>], name: &str) -> Result<(DMat3, DVec3), String> {
    let lengths: Vec<usize> = m.iter().map(Vec::len).collect();
    if !(m.len() == 3 || m.len() == 4) || lengths.iter().any(|&n| n != 4) {
        return Err(format!("{name} is {} rows of {lengths:?} values, not 4 × 4 (or 3 × 4)", m.len()));
    }
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return Err(format!("{name} has a value that is not finite"));
    }
    if m.len() == 4 && m[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(format!("{name}'s last row is {:?}, not [0, 0, 0, 1]", m[3]));
    }
    let linear = DMat3::from_cols_array_2d(&[0, 1, 2].map(|col| [m[0][col], m[1][col], m[2][col]]));
    Ok((linear, DVec3::new(m[0][3], m[1][3], m[2][3])))
}

/// Read a similarity [s R | t] from `path`: a `.npy` of a 4 × 4 or 3 × 4 array (f8 or f4, as
/// `numpy.save` writes it), or text holding its 16 or 12 numbers row by row (as `numpy.savetxt`
/// writes it; commas and brackets are read as spaces, so a JSON list of rows reads too).
pub fn read(path: &Path) -> Result<Similarity, crate::Error> {
    let bytes = crate::read_file(path)?;
    parse(&bytes).map_err(|m| crate::Error::new(path, crate::ErrorKind::WorldTransform(m)))
}

/// [`read`] of a file's bytes.
pub fn parse(bytes: &[u8]) -> Result<Similarity, String> {
    let values = if bytes.starts_with(b"\x93NUMPY") { npy_values(bytes)? } else { text_values(bytes)? };
    let rows: Vec<Vec<f64>> = values.chunks(4).map(<[f64]>::to_vec).collect();
    if !(values.len() == 12 || values.len() == 16) {
        return Err(format!("it holds {} numbers, not the 16 of a 4 × 4 matrix (or the 12 of a 3 × 4)", values.len()));
    }
    Similarity::from_rows(&rows, "the matrix", false)
}

/// The numbers of a text file, separated by white space, commas or brackets.
fn text_values(bytes: &[u8]) -> Result<Vec<f64>, String> {
    let text = std::str::from_utf8(bytes).map_err(|_| "it is neither a .npy file nor text".to_string())?;
    if text.trim_start().starts_with('{') {
        return Err("it is a JSON object, not a matrix (a Nerfstudio run's dataparser_transforms.json is given as \
                    its dataparser transforms)"
            .into());
    }
    let separator = |c: char| c.is_whitespace() || matches!(c, ',' | '[' | ']');
    let word = |w: &str| w.parse::<f64>().map_err(|_| format!("'{w}' is not a number"));
    text.split(separator).filter(|w| !w.is_empty()).map(word).collect()
}

/// The values of a `.npy` of little-endian f8 or f4 in C order, of shape (4, 4) or (3, 4).
fn npy_values(bytes: &[u8]) -> Result<Vec<f64>, String> {
    let (header, body) = crate::image::npy_header(bytes)?;
    let width = match () {
        _ if header.contains("'descr': '<f8'") => 8,
        _ if header.contains("'descr': '<f4'") => 4,
        _ => return Err(format!("only little-endian f8 or f4 is read, header: {}", header.trim())),
    };
    if !header.contains("'fortran_order': False") {
        return Err(format!("only C order is read, header: {}", header.trim()));
    }
    let count = match () {
        _ if header.contains("'shape': (4, 4)") => 16,
        _ if header.contains("'shape': (3, 4)") => 12,
        _ => return Err(format!("the array is not 4 × 4 (or 3 × 4), header: {}", header.trim())),
    };
    if body.len() != count * width {
        return Err(format!("its data has {} bytes, not the {} of {count} numbers", body.len(), count * width));
    }
    let value = |b: &[u8]| match width {
        8 => f64::from_le_bytes(b.try_into().expect("8 bytes")),
        _ => f64::from(f32::from_le_bytes(b.try_into().expect("4 bytes"))),
    };
    Ok(body.chunks_exact(width).map(value).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn turned() -> Similarity {
        let rotation = glam::DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 2.0);
        Similarity { scale: 2.5, rotation: DMat3::from_quat(rotation), translation: DVec3::new(1.0, -2.0, 0.5) }
    }

    fn rows(s: &Similarity) -> Vec<Vec<f64>> {
        let m = s.scale * s.rotation;
        (0..3).map(|r| vec![m.row(r).x, m.row(r).y, m.row(r).z, s.translation[r]]).collect()
    }

    #[test]
    fn a_similarity_then_its_inverse_is_the_identity() {
        let s = turned();
        let x = DVec3::new(0.2, 3.0, -1.0);
        assert!((s.inverse().point(s.point(x)) - x).length() < 1e-12);
        assert!(s.then(s.inverse()).rotation.abs_diff_eq(DMat3::IDENTITY, 1e-12));
        assert!((s.then(turned()).point(x) - s.point(s.point(x))).length() < 1e-12);
    }

    #[test]
    fn every_file_form_of_a_matrix_reads_the_same_map() {
        let s = turned();
        let m = rows(&s);
        let text: String = m.iter().map(|r| format!("{:e} {:e} {:e} {:e}\n", r[0], r[1], r[2], r[3])).collect();
        let with_last = format!("{text}0 0 0 1\n");
        let json = serde_json::to_string(&m).unwrap();
        let mut npy = Vec::new();
        let header = "{'descr': '<f8', 'fortran_order': False, 'shape': (3, 4), }";
        npy.extend_from_slice(b"\x93NUMPY\x01\x00");
        let padded = format!("{header:<117}\n");
        npy.extend_from_slice(&(padded.len() as u16).to_le_bytes());
        npy.extend_from_slice(padded.as_bytes());
        m.iter().flatten().for_each(|v| npy.extend_from_slice(&v.to_le_bytes()));
        for (form, bytes) in
            [("text", text.as_bytes()), ("4 × 4", with_last.as_bytes()), ("json", json.as_bytes()), ("npy", &npy)]
        {
            let read = parse(bytes).unwrap_or_else(|e| panic!("{form}: {e}"));
            assert!((read.scale - s.scale).abs() < 1e-12, "{form}: {read:?}");
            assert!(read.rotation.abs_diff_eq(s.rotation, 1e-12), "{form}: {read:?}");
            assert_eq!(read.translation, s.translation, "{form}");
        }
    }

    #[test]
    fn matrices_that_are_not_similarities_are_refused_by_what_they_are() {
        let refused = |text: &str| parse(text.as_bytes()).unwrap_err();
        assert!(refused("1 0 0 0  0 1 0 0  0 0 -1 0").contains("a mirror"));
        assert!(refused("2 0 0 0  0 1 0 0  0 0 1 0").contains("not a rotation times one scale"));
        assert!(refused("0 0 0 0  0 0 0 0  0 0 0 0").contains("flat"));
        assert!(refused("1 0 0 0  0 1 0 0  0 0 1 0  0 0 1 1").contains("last row"));
        assert!(refused("1 0 0 0  0 1 0 0  0 0 1").contains("11 numbers"));
        assert!(refused("1 0 0 0  0 1 0 0  0 0 1 x").contains("'x' is not a number"));
        assert!(refused("1 0 0 0  0 1 0 0  0 0 1 nan").contains("not finite"));
        assert!(refused("{\"transform\": [], \"scale\": 1}").contains("a JSON object, not a matrix"));
    }
}
