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
use super::spectrum::{Role, Spectrum, Upsampling};
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
    /// `to_srgb` by channel (the R weights of every bin, then G, then B): the layout
    /// [`BinGrid::to_linear_srgb`]'s eight-lane sums read.
    srgb_rows: [Vec<f32>; 3],
    smits: Option<SmitsBins>,
    /// How RGB colours (materials, lights, texels) become spectra on this grid.
    upsampling: Upsampling,
    /// Wavelengths a bin's mean of a Jakob–Hanika texel is taken at, `per_bin` per bin
    /// with equal weights, bin after bin.
    texel_lambdas: Vec<f64>,
    /// `texel_lambdas` on the sigmoid fit's own axis ([`super::jakob_hanika::t_of`]).
    texel_ts: Vec<f64>,
    /// D65 normalised to Y = 1 at each of `texel_lambdas` (decoding a compact triplet).
    texel_d65: Vec<f64>,
    per_bin: usize,
}

/// Channel-major copies of per-channel sRGB weights (see `BinGrid::srgb_rows`).
fn srgb_rows(to_srgb: &[[f32; 3]]) -> [Vec<f32>; 3] {
    [0, 1, 2].map(|c| to_srgb.iter().map(|w| w[c]).collect())
}

/// Bins up to this wide take a texel's spectrum at their midpoint.
const TEXEL_MIDPOINT_NM: f64 = 6.0;
/// Wider bins are split into parts of at most this many nm, two points each.
const TEXEL_PART_NM: f64 = 25.0;

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
            srgb_rows: srgb_rows(&to_srgb),
            to_srgb,
            smits: None,
            upsampling: Upsampling::default(),
            texel_lambdas: Vec::new(),
            texel_ts: Vec::new(),
            texel_d65: Vec::new(),
            per_bin: 0,
        };
        grid.smits = Some(SmitsBins::new(&grid));
        // A bin's mean of a smooth spectrum: its midpoint for narrow bins, else two-point
        // Gauss–Legendre on each of ⌈width / 25 nm⌉ parts (exact for cubics; equal weights).
        let parts = (width / TEXEL_PART_NM).ceil().max(1.0) as usize;
        let points: Vec<f64> = if width <= TEXEL_MIDPOINT_NM {
            vec![0.5]
        } else {
            let g = 0.5 / 3f64.sqrt();
            (0..parts)
                .flat_map(|p| [p as f64 + 0.5 - g, p as f64 + 0.5 + g])
                .map(|u| u / parts as f64)
                .collect()
        };
        grid.per_bin = points.len();
        grid.texel_lambdas = (0..n)
            .flat_map(|i| {
                let a = lambda_min + i as f64 * width;
                points.iter().map(move |u| a + u * width)
            })
            .collect();
        grid.texel_ts = grid
            .texel_lambdas
            .iter()
            .map(|&l| super::jakob_hanika::t_of(l))
            .collect();
        // White light (1, 1, 1) is D65 with Y = 1 (a flat sigmoid of ½, scaled by 2).
        let white = Spectrum::illuminant([1.0; 3]);
        grid.texel_d65 = grid.texel_lambdas.iter().map(|&l| white.eval(l)).collect();
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
            srgb_rows: srgb_rows(&to_srgb),
            to_srgb,
            smits: None,
            upsampling: Upsampling::default(),
            texel_lambdas: Vec::new(),
            texel_ts: Vec::new(),
            texel_d65: Vec::new(),
            per_bin: 0,
        }
    }

    /// This grid with RGB colours upsampled by `u`.
    pub fn with_upsampling(mut self, u: Upsampling) -> Self {
        self.upsampling = u;
        self
    }

    pub fn upsampling(&self) -> Upsampling {
        self.upsampling
    }

    /// The triplet a compact record keeps for a smooth flux `spd`: the paper's Smits
    /// triplet (its decoded spectrum has exactly the flux's colour while the flux is a
    /// Smits spectrum) when scene colours are Smits-upsampled; else the flux's linear-sRGB
    /// colour itself (negative channels, out of gamut, clamped), which
    /// [`BinGrid::decode_triplet_into`] turns back into a smooth spectrum of that colour.
    /// Spectral grids only.
    pub fn encode_triplet(&self, spd: &[f32]) -> [f32; 3] {
        match (&self.smits, self.upsampling) {
            (Some(smits), Upsampling::Smits) => smits.encode(spd),
            _ => self
                .to_linear_srgb(spd)
                .map(|v| if v > 0.0 { v } else { 0.0 }),
        }
    }

    /// Whether compact triplets are Smits triplets (summed per Smits branch) on this grid.
    pub fn smits_triplets(&self) -> bool {
        self.smits.is_some() && self.upsampling == Upsampling::Smits
    }

    /// Writes the spectrum of a (non-Smits) compact triplet into `out`: Jakob–Hanika of
    /// the colour as an emitter (scale × sigmoid × D65, pbrt-v4's illuminant form), bins
    /// corrected so that their XYZ is the triplet's exactly. Triplets are linear, so a sum
    /// of photons' triplets decodes as one.
    pub fn decode_triplet_into(&self, rgb: [f32; 3], out: &mut [f32]) {
        if let (Some(smits), Upsampling::Smits) = (&self.smits, self.upsampling) {
            smits.decode_into(rgb, out);
            return;
        }
        if self.smits.is_none() {
            out.copy_from_slice(&rgb);
            return;
        }
        let (scale, c) = super::jakob_hanika::illuminant_parts_from_table(rgb.map(f64::from));
        if scale <= 0.0 {
            out.fill(0.0);
            return;
        }
        self.sigmoid_bin_means(c, scale, Some(&self.texel_d65), out);
        let target = super::color::linear_srgb_to_xyz(rgb.map(f64::from));
        self.match_colour(out, target);
    }

    /// Bin means of `scale` × the sigmoid of `c` (× `weights` at the same wavelengths, if
    /// given), from the grid's per-bin sample wavelengths.
    fn sigmoid_bin_means(&self, c: [f64; 3], scale: f64, weights: Option<&[f64]>, out: &mut [f32]) {
        let k = scale / self.per_bin as f64;
        let per = self.per_bin;
        // A chunk of whole bins at a time into a buffer, then each bin's points summed in
        // order. Finite coefficients take `eval`'s arithmetic without its branch (a loop
        // the compiler runs two lanes wide); infinite ones (a flat 0 or 1) and NaN take
        // `eval` itself, whose limits they need. The same bits as `eval` point by point.
        let finite = c.iter().all(|v| v.is_finite());
        const POINTS: usize = 64;
        let bins_per_chunk = (POINTS / per.max(1)).max(1);
        let mut buf = [0.0f64; POINTS];
        for (chunk, outs) in out.chunks_mut(bins_per_chunk).enumerate() {
            let at = chunk * bins_per_chunk * per..(chunk * bins_per_chunk + outs.len()) * per;
            let ys = &mut buf[..at.len()];
            if finite {
                for (y, &t) in ys.iter_mut().zip(&self.texel_ts[at.clone()]) {
                    let x = (c[0] * t + c[1]) * t + c[2];
                    *y = 0.5 + 0.5 * x / (1.0 + x * x).sqrt();
                }
            } else {
                for (y, &l) in ys.iter_mut().zip(&self.texel_lambdas[at.clone()]) {
                    *y = super::jakob_hanika::eval(c, l);
                }
            }
            if let Some(w) = weights {
                for (y, &d) in ys.iter_mut().zip(&w[at]) {
                    *y *= d;
                }
            }
            for (v, bin) in outs.iter_mut().zip(ys.chunks_exact(per)) {
                let s: f64 = bin.iter().sum();
                *v = (s * k) as f32;
            }
        }
    }

    /// A reflectance colour per bin in [0, 1] (a texel's: the table's coefficients, no
    /// refinement, so it costs N sigmoid evaluations; Smits' bins for `smits`; the colour
    /// itself on the RGB grid). `out` has one value per channel.
    pub fn upsample_reflectance_into(&self, rgb: [f32; 3], out: &mut [f32]) {
        let rgb = rgb.map(|c| {
            if c.is_finite() {
                c.clamp(0.0, 1.0)
            } else {
                0.0
            }
        });
        match (&self.smits, self.upsampling) {
            (None, _) => out.copy_from_slice(&rgb),
            (Some(smits), Upsampling::Smits) => {
                smits.decode_into(rgb, out);
                for v in out.iter_mut() {
                    *v = v.clamp(0.0, 1.0);
                }
            }
            (Some(_), Upsampling::JakobHanika) => {
                let c = super::jakob_hanika::srgb_table().coeffs(rgb.map(f64::from));
                self.sigmoid_bin_means(c, 1.0, None, out);
            }
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
        let s = &*s.upsampled(self.upsampling);
        let values: Vec<f32> = match (self.transport, s) {
            (Transport::Rgb, _) => s.to_rgb_renderer(role).map(|v| v as f32).to_vec(),
            (Transport::Spectral, Spectrum::Reflectance(c))
                if c.upsampling == Upsampling::Smits =>
            {
                let mut out = vec![0.0; self.len()];
                let smits = self.smits.as_ref().expect("spectral grids have Smits bins");
                smits.decode_into(c.rgb.map(|v| v as f32), &mut out);
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
            self.keep_colour(s, &mut values);
        }
        values
    }

    /// Corrects an emitter's bin values so that their colour *on this grid* is the
    /// spectrum's colour (1 nm sums): bin means weighted by the bins' CMF integrals are
    /// not the spectrum's XYZ when it is steep across a wide bin (a 1000 K blackbody came
    /// out 2.35× too bright at 4 bins; D65 at 20 bins 0.35 % off in white, the Cornell
    /// light 1.6 % in blue). Each bin is scaled by `1 + wᵢ·k` (wᵢ its CMF weights) with the
    /// 3-vector `k` solved so that XYZ matches exactly: a smooth change that keeps zero
    /// bins zero. Where that cannot be done — fewer than 3 bins, a spike in one or two
    /// bins, a correction of more than ±50 % in any bin — only the luminance is kept, by
    /// one scale factor. What few bins still cost is the light's spectral shape (what it
    /// does after reflection), not the colour and brightness a user set.
    ///
    /// With Smits upsampling (the paper's setting) only the luminance is kept, as the paper
    /// did: its compact records decode a photon after one bounce to exactly its colour only
    /// while the light stays a Smits spectrum.
    fn keep_colour(&self, s: &Spectrum, values: &mut [f32]) {
        let exact = s.xyz();
        if !exact.iter().all(|v| v.is_finite()) {
            return;
        }
        if self.upsampling == Upsampling::JakobHanika && self.match_colour(values, exact) {
            return;
        }
        let on_grid = self.to_xyz(values)[1];
        if on_grid > 0.0 && exact[1] > 0.0 && on_grid.is_finite() {
            let k = (exact[1] / on_grid) as f32;
            for v in values.iter_mut() {
                *v *= k;
            }
        }
    }

    /// Scales `values` per bin by `1 + wᵢ·k` so that their XYZ is `target`, if that is a
    /// correction within ±50 % everywhere (else leaves them and returns false: fewer than
    /// 3 bins, or a spike in one or two, make the system singular or the factors wild).
    fn match_colour(&self, values: &mut [f32], target: [f64; 3]) -> bool {
        if values.len() < 3 {
            return false;
        }
        let got = self.to_xyz(values);
        // M k = target − got, with M = Σᵢ vᵢ wᵢ wᵢᵀ.
        let mut m = [[0.0f64; 3]; 3];
        for (w, &v) in self.to_xyz.iter().zip(values.iter()) {
            for r in 0..3 {
                for c in 0..3 {
                    m[r][c] += v as f64 * w[r] * w[c];
                }
            }
        }
        let Some(inv) = super::color::invert3(&m) else {
            return false;
        };
        let k = super::color::mul3(&inv, [0, 1, 2].map(|c| target[c] - got[c]));
        let factor = |w: &[f64; 3]| 1.0 + w[0] * k[0] + w[1] * k[1] + w[2] * k[2];
        if !self.to_xyz.iter().all(|w| (0.5..=1.5).contains(&factor(w))) {
            return false;
        }
        for (w, v) in self.to_xyz.iter().zip(values.iter_mut()) {
            *v = (*v as f64 * factor(w)) as f32;
        }
        true
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
    #[inline]
    pub fn to_linear_srgb(&self, v: &[f32]) -> [f32; 3] {
        // One eight-lane dot product per channel over channel-major weights.
        self.srgb_rows.each_ref().map(|w| spd::dot(w, v))
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
    /// `a` *= `b` bin by bin, returning the new Σa: bit for bit [`mul_assign`] then
    /// [`sum`], in one pass.
    #[inline]
    pub fn mul_assign_sum(a: &mut [f32], b: &[f32]) -> f32 {
        let n = a.len().min(b.len());
        let (a, b) = (&mut a[..n], &b[..n]);
        let mut lanes = [0.0f32; LANES];
        let mut chunks = a.chunks_exact_mut(LANES);
        for (x, y) in (&mut chunks).zip(b.chunks_exact(LANES)) {
            for ((l, x), y) in lanes.iter_mut().zip(x).zip(y) {
                *x *= y;
                *l += *x;
            }
        }
        let mut s = 0.0f32;
        for l in lanes {
            s += l;
        }
        let done = LANES * (n / LANES);
        for (x, y) in chunks.into_remainder().iter_mut().zip(&b[done..]) {
            *x *= y;
            s += *x;
        }
        s
    }

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

    /// Lanes of the vectorisable reductions below: eight independent partial results, so
    /// that the compiler can keep them in one SIMD register (a plain left-to-right f32
    /// sum is one chain of dependent adds, about 4 cycles a bin). Below eight bins the
    /// result is the plain left-to-right sum, bit for bit.
    const LANES: usize = 8;

    pub fn sum(a: &[f32]) -> f32 {
        let chunks = a.chunks_exact(LANES);
        let rest = chunks.remainder();
        let mut lanes = [0.0f32; LANES];
        for c in chunks {
            for (l, v) in lanes.iter_mut().zip(c) {
                *l += v;
            }
        }
        let mut s = 0.0f32;
        for l in lanes {
            s += l;
        }
        for v in rest {
            s += v;
        }
        s
    }

    /// Σ a·b over the shorter length: eight partial sums as in [`sum`] (below eight
    /// entries, the plain left-to-right sum).
    #[inline]
    pub fn dot(a: &[f32], b: &[f32]) -> f32 {
        let n = a.len().min(b.len());
        let (a, b) = (&a[..n], &b[..n]);
        let mut lanes = [0.0f32; LANES];
        for (x, y) in a.chunks_exact(LANES).zip(b.chunks_exact(LANES)) {
            for ((l, x), y) in lanes.iter_mut().zip(x).zip(y) {
                *l += x * y;
            }
        }
        let mut s = 0.0f32;
        for l in lanes {
            s += l;
        }
        let done = LANES * (n / LANES);
        for (x, y) in a[done..].iter().zip(&b[done..]) {
            s += x * y;
        }
        s
    }

    pub fn max(a: &[f32]) -> f32 {
        a.iter().copied().fold(0.0, f32::max)
    }

    /// Index of the only non-zero entry, if exactly one entry is non-zero.
    pub fn single_nonzero(a: &[f32]) -> Option<usize> {
        // The first non-zero entry (a many-bin flux stops at once), then the rest eight
        // entries at a time (branch-free within each eight), stopping at a second one.
        let first = a.iter().position(|&v| v != 0.0)?;
        let mut rest = a[first + 1..].chunks_exact(LANES);
        for c in &mut rest {
            if c.iter().fold(false, |any, &v| any | (v != 0.0)) {
                return None;
            }
        }
        rest.remainder().iter().all(|&v| v == 0.0).then_some(first)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spectral::jakob_hanika::eval;

    /// What `sigmoid_bin_means` computed before it ran in chunks: `eval` point by point.
    fn pointwise(g: &BinGrid, c: [f64; 3], scale: f64, weights: Option<&[f64]>) -> Vec<f32> {
        let (per, k) = (g.per_bin, scale / g.per_bin as f64);
        (0..g.len())
            .map(|b| {
                let at = b * per..(b + 1) * per;
                let s: f64 = match weights {
                    Some(w) => g.texel_lambdas[at.clone()]
                        .iter()
                        .zip(&w[at])
                        .map(|(&l, &d)| eval(c, l) * d)
                        .sum(),
                    None => g.texel_lambdas[at].iter().map(|&l| eval(c, l)).sum(),
                };
                (s * k) as f32
            })
            .collect()
    }

    #[test]
    fn chunked_sigmoid_bin_means_are_the_pointwise_ones_bit_for_bit() {
        // Bin counts with one point a bin (narrow bins), two, and several parts, some
        // crossing the chunk's 64 points unevenly; coefficients up to the fit's bound,
        // flat 0 and 1 (infinite c₂), and a NaN.
        let coeffs = [
            [0.0, 0.0, 0.3],
            [-150.0, 140.0, -30.0],
            [200.0, -200.0, 45.0],
            [3.5, -1.25, 0.75],
            [0.0, 0.0, f64::INFINITY],
            [0.0, 0.0, f64::NEG_INFINITY],
            [f64::NAN, 0.0, 0.0],
        ];
        for n in [1, 3, 7, 20, 33, 100, 470, 1000] {
            let g = BinGrid::with_bins(n).unwrap();
            for c in coeffs {
                for weights in [None, Some(&g.texel_d65[..])] {
                    let mut out = vec![0.0f32; n];
                    g.sigmoid_bin_means(c, 1.7, weights, &mut out);
                    let want = pointwise(&g, c, 1.7, weights);
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(
                        bits(&out),
                        bits(&want),
                        "{n} bins, {c:?}, {}",
                        weights.is_some()
                    );
                }
            }
        }
    }
}
