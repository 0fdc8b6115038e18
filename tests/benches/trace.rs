//! `cargo bench -p splat-tests`: one frame at 1 spp of every ray-tracing method through the same
//! BVH, on a 300 × 200 view of the bonsai capture (`cargo xtask assets`; the cloud fixture
//! without it), and Sun et al. Table 5: 1024 samples per pixel as 16 × 64 against 1024 × 1.
//! Compare methods by their ratios to `opaque` in the same run.

use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{Camera, Scene};
use splat_core::{Frames, RenderSettings};
use std::sync::LazyLock;

fn main() {
    divan::main();
}

static SCENE: LazyLock<(Scene, Camera)> = LazyLock::new(|| match splat_tests::bonsai() {
    Some(scene) => (scene, splat_tests::bonsai_camera().rescaled(300, 200).expect("camera")),
    None => {
        let (scene, camera) = splat_core::scenes::cloud();
        (scene, camera.rescaled(300, 200).expect("camera"))
    }
});

static TRACE: LazyLock<TraceScene<'static>> =
    LazyLock::new(|| TraceScene::new(&SCENE.0, RenderSettings::default()).expect("scene"));

fn frame(method: &Method, camera: &Camera, spp: u32) {
    let frames = Frames { count: spp, seed: 1, ..Frames::default() };
    divan::black_box(render_frames(&TRACE, camera, method, &frames, &|_| {}).expect("render"));
}

#[divan::bench(sample_count = 5, args = ["opaque", "stochastic", "stochastic-n 1x16", "stochastic-pass", "kbuffer", "exact"])]
fn one_frame(name: &str) {
    let method = match name {
        "opaque" => Method::Opaque,
        "stochastic" => Method::Stochastic,
        "stochastic-n 1x16" => Method::StochasticN { m: 1, n: 16 },
        "stochastic-pass" => Method::STOCHASTIC_PASS,
        "kbuffer" => Method::KBUFFER,
        _ => Method::Exact,
    };
    frame(&method, &SCENE.1, 1);
}

/// Table 5 of Sun et al.: 1024 samples per pixel on a 40 × 30 crop, m × n = 16 × 64 against
/// 1024 × 1 (the paper measured 5.1–5.6× on the CPU).
#[divan::bench(sample_count = 3, args = [(16, 64), (1024, 1)])]
fn table5_1024_spp(mn: (u32, u32)) {
    let crop = SCENE.1.crop(130, 40, 40, 30).expect("crop");
    frame(&Method::StochasticN { m: mn.0, n: mn.1 }, &crop, 1);
}
