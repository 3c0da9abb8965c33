//! Random streams and warps.
//!
//! Every stream is keyed by `(seed, pass, index, purpose)` and hashed into a PCG32 state,
//! so a photon's or a pixel's random numbers do not depend on which thread runs it: the
//! same settings give the same image on 1 thread or 16.

use glam::Vec3;
use std::f32::consts::PI;

/// What a stream is for; keeps the photon and camera streams of one index apart.
#[derive(Clone, Copy, Debug)]
#[repr(u64)]
pub enum Purpose {
    Photon = 1,
    Camera = 2,
    /// A pixel's sequence scrambles (one pair per pixel: odd passes, even passes).
    Gather = 3,
    /// The rays that find what the camera sees, for learned emission.
    Visibility = 4,
}

/// PCG32 (O'Neill 2014, XSH-RR).
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

/// SplitMix64 finaliser: a good 64-bit mixer.
pub(crate) fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Rng {
    pub fn stream(seed: u64, pass: u64, index: u64, purpose: Purpose) -> Self {
        let a = mix(seed ^ mix(pass ^ mix(index ^ mix(purpose as u64))));
        let b = mix(a ^ 0xDA94_2042_E4DD_58B5);
        let mut rng = Self {
            state: 0,
            inc: (b << 1) | 1,
        };
        rng.next_u32();
        rng.state = rng.state.wrapping_add(a);
        rng.next_u32();
        rng
    }

    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in [0, 1): 24 random bits, so 1 − 2⁻²⁴ is the largest value.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    #[inline]
    pub fn next_2d(&mut self) -> [f32; 2] {
        [self.next_f32(), self.next_f32()]
    }
}

/// Point `i` of the first two dimensions of the Sobol sequence, a (0,2)-sequence, each
/// dimension XOR-scrambled by its `scramble` word (Kollig & Keller 2002, "Efficient
/// multidimensional sampling"). Every run of 2ᵐ consecutive points starting at a multiple
/// of 2ᵐ has exactly one point in each of the 2ᵐ elementary intervals of area 2⁻ᵐ, and the
/// scramble keeps that (it permutes the intervals), so the points of successive passes
/// fill the square evenly where independent random points would clump. A pixel's
/// final-gather directions use it: their error falls faster than 1/√n over passes.
#[inline]
pub fn sobol02(i: u32, scramble: [u32; 2]) -> [f32; 2] {
    let x = i.reverse_bits() ^ scramble[0];
    let (mut y, mut v, mut i) = (scramble[1], 1u32 << 31, i);
    while i != 0 {
        if i & 1 != 0 {
            y ^= v;
        }
        i >>= 1;
        v ^= v >> 1;
    }
    let f = |b: u32| (b >> 8) as f32 * (1.0 / (1u32 << 24) as f32);
    [f(x), f(y)]
}

/// Point `i` of Roberts' R2 sequence (the 2-D Kronecker sequence of the plastic number)
/// rotated by `offset` (Cranley–Patterson): evenly spread for any run of consecutive
/// points, and built unlike [`sobol02`], so a pixel can use both side by side without the
/// two sharing structure.
#[inline]
pub fn r2(i: u32, offset: [f32; 2]) -> [f32; 2] {
    const A: [f64; 2] = [0.754_877_666_246_692_8, 0.569_840_290_998_053_3];
    [kronecker(i, A[0], offset[0]), kronecker(i, A[1], offset[1])]
}

/// Point `i` of the 1-D Kronecker sequence of irrational `step` rotated by `offset`
/// (Cranley–Patterson): frac(offset + i·step), summed in f64 so that late points keep
/// their spacing, and kept in [0, 1) after rounding to f32. The coordinate every rotated
/// Kronecker sequence here ([`r2`], the pixel's and the wavelength's) is built from.
#[inline]
pub fn kronecker(i: u32, step: f64, offset: f32) -> f32 {
    let x = offset as f64 + i as f64 * step;
    // x.fract() without its libm `trunc` call (x86-64's baseline has no rounding
    // instruction; this was 1 % of a prism render): x − ⌊x⌋ for 0 ≤ x < 2³², where the
    // cast truncates exactly, so the same bits. To i64, not u64: x86-64 converts a double
    // to a signed integer in one instruction, to an unsigned one in a branchy sequence.
    let v = if (0.0..4_294_967_296.0).contains(&x) {
        (x - (x as i64) as f64) as f32
    } else {
        x.fract() as f32
    };
    if v < 1.0 { v } else { 0.0 }
}

/// An orthonormal basis around unit `n` (Duff et al. 2017), returned as (t, b).
#[inline]
pub fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// Cosine-weighted direction about unit `n`; pdf = cos θ / π.
#[inline]
pub fn cosine_hemisphere(n: Vec3, u: [f32; 2]) -> Vec3 {
    let r = u[0].sqrt();
    let phi = 2.0 * PI * u[1];
    let (t, b) = basis(n);
    let z = (1.0 - u[0]).max(0.0).sqrt();
    (t * (r * phi.cos()) + b * (r * phi.sin()) + n * z).normalize()
}

/// Uniform direction on the sphere; pdf = 1 / 4π.
#[inline]
pub fn uniform_sphere(u: [f32; 2]) -> Vec3 {
    let z = 1.0 - 2.0 * u[0];
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u[1];
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// 1 − cos θ for an angle in radians, as 2 sin²(θ/2): exact to f32 precision even for
/// tiny angles, where `1.0 - θ.cos()` in f32 keeps only a few significant bits.
#[inline]
pub fn one_minus_cos(theta: f32) -> f32 {
    let s = (0.5 * theta as f64).sin();
    (2.0 * s * s) as f32
}

/// 1 − cos of the angle between unit vectors `a` and `b`, as |a − b|²/2: precise for
/// nearly parallel vectors (a dot product would round to 1).
#[inline]
pub fn one_minus_cos_between(a: Vec3, b: Vec3) -> f32 {
    0.5 * (a - b).length_squared()
}

/// Uniform direction in the cone about unit `axis` whose half-angle θmax has
/// 1 − cos θmax = `one_minus_cos_max` (see [`one_minus_cos`]); pdf = 1 / (2π (1 − cos θmax)).
///
/// 1 − cos θ is sampled directly (and sin θ = √((1 − cos θ)(1 + cos θ)) from it), so the
/// precision does not depend on the cone's width: a 0.01° cone is as smooth as a 30° one.
#[inline]
pub fn uniform_cone(axis: Vec3, one_minus_cos_max: f32, u: [f32; 2]) -> Vec3 {
    let omc = (u[0] * one_minus_cos_max).clamp(0.0, 2.0);
    let sin_t = (omc * (2.0 - omc)).max(0.0).sqrt();
    let cos_t = 1.0 - omc;
    let phi = 2.0 * PI * u[1];
    let (t, b) = basis(axis);
    (t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + axis * cos_t).normalize()
}

/// Uniform barycentrics (b1, b2) on a triangle (square-root warp).
#[inline]
pub fn uniform_triangle(u: [f32; 2]) -> (f32, f32) {
    let su = u[0].sqrt();
    (1.0 - su, u[1] * su)
}

/// Index `i` with probability `weights[i] / Σ weights` from a CDF built by [`cdf`].
pub fn sample_cdf(cdf: &[f32], u: f32) -> usize {
    let total = *cdf.last().unwrap_or(&0.0);
    let target = u * total;
    cdf.partition_point(|&c| c <= target)
        .min(cdf.len().saturating_sub(1))
}

/// Running sums of `weights` (negative or NaN weights count as 0).
pub fn cdf(weights: &[f32]) -> Vec<f32> {
    let mut acc = 0.0f32;
    weights
        .iter()
        .map(|&w| {
            acc += if w.is_finite() && w > 0.0 { w } else { 0.0 };
            acc
        })
        .collect()
}

pub mod chi2;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kronecker_is_frac_of_offset_plus_i_step_to_the_bit() {
        // The cast-based fractional part against f64::fract at the sequence's steps, the
        // ends of the index range, offsets at 0 and just below 1, and a step near 1 whose
        // late points leave the cast's range.
        let reference = |i: u32, step: f64, offset: f32| {
            let v = ((offset as f64 + i as f64 * step).fract()) as f32;
            if v < 1.0 { v } else { 0.0 }
        };
        let mut rng = Rng::stream(11, 0, 0, Purpose::Camera);
        let steps = [
            0.754_877_666_246_692_7,
            0.569_840_290_998_053_3,
            std::f64::consts::SQRT_2 - 1.0,
            0.999_999_9,
        ];
        let ends = [0, 1, 2, 1 << 31, u32::MAX - 1, u32::MAX];
        for &step in &steps {
            for k in 0..20_000u32 {
                let i = if (k as usize) < ends.len() {
                    ends[k as usize]
                } else {
                    rng.next_u32()
                };
                let offset = match k % 3 {
                    0 => 0.0,
                    1 => 1.0 - f32::EPSILON / 2.0,
                    _ => rng.next_f32(),
                };
                let (got, want) = (kronecker(i, step, offset), reference(i, step, offset));
                assert_eq!(
                    got.to_bits(),
                    want.to_bits(),
                    "i {i}, step {step}, offset {offset}"
                );
                assert!((0.0..1.0).contains(&got));
            }
        }
    }

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a: Vec<u32> = {
            let mut r = Rng::stream(7, 1, 42, Purpose::Photon);
            (0..8).map(|_| r.next_u32()).collect()
        };
        let b: Vec<u32> = {
            let mut r = Rng::stream(7, 1, 42, Purpose::Photon);
            (0..8).map(|_| r.next_u32()).collect()
        };
        let c: Vec<u32> = {
            let mut r = Rng::stream(7, 1, 43, Purpose::Photon);
            (0..8).map(|_| r.next_u32()).collect()
        };
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn uniform_floats_stay_below_one_and_average_half() {
        let mut r = Rng::stream(1, 2, 3, Purpose::Camera);
        let mut sum = 0.0f64;
        for _ in 0..100_000 {
            let v = r.next_f32();
            assert!((0.0..1.0).contains(&v));
            sum += v as f64;
        }
        assert!((sum / 100_000.0 - 0.5).abs() < 0.005);
    }

    #[test]
    fn warps_survive_extreme_inputs() {
        let n = Vec3::new(0.0, 0.0, -1.0);
        for u in [0.0, 0.5, 1.0 - f32::EPSILON / 2.0, 1.0] {
            for v in [0.0, 0.5, 0.99999994] {
                let d = cosine_hemisphere(n, [u, v]);
                assert!(d.is_finite() && (d.length() - 1.0).abs() < 1e-4 && d.dot(n) >= -1e-6);
                let s = uniform_sphere([u, v]);
                assert!(s.is_finite());
                let c = uniform_cone(n, 0.01, [u, v]);
                assert!(c.is_finite() && c.dot(n) >= 0.99 - 1e-4);
            }
        }
    }

    #[test]
    fn cdf_sampling_respects_weights() {
        let c = cdf(&[1.0, 0.0, 3.0, f32::NAN]);
        assert_eq!(sample_cdf(&c, 0.0), 0);
        assert_eq!(sample_cdf(&c, 0.2), 0);
        assert_eq!(sample_cdf(&c, 0.3), 2);
        assert_eq!(sample_cdf(&c, 0.999), 2);
    }

    #[test]
    fn sobol02_blocks_are_0_m_2_nets_under_any_scramble() {
        // Every aligned block of 2^m points has one point in each elementary interval of
        // every shape 2^-a × 2^-(m-a): the property final gathering relies on.
        let mut rng = Rng::stream(5, 0, 0, Purpose::Camera);
        for m in [2u32, 4, 6, 8] {
            for _ in 0..4 {
                let scramble = [rng.next_u32(), rng.next_u32()];
                let start = (rng.next_u32() % 64) << m;
                for a in 0..=m {
                    let mut seen = vec![false; 1 << m];
                    for i in start..start + (1 << m) {
                        let [x, y] = sobol02(i, scramble);
                        assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
                        let cx = (x * (1u32 << a) as f32) as usize;
                        let cy = (y * (1u32 << (m - a)) as f32) as usize;
                        let cell = cx << (m - a) | cy;
                        assert!(!seen[cell], "m {m}, a {a}, block at {start}: two in {cell}");
                        seen[cell] = true;
                    }
                }
            }
        }
        // Distinct scrambles give distinct points (pixels do not share directions).
        assert_ne!(
            sobol02(3, [1 << 30, 2 << 28]),
            sobol02(3, [7 << 27, 9 << 26])
        );
    }
}
