//! The `prismap` command line: parsing and wiring only.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};

use prismap::photon::Storage;
use prismap::render::{RenderSession, RenderSettings};
use prismap::{output, scene};

#[derive(Parser)]
#[command(
    name = "prismap",
    version,
    about = "Interactive spectral photon mapping"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Open the interactive viewer (the default when a display is available).
    View(ViewArgs),
    /// Render a scene headless to PNG or EXR.
    Render(RenderArgs),
    /// Measure speed against error per bin count and storage (the paper's tables, and more).
    Report(ReportArgs),
    /// List the built-in scenes and glasses.
    List,
}

#[derive(clap::Args)]
struct RenderArgs {
    /// A .gltf/.glb file, or a built-in scene name (prism, cornell-box, cornell-blackbody).
    #[arg(default_value = scene::DEFAULT_SCENE)]
    scene: String,
    /// Wavelength bins (1–4096; ignored by --storage rgb).
    #[arg(long, default_value_t = RenderSettings::default().bins)]
    bins: usize,
    /// Photon storage: full (N floats), compact (RGB triplet or spike) or rgb (RGB renderer).
    #[arg(long, default_value = "compact", value_parser = parse_storage)]
    storage: Storage,
    /// Photons emitted per pass.
    #[arg(long, default_value_t = RenderSettings::default().photons_per_pass)]
    photons: usize,
    /// Number of passes (default 16 unless --seconds is given).
    #[arg(long, conflicts_with = "seconds")]
    passes: Option<u64>,
    /// Render passes until this many seconds have passed (at least one pass).
    #[arg(long)]
    seconds: Option<f64>,
    /// Image size WxH.
    #[arg(long, default_value = "256x256", value_parser = parse_size, allow_hyphen_values = true)]
    size: (u32, u32),
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Final-gather rays per pixel per pass (0: show the global photon map directly).
    #[arg(long, default_value_t = RenderSettings::default().final_gather_rays)]
    fg: u32,
    /// Most single-wavelength photons one photon splits into at dispersive glass.
    #[arg(long, default_value_t = RenderSettings::default().dispersion_split)]
    split: usize,
    /// First-pass gather radius of the global map, in scene units (default: estimated).
    #[arg(long)]
    global_radius: Option<f32>,
    /// First-pass gather radius of the caustic map, in scene units (default: estimated).
    #[arg(long)]
    caustic_radius: Option<f32>,
    /// Most megabytes one pass's photon maps may take (default: a quarter of RAM);
    /// photons per pass are lowered to fit.
    #[arg(long)]
    photon_budget: Option<f64>,
    /// Exposure multiplier for the PNG (EXR is written linear, unscaled).
    #[arg(long, default_value_t = 1.0)]
    exposure: f32,
    /// Output image: .png (sRGB) or .exr (linear sRGB). Default: SCENE.png.
    #[arg(short = 'o', long)]
    output: Option<PathBuf>,
    /// Write render statistics as JSON here.
    #[arg(long)]
    stats: Option<PathBuf>,
    /// A reference EXR: with --error-csv, log PSNR against it after every pass.
    #[arg(long, requires = "error_csv")]
    reference: Option<PathBuf>,
    /// Write "pass,seconds,photons,psnr_db" after every pass (needs --reference).
    #[arg(long, requires = "reference")]
    error_csv: Option<PathBuf>,
}

#[derive(clap::Args)]
struct ViewArgs {
    /// A .gltf/.glb file, or a built-in scene name.
    #[arg(default_value = scene::DEFAULT_SCENE)]
    scene: String,
    #[arg(long, default_value_t = RenderSettings::default().bins)]
    bins: usize,
    #[arg(long, default_value = "compact", value_parser = parse_storage)]
    storage: Storage,
    #[arg(long, default_value_t = 50_000)]
    photons: usize,
    #[arg(long, default_value = "256x256", value_parser = parse_size, allow_hyphen_values = true)]
    size: (u32, u32),
    /// Save a screenshot of the whole window here after --after-passes passes, then exit.
    #[arg(long)]
    screenshot: Option<PathBuf>,
    #[arg(long, default_value_t = 8)]
    after_passes: u64,
    /// Probe this pixel from the start, as X,Y.
    #[arg(long, value_parser = parse_pixel)]
    probe: Option<(u32, u32)>,
}

fn parse_pixel(s: &str) -> Result<(u32, u32), String> {
    let (x, y) = s
        .split_once(',')
        .ok_or_else(|| format!("pixel '{s}' must look like 120,64"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|_| format!("pixel '{s}': '{v}' is not a whole number"))
    };
    Ok((p(x)?, p(y)?))
}

fn view(args: ViewArgs) -> Result<()> {
    if let Some(p) = &args.screenshot {
        check_writable(p, &["png"])?;
    }
    if args.after_passes == 0 {
        bail!("--after-passes 0: at least one pass is needed");
    }
    let settings = RenderSettings {
        bins: args.bins,
        storage: args.storage,
        photons_per_pass: args.photons,
        width: args.size.0,
        height: args.size.1,
        ..RenderSettings::default()
    };
    settings.validate().context("invalid settings")?;
    let source = if Path::new(&args.scene).exists()
        || !scene::BUILTIN.iter().any(|(n, _)| *n == args.scene)
    {
        // Fail early with the loader's message rather than inside the window.
        scene::load(Path::new(&args.scene))?;
        prismap::app::SceneSource::File(PathBuf::from(&args.scene))
    } else {
        prismap::app::SceneSource::Builtin(args.scene.clone())
    };
    let capture = args.screenshot.map(|path| prismap::app::Capture {
        path,
        after_passes: args.after_passes,
    });
    if let Some((x, y)) = args.probe
        && (x >= settings.width || y >= settings.height)
    {
        bail!(
            "--probe {x},{y}: outside the {}x{} image",
            settings.width,
            settings.height
        );
    }
    prismap::app::run_native(source, settings, capture, args.probe).map_err(|e| anyhow::anyhow!(e))
}

#[derive(clap::Args)]
struct ReportArgs {
    /// Small images and short runs: under 10 minutes on 2 cores.
    #[arg(long)]
    quick: bool,
    /// Scenes (built-in names or files); default: cornell-box cornell-blackbody prism.
    #[arg(long, num_args = 1..)]
    scenes: Vec<String>,
    /// Folder for report.md, runs.csv, plots and the cached references.
    #[arg(long)]
    out: PathBuf,
}

fn report(args: ReportArgs) -> Result<()> {
    let scenes = if args.scenes.is_empty() {
        prismap::report::default_scenes()
    } else {
        args.scenes
    };
    for s in &scenes {
        scene::load_any(s)?; // fail before hours of work, with the loader's message
    }
    prismap::report::prepare(&args.out)?;
    let report = prismap::report::Report {
        exe: std::env::current_exe().context("cannot find this program's path")?,
        out: args.out.clone(),
        scenes,
        plan: if args.quick {
            prismap::report::Plan::quick()
        } else {
            prismap::report::Plan::full()
        },
        quick: args.quick,
    };
    let start = Instant::now();
    let runs = report.run()?;
    eprintln!(
        "{} runs in {:.1} min → {}",
        runs.len(),
        start.elapsed().as_secs_f64() / 60.0,
        args.out.join("report.md").display()
    );
    Ok(())
}

fn parse_storage(s: &str) -> Result<Storage, String> {
    s.parse()
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("size '{s}' must look like 256x256"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|_| format!("size '{s}': '{v}' is not a positive whole number"))
    };
    Ok((p(w)?, p(h)?))
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::View(args)) => view(args),
        Some(Command::Render(args)) => render(args),
        Some(Command::Report(args)) => report(args),
        Some(Command::List) => {
            list();
            Ok(())
        }
        None if prismap::app::display_available() => {
            match Cli::parse_from(["prismap", "view"]).command {
                Some(Command::View(args)) => view(args),
                _ => unreachable!("`prismap view` parses as the view command"),
            }
        }
        None => {
            eprintln!(
                "prismap: no display, so rendering the built-in '{}' scene headless instead of opening the viewer (see `prismap --help`).",
                scene::DEFAULT_SCENE
            );
            match Cli::parse_from(["prismap", "render"]).command {
                Some(Command::Render(args)) => render(args),
                Some(Command::Report(args)) => report(args),
                _ => unreachable!("`prismap render` parses as the render command"),
            }
        }
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn list() {
    println!("built-in scenes:");
    for (name, _) in scene::BUILTIN {
        println!("  {name}");
    }
    println!("glasses (for extras.prismap.glass):");
    for g in prismap::spectral::tables::glasses() {
        println!(
            "  {:<14} n_d {:.5}  V_d {:.2}",
            g.name, g.nd_catalog, g.vd_catalog
        );
    }
}

/// Checks that `path` can be written before any work is done.
fn check_writable(path: &Path, extensions: &[&str]) -> Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !extensions.iter().any(|e| Some(*e) == ext.as_deref()) {
        bail!(
            "{}: the file must end in {}",
            path.display(),
            extensions
                .iter()
                .map(|e| format!(".{e}"))
                .collect::<Vec<_>>()
                .join(" or ")
        );
    }
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        bail!(
            "{}: the folder {} does not exist",
            path.display(),
            dir.display()
        );
    }
    let probe = dir.join(format!(".prismap-write-test-{}", std::process::id()));
    std::fs::write(&probe, b"").with_context(|| {
        format!(
            "{}: the folder {} is not writable",
            path.display(),
            dir.display()
        )
    })?;
    let _ = std::fs::remove_file(probe);
    Ok(())
}

fn render(args: RenderArgs) -> Result<()> {
    let start = Instant::now();
    let scene = scene::load_any(&args.scene)?;
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{}.png", scene.name)));
    check_writable(&output, &["png", "exr"])?;
    if let Some(s) = &args.stats {
        check_writable(s, &["json"])?;
    }
    if let Some(c) = &args.error_csv {
        check_writable(c, &["csv"])?;
    }
    let reference = match &args.reference {
        Some(r) => {
            let img = output::read_exr(r)?;
            if (img.width, img.height) != args.size {
                bail!(
                    "{}: reference is {}x{}, the render {}x{}",
                    r.display(),
                    img.width,
                    img.height,
                    args.size.0,
                    args.size.1
                );
            }
            Some(img)
        }
        None => None,
    };
    let mut error_log = String::from("pass,seconds,photons,psnr_db\n");
    if !(args.exposure.is_finite() && args.exposure > 0.0) {
        bail!("--exposure {}: must be finite and > 0", args.exposure);
    }
    if let Some(s) = args.seconds
        && !(s.is_finite() && s > 0.0)
    {
        bail!("--seconds {s}: must be finite and > 0");
    }
    if args.passes == Some(0) {
        bail!("--passes 0: at least one pass is needed");
    }
    let threads = match args.threads {
        Some(0) => bail!("--threads 0: at least one thread is needed"),
        Some(t) if t > 1024 => bail!("--threads {t}: at most 1024"),
        Some(t) => t,
        None => std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1),
    };
    let settings = RenderSettings {
        bins: args.bins,
        storage: args.storage,
        photons_per_pass: args.photons,
        width: args.size.0,
        height: args.size.1,
        seed: args.seed,
        final_gather_rays: args.fg,
        dispersion_split: args.split,
        global_radius: args.global_radius,
        caustic_radius: args.caustic_radius,
        photon_budget_bytes: match args.photon_budget {
            Some(mb) if mb.is_finite() && mb > 0.0 && mb < 1e12 => Some((mb * 1e6) as usize),
            Some(mb) => bail!("--photon-budget {mb}: must be a positive number of megabytes"),
            None => None,
        },
        ..RenderSettings::default()
    };
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("cannot start the worker threads")?;
    let mut session = pool
        .install(|| RenderSession::new(&scene, settings))
        .context("invalid settings")?;
    let passes = args
        .passes
        .unwrap_or(if args.seconds.is_some() { u64::MAX } else { 16 });
    let bar = indicatif::ProgressBar::new(if passes == u64::MAX { 0 } else { passes });
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} pass {pos}/{len} {elapsed} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let render_start = Instant::now();
    for _ in 0..passes {
        pool.install(|| session.run_pass())
            .map_err(|_| anyhow::anyhow!("render cancelled"))?;
        if let Some(r) = &reference {
            let st = session.stats();
            error_log += &format!(
                "{},{:.6},{},{:.4}\n",
                st.passes,
                st.photon_seconds + st.gather_seconds,
                st.photons_emitted,
                prismap::metrics::psnr(&session.image(), r, args.exposure)
            );
        }
        bar.inc(1);
        bar.set_message(format!("{:.2} s/pass", session.stats().last_pass_seconds));
        if let Some(s) = args.seconds
            && render_start.elapsed().as_secs_f64() >= s
        {
            break;
        }
    }
    bar.finish_and_clear();
    let image = session.image();
    output::write_image(&output, &image, args.exposure)?;
    let total = start.elapsed().as_secs_f64();
    let stats = output::stats_json(&session, &image, total);
    if let Some(path) = &args.stats {
        output::write_json(path, &stats)?;
    }
    if let Some(path) = &args.error_csv {
        output::write_atomic(path, |tmp| {
            std::fs::write(tmp, &error_log).map_err(|e| e.to_string())
        })?;
    }
    let st = session.stats();
    let mem = session.memory();
    eprintln!(
        "{}: {} passes, {} bins {}, {} photons emitted, {} stored (+{} caustic, {} spikes), maps {:.2} MB ({:.1} B/photon), {:.1} s → {}",
        scene.name,
        st.passes,
        session.scene().bins(),
        session.settings().storage.name(),
        st.photons_emitted,
        st.stored_global,
        st.stored_caustic,
        st.spike_records,
        mem.photon_maps as f64 / 1e6,
        session.bytes_per_photon(),
        total,
        output.display()
    );
    Ok(())
}
