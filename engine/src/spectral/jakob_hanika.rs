//! Jakob & Hanika (2019), "A Low-Dimensional Function Space for Efficient Spectral
//! Upsampling": a colour's spectrum is the sigmoid of a quadratic polynomial in
//! wavelength, `s(λ) = ½ + x / (2√(1 + x²))` with `x = c₀t² + c₁t + c₂` and
//! `t = (λ − 360 nm) / 470 nm`. Smooth, bounded in (0, 1), and — with coefficients fitted
//! so that the spectrum's colour under the colour space's illuminant (D65 for sRGB) is
//! the target — reproduces every colour of the gamut, where Smits (1999) adds blue to
//! saturated yellows and reds.
//!
//! The coefficients are fitted once, offline, on a 3-D grid of colours (Gauss–Newton in
//! CIELAB, each fit starting from its neighbour's answer, as the paper describes) by
//! `cargo run --release -p prismap-engine --bin jh_table`, which writes
//! `assets/jh_srgb.bin`; the renderer interpolates that table trilinearly. A test
//! regenerates part of the table and compares.
//!
//! Table layout: the colour's largest channel `m` picks one of three blocks; inside it,
//! `z` = the largest channel's value (on a grid denser near 0 and 1), `x`, `y` = the next
//! two channels (cyclically) divided by it. Entry `[m][z][y][x]` holds `(c₀, c₁, c₂)`.

use std::sync::OnceLock;

use rayon::prelude::*;

use super::color::XYZ_TO_SRGB;
use super::tables::{CMF_RANGE, cmf, d65};

/// Grid points per axis of the shipped table.
pub const RES: usize = 32;

const MAGIC: &[u8; 4] = b"PMJH";
const VERSION: u32 = 1;
/// Gauss–Newton steps per fit at most, and the squared CIELAB residual that ends it.
const MAX_STEPS: usize = 15;
const DONE_RESIDUAL2: f64 = 1e-6;
/// Coefficients are kept within this magnitude (a step towards a black or a pure-white
/// target would otherwise run off towards infinity).
const MAX_COEFF: f64 = 200.0;

/// The normalised wavelength the polynomial is written in.
#[inline]
pub(super) fn t_of(lambda_nm: f64) -> f64 {
    (lambda_nm - CMF_RANGE.0) / (CMF_RANGE.1 - CMF_RANGE.0)
}

/// The sigmoid spectrum of coefficients `c` at `lambda_nm`, in [0, 1].
#[inline]
pub fn eval(c: [f64; 3], lambda_nm: f64) -> f64 {
    let t = t_of(lambda_nm);
    let x = (c[0] * t + c[1]) * t + c[2];
    if x.is_infinite() {
        return if x > 0.0 { 1.0 } else { 0.0 };
    }
    0.5 + 0.5 * x / (1.0 + x * x).sqrt()
}

/// The fit's colorimetry: per 1 nm sample over the CMF range, the linear-sRGB weights of
/// a reflectance lit by D65 (normalised so that reflectance 1 has Y = 1), and D65's own
/// XYZ (CIELAB's white).
pub struct Fitter {
    lambdas: Vec<f64>,
    rgb_weights: Vec<[f64; 3]>,
    white_xyz: [f64; 3],
}

impl Default for Fitter {
    fn default() -> Self {
        Self::new()
    }
}

impl Fitter {
    pub fn new() -> Self {
        let c = cmf();
        let illum = d65();
        let (lo, hi) = CMF_RANGE;
        let n = (hi - lo).round() as usize + 1;
        let lambdas: Vec<f64> = (0..n).map(|i| lo + i as f64).collect();
        let norm: f64 = lambdas.iter().map(|&l| c.y.eval(l) * illum.eval(l)).sum();
        let mut white_xyz = [0.0; 3];
        let rgb_weights = lambdas
            .iter()
            .map(|&l| {
                let e = illum.eval(l) / norm;
                let xyz = [c.x.eval(l) * e, c.y.eval(l) * e, c.z.eval(l) * e];
                for k in 0..3 {
                    white_xyz[k] += xyz[k];
                }
                std::array::from_fn(|r| (0..3).map(|k| XYZ_TO_SRGB[r][k] * xyz[k]).sum())
            })
            .collect();
        Self {
            lambdas,
            rgb_weights,
            white_xyz,
        }
    }

    /// Linear sRGB of the sigmoid spectrum `c` under D65.
    pub fn rgb_of(&self, c: [f64; 3]) -> [f64; 3] {
        let mut rgb = [0.0; 3];
        for (&l, w) in self.lambdas.iter().zip(&self.rgb_weights) {
            let s = eval(c, l);
            for k in 0..3 {
                rgb[k] += w[k] * s;
            }
        }
        rgb
    }

    fn lab(&self, rgb: [f64; 3]) -> [f64; 3] {
        let xyz = super::color::linear_srgb_to_xyz(rgb);
        let f = |v: f64| {
            const D: f64 = 6.0 / 29.0;
            if v > D * D * D {
                v.cbrt()
            } else {
                v / (3.0 * D * D) + 4.0 / 29.0
            }
        };
        let [fx, fy, fz] = [0, 1, 2].map(|k| f(xyz[k] / self.white_xyz[k]));
        [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
    }

    fn residual(&self, c: [f64; 3], target_lab: [f64; 3]) -> [f64; 3] {
        let got = self.lab(self.rgb_of(c));
        [0, 1, 2].map(|k| target_lab[k] - got[k])
    }

    /// Coefficients whose spectrum has colour `rgb` (in [0, 1]³), starting from `start`:
    /// Gauss–Newton on the CIELAB difference, Jacobian by central differences.
    pub fn solve(&self, rgb: [f64; 3], start: [f64; 3]) -> [f64; 3] {
        const EPS: f64 = 1e-4;
        let target = self.lab(rgb);
        let mut c = start;
        for _ in 0..MAX_STEPS {
            let r = self.residual(c, target);
            let mut jac = [[0.0; 3]; 3];
            for i in 0..3 {
                let (mut lo, mut hi) = (c, c);
                lo[i] -= EPS;
                hi[i] += EPS;
                let (r0, r1) = (self.residual(lo, target), self.residual(hi, target));
                for k in 0..3 {
                    jac[k][i] = (r1[k] - r0[k]) / (2.0 * EPS);
                }
            }
            let Some(step) = solve3(jac, r) else { break };
            for i in 0..3 {
                c[i] -= step[i];
            }
            let peak = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if peak > MAX_COEFF {
                c = c.map(|v| v * MAX_COEFF / peak);
            }
            if r.iter().map(|v| v * v).sum::<f64>() < DONE_RESIDUAL2 {
                break;
            }
        }
        c
    }

    /// One column of the table: block `m`, grid point (`i`, `j`) in x and y, every z.
    /// Fits run outwards from z = res/5 in both directions, each from the previous one's
    /// coefficients (a fit from zero converges there; its neighbours start close).
    pub fn column(&self, res: usize, m: usize, i: usize, j: usize) -> Vec<[f32; 3]> {
        let scale = z_grid(res);
        let (x, y) = (i as f64 / (res - 1) as f64, j as f64 / (res - 1) as f64);
        let mut out = vec![[0.0f32; 3]; res];
        let start = res / 5;
        let mut fit = |k: usize, c: [f64; 3]| {
            let b = scale[k] as f64;
            let mut rgb = [0.0; 3];
            rgb[m] = b;
            rgb[(m + 1) % 3] = x * b;
            rgb[(m + 2) % 3] = y * b;
            let c = self.solve(rgb, c);
            out[k] = c.map(|v| v as f32);
            c
        };
        let mut c = [0.0; 3];
        for k in start..res {
            c = fit(k, c);
        }
        let mut c = [0.0; 3];
        for k in (0..=start).rev() {
            c = fit(k, c);
        }
        out
    }
}

/// Solves `a · x = b` (Gaussian elimination with partial pivoting); None when singular.
fn solve3(mut a: [[f64; 3]; 3], mut b: [f64; 3]) -> Option<[f64; 3]> {
    for col in 0..3 {
        let p = (col..3).max_by(|&r, &s| a[r][col].abs().total_cmp(&a[s][col].abs()))?;
        if a[p][col].abs() < 1e-15 {
            return None;
        }
        a.swap(col, p);
        b.swap(col, p);
        let pivot = a[col];
        for r in col + 1..3 {
            let f = a[r][col] / pivot[col];
            for (v, p) in a[r].iter_mut().zip(pivot).skip(col) {
                *v -= f * p;
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = [0.0; 3];
    for r in (0..3).rev() {
        let s: f64 = (r + 1..3).map(|k| a[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// The z grid: smoothstep of smoothstep, dense near black and near full brightness where
/// the coefficients change fastest.
pub fn z_grid(res: usize) -> Vec<f32> {
    let smooth = |x: f64| x * x * (3.0 - 2.0 * x);
    (0..res)
        .map(|k| smooth(smooth(k as f64 / (res - 1) as f64)) as f32)
        .collect()
}

/// The fitted coefficient table.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    res: usize,
    z: Vec<f32>,
    /// `[m][z][y][x]` → coefficients, `3 · res³` entries.
    data: Vec<[f32; 3]>,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TableError {
    #[error("not a prismap Jakob–Hanika table (bad magic or version)")]
    Header,
    #[error("table resolution {0} is outside 2–256")]
    Resolution(u32),
    #[error("table is {got} bytes, its resolution needs {want}")]
    Size { got: usize, want: usize },
    #[error("table entry {0} is not finite")]
    NotFinite(usize),
}

impl Table {
    /// Fits every entry (both cores; about 10 s at 32³ in a release build).
    pub fn fit(res: usize) -> Self {
        let fitter = Fitter::new();
        let columns: Vec<Vec<[f32; 3]>> = (0..3 * res * res)
            .into_par_iter()
            .map(|idx| {
                let (m, j, i) = (idx / (res * res), idx / res % res, idx % res);
                fitter.column(res, m, i, j)
            })
            .collect();
        let mut data = vec![[0.0f32; 3]; 3 * res * res * res];
        for (idx, col) in columns.iter().enumerate() {
            let (m, j, i) = (idx / (res * res), idx / res % res, idx % res);
            for (k, c) in col.iter().enumerate() {
                data[Self::index(res, m, k, j, i)] = *c;
            }
        }
        Self {
            res,
            z: z_grid(res),
            data,
        }
    }

    #[inline]
    fn index(res: usize, m: usize, k: usize, j: usize, i: usize) -> usize {
        ((m * res + k) * res + j) * res + i
    }

    pub fn res(&self) -> usize {
        self.res
    }

    /// The stored coefficients of block `m` at grid point (x `i`, y `j`, z `k`).
    pub fn entry(&self, m: usize, k: usize, j: usize, i: usize) -> [f32; 3] {
        self.data[Self::index(self.res, m, k, j, i)]
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(12 + 4 * (self.z.len() + 3 * self.data.len()));
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(self.res as u32).to_le_bytes());
        for v in &self.z {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for c in &self.data {
            for v in c {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out
    }

    pub fn from_bytes(bytes: &[u8]) -> Result<Self, TableError> {
        let word = |at: usize| -> Option<[u8; 4]> { bytes.get(at..at + 4)?.try_into().ok() };
        if bytes.get(0..4) != Some(MAGIC) || word(4).map(u32::from_le_bytes) != Some(VERSION) {
            return Err(TableError::Header);
        }
        let res32 = word(8).map(u32::from_le_bytes).ok_or(TableError::Header)?;
        if !(2..=256).contains(&res32) {
            return Err(TableError::Resolution(res32));
        }
        let res = res32 as usize;
        let want = 12 + 4 * (res + 9 * res * res * res);
        if bytes.len() != want {
            return Err(TableError::Size {
                got: bytes.len(),
                want,
            });
        }
        let floats: Vec<f32> = bytes[12..]
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        if let Some(i) = floats.iter().position(|v| !v.is_finite()) {
            return Err(TableError::NotFinite(i));
        }
        let (z, rest) = floats.split_at(res);
        Ok(Self {
            res,
            z: z.to_vec(),
            data: rest.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        })
    }

    /// Coefficients for a reflectance colour (channels clamped to [0, 1]): exact for greys,
    /// trilinear in the table otherwise.
    pub fn coeffs(&self, rgb: [f64; 3]) -> [f64; 3] {
        let rgb = rgb.map(|v| {
            if v.is_finite() {
                v.clamp(0.0, 1.0)
            } else {
                0.0
            }
        });
        if rgb[0] == rgb[1] && rgb[1] == rgb[2] {
            // A flat spectrum: sigmoid(c₂) = v.
            let v = rgb[0];
            let c2 = if v <= 0.0 {
                f64::NEG_INFINITY
            } else if v >= 1.0 {
                f64::INFINITY
            } else {
                (v - 0.5) / (v * (1.0 - v)).sqrt()
            };
            return [0.0, 0.0, c2];
        }
        let m = if rgb[0] >= rgb[1] && rgb[0] >= rgb[2] {
            0
        } else if rgb[1] >= rgb[2] {
            1
        } else {
            2
        };
        let res = self.res;
        let z = rgb[m] as f32;
        let last = (res - 1) as f64;
        let x = rgb[(m + 1) % 3] / rgb[m] * last;
        let y = rgb[(m + 2) % 3] / rgb[m] * last;
        let cell = |v: f64| {
            let i = (v.floor() as usize).min(res - 2);
            (i, v - i as f64)
        };
        let (xi, dx) = cell(x);
        let (yi, dy) = cell(y);
        let zi = self
            .z
            .partition_point(|&s| s <= z)
            .saturating_sub(1)
            .min(res - 2);
        let dz = ((z - self.z[zi]) / (self.z[zi + 1] - self.z[zi])).clamp(0.0, 1.0) as f64;
        let mut c = [0.0f64; 3];
        for (k, wz) in [(zi, 1.0 - dz), (zi + 1, dz)] {
            for (j, wy) in [(yi, 1.0 - dy), (yi + 1, dy)] {
                for (i, wx) in [(xi, 1.0 - dx), (xi + 1, dx)] {
                    let w = wz * wy * wx;
                    let e = self.entry(m, k, j, i);
                    for q in 0..3 {
                        c[q] += w * e[q] as f64;
                    }
                }
            }
        }
        c
    }
}

/// The shipped sRGB table (compiled into the binary).
pub fn srgb_table() -> &'static Table {
    static TABLE: OnceLock<Table> = OnceLock::new();
    TABLE.get_or_init(|| {
        Table::from_bytes(include_bytes!("../../../assets/data/jh_srgb.bin"))
            .expect("the embedded Jakob–Hanika table is valid")
    })
}

/// Coefficients for one colour, refined from the table's by Gauss–Newton (about 0.1 ms:
/// for a scene's few material and light colours, not per texel). The table alone is
/// within 0.0023 per channel for 99 % of the gamut; refined, the colour is exact wherever
/// the sigmoid family can reach it (it cannot quite reach very dark saturated blues, or
/// the brightest near-whites: there the fit's best is kept).
pub fn fit_exactly(rgb: [f64; 3]) -> [f64; 3] {
    let rgb = rgb.map(|v| {
        if v.is_finite() {
            v.clamp(0.0, 1.0)
        } else {
            0.0
        }
    });
    let start = srgb_table().coeffs(rgb);
    if (rgb[0] == rgb[1] && rgb[1] == rgb[2]) || rgb.iter().all(|&v| v <= 0.0) {
        return start;
    }
    let fitter = fitter();
    let refined = fitter.solve(rgb, start);
    let err = |c: [f64; 3]| {
        let got = fitter.rgb_of(c);
        (0..3).map(|k| (got[k] - rgb[k]).abs()).fold(0.0, f64::max)
    };
    if err(refined) < err(start) {
        refined
    } else {
        start
    }
}

fn fitter() -> &'static Fitter {
    static FITTER: OnceLock<Fitter> = OnceLock::new();
    FITTER.get_or_init(Fitter::new)
}

/// An emitter's colour as a scale and a bounded spectrum's coefficients: the spectrum
/// is `scale · s(λ) · D65(λ)/Y(D65)`, with `s` the sigmoid of the colour divided by
/// twice its largest channel (so it stays well inside the table, at most ½).
pub fn illuminant_parts(rgb: [f64; 3]) -> (f64, [f64; 3]) {
    illuminant_parts_by(rgb, fit_exactly)
}

fn illuminant_parts_by(rgb: [f64; 3], coeffs: impl Fn([f64; 3]) -> [f64; 3]) -> (f64, [f64; 3]) {
    let rgb = super::spectrum::clamp_rgb(rgb);
    let peak = rgb.iter().fold(0.0f64, |m, &v| m.max(v));
    if peak <= 0.0 {
        return (0.0, [0.0, 0.0, 0.0]);
    }
    let scale = 2.0 * peak;
    (scale, coeffs(rgb.map(|v| v / scale)))
}

/// [`illuminant_parts`] from the table alone (no refinement: fast enough per photon).
pub fn illuminant_parts_from_table(rgb: [f64; 3]) -> (f64, [f64; 3]) {
    illuminant_parts_by(rgb, |c| srgb_table().coeffs(c))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_table_is_what_the_fit_produces() {
        // A slice of columns (every block, three x-y points each, every z) refitted now
        // must equal the shipped table: the table is reproducible from the code.
        let table = srgb_table();
        assert_eq!(table.res(), RES);
        let fitter = Fitter::new();
        for m in 0..3 {
            for (i, j) in [(0, RES - 1), (RES / 2, 3), (RES - 1, RES / 3)] {
                let col = fitter.column(RES, m, i, j);
                for (k, c) in col.iter().enumerate() {
                    let stored = table.entry(m, k, j, i);
                    for q in 0..3 {
                        let d = (c[q] - stored[q]).abs();
                        assert!(
                            d <= 1e-4 * (1.0 + stored[q].abs()),
                            "block {m} ({i},{j},{k}) coefficient {q}: {} vs stored {}",
                            c[q],
                            stored[q]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn fitted_grid_colours_are_reproduced() {
        // At grid points the fit itself must hit its target (well under a visible ΔE);
        // between them, trilinear coefficients stay close. Checked in linear sRGB.
        let fitter = Fitter::new();
        let table = srgb_table();
        let mut worst: f64 = 0.0;
        let mut rng = crate::sampling::Rng::stream(11, 0, 0, crate::sampling::Purpose::Photon);
        for _ in 0..400 {
            let [a, b] = rng.next_2d();
            let [c, _] = rng.next_2d();
            let rgb = [a as f64, b as f64, c as f64].map(|v| 0.02 + 0.96 * v);
            let got = fitter.rgb_of(table.coeffs(rgb));
            for k in 0..3 {
                worst = worst.max((got[k] - rgb[k]).abs());
            }
        }
        assert!(worst < 0.01, "worst channel error {worst}");
    }

    #[test]
    fn greys_are_flat_and_exact() {
        let table = srgb_table();
        for v in [0.0, 0.18, 0.5, 0.9, 1.0] {
            for l in [380.0, 550.0, 700.0] {
                let s = eval(table.coeffs([v; 3]), l);
                assert!((s - v).abs() < 1e-12, "{v} at {l}: {s}");
            }
        }
    }

    #[test]
    fn bad_tables_are_refused_with_a_reason() {
        assert_eq!(Table::from_bytes(b"nope"), Err(TableError::Header));
        let mut bytes = srgb_table().to_bytes();
        bytes.pop();
        assert!(matches!(
            Table::from_bytes(&bytes),
            Err(TableError::Size { .. })
        ));
        let mut bytes = srgb_table().to_bytes();
        let at = bytes.len() - 4;
        bytes[at..].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(matches!(
            Table::from_bytes(&bytes),
            Err(TableError::NotFinite(_))
        ));
    }

    #[test]
    fn emitters_keep_their_colour_and_scale() {
        // The Cornell light: (17, 12, 4). Its spectrum's colour must be within 1 %.
        let (scale, c) = illuminant_parts([17.0, 12.0, 4.0]);
        assert_eq!(scale, 34.0);
        let got = Fitter::new().rgb_of(c).map(|v| v * scale);
        for (g, want) in got.iter().zip([17.0, 12.0, 4.0]) {
            assert!((g / want - 1.0).abs() < 0.01, "{got:?}");
        }
    }
}
