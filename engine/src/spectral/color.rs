//! Colorimetry: XYZ ↔ linear sRGB (D65) and the sRGB transfer curve.

/// XYZ → linear sRGB (IEC 61966-2-1, D65 white).
pub const XYZ_TO_SRGB: [[f64; 3]; 3] = [
    [3.2404542, -1.5371385, -0.4985314],
    [-0.9692660, 1.8760108, 0.0415560],
    [0.0556434, -0.2040259, 1.0572252],
];

/// Linear sRGB → XYZ (the inverse of [`XYZ_TO_SRGB`]).
pub const SRGB_TO_XYZ: [[f64; 3]; 3] = [
    [0.4124564, 0.3575761, 0.1804375],
    [0.2126729, 0.7151522, 0.0721750],
    [0.0193339, 0.1191920, 0.9503041],
];

pub fn mul3(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

pub fn xyz_to_linear_srgb(xyz: [f64; 3]) -> [f64; 3] {
    mul3(&XYZ_TO_SRGB, xyz)
}

pub fn linear_srgb_to_xyz(rgb: [f64; 3]) -> [f64; 3] {
    mul3(&SRGB_TO_XYZ, rgb)
}

/// Relative luminance Y of a linear sRGB colour.
pub fn luminance(rgb: [f64; 3]) -> f64 {
    SRGB_TO_XYZ[1][0] * rgb[0] + SRGB_TO_XYZ[1][1] * rgb[1] + SRGB_TO_XYZ[1][2] * rgb[2]
}

/// The sRGB opto-electronic transfer function on one linear channel (clamped to [0, 1]).
pub fn srgb_encode(v: f32) -> f32 {
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    if v <= 0.0031308 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// One linear channel as an 8-bit sRGB value (clamped, rounded): the one encoder of
/// PNGs, the viewer's texture, the report's plots and the probe's swatches.
///
/// Exactly [`srgb8_direct`], from a table instead of a `powf` per channel (the
/// `display_encode` bench's 512² image in 2.4 ms instead of 7.7, on the viewer's UI
/// thread): the value's top 16
/// bits (exponent and 7 mantissa bits) pick a bucket, which holds at most one of the 255
/// points where the code steps up, so the code is the bucket's first plus whether the
/// value lies past that point.
#[inline]
pub fn srgb8(v: f32) -> u8 {
    let bits = v.to_bits();
    if bits >= ONE_BITS {
        // From 1 up to the largest finite value: 255. +∞ and NaN lie above, and every
        // negative (the sign bit) far above: 0, as the direct encoder gives them.
        return if bits < INFINITY_BITS { 255 } else { 0 };
    }
    if bits < LOW_BITS {
        return 0;
    }
    let t = srgb8_table();
    let b = ((bits - LOW_BITS) >> BUCKET_SHIFT) as usize;
    t.base[b] + u8::from(v >= t.step[b])
}

/// [`srgb8`] by the transfer curve itself.
fn srgb8_direct(v: f32) -> u8 {
    (srgb_encode(v) * 255.0 + 0.5) as u8
}

/// Mantissa bits dropped from a bucket's index (23 − 7).
const BUCKET_SHIFT: u32 = 16;
/// 1.0's bits: every value from there up (and every non-finite or negative one) is
/// answered without the table.
const ONE_BITS: u32 = 0x3F80_0000;
/// +∞'s bits.
const INFINITY_BITS: u32 = 0x7F80_0000;
/// 2⁻¹⁴'s bits: below it every value encodes as 0 (the first step, at ½ / 255 / 12.92 ≈
/// 1.5 · 10⁻⁴, lies above 2⁻¹³).
const LOW_BITS: u32 = 0x3880_0000;
const BUCKETS: usize = ((ONE_BITS - LOW_BITS) >> BUCKET_SHIFT) as usize;

struct Srgb8Table {
    /// The code at each bucket's lowest value.
    base: Vec<u8>,
    /// The value in the bucket from which the code is one more (∞ when it does not step).
    step: Vec<f32>,
}

fn srgb8_table() -> &'static Srgb8Table {
    static TABLE: std::sync::OnceLock<Srgb8Table> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        // The smallest value of each code from 1 to 255: bisection on the bits, as the
        // encoder is non-decreasing over the positive floats (tested over all of [0, 1]).
        let first_of = |code: u8| {
            let (mut lo, mut hi) = (0u32, ONE_BITS);
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                if srgb8_direct(f32::from_bits(mid)) >= code {
                    hi = mid;
                } else {
                    lo = mid + 1;
                }
            }
            lo
        };
        let firsts: Vec<u32> = (1..=255u8).map(first_of).collect();
        assert!(firsts[0] >= LOW_BITS, "the first step lies below the table");
        let mut base = Vec::with_capacity(BUCKETS);
        let mut step = Vec::with_capacity(BUCKETS);
        // The steps are in increasing order: walk them alongside the buckets (a step at a
        // bucket's lowest value is in its base already).
        let mut next = firsts.iter().copied().peekable();
        for b in 0..BUCKETS as u32 {
            let lo = LOW_BITS + (b << BUCKET_SHIFT);
            let hi = lo + (1 << BUCKET_SHIFT); // exclusive
            while next.next_if(|&f| f <= lo).is_some() {}
            let inside = next.next_if(|&f| f < hi);
            assert!(
                next.peek().is_none_or(|&f| f >= hi),
                "two sRGB steps in one bucket"
            );
            base.push(srgb8_direct(f32::from_bits(lo)));
            step.push(inside.map_or(f32::INFINITY, f32::from_bits));
        }
        Srgb8Table { base, step }
    })
}

/// Inverse of [`srgb_encode`].
pub fn srgb_decode(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Inverse of a 3×3 matrix, or `None` when it is (numerically) singular.
pub fn invert3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let [a, b, c] = m[0];
    let [d, e, f] = m[1];
    let [g, h, i] = m[2];
    let co = [e * i - f * h, f * g - d * i, d * h - e * g];
    let det = a * co[0] + b * co[1] + c * co[2];
    let scale = m.iter().flatten().fold(0.0f64, |s, v| s.max(v.abs()));
    if !det.is_finite() || det.abs() <= 1e-12 * scale.powi(3) {
        return None;
    }
    let r = 1.0 / det;
    Some([
        [co[0] * r, (c * h - b * i) * r, (b * f - c * e) * r],
        [co[1] * r, (a * i - c * g) * r, (c * d - a * f) * r],
        [co[2] * r, (b * g - a * h) * r, (a * e - b * d) * r],
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrices_are_inverse() {
        let p = mul3(&XYZ_TO_SRGB, mul3(&SRGB_TO_XYZ, [0.3, 0.5, 0.9]));
        for (a, b) in p.iter().zip([0.3, 0.5, 0.9]) {
            assert!((a - b).abs() < 1e-6);
        }
        let inv = invert3(&SRGB_TO_XYZ).unwrap();
        for r in 0..3 {
            for c in 0..3 {
                assert!((inv[r][c] - XYZ_TO_SRGB[r][c]).abs() < 1e-5);
            }
        }
        assert!(invert3(&[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]).is_none());
    }

    #[test]
    fn srgb_curve_round_trips() {
        for i in 0..=100 {
            let v = i as f32 / 100.0;
            assert!((srgb_decode(srgb_encode(v)) - v).abs() < 1e-5);
        }
        assert_eq!(srgb_encode(f32::NAN), 0.0);
        assert!((srgb_encode(7.0) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn the_table_encoder_is_the_direct_one_on_every_float_from_0_to_1() {
        // Every f32 in [0, 1] (2³⁰ of them, split over the thread pool; a few seconds in a
        // release build), which also checks that the direct encoder never steps down
        // there, as the table's bisection assumes; then the ends: negatives, values above
        // 1, the infinities, NaNs, subnormals.
        use rayon::prelude::*;
        let bad = (0..=ONE_BITS >> 20)
            .into_par_iter()
            .map(|hi| {
                let mut prev = 0u8;
                let mut bad = 0u64;
                for lo in 0..1u32 << 20 {
                    let bits = (hi << 20) | lo;
                    if bits > ONE_BITS {
                        break;
                    }
                    let v = f32::from_bits(bits);
                    let direct = srgb8_direct(v);
                    bad += u64::from(srgb8(v) != direct || direct < prev);
                    prev = direct;
                }
                bad
            })
            .sum::<u64>();
        assert_eq!(
            bad, 0,
            "values where the encoders differ or the code steps down"
        );
        for v in [
            -0.0,
            -1e-30,
            -0.5,
            -1.0,
            1.0,
            1.0000001,
            7.0,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            f32::from_bits(1),
            f32::MIN_POSITIVE,
        ] {
            assert_eq!(srgb8(v), srgb8_direct(v), "{v:e}");
        }
    }
}

/// CIE xy chromaticity of D65.
pub const D65_XY: [f64; 2] = [0.3127, 0.3290];

/// Dominant wavelength (nm) of a colour seen against D65: the spectral colour on the line
/// from the white point through the colour. Colours in the purple region get the
/// complementary wavelength, returned negative (CIE convention). `None` for black or
/// for a colour at the white point.
pub fn dominant_wavelength(xyz: [f64; 3]) -> Option<f64> {
    let sum = xyz[0] + xyz[1] + xyz[2];
    if !(sum > 0.0 && sum.is_finite()) {
        return None;
    }
    let (x, y) = (xyz[0] / sum, xyz[1] / sum);
    let (dx, dy) = (x - D65_XY[0], y - D65_XY[1]);
    if dx.hypot(dy) < 1e-4 {
        return None;
    }
    let theta = dy.atan2(dx);
    let c = super::tables::cmf();
    let best = |target: f64| -> (f64, f64) {
        let mut best = (f64::INFINITY, 0.0);
        // 0.1 nm steps: near 490 nm the locus turns by ~4° per nm as seen from white.
        for i in 0..=3200 {
            let l = 380.0 + i as f64 * 0.1;
            let (lx, ly, lz) = (c.x.eval(l), c.y.eval(l), c.z.eval(l));
            let s = lx + ly + lz;
            let a = (ly / s - D65_XY[1]).atan2(lx / s - D65_XY[0]);
            let d = (a - target + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
                - std::f64::consts::PI;
            if d.abs() < best.0 {
                best = (d.abs(), l);
            }
        }
        best
    };
    let (d, l) = best(theta);
    if d < 0.5f64.to_radians() {
        Some(l)
    } else {
        let (_, l) = best(theta + std::f64::consts::PI);
        Some(-l)
    }
}

#[cfg(test)]
mod dominant_tests {
    use super::*;

    #[test]
    fn dominant_wavelength_of_spectral_colours_and_purples() {
        let c = crate::spectral::tables::cmf();
        for l in [450.0, 487.0, 490.0, 500.0, 550.0, 600.0, 650.0] {
            let xyz = [c.x.eval(l), c.y.eval(l), c.z.eval(l)];
            let d = dominant_wavelength(xyz).unwrap();
            assert!((d - l).abs() <= 1.0, "{l}: {d}");
        }
        // Magenta (red + blue) has a complementary (negative) dominant wavelength.
        let magenta = linear_srgb_to_xyz([1.0, 0.0, 1.0]);
        assert!(dominant_wavelength(magenta).unwrap() < 0.0);
        // An out-of-gamut cyan (a probe on the prism's rainbow) is ~487 nm, not a purple.
        let cyan = linear_srgb_to_xyz([-0.0244, 0.0423, 0.0618]);
        let d = dominant_wavelength(cyan).unwrap();
        assert!((d - 487.0).abs() < 2.0, "{d}");
        assert_eq!(dominant_wavelength([0.0; 3]), None);
        assert_eq!(
            dominant_wavelength(linear_srgb_to_xyz([1.0, 1.0, 1.0])),
            None
        );
    }
}
