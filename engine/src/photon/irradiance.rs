//! Precomputed irradiance (Christensen 1999, "Faster photon map global illumination"):
//! once per pass, the irradiance of the global map is estimated at every `every`-th
//! stored photon (its k-nearest density estimate from the other photons, at the photon's
//! own position and normal); a final-gather ray then reads the irradiance of the nearest such point on its
//! surface instead of running a density estimate of its own. A pass makes a few tens of
//! thousands of density estimates instead of one per final-gather ray (millions), and each
//! ray costs one nearest-neighbour search.
//!
//! Values are kept in the map's record format: N floats for full records, the colour-exact
//! Smits triplet for compact ones (the irradiance of many photons is smooth, and a
//! final-gather ray's contribution is an average of many), so the cache costs compact
//! storage no more than the photons themselves.

use glam::Vec3;
use rayon::prelude::*;

use super::map::{Kernel, PhotonMap, SurfaceTest};
use super::record::{Record, oct_decode};
use super::{guide, kdtree};
use crate::spectral::{BinGrid, spd};

/// Cache points estimated in a row by one thread, the search radius carried along.
const HINT_CHUNK: usize = 256;

pub struct IrradianceCache {
    positions: Vec<[f32; 3]>,
    normals: Vec<u32>,
    axes: Vec<u8>,
    record: Record,
    stride: usize,
    /// Irradiance per point: `stride` floats (N bins, or a Smits triplet).
    values: Vec<f32>,
    /// Farthest a lookup searches for a point on its surface.
    r_lookup: f32,
    /// Each point by its cell (points are one per cell, see [`thin_out`]).
    cells: CellMap,
    inv_cell: f32,
    /// Final-gather guides by cube, level and surface orientation (see [`guides_by_cube`]):
    /// the index of each in `guides` (empty when the map keeps no incoming directions).
    guide_cells: CellMap,
    /// 1 / the side of a level-0 guide cube.
    inv_guide_cell: f32,
    /// [`guide::GUIDE_FLOATS`] floats per guide (see [`guide::tables`]).
    guides: Vec<f32>,
    /// Which levels have guides (bit per level): a lookup probes only those.
    guide_levels: u32,
    /// This cache's own number (see [`GuideMemo`]).
    id: u64,
}

/// The last guide lookup of one thread's work unit: its cache, its level-0 cube and the
/// guide found there. Cubes nest (a level-0 cube lies in one cube of every level), so
/// the guide is a function of the level-0 cube, and neighbouring camera hits — a pixel's
/// samples, a block's pixels — repeat the lookup for one hash of their key.
#[derive(Clone, Copy, Debug, Default)]
pub struct GuideMemo(Option<(u64, CellKey, Option<u32>)>);

/// Numbers for caches (see [`GuideMemo`]).
static CACHE_IDS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// A level-0 guide cube's side, in point spacings: about the global map's typical search
/// radius, so that a guide pools the photons of a few neighbouring points' estimates.
const GUIDE_CELLS: f32 = 2.0;
/// Coarsest guide level (cubes 2^this level-0 sides wide).
const GUIDE_LEVELS: u8 = 12;
/// Guides are kept only where at least one in this many points with a histogram has one
/// (see [`guides_by_cube`]).
const MIN_GUIDED_SHARE: usize = 16;
/// Levels above its own a point's histogram joins too, so that a lookup in a cube its
/// level left empty (a gap between points) finds the guide of the cube around it.
const GUIDE_REACH: u8 = 2;

/// A point's share of its guide cube (see [`histogram_of`]): its histogram, the photons it
/// counted, and its estimate's radius.
type Histogram = Option<(Box<[f32; guide::CELLS]>, usize, f32)>;

/// A point's share of its guide cube's histogram: the power of the photons of its estimate
/// (`found`, those under `r` away) by the cell of the hemisphere about `n` they came from,
/// normalised (each point weighs the same in its cube), and how many photons a
/// final-gather ray could find (see [`super::map::IncomingCode`]) it counted. None when
/// it counted none.
fn histogram_of(map: &PhotonMap, bins: usize, n: Vec3, found: &[(f32, u32)], r: f32) -> Histogram {
    let r2 = r * r;
    let mut histogram = Box::new([0.0f32; guide::CELLS]);
    let mut count = 0;
    for &(d2, i) in found {
        let i = i as usize;
        if d2 < r2
            && let Some(c) = map.incoming(i).and_then(|d| guide::cell_of(n, d))
        {
            histogram[c] += map.power_of(i, bins);
            count += 1;
        }
    }
    let total: f32 = histogram.iter().sum();
    if count == 0 || !(total > 0.0 && total.is_finite()) {
        return None;
    }
    histogram.iter_mut().for_each(|h| *h /= total);
    Some((histogram, count, r))
}

/// The photons irradiance is estimated at: every `every`-th (the map is in kd order, so
/// they spread as the photons do), but at most one per cube of side `cell` and surface
/// orientation (the normal's dominant axis and sign). Where photons crowd — a caustic
/// concentrates most of a dispersive scene's photons in its rainbow — the points stay
/// one cell apart instead of following the photons; final gathering averages what it
/// reads over a hemisphere, so it never needed them closer. Deterministic: the first
/// photon of each cell in map order is kept.
fn thin_out(map: &PhotonMap, every: usize, inv_cell: f32) -> Vec<usize> {
    let mut seen = CellMap::default();
    (0..map.len())
        .step_by(every.max(1))
        .filter(|&i| {
            let n = oct_decode(map.normal_code(i));
            let key = cell_key(Vec3::from_array(map.positions()[i]), n, inv_cell);
            seen.insert(key, 0).is_none()
        })
        .collect()
}

/// A cube of the cell grid and a surface orientation class (dominant axis and sign of
/// the normal, 0–5).
pub(super) type CellKey = (i32, i32, i32, u8);

pub(super) fn cell_key(p: Vec3, n: Vec3, inv_cell: f32) -> CellKey {
    let a = n.abs();
    let axis = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    let side = (axis * 2 + (n[axis] < 0.0) as usize) as u8;
    let q = |v: f32| super::occupancy::floor_clamped(v * inv_cell);
    (q(p.x), q(p.y), q(p.z), side)
}

/// The guide cube of `p` at `level` (side 2^level / `inv_cell`), with the orientation
/// class of `n` and the level in the key's last field.
fn guide_key(p: Vec3, n: Vec3, inv_cell: f32, level: u8) -> CellKey {
    let (x, y, z, side) = cell_key(p, n, inv_cell / (1u32 << level) as f32);
    (x, y, z, side + 6 * level)
}

/// The level a [`guide_key`] was made at.
fn level_of(key: &CellKey) -> u8 {
    key.3 / 6
}

/// A multiply–rotate hash for cell keys (the keys are small integers: SipHash's
/// protection against chosen keys buys nothing here and costs a lookup's worth of time).
#[derive(Default)]
pub(super) struct CellHasher(u64);

impl std::hash::Hasher for CellHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u8(&mut self, v: u8) {
        self.write_u64(v as u64);
    }
    fn write_i32(&mut self, v: i32) {
        self.write_u64(v as u32 as u64);
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(23) ^ v).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

type CellMap = std::collections::HashMap<CellKey, u32, std::hash::BuildHasherDefault<CellHasher>>;

/// The guides of the points' cubes. Each point joins the cube that holds it at the
/// finest level whose cubes (side 2^level / `inv_guide_cell`) are as wide as its
/// estimate's radius, and the [`GUIDE_REACH`] coarser cubes around that: where photons
/// are sparse the points are too, and their cubes grow with them, so that a lookup finds
/// a guide there as well (the finest one: see [`IrradianceCache::guide_at`]). Each cube's points'
/// histograms are summed and made a guide where they counted at least
/// [`guide::MIN_PHOTONS`] photons and are peaked enough to pay ([`guide::MIN_PEAK`]). Deterministic: the cubes are kept in the order of
/// their first point.
fn guides_by_cube(
    points: &[([f32; 3], u32, Vec<f32>, Histogram)],
    inv_guide_cell: f32,
) -> (CellMap, Vec<f32>, u32) {
    let mut cubes = CellMap::default();
    let mut sums: Vec<(CellKey, [f32; guide::CELLS], usize)> = Vec::new();
    for (pos, normal, _, histogram) in points {
        let Some((h, count, r)) = histogram else {
            continue;
        };
        let level = (0..GUIDE_LEVELS)
            .find(|&l| r * inv_guide_cell <= (1u32 << l) as f32)
            .unwrap_or(GUIDE_LEVELS);
        let (p, n) = (Vec3::from_array(*pos), oct_decode(*normal));
        for level in level..=(level + GUIDE_REACH).min(GUIDE_LEVELS) {
            let key = guide_key(p, n, inv_guide_cell, level);
            let next = sums.len() as u32;
            let at = *cubes.entry(key).or_insert(next) as usize;
            if at == sums.len() {
                sums.push((key, [0.0; guide::CELLS], 0));
            }
            let (_, sum, total) = &mut sums[at];
            sum.iter_mut().zip(h.iter()).for_each(|(s, h)| *s += h);
            *total += count;
        }
    }
    let mut guide_cells = CellMap::default();
    let mut guides = Vec::new();
    let mut levels = 0u32;
    for (key, sum, count) in &sums {
        if *count >= guide::MIN_PHOTONS
            && guide::peak(sum, *count) >= guide::MIN_PEAK
            && let Some(table) = guide::tables(sum)
        {
            levels |= 1 << level_of(key);
            guide_cells.insert(*key, (guides.len() / guide::GUIDE_FLOATS) as u32);
            guides.extend_from_slice(&table);
        }
    }
    // A handful of guides among many points changes nothing to see, while every camera
    // sample would pay a lookup: the rays stay cosine-distributed everywhere.
    let histograms = points.iter().filter(|p| p.3.is_some()).count();
    if guide_cells.len() * MIN_GUIDED_SHARE < histograms {
        return Default::default();
    }
    (guide_cells, guides, levels)
}

impl IrradianceCache {
    /// Estimates irradiance at every `every`-th photon of `map` with `kernel` (radii below
    /// `r_min` are raised to it). `r_lookup` bounds the nearest-point search.
    /// Where the map keeps its photons' incoming directions, each point also gets a
    /// final-gather guide ([`guide`]).
    pub fn build(
        map: &PhotonMap,
        grid: &BinGrid,
        kernel: Kernel,
        every: usize,
        r_min: f32,
        r_lookup: f32,
    ) -> Self {
        let n = grid.len();
        let guided = map.keeps_incoming();
        // Smits triplets are kept as triplets (decoded per lookup at O(N)); colour
        // triplets would need a Jakob–Hanika decode per lookup, so their cache keeps N
        // floats per point (decoded once per point).
        let record =
            if grid.smits_triplets() && matches!(map.record(), Record::Compact | Record::Packed) {
                Record::Compact
            } else {
                Record::Full
            };
        let stride = record.flux_stride(n);
        // Points are about √every photon spacings apart where photons are typical; the
        // typical k-nearest radius spans √k spacings.
        let spacing =
            kernel.r_start / (kernel.k.max(1) as f32).sqrt() * (every.max(1) as f32).sqrt();
        let inv_cell = if spacing > 0.0 && spacing.is_finite() {
            1.0 / spacing
        } else {
            0.0
        };
        let ids = thin_out(map, every, inv_cell);
        // Chunks of neighbouring points (the map is in kd order): each estimate's search
        // starts at the previous one's radius, reset per chunk so that the result never
        // depends on the thread count.
        type Point = ([f32; 3], u32, Vec<f32>, Histogram);
        let estimates: Vec<Point> = ids
            .par_chunks(HINT_CHUNK)
            .flat_map_iter(|chunk| {
                let (mut found, mut e, mut hint) = (Vec::new(), vec![0.0f32; n], 0.0);
                chunk
                    .iter()
                    .map(|&i| {
                        let normal = map.normal_code(i);
                        e.fill(0.0);
                        let k = kernel.starting_at(hint);
                        let nrm = oct_decode(normal);
                        // From the other photons: the point's own would bias it.
                        let est = map.estimate_at_photon(grid, i, k, &mut found, &mut e);
                        hint = est.r_k;
                        let histogram = guided.then(|| histogram_of(map, n, nrm, &found, est.r));
                        let r = est.r.max(r_min);
                        spd::scale(&mut e, 1.0 / (std::f32::consts::PI * r * r));
                        let value = match (record, grid.smits()) {
                            (Record::Compact, Some(_)) => grid.encode_triplet(&e).to_vec(),
                            _ => e.clone(),
                        };
                        (map.positions()[i], normal, value, histogram.flatten())
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        let raw: Vec<[f32; 3]> = estimates.iter().map(|e| e.0).collect();
        let (order, axes) = kdtree::build_order(&raw);
        let mut positions = Vec::with_capacity(order.len());
        let mut normals = Vec::with_capacity(order.len());
        let mut values = Vec::with_capacity(order.len() * stride);
        let mut cells = CellMap::default();
        for &o in &order {
            let (pos, normal, value, _) = &estimates[o as usize];
            let key = cell_key(Vec3::from_array(*pos), oct_decode(*normal), inv_cell);
            cells.insert(key, positions.len() as u32);
            positions.push(*pos);
            normals.push(*normal);
            values.extend_from_slice(value);
        }
        let inv_guide_cell = inv_cell / GUIDE_CELLS;
        let (guide_cells, guides, guide_levels) = if guided {
            guides_by_cube(&estimates, inv_guide_cell)
        } else {
            Default::default()
        };
        Self {
            positions,
            normals,
            axes,
            record,
            stride,
            values,
            r_lookup,
            cells,
            inv_cell,
            guide_cells,
            inv_guide_cell,
            guides,
            guide_levels,
            id: CACHE_IDS.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
        }
    }

    /// Final-gather guides kept (one per guided cube).
    pub fn guides(&self) -> usize {
        self.guides.len() / guide::GUIDE_FLOATS
    }

    /// The final-gather guide (see [`guide::warp`]) of the finest cube holding `p` that
    /// has one, for the surface orientation of the side `n` faces, if any (see
    /// [`guides_by_cube`]). `memo` remembers the last answer (see [`GuideMemo`]).
    #[inline]
    pub fn guide_at(&self, p: Vec3, n: Vec3, memo: &mut GuideMemo) -> Option<&[f32]> {
        if self.guides.is_empty() {
            return None;
        }
        let key = guide_key(p, n, self.inv_guide_cell, 0);
        let g = match memo.0 {
            Some((id, k, g)) if id == self.id && k == key => g,
            _ => {
                let mut levels = self.guide_levels;
                let mut found = None;
                while levels != 0 {
                    let l = levels.trailing_zeros() as u8;
                    levels &= levels - 1;
                    if let Some(&g) = self
                        .guide_cells
                        .get(&guide_key(p, n, self.inv_guide_cell, l))
                    {
                        found = Some(g);
                        break;
                    }
                }
                memo.0 = Some((self.id, key, found));
                found
            }
        };
        let g = g? as usize;
        Some(&self.guides[g * guide::GUIDE_FLOATS..(g + 1) * guide::GUIDE_FLOATS])
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Bytes of the points, their normals and values, the kd axis bytes and the cell map.
    pub fn memory_bytes(&self) -> usize {
        self.positions.len() * 12
            + self.normals.len() * 4
            + self.values.len() * 4
            + self.axes.len()
            + self.guides.len() * 4
            + (self.cells.capacity() + self.guide_cells.capacity())
                * (size_of::<(CellKey, u32)>() + 1)
    }

    /// The irradiance (N bins) of the nearest point on the surface and side `n` faces at
    /// `p`, into `out`; false (and `out` zero) when no point lies within the lookup radius.
    pub fn lookup(&self, grid: &BinGrid, p: Vec3, n: Vec3, out: &mut [f32]) -> bool {
        match self.nearest(p, n) {
            Some(i) => {
                self.value_into(grid, i, out);
                true
            }
            None => {
                out.fill(0.0);
                false
            }
        }
    }

    /// The nearest point on the surface and side `n` faces at `p`, within the lookup
    /// radius (the point [`Self::lookup`] reads).
    #[inline]
    pub fn nearest(&self, p: Vec3, n: Vec3) -> Option<usize> {
        let test = SurfaceTest::new(&self.positions, |i| self.normals[i], p, n);
        let accept = |i: usize| test.accepts(i);
        // The point in the query's own cell, if it has one on the query's surface: within
        // a cell's diagonal of it, which is as close as the points' spacing resolves (a
        // hash probe instead of a tree search for most rays). Else one nearest-neighbour
        // search out to the cap: it visits the near side first, so its radius drops to the
        // nearest point's distance almost at once.
        match self.cells.get(&cell_key(p, n, self.inv_cell)) {
            Some(&i) if accept(i as usize) => Some(i as usize),
            _ => {
                let r2 = self.r_lookup * self.r_lookup;
                kdtree::nearest_within(&self.positions, &self.axes, p, r2, accept)
                    .map(|(_, i)| i as usize)
            }
        }
    }

    /// Point `i`'s irradiance as N floats, when the cache keeps it so (else None: see
    /// [`Self::value_into`]).
    #[inline]
    pub fn value(&self, i: usize) -> Option<&[f32]> {
        (self.record == Record::Full).then(|| &self.values[i * self.stride..(i + 1) * self.stride])
    }

    /// Point `i`'s irradiance (N bins) into `out`.
    pub fn value_into(&self, grid: &BinGrid, i: usize, out: &mut [f32]) {
        let v = &self.values[i * self.stride..(i + 1) * self.stride];
        match (self.record, grid.smits()) {
            (Record::Compact, Some(_)) => {
                out.fill(0.0);
                grid.decode_triplet_into([v[0], v[1], v[2]], out)
            }
            // Every bin overwritten: no clearing first.
            _ => out.copy_from_slice(v),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photon::PhotonBatch;
    use crate::photon::map::tests::uniform_unit_square;
    use crate::sampling::{Purpose, Rng};

    #[test]
    fn uniform_photons_give_their_irradiance_at_every_lookup() {
        // E = 4 per unit area.
        let grid = BinGrid::with_bins(4).unwrap();
        for record in [Record::Full, Record::Compact] {
            let map = uniform_unit_square(&grid, record, 2);
            let kernel = Kernel {
                k: 64,
                r_max: 0.2,
                r_start: 0.03,
                shrink: 0.7,
            };
            let cache = IrradianceCache::build(&map, &grid, kernel, 4, 1e-6, 0.1);
            // Every 4th photon, a few merged where two fall in one cell.
            assert!((7_000..=10_000).contains(&cache.len()), "{}", cache.len());
            let mut out = vec![0.0; 4];
            let mut sum = 0.0;
            for i in 0..400 {
                let p = Vec3::new(
                    0.3 + 0.4 * (i % 20) as f32 / 20.0,
                    0.3 + 0.4 * (i / 20) as f32 / 20.0,
                    0.0,
                );
                assert!(cache.lookup(&grid, p, Vec3::Z, &mut out));
                // Luminance relative to the flat flux's: compact records keep a flux's
                // colour, not its bins (a flat flux comes back D65-shaped).
                sum += grid.to_xyz(&out)[1] / grid.to_xyz(&[1.0; 4])[1];
            }
            let mean = sum / 400.0;
            assert!((mean / 4.0 - 1.0).abs() < 0.03, "{record:?}: {mean}");
            // The other side of the surface finds nothing.
            assert!(!cache.lookup(&grid, Vec3::new(0.5, 0.5, 0.0), -Vec3::Z, &mut out));
        }
    }

    /// A known bias, pinned down: in a uniform region the cache's nearest-point lookups read
    /// about 3 % dark, because its points sit at photons of the map their own estimates
    /// count. Where photons happen to be sparse, points are too, so those points' low
    /// estimates own larger Voronoi cells and are read more often. The control: the same
    /// points given estimates from an independent map (another seed) read the exact value
    /// within noise. Session 37 measured, over 12 seeds: 3.867 against 3.994 (exact 4);
    /// with kd leaves of 32 photons, 3.874 against 3.985. The cache's fix (BENCHMARKS.md,
    /// session 37) must make the first figure exact too: then this test's second
    /// assertion is to become `(same / 4 - 1).abs() < 0.01`.
    #[test]
    fn points_placed_by_their_own_photons_read_dark_in_a_uniform_region() {
        let grid = BinGrid::with_bins(4).unwrap();
        let kernel = Kernel {
            k: 64,
            r_max: 0.2,
            r_start: 0.03,
            shrink: 0.7,
        };
        let (mut all_same, mut all_ind) = (0.0, 0.0);
        for seed in 1..=12u64 {
            let a = uniform_unit_square(&grid, Record::Full, seed);
            let b = uniform_unit_square(&grid, Record::Full, seed + 1000);
            // Points: every 4th photon of `a` (kd order). Values: estimates on `a` (each
            // without its own photon, as the cache makes them) or on the independent `b`.
            let ids: Vec<usize> = (0..a.len()).step_by(4).collect();
            let pts: Vec<[f32; 3]> = ids.iter().map(|&i| a.positions()[i]).collect();
            let (order, axes) = kdtree::build_order(&pts);
            let pts_kd: Vec<[f32; 3]> = order.iter().map(|&o| pts[o as usize]).collect();
            let mut found = Vec::new();
            let mut e = vec![0.0f32; 4];
            let mut val = |m: &PhotonMap, i: Option<usize>, p: Vec3| {
                e.fill(0.0);
                let est = match i {
                    Some(i) => m.estimate_at_photon(&grid, i, kernel, &mut found, &mut e),
                    None => m.estimate(&grid, p, Vec3::Z, kernel, &mut found, &mut e),
                };
                (grid.to_xyz(&e)[1] / grid.to_xyz(&[1.0; 4])[1])
                    / (std::f64::consts::PI * (est.r as f64).powi(2))
            };
            let same: Vec<f64> = order
                .iter()
                .map(|&o| val(&a, Some(ids[o as usize]), Vec3::ZERO))
                .collect();
            let ind: Vec<f64> = order
                .iter()
                .map(|&o| val(&b, None, Vec3::from_array(pts[o as usize])))
                .collect();
            let (mut s1, mut s2) = (0.0, 0.0);
            for i in 0..400 {
                let p = Vec3::new(
                    0.3 + 0.4 * (i % 20) as f32 / 20.0,
                    0.3 + 0.4 * (i / 20) as f32 / 20.0,
                    0.0,
                );
                let (_, j) = kdtree::nearest_within(&pts_kd, &axes, p, 0.01, |_| true).unwrap();
                s1 += same[j as usize];
                s2 += ind[j as usize];
            }
            println!(
                "seed {seed}: lookups of own-photon values {:.4}, of independent values {:.4}",
                s1 / 400.0,
                s2 / 400.0
            );
            all_same += s1 / 400.0;
            all_ind += s2 / 400.0;
        }
        let (same, independent) = (all_same / 12.0, all_ind / 12.0);
        println!(
            "mean over seeds: own-photon values {same:.4}, independent values {independent:.4} (exact 4)"
        );
        // The control: points and lookups are sound when the values are independent.
        assert!((independent / 4.0 - 1.0).abs() < 0.01, "{independent}");
        // The bias: the cache's own values read dark by about σ² (σ ≈ 18 % here).
        assert!(
            same / independent < 0.985 && same / independent > 0.94,
            "{same} against {independent}"
        );
    }

    #[test]
    fn a_crowd_of_photons_gets_one_point_per_cell() {
        // 40 000 photons uniform on the unit square plus 40 000 crowded into a 0.02-wide
        // caustic: the crowd adds points only one cell apart, not one per 4 photons.
        let grid = BinGrid::with_bins(4).unwrap();
        let mut b = PhotonBatch::new(Record::Compact, &grid);
        let mut rng = Rng::stream(3, 0, 0, Purpose::Photon);
        for i in 0..80_000 {
            let [x, y] = rng.next_2d();
            let (x, y) = if i % 2 == 0 {
                (x, y)
            } else {
                (0.5 + 0.02 * x, 0.5 + 0.02 * y)
            };
            b.push(&grid, Vec3::new(x, y, 0.0), Vec3::Z, &[1e-4; 4]);
        }
        let map = PhotonMap::build(b);
        let kernel = Kernel {
            k: 64,
            r_max: 0.2,
            r_start: 0.03,
            shrink: 1.0,
        };
        let cache = IrradianceCache::build(&map, &grid, kernel, 4, 1e-6, 0.1);
        // Cells of 0.0075: the crowd spans at most 4 × 4 of them.
        assert!(cache.len() <= 10_000 + 16, "{}", cache.len());
        let mut out = vec![0.0; 4];
        // The crowd's irradiance (4 + 4/0.0004 = 10 004 per unit area) is still read there.
        assert!(cache.lookup(&grid, Vec3::new(0.51, 0.51, 0.0), Vec3::Z, &mut out));
        assert!(out[0] > 1000.0, "{}", out[0]);
    }

    /// The mean cache lookup over a window across a bright patch's edge, relative to the
    /// exact mean: the left half has 64× the right half's photons (equal fluxes), so 64×
    /// its irradiance.
    fn mean_across_an_edge(every: usize) -> f32 {
        let grid = BinGrid::with_bins(4).unwrap();
        let mut b = PhotonBatch::new(Record::Full, &grid);
        let mut rng = Rng::stream(5, 0, 0, Purpose::Photon);
        let (dark, bright) = (1_000, 64_000);
        for i in 0..dark + bright {
            let [x, y] = rng.next_2d();
            let x = if i < dark { 0.5 + 0.5 * x } else { 0.5 * x };
            b.push(&grid, Vec3::new(x, y, 0.0), Vec3::Z, &[1e-4; 4]);
        }
        let map = PhotonMap::build(b);
        // Irradiance per unit area: photons × flux / area, each half 0.5 of the square.
        let (e_dark, e_bright) = (dark as f32 * 1e-4 / 0.5, bright as f32 * 1e-4 / 0.5);
        let kernel = Kernel {
            k: 32,
            r_max: 0.2,
            r_start: map.typical_knn_radius(32, 256).unwrap(),
            shrink: 1.0,
        };
        let cache = IrradianceCache::build(&map, &grid, kernel, every, 1e-6, 0.2);
        let mut out = vec![0.0; 4];
        let (n, mut sum) = (200, 0.0);
        for i in 0..n * n {
            let p = Vec3::new(
                0.25 + 0.5 * ((i % n) as f32 + 0.5) / n as f32,
                0.25 + 0.5 * ((i / n) as f32 + 0.5) / n as f32,
                0.0,
            );
            assert!(cache.lookup(&grid, p, Vec3::Z, &mut out));
            sum += out[0];
        }
        sum / (n * n) as f32 / (0.5 * (e_dark + e_bright))
    }

    #[test]
    fn the_nearest_point_leans_to_the_bright_side_by_its_spacing() {
        // Points sit at photons, which crowd on the bright side: a lookup on the dark side
        // near the edge finds a bright point first more often than the reverse, about half
        // the dark side's point spacing into the dark. The bias goes with the spacing, so
        // the session thins points out less as the radius shrinks (`precompute_every`).
        use crate::render::session::{PRECOMPUTE_EVERY, precompute_every};
        let by_step: Vec<f32> = [1, 2, 4, 8, 16].map(mean_across_an_edge).to_vec();
        println!(
            "mean across an edge / exact, every 1st, 2nd, 4th, 8th, 16th photon: {by_step:.4?}"
        );
        // Measured: 0.993, 1.000, 1.016, 1.039, 1.067.
        let first = mean_across_an_edge(precompute_every(1.0));
        assert_eq!(precompute_every(1.0), PRECOMPUTE_EVERY);
        assert!(first > 1.04, "{first}");
        // From the 2nd photon on the bias grows with the step (at 1 and 2 the points are
        // as dense as the estimates resolve, and the two differ by noise).
        assert!(
            by_step.windows(2).skip(1).all(|w| w[1] > w[0]),
            "{by_step:?}"
        );
        // Late passes (the radius shrunk to 0.15 of the first pass's): every 2nd photon.
        let late = mean_across_an_edge(precompute_every(0.15));
        assert!((late - 1.0).abs() < 0.01, "{late}");
        assert_eq!(
            (precompute_every(0.0), precompute_every(f32::NAN)),
            (1, PRECOMPUTE_EVERY)
        );
    }
}
