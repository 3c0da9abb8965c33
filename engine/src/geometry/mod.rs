//! Rays, triangles and the `obvhs` CWBVH that finds them (or, in scenes of a few dozen
//! triangles, a SIMD test of every triangle: [`flat`]).

mod flat;

use glam::{Vec3, Vec3A};
use obvhs::{
    BvhBuildParams, cwbvh::CwBvh, ray::RayHit, rt_triangle::RtTriangle, triangle::Triangle,
};
use std::time::Duration;

/// A hit: distance along the ray and the index of the triangle (in scene order).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub prim: u32,
}

/// obvhs' CWBVH node test ignores the ray's t_min and culls every child box the ray
/// leaves before t = 1e-4 (`cwbvh::node::EPSILON`, in the ray's parameter): a triangle
/// nearer than that to a ray's origin was never hit. Rays start within that of a wall at
/// every corner of a room (a shadow ray from a wall 6·10⁻⁵ below the ceiling passed through
/// it and lit the inside of a closed box), and in a scene modelled at millimetre scale it
/// is a tenth of the scene. So every ray starts [`BACK_OFF`] behind its origin with t_min =
/// [`BACK_OFF`]: the node test then passes the near boxes, the triangle test (which does
/// honour t_min) still refuses anything behind the true origin.
const BACK_OFF: f32 = 2e-4;

/// An obvhs ray from `origin` along `dir` over t in [0, `t_max`], backed off (see
/// [`BACK_OFF`]); the hits' t then count from `origin - BACK_OFF·dir`.
#[inline]
fn backed_off_ray(origin: Vec3, dir: Vec3, t_max: f32) -> obvhs::ray::Ray {
    let r = backed_off_flat_ray(origin, dir, t_max);
    obvhs::ray::Ray::new(r.origin, r.direction, r.tmin, r.tmax)
}

/// [`backed_off_ray`] without the reciprocal direction (which only the BVH's box tests
/// need): the same origin, direction and interval, so the same triangle tests.
#[inline]
fn backed_off_flat_ray(origin: Vec3, dir: Vec3, t_max: f32) -> flat::FlatRay {
    let dir = positive_zeros(dir);
    let start = Vec3A::from(origin) - Vec3A::from(dir) * BACK_OFF;
    flat::FlatRay {
        origin: start,
        direction: Vec3A::from(dir),
        tmin: BACK_OFF,
        tmax: t_max + BACK_OFF,
    }
}

/// `dir` with every −0.0 component made +0.0: obvhs' traversal misses everything along a
/// ray with a negative-zero component (a sun shining straight down along (−0, −1, −0)
/// lit nothing).
#[inline]
fn positive_zeros(dir: Vec3) -> Vec3 {
    dir + Vec3::ZERO
}

/// A triangle with what shading needs precomputed.
#[derive(Clone, Copy, Debug)]
pub struct TriData {
    pub v0: Vec3,
    pub e1: Vec3,
    pub e2: Vec3,
    /// Unit geometric normal (front face: counter-clockwise winding).
    pub normal: Vec3,
    pub area: f32,
    pub material: u32,
}

impl TriData {
    /// Barycentric coordinates (b1, b2) of a point in the triangle's plane: p = v0 +
    /// b1·e1 + b2·e2.
    #[inline]
    pub fn barycentric(&self, p: Vec3) -> (f32, f32) {
        let d = p - self.v0;
        let (d00, d01, d11) = (
            self.e1.dot(self.e1),
            self.e1.dot(self.e2),
            self.e2.dot(self.e2),
        );
        let (d20, d21) = (d.dot(self.e1), d.dot(self.e2));
        let denom = d00 * d11 - d01 * d01;
        if !(denom.abs() > 0.0) {
            return (0.0, 0.0);
        }
        (
            (d11 * d20 - d01 * d21) / denom,
            (d00 * d21 - d01 * d20) / denom,
        )
    }
}

/// Where a ray met a surface, with the normals shading needs: the one surface-hit type of
/// the photon tracer and the gather.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceHit {
    pub p: Vec3,
    /// Geometric normal (front face: counter-clockwise winding).
    pub n: Vec3,
    /// `n` turned towards the side the ray came from.
    pub nf: Vec3,
    /// Whether the ray hit the front face.
    pub front: bool,
    /// Distance along the ray.
    pub t: f32,
    /// Barycentric coordinates (b1, b2) of the hit in its triangle.
    pub bary: (f32, f32),
    /// The triangle's index in scene order.
    pub prim: u32,
    /// The interpolated shading normal turned to the same side as `nf` (equal to `nf` on
    /// flat-shaded triangles).
    pub ns: Vec3,
    pub material: u32,
}

impl SurfaceHit {
    /// The hit of the ray `origin + t·dir` with `tri` at distance `t`; `shading` holds
    /// the triangle's vertex normals, if it has them.
    #[inline]
    pub fn new(
        tri: &TriData,
        shading: Option<&[Vec3; 3]>,
        origin: Vec3,
        dir: Vec3,
        t: f32,
    ) -> Self {
        let n = tri.normal;
        let front = dir.dot(n) < 0.0;
        let p = origin + dir * t;
        let nf = if front { n } else { -n };
        let bary = tri.barycentric(p);
        let ns = match shading {
            Some(vn) => {
                let (b1, b2) = bary;
                let s = (vn[0] * (1.0 - b1 - b2) + vn[1] * b1 + vn[2] * b2).normalize_or_zero();
                // Turned to the geometric side the ray came from; a degenerate blend is flat.
                let s = if s.dot(nf) < 0.0 { -s } else { s };
                if s == Vec3::ZERO || !s.is_finite() {
                    nf
                } else {
                    s
                }
            }
            None => nf,
        };
        Self {
            p,
            n,
            nf,
            front,
            t,
            bary,
            prim: 0,
            ns,
            material: tri.material,
        }
    }
}

/// Scenes of at most this many triangles are searched without a BVH, every triangle
/// tested eight at a time ([`flat::Flat`]): cheaper than the CWBVH's node tests up to about
/// 100 triangles on CPUs without AVX and about 200 with it (BENCHMARKS.md, session 27).
/// One cut for every CPU, so that a scene is searched the same way (and renders the same
/// image) on any machine.
pub const FLAT_MAX_TRIANGLES: usize = 64;

/// The scene's triangles in a compressed wide BVH (obvhs' CWBVH, medium build), or for
/// scenes of at most [`FLAT_MAX_TRIANGLES`], in blocks of eight tested all at once.
pub struct Accel {
    bvh: CwBvh,
    /// The small scene's blocks (then `bvh` and `tris` are empty: the blocks hold the
    /// triangles, in scene order).
    flat: Option<flat::Flat>,
    /// Triangles in BVH leaf order (so leaves index them directly), with their edges and
    /// normal precomputed: `RtTriangle::intersect` is `Triangle::intersect`'s arithmetic
    /// (e1 = v0 − v1, e2 = v2 − v0, n = e1 × e2) without recomputing them per test, so the
    /// same hits to the bit.
    tris: Vec<RtTriangle>,
    /// BVH order → scene triangle index (the identity in a flat scene).
    ids: Vec<u32>,
    /// Scene bounds' diagonal length, for ray offsets.
    diagonal: f32,
    /// Triangles with holes (glTF alphaMode MASK or BLEND), if any: see [`Cutouts`].
    cutouts: Option<(Vec<bool>, std::sync::Arc<dyn Cutouts>)>,
}

/// Where triangles have holes: a ray passes through triangle `prim` (scene order) at the
/// point `p` on it when `passes` says so (glTF's alpha cut-outs, for leaves and fences,
/// and blending, which `passes` decides at random, as a pure function of `prim` and `p`).
/// Both closest-hit and shadow rays ask it, during traversal.
pub trait Cutouts: Send + Sync {
    fn passes(&self, prim: u32, p: Vec3) -> bool;
}

impl Accel {
    /// Builds the BVH (blocks of eight for a scene of at most [`FLAT_MAX_TRIANGLES`]).
    /// `triangles` must be non-degenerate and finite (the loader ensures it).
    pub fn new(triangles: &[[Vec3; 3]]) -> Self {
        Self::with_flat_max(triangles, FLAT_MAX_TRIANGLES)
    }

    /// [`Self::new`] with the BVH used above `flat_max` triangles (0: always; for tests and
    /// benchmarks comparing the two).
    pub fn with_flat_max(triangles: &[[Vec3; 3]], flat_max: usize) -> Self {
        let input: Vec<Triangle> = triangles
            .iter()
            .map(|t| Triangle {
                v0: t[0].into(),
                v1: t[1].into(),
                v2: t[2].into(),
            })
            .collect();
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for t in triangles {
            for v in t {
                lo = lo.min(*v);
                hi = hi.max(*v);
            }
        }
        let diagonal = if triangles.is_empty() {
            1.0
        } else {
            (hi - lo).length().max(1e-6)
        };
        if input.is_empty() {
            return Self {
                bvh: CwBvh::default(),
                flat: None,
                tris: Vec::new(),
                ids: Vec::new(),
                diagonal,
                cutouts: None,
            };
        }
        if input.len() <= flat_max {
            let tris: Vec<RtTriangle> = input.iter().map(RtTriangle::from).collect();
            return Self {
                bvh: CwBvh::default(),
                flat: Some(flat::Flat::new(&tris)),
                tris: Vec::new(),
                ids: (0..input.len() as u32).collect(),
                diagonal,
                cutouts: None,
            };
        }
        let bvh = obvhs::cwbvh::builder::build_cwbvh_from_tris(
            &input,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        let ids = bvh.primitive_indices.clone();
        let tris = ids
            .iter()
            .map(|&i| RtTriangle::from(&input[i as usize]))
            .collect();
        Self {
            bvh,
            flat: None,
            tris,
            ids,
            diagonal,
            cutouts: None,
        }
    }

    /// Whether rays search a BVH (false: the scene is small, its triangles all tested).
    pub fn uses_bvh(&self) -> bool {
        self.flat.is_none() && !self.ids.is_empty()
    }

    /// Gives the triangles flagged in `holed` (scene order) holes where `cutouts` says.
    pub fn set_cutouts(&mut self, holed: &[bool], cutouts: std::sync::Arc<dyn Cutouts>) {
        let by_leaf: Vec<bool> = self
            .ids
            .iter()
            .map(|&i| holed.get(i as usize).copied().unwrap_or(false))
            .collect();
        self.cutouts = by_leaf.iter().any(|&h| h).then_some((by_leaf, cutouts));
    }

    /// Triangle `id` (BVH order) against `r`: its distance, or ∞ for a miss or a hole.
    #[inline(always)]
    fn test(&self, r: &obvhs::ray::Ray, id: usize) -> f32 {
        let t = self.tris[id].intersect(r);
        if t.is_finite() && self.holed_at(r.origin, r.direction, id, t) {
            f32::INFINITY
        } else {
            t
        }
    }

    /// Whether the ray from `origin` along `dir` passes through a hole of triangle `id`
    /// (BVH order) where it hits it, at distance `t`.
    #[inline(always)]
    fn holed_at(&self, origin: Vec3A, dir: Vec3A, id: usize, t: f32) -> bool {
        match &self.cutouts {
            Some((holed, cut)) if holed[id] => {
                let p = Vec3::from(origin + dir * t);
                cut.passes(self.ids[id], p)
            }
            _ => false,
        }
    }

    pub fn diagonal(&self) -> f32 {
        self.diagonal
    }

    /// Closest hit with t in (0, `t_max`).
    #[inline]
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<Hit> {
        if self.ids.is_empty() {
            return None;
        }
        if let Some(flat) = &self.flat {
            let r = backed_off_flat_ray(origin, dir, t_max);
            return flat
                .closest(&r, |id, t| !self.holed_at(r.origin, r.direction, id, t))
                .map(|(t, id)| Hit {
                    t: (t - BACK_OFF).max(0.0),
                    prim: self.ids[id],
                });
        }
        let ray = backed_off_ray(origin, dir, t_max);
        let mut hit = RayHit::none();
        if self
            .bvh
            .ray_traverse(ray, &mut hit, |r, id| self.test(r, id))
        {
            Some(Hit {
                t: (hit.t - BACK_OFF).max(0.0),
                prim: self.ids[hit.primitive_id as usize],
            })
        } else {
            None
        }
    }

    /// Whether anything lies between `origin` and `origin + dir·t_max`.
    #[inline]
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_max: f32) -> bool {
        if self.ids.is_empty() {
            return false;
        }
        if let Some(flat) = &self.flat {
            let r = backed_off_flat_ray(origin, dir, t_max);
            return flat.any(&r, |id, t| !self.holed_at(r.origin, r.direction, id, t));
        }
        let ray = backed_off_ray(origin, dir, t_max);
        !self.bvh.ray_traverse_miss(ray, |r, id| self.test(r, id))
    }

    /// Moves `p` off a surface with normal `n` to the side of `dir`, by an amount that grows
    /// with the magnitude of `p` (f32 spacing) and with the scene's size.
    #[inline]
    pub fn offset(&self, p: Vec3, n: Vec3, dir: Vec3) -> Vec3 {
        let eps = 1e-6 * self.diagonal + 4e-6 * p.abs().max_element();
        if n.dot(dir) >= 0.0 {
            p + n * eps
        } else {
            p - n * eps
        }
    }

    /// Bytes of the BVH: nodes, index map and leaf triangles.
    pub fn memory_bytes(&self) -> usize {
        self.bvh.nodes.len() * std::mem::size_of::<obvhs::cwbvh::node::CwBvhNode>()
            + self.bvh.primitive_indices.len() * 4
            + self.tris.len() * std::mem::size_of::<RtTriangle>()
            + self.ids.len() * 4
            + self.flat.as_ref().map_or(0, flat::Flat::memory_bytes)
    }
}

/// Twice the area and the unit normal of a triangle (normal is zero if degenerate).
pub fn triangle_normal(t: &[Vec3; 3]) -> (f32, Vec3) {
    let c = (t[1] - t[0]).cross(t[2] - t[0]);
    let len = c.length();
    if len > 0.0 && len.is_finite() {
        (len, c / len)
    } else {
        (0.0, Vec3::ZERO)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_aligned_rays_with_negative_zero_components_hit() {
        let floor = [
            [
                Vec3::new(-2.0, 0.0, -2.0),
                Vec3::new(-2.0, 0.0, 2.0),
                Vec3::new(2.0, 0.0, 2.0),
            ],
            [
                Vec3::new(-2.0, 0.0, -2.0),
                Vec3::new(2.0, 0.0, 2.0),
                Vec3::new(2.0, 0.0, -2.0),
            ],
        ];
        let o = Vec3::new(0.1, 2.85, 0.2);
        for (accel, d) in both(&floor).iter().flat_map(|a| {
            [
                (a, -Vec3::Y),
                (a, Vec3::new(0.0, -1.0, 0.0)),
                (a, Vec3::new(-0.0, -1.0, 0.0)),
            ]
        }) {
            let hit = accel.intersect(o, d, f32::INFINITY);
            assert!(
                hit.is_some_and(|h| (h.t - 2.85).abs() < 1e-5),
                "{d:?}: {hit:?}"
            );
            assert!(accel.occluded(o, d, f32::INFINITY), "{d:?}");
        }
    }

    fn quad(z: f32, size: f32, offset: Vec3) -> Vec<[Vec3; 3]> {
        let a = Vec3::new(-size, -size, z) + offset;
        let b = Vec3::new(size, -size, z) + offset;
        let c = Vec3::new(size, size, z) + offset;
        let d = Vec3::new(-size, size, z) + offset;
        vec![[a, b, c], [a, c, d]]
    }

    #[test]
    fn hits_and_misses() {
        for accel in both(&quad(5.0, 1.0, Vec3::ZERO)) {
            let o = Vec3::new(0.1, 0.3, 0.0);
            let h = accel.intersect(o, Vec3::Z, f32::INFINITY).unwrap();
            assert!((h.t - 5.0).abs() < 1e-5);
            assert!(accel.intersect(o, -Vec3::Z, f32::INFINITY).is_none());
            assert!(accel.occluded(o, Vec3::Z, 6.0));
            assert!(!accel.occluded(o, Vec3::Z, 4.0));
        }
        let empty = Accel::new(&[]);
        assert!(empty.intersect(Vec3::ZERO, Vec3::Z, 1.0).is_none());
        assert!(!empty.occluded(Vec3::ZERO, Vec3::Z, 1.0));
    }

    #[test]
    fn spawned_rays_do_not_rehit_their_surface_at_any_scale() {
        // Mitsuba 3's ray-offset test configurations: (offset, scale).
        for (off, scale) in [(0.0, 1.0), (1e3, 1.0), (0.0, 1e-3), (1e4, 1e3)] {
            let o = Vec3::splat(off);
            for accel in both(&quad(0.0, scale, o)) {
                let mut fails = 0;
                for i in 0..4096 {
                    let u = (i % 64) as f32 / 64.0 - 0.5;
                    let v = (i / 64) as f32 / 64.0 - 0.5;
                    let p = o + Vec3::new(u * scale, v * scale, 0.0);
                    let dir = Vec3::new(0.3, -0.2, 1.0).normalize();
                    let q = accel.offset(p, Vec3::Z, dir);
                    if let Some(h) = accel.intersect(q, dir, f32::INFINITY)
                        && h.t < 1e-3 * scale
                    {
                        fails += 1;
                    }
                    // A receiver just above is not falsely occluded.
                    let q2 = accel.offset(p, Vec3::Z, Vec3::Z);
                    if accel.occluded(q2, Vec3::Z, 0.5 * scale) {
                        fails += 1;
                    }
                }
                assert_eq!(fails, 0, "offset {off} scale {scale}");
            }
        }
    }

    #[test]
    fn a_triangle_right_in_front_of_a_ray_is_hit_at_any_scale() {
        // obvhs' node test culls boxes the ray leaves before t = 1e-4: a ray starting
        // 6·10⁻⁵ below a ceiling (a shadow ray from a wall's top row) went through it.
        for scale in [1e-3f32, 1.0, 1e3] {
            for (accel, gap) in both(&quad(scale, scale, Vec3::ZERO))
                .iter()
                .flat_map(|a| [1e-6f32, 3e-5, 6e-5, 1e-4, 3e-4, 1e-2].map(|g| (a, g)))
            {
                let o = Vec3::new(0.1 * scale, -0.2 * scale, scale - gap * scale);
                let dir = Vec3::new(0.7, 0.1, 0.7).normalize();
                let t = gap * scale / dir.z;
                let hit = accel.intersect(o, dir, f32::INFINITY);
                assert!(
                    hit.is_some_and(|h| (h.t - t).abs() <= 1e-5 * scale + 1e-6 * t),
                    "scale {scale}, gap {gap}: {hit:?}, expected t {t}"
                );
                assert!(accel.occluded(o, dir, 2.0 * t), "scale {scale}, gap {gap}");
                assert!(!accel.occluded(o, dir, 0.5 * t), "scale {scale}, gap {gap}");
                // Nothing behind the origin is hit.
                assert!(accel.intersect(o, -dir, f32::INFINITY).is_none());
            }
        }
    }

    #[test]
    fn the_flat_blocks_find_what_the_bvh_finds_in_the_built_in_scenes() {
        use crate::sampling::{Purpose, Rng, uniform_sphere};
        for name in ["cornell-box", "prism"] {
            let tris = crate::scene::load_builtin(name).unwrap().triangles;
            let [bvh, flat] = both(&tris);
            let (lo, hi) = tris.iter().flatten().fold(
                (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
                |(lo, hi), v| (lo.min(*v), hi.max(*v)),
            );
            let mut rng = Rng::stream(3, 0, 0, Purpose::Photon);
            // Hits found by both at the same distance to the bit; others (a ray through a
            // shared edge, where the BVH's box test and the triangles' own tests round
            // differently) may differ by a few ulps or in the triangle named.
            let (mut hits, mut exact, mut occlusions_differ) = (0, 0, 0);
            for k in 0..20_000 {
                let u = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                let o = lo + (hi - lo) * (0.1 + 0.8 * u);
                let d = uniform_sphere(rng.next_2d());
                let t_max = if k % 2 == 0 {
                    f32::INFINITY
                } else {
                    0.3 * (hi - lo).length()
                };
                match (bvh.intersect(o, d, t_max), flat.intersect(o, d, t_max)) {
                    (Some(a), Some(b)) => {
                        hits += 1;
                        assert!(
                            (a.t - b.t).abs() <= 1e-5 * a.t,
                            "{name} ray {k}: {a:?} {b:?}"
                        );
                        exact += usize::from(a == b);
                    }
                    (None, None) => {}
                    (a, b) => panic!("{name} ray {k}: the BVH found {a:?}, the blocks {b:?}"),
                }
                occlusions_differ +=
                    usize::from(bvh.occluded(o, d, t_max) != flat.occluded(o, d, t_max));
            }
            assert!(hits > 5_000, "{name}: {hits} hits");
            assert!(
                exact * 1000 >= hits * 999,
                "{name}: {exact} of {hits} hits the same"
            );
            assert!(
                occlusions_differ <= 2,
                "{name}: {occlusions_differ} occlusions differ"
            );
        }
    }

    /// Holes wherever x > 0.
    struct RightHalfHoled;

    impl Cutouts for RightHalfHoled {
        fn passes(&self, _prim: u32, p: Vec3) -> bool {
            p.x > 0.0
        }
    }

    #[test]
    fn rays_pass_through_cut_outs_on_either_path() {
        // A holed quad at z = 1 (holes where x > 0) in front of a solid one at z = 2.
        let mut tris = quad(1.0, 1.0, Vec3::ZERO);
        tris.extend(quad(2.0, 1.0, Vec3::ZERO));
        for mut accel in both(&tris) {
            accel.set_cutouts(
                &[true, true, false, false],
                std::sync::Arc::new(RightHalfHoled),
            );
            for x in [-0.7f32, -0.2, 0.2, 0.7] {
                for y in [-0.5f32, 0.4] {
                    let o = Vec3::new(x, y, 0.0);
                    let holed = x > 0.0;
                    let hit = accel.intersect(o, Vec3::Z, f32::INFINITY).unwrap();
                    let (t, prims) = if holed { (2.0, [2, 3]) } else { (1.0, [0, 1]) };
                    assert!((hit.t - t).abs() < 1e-5, "x {x} y {y}: {hit:?}");
                    assert!(prims.contains(&hit.prim), "x {x} y {y}: {hit:?}");
                    assert_eq!(accel.occluded(o, Vec3::Z, 1.5), !holed, "x {x} y {y}");
                    assert!(accel.occluded(o, Vec3::Z, 2.5), "x {x} y {y}");
                }
            }
        }
    }

    /// The same triangles behind the CWBVH and in flat blocks.
    fn both(tris: &[[Vec3; 3]]) -> [Accel; 2] {
        [
            Accel::with_flat_max(tris, 0),
            Accel::with_flat_max(tris, usize::MAX),
        ]
    }

    #[test]
    fn degenerate_triangles_have_zero_area() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
        assert_eq!(triangle_normal(&t).0, 0.0);
        let t = [Vec3::ZERO, Vec3::ZERO, Vec3::ZERO];
        assert_eq!(triangle_normal(&t).1, Vec3::ZERO);
    }
}
