//! Which cubes of a coarse grid hold photons: a density estimate whose search sphere
//! touches only empty cubes has no photon to find, and is answered without a tree search.
//! On the prism, 86 % of the caustic map's estimates (one per camera sample that reaches a
//! diffuse surface) lie where no caustic photon is within the search cap, and an empty kd
//! range search at the cap cost about 600 ns; a hash probe of 8 cubes (27 when a sphere's
//! padded bounds straddle a third) does not. Most of those queries are answered by one
//! probe: of the set of cubes next to an occupied one.

use std::collections::HashSet;
use std::hash::BuildHasherDefault;

use glam::Vec3;

use super::irradiance::CellHasher;

type Cube = (i32, i32, i32);

#[derive(Clone, Debug)]
pub struct Occupancy {
    /// The cubes' side: twice the largest radius the grid answers for, so that a sphere
    /// of that radius overlaps 2 cubes along each axis (3 in the rare case its padded
    /// bounds reach into a third).
    side: f32,
    inv_side: f32,
    cubes: CubeSet,
    /// Every cube within one step (of 27) of an occupied cube: a query whose own cube is
    /// not among them has no photon within half a side, without probing 8 cubes.
    near: CubeSet,
}

type CubeSet = HashSet<Cube, BuildHasherDefault<CellHasher>>;

fn cube_of(v: f32) -> i32 {
    // NaN gives 0: a non-finite query gets a (conservative) probe, not a panic.
    floor_clamped(v)
}

/// ⌊v⌋ clamped to ±10⁹, as an integer (NaN: 0) — `v.floor().clamp(-1e9, 1e9) as i32`
/// without the libm `floorf` call that x86-64's baseline makes of `floor` (it has no
/// rounding instruction; 1 % of a prism render's instructions went there). The cast
/// truncates towards zero, exactly for every clamped float (those beyond 2²⁴ are whole);
/// one step down where that rounded a negative fraction up. Tested to agree everywhere.
#[inline]
pub(super) fn floor_clamped(v: f32) -> i32 {
    let c = v.clamp(-1e9, 1e9);
    let t = c as i32;
    t - i32::from((t as f32) > c)
}

impl Occupancy {
    /// The grid of `positions` that answers for search radii up to `r_max` (> 0).
    pub fn build(positions: &[[f32; 3]], r_max: f32) -> Self {
        let side = 2.0 * r_max;
        let inv_side = 1.0 / side;
        let cubes: CubeSet = positions
            .iter()
            .map(|p| {
                let q = |v: f32| cube_of(v * inv_side);
                (q(p[0]), q(p[1]), q(p[2]))
            })
            .collect();
        let mut near = CubeSet::default();
        for &(x, y, z) in &cubes {
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        near.insert((x + dx, y + dy, z + dz));
                    }
                }
            }
        }
        Self {
            side,
            inv_side,
            cubes,
            near,
        }
    }

    /// Whether a photon may lie within `r` of `p`: false only when none does (exact in
    /// that direction: a "may" is settled by the search). Radii above the grid's own are
    /// always a "may".
    pub fn may_hold_within(&self, p: Vec3, r: f32) -> bool {
        if !(2.0 * r <= self.side) {
            return true;
        }
        // A photon within r ≤ side/2 of p is at most half a side away along each axis, so
        // its cube is p's or a neighbour of p's. That holds for the rounded cube
        // coordinates while they stay below 2²² (rounding each by under a quarter side);
        // farther out, only the padded probe below answers.
        let own = p * self.inv_side;
        if own.abs().max_element() < (1u32 << 22) as f32 {
            let c = own.to_array().map(cube_of);
            if !self.near.contains(&(c[0], c[1], c[2])) {
                return false;
            }
        }
        // Padded past f32 rounding of p ± r, so that a photon on the sphere's edge is
        // never in a cube left out.
        let r = r * (1.0 + 1e-4) + 1e-6 * p.abs().max_element();
        let lo = ((p - Vec3::splat(r)) * self.inv_side)
            .to_array()
            .map(cube_of);
        let hi = ((p + Vec3::splat(r)) * self.inv_side)
            .to_array()
            .map(cube_of);
        (lo[0]..=hi[0]).any(|x| {
            (lo[1]..=hi[1]).any(|y| (lo[2]..=hi[2]).any(|z| self.cubes.contains(&(x, y, z))))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Purpose, Rng};

    #[test]
    fn the_clamped_floor_agrees_with_floor_everywhere() {
        let reference = |v: f32| v.floor().clamp(-1e9, 1e9) as i32;
        let mut specials = vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            0.999_999_9,
            -0.999_999_9,
            1e-30,
            -1e-30,
            16_777_215.5,
            -16_777_215.5,
            16_777_216.0,
            -16_777_217.0,
            8_388_607.5,
            -8_388_608.5,
            1e9,
            -1e9,
            1.000_001e9,
            -1.000_001e9,
            3e9,
            -3e9,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
        ];
        // Every float around the integers up to ±2²⁵, and a spread of bit patterns.
        for k in (-(1i64 << 25)..(1i64 << 25)).step_by(9_973) {
            let x = k as f32;
            specials.extend([x, x.next_up(), x.next_down(), x + 0.5, x - 0.25]);
        }
        for b in (0..=u32::MAX).step_by(65_537) {
            specials.push(f32::from_bits(b));
        }
        for v in specials {
            assert_eq!(
                floor_clamped(v),
                reference(v),
                "{v:e} ({:#010x})",
                v.to_bits()
            );
        }
    }

    #[test]
    fn an_empty_answer_is_never_wrong_and_far_queries_get_one() {
        // Photons in two clumps; queries everywhere at radii up to the grid's: whenever a
        // photon lies within r of the query, the grid must say "may" (brute force).
        let mut rng = Rng::stream(11, 0, 0, Purpose::Photon);
        let mut positions = Vec::new();
        for c in [Vec3::new(0.2, 0.0, 0.3), Vec3::new(-0.5, 0.4, -0.1)] {
            for _ in 0..500 {
                let [a, b] = rng.next_2d();
                let d = Vec3::new(a - 0.5, b - 0.5, rng.next_f32() - 0.5) * 0.1;
                positions.push((c + d).to_array());
            }
        }
        let r_max = 0.02;
        let grid = Occupancy::build(&positions, r_max);
        let (mut empty, mut wrong) = (0, 0);
        for _ in 0..20_000 {
            let [a, b] = rng.next_2d();
            let p = Vec3::new(a * 2.0 - 1.0, b * 2.0 - 1.0, rng.next_f32() * 2.0 - 1.0);
            let r = r_max * rng.next_f32();
            let near = positions
                .iter()
                .any(|q| Vec3::from_array(*q).distance_squared(p) <= r * r);
            let may = grid.may_hold_within(p, r);
            wrong += (near && !may) as u32;
            empty += !may as u32;
        }
        // Queries just within r of a photon, in every direction (across cube faces and
        // corners): every one must be a "may".
        for i in 0..20_000 {
            let q = Vec3::from_array(positions[i % positions.len()]);
            let r = r_max * (0.05 + 0.95 * rng.next_f32());
            let dir = crate::sampling::uniform_sphere(rng.next_2d());
            let p = q + dir * r * 0.999;
            wrong += (!grid.may_hold_within(p, r)) as u32;
        }
        assert_eq!(wrong, 0);
        // Most of the cube [-1, 1]³ is far from both clumps.
        assert!(empty > 18_000, "{empty}");
        // Larger radii than the grid's are a "may", even far from every photon.
        assert!(grid.may_hold_within(Vec3::splat(5.0), 3.0 * r_max));
        // A NaN query probes one cube instead of panicking (the kd search would find
        // nothing for it either).
        let _ = grid.may_hold_within(Vec3::splat(f32::NAN), r_max);
    }
}
