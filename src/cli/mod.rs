//! The command line's arguments (clap) and their parsers. Defaults come from the engine's
//! [`RenderSettings`] presets; every check of a value is the engine's (its errors name
//! the flag), so the CLI only parses and wires.

pub mod commands;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};

use crate::photon::Storage;
use crate::render::RenderSettings;
use crate::scene;
use crate::spectral::Upsampling;

#[derive(Parser)]
#[command(
    name = "prismap",
    version,
    about = "Interactive spectral photon mapping"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Subcommand)]
pub enum Command {
    /// Open the interactive viewer (the default when a display is available).
    View(ViewArgs),
    /// Render a scene headless to PNG or EXR.
    Render(Box<RenderArgs>),
    /// Measure speed against error per bin count and storage (the paper's tables, and more).
    Report(ReportArgs),
    /// List the built-in scenes, glasses and setting presets.
    List,
}

#[derive(clap::Args)]
pub struct RenderArgs {
    /// A .gltf/.glb file, or a built-in scene name (prism, cornell-box, cornell-blackbody,
    /// cornell-f11).
    #[arg(default_value = scene::DEFAULT_SCENE)]
    pub scene: String,
    /// Start from a named preset (preview, interactive, default, reference); the other
    /// flags override it.
    #[arg(long)]
    pub preset: Option<String>,
    /// Wavelength bins, 1–4096 (default: chosen for the scene, as the viewer's "auto" — 100
    /// with dispersive glass, 20 with a spectral light, else 8 — or the preset's with
    /// --preset; ignored by --storage rgb).
    #[arg(long)]
    pub bins: Option<usize>,
    /// Photon storage: full (N floats), compact (RGB triplet or spike), packed (compact in
    /// 19 bytes a photon), spiked (compact plus one exact spike, 37 bytes: for fluorescent
    /// lamps) or rgb (RGB renderer).
    #[arg(long, value_parser = parse_storage)]
    pub storage: Option<Storage>,
    /// How scene colours become spectra: jh (Jakob–Hanika 2019, the colour as given) or
    /// smits (Smits 1999, the paper's).
    #[arg(long, value_parser = parse_spectra)]
    pub spectra: Option<Upsampling>,
    /// Photons emitted per pass.
    #[arg(long)]
    pub photons: Option<usize>,
    /// Number of passes (default 32 unless --seconds is given).
    #[arg(long)]
    pub passes: Option<u64>,
    /// Render passes until this many seconds have passed (at least one pass; with
    /// --passes, whichever comes first).
    #[arg(long, allow_negative_numbers = true)]
    pub seconds: Option<f64>,
    /// Image size WxH (default: 256 rows, as wide as the scene's camera asks).
    #[arg(long, value_parser = parse_size, allow_hyphen_values = true)]
    pub size: Option<(u32, u32)>,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Final-gather rays per pixel per pass (0: show the global photon map directly).
    #[arg(long)]
    pub fg: Option<u32>,
    /// Do not pool final-gather rays between neighbouring pixels (by default 2×2 pixels
    /// whose camera samples all reached one surface average their rays together).
    #[arg(long)]
    pub no_fg_pool: bool,
    /// Guide final-gather rays by the photons: each ray's direction is drawn from where
    /// the global photons around it came from, mixed with the cosine distribution (for
    /// walls lit by small bright patches, such as the floor under a spotlight)
    #[arg(long)]
    pub fg_guide: bool,
    /// Wavelengths a camera sample follows past the first dispersive glass it meets,
    /// stratified (glass seen directly then shows them all instead of one at random; 1–64)
    #[arg(long)]
    pub glass_split: Option<u32>,
    /// Do not let Suns, point lights and spots learn where their photons are useful (by
    /// default a light whose photons mostly land where the camera never looks, such as a
    /// Sun outside a room, emits more of them towards what it sees, weighted so nothing
    /// changes but the noise)
    #[arg(long)]
    pub no_adapt_emission: bool,
    /// Camera rays per pixel per pass, spread over the pixel; the final-gather rays are
    /// shared out among them (edges and the light seen directly need many).
    #[arg(long)]
    pub samples: Option<u32>,
    /// Most single-wavelength photons one photon splits into at dispersive glass.
    #[arg(long)]
    pub split: Option<usize>,
    /// Caustic-map photons per pass, as a multiple of --photons (1: only the global
    /// photons' caustic paths; the extra ones end at their first diffuse hit). Lights
    /// aim the extra ones at the scene's glass and mirrors where they can, and then send
    /// fewer of them.
    #[arg(long)]
    pub caustic_factor: Option<usize>,
    /// Neighbours a global-map density estimate adapts its radius to.
    #[arg(long)]
    pub global_k: Option<usize>,
    /// Neighbours a caustic-map estimate adapts its radius to, per unit of
    /// --caustic-factor (it gathers k × factor photons: the same radius at any factor).
    #[arg(long)]
    pub caustic_k: Option<usize>,
    /// Safety cap on any path's bounces (Russian roulette ends paths long before).
    #[arg(long)]
    pub max_bounces: Option<u32>,
    /// Knaus–Zwicker radius reduction α in (0, 1).
    #[arg(long, allow_negative_numbers = true)]
    pub alpha: Option<f64>,
    /// First-pass gather radius of the global map, in scene units (default: estimated).
    #[arg(long, allow_negative_numbers = true)]
    pub global_radius: Option<f32>,
    /// First-pass gather radius of the caustic map, in scene units (default: estimated).
    #[arg(long, allow_negative_numbers = true)]
    pub caustic_radius: Option<f32>,
    /// Most megabytes the photon maps may take (default: a quarter of RAM): one pass's,
    /// plus the next pass's while they are traced during its gather (only when both fit);
    /// photons per pass are lowered until one pass's fit.
    #[arg(long, allow_negative_numbers = true)]
    pub photon_budget: Option<f64>,
    /// Exposure multiplier for the PNG (default: automatic, from the image; EXR is always
    /// written linear, unscaled).
    #[arg(long, allow_negative_numbers = true)]
    pub exposure: Option<f32>,
    /// Output image: .png (sRGB) or .exr (linear sRGB). Default: SCENE.png.
    #[arg(short = 'o', long)]
    pub output: Option<PathBuf>,
    /// With an .exr output: write every bin as a spectral channel (Fichet et al. 2021's
    /// layout, S0.<wavelength>nm) beside R, G, B. Keeps 4 bytes per bin per pixel.
    #[arg(long)]
    pub spectral: bool,
    /// Write render statistics as JSON here.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// A reference EXR: with --error-csv, log PSNR against it after every pass.
    #[arg(long, requires = "error_csv")]
    pub reference: Option<PathBuf>,
    /// Write "pass,seconds,photons,psnr_db" after every pass (needs --reference).
    #[arg(long, requires = "reference")]
    pub error_csv: Option<PathBuf>,
}

impl RenderArgs {
    /// The preset (or the defaults) with every given flag applied, validated.
    pub fn settings(&self) -> Result<RenderSettings> {
        let base = match &self.preset {
            Some(p) => RenderSettings::preset(p)?,
            None => RenderSettings::default(),
        };
        let s = RenderSettings {
            bins: self.bins.unwrap_or(base.bins),
            storage: self.storage.unwrap_or(base.storage),
            spectra: self.spectra.unwrap_or(base.spectra),
            photons_per_pass: self.photons.unwrap_or(base.photons_per_pass),
            width: self.size.map_or(base.width, |s| s.0),
            height: self.size.map_or(base.height, |s| s.1),
            seed: self.seed.unwrap_or(base.seed),
            final_gather_rays: self.fg.unwrap_or(base.final_gather_rays),
            pool_gather: base.pool_gather && !self.no_fg_pool,
            guide_gather: base.guide_gather || self.fg_guide,
            camera_samples: self.samples.unwrap_or(base.camera_samples),
            glass_split: self.glass_split.unwrap_or(base.glass_split),
            adapt_emission: base.adapt_emission && !self.no_adapt_emission,
            dispersion_split: self.split.unwrap_or(base.dispersion_split),
            caustic_factor: self.caustic_factor.unwrap_or(base.caustic_factor),
            global_k: self.global_k.unwrap_or(base.global_k),
            caustic_k: self.caustic_k.unwrap_or(base.caustic_k),
            max_bounces: self.max_bounces.unwrap_or(base.max_bounces),
            alpha: self.alpha.unwrap_or(base.alpha),
            global_radius: self.global_radius.or(base.global_radius),
            caustic_radius: self.caustic_radius.or(base.caustic_radius),
            photon_budget_bytes: match self.photon_budget {
                Some(mb) => Some(crate::render::settings::photon_budget_from_mb(mb)?),
                None => base.photon_budget_bytes,
            },
            ..base
        };
        s.validate()?;
        Ok(s)
    }
}

#[derive(clap::Args)]
pub struct ViewArgs {
    /// A .gltf/.glb file, or a built-in scene name.
    #[arg(default_value = scene::DEFAULT_SCENE)]
    pub scene: String,
    /// Wavelength bins (default: chosen for the scene — 100 with dispersive glass, 20 with
    /// a spectral light, else 8 — as the viewer's "auto")
    #[arg(long)]
    pub bins: Option<usize>,
    #[arg(long, default_value = "compact", value_parser = parse_storage)]
    pub storage: Storage,
    /// How scene colours become spectra: jh (Jakob–Hanika 2019) or smits (Smits 1999).
    #[arg(long, default_value = "jh", value_parser = parse_spectra)]
    pub spectra: Upsampling,
    #[arg(long, default_value_t = RenderSettings::interactive().photons_per_pass)]
    pub photons: usize,
    /// Image size WxH (default: 256 rows in the scene camera's shape).
    #[arg(long, value_parser = parse_size, allow_hyphen_values = true)]
    pub size: Option<(u32, u32)>,
    /// Save a screenshot of the whole window here after --after-passes passes, then exit.
    #[arg(long)]
    pub screenshot: Option<PathBuf>,
    #[arg(long, default_value_t = 8)]
    pub after_passes: u64,
    /// With --screenshot: freeze the image as compare mode's "A" after --after-passes,
    /// switch to this storage, render as many passes again, then take the screenshot.
    #[arg(long, value_parser = parse_storage, requires = "screenshot")]
    pub compare_with: Option<Storage>,
    /// Probe this pixel from the start, as X,Y.
    #[arg(long, value_parser = parse_pixel)]
    pub probe: Option<(u32, u32)>,
}

#[derive(clap::Args)]
pub struct ReportArgs {
    /// Small images and short runs: under 10 minutes on 2 cores.
    #[arg(long)]
    pub quick: bool,
    /// Scenes (built-in names or files); default: cornell-box cornell-blackbody prism.
    #[arg(long, num_args = 1..)]
    pub scenes: Vec<String>,
    /// Folder for report.md, runs.csv, plots and the cached references.
    #[arg(long)]
    pub out: PathBuf,
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

fn parse_storage(s: &str) -> Result<Storage, String> {
    s.parse()
}

fn parse_spectra(s: &str) -> Result<Upsampling, String> {
    Upsampling::ALL
        .into_iter()
        .find(|u| u.name().eq_ignore_ascii_case(s.trim()))
        .ok_or_else(|| format!("spectra '{s}' must be jh or smits"))
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

/// Checks that `path` can be written before any work is done.
pub fn check_writable(path: &Path, extensions: &[&str]) -> Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !extensions.iter().any(|e| Some(*e) == ext.as_deref()) {
        let list: Vec<String> = extensions.iter().map(|e| format!(".{e}")).collect();
        bail!(
            "{}: the file must end in {}",
            path.display(),
            list.join(" or ")
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
