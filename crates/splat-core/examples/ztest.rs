//! Is an estimator unbiased? Render its mean over F frames, the per-frame variance of an
//! independent run, and the exact image; the per-pixel z-test (docs/architecture.md, "How
//! correctness is proven") passes Algorithm 1 of Sun et al. 2025 and rejects 3DGRT's depth
//! sampling, which is biased:
//!
//! ```sh
//! cargo run --release -p splat-core --example ztest
//! ```
use splat_core::stats::ZTest;
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{Frames, RenderSettings, scenes};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (scene, camera) = scenes::layers();
    let camera = camera.rescaled(64, 24)?;
    let trace = TraceScene::new(&scene, RenderSettings::default())?;
    let render = |method: &Method, count, seed| {
        render_frames(&trace, &camera, method, &Frames { count, seed, ..Frames::default() }, &|_| {})
    };
    let exact = render(&Method::Exact, 1, 0)?;
    let mut verdicts = Vec::new();
    for method in [Method::Stochastic, Method::DepthSampling { k: 4 }] {
        let mean = render(&method, 256, 1)?;
        let variance = render(&method, 1024, 2)?.variance;
        let z = ZTest::new(mean.mean.data(), exact.mean.data(), variance.data(), 256, 3);
        println!(
            "{method:?}: global {:.2}, spread {:.2}, outliers {:.1} % → {}",
            z.global,
            z.spread,
            100.0 * z.outliers,
            if z.passes() { "unbiased" } else { "REJECTED" }
        );
        verdicts.push(z.passes());
    }
    // The example checks itself: the first passes, the control does not.
    if verdicts != [true, false] {
        return Err(format!("unexpected verdicts {verdicts:?}").into());
    }
    Ok(())
}
