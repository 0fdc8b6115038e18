//! The GPU rasterizer at S samples per pixel (Laine & Karras 2011's MSAA setting): every raster
//! method's frame equals the CPU reference's frame at the standard sample pattern, decision for
//! decision; what the GPU cannot render is refused with a message.

mod common;

use common::{context, fixture};
use splat_core::frame::RenderOutput;
use splat_core::lighting::{Lighting, Look, Shadows};
use splat_core::mesh::{MeshMaterial, Meshes, TriangleMesh};
use splat_core::raster::{
    Blend, FragmentDepth, RasterMethod, RasterSettings, Rasterizer, SamplePattern, SplatExtent, render_raster,
};
use splat_core::{Camera, Frames, RenderSettings, Scene, lk_scenes};
use splat_gpu::{GpuContext, GpuRasterizer, RasterPipelines, RasterScene};
use std::sync::OnceLock;

fn pipelines(ctx: &GpuContext) -> &'static RasterPipelines {
    static PIPES: OnceLock<RasterPipelines> = OnceLock::new();
    PIPES.get_or_init(|| RasterPipelines::new(ctx).expect("raster pipelines"))
}

const METHODS: [RasterMethod; 6] = [
    RasterMethod::Sorted { blend: Blend::Over },
    RasterMethod::Sorted { blend: Blend::Under },
    RasterMethod::StochasticSplat,
    RasterMethod::Enderton,
    RasterMethod::Stratified { scramble: true },
    RasterMethod::Stratified { scramble: false },
];

fn standard(samples: u32, fragment_depth: FragmentDepth) -> RasterSettings {
    RasterSettings { samples, sample_pattern: SamplePattern::Standard, fragment_depth, ..RasterSettings::default() }
}

/// Pixels whose colour differs by more than `tol` or whose coverage differs, and the largest
/// colour difference of the others.
fn differing(a: &RenderOutput, b: &RenderOutput, tol: f32) -> (Vec<usize>, f32) {
    let pixels = a.alpha.data().len();
    let mut worst = 0.0f32;
    let bad = (0..pixels)
        .filter(|&p| {
            let d = (0..3).map(|c| (a.mean.data()[3 * p + c] - b.mean.data()[3 * p + c]).abs()).fold(0.0, f32::max);
            let da = (a.alpha.data()[p] - b.alpha.data()[p]).abs();
            // NaN counts as differing.
            let off = d.is_nan() || da.is_nan() || d > tol || da > tol;
            if !off {
                worst = worst.max(d);
            }
            off
        })
        .collect();
    (bad, worst)
}

struct Compared {
    /// Pixels that differ although no decision of theirs lay within 1e-5 of its threshold.
    bad: Vec<usize>,
    /// Pixels that differ by such a near decision or depth tie (f32 rounding may flip it).
    near: usize,
    /// Pixels with some coverage on the CPU.
    written: usize,
    worst: f32,
}

/// One frame (seed `seed`) of `method` at `raster` lit by `lighting` on both backends, the
/// CPU's samples at `cpu_pattern`.
#[allow(clippy::too_many_arguments)]
fn compare_with(
    ctx: &GpuContext,
    scene: &Scene,
    camera: &Camera,
    method: &RasterMethod,
    raster: RasterSettings,
    cpu_pattern: SamplePattern,
    seed: u32,
    lighting: &Lighting,
) -> Compared {
    compare_among(ctx, scene, &Meshes::none(), camera, method, raster, cpu_pattern, seed, lighting)
}

/// [`compare_with`] among `meshes`.
#[allow(clippy::too_many_arguments)]
fn compare_among(
    ctx: &GpuContext,
    scene: &Scene,
    meshes: &Meshes,
    camera: &Camera,
    method: &RasterMethod,
    raster: RasterSettings,
    cpu_pattern: SamplePattern,
    seed: u32,
    lighting: &Lighting,
) -> Compared {
    // A background that mirror shares reflect (forward-shaded, they see it).
    let settings = RenderSettings { background: glam::Vec3::new(0.25, 0.3, 0.35), ..RenderSettings::default() };
    let cpu_raster = RasterSettings { sample_pattern: cpu_pattern, ..raster };
    let cpu_r = Rasterizer::new(scene, camera, settings, cpu_raster)
        .unwrap()
        .with_meshes(meshes)
        .with_lighting(lighting)
        .unwrap();
    let frames = Frames { count: 1, seed, ..Frames::default() };
    let cpu = render_raster(&cpu_r, method, &frames, &|_| {}).unwrap();
    let gpu_scene = RasterScene::new_lit(ctx, scene, &settings, lighting).unwrap().with_meshes(ctx, meshes).unwrap();
    let gpu_r = GpuRasterizer::new(ctx, pipelines(ctx), &gpu_scene, camera, &raster).unwrap();
    let gpu = gpu_r.render(method, &frames).unwrap().0;
    let (differ, worst) = differing(&gpu, &cpu, 1e-5);
    let (near, bad): (Vec<usize>, Vec<usize>) = differ.iter().partition(|&&p| {
        let (x, y) = (p as u32 % camera.width, p as u32 / camera.width);
        let tie = raster.fragment_depth == FragmentDepth::Center
            && splat_tests::flips::raster_depth_gap(&cpu_r, x, y) < splat_tests::flips::DEPTH_TIE;
        // Line 9 sorts the survivors by the depth each sample holds: two samples' mesh depths
        // equal on the CPU (a plane seen at mirrored sample positions) may round apart on the GPU.
        let stored_tie = matches!(method, RasterMethod::Stratified { .. })
            && splat_tests::flips::raster_stored_depth_gap(&cpu_r, x, y) < splat_tests::flips::DEPTH_TIE;
        method.is_stochastic()
            && (tie
                || stored_tie
                || splat_tests::flips::raster_gap(&cpu_r, method, &frames, x, y) < splat_tests::flips::FLIP_GAP)
    });
    let written = cpu.alpha.data().iter().filter(|&&a| a > 0.0).count();
    Compared { bad, near: near.len(), written, worst }
}

fn compare(
    ctx: &GpuContext,
    scene: &Scene,
    camera: &Camera,
    method: &RasterMethod,
    raster: RasterSettings,
    seed: u32,
) -> Compared {
    compare_with(ctx, scene, camera, method, raster, raster.sample_pattern, seed, &Lighting::default())
}

/// One frame of every raster method at S = 4 standard samples equals the CPU frame pixel for
/// pixel (sample masks equal: the coverage is the written share of the samples), on three
/// fixtures, two seeds and two footprints (the 3DGS tiles, the √8σ ellipse); Enderton and stratified also at S = 8 and 16 (compute, any adapter).
#[test]
fn one_frame_at_standard_samples_equals_the_cpu_frame() {
    let Some(ctx) = context() else { return };
    eprintln!("adapter multisamples at {:?}", ctx.msaa_counts);
    for name in ["layers", "ramp", "cloud"] {
        let (scene, camera) = fixture(name, 64, 48);
        for method in METHODS {
            let counts: &[u32] = match method {
                RasterMethod::Enderton | RasterMethod::Stratified { .. } => &[4, 8, 16],
                _ => &[4, 8],
            };
            for &s in counts {
                if !matches!(method, RasterMethod::Enderton | RasterMethod::Stratified { .. })
                    && !ctx.msaa_counts.contains(&s)
                {
                    continue;
                }
                for (seed, extent) in [(3, SplatExtent::ThreeDgs), (4, SplatExtent::Sqrt8)] {
                    let raster = RasterSettings { extent, ..standard(s, FragmentDepth::Center) };
                    let c = compare(ctx, &scene, &camera, &method, raster, seed);
                    eprintln!(
                        "{name} {method:?} S = {s} seed {seed} {extent:?}: {} of {} written pixels differ by a near decision, max |Δ| of the rest {:.1e}",
                        c.near, c.written, c.worst
                    );
                    assert!(c.written > 64 * 48 / 10, "{name}: too few written pixels to test");
                    assert!(c.bad.is_empty(), "{name} {method:?} S = {s} seed {seed}: pixels {:?} differ", c.bad);
                }
            }
        }
    }
}

/// Lit, every raster method lights each sample along its own ray at its own depth, as the CPU
/// does: sorted splatting composited sample by sample in the tile pass (the surface look lit
/// once at sample 0's pick, the volumetric look every fragment), StochasticSplats shaded per sample, the compute raster operations (Enderton,
/// Laine–Karras) per written sample. One frame at S = 1 and 4 at centre depth and at S = 4 (and
/// 16 for the raster operations) at the max-density-plane depth equals the CPU's but for
/// decisions within 1e-5 of their threshold (sorted: within 1e-5, f32 against f64
/// compositing); lighting changes each image far beyond the tolerance.
#[test]
fn lit_frames_equal_the_cpu_at_every_sample_count() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("layers", 48, 36);
    let methods = [
        (RasterMethod::Sorted { blend: Blend::Over }, Look::Surface),
        (RasterMethod::Sorted { blend: Blend::Over }, Look::Volumetric),
        (RasterMethod::StochasticSplat, Look::Volumetric),
        (RasterMethod::Enderton, Look::Volumetric),
        (RasterMethod::Stratified { scramble: true }, Look::Volumetric),
    ];
    for (method, look) in methods {
        let lighting = common::lighting(Shadows::None, look);
        let sorted = matches!(method, RasterMethod::Sorted { .. });
        let rop = matches!(method, RasterMethod::Enderton | RasterMethod::Stratified { .. });
        for (s, depth) in [
            (1, FragmentDepth::Center),
            (4, FragmentDepth::Center),
            (4, FragmentDepth::MaxDensityPlane),
            (16, FragmentDepth::MaxDensityPlane),
        ] {
            let per_sample = s > 1 || depth == FragmentDepth::MaxDensityPlane;
            let plane = depth == FragmentDepth::MaxDensityPlane;
            if sorted && (plane || s > 4) {
                continue; // sorted splatting orders by centre depth; S = 16 adds nothing to S = 4
            }
            if !rop && !sorted && (!ctx.msaa_counts.contains(&s) || per_sample && !ctx.sample_rate_shading) {
                eprintln!("lit {method:?} {look:?} S = {s} {depth:?}: not on {}", ctx.describe());
                continue;
            }
            let c =
                compare_with(ctx, &scene, &camera, &method, standard(s, depth), SamplePattern::Standard, 3, &lighting);
            eprintln!(
                "lit {method:?} {look:?} S = {s} {depth:?}: {} of {} written pixels differ by a near decision",
                c.near, c.written
            );
            assert!(c.bad.is_empty(), "lit {method:?} {look:?} S = {s} {depth:?}: pixels {:?} differ", c.bad);
        }
        let frames = Frames { count: 1, seed: 3, ..Frames::default() };
        let settings = RenderSettings::default();
        let r = || Rasterizer::new(&scene, &camera, settings, standard(4, FragmentDepth::Center)).unwrap();
        let unlit = render_raster(&r(), &method, &frames, &|_| {}).unwrap();
        let lit = render_raster(&r().with_lighting(&lighting).unwrap(), &method, &frames, &|_| {}).unwrap();
        let (changed, _) = differing(&lit, &unlit, 0.01);
        assert!(changed.len() > 100, "{method:?}: lighting changes {} pixels only", changed.len());
    }
}

/// The comparison above can fail: against the CPU at the Hammersley positions (the same count,
/// other points; the decisions are keyed by sample index, so only footprint edges differ: the
/// √8σ ellipse cuts many pixels whose centre alpha passes the cull) every method differs on many
/// pixels.
#[test]
fn other_sample_positions_are_told_apart() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 64, 48);
    for method in METHODS {
        let raster = RasterSettings { extent: SplatExtent::Sqrt8, ..standard(4, FragmentDepth::Center) };
        let c = compare_with(ctx, &scene, &camera, &method, raster, SamplePattern::Hammersley, 3, &Lighting::default());
        eprintln!("{method:?}: {} pixels differ from the CPU at Hammersley positions", c.bad.len() + c.near);
        assert!(c.bad.len() > 20, "{method:?}: only {} pixels differ", c.bad.len());
    }
}

/// The max-density-plane depth (StochasticSplats' pop-free billboards): StochasticSplats written
/// through frag_depth at sample rate, Enderton and stratified in the compute raster operations,
/// equal the CPU frame at S = 1 and 4; the depth changes the image (centre depth differs).
#[test]
fn max_density_plane_frames_equal_the_cpu_frame() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("layers", 64, 48);
    let methods = [RasterMethod::StochasticSplat, RasterMethod::Enderton, RasterMethod::Stratified { scramble: true }];
    for method in methods {
        for s in [1, 4] {
            for seed in [3, 4] {
                let c = compare(ctx, &scene, &camera, &method, standard(s, FragmentDepth::MaxDensityPlane), seed);
                eprintln!(
                    "plane {method:?} S = {s} seed {seed}: {} of {} written pixels differ by a near decision, max |Δ| of the rest {:.1e}",
                    c.near, c.written, c.worst
                );
                assert!(c.bad.is_empty(), "plane {method:?} S = {s} seed {seed}: pixels {:?} differ", c.bad);
            }
        }
        let settings = RenderSettings::default();
        let cpu_centre = Rasterizer::new(&scene, &camera, settings, standard(4, FragmentDepth::Center)).unwrap();
        let frames = Frames { count: 1, seed: 3, ..Frames::default() };
        let centre = render_raster(&cpu_centre, &method, &frames, &|_| {}).unwrap();
        let gpu_scene = RasterScene::new(ctx, &scene, &settings).unwrap();
        let plane =
            GpuRasterizer::new(ctx, pipelines(ctx), &gpu_scene, &camera, &standard(4, FragmentDepth::MaxDensityPlane))
                .unwrap()
                .render(&method, &frames)
                .unwrap()
                .0;
        let (differ, _) = differing(&plane, &centre, 1e-5);
        assert!(differ.len() > 20, "{method:?}: the plane depth changed only {} pixels", differ.len());
    }
}

/// What the GPU cannot render at these settings is refused with a message naming it: the
/// Hammersley pattern at S > 1, sorted splatting at the plane depth, a count the adapter does not
/// multisample at, the iso-opacity depth at the plane depth, a mesh pre-pass above the binding
/// limit.
#[test]
fn unsupported_sample_settings_are_refused_with_a_message() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("layers", 16, 12);
    let settings = RenderSettings::default();
    let gpu_scene = RasterScene::new(ctx, &scene, &settings).unwrap();
    let frames = Frames::default();
    let sorted = RasterMethod::Sorted { blend: Blend::Over };
    let hammersley = RasterSettings { samples: 4, ..RasterSettings::default() };
    let e = GpuRasterizer::new(ctx, pipelines(ctx), &gpu_scene, &camera, &hammersley).err().unwrap().to_string();
    assert!(e.contains("use the standard sample pattern or the CPU backend"), "{e}");
    let plane =
        GpuRasterizer::new(ctx, pipelines(ctx), &gpu_scene, &camera, &standard(1, FragmentDepth::MaxDensityPlane))
            .unwrap();
    let e = plane.render(&sorted, &frames).unwrap_err().to_string();
    assert!(e.contains("max-density plane") && e.contains("the CPU backend"), "{e}");
    for s in [2, 8, 16] {
        let r =
            GpuRasterizer::new(ctx, pipelines(ctx), &gpu_scene, &camera, &standard(s, FragmentDepth::Center)).unwrap();
        match r.render(&RasterMethod::StochasticSplat, &frames) {
            Ok(_) => assert!(ctx.msaa_counts.contains(&s), "S = {s} rendered although the adapter lacks it"),
            Err(e) => {
                let e = e.to_string();
                assert!(!ctx.msaa_counts.contains(&s), "S = {s}: {e}");
                assert!(e.contains(&format!("{:?}", ctx.msaa_counts)), "{e}");
            }
        }
    }
    let four = standard(4, FragmentDepth::Center);
    let r = GpuRasterizer::new(ctx, pipelines(ctx), &gpu_scene, &camera, &standard(4, FragmentDepth::MaxDensityPlane))
        .unwrap();
    let e = r.depth_pick().expect_err("depth pick at the plane depth").to_string();
    assert!(e.contains("centre-depth order") && e.contains("the CPU backend"), "{e}");
    // Among meshes the pre-pass holds every sample; where that exceeds the adapter's binding
    // limit the rasterizer is refused before any work, with the sizes.
    let wall = splat_tests::placed(
        splat_core::mesh::TriangleMesh::plane(),
        3.0,
        glam::Vec3::Z,
        glam::Vec3::new(0.0, 0.0, -1.2),
    );
    let meshes = splat_core::mesh::Meshes::new(&[(wall, splat_core::mesh::MeshMaterial::default())]).unwrap();
    let among = RasterScene::new(ctx, &scene, &settings).unwrap().with_meshes(ctx, &meshes).unwrap();
    GpuRasterizer::new(ctx, pipelines(ctx), &among, &camera, &four).expect("the pre-pass fits the real limit");
    // The check comes first, so the pipelines of the other device are never touched.
    let small = GpuContext::new().unwrap().with_binding_limit(16 * 16 * 12 * 4 - 1);
    let among = RasterScene::new(&small, &scene, &settings).unwrap().with_meshes(&small, &meshes).unwrap();
    let e = GpuRasterizer::new(&small, pipelines(ctx), &among, &camera, &four).err().unwrap().to_string();
    assert!(e.contains("mesh pre-pass") && e.contains("16 × 12 × 4 samples") && e.contains("the CPU backend"), "{e}");
}

/// A view of the bonsai capture whose tiles hold more splats than lavapipe's loop budget lets one
/// dispatch walk: Enderton and stratified take the lists in chunks (the state kept between
/// them), and the frame still equals the CPU's at S = 4.
#[test]
fn long_tile_lists_are_walked_in_chunks_and_equal_the_cpu() {
    let Some(ctx) = context() else { return };
    let Some(bonsai) = splat_tests::bonsai() else { return };
    let camera = splat_tests::bonsai_camera().rescaled(300, 200).unwrap().crop(112, 80, 64, 16).unwrap();
    let scene = splat_tests::in_view(&bonsai, &camera);
    let settings = RenderSettings::default();
    let gpu_scene = RasterScene::new(ctx, &scene, &settings).unwrap();
    let raster = standard(4, FragmentDepth::Center);
    let gpu = GpuRasterizer::new(ctx, pipelines(ctx), &gpu_scene, &camera, &raster).unwrap();
    let (chunk, chunks) = gpu.raster_operation_chunks().unwrap();
    eprintln!("{} splats in view, lists walked {chunk} splats at a time in {chunks} chunks", scene.particles.len());
    if ctx.info.device_type == wgpu::DeviceType::Cpu {
        assert!(chunks > 1, "the view should need several chunks on lavapipe");
    }
    for method in [RasterMethod::Enderton, RasterMethod::Stratified { scramble: true }] {
        let c = compare(ctx, &scene, &camera, &method, raster, 3);
        eprintln!("bonsai {method:?}: {} near, max |Δ| {:.1e}", c.near, c.worst);
        assert!(c.written > 64 * 16 / 2 && c.bad.is_empty(), "bonsai {method:?}: pixels {:?} differ", c.bad);
    }
}

/// Transparent mesh triangles are fragments of Enderton's and Laine–Karras's raster operations,
/// drawn before the splats in the meshes' order: one frame equals the CPU's frame at S = 4, 8
/// and 16 on Laine & Karras's Figure 3b stack (five quads at α = 0.75, no splats) and on the
/// splat sheets among a lit transparent quad slanted through them, a quad whose opacity ramps
/// per vertex, and an opaque quad behind (its depth test: a mesh pre-pass of opaque triangles
/// only); and on the motor (a tile's triangles walked in chunks on lavapipe). Sorted splatting
/// and StochasticSplats refuse them, naming the raster operations.
#[test]
fn transparent_triangles_are_fragments_of_the_raster_operations() {
    let Some(ctx) = context() else { return };
    let stack = lk_scenes::stack();
    let (sheets, sheets_camera) = fixture("layers", 64, 48);
    let lit = |color| MeshMaterial { color, opacity: 0.45, ..MeshMaterial::default() };
    let mut ramp = splat_tests::placed(TriangleMesh::plane(), 0.5, glam::Vec3::Z, glam::Vec3::new(0.3, -0.1, -0.35));
    ramp.opacities = ramp.positions.iter().map(|p| 0.2 + 0.6 * (p.x + 0.2)).collect();
    let among = Meshes::new(&[
        (
            splat_tests::placed(
                TriangleMesh::plane(),
                0.6,
                glam::Vec3::new(0.4, 0.3, 1.0),
                glam::Vec3::new(0.0, 0.0, 0.05),
            ),
            lit(glam::Vec3::new(0.2, 0.6, 0.9)),
        ),
        // Its gold-tinted mirror share sees the background by Schlick's Fresnel.
        (
            ramp,
            MeshMaterial {
                color: glam::Vec3::new(0.9, 0.5, 0.1),
                mirror: 0.4,
                mirror_tint: glam::Vec3::new(1.0, 0.78, 0.34),
                ..MeshMaterial::default()
            },
        ),
        (
            splat_tests::placed(TriangleMesh::plane(), 1.5, glam::Vec3::Z, glam::Vec3::new(0.0, 0.0, -1.0)),
            MeshMaterial::default(),
        ),
    ])
    .unwrap();
    let lighting = common::lighting(Shadows::None, Look::Volumetric);
    let motor = lk_scenes::motor(8);
    let motor_camera = motor.camera.crop(48, 32, 48, 32).unwrap();
    let cases = [
        ("stack", &stack.scene, &stack.meshes, stack.camera, &stack.lighting, &[4u32, 8, 16][..]),
        ("sheets among quads", &sheets, &among, sheets_camera, &lighting, &[4, 8, 16][..]),
        ("motor", &motor.scene, &motor.meshes, motor_camera, &motor.lighting, &[4][..]),
    ];
    for (name, scene, meshes, camera, lighting, counts) in cases {
        for method in [RasterMethod::Enderton, RasterMethod::Stratified { scramble: true }] {
            for &s in counts {
                let raster = standard(s, FragmentDepth::Center);
                let c =
                    compare_among(ctx, scene, meshes, &camera, &method, raster, SamplePattern::Standard, 5, lighting);
                eprintln!(
                    "{name} {method:?} S = {s}: {} of {} written pixels differ by a near decision, max |Δ| of the rest {:.1e}",
                    c.near, c.written, c.worst
                );
                let pixels = (camera.width * camera.height) as usize;
                assert!(c.written > pixels / 4, "{name}: too few written pixels to test");
                assert!(c.bad.is_empty(), "{name} {method:?} S = {s}: pixels {:?} differ", c.bad);
            }
        }
    }
    let settings = RenderSettings::default();
    let motor_scene = RasterScene::new(ctx, &motor.scene, &settings).unwrap().with_meshes(ctx, &motor.meshes).unwrap();
    let motor_r =
        GpuRasterizer::new(ctx, pipelines(ctx), &motor_scene, &motor_camera, &standard(4, FragmentDepth::Center))
            .unwrap();
    let (per_chunk, chunks) = motor_r.triangle_operation_chunks();
    eprintln!("motor: the longest tile list walked {per_chunk} triangles at a time in {chunks} chunks");
    if ctx.info.device_type == wgpu::DeviceType::Cpu {
        assert!(chunks > 1, "the motor's tiles should need several chunks on lavapipe");
    }
    for method in [RasterMethod::Sorted { blend: Blend::Under }, RasterMethod::StochasticSplat] {
        let refused = motor_r.render(&method, &Frames::default()).unwrap_err().to_string();
        assert!(refused.contains("draws no transparent mesh triangles") && refused.contains("Enderton"), "{refused}");
    }
}
