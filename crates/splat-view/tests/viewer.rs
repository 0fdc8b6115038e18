//! The viewer without a window: egui_kittest drives the real UI on the wgpu renderer
//! (lavapipe here), the render thread renders, and the tests read the view's texture back.
//! Switching the method changes the image, a camera move restarts the accumulation, the GPU
//! view draws what a batch render of the same frames shows, the window's pixels are those of
//! `splat render`'s PNG of the same view, and the panels render as the committed snapshot (the
//! README's screenshot).

use eframe::egui;
use eframe::egui_wgpu::{self, RenderState, WgpuSetup};
use egui_kittest::kittest::Queryable;
use egui_kittest::wgpu::{WgpuTestRenderer, create_render_state, default_wgpu_setup};
use egui_kittest::{Harness, SnapshotOptions};
use splat_core::MethodId;
use splat_core::frame::Frames;
use splat_core::trace::{Method, TraceScene};
use splat_core::{Algorithm, Camera, Shot};
use splat_gpu::{DisplayTransform, GpuContext, GpuTracer, PixelState, TracePipeline};
use splat_view::settings::{Backend, Settings};
use splat_view::worker::{Status, Target, Worker};
use splat_view::{BackendChoice, Options, Viewer};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The UI's render state on a device with the kernels' limits, or `None` (recorded as
/// skipped, a failure under CI=true) without an adapter.
fn render_state() -> Option<RenderState> {
    let mut setup = default_wgpu_setup();
    if let WgpuSetup::CreateNew(create) = &mut setup {
        create.device_descriptor = Arc::new(GpuContext::device_descriptor);
    }
    let create = std::panic::AssertUnwindSafe(|| create_render_state(setup, egui_wgpu::RendererOptions::PREDICTABLE));
    match std::panic::catch_unwind(create) {
        Ok(state) => Some(state),
        Err(_) => {
            splat_tests::skip(&splat_tests::current_test(), "no wgpu adapter for the UI");
            None
        }
    }
}

fn options(backend: BackendChoice, max_frames: u32) -> Options {
    Options { backend, camera_index: 0, up: splat_core::glam::Vec3::Y, quit_after: None, max_frames }
}

/// A harness of a viewer of the fixture `scene` (`fixtures/NAME.ply` and its cameras.json,
/// or a world file `fixtures/worlds/NAME.toml`), or of the demo.
fn harness(scene: Option<&str>, options: &Options) -> Option<(Harness<'static, Viewer>, RenderState)> {
    let state = render_state()?;
    let fixtures = splat_tests::root().join("fixtures");
    let (scene_path, cameras) = match scene {
        Some(world) if world.ends_with(".toml") => (Some(fixtures.join("worlds").join(world)), None),
        Some(s) => (Some(fixtures.join(format!("{s}.ply"))), Some(fixtures.join(format!("{s}.cameras.json")))),
        None => (None, None),
    };
    harness_of(state, scene_path.as_deref(), cameras.as_deref(), options)
}

/// A harness of a viewer of the scene and cameras at these paths.
fn harness_of(
    state: RenderState,
    scene: Option<&std::path::Path>,
    cameras: Option<&std::path::Path>,
    options: &Options,
) -> Option<(Harness<'static, Viewer>, RenderState)> {
    let loaded =
        splat_view::load::load(scene, cameras.map(|c| (c, false)), Default::default(), Default::default(), None)
            .expect("the fixture loads");
    let mut viewer = Viewer::new(loaded, options, state.clone(), egui::Context::default());
    viewer.hide_rate = true;
    let harness = Harness::builder()
        .with_size(egui::vec2(1000.0, 640.0))
        .renderer(WgpuTestRenderer::from_render_state(state.clone()))
        .build_ui_state(|ui, viewer: &mut Viewer| viewer.show(ui), viewer);
    Some((harness, state))
}

/// Step the UI until the render thread is done with the posted job (or has `frames`).
fn settle(harness: &mut Harness<'static, Viewer>, frames: u32) -> Status {
    let start = Instant::now();
    loop {
        harness.step();
        if let Some(status) = harness.state().status()
            && (status.idle || status.frames >= frames || status.error.is_some())
        {
            assert!(status.error.is_none(), "the render failed: {status:?}");
            return status;
        }
        assert!(start.elapsed() < Duration::from_secs(120), "the render thread did not finish");
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The view's texture, RGBA8 rows.
fn texels(state: &RenderState, viewer: &Viewer) -> (u32, u32, Vec<u8>) {
    let texture = viewer.texture().expect("the view has a texture");
    let bytes = splat_gpu::read_rgba8(&state.device, &state.queue, texture).expect("readback");
    (texture.width(), texture.height(), bytes)
}

/// Mean absolute difference of two images' bytes, per channel value.
fn mean_abs(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| f64::from(x.abs_diff(*y))).sum::<f64>() / a.len() as f64
}

/// A left-button drag from `from` to `to`.
fn drag(h: &mut Harness<'static, Viewer>, from: egui::Pos2, to: egui::Pos2) {
    h.drag_at(from);
    h.step();
    h.hover_at(to);
    h.step();
    h.drop_at(to);
    h.step();
}

/// Choose `option` of the combo box labelled `combo`, as a user would.
fn choose(harness: &mut Harness<'static, Viewer>, combo: &str, option: &str) {
    harness.get_by_label(combo).click();
    harness.run_steps(2);
    harness.get_by_label(option).click();
    harness.run_steps(2);
}

#[test]
fn switching_the_method_changes_the_image() {
    let Some((mut h, state)) = harness(Some("cloud"), &options(BackendChoice::Cpu, 4)) else { return };
    let first = settle(&mut h, 4);
    assert_eq!(first.frames, 4);
    let (_, _, stochastic) = texels(&state, h.state());
    // The same job again gives the same bytes: the comparison below can come out small.
    h.state_mut().settings_mut().seed = 7;
    settle(&mut h, 4);
    h.state_mut().settings_mut().seed = 0;
    settle(&mut h, 4);
    let (_, _, again) = texels(&state, h.state());
    assert_eq!(mean_abs(&stochastic, &again), 0.0, "the same seed and method gave another image");

    choose(&mut h, "method", "depth-sampling-k");
    assert_eq!(h.state().settings().method(), Method::DepthSampling { k: splat_core::trace::DEFAULT_K });
    let status = settle(&mut h, 4);
    assert!(status.job > first.job);
    let (_, _, biased) = texels(&state, h.state());
    let changed = mean_abs(&stochastic, &biased);
    assert!(changed > 0.5, "depth sampling looks like Algorithm 1 (mean |Δ| {changed:.3} of 255)");

    choose(&mut h, "method", "exact");
    let exact = settle(&mut h, 4);
    assert_eq!(exact.frames, 1, "a deterministic method is done after one frame");
    assert!(exact.idle);
}

#[test]
fn a_camera_move_restarts_the_accumulation() {
    let Some((mut h, state)) = harness(Some("cloud"), &options(BackendChoice::Cpu, 3)) else { return };
    assert_eq!(h.state().view(), Some(0), "the first view of the cameras.json opens");
    assert_eq!(settle(&mut h, 3).frames, 3);
    let camera = h.state().camera().expect("a job was posted");
    // Paused, a drag across the view with the left button (an orbit) shows one frame of the
    // new view: neither the old view's frames nor a black texture.
    h.state_mut().settings_mut().paused = true;
    settle(&mut h, 3);
    let (_, _, old) = texels(&state, h.state());
    drag(&mut h, egui::pos2(600.0, 300.0), egui::pos2(680.0, 330.0));
    let paused = settle(&mut h, 3);
    assert_eq!(h.state().view(), None, "the camera left the loaded view");
    assert_ne!(h.state().camera(), Some(camera));
    assert_eq!(paused.frames, 1, "paused, the moved view shows exactly one frame of itself");
    assert!(paused.idle, "paused after that frame");
    let (_, _, shown) = texels(&state, h.state());
    assert!(brightness(&shown) > 0.25 * brightness(&old), "the moved view is black while paused");
    h.state_mut().settings_mut().paused = false;
    assert_eq!(settle(&mut h, 3).frames, 3);
    let (_, _, before) = texels(&state, h.state());
    // A second move, rendering: the same size, another image.
    let job = h.state().status().unwrap().job;
    drag(&mut h, egui::pos2(600.0, 300.0), egui::pos2(520.0, 280.0));
    let moved = settle(&mut h, 3);
    assert!(moved.job > job);
    let (_, _, after) = texels(&state, h.state());
    assert!(mean_abs(&before, &after) > 0.5, "the moved view shows the same image");
    // N returns to the loaded view.
    h.key_press(egui::Key::N);
    h.step();
    assert_eq!(h.state().view(), Some(0), "the cloud has one view: N wraps to it");
    assert_eq!(h.state().camera(), Some(camera), "the loaded view is shown as it was");
}

#[test]
fn n_and_p_step_through_the_views_and_f_returns_to_the_opening_one() {
    let Some(state) = render_state() else { return };
    let fixtures = splat_tests::root().join("fixtures");
    let (_, camera) = splat_tests::harness::fixture("cloud", 64, 48);
    let views: Vec<_> = (0..3).map(|i| Camera { cx: camera.cx + 4.0 * i as f32, ..camera }).collect();
    let cameras = splat_tests::root().join("target/viewer-three-views.cameras.json");
    splat_io::cameras::write_cameras(&cameras, &views).unwrap();
    let options = Options { camera_index: 1, ..options(BackendChoice::Cpu, 1) };
    let (mut h, _) = harness_of(state, Some(&fixtures.join("cloud.ply")), Some(&cameras), &options).unwrap();
    assert_eq!(h.state().view(), Some(1), "--camera-index 1 opens the second view");
    for (key, expected) in [(egui::Key::N, 2), (egui::Key::N, 0), (egui::Key::P, 2), (egui::Key::F, 1)] {
        h.key_press(key);
        h.step();
        assert_eq!(h.state().view(), Some(expected), "after {key:?}");
    }
    h.key_press(egui::Key::N);
    h.step();
    drag(&mut h, egui::pos2(600.0, 300.0), egui::pos2(640.0, 360.0));
    assert_eq!(h.state().view(), None, "a drag leaves the loaded views");
    h.key_press(egui::Key::F);
    h.step();
    assert_eq!(h.state().view(), Some(1), "F returns to the opening view");
}

#[test]
fn the_gpu_view_draws_the_frames_of_a_batch_render() {
    let Some((mut h, state)) = harness(Some("cloud"), &options(BackendChoice::Gpu, 4)) else { return };
    h.state_mut().settings_mut().scale = 0.25;
    assert_eq!(settle(&mut h, 4).frames, 4);
    let (w, hgt, view) = texels(&state, h.state());
    let camera = h.state().camera().unwrap();
    assert_eq!((camera.width, camera.height), (w, hgt));
    let worst = against_a_batch_render(&camera, &view, 4, Backend::Gpu);
    assert!(worst <= 1, "the window's texture differs from the batch render by {worst}");
}

/// `splat serve`'s target: the view in host memory (the render thread's `Target::Host`) shows
/// the frames of a batch render: on the GPU drawn by the same display pass and read back, on
/// the CPU frame i of the view being frame i of the batch (its key and camera sample).
#[test]
fn the_view_in_host_memory_is_the_batch_render() {
    if let Err(e) = GpuContext::new() {
        return splat_tests::skip(&splat_tests::current_test(), &format!("no GPU adapter ({e})"));
    }
    let root = splat_tests::root();
    let camera = splat_io::cameras::read_cameras(&root.join("fixtures/cloud.cameras.json")).unwrap()[0]
        .rescaled(96, 72)
        .unwrap();
    for backend in [Backend::Gpu, Backend::Cpu] {
        let loaded = splat_view::load::load(
            Some(&root.join("fixtures/cloud.ply")),
            None,
            Default::default(),
            Default::default(),
            None,
        )
        .expect("the cloud");
        let mut settings = Settings::new(loaded.info.render, &loaded.world.lighting, backend);
        settings.max_frames = 4;
        let gpu = (backend == Backend::Gpu).then(|| GpuContext::new().expect("an adapter, as above"));
        let mut worker = Worker::spawn(loaded.world, gpu, None, || {});
        let feed = worker.feed();
        let job = worker.post(camera, &settings, 0, || Target::Host);
        let start = Instant::now();
        let frame = loop {
            let frame = feed.wait(0, Duration::from_secs(1));
            assert!(feed.status().error.is_none(), "{:?}", feed.status());
            if frame.job == job && frame.frames == 4 {
                break frame;
            }
            assert!(start.elapsed() < Duration::from_secs(120), "no frame 4: {:?}", feed.status());
        };
        assert_eq!((frame.width, frame.height), (96, 72));
        let worst = against_a_batch_render(&camera, &frame.rgba, 4, backend);
        assert!(worst <= 1, "{backend:?}: the host frame differs from the batch render by {worst}");
    }
}

/// The panel starts splatting a capture as its trainer does: a `.ply` naming gsplat's
/// antialiased mode with gsplat's opacity-aware footprint (the CLI's default for it too), a
/// plain one with the 3DGS tiles.
#[test]
fn the_panel_splats_a_capture_as_its_trainer() {
    use splat_core::raster::{Response, SplatExtent};
    let root = splat_tests::root();
    let mut scene = splat_io::read_scene(&root.join("fixtures/cloud.ply")).unwrap();
    let antialiased = std::env::temp_dir().join(format!("splat-view-antialiased-{}.ply", std::process::id()));
    scene.screen_filter = splat_core::ScreenFilter::Antialiased;
    splat_io::write_scene(&antialiased, &scene, Default::default()).unwrap();
    for (path, extent) in
        [(antialiased.clone(), SplatExtent::AlphaCull), (root.join("fixtures/cloud.ply"), SplatExtent::ThreeDgs)]
    {
        let loaded = splat_view::load::load(Some(&path), None, Default::default(), Default::default(), None).unwrap();
        let (_, settings) = options(BackendChoice::Cpu, 1).start(loaded.info, &loaded.world.lighting, Backend::Cpu);
        assert_eq!((settings.params.raster.extent, settings.params.raster.response), (extent, Response::Projected));
    }
    std::fs::remove_file(antialiased).unwrap();
}

/// `splat view`'s scene options, as a command line of their own.
#[derive(clap::Parser)]
struct Opened {
    #[command(flatten)]
    scene: splat_view::SceneArgs,
}

/// `splat view`'s scene options as its command line `args` (the command's name first) give them.
fn scene_args(args: &[&str]) -> splat_view::SceneArgs {
    <Opened as clap::Parser>::try_parse_from(args).expect("the options parse").scene
}

/// `--data-factor` reads the views as the `splat` commands do (K / F, sides floored), so
/// that a trainer's downscaled views open in the window as they render; the control is the
/// views without it, at the file's size.
#[test]
fn the_window_reads_downscaled_views_as_the_commands_do() {
    let root = splat_tests::root();
    let (ply, cameras) = (root.join("fixtures/cloud.ply"), root.join("fixtures/cloud.cameras.json"));
    let args = [&["view", ply.to_str().unwrap(), "--camera", cameras.to_str().unwrap()][..], &["--data-factor", "3"]];
    let loaded = scene_args(&args.concat()).load().expect("the cloud");
    let options = splat_io::cameras::ViewOptions { factor: Some(3), ..Default::default() };
    let read = splat_io::cameras::read_views_in(&cameras, options).unwrap();
    assert_eq!(loaded.info.views, read);
    assert_eq!((read[0].1.width, read[0].1.height), (42, 32));
    let whole = scene_args(args[0]).load().unwrap();
    assert_eq!((whole.info.views[0].1.width, whole.info.views[0].1.height), (128, 96));
    // A view index or a data factor without views would change nothing: refused by name.
    let parse = |args: &[&str]| <Opened as clap::Parser>::try_parse_from(args).map(|_| ()).unwrap_err().to_string();
    for flag in [["--camera-index", "2"], ["--data-factor", "2"]] {
        let e = parse(&[&["view", ply.to_str().unwrap()][..], &flag].concat());
        assert!(e.contains("--camera <CAMERA>"), "{flag:?}: {e}");
    }
}

/// `--preset` starts the window with that trainer's renderer, as `splat render --preset` draws
/// it: its kernel, near plane, screen filter, extent and response (3DGRT's degree-4 kernel
/// along the rays; gsplat's antialiased filter and footprint), over the plain `.ply`'s 3DGS
/// defaults (the control).
#[test]
fn a_preset_starts_the_window_with_its_trainers_renderer() {
    use splat_core::raster::{Response, SplatExtent};
    use splat_core::trainer::Preset;
    let ply = splat_tests::root().join("fixtures/cloud.ply");
    let ply = ply.to_str().unwrap();
    for (preset, filter) in [
        (None, splat_core::ScreenFilter::Dilation),
        (Some(Preset::ThreeDgrt), splat_core::ScreenFilter::Dilation),
        (Some(Preset::GsplatAntialiased), splat_core::ScreenFilter::Antialiased),
    ] {
        let flags: &[&str] = match preset {
            Some(p) => &["--preset", p.name()],
            None => &[],
        };
        let loaded = scene_args(&[&["view", ply][..], flags].concat()).load().expect("the cloud loads");
        let expected = preset.unwrap_or(Preset::ThreeDgs);
        let render = loaded.info.render;
        assert_eq!((render.kernel.degree, render.kernel.cutoff), (expected.kernel_degree(), expected.cutoff()));
        assert_eq!((render.near, loaded.info.screen_filter), (expected.near(), filter), "{preset:?}");
        let (_, settings) = options(BackendChoice::Cpu, 1).start(loaded.info, &loaded.world.lighting, Backend::Cpu);
        let splatting = (settings.params.raster.extent, settings.params.raster.response);
        assert_eq!(splatting, (expected.extent(), expected.response()), "{preset:?}");
    }
    assert_eq!(Preset::ThreeDgrt.response(), Response::AlongRay);
    assert_eq!(Preset::GsplatAntialiased.extent(), SplatExtent::AlphaCull);
    assert_ne!(Preset::ThreeDgrt.kernel_degree(), Preset::ThreeDgs.kernel_degree());
}

/// The largest difference, in 8-bit levels, between `view` (RGBA8 of `camera`) and a batch
/// render of `frames` frames of Algorithm 1 on the cloud fixture on `backend`, shown with the
/// default display transform; fails on a nearly empty view.
fn against_a_batch_render(camera: &Camera, view: &[u8], frames: u32, backend: Backend) -> u8 {
    let root = splat_tests::root();
    let scene = splat_io::read_scene(&root.join("fixtures/cloud.ply")).unwrap();
    let trace = TraceScene::new(&scene, splat_core::RenderSettings::default()).unwrap();
    let batch = Frames { count: frames, ..Frames::default() };
    let batch = match backend {
        Backend::Gpu => {
            let ctx = GpuContext::new().expect("an adapter, as the view has one");
            let pipeline = TracePipeline::new(&ctx).unwrap();
            let tracer = GpuTracer::new(&ctx, &pipeline, &trace).unwrap();
            tracer.render(camera, &Method::Stochastic, &batch).unwrap().0
        }
        Backend::Cpu => Algorithm::Trace(Method::Stochastic).render_on(&trace, camera, &batch, &|_| {}).unwrap(),
    };
    let display = DisplayTransform::default();
    let mut worst = 0u8;
    for (p, texel) in view.chunks(4).enumerate() {
        let (x, y) = (p as u32 % camera.width, p as u32 / camera.width);
        let pixel = PixelState {
            mean: batch.mean.pixel(x, y).try_into().unwrap(),
            variance: [0.0; 3],
            depth: f32::NAN,
            normal: [0.0; 3],
        };
        let expected = display.rgba8(&pixel);
        worst = worst.max(expected.iter().zip(texel).map(|(a, b)| a.abs_diff(*b)).max().unwrap());
    }
    assert!(view.chunks(4).filter(|t| t[0] > 0).count() > view.len() / 40, "the view is nearly empty");
    worst
}

/// Mean of the view's bytes (its brightness).
fn brightness(texels: &[u8]) -> f64 {
    texels.iter().map(|&b| f64::from(b)).sum::<f64>() / texels.len() as f64
}

#[test]
fn tuning_a_light_relights_the_view() {
    let Some((mut h, state)) = harness(Some("demo-lit.toml"), &options(BackendChoice::Cpu, 2)) else { return };
    assert!(!h.state().settings().lights.is_empty(), "the lit demo has lights");
    assert!(h.get_all_by_label("lights").next().is_some(), "no lights section");
    let lit = settle(&mut h, 2);
    let (_, _, before) = texels(&state, h.state());
    for light in &mut h.state_mut().settings_mut().lights {
        light.intensity = 0.0;
    }
    let dark = settle(&mut h, 2);
    assert!(dark.job > lit.job && dark.frames == 2);
    let (_, _, after) = texels(&state, h.state());
    let (b, a) = (brightness(&before), brightness(&after));
    assert!(a < 0.9 * b, "switching the lights off left the view as bright ({a:.1} vs {b:.1})");
}

#[test]
fn the_panels_render() {
    let Some((mut h, _)) = harness(None, &options(BackendChoice::Cpu, 16)) else { return };
    assert_eq!(settle(&mut h, 16).frames, 16);
    for label in ["pipeline", "method", "random numbers", "accumulation", "kernel degree", "show", "RMSE vs exact"] {
        assert!(h.get_all_by_label(label).next().is_some(), "the panel has no '{label}'");
    }
    h.run_steps(2);
    h.snapshot_options("viewer", &SnapshotOptions::default());
}

/// What the window shows at pixel centre `(px, py)` (in pixels) of an RGBA8 image `w` × `h`
/// drawn into `shown` (in pixels): egui-wgpu's predictable texture filtering, bilinear between
/// texel centres and clamped to the edge, on the bytes as stored. egui treats them as
/// gamma-encoded, which is what the PNG holds.
fn shown_at(rgba: &[u8], (w, h): (u32, u32), shown: egui::Rect, px: u32, py: u32) -> [f64; 3] {
    let u = (px as f32 + 0.5 - shown.min.x) / shown.width() * w as f32 - 0.5;
    let v = (py as f32 + 0.5 - shown.min.y) / shown.height() * h as f32 - 0.5;
    let (x0, y0) = (u.floor(), v.floor());
    let (fx, fy) = (f64::from(u - x0), f64::from(v - y0));
    let texel = |x: f32, y: f32, c: usize| {
        let (x, y) = ((x as i64).clamp(0, i64::from(w) - 1), (y as i64).clamp(0, i64::from(h) - 1));
        f64::from(rgba[4 * (y as usize * w as usize + x as usize) + c])
    };
    std::array::from_fn(|c| {
        let top = texel(x0, y0, c) * (1.0 - fx) + texel(x0 + 1.0, y0, c) * fx;
        let bottom = texel(x0, y0 + 1.0, c) * (1.0 - fx) + texel(x0 + 1.0, y0 + 1.0, c) * fx;
        top * (1.0 - fy) + bottom * fy
    })
}

/// `splat render`'s 8-bit PNG of the exact method at `camera` of the scene the viewer loaded
/// from `scene` and `cameras`, as RGBA8 bytes: the CLI's render call and PNG writer, read back.
fn png_of_splat_render(scene: Option<&std::path::Path>, camera: &Camera, name: &str) -> Vec<u8> {
    let loaded =
        splat_view::load::load(scene, None, Default::default(), Default::default(), None).expect("the scene loads");
    let world = &loaded.world;
    let out = Algorithm::Trace(Method::Exact)
        .render_world(
            &Shot {
                scene: &world.scene,
                meshes: &world.meshes,
                lighting: &world.lighting,
                camera,
                settings: &loaded.info.render,
            },
            &Frames::default(),
            &|_| {},
        )
        .expect("the exact render");
    let png = splat_tests::root().join(format!("target/viewer-{name}-splat-render.png"));
    splat_io::image::write_image(&png, &out.mean).expect("the PNG is written");
    let image = splat_io::image::read_image(&png).expect("the PNG reads back");
    let mut rgba = Vec::with_capacity(4 * camera.width as usize * camera.height as usize);
    for y in 0..camera.height {
        for x in 0..camera.width {
            let p = image.pixel(x, y);
            rgba.extend([p[0], p[1], p[2], 1.0].map(splat_core::image::to_u8));
        }
    }
    rgba
}

/// Differences, in 8-bit levels, between the window as rendered and the PNG of `splat render`
/// where the view is drawn (the status text over its top left and a pixel along its edges left
/// out): the largest and the share of channel values more than one level apart.
fn window_against_splat_render(scene: Option<&str>, backend: BackendChoice) -> Option<(f64, f64)> {
    let (mut h, _) = harness(scene, &options(backend, 1))?;
    h.state_mut().settings_mut().trace = MethodId::Exact;
    let status = settle(&mut h, 1);
    assert_eq!(status.frames, 1, "exact is done after one frame");
    h.run_steps(2);
    let window = h.render().expect("the UI renders");
    let camera = h.state().camera().expect("a job was posted");
    let path = scene.map(|s| splat_tests::root().join("fixtures").join(format!("{s}.ply")));
    let reference = png_of_splat_render(path.as_deref(), &camera, scene.unwrap_or("demo"));
    let ppp = h.ctx.pixels_per_point();
    let shown = h.state().image_rect().expect("the view was drawn");
    let shown = egui::Rect::from_min_max((shown.min.to_vec2() * ppp).to_pos2(), (shown.max.to_vec2() * ppp).to_pos2());
    let status_text = 64.0 * ppp;
    let (mut worst, mut apart, mut count) = (0.0f64, 0usize, 0usize);
    for py in (shown.min.y.ceil() as u32 + 1)..(shown.max.y.floor() as u32).saturating_sub(1) {
        if (py as f32) < status_text {
            continue;
        }
        for px in (shown.min.x.ceil() as u32 + 1)..(shown.max.x.floor() as u32).saturating_sub(1) {
            let expected = shown_at(&reference, (camera.width, camera.height), shown, px, py);
            let got = window.get_pixel(px, py).0;
            for c in 0..3 {
                let d = (f64::from(got[c]) - expected[c]).abs();
                worst = worst.max(d);
                apart += usize::from(d > 1.0);
                count += 1;
            }
        }
    }
    assert!(count > 30_000, "only {count} channel values compared");
    assert!(reference.chunks(4).filter(|p| p[0] > 16).count() > reference.len() / 80, "the view is nearly black");
    Some((worst, apart as f64 / count as f64))
}

/// The window shows what `splat render` writes: on the demo and on the cloud fixture (a loaded
/// view, letterboxed), the pixels of the rendered UI equal the PNG of the same view within one
/// 8-bit level (the bilinear resampling and the framebuffer's rounding; measured: 0.5; exact
/// renders, so no noise). With the view texture in an sRGB format, decoded once more by egui's
/// sampler, every mid grey shows as about its 2.2th power and the test fails.
#[test]
fn the_window_shows_the_pixels_of_splat_render() {
    for scene in [None, Some("cloud")] {
        let Some((worst, apart)) = window_against_splat_render(scene, BackendChoice::Cpu) else { return };
        let name = scene.unwrap_or("demo");
        eprintln!("{name}: largest difference {worst:.2} levels, {:.4} % more than one", 100.0 * apart);
        assert!(
            worst <= 1.0,
            "{name}: the window differs from splat render's PNG by up to {worst:.1} levels ({:.3} % more than one)",
            100.0 * apart
        );
    }
}

/// The GPU view's display pass draws the same pixels (the exact method on the device, its
/// rounding against the CPU's).
#[test]
fn the_gpu_window_shows_the_pixels_of_splat_render() {
    let Some((worst, apart)) = window_against_splat_render(Some("cloud"), BackendChoice::Gpu) else { return };
    eprintln!("GPU view: largest difference {worst:.2} levels, {:.4} % more than one", 100.0 * apart);
    assert!(
        worst <= 1.0,
        "the GPU window differs from splat render's PNG by up to {worst:.1} levels ({:.3} % more than one)",
        100.0 * apart
    );
}
