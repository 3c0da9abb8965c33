//! The renderer's runtime bin grid: N uniform wavelength bins (or, for the RGB baseline,
//! three RGB channels), each bin's colour-matching weights integrated exactly from the
//! 1 nm tables, projection of continuous spectra onto the bins, and conversion of bin
//! values to colour.
//!
//! A bin's value is the **mean** of the spectrum over the bin. With the weights
//! `w_i = ∫_bin cmf dλ / ∫_360^830 ȳ dλ`, XYZ = Σ v_i w_i, so a flat spectrum of 1 has Y = 1
//! at every N.

use super::color::XYZ_TO_SRGB;
use super::smits::SmitsBins;
use super::spectrum::{Role, Spectrum};
use super::tables::{CMF_RANGE, cmf};

/// The bin counts of the paper's tables (Lai & Christensen, Tables 1 and 2): the viewer's
/// presets and the report's sweep.
pub const PAPER_BINS: [usize; 7] = [4, 5, 6, 8, 10, 20, 100];

/// The most bins a grid may have. Spike records store the bin index in an f32, exact up to
/// 2²⁴; the limit is far lower so that an absurd request is refused, not swapped.
pub const MAX_BINS: usize = 4096;

/// How light is carried through the scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Transport {
    /// N wavelength bins.
    Spectral,
    /// Three linear-sRGB channels: the plain RGB renderer baseline.
    Rgb,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridError {
    #[error("bins = {0}: the number of bins must be between 1 and {MAX_BINS}")]
    BadBinCount(usize),
    #[error("wavelength range {0}–{1} nm must be increasing and inside the CIE tables' 360–830 nm")]
    BadRange(f64, f64),
}

#[derive(Clone, Debug)]
pub struct BinGrid {
    transport: Transport,
    lambda_min: f64,
    lambda_max: f64,
    centers: Vec<f64>,
    to_xyz: Vec<[f64; 3]>,
    to_srgb: Vec<[f32; 3]>,
    smits: Option<SmitsBins>,
}

impl BinGrid {
    /// `n` uniform bins over `[lambda_min, lambda_max]` nm.
    pub fn spectral(n: usize, lambda_min: f64, lambda_max: f64) -> Result<Self, GridError> {
        if n == 0 || n > MAX_BINS {
            return Err(GridError::BadBinCount(n));
        }
        let (lo, hi) = CMF_RANGE;
        if !(lambda_min.is_finite() && lambda_max.is_finite())
            || lambda_min < lo
            || lambda_max > hi
            || lambda_min >= lambda_max
        {
            return Err(GridError::BadRange(lambda_min, lambda_max));
        }
        let width = (lambda_max - lambda_min) / n as f64;
        let c = cmf();
        let norm = c.y.integral(lo, hi);
        let mut to_xyz = Vec::with_capacity(n);
        let mut to_srgb = Vec::with_capacity(n);
        let mut centers = Vec::with_capacity(n);
        for i in 0..n {
            let a = lambda_min + i as f64 * width;
            let b = a + width;
            centers.push(0.5 * (a + b));
            let xyz =
                [c.x.integral(a, b), c.y.integral(a, b), c.z.integral(a, b)].map(|v| v / norm);
            to_xyz.push(xyz);
            to_srgb.push(super::color::mul3(&XYZ_TO_SRGB, xyz).map(|v| v as f32));
        }
        let mut grid = Self {
            transport: Transport::Spectral,
            lambda_min,
            lambda_max,
            centers,
            to_xyz,
            to_srgb,
            smits: None,
        };
        grid.smits = Some(SmitsBins::new(&grid));
        Ok(grid)
    }

    /// The default range, 360–830 nm, as in the paper.
    pub fn with_bins(n: usize) -> Result<Self, GridError> {
        Self::spectral(n, CMF_RANGE.0, CMF_RANGE.1)
    }

    /// Three linear-sRGB channels (the RGB baseline).
    pub fn rgb() -> Self {
        let to_srgb = vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let to_xyz = (0..3)
            .map(|c| {
                let mut e = [0.0; 3];
                e[c] = 1.0;
                super::color::linear_srgb_to_xyz(e)
            })
            .collect();
        Self {
            transport: Transport::Rgb,
            lambda_min: CMF_RANGE.0,
            lambda_max: CMF_RANGE.1,
            // Nominal dominant wavelengths of the sRGB primaries, for labels only.
            centers: vec![611.0, 549.0, 464.0],
            to_xyz,
            to_srgb,
            smits: None,
        }
    }

    pub fn transport(&self) -> Transport {
        self.transport
    }

    /// Number of channels (bins, or 3 for RGB).
    pub fn len(&self) -> usize {
        self.to_srgb.len()
    }

    pub fn is_empty(&self) -> bool {
        self.to_srgb.is_empty()
    }

    /// Bin centres in nm (nominal primaries' wavelengths for RGB).
    pub fn centers(&self) -> &[f64] {
        &self.centers
    }

    /// The wavelength at which a bin's index of refraction is evaluated. The RGB baseline
    /// uses 550 nm for every channel: it cannot disperse.
    pub fn ior_wavelength(&self, bin: usize) -> f64 {
        match self.transport {
            Transport::Spectral => self.centers[bin],
            Transport::Rgb => 550.0,
        }
    }

    /// The bin holding `lambda_nm`, if inside the range.
    pub fn bin_of(&self, lambda_nm: f64) -> Option<usize> {
        if self.transport != Transport::Spectral
            || !(lambda_nm >= self.lambda_min && lambda_nm <= self.lambda_max)
        {
            return None;
        }
        let w = (self.lambda_max - self.lambda_min) / self.len() as f64;
        Some((((lambda_nm - self.lambda_min) / w) as usize).min(self.len() - 1))
    }

    pub fn bin_edges(&self, bin: usize) -> (f64, f64) {
        let w = (self.lambda_max - self.lambda_min) / self.len() as f64;
        let a = self.lambda_min + bin as f64 * w;
        (a, a + w)
    }

    /// Per-channel weights to linear sRGB.
    pub fn srgb_weights(&self) -> &[[f32; 3]] {
        &self.to_srgb
    }

    pub fn smits(&self) -> Option<&SmitsBins> {
        self.smits.as_ref()
    }

    /// Projects a continuous spectrum onto the channels (bin means; RGB values for the
    /// RGB baseline). Never negative, never NaN.
    pub fn project(&self, s: &Spectrum, role: Role) -> Vec<f32> {
        let values: Vec<f32> = match (self.transport, s) {
            (Transport::Rgb, _) => s.to_rgb_renderer(role).map(|v| v as f32).to_vec(),
            (Transport::Spectral, Spectrum::Reflectance(rgb)) => {
                let mut out = vec![0.0; self.len()];
                let smits = self.smits.as_ref().expect("spectral grids have Smits bins");
                smits.decode_into(super::spectrum::clamp_rgb(*rgb).map(|v| v as f32), &mut out);
                out
            }
            (Transport::Spectral, _) => (0..self.len())
                .map(|i| {
                    let (a, b) = self.bin_edges(i);
                    s.average(a, b) as f32
                })
                .collect(),
        };
        let mut values: Vec<f32> = values
            .into_iter()
            .map(|v| if v.is_finite() && v > 0.0 { v } else { 0.0 })
            .collect();
        if self.transport == Transport::Spectral && role == Role::Emission {
            self.keep_luminance(s, &mut values);
        }
        values
    }

    /// Rescales an emitter's bin values so that their luminance *on this grid* equals the
    /// spectrum's luminance (1 nm sums): bin means weighted by the bins' ȳ integrals are
    /// not the luminance when a spectrum is steep across a wide bin (a 1000 K blackbody
    /// came out 2.35× too bright at 4 bins). What few bins still cost is the colour, not
    /// the brightness a user set.
    fn keep_luminance(&self, s: &Spectrum, values: &mut [f32]) {
        let on_grid = self.to_xyz(values)[1];
        let exact = s.luminance();
        if on_grid > 0.0 && exact > 0.0 && on_grid.is_finite() && exact.is_finite() {
            let k = (exact / on_grid) as f32;
            for v in values.iter_mut() {
                *v *= k;
            }
        }
    }

    /// XYZ of channel values.
    pub fn to_xyz(&self, v: &[f32]) -> [f64; 3] {
        let mut xyz = [0.0f64; 3];
        for (w, &x) in self.to_xyz.iter().zip(v) {
            for c in 0..3 {
                xyz[c] += w[c] * x as f64;
            }
        }
        xyz
    }

    /// Linear sRGB of channel values (the film's conversion; may be negative out of gamut).
    pub fn to_linear_srgb(&self, v: &[f32]) -> [f32; 3] {
        let mut rgb = [0.0f32; 3];
        for (w, &x) in self.to_srgb.iter().zip(v) {
            rgb[0] += w[0] * x;
            rgb[1] += w[1] * x;
            rgb[2] += w[2] * x;
        }
        rgb
    }

    /// A short description: "100 bins, 360–830 nm" or "RGB".
    pub fn describe(&self) -> String {
        match self.transport {
            Transport::Spectral => format!(
                "{} bins, {}–{} nm",
                self.len(),
                self.lambda_min,
                self.lambda_max
            ),
            Transport::Rgb => "RGB".to_string(),
        }
    }
}

/// Arithmetic on channel vectors (all slices have the grid's length).
pub mod spd {
    pub fn mul_assign(a: &mut [f32], b: &[f32]) {
        for (x, y) in a.iter_mut().zip(b) {
            *x *= y;
        }
    }

    pub fn scale(a: &mut [f32], k: f32) {
        for x in a.iter_mut() {
            *x *= k;
        }
    }

    pub fn add_scaled(acc: &mut [f32], a: &[f32], k: f32) {
        for (x, y) in acc.iter_mut().zip(a) {
            *x += y * k;
        }
    }

    pub fn sum(a: &[f32]) -> f32 {
        a.iter().sum()
    }

    pub fn max(a: &[f32]) -> f32 {
        a.iter().copied().fold(0.0, f32::max)
    }

    /// Index of the only non-zero entry, if exactly one entry is non-zero.
    pub fn single_nonzero(a: &[f32]) -> Option<usize> {
        let mut found = None;
        for (i, &v) in a.iter().enumerate() {
            if v != 0.0 {
                if found.is_some() {
                    return None;
                }
                found = Some(i);
            }
        }
        found
    }

    pub fn all_finite(a: &[f32]) -> bool {
        a.iter().all(|v| v.is_finite())
    }
}
