//! The same scene, settings and seed give the bit-identical image whatever the thread count,
//! for the exact renderer, every stochastic ray-tracing method and every raster method.

use splat_core::raster::{Blend, RasterMethod, RasterSettings, Rasterizer, render_raster};
use splat_core::scenes;
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{Frames, RenderSettings, Shot, render_oracle};

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap()
}

fn exact_with_threads(threads: usize) -> Vec<f32> {
    let (scene, camera) = scenes::cloud();
    let out = pool(threads).install(|| {
        render_oracle(&scene, &camera, &RenderSettings::default(), &splat_core::Frames::default(), &|_| {}).unwrap()
    });
    [out.mean, out.alpha, out.depth, out.normal].iter().flat_map(|i| i.data().to_vec()).collect()
}

fn method_with_threads(method: &Method, threads: usize, seed: u32) -> Vec<f32> {
    let (scene, camera) = scenes::cloud();
    let camera = camera.rescaled(48, 36).unwrap();
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let frames = Frames { count: 3, seed, ..Frames::default() };
    let out = pool(threads).install(|| render_frames(&trace, &camera, method, &frames, &|_| {}).unwrap());
    [out.mean, out.variance, out.alpha, out.depth, out.normal].iter().flat_map(|i| i.data().to_vec()).collect()
}

fn same_bits(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[test]
fn exact_image_is_identical_for_one_two_and_three_threads() {
    let one = exact_with_threads(1);
    for threads in [2, 3] {
        assert!(same_bits(&one, &exact_with_threads(threads)), "{threads} threads differ");
    }
}

#[test]
fn stochastic_images_are_identical_across_thread_counts_and_differ_across_seeds() {
    for method in [
        Method::Stochastic,
        Method::StochasticN { m: 2, n: 3 },
        Method::STOCHASTIC_PASS,
        Method::DepthSampling { k: 2 },
        Method::KBUFFER,
    ] {
        let one = method_with_threads(&method, 1, 5);
        assert!(same_bits(&one, &method_with_threads(&method, 2, 5)), "{method:?}: 2 threads differ");
        if method.is_stochastic() {
            assert!(!same_bits(&one, &method_with_threads(&method, 1, 6)), "{method:?}: seeds 5 and 6 agree");
        }
    }
}

fn raster_with_threads(method: &RasterMethod, threads: usize, seed: u32) -> Vec<f32> {
    let (scene, camera) = scenes::cloud();
    let camera = camera.rescaled(48, 36).unwrap();
    let raster = RasterSettings { samples: 4, ..RasterSettings::default() };
    let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), raster).unwrap();
    let frames = Frames { count: 3, seed, ..Frames::default() };
    let out = pool(threads).install(|| render_raster(&r, method, &frames, &|_| {}).unwrap());
    [out.mean, out.variance, out.alpha, out.depth, out.normal].iter().flat_map(|i| i.data().to_vec()).collect()
}

#[test]
fn raster_images_are_identical_across_thread_counts_and_differ_across_seeds() {
    for method in [
        RasterMethod::Sorted { blend: Blend::Under },
        RasterMethod::StochasticSplat,
        RasterMethod::Enderton,
        RasterMethod::Stratified { scramble: true },
    ] {
        let one = raster_with_threads(&method, 1, 5);
        assert!(same_bits(&one, &raster_with_threads(&method, 2, 5)), "{method:?}: 2 threads differ");
        if method.is_stochastic() {
            assert!(!same_bits(&one, &raster_with_threads(&method, 1, 6)), "{method:?}: seeds 5 and 6 agree");
        }
    }
}

/// The lit demo world (stochastic shadow rays, a soft spot light): `exact`, `stochastic` and
/// `stochastic-splat` give bit-identical images for 1 and 3 threads, and another seed moves the
/// shadows.
#[test]
fn lit_images_are_identical_across_thread_counts() {
    use splat_core::Algorithm;
    let world = splat_io::world::read_world(&splat_tests::root().join(splat_tests::golden::LIT_WORLD)).unwrap();
    let camera = world.camera.unwrap().rescaled(48, 36).unwrap();
    let settings = RenderSettings { background: world.background.unwrap_or_default(), ..RenderSettings::default() };
    let raster = RasterSettings { samples: 4, ..RasterSettings::default() };
    let render = |algorithm: &Algorithm, threads: usize, seed: u32| {
        let frames = Frames { count: 2, seed, ..Frames::default() };
        let out = pool(threads)
            .install(|| algorithm.render_lit(&world.scene, &camera, &settings, &world.lighting, &frames, &|_| {}))
            .unwrap();
        [out.mean, out.variance, out.alpha, out.depth, out.normal]
            .iter()
            .flat_map(|i| i.data().to_vec())
            .collect::<Vec<_>>()
    };
    for algorithm in [
        Algorithm::Trace(Method::Exact),
        Algorithm::Trace(Method::Stochastic),
        Algorithm::Raster(RasterMethod::StochasticSplat, raster),
    ] {
        let one = render(&algorithm, 1, 5);
        assert!(same_bits(&one, &render(&algorithm, 3, 5)), "{algorithm:?}: 3 threads differ");
        assert!(!same_bits(&one, &render(&algorithm, 1, 6)), "{algorithm:?}: seeds 5 and 6 agree");
    }
}

/// The demo among meshes by every pipeline (stochastic shadows, an area light, mirror and glass
/// bounces): bit-identical for one and three threads, different for another seed.
#[test]
fn mesh_world_images_are_identical_across_thread_counts() {
    use splat_core::Algorithm;
    let world = splat_io::world::read_world(&splat_tests::root().join(splat_tests::golden::MESH_WORLD)).unwrap();
    let meshes = splat_core::mesh::Meshes::new(&world.meshes).unwrap();
    let camera = world.camera.unwrap().rescaled(40, 30).unwrap();
    let s4 = RasterSettings { samples: 4, ..RasterSettings::default() };
    let under = RasterMethod::Sorted { blend: Blend::Under };
    for algorithm in [
        Algorithm::Trace(Method::Stochastic),
        Algorithm::Trace(Method::Exact),
        Algorithm::Raster(RasterMethod::StochasticSplat, s4),
        Algorithm::Hybrid(under, s4, Method::Stochastic),
    ] {
        let render = |threads: usize, seed: u32| {
            let frames = Frames { count: 2, seed, ..Frames::default() };
            let out = pool(threads).install(|| {
                let settings = RenderSettings::default();
                let shot = Shot {
                    scene: &world.scene,
                    meshes: &meshes,
                    lighting: &world.lighting,
                    camera: &camera,
                    settings: &settings,
                };
                algorithm.render_world(&shot, &frames, &|_| {})
            });
            let out = out.unwrap();
            [out.mean, out.alpha, out.depth, out.normal].iter().flat_map(|i| i.data().to_vec()).collect::<Vec<f32>>()
        };
        let one = render(1, 5);
        assert!(same_bits(&one, &render(3, 5)), "{algorithm:?}: 3 threads differ");
        assert!(!same_bits(&one, &render(1, 6)), "{algorithm:?}: seeds 5 and 6 agree");
    }
}
