//! Camera in the OpenCV convention (x right, y down, z forward), as COLMAP and 3DGS use: a
//! pinhole, or one of COLMAP's distorted, fisheye and equirectangular lenses ([`Lens`]).

use crate::hit::Ray;
pub use crate::lens::{Distortion, Lens};
use crate::particle::Aabb;
use glam::{Mat3, Vec2, Vec3};
use thiserror::Error;

/// Why a camera cannot be built.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum CameraError {
    /// Width or height is zero or too large to address.
    #[error("image size {width}×{height} is invalid: each side must be in 1..={max}")]
    Size {
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
        /// Largest side accepted.
        max: u32,
    },
    /// A focal length or principal point is not a positive finite number.
    #[error("intrinsics are invalid: {0}")]
    Intrinsics(String),
    /// The pose is not a finite rigid transform.
    #[error("pose is invalid: {0}")]
    Pose(String),
    /// A renderer that projects through the pinhole was given another lens.
    #[error(
        "{renderer} cannot see through {lens}, only through a pinhole: render it with a ray-tracing method (exact, for one), which traces each pixel's ray through the lens"
    )]
    NotPinhole {
        /// Who refuses.
        renderer: &'static str,
        /// The lens, in words.
        lens: &'static str,
    },
    /// A trainer's undistortion does not apply to the lens ([`crate::undistort`]).
    #[error("{trainer}'s undistortion cannot make a pinhole of this camera: {why}")]
    Undistort {
        /// Whose undistortion.
        trainer: &'static str,
        /// Why not.
        why: String,
    },
}

/// The vertical field of view, in degrees, of a look-at camera that names none and of the
/// camera that frames a scene (the CLI's `--fov`, a world's `[camera]`, Python's
/// `Camera.look_at`).
pub const DEFAULT_FOV_Y: f32 = 50.0;

/// Largest image side accepted (a 16K image; larger is certainly a mistake).
pub const MAX_IMAGE_SIDE: u32 = 16_384;

/// A camera: intrinsics in pixels, a lens (the pinhole unless a camera model says otherwise)
/// and a world-to-camera rigid pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f32,
    /// Focal length along y, pixels.
    pub fy: f32,
    /// Principal point x, pixels (pixel i covers [i, i + 1)).
    pub cx: f32,
    /// Principal point y, pixels.
    pub cy: f32,
    /// World-to-camera rotation: x_cam = R x_world + t.
    pub rotation: Mat3,
    /// World-to-camera translation t.
    pub translation: Vec3,
    /// How directions map to the image: the pinhole, or a COLMAP camera model's lens (the
    /// distortion acts on normalised coordinates, so it does not change with the resolution).
    pub lens: Lens,
}

impl Camera {
    /// A camera from intrinsics and a world-to-camera pose, validated.
    #[allow(clippy::too_many_arguments)]
    pub fn from_intrinsics(
        width: u32,
        height: u32,
        fx: f32,
        fy: f32,
        cx: f32,
        cy: f32,
        world_to_camera_rotation: Mat3,
        world_to_camera_translation: Vec3,
    ) -> Result<Self, CameraError> {
        let cam = Self {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            rotation: world_to_camera_rotation,
            translation: world_to_camera_translation,
            lens: Lens::Pinhole,
        };
        cam.validate()?;
        Ok(cam)
    }

    /// The same camera with `lens`, validated.
    pub fn with_lens(self, lens: Lens) -> Result<Self, CameraError> {
        let cam = Self { lens, ..self };
        cam.validate()?;
        Ok(cam)
    }

    /// Whether its lens is the pinhole, which the splatting methods and the oracle's culling
    /// assume.
    pub fn is_pinhole(&self) -> bool {
        self.lens == Lens::Pinhole
    }

    /// Refuse any lens but the pinhole for `renderer`, which projects through it.
    pub fn require_pinhole(&self, renderer: &'static str) -> Result<(), CameraError> {
        if self.is_pinhole() { Ok(()) } else { Err(CameraError::NotPinhole { renderer, lens: self.lens.describe() }) }
    }

    /// A camera at `eye` looking at `target`, with `up` the world's up direction and `fov_y`
    /// the vertical field of view in degrees; principal point at the image centre.
    pub fn look_at(
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        fov_y_degrees: f32,
        width: u32,
        height: u32,
    ) -> Result<Self, CameraError> {
        for (name, v) in [("eye", eye), ("target", target), ("up", up)] {
            if !v.is_finite() {
                return Err(CameraError::Pose(format!("{name} {v} is not finite")));
            }
        }
        let forward =
            (target - eye).try_normalize().ok_or_else(|| CameraError::Pose("eye and target coincide".into()))?;
        let right = forward
            .cross(up)
            .try_normalize()
            .ok_or_else(|| CameraError::Pose("up is parallel to the view direction".into()))?;
        let down = forward.cross(right);
        if !(fov_y_degrees > 0.0 && fov_y_degrees < 179.0) {
            return Err(CameraError::Intrinsics(format!("field of view {fov_y_degrees}° is outside (0, 179)")));
        }
        let fy = 0.5 * height as f32 / (0.5 * fov_y_degrees.to_radians()).tan();
        // Rows of the world-to-camera rotation are the camera axes in world space.
        let rotation = Mat3::from_cols(right, down, forward).transpose();
        Self::from_intrinsics(
            width,
            height,
            fy,
            fy,
            0.5 * width as f32,
            0.5 * height as f32,
            rotation,
            -(rotation * eye),
        )
    }

    /// A camera that frames `bounds` from the default direction (from +z, or +x when `up` is
    /// along z, lifted 0.35 along `up`) with the default vertical field of view
    /// ([`DEFAULT_FOV_Y`]).
    pub fn framing(bounds: &Aabb, up: Vec3, width: u32, height: u32) -> Result<Self, CameraError> {
        let up = up.try_normalize().ok_or_else(|| CameraError::Pose("up is zero".into()))?;
        if bounds.is_empty() || !bounds.min.is_finite() || !bounds.max.is_finite() {
            return Self::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, up, DEFAULT_FOV_Y, width, height);
        }
        let fov_y = DEFAULT_FOV_Y;
        let aspect = width as f32 / height.max(1) as f32;
        let half_fov_y = 0.5 * fov_y.to_radians();
        let half_fov_x = (half_fov_y.tan() * aspect).atan();
        let half_fov = half_fov_y.min(half_fov_x);
        let radius = (0.5 * (bounds.max - bounds.min).length()).max(1e-3);
        let distance = radius / half_fov.sin();
        let side = if up.z.abs() > 0.9 { Vec3::X } else { Vec3::Z };
        let dir = (side - side.dot(up) * up + 0.35 * up).normalize();
        let center = bounds.center();
        Self::look_at(center + distance * dir, center, up, fov_y, width, height)
    }

    /// Check sizes, intrinsics and pose.
    pub fn validate(&self) -> Result<(), CameraError> {
        if self.width == 0 || self.height == 0 || self.width > MAX_IMAGE_SIDE || self.height > MAX_IMAGE_SIDE {
            return Err(CameraError::Size { width: self.width, height: self.height, max: MAX_IMAGE_SIDE });
        }
        for (name, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(CameraError::Intrinsics(format!("{name} = {v} must be positive")));
            }
        }
        for (name, v) in [("cx", self.cx), ("cy", self.cy)] {
            if !v.is_finite() {
                return Err(CameraError::Intrinsics(format!("{name} = {v} must be finite")));
            }
        }
        if !self.lens.is_finite() {
            return Err(CameraError::Intrinsics(format!("a distortion coefficient is not finite: {:?}", self.lens)));
        }
        if !self.rotation.is_finite() || !self.translation.is_finite() {
            return Err(CameraError::Pose("rotation or translation is not finite".into()));
        }
        let r = self.rotation;
        let err = (r * r.transpose() - Mat3::IDENTITY).to_cols_array().iter().fold(0.0f32, |m, v| m.max(v.abs()));
        if err > 1e-3 || r.determinant() < 0.0 {
            return Err(CameraError::Pose(format!(
                "rotation is not a proper rotation (‖R Rᵀ − I‖∞ = {err:.2e}, det = {:.3})",
                r.determinant()
            )));
        }
        Ok(())
    }

    /// The same view at another resolution: focal lengths and principal point scale with the
    /// image sides.
    pub fn rescaled(&self, width: u32, height: u32) -> Result<Self, CameraError> {
        let (sx, sy) = (width as f32 / self.width as f32, height as f32 / self.height as f32);
        let cam =
            Self { width, height, fx: self.fx * sx, fy: self.fy * sy, cx: self.cx * sx, cy: self.cy * sy, ..*self };
        cam.validate()?;
        Ok(cam)
    }

    /// The camera of its images downscaled by `factor`, as gsplat's COLMAP parser (`data_factor`)
    /// and Nerfstudio's dataparser (`downscale_factor`) take an `images_F/` folder: K divided by
    /// F, the sides floored (W // F). [`Camera::rescaled`] scales K with the sides instead (3DGS's
    /// `-r`, which keeps the field of view), which differs where F does not divide them.
    pub fn downscaled(&self, factor: u32) -> Result<Self, CameraError> {
        if factor == 0 {
            return Err(CameraError::Intrinsics("a downscale factor of 0".into()));
        }
        let f = factor as f32;
        let (width, height) = (self.width / factor, self.height / factor);
        let cam = Self { width, height, fx: self.fx / f, fy: self.fy / f, cx: self.cx / f, cy: self.cy / f, ..*self };
        cam.validate()?;
        Ok(cam)
    }

    /// The window [x0, x0 + width) × [y0, y0 + height) of this camera's image as a camera of
    /// its own: same rays for the same pixels, principal point shifted.
    pub fn crop(&self, x0: u32, y0: u32, width: u32, height: u32) -> Result<Self, CameraError> {
        let cam = Self { width, height, cx: self.cx - x0 as f32, cy: self.cy - y0 as f32, ..*self };
        cam.validate()?;
        Ok(cam)
    }

    /// Camera centre in world space, −Rᵀ t.
    pub fn center(&self) -> Vec3 {
        -(self.rotation.transpose() * self.translation)
    }

    /// Forward axis (camera +z) in world space.
    pub fn forward(&self) -> Vec3 {
        self.rotation.row(2)
    }

    /// Up in world space: camera −y (the image's rows run down, as in OpenCV and COLMAP).
    pub fn up(&self) -> Vec3 {
        -self.rotation.row(1)
    }

    /// The world up a set of views agrees on: the mean of their [`Camera::up`], normalised;
    /// `None` without views or when they cancel out. Captures are filmed mostly upright, so
    /// this is the `up` to frame a capture with (about −y for COLMAP reconstructions).
    pub fn mean_up(views: &[Camera]) -> Option<Vec3> {
        let sum: Vec3 = views.iter().map(Camera::up).sum();
        (sum.length() > 0.1 * views.len() as f32).then(|| sum.normalize())
    }

    /// World point to camera space.
    pub fn to_camera(&self, world: Vec3) -> Vec3 {
        self.rotation * world + self.translation
    }

    /// Camera-space point to continuous pixel coordinates (pixel i covers [i, i + 1)) through
    /// the pinhole, whatever the lens: the splatting methods' projection, which refuse other
    /// lenses ([`Camera::project`] is the lens's).
    pub fn project_camera(&self, p: Vec3) -> Vec2 {
        Vec2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy)
    }

    /// Camera-space point to continuous pixel coordinates through the lens (COLMAP's
    /// `ImgFromCam`), in double precision; `None` where the lens does not see it.
    pub fn project(&self, p: glam::DVec3) -> Option<glam::DVec2> {
        if self.lens == Lens::Equirectangular {
            let f = Lens::equirectangular_position(p)?;
            return Some(f * glam::DVec2::new(f64::from(self.width), f64::from(self.height)));
        }
        let x = self.lens.project(p)?;
        Some(glam::DVec2::new(
            f64::from(self.fx) * x.x + f64::from(self.cx),
            f64::from(self.fy) * x.y + f64::from(self.cy),
        ))
    }

    /// The camera-space direction of continuous pixel position `p` (COLMAP's `CamFromImg`, to
    /// the whole sphere): for the pinhole ((p_x − c_x) / f_x, (p_y − c_y) / f_y, 1); through
    /// another lens a unit vector, the distortion inverted to [`crate::lens::UNDISTORT_TOLERANCE`].
    pub fn direction(&self, p: Vec2) -> Vec3 {
        let normalised = || {
            let (x, y) = (f64::from(p.x - self.cx) / f64::from(self.fx), f64::from(p.y - self.cy) / f64::from(self.fy));
            glam::DVec2::new(x, y)
        };
        match self.lens {
            Lens::Pinhole => Vec3::new((p.x - self.cx) / self.fx, (p.y - self.cy) / self.fy, 1.0),
            Lens::Equirectangular => {
                let size = glam::DVec2::new(f64::from(self.width), f64::from(self.height));
                Lens::equirectangular(p.as_dvec2() / size).as_vec3()
            }
            lens => lens.unproject(normalised()).0.as_vec3(),
        }
    }

    /// The ray through pixel (x, y) at sub-pixel position `offset` ∈ [0, 1)²; (0.5, 0.5) is the
    /// pixel centre. The direction is unit length and the view direction is the camera's forward.
    pub fn ray(&self, x: u32, y: u32, offset: Vec2) -> Ray {
        let d_cam = self.direction(Vec2::new(x as f32 + offset.x, y as f32 + offset.y));
        let dir = (self.rotation.transpose() * d_cam).normalize();
        Ray { view: self.forward(), ..Ray::new(self.center(), dir) }
    }

    /// The smallest cosine between a ray through the image and the view axis: the least over
    /// the image border's corners and edge midpoints (where a pinhole's and a COLMAP lens's
    /// rays lie farthest off axis).
    pub fn min_view_cos(&self) -> f32 {
        let (w, h) = (self.width as f32, self.height as f32);
        let border =
            [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h), (0.5 * w, 0.0), (0.5 * w, h), (0.0, 0.5 * h), (w, 0.5 * h)];
        border.iter().map(|&(x, y)| self.direction(Vec2::new(x, y)).normalize().z).fold(1.0, f32::min)
    }

    /// The ray through the centre of pixel (x, y).
    pub fn pixel_ray(&self, x: u32, y: u32) -> Ray {
        self.ray(x, y, Vec2::splat(0.5))
    }

    /// The ray of a thin lens (depth of field): through pixel (x, y) at sub-pixel `offset`, from
    /// the point `lens` ∈ [0, 1)² of a lens of radius `aperture` (concentric disk mapping) in the
    /// camera's z = 0 plane toward the point the pinhole ray meets the plane in focus, at depth
    /// `focus_distance` along the camera's axis. Points at that depth are sharp; the ray is the
    /// pinhole's when `aperture` is 0.
    pub fn lens_ray(&self, x: u32, y: u32, offset: Vec2, aperture: f32, focus_distance: f32, lens: Vec2) -> Ray {
        let pinhole = self.ray(x, y, offset);
        if aperture <= 0.0 {
            return pinhole;
        }
        // The point in focus: at depth `focus_distance` along the axis, or at that distance
        // along a ray that does not look forward (a fisheye's past 90°).
        let d = self.direction(Vec2::new(x as f32 + offset.x, y as f32 + offset.y));
        let focus = focus_distance * if d.z > 0.0 { d / d.z } else { d.normalize() };
        let on_lens = (aperture * crate::lighting::concentric_disk(lens)).extend(0.0);
        let to_world = self.rotation.transpose();
        let origin = to_world * (on_lens - self.translation);
        let dir = (to_world * (focus - on_lens)).normalize();
        Ray { origin, dir, ..pinhole }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn look_at_follows_opencv_axes() {
        let cam = Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y, 60.0, 64, 48).unwrap();
        assert_relative_eq!(cam.forward().z, -1.0, epsilon = 1e-6);
        assert_relative_eq!(cam.center().z, 5.0, epsilon = 1e-5);
        // A point above the target (world +y) appears in the upper half (smaller pixel y).
        let p = cam.project_camera(cam.to_camera(Vec3::new(0.0, 1.0, 0.0)));
        assert!(p.y < 24.0);
        // A point to the right (+x, seen from +z) appears right of centre.
        let p = cam.project_camera(cam.to_camera(Vec3::new(1.0, 0.0, 0.0)));
        assert!(p.x > 32.0);
    }

    #[test]
    fn mean_up_is_the_up_the_views_were_framed_with() {
        let up = Vec3::new(0.1, -1.0, 0.2).normalize();
        let views: Vec<_> = [Vec3::new(0.0, 0.0, 5.0), Vec3::new(4.0, -1.0, 2.0), Vec3::new(-3.0, 0.5, -4.0)]
            .map(|eye| Camera::look_at(eye, Vec3::ZERO, up, 50.0, 64, 48).unwrap())
            .to_vec();
        // Each view's up is the world up made orthogonal to its forward axis; their mean tilts
        // back towards it.
        assert!(Camera::mean_up(&views).unwrap().dot(up) > 0.95);
        for v in &views {
            assert_relative_eq!(v.up().dot(v.forward()), 0.0, epsilon = 1e-5);
            let above = v.project_camera(v.to_camera(v.center() + 5.0 * v.forward() + v.up()));
            assert!(above.y < 24.0, "camera up is drawn above the centre row");
        }
        assert_eq!(Camera::mean_up(&[]), None);
    }

    #[test]
    fn centre_ray_projects_back_to_its_pixel() {
        let cam = Camera::look_at(Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.1, 0.0, -0.2), Vec3::Y, 45.0, 40, 30).unwrap();
        let ray = cam.pixel_ray(7, 21);
        let p = cam.project_camera(cam.to_camera(ray.at(3.0)));
        assert_relative_eq!(p.x, 7.5, epsilon = 1e-3);
        assert_relative_eq!(p.y, 21.5, epsilon = 1e-3);
    }

    #[test]
    fn rescale_keeps_the_view() {
        let cam = Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y, 60.0, 64, 48).unwrap();
        let big = cam.rescaled(128, 96).unwrap();
        let a = cam.pixel_ray(0, 0).dir;
        let b = big.ray(0, 0, Vec2::ZERO).dir;
        let c = cam.ray(0, 0, Vec2::ZERO).dir;
        assert_relative_eq!(b.dot(c), 1.0, epsilon = 1e-6);
        assert!(a.dot(c) < 1.0);
    }

    #[test]
    fn crop_keeps_the_rays_of_its_pixels() {
        let cam = Camera::look_at(Vec3::new(1.0, 2.0, 3.0), Vec3::ZERO, Vec3::Y, 45.0, 40, 30).unwrap();
        let crop = cam.crop(10, 5, 8, 6).unwrap();
        assert!(crop.pixel_ray(3, 4).dir.abs_diff_eq(cam.pixel_ray(13, 9).dir, 1e-6));
    }

    #[test]
    fn bad_cameras_are_refused() {
        assert!(Camera::look_at(Vec3::ZERO, Vec3::ZERO, Vec3::Y, 60.0, 4, 4).is_err());
        assert!(Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Z, 60.0, 4, 4).is_err());
        assert!(Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, 60.0, 0, 4).is_err());
        assert!(Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, 60.0, 100_000, 4).is_err());
        // A point that is not finite is named as such (a NaN eye read as "eye and target coincide").
        let nan = Vec3::new(0.0, f32::NAN, 0.0);
        for (name, [eye, target, up]) in [
            ("eye", [nan, Vec3::ZERO, Vec3::Y]),
            ("target", [Vec3::Z, nan, Vec3::Y]),
            ("up", [Vec3::Z, Vec3::ZERO, nan]),
        ] {
            let e = Camera::look_at(eye, target, up, 60.0, 4, 4).unwrap_err().to_string();
            assert!(e.contains(&format!("{name} [0, NaN, 0] is not finite")), "{e}");
        }
        let far = Vec3::new(0.0, 0.0, f32::INFINITY);
        let e = Camera::look_at(far, Vec3::ZERO, Vec3::Y, 60.0, 4, 4).unwrap_err().to_string();
        assert!(e.contains("eye [0, 0, inf] is not finite"), "{e}");
    }
}
