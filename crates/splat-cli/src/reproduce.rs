//! `splat reproduce`: the sources' experiments by name, each run through this binary's own
//! commands and written beside the numbers the source published.
//!
//! An experiment is a list of `splat` command lines (the commands a user would type), the
//! source's table copied with its caption, and what is known to differ. Each experiment writes
//! `OUT/NAME.md` (the published table, each command, its output and wall time) and the images
//! and CSV its commands write; `OUT/reproduction.md` indexes them. `--quick` runs every
//! experiment on the built-in demo scene at a few pixels, which is what the tests run so that
//! the commands cannot rot; the full run reads the bonsai capture of `cargo xtask assets`.

use anyhow::{Context, Result, bail};
use clap::Args;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `splat reproduce`.
#[derive(Args)]
pub struct ReproduceArgs {
    /// Experiments to run (all by default); `--list` names them.
    pub names: Vec<String>,
    /// List the experiments with their sources and stop.
    #[arg(long)]
    pub list: bool,
    /// Every experiment on the built-in demo scene at a few pixels (seconds each): checks that
    /// the commands run, measures nothing.
    #[arg(long)]
    pub quick: bool,
    /// Directory of the report (reproduction.md, one NAME.md per experiment, images, CSV).
    #[arg(short, long, default_value = "reproduction")]
    pub output: PathBuf,
    /// The trained capture of the full run (a .splat or .ply). The experiments read it and the
    /// repository's world files by their paths from the repository root: run from there.
    #[arg(long, default_value = "target/assets/bonsai-7k-mini.splat")]
    pub capture: PathBuf,
    /// The backend of the timing experiments (Sun et al. Tables 1, 3, 4–5); gpu also adds the
    /// GPU's rows (S = 4, 8, 16) to Laine & Karras's Table 1.
    #[arg(long, value_enum, default_value = "cpu")]
    pub backend: crate::args::BackendArg,
}

/// One experiment: where it comes from, what the source published, the commands that
/// regenerate it here and what is known to differ.
struct Experiment {
    name: &'static str,
    /// The source's name for it.
    source: &'static str,
    /// The published numbers, as Markdown, with their caption's claim.
    published: &'static str,
    /// What differs from the source's setup, said before any number is read.
    differs: &'static str,
    /// The command lines (arguments after `splat`) of a run.
    commands: fn(&Setup) -> Vec<Vec<String>>,
}

/// `splat stratify ARGS --frames FRAMES -o OUT`.
fn stratify(args: &[&str], frames: &str, out: String) -> Vec<String> {
    let mut line = vec!["stratify".to_string()];
    line.extend(args.iter().map(|a| a.to_string()));
    line.extend(["--frames".into(), frames.into(), "-o".into(), out]);
    line
}

/// What the commands of a run read and write.
struct Setup {
    /// The scene arguments: the capture from its standard view, or nothing (the demo scene).
    scene: Vec<String>,
    /// Image size of the quality experiments (and the paper's 1200 × 800 in a full run).
    size: (u32, u32),
    /// Image size of the timing sweeps (1024 samples a pixel).
    sweep_size: (u32, u32),
    /// Largest spp of the convergence curves.
    max_spp: u32,
    backend: String,
    /// The experiment's own folder.
    dir: PathBuf,
    quick: bool,
}

impl Setup {
    /// `args` after the scene and its size.
    fn scene_at(&self, command: &str, (w, h): (u32, u32), args: &[&str]) -> Vec<String> {
        let mut v = vec![command.to_string()];
        v.extend(self.scene.iter().cloned());
        v.extend(["--width".into(), w.to_string(), "--height".into(), h.to_string()]);
        v.extend(args.iter().map(|s| s.to_string()));
        v
    }

    /// A path in the experiment's folder.
    fn file(&self, name: &str) -> String {
        self.dir.join(name).to_string_lossy().into_owned()
    }
}

/// The experiments, in the order of the report.
const EXPERIMENTS: [Experiment; 14] = [
    Experiment {
        name: "sun-tables-1-3",
        source: "Sun et al. 2025, Tables 1 and 3 (offline seconds at 64, 256 and 1024 spp; interactive frames a second against 3DGS rasterization)",
        published: "Table 1 (RTX 3090 and Ryzen 9 5950X, 1200 × 800, OursMean, seconds), the three 3DGS captures:\n\n\
| asset | #G (M) | 64 spp GPU | 64 spp CPU | 256 spp GPU | 256 spp CPU | 1024 spp GPU | 1024 spp CPU |\n\
|---|---:|---:|---:|---:|---:|---:|---:|\n\
| drjohnson | 3.41 | 0.86 | 46.78 | 3.35 | 191.33 | 13.41 | 759.40 |\n\
| playroom | 2.55 | 0.60 | 31.68 | 2.43 | 127.39 | 9.32 | 511.90 |\n\
| room | 1.59 | 0.61 | 31.93 | 2.38 | 126.95 | 9.43 | 508.62 |\n\n\
Table 3 (frames a second): 3DGS rasterization 324 / 282 / 314; OursMean on the RTX 3090 76.4 / 109.9 / 108.6, on the CPU 1.3 / 2.0 / 2.0.",
        differs: "Another asset (the bonsai capture of `cargo xtask assets`, 273 k splats, against 1.6–3.4 M) \
and other hardware (this machine's CPU threads; a wgpu compute tracer without RT cores on the GPU). \
Compare the shapes: time linear in spp, the CPU's spp rate, stochastic against 3DGS rasterization in one run.",
        commands: |s| {
            let mut runs: Vec<Vec<String>> = [64, 256, 1024]
                .iter()
                .map(|spp| {
                    let spp = if s.quick { (spp / 64).to_string() } else { spp.to_string() };
                    s.scene_at(
                        "bench",
                        s.sweep_size,
                        &["--methods", "stochastic", "--repeat", "1", "--spp", &spp, "--backend", &s.backend],
                    )
                })
                .collect();
            runs.push(s.scene_at(
                "bench",
                s.size,
                &["--methods", "raster-sorted,stochastic-splat", "--repeat", "3", "--backend", &s.backend],
            ));
            runs.push(s.scene_at(
                "bench",
                s.size,
                &["--methods", "stochastic", "--repeat", "3", "--backend", &s.backend],
            ));
            runs
        },
    },
    Experiment {
        name: "sun-tables-4-5",
        source: "Sun et al. 2025, Tables 4–5 (m traversals × n samples of stochastic-n, 1024 samples a pixel)",
        published: "Speed-up over 1024 × 1 (drjohnson; Table 5 on Windows, 4 × 256 from Table 4 on MacOS as its ratio to 16 × 64):\n\n\
| m × n | RTX 3090 | Ryzen 9 5950X |\n\
|---|---:|---:|\n\
| 512 × 2 | 1.81× | 1.57× |\n\
| 256 × 4 | 3.11× | 2.41× |\n\
| 128 × 8 | 4.65× | 3.54× |\n\
| 64 × 16 | 1.25× | 4.48× |\n\
| 32 × 32 | 0.33× | 5.21× |\n\
| 16 × 64 | 0.11× | 5.56× |\n\
| 4 × 256 | (Metal: 1.14× of 16 × 64) | (0.99× of 16 × 64) |\n\n\
\"For the NVIDIA GPU, multi-sampling of 8 is the most optimal ... The CPU implementation persistently shows better performance with higher multi-sampling.\"",
        differs: "Another asset and hardware. The CPU holds up to 256 samples in a traversal; the GPU kernel \
holds 64 and runs 4 × 256 as 16 × 64 (the same slots and image, another cost; the row says so).",
        commands: |s| {
            vec![s.scene_at("bench", s.sweep_size, &["--sweep", "mn", "--repeat", "1", "--backend", &s.backend])]
        },
    },
    Experiment {
        name: "sun-figure-3",
        source: "Sun et al. 2025, Figure 3 (3DGS rasterization against OursMean and OursCenter on 3DGS-trained captures)",
        published: "Images only: \"we see some quality degradation in the second column [OursMean] ... [OursCenter] producing images closely matching rasterization.\"",
        differs: "The 3DGS rasterizer here is `raster-sorted`, pinned to a port of the INRIA forward pass \
(`trainer_parity.rs`); the ray-traced columns are the converged `exact` (the expectation of the stochastic \
renders the figure shows). The claim is checked as PSNR against the rasterizer: OursCenter should be the closer.",
        commands: |s| {
            let render = |name: &str, extra: &[&str]| {
                let out = s.file(&format!("{name}.png"));
                let mut a = vec!["--method"];
                a.extend_from_slice(extra);
                a.extend_from_slice(&["--backend", "cpu", "-o", &out]);
                s.scene_at("render", s.size, &a)
            };
            let compare =
                |test: &str| vec!["compare".to_string(), s.file("3dgs-raster.png"), s.file(&format!("{test}.png"))];
            vec![
                render("3dgs-raster", &["raster-sorted"]),
                render("ours-mean", &["exact", "--hit-distance", "mean"]),
                render("ours-center", &["exact", "--hit-distance", "center"]),
                compare("ours-mean"),
                compare("ours-center"),
            ]
        },
    },
    Experiment {
        name: "sun-figure-6",
        source: "Sun et al. 2025, Figure 6 (convergence of the stochastic ray tracer, 1 to 64 spp)",
        published: "Images only: \"1 spp already produces plausible rendering, and most noise is eliminated with 64 spp or less.\"",
        differs: "Measured, not shown: RMSE of Algorithm 1 against `exact` at each spp and its log–log \
slope (−½ for an unbiased Monte Carlo estimator).",
        commands: |s| {
            let max = s.max_spp.to_string();
            let out = s.file("convergence");
            vec![s.scene_at("converge", s.size, &["--methods", "stochastic", "--max-spp", &max, "-o", &out])]
        },
    },
    Experiment {
        name: "sun-figure-7",
        source: "Sun et al. 2025, Figure 7 (the bias of 3DGRT's stochastic depth sampling at k = 1)",
        published: "Images at 64 spp only: \"The bias of stochastic depth sampling becomes obvious when setting k = 1. In the left zoom-in, the cloth color through the glass becomes more yellow. In the right zoom-in, the caustics from the refractions and reflections are dimmer.\"",
        differs: "Measured in the ray tracer on the bonsai against `exact`, where a bias shows as a floor under \
the RMSE while Algorithm 1 keeps falling as 1/√spp, for depth sampling (the project's `depth-sampling-k`, CPU \
only) at k = 1 and k = 16. In the path tracer through glass (`fixtures/worlds/bonsai-path.toml`, the paper's \
setting) the paths' own noise at 64 spp hides it: RMSE 0.0424 for Algorithm 1 against 0.0428 for k = 1 at \
150 × 100 (`splat converge fixtures/worlds/bonsai-path.toml --pipeline path --methods \
stochastic,depth-sampling-k --k 1 --width 150 --height 100 --max-spp 64 --reference-spp 1024`).",
        commands: |s| {
            let max = if s.quick { "4" } else { "256" };
            [("1", "stochastic,depth-sampling-k"), ("16", "depth-sampling-k")]
                .iter()
                .map(|(k, methods)| {
                    let out = s.file(&format!("convergence-k{k}"));
                    s.scene_at(
                        "converge",
                        s.sweep_size,
                        &["--methods", methods, "--k", k, "--max-spp", max, "-o", &out],
                    )
                })
                .collect()
        },
    },
    Experiment {
        name: "lk-table-1",
        source: "Laine & Karras 2011, Table 1 (RMSE of stratified ÷ Enderton et al. at 4 to 64 samples a pixel)",
        published: "RMSE in 8-bit colour units against thousands of samples a pixel, stratified (ours) and Enderton et al. (comp.):\n\n\
| spp | motor ours | motor comp. | ratio | cloth ours | cloth comp. | ratio |\n\
|---:|---:|---:|---:|---:|---:|---:|\n\
| 4 | 29.5 | 36.3 | 0.81 | 17.0 | 19.3 | 0.88 |\n\
| 8 | 17.9 | 25.3 | 0.71 | 9.7 | 12.3 | 0.79 |\n\
| 16 | 10.3 | 17.2 | 0.60 | 5.6 | 8.4 | 0.67 |\n\
| 32 | 6.3 | 12.1 | 0.52 | 3.3 | 5.8 | 0.57 |\n\
| 64 | 4.0 | 8.7 | 0.46 | 2.0 | 4.1 | 0.49 |",
        differs: "The motor and the cloth are generated here (`splat_core::lk_scenes`: white parts of \
α = 0.3 and a striped, folded cloth of α = 0.4, both diffuse under a headlight, the cloth's triangles in \
random order), not the paper's models; the reference is sorted compositing of the same samples (the \
methods' exact expectation) rather than thousands of samples a pixel, which leaves out the spatial \
sampling error both methods share. The gain depends on how many fragments a surface makes in a pixel: \
`lk-triangle-size` measures it.",
        commands: |s| {
            let (frames, samples, detail) = if s.quick { ("2", "4", "2") } else { ("16", "4,8,16,32,64", "32") };
            let gpu = if s.backend == "gpu" { "gpu" } else { "cpu" };
            vec![stratify(
                &["--scenes", "motor,cloth", "--samples", samples, "--detail", detail, "--backend", gpu],
                frames,
                s.file("table-1"),
            )]
        },
    },
    Experiment {
        name: "lk-triangle-size",
        source: "Laine & Karras 2011, §1.1 and §5 (Enderton et al. stratify only within a fragment; the paper's models are detailed)",
        published: "No table: the comparison method's noise falls like 1/√S in Table 1 (36.3 → 17.2 → 8.7 at 4, 16, 64 samples), \
the rate of unstratified sampling, which is what fragments covering few samples each give it.",
        differs: "The motor subdivided 4, 8, 16 and 32 times as finely (triangles from about 10 pixels to about a sixth of one): \
the experiment behind the explanation of Table 1's ratios.",
        commands: |s| {
            let (frames, samples, details): (&str, &str, &[&str]) =
                if s.quick { ("2", "4", &["1"]) } else { ("8", "4,16,64", &["4", "8", "16", "32"]) };
            details
                .iter()
                .map(|d| {
                    let out = s.file(&format!("triangle-size-{d}"));
                    stratify(&["--scenes", "motor", "--samples", samples, "--detail", d], frames, out)
                })
                .collect()
        },
    },
    Experiment {
        name: "lk-figure-1",
        source: "Laine & Karras 2011, Figure 1 (an opacity ramp, a quad of α = 0.61 and five quads of α = 0.75, 16 samples a pixel)",
        published: "Images only: Enderton et al.'s noise is clumpy and higher along the edges between the five quads; \
the stratified method's is even, with no visible edges.",
        differs: "The same three bands of white triangles on black, generated here; the tables give the RMSE of the whole image \
per pixel and of 4 × 4 pixel blocks' means (the clumps the figure shows are noise that survives that averaging).",
        commands: |s| {
            let frames = if s.quick { "2" } else { "16" };
            let args = ["--scenes", "figure-1", "--samples", "4,16"];
            let blocks = [args.as_slice(), &["--block", "4"]].concat();
            vec![stratify(&args, frames, s.file("figure-1")), stratify(&blocks, frames, s.file("figure-1-blocks"))]
        },
    },
    Experiment {
        name: "lk-figure-3b",
        source: "Laine & Karras 2011, Figure 3b (the Sobol sequence in place of the hash scramble: 8 white surfaces of α = 0.1, 8 samples a pixel)",
        published: "Images only: with Sobol's simple parity hash, significant correlations remain when several surfaces are drawn.",
        differs: "Eight stacked white planes of α = 0.1 on black; columns: Enderton, the paper's scramble, Sobol.",
        commands: |s| {
            let frames = if s.quick { "2" } else { "32" };
            vec![stratify(
                &["--scenes", "stack", "--samples", "8,16", "--variants", "paper,sobol"],
                frames,
                s.file("figure-3b"),
            )]
        },
    },
    Experiment {
        name: "lk-figure-6",
        source: "Laine & Karras 2011, Figure 6 (the cloth with its triangles in random order, with and without sorting the samples)",
        published: "Images only: without sorting, the noise is higher where the far surface was drawn first; with sorting it is the same everywhere.",
        differs: "The generated cloth (stripes and triangles in random order) at 16 samples, with triangles of a few pixels \
(detail 4) and of half a pixel (detail 16); columns: Enderton, sorted samples (the paper), unsorted.",
        commands: |s| {
            let (frames, details): (&str, &[&str]) = if s.quick { ("2", &["1"]) } else { ("16", &["4", "16"]) };
            details
                .iter()
                .map(|d| {
                    let args = ["--scenes", "cloth", "--samples", "16", "--variants", "paper,unsorted", "--detail", d];
                    stratify(&args, frames, s.file(&format!("figure-6-detail-{d}")))
                })
                .collect()
        },
    },
    Experiment {
        name: "lk-figure-8",
        source: "Laine & Karras 2011, Figure 8 (smoke of textured billboards of α = 0.05, 16 samples a pixel)",
        published: "Images only: with dozens of layers the method loses most of its effectiveness but never performs worse than the comparison.",
        differs: "64 generated billboards whose opacity fades from 0.05 at the centre to 0 at the rim (per-vertex opacities), grey on black.",
        commands: |s| {
            let frames = if s.quick { "2" } else { "16" };
            vec![stratify(&["--scenes", "smoke", "--samples", "16"], frames, s.file("figure-8"))]
        },
    },
    Experiment {
        name: "lk-morton",
        source: "Laine & Karras 2011, §3.1 (pixel indices along the Morton curve instead of the Hilbert curve)",
        published: "No numbers: a Morton curve gives every aligned 2 × 2, 4 × 4 … block the same structure, so that pixels of even and odd rows \
get different expected values; the Hilbert curve shows no structure.",
        differs: "The motor at 16 samples with both pixel orders. Here every frame starts its surface ids at a random value, so each pixel's \
expected value is right whatever the curve; what the curve can change is the noise.",
        commands: |s| {
            let (frames, detail) = if s.quick { ("2", "2") } else { ("16", "16") };
            let args = ["--scenes", "motor", "--samples", "16", "--variants", "paper,morton", "--detail", detail];
            vec![stratify(&args, frames, s.file("morton"))]
        },
    },
    Experiment {
        name: "vk-hit-distance",
        source: "vk_gaussian_splatting, Lighting §1.4.3 (the surfaces each hit distance picks)",
        published: "Images only: the icosahedron proxy, the AABB maximum density and the rasterizer's billboard give different picked surfaces.",
        differs: "The comparison as a table (share of pixels each picks, depth differences against the maximum density) and the depth images side by side.",
        commands: |s| vec![s.scene_at("hit-distance", s.size, &["-o", &s.file("hit-distance")])],
    },
    Experiment {
        name: "vk-fp16-drift",
        source: "vk_gaussian_splatting, Lighting (accumulation formats: FP16 by default, FP32 past 150–200 frames)",
        published: "Advice, no numbers: switch the accumulation to FP32 past 150–200 frames.",
        differs: "Measured as RMSE against `exact` of the same frames accumulated in f32 and in f16: where f16 leaves the f32 curve is where the advice applies.",
        commands: |s| {
            let max = if s.quick { "4" } else { "1024" };
            ["f32", "f16"]
                .iter()
                .map(|format| {
                    let out = s.file(&format!("accumulation-{format}"));
                    s.scene_at(
                        "converge",
                        s.sweep_size,
                        &["--methods", "stochastic", "--max-spp", max, "--accumulation", format, "-o", &out],
                    )
                })
                .collect()
        },
    },
];

/// Run `splat reproduce`.
pub fn run(args: ReproduceArgs) -> Result<()> {
    if args.list {
        for e in &EXPERIMENTS {
            println!("{:<16} {}", e.name, e.source);
        }
        return Ok(());
    }
    let chosen: Vec<&Experiment> = if args.names.is_empty() {
        EXPERIMENTS.iter().collect()
    } else {
        args.names
            .iter()
            .map(|n| {
                EXPERIMENTS.iter().find(|e| e.name == n).with_context(|| {
                    let names: Vec<&str> = EXPERIMENTS.iter().map(|e| e.name).collect();
                    format!("no experiment '{n}': choose among {}", names.join(", "))
                })
            })
            .collect::<Result<_>>()?
    };
    if !args.quick && !args.capture.exists() {
        bail!(
            "the capture {} is missing: run `cargo xtask assets` (or give --capture FILE), or --quick for the demo scene",
            args.capture.display()
        );
    }
    let exe = std::env::current_exe().context("finding this splat binary")?;
    std::fs::create_dir_all(&args.output).with_context(|| format!("creating {}", args.output.display()))?;
    let mut index = String::from(
        "# Reproduction\n\nEach experiment's published numbers, the commands that regenerate them here and their output.\n\n\
         | experiment | source | wall time |\n|---|---|---:|\n",
    );
    for e in chosen {
        let dir = args.output.join(e.name);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let setup = setup(&args, dir);
        let start = Instant::now();
        let report = run_experiment(&exe, e, &setup)?;
        let seconds = start.elapsed().as_secs_f64();
        let file = args.output.join(format!("{}.md", e.name));
        std::fs::write(&file, format!("{report}\nWall time of the experiment: {seconds:.1} s.\n"))
            .with_context(|| format!("writing {}", file.display()))?;
        eprintln!("{}: {seconds:.1} s, {}", e.name, file.display());
        writeln!(index, "| [{0}]({0}.md) | {1} | {seconds:.1} s |", e.name, e.source)?;
    }
    let path = args.output.join("reproduction.md");
    std::fs::write(&path, index).with_context(|| format!("writing {}", path.display()))?;
    println!("wrote {}", path.display());
    Ok(())
}

/// The setup of a run: the demo scene at a few pixels (`--quick`) or the capture from the
/// standard view (`splat_tests::bonsai_camera`'s) at the paper's sizes.
fn setup(args: &ReproduceArgs, dir: PathBuf) -> Setup {
    let backend = format!("{:?}", args.backend).to_lowercase();
    if args.quick {
        return Setup { scene: vec![], size: (24, 16), sweep_size: (6, 4), max_spp: 4, backend, dir, quick: true };
    }
    let view = ["--eye", "0,-1.5,4", "--target", "0,0.5,0", "--up", "0,-1,0"];
    let mut scene = vec![args.capture.to_string_lossy().into_owned()];
    scene.extend(view.iter().map(|s| s.to_string()));
    Setup { scene, size: (1200, 800), sweep_size: (300, 200), max_spp: 64, backend, dir, quick: false }
}

/// Run each command of `e` and write its section: the published table, then each command with
/// its output.
fn run_experiment(exe: &Path, e: &Experiment, setup: &Setup) -> Result<String> {
    let mut md = format!(
        "# {}\n\n{}\n\n## Published\n\n{}\n\n## What differs\n\n{}\n\n## Here\n\n",
        e.name, e.source, e.published, e.differs
    );
    for command in (e.commands)(setup) {
        let start = Instant::now();
        let out = std::process::Command::new(exe)
            .args(&command)
            .output()
            .with_context(|| format!("running splat {}", command.join(" ")))?;
        let seconds = start.elapsed().as_secs_f64();
        let stdout = String::from_utf8_lossy(&out.stdout);
        if !out.status.success() {
            bail!("{}: `splat {}` failed:\n{}", e.name, command.join(" "), String::from_utf8_lossy(&out.stderr));
        }
        writeln!(md, "`splat {}` ({seconds:.1} s):\n\n{}\n", command.join(" "), stdout.trim_end())?;
    }
    // The images the commands wrote, linked from the report beside the folder.
    let mut images: Vec<PathBuf> = std::fs::read_dir(&setup.dir)
        .with_context(|| format!("reading {}", setup.dir.display()))?
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    images.sort();
    for image in images {
        let name = image.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        writeln!(md, "![{name}]({}/{name})\n", e.name)?;
    }
    Ok(md)
}
