//! Image error metrics and process measurements: PSNR (the paper's equation 6),
//! CIEDE2000, and peak resident memory.

use crate::render::Image;
use crate::spectral::color::{SRGB_TO_XYZ, mul3, srgb_encode};

/// PSNR by the paper's equation 6 on [0, 1] display values: 10·log10(MN / Σ(a−b)²), the
/// squared differences summed over pixels and averaged over the three channels.
/// Infinite for identical images.
pub fn psnr(a: &Image, b: &Image, exposure: f32) -> Result<f64, SizeMismatch> {
    same_size(a, b)?;
    Ok(psnr_of_pairs(
        a.pixels.len(),
        |i| (a.pixels[i], b.pixels[i]),
        exposure,
    ))
}

/// Pixels whose squared display differences are summed in a row (in order) before the
/// chunks' sums are added up in order: the same bits on any thread count.
const SSE_CHUNK: usize = 4096;

/// [`psnr`] of `n` pixel pairs given by `pair` (so a caller compares images it never
/// builds, such as a film's two halves). The sRGB encoding, six `powf` a pixel, is
/// spread over the thread pool in fixed chunks.
pub fn psnr_of_pairs(
    n: usize,
    pair: impl Fn(usize) -> ([f32; 3], [f32; 3]) + Sync,
    exposure: f32,
) -> f64 {
    use rayon::prelude::*;
    let chunks = n.div_ceil(SSE_CHUNK);
    let sums: Vec<f64> = (0..chunks)
        .into_par_iter()
        .map(|chunk| {
            let mut sse = 0.0f64;
            for i in chunk * SSE_CHUNK..((chunk + 1) * SSE_CHUNK).min(n) {
                let (p, q) = pair(i);
                for c in 0..3 {
                    let d =
                        srgb_encode(p[c] * exposure) as f64 - srgb_encode(q[c] * exposure) as f64;
                    sse += d * d / 3.0;
                }
            }
            sse
        })
        .collect();
    let sse: f64 = sums.iter().sum();
    if sse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (n as f64 / sse).log10()
    }
}

/// Two images compared pixel by pixel differ in size (e.g. a user's reference image).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the images differ in size: {0}x{1} against {2}x{3}")]
pub struct SizeMismatch(pub u32, pub u32, pub u32, pub u32);

fn same_size(a: &Image, b: &Image) -> Result<(), SizeMismatch> {
    if (a.width, a.height) == (b.width, b.height) && a.pixels.len() == b.pixels.len() {
        Ok(())
    } else {
        Err(SizeMismatch(a.width, a.height, b.width, b.height))
    }
}

/// CIELAB of a linear-sRGB colour shown on a display (clamped to [0, 1]), D65 white.
pub fn lab_of_display(rgb: [f32; 3], exposure: f32) -> [f64; 3] {
    let lin = rgb.map(|v| {
        let v = v * exposure;
        if v.is_finite() {
            v.clamp(0.0, 1.0) as f64
        } else {
            0.0
        }
    });
    let xyz = mul3(&SRGB_TO_XYZ, lin);
    let white = mul3(&SRGB_TO_XYZ, [1.0, 1.0, 1.0]);
    let f = |t: f64| {
        let d = 6.0 / 29.0;
        if t > d * d * d {
            t.cbrt()
        } else {
            t / (3.0 * d * d) + 4.0 / 29.0
        }
    };
    let (fx, fy, fz) = (
        f(xyz[0] / white[0]),
        f(xyz[1] / white[1]),
        f(xyz[2] / white[2]),
    );
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// CIEDE2000 colour difference (Sharma, Wu & Dalal 2005), kL = kC = kH = 1.
pub fn ciede2000(lab1: [f64; 3], lab2: [f64; 3]) -> f64 {
    use std::f64::consts::PI;
    let [l1, a1, b1] = lab1;
    let [l2, a2, b2] = lab2;
    let c1 = a1.hypot(b1);
    let c2 = a2.hypot(b2);
    let cbar = 0.5 * (c1 + c2);
    let g = 0.5 * (1.0 - (cbar.powi(7) / (cbar.powi(7) + 25f64.powi(7))).sqrt());
    let (a1p, a2p) = ((1.0 + g) * a1, (1.0 + g) * a2);
    let (c1p, c2p) = (a1p.hypot(b1), a2p.hypot(b2));
    let hue = |b: f64, a: f64| {
        if a == 0.0 && b == 0.0 {
            0.0
        } else {
            b.atan2(a).rem_euclid(2.0 * PI)
        }
    };
    let (h1p, h2p) = (hue(b1, a1p), hue(b2, a2p));
    let dlp = l2 - l1;
    let dcp = c2p - c1p;
    let mut dhp = h2p - h1p;
    if c1p * c2p == 0.0 {
        dhp = 0.0;
    } else if dhp > PI {
        dhp -= 2.0 * PI;
    } else if dhp < -PI {
        dhp += 2.0 * PI;
    }
    let dhp_big = 2.0 * (c1p * c2p).sqrt() * (dhp / 2.0).sin();
    let lbarp = 0.5 * (l1 + l2);
    let cbarp = 0.5 * (c1p + c2p);
    let hbarp = if c1p * c2p == 0.0 {
        h1p + h2p
    } else if (h1p - h2p).abs() <= PI {
        0.5 * (h1p + h2p)
    } else if h1p + h2p < 2.0 * PI {
        0.5 * (h1p + h2p + 2.0 * PI)
    } else {
        0.5 * (h1p + h2p - 2.0 * PI)
    };
    let t = 1.0 - 0.17 * (hbarp - PI / 6.0).cos()
        + 0.24 * (2.0 * hbarp).cos()
        + 0.32 * (3.0 * hbarp + PI / 30.0).cos()
        - 0.20 * (4.0 * hbarp - 63.0 * PI / 180.0).cos();
    let dtheta = 30f64.to_radians() * (-((hbarp.to_degrees() - 275.0) / 25.0).powi(2)).exp();
    let rc = 2.0 * (cbarp.powi(7) / (cbarp.powi(7) + 25f64.powi(7))).sqrt();
    let sl = 1.0 + 0.015 * (lbarp - 50.0).powi(2) / (20.0 + (lbarp - 50.0).powi(2)).sqrt();
    let sc = 1.0 + 0.045 * cbarp;
    let sh = 1.0 + 0.015 * cbarp * t;
    let rt = -(2.0 * dtheta).sin() * rc;
    ((dlp / sl).powi(2)
        + (dcp / sc).powi(2)
        + (dhp_big / sh).powi(2)
        + rt * (dcp / sc) * (dhp_big / sh))
        .sqrt()
}

/// Mean and 95th percentile of per-pixel CIEDE2000 between two images as displayed.
pub fn de2000_stats(a: &Image, b: &Image, exposure: f32) -> Result<(f64, f64), SizeMismatch> {
    same_size(a, b)?;
    let mut d: Vec<f64> = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(p, q)| ciede2000(lab_of_display(*p, exposure), lab_of_display(*q, exposure)))
        .collect();
    if d.is_empty() {
        return Ok((0.0, 0.0));
    }
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    d.sort_by(f64::total_cmp);
    let p95 = d[((d.len() - 1) as f64 * 0.95).round() as usize];
    Ok((mean, p95))
}

/// The fraction of pixels brighter (in luminance) than `factor` times the median of their
/// 8 neighbours: isolated bright speckles, the signature of a gather radius too small for
/// the photon density. Pixels below 1e-3 of the brightest are not counted.
pub fn speckle_fraction(image: &Image, factor: f32) -> f64 {
    let (w, h) = (image.width as i64, image.height as i64);
    if w < 3 || h < 3 {
        return 0.0;
    }
    let y: Vec<f32> = image
        .pixels
        .iter()
        .map(|p| {
            let v = 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
            if v.is_finite() { v } else { 0.0 }
        })
        .collect();
    let floor = 1e-3 * y.iter().cloned().fold(0.0f32, f32::max);
    let at = |x: i64, yy: i64| y[(yy.clamp(0, h - 1) * w + x.clamp(0, w - 1)) as usize];
    let mut speckles = 0usize;
    for py in 0..h {
        for px in 0..w {
            let v = at(px, py);
            if v <= floor {
                continue;
            }
            let mut n = [0f32; 8];
            let mut k = 0;
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if dx != 0 || dy != 0 {
                        n[k] = at(px + dx, py + dy);
                        k += 1;
                    }
                }
            }
            n.sort_by(f32::total_cmp);
            let median = 0.5 * (n[3] + n[4]);
            if v > factor * median {
                speckles += 1;
            }
        }
    }
    speckles as f64 / (w * h) as f64
}

/// Peak resident memory of this process (Linux `VmHWM`), if known.
pub fn peak_rss_bytes() -> Option<u64> {
    proc_kib("/proc/self/status", "VmHWM:").map(|k| k * 1024)
}

/// Resident memory of this process now (Linux `VmRSS`), if known.
pub fn resident_bytes() -> Option<u64> {
    proc_kib("/proc/self/status", "VmRSS:").map(|k| k * 1024)
}

/// The machine's memory (Linux `MemTotal`), if known.
pub fn total_memory_bytes() -> Option<u64> {
    proc_kib("/proc/meminfo", "MemTotal:").map(|k| k * 1024)
}

/// The one reader of Linux's `/proc` memory figures: `key:  N kB` lines.
fn proc_kib(file: &str, key: &str) -> Option<u64> {
    let s = std::fs::read_to_string(file).ok()?;
    let line = s.lines().find(|l| l.starts_with(key))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ciede2000_matches_sharma_test_data() {
        // Pairs 1, 7, 13, 19, 25 and 34 of Sharma, Wu & Dalal's table, with their ΔE00.
        let cases = [
            ([50.0, 2.6772, -79.7751], [50.0, 0.0, -82.7485], 2.0425),
            ([50.0, 0.0, 0.0], [50.0, -1.0, 2.0], 2.3669),
            ([50.0, 2.5, 0.0], [56.0, -27.0, -3.0], 31.9030),
            ([50.0, 2.5, 0.0], [50.0, 3.1736, 0.5854], 1.0000),
            (
                [60.2574, -34.0099, 36.2677],
                [60.4626, -34.1751, 39.4387],
                1.2644,
            ),
            (
                [2.0776, 0.0795, -1.1350],
                [0.9033, -0.0636, -0.5514],
                0.9082,
            ),
        ];
        for (a, b, want) in cases {
            let got = ciede2000(a, b);
            assert!((got - want).abs() < 1e-4, "{a:?} {b:?}: {got} vs {want}");
            assert!((ciede2000(b, a) - want).abs() < 1e-4, "symmetric");
        }
        assert_eq!(ciede2000([50.0, 10.0, 10.0], [50.0, 10.0, 10.0]), 0.0);
    }

    #[test]
    fn white_is_l100_and_psnr_follows_equation_6() {
        let lab = lab_of_display([1.0, 1.0, 1.0], 1.0);
        assert!((lab[0] - 100.0).abs() < 1e-6 && lab[1].abs() < 1e-6 && lab[2].abs() < 1e-6);
        let img = |v: f32| Image {
            width: 1,
            height: 1,
            pixels: vec![[v; 3]],
        };
        assert_eq!(psnr(&img(0.5), &img(0.5), 1.0), Ok(f64::INFINITY));
        // Every value off by 0.1 in display space → MSE 0.01 → 20 dB.
        let b = img(crate::spectral::color::srgb_decode(0.1));
        assert!((psnr(&img(0.0), &b, 1.0).unwrap() - 20.0).abs() < 1e-3);
        let (m, p) = de2000_stats(&img(0.5), &img(0.5), 1.0).unwrap();
        assert_eq!((m, p), (0.0, 0.0));
        // A reference of another size is an error, not a panic.
        let wide = Image {
            width: 2,
            height: 1,
            pixels: vec![[0.5; 3]; 2],
        };
        assert_eq!(psnr(&img(0.5), &wide, 1.0), Err(SizeMismatch(1, 1, 2, 1)));
        assert!(de2000_stats(&wide, &img(0.5), 1.0).is_err());
    }

    #[test]
    fn psnr_counts_every_pixel_of_every_chunk_the_same_on_any_thread_count() {
        // 3 chunks and a part: two pixels off by 0.1 in display space, the first of the
        // second chunk and the last of the partial one, give MSE 2 · 0.01 / n; a chunk's
        // edge dropped or counted twice would move it.
        let n = 3 * SSE_CHUNK + 17;
        let a = Image {
            width: n as u32,
            height: 1,
            pixels: vec![[0.0; 3]; n],
        };
        let mut b = a.clone();
        b.pixels[n - 1] = [crate::spectral::color::srgb_decode(0.1); 3];
        b.pixels[SSE_CHUNK] = [crate::spectral::color::srgb_decode(0.1); 3];
        let expect = 10.0 * (n as f64 / (2.0 * 0.01)).log10();
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| psnr(&a, &b, 1.0).unwrap())
        };
        let one = on(1);
        assert!((one - expect).abs() < 1e-3, "{one} against {expect}");
        assert_eq!(one.to_bits(), on(2).to_bits());
        assert_eq!(one.to_bits(), on(5).to_bits());
    }

    #[test]
    fn speckles_are_counted_and_edges_are_not() {
        let mut img = Image {
            width: 10,
            height: 10,
            pixels: vec![[0.1; 3]; 100],
        };
        assert_eq!(speckle_fraction(&img, 10.0), 0.0);
        // A bright half-plane is an edge, not a speckle.
        for y in 0..10 {
            for x in 5..10 {
                img.pixels[y * 10 + x] = [5.0; 3];
            }
        }
        assert_eq!(speckle_fraction(&img, 10.0), 0.0);
        // Two isolated bright pixels on the dark side are.
        img.pixels[22] = [50.0; 3];
        img.pixels[71] = [50.0; 3];
        assert_eq!(speckle_fraction(&img, 10.0), 0.02);
    }

    #[test]
    fn peak_memory_is_reported_on_linux() {
        if cfg!(target_os = "linux") {
            assert!(peak_rss_bytes().unwrap() > 1_000_000);
            assert!(resident_bytes().unwrap() > 1_000_000);
            assert!(total_memory_bytes().unwrap() > resident_bytes().unwrap());
        }
    }
}
