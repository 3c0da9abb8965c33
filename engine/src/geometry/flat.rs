//! Small scenes without a BVH: every triangle tested, four at a time.
//!
//! obvhs' CWBVH spends most of a ray in its node tests (decoding eight quantised child
//! boxes per node): a ray through the 36-triangle Cornell box costs about 130 ns for 3
//! nodes and 3 triangle tests, the 14-triangle prism about 60 ns for 1 node and 1 test.
//! Testing every triangle of so small a scene in blocks of four, one SIMD lane each, costs
//! less than those node tests (measured in BENCHMARKS.md, session 27). The arithmetic per
//! lane is `RtTriangle::intersect`'s, operation for operation, so a lane returns the same
//! bits as that test on the same triangle.

use glam::{Vec3A, Vec4};
use obvhs::{ray::Ray, rt_triangle::RtTriangle};

/// Four triangles' `RtTriangle` fields, one lane each, by component.
#[derive(Clone, Copy)]
struct Block {
    v0: [Vec4; 3],
    e1: [Vec4; 3],
    e2: [Vec4; 3],
    ng: [Vec4; 3],
    /// Lanes that hold a triangle (the last block may be partly empty).
    lanes: u32,
}

/// Triangles in blocks of four (in the order given).
pub(super) struct Flat {
    blocks: Vec<Block>,
}

/// A ray: origin, direction and the interval [tmin, tmax] a hit must lie in (an obvhs
/// `Ray` without the reciprocal direction its box tests need).
#[derive(Clone, Copy, Debug)]
pub(super) struct FlatRay {
    pub origin: Vec3A,
    pub direction: Vec3A,
    pub tmin: f32,
    pub tmax: f32,
}

impl From<&Ray> for FlatRay {
    fn from(r: &Ray) -> Self {
        Self {
            origin: r.origin,
            direction: r.direction,
            tmin: r.tmin,
            tmax: r.tmax,
        }
    }
}

/// A ray's origin and direction, each component broadcast to four lanes.
struct Wide {
    o: [Vec4; 3],
    d: [Vec4; 3],
    tmin: Vec4,
}

impl Wide {
    #[inline(always)]
    fn new(ray: &FlatRay) -> Self {
        let (o, d) = (ray.origin, ray.direction);
        Self {
            o: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            d: [Vec4::splat(d.x), Vec4::splat(d.y), Vec4::splat(d.z)],
            tmin: Vec4::splat(ray.tmin),
        }
    }
}

impl Flat {
    pub(super) fn new(tris: &[RtTriangle]) -> Self {
        let lane = |v: Vec3A, c: usize| v.to_array()[c];
        let blocks = tris
            .chunks(4)
            .map(|chunk| {
                let pick = |field: fn(&RtTriangle) -> Vec3A| {
                    [0, 1, 2].map(|c| {
                        Vec4::from_array(
                            [0, 1, 2, 3].map(|i| chunk.get(i).map_or(0.0, |t| lane(field(t), c))),
                        )
                    })
                };
                Block {
                    v0: pick(|t| t.v0),
                    e1: pick(|t| t.e1),
                    e2: pick(|t| t.e2),
                    ng: pick(|t| t.ng),
                    lanes: (1u32 << chunk.len()) - 1,
                }
            })
            .collect();
        Self { blocks }
    }

    pub(super) fn memory_bytes(&self) -> usize {
        self.blocks.len() * std::mem::size_of::<Block>()
    }

    /// The closest hit within [tmin, tmax] as (t, triangle index), skipping hits that
    /// `keep(index, t)` refuses (cut-outs); of equally near hits the lowest index wins.
    #[inline]
    pub(super) fn closest(
        &self,
        ray: &FlatRay,
        keep: impl Fn(usize, f32) -> bool,
    ) -> Option<(f32, usize)> {
        let w = Wide::new(ray);
        // Every block is tested against the ray's own tmax, not the nearest hit so far:
        // the blocks' tests then do not wait on each other (the division's latency
        // overlaps), and the nearer-than-best test below is the same comparison.
        let tmax = Vec4::splat(ray.tmax);
        let mut best = ray.tmax;
        let mut found = None;
        for (b, block) in self.blocks.iter().enumerate() {
            let (mut mask, t) = block.test(&w, tmax);
            if mask == 0 {
                continue;
            }
            let t = t.to_array();
            while mask != 0 {
                let i = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                if t[i] < best && keep(4 * b + i, t[i]) {
                    best = t[i];
                    found = Some((t[i], 4 * b + i));
                }
            }
        }
        found
    }

    /// Whether any triangle is hit within [tmin, tmax] that `keep(index, t)` accepts.
    #[inline]
    pub(super) fn any(&self, ray: &FlatRay, keep: impl Fn(usize, f32) -> bool) -> bool {
        let w = Wide::new(ray);
        let tmax = Vec4::splat(ray.tmax);
        for (b, block) in self.blocks.iter().enumerate() {
            let (mut mask, t) = block.test(&w, tmax);
            if mask == 0 {
                continue;
            }
            let t = t.to_array();
            while mask != 0 {
                let i = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                // Strictly before tmax, as obvhs' any-hit traversal counts a hit.
                if t[i] < ray.tmax && keep(4 * b + i, t[i]) {
                    return true;
                }
            }
        }
        false
    }
}

impl Block {
    /// `RtTriangle::intersect` in each lane: the lanes hit within [tmin, tmax] as a bit
    /// mask, and their distances.
    #[inline(always)]
    fn test(&self, w: &Wide, tmax: Vec4) -> (u32, Vec4) {
        let [ox, oy, oz] = w.o;
        let [dx, dy, dz] = w.d;
        // c = v0 − o; r = d × c (glam's cross: each lane a·b − c·d, in this order).
        let (cx, cy, cz) = (self.v0[0] - ox, self.v0[1] - oy, self.v0[2] - oz);
        let rx = dy * cz - cy * dz;
        let ry = dz * cx - cz * dx;
        let rz = dx * cy - cx * dy;
        // Dot products as glam's: (x + y) + z.
        let dot = |a: [Vec4; 3], b: [Vec4; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let inv_det = Vec4::ONE / dot(self.ng, [dx, dy, dz]);
        let r = [rx, ry, rz];
        let u = dot(r, self.e2) * inv_det;
        let v = dot(r, self.e1) * inv_det;
        let w_ = Vec4::ONE - u - v;
        // Valid: a non-zero 1/det and no sign bit among u, v, w (a −0.0 misses, as there).
        let signs = u.is_negative_bitmask() | v.is_negative_bitmask() | w_.is_negative_bitmask();
        let nonzero = inv_det.cmpne(Vec4::ZERO).bitmask();
        let t = dot(self.ng, [cx, cy, cz]) * inv_det;
        let within = (t.cmpge(w.tmin) & t.cmple(tmax)).bitmask();
        (nonzero & !signs & within & self.lanes, t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Purpose, Rng, uniform_sphere};
    use obvhs::triangle::Triangle;

    fn random_tris(n: usize, rng: &mut Rng) -> Vec<RtTriangle> {
        let mut p =
            || Vec3A::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3A::ONE;
        (0..n)
            .map(|_| {
                let (v0, v1, v2) = (p(), p(), p());
                RtTriangle::from(&Triangle { v0, v1, v2 })
            })
            .collect()
    }

    #[test]
    fn every_lane_returns_the_scalar_tests_bits() {
        let mut rng = Rng::stream(7, 0, 0, Purpose::Photon);
        for n in [1, 2, 3, 4, 5, 7, 8, 13, 36] {
            let mut tris = random_tris(n, &mut rng);
            // Hard cases: a degenerate triangle, one in the ray's plane, a shared edge.
            tris.push(RtTriangle::from(&Triangle {
                v0: Vec3A::ZERO,
                v1: Vec3A::X,
                v2: Vec3A::X * 2.0,
            }));
            tris.push(RtTriangle::from(&Triangle {
                v0: Vec3A::ZERO,
                v1: Vec3A::X,
                v2: Vec3A::Y,
            }));
            tris.push(RtTriangle::from(&Triangle {
                v0: Vec3A::X,
                v1: Vec3A::Y,
                v2: Vec3A::ONE,
            }));
            let flat = Flat::new(&tris);
            for k in 0..4000 {
                let o = Vec3A::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 3.0
                    - Vec3A::splat(1.5);
                let d = Vec3A::from(uniform_sphere(rng.next_2d()));
                // Some rays run along the z = 0 plane, through the shared edge's ends.
                let (o, d) = match k % 4 {
                    0 => (
                        Vec3A::new(o.x, o.y, 0.0),
                        Vec3A::new(d.x, d.y, 0.0).normalize(),
                    ),
                    1 => (o, (Vec3A::new(0.5, 0.5, 0.0) - o).normalize()),
                    _ => (o, d),
                };
                let tmax = if k % 3 == 0 { 1.0 } else { f32::INFINITY };
                let obvhs_ray = Ray::new(o, d, 1e-4, tmax);
                let scalar: Vec<f32> = tris.iter().map(|t| t.intersect(&obvhs_ray)).collect();
                let ray = FlatRay::from(&obvhs_ray);
                let w = Wide::new(&ray);
                for (b, block) in flat.blocks.iter().enumerate() {
                    let (mask, t) = block.test(&w, Vec4::splat(ray.tmax));
                    for i in 0..4 {
                        let Some(&s) = scalar.get(4 * b + i) else {
                            assert_eq!(mask >> i & 1, 0, "an empty lane hit");
                            continue;
                        };
                        let hit = mask >> i & 1 == 1;
                        assert_eq!(hit, s.is_finite(), "n {n} ray {k} tri {}", 4 * b + i);
                        if hit {
                            assert_eq!(t[i].to_bits(), s.to_bits(), "n {n} ray {k}");
                        }
                    }
                }
                // The closest hit is the scalar minimum, the lowest index on a tie.
                let expected = scalar
                    .iter()
                    .enumerate()
                    .filter(|(_, t)| t.is_finite())
                    .fold(None, |best: Option<(f32, usize)>, (i, &t)| match best {
                        Some((b, _)) if b <= t => best,
                        _ => Some((t, i)),
                    });
                let got = flat.closest(&ray, |_, _| true);
                assert_eq!(
                    got.map(|(t, i)| (t.to_bits(), i)),
                    expected.map(|(t, i)| (t.to_bits(), i))
                );
                let any = scalar.iter().any(|&t| t < ray.tmax);
                assert_eq!(flat.any(&ray, |_, _| true), any);
                // A filter refusing the nearest finds the next.
                if let Some((_, near)) = expected {
                    let next = scalar
                        .iter()
                        .enumerate()
                        .filter(|&(i, t)| i != near && t.is_finite())
                        .map(|(_, t)| *t)
                        .fold(f32::INFINITY, f32::min);
                    let got = flat.closest(&ray, |i, _| i != near);
                    assert_eq!(got.map(|g| g.0).unwrap_or(f32::INFINITY), next);
                }
            }
        }
    }
}
