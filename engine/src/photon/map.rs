//! One photon-map type over the three storage formats: records in kd order plus the
//! density-estimation query that turns them back into N bins.

use glam::Vec3;

use super::kdtree;
use super::record::{PhotonHeader, Record, decode_spike, encode_spike};
use crate::spectral::smits::BranchSums;
use crate::spectral::{BinGrid, spd};

/// Photons as the tracer produces them, not yet searchable.
#[derive(Clone, Debug)]
pub struct PhotonBatch {
    record: Record,
    stride: usize,
    pub headers: Vec<PhotonHeader>,
    pub flux: Vec<f32>,
    pub spikes: usize,
}

impl PhotonBatch {
    /// An empty batch of `record`s for `grid`. Compact records need a spectral grid; on
    /// the RGB grid a "triplet" is the flux itself, so full records are kept (same bytes).
    pub fn new(record: Record, grid: &BinGrid) -> Self {
        let record = if grid.smits().is_some() {
            record
        } else {
            Record::Full
        };
        Self {
            record,
            stride: record.flux_stride(grid.len()),
            headers: Vec::new(),
            flux: Vec::new(),
            spikes: 0,
        }
    }

    pub fn len(&self) -> usize {
        self.headers.len()
    }

    pub fn is_empty(&self) -> bool {
        self.headers.is_empty()
    }

    /// Stores a photon's flux in this batch's format. Photons with no (or non-finite)
    /// flux are never stored.
    pub fn push(&mut self, grid: &BinGrid, pos: Vec3, dir: Vec3, flux: &[f32]) {
        if !(spd::sum(flux) > 0.0) || !spd::all_finite(flux) {
            return;
        }
        self.headers.push(PhotonHeader::new(pos, dir));
        match (self.record, grid.smits()) {
            (Record::Compact, Some(smits)) => {
                let rec = match spd::single_nonzero(flux) {
                    Some(bin) => {
                        self.spikes += 1;
                        encode_spike(bin, flux[bin])
                    }
                    None => smits.encode(flux),
                };
                self.flux.extend_from_slice(&rec);
            }
            _ => self.flux.extend_from_slice(flux),
        }
    }

    /// Bytes these photons will take in a map (records + kd axis byte).
    pub fn memory_bytes(&self) -> usize {
        self.headers.len() * (size_of::<PhotonHeader>() + 1) + self.flux.len() * 4
    }

    pub fn append(&mut self, mut other: PhotonBatch) {
        self.headers.append(&mut other.headers);
        self.flux.append(&mut other.flux);
        self.spikes += other.spikes;
    }
}

/// A searchable photon map.
#[derive(Clone, Debug)]
pub struct PhotonMap {
    record: Record,
    stride: usize,
    positions: Vec<[f32; 3]>,
    dirs: Vec<u32>,
    flux: Vec<f32>,
    axes: Vec<u8>,
    spikes: usize,
}

impl PhotonMap {
    /// Reorders the batch into a balanced kd-tree.
    pub fn build(batch: PhotonBatch) -> Self {
        let raw_pos: Vec<[f32; 3]> = batch.headers.iter().map(|h| h.pos).collect();
        let (order, axes) = kdtree::build_order(&raw_pos);
        let stride = batch.stride;
        let mut positions = Vec::with_capacity(order.len());
        let mut dirs = Vec::with_capacity(order.len());
        let mut flux = Vec::with_capacity(batch.flux.len());
        for &i in &order {
            let i = i as usize;
            positions.push(raw_pos[i]);
            dirs.push(batch.headers[i].dir);
            flux.extend_from_slice(&batch.flux[i * stride..(i + 1) * stride]);
        }
        Self {
            record: batch.record,
            stride,
            positions,
            dirs,
            flux,
            axes,
            spikes: batch.spikes,
        }
    }

    pub fn record(&self) -> Record {
        self.record
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Spike records (compact storage only).
    pub fn spike_records(&self) -> usize {
        self.spikes
    }

    /// Exact bytes of the records and the search structure (kd axis bytes).
    pub fn memory_bytes(&self) -> usize {
        self.positions.len() * 12 + self.dirs.len() * 4 + self.flux.len() * 4 + self.axes.len()
    }

    pub fn positions(&self) -> &[[f32; 3]] {
        &self.positions
    }

    /// Median distance from a spread of stored photons to their k-th nearest neighbour: a
    /// scale for the gather radius that adapts to how densely photons land.
    pub fn typical_knn_radius(&self, k: usize, samples: usize) -> Option<f32> {
        if self.len() < 2 {
            return None;
        }
        let step = (self.len() / samples.max(1)).max(1);
        let mut d: Vec<f32> = (0..self.len())
            .step_by(step)
            .map(|i| {
                kdtree::kth_nearest_distance(
                    &self.positions,
                    &self.axes,
                    Vec3::from_array(self.positions[i]),
                    k + 1, // the photon itself is its own nearest
                )
            })
            .filter(|v| v.is_finite() && *v > 0.0)
            .collect();
        if d.is_empty() {
            return None;
        }
        d.sort_by(f32::total_cmp);
        Some(d[d.len() / 2])
    }

    /// Adds to `out` (N bins) the flux of every photon within `radius` of `p` that arrived
    /// on the side `n` faces (travel direction · n < 0). Returns how many were found.
    /// Compact records are expanded as the paper prescribes (spike → its bin; triplet →
    /// Smits), summed per Smits branch so that each photon costs O(1).
    pub fn gather(&self, grid: &BinGrid, p: Vec3, n: Vec3, radius: f32, out: &mut [f32]) -> usize {
        let mut count = 0;
        let r2 = radius * radius;
        let facing = |i: usize| super::record::oct_decode(self.dirs[i]).dot(n) < 0.0;
        match self.record {
            Record::Full => {
                let s = self.stride;
                kdtree::for_each_within(&self.positions, &self.axes, p, r2, |i, _| {
                    if facing(i) {
                        spd::add_scaled(out, &self.flux[i * s..(i + 1) * s], 1.0);
                        count += 1;
                    }
                });
            }
            Record::Compact => {
                let mut sums = BranchSums::default();
                kdtree::for_each_within(&self.positions, &self.axes, p, r2, |i, _| {
                    if facing(i) {
                        let rec = [self.flux[3 * i], self.flux[3 * i + 1], self.flux[3 * i + 2]];
                        match decode_spike(rec) {
                            Some((bin, a)) => {
                                if let Some(v) = out.get_mut(bin) {
                                    *v += a;
                                }
                            }
                            None => sums.add(rec, 1.0),
                        }
                        count += 1;
                    }
                });
                if let Some(smits) = grid.smits() {
                    sums.expand_into(smits, out);
                }
            }
        }
        count
    }

    /// The flux of stored photon `i` in N bins (for tests and the probe).
    pub fn flux_of(&self, grid: &BinGrid, i: usize, out: &mut [f32]) {
        out.fill(0.0);
        let rec = &self.flux[i * self.stride..(i + 1) * self.stride];
        match self.record {
            Record::Full => out.copy_from_slice(rec),
            Record::Compact => match decode_spike([rec[0], rec[1], rec[2]]) {
                Some((bin, a)) => out[bin] = a,
                None => {
                    if let Some(s) = grid.smits() {
                        s.decode_into([rec[0], rec[1], rec[2]], out)
                    }
                }
            },
        }
    }
}
