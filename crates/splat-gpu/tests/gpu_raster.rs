//! GPU splatting against the CPU raster reference (on lavapipe in CI): the radix sort against a
//! CPU sort, projection and depth order, sorted over/under images, the tile rasterizer's
//! iso-opacity depth and picked splat, and one StochasticSplats frame decision by decision.

mod common;

use common::{context, fixture};
use splat_core::Frames;
use splat_core::RenderSettings;
use splat_core::lighting::{Lighting, Look, Shadows};
use splat_core::raster::{
    Blend, FragmentDepth, RasterMethod, RasterSettings, Rasterizer, SamplePattern, SplatExtent, render_raster,
};
use splat_core::rng::SplitMix64;
use splat_core::trainer::Preset;
use splat_core::{Camera, Scene};
use splat_gpu::sort::{
    BLOCK, CULLED, RADIX, SCAN_TILE, cpu_radix_sort, culled_workgroups, depth_key, exclusive_scan, sort_culled_pairs,
    sort_pairs,
};
use splat_gpu::{GpuContext, GpuRasterizer, RasterPipelines, RasterScene};
use std::sync::OnceLock;

fn pipelines(ctx: &GpuContext) -> &'static RasterPipelines {
    static PIPES: OnceLock<RasterPipelines> = OnceLock::new();
    PIPES.get_or_init(|| RasterPipelines::new(ctx).expect("the raster kernels compile"))
}

fn cpu_sorted(keys: &[u32], bits: u32) -> (Vec<u32>, Vec<u32>) {
    let (mut k, mut v) = (keys.to_vec(), (0..keys.len() as u32).collect());
    cpu_radix_sort(&mut k, &mut v, bits);
    (k, v)
}

/// The GPU sort equals the CPU sort (keys and the stable order of values) on random keys of
/// sizes around block boundaries and on adversarial ones: all equal, reversed, few distinct,
/// depth keys with NaN and negative depths filtered out before sorting; the culling sort of the
/// depth order equals the CPU sort of the keys it keeps, however many it drops; and the scan
/// the sort is built from equals the CPU's.
#[test]
fn gpu_sort_and_scan_equal_the_cpu_ones() {
    let Some(ctx) = context() else { return };
    let sort = pipelines(ctx).sort();
    let mut rng = SplitMix64::new(7);
    let mut cases: Vec<(String, Vec<u32>, u32)> = Vec::new();
    for n in [1usize, 255, 256, 257, 1000, 1023, 1024, 1025, 65_537] {
        cases.push((format!("random {n}"), (0..n).map(|_| rng.next_u64() as u32).collect(), 32));
    }
    cases.push(("all equal".into(), vec![0xDEAD_BEEF; 3000], 32));
    cases.push(("reversed".into(), (0..5000u32).rev().collect(), 32));
    cases.push(("few distinct".into(), (0..7000).map(|_| (rng.next_u64() % 5) as u32).collect(), 32));
    cases.push(("12-bit tile keys".into(), (0..9000).map(|_| (rng.next_u64() % 3750) as u32).collect(), 12));
    let depths: Vec<f32> = (0..4000)
        .map(|i| match i % 50 {
            0 => f32::NAN,
            1 => -rng.range(0.0, 5.0),
            2 => f32::INFINITY,
            3 => 1.5, // ties
            _ => rng.range(0.2, 100.0),
        })
        .collect();
    cases.push(("depths, NaN filtered".into(), depths.iter().filter_map(|&z| depth_key(z)).collect(), 32));
    // Split over bindings of 16,384 keys: 5 parts of each array, in binding arrays and one
    // binding each.
    let smalls: Vec<_> = common::part_binding_contexts(|c| c.with_index_binding_limit(64 * 1024))
        .into_iter()
        .map(|(bound, small)| {
            let pipes = RasterPipelines::new(&small).unwrap();
            (bound, small, pipes)
        })
        .collect();
    // The sorts a case runs on: the whole one, or each split one.
    let on = |split: bool| -> Vec<(&GpuContext, &splat_gpu::RadixSort, String)> {
        if !split {
            return vec![(ctx, sort, String::new())];
        }
        smalls.iter().map(|(bound, small, pipes)| (small, pipes.sort(), format!(" ({bound:?})"))).collect()
    };
    cases.push(("random 70000, split".into(), (0..70_000).map(|_| rng.next_u64() as u32).collect(), 32));
    for ((name, keys, bits), (ctx, sort, bound)) in
        cases.iter().flat_map(|case| on(case.0.ends_with("split")).into_iter().map(move |on| (case, on)))
    {
        let (keys, bits) = (keys.as_slice(), *bits);
        let name = format!("{name}{bound}");
        let vals: Vec<u32> = (0..keys.len() as u32).collect();
        let gpu = sort_pairs(ctx, sort, keys, &vals, bits).unwrap();
        assert_eq!(gpu, cpu_sorted(keys, bits), "{name}");
        let mut std_sorted: Vec<(u32, u32)> = keys.iter().copied().zip(vals).collect();
        std_sorted.sort_by_key(|&(k, _)| k); // std's stable sort: the specification
        if bits == 32 {
            assert_eq!(gpu.1, std_sorted.iter().map(|p| p.1).collect::<Vec<_>>(), "{name}: not stable");
        }
    }
    // The culling sort (the depth sort's and the shuffle's): the pairs of value CULLED dropped
    // by the first pass, the later passes sized on the device. Kept shares from all to none, so that the later passes have
    // as many scan levels as the first (half kept), fewer used than the first's (100 of 70,000:
    // one tile under two levels), or no block at all; whole and split over bindings. On one bit
    // of zero keys it is the compaction of StochasticSplats' scene order at the max-density
    // plane: the kept pairs in input order (the CPU sort on one bit leaves them so).
    let culled_cases = [
        ("none culled", 1000, 1.0, false, 32),
        ("half culled", 70_000, 0.5, false, 32),
        ("100 kept of 70000", 70_000, 100.0 / 70_000.0, false, 32),
        ("all culled", 5000, 0.0, false, 32),
        ("depths with culled", 4000, 0.7, false, 32),
        ("half culled, split", 70_000, 0.5, true, 32),
        ("compaction, half culled", 70_000, 0.5, false, 1),
        ("compaction, 100 kept of 70000", 70_000, 100.0 / 70_000.0, false, 1),
        ("compaction, 0.9 kept, split", 70_000, 0.9, true, 1),
    ];
    for (name, n, kept, split, bits) in culled_cases {
        // As the projection keys them: unsortable depths and culled splats of value CULLED.
        let (keys, vals): (Vec<u32>, Vec<u32>) = (0..n)
            .map(|i| {
                let key = if name.starts_with("depths") {
                    depth_key(depths[i % depths.len()])
                } else if name.starts_with("compaction") {
                    Some(0)
                } else {
                    Some(rng.next_u64() as u32)
                };
                match key.filter(|_| rng.next_f32() < kept) {
                    Some(key) => (key, i as u32),
                    None => (CULLED, CULLED),
                }
            })
            .unzip();
        let (mut k, mut v): (Vec<u32>, Vec<u32>) =
            keys.iter().copied().zip(vals.iter().copied()).filter(|&(_, v)| v != CULLED).unzip();
        cpu_radix_sort(&mut k, &mut v, bits);
        if bits == 1 {
            assert!(v.is_sorted(), "{name}: the compaction's expectation is the kept ids in input order");
        }
        for (ctx, sort, bound) in on(split) {
            let gpu = sort_culled_pairs(ctx, sort, &keys, &vals, bits).unwrap();
            let differ = (0..k.len().max(gpu.0.len())).find(|&i| gpu.0.get(i) != k.get(i) || gpu.1.get(i) != v.get(i));
            let (sorted, kept) = (gpu.0.len(), k.len());
            assert_eq!(differ, None, "{name}{bound}: {sorted} pairs sorted, {kept} kept; the first differs there");
        }
    }
    // sort_setup's workgroups where the blocks pass one row of the dispatch grid (65,535
    // workgroups: more take rows of it), at counts this device could not sort: 70 M pairs, of
    // which none, 1,000, a row's worth of blocks, one more, or 68 M are kept.
    let row = 65_535u32;
    let grid = |k: u32| if k <= row { [k, 1, 1] } else { [row, k.div_ceil(row), 1] };
    let cases = [(0, 0), (1000, 1), (row * BLOCK, row), (row * BLOCK + 1, row + 1), (68_000_000, 66_407)];
    for (visible, blocks) in cases {
        let (passes, levels) = culled_workgroups(ctx, sort, 70_000_000, visible).unwrap();
        assert_eq!(passes, vec![grid(blocks); 3], "{visible} kept: the later passes' blocks");
        let mut len = RADIX * blocks;
        for (i, &groups) in levels.iter().enumerate() {
            len = len.div_ceil(SCAN_TILE);
            assert_eq!(groups, grid(len), "{visible} kept: scan level {i}'s tiles");
        }
        if visible == 68_000_000 {
            assert_eq!(levels, [[16_602, 1, 1], [17, 1, 1], [1, 1, 1]], "17,000,192 histogram entries");
        }
    }
    // The scan the sort is built from, at the sizes where it gains a level (one tile, two
    // levels, three), whole and split over bindings.
    let t = SCAN_TILE as usize;
    for (n, split) in [(1, false), (t, false), (t + 1, false), (300_001, false), (t * t + 5, false), (70_000, true)] {
        let values: Vec<u32> = (0..n).map(|_| (rng.next_u64() % 1000) as u32).collect();
        let expected: Vec<u32> = values.iter().scan(0u32, |sum, &v| Some(std::mem::replace(sum, *sum + v))).collect();
        for (ctx, sort, bound) in on(split) {
            assert_eq!(exclusive_scan(ctx, sort, &values).unwrap(), expected, "scan of {n}, split {split}{bound}");
        }
    }
    // More parts than the adapter binds (storage bindings, or buffers in binding arrays): refused
    // with what fits, before any work.
    for (_, tiny) in common::part_binding_contexts(|c| c.with_index_binding_limit(1024).with_binding_array_elements(64))
    {
        let e = smalls[0].2.sort().buffers(&tiny, 1 << 20).err().expect("too many parts").to_string();
        assert!(e.contains("radix sort") && e.contains("pairs") && e.contains("fits about"), "{e}");
    }
}

struct Case {
    scene: Scene,
    camera: Camera,
}

fn case(name: &str, w: u32, h: u32) -> Case {
    let (scene, camera) = fixture(name, w, h);
    Case { scene, camera }
}

fn cpu_raster(c: &Case) -> Rasterizer<'_> {
    Rasterizer::new(&c.scene, &c.camera, RenderSettings::default(), RasterSettings::default()).unwrap()
}

/// The near plane reaches the GPU's projection: a particle 0.1 in front of the camera is
/// projected at gsplat's near plane (0.01) and culled at 3DGS's (0.2), as on the CPU.
#[test]
fn the_near_plane_culls_as_on_the_cpu() {
    let Some(ctx) = context() else { return };
    let mut c = case("cloud", 64, 48);
    let near = c.camera.center() + 0.1 * c.camera.forward();
    let id = c.scene.particles.len() as u32;
    c.scene.particles.push(splat_core::Particle::with_rgb(
        near,
        glam::Vec3::splat(0.0008),
        glam::Quat::IDENTITY,
        0.9,
        glam::Vec3::ONE,
    ));
    for (plane, drawn) in [(Preset::GsplatAntialiased.near(), true), (Preset::ThreeDgs.near(), false)] {
        let settings = RenderSettings { near: plane, ..RenderSettings::default() };
        let cpu = Rasterizer::new(&c.scene, &c.camera, settings, RasterSettings::default()).unwrap();
        let scene = RasterScene::new(ctx, &c.scene, &settings).unwrap();
        let gpu = GpuRasterizer::new(ctx, pipelines(ctx), &scene, &c.camera, &RasterSettings::default()).unwrap();
        let on_cpu = cpu.splats().iter().any(|s| s.id == id);
        let on_gpu = gpu.order().unwrap().contains(&id);
        assert_eq!((on_cpu, on_gpu), (drawn, drawn), "near plane {plane}: CPU {on_cpu}, GPU {on_gpu}");
    }
}

/// The GPU projection equals the CPU's splat by splat, and its depth order is the CPU's.
#[test]
fn projection_and_depth_order_equal_the_cpu() {
    let Some(ctx) = context() else { return };
    for name in ["layers", "ramp", "cloud"] {
        let c = case(name, 64, 48);
        let cpu = cpu_raster(&c);
        let scene = RasterScene::new(ctx, &c.scene, &RenderSettings::default()).unwrap();
        let gpu = GpuRasterizer::new(ctx, pipelines(ctx), &scene, &c.camera, &RasterSettings::default()).unwrap();
        let splats = gpu.splats().unwrap();
        let order = gpu.order().unwrap();
        let cpu_order: Vec<u32> = cpu.splats().iter().map(|s| s.id).collect();
        assert_eq!(order, cpu_order, "{name}: depth order");
        for s in cpu.splats() {
            let g = &splats[s.id as usize];
            // The rect is cut to the visible radius (computed in f64 here, f32 there): an edge
            // may fall a pixel apart, where the alpha cull takes the pixel on both.
            let edges = g.rect.iter().zip(s.rect).all(|(&a, b)| a.abs_diff(b) <= 1);
            assert!(edges, "{name} splat {}: rect {:?} vs {:?}", s.id, g.rect, s.rect);
            assert!((g.bound - s.bound).abs() <= 1e-4 * s.bound, "{name} splat {}: bound", s.id);
            let close = |a: f32, b: f32| (a - b).abs() <= 1e-4 * (1.0 + b.abs());
            assert!(close(g.mean[0], s.mean.x) && close(g.mean[1], s.mean.y), "{name} {}: mean", s.id);
            assert!(close(g.depth, s.depth), "{name} {}: depth", s.id);
            for (a, b) in g.conic.iter().zip(s.conic.to_array()) {
                assert!(
                    (a - b).abs() <= 1e-3 * (1e-3 + b.abs()),
                    "{name} {}: conic {:?} vs {}",
                    s.id,
                    g.conic,
                    s.conic
                );
            }
            for (a, b) in g.color.iter().zip(s.color.to_array()) {
                assert!((a - b).abs() <= 1e-5, "{name} {}: colour", s.id);
            }
        }
        let culled = splats.iter().filter(|s| s.rect[0] >= s.rect[2]).count();
        assert_eq!(culled, c.scene.particles.len() - cpu.splats().len(), "{name}: culled count");
    }
}

/// The largest |a − b|, NaN if any difference is NaN (`f32::max` would skip it).
fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, |m, d| if m.is_nan() || d.is_nan() { f32::NAN } else { m.max(d) })
}

/// Sorted GPU splatting (instanced quads, hardware blending) equals the CPU `raster-sorted`
/// image: within 1e-4 with RGBA32F blending (f32 against the CPU's f64; lavapipe: ~4e-7) and 8e-3 with RGBA16F
/// (half floats: ~1/2 of an 8-bit unit); over = under on the GPU to the same tolerance.
#[test]
fn sorted_splatting_equals_the_cpu_over_and_under() {
    let Some(ctx) = context() else { return };
    let pipes = pipelines(ctx);
    let tolerance = if pipes.blend_format == splat_gpu::wgpu::TextureFormat::Rgba32Float { 1e-4 } else { 8e-3 };
    for name in ["layers", "ramp", "cloud"] {
        let c = case(name, 64, 48);
        let cpu =
            render_raster(&cpu_raster(&c), &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {})
                .unwrap();
        let scene = RasterScene::new(ctx, &c.scene, &RenderSettings::default()).unwrap();
        let gpu = GpuRasterizer::new(ctx, pipes, &scene, &c.camera, &RasterSettings::default()).unwrap();
        let over = gpu.render(&RasterMethod::Sorted { blend: Blend::Over }, &Frames::default()).unwrap().0;
        let under = gpu.render(&RasterMethod::Sorted { blend: Blend::Under }, &Frames::default()).unwrap().0;
        let d_over = max_abs_diff(over.mean.data(), cpu.mean.data());
        let d_under = max_abs_diff(under.mean.data(), cpu.mean.data());
        let d_alpha =
            max_abs_diff(under.alpha.data(), cpu.alpha.data()).max(max_abs_diff(over.alpha.data(), cpu.alpha.data()));
        let d_both = max_abs_diff(over.mean.data(), under.mean.data());
        eprintln!(
            "{name}: |over − cpu| {d_over:.2e}, |under − cpu| {d_under:.2e}, alpha {d_alpha:.2e}, |over − under| {d_both:.2e}"
        );
        assert!(d_over <= tolerance && d_under <= tolerance && d_alpha <= tolerance && d_both <= tolerance, "{name}");
        assert!(cpu.alpha.data().iter().any(|&a| a > 0.5), "{name}: the test image is not empty");
    }
}

/// The tile rasterizer's iso-opacity depth, picked splat and integrated normal equal the CPU's
/// sorted-under ones, at one sample per pixel and at four (sample 0's, as the CPU takes them):
/// picks identical except where the transmittance lies within f32 rounding of the threshold
/// (bounded to 0.5 % of pixels), depths within 1e-5 relative where the picks agree, normals
/// within 1e-3; at one sample the colour too. The four-sample pick differs from the
/// one-sample pick (the control: sample 0 is not the centre).
#[test]
fn depth_pick_equals_the_cpu() {
    let Some(ctx) = context() else { return };
    let four = RasterSettings {
        samples: 4,
        sample_pattern: splat_core::raster::SamplePattern::Standard,
        ..RasterSettings::default()
    };
    for (name, raster) in [
        ("layers", RasterSettings::default()),
        ("ramp", RasterSettings::default()),
        ("cloud", RasterSettings::default()),
        ("cloud", four),
    ] {
        let c = case(name, 70, 50); // not a multiple of the tile size
        let cpu_r = Rasterizer::new(&c.scene, &c.camera, RenderSettings::default(), raster).unwrap();
        let cpu =
            render_raster(&cpu_r, &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {}).unwrap();
        let scene = RasterScene::new(ctx, &c.scene, &RenderSettings::default()).unwrap();
        let gpu = GpuRasterizer::new(ctx, pipelines(ctx), &scene, &c.camera, &raster).unwrap().depth_pick().unwrap();
        if raster.samples > 1 {
            let centre = GpuRasterizer::new(ctx, pipelines(ctx), &scene, &c.camera, &RasterSettings::default())
                .unwrap()
                .depth_pick()
                .unwrap();
            let apart = |a: &Option<f32>, b: &Option<f32>| match (a, b) {
                (Some(a), Some(b)) => (a - b).abs() > 1e-5 * b,
                _ => a.is_some() != b.is_some(),
            };
            let moved = gpu.depth.iter().zip(&centre.depth).filter(|(a, b)| apart(a, b)).count();
            eprintln!("{name} at S = 4: {moved} depths differ from the pixel centre's beyond the tolerance");
            assert!(moved > 100, "{name}: sample 0's pick is the centre's");
        }
        let pixels = cpu.picked.len();
        let differing = gpu.picked.iter().zip(&cpu.picked).filter(|(a, b)| a != b).count();
        let picked = cpu.picked.iter().filter(|p| p.is_some()).count();
        eprintln!("{name}: {differing} of {pixels} picks differ ({picked} picked, {} pairs)", gpu.pairs);
        assert!(picked > pixels / 10, "{name}: too few picks to test");
        assert!(differing * 200 <= pixels, "{name}");
        for (i, (g, c)) in gpu.picked.iter().zip(&cpu.picked).enumerate() {
            if g.is_some() && g == c {
                let (dg, dc) = (gpu.depth[i].unwrap(), cpu.depth.data()[i]);
                assert!((dg - dc).abs() <= 1e-5 * dc, "{name} pixel {i}: depth {dg} vs {dc}");
            }
        }
        // The integrated normal of every pixel, as the CPU's (zero where no fragment).
        let normals = max_abs_diff(gpu.normal.data(), cpu.normal.data());
        assert!(normals <= 1e-3, "{name}: normals differ by {normals}");
        assert!(cpu.normal.data().iter().any(|&n| n.abs() > 0.5), "{name}: no normals to compare");
        if raster.samples == 1 {
            assert!(max_abs_diff(gpu.color.data(), cpu.mean.data()) <= 2e-4, "{name}: colour");
        }
    }
    // Kernel-ellipsoid normals (vk_gaussian_splatting Lighting §2.4) integrate as the CPU's, and
    // differ from the plane's (the control).
    let c = case("cloud", 70, 50);
    let ellipsoid =
        RenderSettings { normal_mode: splat_core::normal::NormalMode::KernelEllipsoid, ..RenderSettings::default() };
    let cpu = Rasterizer::new(&c.scene, &c.camera, ellipsoid, RasterSettings::default()).unwrap();
    let cpu = render_raster(&cpu, &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {}).unwrap();
    let plane =
        render_raster(&cpu_raster(&c), &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {})
            .unwrap();
    let scene = RasterScene::new(ctx, &c.scene, &ellipsoid).unwrap();
    let gpu = GpuRasterizer::new(ctx, pipelines(ctx), &scene, &c.camera, &RasterSettings::default())
        .unwrap()
        .depth_pick()
        .unwrap();
    let (normals, apart) =
        (max_abs_diff(gpu.normal.data(), cpu.normal.data()), max_abs_diff(plane.normal.data(), cpu.normal.data()));
    eprintln!("ellipsoid normals: |GPU − CPU| {normals:.1e}, |plane − ellipsoid| {apart:.1e}");
    assert!(normals <= 1e-3 && apart > 0.1, "ellipsoid normals: {normals}, apart from the plane's by {apart}");
}

/// One StochasticSplats frame with a fixed seed makes the CPU frame's decisions: identical
/// pixels except where a decision's u lies within 1e-5 of its alpha (checked pixel by pixel
/// through the CPU's own decisions, and counted).
#[test]
fn one_stochastic_frame_equals_the_cpu_frame() {
    let Some(ctx) = context() else { return };
    for name in ["layers", "ramp", "cloud"] {
        let c = case(name, 64, 48);
        let scene = RasterScene::new(ctx, &c.scene, &RenderSettings::default()).unwrap();
        let gpu = GpuRasterizer::new(ctx, pipelines(ctx), &scene, &c.camera, &RasterSettings::default()).unwrap();
        let cpu_r = cpu_raster(&c);
        for seed in [3, 4] {
            let frames = Frames { count: 1, seed, ..Frames::default() };
            let cpu = render_raster(&cpu_r, &RasterMethod::StochasticSplat, &frames, &|_| {}).unwrap();
            let g = gpu.render(&RasterMethod::StochasticSplat, &frames).unwrap().0;
            let pixels = (c.camera.width * c.camera.height) as usize;
            let differing: Vec<usize> = (0..pixels)
                .filter(|&p| {
                    let rgb = |img: &splat_core::image::Image| img.data()[3 * p..3 * p + 3].to_vec();
                    let d = max_abs_diff(&rgb(&g.mean), &rgb(&cpu.mean));
                    d.is_nan() || d > 1e-5 || g.alpha.data()[p] != cpu.alpha.data()[p]
                })
                .collect();
            // A pixel may differ only by a decision whose u lay within 1e-5 of its alpha.
            let (near, bad): (Vec<usize>, Vec<usize>) = differing.iter().partition(|&&p| {
                let (x, y) = (p as u32 % c.camera.width, p as u32 / c.camera.width);
                splat_tests::flips::raster_gap(&cpu_r, &RasterMethod::StochasticSplat, &frames, x, y)
                    < splat_tests::flips::FLIP_GAP
            });
            let written = cpu.alpha.data().iter().filter(|&&a| a > 0.0).count();
            eprintln!(
                "{name} seed {seed}: {} of {pixels} pixels differ by a decision within 1e-5 of its threshold ({written} written)",
                near.len()
            );
            assert!(written > pixels / 10, "{name}: too few written pixels to test");
            assert!(bad.is_empty(), "{name} seed {seed}: pixels {bad:?} differ with no decision near its threshold");
        }
        // Another seed makes other decisions: the comparison above can fail.
        let a =
            gpu.render(&RasterMethod::StochasticSplat, &Frames { count: 1, seed: 3, ..Frames::default() }).unwrap().0;
        let b =
            gpu.render(&RasterMethod::StochasticSplat, &Frames { count: 1, seed: 5, ..Frames::default() }).unwrap().0;
        assert!(max_abs_diff(a.mean.data(), b.mean.data()) > 0.1, "{name}: seeds do not matter");
    }
}

/// Settings the GPU does not rasterize are refused with a message, not rendered wrongly: the
/// early stop, the Hammersley pattern at S > 1 (the hardware's samples are the standard ones)
/// and the response along the ray (3DGUT, 2DGS); tests/gpu_msaa.rs has the rest.
#[test]
fn cpu_only_raster_settings_are_refused() {
    let Some(ctx) = context() else { return };
    let c = case("layers", 16, 12);
    let scene = RasterScene::new(ctx, &c.scene, &RenderSettings::default()).unwrap();
    let hammersley = RasterSettings { samples: 4, ..RasterSettings::default() };
    for m in [RasterMethod::Enderton, RasterMethod::Stratified { scramble: true }] {
        let e = GpuRasterizer::supports(&m, &hammersley).unwrap_err().to_string();
        assert!(e.contains("standard"), "{e}");
        assert!(GpuRasterizer::supports(&m, &RasterSettings::default()).is_ok());
    }
    let early = RasterSettings { early_stop: true, ..RasterSettings::default() };
    let e = GpuRasterizer::new(ctx, pipelines(ctx), &scene, &c.camera, &early).err().expect("early stop").to_string();
    assert!(e.contains("early stop"), "{e}");
    let along = RasterSettings { response: splat_core::raster::Response::AlongRay, ..RasterSettings::default() };
    let e =
        GpuRasterizer::new(ctx, pipelines(ctx), &scene, &c.camera, &along).err().expect("along the ray").to_string();
    assert!(e.contains("along the pixel's ray") && e.contains("CPU"), "{e}");
}

/// StochasticSplats draws the visible splats alone: in depth order at centre depth (where the
/// depth order breaks ties by id, as the CPU does), and in scene order at the max-density plane
/// (where splats of different centre depths can tie at a sample, and only the scene order
/// breaks every tie by the lower id): the depth order's ids ascending, compacted on the device
/// from the projection's values. A crop of the `cloud` culls over a quarter of it; whole, and with the
/// order split over two bindings of 8 KiB. The two orders differ, so the check cannot pass with
/// either in place of the other; frames drawn in the split order equal the whole scene's.
#[test]
fn stochastic_splats_draw_in_scene_order_at_the_max_density_plane() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 64, 48);
    let camera = camera.crop(8, 4, 24, 30).unwrap();
    let small = GpuContext::new().unwrap().with_index_binding_limit(8 * 1024);
    let small_pipes = RasterPipelines::new(&small).unwrap();
    let whole = RasterScene::new(ctx, &scene, &RenderSettings::default()).unwrap();
    let split = RasterScene::new(&small, &scene, &RenderSettings::default()).unwrap();
    assert_eq!(split.split().ranks.parts, 2);
    let at = |depth| RasterSettings { fragment_depth: depth, ..RasterSettings::default() };
    let depth_order = Rasterizer::new(&scene, &camera, RenderSettings::default(), at(FragmentDepth::Center))
        .unwrap()
        .splats()
        .iter()
        .map(|s| s.id)
        .collect::<Vec<_>>();
    let mut scene_order = depth_order.clone();
    scene_order.sort_unstable();
    let visible = format!("{} of {} visible", depth_order.len(), scene.particles.len());
    assert!(depth_order.len() * 4 < scene.particles.len() * 3, "{visible}");
    assert_ne!(scene_order, depth_order);
    let frames = Frames { count: 2, seed: 7, ..Frames::default() };
    let mut images = Vec::new();
    for (ctx, pipes, gpu_scene) in [(ctx, pipelines(ctx), &whole), (&small, &small_pipes, &split)] {
        let same = |gpu: Vec<u32>, cpu: &[u32], what: &str| {
            let first = (0..gpu.len().max(cpu.len())).find(|&i| gpu.get(i) != cpu.get(i));
            assert_eq!(first, None, "{what}: {} ids against {}; the first that differs", gpu.len(), cpu.len());
        };
        let centre = GpuRasterizer::new(ctx, pipes, gpu_scene, &camera, &at(FragmentDepth::Center)).unwrap();
        same(centre.stochastic_order().unwrap(), &depth_order, "centre depth");
        let plane = GpuRasterizer::new(ctx, pipes, gpu_scene, &camera, &at(FragmentDepth::MaxDensityPlane)).unwrap();
        same(plane.order().unwrap(), &depth_order, "the depth order at the plane");
        same(plane.stochastic_order().unwrap(), &scene_order, "the max-density plane");
        if ctx.sample_rate_shading {
            images.push(plane.render(&RasterMethod::StochasticSplat, &frames).unwrap().0.mean.data().to_vec());
        } else {
            let reason = format!("{} shades no samples apart", ctx.describe());
            splat_tests::skip("the max-density plane's split frames", &reason);
        }
    }
    if let [whole, split] = &images[..] {
        assert!(whole.iter().zip(split).all(|(a, b)| a.to_bits() == b.to_bits()), "split frames differ");
        assert!(whole.iter().any(|&x| x > 0.1), "nothing drawn");
    }
}

/// Depth ties resolve as on the CPU, to the lower splat id (drawn first, kept by the `less`
/// depth test); a nearer splat with a higher id still wins (the depth test, not draw order).
#[test]
fn stochastic_depth_ties_keep_the_lower_id_like_the_cpu() {
    use glam::{Quat, Vec3};
    use splat_core::particle::Particle;
    use splat_core::rng::{RayRng, RngScheme, frame_key};
    let Some(ctx) = context() else { return };
    let at = |x: f32, z: f32, rgb: Vec3| {
        Particle::with_rgb(Vec3::new(x, 0.0, z), Vec3::splat(0.3), Quat::IDENTITY, 0.99, rgb)
    };
    let (red, green, blue) = (Vec3::X, Vec3::Y, Vec3::Z);
    // Left: ids 0 (red) and 1 (green) at the same place. Right: id 2 (blue) behind id 3 (red).
    let scene = Scene::new(vec![at(-0.6, 0.0, red), at(-0.6, 0.0, green), at(0.6, -0.2, blue), at(0.6, 0.2, red)], 0);
    let camera = Camera::look_at(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, Vec3::Y, 40.0, 48, 24).unwrap();
    let c = Case { scene, camera };
    let gpu_scene = RasterScene::new(ctx, &c.scene, &RenderSettings::default()).unwrap();
    let gpu = GpuRasterizer::new(ctx, pipelines(ctx), &gpu_scene, &c.camera, &RasterSettings::default()).unwrap();
    let mut contested = 0; // pairs where both splats were accepted: the tie rule decides
    for seed in 0..8 {
        let frames = Frames { count: 1, seed, ..Frames::default() };
        let cpu = render_raster(&cpu_raster(&c), &RasterMethod::StochasticSplat, &frames, &|_| {}).unwrap();
        let g = gpu.render(&RasterMethod::StochasticSplat, &frames).unwrap().0;
        assert!(max_abs_diff(g.mean.data(), cpu.mean.data()) <= 1e-6, "seed {seed}");
        // At the pixel under each pair, the colour is the first accepted of (front, back):
        // id 0 before the tied id 1, id 3 (in front) before id 2, decided by the core's hash.
        let r = cpu_raster(&c);
        for (front, back) in [(0u32, 1u32), (3, 2)] {
            let q = c.camera.project_camera(c.camera.to_camera(c.scene.particles[front as usize].mean));
            let (x, y) = (q.x as u32, q.y as u32);
            let px = r.pixel(x, y);
            let frags = r.fragments(&px);
            let rng = RayRng::new(x, y, frame_key(seed, 0), RngScheme::Hash);
            let accepted = |id: u32| {
                let f = frags.iter().find(|f| r.splats()[f.source as usize].id == id).unwrap();
                rng.particle(id, 0, Vec3::ZERO) < f.alpha
            };
            let expected = [front, back]
                .into_iter()
                .find(|&id| accepted(id))
                .map(|id| splat_core::sh::eval(c.scene.particles[id as usize].sh.as_slice(), 0, Vec3::Z).to_array());
            let p = (y * c.camera.width + x) as usize;
            let rgb = &g.mean.data()[3 * p..3 * p + 3];
            if let Some(e) = expected {
                assert!(max_abs_diff(rgb, &e) < 1e-5, "seed {seed} pair ({front}, {back}): {rgb:?} vs {e:?}");
            }
            contested += usize::from(accepted(front) && accepted(back));
        }
    }
    assert!(contested >= 8, "only {contested} of 16 pairs had both splats accepted: the rule went untested");
}

/// On real data (a 96 × 64 crop of the bonsai capture's standard view: anisotropic, SH
/// degree 3, tens of thousands of overlapping splats) sorted splatting, one StochasticSplats
/// frame and the picks agree with the CPU as on the fixtures.
#[test]
fn bonsai_crop_equals_the_cpu() {
    let Some(ctx) = context() else { return };
    let Some(scene) = splat_tests::bonsai() else { return };
    let camera = splat_tests::bonsai_camera().crop(552, 368, 96, 64).unwrap();
    let c = Case { scene, camera };
    let cpu_r = cpu_raster(&c);
    let gpu_scene = RasterScene::new(ctx, &c.scene, &RenderSettings::default()).unwrap();
    let gpu = GpuRasterizer::new(ctx, pipelines(ctx), &gpu_scene, &c.camera, &RasterSettings::default()).unwrap();
    assert_eq!(gpu.order().unwrap(), cpu_r.splats().iter().map(|s| s.id).collect::<Vec<_>>(), "depth order");
    let sorted =
        render_raster(&cpu_r, &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {}).unwrap();
    let over = gpu.render(&RasterMethod::Sorted { blend: Blend::Over }, &Frames::default()).unwrap().0;
    let d = max_abs_diff(over.mean.data(), sorted.mean.data());
    let pick = gpu.depth_pick().unwrap();
    let differing = pick.picked.iter().zip(&sorted.picked).filter(|(a, b)| a != b).count();
    let frames = Frames { count: 1, seed: 8, ..Frames::default() };
    let cpu_frame = render_raster(&cpu_r, &RasterMethod::StochasticSplat, &frames, &|_| {}).unwrap();
    let gpu_frame = gpu.render(&RasterMethod::StochasticSplat, &frames).unwrap().0;
    let pixels = sorted.picked.len();
    let frame_diff = (0..pixels)
        .filter(|&p| {
            max_abs_diff(&gpu_frame.mean.data()[3 * p..3 * p + 3], &cpu_frame.mean.data()[3 * p..3 * p + 3]) > 1e-5
        })
        .count();
    eprintln!(
        "bonsai crop: {} splats, |over − cpu| {d:.2e}, {differing} of {pixels} picks and {frame_diff} stochastic pixels differ, {} pairs",
        cpu_r.splats().len(),
        pick.pairs
    );
    let tolerance =
        if pipelines(ctx).blend_format == splat_gpu::wgpu::TextureFormat::Rgba32Float { 1e-4 } else { 8e-3 };
    assert!(d <= tolerance, "sorted splatting differs by {d}");
    assert!(differing * 200 <= pixels && frame_diff * 200 <= pixels);
}

/// A scene larger than a binding renders as it does whole: at 64 KiB bindings the `cloud`'s
/// 3,000 SH-3 particles are projected in 12 chunks of 256, and its projected splats (64 bytes each) and
/// canonical transforms (48) are split over 3 bindings each ([`splat_gpu::RasterSplit`]), which
/// the projection writes and the splat draw, the tile rasterizer and the raster operations read
/// through generated accessors; at 8 KiB bindings of its 4-byte arrays, the depth sort's keys
/// and values and the tile offsets are split over 2 (2,048 each), and so are the tile pairs,
/// which the sort, the binning and the tile passes read and write through theirs. The
/// projected splats and every frame are bit for bit the whole scene's: sorted (the draw),
/// StochasticSplats and Enderton (the raster operations), through a pinhole and a fisheye, and
/// lit (the canonical transforms' normals) sorted on the tile rasterizer and stochastic in the
/// draw.
#[test]
fn split_scenes_render_the_whole_scenes_frames() {
    let Some(ctx) = context() else { return };
    let c = case("cloud", 48, 36);
    for (bound, small) in
        common::part_binding_contexts(|c| c.with_binding_limit(64 * 1024).with_index_binding_limit(8 * 1024))
    {
        split_scene_renders_the_whole_scenes_frames(ctx, &c, &small, bound);
    }
}

/// [`split_scenes_render_the_whole_scenes_frames`] on `small`, whose split arrays are bound as
/// `bound`.
fn split_scene_renders_the_whole_scenes_frames(
    ctx: &'static GpuContext,
    c: &Case,
    small: &GpuContext,
    bound: splat_gpu::PartBindings,
) {
    use splat_core::camera::{Distortion, Lens};
    let small_pipes = RasterPipelines::new(small).unwrap();
    let lighting = common::lighting(Shadows::None, Look::Surface);
    let scenes = |lighting: &Lighting| {
        let settings = RenderSettings::default();
        let whole = RasterScene::new_lit(ctx, &c.scene, &settings, lighting).unwrap();
        let split = RasterScene::new_lit(small, &c.scene, &settings, lighting).unwrap();
        (whole, split)
    };
    let (unlit, lit) = (scenes(&Lighting::default()), scenes(&lighting));
    let parts =
        |s: &RasterScene| (s.chunks(), s.split().splats.parts, s.split().canonical.parts, s.split().ranks.parts);
    assert_eq!((parts(&unlit.0), parts(&unlit.1)), ((1, 1, 1, 1), (12, 3, 3, 2)));
    assert_eq!(unlit.1.split().parts, bound);
    let fisheye =
        Distortion { radial: [0.04, -0.01, 0.002, 0.0], rational: [0.0; 3], tangential: [0.0; 2], prism: [0.0; 2] };
    let through_fisheye = c.camera.with_lens(Lens::Fisheye(fisheye)).unwrap();
    let sorted = RasterMethod::Sorted { blend: Blend::Over };
    let cases = [
        (&unlit, c.camera, sorted),
        (&unlit, c.camera, RasterMethod::StochasticSplat),
        (&unlit, c.camera, RasterMethod::Enderton),
        (&unlit, through_fisheye, sorted),
        (&lit, c.camera, sorted),
        (&lit, c.camera, RasterMethod::StochasticSplat),
    ];
    let frames = Frames { count: 2, seed: 5, ..Frames::default() };
    for ((whole, split), camera, method) in cases {
        let settings = RasterSettings::default();
        let a = GpuRasterizer::new(ctx, pipelines(ctx), whole, &camera, &settings).unwrap();
        let b = GpuRasterizer::new(small, &small_pipes, split, &camera, &settings).unwrap();
        let splats = a.splats().unwrap();
        assert!(splats == b.splats().unwrap(), "{method:?}: the projected splats differ");
        assert!(a.order().unwrap() == b.order().unwrap(), "{method:?}: the depth orders differ");
        // The tile pairs the visible splats make (16-pixel tiles): more than one part holds.
        let pairs: u32 = splats
            .iter()
            .filter(|s| s.rect[0] < s.rect[2] && s.rect[1] < s.rect[3])
            .map(|s| (s.rect[2].div_ceil(16) - s.rect[0] / 16) * (s.rect[3].div_ceil(16) - s.rect[1] / 16))
            .sum();
        assert!(pairs > 2048, "{method:?}: {pairs} tile pairs fit one 8 KiB binding");
        let (a, b) = (a.render(&method, &frames).unwrap().0, b.render(&method, &frames).unwrap().0);
        let differ = a.mean.data().iter().zip(b.mean.data()).filter(|(x, y)| x.to_bits() != y.to_bits()).count();
        let lit = whole.is_lit();
        assert_eq!(
            differ, 0,
            "{method:?} through {:?} (lit: {lit}, {bound:?}): values that differ, split against whole",
            camera.lens
        );
        assert!(a.alpha.data().iter().any(|&x| x > 0.1), "{method:?}: nothing drawn");
    }
}

/// Splatting from f16 or u8 SH storage (`RenderSettings::sh_storage`) projects the colours of
/// the scene with every coefficient as stored and read back (`ShStorage::load`) and held in
/// f32, bit for bit (the projection's `sh_at` decodes them exactly), in one chunk and in 12:
/// sorted and StochasticSplats; and the rounding shows (the f32 image differs).
#[test]
fn compact_sh_splats_the_scene_as_stored() {
    use splat_core::sh::ShStorage;
    let Some(ctx) = context() else { return };
    let c = case("cloud", 48, 36);
    let small = GpuContext::new().unwrap().with_binding_limit(64 * 1024);
    let small_pipes = RasterPipelines::new(&small).unwrap();
    let plain = RasterScene::new(ctx, &c.scene, &RenderSettings::default()).unwrap();
    let frames = Frames { count: 2, seed: 5, ..Frames::default() };
    let render = |ctx: &GpuContext, pipes: &RasterPipelines, scene: &RasterScene, method: &RasterMethod| {
        let r = GpuRasterizer::new(ctx, pipes, scene, &c.camera, &RasterSettings::default()).unwrap();
        r.render(method, &frames).unwrap().0.mean.data().to_vec()
    };
    for storage in [ShStorage::F16, ShStorage::U8] {
        let mut rounded = c.scene.clone();
        for p in &mut rounded.particles {
            p.sh = std::array::from_fn(|k| storage.load(p.sh[k], k)).into();
        }
        let settings = RenderSettings { sh_storage: storage, ..RenderSettings::default() };
        let reference = RasterScene::new(ctx, &rounded, &RenderSettings::default()).unwrap();
        for method in [RasterMethod::Sorted { blend: Blend::Over }, RasterMethod::StochasticSplat] {
            let want = render(ctx, pipelines(ctx), &reference, &method);
            let unchanged = want == render(ctx, pipelines(ctx), &plain, &method);
            assert!(!unchanged, "{storage:?}, {method:?}: the storage changes nothing");
            for (ctx, pipes) in [(ctx, pipelines(ctx)), (&small, &small_pipes)] {
                let compact = RasterScene::new(ctx, &c.scene, &settings).unwrap();
                assert_eq!(compact.split().sh_storage, storage);
                let got = render(ctx, pipes, &compact, &method);
                let differ = got.iter().zip(&want).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
                let chunks = compact.chunks();
                assert_eq!(
                    differ, 0,
                    "{storage:?}, {method:?} in {chunks} chunks: values that differ from the stored scene's"
                );
            }
        }
    }
}

/// Bad input gets a typed error naming the problem: a scene above the binding limit, a NaN
/// particle, an invalid camera; a scene without particles is no error (the background).
#[test]
fn bad_raster_input_is_refused_with_a_message() {
    let Some(ctx) = context() else { return };
    let c = case("cloud", 16, 12);
    for (_, small) in common::part_binding_contexts(|c| c.with_binding_limit(4096).with_binding_array_elements(24)) {
        let e = RasterScene::new(&small, &c.scene, &RenderSettings::default()).err().expect("too large").to_string();
        assert!(e.contains("projected splats") && e.contains("4096") && e.contains("fits about"), "{e}");
    }
    // A scene without particles (transparent triangles alone, Laine & Karras's scenes) is no
    // error: every method draws the background.
    let settings = RenderSettings { background: glam::Vec3::new(0.2, 0.4, 0.6), ..RenderSettings::default() };
    let empty = RasterScene::new(ctx, &Scene::new(Vec::new(), 0), &settings).unwrap();
    let nothing = GpuRasterizer::new(ctx, pipelines(ctx), &empty, &c.camera, &RasterSettings::default()).unwrap();
    for method in [RasterMethod::Sorted { blend: Blend::Over }, RasterMethod::StochasticSplat, RasterMethod::Enderton] {
        let out = nothing.render(&method, &Frames::default()).unwrap().0;
        let background = out.mean.data().chunks(3).all(|p| p == [0.2, 0.4, 0.6]);
        assert!(background && out.alpha.data().iter().all(|&a| a == 0.0), "{method:?} without particles");
    }
    let mut nan = c.scene.clone();
    nan.particles[3].mean.x = f32::NAN;
    let e = RasterScene::new(ctx, &nan, &RenderSettings::default()).err().expect("NaN").to_string();
    assert!(e.to_lowercase().contains("particle 3"), "{e}");
    let scene = RasterScene::new(ctx, &c.scene, &RenderSettings::default()).unwrap();
    let mut camera = c.camera;
    camera.fx = 0.0;
    let e = GpuRasterizer::new(ctx, pipelines(ctx), &scene, &camera, &RasterSettings::default())
        .err()
        .expect("bad camera")
        .to_string();
    assert!(e.contains("focal") || e.contains("fx"), "{e}");
    let early = RasterSettings { early_stop: true, ..RasterSettings::default() };
    let e = GpuRasterizer::new(ctx, pipelines(ctx), &scene, &c.camera, &early).err().expect("early stop").to_string();
    assert!(e.contains("use rasterization without early stop or the CPU backend"), "{e}");
}

/// Through a lens the GPU splats by the unscented transform as the CPU does (its `project` in
/// f32 where the CPU's is in f64, the sigma-point axes from the inverse of the canonical
/// transform, `lens.wgsl`'s forward model and its pixel rays): sorted splatting through a
/// distorted perspective lens, a distorted fisheye and the equirectangular lens equals the
/// CPU's image to the blend format's tolerance, except at a few pixels where the rounding moves
/// a footprint's edge by a pixel (bounded: at most 1 % of pixels, each off by less than one
/// splat's alpha past the 3DGS box's 3σ, opacity × e^−4.5 < 0.012); the control, the CPU
/// through the pinhole of the same intrinsics, is far off.
#[test]
fn splatting_through_each_lens_equals_the_cpu() {
    use splat_core::camera::{Distortion, Lens};
    let Some(ctx) = context() else { return };
    let pipes = pipelines(ctx);
    let tolerance = if pipes.blend_format == splat_gpu::wgpu::TextureFormat::Rgba32Float { 1e-4 } else { 8e-3 };
    let c = case("cloud", 64, 48);
    let distortion =
        Distortion { radial: [-0.2, 0.05, 0.0, 0.0], rational: [0.0; 3], tangential: [1e-3, -1e-3], prism: [0.0; 2] };
    let fisheye = Distortion { radial: [0.04, -0.01, 0.002, 0.0], tangential: [0.0; 2], ..distortion };
    let scene = RasterScene::new(ctx, &c.scene, &RenderSettings::default()).unwrap();
    let sorted = RasterMethod::Sorted { blend: Blend::Under };
    for (name, lens) in [
        ("perspective", Lens::Perspective(distortion)),
        ("fisheye", Lens::Fisheye(fisheye)),
        ("equirectangular", Lens::Equirectangular),
    ] {
        let camera = c.camera.with_lens(lens).unwrap();
        let cpu_render = |camera: &Camera| {
            let r = Rasterizer::new(&c.scene, camera, RenderSettings::default(), RasterSettings::default()).unwrap();
            render_raster(&r, &sorted, &Frames::default(), &|_| {}).unwrap()
        };
        let gpu = GpuRasterizer::new(ctx, pipes, &scene, &camera, &RasterSettings::default()).unwrap();
        let gpu = gpu.render(&sorted, &Frames::default()).unwrap().0;
        let cpu = cpu_render(&camera);
        let d = max_abs_diff(gpu.mean.data(), cpu.mean.data());
        let rims = gpu
            .mean
            .data()
            .chunks(3)
            .zip(cpu.mean.data().chunks(3))
            .filter(|(a, b)| max_abs_diff(a, b) > tolerance)
            .count();
        let control = max_abs_diff(gpu.mean.data(), cpu_render(&c.camera).mean.data());
        eprintln!(
            "{name}: |GPU − CPU| {d:.2e} ({rims} pixels above {tolerance:.0e}), |GPU − CPU pinhole| {control:.2e}"
        );
        assert!(
            d < 0.012 && rims * 100 <= (64 * 48),
            "{name}: the GPU's unscented splatting differs from the CPU's by {d} ({rims} pixels)"
        );
        assert!(control > 0.05, "{name}: the lens changes nothing ({control})");
    }
}

/// GPU sorted splatting with the default extent is the INRIA 3DGS rasterizer: it equals the
/// independent forward pass of `splat_tests::inria` (no early stop, which the GPU refuses) on a
/// fixture of SH degree 0 and one of degree 3, to the blend format's tolerance; the √8σ extent
/// is rejected by the same comparison. With the gsplat-antialiased or Mip-Splatting preset's
/// screen filter and extent it equals that trainer's forward pass.
#[test]
fn gpu_sorted_splatting_equals_the_3dgs_forward_pass() {
    let Some(ctx) = context() else { return };
    let pipes = pipelines(ctx);
    let tolerance = if pipes.blend_format == splat_gpu::wgpu::TextureFormat::Rgba32Float { 1e-4 } else { 8e-3 };
    for name in ["layers", "cloud"] {
        let c = case(name, 128, 96);
        let options = splat_tests::inria::Options { background: [0.0; 3], ..Default::default() };
        let reference: Vec<f32> = splat_tests::inria::render(&c.scene, &c.camera, &options).concat();
        let scene = RasterScene::new(ctx, &c.scene, &RenderSettings::default()).unwrap();
        let render = |extent| {
            let raster = RasterSettings { extent, ..RasterSettings::default() };
            let gpu = GpuRasterizer::new(ctx, pipes, &scene, &c.camera, &raster).unwrap();
            gpu.render(&RasterMethod::Sorted { blend: Blend::Over }, &Frames::default()).unwrap().0
        };
        let d = max_abs_diff(render(SplatExtent::ThreeDgs).mean.data(), &reference);
        let control = max_abs_diff(render(SplatExtent::Sqrt8).mean.data(), &reference);
        eprintln!("{name}: |GPU 3dgs − reference| {d:.2e}, |GPU √8σ − reference| {control:.2e}");
        assert!(d <= tolerance, "{name}: GPU sorted splatting differs from the 3DGS forward pass by {d}");
        assert!(control > 1e-2, "{name}: the √8σ extent passes as 3DGS ({control})");
    }
    // The other trainers' presets (screen filter and footprint), on the cloud of few-pixel
    // splats where the filters matter; the control is the 3DGS dilation on their captures.
    let c = case("cloud", 128, 96);
    let dilated = RasterScene::new(ctx, &c.scene, &RenderSettings::default()).unwrap();
    for (preset, forward) in [
        (Preset::GsplatAntialiased, splat_tests::inria::Forward::GSPLAT_ANTIALIASED),
        (Preset::MipSplatting, splat_tests::inria::Forward::MIP_SPLATTING),
    ] {
        let options = splat_tests::inria::Options { background: [0.0; 3], forward, ..Default::default() };
        let reference: Vec<f32> = splat_tests::inria::render(&c.scene, &c.camera, &options).concat();
        let capture = Scene { screen_filter: preset.screen_filter().unwrap(), ..c.scene.clone() };
        let raster = RasterSettings { extent: preset.extent(), ..RasterSettings::default() };
        let render = |scene: &RasterScene| {
            let gpu = GpuRasterizer::new(ctx, pipes, scene, &c.camera, &raster).unwrap();
            gpu.render(&RasterMethod::Sorted { blend: Blend::Over }, &Frames::default()).unwrap().0
        };
        let d = max_abs_diff(
            render(&RasterScene::new(ctx, &capture, &RenderSettings::default()).unwrap()).mean.data(),
            &reference,
        );
        let control = max_abs_diff(render(&dilated).mean.data(), &reference);
        eprintln!("cloud {preset:?}: |GPU − its trainer| {d:.2e}, |GPU 3DGS dilation − its trainer| {control:.2e}");
        assert!(d <= tolerance, "cloud: the GPU's {preset:?} differs from its trainer's forward pass by {d}");
        assert!(control > 1e-2, "cloud: the 3DGS dilation passes for {preset:?} ({control})");
    }
}

/// Lit, the GPU rasterizer equals the CPU reference: sorted splatting through the compute tile
/// rasterizer in both looks (the surface look lit once per pixel at the picked depth, the
/// volumetric one per fragment) within 1e-3 except where the pick differs by f32 rounding at the
/// threshold (at most 0.5 % of pixels), and one StochasticSplats frame with each written
/// fragment lit, identical but for decisions within 1e-5 of their threshold. Lighting changes
/// each image by far more than the tolerance.
#[test]
fn lit_rasterization_equals_the_cpu() {
    let Some(ctx) = context() else { return };
    for name in ["layers", "cloud"] {
        let c = case(name, 48, 36);
        let unlit =
            render_raster(&cpu_raster(&c), &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {})
                .unwrap();
        for look in [Look::Surface, Look::Volumetric] {
            let lighting = common::lighting(Shadows::None, look);
            let cpu_r = cpu_raster(&c).with_lighting(lighting.clone()).unwrap();
            let scene = RasterScene::new_lit(ctx, &c.scene, &RenderSettings::default(), &lighting).unwrap();
            let gpu = GpuRasterizer::new(ctx, pipelines(ctx), &scene, &c.camera, &RasterSettings::default()).unwrap();
            let sorted = RasterMethod::Sorted { blend: Blend::Over };
            let cpu = render_raster(&cpu_r, &sorted, &Frames::default(), &|_| {}).unwrap();
            let g = gpu.render(&sorted, &Frames::default()).unwrap().0;
            let effect = max_abs_diff(cpu.mean.data(), unlit.mean.data());
            assert!(effect > 0.1, "{name} {look:?}: lighting changes the image by {effect} only");
            let pixels = cpu.picked.len();
            let off: Vec<usize> = (0..pixels)
                .filter(|&p| max_abs_diff(&g.mean.data()[3 * p..3 * p + 3], &cpu.mean.data()[3 * p..3 * p + 3]) > 1e-3)
                .collect();
            let pick_flips = off.iter().filter(|&&p| g.picked[p] != cpu.picked[p]).count();
            eprintln!("{name} {look:?} sorted: {} pixels off, {pick_flips} of them by a different pick", off.len());
            assert!(off.len() == pick_flips && pick_flips * 200 <= pixels, "{name} {look:?}: pixels {off:?}");
            // The normal image too: zero where the surface look found no surface, as on the CPU.
            let normals_off = (0..pixels)
                .filter(|&p| g.picked[p] == cpu.picked[p])
                .filter(|&p| {
                    max_abs_diff(&g.normal.data()[3 * p..3 * p + 3], &cpu.normal.data()[3 * p..3 * p + 3]) > 1e-3
                })
                .count();
            assert_eq!(normals_off, 0, "{name} {look:?}: normals differ");
            let frames = Frames { count: 1, seed: 3, ..Frames::default() };
            let cpu = render_raster(&cpu_r, &RasterMethod::StochasticSplat, &frames, &|_| {}).unwrap();
            let g = gpu.render(&RasterMethod::StochasticSplat, &frames).unwrap().0;
            let bad: Vec<usize> = (0..pixels)
                .filter(|&p| {
                    let d = max_abs_diff(&g.mean.data()[3 * p..3 * p + 3], &cpu.mean.data()[3 * p..3 * p + 3]);
                    let (x, y) = (p as u32 % c.camera.width, p as u32 / c.camera.width);
                    (d.is_nan() || d > 1e-3)
                        && splat_tests::flips::raster_gap(&cpu_r, &RasterMethod::StochasticSplat, &frames, x, y)
                            >= splat_tests::flips::FLIP_GAP
                })
                .collect();
            assert!(bad.is_empty(), "{name} {look:?} stochastic-splat: pixels {bad:?}");
        }
    }
}

/// The wall, glass sphere and half-mirror (gold-tinted) the splats of `layers` lie among.
fn among_meshes() -> splat_core::mesh::Meshes {
    use glam::Vec3;
    use splat_core::mesh::{MeshMaterial, Meshes, TriangleMesh};
    let place = splat_tests::placed;
    Meshes::new(&[
        (place(TriangleMesh::plane(), 3.0, Vec3::Z, Vec3::new(0.0, 0.0, -1.2)), MeshMaterial::default()),
        (
            place(TriangleMesh::sphere(24, 12), 0.35, Vec3::Y, Vec3::new(-0.3, -0.2, 0.3)),
            MeshMaterial { transmission: 0.9, ..MeshMaterial::default() },
        ),
        (
            place(TriangleMesh::plane(), 0.5, Vec3::new(-1.0, 0.0, 1.0), Vec3::new(0.7, 0.1, 0.2)),
            MeshMaterial {
                color: Vec3::new(0.9, 0.4, 0.2),
                mirror: 0.5,
                mirror_tint: Vec3::new(1.0, 0.78, 0.34),
                ..MeshMaterial::default()
            },
        ),
    ])
    .unwrap()
}

/// One frame of each (method, lit, fragment depth) of `cases` at `samples` standard samples per
/// pixel among [`among_meshes`], GPU against the CPU reference `Rasterizer::with_meshes`: every
/// pixel within 1e-4 in colour and coverage but for a stochastic decision within 1e-5 of its
/// threshold or a depth tie, and the meshes change every image far beyond that. Then lit sorted
/// splatting in both looks (the compute tile rasterizer, which reads the pre-pass too), with its
/// depth, normal and pick: the mesh's where the splats stay below the iso threshold.
fn compare_among_meshes(samples: u32, cases: &[(RasterMethod, bool, FragmentDepth)]) {
    let Some(ctx) = context() else { return };
    let c = case("layers", 48, 36);
    let meshes = among_meshes();
    let settings = RenderSettings { background: glam::Vec3::new(0.05, 0.05, 0.1), ..RenderSettings::default() };
    let lit = common::lighting(Shadows::None, Look::Volumetric);
    let standard = |fragment_depth| RasterSettings {
        samples,
        sample_pattern: SamplePattern::Standard,
        fragment_depth,
        ..RasterSettings::default()
    };
    for &(method, is_lit, depth) in cases {
        let lighting = if is_lit { lit.clone() } else { splat_core::lighting::Lighting::default() };
        let raster = standard(depth);
        let bare =
            || Rasterizer::new(&c.scene, &c.camera, settings, raster).unwrap().with_lighting(lighting.clone()).unwrap();
        let cpu_r = bare().with_meshes(meshes.clone());
        let scene =
            RasterScene::new_lit(ctx, &c.scene, &settings, &lighting).unwrap().with_meshes(ctx, &meshes).unwrap();
        let gpu = GpuRasterizer::new(ctx, pipelines(ctx), &scene, &c.camera, &raster).unwrap();
        let frames = Frames { count: 1, seed: 5, ..Frames::default() };
        let cpu = render_raster(&cpu_r, &method, &frames, &|_| {}).unwrap();
        let without = render_raster(&bare(), &method, &frames, &|_| {}).unwrap();
        let g = match gpu.render(&method, &frames) {
            Ok(g) => g.0,
            Err(e) if !ctx.sample_rate_shading && e.to_string().contains("MULTISAMPLED_SHADING") => {
                eprintln!("{method:?} lit {is_lit} {depth:?}: refused without sample-rate shading ({e})");
                continue;
            }
            Err(e) => panic!("{method:?} lit {is_lit} {depth:?} S = {samples}: {e}"),
        };
        let effect = max_abs_diff(cpu.mean.data(), without.mean.data());
        assert!(effect > 0.1, "{method:?} lit {is_lit}: the meshes change the image by {effect} only");
        let pixels = cpu.alpha.data().len();
        let mut near = 0;
        let bad: Vec<(u32, u32, f32)> = (0..pixels)
            .filter_map(|p| {
                let d = max_abs_diff(&g.mean.data()[3 * p..3 * p + 3], &cpu.mean.data()[3 * p..3 * p + 3]);
                let a = (g.alpha.data()[p] - cpu.alpha.data()[p]).abs();
                let (x, y) = (p as u32 % c.camera.width, p as u32 / c.camera.width);
                if !(d.is_nan() || d > 1e-4 || a > 1e-4) {
                    return None;
                }
                let flips = || {
                    let tie = depth == FragmentDepth::Center
                        && splat_tests::flips::raster_depth_gap(&cpu_r, x, y) < splat_tests::flips::DEPTH_TIE;
                    tie || splat_tests::flips::raster_gap(&cpu_r, &method, &frames, x, y) < splat_tests::flips::FLIP_GAP
                };
                if method.is_stochastic() && flips() {
                    near += 1;
                    return None;
                }
                Some((x, y, d))
            })
            .collect();
        eprintln!(
            "{method:?} lit {is_lit} {depth:?} S = {samples}: {near} pixels differ by a decision near its threshold"
        );
        assert!(bad.is_empty(), "{method:?} lit {is_lit} {depth:?} S = {samples}: pixels (x, y, difference) {bad:?}");
    }
    for look in [Look::Surface, Look::Volumetric] {
        let lighting = common::lighting(Shadows::None, look);
        let raster = standard(FragmentDepth::Center);
        let cpu_r = Rasterizer::new(&c.scene, &c.camera, settings, raster)
            .unwrap()
            .with_lighting(lighting.clone())
            .unwrap()
            .with_meshes(meshes.clone());
        let scene =
            RasterScene::new_lit(ctx, &c.scene, &settings, &lighting).unwrap().with_meshes(ctx, &meshes).unwrap();
        let gpu = GpuRasterizer::new(ctx, pipelines(ctx), &scene, &c.camera, &raster).unwrap();
        let under = RasterMethod::Sorted { blend: Blend::Under };
        let cpu = render_raster(&cpu_r, &under, &Frames::default(), &|_| {}).unwrap();
        let g = gpu.render(&under, &Frames::default()).unwrap().0;
        let pixels = cpu.picked.len();
        let mut mesh_depths = 0;
        for p in 0..pixels {
            let (dc, dg) = (cpu.depth.data()[p], g.depth.data()[p]);
            let same_depth = (dc.is_nan() && dg.is_nan()) || (dc - dg).abs() <= 1e-4 * dc.abs().max(1.0);
            let colour = max_abs_diff(&g.mean.data()[3 * p..3 * p + 3], &cpu.mean.data()[3 * p..3 * p + 3]);
            let alpha = (g.alpha.data()[p] - cpu.alpha.data()[p]).abs();
            let normal = max_abs_diff(&g.normal.data()[3 * p..3 * p + 3], &cpu.normal.data()[3 * p..3 * p + 3]);
            assert!(
                colour <= 1e-3 && alpha <= 1e-4 && normal <= 1e-3 && same_depth && g.picked[p] == cpu.picked[p],
                "{look:?} S = {samples} pixel {p}: colour {colour}, alpha {alpha}, normal {normal}, depth {dc} vs {dg}, pick {:?} vs {:?}",
                cpu.picked[p],
                g.picked[p]
            );
            mesh_depths += usize::from(cpu.picked[p].is_none() && !dc.is_nan());
        }
        assert!(mesh_depths > pixels / 10, "{look:?}: only {mesh_depths} pixels take the mesh's depth");
    }
}

/// The three passes among meshes (vk_gaussian_splatting Lighting §1.5.3 and §3) on the GPU at
/// one sample per pixel ([`compare_among_meshes`]): a matte wall behind the sheets, a glass
/// sphere and a half-mirror among them (their shares see the background in both), the mesh
/// pre-pass, the splats' depth test and the mesh blended under them. Sorted over and under,
/// StochasticSplats (unlit and lit, at centre depth and at the max-density plane), Enderton
/// (unlit and lit) and stratified (lit: the raster operations start each pixel from the mesh's
/// depth).
#[test]
fn three_pass_compositing_among_meshes_equals_the_cpu() {
    use FragmentDepth::{Center, MaxDensityPlane};
    compare_among_meshes(
        1,
        &[
            (RasterMethod::Sorted { blend: Blend::Over }, false, Center),
            (RasterMethod::Sorted { blend: Blend::Under }, false, Center),
            (RasterMethod::StochasticSplat, false, Center),
            (RasterMethod::StochasticSplat, true, Center),
            (RasterMethod::StochasticSplat, false, MaxDensityPlane),
            (RasterMethod::Enderton, false, Center),
            (RasterMethod::Enderton, true, Center),
            (RasterMethod::Stratified { scramble: true }, true, Center),
        ],
    );
}

/// The same at four samples per pixel: the mesh pre-pass casts a ray through each sample, each
/// sample's fragments are depth tested against its own mesh and composited over its own colour
/// (a mesh edge inside a pixel covers some of its samples), in the render pipelines' sample
/// masks, the raster operations and the tile pass alike.
#[test]
fn three_pass_compositing_among_meshes_at_four_samples_equals_the_cpu() {
    use FragmentDepth::{Center, MaxDensityPlane};
    compare_among_meshes(
        4,
        &[
            (RasterMethod::Sorted { blend: Blend::Over }, false, Center),
            (RasterMethod::Sorted { blend: Blend::Under }, false, Center),
            (RasterMethod::StochasticSplat, false, Center),
            (RasterMethod::StochasticSplat, true, MaxDensityPlane),
            (RasterMethod::Enderton, true, Center),
            (RasterMethod::Stratified { scramble: true }, false, MaxDensityPlane),
            (RasterMethod::Stratified { scramble: false }, true, Center),
        ],
    );
}

/// Splatting through a camera drawn per frame (a box pixel filter and a thin lens,
/// `splat_core::camera_sampling`) on the GPU: each frame projected through its own pinhole
/// camera and folded as the CPU folds them. Sorted splatting equals the CPU's to the blending
/// tolerance, StochasticSplats' mean to a few decisions within f32 rounding of their threshold,
/// and frame 0's depth pick is the CPU's; the control, the still camera, is far off.
#[test]
fn a_camera_drawn_per_frame_splats_as_on_the_cpu() {
    use splat_core::camera_sampling::{CameraSampling, PixelFilter, ThinLens};
    use splat_core::lighting::Lighting;
    use splat_core::mesh::Meshes;
    let Some(ctx) = context() else { return };
    let pipes = pipelines(ctx);
    let tolerance = if pipes.blend_format == splat_gpu::wgpu::TextureFormat::Rgba32Float { 1e-4 } else { 8e-3 };
    let (scene, camera) = fixture("layers", 48, 36);
    let sampling =
        CameraSampling { filter: PixelFilter::Box, lens: Some(ThinLens { aperture: 0.3, focus_distance: 2.0 }) };
    let settings = RenderSettings { sampling, ..RenderSettings::default() };
    let (lighting, meshes) = (Lighting::default(), Meshes::none());
    let shot =
        splat_core::Shot { scene: &scene, meshes: &meshes, lighting: &lighting, camera: &camera, settings: &settings };
    let still = RenderSettings::default();
    let still_shot = splat_core::Shot { settings: &still, ..shot };
    let raster =
        RasterSettings { sample_pattern: splat_core::raster::SamplePattern::Standard, ..RasterSettings::default() };
    let frames = Frames { count: 8, seed: 6, ..Frames::default() };
    for method in [RasterMethod::Sorted { blend: Blend::Under }, RasterMethod::StochasticSplat] {
        let algorithm = splat_core::Algorithm::Raster(method, raster);
        let extras = splat_gpu::Extras { depth: !method.is_stochastic(), normal: false };
        let cpu = algorithm.render_world(&shot, &frames, &|_| {}).unwrap();
        let gpu = splat_gpu::render(ctx, &algorithm, &shot, extras, &frames).unwrap();
        let control = algorithm.render_world(&still_shot, &frames, &|_| {}).unwrap();
        let d = max_abs_diff(cpu.mean.data(), gpu.mean.data());
        let mean = cpu.mean.data().iter().zip(gpu.mean.data()).map(|(a, b)| f64::from((a - b).abs())).sum::<f64>()
            / cpu.mean.data().len() as f64;
        let far = max_abs_diff(control.mean.data(), gpu.mean.data());
        eprintln!("{method:?}: max |GPU − CPU| {d:.2e}, mean {mean:.2e}, still camera {far:.2e}");
        if method.is_stochastic() {
            assert!(mean < 2e-3, "{method:?}: mean |GPU − CPU| {mean}");
        } else {
            assert!(d <= tolerance, "{method:?}: {d}");
            // Where both pick a depth it agrees; where one does, so does the other.
            let (mut picked, mut worst) = (0, 0.0f32);
            for (a, b) in cpu.depth.data().iter().zip(gpu.depth.data()) {
                assert_eq!(a.is_nan(), b.is_nan(), "{method:?}: frame 0's depth {a} against {b}");
                if !a.is_nan() {
                    picked += 1;
                    worst = worst.max((a - b).abs());
                }
            }
            assert!(picked > 100 && worst < 1e-3, "{method:?}: {picked} depths, off by {worst}");
        }
        assert!(far > 1e-2, "{method:?}: the sampled camera changes nothing ({far})");
    }
}
