//! The window: a side panel of settings, the view with its camera controls, and the status
//! line. Everything that renders happens on the render thread ([`crate::worker`]); the window
//! only posts jobs and shows the texture the thread draws into.

use crate::camera::Orbit;
use crate::load::{Loaded, SceneInfo};
pub use crate::navigate::KEY_BINDINGS;
use crate::navigate::{Action, FLY_KEYS, JUMP_KEYS, Navigation, fly_action, key_action};
use crate::settings::{Backend, LOOKS, ParamValue, Pipeline, SHADOWS, Settings, is_count, look_name};
use crate::settings::{RNGS, param_choices, param_value, rng_name, set_param, shadows_name};
use crate::worker::{self, Status, Worker};
use eframe::egui::{self, Key, PointerButton, Sense};
use eframe::egui_wgpu;
use splat_core::catalogue::{Limits, Param};
use splat_core::glam::Vec3;
use splat_core::lighting::Lighting;
use splat_core::normal::NormalMode;
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

impl BackendChoice {
    /// Where frames render, and why, given the adapter and the GPU context made on it (`Err(None)`
    /// when none was asked for, `Err(Some(why))` when it could not be made).
    pub fn resolve(
        self,
        adapter: Option<&wgpu::AdapterInfo>,
        gpu: &Result<GpuContext, Option<String>>,
    ) -> (Backend, String) {
        let hardware = adapter.is_some_and(|a| a.device_type != wgpu::DeviceType::Cpu);
        let name = adapter.map_or("", |a| &a.name);
        let backend = match (gpu, self) {
            (Ok(_), BackendChoice::Gpu) => Backend::Gpu,
            (Ok(_), BackendChoice::Auto) if hardware => Backend::Gpu,
            _ => Backend::Cpu,
        };
        let note = match (gpu, hardware) {
            (Err(None), _) => "--backend cpu: rendering on the CPU".into(),
            (Err(Some(e)), _) => format!("the GPU tracer cannot run here ({e}): rendering on the CPU"),
            (Ok(_), true) => format!("GPU: {name}"),
            (Ok(_), false) if backend == Backend::Gpu => {
                format!("{name} is a CPU Vulkan driver: the GPU tracer runs on it, slowly")
            }
            (Ok(_), false) => format!("{name} is a CPU Vulkan driver (slow): tracing on the CPU unless GPU is chosen"),
        };
        (backend, note)
    }
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

impl Options {
    /// How the window and the server start on `scene`: the navigation at the opening view and
    /// the panel's settings on `backend` with the frame limit.
    pub fn start(&self, scene: SceneInfo, lighting: &Lighting, backend: Backend) -> (Navigation, Settings) {
        let mut settings = Settings::new(scene.render, lighting, backend);
        settings.max_frames = self.max_frames;
        (settings.params.raster.extent, settings.params.raster.response) = scene.splatting;
        (Navigation::new(scene, self.camera_index, self.up), settings)
    }
}

/// The texture the render thread draws into, registered with the UI renderer.
struct Target {
    texture: wgpu::Texture,
    id: egui::TextureId,
}

/// The viewer's state.
pub struct Viewer {
    /// The orbit, the loaded view shown and the keys' actions (shared with `splat serve`).
    nav: Navigation,
    settings: Settings,
    /// Why the panel's GPU choice is what it is (adapter name, or why the CPU renders).
    backend_note: String,
    gpu_available: bool,
    worker: Worker,
    render_state: egui_wgpu::RenderState,
    target: Option<Target>,
    /// Where the view's texture was last drawn in the window, in points.
    shown: Option<egui::Rect>,
    quit_after: Option<u32>,
    /// A test hook: show no frames/s (its value varies from run to run) so that snapshots are
    /// repeatable.
    pub hide_rate: bool,
}

impl Viewer {
    /// A viewer of `loaded` on the UI's device (`render_state`), waking `egui` when frames
    /// arrive.
    pub fn new(loaded: Loaded, options: &Options, render_state: egui_wgpu::RenderState, egui: egui::Context) -> Self {
        let gpu = match options.backend {
            BackendChoice::Cpu => Err(None),
            _ => {
                GpuContext::from_device(&render_state.adapter, render_state.device.clone(), render_state.queue.clone())
                    .map_err(|e| Some(e.to_string()))
            }
        };
        let (backend, backend_note) = options.backend.resolve(Some(&render_state.adapter.get_info()), &gpu);
        let gpu_available = gpu.is_ok();
        let Loaded { world, info } = loaded;
        let (nav, settings) = options.start(info, &world.lighting, backend);
        let worker = Worker::spawn(world, gpu.ok(), Some(render_state.queue.clone()), move || egui.request_repaint());
        Self {
            nav,
            settings,
            backend_note,
            gpu_available,
            worker,
            render_state,
            target: None,
            shown: None,
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
        self.worker.posted_status()
    }

    /// The orbit camera.
    pub fn orbit(&self) -> &Orbit {
        self.nav.orbit()
    }

    /// The camera of the last job posted.
    pub fn camera(&self) -> Option<Camera> {
        self.worker.posted().map(|p| p.camera)
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
        self.nav.view()
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

    /// The camera of the view ([`Navigation::camera`]) and the rectangle of the window it
    /// fills, centred in `rect`.
    fn view_camera(&self, rect: egui::Rect, ppp: f32) -> (Camera, egui::Rect) {
        let (camera, [w, h]) = self.nav.camera([rect.width(), rect.height()], self.settings.scale * ppp);
        (camera, egui::Rect::from_center_size(rect.center(), egui::vec2(w, h)))
    }

    /// A texture of `width` × `height` for the render thread, registered for the UI.
    fn ensure_target(&mut self, width: u32, height: u32) {
        if self.target.as_ref().is_some_and(|t| (t.texture.width(), t.texture.height()) == (width, height)) {
            return;
        }
        let usage =
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC;
        let texture = worker::view_texture(&self.render_state.device, (width, height), usage);
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
        let texture = &self.target.as_ref().expect("made before posting").texture;
        self.nav.post(&mut self.worker, camera, &mut self.settings, || worker::Target::Texture(texture.clone()));
    }

    /// Mouse and keys as [`Action`]s ([`KEY_BINDINGS`]): drag turns, right or middle drag
    /// pans, the wheel dollies, W A S D Q E fly, the other keys jump.
    fn navigate(&mut self, ui: &egui::Ui, response: &egui::Response, rect: egui::Rect) {
        let delta = response.drag_delta();
        let mut actions = Vec::new();
        if response.dragged_by(PointerButton::Primary) {
            actions.push(Action::Rotate(delta.x, delta.y));
        } else if response.dragged_by(PointerButton::Secondary) || response.dragged_by(PointerButton::Middle) {
            actions.push(Action::Pan(delta.x, delta.y, rect.height()));
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta().y);
            if scroll != 0.0 {
                actions.push(Action::Zoom(scroll / 50.0));
            }
        }
        if !ui.ctx().text_edit_focused() {
            actions.extend(self.fly(ui));
            let pressed = ui.input(|i| JUMP_KEYS.map(|k| Key::from_name(k).is_some_and(|k| i.key_pressed(k))));
            actions.extend(JUMP_KEYS.iter().zip(pressed).filter(|p| p.1).filter_map(|(k, _)| key_action(k)));
        }
        for action in actions {
            self.nav.act(action, &mut self.settings);
        }
    }

    /// W A S D Q E held for this frame's time ([`fly_action`]).
    fn fly(&mut self, ui: &egui::Ui) -> Option<Action> {
        let (dt, fast, down) = ui.input(|i| {
            let down = FLY_KEYS.map(|c| Key::from_name(&c.to_string()).is_some_and(|k| i.key_down(k)));
            (i.stable_dt.min(0.1), i.modifiers.shift, down)
        });
        let fly = fly_action(down, fast, dt);
        if fly.is_some() {
            ui.ctx().request_repaint();
        }
        fly
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
        let view = match (self.nav.view(), self.nav.view().and_then(|i| self.nav.scene().views.get(i))) {
            (Some(i), Some((name, _))) => format!("view {} of {}: {name}", i + 1, self.nav.scene().views.len()),
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
        ui.label(format!(
            "{}: {} splats, SH degree {}",
            self.nav.scene().name,
            self.nav.scene().particles,
            self.nav.scene().sh_degree
        ))
        .on_hover_text(format!("splatting through {}", self.nav.scene().screen_filter.describe()));
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
        combo(ui, "random numbers", &mut s.rng, &RNGS, |r| rng_name(r).into());
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
        combo(ui, "look", &mut s.look, &LOOKS, |l| look_name(l).into());
        combo(ui, "shadows", &mut s.shadows, &SHADOWS, |s| shadows_name(s).into());
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
        let (s, nav) = (&mut self.settings, &mut self.nav);
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
                nav.act(Action::Restart, s);
            }
        });
        if !nav.scene().views.is_empty() {
            ui.horizontal(|ui| {
                if ui.button("previous view").clicked() {
                    nav.act(Action::StepView(-1), s);
                }
                if ui.button("next view").clicked() {
                    nav.act(Action::StepView(1), s);
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

/// The widget of one method parameter ([`param_value`]): a slider over the catalogue's limits
/// for a number, a menu for a choice, a check box for a switch.
fn parameter(ui: &mut egui::Ui, param: Param, p: &mut Parameters) {
    let info = param.info();
    let changed = match param_value(p, param) {
        ParamValue::Number(mut v) => {
            let range = info.limits.map_or(0.0..=1.0, |l: Limits| l.min..=l.slider_max);
            let slider = egui::Slider::new(&mut v, range).text(info.label);
            let changed = ui.add(if is_count(param) { slider.integer() } else { slider }).changed();
            changed.then_some(ParamValue::Number(v))
        }
        ParamValue::Switch(mut on) => ui.checkbox(&mut on, info.label).changed().then_some(ParamValue::Switch(on)),
        ParamValue::Choice(current) => {
            let mut chosen = None;
            egui::ComboBox::from_label(info.label).selected_text(&current).show_ui(ui, |ui| {
                for choice in param_choices(param) {
                    if ui.selectable_label(choice == current, &choice).clicked() {
                        chosen = Some(ParamValue::Choice(choice));
                    }
                }
            });
            chosen
        }
    };
    if let Some(value) = changed {
        set_param(p, param, value).expect("the widget offers the parameter's own kind and choices");
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
