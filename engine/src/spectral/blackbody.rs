//! Planck's law, evaluated in f64 without overflow.

/// Second radiation constant c₂ = hc/k in nm·K.
const C2_NM_K: f64 = 1.438_776_877e7;

/// Spectral radiance of a blackbody at `lambda_nm` and `kelvin`, up to a constant factor
/// (the factor 2hc² is dropped: emitters are always normalised, see [`super::Spectrum`]).
///
/// Written as `exp(-x) / (λ⁵ · (1 − exp(-x)))` with `-expm1(-x)` so that large `x = c₂/λT`
/// underflows gracefully to 0 instead of overflowing `exp(x)` (an f32 `exp` overflows near
/// x = 88.7, reached at 360 nm below 450 K). Returns 0 for non-positive or non-finite input.
pub fn planck_relative(lambda_nm: f64, kelvin: f64) -> f64 {
    if !(kelvin > 0.0 && lambda_nm > 0.0 && kelvin.is_finite() && lambda_nm.is_finite()) {
        return 0.0;
    }
    let x = C2_NM_K / (lambda_nm * kelvin);
    // λ in µm keeps λ⁵ near 1 for visible light.
    let l_um = lambda_nm * 1e-3;
    let v = (-x).exp() / (l_um.powi(5) * -(-x).exp_m1());
    if v.is_finite() { v } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wien_peak() {
        // Wien's displacement law: λ_max = 2.897771955e6 nm·K / T.
        for t in [3000.0, 5000.0, 6500.0] {
            let expected = 2.897_771_955e6 / t;
            let mut best = (0.0, 0.0);
            let mut l = expected - 50.0;
            while l < expected + 50.0 {
                let v = planck_relative(l, t);
                if v > best.1 {
                    best = (l, v);
                }
                l += 0.01;
            }
            assert!(
                (best.0 - expected).abs() < 0.05,
                "T={t}: {best:?} vs {expected}"
            );
        }
    }

    #[test]
    fn never_overflows_or_goes_negative() {
        for t in [
            f64::NAN,
            -1.0,
            0.0,
            1.0,
            100.0,
            800.0,
            6500.0,
            1e5,
            1e9,
            f64::INFINITY,
        ] {
            for l in [360.0, 555.0, 830.0] {
                let v = planck_relative(l, t);
                assert!(v.is_finite() && v >= 0.0, "T={t} λ={l}: {v}");
            }
        }
        assert_eq!(planck_relative(360.0, 1.0), 0.0);
    }
}
