//! One photon-map type over the three storage formats: records in kd order plus the
//! density-estimation query that turns them back into N bins.

use glam::Vec3;

use std::cell::Cell;
use std::sync::OnceLock;

use super::kdtree;
use super::occupancy::Occupancy;
use super::record::{
    NormalCode, PhotonHeader, Record, decode_spike, encode_spike, oct_decode, oct_from_16,
    oct_to_16, pack_record, unpack_record,
};
use crate::spectral::smits::BranchSums;
use crate::spectral::{BinGrid, spd};

thread_local! {
    /// A decoded colour triplet (N bins), reused by every estimate on this thread.
    static DECODED: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
    /// A spiked record's residual and its decoding (2 × N bins), reused per photon.
    static RESIDUAL: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Squared distance between `flux` and the triplet `t` decoded, plus `amp` in `bin`.
fn decoded_error(
    grid: &BinGrid,
    flux: &[f32],
    t: [f32; 3],
    spike: (usize, f32),
    buf: &mut [f32],
) -> f32 {
    grid.decode_triplet_into(t, buf);
    buf[spike.0] += spike.1;
    flux.iter()
        .zip(buf.iter())
        .map(|(a, b)| (a - b) * (a - b))
        .sum()
}

/// A spiked record (see [`Record::Spiked`]) of a flux with two or more non-zero bins: the
/// bin standing highest above its neighbours (its excess over the larger of them) is kept
/// exactly as `(bin, excess)` and the rest, that bin lowered to its neighbour, becomes the
/// triplet — when that decodes closer to `flux` (squared error over the bins) than the
/// flux's own triplet does; else the plain triplet with a zero spike. Excesses under 2 %
/// of the flux are not tried.
pub fn encode_spiked(grid: &BinGrid, flux: &[f32]) -> [f32; 5] {
    let n = flux.len();
    let neighbour = |b: usize| {
        let l = if b > 0 { flux[b - 1] } else { 0.0 };
        let r = if b + 1 < n { flux[b + 1] } else { 0.0 };
        l.max(r)
    };
    let (bin, excess) = (0..n)
        .map(|b| (b, flux[b] - neighbour(b)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, 0.0));
    let plain = grid.encode_triplet(flux);
    // A bin less than 2 % of the flux above its neighbours is no line worth a spike (and
    // smooth spectra skip the two trial decodings).
    if !(excess > 0.02 * spd::sum(flux)) {
        return [plain[0], plain[1], plain[2], 0.0, 0.0];
    }
    RESIDUAL.with_borrow_mut(|buf| {
        buf.clear();
        buf.extend_from_slice(flux);
        buf[bin] -= excess;
        buf.resize(2 * n, 0.0);
        let (residual, decoded) = buf.split_at_mut(n);
        let t = grid.encode_triplet(residual);
        let with_spike = decoded_error(grid, flux, t, (bin, excess), decoded);
        let without = decoded_error(grid, flux, plain, (0, 0.0), decoded);
        if with_spike < without {
            [t[0], t[1], t[2], bin as f32, excess]
        } else {
            [plain[0], plain[1], plain[2], 0.0, 0.0]
        }
    })
}

/// Photons as the tracer produces them, not yet searchable.
#[derive(Clone, Debug)]
pub struct PhotonBatch {
    record: Record,
    stride: usize,
    pub headers: Vec<PhotonHeader>,
    pub flux: Vec<f32>,
    /// Packed records (packed storage only; `flux` is then empty).
    pub packed: Vec<u32>,
    pub spikes: usize,
    /// Each photon's [`IncomingCode`], one per header, when the batch keeps them (see
    /// [`super::PhotonSettings::incoming`]); else empty.
    pub incoming: Vec<u16>,
}

/// Where a stored photon came from, for guiding final-gather rays: the direction back
/// along its last flight in 2×8-bit octahedral code ([`oct_to_16`]), or
/// [`IncomingCode::NONE`] for a photon whose last flight did not start at a diffuse
/// surface: one straight from a light (direct lighting's), or through glass or off a
/// mirror (a final-gather ray sent back through dispersive glass carries one wavelength:
/// colour noise, not light).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IncomingCode(pub u16);

impl IncomingCode {
    pub const NONE: Self = Self(0);

    /// The code of a photon that left a diffuse surface along `dir` (travelling), which
    /// it came from: −`dir`. Never [`Self::NONE`] (a code of 0 moves one step, a fraction
    /// of a degree).
    pub fn from_travel(dir: Vec3) -> Self {
        Self(oct_to_16(super::record::oct_encode(-dir)).max(1))
    }

    /// The unit direction the photon came from, or None.
    pub fn direction(self) -> Option<Vec3> {
        (self != Self::NONE).then(|| oct_decode(oct_from_16(self.0)))
    }
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
            packed: Vec::new(),
            spikes: 0,
            incoming: Vec::new(),
        }
    }

    pub fn len(&self) -> usize {
        self.headers.len()
    }

    /// Records `code` for the photons pushed since the batch held `before` (none, one,
    /// or none when the push rejected its flux), keeping one code per photon.
    pub fn tag_incoming(&mut self, before: usize, code: IncomingCode) {
        debug_assert_eq!(self.incoming.len(), before);
        self.incoming.resize(self.headers.len(), code.0);
    }

    pub fn is_empty(&self) -> bool {
        self.headers.is_empty()
    }

    /// Room for `photons` more photons without reallocating.
    pub fn reserve(&mut self, photons: usize) {
        self.headers.reserve(photons);
        if self.record == Record::Packed {
            self.packed.reserve(photons);
        } else {
            self.flux.reserve(photons * self.stride);
        }
    }

    /// Stores a photon's flux in this batch's format, with the landing surface's normal
    /// turned towards the side the photon came from. Photons with no (or non-finite) flux
    /// are never stored.
    pub fn push(&mut self, grid: &BinGrid, pos: Vec3, normal: impl Into<NormalCode>, flux: &[f32]) {
        let normal = normal.into();
        // A NaN or infinity in any bin makes the sum NaN or infinite (so does a sum past
        // f32::MAX, which no record could hold): one pass rejects all three.
        let total = spd::sum(flux);
        if !(total > 0.0 && total.is_finite()) {
            return;
        }
        match (self.record, grid.smits()) {
            (Record::Full, _) | (_, None) => {
                self.headers.push(PhotonHeader::new(pos, normal));
                self.flux.extend_from_slice(flux);
            }
            _ => match spd::single_nonzero(flux) {
                // A single-bin flux is a lossless spike in every compact-family record.
                Some(bin) => self.push_single(grid, pos, normal, bin, flux[bin], flux.len()),
                None => {
                    self.headers.push(PhotonHeader::new(pos, normal));
                    match self.record {
                        Record::Spiked => self.flux.extend_from_slice(&encode_spiked(grid, flux)),
                        Record::Packed => self.packed.push(pack_record(grid.encode_triplet(flux))),
                        _ => self.flux.extend_from_slice(&grid.encode_triplet(flux)),
                    }
                }
            },
        }
    }

    /// [`PhotonBatch::push`] of a flux of `n` bins that is `value` in bin `bin` and zero
    /// elsewhere, without reading or building the vector: the same record, bit for bit.
    pub fn push_single(
        &mut self,
        grid: &BinGrid,
        pos: Vec3,
        normal: impl Into<NormalCode>,
        bin: usize,
        value: f32,
        n: usize,
    ) {
        if !(value > 0.0) || !value.is_finite() || bin >= n {
            return;
        }
        self.headers.push(PhotonHeader::new(pos, normal));
        match (self.record, grid.smits()) {
            (Record::Spiked, Some(_)) => {
                self.spikes += 1;
                self.flux.extend_from_slice(&encode_spike(bin, value));
                self.flux.extend_from_slice(&[0.0, 0.0]);
            }
            (Record::Compact | Record::Packed, Some(_)) => {
                self.spikes += 1;
                let rec = encode_spike(bin, value);
                if self.record == Record::Packed {
                    self.packed.push(pack_record(rec));
                } else {
                    self.flux.extend_from_slice(&rec);
                }
            }
            _ => {
                let start = self.flux.len();
                self.flux.resize(start + n, 0.0);
                self.flux[start + bin] = value;
            }
        }
    }

    /// Bytes these photons will take in a map (records + kd axis byte).
    pub fn memory_bytes(&self) -> usize {
        if self.record == Record::Packed {
            return self.headers.len() * super::record::PACKED_BYTES;
        }
        self.headers.len() * (size_of::<PhotonHeader>() + 1)
            + self.flux.len() * 4
            + self.incoming.len() * 2
    }

    pub fn append(&mut self, mut other: PhotonBatch) {
        self.incoming.append(&mut other.incoming);
        self.headers.append(&mut other.headers);
        self.flux.append(&mut other.flux);
        self.packed.append(&mut other.packed);
        self.spikes += other.spikes;
    }

    /// The photons of `batches` one after another (what appending them in order to an
    /// empty batch of `record`s for `grid` gives, to the byte), copied on every thread:
    /// the photon pass's chunks are merged so, where one thread copying them all left the
    /// other idle.
    pub fn concat(record: Record, grid: &BinGrid, batches: Vec<PhotonBatch>) -> Self {
        let mut out = Self::new(record, grid);
        out.spikes = batches.iter().map(|b| b.spikes).sum();
        let keeps_incoming = batches.iter().any(|b| !b.incoming.is_empty());
        out.headers = concat_par(batches.iter().map(|b| &b.headers[..]).collect());
        out.flux = concat_par(batches.iter().map(|b| &b.flux[..]).collect());
        out.packed = concat_par(batches.iter().map(|b| &b.packed[..]).collect());
        if keeps_incoming {
            out.incoming = concat_par(batches.iter().map(|b| &b.incoming[..]).collect());
        }
        out
    }
}

/// `parts` one after another in one vector, each part copied by a rayon task into its
/// own slice of the output.
fn concat_par<T: Copy + Send + Sync>(parts: Vec<&[T]>) -> Vec<T> {
    use rayon::prelude::*;
    let total = parts.iter().map(|p| p.len()).sum();
    let mut out: Vec<T> = Vec::with_capacity(total);
    let spare = &mut out.spare_capacity_mut()[..total];
    let mut slices = Vec::with_capacity(parts.len());
    let mut rest = spare;
    for p in &parts {
        let (head, tail) = rest.split_at_mut(p.len());
        slices.push(head);
        rest = tail;
    }
    slices
        .into_par_iter()
        .zip(parts.into_par_iter())
        .for_each(|(dst, src)| {
            for (d, s) in dst.iter_mut().zip(src) {
                d.write(*s);
            }
        });
    // SAFETY: the slices above cover the first `total` elements exactly once, and every
    // one was written.
    unsafe { out.set_len(total) };
    out
}

/// `pick(i)` for every index `i` of `order`, in that order, computed on every thread.
fn in_order<T: Send>(order: &[u32], pick: impl Fn(usize) -> T + Sync) -> Vec<T> {
    use rayon::prelude::*;
    order.par_iter().map(|&i| pick(i as usize)).collect()
}

/// Smallest cosine between a photon's stored normal and a query's normal for the photon to
/// count (37°): adjacent facets of a tessellated curved surface pass, a perpendicular or
/// opposite face does not.
pub const MIN_NORMAL_COS: f32 = 0.8;

/// How a density estimate chooses its photons (see [`PhotonMap::estimate`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Kernel {
    /// Neighbours the radius adapts to; 0 for a fixed radius.
    pub k: usize,
    /// Largest radius searched (the fixed radius when `k` is 0), scene units.
    pub r_max: f32,
    /// First radius searched: a range search there that finds k photons settles the
    /// query; else range searches at radii grown by the count found, up to `r_max`, do
    /// (the typical k-nearest radius is a good start).
    pub r_start: f32,
    /// This pass's Knaus–Zwicker factor r_k/r_1 (≤ 1).
    pub shrink: f32,
}

/// A regrown k-nearest search aims for this many times k photons (the photon count
/// grows as r², so the radius grows by √(margin·k / found)): too small and it searches
/// a third time, too large and it visits photons it discards. 1.3 was fastest of
/// 1.0–2.0 on the gather benchmark (BENCHMARKS.md, session 21).
const KNN_GROWTH_MARGIN: f32 = 1.3;

/// Fewest neighbours [`Kernel::adaptive`] searches for; below this the shrink is applied
/// to the radius instead.
pub const MIN_SHRUNK_K: usize = 8;

impl Kernel {
    /// A k-nearest kernel at this pass's Knaus–Zwicker `shrink`, searched as cheaply as it
    /// can be. Shrinking the k-nearest radius r_k by s sums on average m = (k−1)·s²
    /// photons; the same is summed, in expectation and at the same expected radius, by
    /// searching only the k' = ⌈m⌉ + 1 nearest (at least [`MIN_SHRUNK_K`], at most k) and
    /// shrinking their radius by s' = √(m / (k'−1)) ≤ 1: in a uniform region
    /// E[(k'−1)·s'² / (π s'² r²_k')] = λ as before. The search radii (`r_start`, `r_max`)
    /// scale by q = √((k'−1)/(k−1)), so a neighbourhood too sparse to hold k' photons
    /// within q·`r_max` is summed within s'·q·`r_max` = s·`r_max`, as the unfolded kernel
    /// sums one holding fewer than k within `r_max`. Late passes thus search for a third of
    /// the photons, not all k, to sum the third they keep.
    pub fn adaptive(k: usize, r_max: f32, r_start: f32, shrink: f32) -> Self {
        let unfolded = Self {
            k,
            r_max,
            r_start,
            shrink,
        };
        if k <= MIN_SHRUNK_K || !(shrink > 0.0 && shrink < 1.0) {
            return unfolded;
        }
        let m = (k - 1) as f64 * f64::from(shrink) * f64::from(shrink);
        let k_eff = ((m.ceil() as usize) + 1).clamp(MIN_SHRUNK_K, k);
        let q = (((k_eff - 1) as f64) / ((k - 1) as f64)).sqrt();
        let s = (m / (k_eff - 1) as f64).sqrt().min(1.0);
        Self {
            k: k_eff,
            r_max: (f64::from(r_max) * q) as f32,
            r_start: (f64::from(r_start) * q) as f32,
            shrink: s as f32,
        }
    }

    /// This kernel with its first search radius at `hint` (a neighbouring query's
    /// k-nearest radius), if one is known (> 0). The result never depends on the start:
    /// only how much searching finds it.
    pub fn starting_at(self, hint: f32) -> Self {
        if self.k > 0 && hint > 0.0 {
            Self {
                r_start: 1.1 * hint,
                ..self
            }
        } else {
            self
        }
    }
}

/// What a density estimate measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// The radius whose photons were summed (divide by π r²).
    pub r: f32,
    /// The k-nearest radius before the pass's shrink (`r_max` when fewer than k were
    /// found; the fixed radius for a fixed kernel): a good start for a neighbour's search.
    pub r_k: f32,
}

/// The same-surface test of [`PhotonMap::estimate`] (and of the irradiance cache's
/// lookups) for one query at `p` facing `n`, remembering the facing test's answer for the
/// last normal code seen: the points of one flat surface share a code, so most candidates
/// skip the octahedral decode (the same answers, tested).
pub(super) struct SurfaceTest<'a, C> {
    positions: &'a [[f32; 3]],
    /// Point i's octahedral normal code.
    code: C,
    p: Vec3,
    n: Vec3,
    last: Cell<(u32, bool)>,
}

impl<'a, C: Fn(usize) -> u32> SurfaceTest<'a, C> {
    pub(super) fn new(positions: &'a [[f32; 3]], code: C, p: Vec3, n: Vec3) -> Self {
        let last = Cell::new((0, super::record::oct_within(0, n, MIN_NORMAL_COS)));
        Self {
            positions,
            code,
            p,
            n,
            last,
        }
    }

    /// Whether point `i` lies on the query's surface and side: its normal within 37° of
    /// `n`, and within a flat slab about the query's tangent plane (|Δ·n| ≤ |Δ|/8).
    #[inline(always)]
    pub(super) fn accepts(&self, i: usize) -> bool {
        let d = Vec3::from_array(self.positions[i]) - self.p;
        let h = d.dot(self.n);
        if h * h > (1.0 / 64.0) * d.length_squared() + 1e-12 {
            return false;
        }
        let code = (self.code)(i);
        let (last, facing) = self.last.get();
        if code == last {
            return facing;
        }
        let facing = super::record::oct_within(code, self.n, MIN_NORMAL_COS);
        self.last.set((code, facing));
        facing
    }
}

/// A searchable photon map.
#[derive(Clone, Debug)]
pub struct PhotonMap {
    record: Record,
    stride: usize,
    positions: Vec<[f32; 3]>,
    /// Octahedral normals in 2×16 bits (2×8 bits in `normals16` for packed records).
    normals: Vec<u32>,
    normals16: Vec<u16>,
    flux: Vec<f32>,
    packed: Vec<u32>,
    /// Incoming codes per photon ([`IncomingCode`]), when the batch kept them; else empty.
    incoming: Vec<u16>,
    axes: Vec<u8>,
    spikes: usize,
    /// Which cubes hold photons, built by the first density estimate for its search cap
    /// (each map is read with one kernel a pass): empty neighbourhoods skip the search.
    occupancy: OnceLock<Occupancy>,
}

impl PhotonMap {
    /// Reorders the batch into a balanced kd-tree.
    pub fn build(batch: PhotonBatch) -> Self {
        use rayon::prelude::*;
        let raw_pos: Vec<[f32; 3]> = batch.headers.par_iter().map(|h| h.pos).collect();
        let (order, axes) = kdtree::build_order(&raw_pos);
        let stride = batch.stride;
        let packed_records = batch.record == Record::Packed;
        let keeps_incoming = batch.incoming.len() == batch.headers.len();
        debug_assert!(keeps_incoming || batch.incoming.is_empty());
        // Each array gathered into kd order on every thread (a serial copy of them all was
        // a fifth of a small scene's photon pass on one core).
        let positions = in_order(&order, |i| raw_pos[i]);
        let incoming = if keeps_incoming {
            in_order(&order, |i| batch.incoming[i])
        } else {
            Vec::new()
        };
        let (mut normals, mut normals16, mut flux, mut packed) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        if packed_records {
            normals16 = in_order(&order, |i| oct_to_16(batch.headers[i].normal));
            packed = in_order(&order, |i| batch.packed[i]);
        } else {
            normals = in_order(&order, |i| batch.headers[i].normal);
            flux = vec![0.0f32; batch.flux.len()];
            if stride > 0 {
                flux.par_chunks_mut(stride)
                    .zip(order.par_iter())
                    .for_each(|(dst, &i)| {
                        let i = i as usize;
                        dst.copy_from_slice(&batch.flux[i * stride..(i + 1) * stride]);
                    });
            }
        }
        Self {
            record: batch.record,
            stride,
            positions,
            normals,
            normals16,
            flux,
            packed,
            incoming,
            axes,
            spikes: batch.spikes,
            occupancy: OnceLock::new(),
        }
    }

    /// Builds now the occupancy grid that the first density estimate with a search cap of
    /// `r_max` would otherwise build, on one thread, while the map's other estimates
    /// waited for it. The pass's kernels are known before its gather (see
    /// `RenderSession::prepare`, which runs beside the previous pass's gather from the
    /// second pass on). A grid already built stays.
    pub fn prepare_search(&self, r_max: f32) {
        if r_max > 0.0 && r_max.is_finite() {
            self.occupancy
                .get_or_init(|| Occupancy::build(&self.positions, r_max));
        }
    }

    /// Whether a photon may lie within `r` of `p` (false only when none does), by the
    /// occupancy grid built for `r_max` on first use (or by [`Self::prepare_search`]).
    fn may_hold_within(&self, p: Vec3, r: f32, r_max: f32) -> bool {
        if !(r_max > 0.0 && r_max.is_finite()) {
            return true;
        }
        let grid = self
            .occupancy
            .get_or_init(|| Occupancy::build(&self.positions, r_max));
        grid.may_hold_within(p, r)
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
        self.positions.len() * 12
            + self.normals.len() * 4
            + self.normals16.len() * 2
            + self.flux.len() * 4
            + self.packed.len() * 4
            + self.incoming.len() * 2
            + self.axes.len()
    }

    pub fn positions(&self) -> &[[f32; 3]] {
        &self.positions
    }

    /// Whether the map keeps its photons' incoming directions (an empty map keeps none).
    pub fn keeps_incoming(&self) -> bool {
        !self.incoming.is_empty()
    }

    /// Where stored photon `i` came from (None when the map keeps no directions, or for a
    /// photon final-gather rays would not find: see [`IncomingCode`]).
    #[inline]
    pub fn incoming(&self, i: usize) -> Option<Vec3> {
        IncomingCode(*self.incoming.get(i)?).direction()
    }

    /// Stored photon `i`'s flux summed over the bins, roughly (exact for full records and
    /// spikes; a triplet's mean × `bins`, which a flat spectrum's triplet meets): what
    /// guiding weighs photons by, where only the proportions matter.
    #[inline]
    pub fn power_of(&self, i: usize, bins: usize) -> f32 {
        match self.record {
            Record::Full => spd::sum(&self.flux[i * self.stride..(i + 1) * self.stride]),
            _ => {
                let rec = self.compact_record(i);
                let mut power = match decode_spike(rec) {
                    Some((_, a)) => a,
                    None => (rec[0] + rec[1] + rec[2]) / 3.0 * bins as f32,
                };
                if self.record == Record::Spiked {
                    power += self.flux[5 * i + 4];
                }
                power
            }
        }
    }

    /// The octahedral code of stored photon `i`'s normal.
    #[inline]
    pub fn normal_code(&self, i: usize) -> u32 {
        match self.normals.get(i) {
            Some(&n) => n,
            None => oct_from_16(self.normals16[i]),
        }
    }

    /// Stored photon `i`'s compact record (compact, packed and spiked storage).
    #[inline(always)]
    fn compact_record(&self, i: usize) -> [f32; 3] {
        if self.record == Record::Packed {
            unpack_record(self.packed[i])
        } else {
            let s = self.stride * i;
            [self.flux[s], self.flux[s + 1], self.flux[s + 2]]
        }
    }

    /// Adds stored photon `i`'s spikes to `out` — a spike record's, and a spiked record's
    /// extra one — and returns its triplet, if its record holds one (compact, packed and
    /// spiked storage).
    #[inline(always)]
    fn add_spikes(&self, i: usize, out: &mut [f32]) -> Option<[f32; 3]> {
        let mut add = |bin: usize, a: f32| {
            if let Some(v) = out.get_mut(bin) {
                *v += a;
            }
        };
        if self.record == Record::Spiked {
            let (bin, a) = (self.flux[5 * i + 3], self.flux[5 * i + 4]);
            if a != 0.0 {
                add(bin as usize, a);
            }
        }
        let rec = self.compact_record(i);
        match decode_spike(rec) {
            Some((bin, a)) => {
                add(bin, a);
                None
            }
            None => Some(rec),
        }
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

    /// Whether stored photon `i` lies on the query's surface and side: its normal within
    /// 37° of `n`, and within a flat slab about the query's tangent plane (|Δ·n| ≤ |Δ|/8,
    /// so a curved surface still counts out to a quarter of its radius of curvature, and a
    /// parallel surface a gap g away only beyond 8g). Density estimation has no visibility:
    /// coplanar surfaces on both sides of a wall still share photons within one radius.
    /// (The searches run [`SurfaceTest`], which answers the same; this is its reference.)
    #[cfg(test)]
    fn same_surface(&self, i: usize, p: Vec3, n: Vec3) -> bool {
        let d = Vec3::from_array(self.positions[i]) - p;
        let h = d.dot(n);
        h * h <= (1.0 / 64.0) * d.length_squared() + 1e-12
            && super::record::oct_within(self.normal_code(i), n, MIN_NORMAL_COS)
    }

    /// [`Self::same_surface`] for the candidates of one query at `p` facing `n`.
    fn surface_test(&self, p: Vec3, n: Vec3) -> SurfaceTest<'_, impl Fn(usize) -> u32 + '_> {
        SurfaceTest::new(&self.positions, |i| self.normal_code(i), p, n)
    }

    /// Adds to `out` (N bins) the flux of the photons of a density estimate at `p` on a
    /// surface facing `n`, and returns the estimate's radius r (the caller divides by
    /// π r²) and its k-nearest radius. Only photons on the same surface and side count (`same_surface`).
    ///
    /// With `kernel.k > 0` the radius adapts per query (Jensen's k-nearest-neighbour
    /// estimate): r_k is the distance to the k-th nearest photon within `r_max` (or
    /// `r_max` if fewer), and the photons strictly inside r = `shrink`·r_k are summed.
    /// For photons of density λ, (k−1) of them fall uniformly inside r_k, so the expected
    /// sum is (k−1)·shrink² photons over π·shrink²·r_k², and E[(k−1)/(π r_k²)] = λ: the
    /// estimate is unbiased in a uniform region for every shrink ≤ 1, and the Knaus–Zwicker
    /// shrink over passes makes it consistent elsewhere. With `k == 0` the radius is fixed:
    /// `shrink`·`r_max`.
    pub fn estimate(
        &self,
        grid: &BinGrid,
        p: Vec3,
        n: Vec3,
        kernel: Kernel,
        found: &mut Vec<(f32, u32)>,
        out: &mut [f32],
    ) -> Estimate {
        self.estimate_among(grid, p, n, kernel, |_| true, found, out)
    }

    /// [`Self::estimate`] from the photons `keep` accepts only (by index): the irradiance
    /// cache's estimates count only the half of the photons that does not place its
    /// points (see `irradiance::one_per_cell`).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn estimate_among(
        &self,
        grid: &BinGrid,
        p: Vec3,
        n: Vec3,
        kernel: Kernel,
        keep: impl Fn(usize) -> bool + Copy,
        found: &mut Vec<(f32, u32)>,
        out: &mut [f32],
    ) -> Estimate {
        let test = self.surface_test(p, n);
        let accept = |i: usize| keep(i) && test.accepts(i);
        if kernel.k == 0 {
            let r = kernel.r_max * kernel.shrink;
            found.clear();
            if !self.may_hold_within(p, r, kernel.r_max) {
                self.sum_flux(grid, std::iter::empty(), out);
                return Estimate {
                    r,
                    r_k: kernel.r_max,
                };
            }
            kdtree::for_each_within(&self.positions, &self.axes, p, r * r, |i, d2| {
                if accept(i) {
                    found.push((d2, i as u32));
                }
            });
            self.sum_flux(grid, found.iter().map(|f| f.1 as usize), out);
            return Estimate {
                r,
                r_k: kernel.r_max,
            };
        }
        // The k nearest within r_max are the k nearest within any smaller radius that
        // holds k photons: most queries find them within the first radius (a range search
        // and a selection); the rest search again with the radius grown by the photon
        // count found so far (density ~ count / r², so the next radius should hold
        // about KNN_GROWTH_MARGIN·k), never past r_max. A range search with a selection
        // is cheaper per photon than a heap-based k-nearest search (measured in
        // BENCHMARKS.md, session 21).
        let r = kernel.r_start.clamp(f32::MIN_POSITIVE, kernel.r_max);
        found.clear();
        // Nothing within the cap: what the range search below would conclude, without it
        // (the same radii, bit for bit).
        if r >= kernel.r_max && !self.may_hold_within(p, r, kernel.r_max) {
            let r2_k = r * r;
            let r2 = r2_k * kernel.shrink * kernel.shrink;
            self.sum_flux(grid, std::iter::empty(), out);
            return Estimate {
                r: r2.sqrt(),
                r_k: r2_k.sqrt(),
            };
        }
        kdtree::for_each_within(&self.positions, &self.axes, p, r * r, |i, d2| {
            if accept(i) {
                found.push((d2, i as u32));
            }
        });
        let r = if found.len() < kernel.k && r < kernel.r_max {
            self.regrow_search(p, n, r, kernel, keep, found)
        } else {
            r
        };
        let r2_k = if found.len() >= kernel.k {
            let by_distance = |a: &(f32, u32), b: &(f32, u32)| a.0.total_cmp(&b.0);
            let (_, kth, _) = found.select_nth_unstable_by(kernel.k - 1, by_distance);
            let r2_k = kth.0;
            // Past the k-th lie only photons at least r_k away: none is inside a radius
            // shrunk below r_k, so the sum below need not look at them.
            if kernel.shrink <= 1.0 {
                found.truncate(kernel.k);
            }
            r2_k
        } else {
            // Fewer than k within r_max: the search stopped at r_max.
            r * r
        };
        let r2 = r2_k * kernel.shrink * kernel.shrink;
        let inside = found.iter().filter(|f| f.0 < r2).map(|f| f.1 as usize);
        self.sum_flux(grid, inside, out);
        Estimate {
            r: r2.sqrt(),
            r_k: r2_k.sqrt(),
        }
    }

    /// The range search of [`Self::estimate`] again at radii grown from `r` (which held
    /// `found`, fewer than k) until k are found or `r_max` is reached; returns the last
    /// radius, `found` holding every accepted photon within it. Kept out of line: most of
    /// the renderer's queries never come here (their start is a neighbour's radius), and
    /// inlined into the estimate it slowed their single search (measured, session 21).
    /// Only photons `keep` accepts count.
    #[inline(never)]
    fn regrow_search(
        &self,
        p: Vec3,
        n: Vec3,
        mut r: f32,
        kernel: Kernel,
        keep: impl Fn(usize) -> bool,
        found: &mut Vec<(f32, u32)>,
    ) -> f32 {
        let test = self.surface_test(p, n);
        while found.len() < kernel.k && r < kernel.r_max {
            let grow = ((KNN_GROWTH_MARGIN * kernel.k as f32) / found.len().max(1) as f32)
                .sqrt()
                .max(1.25);
            r = (r * grow).min(kernel.r_max);
            found.clear();
            kdtree::for_each_within(&self.positions, &self.axes, p, r * r, |i, d2| {
                if keep(i) && test.accepts(i) {
                    found.push((d2, i as u32));
                }
            });
        }
        r
    }

    /// Adds the flux of photons `ids` to `out` (N bins). Compact and packed records: a
    /// spike goes to its bin; Smits triplets are summed per Smits branch and expanded as
    /// the paper prescribes, colour triplets are summed and decoded once — O(1) a photon.
    fn sum_flux(&self, grid: &BinGrid, ids: impl Iterator<Item = usize>, out: &mut [f32]) {
        match (self.record, grid.smits()) {
            (Record::Compact | Record::Packed | Record::Spiked, Some(smits))
                if grid.smits_triplets() =>
            {
                let mut sums = BranchSums::default();
                for i in ids {
                    if let Some(rec) = self.add_spikes(i, out) {
                        sums.add(rec, 1.0);
                    }
                }
                sums.expand_into(smits, out);
            }
            (Record::Compact | Record::Packed | Record::Spiked, Some(_)) => {
                // Colour triplets: summed, then decoded once.
                let mut sum = [0.0f32; 3];
                let mut any = false;
                for i in ids {
                    if let Some(rec) = self.add_spikes(i, out) {
                        any = true;
                        for c in 0..3 {
                            sum[c] += rec[c];
                        }
                    }
                }
                if any {
                    DECODED.with_borrow_mut(|decoded| {
                        decoded.resize(out.len(), 0.0);
                        grid.decode_triplet_into(sum, decoded);
                        spd::add_scaled(out, decoded, 1.0);
                    });
                }
            }
            _ => {
                let s = self.stride;
                for i in ids {
                    spd::add_scaled(out, &self.flux[i * s..(i + 1) * s], 1.0);
                }
            }
        }
    }

    /// Adds to `out` (N bins) the flux of every photon within `radius` of `p` on the
    /// surface and side `n` faces (a fixed-radius estimate). Returns how many were found.
    pub fn gather(&self, grid: &BinGrid, p: Vec3, n: Vec3, radius: f32, out: &mut [f32]) -> usize {
        let mut found = Vec::new();
        let kernel = Kernel {
            k: 0,
            r_max: radius,
            r_start: radius,
            shrink: 1.0,
        };
        self.estimate(grid, p, n, kernel, &mut found, out);
        found.len()
    }

    /// The flux of stored photon `i` in N bins (for tests and the probe).
    pub fn flux_of(&self, grid: &BinGrid, i: usize, out: &mut [f32]) {
        out.fill(0.0);
        match self.record {
            Record::Full => out.copy_from_slice(&self.flux[i * self.stride..(i + 1) * self.stride]),
            Record::Compact | Record::Packed | Record::Spiked => {
                // The triplet decodes into `out` (overwriting it), the spikes add after.
                let rec = self.compact_record(i);
                if decode_spike(rec).is_none() && grid.smits().is_some() {
                    grid.decode_triplet_into(rec, out);
                }
                self.add_spikes(i, out);
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    #[test]
    fn concatenated_batches_hold_what_appending_them_in_order_holds() {
        use crate::sampling::{Purpose, Rng};
        let grid = BinGrid::with_bins(8).unwrap();
        let mut rng = Rng::stream(5, 0, 0, Purpose::Photon);
        for record in [
            Record::Full,
            Record::Compact,
            Record::Packed,
            Record::Spiked,
        ] {
            for incoming in [false, true] {
                // Batches of several sizes, empty ones among them, with triplets and spikes.
                let batches: Vec<PhotonBatch> = [0usize, 7, 0, 300, 1, 64]
                    .iter()
                    .map(|&n| {
                        let mut b = PhotonBatch::new(record, &grid);
                        for _ in 0..n {
                            let pos = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                            let mut flux: Vec<f32> = (0..8).map(|_| rng.next_f32()).collect();
                            if rng.next_f32() < 0.3 {
                                flux.iter_mut().skip(1).for_each(|f| *f = 0.0);
                            }
                            let before = b.len();
                            b.push(&grid, pos, Vec3::Z, &flux);
                            if incoming {
                                b.tag_incoming(before, IncomingCode::from_travel(-pos));
                            }
                        }
                        b
                    })
                    .collect();
                let mut appended = PhotonBatch::new(record, &grid);
                for b in batches.clone() {
                    appended.append(b);
                }
                let joined = PhotonBatch::concat(record, &grid, batches);
                let bytes = |b: &PhotonBatch| {
                    let h: Vec<_> = b
                        .headers
                        .iter()
                        .map(|h| (h.pos.map(f32::to_bits), h.normal))
                        .collect();
                    let f: Vec<u32> = b.flux.iter().map(|v| v.to_bits()).collect();
                    (
                        h,
                        f,
                        b.packed.clone(),
                        b.incoming.clone(),
                        b.spikes,
                        b.stride,
                    )
                };
                assert_eq!(
                    bytes(&joined),
                    bytes(&appended),
                    "{record:?}, incoming {incoming}"
                );
                assert_eq!(joined.len(), 372);
            }
        }
    }

    #[test]
    fn a_single_bin_push_stores_what_pushing_its_vector_stores() {
        for bins in [1usize, 4, 20, 100] {
            let grid = BinGrid::with_bins(bins).unwrap();
            for record in [
                Record::Full,
                Record::Compact,
                Record::Packed,
                Record::Spiked,
            ] {
                let (mut a, mut b) = (
                    PhotonBatch::new(record, &grid),
                    PhotonBatch::new(record, &grid),
                );
                for (k, value) in [
                    (0usize, 1.5f32),
                    (bins - 1, 3e-7),
                    (bins / 2, 0.0),
                    (0, f32::NAN),
                    (0, -1.0),
                ] {
                    let mut flux = vec![0.0f32; bins];
                    flux[k] = value;
                    let (p, n) = (Vec3::new(k as f32, 0.5, -2.0), Vec3::Y);
                    a.push(&grid, p, n, &flux);
                    b.push_single(&grid, p, n, k, value, bins);
                }
                assert_eq!(
                    a.len(),
                    2,
                    "{bins} bins {record:?}: zero, NaN and negative are dropped"
                );
                assert_eq!(a.len(), b.len());
                assert_eq!(a.spikes, b.spikes);
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a.flux), bits(&b.flux), "{bins} bins {record:?}");
                assert_eq!(a.packed, b.packed);
                for (ha, hb) in a.headers.iter().zip(&b.headers) {
                    assert_eq!(ha.position(), hb.position());
                    assert_eq!(ha.normal(), hb.normal());
                }
            }
        }
    }

    #[test]
    fn a_many_bin_flux_with_a_nan_an_infinity_or_an_overflowing_sum_is_dropped() {
        for bins in [2usize, 20, 100] {
            let grid = BinGrid::with_bins(bins).unwrap();
            for record in [Record::Full, Record::Compact, Record::Spiked] {
                let mut batch = PhotonBatch::new(record, &grid);
                let good = vec![0.5f32; bins];
                for (k, bad) in [
                    (0, f32::NAN),
                    (bins - 1, f32::NAN),
                    (bins / 2, f32::INFINITY),
                    (bins - 1, f32::NEG_INFINITY),
                    (1, f32::MAX),
                ] {
                    let mut flux = good.clone();
                    flux[k] = bad;
                    if bad == f32::MAX {
                        flux[0] = f32::MAX;
                    }
                    batch.push(&grid, Vec3::ZERO, Vec3::Y, &flux);
                    assert_eq!(batch.len(), 0, "{bins} bins {record:?}: {bad} at {k}");
                }
                batch.push(&grid, Vec3::ZERO, Vec3::Y, &good);
                assert_eq!(
                    batch.len(),
                    1,
                    "{bins} bins {record:?}: a finite flux is kept"
                );
            }
        }
    }

    fn error(grid: &BinGrid, flux: &[f32], rec: [f32; 5]) -> f32 {
        let mut buf = vec![0.0; flux.len()];
        decoded_error(
            grid,
            flux,
            [rec[0], rec[1], rec[2]],
            (rec[3] as usize, rec[4]),
            &mut buf,
        )
    }

    #[test]
    fn a_spiked_record_keeps_a_lamp_line_exactly_and_never_decodes_worse() {
        let grid = BinGrid::with_bins(20).unwrap();
        // A low smooth base under one line, as a fluorescent lamp's light: the line's
        // excess over its neighbours is kept exactly, and the record decodes closer
        // than the plain triplet.
        let mut lamp: Vec<f32> = (0..20).map(|i| 0.1 + 0.005 * i as f32).collect();
        lamp[8] += 2.0;
        let rec = encode_spiked(&grid, &lamp);
        assert_eq!(rec[3], 8.0);
        assert!(
            (rec[4] - (lamp[8] - lamp[7].max(lamp[9]))).abs() < 1e-6,
            "{rec:?}"
        );
        let plain = grid.encode_triplet(&lamp);
        let plain = [plain[0], plain[1], plain[2], 0.0, 0.0];
        assert!(
            error(&grid, &lamp, rec) < 0.5 * error(&grid, &lamp, plain),
            "{} against {}",
            error(&grid, &lamp, rec),
            error(&grid, &lamp, plain)
        );
        // Smooth spectra keep the plain triplet (no spike worth its trial decodings), and
        // whatever is chosen never decodes worse than the plain triplet.
        let smooth: Vec<f32> = (0..20).map(|i| 1.0 + 0.02 * i as f32).collect();
        let rec = encode_spiked(&grid, &smooth);
        assert_eq!((rec[3], rec[4]), (0.0, 0.0));
        for peak in [0.01f32, 0.1, 0.5, 3.0] {
            for bin in [0usize, 5, 19] {
                let mut f: Vec<f32> = (0..20).map(|i| 0.3 + 0.01 * i as f32).collect();
                f[bin] += peak;
                let rec = encode_spiked(&grid, &f);
                let p = grid.encode_triplet(&f);
                let e = error(&grid, &f, rec);
                assert!(e <= error(&grid, &f, [p[0], p[1], p[2], 0.0, 0.0]) * (1.0 + 1e-6));
            }
        }
    }

    #[test]
    fn a_map_of_spiked_records_sums_the_spike_and_the_triplet() {
        // One photon: the map's estimate is its decoded triplet plus its spike, in its bin.
        let grid = BinGrid::with_bins(20).unwrap();
        let mut lamp: Vec<f32> = (0..20).map(|i| 0.1 + 0.005 * i as f32).collect();
        lamp[12] += 1.5;
        let mut b = PhotonBatch::new(Record::Spiked, &grid);
        b.push(&grid, Vec3::ZERO, Vec3::Z, &lamp);
        let map = PhotonMap::build(b);
        let rec = encode_spiked(&grid, &lamp);
        let mut want = vec![0.0; 20];
        grid.decode_triplet_into([rec[0], rec[1], rec[2]], &mut want);
        want[12] += rec[4];
        let mut got = vec![0.0; 20];
        assert_eq!(map.gather(&grid, Vec3::ZERO, Vec3::Z, 0.1, &mut got), 1);
        for (g, w) in got.iter().zip(&want) {
            assert!(
                (g - w).abs() <= 1e-6 * w.abs().max(1.0),
                "{got:?} against {want:?}"
            );
        }
        let mut one = vec![0.0; 20];
        map.flux_of(&grid, 0, &mut one);
        assert_eq!(one, got);
    }

    /// 40 000 photons of flux 1e-4 (4 bins) uniform on the unit square, facing +z, from
    /// stream `seed`: irradiance E = 4 per unit area.
    pub(crate) fn uniform_unit_square(grid: &BinGrid, record: Record, seed: u64) -> PhotonMap {
        let mut b = PhotonBatch::new(record, grid);
        let mut rng = crate::sampling::Rng::stream(seed, 0, 0, crate::sampling::Purpose::Photon);
        for _ in 0..40_000 {
            let [x, y] = rng.next_2d();
            b.push(grid, Vec3::new(x, y, 0.0), Vec3::Z, &[1e-4; 4]);
        }
        PhotonMap::build(b)
    }

    /// The remembered facing test answers as the plain one for every candidate, in runs of
    /// one normal and across changes of normal, near the 37° limit too.
    #[test]
    fn the_surface_test_answers_as_same_surface_does() {
        let grid = BinGrid::with_bins(4).unwrap();
        let mut b = PhotonBatch::new(Record::Full, &grid);
        let mut rng = crate::sampling::Rng::stream(4, 0, 0, crate::sampling::Purpose::Photon);
        let tilt = MIN_NORMAL_COS.acos();
        let mut n = Vec3::Z;
        for i in 0..4000 {
            // Runs of one normal, some just inside and some just outside 37° of +z.
            if i % 7 == 0 {
                let [u, v] = rng.next_2d();
                let a = tilt + (u - 0.5) * 0.02 + if v < 0.3 { 1.0 } else { 0.0 };
                let phi = v * std::f32::consts::TAU;
                n = Vec3::new(a.sin() * phi.cos(), a.sin() * phi.sin(), a.cos());
            }
            let [x, y] = rng.next_2d();
            b.push(&grid, Vec3::new(x, y, 0.01 * (x - y)), n, &[1.0; 4]);
        }
        let map = PhotonMap::build(b);
        let (mut agree, mut accepted) = (0, 0);
        for q in 0..20 {
            let p = Vec3::new(0.05 * q as f32, 0.5, 0.0);
            let test = map.surface_test(p, Vec3::Z);
            for i in 0..map.len() {
                let want = map.same_surface(i, p, Vec3::Z);
                assert_eq!(test.accepts(i), want, "photon {i}, query {q}");
                agree += 1;
                accepted += usize::from(want);
            }
        }
        assert_eq!(agree, 20 * 4000);
        // Both answers occur often: the test is not vacuous.
        assert!((10_000..70_000).contains(&accepted), "{accepted}");
    }

    /// Whatever radius the search starts at — far too small, about right, past the cap —
    /// the estimate's r_k is the k-th nearest same-surface photon within r_max (brute
    /// force), and it sums exactly the photons inside shrink·r_k.
    #[test]
    fn a_k_nearest_estimate_finds_the_brute_force_neighbours_from_any_start_radius() {
        let grid = BinGrid::with_bins(4).unwrap();
        let mut b = PhotonBatch::new(Record::Full, &grid);
        let mut rng = crate::sampling::Rng::stream(9, 0, 0, crate::sampling::Purpose::Photon);
        for i in 0..20_000 {
            let [x, y] = rng.next_2d();
            // Every fifth photon lies on a perpendicular wall through the same points: it
            // is near in space but not on the query's surface.
            let n = if i % 5 == 0 { Vec3::X } else { Vec3::Z };
            b.push(&grid, Vec3::new(x, y, 0.0), n, &[1.0; 4]);
        }
        let map = PhotonMap::build(b);
        let (mut found, mut out) = (Vec::new(), vec![0.0; 4]);
        let (k, r_max) = (48usize, 0.05f32);
        let queries = [
            Vec3::new(0.5, 0.5, 0.0),
            Vec3::new(0.01, 0.99, 0.0),
            Vec3::new(1.03, 0.5, 0.0), // off the edge: fewer than k within the cap
            Vec3::new(1.2, 0.5, 0.0),  // nothing within the cap
            Vec3::new(0.3, 0.7, 0.004), // slightly above the plane
        ];
        for p in queries {
            let mut d2: Vec<f32> = (0..map.len())
                .filter(|&i| map.same_surface(i, p, Vec3::Z))
                .map(|i| {
                    let q = map.positions[i];
                    let d = [p.x - q[0], p.y - q[1], p.z - q[2]];
                    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
                })
                .filter(|&d2| d2 <= r_max * r_max)
                .collect();
            d2.sort_by(f32::total_cmp);
            let want_rk = d2.get(k - 1).map_or(r_max, |d| d.sqrt());
            for r_start in [1e-5f32, 0.002, 0.01, 0.03, 0.05, 0.5] {
                for shrink in [1.0f32, 0.7] {
                    let kernel = Kernel {
                        k,
                        r_max,
                        r_start,
                        shrink,
                    };
                    out.fill(0.0);
                    let est = map.estimate(&grid, p, Vec3::Z, kernel, &mut found, &mut out);
                    assert!(
                        (est.r_k - want_rk).abs() <= 1e-6 * want_rk,
                        "{p} {kernel:?}: r_k {} against {want_rk}",
                        est.r_k
                    );
                    let r2 = est.r * est.r;
                    let inside = d2.iter().filter(|&&d| d < r2).count();
                    assert_eq!(out[0], inside as f32, "{p} {kernel:?}: {est:?}");
                }
            }
        }
    }

    #[test]
    fn a_folded_kernel_estimates_what_the_unfolded_one_does_from_fewer_neighbours() {
        let grid = BinGrid::with_bins(4).unwrap();
        let map = uniform_unit_square(&grid, Record::Full, 5);
        let (mut found, mut out) = (Vec::new(), vec![0.0; 4]);
        for shrink in [1.0f32, 0.8, 0.5, 0.3] {
            let plain = Kernel {
                k: 96,
                r_max: 0.2,
                r_start: 0.03,
                shrink,
            };
            let folded = Kernel::adaptive(96, 0.2, 0.03, shrink);
            assert!((MIN_SHRUNK_K..=96).contains(&folded.k), "{folded:?}");
            assert!(folded.shrink <= 1.0 && folded.shrink > 0.0, "{folded:?}");
            if shrink < 1.0 {
                assert!(folded.k < 96, "{shrink}: {folded:?}");
            } else {
                assert_eq!(folded, plain);
            }
            // Mean irradiance over 1 600 query points, and mean photons summed.
            let mut mean = |kernel: Kernel| {
                let (mut e, mut summed) = (0.0f64, 0usize);
                for i in 0..1600 {
                    let p = Vec3::new(
                        0.3 + 0.4 * (i % 40) as f32 / 40.0,
                        0.3 + 0.4 * (i / 40) as f32 / 40.0,
                        0.0,
                    );
                    out.fill(0.0);
                    let est = map.estimate(&grid, p, Vec3::Z, kernel, &mut found, &mut out);
                    summed += found.iter().filter(|f| f.0 < est.r * est.r).count();
                    e += f64::from(out[0]) / (std::f64::consts::PI * f64::from(est.r).powi(2));
                }
                (e / 1600.0, summed as f64 / 1600.0)
            };
            let (e_plain, n_plain) = mean(plain);
            let (e_folded, n_folded) = mean(folded);
            // Both unbiased (4 % is over 4 standard errors at the fewest summed).
            assert!((e_plain / 4.0 - 1.0).abs() < 0.04, "{shrink}: {e_plain}");
            assert!((e_folded / 4.0 - 1.0).abs() < 0.04, "{shrink}: {e_folded}");
            // Summing as many photons on average: (k−1)·s².
            let m = 95.0 * f64::from(shrink).powi(2);
            for n in [n_plain, n_folded] {
                assert!(
                    (n / m - 1.0).abs() < 0.1,
                    "{shrink}: {n} summed, {m} expected"
                );
            }
        }
        // Where fewer than k photons lie within the cap, both sum within s·r_max.
        let mut b = PhotonBatch::new(Record::Full, &grid);
        for d in [0.049f32, 0.051, 0.09] {
            b.push(&grid, Vec3::new(d, 0.0, 0.0), Vec3::Z, &[1.0; 4]);
        }
        let sparse = PhotonMap::build(b);
        let plain = Kernel {
            k: 96,
            r_max: 0.1,
            r_start: 0.01,
            shrink: 0.5,
        };
        for kernel in [plain, Kernel::adaptive(96, 0.1, 0.01, 0.5)] {
            out.fill(0.0);
            let est = sparse.estimate(&grid, Vec3::ZERO, Vec3::Z, kernel, &mut found, &mut out);
            assert!((est.r - 0.05).abs() < 1e-6, "{kernel:?}: {est:?}");
            assert_eq!(
                out[0], 1.0,
                "{kernel:?}: only the photon at 0.049 is summed"
            );
        }
    }
}
