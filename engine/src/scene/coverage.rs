//! How much of a density estimate's disc lies on the surface it estimates on.
//!
//! A photon density estimate divides the flux of the photons within r of a point by
//! π r², the area of the disc they could have landed on. Where the surface ends inside
//! the disc — at a wall (a concave edge: the floor meets the wall) or at an edge the
//! surface falls away from (a convex edge: the top of a box) — photons land only on part
//! of it, and π r² reads the corner dark: the k-nearest boundary bias, the reason a
//! furnace read 3 % dark with final gathering, and a sun-lit room's walls 3 % dark
//! without the irradiance cache (BENCHMARKS.md, session 38). Dividing by the part of the
//! disc on the surface, A(r), removes it: for photons of a Poisson process, the
//! k-nearest estimate (k − 1) / A(r_k) is unbiased for any shape of surface, since
//! λ·A(r_k) is then Gamma(k)-distributed (the area plays the part the disc did).
//!
//! A(r) is measured by rays, not photons, so it carries none of the photons' noise. From
//! the point, [`PROBES`] directions over the tangent plane each find how far the surface
//! reaches, ρ: a ray along the plane finds the nearest wall, a ray down onto the plane
//! there checks that the surface is still under it (else three more halve the distance to
//! where it ends). The region is then ½ ∫ ρ(θ)² dθ, and the probes' directions, turned by
//! a random angle per point, make ½ Σ ρ² · 2π / M an unbiased estimate of it.

use glam::Vec3;

use super::SpectralScene;
use crate::sampling::basis;

/// Directions probed per disc.
pub const PROBES: usize = 8;
/// Halvings of the distance to a convex edge once a probe's far end finds no surface.
const EDGE_HALVINGS: u32 = 3;
/// A surface continues the disc's where its normal lies within this of the disc's (the
/// density estimates' facing test: 37°).
const SAME_SURFACE_COS: f32 = 0.8;
/// The density estimates' slab: a photon Δ away counts when |Δ·n| ≤ |Δ| × this.
const SLAB: f32 = 1.0 / 8.0;

impl SpectralScene {
    /// The area of the part of the disc of radius `r` about `p` (on a surface whose
    /// geometric normal, on the side the photons came from, is `n`) that lies on that
    /// surface: π r² where the surface holds the whole disc, less where a wall or an edge
    /// cuts it (see the module's text). `spin` in [0, 1) turns the probes' directions.
    pub fn disc_area_on_surface(&self, p: Vec3, n: Vec3, r: f32, spin: f32) -> f32 {
        let full = std::f32::consts::PI * r * r;
        if !(r > 0.0 && r.is_finite() && p.is_finite() && n.is_finite()) {
            return full;
        }
        let (t, b) = basis(n);
        let mut sum = 0.0;
        for j in 0..PROBES {
            let phi = std::f32::consts::TAU * (j as f32 + spin) / PROBES as f32;
            let u = t * phi.cos() + b * phi.sin();
            let reach = self.surface_reach(p, n, u, r);
            sum += reach * reach;
        }
        // ½ Σ ρ² · 2π / M.
        (std::f32::consts::PI * sum / PROBES as f32).min(full)
    }

    /// How far along `u` (in the tangent plane) from `p` the surface of normal `n`
    /// reaches, up to `r`.
    fn surface_reach(&self, p: Vec3, n: Vec3, u: Vec3, r: f32) -> f32 {
        // A wall: the nearest surface along the plane, a little above it, that is not the
        // disc's own surface curving up.
        let lift = r * (SLAB / 8.0);
        let origin = p + n * lift;
        let wall = match self.accel.intersect(origin, u, r) {
            Some(hit) if !self.continues(hit.prim, u, n) => hit.t.min(r),
            _ => r,
        };
        // The far end of the reach: is the surface still under it? Inside a wall's reach
        // only: past the wall lies another room's floor, which photons of this one never
        // reach.
        let far = wall * 0.98;
        if self.surface_under(p, n, u, far) {
            return wall;
        }
        let (mut lo, mut hi) = (0.0f32, far);
        for _ in 0..EDGE_HALVINGS {
            let mid = 0.5 * (lo + hi);
            if self.surface_under(p, n, u, mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// Whether a surface facing like `n` lies within the density estimates' slab under
    /// the point `s` along `u` from `p`.
    fn surface_under(&self, p: Vec3, n: Vec3, u: Vec3, s: f32) -> bool {
        let h = s * SLAB;
        if h <= 0.0 {
            return true;
        }
        let origin = p + u * s + n * h;
        match self.accel.intersect(origin, -n, 2.0 * h) {
            Some(hit) => self.continues(hit.prim, -n, n),
            None => false,
        }
    }

    /// Whether triangle `prim`, met by a ray along `dir`, faces that ray like `n`: the
    /// disc's surface continued.
    fn continues(&self, prim: u32, dir: Vec3, n: Vec3) -> bool {
        let tn = self.tris[prim as usize].normal;
        let facing = if dir.dot(tn) < 0.0 { tn } else { -tn };
        facing.dot(n) >= SAME_SURFACE_COS
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::load_builtin;
    use crate::spectral::BinGrid;
    use std::f32::consts::PI;

    /// A 4 × 4 floor at y = 0 (x, z in −2…2) with a wall at x = 2 and a 1 × 1 × 0.5 block
    /// standing on it (x, z in −1.5…−0.5): the Cornell box's materials, these triangles.
    fn floor_wall_and_block() -> SpectralScene {
        let mut scene = load_builtin("cornell-box").unwrap();
        let quad = |p: Vec3, a: Vec3, b: Vec3| [[p, p + a, p + a + b], [p, p + a + b, p + b]];
        let mut tris = Vec::new();
        tris.extend(quad(
            Vec3::new(-2.0, 0.0, -2.0),
            Vec3::Z * 4.0,
            Vec3::X * 4.0,
        ));
        tris.extend(quad(
            Vec3::new(2.0, 0.0, -2.0),
            Vec3::Y * 3.0,
            Vec3::Z * 4.0,
        ));
        let (lo, hi) = (Vec3::new(-1.5, 0.0, -1.5), Vec3::new(-0.5, 0.5, -0.5));
        let s = hi - lo;
        tris.extend(quad(
            Vec3::new(lo.x, hi.y, lo.z),
            Vec3::Z * s.z,
            Vec3::X * s.x,
        ));
        tris.extend(quad(lo, Vec3::Y * s.y, Vec3::Z * s.z));
        tris.extend(quad(
            Vec3::new(hi.x, lo.y, lo.z),
            Vec3::Z * s.z,
            Vec3::Y * s.y,
        ));
        tris.extend(quad(lo, Vec3::X * s.x, Vec3::Y * s.y));
        tris.extend(quad(
            Vec3::new(lo.x, lo.y, hi.z),
            Vec3::Y * s.y,
            Vec3::X * s.x,
        ));
        scene.triangle_material = vec![0; tris.len()];
        scene.triangles = tris;
        SpectralScene::new(&scene, BinGrid::with_bins(4).unwrap())
    }

    /// The mean over `spins` evenly spread turns of the probes, over π r².
    fn mean_share(s: &SpectralScene, p: Vec3, n: Vec3, r: f32, spins: usize) -> f32 {
        (0..spins)
            .map(|k| s.disc_area_on_surface(p, n, r, k as f32 / spins as f32))
            .sum::<f32>()
            / (spins as f32 * PI * r * r)
    }

    /// The share of a disc of radius 1 left by a chord `d` from its centre.
    fn beyond_a_chord(d: f32) -> f32 {
        let d = d.clamp(-1.0, 1.0);
        1.0 - (d.acos() - d * (1.0 - d * d).sqrt()) / PI
    }

    #[test]
    fn a_disc_inside_its_surface_is_whole() {
        let s = floor_wall_and_block();
        let p = Vec3::new(0.5, 0.0, 1.0);
        for spin in [0.0, 0.3, 0.99] {
            assert_eq!(s.disc_area_on_surface(p, Vec3::Y, 0.4, spin), PI * 0.16);
        }
    }

    #[test]
    fn a_wall_cuts_the_disc_at_its_chord() {
        // The floor at d from the wall x = 2 (a concave edge), radius 0.4: unbiased over
        // the probes' turn, and within 12 % at any one turn (measured: up to 9.6 % at
        // d = r / 8, where two probes straddle the chord's steepest part; 1 / Â's bias
        // from that spread is about its variance, 0.3 %).
        let s = floor_wall_and_block();
        let r = 0.4;
        for d in [0.05, 0.1, 0.2, 0.3] {
            let p = Vec3::new(2.0 - d, 0.0, 1.0);
            let exact = beyond_a_chord(d / r);
            let mean = mean_share(&s, p, Vec3::Y, r, 256);
            println!("wall at {d}: {mean:.4} (exact {exact:.4})");
            assert!(
                (mean / exact - 1.0).abs() < 0.002,
                "{d}: {mean} against {exact}"
            );
            for spin in [0.0, 0.25, 0.7] {
                let one = s.disc_area_on_surface(p, Vec3::Y, r, spin) / (PI * r * r);
                assert!(
                    (one / exact - 1.0).abs() < 0.12,
                    "{d} {spin}: {one} against {exact}"
                );
            }
        }
    }

    #[test]
    fn a_surface_ending_at_an_edge_is_cut_there() {
        // The block's top at d from its edge x = −0.5 (a convex edge: nothing there for a
        // ray along the top to hit; the rays down onto it find where it ends).
        let s = floor_wall_and_block();
        let r = 0.3;
        for d in [0.05, 0.15, 0.25] {
            let p = Vec3::new(-0.5 - d, 0.5, -1.0);
            let exact = beyond_a_chord(d / r);
            let mean = mean_share(&s, p, Vec3::Y, r, 256);
            println!("edge at {d}: {mean:.4} (exact {exact:.4})");
            assert!(
                (mean / exact - 1.0).abs() < 0.02,
                "{d}: {mean} against {exact}"
            );
        }
        // And the floor beside the block: the block's side is a wall.
        let p = Vec3::new(-0.4, 0.0, -1.0);
        let (mean, exact) = (mean_share(&s, p, Vec3::Y, r, 256), beyond_a_chord(0.1 / r));
        assert!((mean / exact - 1.0).abs() < 0.01, "{mean} against {exact}");
    }

    #[test]
    fn bad_radii_and_points_give_the_whole_disc() {
        let s = floor_wall_and_block();
        let p = Vec3::new(0.5, 0.0, 1.0);
        assert_eq!(s.disc_area_on_surface(p, Vec3::Y, 0.0, 0.5), 0.0);
        assert!(s.disc_area_on_surface(p, Vec3::Y, f32::NAN, 0.5).is_nan());
        let r = s.disc_area_on_surface(Vec3::NAN, Vec3::Y, 0.1, 0.5);
        assert_eq!(r, PI * 0.01);
    }
}
