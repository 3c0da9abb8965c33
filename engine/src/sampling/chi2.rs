//! One chi-square goodness-of-fit helper for every sampling routine (after pbrt-v4's
//! `bsdfs_test.cpp` and Mitsuba 3's `chi2.py`): histogram samples over (cos θ, φ) cells
//! about an axis, compare with the integrated pdf, pool cells expecting fewer than 5.

use glam::Vec3;
use std::f64::consts::PI;

use super::basis;

/// p-value of a chi-square statistic with `dof` degrees of freedom (regularised upper
/// incomplete gamma function, series/continued fraction from Numerical Recipes).
pub fn chi2_p_value(stat: f64, dof: usize) -> f64 {
    let a = dof as f64 / 2.0;
    let x = stat / 2.0;
    if x <= 0.0 {
        return 1.0;
    }
    let ln_gamma_a = ln_gamma(a);
    if x < a + 1.0 {
        let mut sum = 1.0 / a;
        let mut term = sum;
        let mut ap = a;
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        1.0 - sum * (-x + a * x.ln() - ln_gamma_a).exp()
    } else {
        let mut b = x + 1.0 - a;
        let mut c = 1e300;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < 1e-300 {
                d = 1e-300;
            }
            c = b + an / c;
            if c.abs() < 1e-300 {
                c = 1e-300;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (-x + a * x.ln() - ln_gamma_a).exp() * h
    }
}

fn ln_gamma(x: f64) -> f64 {
    // Lanczos approximation (g = 7, n = 9).
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    let x = x - 1.0;
    let mut a = G[0];
    let t = x + 7.5;
    for (i, g) in G.iter().enumerate().skip(1) {
        a += g / (x + i as f64);
    }
    0.5 * (2.0 * PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Chi-square test of a direction sampler about `axis` against `pdf` (per steradian).
/// Returns the p-value; a correct sampler gives p well above 0.01 for most seeds.
pub fn test_directions(
    axis: Vec3,
    samples: usize,
    mut sample: impl FnMut(usize) -> Vec3,
    pdf: impl Fn(Vec3) -> f64,
) -> f64 {
    const THETA: usize = 40;
    const PHI: usize = 80;
    let (t, b) = basis(axis);
    let cell = |d: Vec3| -> usize {
        let z = d.dot(axis).clamp(-1.0, 1.0) as f64;
        let phi = (d.dot(b) as f64)
            .atan2(d.dot(t) as f64)
            .rem_euclid(2.0 * PI);
        let i = (((1.0 - z) / 2.0 * THETA as f64) as usize).min(THETA - 1);
        let j = ((phi / (2.0 * PI) * PHI as f64) as usize).min(PHI - 1);
        i * PHI + j
    };
    let mut observed = vec![0f64; THETA * PHI];
    for s in 0..samples {
        let d = sample(s);
        observed[cell(d)] += 1.0;
    }
    // Expected counts: integrate the pdf over each cell with a 4×4 midpoint rule.
    let mut expected = vec![0f64; THETA * PHI];
    for (i, row) in expected.chunks_mut(PHI).enumerate() {
        for (j, e) in row.iter_mut().enumerate() {
            let mut acc = 0.0;
            for a in 0..4 {
                for c in 0..4 {
                    let z = 1.0 - 2.0 * (i as f64 + (a as f64 + 0.5) / 4.0) / THETA as f64;
                    let phi = 2.0 * PI * (j as f64 + (c as f64 + 0.5) / 4.0) / PHI as f64;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    let d =
                        t * (r * phi.cos()) as f32 + b * (r * phi.sin()) as f32 + axis * z as f32;
                    acc += pdf(d);
                }
            }
            let area = (2.0 / THETA as f64) * (2.0 * PI / PHI as f64);
            *e = acc / 16.0 * area * samples as f64;
        }
    }
    // Pool cells expecting fewer than 5 samples; samples in zero-pdf cells fail outright.
    let mut stat = 0.0;
    let mut dof = 0usize;
    let (mut pool_o, mut pool_e) = (0.0, 0.0);
    for (o, e) in observed.iter().zip(&expected) {
        if *e == 0.0 {
            if *o > samples as f64 * 1e-5 {
                return 0.0;
            }
            continue;
        }
        if *e < 5.0 {
            pool_o += o;
            pool_e += e;
            if pool_e >= 5.0 {
                stat += (pool_o - pool_e).powi(2) / pool_e;
                dof += 1;
                pool_o = 0.0;
                pool_e = 0.0;
            }
        } else {
            stat += (o - e).powi(2) / e;
            dof += 1;
        }
    }
    if pool_e > 0.0 {
        stat += (pool_o - pool_e).powi(2) / pool_e;
        dof += 1;
    }
    chi2_p_value(stat, dof.saturating_sub(1).max(1))
}

/// Chi-square test of a sampler that should be uniform in the cone about `axis` with
/// 1 − cos θmax = `omc_max`: samples are binned in the cone's own coordinates, u = (1 − cos θ)
/// / (1 − cos θmax) and φ, where a uniform cone is uniform (so a 0.01° cone is tested as
/// finely as a hemisphere). 1 − cos θ is computed from the direction's component across
/// the axis in f64, so the test sees the sampler's precision, not its own. A sample outside
/// the cone (u > 1.01: an f32 direction 0.01° off an oblique axis is only that precise)
/// fails the test. Returns the p-value.
pub fn test_cone(
    axis: Vec3,
    omc_max: f64,
    samples: usize,
    mut sample: impl FnMut(usize) -> Vec3,
) -> f64 {
    const U: usize = 50;
    const PHI: usize = 40;
    let (t, b) = basis(axis);
    let (t, b, a) = (t.as_dvec3(), b.as_dvec3(), axis.as_dvec3());
    let mut observed = vec![0f64; U * PHI];
    for s in 0..samples {
        let d = sample(s).as_dvec3();
        let (x, y, z) = (d.dot(t), d.dot(b), d.dot(a));
        let len = (x * x + y * y + z * z).sqrt();
        let s2 = (x * x + y * y) / (len * len);
        let omc = if z >= 0.0 {
            s2 / (1.0 + (1.0 - s2).max(0.0).sqrt())
        } else {
            2.0
        };
        let u = omc / omc_max;
        if !(u <= 1.01) {
            return 0.0;
        }
        let phi = y.atan2(x).rem_euclid(2.0 * PI);
        let i = ((u * U as f64) as usize).min(U - 1);
        let j = ((phi / (2.0 * PI) * PHI as f64) as usize).min(PHI - 1);
        observed[i * PHI + j] += 1.0;
    }
    let e = samples as f64 / (U * PHI) as f64;
    let stat: f64 = observed.iter().map(|o| (o - e).powi(2) / e).sum();
    chi2_p_value(stat, U * PHI - 1)
}

#[cfg(test)]
mod tests {
    use super::super::{
        Purpose, Rng, cosine_hemisphere, one_minus_cos, uniform_cone, uniform_sphere,
    };
    use super::*;

    #[test]
    fn p_values_are_right() {
        // Known values: χ²(3.84, 1) ≈ 0.05, χ²(18.31, 10) ≈ 0.05.
        assert!((chi2_p_value(3.841, 1) - 0.05).abs() < 1e-3);
        assert!((chi2_p_value(18.307, 10) - 0.05).abs() < 1e-3);
        assert!((chi2_p_value(124.342, 100) - 0.05).abs() < 1e-3);
    }

    #[test]
    fn cosine_hemisphere_passes_and_uniform_sphere_fails_its_pdf() {
        let n = Vec3::new(0.3, -0.5, 0.8).normalize();
        let mut rng = Rng::stream(1, 0, 0, Purpose::Photon);
        let p = test_directions(
            n,
            1_000_000,
            |_| cosine_hemisphere(n, rng.next_2d()),
            |d| (d.dot(n).max(0.0) as f64) / PI,
        );
        assert!(p > 1e-3, "cosine p = {p}");
        // The helper must be able to fail: uniform hemisphere against the cosine pdf.
        let mut rng = Rng::stream(2, 0, 0, Purpose::Photon);
        let p_bad = test_directions(
            n,
            1_000_000,
            |_| {
                let d = uniform_sphere(rng.next_2d());
                if d.dot(n) < 0.0 { -d } else { d }
            },
            |d| (d.dot(n).max(0.0) as f64) / PI,
        );
        assert!(p_bad < 1e-6, "wrong sampler p = {p_bad}");
    }

    #[test]
    fn sphere_and_cone_samplers_pass() {
        let axis = Vec3::Y;
        let mut rng = Rng::stream(3, 0, 0, Purpose::Photon);
        let p = test_directions(
            axis,
            500_000,
            |_| uniform_sphere(rng.next_2d()),
            |_| 1.0 / (4.0 * PI),
        );
        assert!(p > 1e-3, "sphere p = {p}");
        let cos_max = 0.5f32;
        let mut rng = Rng::stream(4, 0, 0, Purpose::Photon);
        let p = test_directions(
            axis,
            500_000,
            |_| uniform_cone(axis, 1.0 - cos_max, rng.next_2d()),
            |d| {
                if d.dot(axis) >= cos_max {
                    1.0 / (2.0 * PI * (1.0 - cos_max as f64))
                } else {
                    0.0
                }
            },
        );
        assert!(p > 1e-3, "cone p = {p}");
    }

    #[test]
    fn cone_sampler_is_uniform_at_every_width_and_keeps_its_solid_angle() {
        // Issue #8: cos θ = 1 − u(1 − cos θmax) in f32 gave a 0.15° cone only 58 rings.
        let axis = Vec3::new(0.2, -0.9, 0.4).normalize();
        for (k, degrees) in [0.01f32, 0.15, 30.0].into_iter().enumerate() {
            let omc = one_minus_cos(degrees.to_radians());
            let mut rng = Rng::stream(5, k as u64, 0, Purpose::Photon);
            let p = test_cone(axis, omc as f64, 400_000, |_| {
                uniform_cone(axis, omc, rng.next_2d())
            });
            assert!(p > 1e-3, "{degrees}° cone: p = {p}");
            // Solid angle 2π(1 − cos θmax) from the sampler: the mean of 1 − cos θ over a
            // regular grid of u is half its maximum (f64 from the direction's transverse part).
            let m = 100_000;
            let a = axis.as_dvec3().normalize();
            let mean: f64 = (0..m)
                .map(|i| {
                    let v = (i as f64 * 0.618_033_988_75).fract() as f32;
                    let d = uniform_cone(axis, omc, [(i as f32 + 0.5) / m as f32, v]);
                    let d = d.as_dvec3().normalize();
                    let s2 = d.cross(a).length_squared();
                    s2 / (1.0 + (1.0 - s2).sqrt())
                })
                .sum::<f64>()
                / m as f64;
            let exact = 0.5 * (0.5 * (degrees as f64).to_radians()).sin().powi(2) * 2.0;
            assert!(
                (mean / exact - 1.0).abs() < 1e-4,
                "{degrees}°: sampled mean 1 − cos θ {mean:e}, exact {exact:e}"
            );
        }
    }

    #[test]
    fn cone_test_rejects_the_f32_cosine_sampler() {
        // The old sampler (cos θ in f32) must fail the cone test at 0.15°: it can fail.
        let axis = Vec3::Z;
        let cos_max = 0.15f32.to_radians().cos();
        let mut rng = Rng::stream(6, 0, 0, Purpose::Photon);
        let p = test_cone(axis, 1.0 - (0.15f64).to_radians().cos(), 400_000, |_| {
            let [u, v] = rng.next_2d();
            let cos_t = 1.0 - u * (1.0 - cos_max);
            let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
            let phi = 2.0 * std::f32::consts::PI * v;
            Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t).normalize()
        });
        assert!(p < 1e-6, "f32 cosine sampler p = {p}");
    }
}
