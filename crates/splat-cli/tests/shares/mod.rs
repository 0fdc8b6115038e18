//! Renders past one machine: `splat render --frames A..B` shares of a run merged by `splat
//! merge` equal the run rendered at once (bit for bit where every frame is the same, within two
//! f32 ulps of the mean where they differ: the shares' means are f32, the run's is folded in
//! f64), on the GPU as on the CPU, and `--all-cameras --shard I/N` tasks fill the folder the
//! whole set fills.

use splat_tests::root;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn splat(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_splat")).args(args).current_dir(root()).output().expect("run splat")
}

fn ok(args: &[&str]) {
    let o = splat(args);
    assert!(o.status.success(), "splat {}: {}", args.join(" "), String::from_utf8_lossy(&o.stderr));
}

fn refused(args: &[&str], message: &str) {
    let o = splat(args);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && stderr.contains(message),
        "splat {}: expected '{message}' in {stderr}",
        args.join(" ")
    );
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("splat-shares-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn text(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn npy(p: &Path) -> Vec<f32> {
    splat_io::image::read_npy(p).unwrap().data().to_vec()
}

/// Units in the last place between two f32 of one sign (0 when equal).
fn ulps(a: f32, b: f32) -> u32 {
    if a == b { 0 } else { (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs() as u32 }
}

/// The largest ulp distance between two images, and the largest relative difference.
fn distance(a: &[f32], b: &[f32]) -> (u32, f64) {
    assert_eq!(a.len(), b.len());
    let ulp = a.iter().zip(b).map(|(x, y)| ulps(*x, *y)).max().unwrap();
    let rel = a
        .iter()
        .zip(b)
        .map(|(x, y)| f64::from((x - y).abs()) / f64::from(x.abs().max(y.abs()).max(1e-6)))
        .fold(0.0, f64::max);
    (ulp, rel)
}

/// Render `frames` frames of `render` at once, then as the shares split at `cuts`, merge the
/// shares (given in reverse order) and compare: (mean ulps, variance relative, alpha ulps; the
/// path tracer writes no alpha).
fn run_against_shares(name: &str, render: &[&str], frames: u32, cuts: &[u32]) -> (u32, f64, u32) {
    let file = |what: &str| scratch(&format!("{name}-{what}"));
    let with_alpha = !render.contains(&"path");
    let images = |prefix: &str| {
        let (mean, variance, alpha) = (
            file(&format!("{prefix}mean.npy")),
            file(&format!("{prefix}var.npy")),
            file(&format!("{prefix}alpha.npy")),
        );
        let mut flags = vec!["-o".to_string(), text(&mean).into(), "--variance".into(), text(&variance).into()];
        if with_alpha {
            flags.extend(["--alpha".to_string(), text(&alpha).into()]);
        }
        (mean, variance, alpha, flags)
    };
    let (mean, variance, alpha, flags) = images("");
    let spp = frames.to_string();
    let mut whole = vec!["render"];
    whole.extend_from_slice(render);
    whole.extend_from_slice(&["--spp", &spp]);
    whole.extend(flags.iter().map(String::as_str));
    ok(&whole);
    let bounds: Vec<u32> = std::iter::once(0).chain(cuts.iter().copied()).chain([frames]).collect();
    let mut parts = Vec::new();
    for pair in bounds.windows(2) {
        let part = file(&format!("{}-{}.acc", pair[0], pair[1]));
        let range = format!("{}..{}", pair[0], pair[1]);
        let mut share = vec!["render"];
        share.extend_from_slice(render);
        share.extend_from_slice(&["--frames", &range, "-o", text(&part)]);
        ok(&share);
        parts.push(part);
    }
    let (m_mean, m_var, m_alpha, flags) = images("merged-");
    let mut merge = vec!["merge"];
    merge.extend(parts.iter().rev().map(|p| text(p)));
    merge.extend(flags.iter().map(String::as_str));
    ok(&merge);
    let (mean_ulps, _) = distance(&npy(&mean), &npy(&m_mean));
    let (_, variance_rel) = distance(&npy(&variance), &npy(&m_var));
    let alpha_ulps = if with_alpha { distance(&npy(&alpha), &npy(&m_alpha)).0 } else { 0 };
    (mean_ulps, variance_rel, alpha_ulps)
}

const CLOUD: [&str; 7] =
    ["fixtures/cloud.ply", "--camera", "fixtures/cloud.cameras.json", "--width", "40", "--height", "30"];

/// Every frame-indexed draw of the run (the decisions of ray tracing and splatting, the box
/// filter's pixel samples, the oracle's frames, the path tracer's Sobol index) is the share's
/// own: shares merge into the run within two ulps of the mean and alpha (measured: 1), the
/// variance within 10⁻⁵ relative (measured: at most 1.3 · 10⁻⁶), and a deterministic method
/// equal bit for bit. Drawing the box filter's samples by the share's own frame count instead
/// of the run's frame index puts the mean 10⁹ ulps off.
#[test]
fn shares_of_a_run_merge_into_the_run() {
    let with =
        |extra: &[&'static str]| -> Vec<&'static str> { CLOUD.iter().copied().chain(extra.iter().copied()).collect() };
    let cases: [(&str, Vec<&str>); 5] = [
        ("stochastic", with(&["--method", "stochastic", "--seed", "5"])),
        (
            "box-filter",
            with(&["--method", "stochastic-n", "--samples-per-traversal", "3", "--pixel-filter", "box", "--seed", "2"]),
        ),
        (
            "splat-box",
            with(&["--method", "stochastic-splat", "--raster-samples", "4", "--pixel-filter", "box", "--seed", "3"]),
        ),
        ("oracle-box", with(&["--method", "oracle", "--pixel-filter", "box"])),
        ("path", vec!["--pipeline", "path", "--width", "24", "--height", "18", "--seed", "4", "--backend", "cpu"]),
    ];
    for (name, render) in &cases {
        let (mean, variance, alpha) = run_against_shares(name, render, 12, &[5, 7]);
        eprintln!("{name}: mean {mean} ulps, variance {variance:e} relative, alpha {alpha} ulps");
        assert!(
            mean <= 2 && alpha <= 2 && variance <= 1e-5,
            "{name}: mean {mean} ulps, variance {variance:e}, alpha {alpha} ulps"
        );
    }
    let exact = with(&["--method", "exact"]);
    assert_eq!(
        run_against_shares("exact", &exact, 3, &[1]),
        (0, 0.0, 0),
        "a deterministic render is the same in any share"
    );
}

/// The controls: a share of another seed, overlapping shares and a gap are refused by name;
/// and shares of another seed would differ from the run far beyond the bound (so the bound
/// means something).
#[test]
fn shares_of_different_runs_overlaps_and_gaps_are_refused() {
    let share = |range: &str, seed: &str, name: &str| {
        let path = scratch(name);
        let mut args: Vec<&str> = vec!["render"];
        args.extend_from_slice(&CLOUD);
        args.extend_from_slice(&["--method", "stochastic", "--seed", seed, "--frames", range, "-o", text(&path)]);
        ok(&args);
        path
    };
    let (a, b) = (share("0..4", "1", "c-a.acc"), share("4..8", "1", "c-b.acc"));
    let (other, overlap, late) =
        (share("4..8", "2", "c-other.acc"), share("3..8", "1", "c-overlap.acc"), share("5..8", "1", "c-late.acc"));
    let out = scratch("c-out.npy");
    refused(&["merge", text(&a), text(&other), "-o", text(&out)], "are shares of different renders");
    refused(&["merge", text(&a), text(&overlap), "-o", text(&out)], "the shares' frames overlap: 0..4 and 3..8");
    refused(&["merge", text(&a), text(&late), "-o", text(&out)], "the shares leave frames 4..5 out");
    let merged = scratch("c-merged.acc");
    ok(&["merge", text(&a), text(&b), "-o", text(&merged)]);
    let wrong = splat_io::accumulation::read(&merged).unwrap().accumulation;
    let other = splat_io::accumulation::read(&other).unwrap().accumulation;
    let right = splat_io::accumulation::read(&b).unwrap().accumulation;
    assert_eq!((wrong.first, wrong.count), (0, 8));
    let (ulps, _) = distance(right.mean.data(), other.mean.data());
    assert!(ulps > 1000, "another seed's frames 4..8 differ from this seed's ({ulps} ulps)");
    let cut = scratch("c-cut.acc");
    let bytes = std::fs::read(&b).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() - 10]).unwrap();
    refused(&["merge", text(&a), text(&cut), "-o", text(&out)], "the file holds");
    refused(&["render", "--frames", "4..4", "-o", text(&out)], "is not a range of frames");
    refused(&["render", "--frames", "0..4", "-o", text(&out)], "give -o PART.acc");
    refused(&["render", "--frames", "0..4", "--spp", "4", "-o", text(&cut)], "cannot be used with");
}

/// The N tasks of a job array (`--shard I/N`) write, together, the files of the whole set.
#[test]
fn shards_fill_the_folder_of_the_whole_set() {
    let (whole, shards) = (scratch("views-whole"), scratch("views-shards"));
    // Five views of the cloud: the fixture's view moved sideways.
    let json = std::fs::read_to_string(root().join("fixtures/cloud.cameras.json")).unwrap();
    let view = serde_json::from_str::<serde_json::Value>(&json).unwrap()[0].clone();
    let views: Vec<serde_json::Value> = (0..5)
        .map(|i| {
            let mut v = view.clone();
            v["img_name"] = format!("view{i}").into();
            v["position"][0] = (v["position"][0].as_f64().unwrap() + 0.1 * f64::from(i)).into();
            v
        })
        .collect();
    let cameras = scratch("five.cameras.json");
    std::fs::write(&cameras, serde_json::to_string(&views).unwrap()).unwrap();
    let base = [
        "render",
        "fixtures/cloud.ply",
        "--camera",
        text(&cameras),
        "--all-cameras",
        "--width",
        "32",
        "--height",
        "24",
    ];
    let mut args = base.to_vec();
    args.extend_from_slice(&["-o", text(&whole)]);
    ok(&args);
    for shard in ["0/3", "1/3", "2/3"] {
        let mut args = base.to_vec();
        args.extend_from_slice(&["--shard", shard, "-o", text(&shards)]);
        ok(&args);
    }
    let listing = |dir: &Path| {
        let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&p).unwrap()))
            .collect();
        files.sort();
        files
    };
    let (a, b) = (listing(&whole), listing(&shards));
    assert_eq!(a.len(), 5, "one image a view");
    assert!(a == b, "the shards' files differ from the whole set's");
    let mut args = base.to_vec();
    args.extend_from_slice(&["--shard", "3/3", "-o", text(&shards)]);
    refused(&args, "is not a share");
}

/// The GPU renders a share's own frames: its share of frames 5..12 is the CPU's (every
/// varying pixel-channel within 10⁻⁴ but where a decision's u lies within the kernels' rounding
/// of its threshold; frames 0..7 agree with it on few), and GPU shares merged equal the GPU's
/// run within the f32 rounding of its running means.
#[test]
fn gpu_shares_are_the_cpus_shares() {
    let render = |backend: &str, range: &str, name: &str| -> Option<splat_core::frame::Accumulation> {
        let path = scratch(name);
        let mut args: Vec<&str> = vec!["render"];
        args.extend_from_slice(&CLOUD);
        args.extend_from_slice(&["--method", "stochastic", "--pixel-filter", "box", "--seed", "7"]);
        args.extend_from_slice(&["--backend", backend, "--frames", range, "-o", text(&path)]);
        let o = splat(&args);
        let stderr = String::from_utf8_lossy(&o.stderr);
        if !o.status.success() && backend == "gpu" && stderr.contains("adapter") {
            splat_tests::skip("gpu_shares_are_the_cpus_shares", &stderr);
            return None;
        }
        assert!(o.status.success(), "{stderr}");
        Some(splat_io::accumulation::read(&path).unwrap().accumulation)
    };
    let Some(gpu) = render("gpu", "5..12", "g-share.acc") else { return };
    let cpu = render("cpu", "5..12", "c-share.acc").unwrap();
    // Agreement within 10⁻⁴ on the pixel-channels whose frames vary (elsewhere every run agrees).
    let varying: Vec<usize> = (0..cpu.variance.data().len()).filter(|&i| cpu.variance.data()[i] > 0.0).collect();
    let close = |a: &[f32], b: &[f32]| {
        varying.iter().filter(|&&i| (a[i] - b[i]).abs() <= 1e-4).count() as f64 / varying.len() as f64
    };
    let agree = close(gpu.mean.data(), cpu.mean.data());
    let early = render("cpu", "0..7", "c-early.acc").unwrap();
    let other = close(early.mean.data(), cpu.mean.data());
    assert!(varying.len() > 1000, "the view varies: {} pixel-channels", varying.len());
    assert!(
        agree >= 0.99 && other < 0.2,
        "the GPU's frames 5..12: {agree:.3} agree with the CPU's; frames 0..7: {other:.3}"
    );
    let head = render("gpu", "0..5", "g-head.acc").unwrap();
    let whole = render("gpu", "0..12", "g-whole.acc").unwrap();
    let merged = splat_core::frame::Accumulation::merge(&[gpu, head]).unwrap();
    let largest = merged.mean.data().iter().zip(whole.mean.data()).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
    eprintln!(
        "GPU share agrees with the CPU's on {:.2} %, frames 0..7 on {:.2} %; merged against the run {largest:e}",
        100.0 * agree,
        100.0 * other
    );
    assert!(largest <= 1e-5, "GPU shares merged against the GPU's run: {largest:e}");
}
