//! The viewer's camera: an orbit about a target (drag to turn, wheel to dolly, right drag to
//! pan) that also flies (W A S D, Q E), turned into a pinhole [`Camera`] for each frame.

use splat_core::Camera;
use splat_core::glam::{Mat3, Vec3};

/// An orbit camera: the eye at `distance` from `target`, in the direction given by `yaw` about
/// `up` and `pitch` above the plane normal to it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Orbit {
    /// The point looked at and turned about.
    pub target: Vec3,
    /// Eye to target.
    pub distance: f32,
    /// Angle about `up`, radians.
    pub yaw: f32,
    /// Elevation above the plane normal to `up`, radians (kept inside ±89°).
    pub pitch: f32,
    /// The world's up (unit).
    pub up: Vec3,
    /// Vertical field of view, degrees.
    pub fov_y: f32,
}

/// Largest elevation: the view never looks straight along `up`.
const MAX_PITCH: f32 = 89.0 * std::f32::consts::PI / 180.0;

impl Orbit {
    /// The orbit whose camera looks like `camera` (pose and vertical field of view), turning
    /// about the point `distance` ahead of it, with the camera's own up.
    pub fn from_camera(camera: &Camera, distance: f32) -> Self {
        let up = -camera.rotation.row(1);
        let forward = camera.forward();
        let (a, b) = basis(up);
        let back = -forward;
        Self {
            target: camera.center() + distance * forward,
            distance,
            yaw: back.dot(b).atan2(back.dot(a)),
            pitch: back.dot(up).clamp(-1.0, 1.0).asin().clamp(-MAX_PITCH, MAX_PITCH),
            up,
            fov_y: 2.0 * (0.5 * camera.height as f32 / camera.fy).atan().to_degrees(),
        }
    }

    /// Unit vector from the target to the eye.
    fn back(&self) -> Vec3 {
        let (a, b) = basis(self.up);
        self.pitch.cos() * (self.yaw.cos() * a + self.yaw.sin() * b) + self.pitch.sin() * self.up
    }

    /// The eye.
    pub fn eye(&self) -> Vec3 {
        self.target + self.distance * self.back()
    }

    /// The camera of a `width` × `height` view.
    pub fn camera(&self, width: u32, height: u32) -> Camera {
        Camera::look_at(self.eye(), self.target, self.up, self.fov_y, width, height)
            .expect("the pitch stays off the up axis and the distance positive")
    }

    /// Turn by a drag of (`dx`, `dy`) window points.
    pub fn rotate(&mut self, dx: f32, dy: f32) {
        self.yaw -= 0.008 * dx;
        self.pitch = (self.pitch + 0.008 * dy).clamp(-MAX_PITCH, MAX_PITCH);
    }

    /// Move the target in the image plane by a drag of (`dx`, `dy`) points of a view
    /// `height` points high, so that what is under the cursor stays there.
    pub fn pan(&mut self, dx: f32, dy: f32, height: f32) {
        let (right, down, _) = self.axes();
        let per_point = 2.0 * self.distance * (0.5 * self.fov_y.to_radians()).tan() / height.max(1.0);
        self.target -= per_point * (dx * right + dy * down);
    }

    /// Dolly: `steps` wheel notches towards the target (negative: away).
    pub fn zoom(&mut self, steps: f32) {
        self.distance = (self.distance * (-0.1 * steps).exp()).clamp(1e-4, 1e6);
    }

    /// Fly: move eye and target by `forward`, `right` and `up` scene units.
    pub fn fly(&mut self, forward: f32, right: f32, up: f32) {
        let (r, _, f) = self.axes();
        self.target += forward * f + right * r + up * self.up;
    }

    /// Right, down and forward of the view.
    fn axes(&self) -> (Vec3, Vec3, Vec3) {
        let camera: Mat3 = self.camera(2, 2).rotation;
        (camera.row(0), camera.row(1), camera.row(2))
    }
}

/// Two unit vectors that make a right-handed frame with `up`.
fn basis(up: Vec3) -> (Vec3, Vec3) {
    let a = up.any_orthonormal_vector();
    (a, up.cross(a))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-4
    }

    #[test]
    fn an_orbit_made_from_a_camera_gives_that_camera_back() {
        let camera =
            Camera::look_at(Vec3::new(1.0, -2.0, 4.0), Vec3::new(0.0, 0.5, 0.0), -Vec3::Y, 40.0, 64, 48).unwrap();
        let orbit = Orbit::from_camera(&camera, 3.0);
        let again = orbit.camera(64, 48);
        assert!(close(again.center(), camera.center()), "{} vs {}", again.center(), camera.center());
        assert!(close(again.forward(), camera.forward()));
        assert!(close(again.rotation.row(1), camera.rotation.row(1)));
        assert!((again.fy - camera.fy).abs() < 1e-3);
    }

    #[test]
    fn turning_keeps_the_distance_and_panning_keeps_the_direction() {
        let mut orbit =
            Orbit::from_camera(&Camera::look_at(Vec3::Z * 5.0, Vec3::ZERO, Vec3::Y, 50.0, 8, 8).unwrap(), 5.0);
        let before = orbit;
        orbit.rotate(120.0, -40.0);
        assert!(((orbit.eye() - orbit.target).length() - 5.0).abs() < 1e-4);
        assert!(!close(orbit.eye(), before.eye()));
        let forward = orbit.camera(8, 8).forward();
        orbit.pan(30.0, 10.0, 400.0);
        assert!(close(orbit.camera(8, 8).forward(), forward));
        orbit.rotate(0.0, 1e6);
        assert!(orbit.pitch <= MAX_PITCH);
        orbit.zoom(3.0);
        assert!(orbit.distance < 5.0);
        let target = orbit.target;
        orbit.fly(1.0, 0.0, 0.0);
        assert!(((orbit.target - target).length() - 1.0).abs() < 1e-5);
    }
}
