//! The Embree peer is a baseline only if it computes what splat computes: the same seed must
//! give the same image, method by method, with either set of boxes (the boxes change what is
//! visited, never what is hit). Without Embree the test skips loudly (fails under `CI=true`,
//! where `cargo xtask test` installs libembree-dev first).

use embree_peer::{EmbreePeer, PeerBounds, PeerMethod};
use splat_core::frame::Frames;
use splat_core::rng::frame_key;
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{RenderSettings, scenes};

/// Largest channel difference and the share of pixels apart ([`embree_peer::difference`]).
fn compare(a: &[f32], b: &[f32]) -> (f32, f64) {
    let (max, apart) = embree_peer::difference(a, b);
    (max, apart as f64 / (a.len() / 3) as f64)
}

/// Opaque, stochastic (Algorithm 1) and exact agree with splat-core to float noise on two
/// fixtures (the dense cloud and the layers), with cutoff boxes and with splat's boxes; and the
/// comparison can fail: the peer's stochastic image of another seed is rejected.
#[test]
fn the_peer_makes_the_decisions_of_the_cpu_tracer() {
    if !embree_peer::available() {
        splat_tests::skip(&splat_tests::current_test(), embree_peer::NOT_BUILT);
        return;
    }
    let settings = RenderSettings::default();
    let frames = Frames { count: 1, seed: 1, ..Frames::default() };
    for (name, (scene, camera)) in [("cloud", scenes::cloud()), ("layers", scenes::layers())] {
        let camera = camera.rescaled(64, 48).unwrap();
        let trace = TraceScene::new(&scene, settings).unwrap();
        for bounds in [PeerBounds::Cutoff, PeerBounds::Splat] {
            let peer = EmbreePeer::build(&scene, &settings, bounds, 2).unwrap();
            for (method, peer_method) in [
                (Method::Opaque, PeerMethod::Opaque),
                (Method::Stochastic, PeerMethod::Stochastic),
                (Method::Exact, PeerMethod::Exact),
            ] {
                let splat = render_frames(&trace, &camera, &method, &frames, &|_| {}).unwrap();
                let image = peer.render(&camera, peer_method, frame_key(frames.seed, 0), 2);
                let (max, apart) = compare(splat.mean.data(), &image);
                eprintln!("{name} {bounds:?} {method:?}: max |Δ| {max:.1e}, {:.2} % of pixels apart", 100.0 * apart);
                assert!(max <= 1e-5, "{name}, {bounds:?} boxes, {method:?}: the images differ by {max}");
            }
            let splat = render_frames(&trace, &camera, &Method::Stochastic, &frames, &|_| {}).unwrap();
            let other_seed = peer.render(&camera, PeerMethod::Stochastic, frame_key(frames.seed + 1, 0), 2);
            let (max, apart) = compare(splat.mean.data(), &other_seed);
            assert!(apart > 0.1 && max > 0.1, "{name}: another seed passed ({:.1} % apart)", 100.0 * apart);
        }
    }
}
