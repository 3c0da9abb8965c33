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
        for (s, p) in self.sum.iter_mut().zip(pass) {
            if p.iter().all(|v| v.is_finite()) {
                for c in 0..3 {
                    s[c] += p[c] as f64;
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
        self.sum.len() * size_of::<[f64; 3]>()
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
