//! What each subcommand does: load, check the outputs can be written, hand the work to
//! the engine (render), the viewer (view) or the report, and write the results.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};

use super::{RenderArgs, ReportArgs, ViewArgs, check_writable};
use crate::output::{self, Stats};
use crate::photon::Storage;
use crate::render::settings::{thread_count, validate_exposure};
use crate::render::{ErrorReference, Flow, RenderSession, RenderSettings, Stop, error_csv};
use crate::{app, report, scene};

pub fn render(args: RenderArgs) -> Result<()> {
    let start = Instant::now();
    let scene = scene::load_any(&args.scene)?;
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{}.png", scene.name)));
    check_writable(&output, &["png", "exr"])?;
    if args.spectral {
        check_writable(&output, &["exr"])
            .context("--spectral writes an OpenEXR file: give -o NAME.exr")?;
    }
    for (path, ext) in [(&args.stats, "json"), (&args.error_csv, "csv")] {
        if let Some(p) = path {
            check_writable(p, &[ext])?;
        }
    }
    let exposure = args.exposure.map(validate_exposure).transpose()?;
    let stop = Stop::from_flags(args.passes, args.seconds)?;
    let mut settings = args.settings()?;
    if args.bins.is_none() && args.preset.is_none() && settings.storage != Storage::Rgb {
        // The bins the scene needs, as the viewer picks them (RGB storage has none).
        let (bins, why) = scene.auto_bins();
        settings.bins = bins;
        eprintln!("{}: {why} (--bins sets them)", scene.name);
    }
    if args.size.is_none() {
        // The camera's shape (a 16:9 Blender camera renders 16:9).
        (settings.width, settings.height) = scene.image_size(settings.height);
    }
    let reference = match &args.reference {
        Some(r) => Some(output::read_exr(r)?),
        None => None,
    };
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(thread_count(args.threads)?)
        .build()
        .context("cannot start the worker threads")?;
    let mut session = pool.install(|| RenderSession::new(&scene, settings))?;
    if args.spectral {
        if session.scene().grid.transport() == crate::spectral::Transport::Rgb {
            bail!("--spectral: --storage rgb renders no spectra (use full or compact)");
        }
        session.keep_spectra(true);
    }
    let bar = progress_bar(stop);
    // The error log compares display values at the given exposure (1 when automatic:
    // the reference and the render are the same scene).
    let reference = reference.as_ref().map(|image| ErrorReference {
        image,
        exposure: exposure.unwrap_or(1.0),
    });
    let log = pool
        .install(|| {
            session.run(stop, reference, &mut |s, _| {
                bar.inc(1);
                bar.set_message(format!("{:.2} s/pass", s.stats().last_pass_seconds));
                Flow::Continue
            })
        })
        .with_context(|| format!("{}: render failed", scene.name))?;
    bar.finish_and_clear();
    let image = session.image();
    let exposure = exposure
        .unwrap_or_else(|| output::auto_exposure_skipping(&image, &session.emitter_pixels()));
    let is_png = output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if is_png && let Some(w) = output::clipping_warning(&image, exposure) {
        eprintln!("warning: {w}");
    }
    match session.spectral_film() {
        Some(film) => {
            let spectra = output::SpectralImage {
                width: film.width(),
                height: film.height(),
                wavelengths: session.scene().grid.centers().to_vec(),
                values: film.develop(),
            };
            output::write_spectral_exr(&output, &spectra, &image)?;
        }
        None => output::write_image(&output, &image, exposure)?,
    }
    let stats = Stats::of(&session, &image, start.elapsed().as_secs_f64());
    if let Some(path) = &args.stats {
        output::write_json(path, &stats)?;
    }
    if let Some(path) = &args.error_csv {
        let csv = error_csv(&log);
        output::write_atomic(path, |tmp| {
            std::fs::write(tmp, &csv).map_err(|e| e.to_string())
        })?;
    }
    eprintln!("{}", summary(&stats, &output));
    Ok(())
}

fn progress_bar(stop: Stop) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(stop.passes.unwrap_or(0));
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} pass {pos}/{len} {elapsed} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar
}

fn summary(st: &Stats, output: &Path) -> String {
    format!(
        "{}: {} passes, {} bins {}, {} photons emitted, {} stored (+{} caustic, {} spikes), maps {:.2} MB ({:.1} B/photon), {:.1} s → {}",
        st.scene,
        st.passes,
        st.bins,
        st.storage,
        st.photons.emitted,
        st.photons.stored_global,
        st.photons.stored_caustic,
        st.photons.spike_records,
        st.memory_bytes.photon_maps as f64 / 1e6,
        st.bytes_per_photon,
        st.seconds.total,
        output.display()
    )
}

pub fn view(args: ViewArgs) -> Result<()> {
    if let Some(p) = &args.screenshot {
        check_writable(p, &["png"])?;
    }
    if args.after_passes == 0 {
        bail!("--after-passes 0: at least one pass is needed");
    }
    // Fail early with the loader's message rather than inside the window.
    let loaded = scene::load_any(&args.scene)?;
    let (width, height) = args.size.unwrap_or_else(|| loaded.image_size(256));
    let auto_bins = args.bins.is_none();
    let settings = RenderSettings {
        bins: args.bins.unwrap_or_else(|| loaded.auto_bins().0),
        storage: args.storage,
        spectra: args.spectra,
        photons_per_pass: args.photons,
        width,
        height,
        ..RenderSettings::interactive()
    };
    settings.validate()?;
    let source = if Path::new(&args.scene).exists() || scene::builtin(&args.scene).is_none() {
        app::SceneSource::File(PathBuf::from(&args.scene))
    } else {
        app::SceneSource::Builtin(args.scene.clone())
    };
    if let Some((x, y)) = args.probe
        && (x >= settings.width || y >= settings.height)
    {
        let (w, h) = (settings.width, settings.height);
        bail!("--probe {x},{y}: outside the {w}x{h} image");
    }
    let capture = args.screenshot.map(|path| app::Capture {
        path,
        after_passes: args.after_passes,
        compare_with: args.compare_with,
    });
    app::run_native(source, settings, auto_bins, capture, args.probe)
        .map_err(|e| anyhow::anyhow!(e))
}

pub fn report(args: ReportArgs) -> Result<()> {
    let scenes = if args.scenes.is_empty() {
        report::default_scenes()
    } else {
        args.scenes
    };
    for s in &scenes {
        scene::load_any(s)?; // fail before hours of work, with the loader's message
    }
    report::prepare(&args.out)?;
    let plan = if args.quick {
        report::Plan::quick()
    } else {
        report::Plan::full()
    };
    let report = report::Report {
        exe: std::env::current_exe().context("cannot find this program's path")?,
        out: args.out.clone(),
        scenes,
        plan,
        quick: args.quick,
    };
    let start = Instant::now();
    let runs = report.run()?;
    let minutes = start.elapsed().as_secs_f64() / 60.0;
    let md = args.out.join("report.md");
    eprintln!("{} runs in {minutes:.1} min → {}", runs.len(), md.display());
    Ok(())
}

pub fn list() {
    println!("built-in scenes:");
    for (name, _) in scene::BUILTIN {
        println!("  {name}");
    }
    println!("glasses (for extras.prismap.glass):");
    for g in crate::spectral::tables::glasses() {
        println!(
            "  {:<14} n_d {:.5}  V_d {:.2}",
            g.name, g.nd_catalog, g.vd_catalog
        );
    }
    println!("presets (for --preset):");
    for (name, preset) in crate::render::settings::PRESETS {
        let s = preset();
        println!(
            "  {name:<12} {} bins {}, {} photons/pass, {}x{}, {} final-gather rays{}, {} camera samples",
            s.bins,
            s.storage.name(),
            s.photons_per_pass,
            s.width,
            s.height,
            s.final_gather_rays,
            if s.pool_gather { " (pooled)" } else { "" },
            s.camera_samples
        );
    }
}
