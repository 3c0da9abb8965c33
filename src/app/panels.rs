//! The viewer's panels: controls, statistics and memory, the pixel probe, the image.

use egui::{Color32, RichText};
use egui_plot::{Line, Plot, PlotPoints, Polygon};

use super::{Action, SceneSource, ToneMap, ViewerApp};
use crate::photon::Storage;
use crate::spectral::color::{SRGB_TO_XYZ, XYZ_TO_SRGB, dominant_wavelength, mul3, srgb8};

/// Image heights offered; the width follows the scene camera's aspect ratio.
const HEIGHTS: [u32; 5] = [128, 256, 384, 512, 768];

pub fn controls(app: &mut ViewerApp, ui: &mut egui::Ui) {
    egui::Panel::left("controls")
        .resizable(true)
        .default_size(270.0)
        .show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| {
                let mut restart = false;
                ui.heading("prismap");
                let mut open = None;
                egui::ComboBox::from_label("Scene")
                    .selected_text(app.source().label())
                    .width(190.0)
                    // A long path is elided to the box (the list shows it whole).
                    .truncate()
                    .show_ui(ui, |ui| {
                        for (name, _) in crate::scene::BUILTIN {
                            let s = SceneSource::Builtin(name.to_string());
                            if ui.selectable_label(*app.source() == s, s.label()).clicked() {
                                open = Some(s);
                            }
                        }
                        for p in app.scene_files.clone() {
                            let s = SceneSource::File(p);
                            if ui.selectable_label(*app.source() == s, s.label()).clicked() {
                                open = Some(s);
                            }
                        }
                    })
                    .response
                    .on_hover_text("The built-in scenes, then the other .gltf/.glb files found in scenes/");
                ui.horizontal(|ui| {
                    let field = ui.add(
                        egui::TextEdit::singleline(&mut app.path_input)
                            .hint_text("path/to/scene.gltf")
                            .desired_width(130.0),
                    )
                    .on_hover_text("Type the path of a .gltf or .glb file and press Enter to open it");
                    let entered =
                        field.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
                    let clicked = ui
                        .button("Open")
                        .on_hover_text("Open the .gltf/.glb typed on the left (or press Enter there)")
                        .clicked();
                    if (entered || clicked) && !app.path_input.trim().is_empty() {
                        open = Some(SceneSource::File(app.path_input.trim().into()));
                    }
                    if ui
                        .button("Browse…")
                        .on_hover_text("Choose a .gltf or .glb file to open")
                        .clicked()
                    {
                        app.act(Action::OpenDialog);
                    }
                });
                ui.small("…or drop a .gltf/.glb on the window");
                if let Some(s) = open {
                    app.act(Action::Open(s));
                }
                ui.separator();

                ui.label("Storage");
                ui.horizontal(|ui| {
                    for s in Storage::ALL {
                        let (key, tip) = storage_tip(s);
                        restart |= ui
                            .radio_value(&mut app.settings.storage, s, s.name())
                            .on_hover_text(format!("{tip}  [{key}]"))
                            .changed();
                    }
                });
                ui.add_enabled_ui(app.settings.storage != Storage::Rgb, |ui| {
                    ui.horizontal(|ui| {
                        ui.label("Colours")
                            .on_hover_text("How the scene's RGB colours become spectra");
                        for (u, tip) in [
                            (crate::spectral::Upsampling::JakobHanika, "Jakob–Hanika 2019: smooth spectra with exactly the colours the scene gives"),
                            (crate::spectral::Upsampling::Smits, "Smits 1999, as the paper: saturated reds and yellows come out with extra blue"),
                        ] {
                            restart |= ui
                                .radio_value(&mut app.settings.spectra, u, u.label())
                                .on_hover_text(tip)
                                .changed();
                        }
                    });
                    let r = ui
                        .add(
                            egui::Slider::new(&mut app.settings.bins, 1..=1000)
                                .logarithmic(true)
                                .text("Bins"),
                        )
                        .on_hover_text("Wavelength bins over 360–830 nm: what photons carry and the film stores per pixel");
                    if r.changed() {
                        app.auto_bins = false;
                        restart = true;
                    }
                    ui.horizontal_wrapped(|ui| {
                        for p in crate::spectral::PAPER_BINS {
                            let width = (app.settings.lambda_max - app.settings.lambda_min) / p as f64;
                            if ui
                                .selectable_label(
                                    !app.auto_bins && app.settings.bins == p,
                                    p.to_string(),
                                )
                                .on_hover_text(format!(
                                    "{p} bins of {width:.1} nm from {:.0} to {:.0} nm, one of the paper's bin counts",
                                    app.settings.lambda_min, app.settings.lambda_max
                                ))
                                .clicked()
                            {
                                app.settings.bins = p;
                                app.auto_bins = false;
                                restart = true;
                            }
                        }
                        if ui
                            .selectable_label(app.auto_bins, "auto")
                            .on_hover_text("Bins chosen for the scene: 100 with dispersive glass, 20 with a spectral light, else 8  [A]")
                            .clicked()
                        {
                            app.auto_bins = true;
                            restart = true;
                        }
                    });
                    if app.auto_bins {
                        ui.small(&app.auto_reason);
                    }
                });
                restart |= ui
                    .add(
                        egui::Slider::new(&mut app.settings.photons_per_pass, 1_000..=2_000_000)
                            .logarithmic(true)
                            .text("Photons/pass"),
                    )
                    .on_hover_text("Photons emitted per pass; each pass also shrinks the gather radius a little")
                    .changed();
                ui.horizontal(|ui| {
                    restart |= ui
                        .add(
                            egui::Slider::new(&mut app.settings.final_gather_rays, 0..=64)
                                .text("Final gather"),
                        )
                        .on_hover_text("Final-gather rays per pixel per pass for indirect light; 0 shows the global photon map directly")
                        .changed();
                    if ui
                        .selectable_label(app.settings.pool_gather, "pool")
                        .on_hover_text("Neighbouring pixels (2×2) whose camera samples all reached one surface average their final-gather rays together: less noise in indirect light for the same rays (--no-fg-pool turns it off)")
                        .clicked()
                    {
                        app.settings.pool_gather = !app.settings.pool_gather;
                        restart = true;
                    }
                    if ui
                        .selectable_label(app.settings.guide_gather, "guide")
                        .on_hover_text("Final-gather rays go where the photons around them came from, mixed with the cosine distribution: less noise on walls lit by small bright patches (the floor under a spotlight), some cost elsewhere (--fg-guide)")
                        .clicked()
                    {
                        app.settings.guide_gather = !app.settings.guide_gather;
                        restart = true;
                    }
                });
                restart |= ui
                    .add(
                        egui::Slider::new(&mut app.settings.camera_samples, 1..=16)
                            .text("Camera samples"),
                    )
                    .on_hover_text("Camera rays per pixel per pass, spread over the pixel (--samples); the final-gather rays are shared out among them")
                    .changed();
                restart |= ui
                    .add(
                        egui::Slider::new(&mut app.settings.glass_split, 1..=16)
                            .text("Glass split"),
                    )
                    .on_hover_text("Wavelengths each camera ray follows past the first dispersive glass it meets, stratified over the spectrum (--glass-split): glass seen directly shows them all instead of one at random, so its colour noise falls; 1 follows one")
                    .changed();
                {
                    egui::ComboBox::from_label("Resolution")
                        .selected_text(format!("{}×{}", app.settings.width, app.settings.height))
                        .show_ui(ui, |ui| {
                            for h in HEIGHTS {
                                let (w, h) = app.scene_image_size(h);
                                let here = (app.settings.width, app.settings.height) == (w, h);
                                if ui.selectable_label(here, format!("{w}×{h}")).clicked() {
                                    (app.settings.width, app.settings.height) = (w, h);
                                    restart = true;
                                }
                            }
                        })
                        .response
                        .on_hover_text("Image size in pixels; the width follows the scene camera's aspect ratio");
                }
                ui.separator();
                ui.horizontal(|ui| {
                    let r = ui
                        .add(
                            egui::Slider::new(&mut app.exposure, 1e-5..=1e3)
                                .logarithmic(true)
                                .text("Exposure"),
                        )
                        .on_hover_text("Brightness of the display (a linear factor on radiance); PNG saves use it, EXR saves stay linear");
                    if r.changed() {
                        app.auto_exposure = false;
                    }
                    ui.checkbox(&mut app.auto_exposure, "auto-expose")
                        .on_hover_text("Expose each new image so middle grey and the highlights both show (photometric scenes can be thousands of nits)");
                });
                ui.horizontal(|ui| {
                    ui.radio_value(&mut app.tone, ToneMap::Clamp, "clamp")
                        .on_hover_text("Display values above 1 as white");
                    ui.radio_value(&mut app.tone, ToneMap::Reinhard, "Reinhard")
                        .on_hover_text("Compress highlights: x / (1 + x)");
                });
                let mut denoise = app.denoise_view;
                if ui
                    .checkbox(&mut denoise, "Denoised view")
                    .on_hover_text("Show the image filtered (edge-avoiding à-trous guided by normals, depth and albedo; a few ms). Display only: saves, probes and error figures use the raw film  [D]")
                    .changed()
                {
                    app.set_denoise_view(denoise);
                }
                ui.separator();
                ui.horizontal(|ui| {
                    let label = if app.paused { "Resume" } else { "Pause" };
                    if ui.button(label).on_hover_text("[space]").clicked() {
                        app.act(Action::SetPaused(!app.paused));
                    }
                    if ui
                        .button("Restart")
                        .on_hover_text("Start refining again from one pass  [R]")
                        .clicked()
                    {
                        restart = true;
                    }
                    if ui
                        .button("Reset view")
                        .on_hover_text("Back to the scene's own camera (drag to orbit, scroll to zoom)  [V]")
                        .clicked()
                    {
                        app.act(Action::ResetView);
                    }
                });
                ui.horizontal(|ui| {
                    for (ext, tip) in [
                        ("png", "The image as you see it (sRGB, this exposure)  [S]"),
                        ("exr", "The linear image, unscaled (OpenEXR)  [E]"),
                    ] {
                        if ui
                            .button(format!("Save {}", ext.to_uppercase()))
                            .on_hover_text(tip)
                            .clicked()
                        {
                            app.act(Action::Save(ext));
                        }
                    }
                });
                ui.horizontal(|ui| {
                    let spectral = app.settings.storage != Storage::Rgb;
                    let mut keep = app.keep_spectra;
                    if ui
                        .add_enabled(spectral, egui::Checkbox::new(&mut keep, "Keep spectra"))
                        .on_hover_text("Keep every pixel's spectrum (4 bytes per bin per pixel, shown in the memory panel) so it can be saved as a spectral EXR")
                        .changed()
                    {
                        app.set_keep_spectra(keep);
                    }
                    let ready = app.snapshot.as_ref().is_some_and(|s| s.spectra.is_some());
                    if ui
                        .add_enabled(ready, egui::Button::new("Save spectral EXR"))
                        .on_hover_text("Every bin as a channel S0.<wavelength>nm beside R, G, B (Fichet et al. 2021's OpenEXR layout for spectral images)")
                        .on_disabled_hover_text("Turn on Keep spectra and let a pass finish: the spectral EXR needs every pixel's spectrum")
                        .clicked()
                    {
                        app.act(Action::Save("spectral.exr"));
                    }
                });
                ui.small(format!("into {}/", app.save_dir.display()));
                ui.separator();
                compare_controls(app, ui);
                ui.small("keys: space pause · R restart · V view · S/E save · 1/2/4/5/3 full/compact/packed/spiked/rgb · A auto bins · F freeze A · D denoised view · F1 or ? all keys");
                if restart {
                    app.act(Action::Restart);
                }
                if !app.status.is_empty() {
                    ui.separator();
                    if app.status_is_error {
                        ui.colored_label(Color32::LIGHT_RED, &app.status);
                    } else {
                        ui.label(&app.status);
                    }
                }
                if let Some(e) = app.render_error() {
                    ui.colored_label(Color32::LIGHT_RED, format!("error: {e}"));
                }
            });
        });
}

/// Compare mode: freeze "A", then choose how A and the live B are shown.
fn compare_controls(app: &mut ViewerApp, ui: &mut egui::Ui) {
    use super::compare::CompareView;
    ui.label("Compare");
    let Some(a) = &app.compare else {
        if ui
            .button("Freeze as A")
            .on_hover_text("Keep this image and its probe spectra as \"A\"; then change storage or bins and compare the live render \"B\" with it  [F]")
            .clicked()
        {
            app.act(Action::Freeze);
        }
        return;
    };
    let label = a.label.clone();
    ui.horizontal(|ui| {
        ui.small(format!("A: {label}"));
        if ui
            .small_button("clear")
            .on_hover_text("Leave compare mode  [F]")
            .clicked()
        {
            app.act(Action::Unfreeze);
        }
    });
    let mut changed = false;
    ui.horizontal(|ui| {
        changed |= ui
            .radio_value(&mut app.compare_view, CompareView::Split, "split")
            .on_hover_text("A left of the line, B right of it")
            .changed();
        changed |= ui
            .radio_value(&mut app.compare_view, CompareView::Difference, "difference")
            .on_hover_text("|A − B| as displayed, times the gain")
            .changed();
    });
    match app.compare_view {
        CompareView::Split => {
            ui.add(egui::Slider::new(&mut app.compare_split, 0.0..=1.0).text("split"))
                .on_hover_text("Where the image changes from A (left) to the live B (right)");
        }
        CompareView::Difference => {
            changed |= ui
                .add(
                    egui::Slider::new(&mut app.compare_gain, 1.0..=256.0)
                        .logarithmic(true)
                        .text("× gain"),
                )
                .on_hover_text("How much the difference |A − B| is magnified to be seen")
                .changed();
        }
    }
    if changed {
        app.update_compare(&ui.ctx().clone());
    }
    match &app.agreement {
        Some(g) => {
            let psnr = if g.psnr_db.is_finite() {
                format!("{:.2} dB", g.psnr_db)
            } else {
                "identical".to_string()
            };
            ui.label(format!(
                "B against A: PSNR {psnr}, ΔE2000 mean {:.2}, p95 {:.2}",
                g.de_mean, g.de_p95
            ))
            .on_hover_text("On the images as displayed, at the current exposure (PSNR: the paper's equation 6)");
        }
        None => {
            ui.colored_label(
                Color32::LIGHT_RED,
                "A and B differ in size: pick A's resolution to compare",
            );
        }
    }
}

/// Bytes as the memory panel shows them ("4.93 MB", "620.1 kB").
pub fn format_bytes(bytes: f64) -> String {
    if bytes >= 1e6 {
        format!("{:.2} MB", bytes / 1e6)
    } else {
        format!("{:.1} kB", bytes / 1e3)
    }
}

pub fn statistics(app: &mut ViewerApp, ui: &mut egui::Ui) {
    egui::Panel::right("stats")
        .resizable(true)
        .default_size(290.0)
        .show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| {
                ui.heading("Render");
                let Some(s) = &app.snapshot else {
                    ui.label("rendering the first pass…");
                    return;
                };
                let st = &s.stats;
                let pixels = (app.settings.width * app.settings.height) as f64;
                let secs = st.photon_seconds + st.gather_seconds;
                egui::Grid::new("stats")
                    .num_columns(2)
                    .striped(true)
                    .show(ui, |ui| {
                        let mut row = |k: &str, v: String| {
                            ui.label(k);
                            ui.label(v);
                            ui.end_row();
                        };
                        row(
                            "passes",
                            if s.preview {
                                "quick preview".to_string()
                            } else {
                                st.passes.to_string()
                            },
                        );
                        row("photons emitted", st.photons_emitted.to_string());
                        if st.caustic_photons_emitted > 0 {
                            let label = if st.caustic_photons_aimed {
                                "+ aimed at glass"
                            } else {
                                "+ for caustics"
                            };
                            row(label, st.caustic_photons_emitted.to_string());
                        }
                        if let Some(share) = st.emission_useful_share {
                            // Suns, point lights and spots count where their photons land.
                            let label = if st.emission_adapted {
                                "useful photons (learned)"
                            } else {
                                "useful photons"
                            };
                            row(label, format!("{:.0} %", 100.0 * share));
                        }
                        row("stored (global)", st.stored_global.to_string());
                        row("stored (caustic)", st.stored_caustic.to_string());
                        row("spike records", st.spike_records.to_string());
                        row(
                            "time per pass",
                            format!("{:.0} ms", 1e3 * st.last_pass_seconds),
                        );
                        row(
                            "samples per second",
                            format!("{:.0}", pixels * st.passes as f64 / secs.max(1e-9)),
                        );
                        if let Some(pool) = app.worker_pool() {
                            let priority = if pool.below_ui {
                                "below the UI"
                            } else {
                                "one core left to the UI"
                            };
                            row("render threads", format!("{} ({priority})", pool.threads));
                        }
                        row("radius (global)", format!("{:.4}", st.r_global));
                        if st.r_caustic > 0.0 {
                            row("radius (caustic)", format!("{:.4}", st.r_caustic));
                        }
                        if let (Some(db), false) = (s.noise_psnr_db, s.preview) {
                            row("noise left", format!("≈ {db:.1} dB"));
                        }
                        row(
                            "target",
                            match app.target_reached {
                                Some((g, _, _)) if g == s.generation => "reached".to_string(),
                                _ => "not yet".to_string(),
                            },
                        );
                    });
                ui.horizontal(|ui| {
                    ui.label("Target");
                    if ui
                        .add(
                            egui::DragValue::new(&mut app.target_db)
                                .range(10.0..=80.0)
                                .speed(0.5)
                                .suffix(" dB"),
                        )
                        .on_hover_text("The noise level that counts as converged (the \"noise left\" estimate); +3 dB takes twice the passes")
                        .changed()
                    {
                        app.target_reached = None;
                    }
                    ui.checkbox(&mut app.stop_at_target, "stop there")
                        .on_hover_text("Pause when the target is reached (space resumes)");
                });
                if let Some((g, passes, secs)) = app.target_reached
                    && g == s.generation
                {
                    ui.small(format!(
                        "{:.0} dB reached at pass {passes}, after {secs:.1} s",
                        app.target_db
                    ));
                }
                if s.noise_psnr_db.is_some() && !s.preview {
                    ui.small("noise left: PSNR of the image against its own expectation, from the odd against the even passes (noise only, not the bias a radius still carries); +3 dB per doubling of passes");
                }
                ui.separator();
                ui.heading("Memory");
                let m = &s.memory;
                let stored = (st.stored_global + st.stored_caustic) as f64;
                egui::Grid::new("memory")
                    .num_columns(2)
                    .striped(true)
                    .show(ui, |ui| {
                        let mut row = |k: &str, v: String| {
                            ui.label(k);
                            ui.label(v);
                            ui.end_row();
                        };
                        row("global map", format_bytes(m.global_map as f64));
                        row("caustic map", format_bytes(m.caustic_map as f64));
                        row("photon maps", format_bytes(m.photon_maps as f64));
                        if m.next_pass_maps > 0 {
                            // Traced during this pass's gather, for the next pass.
                            row("next pass's maps", format_bytes(m.next_pass_maps as f64));
                        }
                        row("bytes per photon", format!("{:.1}", s.bytes_per_photon));
                        row("film (+ probes)", format_bytes(m.film as f64));
                        // A small scene's rays test every triangle (no BVH).
                        let search = if m.bvh_skipped { "triangles (no BVH)" } else { "BVH" };
                        row(search, format_bytes(m.bvh as f64));
                        if let Some(r) = crate::metrics::resident_bytes() {
                            row("process resident", format_bytes(r as f64));
                        }
                    });
                // What the other storages would take for the same photons (exact: fixed sizes).
                let bins = if app.settings.storage == Storage::Rgb {
                    app.settings.bins
                } else {
                    s.bins
                };
                ui.label(RichText::new("same photons, other storage:").small());
                for other in Storage::ALL {
                    let b = stored * other.bytes_per_photon(bins) as f64;
                    let here = other == app.settings.storage;
                    let text = format!(
                        "{}{:<8} {} ({} B/photon{})",
                        if here { "> " } else { "  " },
                        other.name(),
                        format_bytes(b),
                        other.bytes_per_photon(bins),
                        if other == Storage::Full {
                            format!(", {bins} bins")
                        } else {
                            String::new()
                        }
                    );
                    ui.label(RichText::new(text).monospace().small());
                }
                let hist = app.memory_history();
                if hist.len() > 1 {
                    Plot::new("memory history")
                        .height(120.0)
                        .allow_drag(false)
                        .allow_zoom(false)
                        .allow_scroll(false)
                        .x_axis_label("seconds since start")
                        .y_axis_label("MB")
                        .show(ui, |p| {
                            let maps: Vec<[f64; 2]> = hist
                                .iter()
                                .map(|h| [h.seconds, h.photon_maps / 1e6])
                                .collect();
                            let rss: Vec<[f64; 2]> =
                                hist.iter().map(|h| [h.seconds, h.resident / 1e6]).collect();
                            p.line(
                                Line::new("photon maps", PlotPoints::from(maps))
                                    .color(MAPS_COLOUR),
                            );
                            p.line(
                                Line::new("resident", PlotPoints::from(rss)).color(RESIDENT_COLOUR),
                            );
                        });
                    // A caption instead of the plot's legend (whose entries are toggles
                    // with nothing to explain them).
                    ui.horizontal(|ui| {
                        ui.label(RichText::new("— photon maps").color(MAPS_COLOUR).small());
                        ui.label(
                            RichText::new("— process resident memory")
                                .color(RESIDENT_COLOUR)
                                .small(),
                        );
                    });
                }
                if !s.skipped.is_empty() {
                    ui.separator();
                    ui.label(RichText::new("skipped").strong());
                    for k in &s.skipped {
                        ui.small(k);
                    }
                }
                if !s.warnings.is_empty() {
                    ui.label(RichText::new("scene warnings").strong());
                    for w in &s.warnings {
                        ui.small(w);
                    }
                }
                if let Some(l) = app.first_image_latency {
                    ui.small(format!(
                        "first image after the last change: {:.0} ms",
                        l * 1e3
                    ));
                }
            });
        });
}

/// Display colour of a spectral line at `l` nm (for tinting the axis).
fn wavelength_colour(l: f64) -> Color32 {
    let c = crate::spectral::tables::cmf();
    let rgb = mul3(&XYZ_TO_SRGB, [c.x.eval(l), c.y.eval(l), c.z.eval(l)]).map(|v| v.max(0.0));
    let m = rgb.iter().cloned().fold(1e-9, f64::max);
    let bright = (c.y.eval(l) / 0.3).min(1.0).sqrt().max(0.15);
    let [r, g, b] = rgb.map(|v| srgb8((v / m * bright) as f32));
    Color32::from_rgb(r, g, b)
}

const PROBE_COLOURS: [Color32; 4] = [
    Color32::WHITE,
    Color32::from_rgb(255, 170, 0),
    Color32::from_rgb(0, 200, 255),
    Color32::from_rgb(255, 90, 200),
];

pub fn probe(app: &mut ViewerApp, ui: &mut egui::Ui) {
    let has_probe = app.probe.is_some() || !app.pinned.is_empty();
    egui::Panel::bottom("probe")
        .resizable(true)
        .min_size(if has_probe { 230.0 } else { 28.0 })
        .show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.heading("Pixel spectrum");
                ui.small("click the image (or hold Alt and hover) to probe a pixel");
            });
            let Some(snap) = app.snapshot.clone() else {
                return;
            };
            let mut shown: Vec<(u32, u32)> = app.pinned.clone();
            if let Some(p) = app.probe
                && !shown.contains(&p)
            {
                shown.push(p);
            }
            if shown.is_empty() {
                return;
            }
            let spectral = app.settings.storage != Storage::Rgb;
            ui.horizontal(|ui| {
                // Readouts for each probe.
                ui.vertical(|ui| {
                    for (i, &(x, y)) in shown.iter().enumerate() {
                        let Some(p) = snap.probes.iter().find(|p| (p.x, p.y) == (x, y)) else {
                            ui.label(format!("({x}, {y}): waiting for the next pass…"));
                            continue;
                        };
                        let mean = p.mean();
                        let lin = snap.srgb_weights.iter().zip(&mean).fold(
                            [0.0f64; 3],
                            |mut acc, (w, v)| {
                                for c in 0..3 {
                                    acc[c] += (w[c] * v) as f64;
                                }
                                acc
                            },
                        );
                        let xyz = mul3(&SRGB_TO_XYZ, lin);
                        let disp = lin.map(|v| srgb8(v as f32 * app.exposure));
                        let pixel = snap
                            .image
                            .get(x.min(snap.image.width - 1), y.min(snap.image.height - 1));
                        let dom = dominant_wavelength(xyz)
                            .map(|l| {
                                if l < 0.0 {
                                    format!("{:.0} nm (complementary)", -l)
                                } else {
                                    format!("{l:.0} nm")
                                }
                            })
                            .unwrap_or_else(|| "—".into());
                        ui.horizontal(|ui| {
                            ui.colored_label(PROBE_COLOURS[i % 4], format!("probe ({x}, {y})"));
                            let (rect, _) = ui
                                .allocate_exact_size(egui::vec2(14.0, 14.0), egui::Sense::hover());
                            ui.painter().rect_filled(
                                rect,
                                2.0,
                                Color32::from_rgb(disp[0], disp[1], disp[2]),
                            );
                            if app.pinned.contains(&(x, y)) {
                                if ui.small_button("unpin").clicked() {
                                    app.act(Action::Unpin((x, y)));
                                }
                            } else if ui.small_button("pin").clicked() {
                                app.act(Action::PinProbe);
                            }
                            if ui.small_button("CSV").clicked() {
                                app.act(Action::ExportProbe((x, y)));
                            }
                        });
                        ui.small(format!("XYZ {:.4} {:.4} {:.4}", xyz[0], xyz[1], xyz[2]));
                        ui.small(format!(
                            "linear sRGB {:.4} {:.4} {:.4}",
                            lin[0], lin[1], lin[2]
                        ));
                        ui.small(format!(
                            "display sRGB {} {} {}   dominant λ {dom}",
                            disp[0], disp[1], disp[2]
                        ));
                        ui.small(format!(
                        "image pixel {:.4} {:.4} {:.4} over {} passes; spectrum over the last {}",
                        pixel[0], pixel[1], pixel[2], snap.stats.passes, p.passes
                    ));
                    }
                });
                // The plot: radiance per bin against wavelength, the axis tinted with the spectrum.
                let max = snap
                    .probes
                    .iter()
                    .filter(|p| shown.contains(&(p.x, p.y)))
                    .flat_map(|p| p.mean())
                    .fold(0.0f32, f32::max)
                    .max(1e-6) as f64;
                Plot::new("spd")
                    .height(ui.available_height().max(120.0))
                    .x_axis_label(if spectral {
                        "wavelength (nm)"
                    } else {
                        "RGB transport: channels at nominal primaries (nm)"
                    })
                    .y_axis_label("radiance / bin")
                    .include_x(360.0)
                    .include_x(830.0)
                    .include_y(0.0)
                    .show(ui, |plot| {
                        let h = 0.05 * max;
                        let mut l = 360.0;
                        while l < 830.0 {
                            let poly = Polygon::new(
                                "",
                                PlotPoints::from(vec![
                                    [l, -h],
                                    [l + 5.0, -h],
                                    [l + 5.0, 0.0],
                                    [l, 0.0],
                                ]),
                            )
                            .fill_color(wavelength_colour(l + 2.5))
                            .stroke(egui::Stroke::NONE);
                            plot.polygon(poly);
                            l += 5.0;
                        }
                        // The newest probe as the engine has it: one bar per bin, its width
                        // the bin's, tinted by its wavelength (hover reads a bin's value).
                        let primary = app.probe.or_else(|| shown.first().copied());
                        if spectral
                            && let Some(p) =
                                primary.and_then(|px| snap.probes.iter().find(|p| (p.x, p.y) == px))
                        {
                            let w = if snap.wavelengths.len() > 1 {
                                snap.wavelengths[1] - snap.wavelengths[0]
                            } else {
                                470.0
                            };
                            let bars: Vec<egui_plot::Bar> = snap
                                .wavelengths
                                .iter()
                                .zip(p.mean())
                                .map(|(l, v)| {
                                    egui_plot::Bar::new(*l, v as f64)
                                        .width(w)
                                        .fill(wavelength_colour(*l).gamma_multiply(0.6))
                                        .stroke(egui::Stroke::new(0.5, Color32::GRAY))
                                        .name(format!("{:.0}–{:.0} nm", l - w / 2.0, l + w / 2.0))
                                })
                                .collect();
                            plot.bar_chart(egui_plot::BarChart::new("bins", bars));
                        }
                        for (i, &(x, y)) in shown.iter().enumerate() {
                            if let Some(p) = snap.probes.iter().find(|p| (p.x, p.y) == (x, y)) {
                                let pts: Vec<[f64; 2]> = snap
                                    .wavelengths
                                    .iter()
                                    .zip(p.mean())
                                    .map(|(l, v)| [*l, v as f64])
                                    .collect();
                                plot.line(
                                    Line::new(format!("({x}, {y})"), PlotPoints::from(pts))
                                        .color(PROBE_COLOURS[i % 4]),
                                );
                            }
                            // Compare mode: the same pixel's spectrum in A, dashed.
                            if let Some(fp) = app
                                .compare
                                .as_ref()
                                .and_then(|a| a.probes.iter().find(|p| p.pixel == (x, y)))
                            {
                                let pts: Vec<[f64; 2]> = fp
                                    .wavelengths
                                    .iter()
                                    .zip(&fp.spectrum)
                                    .map(|(l, v)| [*l, *v as f64])
                                    .collect();
                                plot.line(
                                    Line::new(format!("A ({x}, {y})"), PlotPoints::from(pts))
                                        .color(PROBE_COLOURS[i % 4])
                                        .style(egui_plot::LineStyle::Dashed { length: 6.0 }),
                                );
                            }
                        }
                    });
            });
        });
}

/// Writes the spectrum of the probe at `pixel` (from the newest snapshot) as CSV.
pub fn export_probe_csv(app: &ViewerApp, pixel: (u32, u32)) -> Result<std::path::PathBuf, String> {
    let snap = app.snapshot.as_ref().ok_or("no image yet")?;
    let p = snap
        .probes
        .iter()
        .find(|p| (p.x, p.y) == pixel)
        .ok_or_else(|| format!("no probe at ({}, {})", pixel.0, pixel.1))?;
    export_csv(app, snap, p)
}

fn export_csv(
    app: &ViewerApp,
    snap: &super::Snapshot,
    p: &crate::render::Probe,
) -> Result<std::path::PathBuf, String> {
    std::fs::create_dir_all(&app.save_dir).map_err(|e| e.to_string())?;
    let path = app.save_dir.join(format!("probe-{}-{}.csv", p.x, p.y));
    let mut text = if app.settings.storage == Storage::Rgb {
        "channel,radiance\n".to_string()
    } else {
        "wavelength_nm,radiance\n".to_string()
    };
    for (i, (l, v)) in snap.wavelengths.iter().zip(p.mean()).enumerate() {
        if app.settings.storage == Storage::Rgb {
            text += &format!("{},{v}\n", ["r", "g", "b"][i.min(2)]);
        } else {
            text += &format!("{l},{v}\n");
        }
    }
    crate::output::write_atomic(&path, |tmp| {
        std::fs::write(tmp, text.as_bytes()).map_err(|e| e.to_string())
    })
    .map_err(|e| e.to_string())?;
    Ok(path)
}

/// The keyboard shortcuts, one per line (the help overlay and its test read this list).
/// The memory plot's line colours (named in its caption).
const MAPS_COLOUR: egui::Color32 = egui::Color32::from_rgb(90, 160, 255);
const RESIDENT_COLOUR: egui::Color32 = egui::Color32::from_rgb(255, 150, 60);

/// A storage's shortcut key and one-sentence tooltip (exhaustive: a new storage needs both).
fn storage_tip(s: Storage) -> (&'static str, &'static str) {
    match s {
        Storage::Full => ("1", "Full: every stored photon keeps all N bins (N floats)"),
        Storage::Compact => (
            "2",
            "Compact (Lai & Christensen): an RGB triplet, or a lossless (−1, bin, amplitude) spike for a single-wavelength photon — 3 floats at any N",
        ),
        Storage::Packed => (
            "4",
            "Packed: compact in 32 bits (shared-exponent triplet, or a 12-bit bin and 19-bit amplitude) with a 16-bit normal — 19 bytes a photon at any N",
        ),
        Storage::Spiked => (
            "5",
            "Spiked: compact plus one exact (bin, amplitude) spike for a peaked spectrum such as a fluorescent lamp's, kept only where it decodes closer — 37 bytes a photon at any N",
        ),
        Storage::Rgb => (
            "3",
            "RGB: the plain RGB renderer, the baseline (no spectra, no dispersion)",
        ),
    }
}

pub const SHORTCUTS: [(&str, &str); 15] = [
    ("space", "pause / resume refining"),
    ("R", "restart from one pass"),
    ("V", "back to the scene's camera"),
    ("S", "save a PNG (as shown)"),
    ("E", "save an EXR (linear)"),
    ("1", "full storage (N floats a photon)"),
    ("2", "compact storage (triplet or spike)"),
    ("4", "packed storage (compact in 19 bytes)"),
    ("5", "spiked storage (compact plus one exact spike)"),
    ("3", "RGB renderer (the baseline)"),
    ("A", "bins chosen for the scene"),
    ("F", "freeze the image as A / leave compare mode"),
    ("D", "denoised view (display only)"),
    ("F1 or ?", "this help"),
    ("Esc", "close this help"),
];

/// The help overlay: what each key does.
pub fn help(app: &mut ViewerApp, ctx: &egui::Context) {
    let mut open = app.show_help;
    egui::Window::new("Keyboard shortcuts")
        .open(&mut open)
        .collapsible(false)
        .resizable(false)
        .anchor(egui::Align2::CENTER_CENTER, egui::Vec2::ZERO)
        .show(ctx, |ui| {
            egui::Grid::new("shortcuts").num_columns(2).striped(true).show(ui, |ui| {
                for (key, what) in SHORTCUTS {
                    ui.strong(key);
                    ui.label(what);
                    ui.end_row();
                }
            });
            ui.small("Drag to orbit, Shift-drag or right-drag to pan, scroll to zoom; click the image to probe a pixel. Keys work when no text field has focus.");
        });
    app.show_help = open && app.show_help;
}

pub fn image(app: &mut ViewerApp, ui: &mut egui::Ui) {
    egui::CentralPanel::default().show(ui, |ui| {
        let Some(tex) = &app.texture else {
            ui.centered_and_justified(|ui| ui.label("rendering…"));
            return;
        };
        let (w, h) = (app.settings.width as f32, app.settings.height as f32);
        let avail = ui.available_size();
        let scale = (avail.x / w).min(avail.y / h).max(0.05);
        let size = egui::vec2(w * scale, h * scale);
        // Centre the image; its response rect is exactly the image, so clicks map to pixels.
        let rect = egui::Rect::from_center_size(ui.available_rect_before_wrap().center(), size);
        let resp = ui.put(
            rect,
            egui::Image::from_texture(egui::load::SizedTexture::new(tex.id(), size))
                .sense(egui::Sense::click_and_drag()),
        );
        if app.denoise_view {
            let at = egui::Rect::from_min_size(
                rect.left_top() + egui::vec2(6.0, 4.0),
                egui::vec2(260.0, 18.0),
            );
            ui.put(
                at,
                egui::Label::new(
                    egui::RichText::new("DENOISED VIEW (display only)")
                        .color(egui::Color32::from_rgb(255, 200, 80))
                        .strong(),
                )
                .selectable(false)
                .sense(egui::Sense::hover()),
            );
        }
        let to_pixel = |pos: egui::Pos2| -> Option<(u32, u32)> {
            let r = resp.rect;
            let u = (pos.x - r.min.x) / r.width();
            let v = (pos.y - r.min.y) / r.height();
            ((0.0..1.0).contains(&u) && (0.0..1.0).contains(&v))
                .then_some(((u * w) as u32, (v * h) as u32))
        };
        let mut restart = false;
        if resp.clicked()
            && let Some(px) = resp.interact_pointer_pos().and_then(to_pixel)
        {
            app.act(Action::SetProbe(px));
        }
        if resp.hovered()
            && ui.input(|i| i.modifiers.alt)
            && let Some(px) = resp.hover_pos().and_then(to_pixel)
            && app.probe != Some(px)
        {
            app.act(Action::SetProbe(px));
        }
        if resp.dragged_by(egui::PointerButton::Primary) && !ui.input(|i| i.modifiers.shift) {
            let d = resp.drag_delta();
            app.orbit.rotate(d.x, d.y);
            restart |= d != egui::Vec2::ZERO;
        } else if resp.dragged_by(egui::PointerButton::Secondary)
            || resp.dragged_by(egui::PointerButton::Primary)
        {
            let d = resp.drag_delta();
            app.orbit.pan_by(d.x, d.y, size.y);
            restart |= d != egui::Vec2::ZERO;
        }
        if resp.hovered() {
            let s = ui.input(|i| i.smooth_scroll_delta.y);
            if s != 0.0 {
                app.orbit.zoom_by(s);
                restart = true;
            }
        }
        // Compare mode: A over the left of the split, or the difference over all of it.
        if let (Some(a), Some(tex_a)) = (&app.compare, app.compare_texture()) {
            let r = resp.rect;
            let painter = ui.painter_at(r);
            let white = Color32::WHITE;
            let full_uv = egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0));
            match app.compare_view {
                super::compare::CompareView::Split => {
                    let f = app.compare_split.clamp(0.0, 1.0);
                    let x = r.min.x + f * r.width();
                    let left = egui::Rect::from_min_max(r.min, egui::pos2(x, r.max.y));
                    let uv = egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(f, 1.0));
                    painter.image(tex_a.id(), left, uv, white);
                    painter.vline(x, r.y_range(), egui::Stroke::new(1.5, Color32::YELLOW));
                    let font = egui::FontId::proportional(13.0);
                    painter.text(
                        r.min + egui::vec2(6.0, 4.0),
                        egui::Align2::LEFT_TOP,
                        format!("A: {}", a.label),
                        font.clone(),
                        Color32::YELLOW,
                    );
                    painter.text(
                        egui::pos2(r.max.x - 6.0, r.min.y + 4.0),
                        egui::Align2::RIGHT_TOP,
                        "B: live",
                        font,
                        Color32::YELLOW,
                    );
                }
                super::compare::CompareView::Difference => {
                    painter.image(tex_a.id(), r, full_uv, white);
                    painter.text(
                        r.min + egui::vec2(6.0, 4.0),
                        egui::Align2::LEFT_TOP,
                        format!("|A − B| × {:.0}", app.compare_gain),
                        egui::FontId::proportional(13.0),
                        Color32::YELLOW,
                    );
                }
            }
        }
        // Mark probes on the image.
        let mut marks: Vec<(u32, u32)> = app.pinned.clone();
        marks.extend(app.probe);
        for (i, (x, y)) in marks.iter().enumerate() {
            let p =
                resp.rect.min + egui::vec2((*x as f32 + 0.5) * scale, (*y as f32 + 0.5) * scale);
            let colour = if Some((*x, *y)) == app.probe {
                PROBE_COLOURS[0]
            } else {
                PROBE_COLOURS[(i + 1) % 4]
            };
            ui.painter()
                .circle_stroke(p, 5.0, egui::Stroke::new(1.5, colour));
        }
        if restart {
            app.act(Action::Restart);
        }
    });
}
