//! What a person steers besides the panel's settings: the orbit camera, which loaded view is
//! shown, and what the keys do. One model for the window and the page of `splat serve`, each
//! turning its own input events into [`Action`]s.

use crate::camera::Orbit;
use crate::load::SceneInfo;
use crate::settings::Settings;
use crate::worker::{Target, Worker};
use splat_core::Camera;
use splat_core::glam::Vec3;
use splat_gpu::DisplayMode;

/// One step of navigation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Action {
    /// A left drag of (dx, dy) points: turn about the target.
    Rotate(f32, f32),
    /// A right or middle drag of (dx, dy) points over a view `height` points high: pan.
    Pan(f32, f32, f32),
    /// Wheel notches towards the target (negative: away).
    Zoom(f32),
    /// Fly by (forward, right, up) in units of the scene's radius.
    Fly(f32, f32, f32),
    /// Show the loaded view this many steps on (wrapping).
    StepView(isize),
    /// Back to the opening view.
    Home,
    /// A new accumulation of the same view.
    Restart,
    /// Pause or resume.
    TogglePause,
    /// Show this quantity.
    Show(DisplayMode),
}

/// The key bindings, as the window's panel, the page and the README list them.
pub const KEY_BINDINGS: &[&str] = &[
    "left drag: orbit",
    "right or middle drag: pan",
    "wheel: dolly",
    "W A S D: fly forward, left, back, right",
    "Q E: fly down, up (Shift: faster)",
    "N / P: next / previous loaded view",
    "F: back to the opening view (--camera-index, else the scene's framing)",
    "R: restart the accumulation",
    "Space: pause",
    "1 2 3 4: colour, depth, normals, variance",
];

/// The keys that fly, in the order of [`fly_action`]'s `down`: W S A D E Q.
pub const FLY_KEYS: [char; 6] = ['w', 's', 'a', 'd', 'e', 'q'];

/// The keys that jump ([`key_action`]), by name.
pub const JUMP_KEYS: [&str; 9] = ["N", "P", "F", "R", "Space", "1", "2", "3", "4"];

/// The action of a key that jumps (a key's name, case ignored: "N", "space", "1"), if any.
pub fn key_action(key: &str) -> Option<Action> {
    let modes = DisplayMode::ALL;
    match key.to_ascii_lowercase().as_str() {
        "n" => Some(Action::StepView(1)),
        "p" => Some(Action::StepView(-1)),
        "f" => Some(Action::Home),
        "r" => Some(Action::Restart),
        "space" | " " => Some(Action::TogglePause),
        digit @ ("1" | "2" | "3" | "4") => Some(Action::Show(modes[digit.parse::<usize>().ok()? - 1])),
        _ => None,
    }
}

/// (forward, right, up) of the fly keys held `down` (in [`FLY_KEYS`] order), each −1, 0 or 1.
fn fly_direction(down: [bool; 6]) -> (f32, f32, f32) {
    let axis = |plus: bool, minus: bool| f32::from(u8::from(plus)) - f32::from(u8::from(minus));
    (axis(down[0], down[1]), axis(down[3], down[2]), axis(down[4], down[5]))
}

/// The flight of the fly keys held `down` (in [`FLY_KEYS`] order) for `seconds`: half the
/// scene's radius a second, two with `fast` (Shift); `None` when none is held.
pub fn fly_action(down: [bool; 6], fast: bool, seconds: f32) -> Option<Action> {
    let speed = if fast { 2.0 } else { 0.5 } * seconds;
    let (forward, right, up) = fly_direction(down);
    (forward != 0.0 || right != 0.0 || up != 0.0).then_some(Action::Fly(speed * forward, speed * right, speed * up))
}

/// The camera's state: the orbit, the loaded view it still shows, and where "home" is.
pub struct Navigation {
    scene: SceneInfo,
    orbit: Orbit,
    /// The loaded view shown while the camera has not moved from it.
    view: Option<usize>,
    /// The view F returns to (`--camera-index`) and the world's up for framing.
    home: usize,
    up: Vec3,
    /// Bumped by [`Action::Restart`]: a new accumulation of the same view.
    pub restart: u64,
}

impl Navigation {
    /// Open on loaded view `camera_index` (or the scene's own camera, or a framing with world
    /// up `up`).
    pub fn new(scene: SceneInfo, camera_index: usize, up: Vec3) -> Self {
        let (view, orbit) = initial_view(&scene, camera_index, up);
        Self { scene, orbit, view, home: camera_index, up, restart: 0 }
    }

    /// What is known of the scene.
    pub fn scene(&self) -> &SceneInfo {
        &self.scene
    }

    /// The orbit camera.
    pub fn orbit(&self) -> &Orbit {
        &self.orbit
    }

    /// Which loaded view is shown, `None` once the camera has moved.
    pub fn view(&self) -> Option<usize> {
        self.view
    }

    /// Apply `action`; pausing and the display mode are `settings`'.
    pub fn act(&mut self, action: Action, settings: &mut Settings) {
        let radius = self.scene.sphere().1;
        match action {
            Action::Rotate(dx, dy) => self.moved(|o| o.rotate(dx, dy)),
            Action::Pan(dx, dy, height) => self.moved(|o| o.pan(dx, dy, height)),
            Action::Zoom(steps) => self.moved(|o| o.zoom(steps)),
            Action::Fly(forward, right, up) => self.moved(|o| o.fly(radius * forward, radius * right, radius * up)),
            Action::StepView(by) => self.step_view(by),
            Action::Home => (self.view, self.orbit) = initial_view(&self.scene, self.home, self.up),
            Action::Restart => self.restart += 1,
            Action::TogglePause => settings.paused = !settings.paused,
            Action::Show(mode) => settings.display.mode = mode,
        }
    }

    /// Move the orbit: a camera that moved leaves the loaded view.
    fn moved(&mut self, change: impl FnOnce(&mut Orbit)) {
        let before = self.orbit;
        change(&mut self.orbit);
        if self.orbit != before {
            self.view = None;
        }
    }

    /// Show the loaded view `by` steps after the current one (wrapping).
    fn step_view(&mut self, by: isize) {
        let n = self.scene.views.len();
        if n == 0 {
            return;
        }
        let current = self.view.unwrap_or(0) as isize;
        let i = (current + by).rem_euclid(n as isize) as usize;
        (self.view, self.orbit) = initial_view(&self.scene, i, self.up);
    }

    /// The camera of a view that fills `size` (points), rendered at `pixels_per_point`: the
    /// loaded view itself at its own aspect, letterboxed, until the camera moves, the orbit's
    /// after; with the size (points) of the part of `size` it fills.
    pub fn camera(&self, size: [f32; 2], pixels_per_point: f32) -> (Camera, [f32; 2]) {
        let pixels = |points: f32| ((points * pixels_per_point).round() as u32).max(8);
        let file = self.view.and_then(|i| self.scene.views.get(i).map(|v| v.1).or(self.scene.camera));
        if let Some(file) = file {
            let aspect = file.width as f32 / file.height as f32;
            let shown =
                if size[0] / size[1] > aspect { [size[1] * aspect, size[1]] } else { [size[0], size[0] / aspect] };
            return (file.rescaled(pixels(shown[0]), pixels(shown[1])).unwrap_or(file), shown);
        }
        (self.orbit.camera(pixels(size[0]), pixels(size[1])), size)
    }

    /// Depths shown white and black: the scene's central sphere seen from `camera`.
    fn depth_range(&self, camera: &Camera) -> (f32, f32) {
        let (center, radius) = self.scene.sphere();
        let d = (center - camera.center()).length();
        ((d - radius).max(0.0), d + radius)
    }

    /// Post the job of `camera` and `settings` into `target` with this navigation's restart
    /// generation ([`Worker::post`]: nothing when none of them changed), the display's depth
    /// range set for `camera` first.
    pub fn post(&self, worker: &mut Worker, camera: Camera, settings: &mut Settings, target: impl FnOnce() -> Target) {
        (settings.display.depth_near, settings.display.depth_far) = self.depth_range(&camera);
        worker.post(camera, settings, self.restart, target);
    }
}

/// The first view: loaded view `camera_index` when there are loaded views (clamped), else
/// the file's camera, else a framing of the scene with world up `up`; and the orbit about the
/// scene's centre that starts there.
fn initial_view(loaded: &SceneInfo, camera_index: usize, up: Vec3) -> (Option<usize>, Orbit) {
    let (center, radius) = loaded.sphere();
    let (view, camera) = if loaded.views.is_empty() {
        let camera = loaded.camera.unwrap_or_else(|| {
            Camera::framing(&loaded.bounds, up, 16, 10).expect("framing a finite box gives a camera")
        });
        (loaded.camera.map(|_| 0), camera)
    } else {
        let i = camera_index.min(loaded.views.len() - 1);
        (Some(i), loaded.views[i].1)
    };
    let distance = (center - camera.center()).dot(camera.forward()).max(0.1 * radius);
    (view, Orbit::from_camera(&camera, distance))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_key_that_jumps_has_its_action() {
        assert_eq!(key_action("N"), Some(Action::StepView(1)));
        assert_eq!(key_action("space"), Some(Action::TogglePause));
        assert_eq!(key_action(" "), Some(Action::TogglePause));
        for (digit, mode) in ["1", "2", "3", "4"].into_iter().zip(DisplayMode::ALL) {
            assert_eq!(key_action(digit), Some(Action::Show(mode)));
        }
        assert_eq!(key_action("5"), None);
        assert_eq!(key_action("w"), None, "flying is held, not pressed");
        assert!(JUMP_KEYS.iter().all(|k| key_action(k).is_some()), "a jump key without an action");
        assert_eq!(fly_direction([true, false, false, true, false, true]), (1.0, 1.0, -1.0));
        assert_eq!(fly_action([false; 6], true, 0.1), None);
        assert_eq!(fly_action([true, false, false, false, false, false], true, 0.1), Some(Action::Fly(0.2, 0.0, 0.0)));
    }
}
