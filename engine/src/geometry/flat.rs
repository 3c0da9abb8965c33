//! Small scenes without a BVH: every triangle tested, eight at a time.
//!
//! obvhs' CWBVH spends most of a ray in its node tests (decoding eight quantised child
//! boxes per node): a ray through the 36-triangle Cornell box costs about 130 ns for 3
//! nodes and 3 triangle tests, the 14-triangle prism about 60 ns for 1 node and 1 test.
//! Testing every triangle of so small a scene in blocks of eight, one SIMD lane each (two
//! 4-lane halves on any x86-64 or other CPU, one 8-lane AVX register where the CPU has
//! AVX, detected at run time), costs less than those node tests (measured in
//! BENCHMARKS.md, session 27). The arithmetic per lane is `RtTriangle::intersect`'s,
//! operation for operation (fused multiply-adds exactly where glam fuses them: only in its
//! cross product, and only in a build for FMA CPUs), so every lane returns the same bits
//! as that test on the same triangle, on either path and in either build.

use glam::{Vec3A, Vec4};
#[cfg(test)]
use obvhs::ray::Ray;
use obvhs::rt_triangle::RtTriangle;

/// Lanes a block holds.
const LANES: usize = 8;

/// Eight triangles' `RtTriangle` fields, one lane each: rows v0.x, v0.y, v0.z, e1.x … ng.z.
#[derive(Clone, Copy)]
#[repr(C, align(32))]
struct Block {
    rows: [[f32; LANES]; 12],
    /// Lanes that hold a triangle (the last block may be partly empty).
    lanes: u32,
}

const V0: usize = 0;
const E1: usize = 3;
const E2: usize = 6;
const NG: usize = 9;

/// Triangles in blocks of eight (in the order given).
pub(super) struct Flat {
    blocks: Vec<Block>,
    /// Test with AVX (the CPU has it).
    avx: bool,
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

#[cfg(test)]
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

/// What a block's test found: hit lanes as a bit mask, and every lane's distance.
type Lanes = (u32, [f32; LANES]);

impl Flat {
    pub(super) fn new(tris: &[RtTriangle]) -> Self {
        let blocks = tris
            .chunks(LANES)
            .map(|chunk| {
                let mut rows = [[0.0; LANES]; 12];
                for (i, t) in chunk.iter().enumerate() {
                    for (base, v) in [(V0, t.v0), (E1, t.e1), (E2, t.e2), (NG, t.ng)] {
                        for (c, x) in v.to_array().into_iter().enumerate() {
                            rows[base + c][i] = x;
                        }
                    }
                }
                Block {
                    rows,
                    lanes: (1u32 << chunk.len()) - 1,
                }
            })
            .collect();
        Self {
            blocks,
            avx: crate::cpu::has_avx(),
        }
    }

    pub(super) fn memory_bytes(&self) -> usize {
        self.blocks.len() * std::mem::size_of::<Block>()
    }

    /// The closest hit within [tmin, tmax) as (t, triangle index), skipping hits that
    /// `keep(index, t)` refuses (cut-outs); of equally near hits the lowest index wins.
    #[inline]
    pub(super) fn closest(
        &self,
        ray: &FlatRay,
        keep: impl Fn(usize, f32) -> bool,
    ) -> Option<(f32, usize)> {
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: `avx` is set only where the CPU reports AVX.
            return unsafe { avx::closest(&self.blocks, ray, keep) };
        }
        let w = Wide::new(ray);
        closest_with(&self.blocks, ray, keep, |b| b.test(&w))
    }

    /// Whether any triangle is hit within [tmin, tmax) that `keep(index, t)` accepts.
    #[inline]
    pub(super) fn any(&self, ray: &FlatRay, keep: impl Fn(usize, f32) -> bool) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: `avx` is set only where the CPU reports AVX.
            return unsafe { avx::any(&self.blocks, ray, keep) };
        }
        let w = Wide::new(ray);
        any_with(&self.blocks, ray, keep, |b| b.test(&w))
    }
}

#[cfg(test)]
impl Flat {
    /// Every block's lanes against `ray` (on the path `self.avx` picks).
    fn lanes_of(&self, ray: &FlatRay) -> Vec<Lanes> {
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: as above.
            return unsafe { avx::lanes_of(&self.blocks, ray) };
        }
        let w = Wide::new(ray);
        self.blocks.iter().map(|b| b.test(&w)).collect()
    }
}

/// The closest accepted hit over `blocks`, each tested by `test` against the ray's own
/// tmax (so the blocks' tests do not wait on each other; the nearer-than-best comparison
/// here is the traversal's `t < tmax`).
#[inline(always)]
fn closest_with(
    blocks: &[Block],
    ray: &FlatRay,
    keep: impl Fn(usize, f32) -> bool,
    test: impl Fn(&Block) -> Lanes,
) -> Option<(f32, usize)> {
    let mut best = ray.tmax;
    let mut found = None;
    each_hit(blocks, test, |i, t| {
        if t < best && keep(i, t) {
            best = t;
            found = Some((t, i));
        }
        true
    });
    found
}

/// Whether any accepted hit lies strictly before tmax (as obvhs' any-hit traversal
/// counts one).
#[inline(always)]
fn any_with(
    blocks: &[Block],
    ray: &FlatRay,
    keep: impl Fn(usize, f32) -> bool,
    test: impl Fn(&Block) -> Lanes,
) -> bool {
    each_hit(blocks, test, |i, t| !(t < ray.tmax && keep(i, t)))
}

/// Calls `f(triangle index, t)` for every hit lane of every block, in index order, until
/// `f` returns false; returns whether it stopped there.
#[inline(always)]
fn each_hit(
    blocks: &[Block],
    test: impl Fn(&Block) -> Lanes,
    mut f: impl FnMut(usize, f32) -> bool,
) -> bool {
    for (b, block) in blocks.iter().enumerate() {
        let (mut mask, t) = test(block);
        while mask != 0 {
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            if !f(LANES * b + i, t[i]) {
                return true;
            }
        }
    }
    false
}

/// A ray's origin and direction, each component broadcast to four lanes.
struct Wide {
    o: [Vec4; 3],
    d: [Vec4; 3],
    tmin: Vec4,
    tmax: Vec4,
}

impl Wide {
    #[inline(always)]
    fn new(ray: &FlatRay) -> Self {
        let (o, d) = (ray.origin, ray.direction);
        Self {
            o: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            d: [Vec4::splat(d.x), Vec4::splat(d.y), Vec4::splat(d.z)],
            tmin: Vec4::splat(ray.tmin),
            tmax: Vec4::splat(ray.tmax),
        }
    }
}

impl Block {
    /// `RtTriangle::intersect` in each lane, as two halves of four.
    #[inline(always)]
    fn test(&self, w: &Wide) -> Lanes {
        let (lo, tlo) = self.test_half(w, 0);
        let (hi, thi) = self.test_half(w, 4);
        let mut t = [0.0; LANES];
        t[..4].copy_from_slice(&tlo.to_array());
        t[4..].copy_from_slice(&thi.to_array());
        ((lo | hi << 4) & self.lanes, t)
    }

    /// Lanes `at..at + 4`: those hit within [tmin, tmax] as a bit mask, and their distances.
    #[inline(always)]
    fn test_half(&self, w: &Wide, at: usize) -> (u32, Vec4) {
        let row = |k: usize| Vec4::from_slice(&self.rows[k][at..at + 4]);
        let [ox, oy, oz] = w.o;
        let [dx, dy, dz] = w.d;
        // c = v0 − o; r = d × c (glam's cross: each lane a·b − c·d, in this order, the
        // second product fused into the subtraction where the build targets FMA, as glam
        // does then).
        let (cx, cy, cz) = (row(V0) - ox, row(V0 + 1) - oy, row(V0 + 2) - oz);
        #[cfg(target_feature = "fma")]
        let sub_mul = |ab: Vec4, c: Vec4, d: Vec4| (-c).mul_add(d, ab);
        #[cfg(not(target_feature = "fma"))]
        let sub_mul = |ab: Vec4, c: Vec4, d: Vec4| ab - c * d;
        let rx = sub_mul(dy * cz, cy, dz);
        let ry = sub_mul(dz * cx, cz, dx);
        let rz = sub_mul(dx * cy, cx, dy);
        // Dot products as glam's: (x + y) + z.
        let dot = |a: [Vec4; 3], b: usize| a[0] * row(b) + a[1] * row(b + 1) + a[2] * row(b + 2);
        let inv_det = Vec4::ONE / dot([dx, dy, dz], NG);
        let r = [rx, ry, rz];
        let u = dot(r, E2) * inv_det;
        let v = dot(r, E1) * inv_det;
        let w_ = Vec4::ONE - u - v;
        // Valid: a non-zero 1/det and no sign bit among u, v, w (a −0.0 misses, as there).
        let signs = u.is_negative_bitmask() | v.is_negative_bitmask() | w_.is_negative_bitmask();
        let nonzero = inv_det.cmpne(Vec4::ZERO).bitmask();
        let t = dot([cx, cy, cz], NG) * inv_det;
        let within = (t.cmpge(w.tmin) & t.cmple(w.tmax)).bitmask();
        (nonzero & !signs & within, t)
    }
}

/// The same test on eight lanes at once, for CPUs with AVX.
#[cfg(target_arch = "x86_64")]
mod avx {
    use super::{Block, E1, E2, FlatRay, LANES, Lanes, NG, V0};
    use std::arch::x86_64::*;

    struct Wide {
        o: [__m256; 3],
        d: [__m256; 3],
        tmin: __m256,
        tmax: __m256,
    }

    #[target_feature(enable = "avx")]
    fn wide(ray: &FlatRay) -> Wide {
        let (o, d) = (ray.origin, ray.direction);
        Wide {
            o: [o.x, o.y, o.z].map(|x| _mm256_set1_ps(x)),
            d: [d.x, d.y, d.z].map(|x| _mm256_set1_ps(x)),
            tmin: _mm256_set1_ps(ray.tmin),
            tmax: _mm256_set1_ps(ray.tmax),
        }
    }

    #[target_feature(enable = "avx")]
    #[inline]
    fn row(b: &Block, k: usize) -> __m256 {
        // SAFETY: a row is eight f32s at a 32-byte boundary (the block's alignment, rows
        // being 32 bytes each).
        unsafe { _mm256_load_ps(b.rows[k].as_ptr()) }
    }

    #[target_feature(enable = "avx")]
    #[inline]
    fn dot(a: [__m256; 3], b: &Block, k: usize) -> __m256 {
        let xy = _mm256_add_ps(
            _mm256_mul_ps(a[0], row(b, k)),
            _mm256_mul_ps(a[1], row(b, k + 1)),
        );
        _mm256_add_ps(xy, _mm256_mul_ps(a[2], row(b, k + 2)))
    }

    /// `ab − c·d` as glam's cross product computes it: fused where the build targets FMA.
    #[target_feature(enable = "avx")]
    #[inline]
    fn sub_mul(ab: __m256, c: __m256, d: __m256) -> __m256 {
        #[cfg(target_feature = "fma")]
        {
            // SAFETY: the whole build targets FMA (this branch exists only then).
            unsafe { _mm256_fnmadd_ps(c, d, ab) }
        }
        #[cfg(not(target_feature = "fma"))]
        {
            _mm256_sub_ps(ab, _mm256_mul_ps(c, d))
        }
    }

    /// [`Block::test`]'s arithmetic, the same operations in the same order.
    #[target_feature(enable = "avx")]
    #[inline]
    fn test(b: &Block, w: &Wide) -> Lanes {
        let [ox, oy, oz] = w.o;
        let [dx, dy, dz] = w.d;
        let cx = _mm256_sub_ps(row(b, V0), ox);
        let cy = _mm256_sub_ps(row(b, V0 + 1), oy);
        let cz = _mm256_sub_ps(row(b, V0 + 2), oz);
        let rx = sub_mul(_mm256_mul_ps(dy, cz), cy, dz);
        let ry = sub_mul(_mm256_mul_ps(dz, cx), cz, dx);
        let rz = sub_mul(_mm256_mul_ps(dx, cy), cx, dy);
        let one = _mm256_set1_ps(1.0);
        let inv_det = _mm256_div_ps(one, dot([dx, dy, dz], b, NG));
        let u = _mm256_mul_ps(dot([rx, ry, rz], b, E2), inv_det);
        let v = _mm256_mul_ps(dot([rx, ry, rz], b, E1), inv_det);
        let w_ = _mm256_sub_ps(_mm256_sub_ps(one, u), v);
        let signs = _mm256_movemask_ps(_mm256_or_ps(_mm256_or_ps(u, v), w_)) as u32;
        let nonzero =
            _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_NEQ_UQ>(inv_det, _mm256_setzero_ps())) as u32;
        let t = _mm256_mul_ps(dot([cx, cy, cz], b, NG), inv_det);
        let within = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GE_OQ>(t, w.tmin),
            _mm256_cmp_ps::<_CMP_LE_OQ>(t, w.tmax),
        );
        let within = _mm256_movemask_ps(within) as u32;
        let mut ts = [0.0f32; LANES];
        // SAFETY: `ts` holds eight f32s (an unaligned store).
        unsafe { _mm256_storeu_ps(ts.as_mut_ptr(), t) };
        (nonzero & !signs & within & b.lanes, ts)
    }

    #[target_feature(enable = "avx")]
    pub(super) fn closest(
        blocks: &[Block],
        ray: &FlatRay,
        keep: impl Fn(usize, f32) -> bool,
    ) -> Option<(f32, usize)> {
        let w = wide(ray);
        super::closest_with(blocks, ray, keep, |b| test(b, &w))
    }

    #[cfg(test)]
    #[target_feature(enable = "avx")]
    pub(super) fn lanes_of(blocks: &[Block], ray: &FlatRay) -> Vec<Lanes> {
        let w = wide(ray);
        blocks.iter().map(|b| test(b, &w)).collect()
    }

    #[target_feature(enable = "avx")]
    pub(super) fn any(blocks: &[Block], ray: &FlatRay, keep: impl Fn(usize, f32) -> bool) -> bool {
        let w = wide(ray);
        super::any_with(blocks, ray, keep, |b| test(b, &w))
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
            let mut flat = Flat::new(&tris);
            let paths = if flat.avx { 2 } else { 1 };
            for k in 0..4000 * paths {
                // Both paths where the CPU has AVX: the 8-lane one, then the portable one.
                flat.avx = flat.avx && k < 4000;
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
                for (b, (mask, t)) in flat.lanes_of(&ray).into_iter().enumerate() {
                    for (i, ti) in t.into_iter().enumerate() {
                        let Some(&s) = scalar.get(LANES * b + i) else {
                            assert_eq!(mask >> i & 1, 0, "an empty lane hit");
                            continue;
                        };
                        let hit = mask >> i & 1 == 1;
                        let at = format!("n {n} ray {k} tri {} avx {}", LANES * b + i, flat.avx);
                        assert_eq!(hit, s.is_finite(), "{at}");
                        if hit {
                            assert_eq!(ti.to_bits(), s.to_bits(), "{at}");
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
