//! The seams an interactive viewer builds on: a progressive view accumulates exactly the
//! frames of a batch render, restarts on a camera move or a new method, and draws each display
//! mode into a caller's texture as the CPU twin shows it; a context made from the caller's
//! device runs the kernels, one with too few storage bindings is refused.

mod common;

use common::{context, fixture, tracer};
use splat_core::frame::{Frames, RenderOutput};
use splat_core::trace::{Method, TraceScene};
use splat_core::{Camera, RenderSettings};
use splat_gpu::{
    DisplayMode, DisplayTransform, GpuContext, PixelState, ProgressiveTrace, Rgba8Readback, read_rgba8, wgpu,
};

/// The largest |a − b| over two images' values.
fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

fn batch(tracer: &splat_gpu::GpuTracer, camera: &Camera, method: &Method, count: u32) -> RenderOutput {
    tracer.render(camera, method, &Frames { count, ..Frames::default() }).expect("GPU render").0
}

/// One read-back kept across reads returns each texture's texels as written: the same size
/// twice (its staging buffer reused, the second contents read, not the first's), another size
/// (a buffer made again), rows whose padding to 256 bytes is dropped, and back.
#[test]
fn a_kept_readback_reads_each_texture_as_written() {
    let Some(ctx) = context() else { return };
    let mut readback = Rgba8Readback::default();
    for (k, (w, h)) in [(13u32, 7u32), (13, 7), (70, 3), (13, 7)].into_iter().enumerate() {
        let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("written"),
            size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let texels: Vec<u8> = (0..4 * w * h).map(|i| (i * 7 + k as u32 * 31) as u8).collect();
        ctx.queue.write_texture(
            texture.as_image_copy(),
            &texels,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(4 * w), rows_per_image: Some(h) },
            texture.size(),
        );
        assert_eq!(readback.read(&ctx.device, &ctx.queue, &texture).unwrap(), texels, "read {k}, {w} × {h}");
    }
}

#[test]
fn steps_accumulate_the_frames_of_a_batch_render_and_restart_on_a_move() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 40, 30);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let tracer = tracer(ctx, &trace);
    let method = Method::Stochastic;
    let mut view = ProgressiveTrace::new(&tracer, &camera, &method, &Frames::default()).unwrap();
    assert_eq!(view.step(&tracer, 3).unwrap(), 3);
    assert_eq!(view.step(&tracer, 5).unwrap(), 5);
    assert_eq!(view.frames(), 8);
    let progressive = view.read(ctx).unwrap();
    let whole = batch(&tracer, &camera, &method, 8);
    let same = max_diff(progressive.mean.data(), whole.mean.data());
    let variance = max_diff(progressive.variance.data(), whole.variance.data());
    assert!(
        same < 1e-5 && variance < 1e-5,
        "8 frames in two steps differ from one render by {same} (variance {variance})"
    );
    // The comparison can fail: 8 frames are not 7.
    let seven = max_diff(progressive.mean.data(), batch(&tracer, &camera, &method, 7).mean.data());
    assert!(seven > 1e-3, "7 and 8 frames differ by only {seven}");

    // A move restarts: 4 frames after it are a fresh render of the new camera, nothing of the old.
    let moved = Camera { cx: camera.cx + 3.0, ..camera };
    view.set_camera(&tracer, &moved).unwrap();
    assert_eq!(view.frames(), 0);
    view.step(&tracer, 4).unwrap();
    let after = view.read(ctx).unwrap();
    let fresh = max_diff(after.mean.data(), batch(&tracer, &moved, &method, 4).mean.data());
    assert!(fresh < 1e-5, "after a move, 4 frames differ from a fresh render by {fresh}");
    let stale = max_diff(after.mean.data(), batch(&tracer, &camera, &method, 4).mean.data());
    assert!(stale > 1e-3, "the moved view still looks like the old one ({stale})");

    // A deterministic method is done after one frame; a new method restarts.
    view.set_method(&Method::Exact).unwrap();
    assert_eq!(view.step(&tracer, 16).unwrap(), 1);
    assert_eq!(view.step(&tracer, 16).unwrap(), 0);
    assert!(view.is_converged(&tracer));
    let exact = view.read(ctx).unwrap();
    assert!(max_diff(exact.mean.data(), batch(&tracer, &moved, &Method::Exact, 1).mean.data()) < 1e-6);
}

/// A texture the display pass can draw into and the test can read back.
fn target(ctx: &GpuContext, camera: &Camera, format: wgpu::TextureFormat) -> wgpu::Texture {
    ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("target"),
        size: wgpu::Extent3d { width: camera.width, height: camera.height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}

#[test]
fn the_display_pass_draws_each_mode_as_its_cpu_twin() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 64, 48);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let tracer = tracer(ctx, &trace);
    let mut view = ProgressiveTrace::new(&tracer, &camera, &Method::Stochastic, &Frames::default()).unwrap();
    view.step(&tracer, 6).unwrap();
    let state = view.read(ctx).unwrap();
    for format in [wgpu::TextureFormat::Rgba8Unorm, wgpu::TextureFormat::Rgba8UnormSrgb] {
        for mode in DisplayMode::ALL {
            let display = DisplayTransform { mode, depth_near: 2.0, depth_far: 8.0, variance_scale: 4.0 };
            let texture = target(ctx, &camera, format);
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            let view_of = texture.create_view(&Default::default());
            view.present(ctx, &mut encoder, &view_of, format, &display).unwrap();
            ctx.queue.submit([encoder.finish()]);
            let texels = read_rgba8(&ctx.device, &ctx.queue, &texture).unwrap();
            let mut worst = 0u8;
            let mut shown = 0usize;
            for (p, texel) in texels.chunks(4).enumerate() {
                let (x, y) = (p as u32 % camera.width, p as u32 / camera.width);
                let pixel = PixelState {
                    mean: state.mean.pixel(x, y).try_into().unwrap(),
                    variance: state.variance.pixel(x, y).try_into().unwrap(),
                    depth: state.depth.pixel(x, y)[0],
                    normal: state.normal.pixel(x, y).try_into().unwrap(),
                };
                let cpu = display.rgba8(&pixel);
                worst = worst.max(cpu.iter().zip(texel).map(|(a, b)| a.abs_diff(*b)).max().unwrap());
                shown += usize::from(cpu[0] > 0);
            }
            assert!(worst <= 1, "{mode:?} into {format:?}: a byte differs from the CPU twin by {worst}");
            assert!(shown > texels.len() / 40, "{mode:?} shows almost nothing ({shown} lit pixels)");
        }
    }
}

#[test]
fn a_context_on_the_callers_device_runs_the_kernels_and_too_few_bindings_are_refused() {
    let Some(ours) = context() else { return };
    let adapter = pollster::block_on(async {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        instance.request_adapter(&Default::default()).await
    })
    .expect("an adapter, as the shared context found one");
    let device =
        |descriptor: &wgpu::DeviceDescriptor| pollster::block_on(adapter.request_device(descriptor)).expect("device");
    let (d, q) = device(&wgpu::DeviceDescriptor::default());
    let refused = GpuContext::from_device(&adapter, d, q).err().expect("default limits are too few").to_string();
    assert!(refused.contains("storage buffers per shader stage"), "{refused}");
    let (d, q) = device(&GpuContext::device_descriptor(&adapter));
    let ctx = GpuContext::from_device(&adapter, d, q).expect("the descriptor's device");
    assert_eq!(ctx.info.name, ours.info.name);
    let (scene, camera) = fixture("cloud", 32, 24);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let pipeline = splat_gpu::TracePipeline::new(&ctx).unwrap();
    let on_theirs = splat_gpu::GpuTracer::new(&ctx, &pipeline, &trace).unwrap();
    let a = batch(&on_theirs, &camera, &Method::Stochastic, 4);
    let b = batch(&tracer(ours, &trace), &camera, &Method::Stochastic, 4);
    assert!(max_diff(a.mean.data(), b.mean.data()) < 1e-6);
}
