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

pub mod adaptive;
use adaptive::EmissionCells;

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

/// A sphere around some of the specular triangles; caustic-only photons are aimed at a
/// few of them, which together hold every mirror and glass triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target {
    pub center: Vec3,
    pub radius: f32,
}

/// Most targets a scene's specular triangles are grouped into.
pub const MAX_TARGETS: usize = 8;

/// That a light aims its caustic-only photons at the targets, and the share of its
/// unaimed photons that would have headed into them (0 for an area light that faces
/// away from every target: none of its photons can start a caustic path).
#[derive(Clone, Copy, Debug)]
struct Aim {
    share: f32,
    /// Bit k: target k lies in front of an area triangle (all set for other lights).
    front: u8,
    /// A point light's or spot's cones to the targets, fixed at [`LightSet::aim_at`]:
    /// an index into [`LightSet`]'s `cones`.
    cones: Option<u32>,
}

/// Cones to each target from one position: axis and 1 − cos of the half-angle.
type Cones = [(Vec3, f32); MAX_TARGETS];

/// The cone from `position` that holds `target`: its axis and 1 − cos of its half-angle;
/// None from inside (or at the edge of) the sphere, where every direction may reach it.
#[inline]
fn cone_to(target: Target, position: Vec3) -> Option<(Vec3, f32)> {
    let to = target.center - position;
    let d = to.length();
    if !(d > target.radius * 1.001) || !d.is_finite() {
        return None;
    }
    let sin = target.radius / d;
    // 1 − cos θ = sin²θ / (1 + cos θ): precise for a small, far target.
    let omc = sin * sin / (1.0 + (1.0 - sin * sin).max(0.0).sqrt());
    (omc > 0.0).then_some((to / d, omc))
}

/// Where a target lies against an emissive triangle's plane.
enum Side {
    /// Wholly in front, by more than its radius.
    Front,
    /// Wholly behind: no photon of the triangle can reach it.
    Behind,
    /// Cut by the plane (or touching it).
    Across,
}

fn side_of(t: &TriData, target: Target) -> Side {
    let d = t.normal.dot(target.center - t.v0);
    if d > target.radius * 1.001 {
        Side::Front
    } else if d < -target.radius * 1.001 {
        Side::Behind
    } else {
        Side::Across
    }
}

/// The cones from `position` to those of `targets` whose bit is set in `keep`, into
/// `out`: how many, or None where `position` is inside one.
#[inline]
fn cones_to(targets: &[Target], position: Vec3, keep: u8, out: &mut Cones) -> Option<usize> {
    let mut n = 0;
    for (k, &t) in targets.iter().take(MAX_TARGETS).enumerate() {
        if keep & (1 << k) != 0 {
            out[n] = cone_to(t, position)?;
            n += 1;
        }
    }
    Some(n)
}

/// Picks one of `n` pieces in proportion to `weight` (one draw, only where there are
/// several); returns it and the weights' sum.
#[inline]
fn pick(n: usize, weight: impl Fn(usize) -> f32, rng: &mut Rng) -> (usize, f32) {
    let total: f32 = (0..n).map(&weight).sum();
    if n <= 1 {
        return (0, total);
    }
    let mut u = rng.next_f32() * total;
    for j in 0..n - 1 {
        let w = weight(j);
        if u < w {
            return (j, total);
        }
        u -= w;
    }
    (n - 1, total)
}

/// A uniform direction in the union of `cones` (picked by solid angle, then uniform in
/// the one picked) and its weight, the union's solid angle as the sampling saw it: Σ Ω
/// over the cones that hold the direction.
#[inline]
fn sample_cones(cones: &[(Vec3, f32)], rng: &mut Rng) -> (Vec3, f32) {
    use std::f32::consts::PI;
    let (j, total) = pick(cones.len(), |k| cones[k].1, rng);
    let (axis, omc) = cones[j];
    let dir = uniform_cone(axis, omc, rng.next_2d());
    let holding = 1 + cones
        .iter()
        .enumerate()
        .filter(|&(k, &(a, o))| k != j && one_minus_cos_between(dir, a) <= o)
        .count();
    (dir, 2.0 * PI * total / holding as f32)
}

/// A uniform start point, on the plane through `plane` facing `dir`, in the union of the
/// targets' shadow discs (picked by area, then uniform in the one picked), and its
/// weight: the union's area as the sampling saw it.
#[inline]
fn sample_discs(targets: &[Target], dir: Vec3, plane: Vec3, rng: &mut Rng) -> (Vec3, f32) {
    use std::f32::consts::PI;
    let n = targets.len().min(MAX_TARGETS);
    let on_plane = |t: Target| t.center - dir * dir.dot(t.center - plane);
    let (j, total) = pick(n, |k| targets[k].radius * targets[k].radius, rng);
    let origin = on_plane(targets[j]) + disc_point(dir, targets[j].radius, rng.next_2d());
    let holding = 1
        + (0..n)
            .filter(|&k| {
                k != j
                    && (origin - on_plane(targets[k])).length_squared()
                        <= targets[k].radius * targets[k].radius
            })
            .count();
    (origin, PI * total / holding as f32)
}

impl Aim {
    /// Whether and how much `light` aims at `targets` (at most [`MAX_TARGETS`]), and a
    /// point light's or spot's cones to them; None where aiming would not narrow its
    /// emission.
    fn of(light: &Light, tris: &[TriData], targets: &[Target]) -> Option<(Self, Option<Cones>)> {
        let mut cones = [(Vec3::ZERO, 0.0); MAX_TARGETS];
        let all = u8::MAX;
        let (mut front, mut fixed) = (all, false);
        let share = match light.kind {
            LightKind::Point { position } => {
                let n = cones_to(targets, position, all, &mut cones)?;
                fixed = true;
                cones[..n].iter().map(|c| 0.5 * c.1).sum::<f32>()
            }
            LightKind::Spot {
                position,
                omc_outer,
                ..
            } => {
                let n = cones_to(targets, position, all, &mut cones)?;
                fixed = true;
                cones[..n].iter().map(|c| c.1).sum::<f32>() / omc_outer
            }
            LightKind::Distant { radius, .. } | LightKind::Environment { radius, .. } => {
                if !targets.iter().all(|t| t.radius < radius) {
                    return None;
                }
                targets
                    .iter()
                    .map(|t| (t.radius / radius).powi(2))
                    .sum::<f32>()
            }
            LightKind::Area { tri } => {
                // Only a triangle whose plane keeps each target wholly in front of it or
                // wholly behind, so that every point of it sees the ones in front from
                // outside; those behind it cannot receive its light.
                let t = tris.get(tri as usize)?;
                if targets
                    .iter()
                    .any(|&g| matches!(side_of(t, g), Side::Across))
                {
                    return None;
                }
                front = targets
                    .iter()
                    .enumerate()
                    .filter(|&(_, &g)| matches!(side_of(t, g), Side::Front))
                    .fold(0u8, |m, (k, _)| m | 1 << k);
                let n = cones_to(targets, t.v0 + (t.e1 + t.e2) / 3.0, front, &mut cones)?;
                // The share of its cosine-weighted photons into the cones from its
                // centroid: each cone's projected solid angle over π, sin²θ·cos γ.
                cones[..n]
                    .iter()
                    .map(|&(axis, omc)| omc * (2.0 - omc) * axis.dot(t.normal).max(0.0))
                    .sum::<f32>()
            }
        };
        let aim = Self {
            share,
            front,
            cones: None,
        };
        (0.0..1.0)
            .contains(&share)
            .then_some((aim, fixed.then_some(cones)))
    }
}

/// A photon as it leaves a light: flux already divided by the photon count and the
/// light's selection probability.
/// Where a photon leaves its light ([`LightSet::emit_into`]).
#[derive(Clone, Copy, Debug)]
pub struct PhotonStart {
    pub origin: Vec3,
    pub dir: Vec3,
    pub light: usize,
    /// A learning light's cell ([`adaptive`]), where the pass counts cells.
    pub cell: Option<usize>,
}

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
    /// The spheres caustic-only photons are aimed at ([`Self::aim_at`]).
    targets: Vec<Target>,
    /// Per light, whether its caustic-only photons are aimed at the targets; empty when
    /// nothing is aimed.
    aims: Vec<Option<Aim>>,
    /// The point lights' and spots' cones to the targets (see [`Aim::cones`]).
    cones: Vec<Cones>,
    /// Per light, the probability that an aimed caustic-only photon leaves it (emit pmf
    /// × √share, normalised; see [`Self::aimed_pmf`]); empty when nothing is aimed.
    aimed_pmf: Vec<f32>,
    aimed_cdf: Vec<f32>,
    /// Σ over lights of emit pmf × √share (1 when nothing is aimed).
    aimed_count: f64,
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
            targets: Vec::new(),
            aims: Vec::new(),
            cones: Vec::new(),
            aimed_pmf: Vec::new(),
            aimed_cdf: Vec::new(),
            aimed_count: 1.0,
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

    /// Aims the caustic-only photons at `targets` (spheres that together hold every mirror
    /// and glass triangle, at most [`MAX_TARGETS`]): a caustic path's first hit lies inside
    /// one, so a photon that misses them all cannot be a caustic photon. A point light
    /// then emits into the spheres' cones, a spot into those cones where they are narrower
    /// than its own (directions outside the spot carry its zero falloff), a distant light
    /// from the spheres' shadow discs on its start plane, an area triangle into the cones
    /// from the point each photon leaves (where its plane keeps each sphere wholly in
    /// front of it or behind), the sky along each direction from the spheres' shadow
    /// discs. A cone or disc is picked by its solid angle or area, and each photon's
    /// weight is the union's measure as the sampling saw it (Σ over the cones or discs
    /// that hold the sample), so every aimed light's caustic flux is unbiased where they
    /// overlap too. Lights inside a sphere emit as before.
    ///
    /// Each light's share s (of its unaimed photons that would head into the spheres; 1
    /// for a light that does not aim) sets how many aimed photons it gets: in proportion
    /// to emit pmf × √s ([`Self::aimed_pmf`]), the geometric mean of its unaimed photons'
    /// useful count and whole count (see `photon::trace`).
    pub fn aim_at(&mut self, targets: &[Target], tris: &[TriData]) {
        self.targets = targets.iter().copied().take(MAX_TARGETS).collect();
        self.cones.clear();
        self.aims = Vec::with_capacity(self.lights.len());
        for l in &self.lights {
            let aim = Aim::of(l, tris, &self.targets).map(|(mut aim, cones)| {
                if let Some(c) = cones {
                    aim.cones = Some(self.cones.len() as u32);
                    self.cones.push(c);
                }
                aim
            });
            self.aims.push(aim);
        }
        if self.targets.is_empty() || self.aims.iter().all(Option::is_none) {
            self.aims.clear();
            return;
        }
        let weights: Vec<f64> = (0..self.lights.len())
            .map(|i| f64::from(self.emit_pmf[i]) * f64::from(self.share(i)).sqrt())
            .collect();
        let total: f64 = weights.iter().sum();
        if !(total > 0.0) {
            self.aims.clear();
            return;
        }
        self.aimed_count = total.min(1.0);
        self.aimed_pmf = weights.iter().map(|w| (w / total) as f32).collect();
        self.aimed_cdf = cdf(&self.aimed_pmf);
    }

    /// The spheres caustic-only photons are aimed at (empty before [`Self::aim_at`]).
    pub fn targets(&self) -> &[Target] {
        &self.targets
    }

    /// Whether any light aims its caustic-only photons ([`Self::aim_at`]).
    pub fn aims(&self) -> bool {
        !self.aims.is_empty()
    }

    /// Whether light `i` aims its caustic-only photons at the targets.
    pub fn aims_light(&self, i: usize) -> bool {
        self.aims.get(i).copied().flatten().is_some()
    }

    /// The share of light `i`'s unaimed photons that would head into the targets (1 for a
    /// light that does not aim): how much denser its aimed photons are.
    pub fn share(&self, i: usize) -> f32 {
        self.aims.get(i).copied().flatten().map_or(1.0, |a| a.share)
    }

    /// Σ over lights of emit pmf × √share: aimed caustic-only photons, per unaimed one
    /// (1 when nothing is aimed).
    pub fn aimed_count(&self) -> f64 {
        self.aimed_count
    }

    /// Probability that an aimed caustic-only photon leaves light `i` (its emit pmf when
    /// nothing is aimed).
    pub fn aimed_pmf(&self, i: usize) -> f32 {
        self.aimed_pmf.get(i).copied().unwrap_or(self.emit_pmf[i])
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
        let start = self.emit_into(tris, accel, photons, false, None, rng, &mut flux)?;
        let (origin, dir) = (start.origin, start.dir);
        Some(Emitted { origin, dir, flux })
    }

    /// [`Self::emit`] with the flux written into `flux` (resized to the bins; no
    /// allocation once it has been): returns the photon's start and light.
    /// `aimed`: a caustic-only photon, from a light chosen by [`Self::aimed_pmf`] and aimed
    /// at the targets where that light aims ([`Self::aim_at`]). `cells`: the pass's
    /// learned emission ([`adaptive`]), for photons that are not aimed; a learning
    /// light's photon then reports its cell.
    #[allow(clippy::too_many_arguments)]
    pub fn emit_into(
        &self,
        tris: &[TriData],
        accel: &Accel,
        photons: usize,
        aimed: bool,
        cells: Option<&EmissionCells>,
        rng: &mut Rng,
        flux: &mut Vec<f32>,
    ) -> Option<PhotonStart> {
        use std::f32::consts::PI;
        if self.lights.is_empty() {
            return None;
        }
        let aimed = aimed && self.aims();
        let (cdf, pmfs) = if aimed {
            (&self.aimed_cdf, &self.aimed_pmf)
        } else {
            (&self.emit_cdf, &self.emit_pmf)
        };
        let li = sample_cdf(cdf, rng.next_f32());
        let (light, pmf) = (&self.lights[li], pmfs[li]);
        if !(pmf > 0.0) {
            return None;
        }
        let aim = if aimed { self.aims[li] } else { None };
        let targets = &self.targets[..];
        let fixed_cones = |aim: Aim| Some(&self.cones.get(aim.cones? as usize)?[..targets.len()]);
        let mut cell = None;
        let (origin, dir, weight) = match (light.kind, aim) {
            (LightKind::Point { position }, Some(aim)) => {
                let (dir, solid_angle) = sample_cones(fixed_cones(aim)?, rng);
                (position, dir, solid_angle)
            }
            (
                LightKind::Spot {
                    position,
                    axis: spot_axis,
                    omc_outer,
                    omc_inner,
                },
                Some(aim),
            ) => {
                let (dir, solid_angle) = sample_cones(fixed_cones(aim)?, rng);
                let falloff =
                    spot_falloff(one_minus_cos_between(dir, spot_axis), omc_outer, omc_inner);
                if !(falloff > 0.0) {
                    return None;
                }
                (position, dir, solid_angle * falloff)
            }
            (
                LightKind::Distant {
                    dir,
                    center,
                    radius,
                },
                Some(_),
            ) => {
                // The unaimed photons' start plane: one radius behind the scene sphere's
                // centre, facing `dir`.
                let (origin, area) = sample_discs(targets, dir, center - dir * radius, rng);
                (origin, dir, area)
            }
            (LightKind::Area { tri }, Some(aim)) => {
                let t = &tris[tri as usize];
                let (b1, b2) = uniform_triangle(rng.next_2d());
                let p = t.v0 + t.e1 * b1 + t.e2 * b2;
                let mut cones = [(Vec3::ZERO, 0.0); MAX_TARGETS];
                let n = cones_to(targets, p, aim.front, &mut cones)?;
                if n == 0 {
                    return None;
                }
                let (dir, solid_angle) = sample_cones(&cones[..n], rng);
                // Radiance × cos θ over the triangle and the cones (all in front of it).
                let cos = dir.dot(t.normal);
                if !(cos > 0.0) {
                    return None;
                }
                let origin = accel.offset(p, t.normal, dir);
                (origin, dir, t.area * solid_angle * cos)
            }
            (LightKind::Environment { center, radius }, Some(_)) => {
                // As unaimed, but from the spheres' shadow discs on the start plane.
                let dir = uniform_sphere(rng.next_2d());
                let (origin, area) = sample_discs(targets, dir, center - dir * radius, rng);
                (origin, dir, 4.0 * PI * area)
            }
            (kind, None) if cells.is_some_and(|c| c.learns(li)) => {
                let cells = cells?;
                let (origin, dir, weight, c) = match cells.sample(li, rng) {
                    Some(s) => {
                        let (origin, dir, weight) = Self::emit_at(&kind, s.u, true);
                        (origin, dir, weight * s.factor, s.cell)
                    }
                    // As unaimed (the same draws), the photon's cell found after.
                    None => {
                        let u = rng.next_2d();
                        let (origin, dir, weight) = Self::emit_at(&kind, u, false);
                        let cell = match kind {
                            LightKind::Distant {
                                dir,
                                center,
                                radius,
                            } => adaptive::cell_of(adaptive::square_point(
                                dir,
                                radius,
                                origin - (center - dir * radius),
                            )),
                            _ => adaptive::cell_of(u),
                        };
                        (origin, dir, weight, cell)
                    }
                };
                cell = Some(c);
                (origin, dir, weight)
            }
            (kind, _) => Self::emit_unaimed(&kind, tris, accel, rng),
        };
        flux.clear();
        flux.extend_from_slice(&light.spectrum);
        spd::scale(flux, weight / (pmf * photons as f32));
        Some(PhotonStart {
            origin,
            dir,
            light: li,
            cell,
        })
    }

    /// A learning light's photon ([`adaptive::learns`]: a distant light, a point light or
    /// a spot) from the point `u` of its emission square, as [`Self::emit_unaimed`]
    /// places it (a distant light from its disc), or with `square` from a distant
    /// light's start square ([`adaptive::square_start`]).
    #[inline(always)]
    fn emit_at(kind: &LightKind, u: [f32; 2], square: bool) -> (Vec3, Vec3, f32) {
        use std::f32::consts::PI;
        match *kind {
            LightKind::Point { position } => (position, uniform_sphere(u), 4.0 * PI),
            LightKind::Spot {
                position,
                axis,
                omc_outer,
                omc_inner,
            } => {
                let dir = uniform_cone(axis, omc_outer, u);
                let solid_angle = 2.0 * PI * omc_outer;
                let falloff = spot_falloff(one_minus_cos_between(dir, axis), omc_outer, omc_inner);
                (position, dir, solid_angle * falloff)
            }
            LightKind::Distant {
                dir,
                center,
                radius,
            } if square => {
                let (origin, area) = adaptive::square_start(dir, center, radius, u);
                (origin, dir, area)
            }
            LightKind::Distant {
                dir,
                center,
                radius,
            } => {
                // A disc of the bounding sphere's radius, one radius behind its centre.
                let origin = center - dir * radius + disc_point(dir, radius, u);
                (origin, dir, PI * radius * radius)
            }
            // Not learning lights: emitted by `emit_unaimed`.
            LightKind::Area { .. } | LightKind::Environment { .. } => (Vec3::ZERO, Vec3::Z, 0.0),
        }
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
            LightKind::Point { .. } | LightKind::Spot { .. } | LightKind::Distant { .. } => {
                Self::emit_at(kind, rng.next_2d(), false)
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
        // A point light, a spot tilted so that the target sits on its falloff ramp, a sun,
        // an emissive triangle tilted away from the target (so that the cosine varies over
        // the cone, and across the triangle the cone itself), and the sky, each with a
        // sphere off to one side. Unaimed, the flux of the photons whose ray meets the
        // sphere estimates what enters it; aimed, every photon meets it (checked) and their
        // flux must estimate the same, from far fewer photons.
        use crate::sampling::{Purpose, Rng};
        let target = Target {
            center: Vec3::new(0.4, -1.0, 0.3),
            radius: 0.25,
        };
        // Then three targets: the first, one behind it as the lights see it (their cones
        // and discs overlap), and a small one up behind the area light's back.
        let three = [
            target,
            Target {
                center: Vec3::new(0.55, -1.4, 0.35),
                radius: 0.2,
            },
            Target {
                center: Vec3::new(0.0, 0.6, 0.0),
                radius: 0.1,
            },
        ];
        let meets = |targets: &[Target], o: Vec3, d: Vec3| {
            targets.iter().any(|target| {
                let oc = target.center - o;
                let t = oc.dot(d);
                t > 0.0 && (oc - d * t).length_squared() <= target.radius * target.radius * 1.0001
            })
        };
        let spot = LightKind::Spot {
            position: Vec3::ZERO,
            axis: Vec3::new(0.45, -1.0, 0.0).normalize(),
            omc_outer: crate::sampling::one_minus_cos(40f32.to_radians()),
            omc_inner: crate::sampling::one_minus_cos(10f32.to_radians()),
        };
        // A 0.6-wide triangle about the origin, facing down but tilted 40° away from the
        // target (which it sees 63° off its normal from its centroid).
        let (v0, v1, v2) = (
            Vec3::new(-0.3, 0.0, -0.2),
            Vec3::new(0.3, 0.0, -0.2),
            Vec3::new(0.0, 0.0, 0.4),
        );
        let (e1, e2) = (v1 - v0, v2 - v0);
        let tilt = glam::Quat::from_rotation_z(-40f32.to_radians());
        let (e1, e2) = (tilt * e1, tilt * e2);
        let normal = e1.cross(e2).normalize();
        assert!(normal.y < 0.0 && normal.dot(target.center - v0) > target.radius);
        let tri = TriData {
            v0,
            e1,
            e2,
            normal,
            area: 0.5 * e1.cross(e2).length(),
            material: 0,
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
            ("area", LightKind::Area { tri: 0 }),
            (
                "sky",
                LightKind::Environment {
                    center: Vec3::new(0.0, -1.0, 0.0),
                    radius: 2.0,
                },
            ),
        ];
        let accel = Accel::new(&[]);
        let tris = [tri];
        for ((name, kind), targets) in kinds
            .iter()
            .flat_map(|k| [(k, &three[..1]), (k, &three[..])])
        {
            let light = Light {
                kind: *kind,
                spectrum: vec![1.0],
                power: 1.0,
            };
            let mut set = LightSet::new(vec![light], &tris);
            set.aim_at(targets, &tris);
            assert!(set.aims(), "{name} should aim");
            let total = |aimed: bool, photons: usize| {
                let (mut sum, mut left, mut met) = (0.0f64, 0usize, 0usize);
                let mut flux = Vec::new();
                for i in 0..photons {
                    let mut rng = Rng::stream(3, 1, i as u64, Purpose::Photon);
                    if let Some(PhotonStart {
                        origin: o, dir: d, ..
                    }) = set.emit_into(&tris, &accel, photons, aimed, None, &mut rng, &mut flux)
                    {
                        left += 1;
                        if meets(targets, o, d) {
                            sum += f64::from(flux[0]);
                            met += 1;
                        }
                    }
                }
                (sum, left, met)
            };
            // 8 M unaimed photons put the reference within 0.3 % (1σ; 1.3 % of them meet
            // the first target from the point light, 0.5 % from the sky).
            let (unaimed, _, _) = total(false, 8_000_000);
            let (aimed, left, met) = total(true, 100_000);
            let rel = aimed / unaimed - 1.0;
            println!(
                "{name}, {} targets: into them {unaimed:.5} unaimed, {aimed:.5} aimed ({rel:+.4}), {met} of {left} aimed photons met one, share {:.4}",
                targets.len(),
                set.share(0)
            );
            assert!(
                rel.abs() < 0.01,
                "{name}, {} targets: aimed {aimed} against unaimed {unaimed}",
                targets.len()
            );
            // Every photon that leaves meets a target; only the spot's, aimed where its
            // falloff is zero, do not leave.
            assert_eq!(met, left, "{name}: aimed photons missed the targets");
            assert!(*name == "spot" || left == 100_000, "{name}: {left} left");
        }
    }

    #[test]
    fn aimed_photons_are_shared_among_lights_by_pmf_times_root_share() {
        // A point light (aims: share s < 1) and an area light whose plane cuts the target
        // (does not aim: share 1). The aimed photons go p·√s : p·1, and unaimed photons
        // of the area light keep their own weights.
        let target = Target {
            center: Vec3::new(0.0, -2.0, 0.0),
            radius: 0.25,
        };
        let (e1, e2) = (Vec3::new(0.0, 0.0, 1.0), Vec3::new(1.0, 0.0, 0.0));
        let tri = TriData {
            v0: Vec3::new(-0.5, -2.0, -0.5),
            e1,
            e2,
            normal: e1.cross(e2).normalize(),
            area: 0.5,
            material: 0,
        };
        let lights = vec![
            Light {
                kind: LightKind::Point {
                    position: Vec3::ZERO,
                },
                spectrum: vec![1.0],
                power: 3.0,
            },
            Light {
                kind: LightKind::Area { tri: 0 },
                spectrum: vec![1.0],
                power: 1.0,
            },
        ];
        let tris = [tri];
        let mut set = LightSet::new(lights, &tris);
        set.aim_at(&[target], &tris);
        assert!(set.aims());
        let s = set.share(0);
        assert!(s > 0.0 && s < 0.01, "the point light's share {s}");
        assert_eq!(set.share(1), 1.0, "the area light cuts the target");
        let (p0, p1) = (set.emit_pmf(0), set.emit_pmf(1));
        let w = [f64::from(p0) * f64::from(s).sqrt(), f64::from(p1)];
        let sum = w[0] + w[1];
        assert!((set.aimed_count() - sum).abs() < 1e-6);
        for (i, wi) in w.iter().enumerate() {
            assert!((f64::from(set.aimed_pmf(i)) - wi / sum).abs() < 1e-6);
        }
        // Drawn: the aimed photons' lights follow those probabilities (χ² on 2 cells).
        let accel = Accel::new(&[]);
        let mut counts = [0usize; 2];
        let mut flux = Vec::new();
        let n = 200_000;
        for i in 0..n {
            let mut rng =
                crate::sampling::Rng::stream(5, 1, i as u64, crate::sampling::Purpose::Photon);
            if let Some(start) = set.emit_into(&tris, &accel, n, true, None, &mut rng, &mut flux) {
                counts[start.light] += 1;
            }
        }
        let drawn = (counts[0] + counts[1]) as f64;
        let chi2: f64 = (0..2)
            .map(|i| {
                let e = drawn * f64::from(set.aimed_pmf(i));
                (counts[i] as f64 - e).powi(2) / e
            })
            .sum();
        assert!(chi2 < 10.8, "χ² {chi2} (1 dof, p = 0.001): {counts:?}");
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
