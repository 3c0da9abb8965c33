//! Light sources: what they emit and how they fall off. Angles of narrow cones are kept
//! as 1 − cos θ (see [`crate::sampling::one_minus_cos`]), never as cos θ, so a 0.01° spot
//! is as precise as a 30° one.

/// glTF's spot falloff: smooth (squared linear ramp) between the cone angles, a hard
/// edge when they coincide. Every angle is given as 1 − cos θ: `omc` of the direction,
/// `omc_outer` and `omc_inner` of the cone's edges (outer ≥ inner). (The glTF sample code
/// clamps the ramp width to 0.001, which would dim a 1° spotlight a thousandfold.)
#[inline]
pub fn spot_falloff(omc: f32, omc_outer: f32, omc_inner: f32) -> f32 {
    let width = omc_outer - omc_inner;
    if width <= 0.0 {
        return if omc <= omc_outer { 1.0 } else { 0.0 };
    }
    let t = ((omc_outer - omc) / width).clamp(0.0, 1.0);
    t * t
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::one_minus_cos;

    #[test]
    fn spot_falloff_is_bounded_and_follows_the_cosine_ramp() {
        // Cone edges at cos = 0.9 and 0.95: halfway in cosine gives (1/2)² = 1/4.
        let (co, ci) = (0.1f32, 0.05f32);
        assert_eq!(spot_falloff(0.0, co, ci), 1.0);
        assert_eq!(spot_falloff(0.2, co, ci), 0.0);
        assert!((spot_falloff(0.075, co, ci) - 0.25).abs() < 1e-4);
        assert_eq!(spot_falloff(0.5, 0.5, 0.5), 1.0);
        assert_eq!(spot_falloff(0.6, 0.5, 0.5), 0.0);
        // A half-degree spotlight keeps its full intensity on its axis, and a 0.01° ramp
        // is resolved: halfway between 0.005° and 0.01° (in 1 − cos) gives 1/4.
        let (co, ci) = (
            one_minus_cos(0.5f32.to_radians()),
            one_minus_cos(0.4f32.to_radians()),
        );
        assert_eq!(spot_falloff(0.0, co, ci), 1.0);
        let (co, ci) = (
            one_minus_cos(0.01f32.to_radians()),
            one_minus_cos(0.005f32.to_radians()),
        );
        assert!((spot_falloff(0.5 * (co + ci), co, ci) - 0.25).abs() < 1e-3);
    }
}
