//! Photon emission that learns where a light's photons are useful.
//!
//! A Sun lighting a room through a window emits over the whole scene's bounding disc, so
//! most of its photons land on the roof and the outer walls, which the camera never sees:
//! in the sun-lit room fixture 12 724 of 131 950 stored photons came off a diffuse surface.
//! A point light or a spot in a large scene wastes its photons the same way, wherever the
//! camera looks at only a part of what it lights.
//!
//! So each such light's emission is split into [`CELLS`] cells of equal measure: a
//! distant light's start square (of the bounding sphere's side, [`SIDE`] × [`SIDE`]
//! squares in its plane), a point light's sphere and a spot's cone of directions (cells of
//! the square its direction is warped from, which are of equal solid angle). The photon
//! pass counts, per cell, the photons it emitted and those that were *useful*: stored at
//! least once on a surface the camera sees, or one final-gather bounce from what it sees
//! ([`crate::photon::visibility::VisibleSurfaces`]). Once a light has shown that fewer than
//! half of its photons are useful ([`ADAPT_BELOW`]), later passes pick its cells with
//! probability
//!
//!   p_c = α · u_c + (1 − α) · q_c,
//!
//! where u_c is the cell's share of the light's plain emission (1 / [`CELLS`]) and q_c
//! follows the cell's useful fraction so far (shrunk towards the light's mean where the
//! cell has few photons; at least half its likeliest neighbour's; capped so that no cell
//! gets more than [`MAX_DENSER`] times its plain share), and a photon's flux is divided
//! by p_c / u_c. Every pass's emission is then an unbiased estimate of the light's,
//! whatever its table: the table depends only on earlier passes. The defensive share
//! α = [`DEFENSIVE`] keeps every cell sampled (a photon's flux grows at most 1/α-fold)
//! and keeps the counts learning everywhere.

use std::sync::Arc;

use glam::Vec3;

use super::{LightKind, LightSet};
use crate::sampling::{Rng, cdf, sample_cdf};

/// Cells along each side of a light's emission square.
pub const SIDE: usize = 32;
/// Cells a learning light's emission is split into.
pub const CELLS: usize = SIDE * SIDE;
/// The share of an adapted light's photons emitted as without adaptation: a photon's
/// flux grows at most 1/α-fold.
pub const DEFENSIVE: f32 = 0.5;
/// Most photons a cell gets, in multiples of its plain share: a photon's flux shrinks at
/// most this many times. Photons of a pass then differ in flux by at most
/// `MAX_DENSER / DEFENSIVE` (12). Density estimates stay unbiased whatever the spread,
/// but where light and heavy photons mix (the edge of what the camera sees, where a few
/// heavy photons from unseen cells fall among many light ones) a spread of 400 made
/// them heavy-tailed: most passes came out a few per cent dark, a rare one bright. In a
/// sun-lit scene the pixels then read 0.96–0.99 of the exact value in pass after pass.
pub const MAX_DENSER: f32 = 6.0;
/// A light adapts once fewer than this share of its photons proved useful.
pub const ADAPT_BELOW: f64 = 0.5;
/// Photons a light emits before it decides, and useful ones it needs to adapt.
const MIN_EMITTED: u64 = 4096;
const MIN_USEFUL: u64 = 32;
/// A light that has emitted this many photons with fewer than [`MIN_USEFUL`] useful
/// ones never adapts (what its photons should aim at, it has not found).
const GIVE_UP_AFTER: u64 = 65_536;
/// The shrinkage of a cell's useful fraction towards its light's mean: as if each cell
/// had this many more photons, useful at the mean rate.
const PRIOR_PHOTONS: f64 = 2.0;
/// Most lights whose photons are counted (the first ones, by index).
pub const MAX_LEARNING_LIGHTS: usize = 64;

/// Whether a light of `kind` learns its emission (lights whose photons can leave the
/// part of the scene the camera sees: distant lights, point lights and spots).
pub fn learns(kind: &LightKind) -> bool {
    matches!(
        kind,
        LightKind::Distant { .. } | LightKind::Point { .. } | LightKind::Spot { .. }
    )
}

/// The cell of a point `u` of the unit square.
#[inline]
pub fn cell_of(u: [f32; 2]) -> usize {
    let q = |v: f32| ((v * SIDE as f32) as usize).min(SIDE - 1);
    q(u[0]) + SIDE * q(u[1])
}

/// One light's cell probabilities for a pass.
#[derive(Clone, Debug)]
struct CellTable {
    pmf: Box<[f32]>,
    cdf: Box<[f32]>,
}

/// How a pass emits: per light, whether its photons are counted per cell and, once it
/// has adapted, its cells' probabilities.
#[derive(Clone, Debug, Default)]
pub struct EmissionCells {
    /// Per light: whether it learns (its photons report their cell).
    learning: Vec<bool>,
    tables: Vec<Option<CellTable>>,
}

/// Where an adapted light's photon starts in its emission square: a point of the unit
/// square and the factor its flux is multiplied by (u_c / p_c).
#[derive(Clone, Copy, Debug)]
pub struct CellSample {
    pub u: [f32; 2],
    pub cell: usize,
    pub factor: f32,
}

impl EmissionCells {
    /// Whether light `i`'s photons report their cell.
    #[inline]
    pub fn learns(&self, i: usize) -> bool {
        self.learning.get(i).copied().unwrap_or(false)
    }

    /// Whether light `i` emits by a learned table.
    pub fn adapted(&self, i: usize) -> bool {
        self.tables.get(i).is_some_and(Option::is_some)
    }

    /// Whether any light has adapted.
    pub fn any_adapted(&self) -> bool {
        self.tables.iter().any(Option::is_some)
    }

    /// A start point for adapted light `i` (one draw picks the cell, two place the point
    /// in it); None when it emits as without adaptation.
    #[inline]
    pub fn sample(&self, i: usize, rng: &mut Rng) -> Option<CellSample> {
        let table = self.tables.get(i)?.as_ref()?;
        let cell = sample_cdf(&table.cdf, rng.next_f32());
        let p = table.pmf[cell];
        if !(p > 0.0) {
            return None;
        }
        let [a, b] = rng.next_2d();
        let (x, y) = (cell % SIDE, cell / SIDE);
        let side = SIDE as f32;
        // Within the cell, kept below its upper edge (f32 rounding at the square's top).
        let u = [
            ((x as f32 + a) / side).min(1.0 - f32::EPSILON),
            ((y as f32 + b) / side).min(1.0 - f32::EPSILON),
        ];
        Some(CellSample {
            u,
            cell,
            factor: 1.0 / (CELLS as f32 * p),
        })
    }
}

/// One photon's report: its light, its cell and whether it was useful, in 32 bits.
#[inline]
pub fn report(light: usize, cell: usize, useful: bool) -> u32 {
    debug_assert!(light < MAX_LEARNING_LIGHTS && cell < CELLS);
    ((light as u32) << 16) | ((cell as u32) << 1) | u32::from(useful)
}

fn unpack(r: u32) -> (usize, usize, bool) {
    ((r >> 16) as usize, ((r >> 1) & 0x7fff) as usize, r & 1 == 1)
}

/// What a light has learned so far.
#[derive(Clone, Debug)]
struct LightCounts {
    emitted: Vec<u32>,
    useful: Vec<u32>,
    /// None until decided; then whether it adapts.
    adapts: Option<bool>,
}

/// The emission counts of a render's passes so far, and the cells the next pass emits by.
#[derive(Clone, Debug)]
pub struct EmissionLearner {
    counts: Vec<Option<LightCounts>>,
    cells: Arc<EmissionCells>,
    /// The last pass's counted photons and useful ones.
    last: (u64, u64),
}

impl EmissionLearner {
    /// A learner for `lights`; None when no light learns. A light that aims its
    /// caustic-only photons at glass or mirrors ([`LightSet::aim_at`]) does not learn:
    /// its global photons' caustic records are blended with the aimed photons' at weights
    /// that balance their flux for plain emission, and learned flux would unbalance them
    /// (the caustic map then mixed records of fluxes 10 times apart, and a sun-lit pane's
    /// floor read 2 % dark at 4 passes).
    pub fn new(lights: &LightSet) -> Option<Self> {
        let learning: Vec<bool> = lights
            .iter()
            .enumerate()
            .map(|(i, l)| i < MAX_LEARNING_LIGHTS && learns(&l.kind) && !lights.aims_light(i))
            .collect();
        if !learning.contains(&true) {
            return None;
        }
        let counts = learning
            .iter()
            .map(|&on| {
                on.then(|| LightCounts {
                    emitted: vec![0; CELLS],
                    useful: vec![0; CELLS],
                    adapts: None,
                })
            })
            .collect();
        let tables = vec![None; learning.len()];
        Some(Self {
            counts,
            cells: Arc::new(EmissionCells { learning, tables }),
            last: (0, 0),
        })
    }

    /// The cells the next pass emits by.
    pub fn cells(&self) -> Arc<EmissionCells> {
        Arc::clone(&self.cells)
    }

    /// The last pass's share of counted photons that were useful (None before a pass
    /// counted any).
    pub fn useful_share(&self) -> Option<f64> {
        let (n, u) = self.last;
        (n > 0).then(|| u as f64 / n as f64)
    }

    /// Whether any light has adapted.
    pub fn adapted(&self) -> bool {
        self.cells.any_adapted()
    }

    /// This learner with a pass's photon `reports` ([`report`]) added, and the next pass's
    /// cells rebuilt from every pass so far.
    pub fn learned(&self, reports: &[u32]) -> Self {
        let mut next = self.clone();
        let mut last = (0u64, 0u64);
        for &r in reports {
            let (light, cell, useful) = unpack(r);
            let Some(Some(c)) = next.counts.get_mut(light) else {
                continue;
            };
            c.emitted[cell] = c.emitted[cell].saturating_add(1);
            c.useful[cell] = c.useful[cell].saturating_add(u32::from(useful));
            last.0 += 1;
            last.1 += u64::from(useful);
        }
        next.last = last;
        let tables = next
            .counts
            .iter_mut()
            .map(|c| c.as_mut().and_then(LightCounts::table))
            .collect();
        next.cells = Arc::new(EmissionCells {
            learning: self.cells.learning.clone(),
            tables,
        });
        next
    }
}

impl LightCounts {
    /// Decides (once) whether the light adapts, and if it does, its table from the
    /// counts so far.
    fn table(&mut self) -> Option<CellTable> {
        let n: u64 = self.emitted.iter().map(|&e| u64::from(e)).sum();
        let u: u64 = self.useful.iter().map(|&e| u64::from(e)).sum();
        if self.adapts.is_none() {
            let mean = u as f64 / n.max(1) as f64;
            if n >= MIN_EMITTED && u >= MIN_USEFUL {
                self.adapts = Some(mean < ADAPT_BELOW);
            } else if n >= GIVE_UP_AFTER {
                self.adapts = Some(false);
            }
        }
        if self.adapts != Some(true) {
            return None;
        }
        let mean = u as f64 / n as f64;
        let fraction: Vec<f64> = self
            .emitted
            .iter()
            .zip(&self.useful)
            .map(|(&e, &s)| (f64::from(s) + PRIOR_PHOTONS * mean) / (f64::from(e) + PRIOR_PHOTONS))
            .collect();
        // Each cell at least half as likely as its likeliest neighbour: the photons' flux
        // then changes by steps of at most 2 between neighbouring cells.
        let side = SIDE as isize;
        let dilated: Vec<f64> = (0..CELLS)
            .map(|c| {
                let (x, y) = ((c % SIDE) as isize, (c / SIDE) as isize);
                let mut f = fraction[c];
                for (dx, dy) in [
                    (-1, 0),
                    (1, 0),
                    (0, -1),
                    (0, 1),
                    (-1, -1),
                    (1, 1),
                    (-1, 1),
                    (1, -1),
                ] {
                    let (nx, ny) = (x + dx, y + dy);
                    if (0..side).contains(&nx) && (0..side).contains(&ny) {
                        f = f.max(0.5 * fraction[(nx + side * ny) as usize]);
                    }
                }
                f
            })
            .collect();
        let a = f64::from(DEFENSIVE);
        // The learned part's share per cell, at most what keeps every cell within
        // MAX_DENSER of its plain share.
        let cap = (f64::from(MAX_DENSER) - a) / ((1.0 - a) * CELLS as f64);
        let learned = capped_shares(&dilated, cap)?;
        let pmf: Box<[f32]> = learned
            .iter()
            .map(|q| (a / CELLS as f64 + (1.0 - a) * q) as f32)
            .collect();
        let cdf = cdf(&pmf).into_boxed_slice();
        Some(CellTable { pmf, cdf })
    }
}

/// `weights` normalised to sum 1 with no share above `cap` (≥ 1 / len): the excess of
/// the shares over it is handed to the others in proportion to their weights, until none
/// is left over (water-filling). None when the weights sum to nothing.
fn capped_shares(weights: &[f64], cap: f64) -> Option<Vec<f64>> {
    let total: f64 = weights.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return None;
    }
    let mut q: Vec<f64> = weights.iter().map(|w| w / total).collect();
    let mut capped = vec![false; q.len()];
    for _ in 0..q.len() {
        let mut excess = 0.0;
        for (qi, c) in q.iter_mut().zip(capped.iter_mut()) {
            if *qi > cap {
                excess += *qi - cap;
                *qi = cap;
                *c = true;
            }
        }
        if excess <= 0.0 {
            break;
        }
        let free: f64 = q
            .iter()
            .zip(&capped)
            .filter(|(_, c)| !**c)
            .map(|(v, _)| v)
            .sum();
        let left = capped.iter().filter(|c| !**c).count();
        if left == 0 {
            break;
        }
        for (qi, _) in q.iter_mut().zip(&capped).filter(|(_, c)| !**c) {
            // In proportion to their shares (evenly where those are all zero).
            *qi += if free > 0.0 {
                excess * *qi / free
            } else {
                excess / left as f64
            };
        }
    }
    Some(q)
}

/// A distant light's photon start for a point `u` of its emission square: the square of
/// side 2·`radius` centred on the disc it emits from plainly, and the square's area.
#[inline]
pub fn square_start(dir: Vec3, center: Vec3, radius: f32, u: [f32; 2]) -> (Vec3, f32) {
    let (t, b) = crate::sampling::basis(dir);
    let x = (2.0 * u[0] - 1.0) * radius;
    let y = (2.0 * u[1] - 1.0) * radius;
    (center - dir * radius + t * x + b * y, 4.0 * radius * radius)
}

/// The point of the unit square that [`square_start`] maps to a start `offset` from the
/// disc's centre (in its plane).
#[inline]
pub fn square_point(dir: Vec3, radius: f32, offset: Vec3) -> [f32; 2] {
    let (t, b) = crate::sampling::basis(dir);
    let inv = 0.5 / radius;
    [
        (offset.dot(t) * inv + 0.5).clamp(0.0, 1.0),
        (offset.dot(b) * inv + 0.5).clamp(0.0, 1.0),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn counts(emitted: &[(usize, u32, u32)]) -> LightCounts {
        let mut c = LightCounts {
            emitted: vec![0; CELLS],
            useful: vec![0; CELLS],
            adapts: None,
        };
        for &(cell, e, u) in emitted {
            c.emitted[cell] = e;
            c.useful[cell] = u;
        }
        c
    }

    #[test]
    fn a_light_whose_photons_are_mostly_useful_never_adapts() {
        let mut c = counts(&(0..CELLS).map(|k| (k, 8, 6)).collect::<Vec<_>>());
        assert!(c.table().is_none());
        assert_eq!(c.adapts, Some(false));
        // Decided once: later counts do not change it.
        c.useful.fill(0);
        c.useful[0] = 8;
        assert!(c.table().is_none());
    }

    #[test]
    fn an_adapted_table_favours_useful_cells_and_keeps_the_defensive_share_everywhere() {
        // 2 % of the cells hold every useful photon.
        let useful: Vec<usize> = (0..CELLS).step_by(50).collect();
        let list: Vec<(usize, u32, u32)> = (0..CELLS)
            .map(|k| (k, 8, if useful.contains(&k) { 8 } else { 0 }))
            .collect();
        let mut c = counts(&list);
        let t = c.table().expect("adapts");
        let sum: f64 = t.pmf.iter().map(|&p| f64::from(p)).sum();
        assert!((sum - 1.0).abs() < 1e-5, "{sum}");
        let floor = DEFENSIVE / CELLS as f32;
        let ceiling = MAX_DENSER / CELLS as f32;
        assert!(
            t.pmf
                .iter()
                .all(|&p| p >= floor * 0.999 && p <= ceiling * 1.001)
        );
        // The useful cells are at the ceiling: MAX_DENSER times their plain share.
        let on_useful: f32 = useful.iter().map(|&k| t.pmf[k]).sum();
        let most = MAX_DENSER * useful.len() as f32 / CELLS as f32;
        // (Their dilated neighbours share the learned part: most, not all, reach it.)
        assert!(on_useful > 0.85 * most, "{on_useful} of {most}");
        // Their neighbours get at least half as many as they would: flux steps of ≤ 2.
        let next = useful[1] + 1;
        assert!(t.pmf[next] >= 0.45 * t.pmf[useful[1]], "{}", t.pmf[next]);
    }

    #[test]
    fn cell_samples_are_unbiased_for_any_table() {
        // E[factor · g(u)] = ∫ g over the square, for a g that is not constant per cell.
        let list: Vec<(usize, u32, u32)> = (0..CELLS)
            .map(|k| (k, 10, if k % 7 == 0 { 9 } else { 0 }))
            .collect();
        let mut c = counts(&list);
        let table = c.table().unwrap();
        let cells = EmissionCells {
            learning: vec![true],
            tables: vec![Some(table)],
        };
        let g = |u: [f32; 2]| (3.0 * u[0]).sin().abs() + u[1] * u[1];
        let exact = (1.0 - (3.0f64).cos()) / 3.0 + 1.0 / 3.0;
        let mut rng = Rng::stream(7, 1, 0, crate::sampling::Purpose::Photon);
        let n = 400_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            let s = cells.sample(0, &mut rng).unwrap();
            // Within the cell (a point a rounding step from its upper edge may round onto
            // it, which changes nothing: the point is uniform in the cell either way).
            let [x, y] = [s.cell % SIDE, s.cell / SIDE].map(|v| v as f32 / SIDE as f32);
            let step = 1.0 / SIDE as f32 + 1e-6;
            assert!(s.u[0] >= x && s.u[0] <= x + step && s.u[1] >= y && s.u[1] <= y + step);
            sum += f64::from(s.factor * g(s.u));
        }
        let mean = sum / n as f64;
        assert!((mean - exact).abs() < 0.01 * exact, "{mean} vs {exact}");
    }

    #[test]
    fn the_square_start_and_its_inverse_agree() {
        let dir = Vec3::new(0.3, -0.9, 0.2).normalize();
        let (center, radius) = (Vec3::new(1.0, 2.0, 3.0), 2.5);
        for u in [[0.1, 0.2], [0.5, 0.5], [0.93, 0.07]] {
            let (p, area) = square_start(dir, center, radius, u);
            assert!((area - 25.0).abs() < 1e-4);
            let back = square_point(dir, radius, p - (center - dir * radius));
            assert!((back[0] - u[0]).abs() < 1e-5 && (back[1] - u[1]).abs() < 1e-5);
        }
    }

    #[test]
    fn capped_shares_sum_to_one_below_the_cap_and_keep_the_order() {
        let w = [10.0, 5.0, 1.0, 1.0, 0.0, 3.0];
        let q = capped_shares(&w, 0.3).unwrap();
        assert!((q.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!(q.iter().all(|&v| v <= 0.3 + 1e-12));
        assert!(q[0] >= q[1] && q[1] >= q[5] && q[5] >= q[2] && q[4] == 0.0);
        assert!(capped_shares(&[0.0, 0.0], 0.6).is_none());
        assert!(capped_shares(&[f64::NAN, 1.0], 0.6).is_none());
    }

    #[test]
    fn reports_round_trip() {
        for (l, c, u) in [(0, 0, false), (63, CELLS - 1, true), (5, 333, true)] {
            assert_eq!(unpack(report(l, c, u)), (l, c, u));
        }
    }
}
