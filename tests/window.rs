//! The real viewer window under Xvfb (packages: xvfb, xauth, libgl1-mesa-dri, libegl1,
//! libvulkan1, mesa-vulkan-drivers, libxkbcommon-x11-0 — `.ci/run` installs them), and
//! the behaviour without any display.

use std::path::PathBuf;
use std::process::Command;

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("prismap-window-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn have(cmd: &str) -> bool {
    Command::new("sh")
        .arg("-c")
        .arg(format!("command -v {cmd}"))
        .output()
        .is_ok_and(|o| o.status.success())
}

#[test]
fn viewer_window_screenshot_under_xvfb_is_window_sized_and_not_blank() {
    if std::env::var_os("PRISMAP_SKIP_WINDOW_TEST").is_some() {
        eprintln!("PRISMAP_SKIP_WINDOW_TEST is set: window test not run");
        return;
    }
    assert!(
        have("xvfb-run"),
        "xvfb-run is missing: install the packages listed in .ci/run (or set PRISMAP_SKIP_WINDOW_TEST=1)"
    );
    let dir = temp_dir("xvfb");
    let shot = dir.join("window.png");
    let out = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1400x900x24"])
        .arg(env!("CARGO_BIN_EXE_prismap"))
        .args([
            "view",
            "prism",
            "--photons",
            "20000",
            "--size",
            "128x128",
            "--after-passes",
            "2",
            // Compare mode on the way: A (compact) frozen after 2 passes, B in full.
            "--compare-with",
            "full",
            "--screenshot",
        ])
        .arg(&shot)
        .env("XDG_RUNTIME_DIR", &dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "viewer failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&shot).unwrap().to_rgb8();
    assert_eq!((img.width(), img.height()), (1280, 800), "the whole window");
    // Not blank: many distinct colours (panels, text, the render with its rainbow).
    let mut colours: Vec<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    colours.sort();
    colours.dedup();
    assert!(
        colours.len() > 100,
        "only {} colours: blank window?",
        colours.len()
    );
    // Compare mode's split line (yellow) runs down the image.
    let yellow = img
        .pixels()
        .filter(|p| p.0[0] > 230 && p.0[1] > 230 && p.0[2] < 60)
        .count();
    assert!(
        yellow > 100,
        "{yellow} yellow pixels: no compare split line?"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn without_a_display_view_says_so_and_the_default_job_renders_headless() {
    let dir = temp_dir("nodisplay");
    let out = Command::new(env!("CARGO_BIN_EXE_prismap"))
        .arg("view")
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no display") && err.contains("prismap render"),
        "{err}"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_prismap"))
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.join("prism.png").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
