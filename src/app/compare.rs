//! Compare mode: the current image and probe spectra are frozen as "A"; storage, bins or
//! anything else may then change, and the live render "B" is shown beside A — split at
//! a movable line, or as their difference ×N — with PSNR and ΔE2000 between them, and
//! A's probe spectra on the same plot as B's. Full against compact against RGB at the same
//! photons is the demonstration the viewer exists for.

use std::sync::Arc;

use crate::render::Image;

/// A frozen render.
#[derive(Clone, Debug)]
pub struct Frozen {
    /// What it was rendered with ("compact, 100 bins, 12 passes").
    pub label: String,
    pub image: Arc<Image>,
    /// The probes' spectra when it was frozen.
    pub probes: Vec<FrozenProbe>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct FrozenProbe {
    pub pixel: (u32, u32),
    /// Bin centres (nm) and the mean radiance per bin.
    pub wavelengths: Vec<f64>,
    pub spectrum: Vec<f32>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CompareView {
    /// A left of the split line, B right of it.
    Split,
    /// |A − B| × gain, per channel, as displayed.
    Difference,
}

/// How the live image agrees with A, as displayed (the same exposure for both).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Agreement {
    /// The paper's equation 6 on display values.
    pub psnr_db: f64,
    /// Mean and 95th percentile of per-pixel CIEDE2000.
    pub de_mean: f64,
    pub de_p95: f64,
}

/// The agreement of `b` with `a` at `exposure`; None when their sizes differ.
pub fn agreement(a: &Image, b: &Image, exposure: f32) -> Option<Agreement> {
    let psnr_db = crate::metrics::psnr(a, b, exposure).ok()?;
    let (de_mean, de_p95) = crate::metrics::de2000_stats(a, b, exposure).ok()?;
    Some(Agreement {
        psnr_db,
        de_mean,
        de_p95,
    })
}

/// The difference image |A − B| × `gain` of the two as displayed at `exposure` (sRGB
/// bytes); None when their sizes differ.
pub fn difference_display(a: &Image, b: &Image, exposure: f32, gain: f32) -> Option<Vec<u8>> {
    if (a.width, a.height) != (b.width, b.height) {
        return None;
    }
    let enc = |v: f32| crate::spectral::color::srgb8(v * exposure) as f32;
    Some(
        a.pixels
            .iter()
            .zip(&b.pixels)
            .flat_map(|(p, q)| {
                (0..3).map(move |c| ((enc(p[c]) - enc(q[c])).abs() * gain).min(255.0) as u8)
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(v: f32) -> Image {
        Image {
            width: 2,
            height: 1,
            pixels: vec![[v, v, v], [0.5, 0.25, 0.125]],
        }
    }

    #[test]
    fn identical_images_agree_perfectly_and_differ_by_nothing() {
        let a = image(0.2);
        let g = agreement(&a, &a, 1.0).unwrap();
        assert!(g.psnr_db.is_infinite() || g.psnr_db > 90.0, "{g:?}");
        assert_eq!((g.de_mean, g.de_p95), (0.0, 0.0));
        assert!(
            difference_display(&a, &a, 1.0, 8.0)
                .unwrap()
                .iter()
                .all(|&v| v == 0)
        );
    }

    #[test]
    fn a_difference_is_scaled_and_sizes_must_match() {
        let (a, b) = (image(0.2), image(0.21));
        let d = difference_display(&a, &b, 1.0, 10.0).unwrap();
        // 0.2 and 0.21 encode to sRGB 124 and 126: two levels, ×10.
        use crate::spectral::color::srgb8;
        assert_eq!((srgb8(0.2), srgb8(0.21)), (124, 126));
        assert_eq!(&d[..3], &[20, 20, 20]);
        assert_eq!(&d[3..], &[0, 0, 0]);
        let g = agreement(&a, &b, 1.0).unwrap();
        assert!(g.psnr_db.is_finite() && g.de_mean > 0.0);
        let small = Image {
            width: 1,
            height: 1,
            pixels: vec![[0.0; 3]],
        };
        assert!(agreement(&a, &small, 1.0).is_none());
        assert!(difference_display(&a, &small, 1.0, 1.0).is_none());
    }
}
