//! The real window: `splat-view` opens under Xvfb (a virtual X server), renders frames of a
//! capture and closes by itself, printing nothing of the graphics stack's; bad input fails
//! before any window, and without a desktop the error says how to get one.

use std::path::PathBuf;
use std::process::{Command, Output};

fn fixture(name: &str) -> PathBuf {
    splat_tests::root().join("fixtures").join(name)
}

fn viewer(args: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_splat-view"));
    command.args(args);
    command
}

fn text(output: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr))
}

/// Whether `program` is on the PATH.
fn installed(program: &str) -> bool {
    Command::new("sh").args(["-c", &format!("command -v {program}")]).output().is_ok_and(|o| o.status.success())
}

#[test]
fn a_real_window_opens_renders_and_closes_under_xvfb() {
    if !installed("xvfb-run") {
        return splat_tests::skip(&splat_tests::current_test(), "xvfb-run is not installed (Debian package xvfb)");
    }
    let (scene, cameras) = (fixture("cloud.ply"), fixture("cloud.cameras.json"));
    let output = Command::new("timeout")
        .args(["300", "xvfb-run", "-a", "-s", "-screen 0 1280x800x24"])
        .arg(env!("CARGO_BIN_EXE_splat-view"))
        .arg(&scene)
        .arg("--camera")
        .arg(&cameras)
        .args(["--quit-after", "3", "--width", "900", "--height", "600"])
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .output()
        .expect("timeout and xvfb-run run");
    let said = text(&output);
    assert!(output.status.success(), "splat-view under xvfb-run failed ({}): {said}", output.status);
    assert!(said.contains("splat view: rendered 3 frames of"), "no summary of 3 frames: {said}");
    // Without a desktop session, Mesa's device-select layer would print XDG_RUNTIME_DIR errors.
    assert!(!said.contains("XDG_RUNTIME_DIR"), "the graphics stack printed: {said}");
}

#[test]
fn bad_input_fails_before_any_window() {
    let missing = viewer(&["no-such-scene.ply"]).env_remove("DISPLAY").output().unwrap();
    assert_eq!(missing.status.code(), Some(1));
    assert!(text(&missing).contains("no-such-scene.ply"), "{}", text(&missing));
    let cloud = fixture("cloud.ply");
    let cameras = fixture("cloud.cameras.json");
    let index = viewer(&[cloud.to_str().unwrap(), "--camera", cameras.to_str().unwrap(), "--camera-index", "5"])
        .env_remove("DISPLAY")
        .output()
        .unwrap();
    assert!(text(&index).contains("--camera-index 5 but"), "{}", text(&index));
    let up = viewer(&["--up", "0,0,0"]).output().unwrap();
    assert!(!up.status.success() && text(&up).contains("not a direction"), "{}", text(&up));
}

#[test]
fn without_a_desktop_the_error_says_how_to_get_one() {
    let output = viewer(&[fixture("cloud.ply").to_str().unwrap()])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1), "{}", text(&output));
    assert!(text(&output).contains("xvfb-run"), "{}", text(&output));
}
