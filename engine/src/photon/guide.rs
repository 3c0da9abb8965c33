//! Final-gather directions guided by the photons (Jensen 1995, "Importance driven path
//! tracing using the photon map"): where a point's indirect light comes mostly from a
//! small bright patch — a wall lit only by the floor under a spotlight — cosine-sampled
//! final-gather rays find the patch rarely, and the few that do bring back a great deal:
//! speckle. The global photons around the point know where its indirect light comes from,
//! so the irradiance cache keeps, at each of its points, a histogram of those photons'
//! incoming directions, and a final-gather ray draws its direction from that histogram
//! mixed with the cosine distribution.
//!
//! The histogram lives in the square that [`cosine_hemisphere`] warps to the hemisphere:
//! rings of equal sin²θ by sectors of equal φ, so each cell holds an equal share of the
//! cosine distribution. A ray's square point is warped by the histogram's piecewise-
//! constant distribution first (its ring from the ring marginal, its sector from that
//! ring's conditional), then by the cosine map: the pixel's stratified sequence stays
//! stratified, and the ray's density is the cosine density times CELLS · P(cell), so its
//! radiance is weighed by 1 / (CELLS · P(cell)). A share [`COSINE_SHARE`] of every cell's
//! probability is the cosine distribution's own, so every direction keeps a density, the
//! estimate stays unbiased whatever the photons say, and no ray weighs more than
//! 1 / [`COSINE_SHARE`].
//!
//! [`cosine_hemisphere`]: crate::sampling::cosine_hemisphere

use glam::Vec3;

use crate::sampling::basis;

/// Rings of the histogram, in sin²θ (equal shares of the cosine distribution).
pub const RINGS: usize = 8;
/// Sectors of each ring, in φ.
pub const SECTORS: usize = 8;
pub const CELLS: usize = RINGS * SECTORS;
/// Floats a guide keeps: the ring marginal's CDF, then each ring's sector CDF.
pub const GUIDE_FLOATS: usize = RINGS + CELLS;
/// The share of a guided ray's distribution that stays cosine-weighted.
pub const COSINE_SHARE: f32 = 0.25;
/// Fewest photons (that a final-gather ray could find) a guide is built from; below,
/// the point's rays stay cosine-distributed.
pub const MIN_PHOTONS: usize = 8;
/// How peaked the photons' directions must be for a guide to pay: CELLS · Σ P(cell)²
/// (1 for light spread as the cosine distribution, CELLS for light from one cell; the
/// cosine-sampled estimate's second moment grows with it), less the part a histogram of
/// n photons shows from its own noise (CELLS / n). Below it, where light arrives from
/// all round (a Cornell box's walls), a guide drawn from a few dozen photons would only
/// add the histogram's noise to the rays, so the rays stay cosine-distributed.
pub const MIN_PEAK: f32 = 8.0;

/// [`MIN_PEAK`]'s measure of `histogram` (power per cell) counted from `photons` photons.
pub fn peak(histogram: &[f32; CELLS], photons: usize) -> f32 {
    let total: f32 = histogram.iter().sum();
    if !(total > 0.0) || photons == 0 {
        return 0.0;
    }
    let sum_sq: f32 = histogram.iter().map(|h| (h / total) * (h / total)).sum();
    CELLS as f32 * sum_sq - CELLS as f32 / photons as f32
}

/// The cell of the hemisphere about `n` that direction `d` lies in, as [`cosine_hemisphere`]
/// maps the square (the inverse of its map); None below the surface.
///
/// [`cosine_hemisphere`]: crate::sampling::cosine_hemisphere
#[inline]
pub fn cell_of(n: Vec3, d: Vec3) -> Option<usize> {
    let (x, y, u0) = in_frame(n, d)?;
    let ring = ((u0 * RINGS as f32) as usize).min(RINGS - 1);
    Some(ring * SECTORS + octant(x, y))
}

/// `d` in the frame [`cosine_hemisphere`] uses about `n` ([`basis`]): its tangent
/// coordinates x and y, and x² + y² (sin²θ, the square's first coordinate); None when
/// `d` lies below the surface (or is not finite).
///
/// [`cosine_hemisphere`]: crate::sampling::cosine_hemisphere
#[inline]
fn in_frame(n: Vec3, d: Vec3) -> Option<(f32, f32, f32)> {
    if !(d.dot(n) > 0.0) {
        return None;
    }
    let (t, b) = basis(n);
    let (x, y) = (d.dot(t), d.dot(b));
    Some((x, y, (x * x + y * y).clamp(0.0, 1.0)))
}

/// The sector of φ = atan2(y, x) among eight of π/4 from φ = 0 (`floor(φ / (π/4))`, φ in
/// [0, 2π)), by comparisons instead of an arctangent.
#[inline]
fn octant(x: f32, y: f32) -> usize {
    const _: () = assert!(SECTORS == 8);
    if y >= 0.0 {
        if x > 0.0 {
            usize::from(y >= x)
        } else if y > -x {
            2
        } else {
            3
        }
    } else if x < 0.0 {
        if -y < -x { 4 } else { 5 }
    } else if -y > x {
        6
    } else {
        7
    }
}

/// The point of the unit square that [`cosine_hemisphere`]`(n, ·)` maps to unit `d`;
/// None when `d` lies below the surface (or is not finite).
///
/// [`cosine_hemisphere`]: crate::sampling::cosine_hemisphere
#[inline]
pub fn square_of(n: Vec3, d: Vec3) -> Option<[f32; 2]> {
    let (x, y, u0) = in_frame(n, d)?;
    let mut u1 = y.atan2(x) * std::f32::consts::FRAC_1_PI * 0.5;
    if u1 < 0.0 {
        u1 += 1.0;
    }
    Some([u0, if u1 < 1.0 { u1 } else { 0.0 }])
}

/// A guide's tables from the power of the photons in each cell, mixed with the cosine
/// distribution (see the module docs); None when the histogram holds nothing (or
/// anything not finite).
pub fn tables(histogram: &[f32; CELLS]) -> Option<[f32; GUIDE_FLOATS]> {
    let total: f64 = histogram.iter().map(|&h| h as f64).sum();
    if !(total > 0.0 && total.is_finite()) || histogram.iter().any(|h| !(*h >= 0.0)) {
        return None;
    }
    let cosine = COSINE_SHARE as f64 / CELLS as f64;
    let guided = (1.0 - COSINE_SHARE as f64) / total;
    let p = |c: usize| cosine + guided * histogram[c] as f64;
    let mut out = [0.0f32; GUIDE_FLOATS];
    let mut ring_sum = 0.0f64;
    for ring in 0..RINGS {
        let cells = ring * SECTORS..(ring + 1) * SECTORS;
        let mass: f64 = cells.clone().map(p).sum();
        let mut sum = 0.0f64;
        for c in cells {
            sum += p(c);
            out[RINGS + c] = (sum / mass) as f32;
        }
        out[RINGS + ring * SECTORS + SECTORS - 1] = 1.0;
        ring_sum += mass;
        out[ring] = ring_sum as f32;
    }
    out[RINGS - 1] = 1.0;
    Some(out)
}

/// The interval of `cdf` (increasing, ending at 1) that `x` in [0, 1) falls in: its index,
/// and `x`'s place within it, in [0, 1), and the interval's width.
#[inline]
fn pick(cdf: &[f32], x: f32) -> (usize, f32, f32) {
    let last = cdf.len() - 1;
    let i = cdf[..last].iter().take_while(|&&c| c <= x).count();
    let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
    let width = cdf[i] - lo;
    let within = ((x - lo) / width).clamp(0.0, ONE_BELOW);
    (i, within, width)
}

/// The largest f32 below 1.
const ONE_BELOW: f32 = 1.0 - f32::EPSILON / 2.0;

/// Warps square point `u` by the guide `table` (see [`tables`]): the point to hand to
/// [`cosine_hemisphere`], and the weight of the ray's radiance, 1 / (CELLS · P(cell)).
///
/// [`cosine_hemisphere`]: crate::sampling::cosine_hemisphere
#[inline]
pub fn warp(table: &[f32], [u0, u1]: [f32; 2]) -> ([f32; 2], f32) {
    debug_assert_eq!(table.len(), GUIDE_FLOATS);
    let (ring, v0, p_ring) = pick(&table[..RINGS], u0);
    let row = &table[RINGS + ring * SECTORS..RINGS + (ring + 1) * SECTORS];
    let (sector, v1, p_sector) = pick(row, u1);
    let warped = [
        (ring as f32 + v0) / RINGS as f32,
        (sector as f32 + v1) / SECTORS as f32,
    ];
    (warped, 1.0 / (CELLS as f32 * p_ring * p_sector))
}

/// The weight [`warp`] gives a ray in `cell` (1 / (CELLS · P(cell))).
pub fn weight_of(table: &[f32], cell: usize) -> f32 {
    let (ring, sector) = (cell / SECTORS, cell % SECTORS);
    let width = |cdf: &[f32], i: usize| cdf[i] - if i == 0 { 0.0 } else { cdf[i - 1] };
    let row = &table[RINGS + ring * SECTORS..RINGS + (ring + 1) * SECTORS];
    1.0 / (CELLS as f32 * width(&table[..RINGS], ring) * width(row, sector))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::chi2::chi2_p_value;
    use crate::sampling::{Purpose, Rng, cosine_hemisphere};

    fn normals() -> Vec<Vec3> {
        vec![
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.8, 0.2).normalize(),
            Vec3::new(-1e-4, 1.0, -1e-4).normalize(),
        ]
    }

    #[test]
    fn a_directions_cell_is_the_cell_of_its_square_point() {
        let mut rng = Rng::stream(9, 0, 0, Purpose::Photon);
        for n in normals() {
            for _ in 0..20_000 {
                let d = crate::sampling::uniform_sphere(rng.next_2d());
                let Some([u0, u1]) = square_of(n, d) else {
                    assert_eq!(cell_of(n, d), None);
                    continue;
                };
                let ring = ((u0 * RINGS as f32) as usize).min(RINGS - 1);
                let sector = ((u1 * SECTORS as f32) as usize).min(SECTORS - 1);
                let cell = cell_of(n, d).unwrap();
                // Only a direction within rounding of a sector's edge may differ.
                let edge = (u1 * SECTORS as f32 - (u1 * SECTORS as f32).round()).abs() < 1e-4;
                assert!(
                    cell == ring * SECTORS + sector || edge,
                    "{d} about {n}: {u1}"
                );
            }
        }
    }

    #[test]
    fn the_square_point_of_a_cosine_direction_is_the_one_it_came_from() {
        let mut rng = Rng::stream(7, 0, 0, Purpose::Photon);
        for n in normals() {
            for _ in 0..20_000 {
                let u = rng.next_2d();
                let d = cosine_hemisphere(n, u);
                let Some(back) = square_of(n, d) else {
                    // Only a direction on the horizon (u0 → 1) may round below it.
                    assert!(u[0] > 0.999_99, "{u:?} → {d} about {n}");
                    continue;
                };
                assert!((back[0] - u[0]).abs() < 1e-4, "{u:?} → {back:?} about {n}");
                // φ wraps: compare on the circle; near the pole φ is ill-defined.
                let dphi = (back[1] - u[1]).abs();
                let dphi = dphi.min(1.0 - dphi);
                assert!(
                    u[0] < 1e-6 || dphi < 1e-3 / u[0].sqrt().max(1e-3),
                    "{u:?} → {back:?} about {n}"
                );
            }
            assert_eq!(square_of(n, -n), None);
            assert_eq!(square_of(n, Vec3::NAN), None);
        }
    }

    /// A histogram with most of its power in one small cell, some in another, and
    /// nothing elsewhere.
    fn peaked() -> [f32; CELLS] {
        let mut h = [0.0f32; CELLS];
        h[6 * SECTORS + 3] = 9.0;
        h[2 * SECTORS + 7] = 1.0;
        h
    }

    #[test]
    fn warped_points_fall_in_each_cell_as_often_as_the_guide_says() {
        // χ² over the 64 cells of 200 000 warped uniform points against the mixture's
        // cell probabilities 1 / (CELLS · weight).
        let table = tables(&peaked()).unwrap();
        let mut counts = [0u64; CELLS];
        let mut rng = Rng::stream(11, 0, 0, Purpose::Photon);
        let samples = 200_000;
        for _ in 0..samples {
            let (w, weight) = warp(&table, rng.next_2d());
            assert!(
                (0.0..1.0).contains(&w[0]) && (0.0..1.0).contains(&w[1]),
                "{w:?}"
            );
            let cell = (w[0] * RINGS as f32) as usize * SECTORS + (w[1] * SECTORS as f32) as usize;
            assert!((weight / weight_of(&table, cell) - 1.0).abs() < 1e-5);
            counts[cell] += 1;
        }
        let expected: Vec<f64> = (0..CELLS)
            .map(|c| samples as f64 / (CELLS as f64 * weight_of(&table, c) as f64))
            .collect();
        let stat: f64 = (counts.iter().zip(&expected))
            .map(|(&o, &e)| (o as f64 - e).powi(2) / e)
            .sum();
        let p = chi2_p_value(stat, CELLS - 1);
        assert!(p > 1e-3, "χ² p = {p}");
        // The cosine share keeps every cell's weight at most 1 / COSINE_SHARE, and the
        // peak's cell holds most of the rays.
        for c in 0..CELLS {
            assert!(weight_of(&table, c) <= 1.0 / COSINE_SHARE * (1.0 + 1e-5));
        }
        assert!(counts[6 * SECTORS + 3] as f64 > 0.6 * samples as f64);
    }

    #[test]
    fn a_guided_estimate_of_a_hemisphere_integral_is_unbiased_and_less_noisy() {
        // Radiance from a small bright patch (in the peak's cell) over a dim sky: the
        // irradiance /π, ∫ L cos/π dω, by cosine-sampled and by guided rays. Both must
        // agree with the exact value; the guided one with far less variance.
        let n = Vec3::new(0.2, 0.1, 1.0).normalize();
        let patch = 6 * SECTORS + 3;
        let radiance = |d: Vec3| {
            if cell_of(n, d) == Some(patch) {
                1000.0
            } else {
                1.0
            }
        };
        // Each cell holds 1/CELLS of the cosine distribution.
        let exact = (1000.0 + (CELLS - 1) as f64) / CELLS as f64;
        let table = tables(&peaked()).unwrap();
        let mut rng = Rng::stream(5, 0, 0, Purpose::Photon);
        let samples = 400_000;
        let (mut plain, mut guided) = ((0.0f64, 0.0f64), (0.0f64, 0.0f64));
        for _ in 0..samples {
            let u = rng.next_2d();
            let l = radiance(cosine_hemisphere(n, u)) as f64;
            plain = (plain.0 + l, plain.1 + l * l);
            let (w, weight) = warp(&table, u);
            let l = (radiance(cosine_hemisphere(n, w)) * weight) as f64;
            guided = (guided.0 + l, guided.1 + l * l);
        }
        let stats = |(s, s2): (f64, f64)| {
            let mean = s / samples as f64;
            (mean, s2 / samples as f64 - mean * mean)
        };
        let ((m_plain, v_plain), (m_guided, v_guided)) = (stats(plain), stats(guided));
        for (m, v) in [(m_plain, v_plain), (m_guided, v_guided)] {
            let sigma = (v / samples as f64).sqrt();
            assert!((m - exact).abs() < 4.0 * sigma, "{m} vs {exact} ± {sigma}");
        }
        assert!(v_guided < 0.1 * v_plain, "{v_guided} vs {v_plain}");
    }

    #[test]
    fn an_empty_or_broken_histogram_gives_no_guide() {
        assert!(tables(&[0.0; CELLS]).is_none());
        let mut h = peaked();
        h[0] = f32::NAN;
        assert!(tables(&h).is_none());
        h[0] = -1.0;
        assert!(tables(&h).is_none());
        h[0] = f32::INFINITY;
        assert!(tables(&h).is_none());
        // A uniform histogram is the cosine distribution: every weight 1.
        let table = tables(&[2.5; CELLS]).unwrap();
        for c in 0..CELLS {
            assert!((weight_of(&table, c) - 1.0).abs() < 1e-5);
        }
    }
}
