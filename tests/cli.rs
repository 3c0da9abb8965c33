//! The `prismap` binary: renders, writes stats, and refuses bad arguments with a clear
//! message, a non-zero status and no partial file.

use std::path::PathBuf;
use std::process::Command;

fn prismap() -> Command {
    Command::new(env!("CARGO_BIN_EXE_prismap"))
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("prismap-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn render_picks_the_bins_the_scene_needs_unless_told() {
    // As the viewer's "auto": 100 bins for dispersive glass, 20 for a spectral light, 8
    // for RGB inputs; --bins and --preset win.
    let dir = temp_dir("bins");
    let cases: [(&str, &[&str], u64); 6] = [
        ("prism", &[], 100),
        ("cornell-blackbody", &[], 20),
        ("cornell-box", &[], 8),
        ("cornell-box", &["--bins", "12"], 12),
        ("prism", &["--preset", "preview"], 20),
        // RGB storage has three channels and no bins to choose.
        ("prism", &["--storage", "rgb"], 3),
    ];
    for (i, (scene, extra, bins)) in cases.into_iter().enumerate() {
        let stats = dir.join(format!("{i}.json"));
        let out = prismap()
            .args([
                "render",
                scene,
                "--passes",
                "1",
                "--size",
                "16x16",
                "--photons",
                "2000",
            ])
            .args(extra)
            .arg("-o")
            .arg(dir.join(format!("{i}.png")))
            .arg("--stats")
            .arg(&stats)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{scene} {extra:?}: {stderr}");
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
        assert_eq!(s["bins"], bins, "{scene} {extra:?}");
        // A chosen count says why, once; a given one says nothing about it.
        assert_eq!(
            stderr.contains("(--bins sets them)"),
            extra.is_empty(),
            "{stderr}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn stats_say_where_caustic_photons_were_aimed_at_the_glass() {
    // Blender's sun-lit glass ball and rough materials, and the prism's ceiling panel, aim
    // their caustic-only photons, and send fewer of them than the unaimed (factor − 1) ×
    // photons (the prism's spot, narrower than its glass, keeps its whole share); the
    // Cornell box has no glass.
    let dir = temp_dir("aimed");
    let blender = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenes/blender/textured-glass.glb"
    );
    let rough = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenes/blender/rough-materials.glb"
    );
    // (scene, aimed, spheres aimed at): rough-materials.glb's gold ball, frosted ball,
    // green slab and mirror stand apart and get one each.
    for (i, (scene, aimed, targets)) in [
        (blender, true, 1),
        (rough, true, 4),
        ("prism", true, 1),
        ("cornell-box", false, 0),
    ]
    .into_iter()
    .enumerate()
    {
        let stats = dir.join(format!("{i}.json"));
        succeeds(
            prismap()
                .args(["render", scene, "--passes", "1", "--size", "16x16"])
                .args(["--photons", "2000", "--caustic-factor", "4", "--bins", "8"])
                .arg("-o")
                .arg(dir.join(format!("{i}.png")))
                .arg("--stats")
                .arg(&stats),
        );
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
        let photons = &s["photons"];
        assert_eq!(photons["caustic_aimed"], aimed, "{scene}: {photons}");
        assert_eq!(photons["caustic_targets"], targets, "{scene}: {photons}");
        let extra = photons["caustic_emitted"].as_u64().unwrap();
        if aimed {
            assert!((1..6000).contains(&extra), "{scene}: {photons}");
        } else {
            assert_eq!(extra, 0, "{scene}: {photons}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn render_writes_png_exr_and_stats() {
    let dir = temp_dir("ok");
    let png = dir.join("cb.png");
    let stats = dir.join("cb.json");
    succeeds(
        prismap()
            .args([
                "render",
                "cornell-box",
                "--bins",
                "8",
                "--storage",
                "full",
                "--photons",
                "5000",
                "--passes",
                "2",
            ])
            .args(["--size", "32x24", "--fg", "2", "--threads", "2", "-o"])
            .arg(&png)
            .arg("--stats")
            .arg(&stats),
    );
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (32, 24));
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    for key in [
        "scene",
        "bins",
        "storage",
        "size",
        "passes",
        "seed",
        "photons",
        "memory_bytes",
        "bytes_per_photon",
        "seconds",
        "nonfinite_pixels",
        "skipped",
    ] {
        assert!(s.get(key).is_some(), "stats lack {key}: {s}");
    }
    for key in [
        "emitted",
        "stored_global",
        "stored_caustic",
        "spike_records",
    ] {
        assert!(s["photons"].get(key).is_some(), "{key}");
    }
    for key in ["global_map", "caustic_map", "photon_maps", "film", "bvh"] {
        assert!(s["memory_bytes"][key].as_u64().is_some(), "{key}");
    }
    assert_eq!(s["scene"], "cornell-box");
    assert_eq!(s["storage"], "full");
    assert_eq!(s["bins"], 8);
    assert_eq!(s["passes"], 2);
    assert_eq!(s["photons"]["emitted"], 10_000);
    assert_eq!(s["bytes_per_photon"], 16.0 + 4.0 * 8.0 + 1.0);
    assert_eq!(s["nonfinite_pixels"], 0);
    let exr = dir.join("cb.exr");
    succeeds(
        prismap()
            .args([
                "render",
                "prism",
                "--photons",
                "3000",
                "--passes",
                "1",
                "--size",
                "16x16",
                "-o",
            ])
            .arg(&exr),
    );
    assert_eq!(prismap::output::read_exr(&exr).unwrap().width, 16);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `prismap render SCENE` for 2 passes of 4 000 photons at `size` with `extra` flags, into
/// `dir/NAME.exr` with its stats: the EXR's bytes and the stats.
fn render_with_stats(
    dir: &std::path::Path,
    scene: &str,
    size: &str,
    extra: &[&str],
    name: &str,
) -> (Vec<u8>, prismap::output::Stats) {
    let (exr, stats) = (
        dir.join(format!("{name}.exr")),
        dir.join(format!("{name}.json")),
    );
    let mut cmd = prismap();
    cmd.args(["render", scene, "--photons", "4000", "--passes", "2"])
        .args(["--size", size])
        .args(extra)
        .arg("-o")
        .arg(&exr)
        .arg("--stats")
        .arg(&stats);
    succeeds(&mut cmd);
    let s = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    (std::fs::read(&exr).unwrap(), s)
}

#[test]
fn no_fg_pool_renders_each_pixel_from_its_own_rays_and_the_stats_say_which() {
    let dir = temp_dir("pool");
    let run =
        |extra: &[&str], name: &str| render_with_stats(&dir, "cornell-box", "24x24", extra, name);
    let (pooled, on) = run(&[], "pooled");
    let (own, off) = run(&["--no-fg-pool"], "own");
    assert!(on.fg_pool && !off.fg_pool);
    assert_ne!(pooled, own, "pooling changes the pixels' indirect light");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn fg_guide_and_glass_split_change_the_prism_and_the_stats_say_so() {
    let dir = temp_dir("guide-split");
    let run = |extra: &[&str], name: &str| render_with_stats(&dir, "prism", "48x27", extra, name);
    let (default, s) = run(&[], "default");
    assert!(
        !s.fg_guide && s.glass_split == 4,
        "{} {}",
        s.fg_guide,
        s.glass_split
    );
    let (one, s) = run(&["--glass-split", "1"], "one");
    assert_eq!(s.glass_split, 1);
    assert_ne!(
        default, one,
        "four wavelengths past the glass change its pixels"
    );
    let (with_guide, s) = run(&["--fg-guide"], "guided");
    assert!(s.fg_guide);
    assert_ne!(
        default, with_guide,
        "guided final-gather rays change the pixels"
    );
    // An absurd split is refused, naming the flag and the value.
    let out = prismap()
        .args(["render", "prism", "--glass-split", "0", "--passes", "1"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--glass-split") && err.contains('0'), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn same_command_gives_a_bit_identical_exr_on_1_2_and_8_threads() {
    let dir = temp_dir("det");
    let run = |threads: &str, name: &str| {
        let p = dir.join(name);
        let out = prismap()
            .args([
                "render",
                "prism",
                "--photons",
                "8000",
                "--passes",
                "2",
                "--size",
                "40x30",
                "--threads",
                threads,
                "-o",
            ])
            .arg(&p)
            .output()
            .unwrap();
        assert!(out.status.success());
        std::fs::read(&p).unwrap()
    };
    let one = run("1", "a.exr");
    assert_eq!(one, run("2", "b.exr"));
    assert_eq!(one, run("8", "c.exr"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Runs `cmd` expecting success (its stderr in the message if not); returns its output.
fn succeeds(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Runs prismap expecting failure; returns stderr.
fn fails(args: &[&str]) -> String {
    let out = prismap().args(args).output().unwrap();
    assert!(!out.status.success(), "{args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn bad_arguments_fail_clearly_and_leave_no_file() {
    let dir = temp_dir("bad");
    let png = dir.join("x.png");
    let p = png.to_str().unwrap();
    let e = fails(&["render", "cornell-box", "--bins", "0", "-o", p]);
    assert!(e.contains("bins") && e.contains('0'), "{e}");
    let e = fails(&["render", "cornell-box", "--bins", "1000000", "-o", p]);
    assert!(e.contains("1000000"), "{e}");
    let e = fails(&["render", "cornell-box", "--size", "-5x3", "-o", p]);
    assert!(e.contains("size"), "{e}");
    let e = fails(&["render", "cornell-box", "--size", "0x3", "-o", p]);
    assert!(e.contains("--size 0x3"), "{e}");
    // Every bad value is named by the flag the user typed, not an internal field.
    for (flag, value) in [
        ("--photons", "0"),
        ("--passes", "0"),
        ("--seconds", "-2"),
        ("--exposure", "-1"),
        ("--photon-budget", "-3"),
        ("--fg", "5000"),
        ("--alpha", "1.5"),
        ("--max-bounces", "0"),
        ("--preset", "fast"),
    ] {
        let e = fails(&["render", "cornell-box", flag, value, "-o", p]);
        assert!(
            e.contains(&format!("{flag} {value}")),
            "{flag} {value}: {e}"
        );
    }
    let e = fails(&["render", "cornell-box", "--storage", "zip", "-o", p]);
    assert!(e.contains("zip"), "{e}");
    let e = fails(&["render", "no-such-scene.gltf", "-o", p]);
    assert!(e.contains("no-such-scene.gltf"), "{e}");
    let e = fails(&["render", "cornell-box", "--threads", "0", "-o", p]);
    assert!(e.contains("threads"), "{e}");
    let e = fails(&[
        "render",
        "cornell-box",
        "-o",
        dir.join("missing/x.png").to_str().unwrap(),
    ]);
    assert!(e.contains("does not exist"), "{e}");
    let e = fails(&[
        "render",
        "cornell-box",
        "-o",
        dir.join("x.bmp").to_str().unwrap(),
    ]);
    assert!(e.contains(".png"), "{e}");
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        0,
        "no partial files"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_readmes_cargo_run_picks_the_prismap_binary() {
    // `cargo run --release` at the top is the README's main command. The workspace builds
    // both crates by default and the engine has a binary of its own (`jh_table`), so
    // without a `default-run` cargo refuses to choose: what cargo's metadata says it runs.
    let out = succeeds(
        Command::new(env!("CARGO"))
            .args([
                "metadata",
                "--format-version",
                "1",
                "--no-deps",
                "--offline",
            ])
            .current_dir(env!("CARGO_MANIFEST_DIR")),
    );
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let packages = meta["packages"].as_array().unwrap();
    let default_members: Vec<&str> = meta["workspace_default_members"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m.as_str().unwrap())
        .collect();
    let bins: Vec<&str> = packages
        .iter()
        .filter(|p| default_members.contains(&p["id"].as_str().unwrap()))
        .flat_map(|p| p["targets"].as_array().unwrap())
        .filter(|t| t["kind"].as_array().unwrap().iter().any(|k| k == "bin"))
        .map(|t| t["name"].as_str().unwrap())
        .collect();
    assert!(bins.contains(&"prismap"), "{bins:?}");
    if bins.len() > 1 {
        let root = packages.iter().find(|p| p["name"] == "prismap").unwrap();
        assert_eq!(
            root["default_run"], "prismap",
            "binaries {bins:?}: `cargo run` needs the root package's default-run"
        );
    }
}
