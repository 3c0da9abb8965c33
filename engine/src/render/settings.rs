//! One `RenderSettings` shared by the CLI, the viewer and the reports, with named presets.

use serde::{Deserialize, Serialize};

use crate::photon::Storage;
use crate::spectral::{BinGrid, GridError, MAX_BINS};

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
    /// Neighbours used to estimate the first-pass radii.
    pub global_k: usize,
    pub caustic_k: usize,
    /// Most single-bin photons one photon splits into at dispersive glass.
    pub dispersion_split: usize,
    /// Most bytes one pass's photon maps may take; None: a quarter of the machine's RAM.
    /// Photons per pass are lowered to fit (and the stats say so).
    pub photon_budget_bytes: Option<usize>,
}

/// Smallest photon budget accepted.
pub const MIN_PHOTON_BUDGET: usize = 64 * 1024;

/// A quarter of the machine's memory (Linux /proc/meminfo), else 4 GiB.
pub fn default_photon_budget() -> usize {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|s| {
            let line = s.lines().find(|l| l.starts_with("MemTotal:"))?;
            let kb: usize = line.split_whitespace().nth(1)?.parse().ok()?;
            Some(kb * 1024 / 4)
        })
        .unwrap_or(4 << 30)
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            bins: 20,
            lambda_min: 360.0,
            lambda_max: 830.0,
            storage: Storage::Compact,
            photons_per_pass: 100_000,
            width: 256,
            height: 256,
            seed: 1,
            final_gather_rays: 8,
            max_bounces: DEFAULT_MAX_BOUNCES,
            alpha: 2.0 / 3.0,
            global_radius: None,
            caustic_radius: None,
            global_k: 48,
            caustic_k: 24,
            dispersion_split: 4,
            photon_budget_bytes: None,
        }
    }
}

/// A setting out of range, with the field, the value and the allowed range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SettingsError {
    #[error("{field} = {value}: {reason}")]
    OutOfRange {
        field: &'static str,
        value: String,
        reason: String,
    },
    #[error(transparent)]
    Grid(#[from] GridError),
}

fn out_of_range(field: &'static str, value: impl ToString, reason: impl ToString) -> SettingsError {
    SettingsError::OutOfRange {
        field,
        value: value.to_string(),
        reason: reason.to_string(),
    }
}

/// Default safety cap on path bounces (see [`RenderSettings::max_bounces`]).
pub const DEFAULT_MAX_BOUNCES: u32 = 1024;
/// Largest accepted bounce cap.
pub const MAX_BOUNCES: u32 = 100_000;

/// Largest accepted image side.
pub const MAX_SIDE: u32 = 16_384;
/// Most photons per pass.
pub const MAX_PHOTONS_PER_PASS: usize = 50_000_000;

impl RenderSettings {
    /// Fast and noisy: for the viewer's first seconds and for tests.
    pub fn preview() -> Self {
        Self {
            photons_per_pass: 20_000,
            width: 128,
            height: 128,
            final_gather_rays: 4,
            ..Self::default()
        }
    }

    pub fn validate(&self) -> Result<(), SettingsError> {
        if self.storage != Storage::Rgb && (self.bins == 0 || self.bins > MAX_BINS) {
            return Err(out_of_range(
                "bins",
                self.bins,
                format!("must be between 1 and {MAX_BINS}"),
            ));
        }
        for (field, v) in [("width", self.width), ("height", self.height)] {
            if v == 0 || v > MAX_SIDE {
                return Err(out_of_range(
                    field,
                    v,
                    format!("must be between 1 and {MAX_SIDE}"),
                ));
            }
        }
        if self.photons_per_pass == 0 || self.photons_per_pass > MAX_PHOTONS_PER_PASS {
            return Err(out_of_range(
                "photons_per_pass",
                self.photons_per_pass,
                format!("must be between 1 and {MAX_PHOTONS_PER_PASS}"),
            ));
        }
        if self.final_gather_rays > 1024 {
            return Err(out_of_range(
                "final_gather_rays",
                self.final_gather_rays,
                "must be at most 1024",
            ));
        }
        if self.max_bounces == 0 || self.max_bounces > MAX_BOUNCES {
            return Err(out_of_range(
                "max_bounces",
                self.max_bounces,
                format!("must be between 1 and {MAX_BOUNCES}"),
            ));
        }
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return Err(out_of_range("alpha", self.alpha, "must be in (0, 1)"));
        }
        for (field, r) in [
            ("global_radius", self.global_radius),
            ("caustic_radius", self.caustic_radius),
        ] {
            if let Some(r) = r
                && !(r.is_finite() && r > 0.0)
            {
                return Err(out_of_range(field, r, "must be finite and > 0"));
            }
        }
        for (field, k) in [("global_k", self.global_k), ("caustic_k", self.caustic_k)] {
            if k == 0 || k > 10_000 {
                return Err(out_of_range(field, k, "must be between 1 and 10000"));
            }
        }
        if self.dispersion_split == 0 || self.dispersion_split > MAX_BINS {
            return Err(out_of_range(
                "dispersion_split",
                self.dispersion_split,
                format!("must be between 1 and {MAX_BINS}"),
            ));
        }
        if let Some(b) = self.photon_budget_bytes
            && b < MIN_PHOTON_BUDGET
        {
            return Err(out_of_range(
                "photon_budget_bytes",
                b,
                format!("must be at least {MIN_PHOTON_BUDGET}"),
            ));
        }
        self.grid().map(|_| ()).map_err(SettingsError::from)
    }

    /// The bin grid these settings ask for.
    pub fn grid(&self) -> Result<BinGrid, GridError> {
        match self.storage {
            Storage::Rgb => Ok(BinGrid::rgb()),
            _ => BinGrid::spectral(self.bins, self.lambda_min, self.lambda_max),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid_and_absurd_values_are_named() {
        RenderSettings::default().validate().unwrap();
        RenderSettings::preview().validate().unwrap();
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
        assert!(bad.validate().unwrap_err().to_string().contains("width"));
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
    }
}
