//! Light sources: what they emit, how photons leave them, and how a surface point samples
//! them for direct light. Angles of narrow cones are kept as 1 − cos θ (see
//! [`crate::sampling::one_minus_cos`]), never as cos θ, so a 0.01° spot is as precise as a
//! 30° one.

use glam::Vec3;

use crate::geometry::{Accel, TriData};
use crate::sampling::{
    Rng, cdf, cosine_hemisphere, one_minus_cos_between, sample_cdf, uniform_cone, uniform_sphere,
    uniform_triangle,
};
use crate::spectral::spd;

#[derive(Clone, Copy, Debug)]
pub enum LightKind {
    /// An emissive triangle (one-sided, Lambertian).
    Area {
        tri: u32,
    },
    Point {
        position: Vec3,
    },
    Spot {
        position: Vec3,
        axis: Vec3,
        /// 1 − cos of the outer and inner cone angles (precise for narrow cones).
        omc_outer: f32,
        omc_inner: f32,
    },
    /// Parallel light travelling along `dir` (glTF directional, Blender's Sun); the
    /// spectrum is the irradiance on a surface facing it. Photons start on a disc that
    /// covers the scene's bounding sphere (`center`, `radius`).
    Distant {
        dir: Vec3,
        center: Vec3,
        radius: f32,
    },
    /// A uniform sky of the spectrum's radiance all around the scene's bounding sphere;
    /// photons enter the sphere from every direction.
    Environment {
        center: Vec3,
        radius: f32,
    },
}

#[derive(Clone, Debug)]
pub struct Light {
    pub kind: LightKind,
    /// Per-bin emitted radiance (area) or intensity (punctual).
    pub spectrum: Vec<f32>,
    /// Emitted power as luminance (Y), for choosing lights.
    pub power: f32,
}

/// The sphere around every specular triangle, which caustic-only photons are aimed at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target {
    pub center: Vec3,
    pub radius: f32,
}

/// How one light aims its caustic-only photons at the [`Target`], and the share of its
/// unaimed photons that would have headed into it.
#[derive(Clone, Copy, Debug)]
struct Aim {
    kind: AimKind,
    share: f32,
}

#[derive(Clone, Copy, Debug)]
enum AimKind {
    /// Directions in the cone about `axis` with 1 − cos of its half-angle `omc`.
    Cone { axis: Vec3, omc: f32 },
    /// Starts on the disc of `radius` about `center`, on the light's start plane.
    Disc { center: Vec3, radius: f32 },
}

impl Aim {
    /// How `light` aims at `target`; None where aiming would not narrow its emission.
    fn of(light: &Light, target: Target) -> Option<Self> {
        let cone_from = |position: Vec3| {
            let to = target.center - position;
            let d = to.length();
            // From inside (or at the edge of) the sphere every direction may reach it.
            if !(d > target.radius * 1.001) || !d.is_finite() {
                return None;
            }
            let sin = target.radius / d;
            // 1 − cos θ = sin²θ / (1 + cos θ): precise for a small, far target.
            let omc = sin * sin / (1.0 + (1.0 - sin * sin).max(0.0).sqrt());
            (omc > 0.0).then_some((to / d, omc))
        };
        let (kind, share) = match light.kind {
            LightKind::Point { position } => {
                let (axis, omc) = cone_from(position)?;
                (AimKind::Cone { axis, omc }, 0.5 * omc)
            }
            LightKind::Spot {
                position,
                omc_outer,
                ..
            } => {
                let (axis, omc) = cone_from(position)?;
                if omc >= omc_outer {
                    return None;
                }
                (AimKind::Cone { axis, omc }, omc / omc_outer)
            }
            LightKind::Distant {
                dir,
                center,
                radius,
            } => {
                if !(target.radius < radius) {
                    return None;
                }
                // The start plane of the unaimed photons (one radius behind the scene
                // sphere's centre, facing `dir`), under the target's centre.
                let along = dir.dot(target.center - center) + radius;
                let center = target.center - dir * along;
                let share = (target.radius / radius).powi(2);
                (
                    AimKind::Disc {
                        center,
                        radius: target.radius,
                    },
                    share,
                )
            }
            LightKind::Area { .. } | LightKind::Environment { .. } => return None,
        };
        (share.is_finite() && share > 0.0 && share < 1.0).then_some(Self { kind, share })
    }
}

/// A photon as it leaves a light: flux already divided by the photon count and the
/// light's selection probability.
pub struct Emitted {
    pub origin: Vec3,
    pub dir: Vec3,
    pub flux: Vec<f32>,
}

/// The scene's lights with their two selection distributions: photon emission (half by
/// power, half evenly over light groups, so a small bright spot next to a large dim panel
/// still gets photons for its caustic) and direct lighting (by power).
pub struct LightSet {
    lights: Vec<Light>,
    /// Per light, how its caustic-only photons are aimed at the scene's [`Target`] (see
    /// [`Self::aim_at`]); empty when nothing is aimed.
    aims: Vec<Option<Aim>>,
    /// Σ over lights of emit pmf × the share of its unaimed photons that would head into
    /// the target (1 for a light that is not aimed).
    aimed_share: f32,
    emit_pmf: Vec<f32>,
    emit_cdf: Vec<f32>,
    direct_pmf: Vec<f32>,
    direct_cdf: Vec<f32>,
}

impl LightSet {
    /// All area triangles of one material count as one group; punctual lights are their
    /// own groups.
    pub fn new(lights: Vec<Light>, tris: &[TriData]) -> Self {
        let total: f64 = lights.iter().map(|l| l.power as f64).sum();
        let group_key = |i: usize, l: &Light| match l.kind {
            LightKind::Area { tri } => tris[tri as usize].material as usize,
            _ => usize::MAX - i,
        };
        let mut groups: Vec<(usize, f64)> = Vec::new();
        let mut light_group = Vec::with_capacity(lights.len());
        for (i, l) in lights.iter().enumerate() {
            let key = group_key(i, l);
            let idx = groups
                .iter()
                .position(|(k, _)| *k == key)
                .unwrap_or_else(|| {
                    groups.push((key, 0.0));
                    groups.len() - 1
                });
            groups[idx].1 += l.power as f64;
            light_group.push(idx);
        }
        let emit_pmf: Vec<f32> = lights
            .iter()
            .zip(&light_group)
            .map(|(l, &g)| {
                let by_power = l.power as f64 / total;
                let in_group = l.power as f64 / groups[g].1;
                (0.5 * by_power + 0.5 * in_group / groups.len() as f64) as f32
            })
            .collect();
        let direct_pmf: Vec<f32> = lights
            .iter()
            .map(|l| (l.power as f64 / total) as f32)
            .collect();
        Self {
            aims: Vec::new(),
            aimed_share: 1.0,
            emit_cdf: cdf(&emit_pmf),
            direct_cdf: cdf(&direct_pmf),
            emit_pmf,
            direct_pmf,
            lights,
        }
    }

    pub fn len(&self) -> usize {
        self.lights.len()
    }

    pub fn is_empty(&self) -> bool {
        self.lights.is_empty()
    }

    pub fn iter(&self) -> std::slice::Iter<'_, Light> {
        self.lights.iter()
    }

    /// Aims the caustic-only photons of point, spot and distant lights at `target` (the
    /// sphere around every mirror and glass triangle): a caustic path's first hit lies
    /// inside it, so a photon that misses it cannot be a caustic photon. A point light then
    /// emits into the sphere's cone, a spot into that cone where it is narrower than its
    /// own (directions outside the spot carry its zero falloff), a distant light from the
    /// sphere's shadow disc on its start plane; each photon's weight is the sampled solid
    /// angle or area, so every aimed light's caustic flux is unbiased. Area lights and the
    /// sky, and lights inside the sphere, emit as before.
    pub fn aim_at(&mut self, target: Target) {
        self.aims = self.lights.iter().map(|l| Aim::of(l, target)).collect();
        self.aimed_share = self
            .aims
            .iter()
            .zip(&self.emit_pmf)
            .map(|(a, &pmf)| pmf * a.as_ref().map_or(1.0, |a| a.share))
            .sum::<f32>()
            .clamp(0.0, 1.0);
        if self.aims.iter().all(Option::is_none) {
            self.aims.clear();
            self.aimed_share = 1.0;
        }
    }

    /// Whether any light aims its caustic-only photons ([`Self::aim_at`]).
    pub fn aims(&self) -> bool {
        !self.aims.is_empty()
    }

    /// The expected share of unaimed caustic-only photons that would head into the
    /// target (1 when nothing is aimed): how much denser the aimed photons are.
    pub fn aimed_share(&self) -> f32 {
        self.aimed_share
    }

    /// Probability that a photon leaves light `i`.
    pub fn emit_pmf(&self, i: usize) -> f32 {
        self.emit_pmf[i]
    }

    /// Chooses a light and emits one of `photons` photons from it.
    pub fn emit(
        &self,
        tris: &[TriData],
        accel: &Accel,
        photons: usize,
        rng: &mut Rng,
    ) -> Option<Emitted> {
        let mut flux = Vec::new();
        let (origin, dir) = self.emit_into(tris, accel, photons, false, rng, &mut flux)?;
        Some(Emitted { origin, dir, flux })
    }

    /// [`Self::emit`] with the flux written into `flux` (resized to the bins; no
    /// allocation once it has been): returns the photon's origin and direction. `aimed`:
    /// a caustic-only photon, aimed at the target where its light is ([`Self::aim_at`]).
    pub fn emit_into(
        &self,
        tris: &[TriData],
        accel: &Accel,
        photons: usize,
        aimed: bool,
        rng: &mut Rng,
        flux: &mut Vec<f32>,
    ) -> Option<(Vec3, Vec3)> {
        use std::f32::consts::PI;
        if self.lights.is_empty() {
            return None;
        }
        let li = sample_cdf(&self.emit_cdf, rng.next_f32());
        let (light, pmf) = (&self.lights[li], self.emit_pmf[li]);
        if !(pmf > 0.0) {
            return None;
        }
        let aim = if aimed {
            self.aims.get(li).copied().flatten()
        } else {
            None
        };
        let (origin, dir, weight) = match (light.kind, aim) {
            (
                LightKind::Point { position },
                Some(Aim {
                    kind: AimKind::Cone { axis, omc },
                    ..
                }),
            ) => {
                let dir = uniform_cone(axis, omc, rng.next_2d());
                (position, dir, 2.0 * PI * omc)
            }
            (
                LightKind::Spot {
                    position,
                    axis: spot_axis,
                    omc_outer,
                    omc_inner,
                },
                Some(Aim {
                    kind: AimKind::Cone { axis, omc },
                    ..
                }),
            ) => {
                let dir = uniform_cone(axis, omc, rng.next_2d());
                let falloff =
                    spot_falloff(one_minus_cos_between(dir, spot_axis), omc_outer, omc_inner);
                if !(falloff > 0.0) {
                    return None;
                }
                (position, dir, 2.0 * PI * omc * falloff)
            }
            (
                LightKind::Distant { dir, .. },
                Some(Aim {
                    kind: AimKind::Disc { center, radius },
                    ..
                }),
            ) => {
                let origin = center + disc_point(dir, radius, rng.next_2d());
                (origin, dir, PI * radius * radius)
            }
            (kind, _) => Self::emit_unaimed(&kind, tris, accel, rng),
        };
        flux.clear();
        flux.extend_from_slice(&light.spectrum);
        spd::scale(flux, weight / (pmf * photons as f32));
        Some((origin, dir))
    }

    /// A photon's start, direction and weight (the flux per unit of the light's spectrum)
    /// as `kind` emits it over its whole extent.
    #[inline(always)]
    fn emit_unaimed(
        kind: &LightKind,
        tris: &[TriData],
        accel: &Accel,
        rng: &mut Rng,
    ) -> (Vec3, Vec3, f32) {
        use std::f32::consts::PI;
        match *kind {
            LightKind::Area { tri } => {
                let t = &tris[tri as usize];
                let (b1, b2) = uniform_triangle(rng.next_2d());
                let p = t.v0 + t.e1 * b1 + t.e2 * b2;
                let dir = cosine_hemisphere(t.normal, rng.next_2d());
                let origin = accel.offset(p, t.normal, dir);
                (origin, dir, std::f32::consts::PI * t.area)
            }
            LightKind::Point { position } => (
                position,
                uniform_sphere(rng.next_2d()),
                4.0 * std::f32::consts::PI,
            ),
            LightKind::Spot {
                position,
                axis,
                omc_outer,
                omc_inner,
            } => {
                let dir = uniform_cone(axis, omc_outer, rng.next_2d());
                let solid_angle = 2.0 * std::f32::consts::PI * omc_outer;
                let falloff = spot_falloff(one_minus_cos_between(dir, axis), omc_outer, omc_inner);
                (position, dir, solid_angle * falloff)
            }
            LightKind::Distant {
                dir,
                center,
                radius,
            } => {
                // A disc of the bounding sphere's radius, one radius behind its centre.
                let origin = center - dir * radius + disc_point(dir, radius, rng.next_2d());
                (origin, dir, PI * radius * radius)
            }
            LightKind::Environment { center, radius } => {
                // Direction uniform on the sphere, start point uniform on the disc across
                // the bounding sphere facing it: flux L · 4π · πR².
                let dir = uniform_sphere(rng.next_2d());
                let origin = center - dir * radius + disc_point(dir, radius, rng.next_2d());
                (origin, dir, 4.0 * PI * PI * radius * radius)
            }
        }
    }

    /// Irradiance (N bins) at `p` from one light sample with a shadow ray, into `out`;
    /// zero when the sample is occluded or faces away. `nf` is the geometric normal on the
    /// side seen (light must arrive on that side), `ns` the shading normal the cosine is
    /// taken with (smooth shading; `nf` itself on flat triangles).
    #[allow(clippy::too_many_arguments)]
    pub fn direct(
        &self,
        tris: &[TriData],
        accel: &Accel,
        p: Vec3,
        nf: Vec3,
        ns: Vec3,
        [u_light, u, v]: [f32; 3],
        out: &mut [f32],
    ) {
        match self.sample_direct_at(tris, accel, p, (nf, ns), u_light, [u, v]) {
            Some(s) => {
                let (spectrum, k) = (&self.lights[s.light].spectrum, s.cos * s.weight);
                debug_assert_eq!(spectrum.len(), out.len());
                for (o, l) in out.iter_mut().zip(spectrum) {
                    *o = l * k;
                }
            }
            None => out.fill(0.0),
        }
    }

    /// One unoccluded light sample seen from `p` on the side `nf` faces: the light, the
    /// direction to it, cos θ with `nf`, and the weight that turns the light's spectrum
    /// into radiance (or irradiance, for punctual and distant lights) per unit solid angle
    /// sampled — irradiance = spectrum · cos · weight. None when occluded or facing away.
    pub fn sample_direct(
        &self,
        tris: &[TriData],
        accel: &Accel,
        p: Vec3,
        nf: Vec3,
        rng: &mut Rng,
    ) -> Option<DirectSample> {
        self.sample_direct_at(tris, accel, p, (nf, nf), rng.next_f32(), rng.next_2d())
    }

    /// [`Self::sample_direct`] with its random numbers given: `u_light` picks the light,
    /// `uv` the point on it (a pixel's sequence across passes, see `gather`). The normals
    /// are (geometric on the side seen, shading): the light must lie above both, and the
    /// cosine is the shading normal's.
    pub fn sample_direct_at(
        &self,
        tris: &[TriData],
        accel: &Accel,
        p: Vec3,
        (nf, ns): (Vec3, Vec3),
        u_light: f32,
        uv: [f32; 2],
    ) -> Option<DirectSample> {
        if self.lights.is_empty() {
            return None;
        }
        let li = sample_cdf(&self.direct_cdf, u_light);
        let (light, pmf) = (&self.lights[li], self.direct_pmf[li]);
        if !(pmf > 0.0) {
            return None;
        }
        let (wn, dist, weight) = match &light.kind {
            LightKind::Distant { dir, .. } => (-*dir, f32::INFINITY, 1.0),
            LightKind::Environment { .. } => {
                // Cosine-weighted: radiance · cos / (cos/π) = π · radiance per sample.
                let wn = cosine_hemisphere(nf, uv);
                let cos = nf.dot(wn).max(1e-6);
                (wn, f32::INFINITY, std::f32::consts::PI / cos)
            }
            _ => {
                let (target, weight) = sample_towards(light, tris, p, uv)?;
                let w = target - p;
                let dist = w.length();
                (w / dist, dist, weight)
            }
        };
        let cos_x = ns.dot(wn);
        if !(cos_x > 0.0 && weight.is_finite() && weight > 0.0) {
            return None;
        }
        if ns != nf && !(nf.dot(wn) > 0.0) {
            return None;
        }
        let origin = accel.offset(p, nf, wn);
        if accel.occluded(origin, wn, dist * (1.0 - 1e-4)) {
            return None;
        }
        Some(DirectSample {
            light: li,
            dir: wn,
            cos: cos_x,
            weight: weight / pmf,
        })
    }

    /// Whether light `i` is punctual or distant (no ray can hit it: only light sampling
    /// sees it).
    pub fn is_delta(&self, i: usize) -> bool {
        matches!(
            self.lights[i].kind,
            LightKind::Point { .. } | LightKind::Spot { .. } | LightKind::Distant { .. }
        )
    }

    pub fn spectrum(&self, i: usize) -> &[f32] {
        &self.lights[i].spectrum
    }
}

/// A light sample that reached its point (see [`LightSet::sample_direct`]).
#[derive(Clone, Copy, Debug)]
pub struct DirectSample {
    pub light: usize,
    pub dir: Vec3,
    pub cos: f32,
    pub weight: f32,
}

/// A point on `light` seen from `p` and its geometry weight (irradiance per unit
/// radiance or intensity, before the receiver's cosine); None when it emits nothing
/// towards `p`.
fn sample_towards(light: &Light, tris: &[TriData], p: Vec3, uv: [f32; 2]) -> Option<(Vec3, f32)> {
    match light.kind {
        LightKind::Distant { .. } | LightKind::Environment { .. } => None,
        LightKind::Area { tri } => {
            let t = &tris[tri as usize];
            let (b1, b2) = uniform_triangle(uv);
            let y = t.v0 + t.e1 * b1 + t.e2 * b2;
            let w = y - p;
            let d2 = w.length_squared();
            let cos_l = -t.normal.dot(w / d2.sqrt());
            (cos_l > 0.0).then_some((y, cos_l * t.area / d2))
        }
        LightKind::Point { position } => Some((position, 1.0 / (position - p).length_squared())),
        LightKind::Spot {
            position,
            axis,
            omc_outer,
            omc_inner,
        } => {
            let w = p - position;
            let d2 = w.length_squared();
            let f = spot_falloff(
                one_minus_cos_between(w / d2.sqrt(), axis),
                omc_outer,
                omc_inner,
            );
            (f > 0.0).then_some((position, f / d2))
        }
    }
}

/// A uniform point on the disc of `radius` perpendicular to unit `axis`, about the origin.
fn disc_point(axis: Vec3, radius: f32, u: [f32; 2]) -> Vec3 {
    let (t, b) = crate::sampling::basis(axis);
    let r = radius * u[0].sqrt();
    let phi = 2.0 * std::f32::consts::PI * u[1];
    t * (r * phi.cos()) + b * (r * phi.sin())
}

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
    fn aimed_photons_carry_into_the_target_the_flux_unaimed_ones_do() {
        // A point light, a spot tilted so that the target sits on its falloff ramp, and a
        // sun, each with a sphere off to one side. Unaimed, the flux of the photons whose
        // ray meets the sphere estimates what enters it; aimed, every photon meets it
        // (checked) and their flux must estimate the same, from far fewer photons.
        use crate::sampling::{Purpose, Rng};
        let target = Target {
            center: Vec3::new(0.4, -1.0, 0.3),
            radius: 0.25,
        };
        let meets = |o: Vec3, d: Vec3| {
            let oc = target.center - o;
            let t = oc.dot(d);
            t > 0.0 && (oc - d * t).length_squared() <= target.radius * target.radius * 1.0001
        };
        let spot = LightKind::Spot {
            position: Vec3::ZERO,
            axis: Vec3::new(0.45, -1.0, 0.0).normalize(),
            omc_outer: crate::sampling::one_minus_cos(40f32.to_radians()),
            omc_inner: crate::sampling::one_minus_cos(10f32.to_radians()),
        };
        let kinds = [
            (
                "point",
                LightKind::Point {
                    position: Vec3::ZERO,
                },
            ),
            ("spot", spot),
            (
                "sun",
                LightKind::Distant {
                    dir: Vec3::new(0.3, -1.0, 0.2).normalize(),
                    center: Vec3::new(0.0, -1.0, 0.0),
                    radius: 2.0,
                },
            ),
        ];
        let accel = Accel::new(&[]);
        for (name, kind) in kinds {
            let light = Light {
                kind,
                spectrum: vec![1.0],
                power: 1.0,
            };
            let mut set = LightSet::new(vec![light], &[]);
            set.aim_at(target);
            assert!(set.aims(), "{name} should aim");
            let total = |aimed: bool, photons: usize| {
                let (mut sum, mut met) = (0.0f64, 0usize);
                let mut flux = Vec::new();
                for i in 0..photons {
                    let mut rng = Rng::stream(3, 1, i as u64, Purpose::Photon);
                    if let Some((o, d)) =
                        set.emit_into(&[], &accel, photons, aimed, &mut rng, &mut flux)
                        && meets(o, d)
                    {
                        sum += f64::from(flux[0]);
                        met += 1;
                    }
                }
                (sum, met)
            };
            // 8 M unaimed photons put the reference within 0.3 % (1σ; 1.3 % of them meet
            // the target from the point light).
            let (unaimed, _) = total(false, 8_000_000);
            let (aimed, met) = total(true, 100_000);
            let rel = aimed / unaimed - 1.0;
            println!(
                "{name}: into the target {unaimed:.5} unaimed, {aimed:.5} aimed ({rel:+.4}), {met} aimed photons met it"
            );
            assert!(
                rel.abs() < 0.01,
                "{name}: aimed {aimed} against unaimed {unaimed}"
            );
            assert_eq!(met, 100_000, "{name}: aimed photons missed the target");
        }
    }

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
