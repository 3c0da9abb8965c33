//! One `RenderSettings` shared by the CLI, the viewer and the reports, with named presets.

use serde::{Deserialize, Serialize};

use crate::photon::Storage;
use crate::spectral::{BinGrid, GridError, MAX_BINS, Transport, Upsampling};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RenderSettings {
    /// Wavelength bins (ignored by `rgb` storage, which transports three RGB channels).
    pub bins: usize,
    pub lambda_min: f64,
    pub lambda_max: f64,
    pub storage: Storage,
    /// Photons emitted per pass.
    pub photons_per_pass: usize,
    pub width: u32,
    pub height: u32,
    pub seed: u64,
    /// Final-gather rays per pixel per pass; 0 shows the global map directly.
    pub final_gather_rays: u32,
    /// Neighbouring pixels (2×2 blocks) pool their final-gather rays where all their
    /// camera samples reached one surface (`--no-fg-pool` turns it off; see
    /// [`crate::render::gather::Gather::block`]).
    #[serde(default = "yes")]
    pub pool_gather: bool,
    /// Final-gather rays draw their directions from where the global photons around
    /// their start came from, mixed with the cosine distribution (`--fg-guide`; see
    /// [`crate::photon::guide`]). Off by default: it pays where walls are lit by small
    /// bright patches (Blender's spot-lit stage: +2.5 dB on its back wall at equal
    /// time), and costs the built-in prism 15 % of its passes for nothing it needs
    /// (BENCHMARKS.md, session 34).
    #[serde(default)]
    pub guide_gather: bool,
    /// Camera rays per pixel per pass (`--samples`), spread over the pixel; the
    /// final-gather rays are shared out among them. Edges, the light seen directly and
    /// direct shadows need many positions within a pixel, and a camera ray costs less
    /// than the final-gather rays it carries.
    #[serde(default = "default_camera_samples")]
    pub camera_samples: u32,
    /// Wavelengths a camera sample follows past the first dispersive glass it meets
    /// (`--glass-split`): glass seen directly shows them all, stratified, instead of one
    /// picked at random. 1 follows one.
    #[serde(default = "default_glass_split")]
    pub glass_split: u32,
    /// Distant lights, point lights and spots learn where their photons are useful (on
    /// surfaces the camera sees, or one bounce from them) and emit more of them there,
    /// each weighted so that every pass stays unbiased (`--no-adapt-emission` turns it
    /// off; see [`crate::lights::adaptive`]). Only a light of which fewer than half the
    /// photons proved useful adapts.
    #[serde(default = "yes")]
    pub adapt_emission: bool,
    /// Safety cap on the bounces of any path, photon or camera. Paths end by Russian
    /// roulette on the reflectance (unbiased); the cap only stops paths that lose no energy
    /// (light trapped by total internal reflection, lossless mirrors). At the default 1024
    /// a surface of albedo 0.99 has ρ¹⁰²⁴ = 3·10⁻⁵ of its light left: nothing visible is cut.
    pub max_bounces: u32,
    /// Progressive radius reduction α of Knaus & Zwicker (2011): r²ₖ₊₁ = r²ₖ (k+α)/(k+1).
    pub alpha: f64,
    /// First-pass gather radius of the global map (scene units); None: estimated.
    pub global_radius: Option<f32>,
    /// First-pass gather radius of the caustic map; None: estimated.
    pub caustic_radius: Option<f32>,
    /// Neighbours a global-map density estimate adapts its radius to.
    pub global_k: usize,
    /// Neighbours a caustic-map estimate adapts its radius to, per unit of
    /// `caustic_factor`: the estimate gathers `caustic_k × caustic_factor` photons
    /// ([`RenderSettings::caustic_neighbours`]), so extra caustic photons lower the noise
    /// at the same radius (the same blur) instead of shrinking the radius at the same
    /// noise.
    pub caustic_k: usize,
    /// Most single-bin photons one photon splits into at dispersive glass.
    pub dispersion_split: usize,
    /// Photons emitted for the caustic map per pass, as a multiple of `photons_per_pass`
    /// (`--caustic-factor`; 1: only the global photons' caustic paths). The extra photons
    /// follow specular bounces only and end at their first diffuse hit, so a caustic is
    /// sampled this many times more densely for little more than one ray per photon that
    /// misses the glass. Ignored where the scene has no mirror or glass.
    ///
    /// Lights aim the extra photons at the spheres around the scene's mirrors and glass
    /// (see [`crate::lights::LightSet::aim_at`]): where those are a share s of what a
    /// light lights, it sends (factor − 1)·√s as many photons per `photons_per_pass`,
    /// every one heading for the glass, so its caustic is 1/√s times as dense at about the
    /// unaimed pass's cost. The estimate still
    /// gathers `caustic_k × caustic_factor` photons: aimed photons sharpen the caustic
    /// (a smaller radius) instead of lowering its noise.
    #[serde(default = "default_caustic_factor")]
    pub caustic_factor: usize,
    /// Most bytes the photon maps may take; None: a quarter of the machine's RAM. Photons
    /// per pass are lowered until one pass's maps fit (and the stats say so); the next
    /// pass's are traced during a gather only when both passes' maps fit together.
    pub photon_budget_bytes: Option<usize>,
    /// How the scene's RGB colours become spectra (`--spectra`).
    #[serde(default)]
    pub spectra: Upsampling,
}

/// Smallest photon budget accepted.
pub const MIN_PHOTON_BUDGET: usize = 64 * 1024;

/// A quarter of the machine's memory (Linux /proc/meminfo), else 4 GiB.
pub fn default_photon_budget() -> usize {
    crate::metrics::total_memory_bytes()
        .map(|b| (b / 4) as usize)
        .unwrap_or(4 << 30)
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            bins: 20,
            lambda_min: 360.0,
            lambda_max: 830.0,
            storage: Storage::Compact,
            // Small passes reach a given error soonest (the speed bench, issue #12):
            // each pass also shrinks the radius, and final-gather directions follow a
            // per-pixel sequence that gains from many passes.
            photons_per_pass: 25_000,
            width: 256,
            height: 256,
            seed: 1,
            final_gather_rays: 4,
            pool_gather: true,
            guide_gather: false,
            camera_samples: DEFAULT_CAMERA_SAMPLES,
            glass_split: DEFAULT_GLASS_SPLIT,
            adapt_emission: true,
            max_bounces: DEFAULT_MAX_BOUNCES,
            alpha: 2.0 / 3.0,
            global_radius: None,
            caustic_radius: None,
            global_k: 48,
            caustic_k: 24,
            dispersion_split: 4,
            caustic_factor: DEFAULT_CAUSTIC_FACTOR,
            photon_budget_bytes: None,
            spectra: Upsampling::default(),
        }
    }
}

/// A setting out of range, named by its command-line flag (the viewer's controls carry
/// the same names in their tooltips), with the value and the allowed range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SettingsError {
    #[error("{flag} {value}: {reason}")]
    OutOfRange {
        flag: &'static str,
        value: String,
        reason: String,
    },
    #[error(transparent)]
    Grid(#[from] GridError),
}

pub(crate) fn out_of_range(
    flag: &'static str,
    value: impl ToString,
    reason: impl ToString,
) -> SettingsError {
    SettingsError::OutOfRange {
        flag,
        value: value.to_string(),
        reason: reason.to_string(),
    }
}

/// Default caustic photons per global photon (the speed bench, issue #12).
pub const DEFAULT_CAUSTIC_FACTOR: usize = 4;
/// Largest accepted caustic factor.
pub const MAX_CAUSTIC_FACTOR: usize = 256;

fn default_caustic_factor() -> usize {
    DEFAULT_CAUSTIC_FACTOR
}

/// Default camera rays per pixel per pass (the speed bench, issue #12).
pub const DEFAULT_CAMERA_SAMPLES: u32 = 4;
/// Most camera rays per pixel per pass.
pub const MAX_CAMERA_SAMPLES: u32 = 256;

fn yes() -> bool {
    true
}

fn default_camera_samples() -> u32 {
    DEFAULT_CAMERA_SAMPLES
}

/// Wavelengths a camera sample follows past dispersive glass, by default.
pub const DEFAULT_GLASS_SPLIT: u32 = 4;
/// Most wavelengths a camera sample may follow past dispersive glass.
pub const MAX_GLASS_SPLIT: u32 = 64;

fn default_glass_split() -> u32 {
    DEFAULT_GLASS_SPLIT
}

/// Default safety cap on path bounces (see [`RenderSettings::max_bounces`]).
pub const DEFAULT_MAX_BOUNCES: u32 = 1024;
/// Largest accepted bounce cap.
pub const MAX_BOUNCES: u32 = 100_000;

/// Largest accepted image side.
pub const MAX_SIDE: u32 = 16_384;
/// Most photons per pass.
pub const MAX_PHOTONS_PER_PASS: usize = 50_000_000;
/// Most worker threads.
pub const MAX_THREADS: usize = 1024;

/// A preset's constructor.
pub type Preset = fn() -> RenderSettings;

/// The named presets, for `--preset` and the viewer.
pub const PRESETS: [(&str, Preset); 4] = [
    ("preview", RenderSettings::preview),
    ("interactive", RenderSettings::interactive),
    ("default", RenderSettings::default),
    ("reference", RenderSettings::reference),
];

impl RenderSettings {
    /// Fast and noisy: the viewer's quick first image and small tests.
    pub fn preview() -> Self {
        Self {
            photons_per_pass: 20_000,
            width: 128,
            height: 128,
            final_gather_rays: 4,
            ..Self::default()
        }
    }

    /// The viewer's default: passes short enough to keep the image moving. Since the
    /// caustic map has photons of its own, these are the defaults' small passes (25 000
    /// photons): in the viewer bench 1.93 full passes a second on the prism at 512²
    /// against 1.40 at 50 000, and in the speed bench sooner to every target.
    pub fn interactive() -> Self {
        Self::default()
    }

    /// A converged image to measure others against: full storage, 100 bins, many photons,
    /// each pixel's own final-gather rays (no pooling's blur).
    pub fn reference() -> Self {
        Self {
            bins: 100,
            storage: Storage::Full,
            photons_per_pass: 200_000,
            pool_gather: false,
            ..Self::default()
        }
    }

    /// A preset by name (see [`PRESETS`]).
    pub fn preset(name: &str) -> Result<Self, SettingsError> {
        PRESETS
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, f)| f())
            .ok_or_else(|| {
                let names: Vec<&str> = PRESETS.iter().map(|(n, _)| *n).collect();
                out_of_range("--preset", name, format!("use one of {}", names.join(", ")))
            })
    }

    /// The quick first image after a change, derived from these settings: a quarter of
    /// the resolution, a tenth of the photons, no final gathering, one camera ray a pixel.
    pub fn quick_preview_of(&self) -> Self {
        Self {
            width: self.width.div_ceil(4),
            height: self.height.div_ceil(4),
            photons_per_pass: (self.photons_per_pass / 10).max(1000),
            final_gather_rays: 0,
            camera_samples: 1,
            ..self.clone()
        }
    }

    /// Whether final-gather rays are guided by the photons: asked for, and there are rays.
    pub fn guides_gather(&self) -> bool {
        self.guide_gather && self.final_gather_rays > 0
    }

    /// Whether final-gather rays are pooled between pixels: asked for, and there are rays.
    pub fn pools_gather(&self) -> bool {
        self.pool_gather && self.final_gather_rays > 0
    }

    /// Neighbours of a caustic-map estimate: `caustic_k` per unit of `caustic_factor`.
    pub fn caustic_neighbours(&self) -> usize {
        self.caustic_k.saturating_mul(self.caustic_factor.max(1))
    }

    /// Light channels these settings transport in (bins, or 3 for RGB).
    pub fn channels(&self) -> usize {
        self.storage.channels(self.bins)
    }

    /// Every check of every field; the error names the flag, the value and the range.
    pub fn validate(&self) -> Result<(), SettingsError> {
        self.validate_image()?;
        self.validate_photons()?;
        self.validate_radii()?;
        self.grid().map(|_| ()).map_err(SettingsError::from)
    }

    fn validate_image(&self) -> Result<(), SettingsError> {
        if self.storage != Storage::Rgb && (self.bins == 0 || self.bins > MAX_BINS) {
            let reason = format!("bins must be between 1 and {MAX_BINS}");
            return Err(out_of_range("--bins", self.bins, reason));
        }
        for v in [self.width, self.height] {
            if v == 0 || v > MAX_SIDE {
                let size = format!("{}x{}", self.width, self.height);
                let reason = format!("each side must be between 1 and {MAX_SIDE} pixels");
                return Err(out_of_range("--size", size, reason));
            }
        }
        if self.final_gather_rays > 1024 {
            let reason = "final-gather rays must be at most 1024";
            return Err(out_of_range("--fg", self.final_gather_rays, reason));
        }
        if self.camera_samples == 0 || self.camera_samples > MAX_CAMERA_SAMPLES {
            let reason =
                format!("camera rays per pixel must be between 1 and {MAX_CAMERA_SAMPLES}");
            return Err(out_of_range("--samples", self.camera_samples, reason));
        }
        if self.glass_split == 0 || self.glass_split > MAX_GLASS_SPLIT {
            let reason = format!(
                "wavelengths a camera sample follows past glass must be between 1 and {MAX_GLASS_SPLIT}"
            );
            return Err(out_of_range("--glass-split", self.glass_split, reason));
        }
        if self.max_bounces == 0 || self.max_bounces > MAX_BOUNCES {
            let reason = format!("the bounce cap must be between 1 and {MAX_BOUNCES}");
            return Err(out_of_range("--max-bounces", self.max_bounces, reason));
        }
        Ok(())
    }

    fn validate_photons(&self) -> Result<(), SettingsError> {
        if self.photons_per_pass == 0 || self.photons_per_pass > MAX_PHOTONS_PER_PASS {
            let reason = format!("photons per pass must be between 1 and {MAX_PHOTONS_PER_PASS}");
            return Err(out_of_range("--photons", self.photons_per_pass, reason));
        }
        if self.dispersion_split == 0 || self.dispersion_split > MAX_BINS {
            let reason = format!("the split count must be between 1 and {MAX_BINS}");
            return Err(out_of_range("--split", self.dispersion_split, reason));
        }
        if self.caustic_factor == 0 || self.caustic_factor > MAX_CAUSTIC_FACTOR {
            let reason = format!("the caustic factor must be between 1 and {MAX_CAUSTIC_FACTOR}");
            return Err(out_of_range(
                "--caustic-factor",
                self.caustic_factor,
                reason,
            ));
        }
        if self.photons_per_pass.saturating_mul(self.caustic_factor) > 4 * MAX_PHOTONS_PER_PASS {
            let reason = format!(
                "--photons × --caustic-factor ({} × {}) must be at most {}",
                self.photons_per_pass,
                self.caustic_factor,
                4 * MAX_PHOTONS_PER_PASS
            );
            return Err(out_of_range(
                "--caustic-factor",
                self.caustic_factor,
                reason,
            ));
        }
        if let Some(b) = self.photon_budget_bytes
            && b < MIN_PHOTON_BUDGET
        {
            let reason = format!(
                "the photon budget must be at least {:.3} MB",
                MIN_PHOTON_BUDGET as f64 / 1e6
            );
            return Err(out_of_range("--photon-budget", b as f64 / 1e6, reason));
        }
        Ok(())
    }

    fn validate_radii(&self) -> Result<(), SettingsError> {
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return Err(out_of_range("--alpha", self.alpha, "must be in (0, 1)"));
        }
        for (flag, r) in [
            ("--global-radius", self.global_radius),
            ("--caustic-radius", self.caustic_radius),
        ] {
            if let Some(r) = r
                && !(r.is_finite() && r > 0.0)
            {
                return Err(out_of_range(flag, r, "a radius must be finite and > 0"));
            }
        }
        for (flag, k) in [
            ("--global-k", self.global_k),
            ("--caustic-k", self.caustic_k),
        ] {
            if k == 0 || k > 10_000 {
                return Err(out_of_range(
                    flag,
                    k,
                    "neighbours must be between 1 and 10000",
                ));
            }
        }
        if self.caustic_neighbours() > 10_000 {
            let reason = format!(
                "--caustic-k × --caustic-factor ({} × {}) must be at most 10000",
                self.caustic_k, self.caustic_factor
            );
            return Err(out_of_range("--caustic-k", self.caustic_k, reason));
        }
        Ok(())
    }

    /// The bin grid these settings ask for.
    pub fn grid(&self) -> Result<BinGrid, GridError> {
        match self.storage.transport() {
            Transport::Rgb => Ok(BinGrid::rgb()),
            Transport::Spectral => BinGrid::spectral(self.bins, self.lambda_min, self.lambda_max)
                .map(|g| g.with_upsampling(self.spectra)),
        }
    }
}

/// A photon budget given in megabytes (`--photon-budget`), as bytes.
pub fn photon_budget_from_mb(mb: f64) -> Result<usize, SettingsError> {
    if mb.is_finite() && mb > 0.0 && mb < 1e12 {
        Ok((mb * 1e6) as usize)
    } else {
        Err(out_of_range(
            "--photon-budget",
            mb,
            "must be a positive number of megabytes",
        ))
    }
}

/// Worker threads (`--threads`): the given count, or every core.
pub fn thread_count(threads: Option<usize>) -> Result<usize, SettingsError> {
    match threads {
        Some(0) => Err(out_of_range(
            "--threads",
            0,
            "at least one thread is needed",
        )),
        Some(t) if t > MAX_THREADS => Err(out_of_range(
            "--threads",
            t,
            format!("at most {MAX_THREADS}"),
        )),
        Some(t) => Ok(t),
        None => Ok(std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)),
    }
}

/// An exposure multiplier for display (`--exposure`): finite and > 0.
pub fn validate_exposure(exposure: f32) -> Result<f32, SettingsError> {
    if exposure.is_finite() && exposure > 0.0 {
        Ok(exposure)
    } else {
        Err(out_of_range(
            "--exposure",
            exposure,
            "must be finite and > 0",
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid_and_absurd_values_are_named() {
        for (name, preset) in PRESETS {
            preset().validate().unwrap();
            assert_eq!(RenderSettings::preset(name).unwrap(), preset());
        }
        assert!(
            RenderSettings::preset("fast")
                .unwrap_err()
                .to_string()
                .contains("interactive")
        );
        RenderSettings::default()
            .quick_preview_of()
            .validate()
            .unwrap();
        let bad = RenderSettings {
            photons_per_pass: 0,
            ..RenderSettings::default()
        };
        let msg = bad.validate().unwrap_err().to_string();
        assert!(msg.starts_with("--photons 0:"), "{msg}");
        assert!(
            photon_budget_from_mb(-1.0)
                .unwrap_err()
                .to_string()
                .contains("--photon-budget")
        );
        assert!(thread_count(Some(0)).is_err() && thread_count(None).unwrap() >= 1);
        assert!(
            validate_exposure(f32::NAN)
                .unwrap_err()
                .to_string()
                .contains("--exposure")
        );
        let bad = RenderSettings {
            bins: 0,
            ..RenderSettings::default()
        };
        let msg = bad.validate().unwrap_err().to_string();
        assert!(msg.contains("bins") && msg.contains('0'), "{msg}");
        let bad = RenderSettings {
            bins: 1_000_000,
            ..RenderSettings::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("1000000"));
        let bad = RenderSettings {
            width: 0,
            ..RenderSettings::default()
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("--size 0x256")
        );
        let bad = RenderSettings {
            global_radius: Some(f32::NAN),
            ..RenderSettings::default()
        };
        assert!(bad.validate().is_err());
        // RGB storage ignores the bin count.
        let rgb = RenderSettings {
            bins: 0,
            storage: Storage::Rgb,
            ..RenderSettings::default()
        };
        rgb.validate().unwrap();
        let bad = RenderSettings {
            caustic_factor: 0,
            ..RenderSettings::default()
        };
        let msg = bad.validate().unwrap_err().to_string();
        assert!(msg.starts_with("--caustic-factor 0:"), "{msg}");
        for samples in [0, MAX_CAMERA_SAMPLES + 1] {
            let bad = RenderSettings {
                camera_samples: samples,
                ..RenderSettings::default()
            };
            let msg = bad.validate().unwrap_err().to_string();
            assert!(msg.starts_with(&format!("--samples {samples}:")), "{msg}");
        }
        let bad = RenderSettings {
            photons_per_pass: MAX_PHOTONS_PER_PASS,
            caustic_factor: 8,
            ..RenderSettings::default()
        };
        let msg = bad.validate().unwrap_err().to_string();
        assert!(
            msg.starts_with("--caustic-factor 8:") && msg.contains("50000000 × 8"),
            "{msg}"
        );
        let bad = RenderSettings {
            caustic_k: 1000,
            caustic_factor: 16,
            ..RenderSettings::default()
        };
        let msg = bad.validate().unwrap_err().to_string();
        assert!(
            msg.starts_with("--caustic-k 1000:") && msg.contains("1000 × 16"),
            "{msg}"
        );
    }
}
