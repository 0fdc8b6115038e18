//! End-to-end tests of the `splat` binary.

/// `splat serve` and its page in headless Chromium.
mod serve;
/// Shares of a run and shards of a view set (`--frames`, `splat merge`, `--shard`), in this test
/// binary rather than one of its own (a binary to link costs CI).
mod shares;

use splat_core::sh::SH_C0;
use splat_tests::reference::{Gaussian, trace};
use splat_tests::root;
use std::path::PathBuf;
use std::process::{Command, Output};

fn splat(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_splat")).args(args).current_dir(root()).output().expect("run splat")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("splat-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `splat render fixtures/layers.ply --method exact -o out.npy` writes linear radiance that the
/// independent f64 implementation of Eq. 3 in `splat_tests::reference` reproduces.
#[test]
fn npy_output_matches_an_independent_eq3() {
    let out = scratch("layers.npy");
    let o = splat(&[
        "render",
        "fixtures/layers.ply",
        "--method",
        "exact",
        "--camera",
        "fixtures/layers.cameras.json",
        "--background",
        "0.1,0.2,0.3",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let image = splat_io::image::read_npy(&out).unwrap();

    let scene = splat_io::ply::read_ply(&root().join("fixtures/layers.ply")).unwrap();
    let gaussians: Vec<Gaussian> = scene
        .particles
        .iter()
        .map(|p| Gaussian {
            mean: p.mean.as_dvec3().to_array(),
            scale: p.scale.as_dvec3().to_array(),
            q: [p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z].map(f64::from),
            opacity: f64::from(p.opacity),
            rgb: p.sh[0].to_array().map(|c| (0.5 + f64::from(SH_C0) * f64::from(c)).max(0.0)),
        })
        .collect();
    // The camera straight from the JSON: centre, camera-to-world rotation rows, fx, fy.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root().join("fixtures/layers.cameras.json")).unwrap()).unwrap();
    let cam = &json[0];
    let num = |v: &serde_json::Value| v.as_f64().unwrap();
    let (w, h) = (num(&cam["width"]), num(&cam["height"]));
    let (fx, fy) = (num(&cam["fx"]), num(&cam["fy"]));
    let origin = [0, 1, 2].map(|k| num(&cam["position"][k]));
    let rot = [0, 1, 2].map(|i| [0, 1, 2].map(|j| num(&cam["rotation"][i][j])));
    assert_eq!((image.width() as f64, image.height() as f64, image.channels()), (w, h, 3));

    let mut worst = 0.0f64;
    for y in 0..image.height() {
        for x in 0..image.width() {
            let d_cam = [(x as f64 + 0.5 - w / 2.0) / fx, (y as f64 + 0.5 - h / 2.0) / fy, 1.0];
            let d = [0, 1, 2].map(|i| (0..3).map(|j| rot[i][j] * d_cam[j]).sum::<f64>());
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let expected = trace(&gaussians, origin, d.map(|c| c / len), [0.1, 0.2, 0.3]);
            for (k, e) in expected.iter().enumerate() {
                worst = worst.max((f64::from(image.pixel(x, y)[k]) - e).abs());
            }
        }
    }
    // f32 hit math against f64: agreement to 1e-5 shows the same hits, alphas and order.
    assert!(worst < 1e-5, "worst difference {worst}");
}

#[test]
fn render_without_arguments_writes_the_demo_scene() {
    let out = scratch("demo.png");
    let o = splat(&["render", "--width", "64", "--height", "48", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(&out).unwrap();
    assert_eq!((img.width(), img.height()), (64, 48));
    assert!(img.to_rgb8().pixels().any(|p| p.0.iter().any(|&c| c > 100)), "the demo image is blank");
}

#[test]
fn render_without_camera_frames_the_scene_and_writes_every_output() {
    let paths = ["c.exr", "c-alpha.npy", "c-depth.png", "c-normal.exr"].map(scratch);
    let s = paths.each_ref().map(|p| p.to_str().unwrap());
    let o = splat(&[
        "render",
        "fixtures/cloud.ply",
        "--width",
        "48",
        "--height",
        "32",
        "-o",
        s[0],
        "--alpha",
        s[1],
        "--depth",
        s[2],
        "--normal",
        s[3],
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    for p in &paths {
        assert!(std::fs::metadata(p).unwrap().len() > 0, "{} is empty", p.display());
    }
    let alpha = splat_io::image::read_npy(&paths[1]).unwrap();
    let covered = alpha.data().iter().filter(|&&a| a > 0.5).count();
    assert!(covered > 48 * 32 / 10, "framing missed the scene: {covered} covered pixels");
}

#[test]
fn bad_input_gives_a_clear_error_and_non_zero_exit() {
    let bytes = std::fs::read(root().join("fixtures/cloud.ply")).unwrap();
    let truncated = scratch("truncated.ply");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["render".into(), truncated.display().to_string(), "-o".into(), scratch("x.png").display().to_string()],
            "truncated",
        ),
        (vec!["info".into(), truncated.display().to_string()], "truncated.ply"),
        (vec!["info".into(), "no/such/file.ply".into()], "no/such/file.ply"),
        (vec!["render".into(), "fixtures/layers.ply".into(), "-o".into(), "out.jpg".into()], ".png, .exr or .npy"),
        (
            vec![
                "render".into(),
                "fixtures/layers.ply".into(),
                "--camera".into(),
                "fixtures/layers.cameras.json".into(),
                "--camera-index".into(),
                "5".into(),
            ],
            "has 1 cameras",
        ),
        (
            vec![
                "render".into(),
                "--iso-threshold".into(),
                "3".into(),
                "-o".into(),
                scratch("y.png").display().to_string(),
            ],
            "iso threshold",
        ),
    ];
    for (args, needle) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = splat(&args);
        assert!(!o.status.success(), "{args:?} succeeded");
        let err = stderr(&o);
        assert!(err.contains(needle), "{args:?}: stderr does not mention '{needle}':\n{err}");
        assert!(!err.contains("panicked"), "{args:?} panicked:\n{err}");
    }
}

#[test]
fn info_reports_count_degree_and_histogram() {
    let o = splat(&["info", "fixtures/cloud.ply"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("particles  3000"), "{text}");
    assert!(text.contains("SH degree  3"), "{text}");
    assert!(text.contains("opacity histogram"), "{text}");
}

#[test]
fn every_method_renders_with_variance_and_the_same_seed_repeats() {
    // Every method of the catalogue, by the name `--method` takes.
    for id in splat_core::MethodId::ALL {
        let method = id.name();
        let out = scratch(&format!("m-{method}.npy"));
        let var = scratch(&format!("m-{method}-var.npy"));
        let args = |o: &PathBuf| {
            vec![
                "render".to_string(),
                "fixtures/cloud.ply".into(),
                "--camera".into(),
                "fixtures/cloud.cameras.json".into(),
                "--width".into(),
                "32".into(),
                "--height".into(),
                "24".into(),
                "--method".into(),
                method.into(),
                "--spp".into(),
                "8".into(),
                "--seed".into(),
                "3".into(),
                "--samples-per-traversal".into(),
                "4".into(),
                "--raster-samples".into(),
                "4".into(),
                "-o".into(),
                o.display().to_string(),
                "--variance".into(),
                var.display().to_string(),
            ]
        };
        let a: Vec<String> = args(&out);
        let o = splat(&a.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(o.status.success(), "{method}: {}", stderr(&o));
        let again = scratch(&format!("m-{method}-again.npy"));
        let b: Vec<String> = args(&again);
        assert!(splat(&b.iter().map(String::as_str).collect::<Vec<_>>()).status.success());
        assert_eq!(
            std::fs::read(&out).unwrap(),
            std::fs::read(&again).unwrap(),
            "{method}: same seed, different image"
        );
        let variance = splat_io::image::read_npy(&var).unwrap();
        assert_eq!(variance.data().iter().any(|&v| v > 0.0), id.entry().stochastic, "{method}: variance image");
    }
}

#[test]
fn converge_writes_csv_plot_and_table() {
    let prefix = scratch("conv");
    let o = splat(&[
        "converge",
        "fixtures/layers.ply",
        "--camera",
        "fixtures/layers.cameras.json",
        "--width",
        "24",
        "--height",
        "18",
        "--max-spp",
        "16",
        "--methods",
        "stochastic,depth-sampling-k,stochastic-splat",
        "-o",
        prefix.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(prefix.with_extension("csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 3 * 5, "{csv}");
    assert!(stderr(&o).contains("raster-sorted against ray-traced exact: RMSE"), "{}", stderr(&o));
    assert!(image::open(prefix.with_extension("png")).is_ok());
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(table.contains("| slope |"), "{table}");
    let bad = splat(&["converge", "--max-spp", "100"]);
    assert!(!bad.status.success() && stderr(&bad).contains("power of two"));
}

/// `converge --pipeline path` measures the path tracer's Gaussian estimators against an
/// exact-compositing reference and reports each one's time to a target RMSE.
#[test]
fn converge_the_path_tracer() {
    let prefix = scratch("conv-path");
    let o = splat(&[
        "converge",
        "fixtures/worlds/demo-meshes.toml",
        "--pipeline",
        "path",
        "--width",
        "16",
        "--height",
        "12",
        "--max-spp",
        "4",
        "--reference-spp",
        "16",
        "-o",
        prefix.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // The path tracer's default methods: stochastic, stochastic-n and exact, at spp 1, 2, 4.
    let csv = std::fs::read_to_string(prefix.with_extension("csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 3 * 3, "{csv}");
    assert!(csv.contains("stochastic-n,") && csv.contains("exact,"), "{csv}");
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(table.contains("| slope |") && table.contains("time to RMSE 0.01"), "{table}");
    let bad = splat(&["converge", "fixtures/worlds/demo-meshes.toml", "--pipeline", "path", "--methods", "opaque"]);
    assert!(!bad.status.success() && stderr(&bad).contains("not a Gaussian estimator"), "{}", stderr(&bad));
}

/// Sorted splatting over and under write the same image; bad raster options are named; the
/// stratification report prints its table.
#[test]
fn raster_over_equals_under_and_bad_options_are_named() {
    let render = |blend: &str| {
        let out = scratch(&format!("blend-{blend}.npy"));
        let o = splat(&[
            "render",
            "fixtures/layers.ply",
            "--camera",
            "fixtures/layers.cameras.json",
            "--method",
            "raster-sorted",
            "--blend",
            blend,
            "--raster-samples",
            "4",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        splat_io::image::read_npy(&out).unwrap()
    };
    let (over, under) = (render("over"), render("under"));
    let worst = over.data().iter().zip(under.data()).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-6, "over and under differ by {worst}");
    let bad = splat(&["render", "--method", "stratified", "--raster-samples", "3", "-o", "x.png"]);
    assert!(!bad.status.success() && stderr(&bad).contains("3 samples per pixel"), "{}", stderr(&bad));
    let trig = splat(&["render", "--method", "stochastic-splat", "--rng", "trig", "-o", "x.png"]);
    assert!(!trig.status.success() && stderr(&trig).contains("hash generator"), "{}", stderr(&trig));
    let prefix = scratch("strat");
    // The rows of the sample counts asked for (the ends of the default 4…64), each variant's.
    let args = ["stratify", "--scenes", "cloth", "--detail", "1", "--variants", "paper,unsorted", "--samples", "4,64"];
    let o = splat(&[&args[..], &["--frames", "2", "-o", prefix.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let table = String::from_utf8_lossy(&o.stdout);
    assert_eq!(table.lines().filter(|l| l.starts_with("| cloth |")).count(), 4, "{table}");
    assert!(table.contains("| cloth | 64 | cpu | hammersley | unsorted |"), "{table}");
    assert!(image::open(prefix.with_extension("png")).is_ok());
    stratify_on_the_gpu_equals_the_cpu(&prefix);
    let unknown = splat(&["stratify", "--scenes", "teapot"]);
    assert!(!unknown.status.success() && stderr(&unknown).contains("unknown scene 'teapot'"));
    let unknown = splat(&["stratify", "--variants", "halton"]);
    assert!(!unknown.status.success() && stderr(&unknown).contains("unknown variant 'halton'"), "{}", stderr(&unknown));
}

/// `splat stratify --backend gpu`: the GPU's rows at S = 4, 8, 16 beside the CPU's, the same
/// RMSE when the CPU takes the standard pattern too (the same decisions), on splats (the plates)
/// and on transparent triangles (Figure 3b's stack).
fn stratify_on_the_gpu_equals_the_cpu(prefix: &std::path::Path) {
    let args =
        ["stratify", "--scenes", "plates,stack", "--frames", "2", "--sample-pattern", "standard", "--backend", "gpu"];
    let o = splat(&[&args[..], &["-o", prefix.to_str().unwrap()]].concat());
    if !o.status.success() {
        gpu_missing(&stderr(&o));
        return;
    }
    let table = String::from_utf8_lossy(&o.stdout);
    for (scene, s) in ["plates", "stack"].into_iter().flat_map(|scene| [4, 8, 16].map(|s| (scene, s))) {
        let cells = |backend: &str| {
            let row = table.lines().find(|l| l.starts_with(&format!("| {scene} | {s} | {backend} | standard |")));
            row.unwrap_or_else(|| panic!("no {scene} {backend} row at S = {s}:\n{table}"))
                .split('|')
                .skip(5)
                .collect::<String>()
        };
        assert_eq!(cells("cpu"), cells("gpu"), "{scene} S = {s}:\n{table}");
    }
    assert!(table.contains("| plates | 64 | cpu | hammersley |"), "{table}");
}

/// `splat bench` times every method against opaque and counts its BVH work per ray
/// (traversals, wide nodes, leaves, primitive tests, bytes read): the counts are the same on one
/// thread as on three, a Gaussian method does more work than an opaque ray, and `exact`, which
/// visits every hit, tests more particles than Algorithm 1, which shrinks t_max to its first
/// accepted hit.
#[test]
fn bench_reports_every_method_against_opaque() {
    let bench = |threads: &str| {
        let args =
            ["bench", "fixtures/cloud.ply", "--width", "32", "--height", "24", "--repeat", "1", "--threads", threads];
        let o = splat(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let (one, three) = (bench("1"), bench("3"));
    // The work columns (the last five) of method m's row.
    let work = |text: &str, m: &str| -> Vec<f64> {
        let row =
            text.lines().find(|l| l.starts_with(&format!("| {m} |"))).unwrap_or_else(|| panic!("{m} missing:\n{text}"));
        let cells: Vec<&str> = row.split('|').map(str::trim).filter(|c| !c.is_empty()).collect();
        cells[cells.len() - 5..].iter().map(|c| c.parse().unwrap()).collect()
    };
    for m in ["opaque", "stochastic", "stochastic-n", "stochastic-pass", "kbuffer", "exact"] {
        let counts = work(&one, m);
        assert_eq!(counts, work(&three, m), "{m}: the work depends on the threads");
        assert!(counts[0] >= 1.0 && counts[1] >= 1.0 && counts[3] >= counts[2], "{m}: {counts:?}");
    }
    let (opaque, stochastic, exact) = (work(&one, "opaque"), work(&one, "stochastic"), work(&one, "exact"));
    assert!(stochastic[3] > opaque[3] && exact[3] > stochastic[3], "tests a ray: {opaque:?} {stochastic:?} {exact:?}");
}

/// `splat bench --backend gpu` times the ray-tracing methods and reports the kernel's own work
/// counter, its loop iterations a pixel (traversal steps and particle visits): positive for every
/// method, the same in two runs, and more for `exact`, which visits every hit, than for
/// Algorithm 1.
#[test]
fn bench_reports_the_gpu_tracers_loop_steps() {
    let args = ["bench", "fixtures/cloud.ply", "--width", "24", "--height", "16", "--repeat", "2", "--backend", "gpu"];
    let o = splat(&[&args[..], &["--methods", "stochastic,exact"]].concat());
    if !o.status.success() {
        gpu_missing(&stderr(&o));
        return;
    }
    let text = String::from_utf8_lossy(&o.stdout);
    let steps = |m: &str| -> f64 {
        let row =
            text.lines().find(|l| l.starts_with(&format!("| {m} |"))).unwrap_or_else(|| panic!("{m} missing:\n{text}"));
        row.split('|').map(str::trim).rfind(|c| !c.is_empty()).unwrap().parse().unwrap()
    };
    let (stochastic, exact) = (steps("stochastic"), steps("exact"));
    assert!(stochastic > 1.0 && exact > stochastic, "loop steps a pixel: {stochastic} {exact}\n{text}");
}

/// `splat bench --sweep mn` prints the eight m × n rows of Sun et al. Tables 4–5 with their
/// speed-ups and RMSE against exact (1024 × 1 is the baseline, 1.00× by definition), every row
/// the same image, on the CPU and on the GPU (which runs 4 × 256 as 16 × 64 and says so).
#[test]
fn bench_sweeps_the_m_n_rows_of_tables_4_and_5() {
    let args = ["bench", "fixtures/layers.ply", "--width", "8", "--height", "6", "--repeat", "1", "--sweep", "mn"];
    for backend in ["cpu", "gpu"] {
        let o = splat(&[&args[..], &["--backend", backend]].concat());
        if backend == "gpu" && !o.status.success() {
            gpu_missing(&stderr(&o));
            return;
        }
        assert!(o.status.success(), "{backend}: {}", stderr(&o));
        let text = String::from_utf8_lossy(&o.stdout);
        for (m, n) in [(1024, 1), (512, 2), (256, 4), (128, 8), (64, 16), (32, 32), (16, 64), (4, 256)] {
            let row = format!("| {m} × {n} ");
            assert!(text.contains(&row), "{backend}: {row} missing:\n{text}");
        }
        assert!(!text.contains("refused"), "{backend}: a row is refused:\n{text}");
        if backend == "gpu" {
            assert!(text.contains("| 4 × 256 (as 16 × 64) |"), "{text}");
        }
        let rows =
            text.lines().filter(|l| l.strip_prefix("| ").is_some_and(|r| r.starts_with(|c: char| c.is_ascii_digit())));
        for line in rows.filter(|l| !l.contains("refused")) {
            let diff: f64 = line.split('|').nth(6).unwrap().trim().parse().unwrap();
            assert!(diff < 1e-5, "{backend}: the rows differ: {line}");
        }
        let first = text.lines().find(|l| l.starts_with("| 1024 × 1 |")).unwrap();
        assert!(first.contains("| 1.00× |"), "{backend}: {first}");
        // 1024 samples of an unbiased estimator: close to exact on this small image.
        let rmse: f64 = first.split('|').nth(5).unwrap().trim().parse().unwrap();
        assert!(rmse > 0.0 && rmse < 0.05, "{backend}: RMSE {rmse}");
    }
}

/// `splat bench --methods raster-sorted,stochastic-splat` times the splatting path: on the CPU
/// both methods as a ratio, on the GPU every stage with the sort's share and keys/s, the device
/// bytes a splat, and each frame's dispatches (two: the draw and the fold) and host waits.
#[test]
fn bench_reports_the_splatting_path() {
    let args = ["bench", "fixtures/cloud.ply", "--width", "32", "--height", "24", "--repeat", "1"];
    let raster = ["--methods", "raster-sorted,stochastic-splat"];
    let o = splat(&[&args[..], &raster[..], &["--backend", "cpu"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("| raster-sorted | ") && text.contains("| stochastic-splat | "), "{text}");
    let o = splat(&[&args[..], &raster[..], &["--backend", "gpu"]].concat());
    if !o.status.success() {
        gpu_missing(&stderr(&o));
        return;
    }
    let text = String::from_utf8_lossy(&o.stdout);
    for row in ["| projection |", "| depth sort (", "Mkeys/s", "| **sorted frame** |", "× the sorted frame"] {
        assert!(text.contains(row), "{row} missing:\n{text}");
    }
    assert!(text.contains("bytes a splat on the device"), "{text}");
    // The depth sort of a scene of one scan tile: sort_setup, then four 8-bit passes of three
    // dispatches each (the histogram, the scan's one tile, the scatter).
    assert!(text.contains("4 passes of 8 bits, 13 dispatches"), "the depth sort's counters:\n{text}");
    // The work counters: a sorted frame and a StochasticSplats frame are each a draw and the fold
    // of its target into the running mean.
    for method in ["raster-sorted", "stochastic-splat"] {
        let row = text.lines().find(|l| l.starts_with(&format!("| {method} | centre |")));
        let cells: Vec<&str> = row.unwrap_or_else(|| panic!("no {method} row:\n{text}")).split('|').collect();
        assert_eq!(cells[5].trim(), "2.00", "{method}: dispatches a frame:\n{text}");
    }
}

/// `--backend gpu` renders the raster methods as the CPU does (same decisions for the
/// stochastic methods, same blending for `raster-sorted`, with its iso-depth image), at one
/// sample and at four, where the GPU takes the standard pattern by default and the CPU is asked
/// for it; what the GPU cannot do is refused with a message and exit code 1.
#[test]
fn gpu_raster_backend_matches_cpu_backend() {
    let render = |backend: &str, method: &str, out: &PathBuf, extra: &[&str]| {
        let mut args = vec!["render", "fixtures/cloud.ply", "--camera", "fixtures/cloud.cameras.json"];
        args.extend(["--width", "40", "--height", "30", "--spp", "8", "--seed", "5", "--method", method]);
        args.extend(["--backend", backend, "-o", out.to_str().unwrap()]);
        args.extend(extra);
        splat(&args)
    };
    let four = ["--raster-samples", "4"];
    let cases: [(&str, &[&str]); 6] = [
        ("raster-sorted", &[]),
        ("stochastic-splat", &[]),
        ("raster-sorted", &four),
        ("stochastic-splat", &four),
        ("enderton", &four),
        ("stratified", &four),
    ];
    for (method, samples) in cases {
        let tag = format!("{method}-{}", samples.len());
        let (cpu_out, gpu_out) = (scratch(&format!("{tag}-cpu.npy")), scratch(&format!("{tag}-gpu.npy")));
        let depth = |name: &str| scratch(&format!("{tag}-{name}-depth.npy"));
        let extra = |name: &str| {
            let mut e: Vec<String> = samples.iter().map(|s| s.to_string()).collect();
            if name == "cpu" && !samples.is_empty() {
                e.extend(["--sample-pattern".into(), "standard".into()]);
            }
            if method == "raster-sorted" {
                e.extend(["--depth".to_string(), depth(name).to_str().unwrap().to_string()]);
            }
            e
        };
        let (cpu_extra, gpu_extra) = (extra("cpu"), extra("gpu"));
        let cpu_args: Vec<&str> = cpu_extra.iter().map(String::as_str).collect();
        let gpu_args: Vec<&str> = gpu_extra.iter().map(String::as_str).collect();
        assert!(render("cpu", method, &cpu_out, &cpu_args).status.success());
        let o = render("gpu", method, &gpu_out, &gpu_args);
        if !o.status.success() {
            gpu_missing(&stderr(&o));
            return;
        }
        let read = |p: &PathBuf| splat_io::image::read_npy(p).unwrap();
        let worst = |a: &splat_core::Image, b: &splat_core::Image| {
            a.data()
                .iter()
                .zip(b.data())
                .filter(|(x, y)| !(x.is_nan() && y.is_nan()))
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max)
        };
        let d = worst(&read(&cpu_out), &read(&gpu_out));
        assert!(d < 1e-4, "{method} {samples:?}: GPU and CPU backends differ by {d}");
        if method == "raster-sorted" {
            let d = worst(&read(&depth("cpu")), &read(&depth("gpu")));
            assert!(d < 1e-3, "iso-depth differs by {d}");
        }
    }
    for (method, extra, message) in [
        (
            "stochastic-splat",
            vec!["--raster-samples", "4", "--sample-pattern", "hammersley"],
            "--sample-pattern standard",
        ),
        ("raster-sorted", vec!["--fragment-depth", "plane"], "max-density plane"),
        ("stochastic-splat", vec!["--depth", "/tmp/never.npy"], "come from raster-sorted only"),
    ] {
        let o = render("gpu", method, &scratch("refused.npy"), &extra);
        let err = stderr(&o);
        if err.contains("mesa-vulkan-drivers") && std::env::var("CI").is_err() {
            return;
        }
        assert_eq!(o.status.code(), Some(1), "{method} {extra:?}: {err}");
        assert!(err.contains(message), "{method} {extra:?}: {err}");
    }
}

/// `--backend gpu` renders the same image as `--backend cpu` for the same seed (the kernels
/// make the same decisions); without an adapter it fails with a message naming the driver to
/// install, unless CI requires one.
#[test]
fn gpu_backend_matches_cpu_backend() {
    let render = |backend: &str, out: &PathBuf| {
        splat(&[
            "render",
            "fixtures/cloud.ply",
            "--camera",
            "fixtures/cloud.cameras.json",
            "--width",
            "32",
            "--height",
            "24",
            "--method",
            "stochastic",
            "--spp",
            "4",
            "--seed",
            "9",
            "--backend",
            backend,
            "-o",
            out.to_str().unwrap(),
        ])
    };
    let (cpu_out, gpu_out) = (scratch("backend-cpu.npy"), scratch("backend-gpu.npy"));
    assert!(render("cpu", &cpu_out).status.success());
    let o = render("gpu", &gpu_out);
    if !o.status.success() {
        gpu_missing(&stderr(&o));
        return;
    }
    let (a, b) = (splat_io::image::read_npy(&cpu_out).unwrap(), splat_io::image::read_npy(&gpu_out).unwrap());
    let worst = a.data().iter().zip(b.data()).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "GPU and CPU backends differ by {worst}");
}

/// A `--backend gpu` run failed: only the missing-adapter error (which names the driver to
/// install) may skip the test, loudly and never under `CI=true`; any other failure fails it.
fn gpu_missing(err: &str) {
    assert!(err.contains("mesa-vulkan-drivers"), "the GPU backend failed with adapters present: {err}");
    splat_tests::skip(&splat_tests::current_test(), &format!("no GPU adapter ({})", err.trim()));
}

/// `splat render WORLD.toml` lights: the lit demo world renders on the CPU (the world's camera
/// and background, overridable from the command line), `--shadows none` changes the image,
/// the GPU backend renders the same image, and a malformed world is refused with the field named.
#[test]
fn render_lights_a_world_file_on_both_backends() {
    let run = |backend: &str, out: &PathBuf, extra: &[&str]| {
        let mut args = vec![
            "render",
            "fixtures/worlds/demo-lit.toml",
            "--method",
            "stochastic",
            "--spp",
            "2",
            "--width",
            "40",
            "--height",
            "30",
            "--backend",
            backend,
            "-o",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        splat(&args)
    };
    let read = |p: &PathBuf| splat_io::image::read_npy(p).unwrap();
    let (cpu, unshadowed, gpu) = (scratch("lit-cpu.npy"), scratch("lit-none.npy"), scratch("lit-gpu.npy"));
    let o = run("cpu", &cpu, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run("cpu", &unshadowed, &["--shadows", "none"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let diff = |a: &PathBuf, b: &PathBuf| {
        read(a).data().iter().zip(read(b).data()).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max)
    };
    assert!(diff(&cpu, &unshadowed) > 0.05, "the shadows change nothing");
    let bad = scratch("bad-world.toml");
    std::fs::write(
        &bad,
        "[[splats]]\nbuiltin = \"demo\"\n[[lights]]\nkind = \"point\"\nposition = [0, 1, 0]\nintensity = -2\n",
    )
    .unwrap();
    let o = splat(&["render", bad.to_str().unwrap(), "-o", scratch("never.png").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("lights[0]") && stderr(&o).contains("intensity"), "{}", stderr(&o));
    let o = run("gpu", &gpu, &[]);
    if !o.status.success() {
        gpu_missing(&stderr(&o));
        return;
    }
    assert!(diff(&cpu, &gpu) < 1e-4, "GPU and CPU lit images differ by {}", diff(&cpu, &gpu));
}

/// `splat render demo-meshes.toml --pipeline rt|raster|hybrid` renders each pipeline (with the
/// pipeline's default method), the three images differ, a method of the other family is refused
/// with the reason, the GPU renders each pipeline as the CPU does (at one and four samples per
/// pixel), and a mesh file that does not exist is named.
#[test]
fn render_meshes_with_each_pipeline() {
    let run = |extra: &[&str], out: &PathBuf| {
        let mut args = vec!["render", "fixtures/worlds/demo-meshes.toml", "--width", "40", "--height", "30"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--backend", "cpu", "-o", out.to_str().unwrap()]);
        splat(&args)
    };
    let mut images = Vec::new();
    for pipeline in ["rt", "raster", "hybrid"] {
        let out = scratch(&format!("meshes-{pipeline}.npy"));
        let o = run(&["--pipeline", pipeline], &out);
        assert!(o.status.success(), "{pipeline}: {}", stderr(&o));
        images.push(splat_io::image::read_npy(&out).unwrap());
    }
    let rmse = |a: &splat_core::Image, b: &splat_core::Image| splat_core::stats::rmse(a.data(), b.data());
    assert!(rmse(&images[0], &images[1]) > 0.01 && rmse(&images[1], &images[2]) > 0.01);
    let o = run(&["--pipeline", "raster", "--method", "exact"], &scratch("never.png"));
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("not a raster method"), "{}", stderr(&o));
    let world = "fixtures/worlds/demo-meshes.toml";
    // `--backend gpu` takes each pipeline to its GPU renderer, which renders the CPU's image:
    // ray tracing (mirror and glass bounces included), StochasticSplats among the meshes, the
    // hybrid at four samples a pixel, the path tracer (mean difference: a stochastic decision
    // within f32 rounding of its threshold may flip a pixel). Every method of each pipeline is
    // held to the CPU's frame by splat-gpu's own tests (gpu_frames, gpu_raster, gpu_msaa,
    // gpu_path), in one process each rather than one per render here.
    let pipelines = [
        ("rt", "stochastic", "1"),
        ("raster", "stochastic-splat", "1"),
        ("hybrid", "raster-sorted", "4"),
        ("path", "stochastic", "1"),
    ];
    for (pipeline, method, samples) in pipelines {
        let image = |backend: &str| {
            let out = scratch(&format!("meshes-{pipeline}-{method}-{samples}-{backend}.npy"));
            let mut args = vec!["render", world, "--width", "40", "--height", "30", "--spp", "2"];
            args.extend_from_slice(&["--pipeline", pipeline, "--method", method, "--secondary", "stochastic"]);
            args.extend_from_slice(&["--raster-samples", samples, "--sample-pattern", "standard"]);
            args.extend_from_slice(&["--backend", backend, "-o", out.to_str().unwrap()]);
            let o = splat(&args);
            o.status.success().then(|| splat_io::image::read_npy(&out).unwrap()).ok_or_else(|| stderr(&o))
        };
        let cpu = image("cpu").unwrap();
        let gpu = match image("gpu") {
            Ok(gpu) => gpu,
            Err(e) => return gpu_missing(&e),
        };
        let mean: f32 =
            cpu.data().iter().zip(gpu.data()).map(|(a, b)| (a - b).abs()).sum::<f32>() / cpu.data().len() as f32;
        assert!(mean < 1e-4, "{pipeline} {method} at {samples} samples: mean difference {mean}");
    }
    let bad = scratch("missing-mesh.toml");
    std::fs::write(&bad, "[[splats]]\nbuiltin = \"demo\"\n[[meshes]]\nfile = \"nowhere.obj\"\n").unwrap();
    let o = splat(&["render", bad.to_str().unwrap(), "-o", scratch("never.png").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("nowhere.obj"), "{}", stderr(&o));
}

/// A world with a transparent mesh (`opacity` below 1) renders on the CPU by ray tracing, by
/// splatting and by path tracing, differently from the same world with the mesh opaque; on the
/// GPU Enderton's raster operations draw it as the CPU does (the same seed, the standard sample
/// pattern); the GPU hybrid and GPU sorted splatting refuse it with the reason and the flags
/// that would draw it, before any work.
#[test]
fn transparent_meshes_render_on_the_cpu_and_are_refused_elsewhere() {
    let world = |opacity: &str| {
        let path = scratch(&format!("transparent-{opacity}.toml"));
        let toml = format!(
            "[[splats]]\nbuiltin = \"demo\"\n[[meshes]]\nshape = \"plane\"\nrotate = [90.0, 0.0, 0.0]\nscale = 3.0\ncolor = [0.9, 0.2, 0.1]\nopacity = {opacity}\n"
        );
        std::fs::write(&path, toml).unwrap();
        path
    };
    let render = |world: &PathBuf, extra: &[&str]| {
        let out = scratch("transparent.npy");
        let args = [
            &["render", world.to_str().unwrap(), "--width", "24", "--height", "16"],
            extra,
            &["-o", out.to_str().unwrap()],
        ]
        .concat();
        let o = splat(&args);
        (o.status.success().then(|| splat_io::image::read_npy(&out).unwrap()), stderr(&o))
    };
    let (half, opaque) = (world("0.5"), world("1.0"));
    for pipeline in [
        &["--pipeline", "rt", "--method", "exact"][..],
        &["--pipeline", "raster", "--method", "raster-sorted"],
        &["--pipeline", "path", "--spp", "4"],
    ] {
        let ((a, e), (b, f)) = (render(&half, pipeline), render(&opaque, pipeline));
        let (a, b) =
            (a.unwrap_or_else(|| panic!("{pipeline:?}: {e}")), b.unwrap_or_else(|| panic!("{pipeline:?}: {f}")));
        let differ = a.data().iter().zip(b.data()).filter(|(x, y)| (*x - *y).abs() > 1e-3).count();
        assert!(differ > 0, "{pipeline:?}: the transparent plane renders as the opaque one ({e})");
    }
    let (refused, e) = render(&half, &["--backend", "gpu", "--pipeline", "hybrid"]);
    assert!(refused.is_none() && e.contains("the GPU hybrid draws no transparent mesh"), "{e}");
    let (refused, e) = render(&half, &["--backend", "gpu", "--pipeline", "raster", "--method", "raster-sorted"]);
    assert!(refused.is_none() && e.contains("(--method enderton or --backend cpu)"), "{e}");
    // (The GPU ray tracer's frames among transparent meshes: splat-gpu's gpu_frames.rs.)
    let enderton = ["--pipeline", "raster", "--method", "enderton", "--raster-samples", "4"];
    let enderton = [&enderton[..], &["--sample-pattern", "standard", "--spp", "4", "--seed", "3"]].concat();
    let (cpu, e) = render(&half, &[&enderton[..], &["--backend", "cpu"]].concat());
    let cpu = cpu.unwrap_or_else(|| panic!("{e}"));
    let (gpu, e) = render(&half, &[&enderton[..], &["--backend", "gpu"]].concat());
    let Some(gpu) = gpu else { return gpu_missing(&e) };
    let worst = cpu.data().iter().zip(gpu.data()).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "Enderton among a transparent plane: the GPU differs from the CPU by {worst}");
}

/// `--pipeline path` path traces a world with meshes (Gaussian estimators by `--method`, both
/// samplers, a thin lens), the same seed gives the same image, and what it cannot do is refused
/// with the reason.
#[test]
fn path_trace_a_world_with_meshes() {
    let run = |extra: &[&str], out: &PathBuf| {
        let mut args = vec!["render", "fixtures/worlds/demo-meshes.toml", "--width", "32", "--height", "24"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--pipeline", "path", "--spp", "4", "-o", out.to_str().unwrap()]);
        splat(&args)
    };
    let mut images = Vec::new();
    for (name, extra) in [
        ("stochastic", &["--backend", "cpu"][..]),
        ("stochastic-again", &["--backend", "cpu"][..]),
        ("exact", &["--method", "exact", "--sampler", "hash"][..]),
        (
            "lens",
            &[
                "--method",
                "stochastic-n",
                "--samples-per-traversal",
                "4",
                "--aperture",
                "0.05",
                "--focus-distance",
                "4",
            ][..],
        ),
    ] {
        let out = scratch(&format!("path-{name}.npy"));
        let o = run(extra, &out);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        assert!(stderr(&o).contains("path traced"), "{}", stderr(&o));
        images.push(splat_io::image::read_npy(&out).unwrap());
    }
    assert_eq!(images[0].data(), images[1].data(), "the same seed gave two images");
    assert!(images.iter().all(|i| i.data().iter().all(|v| v.is_finite())));
    assert_ne!(images[0].data(), images[3].data());
    let never = scratch("never.png");
    let o = run(&["--method", "raster-sorted"], &never);
    assert!(stderr(&o).contains("not a Gaussian estimator of the path tracer"), "{}", stderr(&o));
    let o = run(&["--backend", "gpu", "--method", "depth-sampling-k"], &never);
    let e = stderr(&o);
    assert!(e.contains("CPU only") || e.contains("mesa-vulkan-drivers"), "{e}");
    let o = run(&["--max-depth", "1000"], &never);
    assert!(stderr(&o).contains("max depth 1000 is above"), "{}", stderr(&o));
    let o = run(&["--aperture=-1"], &never);
    assert!(stderr(&o).contains("aperture"), "{}", stderr(&o));
    assert!(!never.exists());
}

fn npy(path: &std::path::Path) -> Vec<f32> {
    splat_io::image::read_npy(path).unwrap().data().to_vec()
}

/// (height, width) of a colour `.npy`.
fn npy_size(path: &std::path::Path) -> (u32, u32) {
    let image = splat_io::image::read_npy(path).unwrap();
    (image.height(), image.width())
}

fn rmse(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len());
    (a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

/// `splat convert` between every writable format and back; the renders of the converted
/// scenes stay within what each format's quantisation costs (tests/tests/formats.rs derives
/// the bounds; here a ceiling well above the measured errors, and far below a wrong file's).
#[test]
fn convert_round_trips_every_format() {
    let render = |scene: &str, out: &std::path::Path| {
        let o = splat(&[
            "render",
            scene,
            "--camera",
            "fixtures/cloud.cameras.json",
            "--width",
            "64",
            "--height",
            "48",
            "--backend",
            "cpu",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        npy(out)
    };
    let reference = render("fixtures/cloud.ply", &scratch("cloud.npy"));
    let targets = [
        ("cloud.spz", 0.02),
        ("cloud-v2.spz", 0.03),
        ("cloud-v4.spz", 0.02),
        ("cloud.sog", 0.02),
        ("cloud.ply", 1e-5),
        ("cloud.usda", 1e-7),
    ];
    for (target, ceiling) in targets {
        let path = scratch(target);
        let mut args = vec!["convert", "fixtures/cloud.ply", path.to_str().unwrap()];
        match target {
            "cloud-v2.spz" => args.extend(["--spz-version", "2"]),
            "cloud-v4.spz" => args.extend(["--spz-version", "4"]),
            _ => {}
        }
        let o = splat(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(stderr(&o).contains("converted 3000 splats (SH degree 3)"), "{}", stderr(&o));
        let error = rmse(&reference, &render(path.to_str().unwrap(), &scratch(&format!("{target}.npy"))));
        eprintln!("{target}: image RMSE {error:.2e} against the .ply");
        assert!(error < ceiling, "{target}: image RMSE {error} ≥ {ceiling}");
        let back = scratch(&format!("{target}.back.ply"));
        assert!(splat(&["convert", path.to_str().unwrap(), back.to_str().unwrap()]).status.success());
        assert!(splat_io::read_scene(&back).unwrap().particles.len() == 3000);
    }
    // .splat keeps the degree-0 colour and says so.
    let flat = scratch("cloud.splat");
    let o = splat(&["convert", "fixtures/cloud.ply", flat.to_str().unwrap()]);
    assert!(o.status.success() && stderr(&o).contains("SH bands 1–3 are dropped"), "{}", stderr(&o));
    // Refusals: a compressed .ply or .ksplat output (read only), an unknown extension.
    for out in ["x.compressed.ply", "x.ksplat", "x.obj"] {
        let o = splat(&["convert", "fixtures/cloud.ply", scratch(out).to_str().unwrap()]);
        assert!(
            !o.status.success() && stderr(&o).contains(".ply, .splat, .spz, .glb, .gltf, .sog, meta.json or .usda"),
            "{}",
            stderr(&o)
        );
    }
    // `splat info` names the format, its version and its container.
    let o = splat(&["info", scratch("cloud.sog").to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("format     PlayCanvas SOG (version 2, bundled .sog)"), "{text}");
    let o = splat(&["info", scratch("cloud.usda").to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("format     OpenUSD ParticleField3DGaussianSplat (usda layer, 1 prim: /World/gaussians)"),
        "{text}"
    );
    // Axes: a file written as RUB and read as stored renders a different (turned) scene.
    let rub = scratch("rub.spz");
    assert!(splat(&["convert", "fixtures/cloud.ply", rub.to_str().unwrap(), "--spz-axes", "rub"]).status.success());
    let turned = render(rub.to_str().unwrap(), &scratch("rub.npy"));
    assert!(rmse(&reference, &turned) > 0.05, "RUB data read unconverted must differ");
}

/// `fixtures/layers.ply` with one more vertex property `name`, of value `value` in every vertex.
fn layers_with_property(name: &str, value: f32, file: &str) -> std::path::PathBuf {
    let scene = splat_io::ply::read_ply(&root().join("fixtures/layers.ply")).unwrap();
    let text = String::from_utf8(splat_io::ply::encode_ply(&scene, splat_io::ply::PlyFormat::Ascii)).unwrap();
    let (header, body) = text.split_once("end_header\n").unwrap();
    let body: String = body.lines().map(|l| format!("{l} {value}\n")).collect();
    let path = scratch(file);
    std::fs::write(&path, format!("{header}property float {name}\nend_header\n{body}")).unwrap();
    path
}

/// Unknown `.ply` properties are skipped with one warning naming them; `--strict` refuses.
#[test]
fn unknown_ply_properties_warn_or_refuse_with_strict() {
    let path = layers_with_property("semantic_id", 0.5, "semantic.ply");
    let o = splat(&["info", path.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let warnings: Vec<_> = stderr(&o).lines().filter(|l| l.contains("warning")).map(String::from).collect();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(warnings[0].contains("semantic_id") && warnings[0].contains("--strict"), "{warnings:?}");
    let o = splat(&["info", path.to_str().unwrap(), "--strict"]);
    assert!(!o.status.success() && stderr(&o).contains("unknown vertex property 'semantic_id'"), "{}", stderr(&o));
}

/// A Mip-Splatting capture (`filter_3D`) is read with its 3D filter, without a warning, even
/// with `--strict`; `splat info` says so, and the filter changes the render (a filter of 0.02
/// against the layers' scales of about 0.1–0.3).
#[test]
fn mip_splatting_captures_render_with_their_3d_filter() {
    let path = layers_with_property("filter_3D", 0.02, "mip.ply");
    for strict in [false, true] {
        let args = [&["info", path.to_str().unwrap()][..], if strict { &["--strict"] } else { &[] }].concat();
        let o = splat(&args);
        assert!(o.status.success() && !stderr(&o).contains("warning"), "{}", stderr(&o));
        assert!(String::from_utf8_lossy(&o.stdout).contains("3D filter  Mip-Splatting's filter_3D, applied"));
    }
    let render = |scene: &str, out: &std::path::Path| {
        let camera = "fixtures/layers.cameras.json";
        let size = ["--width", "64", "--height", "48", "--backend", "cpu"];
        let o = splat(&[&["render", scene, "--camera", camera, "-o", out.to_str().unwrap()][..], &size].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        npy(out)
    };
    let none = layers_with_property("filter_3D", 0.0, "mip-none.ply");
    let classic = render(root().join("fixtures/layers.ply").to_str().unwrap(), &scratch("mip-classic.npy"));
    let unfiltered = render(none.to_str().unwrap(), &scratch("mip-none.npy"));
    // (The ASCII copy rounds the values to text: a difference far below the filter's.)
    assert!(rmse(&classic, &unfiltered) < 1e-6, "a zero filter is no filter");
    let filtered = render(path.to_str().unwrap(), &scratch("mip.npy"));
    assert!(rmse(&classic, &filtered) > 1e-3, "the filter must change the image");
}

/// Each trainer's capture, as the trainer writes it, renders with `raster-sorted` as that
/// trainer's forward pass does (`splat_tests::inria` with the trainer's `computeCov2D`, from the
/// file's raw values): a Mip-Splatting `.ply` (its `filter_3D`), a gsplat / Brush `.ply`
/// (`SplatRenderMode: mip`) and that file converted to `.spz` (the antialiased flag, carried by
/// `splat convert`). `splat info` names each file's filter. The control: `--screen-filter 3dgs`
/// renders the same files as the 3DGS rasterizer, and the parity tolerance rejects it. The ray
/// tracer (`exact`), which renders the particles without a screen-space filter, is measured
/// against each trainer's image for the record.
#[test]
fn each_trainers_capture_renders_as_its_trainer_does() {
    use splat_core::ScreenFilter;
    use splat_tests::inria::{self, Forward};
    let cloud = root().join("fixtures/cloud.ply");
    let raw = splat_io::ply::read_ply(&cloud).unwrap();
    let text = String::from_utf8(splat_io::ply::encode_ply(&raw, splat_io::ply::PlyFormat::Ascii)).unwrap();
    let (header, body) = text.split_once("end_header\n").unwrap();
    // Mip-Splatting: σ_f of 0.01 against the cloud's scales of 0.015–0.08.
    let mip = scratch("trainer-mip.ply");
    let filtered: String = body.lines().map(|l| format!("{l} 0.01\n")).collect();
    std::fs::write(&mip, format!("{header}property float filter_3D\nend_header\n{filtered}")).unwrap();
    let gsplat = scratch("trainer-gsplat.ply");
    let tagged = header.replacen("element vertex", "comment SplatRenderMode: mip\nelement vertex", 1);
    std::fs::write(&gsplat, format!("{tagged}end_header\n{body}")).unwrap();
    let spz = scratch("trainer-gsplat.spz");
    let o = splat(&["convert", gsplat.to_str().unwrap(), spz.to_str().unwrap()]);
    assert!(o.status.success() && !stderr(&o).contains("warning"), "{}", stderr(&o));

    let camera = splat_io::cameras::read_cameras(&root().join("fixtures/cloud.cameras.json")).unwrap()[0];
    let camera = camera.rescaled(64, 48).unwrap();
    let render = |scene: &std::path::Path, extra: &[&str]| {
        let out = scratch("trainer.npy");
        let args = ["render", scene.to_str().unwrap(), "--camera", "fixtures/cloud.cameras.json", "--width", "64"];
        let rest = ["--height", "48", "--backend", "cpu", "-o", out.to_str().unwrap()];
        let o = splat(&[&args[..], &rest, extra].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        (npy(&out), stderr(&o))
    };
    let sigma = vec![0.01f32; raw.particles.len()];
    let spz_scene = splat_io::read_scene(&spz).unwrap();
    let cases = [
        (&mip, &raw, Forward::MIP_SPLATTING, Some(sigma.as_slice()), ScreenFilter::Mip),
        (&gsplat, &raw, Forward::GSPLAT_ANTIALIASED, None, ScreenFilter::Antialiased),
        (&spz, &spz_scene, Forward::GSPLAT_ANTIALIASED, None, ScreenFilter::Antialiased),
    ];
    for (path, particles, forward, filter_3d, filter) in cases {
        let name = path.file_name().unwrap().to_string_lossy();
        let info = splat(&["info", path.to_str().unwrap()]);
        assert!(String::from_utf8_lossy(&info.stdout).contains(&format!("2D filter  {}", filter.describe())));
        let options = inria::Options { forward, filter_3d, ..Default::default() };
        let reference: Vec<f32> = inria::render(particles, &camera, &options).concat();
        let worst = |image: &[f32]| image.iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        let (ours, _) = render(path, &["--method", "raster-sorted"]);
        let (classic, _) = render(path, &["--method", "raster-sorted", "--screen-filter", "3dgs"]);
        let (traced, note) = render(path, &["--method", "exact"]);
        eprintln!(
            "{name}: raster-sorted max {:.2e}; control --screen-filter 3dgs max {:.2e}, RMSE {:.2e}; \
             exact (ray traced) RMSE {:.2e}",
            worst(&ours),
            worst(&classic),
            rmse(&classic, &reference),
            rmse(&traced, &reference)
        );
        assert!(worst(&ours) < 1e-4, "{name}: raster-sorted is {} from its trainer's image", worst(&ours));
        assert!(worst(&classic) > 1e-2, "{name}: the 3DGS dilation passes for {filter:?}");
        assert!(note.contains("traces the particles themselves, without it"), "{note}");
        assert!(!note.contains("does not apply"), "what the trainer implies is no flag to warn of: {note}");
    }
}

/// The ray tracers and splatting pick a pixel's surface at thresholds of their own
/// (vk_gaussian_splatting Lighting §1.1: "two separate values"), each a world key and a flag:
/// the world's `raster_iso_threshold` moves raster-sorted's depth and not exact's, its
/// `iso_threshold` exact's and not raster-sorted's, and `--raster-iso-threshold` overrides the
/// world's.
#[test]
fn ray_tracing_and_splatting_have_their_own_iso_thresholds() {
    let world = |keys: &str, name: &str| {
        let path = scratch(name);
        std::fs::write(&path, format!("{keys}[[splats]]\nbuiltin = \"demo\"\n")).unwrap();
        path
    };
    let depth = |path: &std::path::Path, method: &str, extra: &[&str]| {
        let (out, depth) = (scratch("iso.npy"), scratch("iso-depth.npy"));
        let args = ["render", path.to_str().unwrap(), "--method", method, "--width", "32", "--height", "24"];
        let rest = ["--backend", "cpu", "-o", out.to_str().unwrap(), "--depth", depth.to_str().unwrap()];
        let o = splat(&[&args[..], &rest, extra].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        npy(&depth)
    };
    let plain = world("", "iso-plain.toml");
    let raster_key = world("raster_iso_threshold = 0.2\n", "iso-raster.toml");
    let ray_key = world("iso_threshold = 0.2\n", "iso-ray.toml");
    let moved = |a: &[f32], b: &[f32]| a.iter().zip(b).filter(|(x, y)| x.to_bits() != y.to_bits()).count();
    let (raster, exact) = (depth(&plain, "raster-sorted", &[]), depth(&plain, "exact", &[]));
    assert!(moved(&depth(&raster_key, "raster-sorted", &[]), &raster) > 20, "raster_iso_threshold moves nothing");
    assert_eq!(moved(&depth(&raster_key, "exact", &[]), &exact), 0, "raster_iso_threshold moves exact");
    assert!(moved(&depth(&ray_key, "exact", &[]), &exact) > 20, "iso_threshold moves nothing");
    assert_eq!(moved(&depth(&ray_key, "raster-sorted", &[]), &raster), 0, "iso_threshold moves raster-sorted");
    let overridden = depth(&raster_key, "raster-sorted", &["--raster-iso-threshold", "0.7"]);
    assert_eq!(moved(&overridden, &raster), 0, "--raster-iso-threshold does not override the world");
}

/// A 2DGS capture splats as 2DGS does without a flag: `raster-sorted` on a file of 2D Gaussians
/// evaluates each along the pixel's ray (equal to `--response along-ray`, far from `--response
/// projected`, which the note names), and the GPU refuses that response, naming the CPU.
#[test]
fn a_2dgs_capture_splats_along_the_rays() {
    let cloud = splat_io::ply::read_ply(&root().join("fixtures/cloud.ply")).unwrap();
    let surfels = scratch("surfels-2dgs.ply");
    std::fs::write(&surfels, splat_tests::two_dgs_ply(&cloud)).unwrap();
    let render = |extra: &[&str]| {
        let out = scratch("surfels-2dgs.npy");
        let args = ["render", surfels.to_str().unwrap(), "--camera", "fixtures/cloud.cameras.json", "--width", "48"];
        let rest = ["--height", "36", "--method", "raster-sorted", "-o", out.to_str().unwrap()];
        let o = splat(&[&args[..], &rest, extra].concat());
        (o.status.success(), npy(&out), stderr(&o))
    };
    let (ok, default, note) = render(&["--backend", "cpu"]);
    assert!(ok && !note.contains("flat ellipses"), "{note}");
    let (_, along, _) = render(&["--backend", "cpu", "--response", "along-ray"]);
    let (_, projected, note) = render(&["--backend", "cpu", "--response", "projected"]);
    assert_eq!(default, along, "a 2DGS file splats along the rays by default");
    let off = default.iter().zip(&projected).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(off > 1e-2 && note.contains("flat ellipses"), "projected differs by {off}: {note}");
    let (ok, _, e) = render(&["--backend", "gpu", "--response", "along-ray"]);
    assert!(!ok && e.contains("CPU"), "{e}");
}

/// A capture's distorted COLMAP camera renders as it is, through its lens: `exact` traces each
/// pixel's ray through the fisheye (what COLMAP's model projects back to the pixel is checked
/// in tests/tests/camera_models.rs; here, that the CLI takes the model and that the lens
/// changes the image against the pinhole of the same intrinsics); `raster-sorted` splats
/// through it by the unscented transform, nearer the ray-traced image than the pinhole's
/// splatting is; the oracle, whose tile culling projects through a pinhole, refuses it with
/// the remedy.
#[test]
fn distorted_colmap_cameras_render_through_their_lens() {
    let dir = scratch("fisheye-model");
    std::fs::create_dir_all(&dir).unwrap();
    let images = "1 0.9961947 0.0871557 0 0 0 0 2.2 1 view.png\n\n";
    std::fs::write(dir.join("images.txt"), images).unwrap();
    let render = |cameras: &str, method: &str, name: &str| {
        std::fs::write(dir.join("cameras.txt"), cameras).unwrap();
        let out = scratch(name);
        let args = ["render", "fixtures/cloud.ply", "--camera", dir.to_str().unwrap(), "--method", method];
        let o = splat(&[&args[..], &["--backend", "cpu", "-o", out.to_str().unwrap()]].concat());
        (o.status.success().then(|| npy(&out)), stderr(&o))
    };
    let fisheye = "1 OPENCV_FISHEYE 96 72 40 40 48 36 0.04 -0.01 0.002 -0.0003\n";
    let (lens, e) = render(fisheye, "exact", "fisheye.npy");
    let lens = lens.unwrap_or_else(|| panic!("{e}"));
    let (pinhole, e) = render("1 PINHOLE 96 72 40 40 48 36\n", "exact", "pinhole.npy");
    let pinhole = pinhole.unwrap_or_else(|| panic!("{e}"));
    assert!(rmse(&lens, &pinhole) > 5e-3, "the fisheye renders as a pinhole ({})", rmse(&lens, &pinhole));
    let (splatted, e) = render(fisheye, "raster-sorted", "splatted.npy");
    let splatted = splatted.unwrap_or_else(|| panic!("{e}"));
    let (ewa, e) = render("1 PINHOLE 96 72 40 40 48 36\n", "raster-sorted", "ewa.npy");
    let ewa = ewa.unwrap_or_else(|| panic!("{e}"));
    // An OPENCV model without distortion splats by the unscented transform through the pinhole.
    let (unscented, e) = render("1 OPENCV 96 72 40 40 48 36 0 0 0 0\n", "raster-sorted", "unscented.npy");
    let unscented = unscented.unwrap_or_else(|| panic!("{e}"));
    let (same_lens, other_lens) = (rmse(&unscented, &ewa), rmse(&splatted, &ewa));
    eprintln!(
        "raster-sorted: the unscented transform through a pinhole RMSE {same_lens:.2e} from EWA; through the fisheye {other_lens:.2e}"
    );
    assert!(same_lens < 0.2 * other_lens, "splatting ignores the lens ({same_lens} against {other_lens})");
    let (refused, e) = render(fisheye, "oracle", "refused.npy");
    assert!(
        refused.is_none() && e.contains("cannot see through a fisheye lens") && e.contains("--method exact"),
        "{e}"
    );
}

/// gsplat's normalised world: `splat info` names the world splats lie in against a COLMAP model
/// with 3D points, and `--gsplat-world` renders the views moved into it, as a cameras.json of
/// the moved views does.
#[test]
fn gsplat_world_is_found_from_the_splats() {
    let base = splat_io::cameras::read_cameras(&root().join("fixtures/cloud.cameras.json")).unwrap()[0];
    let views: Vec<splat_io::colmap::View> = [0.0f32, 0.4, -0.7, 0.9]
        .iter()
        .enumerate()
        .map(|(i, &angle)| {
            let camera = splat_core::Camera { rotation: base.rotation * glam::Mat3::from_rotation_y(angle), ..base };
            splat_io::colmap::View { name: format!("img_{i}.jpg"), camera }
        })
        .collect();
    let dir = scratch("gsplat-sparse");
    std::fs::create_dir_all(&dir).unwrap();
    splat_io::colmap::write_colmap_txt(&dir, &views).unwrap();
    let info = |scene: &std::path::Path| {
        let o = splat(&["info", scene.to_str().unwrap(), "--camera", dir.to_str().unwrap()]);
        assert!(o.status.success(), "{}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let cloud_path = root().join("fixtures/cloud.ply");
    let text = info(&cloud_path);
    assert!(text.contains("world      not measured") && text.contains("points3D.txt"), "{text}");
    // The cloud's means as the model's 3D points: the splats lie in the model's own world.
    let cloud = splat_io::read_scene(&cloud_path).unwrap();
    let points: Vec<glam::DVec3> = cloud.particles.iter().map(|p| p.mean.as_dvec3()).collect();
    let rows: String = points
        .iter()
        .enumerate()
        .map(|(i, p)| format!("{} {} {} {} 128 128 128 0.5\n", i + 1, p.x, p.y, p.z))
        .collect();
    std::fs::write(dir.join("points3D.txt"), rows).unwrap();
    let text = info(&cloud_path);
    assert!(text.contains("world      the COLMAP model's own (100 % of its 3D points"), "{text}");
    // The cloud moved into the second frame gsplat's normalisation can give.
    let posed = splat_io::colmap::read_colmap_posed(&dir).unwrap();
    let poses: Vec<_> = posed.iter().map(splat_io::colmap::PosedView::pose).collect();
    let frame = splat_io::gsplat_world::frames(&poses, &points).unwrap()[1];
    let mut moved = cloud.clone();
    moved.particles.iter_mut().for_each(|p| p.mean = frame.point(p.mean.as_dvec3()).as_vec3());
    let moved_path = scratch("gsplat-world.ply");
    std::fs::write(&moved_path, splat_io::ply::encode_ply(&moved, splat_io::ply::PlyFormat::BinaryLittleEndian))
        .unwrap();
    let text = info(&moved_path);
    let gsplat = text.contains("world      gsplat's normalised world (100 %") && text.contains("--gsplat-world");
    assert!(gsplat && text.contains("without cameras, frame with --up "), "{text}");
    let cameras: Vec<splat_core::Camera> = posed
        .iter()
        .map(|p| {
            let (world_from_camera, centre) = frame.pose(p.pose());
            let rotation = world_from_camera.transpose();
            let translation = (-(rotation * centre)).as_vec3();
            splat_core::Camera { rotation: rotation.as_mat3(), translation, ..p.view.camera }
        })
        .collect();
    let json = scratch("gsplat-world.cameras.json");
    splat_io::cameras::write_cameras(&json, &cameras).unwrap();
    let render = |camera: &std::path::Path, index: &str, extra: &[&str], out: &str| {
        let out = scratch(out);
        let args = ["render", moved_path.to_str().unwrap(), "--camera", camera.to_str().unwrap(), "--camera-index"];
        let size = ["--width", "48", "--height", "36", "--backend", "cpu", "-o", out.to_str().unwrap()];
        let o = splat(&[&args[..], &[index], extra, &size].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        npy(&out)
    };
    let ours = render(&dir, "3", &["--gsplat-world"], "gsplat-world.npy");
    let expected = render(&json, "3", &[], "gsplat-world-json.npy");
    let neighbour = rmse(&ours, &render(&json, "2", &[], "gsplat-world-json2.npy"));
    assert!(rmse(&ours, &expected) < 1e-3 && neighbour > 1e-2, "{} against {neighbour}", rmse(&ours, &expected));
    // The same world given as gsplat's parser.transform saved by numpy.savetxt: from the COLMAP
    // model (its double-precision poses) and from a cameras.json of its views (single precision).
    let saved = |world: &splat_io::similarity::Similarity, name: &str| {
        let (m, t) = (world.scale * world.rotation, world.translation);
        let row = |r: usize| format!("{:.18e} {:.18e} {:.18e} {:.18e}\n", m.row(r).x, m.row(r).y, m.row(r).z, t[r]);
        let path = scratch(name);
        std::fs::write(&path, format!("{}{}{}0 0 0 1\n", row(0), row(1), row(2))).unwrap();
        path
    };
    let matrix = saved(&frame, "parser-transform.txt");
    let flag = ["--world-transform", matrix.to_str().unwrap()];
    let colmap_json = scratch("gsplat-colmap.cameras.json");
    let unmoved: Vec<_> = posed.iter().map(|p| p.view.camera).collect();
    splat_io::cameras::write_cameras(&colmap_json, &unmoved).unwrap();
    for (cameras, name) in [(&dir, "world-transform-colmap.npy"), (&colmap_json, "world-transform-json.npy")] {
        let given = render(cameras, "3", &flag, name);
        assert!(rmse(&given, &expected) < 1e-3, "{name}: {}", rmse(&given, &expected));
    }
    let half_turn =
        splat_io::similarity::Similarity::rotation(glam::DMat3::from_diagonal(glam::dvec3(-1.0, -1.0, 1.0)));
    let other = saved(&frame.then(half_turn), "other-frame.txt");
    let control = render(&dir, "3", &["--world-transform", other.to_str().unwrap()], "world-transform-other.npy");
    assert!(rmse(&control, &expected) > 1e-2, "the other frame renders the same view");
    let o = splat(&[
        "info",
        moved_path.to_str().unwrap(),
        "--camera",
        dir.to_str().unwrap(),
        "--world-transform",
        matrix.to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("world      --world-transform's: 100 % of the model's 3D points lie on the splats"),
        "{text}"
    );
    // Views of a camera file that show none of the splats say that the splats' world may be
    // another: a camera turned away from the cloud, one view and all of them.
    let turned = glam::Mat3::from_rotation_y(std::f32::consts::PI) * base.rotation;
    let away = splat_core::Camera { rotation: turned, translation: -(turned * base.center()), ..base };
    let away_json = scratch("away.cameras.json");
    splat_io::cameras::write_cameras(&away_json, &[away]).unwrap();
    for extra in [&[][..], &["--all-cameras"]] {
        let out = scratch(if extra.is_empty() { "away.npy" } else { "away" });
        let args = ["render", "fixtures/cloud.ply", "--camera", away_json.to_str().unwrap(), "--backend", "cpu"];
        let o = splat(&[&args[..], extra, &["--width", "16", "--height", "12", "-o", out.to_str().unwrap()]].concat());
        let note = if extra.is_empty() { "the view shows none of the splats" } else { "none of the views shows" };
        let e = stderr(&o);
        let ways = ["splat info", "--gsplat-world", "--dataparser-transforms", "--world-transform FILE"];
        assert!(o.status.success() && e.contains(note) && ways.iter().all(|w| e.contains(w)), "{e}");
    }
    let here = scratch("here.npy");
    let o = splat(&["render", "fixtures/cloud.ply", "--camera", dir.to_str().unwrap(), "-o", here.to_str().unwrap()]);
    assert!(o.status.success() && !stderr(&o).contains("none of the splats"), "{}", stderr(&o));
}

/// A COLMAP model renders the same view as the equivalent cameras.json, and `--all-cameras`
/// writes one image per view, named after it.
#[test]
fn colmap_cameras_and_all_cameras() {
    let json = root().join("fixtures/cloud.cameras.json");
    let base = splat_io::cameras::read_cameras(&json).unwrap()[0];
    let views: Vec<splat_io::colmap::View> = [0.0f32, 0.4, -0.7]
        .iter()
        .enumerate()
        .map(|(i, &angle)| {
            let turn = glam::Mat3::from_rotation_y(angle);
            let camera = splat_core::Camera { rotation: base.rotation * turn, ..base };
            splat_io::colmap::View { name: format!("img_{i}.jpg"), camera }
        })
        .collect();
    let dir = scratch("sparse0");
    std::fs::create_dir_all(&dir).unwrap();
    splat_io::colmap::write_colmap_txt(&dir, &views).unwrap();
    let cameras: Vec<_> = views.iter().map(|v| v.camera).collect();
    let json = scratch("three.cameras.json");
    splat_io::cameras::write_cameras(&json, &cameras).unwrap();
    let render = |camera: &std::path::Path, out: &str, index: &str| {
        let out = scratch(out);
        let args = ["render", "fixtures/cloud.ply", "--camera", camera.to_str().unwrap(), "--camera-index", index];
        let o = splat(
            &[&args[..], &["--width", "48", "--height", "36", "--backend", "cpu", "-o", out.to_str().unwrap()]]
                .concat(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
        npy(&out)
    };
    let (a, b) = (render(&dir, "colmap.npy", "2"), render(&json, "json.npy", "2"));
    // Equal up to f32 rounding of the pose (quaternion here, rotation rows there); the control
    // is the neighbouring view.
    let neighbour = rmse(&a, &render(&json, "json1.npy", "1"));
    assert!(rmse(&a, &b) < 1e-3 && neighbour > 1e-2, "COLMAP vs cameras.json {}, neighbour {neighbour}", rmse(&a, &b));
    // The same views as a Nerfstudio transforms.json (camera-to-world, OpenGL axes: the camera's
    // columns x, −y, −z), read from its folder.
    let frames: Vec<_> = views
        .iter()
        .map(|v| {
            let c = &v.camera;
            let [x, y, z] = [0, 1, 2].map(|k| c.rotation.row(k));
            let (y, z, centre) = (-y, -z, c.center());
            let rows = [0, 1, 2].map(|i| serde_json::json!([x[i], y[i], z[i], centre[i]]));
            serde_json::json!({"file_path": format!("images/{}", v.name), "transform_matrix": rows,
                "fl_x": c.fx, "fl_y": c.fy, "cx": c.cx, "cy": c.cy})
        })
        .collect();
    let (w, h) = (base.width, base.height);
    let nerfstudio = scratch("nerfstudio");
    std::fs::create_dir_all(&nerfstudio).unwrap();
    let transforms = serde_json::json!({"w": w, "h": h, "camera_model": "OPENCV", "frames": frames});
    std::fs::write(nerfstudio.join("transforms.json"), transforms.to_string()).unwrap();
    let c = render(&nerfstudio, "transforms.npy", "2");
    assert!(rmse(&c, &b) < 1e-3, "transforms.json vs cameras.json {}", rmse(&c, &b));
    // A Nerfstudio run's dataparser transforms move a transforms.json's cameras, and only those.
    let run = nerfstudio.join("dataparser_transforms.json");
    std::fs::write(&run, r#"{"transform": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]], "scale": 1.0}"#).unwrap();
    for (cameras, ok) in [(&nerfstudio, true), (&dir, false)] {
        let o = splat(&[
            "render",
            "fixtures/cloud.ply",
            "--camera",
            cameras.to_str().unwrap(),
            "--dataparser-transforms",
            run.to_str().unwrap(),
            "--width",
            "8",
            "--height",
            "6",
            "-o",
            scratch("run.npy").to_str().unwrap(),
        ]);
        assert_eq!(o.status.success(), ok, "{}", stderr(&o));
        assert!(ok || stderr(&o).contains("move a transforms.json's cameras"), "{}", stderr(&o));
    }
    // gsplat's normalised world is a COLMAP model's (with its 3D points), found from the splats.
    for (cameras, refusal) in [(&nerfstudio, "gsplat normalises the world of a COLMAP model"), (&dir, "points3D.txt")] {
        let args = ["render", "fixtures/cloud.ply", "--camera", cameras.to_str().unwrap(), "--gsplat-world"];
        let o =
            splat(&[&args[..], &["--width", "8", "--height", "6", "-o", scratch("g.npy").to_str().unwrap()]].concat());
        assert!(!o.status.success() && stderr(&o).contains(refusal), "{}", stderr(&o));
    }
    let out = scratch("views");
    let o = splat(&[
        "render",
        "fixtures/cloud.ply",
        "--camera",
        dir.to_str().unwrap(),
        "--all-cameras",
        "--width",
        "32",
        "--height",
        "24",
        "--backend",
        "cpu",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("rendered 3 views"), "{}", stderr(&o));
    for i in 0..3 {
        assert!(out.join(format!("img_{i}.png")).exists(), "img_{i}.png missing");
    }
    // Written into the capture's own photographs (gsplat's PNG copies here, in images/ beside
    // sparse/), a view would replace its photograph: refused before any render, the photograph
    // kept. Views of another format are no clash there (the control).
    let capture = scratch("capture");
    let (sparse, photos) = (capture.join("sparse/0"), capture.join("images"));
    std::fs::create_dir_all(&sparse).unwrap();
    std::fs::create_dir_all(&photos).unwrap();
    splat_io::colmap::write_colmap_txt(&sparse, &views).unwrap();
    std::fs::write(photos.join("img_1.png"), b"a photograph").unwrap();
    let into = |format: &str| {
        let camera = ["render", "fixtures/cloud.ply", "--camera", sparse.to_str().unwrap(), "--all-cameras"];
        let size = ["--width", "8", "--height", "6", "--backend", "cpu", "--view-format", format];
        splat(&[&camera[..], &size, &["-o", photos.to_str().unwrap()]].concat())
    };
    let o = into("png");
    assert!(!o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("view 1 (img_1.jpg) would be written over its photograph"), "{}", stderr(&o));
    assert_eq!(std::fs::read(photos.join("img_1.png")).unwrap(), b"a photograph");
    let o = into("npy");
    assert!(o.status.success() && photos.join("img_1.npy").exists(), "{}", stderr(&o));
    // 3DGS's training views: all but every 8th by name, so img_1 and img_2.
    let train = scratch("train-views");
    let dir_arg = dir.to_str().unwrap();
    let args = ["--all-cameras", "--split", "3dgs-train", "--width", "8", "--height", "6", "--backend", "cpu"];
    let o = splat(
        &[&["render", "fixtures/cloud.ply", "--camera", dir_arg][..], &args, &["-o", train.to_str().unwrap()]].concat(),
    );
    assert!(o.status.success() && stderr(&o).contains("rendered 2 views"), "{}", stderr(&o));
    let written = [0, 1, 2].map(|i| train.join(format!("img_{i}.png")).exists());
    assert_eq!(written, [false, true, true]);
    let one = scratch("one-view");
    let o = splat(&[
        "render",
        "fixtures/cloud.ply",
        "--camera",
        "fixtures/cloud.cameras.json",
        "--all-cameras",
        "--width",
        "32",
        "--height",
        "24",
        "-o",
        one.to_str().unwrap(),
    ]);
    assert!(o.status.success() && stderr(&o).contains("rendered 1 view,"), "{}", stderr(&o));
    let o = splat(&["render", "fixtures/cloud.ply", "--all-cameras", "-o", out.to_str().unwrap()]);
    assert!(!o.status.success() && stderr(&o).contains("--camera"), "{}", stderr(&o));
}

/// `--undistort` renders a distorted capture's cameras as the pinholes its trainer trained
/// through, at the size of OpenCV's valid-pixel rectangle, so that the oracle, which projects
/// through a pinhole, renders them too; gsplat's fisheye as its ideal fisheye, cropped, which
/// the ray tracers render.
#[test]
fn undistorted_cameras_are_the_trainers_pinholes() {
    let folder = scratch("undistort");
    std::fs::create_dir_all(&folder).unwrap();
    let write = |model: &str, distortion: serde_json::Value| {
        let frame = serde_json::json!({"file_path": "images/a.png",
            "transform_matrix": [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 4], [0, 0, 0, 1]]});
        let mut meta = serde_json::json!({"camera_model": model, "fl_x": 40.0, "fl_y": 40.0, "cx": 24.0,
            "cy": 18.0, "w": 48, "h": 36, "frames": [frame]});
        meta.as_object_mut().unwrap().extend(distortion.as_object().unwrap().clone());
        std::fs::write(folder.join("transforms.json"), meta.to_string()).unwrap();
    };
    let render = |extra: &[&str]| {
        let out = scratch("undistort.npy");
        let camera = folder.to_str().unwrap();
        let args = ["render", "fixtures/cloud.ply", "--camera", camera, "--method", "oracle"];
        (splat(&[&args[..], extra, &["--backend", "cpu", "-o", out.to_str().unwrap()]].concat()), out)
    };
    write("OPENCV", serde_json::json!({"k1": -0.2, "k2": 0.05}));
    let o = splat(&["info", "fixtures/cloud.ply", "--camera", folder.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("a distorted perspective lens (1 view)") && text.contains("--undistort splatfacto"),
        "{text}"
    );
    let (o, _) = render(&[]);
    assert!(!o.status.success() && stderr(&o).contains("only through a pinhole"), "{}", stderr(&o));
    for trainer in ["splatfacto", "gsplat"] {
        let (o, out) = render(&["--undistort", trainer]);
        assert!(o.status.success(), "{trainer}: {}", stderr(&o));
        // A 48 × 36 photo's valid rectangle at alpha 0 is 47 × 35 pixels.
        assert_eq!(npy_size(&out), (35, 47), "{trainer}");
    }
    // Photographs of images_2/ at 25 × 19: the camera is halved and sized to them, then
    // undistorted (as gsplat's parser does it), and rendered at the undistorted camera's size,
    // not stretched back to --width × --height.
    let options = splat_io::cameras::ViewOptions {
        undistort: Some(splat_core::undistort::Undistortion::Gsplat),
        factor: Some(2),
        size: (Some(25), Some(19)),
        ..Default::default()
    };
    let [(_, expected)] = &splat_io::cameras::read_views_in(&folder, options).unwrap()[..] else { panic!("one view") };
    assert_eq!((expected.width, expected.height), (24, 18));
    let (o, out) = render(&["--undistort", "gsplat", "--data-factor", "2", "--width", "25", "--height", "19"]);
    assert!(o.status.success() && npy_size(&out) == (18, 24), "{}", stderr(&o));
    write("OPENCV_FISHEYE", serde_json::json!({"k1": 0.05}));
    let (o, out) = render(&["--undistort", "splatfacto"]);
    assert!(o.status.success() && npy_size(&out) == (36, 48), "{}", stderr(&o));
    // gsplat's ideal fisheye, cropped to where its map lands inside, through a ray tracer.
    let options = splat_io::cameras::ViewOptions {
        undistort: Some(splat_core::undistort::Undistortion::Gsplat),
        ..Default::default()
    };
    let [(_, ideal)] = &splat_io::cameras::read_views_in(&folder, options).unwrap()[..] else { panic!("one view") };
    assert_eq!(ideal.lens, splat_core::camera::Lens::Fisheye(Default::default()));
    assert!(ideal.width < 48 && ideal.height < 36, "{ideal:?}");
    let (o, _) = render(&["--undistort", "gsplat"]);
    assert!(!o.status.success() && stderr(&o).contains("cannot see through a fisheye lens"), "{}", stderr(&o));
    let out = scratch("ideal.npy");
    let camera = folder.to_str().unwrap();
    let args = ["render", "fixtures/cloud.ply", "--camera", camera, "--undistort", "gsplat", "--method", "exact"];
    let o = splat(&[&args[..], &["--backend", "cpu", "-o", out.to_str().unwrap()]].concat());
    assert!(o.status.success() && npy_size(&out) == (ideal.height, ideal.width), "{}", stderr(&o));
}

/// `--all-cameras` prepares the world once (the BVH, the device arrays, the pipelines) and renders
/// every view through it: each view's image is, bit for bit, what `--camera-index` renders of
/// that view alone, on the CPU for a ray-tracing method (a stochastic one, whose frames are
/// keyed by the run), a splatting one and the path tracer, on the GPU for the ray-tracing one
/// and the path tracer (views 1 and 2: a renderer stuck on the first view fails there; the
/// GPU's pipelines make each run a second); the views differ in pose and in size.
#[test]
fn all_cameras_views_are_the_single_view_renders() {
    let json = root().join("fixtures/cloud.cameras.json");
    let base = splat_io::cameras::read_cameras(&json).unwrap()[0];
    let cameras: Vec<_> = [(0.0f32, 32, 24), (0.5, 40, 30), (-0.6, 24, 18)]
        .iter()
        .map(|&(angle, w, h)| {
            let turned = splat_core::Camera { rotation: base.rotation * glam::Mat3::from_rotation_y(angle), ..base };
            turned.rescaled(w, h).unwrap()
        })
        .collect();
    let json = scratch("views3.cameras.json");
    splat_io::cameras::write_cameras(&json, &cameras).unwrap();
    let camera = json.to_str().unwrap();
    let runs = [("cpu", &["stochastic", "raster-sorted", "path"][..], 0), ("gpu", &["stochastic", "path"], 1)];
    for (backend, methods, first) in runs {
        for &method in methods {
            let common = ["render", "fixtures/cloud.ply", "--camera", camera, "--spp", "2", "--backend", backend];
            let how = match method {
                "path" => ["--pipeline", "path", "--max-depth", "2"].as_slice(),
                _ => &["--method", method],
            };
            let common = [&common[..], how].concat();
            let dir = scratch(&format!("views-{backend}-{method}"));
            let dir_arg = dir.to_str().unwrap();
            let o = splat(&[&common[..], &["--all-cameras", "--view-format", "npy", "-o", dir_arg]].concat());
            if backend == "gpu" && !o.status.success() {
                gpu_missing(&stderr(&o));
                return;
            }
            assert!(o.status.success(), "{}", stderr(&o));
            let mut views = Vec::new();
            for i in first..cameras.len() {
                let one = scratch(&format!("view-{backend}-{method}-{i}.npy"));
                let index = i.to_string();
                let o = splat(&[&common[..], &["--camera-index", &index, "-o", one.to_str().unwrap()]].concat());
                assert!(o.status.success(), "{}", stderr(&o));
                let all = npy(&dir.join(format!("view_{i:04}.npy")));
                assert!(all == npy(&one), "{backend} {method}: view {i} of --all-cameras is not its own render");
                views.push(all);
            }
            assert!(views.windows(2).all(|w| w[0] != w[1]), "{backend} {method}: the views are alike");
        }
    }
}

/// `--backend auto` on a machine whose only adapters are CPU ones prints nothing of the
/// graphics stack's and renders what `--backend cpu` renders.
#[test]
fn auto_backend_is_quiet_without_a_hardware_gpu() {
    let run = |backend: &str, out: &std::path::Path| {
        Command::new(env!("CARGO_BIN_EXE_splat"))
            .args(["render", "--width", "32", "--height", "24", "--backend", backend, "-o", out.to_str().unwrap()])
            .env_remove("WGPU_BACKEND")
            .env_remove("WGPU_ADAPTER_NAME")
            .env_remove("XDG_RUNTIME_DIR")
            .current_dir(root())
            .output()
            .unwrap()
    };
    let (a, b) = (scratch("auto.png"), scratch("cpu.png"));
    let (auto, cpu) = (run("auto", &a), run("cpu", &b));
    assert!(auto.status.success() && cpu.status.success());
    let hardware = std::path::Path::new("/dev/dri").exists() || std::path::Path::new("/dev/nvidia0").exists();
    if hardware {
        splat_tests::not_applicable(&splat_tests::current_test(), "this machine has a GPU device node");
        return;
    }
    let lines = |o: &Output| stderr(o).lines().filter(|l| !l.starts_with("rendered")).count();
    assert_eq!(lines(&auto), 0, "auto printed more than its summary:\n{}", stderr(&auto));
    assert_eq!(lines(&cpu), 0);
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}

/// `splat ztest` from the command line: `stochastic` against `exact` passes (exit 0); depth
/// sampling (3DGRT's biased control) and the unbiased mean brightened by 2 % and by 1 % are
/// rejected (exit 1); bad input exits 2.
#[test]
fn ztest_passes_stochastic_and_rejects_biased_means() {
    let scene = ["fixtures/cloud.ply", "--camera", "fixtures/cloud.cameras.json", "--width", "48", "--height", "36"];
    let render = |extra: &[&str], out: &std::path::Path| {
        let o = splat(&[&["render"][..], &scene, &["--backend", "cpu", "-o", out.to_str().unwrap()], extra].concat());
        assert!(o.status.success(), "{}", stderr(&o));
    };
    let (reference, mean, var, run2) =
        (scratch("zt-ref.npy"), scratch("zt-mean.npy"), scratch("zt-var.npy"), scratch("zt-run2.npy"));
    render(&["--method", "exact"], &reference);
    let mean_var = scratch("zt-mean-var.npy");
    render(&["--method", "stochastic", "--spp", "256", "--seed", "1", "--variance", mean_var.to_str().unwrap()], &mean);
    render(&["--method", "stochastic", "--spp", "1024", "--seed", "2", "--variance", var.to_str().unwrap()], &run2);
    let biased = scratch("zt-dsk.npy");
    render(&["--method", "depth-sampling-k", "--spp", "256", "--seed", "1"], &biased);
    let brighter = |k: f32, name: &str| {
        let image = splat_io::image::read_npy(&mean).unwrap();
        let data = image.data().iter().map(|v| v * k).collect();
        let scaled = splat_core::Image::from_data(image.width(), image.height(), image.channels(), data).unwrap();
        let path = scratch(name);
        splat_io::image::write_image(&path, &scaled).unwrap();
        path
    };
    let zmap = scratch("zt-map.png");
    let ztest = |m: &std::path::Path| {
        let args = [m, var.as_path(), reference.as_path()].map(|p| p.to_str().unwrap().to_string());
        splat(&["ztest", &args[0], &args[1], &args[2], "--frames", "256", "--zmap", zmap.to_str().unwrap()])
    };
    let pass = ztest(&mean);
    let text = String::from_utf8_lossy(&pass.stdout).into_owned();
    assert_eq!(pass.status.code(), Some(0), "{text}{}", stderr(&pass));
    assert!(text.contains("verdict    PASS"), "{text}");
    assert!(image::open(&zmap).unwrap().width() >= 480, "the z-map is scaled up with its legend");
    // Pooled with the mean run's own variance, as the suites do.
    let args = [&mean, &var, &reference, &mean_var].map(|p| p.to_str().unwrap().to_string());
    let pooled = splat(&[
        "ztest",
        &args[0],
        &args[1],
        &args[2],
        "--frames",
        "256",
        "--mean-variance",
        &args[3],
        "--variance-frames",
        "1024",
    ]);
    assert_eq!(pooled.status.code(), Some(0), "{}", String::from_utf8_lossy(&pooled.stdout));
    for (m, what) in
        [(biased, "depth sampling"), (brighter(1.02, "zt-102.npy"), "× 1.02"), (brighter(1.01, "zt-101.npy"), "× 1.01")]
    {
        let o = ztest(&m);
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        eprintln!("{what}: {}", text.lines().last().unwrap_or_default());
        assert_eq!(o.status.code(), Some(1), "{what} must be rejected:\n{text}");
    }
    let o = splat(&["ztest", mean.to_str().unwrap(), "nope.npy", reference.to_str().unwrap(), "--frames", "256"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let small = scratch("zt-small.npy");
    splat_io::image::write_image(&small, &splat_core::Image::filled(4, 4, 3, 0.5)).unwrap();
    let o = splat(&[
        "ztest",
        small.to_str().unwrap(),
        var.to_str().unwrap(),
        reference.to_str().unwrap(),
        "--frames",
        "256",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("48×36"), "{}", stderr(&o));
}

/// `splat compare`: identical images score RMSE 0, SSIM 1, ꟻLIP 0; a one-frame stochastic image
/// against the exact one scores worse on all four; the maps are written; sizes must match.
#[test]
fn compare_prints_four_metrics_and_writes_maps() {
    let scene = ["fixtures/cloud.ply", "--camera", "fixtures/cloud.cameras.json", "--width", "48", "--height", "36"];
    let (exact, noisy) = (scratch("cmp-exact.exr"), scratch("cmp-noisy.png"));
    for (method, out) in [("exact", &exact), ("stochastic", &noisy)] {
        let o = splat(
            &[&["render"][..], &scene, &["--method", method, "--backend", "cpu", "-o", out.to_str().unwrap()]].concat(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let metric = |o: &Output, name: &str| -> f64 {
        let text = String::from_utf8_lossy(&o.stdout);
        let line = text.lines().find(|l| l.starts_with(name)).unwrap_or_else(|| panic!("no {name} in {text}"));
        line.split_whitespace().nth(1).unwrap().parse().unwrap()
    };
    let same = splat(&["compare", exact.to_str().unwrap(), exact.to_str().unwrap()]);
    assert!(same.status.success(), "{}", stderr(&same));
    assert_eq!((metric(&same, "RMSE"), metric(&same, "SSIM"), metric(&same, "FLIP")), (0.0, 1.0, 0.0));
    let maps = scratch("cmp");
    let o = splat(&["compare", exact.to_str().unwrap(), noisy.to_str().unwrap(), "--maps", maps.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(metric(&o, "RMSE") > 0.01 && metric(&o, "PSNR") < 40.0, "{}", String::from_utf8_lossy(&o.stdout));
    assert!(metric(&o, "SSIM") < 0.99 && metric(&o, "FLIP") > 0.01, "{}", String::from_utf8_lossy(&o.stdout));
    for suffix in ["abs", "ssim", "flip"] {
        let path = scratch(&format!("cmp-{suffix}.png"));
        assert_eq!(image::open(&path).unwrap().width(), 48, "{suffix} map");
    }
    let o = splat(&["compare", exact.to_str().unwrap(), "fixtures/golden/layers-oracle.png"]);
    assert!(!o.status.success() && stderr(&o).contains("differ in size"), "{}", stderr(&o));
}

/// `splat compare` of two folders: each test image against the reference of its name (a JPEG
/// photograph among them), one row each, and the mean of each metric over the images, each row
/// what comparing the pair alone gives; a test image without a reference is refused by name.
#[test]
fn compare_folders_averages_the_images_metrics() {
    let (gt, renders) = (scratch("cmp-gt"), scratch("cmp-renders"));
    std::fs::create_dir_all(&gt).unwrap();
    std::fs::create_dir_all(&renders).unwrap();
    let scene = ["fixtures/cloud.ply", "--camera", "fixtures/cloud.cameras.json", "--width", "48", "--height", "36"];
    let render = |method: &str, out: &std::path::Path| {
        let args = ["--method", method, "--backend", "cpu", "--seed", "3", "-o", out.to_str().unwrap()];
        let o = splat(&[&["render"][..], &scene, &args].concat());
        assert!(o.status.success(), "{}", stderr(&o));
    };
    render("exact", &gt.join("a.png"));
    render("exact", &scratch("cmp-b.png"));
    image::open(scratch("cmp-b.png")).unwrap().to_rgb8().save(gt.join("b.jpg")).unwrap();
    render("stochastic", &renders.join("a.png"));
    render("oracle", &renders.join("b.png"));
    let o = splat(&["compare", gt.to_str().unwrap(), renders.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout).to_string();
    let row = |name: &str| -> Vec<f64> {
        let line = text.lines().find(|l| l.starts_with(name)).unwrap_or_else(|| panic!("no {name} in {text}"));
        line[name.len()..].split_whitespace().map(|v| v.parse().unwrap()).collect()
    };
    let single = |reference: &std::path::Path, test: &std::path::Path| -> Vec<f64> {
        let o = splat(&["compare", reference.to_str().unwrap(), test.to_str().unwrap()]);
        let text = String::from_utf8_lossy(&o.stdout).to_string();
        ["PSNR", "SSIM", "SSIM", "FLIP"]
            .iter()
            .enumerate()
            .map(|(i, name)| {
                let mut lines = text.lines().filter(|l| l.starts_with(name));
                let line = if i == 2 { lines.nth(1) } else { lines.next() }.unwrap();
                line.split_whitespace().nth(1).unwrap().parse().unwrap()
            })
            .collect()
    };
    let (a, b) = (row("a"), row("b"));
    for (rows, pair) in [
        (&a, single(&gt.join("a.png"), &renders.join("a.png"))),
        (&b, single(&gt.join("b.jpg"), &renders.join("b.png"))),
    ] {
        for (v, w) in rows.iter().zip(&pair) {
            // The rows print PSNR to 3 places, the pair's line to 2.
            assert!((v - w).abs() < 6e-3, "{rows:?} against the pair's {pair:?}");
        }
    }
    let mean = row("mean of 2");
    for k in 0..4 {
        assert!((mean[k] - (a[k] + b[k]) / 2.0).abs() < 2e-3, "{mean:?} of {a:?} and {b:?}");
    }
    assert!(a[0] < b[0], "the one-sample render is the further: {text}");
    std::fs::rename(gt.join("b.jpg"), gt.join("c.jpg")).unwrap();
    let o = splat(&["compare", gt.to_str().unwrap(), renders.to_str().unwrap()]);
    assert!(!o.status.success() && stderr(&o).contains("(the first: b)"), "{}", stderr(&o));
    let o = splat(&["compare", gt.to_str().unwrap(), renders.to_str().unwrap(), "--maps", "m"]);
    assert!(!o.status.success() && stderr(&o).contains("not of two folders"), "{}", stderr(&o));
}

/// Shell completions name every subcommand and option; `render --help` groups its options
/// under headings, output and method first.
#[test]
fn completions_and_help_headings() {
    for (shell, marker) in [("bash", "complete -F"), ("zsh", "#compdef splat"), ("fish", "complete -c splat")] {
        let o = splat(&["completions", shell]);
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success() && text.contains(marker), "{shell}: {}", stderr(&o));
        for word in ["render", "convert", "ztest", "compare", "spz-axes", "all-cameras"] {
            assert!(text.contains(word), "{shell} completions lack {word}");
        }
    }
    let help = String::from_utf8_lossy(&splat(&["render", "--help"]).stdout).into_owned();
    let at = |h: &str| help.find(&format!("\n{h}:\n")).unwrap_or_else(|| panic!("no heading {h}:\n{help}"));
    let order = ["Output", "Method", "Camera", "Scene and shading", "Machine", "Reading scene files", "Splatting"];
    assert!(order.windows(2).all(|w| at(w[0]) < at(w[1])), "headings out of order:\n{help}");
}

#[test]
fn view_is_a_subcommand_that_refuses_bad_input_before_opening_a_window() {
    let help = splat(&["view", "--help"]);
    assert!(help.status.success());
    let text = String::from_utf8_lossy(&help.stdout);
    for option in ["--camera", "--backend", "--quit-after", "--up"] {
        assert!(text.contains(option), "splat view --help lacks {option}: {text}");
    }
    let missing = splat(&["view", "no-such.ply"]);
    assert_eq!(missing.status.code(), Some(1));
    assert!(stderr(&missing).contains("no-such.ply"), "{}", stderr(&missing));
}

/// Run `splat` and return (success, stderr).
fn said(args: &[&str]) -> (bool, String) {
    let o = splat(args);
    let text = stderr(&o);
    assert!(!text.contains("panicked"), "{args:?} panicked:\n{text}");
    (o.status.success(), text)
}

/// A new user's mistakes, each refused with one message that names the problem and the way
/// out, before any rendering starts.
#[test]
fn a_new_users_mistakes_are_refused_with_clear_messages_before_any_work() {
    let out = scratch("mistake.png");
    let out = out.to_str().unwrap();
    let size = "is not an image size: give a whole number of pixels from 1 to 16384";
    for width in
        [&["--width", "0"][..], &["--width=-5"], &["--width", "-5"], &["--width", "ten"], &["--width", "16385"]]
    {
        let (ok, text) = said(&[&["render", "fixtures/cloud.ply", "-o", out][..], width].concat());
        assert!(!ok && text.contains(size), "{width:?}: {text}");
    }
    // The photographs' size that `splat undistort` scales the cameras to, likewise.
    let undistort = ["undistort", "--camera", "fixtures/cloud.cameras.json", "--images", "fixtures", "-o", out];
    for side in [&["--width", "0"][..], &["--height=-5"], &["--height", "16385"]] {
        let (ok, text) = said(&[&undistort[..], side].concat());
        assert!(!ok && text.contains(size), "{side:?}: {text}");
    }
    let (ok, text) = said(&["render", "fixtures/cloud.ply", "-o", "no-such-folder/x.png"]);
    assert!(!ok && text.contains("the folder no-such-folder does not exist"), "{text}");
    let (ok, text) = said(&["render", "fixtures/cloud.ply", "-o", out, "--depth", "no-such-folder/d.npy"]);
    assert!(!ok && text.contains("--depth no-such-folder/d.npy"), "{text}");
    // 16384² needs about 27 GiB: where less is available, refused at once with the estimate.
    let available = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        let line = m.lines().find(|l| l.starts_with("MemAvailable:"))?.to_owned();
        line.split_whitespace().nth(1)?.parse::<u64>().ok()
    });
    match available {
        Some(kib) if kib < 26 << 20 => {
            let start = std::time::Instant::now();
            let (ok, text) =
                said(&["render", "fixtures/cloud.ply", "--width", "16384", "--height", "16384", "-o", out]);
            assert!(!ok && text.contains("render needs about") && text.contains("bytes a pixel"), "{text}");
            assert!(start.elapsed().as_secs() < 20, "the refusal came after {:?}", start.elapsed());
        }
        _ => splat_tests::not_applicable(&splat_tests::current_test(), "16384² fits in this machine's memory"),
    }
    let empty = scratch("empty.splat");
    std::fs::write(&empty, b"").unwrap();
    let (ok, text) = said(&["render", empty.to_str().unwrap(), "-o", out]);
    assert!(!ok && text.contains("holds no splats and no meshes"), "{text}");
    let (ok, text) = said(&["view", empty.to_str().unwrap()]);
    assert!(!ok && text.contains("holds no splats and no meshes"), "the viewer opened an empty scene: {text}");
    let (ok, text) = said(&["render", "fixtures/cloud.ply", "--camera", "fixtures/cloud.ply", "-o", out]);
    assert!(!ok && text.contains("not a camera file") && text.contains("COLMAP"), "{text}");
    // Camera options that would change nothing are refused, naming what they need or clash with:
    // a field of view without a look-at camera, a look-at camera or an up beside --camera's views
    // (which have their own poses), a camera index without them.
    let (ok, text) = said(&["render", "fixtures/cloud.ply", "--fov", "30", "-o", out]);
    assert!(!ok && text.contains("--eye <EYE>") && text.contains("--target <TARGET>"), "{text}");
    let views = ["render", "fixtures/cloud.ply", "--camera", "fixtures/cloud.cameras.json", "-o", out];
    for extra in [&["--eye", "0,0,4", "--target", "0,0,0"][..], &["--up", "0,-1,0"]] {
        let (ok, text) = said(&[&views[..], extra].concat());
        assert!(!ok && text.contains(&format!("'{} <", extra[0])) && text.contains("--camera <CAMERA>"), "{text}");
    }
    let (ok, text) = said(&["render", "fixtures/cloud.ply", "--camera-index", "2", "-o", out]);
    assert!(!ok && text.contains("--camera <CAMERA>"), "{text}");
    // No output replaces what the command reads or another of its outputs, however spelled.
    let input = scratch("own.ply");
    std::fs::copy(root().join("fixtures/plates.ply"), &input).unwrap();
    let before = std::fs::read(&input).unwrap();
    let folder = input.parent().unwrap();
    let spelled = folder.join("..").join(folder.file_name().unwrap()).join(".").join("own.ply");
    let (ok, text) = said(&["convert", input.to_str().unwrap(), spelled.to_str().unwrap()]);
    assert!(!ok && text.contains("which this command reads"), "{text}");
    assert_eq!(std::fs::read(&input).unwrap(), before, "a refused conversion wrote over its input");
    let sog = scratch("own-sog");
    std::fs::create_dir_all(&sog).unwrap();
    let (meta, beside) = (sog.join("meta.json"), sog.join("copy-meta.json"));
    let (ok, text) = said(&["convert", input.to_str().unwrap(), meta.to_str().unwrap()]);
    assert!(ok, "{text}");
    let (ok, text) = said(&["convert", meta.to_str().unwrap(), beside.to_str().unwrap()]);
    assert!(!ok && text.contains("would write its images over those of the input"), "{text}");
    let (ok, text) = said(&["render", "fixtures/cloud.ply", "-o", out, "--alpha", out]);
    assert!(!ok && text.contains("--alpha") && text.contains("is also -o's file"), "{text}");
    let share = scratch("share.acc");
    let (ok, text) = said(&["merge", share.to_str().unwrap(), "-o", share.to_str().unwrap()]);
    assert!(!ok && text.contains("which this command reads"), "{text}");
    let into = |folders: &[&str]| {
        let camera = ["undistort", "--camera", "fixtures/cloud.cameras.json", "--undistort", "gsplat"];
        said(&[&camera[..], &["--images", "fixtures"], folders].concat())
    };
    let (ok, text) = into(&["-o", "fixtures/."]);
    assert!(!ok && text.contains("-o fixtures/. is the folder of the photographs it reads"), "{text}");
    let masks = scratch("undistort-masks");
    let masks = masks.to_str().unwrap();
    let (ok, text) = into(&["-o", masks, "--masks", masks]);
    assert!(!ok && text.contains("is the folder of the undistorted photographs (-o)"), "{text}");
}

/// A world file naming a file that is not there: the error names the world file, the entry
/// and the missing file; under `target/assets/` it says how to fetch the capture.
#[test]
fn a_missing_world_entry_names_the_world_and_the_entry() {
    let world = scratch("missing-entry.toml");
    std::fs::write(
        &world,
        "[[splats]]\nbuiltin = \"demo\"\n[[meshes]]\nfile = \"pedestal.obj\"\n[[splats]]\nfile = \"target/assets/gone.splat\"\n",
    )
    .unwrap();
    let (ok, text) = said(&["render", world.to_str().unwrap(), "-o", scratch("w.png").to_str().unwrap()]);
    assert!(!ok, "{text}");
    assert!(
        text.contains("missing-entry.toml") && text.contains("splats[1]: file = \"target/assets/gone.splat\""),
        "{text}"
    );
    assert!(text.contains("cargo xtask assets"), "no hint for the repository's capture: {text}");
    std::fs::write(&world, "[[splats]]\nbuiltin = \"demo\"\n[[meshes]]\nfile = \"pedestal.obj\"\n").unwrap();
    let (ok, text) = said(&["render", world.to_str().unwrap(), "-o", scratch("w.png").to_str().unwrap()]);
    assert!(!ok && text.contains("meshes[0]: file = \"pedestal.obj\" cannot be read"), "{text}");
    assert!(!text.contains("cargo xtask assets"), "a user's own missing file gets the repository's hint: {text}");
}

/// Options the chosen method does not read are named in a warning; the summary names every
/// file written and says a deterministic method rendered one frame.
#[test]
fn ignored_options_are_named_and_the_summary_says_what_was_done() {
    let (out, alpha) = (scratch("summary.png"), scratch("summary-alpha.png"));
    let scene = ["render", "fixtures/cloud.ply", "--camera", "fixtures/cloud.cameras.json", "--backend", "cpu"];
    let files = ["-o", out.to_str().unwrap(), "--alpha", alpha.to_str().unwrap()];
    let (ok, text) = said(&[&scene[..], &files, &["--raster-samples", "4", "--early-stop", "--spp", "8"]].concat());
    assert!(ok, "{text}");
    for flag in ["--raster-samples", "--early-stop"] {
        assert!(text.contains(&format!("warning: {flag} does not apply to exact")), "{flag}: {text}");
    }
    assert!(text.contains("1 frame (deterministic: --spp 8 adds nothing)"), "{text}");
    assert!(text.contains(&format!("{}, {}", out.display(), alpha.display())), "the summary omits --alpha: {text}");
    let (ok, text) = said(&[&scene[..], &files, &["--method", "stochastic", "--spp", "2", "--k", "4"]].concat());
    assert!(ok && text.contains("stochastic, 2 spp") && text.contains("warning: --k does not apply"), "{text}");
    let (ok, text) = said(&[&scene[..], &files, &["--method", "kbuffer", "--k", "4"]].concat());
    assert!(ok && !text.contains("warning"), "kbuffer reads --k: {text}");
    // Render settings of the splatting path alone are named beside a ray-tracing method.
    let splatting = ["--near-plane", "0.5", "--raster-iso-threshold", "0.5"];
    let (ok, text) = said(&[&scene[..], &files, &splatting].concat());
    for flag in ["--near-plane", "--raster-iso-threshold"] {
        assert!(ok && text.contains(&format!("warning: {flag} applies to the splatting methods")), "{text}");
    }
    let (ok, text) = said(&[&scene[..], &files, &splatting, &["--method", "raster-sorted"]].concat());
    assert!(ok && !text.contains("applies to the splatting methods"), "raster-sorted reads them: {text}");
    let (ok, text) = said(&[&scene[..], &files, &["--method", "stochastic-splat", "--raster-samples", "4"]].concat());
    assert!(ok && !text.contains("warning"), "stochastic-splat reads --raster-samples: {text}");
    // A world set up for the path tracer, rendered without --pipeline path.
    let world = scratch("path-world.toml");
    std::fs::write(&world, "[environment]\ncolor = [0.2, 0.2, 0.2]\n[[splats]]\nbuiltin = \"demo\"\n").unwrap();
    let small = ["--width", "32", "--height", "24", "-o", out.to_str().unwrap()];
    let (ok, text) = said(&[&["render", world.to_str().unwrap()][..], &small].concat());
    assert!(ok && text.contains("warning: the world sets up the path tracer"), "{text}");
    let (ok, text) =
        said(&[&["render", world.to_str().unwrap(), "--pipeline", "path", "--spp", "1"][..], &small].concat());
    assert!(ok && !text.contains("warning"), "{text}");
}

/// `splat info` says which way is up: measured from the views with `--camera`, with advice
/// without; the framing of a scene file without cameras says the same.
#[test]
fn info_and_framing_say_which_way_is_up() {
    let views = scratch("upside-down.cameras.json");
    let down = splat_core::glam::Vec3::new(0.0, -1.0, 0.0);
    let cameras: Vec<_> = [(0.0, 4.0), (3.0, 2.0), (-2.0, 3.0)]
        .map(|(x, z)| {
            splat_core::Camera::look_at((x, -0.5, z).into(), splat_core::glam::Vec3::ZERO, down, 50.0, 64, 48).unwrap()
        })
        .to_vec();
    splat_io::cameras::write_cameras(&views, &cameras).unwrap();
    let o = splat(&["info", "fixtures/cloud.ply", "--camera", views.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success() && text.contains("the mean of 3 views: frame with --up 0,-1,0"), "{text}");
    assert!(text.contains("lenses     a pinhole lens (3 views)\n") && !text.contains("--undistort"), "{text}");
    let o = splat(&["info", "fixtures/cloud.ply"]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("usually -y up"));
    let out = scratch("framed.png");
    let (ok, text) =
        said(&["render", "fixtures/cloud.ply", "--width", "32", "--height", "24", "-o", out.to_str().unwrap()]);
    assert!(ok && text.contains("note: no --camera") && text.contains("--up 0,-1,0"), "{text}");
    let (ok, text) = said(&[
        "render",
        "fixtures/cloud.ply",
        "--up",
        "0,-1,0",
        "--width",
        "32",
        "--height",
        "24",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(ok && !text.contains("note:"), "an explicit --up still gets the note: {text}");
}

/// Help text: each command's own options under their own heading, sizes with their defaults,
/// defaults stated once.
#[test]
fn help_puts_options_under_their_own_headings() {
    let help = |args: &[&str]| String::from_utf8_lossy(&splat(args).stdout).into_owned();
    for (command, option) in [("converge", "--max-spp"), ("bench", "--repeat")] {
        let text = help(&[command, "--help"]);
        let heading =
            text.find("\nMeasurement:\n").unwrap_or_else(|| panic!("{command}: no Measurement heading:\n{text}"));
        let reading = text.find("\nReading scene files:\n").expect("reading heading");
        let at = text.find(&format!("  {option}")).expect("the option");
        assert!(
            at > heading && (reading < heading || at < reading),
            "{command}: {option} is not under Measurement:\n{text}"
        );
    }
    let render = help(&["render", "--help"]);
    assert!(render.contains("640 for render") && render.contains("480 for render"), "{render}");
    let blend = render.find("      --blend <BLEND>").unwrap();
    let blend = &render[blend..blend + render[blend..].find("\n      --").unwrap_or(400)];
    assert_eq!(blend.to_lowercase().matches("default").count(), 1, "--blend states its default twice: {blend}");
}

/// On a machine without a desktop session (`XDG_RUNTIME_DIR` unset), `--backend gpu` prints
/// nothing of the graphics stack's: Mesa's device-select layer, loaded into every Vulkan
/// process, would print "error: XDG_RUNTIME_DIR is invalid or not set" twice (seen with the
/// switch taken out of `main`), and `splat` turns it off.
#[test]
fn the_gpu_backend_is_quiet_without_a_desktop_session() {
    let out = scratch("quiet-gpu.png");
    let o = Command::new(env!("CARGO_BIN_EXE_splat"))
        .args(["render", "--width", "32", "--height", "24", "--backend", "gpu", "-o", out.to_str().unwrap()])
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .current_dir(root())
        .output()
        .unwrap();
    if !o.status.success() {
        return gpu_missing(&stderr(&o));
    }
    let noise: Vec<_> = stderr(&o)
        .lines()
        .filter(|l| !l.starts_with("rendering on") && !l.starts_with("rendered"))
        .map(String::from)
        .collect();
    assert!(noise.is_empty(), "the GPU backend printed more than its two lines: {noise:?}");
}

/// `--preset` sets what a trainer's renderer assumes: `3dgrt` renders as `--kernel-degree 4`
/// with its cutoff given on its own (and not as the default Gaussian kernel), `gsplat-antialiased`
/// sets the screen filter, `splat info` prints the preset with its extent and response, and a
/// splatting render says where it departs from the preset's renderer.
#[test]
fn presets_set_what_their_trainer_assumes() {
    use splat_core::trainer::Preset;
    let render = |extra: &[&str], name: &str| {
        let out = scratch(name);
        let args = ["render", "fixtures/layers.ply", "--camera", "fixtures/layers.cameras.json", "--width", "48"];
        let o =
            splat(&[&args[..], &["--height", "36", "--backend", "cpu", "-o", out.to_str().unwrap()], extra].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        npy(&out)
    };
    let cutoff = format!("{}", Preset::ThreeDgrt.cutoff());
    let preset = render(&["--preset", "3dgrt"], "preset-3dgrt.npy");
    let by_hand = render(&["--kernel-degree", "4", "--cutoff", &cutoff], "preset-by-hand.npy");
    let default = render(&[], "preset-default.npy");
    assert_eq!(preset, by_hand, "--preset 3dgrt is --kernel-degree 4 --cutoff {cutoff}");
    assert!(rmse(&preset, &default) > 1e-3, "the preset changes nothing");
    let info = splat(&["info", "fixtures/layers.ply", "--preset", "gsplat-antialiased"]);
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(
        text.contains("preset     gsplat antialiased") && text.contains("2D filter  gsplat's antialiased mode"),
        "{text}"
    );
    assert!(text.contains("the file names 3dgs"), "{text}");
    let splatted = |extra: &[&str]| {
        let args = ["render", "fixtures/layers.ply", "--method", "raster-sorted", "--width", "16", "--height", "12"];
        let out = scratch("preset-raster.npy");
        let o = splat(&[&args[..], &["--backend", "cpu", "-o", out.to_str().unwrap()], extra].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        stderr(&o)
    };
    let note = splatted(&["--preset", "3dgrt"]);
    assert!(note.contains("3DGRT composites each ray's hits in their own order"), "{note}");
    let note = splatted(&["--preset", "3dgut", "--response", "projected"]);
    assert!(note.contains("3dgut evaluates its particles along each ray"), "{note}");
    let info = splat(&["info", "fixtures/layers.ply", "--preset", "3dgut"]);
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(text.contains("response along-ray") && text.contains("extent 3dgs"), "{text}");
}

/// `--shadows sorted` keeps a world's sorted-shadow settings (it used to reset k, threshold and
/// tint to their defaults), the `--shadow-*` options change them, and the sorted ones are
/// refused on shadows that do not read them.
#[test]
fn shadow_options_keep_the_worlds_and_change_what_they_name() {
    let lit = std::fs::read_to_string(root().join("fixtures/worlds/demo-lit.toml")).unwrap();
    let world = lit.replace("kind = \"stochastic\"", "kind = \"sorted\"\nk = 2\nthreshold = 0.5\ncolored = 0.6");
    let path = scratch("sorted-shadows.toml");
    std::fs::write(&path, world).unwrap();
    let render = |extra: &[&str], name: &str| {
        let out = scratch(name);
        let args = ["render", path.to_str().unwrap(), "--width", "40", "--height", "30", "--backend", "cpu"];
        let o = splat(&[&args[..], &["-o", out.to_str().unwrap()], extra].concat());
        (o.status.success().then(|| npy(&out)), stderr(&o))
    };
    let (world, e) = render(&[], "shadows-world.npy");
    let world = world.unwrap_or_else(|| panic!("{e}"));
    let (named, e) = render(&["--shadows", "sorted"], "shadows-named.npy");
    assert_eq!(named.unwrap_or_else(|| panic!("{e}")), world, "--shadows sorted resets the world's settings");
    let (by_flags, e) = render(
        &["--shadows", "sorted", "--shadow-k", "18", "--shadow-threshold", "0.8", "--shadow-colored", "0"],
        "shadows-defaults.npy",
    );
    let by_flags = by_flags.unwrap_or_else(|| panic!("{e}"));
    assert!(rmse(&by_flags, &world) > 1e-4, "the shadow options change nothing");
    let (refused, e) = render(&["--shadows", "exact", "--shadow-k", "4"], "shadows-refused.npy");
    assert!(refused.is_none() && e.contains("--shadow-k sets sorted shadows") && e.contains("--shadows sorted"), "{e}");
}

/// `--pixel-filter box`, `--aperture` and auto-focus (`--focus-at`) on the ray tracer, the oracle
/// and splatting: a deterministic method then renders every frame, the same seed repeats, the
/// lens changes the image; a focus without a lens and a pixel outside the image are refused with
/// the reason; the GPU hybrid draws the CPU's frames.
#[test]
fn depth_of_field_and_the_box_filter_on_every_pipeline() {
    let run = |extra: &[&str], out: &std::path::Path| {
        let mut args = vec!["render", "--width", "48", "--height", "36", "--spp", "8", "--backend", "cpu", "-o"];
        args.push(out.to_str().unwrap());
        args.extend_from_slice(extra);
        splat(&args)
    };
    let lens = ["--pixel-filter", "box", "--aperture", "0.1", "--focus-at", "24,18"];
    for method in ["exact", "oracle", "raster-sorted", "stochastic-splat"] {
        let (a, b, pinhole) = (
            scratch(&format!("dof-{method}-a.npy")),
            scratch(&format!("dof-{method}-b.npy")),
            scratch(&format!("dof-{method}-p.npy")),
        );
        let o = run(&[&["--method", method][..], &lens].concat(), &a);
        assert!(o.status.success(), "{method}: {}", stderr(&o));
        assert!(stderr(&o).contains("8 spp"), "{method} renders every frame: {}", stderr(&o));
        assert!(run(&[&["--method", method][..], &lens].concat(), &b).status.success());
        assert!(run(&["--method", method], &pinhole).status.success());
        assert_eq!(npy(&a), npy(&b), "{method}: the same seed gave two images");
        let d = rmse(&npy(&a), &npy(&pinhole));
        assert!(d > 5e-3, "{method}: the lens and the filter change nothing (RMSE {d})");
    }
    let never = scratch("dof-never.npy");
    let o = run(&["--focus-at", "24,18"], &never);
    assert!(stderr(&o).contains("add --aperture"), "{}", stderr(&o));
    let o = run(&["--aperture", "0.1", "--focus-at", "480,18"], &never);
    assert!(stderr(&o).contains("outside the 48×36 image"), "{}", stderr(&o));
    assert!(!never.exists());
    // The GPU hybrid draws the same frames: each frame's first hits through that frame's camera.
    let hybrid = [&["--pipeline", "hybrid", "--method", "raster-sorted"][..], &lens].concat();
    let (cpu, gpu) = (scratch("dof-hybrid-cpu.npy"), scratch("dof-hybrid-gpu.npy"));
    assert!(run(&hybrid, &cpu).status.success());
    let size = ["render", "--width", "48", "--height", "36", "--spp", "8", "--backend", "gpu", "-o"];
    let o = splat(&[&size[..], &[gpu.to_str().unwrap()], &hybrid].concat());
    if !o.status.success() {
        return gpu_missing(&stderr(&o));
    }
    let (a, b) = (npy(&cpu), npy(&gpu));
    let mean = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).sum::<f32>() / a.len() as f32;
    assert!(mean < 1e-5, "the GPU hybrid through a lens: mean difference {mean}");
}

/// `splat info` of a world file lists its splats, lights, camera and each mesh with its
/// material, as the world reader holds them.
#[test]
fn info_lists_a_worlds_meshes_and_their_materials() {
    let o = splat(&["info", "fixtures/worlds/demo-meshes.toml"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let world = splat_io::world::read_world(&root().join("fixtures/worlds/demo-meshes.toml")).unwrap();
    let triangles: usize = world.meshes.iter().map(|(m, _)| m.triangles.len()).sum();
    let header = format!("{} meshes ({triangles} triangles)", world.meshes.len());
    assert!(text.contains(&header) && text.contains("camera     eye"), "{text}");
    for (i, (mesh, m)) in world.meshes.iter().enumerate() {
        let line = format!("mesh {i:<5} {} triangles: colour", mesh.triangles.len());
        let shares = format!("transmission {} (ior {})", m.transmission, m.ior);
        assert!(text.lines().any(|l| l.starts_with(&line) && l.contains(&shares)), "mesh {i}: {text}");
    }
}

/// A world file's `pixel_filter` and `sh_storage` are the render's unless the flags say
/// otherwise: the world with `box` renders what the world without it renders under
/// `--pixel-filter box`, and `--pixel-filter center` over it what the plain world renders; the
/// same for `u8` storage of the SH-3 cloud.
#[test]
fn a_world_files_pixel_filter_and_sh_storage_are_the_defaults() {
    let camera = "[camera]\neye = [0, 0.4, 3]\ntarget = [0, 0.4, 0]\n";
    let (boxed, plain) = (scratch("filter-box.toml"), scratch("filter-plain.toml"));
    std::fs::write(&boxed, format!("{camera}pixel_filter = \"box\"\n[[splats]]\nbuiltin = \"demo\"\n")).unwrap();
    std::fs::write(&plain, format!("{camera}[[splats]]\nbuiltin = \"demo\"\n")).unwrap();
    let render = |world: &PathBuf, extra: &[&str], name: &str| {
        let out = scratch(name);
        let mut args = vec!["render", world.to_str().unwrap(), "--width", "32", "--height", "24", "--spp", "4"];
        args.extend_from_slice(&["--method", "exact", "--backend", "cpu", "-o", out.to_str().unwrap()]);
        args.extend_from_slice(extra);
        let o = splat(&args);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        npy(&out)
    };
    let world_box = render(&boxed, &[], "filter-world-box.npy");
    assert_eq!(world_box, render(&plain, &["--pixel-filter", "box"], "filter-flag-box.npy"));
    let centre = render(&plain, &[], "filter-plain.npy");
    assert_eq!(render(&boxed, &["--pixel-filter", "center"], "filter-flag-center.npy"), centre);
    assert!(rmse(&world_box, &centre) > 1e-3, "the box filter changed nothing");
    // The world's SH storage likewise: u8 in the file is `--sh-storage u8`, and the flag wins.
    let u8 = scratch("storage-u8.toml");
    std::fs::write(&u8, format!("sh_storage = \"u8\"\n{camera}[[splats]]\nbuiltin = \"cloud\"\n")).unwrap();
    let cloud = scratch("storage-plain.toml");
    std::fs::write(&cloud, format!("{camera}[[splats]]\nbuiltin = \"cloud\"\n")).unwrap();
    let world_u8 = render(&u8, &[], "storage-world-u8.npy");
    assert_eq!(world_u8, render(&cloud, &["--sh-storage", "u8"], "storage-flag-u8.npy"));
    let f32 = render(&cloud, &[], "storage-plain.npy");
    assert_eq!(render(&u8, &["--sh-storage", "f32"], "storage-flag-f32.npy"), f32);
    assert!(world_u8 != f32, "u8 storage rounded nothing");
}

/// `splat hit-distance` (vk_gaussian_splatting Lighting §1.4.3): a table row per surface and the
/// four depth images side by side; the icosahedron's surface differs from the maximum density's.
#[test]
fn hit_distance_compares_the_picked_surfaces() {
    let prefix = scratch("hits");
    let o = splat(&[
        "hit-distance",
        "fixtures/cloud.ply",
        "--camera",
        "fixtures/cloud.cameras.json",
        "--width",
        "48",
        "--height",
        "36",
        "-o",
        prefix.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let table = String::from_utf8_lossy(&o.stdout).into_owned();
    for row in ["ray tracing, icosahedron", "ray tracing, mean", "ray tracing, center", "rasterization, billboard"] {
        assert!(table.contains(&format!("| {row} |")), "{table}");
    }
    let ico = table.lines().find(|l| l.contains("icosahedron")).unwrap();
    assert!(!ico.contains("| 0.000 % |"), "the proxy moves the surface: {ico}");
    let image = splat_io::image::read_image(&prefix.with_extension("png")).unwrap();
    assert_eq!((image.width(), image.height()), (4 * 48, 36));
}

/// `--accumulation` stores the running mean as vk_gaussian_splatting's formats do: each format
/// gives its own image of the same frames, and an unknown one is refused with the list.
#[test]
fn the_accumulation_format_is_an_option_of_render() {
    let render = |format: &str| {
        let out = scratch(&format!("acc-{format}.npy"));
        let o = splat(&[
            "render",
            "--method",
            "stochastic",
            "--spp",
            "64",
            "--width",
            "32",
            "--height",
            "24",
            "--backend",
            "cpu",
            "--accumulation",
            format,
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{format}: {}", stderr(&o));
        npy(&out)
    };
    let (full, half, byte) = (render("f32"), render("f16"), render("unorm8"));
    assert!(
        rmse(&full, &half) > 0.0 && rmse(&full, &byte) > rmse(&full, &half),
        "{} {}",
        rmse(&full, &half),
        rmse(&full, &byte)
    );
    let o = splat(&["render", "--accumulation", "f8", "-o", scratch("never-acc.png").to_str().unwrap()]);
    assert!(stderr(&o).contains("f16") && stderr(&o).contains("unorm8"), "{}", stderr(&o));
}

/// A look-at vector whose first number is negative is a value, not a flag (clap took
/// `--eye -3,-1,2.5` for an unknown option `-3`).
#[test]
fn camera_vectors_may_start_with_a_minus() {
    let out = scratch("minus.png");
    let o = splat(&[
        "render",
        "--eye",
        "-3,-1,2.5",
        "--target",
        "-0.1,0,0",
        "--up",
        "-0,1,0",
        "--width",
        "8",
        "--height",
        "6",
        "--backend",
        "cpu",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = splat(&["render", "--eye", "--target", "0,0,0", "-o", out.to_str().unwrap()]);
    assert!(!o.status.success() && stderr(&o).contains("--target"), "{}", stderr(&o));
}

/// `splat reproduce --quick` runs every experiment of the sources through the CLI's own commands
/// on the demo scene and writes each report beside the published numbers; `--list` names them,
/// an unknown name is refused with the list, and a full run without the capture says how to
/// fetch it before any work.
#[test]
fn reproduce_runs_every_experiment_of_the_sources() {
    let list = splat(&["reproduce", "--list"]);
    assert!(list.status.success(), "{}", stderr(&list));
    let names: Vec<String> = String::from_utf8_lossy(&list.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect();
    for expected in [
        "sun-tables-1-3",
        "sun-tables-4-5",
        "sun-figure-3",
        "sun-figure-6",
        "sun-figure-7",
        "lk-table-1",
        "lk-triangle-size",
        "lk-figure-1",
        "lk-figure-3b",
        "lk-figure-6",
        "lk-figure-8",
        "lk-morton",
        "vk-hit-distance",
    ] {
        assert!(names.iter().any(|n| n == expected), "{expected} missing from {names:?}");
    }
    let out = scratch("reproduction");
    let _ = std::fs::remove_dir_all(&out);
    let o = splat(&["reproduce", "--quick", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let index = std::fs::read_to_string(out.join("reproduction.md")).unwrap();
    for name in &names {
        assert!(index.contains(&format!("[{name}]({name}.md)")), "{name} missing from the index:\n{index}");
        let report = std::fs::read_to_string(out.join(format!("{name}.md"))).unwrap();
        for section in ["## Published", "## What differs", "## Here", "`splat "] {
            assert!(report.contains(section), "{name}: no {section}:\n{report}");
        }
    }
    let figure = std::fs::read_to_string(out.join("sun-figure-3.md")).unwrap();
    assert!(figure.contains("PSNR") && figure.contains("![ours-center.png](sun-figure-3/ours-center.png)"), "{figure}");
    let o = splat(&["reproduce", "table-9", "--quick", "-o", out.to_str().unwrap()]);
    assert!(!o.status.success() && stderr(&o).contains("sun-tables-4-5"), "{}", stderr(&o));
    let o = splat(&["reproduce", "--capture", "/nonexistent.splat", "-o", out.to_str().unwrap()]);
    assert!(!o.status.success() && stderr(&o).contains("cargo xtask assets"), "{}", stderr(&o));
}

/// `splat info`'s memory line: the bytes held and the process's peak resident set.
fn info_memory(scene: &std::path::Path) -> (f64, f64) {
    let o = splat(&["info", scene.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let line = text.lines().find(|l| l.starts_with("memory")).unwrap_or_else(|| panic!("no memory line: {text}"));
    let number_before = |marker: &str| -> f64 {
        let head = &line[..line.find(marker).unwrap_or_else(|| panic!("{marker} in {line}"))];
        head.trim_end().rsplit(' ').next().unwrap().parse().unwrap()
    };
    let peak = line.rsplit("peak ").next().expect("Linux reports the peak").trim_end_matches(" MB");
    (number_before(" MB held") * 1e6, peak.parse::<f64>().unwrap() * 1e6)
}

/// A mid-sized capture (500,000 splats at SH degree 3, a 124 MB binary `.ply`) loads in
/// little more memory than the file: the particles held ≤ 1.25 × the file, and the process's
/// peak resident set, less that of `splat info` on a 3,000-splat file, ≤ 1.25 × the file too
/// (the reader streams the body in chunks; it held the whole file besides the particles before,
/// 2.06 × it at peak).
#[test]
fn a_large_ply_loads_in_little_more_memory_than_the_file() {
    let n = 500_000;
    let particles = (0..n)
        .map(|i| {
            let t = i as f32 * 1e-4;
            let sh: [glam::Vec3; 16] =
                std::array::from_fn(|k| glam::Vec3::new(t.sin(), k as f32 * 0.01, t.cos()) * 0.1);
            splat_core::Particle::new(
                glam::Vec3::new(t.sin(), t.cos(), t),
                glam::Vec3::new(0.01, 0.02, 0.03),
                glam::Quat::from_rotation_z(t),
                0.5,
                sh,
            )
            .unwrap()
        })
        .collect();
    let path = scratch("large.ply");
    let scene = splat_core::Scene::new(particles, 3);
    splat_io::ply::write_ply(&path, &scene, splat_io::ply::PlyFormat::BinaryLittleEndian).unwrap();
    drop(scene);
    let file = std::fs::metadata(&path).unwrap().len() as f64;
    let (held, peak) = info_memory(&path);
    let (_, baseline) = info_memory(std::path::Path::new("fixtures/cloud.ply"));
    eprintln!(
        "{n} splats, {:.1} MB file: {:.1} MB held ({:.2} ×), peak {:.1} MB less {:.1} MB baseline ({:.2} ×)",
        file / 1e6,
        held / 1e6,
        held / file,
        peak / 1e6,
        baseline / 1e6,
        (peak - baseline) / file
    );
    assert!(held <= 1.25 * file, "held {held} > 1.25 × {file}");
    assert!(peak - baseline <= 1.25 * file, "peak {peak} − {baseline} > 1.25 × {file}");
    let _ = std::fs::remove_file(&path);
}
