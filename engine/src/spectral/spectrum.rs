//! Continuous spectra: what a scene says a light or a surface is, before it is projected
//! onto the renderer's bins. A [`Spectrum`] can be evaluated at any wavelength; the
//! [`super::BinGrid`] turns it into the per-bin values that transport works on.

use std::sync::Arc;

use super::blackbody::planck_relative;
use super::color::xyz_to_linear_srgb;
use super::jakob_hanika;
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
    /// A linear-sRGB reflectance, upsampled as its [`RgbSpectrum::upsampling`] says.
    /// Build with [`Spectrum::reflectance`].
    Reflectance(RgbSpectrum),
    /// An emitter given as linear-sRGB radiance: a bounded spectrum of the colour times
    /// D65 normalised to Y = 1, so that white (1,1,1) is D65 with Y = 1 and displays as
    /// (1,1,1), as pbrt-v4 does for RGB illuminants. Build with [`Spectrum::illuminant`].
    Illuminant(RgbSpectrum),
    /// Another spectrum times a factor.
    Scaled(f64, Arc<Spectrum>),
}

/// How an RGB colour becomes a spectrum.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Upsampling {
    /// Jakob & Hanika (2019): smooth, bounded, and the colour it was given (the default).
    #[default]
    #[serde(rename = "jh")]
    JakobHanika,
    /// Smits (1999), the paper's: piecewise constant; saturated yellows and reds carry
    /// blue (the Cornell light (17, 12, 4) renders with blue 20 % high).
    Smits,
}

impl Upsampling {
    pub const ALL: [Upsampling; 2] = [Upsampling::JakobHanika, Upsampling::Smits];

    /// The name the command line and the reports use.
    pub fn name(self) -> &'static str {
        match self {
            Self::JakobHanika => "jh",
            Self::Smits => "smits",
        }
    }

    pub fn label(self) -> &'static str {
        match self {
            Self::JakobHanika => "Jakob–Hanika 2019",
            Self::Smits => "Smits 1999",
        }
    }
}

/// An RGB colour and its spectrum's parameters: the colour as given (negative channels
/// clamped to 0), and for Jakob–Hanika the sigmoid's coefficients with a scale (1 for
/// reflectances, which are clamped to [0, 1]; twice the largest channel for emitters).
#[derive(Clone, Debug, PartialEq)]
pub struct RgbSpectrum {
    pub rgb: [f64; 3],
    pub upsampling: Upsampling,
    coeffs: [f64; 3],
    scale: f64,
}

impl RgbSpectrum {
    fn reflectance(rgb: [f64; 3], upsampling: Upsampling) -> Self {
        let rgb = clamp_rgb(rgb);
        let bounded = rgb.map(|v| v.min(1.0));
        let coeffs = match upsampling {
            Upsampling::JakobHanika => jakob_hanika::fit_exactly(bounded),
            Upsampling::Smits => [0.0; 3],
        };
        Self {
            rgb,
            upsampling,
            coeffs,
            scale: 1.0,
        }
    }

    fn illuminant(rgb: [f64; 3], upsampling: Upsampling) -> Self {
        let rgb = clamp_rgb(rgb);
        let (scale, coeffs) = match upsampling {
            Upsampling::JakobHanika => jakob_hanika::illuminant_parts(rgb),
            Upsampling::Smits => (1.0, [0.0; 3]),
        };
        Self {
            rgb,
            upsampling,
            coeffs,
            scale,
        }
    }

    /// The bounded (reflectance-like) part at `l`: the sigmoid times its scale, or Smits.
    fn eval(&self, l: f64) -> f64 {
        match self.upsampling {
            Upsampling::JakobHanika => self.scale * jakob_hanika::eval(self.coeffs, l),
            Upsampling::Smits => smits_eval(self.rgb, l),
        }
    }
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
    /// A linear-sRGB reflectance, upsampled by Jakob–Hanika (see [`Spectrum::upsampled`]).
    pub fn reflectance(rgb: [f64; 3]) -> Self {
        Self::Reflectance(RgbSpectrum::reflectance(rgb, Upsampling::JakobHanika))
    }

    /// A linear-sRGB emitter, upsampled by Jakob–Hanika (see [`Spectrum::upsampled`]).
    pub fn illuminant(rgb: [f64; 3]) -> Self {
        Self::Illuminant(RgbSpectrum::illuminant(rgb, Upsampling::JakobHanika))
    }

    /// This spectrum with its RGB colours upsampled by `u` (unchanged when they already
    /// are, or when it has none).
    pub fn upsampled(&self, u: Upsampling) -> std::borrow::Cow<'_, Spectrum> {
        use std::borrow::Cow;
        match self {
            Self::Reflectance(c) if c.upsampling != u => {
                Cow::Owned(Self::Reflectance(RgbSpectrum::reflectance(c.rgb, u)))
            }
            Self::Illuminant(c) if c.upsampling != u => {
                Cow::Owned(Self::Illuminant(RgbSpectrum::illuminant(c.rgb, u)))
            }
            Self::Scaled(k, s) => match s.upsampled(u) {
                Cow::Borrowed(_) => Cow::Borrowed(self),
                Cow::Owned(inner) => Cow::Owned(Self::Scaled(*k, Arc::new(inner))),
            },
            _ => Cow::Borrowed(self),
        }
    }

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
            Self::Reflectance(c) => c.eval(lambda_nm),
            Self::Illuminant(c) => c.eval(lambda_nm) * d65().eval(lambda_nm) / d65_y(),
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
            (Self::Reflectance(c), _) | (Self::Illuminant(c), _) => c.rgb,
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
