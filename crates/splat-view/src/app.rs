//! The window: a side panel of settings, the view with its camera controls, and the status
//! line. Everything that renders happens on the render thread ([`crate::worker`]); the window
//! only posts jobs and shows the texture the thread draws into.

use crate::camera::Orbit;
use crate::load::{Loaded, SceneInfo};
use crate::settings::{Backend, Pipeline, Settings};
use crate::worker::{Job, Status, TEXTURE_FORMAT, Worker};
use eframe::egui::{self, Key, PointerButton, Sense};
use eframe::egui_wgpu;
use splat_core::catalogue::{Limits, Param};
use splat_core::glam::Vec3;
use splat_core::lighting::{Look, Shadows};
use splat_core::normal::NormalMode;
use splat_core::raster::SAMPLE_COUNTS;
use splat_core::raster::{Blend, FragmentDepth, Response, SamplePattern, SplatExtent};
use splat_core::rng::RngScheme;
use splat_core::{Camera, HitDistance};
use splat_core::{MethodId, Parameters};
use splat_gpu::{AccumulationFormat, DisplayMode, GpuContext, wgpu};

/// Where the viewer renders when asked to choose.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendChoice {
    /// The GPU on a hardware adapter; the CPU tracer on a CPU adapter (lavapipe).
    Auto,
    /// The GPU tracer, whatever the adapter (slow on lavapipe).
    Gpu,
    /// The CPU renderers.
    Cpu,
}

/// What the command line sets.
#[derive(Clone, Debug)]
pub struct Options {
    /// Where to render.
    pub backend: BackendChoice,
    /// Index of the first view among the loaded cameras.
    pub camera_index: usize,
    /// The world's up for framing (COLMAP captures: 0,-1,0).
    pub up: Vec3,
    /// Close the window after this many frames of the first view, printing a summary.
    pub quit_after: Option<u32>,
    /// Frames after which the accumulation stops.
    pub max_frames: u32,
}

/// The texture the render thread draws into, registered with the UI renderer.
struct Target {
    texture: wgpu::Texture,
    id: egui::TextureId,
}

/// The viewer's state.
pub struct Viewer {
    scene: SceneInfo,
    orbit: Orbit,
    /// The loaded view shown while the camera has not moved from it.
    view: Option<usize>,
    /// The view F returns to (`--camera-index`) and the world's up for framing.
    home: usize,
    up: Vec3,
    settings: Settings,
    /// Why the panel's GPU choice is what it is (adapter name, or why the CPU renders).
    backend_note: String,
    gpu_available: bool,
    worker: Worker,
    render_state: egui_wgpu::RenderState,
    target: Option<Target>,
    /// Where the view's texture was last drawn in the window, in points.
    shown: Option<egui::Rect>,
    /// The last job posted: its number and what it asked for.
    posted: Option<(u64, Camera, Settings, u64)>,
    /// Bumped by "restart": a new accumulation of the same view.
    restart: u64,
    quit_after: Option<u32>,
    /// A test hook: show no frames/s (its value varies from run to run) so that snapshots are
    /// repeatable.
    pub hide_rate: bool,
}

impl Viewer {
    /// A viewer of `loaded` on the UI's device (`render_state`), waking `egui` when frames
    /// arrive.
    pub fn new(loaded: Loaded, options: &Options, render_state: egui_wgpu::RenderState, egui: egui::Context) -> Self {
        let adapter = render_state.adapter.get_info();
        let hardware = adapter.device_type != wgpu::DeviceType::Cpu;
        let gpu = match options.backend {
            BackendChoice::Cpu => Err(None),
            _ => {
                GpuContext::from_device(&render_state.adapter, render_state.device.clone(), render_state.queue.clone())
                    .map_err(|e| Some(e.to_string()))
            }
        };
        let backend = match (&gpu, options.backend) {
            (Ok(_), BackendChoice::Gpu) => Backend::Gpu,
            (Ok(_), BackendChoice::Auto) if hardware => Backend::Gpu,
            _ => Backend::Cpu,
        };
        let backend_note = match (&gpu, hardware) {
            (Err(None), _) => "--backend cpu: rendering on the CPU".into(),
            (Err(Some(e)), _) => format!("the GPU tracer cannot run here ({e}): rendering on the CPU"),
            (Ok(_), true) => format!("GPU: {}", adapter.name),
            (Ok(_), false) => {
                format!("{} is a CPU Vulkan driver (slow): tracing on the CPU unless GPU is chosen", adapter.name)
            }
        };
        let gpu_available = gpu.is_ok();
        let Loaded { world, info } = loaded;
        let mut settings = Settings::new(info.render, &world.lighting, backend);
        settings.max_frames = options.max_frames;
        let (view, orbit) = initial_view(&info, options.camera_index, options.up);
        let worker = Worker::spawn(world, gpu.ok(), render_state.queue.clone(), move || egui.request_repaint());
        Self {
            scene: info,
            orbit,
            view,
            home: options.camera_index,
            up: options.up,
            settings,
            backend_note,
            gpu_available,
            worker,
            render_state,
            target: None,
            shown: None,
            posted: None,
            restart: 0,
            quit_after: options.quit_after,
            hide_rate: false,
        }
    }

    /// The panel's settings.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Change the settings as the panel would.
    pub fn settings_mut(&mut self) -> &mut Settings {
        &mut self.settings
    }

    /// The render thread's latest status for the posted job, `None` before it has one.
    pub fn status(&self) -> Option<Status> {
        let status = self.worker.status();
        (self.posted.as_ref().map(|p| p.0) == Some(status.job)).then_some(status)
    }

    /// The orbit camera.
    pub fn orbit(&self) -> &Orbit {
        &self.orbit
    }

    /// The camera of the last job posted.
    pub fn camera(&self) -> Option<Camera> {
        self.posted.as_ref().map(|p| p.1)
    }

    /// The texture the view is drawn into.
    pub fn texture(&self) -> Option<&wgpu::Texture> {
        self.target.as_ref().map(|t| &t.texture)
    }

    /// The rectangle of the window (in points) the view's texture was last drawn into.
    pub fn image_rect(&self) -> Option<egui::Rect> {
        self.shown
    }

    /// Which loaded view is shown, `None` once the camera has moved.
    pub fn view(&self) -> Option<usize> {
        self.view
    }

    /// Draw the window's contents and post what they ask for.
    pub fn show(&mut self, ui: &mut egui::Ui) {
        egui::Panel::left("settings").default_size(300.0).show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| self.panel(ui));
        });
        egui::CentralPanel::no_frame().show(ui, |ui| self.viewport(ui));
        if let (Some(n), Some(status)) = (self.quit_after, self.status())
            && (status.frames >= n || status.error.is_some() || status.idle)
        {
            let (w, h) = self.target.as_ref().map_or((0, 0), |t| (t.texture.width(), t.texture.height()));
            match &status.error {
                Some(e) => eprintln!("splat view: {e}"),
                None => println!("splat view: rendered {} frames of {w}×{h} ({})", status.frames, self.backend_note),
            }
            self.quit_after = None;
            ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
        }
    }

    /// The view: the texture, the camera controls and the status line.
    fn viewport(&mut self, ui: &mut egui::Ui) {
        let (rect, response) = ui.allocate_exact_size(ui.available_size(), Sense::click_and_drag());
        self.navigate(ui, &response, rect);
        let ppp = ui.ctx().pixels_per_point();
        let (camera, shown) = self.view_camera(rect, ppp);
        self.ensure_target(camera.width, camera.height);
        let target = self.target.as_ref().expect("just made");
        ui.painter().rect_filled(rect, 0.0, egui::Color32::from_gray(16));
        let uv = egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0));
        ui.painter().image(target.id, shown, uv, egui::Color32::WHITE);
        self.shown = Some(shown);
        self.post(camera);
        self.status_line(ui, rect);
    }

    /// The camera of the view: the loaded view itself (its aspect, letterboxed) until the
    /// camera moves, the orbit's after; with the rectangle of the window it fills.
    fn view_camera(&self, rect: egui::Rect, ppp: f32) -> (Camera, egui::Rect) {
        let scale = self.settings.scale * ppp;
        let pixels = |points: f32| ((points * scale).round() as u32).max(8);
        if let Some(i) = self.view {
            let file = self.scene.views.get(i).map(|v| v.1).or(self.scene.camera);
            if let Some(file) = file {
                let aspect = file.width as f32 / file.height as f32;
                let size = if rect.width() / rect.height() > aspect {
                    egui::vec2(rect.height() * aspect, rect.height())
                } else {
                    egui::vec2(rect.width(), rect.width() / aspect)
                };
                let shown = egui::Rect::from_center_size(rect.center(), size);
                let camera = file.rescaled(pixels(size.x), pixels(size.y)).unwrap_or(file);
                return (camera, shown);
            }
        }
        (self.orbit.camera(pixels(rect.width()), pixels(rect.height())), rect)
    }

    /// A texture of `width` × `height` for the render thread, registered for the UI.
    fn ensure_target(&mut self, width: u32, height: u32) {
        if self.target.as_ref().is_some_and(|t| (t.texture.width(), t.texture.height()) == (width, height)) {
            return;
        }
        let texture = self.render_state.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("splat view"),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: TEXTURE_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_DST
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        let mut renderer = self.render_state.renderer.write();
        let filter = wgpu::FilterMode::Linear;
        let id = match &self.target {
            Some(old) => {
                renderer.update_egui_texture_from_wgpu_texture(&self.render_state.device, &view, filter, old.id);
                old.id
            }
            None => renderer.register_native_texture(&self.render_state.device, &view, filter),
        };
        self.target = Some(Target { texture, id });
    }

    /// Post a job when the camera, the settings or the texture changed.
    fn post(&mut self, camera: Camera) {
        let (near, far) = self.depth_range(&camera);
        self.settings.display.depth_near = near;
        self.settings.display.depth_far = far;
        let unchanged =
            self.posted.as_ref().is_some_and(|(_, c, s, r)| *c == camera && *s == self.settings && *r == self.restart);
        if unchanged {
            return;
        }
        let id = self.posted.as_ref().map_or(1, |p| p.0 + 1);
        let target = self.target.as_ref().expect("made before posting").texture.clone();
        let job = Job { camera, settings: self.settings.clone(), target, generation: self.restart };
        self.worker.submit(id, job);
        self.posted = Some((id, camera, self.settings.clone(), self.restart));
    }

    /// Depths shown white and black: the scene's central sphere seen from the camera.
    fn depth_range(&self, camera: &Camera) -> (f32, f32) {
        let (center, radius) = self.scene.sphere();
        let d = (center - camera.center()).length();
        ((d - radius).max(0.0), d + radius)
    }

    /// Mouse and keys: drag turns, right or middle drag pans, the wheel dollies, W A S D Q E
    /// fly, N and P step through the loaded views, F returns to the opening view, R restarts,
    /// Space pauses, 1–4 choose what is shown.
    fn navigate(&mut self, ui: &egui::Ui, response: &egui::Response, rect: egui::Rect) {
        let before = self.orbit;
        let delta = response.drag_delta();
        if response.dragged_by(PointerButton::Primary) {
            self.orbit.rotate(delta.x, delta.y);
        } else if response.dragged_by(PointerButton::Secondary) || response.dragged_by(PointerButton::Middle) {
            self.orbit.pan(delta.x, delta.y, rect.height());
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta().y);
            if scroll != 0.0 {
                self.orbit.zoom(scroll / 50.0);
            }
        }
        let keys = !ui.ctx().text_edit_focused();
        if keys {
            self.fly(ui);
        }
        if self.orbit != before {
            self.view = None;
        }
        if keys {
            self.keys(ui);
        }
    }

    /// W A S D Q E: move eye and target.
    fn fly(&mut self, ui: &egui::Ui) {
        let (dt, fast, down) = ui.input(|i| {
            let down = [Key::W, Key::S, Key::A, Key::D, Key::E, Key::Q].map(|k| i.key_down(k));
            (i.stable_dt.min(0.1), i.modifiers.shift, down)
        });
        let speed = self.scene.sphere().1 * if fast { 2.0 } else { 0.5 } * dt;
        let axis = |plus: bool, minus: bool| f32::from(u8::from(plus)) - f32::from(u8::from(minus));
        let (forward, right, up) = (axis(down[0], down[1]), axis(down[3], down[2]), axis(down[4], down[5]));
        if forward != 0.0 || right != 0.0 || up != 0.0 {
            self.orbit.fly(speed * forward, speed * right, speed * up);
            ui.ctx().request_repaint();
        }
    }

    /// The keys that jump: views, home, restart, pause, display modes.
    fn keys(&mut self, ui: &egui::Ui) {
        let pressed = ui.input(|i| {
            [Key::N, Key::P, Key::F, Key::R, Key::Space, Key::Num1, Key::Num2, Key::Num3, Key::Num4]
                .map(|k| i.key_pressed(k))
        });
        let [next, previous, home, restart, pause, modes @ ..] = pressed;
        if next || previous {
            self.step_view(if next { 1 } else { -1 });
        }
        if home {
            (self.view, self.orbit) = initial_view(&self.scene, self.home, self.up);
        }
        if restart {
            self.restart += 1;
        }
        if pause {
            self.settings.paused = !self.settings.paused;
        }
        for (mode, chosen) in DisplayMode::ALL.into_iter().zip(modes) {
            if chosen {
                self.settings.display.mode = mode;
            }
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

    /// Frames, rate, RMSE and errors over the top left of the view.
    fn status_line(&self, ui: &egui::Ui, rect: egui::Rect) {
        let status = self.status().unwrap_or_default();
        let mut line = format!("{} frames", status.frames);
        if !self.hide_rate && !status.idle {
            line += &format!(" · {:.1} frames/s", status.frames_per_second);
        }
        if let Some(rmse) = status.rmse {
            line += &format!(" · RMSE vs exact {rmse:.5}");
        }
        if status.idle {
            line += if self.settings.paused { " · paused" } else { " · done" };
        }
        let view = match (self.view, self.view.and_then(|i| self.scene.views.get(i))) {
            (Some(i), Some((name, _))) => format!("view {} of {}: {name}", i + 1, self.scene.views.len()),
            (Some(_), None) => "the scene's camera".into(),
            (None, _) => "free camera".into(),
        };
        let painter = ui.painter();
        let font = egui::FontId::monospace(13.0);
        let at = rect.left_top() + egui::vec2(8.0, 6.0);
        painter.text(at, egui::Align2::LEFT_TOP, &line, font.clone(), egui::Color32::WHITE);
        painter.text(
            at + egui::vec2(0.0, 17.0),
            egui::Align2::LEFT_TOP,
            &view,
            font.clone(),
            egui::Color32::LIGHT_GRAY,
        );
        if let Some(e) = &status.error {
            painter.text(at + egui::vec2(0.0, 34.0), egui::Align2::LEFT_TOP, e, font, egui::Color32::LIGHT_RED);
        }
    }

    /// The side panel.
    fn panel(&mut self, ui: &mut egui::Ui) {
        ui.heading("splat view");
        ui.label(format!("{}: {} splats, SH degree {}", self.scene.name, self.scene.particles, self.scene.sh_degree))
            .on_hover_text(format!("splatting through {}", self.scene.screen_filter.describe()));
        ui.separator();
        self.renderer_section(ui);
        ui.separator();
        self.method_section(ui);
        ui.separator();
        self.scene_section(ui);
        ui.separator();
        self.lighting_section(ui);
        ui.separator();
        self.display_section(ui);
        ui.separator();
        egui::CollapsingHeader::new("keys").show(ui, |ui| {
            for line in KEY_BINDINGS {
                ui.label(*line);
            }
        });
    }

    fn renderer_section(&mut self, ui: &mut egui::Ui) {
        let s = &mut self.settings;
        ui.horizontal(|ui| {
            ui.label("backend");
            ui.add_enabled_ui(self.gpu_available, |ui| ui.radio_value(&mut s.backend, Backend::Gpu, "GPU"));
            ui.radio_value(&mut s.backend, Backend::Cpu, "CPU");
        });
        ui.label(egui::RichText::new(&self.backend_note).small());
        if s.backend == Backend::Gpu && s.pipeline != Pipeline::RayTracing {
            ui.label(egui::RichText::new("splatting renders on the CPU in the viewer").small());
        }
        combo(ui, "pipeline", &mut s.pipeline, &Pipeline::ALL, |p| p.name().to_string());
    }

    fn method_section(&mut self, ui: &mut egui::Ui) {
        let s = &mut self.settings;
        if s.pipeline != Pipeline::RayTracing {
            method_combo(ui, "splatting", &mut s.raster, &Settings::raster_menu());
            for &param in s.raster.entry().params {
                parameter(ui, param, &mut s.params);
            }
        }
        if s.pipeline != Pipeline::Raster {
            let label = if s.pipeline == Pipeline::Hybrid { "secondary method" } else { "method" };
            method_combo(ui, label, &mut s.trace, &Settings::trace_menu());
            for &param in s.trace.entry().params {
                parameter(ui, param, &mut s.params);
            }
        }
        combo(ui, "random numbers", &mut s.rng, &[RngScheme::Hash, RngScheme::Trig], |r| {
            format!("{r:?}").to_lowercase()
        });
        ui.add(egui::DragValue::new(&mut s.seed).prefix("seed "));
        combo(ui, "accumulation", &mut s.accumulation, &AccumulationFormat::ALL, |f| f.name().to_string());
    }

    fn scene_section(&mut self, ui: &mut egui::Ui) {
        let r = &mut self.settings.render;
        combo(ui, "hit distance", &mut r.hit_distance, &HitDistance::ALL, |h| h.name().to_string());
        ui.add(egui::Slider::new(&mut r.kernel.degree, 1..=8).text("kernel degree"));
        ui.add(egui::Slider::new(&mut r.iso_threshold, 0.01..=0.99).text("iso (rays)"));
        ui.add(egui::Slider::new(&mut r.raster_iso_threshold, 0.01..=0.99).text("iso (splats)"));
        combo(ui, "normals", &mut r.normal_mode, &[NormalMode::MaxDensityPlane, NormalMode::KernelEllipsoid], |n| {
            match n {
                NormalMode::MaxDensityPlane => "max-density plane".into(),
                NormalMode::KernelEllipsoid => "kernel ellipsoid".into(),
            }
        });
        let s = &mut self.settings;
        combo(ui, "look", &mut s.look, &[Look::Surface, Look::Volumetric], |l| format!("{l:?}").to_lowercase());
        let shadows = [Shadows::None, Shadows::SORTED, Shadows::Stochastic, Shadows::Exact];
        combo(ui, "shadows", &mut s.shadows, &shadows, |s| match s {
            Shadows::None => "no shadows".into(),
            Shadows::Sorted { .. } => "sorted shadows".into(),
            Shadows::Stochastic => "stochastic shadows".into(),
            _ => "exact shadows".into(),
        });
    }

    /// The world's lights and each splat set's material, edited live (vk_gaussian_splatting's
    /// material and light panels).
    fn lighting_section(&mut self, ui: &mut egui::Ui) {
        let s = &mut self.settings;
        if s.materials.iter().all(|m| m.is_emissive()) && s.lights.is_empty() {
            ui.label(egui::RichText::new("emissive scene: a world file (.toml) gives materials and lights").small());
            return;
        }
        egui::CollapsingHeader::new("lights").default_open(true).show(ui, |ui| {
            if s.lights.is_empty() {
                ui.label(egui::RichText::new("none: a headlight at the camera").small());
            }
            for (i, light) in s.lights.iter_mut().enumerate() {
                ui.horizontal(|ui| {
                    ui.label(format!("{} {i}", light_kind(light)));
                    rgb(ui, &mut light.color);
                    ui.add(
                        egui::DragValue::new(&mut light.intensity).range(0.0..=1e4).speed(0.05).prefix("intensity "),
                    );
                });
                ui.add(egui::Slider::new(&mut light.radius, 0.0..=1.0).text(format!("radius {i}")));
            }
        });
        egui::CollapsingHeader::new("materials").show(ui, |ui| {
            for (i, m) in s.materials.iter_mut().enumerate() {
                ui.label(format!("set {i}"));
                ui.horizontal(|ui| {
                    for (name, colour) in [
                        ("emissive", &mut m.emissive),
                        ("ambient", &mut m.ambient),
                        ("diffuse", &mut m.diffuse),
                        ("specular", &mut m.specular),
                    ] {
                        rgb(ui, colour);
                        ui.label(name);
                    }
                });
                ui.add(
                    egui::Slider::new(&mut m.shininess, 1.0..=512.0).logarithmic(true).text(format!("shininess {i}")),
                );
            }
        });
    }

    fn display_section(&mut self, ui: &mut egui::Ui) {
        let s = &mut self.settings;
        combo(ui, "show", &mut s.display.mode, &DisplayMode::ALL, |m| m.name().to_string());
        if s.display.mode == DisplayMode::Variance {
            ui.add(
                egui::Slider::new(&mut s.display.variance_scale, 0.25..=16.0).logarithmic(true).text("std-dev scale"),
            );
        }
        ui.add(egui::Slider::new(&mut s.scale, 0.125..=1.0).text("render scale"));
        ui.add(egui::DragValue::new(&mut s.max_frames).range(1..=1_000_000).prefix("stop after ").suffix(" frames"));
        ui.checkbox(&mut s.rmse, "RMSE vs exact");
        ui.horizontal(|ui| {
            ui.checkbox(&mut s.paused, "pause");
            if ui.button("restart").clicked() {
                self.restart += 1;
            }
        });
        if !self.scene.views.is_empty() {
            ui.horizontal(|ui| {
                if ui.button("previous view").clicked() {
                    self.step_view(-1);
                }
                if ui.button("next view").clicked() {
                    self.step_view(1);
                }
            });
        }
    }
}

impl eframe::App for Viewer {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.show(ui);
    }
}

/// The key bindings, as the panel and the README list them.
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

/// A colour button editing `colour` (linear RGB, any non-negative value up to 1 per channel).
fn rgb(ui: &mut egui::Ui, colour: &mut Vec3) {
    let mut c = colour.to_array();
    if ui.color_edit_button_rgb(&mut c).changed() {
        *colour = Vec3::from_array(c);
    }
}

fn light_kind(light: &splat_core::lighting::Light) -> &'static str {
    match light.kind {
        splat_core::lighting::LightKind::Point { .. } => "point",
        splat_core::lighting::LightKind::Spot { .. } => "spot",
        splat_core::lighting::LightKind::Directional { .. } => "directional",
    }
}

/// A labelled combo box over `choices`.
/// A menu of the catalogue's methods by name, each with its summary on hover.
fn method_combo(ui: &mut egui::Ui, label: &str, value: &mut MethodId, choices: &[MethodId]) {
    egui::ComboBox::from_label(label).selected_text(value.name()).show_ui(ui, |ui| {
        for &choice in choices {
            ui.selectable_value(value, choice, choice.name()).on_hover_text(choice.entry().summary);
        }
    });
}

/// The widget of one method parameter: a slider over the catalogue's limits for a number, a
/// menu for a choice, a check box for a switch.
fn parameter(ui: &mut egui::Ui, param: Param, p: &mut Parameters) {
    let info = param.info();
    let range = info.limits.map_or(0.0..=1.0, |l: Limits| l.min..=l.slider_max);
    // A slider over the limits; a count moves in whole steps.
    let number = |ui: &mut egui::Ui, value: f64, count: bool| {
        let mut v = value;
        let slider = egui::Slider::new(&mut v, range.clone()).text(info.label);
        ui.add(if count { slider.integer() } else { slider });
        v
    };
    match param {
        Param::K => p.k = number(ui, p.k as f64, true) as usize,
        Param::MaxPasses => p.max_passes = number(ui, f64::from(p.max_passes), true) as u32,
        Param::MinTransmittance => p.min_transmittance = number(ui, f64::from(p.min_transmittance), false) as f32,
        Param::N => p.n = number(ui, f64::from(p.n), true) as u32,
        Param::M => p.m = number(ui, f64::from(p.m), true) as u32,
        Param::Blend => combo(ui, info.label, &mut p.blend, &[Blend::Over, Blend::Under], |b| match b {
            Blend::Over => "back to front".into(),
            Blend::Under => "front to back".into(),
        }),
        Param::EarlyStop => {
            ui.checkbox(&mut p.raster.early_stop, info.label);
        }
        Param::Scramble => {
            ui.checkbox(&mut p.scramble, info.label);
        }
        Param::RasterSamples => {
            combo(ui, info.label, &mut p.raster.samples, &SAMPLE_COUNTS, |n| n.to_string());
        }
        Param::SamplePattern => {
            let patterns = [SamplePattern::Hammersley, SamplePattern::Standard];
            combo(ui, info.label, &mut p.raster.sample_pattern, &patterns, |s| format!("{s:?}").to_lowercase());
        }
        Param::FragmentDepth => {
            let depths = [FragmentDepth::Center, FragmentDepth::MaxDensityPlane];
            combo(ui, info.label, &mut p.raster.fragment_depth, &depths, |d| match d {
                FragmentDepth::Center => "centre".into(),
                FragmentDepth::MaxDensityPlane => "max-density plane".into(),
            });
        }
        Param::Extent => combo(ui, info.label, &mut p.raster.extent, &SplatExtent::ALL, |e| e.name().into()),
        Param::Response => combo(ui, info.label, &mut p.raster.response, &Response::ALL, |r| r.name().into()),
    }
}

fn combo<T: PartialEq + Copy>(
    ui: &mut egui::Ui,
    label: &str,
    value: &mut T,
    choices: &[T],
    name: impl Fn(T) -> String,
) {
    egui::ComboBox::from_label(label).selected_text(name(*value)).show_ui(ui, |ui| {
        for &choice in choices {
            ui.selectable_value(value, choice, name(choice));
        }
    });
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
