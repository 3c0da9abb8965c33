//! The viewer's behaviour, headless with egui_kittest: restarts on setting changes, the
//! memory readout, the pixel probe against the engine, saving.

use std::time::{Duration, Instant};

use egui_kittest::Harness;
use egui_kittest::kittest::{NodeT, Queryable};
use prismap::app::{SceneSource, ViewerApp, format_bytes};
use prismap::photon::Storage;
use prismap::render::{RenderSession, RenderSettings};

fn settings() -> RenderSettings {
    RenderSettings {
        bins: 20,
        storage: Storage::Full,
        width: 48,
        height: 48,
        photons_per_pass: 4_000,
        final_gather_rays: 1,
        ..RenderSettings::default()
    }
}

fn harness(scene: &str) -> Harness<'static, ViewerApp> {
    harness_of(SceneSource::Builtin(scene.into()), 1400.0, 1000.0)
}

/// The viewer on `source` with the tests' settings, in a `w` × `h` window.
fn harness_of(source: SceneSource, w: f32, h: f32) -> Harness<'static, ViewerApp> {
    let ctx = egui::Context::default();
    let app = ViewerApp::new(&ctx, source, settings(), None);
    Harness::builder()
        .with_size(egui::vec2(w, h))
        .build_ui_state(|ui, app: &mut ViewerApp| app.ui(ui), app)
}

/// Steps the UI until `cond` holds (the worker renders in the background).
fn wait_until(h: &mut Harness<'static, ViewerApp>, what: &str, cond: impl Fn(&ViewerApp) -> bool) {
    let start = Instant::now();
    loop {
        h.step();
        if cond(h.state()) {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Waits for two passes, so that the noise estimate (odd against even passes) and its rows
/// are on screen, then pauses (space): a pass still in flight when the render pauses then
/// moves nothing, and the panels keep their layout between looks.
fn pause_with_every_row_shown(h: &mut Harness<'static, ViewerApp>) {
    wait_until(h, "two passes and a noise estimate", |a| {
        passes(a) >= 2
            && a.snapshot
                .as_ref()
                .is_some_and(|s| s.noise_psnr_db.is_some())
    });
    h.key_press(egui::Key::Space);
    h.run_steps(4);
    assert!(h.state().paused, "space pauses");
}

fn passes(app: &ViewerApp) -> u64 {
    app.snapshot
        .as_ref()
        .filter(|s| !s.preview)
        .map_or(0, |s| s.stats.passes)
}

#[test]
fn switching_storage_restarts_and_changes_the_memory_readout() {
    let mut h = harness("cornell-box");
    wait_until(&mut h, "a first pass", |a| passes(a) >= 1);
    h.step();
    // The snapshot the frame just drew (passes keep arriving; each stores other photons).
    let full = h.state().snapshot.clone().unwrap();
    assert_eq!(full.bytes_per_photon, 17.0 + 4.0 * 20.0);
    let full_text = format_bytes(full.memory.photon_maps as f64);
    assert!(
        h.query_all_by_label(&full_text).count() >= 1,
        "the readout shows {full_text}"
    );
    let gen_before = h.state().last_restart_generation;
    h.get_by_label("compact").click();
    h.step();
    assert!(
        h.state().last_restart_generation > gen_before,
        "storage change restarts"
    );
    assert_eq!(h.state().settings.storage, Storage::Compact);
    wait_until(&mut h, "a compact pass", |a| {
        a.snapshot
            .as_ref()
            .is_some_and(|s| s.bytes_per_photon == 29.0)
    });
    h.step();
    let compact = h.state().snapshot.clone().unwrap();
    assert!(
        compact.memory.photon_maps * 3 < full.memory.photon_maps,
        "compact uses far less"
    );
    let compact_text = format_bytes(compact.memory.photon_maps as f64);
    assert!(
        h.query_all_by_label(&compact_text).count() >= 1,
        "the readout shows {compact_text}"
    );
    assert_eq!(
        h.query_all_by_label(&full_text).count(),
        0,
        "the old readout is gone"
    );
}

#[test]
fn changing_bins_restarts() {
    let mut h = harness("cornell-box");
    wait_until(&mut h, "a first pass", |a| passes(a) >= 1);
    let gen_before = h.state().last_restart_generation;
    h.get_by_label("100").click();
    h.step();
    assert!(h.state().last_restart_generation > gen_before);
    wait_until(&mut h, "a 100-bin pass", |a| {
        a.snapshot
            .as_ref()
            .is_some_and(|s| s.bins == 100 && !s.preview)
    });
    // "auto" picks and explains.
    h.get_by_label("auto").click();
    h.step();
    assert!(h.state().auto_bins);
    assert_eq!(h.state().settings.bins, 8, "RGB-only scene");
    h.step();
    h.get_by_label_contains("only RGB inputs");
}

#[test]
fn clicking_a_pixel_plots_the_engines_spectrum_for_it() {
    let mut h = harness("prism");
    wait_until(&mut h, "a first pass", |a| passes(a) >= 1);
    h.get_by_role(egui::accesskit::Role::Image).click();
    h.step();
    let probe = h.state().probe.expect("the click probes a pixel");
    wait_until(&mut h, "probe data", |a| {
        a.snapshot.as_ref().is_some_and(|s| {
            s.probes
                .iter()
                .any(|p| (p.x, p.y) == probe && p.passes >= 2)
        })
    });
    h.set_size(egui::vec2(1400.0, 1000.0));
    h.step();
    h.get_by_label_contains(&format!("({}, {})", probe.0, probe.1));
    let snap = h.state().snapshot.clone().unwrap();
    let shown = snap.probes.iter().find(|p| (p.x, p.y) == probe).unwrap();
    // The engine, same settings: passes before the click without a probe, then with it.
    let scene = prismap::scene::load_builtin("prism").unwrap();
    let mut engine = RenderSession::new(&scene, settings()).unwrap();
    let before = snap.stats.passes - shown.passes;
    for _ in 0..before {
        engine.run_pass().unwrap();
    }
    engine.set_probes(&[probe]);
    for _ in 0..shown.passes {
        engine.run_pass().unwrap();
    }
    assert_eq!(
        engine.probes()[0].sum,
        shown.sum,
        "the viewer's probe is the engine's spectrum"
    );
    // The probed spectrum's colour is the pixel's colour (identical when the probe covers every pass).
    let w = engine.scene().grid.srgb_weights();
    let mean = shown.mean();
    let rgb: Vec<f32> = (0..3)
        .map(|c| w.iter().zip(&mean).map(|(w, v)| w[c] * v).sum())
        .collect();
    if before == 0 {
        let px = snap.image.get(probe.0, probe.1);
        for c in 0..3 {
            assert!(
                (rgb[c] - px[c]).abs() <= 1e-4 * (1.0 + px[c].abs()),
                "{rgb:?} vs {px:?}"
            );
        }
    }
}

#[test]
fn saving_writes_png_and_exr() {
    let mut h = harness("cornell-box");
    let dir = std::env::temp_dir().join(format!("prismap-viewer-save-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    h.state_mut().save_dir = dir.clone();
    wait_until(&mut h, "a first pass", |a| passes(a) >= 1);
    h.get_by_label("Save PNG").click();
    h.step();
    h.get_by_label("Save EXR").click();
    h.step();
    let files: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(files.iter().any(|f| f.ends_with(".png")), "{files:?}");
    assert!(files.iter().any(|f| f.ends_with(".exr")), "{files:?}");
    let png = files.iter().find(|f| f.ends_with(".png")).unwrap();
    let img = image::open(dir.join(png)).unwrap();
    assert_eq!((img.width(), img.height()), (48, 48));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn keep_spectra_then_save_writes_a_spectral_exr() {
    // Issue #14: the viewer can save the film's bins. Off by default (no spectral film
    // memory that nothing reads); ticking "Keep spectra" keeps them from the next pass on.
    let mut h = harness("prism");
    let dir = std::env::temp_dir().join(format!("prismap-viewer-spectral-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    h.state_mut().save_dir = dir.clone();
    wait_until(&mut h, "a first pass", |a| passes(a) >= 1);
    assert!(h.state().snapshot.as_ref().unwrap().spectra.is_none());
    h.get_by_label("Keep spectra").click();
    h.step();
    wait_until(&mut h, "a pass with spectra", |a| {
        a.snapshot.as_ref().is_some_and(|s| s.spectra.is_some())
    });
    h.get_by_label("Save spectral EXR").click();
    h.step();
    let file = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.to_string_lossy().ends_with(".spectral.exr"))
        .expect("a spectral EXR was saved");
    let (spectra, rgb) = prismap::output::read_spectral_exr(&file).unwrap();
    let bins = h.state().snapshot.as_ref().unwrap().bins;
    assert_eq!(spectra.wavelengths.len(), bins);
    assert_eq!((spectra.width, spectra.height), (48, 48));
    assert!(rgb.is_some());
    assert!(spectra.values.iter().any(|v| *v > 0.0));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn reaching_the_noise_target_marks_the_pass_and_can_pause() {
    // Issue #13: a "target reached" marker and an optional stop at the target.
    let mut h = harness("cornell-box");
    h.state_mut().target_db = 12.0;
    h.state_mut().stop_at_target = true;
    wait_until(&mut h, "the target", |a| a.target_is_reached());
    let (_, at_pass, _) = h.state().target_reached.unwrap();
    assert!(at_pass >= 2, "the estimate needs two passes: {at_pass}");
    assert!(h.state().paused, "stop at target pauses");
    let db = h.state().snapshot.as_ref().unwrap().noise_psnr_db.unwrap();
    assert!(db >= 12.0, "{db}");
    assert!(
        h.state().status.contains("target 12 dB reached"),
        "{}",
        h.state().status
    );
    // A higher target is not reached yet: the marker goes.
    h.state_mut().target_db = 80.0;
    h.state_mut().target_reached = None;
    h.step();
    assert!(!h.state().target_is_reached());
}

#[test]
fn the_denoised_view_is_display_only() {
    // Issue #13: an optional, labelled denoised display; the film and saves stay raw.
    let mut h = harness("cornell-box");
    h.state().stop_after(Some(2));
    wait_until(&mut h, "2 passes", |a| passes(a) == 2);
    let raw = h.state().snapshot.as_ref().unwrap().image.clone();
    h.get_by_label("Denoised view").click();
    h.step();
    wait_until(&mut h, "a denoised image", |a| {
        a.snapshot.as_ref().is_some_and(|s| s.denoised.is_some())
    });
    let snap = h.state().snapshot.clone().unwrap();
    assert!(h.state().denoise_view);
    assert_eq!(*snap.image, *raw, "the raw image is unchanged");
    assert_ne!(*snap.denoised.unwrap(), *raw, "the view is filtered");
    h.get_by_label("DENOISED VIEW (display only)");
    // D toggles it back.
    h.key_press(egui::Key::D);
    h.step();
    assert!(!h.state().denoise_view);
}

#[test]
fn automatic_exposure_is_the_engines_metering_of_the_shown_image() {
    // The worker meters each image (so the UI thread does not); the exposure the viewer
    // shows it at is what `prismap render` would pick for it, emitters left out.
    let mut h = harness("cornell-box");
    h.state().stop_after(Some(2));
    wait_until(&mut h, "2 passes", |a| passes(a) == 2);
    h.step();
    let app = h.state();
    let shown = app.snapshot.as_ref().unwrap();
    assert!(app.auto_exposure);
    assert_eq!(shown.emitter_pixels.len(), shown.image.pixels.len());
    let metered = prismap::output::auto_exposure_skipping(&shown.image, &shown.emitter_pixels);
    assert_eq!(app.exposure.to_bits(), metered.to_bits());
    assert_ne!(
        metered.to_bits(),
        prismap::output::auto_exposure(&shown.image).to_bits(),
        "the light seen directly must change the metering, or this test shows nothing"
    );
}

#[test]
fn viewer_image_after_n_passes_equals_the_engines() {
    let mut h = harness("prism");
    h.state().stop_after(Some(3));
    wait_until(&mut h, "3 passes", |a| passes(a) == 3);
    let shown = h.state().snapshot.clone().unwrap();
    let scene = prismap::scene::load_builtin("prism").unwrap();
    let mut engine = RenderSession::new(&scene, settings()).unwrap();
    for _ in 0..3 {
        engine.run_pass().unwrap();
    }
    assert!(
        engine
            .image()
            .pixels
            .iter()
            .zip(&shown.image.pixels)
            .all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits)),
        "the viewer renders exactly what `prismap render` renders"
    );
}

/// Clicks the `label` toggle on `scene` after a first pass and checks that the render
/// restarts with the flag `field` of the settings flipped from `was`, and that the
/// viewer's image after 2 passes is the engine's with the flag flipped, bit for bit, and
/// not the engine's without the click.
fn a_toggle_restarts_with_the_engines_image(
    scene_name: &str,
    label: &str,
    field: fn(&mut RenderSettings) -> &mut bool,
    was: bool,
) {
    let mut h = harness(scene_name);
    h.state().stop_after(Some(2));
    wait_until(&mut h, "a first pass", |a| passes(a) >= 1);
    assert_eq!(
        *field(&mut h.state().settings.clone()),
        was,
        "{label} starts {was}"
    );
    let gen_before = h.state().last_restart_generation;
    h.get_by_label(label).click();
    h.step();
    assert!(h.state().last_restart_generation > gen_before, "restarts");
    assert_eq!(
        *field(&mut h.state().settings.clone()),
        !was,
        "{label} flips"
    );
    wait_until(&mut h, "2 passes after the click", |a| {
        a.last_restart_generation > gen_before && passes(a) == 2
    });
    let shown = h.state().snapshot.clone().unwrap();
    let scene = prismap::scene::load_builtin(scene_name).unwrap();
    let render = |on: bool| {
        let mut s = h.state().settings.clone();
        *field(&mut s) = on;
        let mut engine = RenderSession::new(&scene, s).unwrap();
        for _ in 0..2 {
            engine.run_pass().unwrap();
        }
        engine.image()
    };
    let same = |a: &prismap::render::Image| {
        (a.pixels.iter().zip(&shown.image.pixels))
            .all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits))
    };
    assert!(
        same(&render(!was)),
        "the viewer renders the engine's image after the click"
    );
    assert!(!same(&render(was)), "which the one before it is not");
}

#[test]
fn the_guide_toggle_restarts_with_guided_final_gather_rays() {
    // Guiding is off by default (the prism has guides: its walls are lit by the spot's
    // bright patches).
    a_toggle_restarts_with_the_engines_image("prism", "guide", |s| &mut s.guide_gather, false);
}

#[test]
fn the_pool_toggle_restarts_with_each_pixels_own_rays() {
    // Pooling is on by default.
    a_toggle_restarts_with_the_engines_image("cornell-box", "pool", |s| &mut s.pool_gather, true);
}

#[test]
fn the_viewer_renders_with_wgpu_headless() {
    // egui_kittest's wgpu renderer: Mesa's software Vulkan (mesa-vulkan-drivers), no display.
    let ctx = egui::Context::default();
    let app = ViewerApp::new(&ctx, SceneSource::Builtin("prism".into()), settings(), None);
    let mut h = Harness::builder()
        .with_size(egui::vec2(1000.0, 700.0))
        .wgpu()
        .build_ui_state(|ui, app: &mut ViewerApp| app.ui(ui), app);
    wait_until(&mut h, "a first pass", |a| passes(a) >= 1);
    h.step();
    let img = h.render().expect("wgpu renders headless");
    assert_eq!((img.width(), img.height()), (1000, 700));
    let mut colours: Vec<[u8; 4]> = img.pixels().map(|p| p.0).collect();
    colours.sort();
    colours.dedup();
    assert!(
        colours.len() > 50,
        "only {} colours: nothing drawn?",
        colours.len()
    );
}

#[test]
fn the_viewer_starts_on_the_scenes_own_bin_count() {
    // Issue #13: `prismap view` without --bins picks the bins for the scene ("auto"), and
    // the panel says so: 100 for the dispersive prism, 8 for the RGB Cornell box.
    for (scene, want) in [("prism", 100), ("cornell-box", 8)] {
        let ctx = egui::Context::default();
        let mut app = ViewerApp::new(&ctx, SceneSource::Builtin(scene.into()), settings(), None);
        app.keep_auto_bins();
        assert!(app.auto_bins, "{scene}");
        assert_eq!(app.settings.bins, want, "{scene}");
        let mut h = Harness::builder()
            .with_size(egui::vec2(1400.0, 1000.0))
            .build_ui_state(|ui, app: &mut ViewerApp| app.ui(ui), app);
        wait_until(&mut h, "a first pass", |a| passes(a) >= 1);
        assert_eq!(
            h.state().snapshot.as_ref().unwrap().bins,
            want,
            "{scene}: the worker renders at the automatic bin count"
        );
        h.get_by_label_contains(&format!("{want} bins:"));
    }
}

#[test]
fn keyboard_shortcuts_switch_storage_pause_and_open_a_typed_path() {
    // Issue #13: 1/2/3 switch storage, space pauses and resumes, and Enter in the path
    // field opens what was typed there.
    let mut h = harness("cornell-box");
    h.step();
    h.key_press(egui::Key::Num3);
    h.step();
    assert_eq!(h.state().settings.storage, Storage::Rgb);
    h.key_press(egui::Key::Num2);
    h.step();
    assert_eq!(h.state().settings.storage, Storage::Compact);
    h.key_press(egui::Key::Space);
    h.step();
    assert!(h.state().paused, "space pauses");
    h.key_press(egui::Key::Space);
    h.step();
    assert!(!h.state().paused, "space resumes");
    // A path typed into the field, then Enter: the scene opens (keys typed there are text,
    // not shortcuts: the storage stays).
    let path = format!("{}/scenes/prism.gltf", env!("CARGO_MANIFEST_DIR"));
    h.get_by_role(egui::accesskit::Role::TextInput).click();
    h.step();
    h.get_by_role(egui::accesskit::Role::TextInput)
        .type_text(&path);
    h.step();
    h.key_press(egui::Key::Enter);
    h.step();
    h.step();
    assert_eq!(
        *h.state().source(),
        SceneSource::File(path.clone().into()),
        "Enter opened the typed path"
    );
    assert_eq!(h.state().settings.storage, Storage::Compact);
}

#[test]
fn the_scene_list_shows_each_scene_once_and_the_fixtures() {
    // Issue #13: the built-in scenes were listed twice (built in, and as scenes/*.gltf);
    // the fixtures in subfolders were not listed at all.
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let files = prismap::app::list_scene_files(&dir);
    let names: Vec<String> = files
        .iter()
        .map(|p| p.strip_prefix(&dir).unwrap().display().to_string())
        .collect();
    assert!(
        !names
            .iter()
            .any(|n| n == "prism.gltf" || n == "cornell-box.gltf"),
        "{names:?}"
    );
    for want in ["blender/rough-materials.glb", "khronos/BoxTextured.gltf"] {
        assert!(names.iter().any(|n| n == want), "{want} missing: {names:?}");
    }
}

#[test]
fn compare_mode_keeps_a_while_b_switches_storage() {
    // Issue #13: freeze full storage as "A", switch to compact: the live image and probe
    // are re-measured, A's image and probe spectrum stay, and the two are compared (PSNR,
    // ΔE2000); the difference view is drawn from both.
    let mut h = harness("prism");
    h.state_mut().set_probe((20, 20));
    // The worker may already be rendering when the probe is set: wait for passes that
    // carry it.
    wait_until(&mut h, "two full passes with the probe", |a| {
        passes(a) >= 2
            && a.snapshot
                .as_ref()
                .is_some_and(|s| s.probes.iter().any(|p| (p.x, p.y) == (20, 20)))
    });
    h.key_press(egui::Key::F);
    h.step();
    let a = h.state().compare.clone().expect("F froze A");
    assert!(a.label.starts_with("full"), "{}", a.label);
    let a_probe = a
        .probes
        .iter()
        .find(|p| p.pixel == (20, 20))
        .expect("A keeps the probe");
    assert_eq!(a_probe.spectrum.len(), 20);
    h.key_press(egui::Key::Num2);
    h.step();
    assert_eq!(h.state().settings.storage, Storage::Compact);
    wait_until(&mut h, "two compact passes", |a| {
        passes(a) >= 2 && a.settings.storage == Storage::Compact
    });
    h.step();
    let app = h.state();
    // A is unchanged: same image, same probe spectrum.
    let still = app.compare.as_ref().unwrap();
    assert!(std::sync::Arc::ptr_eq(&still.image, &a.image));
    assert_eq!(still.probes, a.probes);
    let g = app.agreement.expect("B is compared with A");
    println!("compact against full: {g:?}");
    assert!(g.psnr_db.is_finite() && g.psnr_db > 10.0, "{g:?}");
    assert!(app.compare_texture().is_some());
    h.get_by_label_contains("B against A: PSNR");
    // The difference view, then leaving compare mode.
    h.state_mut().compare_view = prismap::app::compare::CompareView::Difference;
    let ctx = h.ctx.clone();
    h.state_mut().update_compare(&ctx);
    assert!(h.state().compare_texture().is_some());
    h.key_press(egui::Key::F);
    h.step();
    assert!(h.state().compare.is_none() && h.state().agreement.is_none());
}

#[test]
fn a_file_that_fails_to_open_is_reported_as_an_error() {
    // Issue #13: errors were grey status text like any other message.
    let mut h = harness("cornell-box");
    h.step();
    h.state_mut()
        .open(SceneSource::File("no/such/scene.gltf".into()));
    h.step();
    let app = h.state();
    assert!(app.status_is_error, "{}", app.status);
    assert!(app.status.contains("no/such/scene.gltf"), "{}", app.status);
    assert_eq!(*app.source(), SceneSource::Builtin("cornell-box".into()));
}

#[test]
fn f1_opens_the_keyboard_help_listing_every_shortcut() {
    // Issue #13: shortcuts listed in a help overlay (F1 or ?), closed by Escape.
    let mut h = harness("cornell-box");
    h.step();
    assert!(h.query_by_label("Keyboard shortcuts").is_none());
    h.key_press(egui::Key::F1);
    h.run_steps(2);
    assert!(h.state().show_help);
    h.get_by_label("Keyboard shortcuts");
    for (key, what) in prismap::app::panels::SHORTCUTS {
        assert!(h.query_all_by_label(key).next().is_some(), "{key}");
        h.get_by_label(what);
    }
    h.key_press(egui::Key::Escape);
    h.run_steps(2);
    assert!(!h.state().show_help);
    assert!(h.query_by_label("Keyboard shortcuts").is_none());
}

#[test]
fn the_main_controls_explain_themselves_on_hover() {
    // Issue #13: a tooltip on every control. Each of these, hovered, shows its sentence.
    let mut h = harness("cornell-box");
    h.ctx
        .global_style_mut(|s| s.interaction.tooltip_delay = 0.0);
    wait_until(&mut h, "a first pass", |a| passes(a) >= 1);
    for (control, tip) in [
        ("full", "every stored photon keeps all N bins"),
        ("compact", "lossless (−1, bin, amplitude) spike"),
        ("packed", "19 bytes a photon"),
        ("rgb", "the plain RGB renderer"),
        ("Jakob–Hanika 2019", "exactly the colours the scene gives"),
        ("Smits 1999", "extra blue"),
        ("auto", "Bins chosen for the scene"),
        ("Denoised view", "Display only"),
        ("Keep spectra", "4 bytes per bin per pixel"),
        ("stop there", "Pause when the target is reached"),
        ("Freeze as A", ""),
    ] {
        h.get_by_label(control).hover();
        h.run_steps(3);
        if !tip.is_empty() {
            assert!(
                h.query_by_label_contains(tip).is_some(),
                "hovering {control:?} shows no tooltip containing {tip:?}"
            );
        }
    }
}

fn harness_sized(scene: &str, w: f32, h: f32) -> Harness<'static, ViewerApp> {
    harness_of(SceneSource::Builtin(scene.into()), w, h)
}

#[test]
fn every_panel_is_reachable_at_800x500_and_whole_at_1920x1080() {
    // Issue #13: nothing clipped in a small window (the side panels scroll to their last
    // control) and nothing needs scrolling in a large one.
    // The panels' rows are all on screen before the check (the noise estimate's rows and
    // its explanation come with the second pass) and the render is paused, so that no row
    // arriving between a scroll and the look moves a control (it did, about 1 run in 8).
    let last_controls = ["Save PNG", "Freeze as A", "stop there", "process resident"];
    for (w, h, scroll) in [(800.0, 500.0, true), (1920.0, 1080.0, false)] {
        let mut harness = harness_sized("cornell-box", w, h);
        pause_with_every_row_shown(&mut harness);
        let screen = egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(w, h));
        for label in last_controls {
            if scroll {
                harness.get_by_label(label).scroll_to_me();
                harness.run_steps(3);
            }
            let r = harness.get_by_label(label).rect();
            assert!(
                screen.contains_rect(r),
                "{w}×{h}: {label:?} at {r:?} is outside the window"
            );
        }
    }
}

/// Whether a node is a control a user operates (and so should explain itself on hover).
fn is_control(role: egui::accesskit::Role) -> bool {
    use egui::accesskit::Role;
    matches!(
        role,
        Role::Button
            | Role::CheckBox
            | Role::RadioButton
            | Role::Slider
            | Role::SpinButton
            | Role::ComboBox
            | Role::TextInput
            | Role::MultilineTextInput
            | Role::Switch
    )
}

/// Every text on screen (labels and control names) with how often it shows, to tell what
/// a hover added (a tooltip may repeat a text already there: a field's own description).
fn texts(h: &Harness<'static, ViewerApp>) -> std::collections::HashMap<String, usize> {
    let mut counts = std::collections::HashMap::new();
    for n in h.query_all(egui_kittest::kittest::By::new().predicate(|_| true)) {
        let a = n.accesskit_node();
        for t in [a.label(), a.value()].into_iter().flatten() {
            *counts.entry(t).or_insert(0) += 1;
        }
    }
    counts
}

#[test]
fn every_control_explains_itself_on_hover() {
    // Issue #13: a tooltip on every control — found from the UI's own accessibility tree,
    // not from a list: each control, hovered, adds a text to the screen that was not
    // there before. The render is paused so that nothing else changes between looks.
    let mut h = harness_sized("prism", 1920.0, 1080.0);
    h.ctx
        .global_style_mut(|s| s.interaction.tooltip_delay = 0.0);
    pause_with_every_row_shown(&mut h);
    let controls = |h: &Harness<'static, ViewerApp>| -> Vec<(String, egui::Rect)> {
        h.query_all(egui_kittest::kittest::By::new().predicate(|n| is_control(n.role())))
            .map(|n| {
                let a = n.accesskit_node();
                let name = a.label().or_else(|| a.value()).unwrap_or_default();
                (format!("{:?} {name:?}", a.role()), n.rect())
            })
            .collect()
    };
    let silent_ones = |h: &mut Harness<'static, ViewerApp>, list: &[(String, egui::Rect)]| {
        let mut silent = Vec::new();
        for (name, rect) in list {
            h.remove_cursor();
            h.run_steps(3);
            let before = texts(h);
            h.hover_at(rect.center());
            h.run_steps(3);
            let after = texts(h);
            if !after
                .iter()
                .any(|(t, n)| before.get(t).is_none_or(|b| n > b))
            {
                silent.push(name.clone());
            }
        }
        silent
    };
    let first = controls(&h);
    assert!(first.len() >= 25, "only {} controls found", first.len());
    let mut silent = silent_ones(&mut h, &first);
    // A probe (its spectrum panel) and compare mode (F) bring their own controls.
    h.remove_cursor();
    h.state_mut().set_probe((10, 10));
    h.state_mut().pin_probe();
    h.key_press(egui::Key::F);
    h.run_steps(4);
    let seen: Vec<&String> = first.iter().map(|c| &c.0).collect();
    let more: Vec<(String, egui::Rect)> = controls(&h)
        .into_iter()
        .filter(|c| !seen.contains(&&c.0))
        .collect();
    assert!(
        !more.is_empty(),
        "compare mode showed no controls of its own"
    );
    silent.extend(silent_ones(&mut h, &more));
    // The difference view's gain.
    h.state_mut().compare_view = prismap::app::compare::CompareView::Difference;
    h.run_steps(4);
    let seen: Vec<String> = first.iter().chain(&more).map(|c| c.0.clone()).collect();
    let gain: Vec<(String, egui::Rect)> = controls(&h)
        .into_iter()
        .filter(|c| !seen.contains(&c.0))
        .collect();
    assert!(gain.iter().any(|c| c.0.contains("gain")), "{gain:?}");
    silent.extend(silent_ones(&mut h, &gain));
    let more = [more, gain].concat();
    assert!(
        silent.is_empty(),
        "{} of {} controls show no tooltip: {silent:#?}",
        silent.len(),
        first.len() + more.len()
    );
}

#[test]
fn the_first_full_pass_replaces_the_quick_preview_even_when_it_is_the_last() {
    // The quick preview and the first full pass both count one pass: the viewer took them
    // for the same image, so with the render stopped after one pass (`view
    // --after-passes 1 --screenshot …`) the full pass was never shown and the screenshot
    // never taken.
    let ctx = egui::Context::default();
    let capture = prismap::app::Capture {
        path: std::env::temp_dir().join("prismap-first-pass.png"),
        after_passes: 1,
        compare_with: None,
    };
    // A full pass long enough (about a second) that the preview is on screen first.
    let slow = RenderSettings {
        width: 192,
        height: 192,
        photons_per_pass: 50_000,
        final_gather_rays: 16,
        ..settings()
    };
    let app = ViewerApp::new(
        &ctx,
        SceneSource::Builtin("cornell-box".into()),
        slow,
        Some(capture),
    );
    let mut h = Harness::builder()
        .with_size(egui::vec2(1400.0, 1000.0))
        .build_ui_state(|ui, app: &mut ViewerApp| app.ui(ui), app);
    wait_until(&mut h, "the quick preview", |a| {
        a.snapshot.as_ref().is_some_and(|s| s.preview)
    });
    wait_until(&mut h, "the first full pass on screen", |a| passes(a) == 1);
}

#[test]
fn a_new_pass_wakes_the_window_for_one_frame_and_an_idle_viewer_paints_none() {
    // A software-rendered window (no GPU) spends about 0.1 s of CPU on a frame: egui's
    // `request_repaint` painted two frames for every pass, and the viewer's passes took
    // 30 % longer in such a window than from the command line.
    // The viewer is made inside the first frame, so that its worker wakes this context.
    let mut h = Harness::builder()
        .with_size(egui::vec2(1400.0, 1000.0))
        .build_ui_state(
            |ui, app: &mut Option<ViewerApp>| {
                let ctx = ui.ctx().clone();
                app.get_or_insert_with(|| {
                    let a = ViewerApp::new(
                        &ctx,
                        SceneSource::Builtin("cornell-box".into()),
                        settings(),
                        None,
                    );
                    a.stop_after(Some(3));
                    a
                })
                .ui(ui)
            },
            None,
        );
    let shown = |h: &Harness<'static, Option<ViewerApp>>| h.state().as_ref().map_or(0, passes);
    let start = Instant::now();
    while shown(&h) < 3 {
        h.step();
        assert!(start.elapsed() < Duration::from_secs(120), "no third pass");
        std::thread::sleep(Duration::from_millis(10));
    }
    // The render has stopped: the window settles and then asks for no frame at all.
    std::thread::sleep(Duration::from_millis(300));
    let mut settled = false;
    for _ in 0..20 {
        h.step();
        if !h.ctx.has_requested_repaint() {
            settled = true;
            break;
        }
    }
    assert!(settled, "the idle viewer keeps asking for frames");
    // One more pass (the panels already show every row): the worker's news wakes the
    // window, once.
    h.state().as_ref().unwrap().stop_after(Some(4));
    let start = Instant::now();
    while !h.ctx.has_requested_repaint() {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "the second pass never woke the window"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    h.step();
    assert_eq!(shown(&h), 4, "the frame the news woke shows the pass");
    // A further frame is due only when egui itself asked for it in that frame (a grid
    // whose columns changed width settles in one more); the news itself asks for none.
    if h.ctx.has_requested_repaint() {
        h.step();
        let causes = h.ctx.repaint_causes();
        assert!(
            !causes.is_empty()
                && causes
                    .iter()
                    .all(|c| c.to_string().contains("egui") && !c.to_string().contains("src/app")),
            "the pass asked for a second frame (causes: {causes:?})"
        );
    }
}

#[test]
fn the_statistics_say_when_caustic_photons_are_aimed_at_the_glass() {
    // The prism's ceiling panel aims its caustic-only photons at the glass: the panel reads
    // "+ aimed at glass" with the pass's extra photons; the Cornell box has no glass, so
    // neither row.
    let mut h = harness("prism");
    wait_until(&mut h, "a first pass", |a| passes(a) >= 1);
    h.key_press(egui::Key::Space);
    h.run_steps(4);
    let st = h.state().snapshot.clone().unwrap().stats;
    assert!(st.caustic_photons_aimed, "the prism aims");
    assert!(st.caustic_photons_emitted > 0);
    h.get_by_label("+ aimed at glass");
    h.get_by_label(&st.caustic_photons_emitted.to_string());
    assert!(h.query_by_label("+ for caustics").is_none());
    let mut h = harness("cornell-box");
    wait_until(&mut h, "a first pass", |a| passes(a) >= 1);
    h.step();
    assert!(h.query_by_label("+ aimed at glass").is_none());
    assert!(h.query_by_label("+ for caustics").is_none());
}

#[test]
fn the_statistics_show_the_share_of_useful_photons_and_whether_emission_learned() {
    // A Sun through a roof window: few of its photons land where the camera looks, so its
    // emission learns within a few passes and the panel says so with the pass's share. The
    // Cornell box's area light does not learn: no row.
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/fixtures/sunlit-room.gltf");
    let mut h = harness_of(SceneSource::File(path), 1400.0, 1000.0);
    wait_until(&mut h, "learned emission", |a| {
        a.snapshot
            .as_ref()
            .is_some_and(|s| s.stats.emission_adapted)
    });
    h.key_press(egui::Key::Space);
    h.run_steps(4);
    let st = h.state().snapshot.clone().unwrap().stats;
    let share = st
        .emission_useful_share
        .expect("a Sun counts its useful photons");
    assert!(share > 0.0 && share < 1.0, "share {share}");
    h.get_by_label("useful photons (learned)");
    h.get_by_label(&format!("{:.0} %", 100.0 * share));
    let mut h = harness("cornell-box");
    wait_until(&mut h, "a first pass", |a| passes(a) >= 1);
    h.step();
    assert!(h.query_by_label("useful photons (learned)").is_none());
    assert!(h.query_by_label("useful photons").is_none());
}
