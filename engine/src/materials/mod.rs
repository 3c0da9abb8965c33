//! Scattering at mirrors and glass: Fresnel reflectance of a dielectric, the refraction
//! direction, mirror reflection, and (in [`microfacet`]) their rough GGX versions; one
//! bounce routine per kind shared by the photon tracer and the gather. (Lambertian
//! reflection is a cosine-weighted direction and a reflectance; it lives in the tracers.)

pub mod microfacet;

use glam::Vec3;

use crate::spectral::spd;

/// Unpolarised Fresnel reflectance for light arriving with `cos_i` = cos θ (≥ 0) from a
/// medium of index `eta_i` onto one of index `eta_t`. Returns 1 under total internal
/// reflection; always in [0, 1].
pub fn fresnel_dielectric(cos_i: f32, eta_i: f32, eta_t: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let eta = eta_i / eta_t;
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (eta_i * cos_i - eta_t * cos_t) / (eta_i * cos_i + eta_t * cos_t);
    let rp = (eta_t * cos_i - eta_i * cos_t) / (eta_t * cos_i + eta_i * cos_t);
    let f = 0.5 * (rs * rs + rp * rp);
    if f.is_finite() {
        f.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// Mirror reflection of incoming direction `d` about unit normal `n`.
#[inline]
pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - 2.0 * d.dot(n) * n
}

/// Refraction of incoming direction `d` (unit) through a surface with unit normal `n`
/// facing the incoming side (d·n ≤ 0), relative index `eta = eta_i / eta_t`. `None` exactly
/// when sin²θt ≥ 1 (total internal reflection).
#[inline]
pub fn refract(d: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = (-d.dot(n)).clamp(0.0, 1.0);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let t = eta * d + (eta * cos_i - cos_t) * n;
    let t = t.normalize_or_zero();
    if t == Vec3::ZERO { None } else { Some(t) }
}

/// What a smooth dielectric does to a ray: the side it arrives on decides the indices.
pub struct DielectricEvent {
    /// New direction.
    pub dir: Vec3,
    /// Whether it was transmitted (refracted).
    pub transmitted: bool,
    /// eta_i / eta_t of the crossing (1 for reflection).
    pub eta_ratio: f32,
}

/// Chooses reflection with probability F (Fresnel) or refraction, for a glass of index
/// `eta` with outward geometric normal `n` (air outside). `u` in [0, 1).
pub fn scatter_dielectric(d: Vec3, n: Vec3, eta: f32, u: f32) -> DielectricEvent {
    let entering = d.dot(n) < 0.0;
    let (eta_i, eta_t, nf) = if entering {
        (1.0, eta, n)
    } else {
        (eta, 1.0, -n)
    };
    let cos_i = -d.dot(nf);
    let f = fresnel_dielectric(cos_i, eta_i, eta_t);
    if u < f {
        return DielectricEvent {
            dir: reflect(d, nf),
            transmitted: false,
            eta_ratio: 1.0,
        };
    }
    match refract(d, nf, eta_i / eta_t) {
        Some(t) => DielectricEvent {
            dir: t,
            transmitted: true,
            eta_ratio: eta_i / eta_t,
        },
        None => DielectricEvent {
            dir: reflect(d, nf),
            transmitted: false,
            eta_ratio: 1.0,
        },
    }
}

/// [`scatter_dielectric`] with a shading normal `ns` (unit, turned to the side the ray
/// comes from): Fresnel and the new direction follow `ns`, so a smooth-shaded glass sphere
/// refracts as a sphere, not as facets. Where shading and geometric normals disagree (near
/// silhouettes) and the result would leave on the wrong side of the actual surface, the
/// geometric normal `n` (outward) is used instead, with the same random number.
pub fn scatter_dielectric_shaded(d: Vec3, n: Vec3, ns: Vec3, eta: f32, u: f32) -> DielectricEvent {
    let entering = d.dot(n) < 0.0;
    if !(-d.dot(ns) > 1e-6) {
        return scatter_dielectric(d, n, eta, u);
    }
    let ns_out = if entering { ns } else { -ns };
    let ev = scatter_dielectric(d, ns_out, eta, u);
    let nf = if entering { n } else { -n };
    let on_its_side = if ev.transmitted {
        ev.dir.dot(nf) < 0.0
    } else {
        ev.dir.dot(nf) > 0.0
    };
    if on_its_side {
        ev
    } else {
        scatter_dielectric(d, n, eta, u)
    }
}

/// Mirror reflection about the shading normal `ns`, or about the geometric `nf` (both
/// facing the incoming side) when the shading one would send the ray into the surface.
#[inline]
pub fn reflect_shaded(d: Vec3, nf: Vec3, ns: Vec3) -> Vec3 {
    let r = reflect(d, ns);
    if r.dot(nf) > 0.0 { r } else { reflect(d, nf) }
}

/// Beer–Lambert: `t` *= exp(−σ·distance) per bin.
#[inline]
pub fn absorb(t: &mut [f32], sigma: &[f32], distance: f32) {
    for (v, s) in t.iter_mut().zip(sigma) {
        *v *= (-s * distance).exp();
    }
}

/// What a metal does to a ray: a perfect mirror (`alpha` 0) or a GGX rough metal.
/// `d`: incoming direction; `nf`/`ns`: geometric and shading normals turned to its side.
/// Returns the new direction, the cosine Schlick's Fresnel is taken at, and the
/// microfacet weight (G2/G1; 1 for the mirror); None when the sample is lost below the
/// surface.
pub fn metal_bounce(
    alpha: f32,
    d: Vec3,
    nf: Vec3,
    ns: Vec3,
    u: [f32; 2],
) -> Option<(Vec3, f32, f32)> {
    if alpha <= 0.0 {
        let r = reflect_shaded(d, nf, ns);
        let h = (r - d).normalize_or_zero();
        return Some((r, (-d).dot(h).max(0.0), 1.0));
    }
    let ev = microfacet::sample_rough_metal(microfacet::Ggx { alpha }, d, ns, u)?;
    (ev.dir.dot(nf) > 0.0).then_some((ev.dir, ev.cos_m, ev.weight))
}

/// What a glass does to a ray: [`scatter_dielectric_shaded`] when smooth (`alpha` 0),
/// else a GGX rough-dielectric sample. Returns the event and its weight (G2/G1; 1 when
/// smooth), None when the sample is lost.
pub fn dielectric_bounce(
    alpha: f32,
    d: Vec3,
    n: Vec3,
    ns: Vec3,
    eta: f32,
    u: [f32; 2],
    u_choice: f32,
) -> Option<(DielectricEvent, f32)> {
    if alpha <= 0.0 {
        return Some((scatter_dielectric_shaded(d, n, ns, eta, u_choice), 1.0));
    }
    let ggx = microfacet::Ggx { alpha };
    let ev = microfacet::sample_rough_dielectric(ggx, d, n, ns, eta, u, u_choice)?;
    let event = DielectricEvent {
        dir: ev.dir,
        transmitted: ev.transmitted,
        eta_ratio: ev.eta_ratio,
    };
    Some((event, ev.weight))
}

/// Russian roulette after a metal bounce: `t` *= Schlick(F0 = `reflectance`, `cos`) ·
/// `weight` per bin, then survives as [`russian_roulette`] does.
pub fn russian_roulette_metal(
    t: &mut [f32],
    reflectance: &[f32],
    cos: f32,
    weight: f32,
    u: f32,
) -> bool {
    debug_assert_eq!(t.len(), reflectance.len());
    let attenuate = |t: &mut [f32]| {
        for (v, &r) in t.iter_mut().zip(reflectance) {
            *v *= microfacet::schlick(r, cos) * weight;
        }
        spd::sum(t)
    };
    russian_roulette_by(t, attenuate, u)
}

/// A camera path's metal bounce: `t` *= Schlick(F0 = `reflectance`, `cos`) · `weight`
/// per bin, kept as a weight (a path that survived roulette on every coloured bounce
/// would show a rough metal as black-or-sky noise), then [`roulette_when_faint`].
pub fn attenuate_metal(t: &mut [f32], reflectance: &[f32], cos: f32, weight: f32, u: f32) -> bool {
    for (v, r) in t.iter_mut().zip(reflectance) {
        *v *= microfacet::schlick(*r, cos) * weight;
    }
    roulette_when_faint(t, u)
}

/// Throughput below which a camera path plays Russian roulette.
pub const FAINT: f32 = 0.25;

/// Russian roulette on a path's own size: a path whose largest bin is below [`FAINT`]
/// survives with probability max/FAINT and is scaled back up to FAINT (unbiased); a
/// brighter one always continues. Paths through many lossy bounces end; a bright path is
/// never cut short.
pub fn roulette_when_faint(t: &mut [f32], u: f32) -> bool {
    let m = spd::max(t);
    if !(m > 0.0) {
        return false;
    }
    if m >= FAINT {
        return true;
    }
    let p = m / FAINT;
    if u >= p {
        return false;
    }
    spd::scale(t, 1.0 / p);
    true
}

/// Russian roulette on a scalar weight (≤ 1 for the microfacet models): survives with
/// probability min(1, w) and keeps the path's size.
pub fn russian_roulette_scalar(t: &mut [f32], w: f32, u: f32) -> bool {
    let attenuate = |t: &mut [f32]| {
        spd::scale(t, w);
        spd::sum(t)
    };
    russian_roulette_by(t, attenuate, u)
}

/// Russian roulette on a reflectance: multiplies `t` by ρ, then survives with
/// p = min(1, Σ(t·ρ)/Σt) and divides by p (unbiased; the path's weight stays near its
/// size before the bounce). Returns false when the path is absorbed. Shared by the photon
/// tracer and the gather, so both sides end paths the same way.
#[inline]
pub fn russian_roulette(t: &mut [f32], reflectance: &[f32], u: f32) -> bool {
    debug_assert_eq!(t.len(), reflectance.len());
    russian_roulette_by(t, |t| spd::mul_assign_sum(t, reflectance), u)
}

/// [`russian_roulette`] of a flux that is `v` in one bin and zero elsewhere, by that
/// bin's factor: the same arithmetic as on the whole vector (its sums are exactly `v`
/// and `v`·factor), so the same photons survive with the same flux, bit for bit.
pub fn russian_roulette_single(v: &mut f32, factor: f32, u: f32) -> bool {
    let before = *v;
    *v *= factor;
    let after = *v;
    if !(before > 0.0 && after > 0.0) {
        return false;
    }
    let p = (after / before).min(1.0);
    if u >= p {
        return false;
    }
    *v *= 1.0 / p;
    true
}

/// [`russian_roulette`] with the bins attenuated by `attenuate`, which returns their new
/// sum (loops over the slice itself, which the compiler vectorises; an indexed factor per
/// bin kept them scalar).
#[inline]
fn russian_roulette_by(t: &mut [f32], attenuate: impl FnOnce(&mut [f32]) -> f32, u: f32) -> bool {
    let before = spd::sum(t);
    let after = attenuate(t);
    if !(before > 0.0 && after > 0.0) {
        return false;
    }
    let p = (after / before).min(1.0);
    if u >= p {
        return false;
    }
    spd::scale(t, 1.0 / p);
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn single_bin_roulette_is_the_vector_roulette_bit_for_bit() {
        let mut rng = crate::sampling::Rng::stream(3, 0, 0, crate::sampling::Purpose::Photon);
        for bins in [1usize, 5, 20, 100] {
            for _ in 0..2000 {
                let b = (rng.next_f32() * bins as f32) as usize % bins;
                let v = rng.next_f32() * 10.0;
                let reflectance: Vec<f32> = (0..bins).map(|_| rng.next_f32() * 1.2).collect();
                let u = rng.next_f32();
                let mut flux = vec![0.0f32; bins];
                flux[b] = v;
                let mut single = v;
                let vector = russian_roulette(&mut flux, &reflectance, u);
                let scalar = russian_roulette_single(&mut single, reflectance[b], u);
                assert_eq!(vector, scalar, "{bins} bins, bin {b}: survival");
                if vector {
                    assert_eq!(flux[b].to_bits(), single.to_bits(), "{bins} bins, bin {b}");
                    assert!(flux.iter().enumerate().all(|(i, &x)| i == b || x == 0.0));
                }
            }
        }
    }

    #[test]
    fn fresnel_is_bounded_everywhere_and_one_at_grazing_and_tir() {
        for &eta_t in &[1.0f32, 1.0 + 1e-7, 1.0 - 1e-7, 1.0 / 1.5, 1.5, 4.0] {
            let mut c = -1.0f32;
            while c <= 1.0 {
                let f = fresnel_dielectric(c, 1.0, eta_t);
                assert!(
                    f.is_finite() && (0.0..=1.0).contains(&f),
                    "cos {c} eta {eta_t}: {f}"
                );
                c += 1e-3;
            }
            assert!((fresnel_dielectric(0.0, 1.0, eta_t) - 1.0).abs() < 1e-6 || eta_t == 1.0);
        }
        // Normal incidence: ((n−1)/(n+1))².
        assert!((fresnel_dielectric(1.0, 1.0, 1.5) - 0.04).abs() < 1e-6);
        // Total internal reflection from inside glass beyond the critical angle.
        let crit = (1.0f32 / 1.5).asin();
        assert_eq!(fresnel_dielectric((crit + 0.01).cos(), 1.5, 1.0), 1.0);
        // Index-matched boundary reflects nothing.
        assert!(fresnel_dielectric(0.3, 1.5, 1.5) < 1e-12);
    }

    #[test]
    fn refraction_obeys_snell_and_reports_tir_exactly() {
        let n = Vec3::Z;
        for i in 0..=89 {
            let th = (i as f32).to_radians();
            let d = Vec3::new(th.sin(), 0.0, -th.cos());
            let eta = 1.0 / 1.5;
            let t = refract(d, n, eta).expect("air → glass never reflects totally");
            let sin_t = t.x;
            assert!((th.sin() * eta - sin_t).abs() < 1e-5, "{i}°");
            // Glass → air: TIR exactly when sin²θt ≥ 1.
            let eta_out = 1.5;
            let tir = eta_out * eta_out * th.sin() * th.sin() >= 1.0;
            assert_eq!(refract(d, n, eta_out).is_none(), tir, "{i}°");
        }
    }

    #[test]
    fn shading_normals_bend_rays_but_never_through_the_wrong_side() {
        let n = Vec3::Z;
        // Flat shading: identical to the geometric case.
        let d = Vec3::new(0.6, 0.0, -0.8);
        let a = scatter_dielectric(d, n, 1.5, 0.5);
        let b = scatter_dielectric_shaded(d, n, n, 1.5, 0.5);
        assert_eq!((a.dir, a.transmitted), (b.dir, b.transmitted));
        // A tilted shading normal changes the refracted direction (a smooth sphere)...
        let ns = Vec3::new(0.2, 0.0, 1.0).normalize();
        let c = scatter_dielectric_shaded(d, n, ns, 1.5, 0.5);
        assert!(c.transmitted && (c.dir - a.dir).length() > 1e-3);
        // ...and whatever the normals, reflected rays stay above the surface and
        // transmitted ones go below it.
        for i in 0..200 {
            let t = i as f32 / 200.0 * 1.4 - 0.7;
            let ns = Vec3::new(t, 0.3 * t, 1.0).normalize();
            for d in [
                Vec3::new(0.99, 0.0, -0.14).normalize(),
                Vec3::new(-0.3, 0.2, -0.9).normalize(),
            ] {
                for u in [0.01, 0.5, 0.99] {
                    let e = scatter_dielectric_shaded(d, n, ns, 1.5, u);
                    assert!(e.dir.is_finite());
                    assert_eq!(e.dir.z < 0.0, e.transmitted, "{d:?} {ns:?} {u}");
                }
                assert!(reflect_shaded(d, n, ns).z > 0.0);
            }
        }
    }

    #[test]
    fn scattering_conserves_probability() {
        // R + T = 1: the fraction of reflections over u matches Fresnel.
        let n = Vec3::Z;
        let d = Vec3::new(0.6, 0.0, -0.8);
        let f = fresnel_dielectric(0.8, 1.0, 1.5);
        let m = 100_000;
        let reflected = (0..m)
            .filter(|k| !scatter_dielectric(d, n, 1.5, (*k as f32 + 0.5) / m as f32).transmitted)
            .count();
        assert!((reflected as f32 / m as f32 - f).abs() < 1e-3);
    }
}
