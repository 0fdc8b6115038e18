//! Project automation: `cargo xtask test | assets | bench | power | fixtures | bless`.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::process::Command;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("test") => test(&args[1..]),
        Some("fixtures") => regenerate("fixtures"),
        Some("bless") => regenerate("bless"),
        Some("assets") => {
            // Every Debian package CI needs, in one apt-get run, before the first is wanted.
            ensure_all()?;
            let bonsai = assets()?;
            println!("{}", bonsai.display());
            println!("{}", interop()?.display());
            Ok(())
        }
        Some("bench") if args.get(1).is_some_and(|a| a.starts_with("--scaling")) => scaling(&args[1]),
        Some("bench") if args.get(1).is_some_and(|a| a == "--gpu") => bench_gpu(),
        Some("bench") => bench(),
        Some("power") => power(),
        _ => {
            eprintln!(
                "usage: cargo xtask <command>\n\n\
                 commands:\n  \
                 test [ARGS]  run every test of the workspace (optimized build), then, without ARGS, the\n               \
                 library examples and `cargo doc` with warnings as errors; ARGS go to cargo test\n  \
                 fixtures     regenerate fixtures/*.ply and fixtures/*.cameras.json\n  \
                 bless        re-render the golden images in fixtures/golden/\n  \
                 assets       fetch and verify the bonsai capture into target/assets/, and write\n               \
                 files of other tools (npm: splat-transform, spz-js, gaussian-splats-3d, three; PyPI: usd-core)\n               \
                 into target/interop/\n  \
                 power        run the full power study of the statistical suites (every injected error;\n               \
                 `test` runs the asserted ones) and write its table into docs/power.md\n  \
                 bench        cargo bench, then `splat bench` on the bonsai capture at 1200×800\n  \
                 bench --scaling[=N,…]  load, BVH build, rays and memory on synthetic SH-3 shells of\n               \
                 N splats (default 100000,500000,2000000,8000000,32000000) into target/scaling/\n  \
                 bench --gpu  the GPU table in one command: every ray-tracing and splatting method on the\n               \
                 bonsai capture at 1200×800, and the splatting of a 6 M-splat SH-3 shell at 1920×1080"
            );
            bail!("missing or unknown command");
        }
    }
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("xtask lives in the workspace").to_path_buf()
}

fn test(extra: &[String]) -> Result<()> {
    ensure_all()?;
    provide_lavapipe()?;
    let skips = skip_log();
    let _ = std::fs::remove_file(&skips);
    let status = if extra.is_empty() && has_nextest() {
        // Every test in a process of its own, as many at a time as the machine has cores: the
        // statistical suites' processes overlap instead of queueing binary after binary (lavapipe
        // keeps one core of two busy on the small test images). One more at a time was tried: the
        // suite on 2 cores took 397 s and then 482 s for one commit (three lavapipe suites at
        // once: 101–111 s each, against 48–63 s two at a time). cargo-nextest runs no doctests;
        // cargo test runs those.
        let run = test_command(&["nextest", "run", "--workspace", "--cargo-profile", "release", "--profile", "ci"]);
        let tests = timed("cargo nextest run (build and tests)", || run_status(run, "cargo nextest run"))?;
        let doc_tests = test_command(&["test", "--workspace", "--release", "--doc"]);
        let docs = timed("doctests", || run_status(doc_tests, "cargo test --doc"))?;
        if tests.success() { docs } else { tests }
    } else {
        if extra.is_empty() {
            eprintln!("cargo-nextest is not installed: running the test binaries one after another with cargo test");
        }
        let mut cmd = test_command(&["test", "--workspace", "--release"]);
        cmd.args(extra);
        run_status(cmd, "cargo test")?
    };
    report_skips(&skips);
    if !status.success() {
        bail!("tests failed ({status})");
    }
    if extra.is_empty() {
        timed("examples", run_examples)?;
        timed("cargo doc", check_docs)?;
        timed("the Python package", python_tests)?;
    }
    Ok(())
}

/// The Python package (crates/splat-py): build its wheel with maturin in the virtual
/// environment `target/python` (made and filled from requirements-test.txt), install it into
/// a fresh virtual environment beside it to prove that it installs there with nothing but its
/// declared dependencies, and run its tests with pytest against this build's `splat` binary.
fn python_tests() -> Result<()> {
    let crate_dir = root().join("crates/splat-py");
    let Some(python) = python_environment(&crate_dir.join("requirements-test.txt"))? else {
        eprintln!("SKIPPED the Python package's tests: Python cannot make a virtual environment here");
        return Ok(());
    };
    let wheel = build_wheel(&crate_dir, &python)?;
    install_fresh(&wheel)?;
    run_checked(
        Command::new(&python).args(PIP_INSTALL).args(["--force-reinstall", "--no-deps"]).arg(&wheel),
        "pip install of the wheel",
    )?;
    let splat = target_dir().join("release/splat");
    if !splat.exists() {
        cargo(&["build", "--quiet", "--release", "--bin", "splat"])?;
    }
    eprintln!("pytest crates/splat-py/tests …");
    let mut pytest = Command::new(&python);
    pytest.current_dir(&crate_dir).args(["-m", "pytest", "-q", "tests"]).env("SPLAT_BIN", &splat);
    run_checked(&mut pytest, "pytest")
}

/// `python -m pip install`, quietly.
const PIP_INSTALL: [&str; 5] = ["-m", "pip", "install", "--quiet", "--disable-pip-version-check"];

/// The interpreter of `target/python`, made when missing and given `requirements`; `None`
/// where Python cannot make one.
fn python_environment(requirements: &Path) -> Result<Option<PathBuf>> {
    let venv = target_dir().join("python");
    let python = venv.join("bin/python");
    if !python.exists() {
        if !ensure_venv()? {
            return Ok(None);
        }
        eprintln!("making the virtual environment {} …", venv.display());
        run_checked(Command::new(system_python()).args(["-m", "venv"]).arg(&venv), "python3 -m venv")?;
    }
    run_checked(
        Command::new(&python).args(PIP_INSTALL).arg("-r").arg(requirements),
        "pip install -r requirements-test.txt",
    )?;
    Ok(Some(python))
}

/// The package's wheel, built by the environment's maturin into `target/wheels`. The wheel's
/// build resolves the features of the workspace's test build (splat-py's Cargo.toml names the
/// ones its dependencies lack), so it compiles pyo3, numpy and the package alone; a renderer
/// crate compiled again means the features drifted, which it says.
fn build_wheel(crate_dir: &Path, python: &Path) -> Result<PathBuf> {
    let wheels = target_dir().join("wheels");
    let _ = std::fs::remove_dir_all(&wheels);
    eprintln!("maturin build --release (crates/splat-py) …");
    let maturin = python.with_file_name("maturin");
    let built = Command::new(maturin)
        .current_dir(crate_dir)
        .args(["build", "--release", "--out"])
        .arg(&wheels)
        .arg("-i")
        .arg(python)
        .output()
        .context("running maturin build")?;
    let log = String::from_utf8_lossy(&built.stderr);
    if !built.status.success() {
        bail!("maturin build failed ({}):\n{log}", built.status);
    }
    if let Some(line) = log.lines().find(|l| l.contains("Compiling splat-core")) {
        eprintln!(
            "warning: maturin compiled the renderer again ({}): the features of `cargo tree -p splat-py -e features` \
             differ from the workspace's; name the missing ones in crates/splat-py/Cargo.toml",
            line.trim()
        );
    }
    std::fs::read_dir(&wheels)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "whl"))
        .context("maturin wrote no wheel")
}

/// Install `wheel` into a new virtual environment (`target/python-fresh`) with its declared
/// dependencies only, and render there.
fn install_fresh(wheel: &Path) -> Result<()> {
    let fresh = target_dir().join("python-fresh");
    let _ = std::fs::remove_dir_all(&fresh);
    run_checked(Command::new(system_python()).args(["-m", "venv"]).arg(&fresh), "python3 -m venv (fresh)")?;
    let python = fresh.join("bin/python");
    run_checked(
        Command::new(&python).args(PIP_INSTALL).arg(wheel),
        "pip install of the wheel into a fresh environment",
    )?;
    let smoke = "import splat; out = splat.render(splat.Scene.demo(), width=32, height=24, backend='cpu'); \
                 assert out['color'].shape == (24, 32, 3) and out['color'].max() > 0; print('fresh environment: ok')";
    run_checked(Command::new(&python).args(["-c", smoke]).current_dir(target_dir()), "the wheel in a fresh environment")
}

/// Whether Python's `venv` can make environments with pip inside them (`ensurepip`, which
/// Debian packages apart as python3-venv, installed here when root; under `CI` its absence is
/// an error).
fn ensure_venv() -> Result<bool> {
    ensure(&VENV)?;
    Ok((VENV.have)())
}

/// The system's Python 3.
fn system_python() -> &'static str {
    if Command::new("python3").arg("--version").output().is_ok() { "python3" } else { "python" }
}

/// Run `cmd`, failing with `what` unless it succeeds.
fn run_checked(cmd: &mut Command, what: &str) -> Result<()> {
    let status = cmd.status().with_context(|| format!("running {what}"))?;
    if !status.success() {
        bail!("{what} failed ({status})");
    }
    Ok(())
}

/// Cargo's output folder: `CARGO_TARGET_DIR`, else `target/`.
fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root().join("target"), PathBuf::from)
}

/// Where the tests record what they skipped (`splat_tests::skip`, told by the environment
/// variable `SPLAT_SKIP_LOG`), for the summary printed after the run.
fn skip_log() -> PathBuf {
    root().join("target/skipped-tests.log")
}

/// `cargo ARGS` in the workspace, with the GPU tests on Vulkan unless `WGPU_BACKEND` says
/// otherwise, and skipped tests recorded in [`skip_log`].
fn test_command(args: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO"));
    cmd.current_dir(root()).args(args).env("SPLAT_SKIP_LOG", skip_log());
    if std::env::var_os("WGPU_BACKEND").is_none() {
        cmd.env("WGPU_BACKEND", "vulkan");
    }
    if let Some(Some(icd)) = LAVAPIPE_ICD.get() {
        cmd.env("VK_DRIVER_FILES", icd);
    }
    cmd
}

/// Mesa's lavapipe of Debian 12's backports, pinned by version and hash: the driver the GPU tests
/// run on where the machine has no GPU. Debian 12's own (Mesa 22.3) has no binding arrays of
/// storage buffers, which the kernels bind split scene arrays in where an adapter has them
/// (docs/architecture.md, "Scenes larger than a binding"); Mesa 25.0's lavapipe has them (a
/// million buffers a stage), so both ways of binding are tested here. It needs the libraries
/// Debian's own `mesa-vulkan-drivers` brings (LLVM 15, the Vulkan loader: [`VULKAN`]).
const LAVAPIPE_DEB: &str = "mesa-vulkan-drivers_25.0.7-2~bpo12+1_amd64.deb";
const LAVAPIPE_POOL: &str = "http://deb.debian.org/debian/pool/main/m/mesa/";
const LAVAPIPE_SHA256: &str = "3899f1800424c60a05df5d6913076a526ca8fdbabec43672cd397563d1ca3263";

/// The pinned lavapipe's ICD manifest once [`provide_lavapipe`] ran: `None` where it does not
/// apply.
static LAVAPIPE_ICD: std::sync::OnceLock<Option<PathBuf>> = std::sync::OnceLock::new();

/// Unpack the pinned lavapipe ([`LAVAPIPE_DEB`]) under `target/lavapipe` (fetched and verified
/// once) and write its ICD manifest, which the test runs then load alone (`VK_DRIVER_FILES`).
/// Not on a machine with a GPU device node (its own driver is the one to test), nor where the
/// caller chose the Vulkan drivers (`VK_DRIVER_FILES`, `VK_ICD_FILENAMES`), nor off x86-64 Linux
/// (the package is amd64): there the tests take the system's driver, and the tests of binding
/// arrays skip if it has none (fail under `CI=true`).
fn provide_lavapipe() -> Result<()> {
    let applies = cfg!(all(target_os = "linux", target_arch = "x86_64"))
        && std::env::var_os("VK_DRIVER_FILES").is_none()
        && std::env::var_os("VK_ICD_FILENAMES").is_none()
        && !gpu_device_node();
    let icd = if applies { Some(unpack_lavapipe()?) } else { None };
    if let Some(icd) = &icd {
        eprintln!("GPU tests on the pinned lavapipe: {}", icd.display());
    }
    let _ = LAVAPIPE_ICD.set(icd);
    Ok(())
}

/// Whether a GPU device node exists (`/dev/dri/renderD*`, `/dev/nvidia*`), as
/// `splat_gpu::GpuContext::hardware` asks.
fn gpu_device_node() -> bool {
    let has = |dir: &str, prefix: &str| {
        std::fs::read_dir(dir)
            .is_ok_and(|entries| entries.flatten().any(|e| e.file_name().to_string_lossy().starts_with(prefix)))
    };
    has("/dev/dri", "renderD") || has("/dev", "nvidia")
}

/// [`LAVAPIPE_DEB`] unpacked under `target/lavapipe`, and the path of the ICD manifest written
/// for it (the library by its absolute path).
fn unpack_lavapipe() -> Result<PathBuf> {
    let dir = target_dir().join("lavapipe");
    let icd = dir.join("lvp_icd.json");
    let library = dir.join("root/usr/lib/x86_64-linux-gnu/libvulkan_lvp.so");
    if icd.exists() && library.exists() {
        return Ok(icd);
    }
    std::fs::create_dir_all(&dir)?;
    let deb = dir.join(LAVAPIPE_DEB);
    if !deb.exists() || verify(&deb, LAVAPIPE_SHA256).is_err() {
        let url = format!("{LAVAPIPE_POOL}{LAVAPIPE_DEB}");
        eprintln!("fetching {url} …");
        let fetch = "import sys, urllib.request; urllib.request.urlretrieve(sys.argv[1], sys.argv[2])";
        run_checked(Command::new(system_python()).args(["-c", fetch, &url]).arg(&deb), "the download of lavapipe")
            .with_context(|| {
                format!("{url} is gone from Debian's pool when backports moves on: pin the version it has now and its sha256")
            })?;
    }
    verify(&deb, LAVAPIPE_SHA256)?;
    run_checked(Command::new("dpkg-deb").arg("-x").arg(&deb).arg(dir.join("root")), "dpkg-deb -x of lavapipe")?;
    if !library.exists() {
        bail!("{} holds no {}", deb.display(), library.display());
    }
    let manifest = format!(
        "{{\"file_format_version\": \"1.0.0\", \"ICD\": {{\"library_path\": \"{}\", \"api_version\": \"1.4.305\"}}}}\n",
        library.display()
    );
    std::fs::write(&icd, manifest)?;
    Ok(icd)
}

/// Run `step`, then print how long it took (CI's budget is the whole run's: docs/architecture.md
/// says what each phase costs).
fn timed<T>(what: &str, step: impl FnOnce() -> Result<T>) -> Result<T> {
    let start = std::time::Instant::now();
    let out = step();
    eprintln!("{what}: {:.0} s", start.elapsed().as_secs_f64());
    out
}

fn run_status(mut cmd: Command, what: &str) -> Result<std::process::ExitStatus> {
    cmd.status().with_context(|| format!("running {what}"))
}

/// Whether `cargo nextest` runs here (the machines' images carry it; `cargo install
/// cargo-nextest` elsewhere).
fn has_nextest() -> bool {
    Command::new(env!("CARGO"))
        .args(["nextest", "--version"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Run every library example; each checks its own result. They are built for the whole
/// workspace at once (`cargo build --workspace --examples`, which reuses the test build: `cargo
/// run -p` would resolve one package's features and build its libraries a second time) and
/// run from `target/release/examples/`.
fn run_examples() -> Result<()> {
    cargo(&["build", "--quiet", "--release", "--workspace", "--examples"])?;
    let out = root().join("target/examples");
    std::fs::create_dir_all(&out)?;
    let path = |name: &str| out.join(name).display().to_string();
    let examples: [(&str, Vec<String>); 3] = [
        ("render_ply", vec!["fixtures/cloud.ply".into(), path("render_ply.png")]),
        ("ztest", vec![]),
        ("trace_gpu", vec![path("trace_gpu.png")]),
    ];
    for (example, args) in examples {
        eprintln!("example {example} …");
        let status = Command::new(target_dir().join("release/examples").join(example))
            .current_dir(root())
            .args(&args)
            .status()
            .with_context(|| format!("running the example {example}"))?;
        if !status.success() {
            bail!("the example {example} failed ({status})");
        }
    }
    Ok(())
}

/// Build the API documentation of the library crates with warnings as errors (broken links,
/// missing docs). The applications (`splat-cli`, `splat-view`) publish no API, and documenting
/// them would check-build the window's stack (winit, egui) once more: minutes of CI on 2 cores.
/// `--release` reuses the test build's proc macros and build scripts (on a fresh 2-core
/// machine after the test build, documenting as far as one doc error took 57 s with it and
/// 176 s in the dev profile, which builds them again).
fn check_docs() -> Result<()> {
    eprintln!(
        "cargo doc --release --workspace --exclude splat-cli --exclude splat-view --exclude splat-py --no-deps \
         (RUSTDOCFLAGS=-D warnings) …"
    );
    let status = Command::new(env!("CARGO"))
        .current_dir(root())
        .args([
            "doc",
            "--release",
            "--workspace",
            "--exclude",
            "splat-cli",
            "--exclude",
            "splat-view",
            "--exclude",
            "splat-py",
            "--no-deps",
            "--quiet",
        ])
        .env("RUSTDOCFLAGS", "-D warnings")
        .status()
        .context("running cargo doc")?;
    if !status.success() {
        bail!("cargo doc found warnings ({status})");
    }
    Ok(())
}

/// Print the tests that skipped (no adapter, no asset) as a summary after cargo's output, so
/// that a run that proved less than it could is visible (under `CI=true` they fail instead).
fn report_skips(log: &Path) {
    let Ok(text) = std::fs::read_to_string(log) else { return };
    let lines: Vec<&str> = text.lines().collect();
    if lines.is_empty() {
        return;
    }
    eprintln!("\n{} test(s) SKIPPED: they proved nothing on this machine", lines.len());
    for line in lines {
        eprintln!("  {line}");
    }
}

/// Vulkan ICD manifests: a driver is installed when one exists.
fn vulkan_icds() -> Vec<PathBuf> {
    ["/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d", "/usr/local/share/vulkan/icd.d"]
        .iter()
        .filter_map(|d| std::fs::read_dir(d).ok())
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect()
}

/// Debian packages a part of the tests needs: what they give, how to tell they are there, and
/// what skips without them.
struct Need {
    what: &'static str,
    packages: &'static [&'static str],
    have: fn() -> bool,
    consequence: &'static str,
}

/// Mesa's Vulkan drivers (lavapipe, a CPU Vulkan implementation), so the GPU tests have an
/// adapter on any machine.
const VULKAN: Need = Need {
    what: "Vulkan driver",
    packages: &["mesa-vulkan-drivers", "libvulkan1"],
    have: || !vulkan_icds().is_empty(),
    consequence: "GPU tests will skip",
};

/// Embree 3's headers and library, for the Embree peer of the CPU tracer (`embree-peer`).
const EMBREE_HEADER: &str = "/usr/include/embree3/rtcore.h";

/// Embree 3 (Debian's libembree-dev), so that the peer's image test and `cargo xtask bench` can
/// build the C++ peer.
const EMBREE: Need = Need {
    what: "Embree 3",
    packages: &["libembree-dev"],
    have: || Path::new(EMBREE_HEADER).exists(),
    consequence: "the Embree peer's test will skip",
};

/// Xvfb and the X client libraries winit loads at run time (it links none of them), for the
/// viewer's real-window test under `xvfb-run`.
const X11_PACKAGES: [&str; 7] =
    ["xvfb", "xauth", "libxkbcommon-x11-0", "libxcursor1", "libxi6", "libxrandr2", "libx11-xcb1"];

/// [`X11_PACKAGES`].
const XVFB: Need = Need {
    what: "Xvfb",
    packages: &X11_PACKAGES,
    have: || {
        let on_path = on_path("xvfb-run");
        let query = Command::new("dpkg-query").args(["-W", "-f=${Status}\n"]).args(X11_PACKAGES).output();
        // Where dpkg is not the package manager, xvfb-run on the PATH is all we can check.
        let installed = query.map_or(true, |o| {
            String::from_utf8_lossy(&o.stdout).lines().filter(|l| l.ends_with(" installed")).count()
                == X11_PACKAGES.len()
        });
        on_path && installed
    },
    consequence: "the viewer's window test will skip",
};

/// Debian's Chromium, for the test of `splat serve`'s page in a real headless browser.
const CHROMIUM: Need = Need {
    what: "Chromium",
    packages: &["chromium"],
    have: || on_path("chromium"),
    consequence: "the test of splat serve's page will skip",
};

/// Python's `venv` with pip inside its environments (`ensurepip`, which Debian packages apart).
const VENV: Need = Need {
    what: "Python's venv",
    packages: &["python3-venv"],
    have: || {
        let probe = Command::new(system_python()).args(["-c", "import ensurepip, venv"]).output();
        probe.is_ok_and(|o| o.status.success())
    },
    consequence: "the Python tests will skip",
};

/// Node.js and npm, which write the files of other tools (`cargo xtask assets`).
const NODE: Need = Need {
    what: "Node.js",
    packages: &["nodejs", "npm"],
    have: || Command::new("npm").arg("--version").output().is_ok_and(|o| o.status.success()),
    consequence: "the tests on other tools' files will skip",
};

/// Every package set `cargo xtask assets` and `test` need.
const NEEDS: [&Need; 6] = [&VULKAN, &EMBREE, &XVFB, &CHROMIUM, &VENV, &NODE];

/// Whether `program` is on the PATH.
fn on_path(program: &str) -> bool {
    Command::new("sh").args(["-c", &format!("command -v {program}")]).output().is_ok_and(|o| o.status.success())
}

/// Install what [`NEEDS`] lack in one apt-get run (one index update, not one a set).
fn ensure_all() -> Result<()> {
    let missing: Vec<&Need> = NEEDS.into_iter().filter(|n| !(n.have)()).collect();
    if missing.is_empty() {
        return Ok(());
    }
    let packages: Vec<&str> = missing.iter().flat_map(|n| n.packages.iter().copied()).collect();
    let what = missing.iter().map(|n| n.what).collect::<Vec<_>>().join(", ");
    let consequences = missing.iter().map(|n| n.consequence).collect::<Vec<_>>().join("; ");
    ensure_packages(|| missing.iter().all(|n| (n.have)()), &packages, &what, &consequences)
}

/// Make one [`Need`] met.
fn ensure(need: &Need) -> Result<()> {
    ensure_packages(need.have, need.packages, need.what, need.consequence)
}

/// Make `have()` true by installing Debian `packages` with apt-get when we are root; otherwise
/// fail under `CI` and warn (`consequence`) elsewhere.
fn ensure_packages(have: impl Fn() -> bool, packages: &[&str], what: &str, consequence: &str) -> Result<()> {
    if have() {
        return Ok(());
    }
    let list = packages.join(" ");
    let uid = Command::new("id").arg("-u").output().map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string());
    if uid.ok().as_deref() != Some("0") {
        if std::env::var_os("CI").is_some() {
            bail!("CI is set, {what} is not installed and we are not root: install {list}");
        }
        eprintln!("{what} not found and not root: {consequence} (install {list})");
        return Ok(());
    }
    eprintln!("{what} not found: installing {list} with apt-get …");
    let apt = |args: &[&str]| -> Result<()> {
        let status = Command::new("apt-get").args(args).env("DEBIAN_FRONTEND", "noninteractive").status()?;
        if !status.success() {
            bail!("apt-get {} failed ({status})", args.join(" "));
        }
        Ok(())
    };
    apt(&["update", "-qq"])?;
    apt(&[&["install", "-y", "-qq"][..], packages].concat())?;
    if !have() {
        bail!("{list} is installed but {what} is still not found");
    }
    Ok(())
}

/// The marker lines of docs/power.md between which `cargo xtask power` writes the table.
const POWER_BEGIN: &str = "<!-- power table: cargo xtask power -->";
const POWER_END: &str = "<!-- end of power table -->";

/// The test binaries with a power study (`splat_tests::harness::assert_power`).
const POWER_SUITES: [&str; 7] = [
    "unbiased",
    "raster_unbiased",
    "gpu_stats",
    "gpu_stats_cloud",
    "gpu_stats_bonsai",
    "gpu_raster_stats",
    "gpu_msaa_stats",
];

/// Run the full power study (every fault of every suite, for every method a suite studies:
/// `SPLAT_POWER=full`, `splat_tests::harness::POWER_STUDY_VAR`; 9 minutes on two cores at
/// 699d157), then gather the rows it wrote to `target/power/` into docs/power.md, suites in
/// order. `cargo xtask test` runs the asserted rows only.
fn power() -> Result<()> {
    ensure(&VULKAN)?;
    provide_lavapipe()?;
    let dir = root().join("target/power");
    if dir.exists() {
        std::fs::remove_dir_all(&dir)?;
    }
    let suites = POWER_SUITES.iter().flat_map(|s| ["--test", s]);
    let mut run = if has_nextest() {
        test_command(&["nextest", "run", "--workspace", "--cargo-profile", "release", "--profile", "ci"])
    } else {
        test_command(&["test", "--workspace", "--release"])
    };
    run.args(suites).env("SPLAT_POWER", "full");
    if !run_status(run, "the power study")?.success() {
        bail!("the power study failed (its verdicts are above); docs/power.md is unchanged");
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| format!("{}: the power study wrote no table", dir.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    files.sort();
    let mut table = String::from(
        "| suite, fixture, method | injected error | global (expected) | spread (expected) | p < 0.01 | floored | z-test |\n\
         |---|---|---:|---:|---:|---:|---|\n",
    );
    for file in &files {
        table += &std::fs::read_to_string(file)?;
    }
    let doc_path = root().join("docs/power.md");
    let doc = std::fs::read_to_string(&doc_path)?;
    let (Some(begin), Some(end)) = (doc.find(POWER_BEGIN), doc.find(POWER_END)) else {
        bail!("{} has no power table markers", doc_path.display());
    };
    let doc = format!("{}{POWER_BEGIN}\n{table}{}", &doc[..begin], &doc[end..]);
    std::fs::write(&doc_path, doc)?;
    println!("wrote {} rows from {} files into {}", table.lines().count() - 2, files.len(), doc_path.display());
    Ok(())
}

/// `splat-tests`' `regenerate fixtures | bless`: the fixture scenes, or the golden images.
fn regenerate(what: &str) -> Result<()> {
    cargo(&["run", "--release", "-p", "splat-tests", "--bin", "regenerate", "--", what])
}

/// Run `binary` with `args`; an error naming it and its arguments when it fails.
fn run_binary(binary: &Path, args: &[&str]) -> Result<()> {
    let name = binary.file_name().map_or_else(|| binary.display().to_string(), |n| n.to_string_lossy().into_owned());
    let status = Command::new(binary).args(args).status().with_context(|| format!("running {name}"))?;
    if !status.success() {
        bail!("{name} {} failed ({status})", args.join(" "));
    }
    Ok(())
}

/// `cargo ARGS` in the workspace; an error unless it succeeds.
fn cargo(args: &[&str]) -> Result<()> {
    let status = Command::new(env!("CARGO")).current_dir(root()).args(args).status().context("running cargo")?;
    if !status.success() {
        bail!("cargo {} failed ({status})", args.join(" "));
    }
    Ok(())
}

/// The benchmarks, every one a ratio measured in one run: divan (`cargo bench`), the Embree
/// peer against the CPU tracer (`embree-peer`), `splat bench` (every method against `opaque`
/// through the same BVH) and `splat bench --sweep mn` (Sun et al. Tables 4–5), all on the
/// bonsai capture from the standard view (`splat_tests::bonsai_camera`) at 1200 × 800, the
/// sweep at 300 × 200 (1024 samples a pixel per row).
fn bench() -> Result<()> {
    let bonsai = assets()?;
    ensure(&EMBREE)?;
    cargo(&["bench", "-p", "splat-tests", "--bench", "trace"])?;
    cargo(&["bench", "-p", "splat-gpu", "--bench", "sort"])?;
    let bonsai = bonsai.to_str().context("non-UTF-8 path")?;
    let view = ["--eye", "0,-1.5,4", "--target", "0,0.5,0", "--up", "0,-1,0"];
    if Path::new(EMBREE_HEADER).exists() {
        println!("\n## The CPU tracer against Embree 3 (user geometry, one callback per particle)\n");
        cargo(&[&["run", "--release", "-p", "embree-peer", "--", bonsai][..], &view].concat())?;
    } else {
        eprintln!("SKIPPED the Embree comparison: {EMBREE_HEADER} is absent (install libembree-dev as root)");
    }
    let splat = |args: &[&str]| {
        cargo(&[&["run", "--release", "-p", "splat-cli", "--", "bench", bonsai][..], &view, args].concat())
    };
    println!("\n## Every ray-tracing method against opaque, through the same BVH\n");
    splat(&["--backend", "cpu"])?;
    println!("\n## Sun et al. Tables 4–5: m traversals × n samples, CPU\n");
    splat(&["--backend", "cpu", "--sweep", "mn", "--width", "300", "--height", "200"])
}

/// `cargo xtask bench --gpu`: the GPU table of issue 40 in one command, for a machine with a GPU
/// (a few minutes on a data-centre GPU; lavapipe takes far longer): `splat bench --backend gpu`
/// of the ray-tracing methods (frame, Mrays/s, cost against Algorithm 1, dispatches and host
/// waits a frame, device bytes a splat) and of the splatting methods (each stage, then each
/// method against raster-sorted) on the bonsai capture from the standard view at 1200 × 800,
/// then raster-sorted and StochasticSplats on a 6 M-splat SH-3 shell ([`write_shell`]) at
/// 1920 × 1080, vk_gaussian_splatting's scale; then sorted splatting against a peer wgpu
/// splatting viewer on the same device (`crates/raster-peer`, outside the workspace so that CI
/// does not build its dependencies) on both scenes. Each table is ratios within its own run.
fn bench_gpu() -> Result<()> {
    let bonsai = assets()?;
    cargo(&["build", "--release", "--bin", "splat"])?;
    let splat = target_dir().join("release/splat");
    let run = |args: &[&str]| run_binary(&splat, args);
    let bonsai = bonsai.to_str().context("non-UTF-8 path")?;
    let view = ["--eye", "0,-1.5,4", "--target", "0,0.5,0", "--up", "0,-1,0", "--width", "1200", "--height", "800"];
    let gpu = ["--backend", "gpu", "--repeat", "3"];
    println!("\n## Ray tracing on the GPU, bonsai, 1200 × 800, 16 spp\n");
    let trace = ["--methods", "stochastic,stochastic-n,stochastic-pass,kbuffer,exact", "--spp", "16"];
    run(&[&["bench", bonsai][..], &view, &gpu, &trace].concat())?;
    println!("\n## Splatting on the GPU, bonsai, 1200 × 800\n");
    let raster = ["--methods", "raster-sorted,stochastic-splat,enderton,stratified", "--spp", "16"];
    run(&[&["bench", bonsai][..], &view, &gpu, &raster].concat())?;
    let dir = target_dir().join("scaling");
    std::fs::create_dir_all(&dir)?;
    let shell = dir.join("shell-6000000.ply");
    write_shell(&shell, 6_000_000)?;
    println!("\n## Splatting on the GPU, a 6 M-splat SH-3 shell, 1920 × 1080\n");
    let shell = shell.to_str().context("non-UTF-8 path")?;
    let size = ["--width", "1920", "--height", "1080", "--methods", "raster-sorted,stochastic-splat", "--spp", "16"];
    run(&[&["bench", shell][..], &size, &gpu].concat())?;
    // The peer reads PLY only: the bonsai converted, and the same shell.
    let bonsai_ply = dir.join("bonsai-7k-mini.ply");
    let bonsai_ply = bonsai_ply.to_str().context("non-UTF-8 path")?;
    run(&["convert", bonsai, bonsai_ply])?;
    let peer_dir = target_dir().join("raster-peer");
    let peer_dir = peer_dir.to_str().context("non-UTF-8 path")?;
    let manifest = ["--manifest-path", "crates/raster-peer/Cargo.toml", "--target-dir", peer_dir];
    cargo(&[&["build", "--release"][..], &manifest].concat())?;
    // A peer that refuses a scene (its own limits) is a result: said, and the table goes on.
    let peer = |args: &[&str]| {
        if let Err(e) = run_binary(&target_dir().join("raster-peer/release/raster-peer"), args) {
            println!("no comparison: {e:#}");
        }
    };
    println!("\n## Splatting against wgpu-3dgs-viewer on the same GPU, bonsai, 1200 × 800\n");
    peer(&[&[bonsai_ply][..], &view, &["--repeat", "3"]].concat());
    println!("\n## Splatting against wgpu-3dgs-viewer on the same GPU, the 6 M-splat shell, 1920 × 1080\n");
    peer(&[shell, "--width", "1920", "--height", "1080", "--repeat", "3"]);
    Ok(())
}

/// `cargo xtask bench --scaling[=N,…]`: how load, BVH build, rays and memory grow with the
/// scene. For each N, a synthetic SH degree 3 shell of N splats ([`write_shell`]) is read by
/// `splat info` twice (the rate of the first read and of the second, warm one; the bytes held)
/// and by `splat bench --backend cpu` (load, build, frame
/// times of opaque, stochastic and exact at 320 × 240, the process's peak memory); a second
/// table gives an exact ray's work counters and the time a thread spends per byte it fetches.
/// Both go to stdout and target/scaling/table.md. The splats shrink as 1/√N, so that a ray
/// meets as many at every N: the per-ray work should then grow as the BVH's depth, log N.
fn scaling(arg: &str) -> Result<()> {
    let sizes: Vec<u64> = match arg.strip_prefix("--scaling=") {
        Some(list) => list
            .split(',')
            .map(|n| n.trim().parse().context("--scaling=N,… takes splat counts"))
            .collect::<Result<_>>()?,
        None => vec![100_000, 500_000, 2_000_000, 8_000_000, 32_000_000],
    };
    cargo(&["build", "--release", "--bin", "splat"])?;
    let splat = target_dir().join("release/splat");
    let dir = target_dir().join("scaling");
    std::fs::create_dir_all(&dir)?;
    let output = |args: &[&str]| -> Result<String> {
        let out = Command::new(&splat).args(args).output().context("running splat")?;
        if !out.status.success() {
            bail!("splat {} failed: {}", args.join(" "), String::from_utf8_lossy(&out.stderr));
        }
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
    };
    // The number after `marker` in `text`.
    let after = |text: &str, marker: &str| -> Result<f64> {
        let at = text.find(marker).with_context(|| format!("no '{marker}' in:\n{text}"))? + marker.len();
        let number: String = text[at..].trim_start().chars().take_while(|c| c.is_ascii_digit() || *c == '.').collect();
        number.parse().with_context(|| format!("no number after '{marker}'"))
    };
    // Column `k` (0: the method, 1: its frame time) of `method`'s row of `splat bench`'s table.
    let column = |table: &str, method: &str, k: usize| -> Result<f64> {
        let row = table.lines().find(|l| l.starts_with(&format!("| {method} |"))).context("no row")?;
        let cell = row.split('|').nth(k + 1).context("no such column")?;
        cell.trim().trim_end_matches('×').parse().with_context(|| format!("'{cell}' in {row}"))
    };
    let mut table = String::from(
        "| splats | file (MB) | first read (GB/s) | warm read (s) | warm read (GB/s) | held (bytes a splat) | BVH build (s) | build (µs a splat) | opaque (ms) | stochastic (ms) | exact (ms) | peak (GB) | peak (bytes a splat) |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    // What an exact ray does and what it costs per byte it fetches: the work should grow as
    // log N; the time grows past it where the fetches leave the caches.
    let mut work = String::from(
        "| splats | exact (ms) | nodes/ray | leaves/ray | tests/ray | bytes/ray | ns per byte fetched |\n\
         |---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for &n in &sizes {
        let path = dir.join(format!("shell-{n}.ply"));
        write_shell(&path, n)?;
        let file = path.to_str().context("non-UTF-8 path")?;
        // The first read finds what the page cache holds of the file; the second finds it all
        // there where memory allows (warm).
        let first_s = after(&output(&["info", file])?, "read ")?;
        let info = output(&["info", file])?;
        let bench = output(&[
            "bench",
            file,
            "--backend",
            "cpu",
            "--methods",
            "stochastic,exact",
            "--width",
            "320",
            "--height",
            "240",
        ])?;
        let (read_s, mb) = (after(&info, "read ")?, after(&info, "MB/s (")?);
        let held = after(&info, "held,")?;
        let build = after(&bench, "BVH built in")?;
        let peak = after(&bench, "peak memory")?;
        let [ms, nodes, leaves, tests, bytes] = [1, 6, 7, 8, 9].map(|k| column(&bench, "exact", k));
        let (ms, bytes) = (ms?, bytes?);
        let row = format!(
            "| {n} | {mb:.0} | {:.2} | {read_s:.2} | {:.2} | {held:.0} | {build:.2} | {:.2} | {:.1} | {:.1} | {:.1} | {peak:.2} | {:.0} |\n",
            mb / 1e3 / first_s,
            mb / 1e3 / read_s,
            build * 1e6 / n as f64,
            column(&bench, "opaque", 1)?,
            column(&bench, "stochastic", 1)?,
            ms,
            peak * 1e9 / n as f64
        );
        print!("{row}");
        table.push_str(&row);
        // 320 × 240 rays a frame: the time a thread spends per byte.
        let threads = after(&bench, "spp, ")?;
        let ns_per_byte = ms * 1e6 * threads / (320.0 * 240.0 * bytes);
        work.push_str(&format!(
            "| {n} | {ms:.1} | {:.1} | {:.1} | {:.1} | {bytes:.0} | {ns_per_byte:.2} |\n",
            nodes?, leaves?, tests?
        ));
    }
    println!("\n{table}\n{work}");
    std::fs::write(dir.join("table.md"), format!("{table}\n{work}"))?;
    Ok(())
}

/// A synthetic SH degree 3 capture of `n` splats as a binary 3DGS `.ply` (kept when already
/// written): means on a shell of radius 1–1.05, scales about 4 × 10⁻³ √(2 × 10⁶ / n), random
/// colours, SH, opacities and rotations from a fixed seed; written as it is made, so that any n
/// fits in memory.
fn write_shell(path: &Path, n: u64) -> Result<()> {
    use std::io::Write as _;
    let mut names: Vec<String> =
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"].map(String::from).to_vec();
    names.extend((0..45).map(|i| format!("f_rest_{i}")));
    names.extend(["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"].map(String::from));
    let mut header = format!("ply\nformat binary_little_endian 1.0\nelement vertex {n}\n");
    for name in &names {
        header.push_str(&format!("property float {name}\n"));
    }
    header.push_str("end_header\n");
    let expected = header.len() as u64 + n * 4 * names.len() as u64;
    if std::fs::metadata(path).is_ok_and(|m| m.len() == expected) {
        return Ok(());
    }
    eprintln!("writing {} ({:.1} GB) …", path.display(), expected as f64 / 1e9);
    let mut out = std::io::BufWriter::with_capacity(1 << 23, std::fs::File::create(path)?);
    out.write_all(header.as_bytes())?;
    // SplitMix64, uniform in [0, 1).
    let mut state = 0x5eed_u64;
    let mut uniform = move || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    };
    let base_scale = 4e-3 * (2e6 / n as f64).sqrt() as f32;
    let mut record = Vec::with_capacity(4 * names.len());
    for _ in 0..n {
        let z = 2.0 * uniform() - 1.0;
        let phi = std::f32::consts::TAU * uniform();
        let r = 1.0 + 0.05 * uniform();
        let s = (1.0 - z * z).max(0.0).sqrt();
        let mut values = vec![r * s * phi.cos(), r * s * phi.sin(), r * z, 0.0, 0.0, 0.0];
        values.extend((0..3).map(|_| 2.0 * uniform() - 1.0));
        values.extend((0..45).map(|_| 0.1 * (uniform() - 0.5)));
        values.push(4.0 * (uniform() - 0.5));
        values.extend((0..3).map(|_| (base_scale * (0.5 + uniform())).ln()));
        values.extend((0..4).map(|_| uniform() - 0.5));
        record.clear();
        for v in values {
            record.extend(v.to_le_bytes());
        }
        out.write_all(&record)?;
    }
    out.flush()?;
    Ok(())
}

/// PyPI source distribution that carries the bonsai capture, pinned by version and hash.
const ASSET_PACKAGE: &str = "gradio-model3dgs==0.2.5";
const ASSET_SDIST: &str = "gradio_model3dgs-0.2.5.tar.gz";
const ASSET_SDIST_SHA256: &str = "2114171f719584852d82cebb19b076c17acf8505058af9be06192a9e69d1f971";
const ASSET_MEMBER: &str =
    "gradio_model3dgs-0.2.5/gradio_cached_examples/12/output/eb4085434ede1588884e/bonsai-7k-mini.splat";
/// The capture: 272,956 splats of the Mip-NeRF 360 bonsai.
pub const BONSAI: &str = "bonsai-7k-mini.splat";
const BONSAI_SHA256: &str = "9e67a38943cd02aa0388c5abf3cb0465a330b7b45ad8aa3d3decc82e5cc8fbb1";

fn sha256_hex(path: &Path) -> Result<String> {
    use sha2::Digest;
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(format!("{:x}", sha2::Sha256::digest(&bytes)))
}

fn verify(path: &Path, expected: &str) -> Result<()> {
    let actual = sha256_hex(path)?;
    if actual != expected {
        bail!("{}: sha256 {actual} does not match the pinned {expected}", path.display());
    }
    Ok(())
}

/// Fetch the bonsai capture with pip (the pinned PyPI sdist), verify both hashes and cache it
/// as `target/assets/bonsai-7k-mini.splat`. Does nothing when the verified file is there.
fn assets() -> Result<PathBuf> {
    let dir = root().join("target/assets");
    let bonsai = dir.join(BONSAI);
    if bonsai.exists() && verify(&bonsai, BONSAI_SHA256).is_ok() {
        return Ok(bonsai);
    }
    std::fs::create_dir_all(&dir)?;
    let sdist = dir.join(ASSET_SDIST);
    if !sdist.exists() || verify(&sdist, ASSET_SDIST_SHA256).is_err() {
        eprintln!("fetching {ASSET_PACKAGE} from PyPI with pip …");
        let python = if Command::new("python3").arg("--version").output().is_ok() { "python3" } else { "python" };
        let status = Command::new(python)
            .args(["-m", "pip", "download", "--no-deps", "--no-binary", ":all:", "--disable-pip-version-check", "-d"])
            .arg(&dir)
            .arg(ASSET_PACKAGE)
            .status()
            .context("running pip (python3 -m pip): is Python with pip installed?")?;
        if !status.success() {
            bail!("pip download {ASSET_PACKAGE} failed ({status})");
        }
    }
    verify(&sdist, ASSET_SDIST_SHA256)?;
    let status = Command::new("tar")
        .arg("-xzf")
        .arg(&sdist)
        .arg("-C")
        .arg(&dir)
        .arg(ASSET_MEMBER)
        .status()
        .context("running tar")?;
    if !status.success() {
        bail!("extracting {ASSET_MEMBER} from {} failed", sdist.display());
    }
    let extracted = dir.join(ASSET_MEMBER);
    verify(&extracted, BONSAI_SHA256)?;
    std::fs::rename(&extracted, &bonsai)?;
    let _ = std::fs::remove_dir_all(dir.join("gradio_model3dgs-0.2.5"));
    Ok(bonsai)
}

/// Folder of the npm packages that write the interop files: package.json, package-lock.json
/// (versions and sha512 integrity of every package, checked by `npm ci`) and make.mjs.
const INTEROP_SOURCES: &str = "xtask/interop";

/// Write `target/interop/`: `source.ply` (the SH degree 3 cloud scene) and what other
/// implementations make of it (spz versions 2–4, compressed .ply, glTF .glb, SOG, .ksplat, USD), and three.js's
/// glTF meshes with materials, for the reader tests in
/// tests/tests/formats.rs. Installs Node.js (Debian's nodejs, npm) when missing and root.
fn interop() -> Result<PathBuf> {
    let dir = root().join("target/interop");
    let npm_dir = dir.join("npm");
    std::fs::create_dir_all(&npm_dir)?;
    ensure(&NODE)?;
    if !(NODE.have)() {
        return Ok(dir);
    }
    for file in ["package.json", "package-lock.json", "make.mjs"] {
        std::fs::copy(root().join(INTEROP_SOURCES).join(file), npm_dir.join(file))?;
    }
    // The SH degree 3 cloud, as `cargo xtask fixtures` writes it.
    std::fs::copy(root().join("fixtures/cloud.ply"), dir.join("source.ply"))?;
    let run = |program: &str, args: &[&str]| -> Result<()> {
        let status = Command::new(program)
            .args(args)
            .current_dir(&npm_dir)
            .status()
            .with_context(|| format!("running {program}"))?;
        if !status.success() {
            bail!("{program} {} failed ({status})", args.join(" "));
        }
        Ok(())
    };
    let installed = ["spz-js", "@playcanvas/splat-transform", "@mkkellogg/gaussian-splats-3d", "three"];
    if !installed.iter().all(|package| npm_dir.join("node_modules").join(package).exists()) {
        eprintln!("installing the pinned npm packages (package-lock.json) …");
        run("npm", &["ci", "--ignore-scripts", "--no-audit", "--no-fund", "--loglevel=error"])?;
    }
    run("node", &["make.mjs", dir.to_str().context("target path is not UTF-8")?])?;
    usd_interop(&dir)?;
    Ok(dir)
}

/// OpenUSD's files of the interop source: usd-core (requirements-usd.txt, installed with
/// `--require-hashes` into `target/interop/usd`) writes them through `usd.py`, which the USD
/// tests also run to read ours.
fn usd_interop(dir: &Path) -> Result<()> {
    if !ensure_venv()? {
        eprintln!("no Python venv here: the USD tests will skip");
        return Ok(());
    }
    let venv = dir.join("usd");
    let python = venv.join("bin/python");
    if !python.exists() {
        run_checked(Command::new(system_python()).args(["-m", "venv"]).arg(&venv), "python3 -m venv (usd-core)")?;
    }
    let requirements = root().join(INTEROP_SOURCES).join("requirements-usd.txt");
    if Command::new(&python).args(["-c", "import pxr.UsdVol"]).output().map_or(true, |o| !o.status.success()) {
        eprintln!("installing usd-core (pinned by hash in {}) …", requirements.display());
        run_checked(
            Command::new(&python).args(PIP_INSTALL).arg("--require-hashes").arg("-r").arg(&requirements),
            "pip install usd-core",
        )?;
    }
    let script = root().join(INTEROP_SOURCES).join("usd.py");
    run_checked(
        Command::new(&python).arg(&script).arg("write").arg(dir.join("source.ply")).arg(dir),
        "usd.py write (usd-core's files of the interop source)",
    )
}
