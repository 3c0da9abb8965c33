//! Precomputed irradiance (Christensen 1999, "Faster photon map global illumination"):
//! once per pass, the irradiance of the global map is estimated at every `every`-th
//! stored photon (its k-nearest density estimate, at the photon's own position and
//! normal); a final-gather ray then reads the irradiance of the nearest such point on its
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

use super::kdtree;
use super::map::{Kernel, PhotonMap};
use super::record::{Record, oct_decode, oct_within};
use crate::spectral::{BinGrid, spd};

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
    /// First radius a lookup searches (most find their point within it).
    r_near: f32,
}

impl IrradianceCache {
    /// Estimates irradiance at every `every`-th photon of `map` with `kernel` (radii below
    /// `r_min` are raised to it). `r_lookup` bounds the nearest-point search.
    pub fn build(
        map: &PhotonMap,
        grid: &BinGrid,
        kernel: Kernel,
        every: usize,
        r_min: f32,
        r_lookup: f32,
    ) -> Self {
        let n = grid.len();
        let record = if grid.smits().is_some() {
            map.record()
        } else {
            Record::Full
        };
        let stride = record.flux_stride(n);
        let ids: Vec<usize> = (0..map.len()).step_by(every.max(1)).collect();
        let estimates: Vec<([f32; 3], u32, Vec<f32>)> = ids
            .par_iter()
            .map_init(
                || (Vec::new(), vec![0.0f32; n]),
                |(found, e), &i| {
                    let p = Vec3::from_array(map.positions()[i]);
                    let normal = map.normal_code(i);
                    e.fill(0.0);
                    let r = map
                        .estimate(grid, p, oct_decode(normal), kernel, found, e)
                        .max(r_min);
                    spd::scale(e, 1.0 / (std::f32::consts::PI * r * r));
                    let value = match (record, grid.smits()) {
                        (Record::Compact, Some(smits)) => smits.encode(e).to_vec(),
                        _ => e.clone(),
                    };
                    (map.positions()[i], normal, value)
                },
            )
            .collect();
        let raw: Vec<[f32; 3]> = estimates.iter().map(|e| e.0).collect();
        let (order, axes) = kdtree::build_order(&raw);
        let mut positions = Vec::with_capacity(order.len());
        let mut normals = Vec::with_capacity(order.len());
        let mut values = Vec::with_capacity(order.len() * stride);
        for &o in &order {
            let (pos, normal, value) = &estimates[o as usize];
            positions.push(*pos);
            normals.push(*normal);
            values.extend_from_slice(value);
        }
        // Points are about √every photon spacings apart; the typical k-nearest radius
        // spans √k spacings, so a small multiple of r_start/√k·√every finds the nearest.
        let spacing =
            kernel.r_start / (kernel.k.max(1) as f32).sqrt() * (every.max(1) as f32).sqrt();
        Self {
            positions,
            normals,
            axes,
            record,
            stride,
            values,
            r_lookup,
            r_near: (3.0 * spacing).min(r_lookup),
        }
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Bytes of the points, their normals and values, and the kd axis bytes.
    pub fn memory_bytes(&self) -> usize {
        self.positions.len() * 12 + self.normals.len() * 4 + self.values.len() * 4 + self.axes.len()
    }

    /// The irradiance (N bins) of the nearest point on the surface and side `n` faces at
    /// `p`, into `out`; false (and `out` zero) when no point lies within the lookup radius.
    pub fn lookup(
        &self,
        grid: &BinGrid,
        p: Vec3,
        n: Vec3,
        found: &mut Vec<(f32, u32)>,
        out: &mut [f32],
    ) -> bool {
        out.fill(0.0);
        let accept = |i: usize| {
            let d = Vec3::from_array(self.positions[i]) - p;
            let h = d.dot(n);
            h * h <= (1.0 / 64.0) * d.length_squared() + 1e-12
                && oct_within(self.normals[i], n, super::map::MIN_NORMAL_COS)
        };
        for r in [
            self.r_near,
            4.0 * self.r_near,
            16.0 * self.r_near,
            self.r_lookup,
        ] {
            let r = r.min(self.r_lookup);
            kdtree::k_nearest_within(&self.positions, &self.axes, p, 1, r * r, accept, found);
            if !found.is_empty() {
                break;
            }
        }
        let Some(&(_, i)) = found.first() else {
            return false;
        };
        let v = &self.values[i as usize * self.stride..(i as usize + 1) * self.stride];
        match (self.record, grid.smits()) {
            (Record::Compact, Some(smits)) => smits.decode_into([v[0], v[1], v[2]], out),
            _ => out.copy_from_slice(v),
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photon::PhotonBatch;
    use crate::sampling::{Purpose, Rng};

    #[test]
    fn uniform_photons_give_their_irradiance_at_every_lookup() {
        // 40 000 photons of flux 1e-4 uniform on the unit square: E = 4 per unit area.
        let grid = BinGrid::with_bins(4).unwrap();
        for record in [Record::Full, Record::Compact] {
            let mut b = PhotonBatch::new(record, &grid);
            let mut rng = Rng::stream(2, 0, 0, Purpose::Photon);
            for _ in 0..40_000 {
                let [x, y] = rng.next_2d();
                b.push(&grid, Vec3::new(x, y, 0.0), Vec3::Z, &[1e-4; 4]);
            }
            let map = PhotonMap::build(b);
            let kernel = Kernel {
                k: 64,
                r_max: 0.2,
                r_start: 0.03,
                shrink: 0.7,
            };
            let cache = IrradianceCache::build(&map, &grid, kernel, 4, 1e-6, 0.1);
            assert_eq!(cache.len(), 10_000);
            let (mut found, mut out) = (Vec::new(), vec![0.0; 4]);
            let mut sum = 0.0;
            for i in 0..400 {
                let p = Vec3::new(
                    0.3 + 0.4 * (i % 20) as f32 / 20.0,
                    0.3 + 0.4 * (i / 20) as f32 / 20.0,
                    0.0,
                );
                assert!(cache.lookup(&grid, p, Vec3::Z, &mut found, &mut out));
                sum += out.iter().sum::<f32>() as f64 / 4.0;
            }
            let mean = sum / 400.0;
            assert!((mean / 4.0 - 1.0).abs() < 0.03, "{record:?}: {mean}");
            // The other side of the surface finds nothing.
            assert!(!cache.lookup(
                &grid,
                Vec3::new(0.5, 0.5, 0.0),
                -Vec3::Z,
                &mut found,
                &mut out
            ));
        }
    }
}
