//! GPU frames against the core on lavapipe in CI: the same decisions frame by frame, buffer
//! limits, lavapipe's loop budget, accumulation precision.

mod common;

use common::{context, fixture, gpu_run, lighting, trace_pipeline, tracer};
use glam::Vec3;
use splat_core::catalogue::Family;
use splat_core::frame::RenderOutput;
use splat_core::lighting::{Look, Shadows};
use splat_core::mesh::{MeshMaterial, Meshes, TriangleMesh};
use splat_core::sh::ShStorage;
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{Algorithm, Frames, MethodId, Parameters, RenderSettings};
use splat_gpu::{AccumulationFormat, Accumulator, GpuContext, GpuError, GpuTracer, PartBindings};
use splat_tests::flips::{FLIP_GAP, FLOAT_TOLERANCE};

/// Every ray-tracing method of the catalogue that has a GPU kernel (a method added to the
/// catalogue is tested here without a line more), with small parameters: k = 4 hits a pass
/// (several passes for the k-buffer and the stochastic pass), 2 traversals of 3 samples.
fn methods() -> Vec<(&'static str, Method)> {
    let p = Parameters { k: 4, m: 2, n: 3, ..Parameters::default() };
    let methods: Vec<_> = MethodId::of(Family::Trace)
        .filter(|id| id.entry().gpu)
        .map(|id| match id.algorithm(&p) {
            Algorithm::Trace(method) => (id.name(), method),
            other => panic!("{id:?} is in the ray-tracing family but builds {other:?}"),
        })
        .collect();
    assert!(methods.len() >= 6, "the catalogue lists {} GPU ray-tracing methods", methods.len());
    methods
}

/// One frame with a fixed seed makes the same decisions on both backends: every pixel agrees
/// to f32 compositing tolerance, for the deterministic methods without exception, for the
/// stochastic ones except where a decision of the pixel had |u − threshold| < 1e-5 (counted,
/// and each one checked through the CPU's own decisions).
#[test]
fn one_frame_equals_the_cpu_frame() {
    let Some(ctx) = context() else { return };
    for fixture_name in ["layers", "cloud"] {
        let (scene, camera) = fixture(fixture_name, 40, 30);
        let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
        let tracer = tracer(ctx, &trace);
        for (name, method) in methods() {
            let frames = Frames { count: 1, seed: 11, ..Frames::default() };
            let cpu = render_frames(&trace, &camera, &method, &frames, &|_| {}).unwrap();
            let gpu = gpu_run(&tracer, &camera, &method, frames);
            let (mut near, mut bad) = (0, Vec::new());
            for (p, (a, b)) in cpu.mean.data().chunks(3).zip(gpu.mean.data().chunks(3)).enumerate() {
                let worst = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
                if worst.is_nan() || worst > FLOAT_TOLERANCE {
                    let (x, y) = (p as u32 % camera.width, p as u32 / camera.width);
                    let gap = if method.is_stochastic() {
                        splat_tests::flips::trace_gap(&trace, &camera, &method, &frames, x, y)
                    } else {
                        f64::INFINITY
                    };
                    if gap < FLIP_GAP { near += 1 } else { bad.push((x, y, worst, gap)) }
                }
            }
            eprintln!("{fixture_name} {name}: {near} pixels differ by a decision within {FLIP_GAP} of its threshold");
            let first: Vec<_> = bad.iter().take(8).collect();
            assert!(
                bad.is_empty(),
                "{fixture_name} {name}: {} pixels differ; the first (x, y, difference, gap): {first:?}",
                bad.len()
            );
        }
    }
}

/// Lit, one frame makes the same decisions and the same shading on both backends, for every
/// shadow kind (vk's sorted pass with a coloured tint, the stochastic shadow ray, the exact
/// transmittance) and both looks: as [`one_frame_equals_the_cpu_frame`].
#[test]
fn one_lit_frame_equals_the_cpu_frame() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("layers", 32, 24);
    let sorted = Shadows::Sorted { k: 8, threshold: 0.8, colored: 0.5 };
    let unlit = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let cases = [
        (Shadows::None, Look::Surface),
        (sorted, Look::Surface),
        (Shadows::Stochastic, Look::Surface),
        (Shadows::Exact, Look::Volumetric),
        (Shadows::Stochastic, Look::Volumetric),
    ];
    for (shadows, look) in cases {
        let trace =
            TraceScene::new(&scene, RenderSettings::default()).unwrap().with_lighting(lighting(shadows, look)).unwrap();
        let tracer = tracer(ctx, &trace);
        for (name, method) in methods() {
            let frames = Frames { count: 1, seed: 11, ..Frames::default() };
            let cpu = render_frames(&trace, &camera, &method, &frames, &|_| {}).unwrap();
            let gpu = gpu_run(&tracer, &camera, &method, frames);
            // The comparison means something: lighting changes the frame far beyond the tolerance.
            let plain = render_frames(&unlit, &camera, &method, &frames, &|_| {}).unwrap();
            let lit_effect = max_difference(cpu.mean.data(), plain.mean.data());
            assert!(lit_effect > 0.1, "{shadows:?} {look:?} {name}: lighting changes the frame by {lit_effect} only");
            let (mut near, mut bad, mut largest) = (0, Vec::new(), 0.0f32);
            for (p, (a, b)) in cpu.mean.data().chunks(3).zip(gpu.mean.data().chunks(3)).enumerate() {
                let worst = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
                largest = largest.max(worst);
                if worst.is_nan() || worst > LIT_TOLERANCE {
                    let (x, y) = (p as u32 % camera.width, p as u32 / camera.width);
                    let gap = splat_tests::flips::trace_gap(&trace, &camera, &method, &frames, x, y);
                    if gap < FLIP_GAP { near += 1 } else { bad.push((x, y, worst, gap)) }
                }
            }
            eprintln!(
                "{shadows:?} {look:?} {name}: largest difference {largest:.1e}, {near} pixels differ by a decision near its threshold"
            );
            assert!(bad.is_empty(), "{shadows:?} {look:?} {name}: pixels (x, y, difference, gap) {bad:?}");
        }
    }
}

/// The GPU tracer reports frame 0's depth, normal and picked particle as the CPU does, unlit and
/// lit (with max-density-plane and kernel-ellipsoid normals, vk_gaussian_splatting Lighting
/// §2.4), for every method: at each pixel the same pick, the depth within 10⁻⁴ (relative) or
/// absent on both, the normal within 10⁻³; a pixel may differ only where a stochastic decision
/// lay within [`FLIP_GAP`] of its threshold or, for at most 1 % of pixels, where the f32 and f64
/// transmittances fall on either side of the iso threshold.
#[test]
fn depth_normal_and_picks_equal_the_cpu() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 24, 18);
    let unlit = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let lit = TraceScene::new(&scene, RenderSettings::default())
        .unwrap()
        .with_lighting(lighting(Shadows::None, Look::Surface))
        .unwrap();
    let ellipsoid =
        RenderSettings { normal_mode: splat_core::normal::NormalMode::KernelEllipsoid, ..RenderSettings::default() };
    let lit_ellipsoid =
        TraceScene::new(&scene, ellipsoid).unwrap().with_lighting(lighting(Shadows::None, Look::Surface)).unwrap();
    // The ellipsoid's normals are other normals: the control of its case.
    let normals =
        |t: &TraceScene| render_frames(t, &camera, &Method::Exact, &Frames::default(), &|_| {}).unwrap().normal;
    let apart = max_difference(normals(&lit).data(), normals(&lit_ellipsoid).data());
    assert!(apart > 0.1, "the kernel ellipsoid's normals are the plane's ({apart})");
    for (label, trace) in [("unlit", &unlit), ("lit", &lit), ("lit, ellipsoid normals", &lit_ellipsoid)] {
        let tracer = tracer(ctx, trace);
        // The normal mode changes the normal only: two methods suffice for the ellipsoid.
        let only = |name: &str| {
            trace.settings().normal_mode != ellipsoid.normal_mode || ["exact", "stochastic"].contains(&name)
        };
        for (name, method) in methods().into_iter().filter(|(name, _)| only(name)) {
            let frames = Frames { count: 1, seed: 11, ..Frames::default() };
            let cpu = render_frames(trace, &camera, &method, &frames, &|_| {}).unwrap();
            let gpu = gpu_run(&tracer, &camera, &method, frames);
            let pixels = (camera.width * camera.height) as usize;
            let agrees = |i: usize| {
                let (dc, dg) = (cpu.depth.data()[i], gpu.depth.data()[i]);
                let depth = (dc.is_nan() && dg.is_nan()) || (dc - dg).abs() <= 1e-4 * dc.abs().max(1.0);
                let normal = max_difference(&cpu.normal.data()[3 * i..3 * i + 3], &gpu.normal.data()[3 * i..3 * i + 3]);
                depth && normal <= 1e-3 && cpu.picked[i] == gpu.picked[i]
            };
            let differing: Vec<usize> = (0..pixels).filter(|&i| !agrees(i)).collect();
            let unexplained: Vec<usize> = differing
                .iter()
                .copied()
                .filter(|&i| {
                    let (x, y) = (i as u32 % camera.width, i as u32 / camera.width);
                    splat_tests::flips::trace_gap(trace, &camera, &method, &frames, x, y) >= FLIP_GAP
                })
                .collect();
            let with_depth = cpu.depth.data().iter().filter(|d| !d.is_nan()).count();
            eprintln!(
                "{label} {name}: {} of {pixels} pixels differ, {} not by a decision near its threshold ({with_depth} with a depth)",
                differing.len(),
                unexplained.len()
            );
            assert!(with_depth > pixels / 10, "{label} {name}: too few depths to test");
            assert!(unexplained.len() * 100 <= pixels, "{label} {name}: pixels {unexplained:?}");
        }
    }
}

/// Meshes on the GPU ray tracer (splat_core::mesh): a lit back wall behind the sheets, a sphere
/// among them and a quad that shadows them; the sphere matte, then glass (index 1.5) with the
/// quad a half gold mirror, so that every segment kind runs (camera, reflected, refracted, total
/// internal reflection). One frame of every method, for three shadow kinds and both looks,
/// equals the CPU frame as [`one_lit_frame_equals_the_cpu_frame`] does, and so do depth, normal
/// and pick (the mesh's where the splats stay below the iso threshold); the meshes change every
/// frame far beyond the tolerance. A pixel may differ only where a decision lay near its
/// threshold or, for at most 1 % of pixels, where f32 rounding along a bounce path (a direction
/// off a tessellated sphere) moves a secondary ray across a splat's edge.
#[test]
fn one_frame_among_meshes_equals_the_cpu_frame() {
    let Some(ctx) = context() else { return };
    let matte_world = mesh_world(matte(0.9, 0.3, 0.2), matte(0.5, 0.5, 0.5));
    let glass = MeshMaterial { transmission: 0.9, ior: 1.5, ..MeshMaterial::default() };
    let mirror = MeshMaterial { mirror: 0.5, mirror_tint: GOLD, ..matte(0.5, 0.5, 0.5) };
    let bounce_world = mesh_world(glass, mirror);
    let sorted = Shadows::Sorted { k: 8, threshold: 0.8, colored: 0.5 };
    let cases = [
        (sorted, Look::Surface, &matte_world),
        (Shadows::Stochastic, Look::Surface, &matte_world),
        (Shadows::Exact, Look::Volumetric, &matte_world),
        (Shadows::Stochastic, Look::Surface, &bounce_world),
        (Shadows::Exact, Look::Volumetric, &bounce_world),
    ];
    for (shadows, look, meshes) in cases {
        frames_among_meshes_equal_the_cpu(ctx, meshes, shadows, look);
    }
}

/// Transparent meshes on the GPU ray tracer (trace/mod.rs `surface_sample`): the sphere of
/// [`one_frame_among_meshes_equals_the_cpu_frame`] at opacity 0.5 (two layers), its quad a half
/// mirror at opacity 0.6 (the ray continued past it and its mirror ray, weighted 1 − α and α),
/// and a quad whose opacity ramps per vertex, before the back wall; shadow rays carry Π (1 − α).
/// One frame of every method, for two shadow kinds and both looks, equals the CPU's frame,
/// depth, normal and pick as there; the transparency changes every frame far beyond the
/// tolerance.
#[test]
fn one_frame_among_transparent_meshes_equals_the_cpu_frame() {
    let Some(ctx) = context() else { return };
    let mut ramp = splat_tests::placed(TriangleMesh::plane(), 0.45, Vec3::Z, Vec3::new(0.25, 0.15, -0.75));
    ramp.opacities = ramp.positions.iter().map(|p| 0.3 + 0.5 * (p.x - 0.25)).collect();
    let see_through = |m: MeshMaterial, opacity| MeshMaterial { opacity, ..m };
    let mirror = MeshMaterial { mirror: 0.5, mirror_tint: GOLD, ..matte(0.5, 0.5, 0.5) };
    let mut world = vec![
        (splat_tests::placed(TriangleMesh::plane(), 3.0, Vec3::Z, Vec3::new(0.0, 0.0, -1.2)), matte(0.8, 0.75, 0.7)),
        (sphere(), see_through(matte(0.9, 0.3, 0.2), 0.5)),
        (quad(), see_through(mirror, 0.6)),
    ];
    world.push((ramp, matte(0.2, 0.5, 0.9)));
    let transparent = Meshes::new(&world).unwrap();
    let opaque =
        Meshes::new(&world.iter().map(|(m, mat)| (m.clone(), see_through(*mat, 1.0))).collect::<Vec<_>>()).unwrap();
    for (shadows, look) in [(Shadows::Exact, Look::Volumetric), (Shadows::Stochastic, Look::Surface)] {
        let seen = frames_among_meshes_equal_the_cpu(ctx, &transparent, shadows, look);
        let (scene, camera) = fixture("layers", 32, 24);
        let trace = TraceScene::new(&scene, among_meshes_settings())
            .unwrap()
            .with_lighting(lighting(shadows, look))
            .unwrap()
            .with_meshes(opaque.clone());
        let frames = Frames { count: 1, seed: 11, ..Frames::default() };
        let behind_opaque = render_frames(&trace, &camera, &Method::Exact, &frames, &|_| {}).unwrap();
        let effect = max_difference(seen.mean.data(), behind_opaque.mean.data());
        assert!(effect > 0.1, "{shadows:?} {look:?}: transparency changes the exact frame by {effect} only");
    }
    // More bounces among transparent mirrors than the segment stack holds: refused, not cut.
    let (scene, _) = fixture("layers", 32, 24);
    let deep = RenderSettings { max_bounces: splat_gpu::MAX_LAYERED_BOUNCES + 1, ..RenderSettings::default() };
    let trace = TraceScene::new(&scene, deep).unwrap().with_meshes(transparent);
    let pipeline = trace_pipeline(ctx);
    let refused = GpuTracer::new(ctx, pipeline, &trace).err().expect("refused").to_string();
    assert!(refused.contains("at most 7") && refused.contains("CPU"), "{refused}");
}

/// The settings of the frames among meshes: a background, which the mirrors reflect.
fn among_meshes_settings() -> RenderSettings {
    RenderSettings { background: Vec3::new(0.25, 0.3, 0.35), ..RenderSettings::default() }
}

/// A gold's reflectance at normal incidence, the tint of the mirrors here.
const GOLD: Vec3 = Vec3::new(1.0, 0.78, 0.34);

fn matte(r: f32, g: f32, b: f32) -> MeshMaterial {
    MeshMaterial { color: Vec3::new(r, g, b), ..MeshMaterial::default() }
}

fn sphere() -> TriangleMesh {
    splat_tests::placed(TriangleMesh::sphere(24, 12), 0.35, Vec3::Y, Vec3::new(-0.3, -0.2, 0.3))
}

fn quad() -> TriangleMesh {
    splat_tests::placed(TriangleMesh::plane(), 0.4, Vec3::new(1.0, 1.0, 1.5), Vec3::new(0.9, 0.9, 1.4))
}

/// A lit back wall, the sphere (material `sphere`) and the quad (material `quad`).
fn mesh_world(sphere_material: MeshMaterial, quad_material: MeshMaterial) -> Meshes {
    Meshes::new(&[
        (splat_tests::placed(TriangleMesh::plane(), 3.0, Vec3::Z, Vec3::new(0.0, 0.0, -1.2)), matte(0.8, 0.75, 0.7)),
        (sphere(), sphere_material),
        (quad(), quad_material),
    ])
    .unwrap()
}

/// One frame of every method among `meshes` on the layers fixture, by `shadows` and `look`, on
/// both backends: colour, depth, normal and pick equal but where a decision lay near its
/// threshold or (at most 1 % of pixels) f32 rounding moved a bounce; the meshes change each frame
/// beyond the tolerance. Returns the CPU's exact frame.
fn frames_among_meshes_equal_the_cpu(
    ctx: &'static GpuContext,
    meshes: &Meshes,
    shadows: Shadows,
    look: Look,
) -> RenderOutput {
    let (scene, camera) = fixture("layers", 32, 24);
    let lit = lighting(shadows, look);
    let bare = TraceScene::new(&scene, among_meshes_settings()).unwrap().with_lighting(lit.clone()).unwrap();
    let trace = TraceScene::new(&scene, among_meshes_settings())
        .unwrap()
        .with_lighting(lit)
        .unwrap()
        .with_meshes(meshes.clone());
    let tracer = tracer(ctx, &trace);
    let frames = Frames { count: 1, seed: 11, ..Frames::default() };
    for (name, method) in methods() {
        let cpu = render_frames(&trace, &camera, &method, &frames, &|_| {}).unwrap();
        let gpu = gpu_run(&tracer, &camera, &method, frames);
        let without = render_frames(&bare, &camera, &method, &frames, &|_| {}).unwrap();
        let effect = max_difference(cpu.mean.data(), without.mean.data());
        assert!(effect > 0.1, "{shadows:?} {look:?} {name}: the meshes change the frame by {effect} only");
        let (mut near, mut bad) = (0, Vec::new());
        let pixels = (camera.width * camera.height) as usize;
        for p in 0..pixels {
            let colour = max_difference(&cpu.mean.data()[3 * p..3 * p + 3], &gpu.mean.data()[3 * p..3 * p + 3]);
            let (dc, dg) = (cpu.depth.data()[p], gpu.depth.data()[p]);
            let depth = (dc.is_nan() && dg.is_nan()) || (dc - dg).abs() <= 1e-4 * dc.abs().max(1.0);
            let normal = max_difference(&cpu.normal.data()[3 * p..3 * p + 3], &gpu.normal.data()[3 * p..3 * p + 3]);
            if colour.is_nan() || colour > LIT_TOLERANCE || !depth || normal > 1e-3 || cpu.picked[p] != gpu.picked[p] {
                let (x, y) = (p as u32 % camera.width, p as u32 / camera.width);
                let gap = splat_tests::flips::trace_gap(&trace, &camera, &method, &frames, x, y);
                if gap < FLIP_GAP { near += 1 } else { bad.push((x, y, colour, gap)) }
            }
        }
        eprintln!(
            "meshes {shadows:?} {look:?} {name}: {near} pixels differ by a decision near its threshold, {} by rounding",
            bad.len()
        );
        assert!(bad.len() * 100 <= pixels, "{shadows:?} {look:?} {name}: pixels (x, y, difference, gap) {bad:?}");
    }
    render_frames(&trace, &camera, &Method::Exact, &frames, &|_| {}).unwrap()
}

fn max_difference(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

/// Lit frames add f32 shading (pow, sin/cos of the light samples, normalisation) to the f32
/// compositing of [`FLOAT_TOLERANCE`].
const LIT_TOLERANCE: f32 = 1e-3;

/// A scene whose particles, BVH nodes (the splats', then the meshes') and SH coefficients are
/// split over several bindings each (`splat_gpu::split`, forced by small binding limits) reads
/// through the kernel's accessors every element the scene in one binding each reads, bit for
/// bit: with parts of a power of two, a last part shorter, and (at SH degree 2, 9 coefficients
/// a particle) particles whose coefficients straddle two parts. With the kernel reading those
/// arrays through the accessors alone (`the_kernel_reads_the_scene_arrays_through_their_accessors`)
/// and the whole scene's frames equal to the CPU's (the tests above), a split scene renders the
/// whole scene's frames; this checks it element by element without compiling the whole kernel
/// for each split (lavapipe: 40 s for 2 × 2 × 2 parts, 80 s for 3 × 2 × 7). Each split with its
/// parts after the first in binding arrays, and one binding each. A part bound at another's
/// binding, or an element read from the wrong part, fails.
#[test]
fn split_scenes_read_every_element_of_the_whole_ones() {
    let Some(ctx) = context() else { return };
    let (mut scene, _) = fixture("cloud", 8, 8);
    scene.sh_degree = 2;
    let world = [
        (splat_tests::placed(TriangleMesh::plane(), 3.0, Vec3::Z, Vec3::new(0.0, 0.0, -1.2)), matte(0.8, 0.75, 0.7)),
        (
            splat_tests::placed(TriangleMesh::sphere(48, 24), 0.35, Vec3::Y, Vec3::new(-0.3, -0.2, 0.3)),
            matte(0.9, 0.3, 0.2),
        ),
    ];
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap().with_meshes(Meshes::new(&world).unwrap());
    let whole = tracer(ctx, &trace).arrays_as_read().unwrap();
    let counts = [scene.particles.len() * 4, 0, scene.particles.len() * 9];
    assert!(
        whole[0].len() == counts[0] && whole[2].len() == counts[2] && whole[1].len() > 2985,
        "{:?}",
        whole.each_ref().map(Vec::len)
    );
    // 3,000 particles and 27,000 SH coefficients of 64 and 16 bytes, about 1,270 nodes of 64
    // (four rows each): parts of 1,024, 1,024 and 4,096 elements at 64 KiB, of 2,048, 2,048
    // and 8,192 at 128 KiB.
    for (limit, parts) in [(64 * 1024, [3, 2, 7]), (128 * 1024, [2, 1, 4])] {
        for (bound, small) in common::part_binding_contexts(|c| c.with_binding_limit(limit)) {
            let pipeline = splat_gpu::TracePipeline::new(&small).unwrap();
            let split = GpuTracer::new(&small, &pipeline, &trace).expect("the split scene binds");
            let s = split.split();
            assert_eq!(([s.particles.parts, s.nodes.parts, s.sh.parts], s.parts), (parts, bound), "{s:?}");
            let read = split.arrays_as_read().unwrap();
            for (k, name) in ["particle", "node", "SH"].iter().enumerate() {
                let first = whole[k].iter().zip(&read[k]).position(|(a, b)| a != b);
                let same = first.is_none() && whole[k].len() == read[k].len();
                assert!(same, "{limit} bytes, {bound:?}: {name} row {first:?} differs");
            }
        }
    }
}

/// With f16 or u8 SH storage (`RenderSettings::sh_storage`, a half or a quarter of the SH
/// memory) the kernel reads every coefficient as the CPU does, `ShStorage::load` of it, bit for
/// bit, whole and split over bindings (27,000 coefficients of 8 or 4 bytes at 64 KiB: 4 or 2
/// parts), and the particles and nodes as with f32: so a render from compact storage is the
/// CPU's render at the same setting, as the f32 kernel's is at f32. A decode that swapped two
/// channels, dropped a half or took the DC term's scale for another's fails.
#[test]
fn compact_sh_reads_the_cpus_rounded_coefficients() {
    let Some(ctx) = context() else { return };
    let (mut scene, _) = fixture("cloud", 8, 8);
    scene.sh_degree = 2;
    let f32_trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let whole = tracer(ctx, &f32_trace).arrays_as_read().unwrap();
    let small = GpuContext::new().unwrap().with_binding_limit(64 * 1024);
    let pipeline = splat_gpu::TracePipeline::new(&small).unwrap();
    for (storage, sh_parts) in [(ShStorage::F16, 4), (ShStorage::U8, 2)] {
        let settings = RenderSettings { sh_storage: storage, ..RenderSettings::default() };
        let trace = TraceScene::new(&scene, settings).unwrap();
        let expected: Vec<[u32; 4]> = scene
            .particles
            .iter()
            .flat_map(|p| (0..9).map(move |k| storage.load(p.sh[k], k)))
            .map(|c| [c.x.to_bits(), c.y.to_bits(), c.z.to_bits(), 0])
            .collect();
        assert!(expected.iter().zip(&whole[2]).any(|(a, b)| a != b), "{storage:?} rounds some coefficient");
        for (ctx, pipeline) in [(ctx, trace_pipeline(ctx)), (&small, &pipeline)] {
            let gpu = GpuTracer::new(ctx, pipeline, &trace).unwrap();
            let read = gpu.arrays_as_read().unwrap();
            assert_eq!(read[..2], whole[..2], "particles and nodes as with f32 SH");
            let first = expected.iter().zip(&read[2]).position(|(a, b)| a != b);
            assert!(first.is_none() && read[2].len() == expected.len(), "{:?}: SH row {first:?} differs", gpu.split());
            assert_eq!(gpu.split().sh_storage, storage);
        }
        let split = GpuTracer::new(&small, &pipeline, &trace).unwrap().split();
        assert_eq!((split.particles.parts, split.sh.parts), (3, sh_parts), "{split:?}");
    }
}

/// A scene whose split needs more bindings than the adapter has is refused (before its BVH is
/// built) with the sizes, the limits and how many particles like these would fit; that count
/// fits and 10 % more does not: with the parts one binding each (over the storage bindings a
/// stage) and in binding arrays (over 24 buffers in them a stage).
#[test]
fn scenes_over_the_bindings_are_refused_with_what_fits() {
    let Some(ctx) = context() else { return };
    for (_, small) in common::part_binding_contexts(|c| c.with_binding_limit(4096).with_binding_array_elements(24)) {
        refused_with_what_fits(ctx, &small);
    }
    // The adapter's own bindings hold a scene of this kind ten thousand times as large, in
    // arrays of buffers (lavapipe 25: 48 storage bindings and a million buffers in arrays a
    // stage, of 128 MiB each).
    if ctx.binding_array_elements_per_stage() > 0 {
        let (scene, _) = fixture("cloud", 8, 8);
        let n = 10_000 * scene.particles.len() as u64;
        assert!(splat_gpu::TraceSplit::capacity(ctx, scene.sh_degree, ShStorage::F32) >= n);
        assert!(splat_gpu::RasterSplit::capacity(ctx) >= n);
    }
}

/// A scene whose arrays hold more elements than the kernels' u32 indices reach is refused for
/// that, whatever the adapter's bindings (with binding arrays it would bind them all), with how
/// many particles like it fit: the ray tracer's SH of a degree-3 scene (16 coefficients a
/// particle) and the splatting kernels' canonical rows (3 a particle) pass the bound first.
#[test]
fn scenes_past_the_kernels_indices_are_refused_for_them() {
    if context().is_none() {
        return;
    }
    let max = u64::from(u32::MAX);
    for (parts, c) in common::part_binding_contexts(|c| c) {
        // In binding arrays the indices alone bound what fits; a binding a part, the bindings.
        let fits_all = |fits: u64, bound: u64| if parts == PartBindings::Array { fits == bound } else { fits < bound };
        let n = max / 16 + 1;
        let refused = splat_gpu::TraceSplit::new(&c, [n, n / 4, 16 * n], ShStorage::F32);
        let Err(e @ GpuError::SceneOverIndices { elements, fits, .. }) = refused else {
            panic!("{n} SH-3 particles: {refused:?}")
        };
        assert!(elements == 16 * n && fits_all(fits, max / 16), "{parts:?}: {e}");
        assert!(e.to_string().contains("32-bit integers (at most 4294967295)"), "{e}");
        assert!(e.remedies().contains(&splat_gpu::Remedy::Cpu));
        let n = max / 3 + 1;
        let refused = splat_gpu::RasterSplit::new(&c, n as usize, ShStorage::F32);
        let Err(e @ GpuError::SceneOverIndices { elements, fits, .. }) = refused else {
            panic!("{n} particles: {refused:?}")
        };
        assert!(elements == 3 * n && fits_all(fits, max / 3), "{parts:?}: {e}");
    }
}

/// A scene whose arrays the device's memory left cannot hold is refused before its BVH is built
/// (`TraceSplit::at_least`, with the estimated nodes) and before its splats are projected
/// (`RasterSplit::new`), naming what they need; arrays that fit are accepted. A CPU adapter's
/// memory left is the host's.
#[test]
fn scenes_over_the_devices_memory_are_refused_before_they_are_built() {
    let Some(ctx) = context() else { return };
    let (scene, _) = fixture("cloud", 8, 8);
    let settings = RenderSettings::default();
    let n = scene.particles.len() as u64;
    let coefficients = splat_core::particle::sh_coeff_count(scene.sh_degree) as u64;
    // The ray tracer's arrays (particles, estimated nodes, SH): refused in no memory, accepted in
    // what they need, refused in a byte less.
    let needed = match splat_gpu::TraceSplit::at_least(
        &GpuContext::new().unwrap().with_memory_available(0),
        &scene,
        &settings,
    ) {
        Err(e @ GpuError::MemoryShort { bytes, available: 0, .. }) => {
            assert!(
                e.to_string().contains("particles, BVH nodes and SH") && e.remedies().contains(&splat_gpu::Remedy::Cpu)
            );
            bytes
        }
        other => panic!("{other:?}"),
    };
    assert!(needed > n * (coefficients * 4), "{needed} bytes for {n} particles");
    let tight = GpuContext::new().unwrap().with_memory_available(needed);
    assert!(splat_gpu::TraceSplit::at_least(&tight, &scene, &settings).is_ok());
    let short = GpuContext::new().unwrap().with_memory_available(needed - 1);
    assert!(matches!(splat_gpu::TraceSplit::at_least(&short, &scene, &settings), Err(GpuError::MemoryShort { .. })));
    // The splatting arrays: a 64-byte projected splat, three 16-byte canonical rows and three
    // u32 of the depth sort a particle.
    let raster = |available| {
        let c = GpuContext::new().unwrap().with_memory_available(available);
        splat_gpu::RasterSplit::new(&c, n as usize, ShStorage::F32).map(|_| ())
    };
    assert!(matches!(raster(n * 124 - 1), Err(GpuError::MemoryShort { bytes, .. }) if bytes == n * 124));
    assert!(raster(n * 124).is_ok());
    // A CPU adapter reports the host's memory left; a hardware one nothing.
    let cpu = ctx.info.device_type == splat_gpu::wgpu::DeviceType::Cpu;
    assert_eq!(ctx.memory_available().is_some(), cpu && splat_core::host::available().is_some());
}

/// [`scenes_over_the_bindings_are_refused_with_what_fits`] on `small`.
fn refused_with_what_fits(ctx: &'static GpuContext, small: &GpuContext) {
    let (scene, _) = fixture("cloud", 8, 8);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let pipeline = splat_gpu::TracePipeline::new(small).unwrap();
    let (n, nodes) = (scene.particles.len() as u64, trace.bvh().len() as u64);
    let coefficients = splat_core::particle::sh_coeff_count(scene.sh_degree) as u64;
    let fits = match GpuTracer::new(small, &pipeline, &trace) {
        Err(e @ GpuError::SceneOverBindings { limit: 4096, fits, .. }) => {
            let msg = e.to_string();
            assert!(msg.contains("4096 bytes") && msg.contains(&format!("fits about {fits} particles")), "{msg}");
            fits
        }
        Err(e) => panic!("unexpected error {e}"),
        Ok(_) => panic!("a scene over the bindings was accepted"),
    };
    let like = |m: u64| splat_gpu::TraceSplit::new(small, [m, nodes * m / n, coefficients * m], ShStorage::F32);
    assert!(fits > 0 && fits < n && like(fits).is_ok() && like(fits + fits / 10).is_err(), "fits {fits} of {n}");
    let early = splat_gpu::TraceSplit::at_least(small, &scene, &RenderSettings::default());
    assert!(matches!(early, Err(GpuError::SceneOverBindings { .. })), "{early:?}");
    assert!(GpuTracer::new(ctx, trace_pipeline(ctx), &trace).is_ok());

    // The capacities `splat bench` prints are the largest scenes accepted: c particles (with the
    // wide nodes the estimate gives them) are, c + 1 are not; u8 SH holds more than f32; the
    // adapter's own limits hold this scene, and the estimate is within 10 % of its nodes.
    let capacity = |storage| splat_gpu::TraceSplit::capacity(small, scene.sh_degree, storage);
    let about = splat_gpu::TraceSplit::nodes_about;
    let with = |m: u64, storage| splat_gpu::TraceSplit::new(small, [m, about(m), coefficients * m], storage);
    assert!(about(n).abs_diff(nodes) * 10 <= nodes, "{nodes} nodes for {n} particles, estimated {}", about(n));
    for storage in [ShStorage::F32, ShStorage::U8] {
        let c = capacity(storage);
        assert!(c > 0 && with(c, storage).is_ok() && with(c + 1, storage).is_err(), "{storage:?}: capacity {c}");
    }
    assert!(capacity(ShStorage::U8) > capacity(ShStorage::F32));
    assert!(splat_gpu::TraceSplit::capacity(ctx, scene.sh_degree, ShStorage::F32) >= n);
    let r = splat_gpu::RasterSplit::capacity(small) as usize;
    let raster = |m| splat_gpu::RasterSplit::new(small, m, ShStorage::F32);
    assert!(r > 0 && raster(r).is_ok() && raster(r + 1).is_err(), "splatting capacity {r}");
    assert!(splat_gpu::RasterSplit::capacity(ctx) >= n);
}

/// vk_gaussian_splatting's warning, measured: a running mean stored in f16 drifts away from the
/// exact (f64) mean of the same frames as frames accumulate, while f32 does not.
#[test]
fn f16_accumulation_drifts_and_f32_does_not() {
    let Some(ctx) = context() else { return };
    let pixels = 256usize;
    let frames = 1024u32;
    // Binary samples (0 or a colour), as a stochastic estimator produces them.
    let sample = |i: usize, f: u32| -> [f32; 4] {
        let u = splat_core::rng::unit_f32(splat_core::rng::pcg(splat_core::rng::xxhash32([i as u32, f, 77])));
        let p = 0.05 + 0.9 * (i as f32 / pixels as f32);
        if u < p { [0.8, 0.45, 0.9, 1.0] } else { [0.0, 0.0, 0.0, 0.0] }
    };
    let mut acc = [AccumulationFormat::F32, AccumulationFormat::F16, AccumulationFormat::Unorm8]
        .map(|f| Accumulator::new(ctx, pixels, f));
    let mut exact = vec![[0.0f64; 4]; pixels];
    let mut report = Vec::new();
    for f in 0..frames {
        let frame: Vec<[f32; 4]> = (0..pixels).map(|i| sample(i, f)).collect();
        for (e, s) in exact.iter_mut().zip(&frame) {
            for c in 0..4 {
                e[c] += (f64::from(s[c]) - e[c]) / f64::from(f + 1);
            }
        }
        for a in &mut acc {
            a.add(ctx, &frame).unwrap();
        }
        if (f + 1).is_power_of_two() && f + 1 >= 16 {
            let errors: Vec<f64> = acc
                .iter()
                .map(|a| {
                    let got = a.read(ctx).unwrap();
                    got.iter()
                        .zip(&exact)
                        .flat_map(|(g, e)| (0..3).map(move |c| (f64::from(g[c]) - e[c]).abs()))
                        .fold(0.0, f64::max)
                })
                .collect();
            report.push((f + 1, errors));
        }
    }
    for (n, e) in &report {
        eprintln!("{n:>5} frames: max |error| f32 {:.2e}, f16 {:.2e}, 8-bit {:.2e}", e[0], e[1], e[2]);
    }
    let last = &report.last().unwrap().1;
    let at_64 = &report.iter().find(|(n, _)| *n == 64).unwrap().1;
    assert!(last[0] < 1e-4, "f32 drifted: {}", last[0]);
    assert!(last[1] > 4.0 * at_64[1].max(1e-4), "f16 did not drift: {report:?}");
    assert!(last[1] > 1.0 / 255.0, "f16 error stays below one 8-bit step: {report:?}");
}

/// The kernels store the running mean as `Frames::accumulation` says, as the CPU does: 64
/// frames of `stochastic` (the ray-tracing kernel's fold) and of StochasticSplats (the raster
/// fold) in f16 and 8-bit unorm agree with the CPU's frames stored the same way, to within the
/// f16 or 8-bit step plus the rare decision that falls within f32 rounding of its threshold;
/// each format is far from the full-precision mean of the same frames (the control).
#[test]
fn the_kernels_store_the_running_mean_as_the_cpu_does() {
    use splat_core::frame::AccumulationFormat;
    use splat_core::raster::{RasterMethod, RasterSettings};
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 32, 24);
    let (settings, lighting, meshes) =
        (RenderSettings::default(), splat_core::lighting::Lighting::default(), splat_core::mesh::Meshes::none());
    let shot =
        splat_core::Shot { scene: &scene, meshes: &meshes, lighting: &lighting, camera: &camera, settings: &settings };
    let raster =
        RasterSettings { sample_pattern: splat_core::raster::SamplePattern::Standard, ..RasterSettings::default() };
    for algorithm in [Algorithm::Trace(Method::Stochastic), Algorithm::Raster(RasterMethod::StochasticSplat, raster)] {
        let run = |accumulation| {
            let frames = Frames { count: 64, seed: 4, accumulation, ..Frames::default() };
            let cpu = algorithm.render_world(&shot, &frames, &|_| {}).unwrap();
            let gpu = splat_gpu::render(ctx, &algorithm, &shot, splat_gpu::Extras::default(), &frames).unwrap();
            (cpu, gpu)
        };
        let (full_cpu, _) = run(AccumulationFormat::F32);
        // f16: the kernels' bit-pattern rounding (common.wgsl `round_f16`) is the CPU's, so a
        // bound far below what truncation instead of rounding would leave (~10⁻⁴); 8 bits: a
        // quarter step, ties rounded in f32 on the GPU and f64 on the CPU.
        for (format, bound) in [(AccumulationFormat::F16, 1e-5), (AccumulationFormat::Unorm8, 0.25 / 255.0)] {
            let (cpu, gpu) = run(format);
            let mean = mean_difference(cpu.mean.data(), gpu.mean.data());
            let control = mean_difference(full_cpu.mean.data(), gpu.mean.data());
            eprintln!(
                "{algorithm:?} {}: mean |GPU − CPU| {mean:.2e}, against full precision {control:.2e}",
                format.name()
            );
            assert!(mean < bound, "{algorithm:?} {}: {mean}", format.name());
            assert!(control > 2.0 * mean, "{algorithm:?} {}: the format changes nothing ({control})", format.name());
        }
    }
}

/// On lavapipe a multi-pass ray too long for one invocation (a k-buffer of one hit a pass
/// re-traverses the cloud's dense core once per hit; 64 samples per traversal) runs one pass
/// (one slot) per dispatch, its state kept in a buffer, and still equals the CPU; a single
/// traversal that is too long is refused with an error naming the pixel, never returned cut
/// short.
#[test]
fn rays_over_the_loop_budget_run_by_pass_or_are_refused_on_lavapipe() {
    let Some(ctx) = context() else { return };
    if ctx.info.device_type != wgpu::DeviceType::Cpu {
        splat_tests::not_applicable(&splat_tests::current_test(), &format!("{} has no loop limiter", ctx.describe()));
        return;
    }
    let (scene, camera) = fixture("cloud", 32, 24);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let gpu_tracer = tracer(ctx, &trace);
    for (method, count) in [
        (Method::KBuffer { k: 1, max_passes: 10_000, min_transmittance: 0.0 }, 1),
        (Method::StochasticPass { k: 1, max_passes: 200 }, 3),
        (Method::StochasticN { m: 1, n: 64 }, 2),
    ] {
        let frames = Frames { count, seed: 5, ..Frames::default() };
        let (gpu, stats) = gpu_tracer.render(&camera, &method, &frames).unwrap();
        let cpu = render_frames(&trace, &camera, &method, &frames, &|_| {}).unwrap();
        assert!(stats.pass_per_dispatch, "{method:?} fit in one invocation: the test shows nothing");
        let worst = cpu.mean.data().iter().zip(gpu.mean.data()).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "{method:?}: GPU differs from CPU by {worst}");
    }
    // 12,000 particles of opacity 0.5 on one line, and every draw raised by 0.6 (the u_shift
    // test hook lowers u by −0.6), so that no particle is ever accepted: a single stochastic
    // traversal visits every one. (Particles below the 1/255 cull would not do: their bounds are
    // empty, and no ray visits them.)
    let particles = (0..12_000)
        .map(|i| {
            let mean = glam::Vec3::new(0.0, 0.0, 1.0 + i as f32 * 0.01);
            splat_core::Particle::with_rgb(mean, glam::Vec3::splat(0.2), glam::Quat::IDENTITY, 0.5, glam::Vec3::ONE)
        })
        .collect();
    let line = splat_core::Scene::new(particles, 0);
    let camera = splat_core::Camera::look_at(glam::Vec3::ZERO, glam::Vec3::Z, glam::Vec3::Y, 1.0, 4, 4).unwrap();
    let trace = TraceScene::new(&line, RenderSettings::default()).unwrap();
    let never = Frames { u_shift: -0.6, ..Frames::default() };
    match tracer(ctx, &trace).render(&camera, &Method::Stochastic, &never) {
        Err(e @ GpuError::LoopBudget { .. }) => {
            assert!(e.to_string().contains("the CPU backend") && e.remedies() == [splat_gpu::Remedy::Cpu], "{e}")
        }
        Err(e) => panic!("unexpected error {e}"),
        Ok((_, stats)) => panic!("accepted {} loop iterations with {} lanes", stats.loop_iterations, ctx.lanes()),
    }
}

/// The GPU time of a render (timestamp queries when the adapter has them, else wall time
/// around submit and wait) is positive and within the wall time of the call, and grows with
/// the work: 16 frames take longer than 1, each the fastest of three runs (speed itself is
/// measured by `splat bench --backend gpu`, not asserted here).
#[test]
fn gpu_time_is_measured_within_the_wall_time() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 48, 36);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let tracer = tracer(ctx, &trace);
    let time = |count| {
        let start = std::time::Instant::now();
        let frames = Frames { count, ..Frames::default() };
        let (_, stats) = tracer.render(&camera, &Method::Stochastic, &frames).unwrap();
        (stats.gpu_time, start.elapsed())
    };
    // Each the fastest of three, so that other tests' load on the machine does not decide.
    let fastest = |count| (0..3).map(|_| time(count)).min_by_key(|t| t.0).unwrap();
    let (one, wall_one) = fastest(1);
    let (many, wall_many) = fastest(16);
    eprintln!("GPU time 1 frame {one:?} (wall {wall_one:?}), 16 frames {many:?} (wall {wall_many:?})");
    assert!(one > std::time::Duration::ZERO && one <= wall_one, "{one:?} vs wall {wall_one:?}");
    assert!(many <= wall_many && many > one, "{many:?} vs {one:?}, wall {wall_many:?}");
}

/// The measurement behind the README's figures on batching frames per dispatch on lavapipe:
/// 256 frames of `stochastic` on `layers` at 32 × 24, one frame per dispatch against the
/// batched default, wall time and the growth of the process's resident memory. A report, not
/// a pass/fail test: `cargo test --release -p splat-gpu --test gpu_frames -- --ignored
/// --nocapture batching`.
#[test]
#[ignore]
fn batching_frames_per_dispatch_report() {
    let rss_kb = || -> u64 {
        let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
        let line = status.lines().find(|l| l.starts_with("VmRSS")).unwrap_or("VmRSS: 0 kB");
        line.split_whitespace().nth(1).and_then(|v| v.parse().ok()).unwrap_or(0)
    };
    let (scene, camera) = fixture("layers", 32, 24);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    for per_dispatch in [1, splat_gpu::FRAMES_PER_DISPATCH] {
        let Ok(mut ctx) = GpuContext::new() else { return splat_tests::skip("batching report", "no GPU adapter") };
        ctx.frames_per_dispatch = per_dispatch;
        let pipeline = splat_gpu::TracePipeline::new(&ctx).unwrap();
        let tracer = GpuTracer::new(&ctx, &pipeline, &trace).unwrap();
        let (before, start) = (rss_kb(), std::time::Instant::now());
        let frames = Frames { count: 256, seed: 1, ..Frames::default() };
        let (_, stats) = tracer.render(&camera, &Method::Stochastic, &frames).unwrap();
        let (time, grown) = (start.elapsed(), rss_kb().saturating_sub(before));
        eprintln!(
            "at most {per_dispatch} frames a dispatch ({} used): {time:?}, +{grown} kB",
            stats.frames_per_dispatch
        );
    }
}

/// Meshes for the hybrid tests: a lit wall behind the layers, a glass sphere and a half mirror.
fn hybrid_meshes() -> splat_core::mesh::Meshes {
    use glam::Vec3;
    use splat_core::mesh::{MeshMaterial, Meshes, TriangleMesh};
    let place = splat_tests::placed;
    Meshes::new(&[
        (place(TriangleMesh::plane(), 3.0, Vec3::Z, Vec3::new(0.0, 0.0, -1.2)), MeshMaterial::default()),
        (
            place(TriangleMesh::sphere(24, 12), 0.35, Vec3::Y, Vec3::new(-0.3, -0.2, 0.3)),
            MeshMaterial { transmission: 0.9, ior: 1.5, ..MeshMaterial::default() },
        ),
        (
            place(TriangleMesh::plane(), 0.4, Vec3::new(1.0, 1.0, 1.5), Vec3::new(0.9, 0.9, 1.4)),
            MeshMaterial { mirror: 0.5, ..MeshMaterial::default() },
        ),
    ])
    .unwrap()
}

/// The hybrid pipeline (vk_gaussian_splatting Lighting §5) makes the CPU's frame from rasterized
/// sorted splatting: colour, depth, normal and pick, among a glass sphere, a half mirror and a
/// lit wall, in both looks (the volumetric one lights every fragment with the tracer's shadow
/// rays, the rasterizer listing each sample's fragments for it), with stochastic and exact
/// shadows and secondary rays; the shadows change the image (the hybrid differs from plain lit
/// rasterization) far beyond the tolerance.
#[test]
fn hybrid_frame_equals_the_cpu_frame() {
    use splat_core::raster::{Blend, RasterMethod, RasterSettings, Rasterizer, render_raster};
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("layers", 32, 24);
    let meshes = hybrid_meshes();
    let pipes = splat_gpu::RasterPipelines::new(ctx).unwrap();
    let under = RasterMethod::Sorted { blend: Blend::Under };
    let raster = RasterSettings::default();
    let cases = [
        (Shadows::Stochastic, Look::Surface, Method::Stochastic),
        (Shadows::Exact, Look::Surface, Method::Exact),
        (Shadows::Stochastic, Look::Volumetric, Method::Stochastic),
        (Shadows::Exact, Look::Volumetric, Method::Exact),
    ];
    for (shadows, look, secondary) in cases {
        let lighting = lighting(shadows, look);
        let settings = RenderSettings::default();
        let trace = TraceScene::new(&scene, settings)
            .unwrap()
            .with_lighting(lighting.clone())
            .unwrap()
            .with_meshes(meshes.clone());
        let frames = Frames { count: 1, seed: 7, ..Frames::default() };
        let cpu_r = Rasterizer::new(&scene, &camera, settings, raster).unwrap().hybrid(&trace, secondary).unwrap();
        let cpu = render_raster(&cpu_r, &under, &frames, &|_| {}).unwrap();
        let plain = Rasterizer::new(&scene, &camera, settings, raster)
            .unwrap()
            .with_lighting(lighting.clone())
            .unwrap()
            .with_meshes(meshes.clone());
        let plain = render_raster(&plain, &under, &frames, &|_| {}).unwrap();
        let effect = max_difference(cpu.mean.data(), plain.mean.data());
        assert!(effect > 0.1, "{shadows:?} {look:?}: the ray tracer changes the image by {effect} only");
        let gpu_scene = splat_gpu::RasterScene::new_lit(ctx, &scene, &settings, &lighting)
            .unwrap()
            .with_meshes(ctx, &meshes)
            .unwrap();
        let rasterizer = |c: &splat_core::Camera| splat_gpu::GpuRasterizer::new(ctx, &pipes, &gpu_scene, c, &raster);
        let tracer = tracer(ctx, &trace);
        let gpu = tracer.render_hybrid(&rasterizer, &camera, &under, &secondary, &frames).unwrap().0;
        let bad = hybrid_pixels_apart(&cpu, &gpu, |_| false);
        eprintln!("hybrid {shadows:?} {look:?} {secondary:?}: {} pixels differ", bad.len());
        assert!(bad.is_empty(), "{shadows:?} {look:?} {secondary:?}: pixels {bad:?}");
    }
}

/// The pixels (index) where the hybrid's GPU image leaves the CPU's: colour beyond
/// [`LIT_TOLERANCE`], depth, normal or pick, unless `flip(pixel)` says a decision of the pixel lay
/// within f32 rounding of its threshold.
fn hybrid_pixels_apart(cpu: &RenderOutput, gpu: &RenderOutput, flip: impl Fn(usize) -> bool) -> Vec<usize> {
    let pixels = cpu.picked.len();
    (0..pixels)
        .filter(|&p| {
            let colour = max_difference(&cpu.mean.data()[3 * p..3 * p + 3], &gpu.mean.data()[3 * p..3 * p + 3]);
            colour.is_nan() || colour > LIT_TOLERANCE || !same_surface(cpu, gpu, p)
        })
        .filter(|&p| !flip(p))
        .collect()
}

/// Whether pixel `p` of the two images has the same depth (10⁻⁴ relative, or none on both),
/// normal (10⁻³) and pick.
fn same_surface(cpu: &RenderOutput, gpu: &RenderOutput, p: usize) -> bool {
    let (dc, dg) = (cpu.depth.data()[p], gpu.depth.data()[p]);
    let depth = (dc.is_nan() && dg.is_nan()) || (dc - dg).abs() <= 1e-4 * dc.abs().max(1.0);
    let normal = max_difference(&cpu.normal.data()[3 * p..3 * p + 3], &gpu.normal.data()[3 * p..3 * p + 3]);
    depth && normal <= 1e-3 && cpu.picked[p] == gpu.picked[p]
}

/// One hybrid render of `first` among [`hybrid_meshes`] through `splat_gpu::render` against the
/// CPU's `Algorithm::render_world` (exact secondary rays): every pixel agrees (colour, frame 0's
/// depth, normal and pick) except where a stochastic decision of one of its frames lay within
/// f32 rounding of its threshold (checked through the CPU rasterizer of that frame's camera) or,
/// with exact shadows, for at most 1 % of the pixels, by a shadow ray's hit at the kernel's
/// cull. Returns the GPU's image.
fn hybrid_agrees(
    ctx: &splat_gpu::GpuContext,
    first: splat_core::raster::RasterMethod,
    raster: splat_core::raster::RasterSettings,
    lighting: &splat_core::lighting::Lighting,
    sampling: splat_core::camera_sampling::CameraSampling,
) -> RenderOutput {
    use splat_core::camera_sampling::frame_sample;
    use splat_core::raster::Rasterizer;
    use splat_tests::flips::raster_frame_gap;
    let (scene, camera) = fixture("layers", 32, 24);
    let meshes = hybrid_meshes();
    let frames = Frames { count: 3, seed: 9, ..Frames::default() };
    let settings = RenderSettings { sampling, ..RenderSettings::default() };
    let shot = splat_core::Shot { scene: &scene, meshes: &meshes, lighting, camera: &camera, settings: &settings };
    let algorithm = Algorithm::Hybrid(first, raster, Method::Exact);
    let cpu = algorithm.render_world(&shot, &frames, &|_| {}).unwrap();
    let gpu = splat_gpu::render(ctx, &algorithm, &shot, splat_gpu::Extras::default(), &frames).unwrap();
    let trace =
        TraceScene::new(&scene, settings).unwrap().with_lighting(lighting.clone()).unwrap().with_meshes(meshes.clone());
    let flip = |p: usize| {
        let (x, y) = (p as u32 % camera.width, p as u32 / camera.width);
        first.is_stochastic()
            && (0..frames.count).any(|f| {
                let c = if sampling.is_random() {
                    sampling.pinhole(&camera, &frame_sample(frames.seed, f)).unwrap()
                } else {
                    camera
                };
                let r = Rasterizer::new(&scene, &c, settings, raster).unwrap().hybrid(&trace, Method::Exact).unwrap();
                let key = splat_core::rng::frame_key(frames.seed, f);
                raster_frame_gap(&r, &first, key, frames.u_shift, x, y) < FLIP_GAP
            })
    };
    let bad = hybrid_pixels_apart(&cpu, &gpu, flip);
    let name = format!(
        "{} first hit at S = {}, lit {} {:?} look, camera {sampling:?}",
        first.id().name(),
        raster.samples,
        lighting.is_on(),
        lighting.look
    );
    // Exact shadows are continuous but for the kernel's cull (α ≥ 1/255 at a shadow ray's
    // hit): a hit at the cull may count on one backend only, moving the pixel by at most
    // ALPHA_CULL × its light; at most 1 % of the pixels may differ by that alone.
    let exact = lighting.shadows == Shadows::Exact;
    let culled = |p: &usize| {
        let (c, g) = (&cpu.mean.data()[3 * p..3 * p + 3], &gpu.mean.data()[3 * p..3 * p + 3]);
        max_difference(c, g) <= splat_core::kernel::ALPHA_CULL && same_surface(&cpu, &gpu, *p)
    };
    let (at_cull, bad): (Vec<usize>, Vec<usize>) = bad.into_iter().partition(|p| exact && culled(p));
    eprintln!("hybrid with {name}: {} pixels apart, {} by a shadow hit at the cull", bad.len(), at_cull.len());
    assert!(at_cull.len() <= (cpu.picked.len() / 100).max(1), "hybrid with {name}: {at_cull:?} differ by the cull");
    assert!(bad.is_empty(), "hybrid with {name}: pixels {bad:?}");
    gpu
}

/// The GPU hybrid's other first hit and its moving camera (vk_gaussian_splatting stochastic
/// transparency page; Sun et al. §4.2's camera rays drawn per frame), [`hybrid_agrees`] with the
/// CPU among the meshes of [`hybrid_frame_equals_the_cpu_frame`], lit with exact shadows:
///
/// - StochasticSplats' closest accepted fragment as the first hit, three frames (each decided
///   again), in both looks (its one opaque fragment is lit as the pick either way), and the
///   sample Enderton's and stratified raster operations write;
/// - sorted splatting and StochasticSplats through a box pixel filter and a thin lens, three
///   frames, each rasterized through its own pinhole camera.
///
/// Controls: the stochastic first hit differs from the sorted one, and the moving camera from
/// the still one, far beyond the tolerance.
#[test]
fn the_hybrid_takes_stochastic_first_hits_and_a_camera_drawn_per_frame() {
    use splat_core::camera_sampling::{CameraSampling, PixelFilter, ThinLens};
    use splat_core::raster::{Blend, RasterMethod, RasterSettings};
    let Some(ctx) = context() else { return };
    let raster = RasterSettings::default();
    let (sorted, accepted) = (RasterMethod::Sorted { blend: Blend::Under }, RasterMethod::StochasticSplat);
    let moving =
        CameraSampling { filter: PixelFilter::Box, lens: Some(ThinLens { aperture: 0.15, focus_distance: 3.0 }) };
    let render = |first, look, sampling| hybrid_agrees(ctx, first, raster, &lighting(Shadows::Exact, look), sampling);
    let still = CameraSampling::default();
    let sorted_still = render(sorted, Look::Surface, still);
    let accepted_still = render(accepted, Look::Surface, still);
    render(accepted, Look::Volumetric, still);
    // Enderton's and Laine–Karras's raster operations at one sample write one splat too.
    render(RasterMethod::Enderton, Look::Surface, still);
    render(RasterMethod::Stratified { scramble: true }, Look::Surface, still);
    let sorted_moving = render(sorted, Look::Surface, moving);
    render(accepted, Look::Surface, moving);
    let first_hits = max_difference(sorted_still.mean.data(), accepted_still.mean.data());
    let camera_moves = max_difference(sorted_still.mean.data(), sorted_moving.mean.data());
    eprintln!(
        "controls: stochastic against sorted first hit {first_hits:.3}, moving against still camera {camera_moves:.3}"
    );
    assert!(first_hits > 0.1 && camera_moves > 0.05, "controls: {first_hits}, {camera_moves}");
}

/// The hybrid at four samples per pixel ([`hybrid_agrees`]): the ray tracer continues each
/// sample's own camera ray from its first hit (raster/mod.rs: the pixel is the mean of its
/// samples). Sorted splatting unlit (each sample's composite over what it sees behind), in the
/// surface look (the mean radiance lit once at sample 0's pick, each sample adding its
/// transmittance times what lies behind it) and in the volumetric look (each sample's fragments
/// lit with shadow rays), StochasticSplats in both looks and Enderton and
/// stratified (each sample's written splat lit as its pick), through a still camera and one
/// drawn per frame. Control: the image differs from the one-sample hybrid's far beyond the
/// tolerance.
#[test]
fn the_hybrid_continues_every_sample_of_the_pixel() {
    use splat_core::camera_sampling::{CameraSampling, PixelFilter};
    use splat_core::raster::{Blend, RasterMethod, RasterSettings, SamplePattern};
    let Some(ctx) = context() else { return };
    let four = RasterSettings { samples: 4, sample_pattern: SamplePattern::Standard, ..RasterSettings::default() };
    let (sorted, accepted) = (RasterMethod::Sorted { blend: Blend::Under }, RasterMethod::StochasticSplat);
    let (still, moving) = (CameraSampling::default(), CameraSampling { filter: PixelFilter::Box, lens: None });
    let surface = lighting(Shadows::Exact, Look::Surface);
    let at_four = hybrid_agrees(ctx, sorted, four, &surface, still);
    hybrid_agrees(ctx, sorted, four, &splat_core::lighting::Lighting::default(), still);
    hybrid_agrees(ctx, sorted, four, &lighting(Shadows::Exact, Look::Volumetric), moving);
    hybrid_agrees(ctx, accepted, four, &surface, still);
    hybrid_agrees(ctx, accepted, four, &lighting(Shadows::Exact, Look::Volumetric), moving);
    hybrid_agrees(ctx, RasterMethod::Enderton, four, &surface, still);
    hybrid_agrees(ctx, RasterMethod::Stratified { scramble: true }, four, &surface, moving);
    let at_one = hybrid_agrees(ctx, sorted, RasterSettings::default(), &surface, still);
    let samples = max_difference(at_one.mean.data(), at_four.mean.data());
    eprintln!("control: four samples against one {samples:.3}");
    assert!(samples > 0.05, "control: {samples}");
}

/// Through each lens family (a distorted perspective lens with every kind of coefficient, a
/// distorted fisheye seeing past 90°, the equirectangular 360° lens) the GPU's rays, its
/// undistortion in f32 (`lens.wgsl`), give the CPU's `exact` frame to the compositing
/// tolerance; the control, the CPU through the pinhole of the same intrinsics, is far off.
#[test]
fn frames_through_each_lens_equal_the_cpu_frames() {
    use splat_core::camera::{Distortion, Lens};
    let Some(ctx) = context() else { return };
    let (scene, pinhole) = fixture("cloud", 40, 30);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let tracer = tracer(ctx, &trace);
    let distortion = Distortion {
        radial: [-0.25, 0.08, -0.01, 0.0],
        rational: [0.03, -0.01, 0.002],
        tangential: [1.5e-3, -1e-3],
        prism: [4e-4, -2e-4],
    };
    let wide = splat_core::Camera { fx: 0.35 * 40.0, fy: 0.35 * 40.0, ..pinhole };
    let fisheye = Distortion { radial: [0.04, -0.01, 0.002, -3e-4], rational: [0.0; 3], ..distortion };
    let method = Method::Exact;
    let frames = Frames { count: 1, seed: 3, ..Frames::default() };
    let render = |camera: &splat_core::Camera| render_frames(&trace, camera, &method, &frames, &|_| {}).unwrap();
    for (name, camera) in [
        ("perspective", pinhole.with_lens(Lens::Perspective(distortion)).unwrap()),
        ("fisheye", wide.with_lens(Lens::Fisheye(fisheye)).unwrap()),
        ("equirectangular", pinhole.with_lens(Lens::Equirectangular).unwrap()),
    ] {
        let cpu = render(&camera);
        let gpu = gpu_run(&tracer, &camera, &method, frames);
        let d = max_difference(cpu.mean.data(), gpu.mean.data());
        let control =
            max_difference(render(&splat_core::Camera { lens: Lens::Pinhole, ..camera }).mean.data(), gpu.mean.data());
        eprintln!("{name}: |GPU − CPU| {d:.1e}, |GPU − CPU pinhole| {control:.1e}");
        assert!(d <= FLOAT_TOLERANCE, "{name}: the GPU's rays through the lens differ from the CPU's by {d}");
        assert!(control > 0.05, "{name}: the lens changes nothing ({control})");
    }
}

/// Each hit distance convention (vk_gaussian_splatting Lighting §1.4: the maximum density, the
/// billboard through the centre, the icosahedron proxy's front face) on the GPU gives the CPU's
/// frame: `exact` and the k-buffer (whose passes depend on the order the distances give) to
/// the compositing tolerance, and the picked depth to 10⁻⁴ relative; the conventions' depths
/// differ from each other by far more.
#[test]
fn each_hit_distance_gives_the_cpu_frame() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 40, 30);
    let frames = Frames { count: 1, seed: 2, ..Frames::default() };
    let mut depths = Vec::new();
    for hit_distance in splat_core::HitDistance::ALL {
        let trace = TraceScene::new(&scene, RenderSettings { hit_distance, ..RenderSettings::default() }).unwrap();
        let tracer = tracer(ctx, &trace);
        for method in [Method::Exact, Method::KBuffer { k: 4, max_passes: 100, min_transmittance: 0.0 }] {
            let cpu = render_frames(&trace, &camera, &method, &frames, &|_| {}).unwrap();
            let gpu = gpu_run(&tracer, &camera, &method, frames);
            let d = max_difference(cpu.mean.data(), gpu.mean.data());
            let depth = cpu.depth.data().iter().zip(gpu.depth.data()).fold(0.0f32, |m, (a, b)| {
                if a.is_nan() && b.is_nan() { m } else { m.max((a - b).abs() / a.abs().max(1.0)) }
            });
            eprintln!("{} {method:?}: |GPU − CPU| {d:.1e}, depth {depth:.1e}", hit_distance.name());
            assert!(d <= FLOAT_TOLERANCE, "{}: {method:?} differs by {d}", hit_distance.name());
            assert!(depth <= 1e-4, "{}: {method:?} depth differs by {depth}", hit_distance.name());
            if method == Method::Exact {
                depths.push(cpu.depth);
            }
        }
    }
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        let apart = max_difference(depths[i].data(), depths[j].data());
        assert!(apart > 1e-2, "conventions {i} and {j} pick the same depths ({apart})");
    }
}

/// Frames drawn through a box pixel filter and a thin lens (`camera_sampling.rs`, its WGSL twin
/// `frame_ray`): the GPU's rays are the CPU's, frame by frame (the same Sobol point of the
/// run's sequence, the same lens point), so four frames of `exact` through a pinhole and through
/// a fisheye agree to the compositing tolerance; the control, the same frames through pixel
/// centres and a pinhole, is far off at the edges of the cloud.
#[test]
fn frames_through_a_sampled_pixel_and_lens_equal_the_cpu_frames() {
    use splat_core::camera::{Distortion, Lens};
    use splat_core::camera_sampling::{CameraSampling, PixelFilter, ThinLens};
    let Some(ctx) = context() else { return };
    let (scene, pinhole) = fixture("cloud", 40, 30);
    let sampling =
        CameraSampling { filter: PixelFilter::Box, lens: Some(ThinLens { aperture: 0.15, focus_distance: 2.5 }) };
    let settings = RenderSettings { sampling, ..RenderSettings::default() };
    let trace = TraceScene::new(&scene, settings).unwrap();
    let still = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let tracer = tracer(ctx, &trace);
    let frames = Frames { count: 4, seed: 5, ..Frames::default() };
    let fisheye = Distortion { radial: [0.04, -0.01, 0.002, -3e-4], ..Distortion::default() };
    for (name, camera) in [("pinhole", pinhole), ("fisheye", pinhole.with_lens(Lens::Fisheye(fisheye)).unwrap())] {
        for method in [Method::Exact, Method::Stochastic] {
            let cpu = render_frames(&trace, &camera, &method, &frames, &|_| {}).unwrap();
            let gpu = gpu_run(&tracer, &camera, &method, frames);
            let d = max_difference(cpu.mean.data(), gpu.mean.data());
            let centres = render_frames(&still, &camera, &method, &frames, &|_| {}).unwrap();
            let control = max_difference(centres.mean.data(), gpu.mean.data());
            let over = cpu.mean.data().iter().zip(gpu.mean.data()).filter(|(a, b)| (*a - *b).abs() > FLOAT_TOLERANCE);
            let over = over.count() / 3;
            eprintln!(
                "{name} {method:?}: |GPU − CPU| {d:.1e} ({over} pixels over {FLOAT_TOLERANCE}), through centres {control:.1e}"
            );
            if method == Method::Exact {
                // A hit whose α lies within f32 rounding of the 1/255 cull (the lens moves the
                // ray origin, rounded differently on each backend) can be kept by one and
                // dropped by the other: its frame then moves by at most 1/255, the mean of
                // four frames by a quarter of that. One pixel in a hundred may do so.
                let cull_flip = settings.kernel.alpha_cull / frames.count as f32;
                assert!(d <= cull_flip, "{name}: the GPU's sampled rays differ from the CPU's by {d}");
                assert!(over * 100 <= (camera.width * camera.height) as usize, "{name}: {over} pixels differ");
            } else {
                // A stochastic frame may flip where a decision falls within f32 rounding of its
                // threshold; the mean stays within a few such flips of four frames.
                let mean = mean_difference(cpu.mean.data(), gpu.mean.data());
                assert!(mean < 2e-3, "{name} {method:?}: mean |GPU − CPU| {mean}");
            }
            assert!(control > 0.05, "{name}: the sampled camera changes nothing ({control})");
        }
    }
}

/// Mean absolute difference of two images.
fn mean_difference(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| f64::from((x - y).abs())).sum::<f64>() / a.len() as f64
}

/// 2DGS surfels (Gaussians [`splat_core::particle::SURFEL_THICKNESS`] thick, seen obliquely): the
/// GPU's f32 canonical transform, which scales the thin axis by 1e5, gives the CPU's `exact`
/// frame to the compositing tolerance.
#[test]
fn surfels_render_on_the_gpu_as_on_the_cpu() {
    let Some(ctx) = context() else { return };
    let (mut scene, camera) = fixture("layers", 40, 30);
    for (i, p) in scene.particles.iter_mut().enumerate() {
        p.rotation = (splat_core::glam::Quat::from_rotation_x(0.5 + 0.3 * i as f32) * p.rotation).normalize();
        p.scale.z = splat_core::particle::surfel_thickness(p.scale.x, p.scale.y);
    }
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let frames = Frames { count: 1, seed: 5, ..Frames::default() };
    let cpu = render_frames(&trace, &camera, &Method::Exact, &frames, &|_| {}).unwrap();
    let gpu = gpu_run(&tracer(ctx, &trace), &camera, &Method::Exact, frames);
    let d = max_difference(cpu.mean.data(), gpu.mean.data());
    eprintln!("surfels: |GPU − CPU| {d:.1e}");
    assert!(d <= FLOAT_TOLERANCE, "surfels differ between the backends by {d}");
}
