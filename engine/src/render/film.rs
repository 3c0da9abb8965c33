//! The film: per-pass images merged into f64 sums, developed on demand.
//!
//! Each pass renders a complete image (one sample per pixel), then [`Film::add_pass`] adds
//! it to per-pixel f64 sums; the developed image is the mean over passes, which is what
//! progressive photon mapping with a shrinking radius needs (Knaus & Zwicker 2011). The
//! sums are f64 because f32 accumulation drifts after millions of passes (an f32 sum stops
//! growing near 2²⁴ samples). Only linear sRGB is kept: no spectral film memory unless a
//! consumer asks for it.

/// Linear-sRGB pixels, row-major, top row first.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[f32; 3]>,
}

impl Image {
    pub fn get(&self, x: u32, y: u32) -> [f32; 3] {
        self.pixels[(y * self.width + x) as usize]
    }
}

#[derive(Clone, Debug)]
pub struct Film {
    width: u32,
    height: u32,
    sum: Vec<[f64; 3]>,
    /// The sums of the odd-numbered passes alone (1st, 3rd, …): with `sum` they give two
    /// independent half-means, whose difference measures the noise left (see
    /// [`Film::noise_psnr`]).
    odd: Vec<[f64; 3]>,
    passes: u64,
    /// Samples dropped because they were NaN or infinite.
    dropped: u64,
}

impl Film {
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            sum: vec![[0.0; 3]; (width * height) as usize],
            odd: vec![[0.0; 3]; (width * height) as usize],
            passes: 0,
            dropped: 0,
        }
    }

    pub fn passes(&self) -> u64 {
        self.passes
    }

    pub fn dropped_samples(&self) -> u64 {
        self.dropped
    }

    /// Adds one pass's image. A non-finite sample is dropped (counted) and contributes 0,
    /// so one bad path never poisons a pixel forever.
    pub fn add_pass(&mut self, pass: &[[f32; 3]]) {
        debug_assert_eq!(pass.len(), self.sum.len());
        let odd = self.passes.is_multiple_of(2); // this is pass passes + 1
        for ((s, o), p) in self.sum.iter_mut().zip(self.odd.iter_mut()).zip(pass) {
            if p.iter().all(|v| v.is_finite()) {
                for c in 0..3 {
                    s[c] += p[c] as f64;
                    if odd {
                        o[c] += p[c] as f64;
                    }
                }
            } else {
                self.dropped += 1;
            }
        }
        self.passes += 1;
    }

    /// The mean image so far (black before the first pass).
    pub fn develop(&self) -> Image {
        let k = if self.passes > 0 {
            1.0 / self.passes as f64
        } else {
            0.0
        };
        Image {
            width: self.width,
            height: self.height,
            pixels: self.sum.iter().map(|s| s.map(|v| (v * k) as f32)).collect(),
        }
    }

    pub fn memory_bytes(&self) -> usize {
        (self.sum.len() + self.odd.len()) * size_of::<[f64; 3]>()
    }

    /// Per pixel, an estimate of the variance of the mean's luminance: from the odd and
    /// even half-means A, B (E|A − B|² = σ²(1/a + 1/b), the mean's variance σ²/n), averaged
    /// over the 3 × 3 neighbourhood (one pixel's |A − B|² alone is a one-sample estimate).
    /// None before two passes.
    pub fn luminance_variance(&self) -> Option<Vec<f32>> {
        if self.passes < 2 {
            return None;
        }
        let n = self.passes as f64;
        let a = n.div_euclid(2.0) + (self.passes % 2) as f64;
        let b = n - a;
        let k = 1.0 / (n * (1.0 / a + 1.0 / b));
        let lum = |c: [f64; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        let raw: Vec<f64> = self
            .sum
            .iter()
            .zip(&self.odd)
            .map(|(s, o)| {
                let odd = lum(*o) / a;
                let even = (lum(*s) - lum(*o)) / b;
                (odd - even).powi(2) * k
            })
            .collect();
        let (w, h) = (self.width as usize, self.height as usize);
        Some(
            (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    let (mut sum, mut count) = (0.0, 0.0);
                    for qy in y.saturating_sub(1)..(y + 2).min(h) {
                        for qx in x.saturating_sub(1)..(x + 2).min(w) {
                            sum += raw[qy * w + qx];
                            count += 1.0;
                        }
                    }
                    (sum / count) as f32
                })
                .collect(),
        )
    }

    /// An estimate, without a reference, of how far the image is from converged: the PSNR
    /// (the paper's equation 6, display values at `exposure`) of the mean over passes
    /// against its own expectation. The odd and the even passes give two independent
    /// half-means A and B; E|A − B|² = σ²(1/a + 1/b) while the full mean's error is σ²/n,
    /// so PSNR(mean) ≈ PSNR(A, B) + 10 log₁₀(n (1/a + 1/b)) (+6 dB for halves). It measures
    /// noise only, not the bias a radius still carries. None before two passes.
    pub fn noise_psnr(&self, exposure: f32) -> Option<f64> {
        if self.passes < 2 {
            return None;
        }
        let n = self.passes as f64;
        let a = n.div_euclid(2.0) + (self.passes % 2) as f64;
        let b = n - a;
        // The two halves' means, pixel by pixel, without building either image.
        let between = crate::metrics::psnr_of_pairs(
            self.sum.len(),
            |i| {
                let (s, o) = (self.sum[i], self.odd[i]);
                (
                    o.map(|x| (x / a) as f32),
                    [s[0] - o[0], s[1] - o[1], s[2] - o[2]].map(|x| (x / b) as f32),
                )
            },
            exposure,
        );
        Some(between + 10.0 * (n * (1.0 / a + 1.0 / b)).log10())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn many_passes_keep_the_mean_and_the_channel_ratios() {
        // ice_halo_sim#380: f32 accumulation drifted the hue. 1e8 passes of one value,
        // through the film's own `add_pass`.
        let mut f = Film::new(1, 1);
        let v = [0.1f32, 0.3, 0.7];
        for _ in 0..100_000_000u64 {
            f.add_pass(&[v]);
        }
        assert_eq!(f.passes(), 100_000_000);
        let p = f.develop().pixels[0];
        for (got, want) in p.iter().zip(v) {
            assert!(((got - want) / want).abs() < 1e-6, "{p:?}");
        }
        for (a, b) in [(0, 1), (1, 2), (0, 2)] {
            let ratio = (p[a] / p[b]) / (v[a] / v[b]);
            assert!((ratio - 1.0).abs() < 1e-6, "channel ratio {a}/{b}: {p:?}");
        }
    }

    #[test]
    fn the_noise_estimate_matches_the_error_against_the_truth() {
        // Passes of a known image plus Gaussian-ish noise: the estimate from the odd and
        // even halves alone agrees with the PSNR against the known image within 1 dB, and
        // rises by ~3 dB per doubling of passes.
        use crate::sampling::{Purpose, Rng};
        let (w, h) = (64u32, 64u32);
        let truth: Vec<[f32; 3]> = (0..w * h)
            .map(|i| [0.2 + 0.1 * (i % 7) as f32 / 7.0, 0.3, 0.15])
            .collect();
        let truth_img = Image {
            width: w,
            height: h,
            pixels: truth.clone(),
        };
        let mut rng = Rng::stream(1, 0, 0, Purpose::Camera);
        let mut f = Film::new(w, h);
        let mut last = None;
        for pass in 1..=64u64 {
            let noisy: Vec<[f32; 3]> = truth
                .iter()
                .map(|p| {
                    p.map(|v| {
                        // Sum of four uniforms: near-Gaussian, zero mean.
                        let u: f32 = (0..4).map(|_| rng.next_f32() - 0.5).sum();
                        v * (1.0 + 0.6 * u)
                    })
                })
                .collect();
            f.add_pass(&noisy);
            if pass == 16 || pass == 64 {
                let est = f.noise_psnr(1.0).unwrap();
                let real = crate::metrics::psnr(&f.develop(), &truth_img, 1.0).unwrap();
                assert!(
                    (est - real).abs() < 1.0,
                    "pass {pass}: estimate {est:.2} dB, real {real:.2} dB"
                );
                if let Some(prev) = last {
                    let gain: f64 = est - prev;
                    assert!((gain - 6.0).abs() < 1.5, "4× passes: +{gain:.2} dB (≈ 6)");
                }
                last = Some(est);
            }
        }
        assert!(Film::new(2, 2).noise_psnr(1.0).is_none());
    }

    #[test]
    fn non_finite_samples_are_dropped_and_counted() {
        let mut f = Film::new(2, 1);
        f.add_pass(&[[1.0, 1.0, 1.0], [f32::NAN, 0.0, 0.0]]);
        f.add_pass(&[[3.0, 3.0, 3.0], [1.0, 1.0, f32::INFINITY]]);
        let img = f.develop();
        assert_eq!(img.pixels[0], [2.0, 2.0, 2.0]);
        assert_eq!(img.pixels[1], [0.0, 0.0, 0.0]);
        assert_eq!(f.dropped_samples(), 2);
    }
}

/// Per-pixel spectra, kept only when something will read them (a spectral EXR): N bins
/// per pixel summed over passes in f32 (4·N bytes a pixel: 100 bins at 256² is 26 MB).
/// Same rule as [`Film`]: a non-finite sample contributes 0 to its pixel.
#[derive(Clone, Debug)]
pub struct SpectralFilm {
    width: u32,
    height: u32,
    bins: usize,
    sum: Vec<f32>,
    passes: u64,
}

impl SpectralFilm {
    pub fn new(width: u32, height: u32, bins: usize) -> Self {
        Self {
            width,
            height,
            bins,
            sum: vec![0.0; width as usize * height as usize * bins],
            passes: 0,
        }
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    pub fn bins(&self) -> usize {
        self.bins
    }

    pub fn passes(&self) -> u64 {
        self.passes
    }

    /// Adds one pass: `bins` values per pixel, row-major.
    pub fn add_pass(&mut self, pass: &[f32]) {
        debug_assert_eq!(pass.len(), self.sum.len());
        for (px, src) in self
            .sum
            .chunks_exact_mut(self.bins)
            .zip(pass.chunks_exact(self.bins))
        {
            if src.iter().all(|v| v.is_finite()) {
                for (s, v) in px.iter_mut().zip(src) {
                    *s += v;
                }
            }
        }
        self.passes += 1;
    }

    /// The mean spectrum of every pixel, `bins` values each, row-major, top row first.
    pub fn develop(&self) -> Vec<f32> {
        let k = if self.passes > 0 {
            1.0 / self.passes as f32
        } else {
            0.0
        };
        self.sum.iter().map(|v| v * k).collect()
    }

    pub fn memory_bytes(&self) -> usize {
        self.sum.len() * 4
    }
}
