//! Continuous spectra: what a scene says a light or a surface is, before it is projected
//! onto the renderer's bins. A [`Spectrum`] can be evaluated at any wavelength; the
//! [`super::BinGrid`] turns it into the per-bin values that transport works on.

use std::sync::Arc;

use super::blackbody::planck_relative;
use super::color::xyz_to_linear_srgb;
use super::tables::{CMF_RANGE, PiecewiseLinear, cmf, d65, smits_basis};

#[derive(Clone, Debug, PartialEq)]
pub enum Spectrum {
    /// The same value at every wavelength.
    Constant(f64),
    /// A measured SPD: linear between samples, **zero** outside the measured range.
    Table(Arc<PiecewiseLinear>),
    /// Planck's law at `kelvin`, scaled so that its luminance Y equals `luminance`
    /// (Y computed with the CIE 1931 ȳ over 360–830 nm, normalised so that a flat
    /// spectrum of 1 has Y = 1: the same units as an emissive RGB's luminance).
    /// Build with [`Spectrum::blackbody`]; `scale` is luminance / Y(Planck), cached.
    Blackbody {
        kelvin: f64,
        luminance: f64,
        scale: f64,
    },
    /// Smits (1999) upsampling of a linear-sRGB reflectance. Negative channels are
    /// clamped to 0 first, so the spectrum is never negative.
    Reflectance([f64; 3]),
    /// An emitter given as linear-sRGB radiance: the Smits reflectance spectrum of the
    /// colour times D65 normalised to Y = 1, so that white (1,1,1) is D65 with Y = 1 and
    /// displays as (1,1,1), as pbrt-v4 does for RGB illuminants.
    Illuminant([f64; 3]),
    /// Another spectrum times a factor.
    Scaled(f64, Arc<Spectrum>),
}

/// What a spectrum describes, which decides its colour in the RGB baseline renderer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Reflectance,
    Emission,
}

/// Error of making a spectrum from user data.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpectrumError {
    #[error("blackbody temperature {0} K must be finite and > 0")]
    BadTemperature(f64),
    #[error("blackbody at {0} K emits no visible light (its luminance underflows)")]
    Invisible(f64),
    #[error("luminance {0} must be finite and ≥ 0")]
    BadLuminance(f64),
}

/// Clamps each channel to [0, ∞) (NaN → 0): the only clamp applied to RGB input.
pub fn clamp_rgb(rgb: [f64; 3]) -> [f64; 3] {
    rgb.map(|v| if v.is_finite() && v > 0.0 { v } else { 0.0 })
}

/// Smits' algorithm on a (non-negative) RGB triple at wavelength `l`.
pub fn smits_eval(rgb: [f64; 3], l: f64) -> f64 {
    let [r, g, b] = clamp_rgb(rgb);
    let basis = smits_basis();
    let [white, cyan, magenta, yellow, red, green, blue] =
        std::array::from_fn::<_, 7, _>(|i| basis[i].eval(l));
    if r <= g && r <= b {
        r * white
            + if g <= b {
                (g - r) * cyan + (b - g) * blue
            } else {
                (b - r) * cyan + (g - b) * green
            }
    } else if g <= r && g <= b {
        g * white
            + if r <= b {
                (r - g) * magenta + (b - r) * blue
            } else {
                (b - g) * magenta + (r - b) * red
            }
    } else {
        b * white
            + if r <= g {
                (r - b) * yellow + (g - r) * green
            } else {
                (g - b) * yellow + (r - g) * red
            }
    }
}

/// Luminance of D65 as tabulated (relative units), so that D65/this has Y = 1.
fn d65_y() -> f64 {
    static Y: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    *Y.get_or_init(|| xyz_of(|l| d65().eval(l))[1])
}

/// XYZ of a function of wavelength: 1 nm point sums over 360–830 nm, normalised so that
/// a flat spectrum of 1 has Y = 1 (CIE practice).
pub fn xyz_of(f: impl Fn(f64) -> f64) -> [f64; 3] {
    let c = cmf();
    let mut xyz = [0.0; 3];
    let mut norm = 0.0;
    let (lo, hi) = CMF_RANGE;
    let mut l = lo;
    while l <= hi + 1e-9 {
        let v = f(l);
        let y = c.y.eval(l);
        xyz[0] += v * c.x.eval(l);
        xyz[1] += v * y;
        xyz[2] += v * c.z.eval(l);
        norm += y;
        l += 1.0;
    }
    xyz.map(|v| v / norm)
}

impl Spectrum {
    /// A blackbody of the given luminance; rejects T ≤ 0, NaN, and temperatures too low
    /// to emit measurable visible light.
    pub fn blackbody(kelvin: f64, luminance: f64) -> Result<Self, SpectrumError> {
        if !(kelvin.is_finite() && kelvin > 0.0) {
            return Err(SpectrumError::BadTemperature(kelvin));
        }
        if !(luminance.is_finite() && luminance >= 0.0) {
            return Err(SpectrumError::BadLuminance(luminance));
        }
        let y = xyz_of(|l| planck_relative(l, kelvin))[1];
        if !(y.is_finite() && y > 1e-300) {
            return Err(SpectrumError::Invisible(kelvin));
        }
        Ok(Self::Blackbody {
            kelvin,
            luminance,
            scale: luminance / y,
        })
    }

    /// The value at `lambda_nm`.
    pub fn eval(&self, lambda_nm: f64) -> f64 {
        match self {
            Self::Constant(c) => *c,
            Self::Table(t) => {
                let xs = t.xs();
                if lambda_nm < xs[0] || lambda_nm > xs[xs.len() - 1] {
                    0.0
                } else {
                    t.eval(lambda_nm)
                }
            }
            Self::Blackbody { kelvin, scale, .. } => planck_relative(lambda_nm, *kelvin) * scale,
            Self::Reflectance(rgb) => smits_eval(*rgb, lambda_nm),
            Self::Illuminant(rgb) => smits_eval(*rgb, lambda_nm) * d65().eval(lambda_nm) / d65_y(),
            Self::Scaled(k, s) => k * s.eval(lambda_nm),
        }
    }

    /// The mean over `[a, b]` nm (a bin's value). Midpoint rule with at least 8 and at
    /// most 4 samples per nm, which is exact to well below 0.1% for these smooth inputs.
    pub fn average(&self, a: f64, b: f64) -> f64 {
        match self {
            Self::Constant(c) => *c,
            _ => {
                let m = ((b - a) * 4.0).ceil().max(8.0) as usize;
                let h = (b - a) / m as f64;
                (0..m)
                    .map(|i| self.eval(a + (i as f64 + 0.5) * h))
                    .sum::<f64>()
                    / m as f64
            }
        }
    }

    pub fn xyz(&self) -> [f64; 3] {
        xyz_of(|l| self.eval(l))
    }

    /// Luminance Y (flat 1 → 1).
    pub fn luminance(&self) -> f64 {
        self.xyz()[1]
    }

    /// The colour the plain RGB renderer uses for this spectrum. RGB inputs are used as
    /// given (that is what an RGB renderer does); a spectral emitter becomes the linear
    /// sRGB of its XYZ; a spectral reflectance becomes its colour under D65. Negative
    /// channels (out of gamut) are clamped to 0.
    pub fn to_rgb_renderer(&self, role: Role) -> [f64; 3] {
        match (self, role) {
            (Self::Reflectance(rgb), _) | (Self::Illuminant(rgb), _) => clamp_rgb(*rgb),
            (Self::Constant(c), Role::Reflectance) => clamp_rgb([*c; 3]),
            (Self::Scaled(k, s), _) => s.to_rgb_renderer(role).map(|v| v * k),
            (_, Role::Emission) => clamp_rgb(xyz_to_linear_srgb(self.xyz())),
            (_, Role::Reflectance) => {
                let xyz = xyz_of(|l| self.eval(l) * d65().eval(l) / d65_y());
                clamp_rgb(xyz_to_linear_srgb(xyz))
            }
        }
    }
}
