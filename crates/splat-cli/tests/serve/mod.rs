//! `splat serve`: its refusals, and the page in a real headless Chromium
//! (`serve/in_chromium.py`, driven over the DevTools protocol with Python's standard library).

use super::splat;
use splat_tests::root;
use std::process::Command;

/// The first of Debian's and other distributions' Chromium binaries on the PATH.
fn chromium() -> Option<String> {
    ["chromium", "chromium-browser", "google-chrome"].into_iter().find_map(|name| {
        let found = Command::new("sh").args(["-c", &format!("command -v {name}")]).output().ok()?;
        found.status.success().then(|| String::from_utf8_lossy(&found.stdout).trim().to_string())
    })
}

/// The page shows what `splat render` writes and steers the render: the token guards every
/// request, the exact method chosen from the panel shows the pixels of `splat render`'s PNG of
/// the same camera within one 8-bit level (the viewer's tolerance), a drag turns the camera
/// and restarts the accumulation, keys change the display and fly, and a second page shows the
/// same accumulation. `SPLAT_SERVE_SCREENSHOT=PATH` also writes the README's screenshot.
#[test]
fn the_served_page_shows_splat_render_and_steers_it() {
    let Some(chromium) = chromium() else {
        return splat_tests::skip(&splat_tests::current_test(), "Chromium is not installed (Debian package chromium)");
    };
    let work = std::env::temp_dir().join(format!("splat-serve-{}", std::process::id()));
    std::fs::create_dir_all(&work).unwrap();
    let script = root().join("crates/splat-cli/tests/serve/in_chromium.py");
    let mut command = Command::new("timeout");
    command.args(["300", "python3"]).arg(script).arg(env!("CARGO_BIN_EXE_splat")).arg(chromium).arg(&work);
    if let Some(shot) = std::env::var_os("SPLAT_SERVE_SCREENSHOT") {
        command.arg(shot);
    }
    let output = command.output().expect("python3 runs");
    let said = format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    eprintln!("{said}");
    assert!(output.status.success(), "the page in Chromium failed ({}): {said}", output.status);
    assert!(said.contains("largest difference"), "the canvas was not compared: {said}");
    let _ = std::fs::remove_dir_all(&work);
}

/// Bad options fail before anything listens: another address than loopback without --public,
/// a view of absurd size, a missing scene.
#[test]
fn serve_refuses_bad_options_at_once() {
    let public = splat(&["serve", "--bind", "0.0.0.0", "--port", "0"]);
    let said = String::from_utf8_lossy(&public.stderr);
    assert!(!public.status.success() && said.contains("--public"), "{said}");
    let huge = splat(&["serve", "--width", "100000", "--port", "0"]);
    assert!(!huge.status.success() && String::from_utf8_lossy(&huge.stderr).contains("--width"));
    let missing = splat(&["serve", "no-such-scene.ply", "--port", "0"]);
    assert!(!missing.status.success() && String::from_utf8_lossy(&missing.stderr).contains("no-such-scene.ply"));
}
