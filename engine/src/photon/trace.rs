//! The photon pass: photons leave the lights carrying all N bins, bounce with Russian
//! roulette, are stored at diffuse hits (global map; caustic map for L S+ D paths) and
//! split into single-bin photons at dispersive glass.
//!
//! **Splitting** (documented choice): a photon with k > 1 non-zero bins reaching a
//! dispersive surface becomes `min(k, S)` single-bin photons (S = `dispersion_split`).
//! If k ≤ S each non-zero bin becomes its own photon with exactly its flux. Otherwise S
//! bins are drawn by stratified sampling of the flux CDF (strata (s + ξ)/S) and each
//! carries Σflux / S in its bin. Either way the split photons' flux sums exactly to the
//! original, and every bin's expected flux is unchanged (unbiased): the stratum s picks
//! bin j with probability S·|I_j ∩ stratum|, so E[flux_j] = Σ/S · S · flux_j/Σ = flux_j.
//! Split photons carry comparable power (Σ/S), as the paper recommends.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use glam::Vec3;
use rayon::prelude::*;

use super::map::{IncomingCode, PhotonBatch, PhotonMap};
use super::record::Record;
use super::visibility::VisibleSurfaces;
use crate::lights::LightSet;
use crate::lights::adaptive::{self, EmissionCells};
use crate::materials::{
    dielectric_bounce, metal_bounce, russian_roulette, russian_roulette_metal,
    russian_roulette_scalar, russian_roulette_single,
};
use crate::sampling::{Purpose, Rng, cosine_hemisphere};
use crate::scene::{SpectralScene, SurfaceKind, path_eta};
use crate::spectral::spd;

/// Photons traced per work item (fixed, so results do not depend on the thread count).
const CHUNK: usize = 1024;

#[derive(Clone, Debug)]
pub struct PhotonSettings {
    pub photons: usize,
    pub record: Record,
    /// Safety cap on a photon's bounces (Russian roulette ends paths long before).
    pub max_bounces: u32,
    pub dispersion_split: usize,
    /// Build a caustic map (only meaningful when the scene has specular surfaces).
    pub caustic_map: bool,
    /// Photons emitted for the caustic map, as a multiple of `photons` (at least 1). The
    /// first `photons` are the global map's, whose L S+ D paths the caustic map keeps too;
    /// the rest follow only specular bounces and end at their first diffuse hit, so where
    /// they miss every mirror and glass they cost one ray. Every caustic photon carries
    /// the flux of one in `photons · caustic_factor`.
    pub caustic_factor: usize,
    /// Most bytes the pass's photon maps may hold (records + kd-tree); the pass stops
    /// with [`TraceStop::OverBudget`] as soon as its stored photons pass it.
    pub max_map_bytes: usize,
    /// Keep each global photon's incoming direction ([`IncomingCode`], 2 bytes a photon),
    /// which guided final gathering reads.
    pub incoming: bool,
    /// Learned emission ([`crate::lights::adaptive`]): the global photons of learning
    /// lights are emitted by these cells and report their cell and whether they reached a
    /// visible surface ([`PhotonPass::reports`]).
    pub adapt: Option<AdaptiveEmission>,
}

/// What learned emission needs in a pass: the cells to emit by, and the surfaces that
/// make a photon useful.
#[derive(Clone, Debug)]
pub struct AdaptiveEmission {
    pub cells: Arc<EmissionCells>,
    pub visible: Arc<VisibleSurfaces>,
}

impl PhotonSettings {
    /// `photons` global photons stored as `record`, with a caustic map from them alone
    /// (no extra caustic photons), dispersive splits into 4, no budget, no incoming
    /// directions and no learned emission.
    pub fn new(photons: usize, record: Record) -> Self {
        Self {
            photons,
            record,
            max_bounces: 1024,
            dispersion_split: 4,
            caustic_map: true,
            caustic_factor: 1,
            max_map_bytes: usize::MAX,
            incoming: false,
            adapt: None,
        }
    }
}

/// What one photon pass produced.
pub struct PhotonPass {
    pub global: PhotonMap,
    pub caustic: Option<PhotonMap>,
    pub emitted: u64,
    /// Photons emitted for the caustic map only (see [`PhotonSettings::caustic_factor`]).
    pub caustic_emitted: u64,
    /// Whether the caustic-only photons were aimed at the specular targets (see
    /// [`crate::lights::LightSet::aim_at`]).
    pub caustic_aimed: bool,
    pub splits: u64,
    /// Per global photon of a learning light, in emission order: its light, cell and
    /// whether it was useful ([`adaptive::report`]); empty without learned emission.
    pub reports: Vec<u32>,
}

/// Why a photon pass stopped early.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceStop {
    Cancelled,
    /// The stored photons would exceed `max_map_bytes`. Photons are counted per chunk,
    /// so at most one chunk per thread is held beyond the budget before the pass stops.
    OverBudget,
}

struct Path {
    origin: Vec3,
    dir: Vec3,
    flux: Vec<f32>,
    depth: u32,
    diffuse_seen: bool,
    specular_seen: bool,
    /// Whether the last bounce was diffuse (the photon flew straight from a diffuse
    /// surface to its next hit).
    from_diffuse: bool,
    /// Where within its bin a single-bin photon's wavelength lies (drawn at its first
    /// dispersive interface, kept after; see [`crate::scene::spectral::eta_in_bin`]).
    lambda_u: Option<f32>,
    /// The one bin a split photon carries (its flux is zero elsewhere): the bounces below
    /// then touch that bin only, with the same arithmetic as on the whole vector.
    single: Option<usize>,
}

/// What a photon is emitted for, and how its flux is stored in the caustic map.
#[derive(Clone, Copy)]
struct Role {
    /// Traced to the end of its path, stored at every diffuse hit (else: a caustic-only
    /// photon, ended at its first diffuse hit).
    global: bool,
    /// Aimed at the scene's specular targets (caustic-only photons, where lights aim).
    aimed: bool,
    /// Photons its emitted flux is shared among (`photons`, or all caustic photons).
    emitted_among: usize,
}

/// The caustic-only photon count, the two roles and, per role and light, the factor
/// from a photon's flux to its caustic record's flux.
type Roles = (usize, [Role; 2], [Vec<f32>; 2]);

/// The caustic-only photon count and the two roles, where lights aim their caustic-only
/// photons at the specular targets or not (see [`crate::lights::LightSet::aim_at`]). Per light,
/// the caustic map is then a fixed blend of two unbiased estimates: the global photons'
/// caustic records at weight α, the aimed photons' at 1 − α. For a light of emit pmf p,
/// share s (of its unaimed photons that would head into the targets) and aimed pmf q,
/// α = P·p·s / (P·p·s + M·q) (P global photons, M aimed ones) is the balance
/// heuristic's weight in expectation: a global photon's caustic record then carries the
/// flux an aimed one does, so neither makes speckles of the other. A light that does not
/// aim (s = 1, q = p) gets the unaimed blend, α = 1 / factor: each caustic record then
/// carries the flux of one in factor × P photons.
///
/// M = (factor − 1)·P·Σ p·√s, shared among lights by q ∝ p·√s: aimed photons all head for
/// the glass, and each one that reaches it costs the split, the trace through it and the
/// estimates where it lands, so each light's count is cut between its unaimed photons'
/// useful number ((factor − 1)·P·p·s, the same cost) and their whole number (the same
/// count) — their geometric mean.
fn roles(photons: usize, factor: usize, lights: &LightSet) -> Roles {
    let extra = (photons as f64) * (factor.saturating_sub(1) as f64);
    let aimed = (extra * lights.aimed_count().clamp(1e-6, 1.0))
        .ceil()
        .min(extra) as usize;
    let alpha: Vec<f64> = (0..lights.len())
        .map(|i| {
            let share = f64::from(lights.share(i)).clamp(1e-12, 1.0);
            let useful_global = photons as f64 * f64::from(lights.emit_pmf(i)) * share;
            let aimed_here = aimed as f64 * f64::from(lights.aimed_pmf(i));
            if aimed_here > 0.0 {
                useful_global / (useful_global + aimed_here)
            } else {
                1.0
            }
        })
        .collect();
    let global = Role {
        global: true,
        aimed: false,
        emitted_among: photons,
    };
    let caustic = Role {
        global: false,
        aimed: lights.aims(),
        emitted_among: aimed.max(1),
    };
    let scales = [
        alpha.iter().map(|&a| a as f32).collect(),
        alpha.iter().map(|&a| (1.0 - a) as f32).collect(),
    ];
    (photons.saturating_add(aimed), [global, caustic], scales)
}

/// Traces `settings.photons` photons for pass `pass`.
pub fn trace_photons(
    scene: &SpectralScene,
    settings: &PhotonSettings,
    seed: u64,
    pass: u64,
    cancel: &AtomicBool,
) -> Result<PhotonPass, TraceStop> {
    let caustic = settings.caustic_map && scene.has_specular;
    let factor = if caustic {
        settings.caustic_factor.max(1)
    } else {
        1
    };
    let aimed = caustic && factor > 1 && scene.lights.aims();
    let (caustic_photons, roles, caustic_scales) = roles(settings.photons, factor, &scene.lights);
    let chunks = caustic_photons.div_ceil(CHUNK);
    let used = AtomicUsize::new(0);
    let over = AtomicBool::new(false);
    let results: Vec<Option<ChunkResult>> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            if cancel.load(Ordering::Relaxed) || over.load(Ordering::Relaxed) {
                return None;
            }
            let mut global = PhotonBatch::new(settings.record, &scene.grid);
            let mut caustics = PhotonBatch::new(settings.record, &scene.grid);
            let mut splits = 0;
            let start = c * CHUNK;
            let end = (start + CHUNK).min(caustic_photons);
            let mut scratch = TraceScratch::default();
            let mut reports = Vec::new();
            let chunk = Chunk {
                scene,
                settings,
                caustic,
                roles,
                caustic_scales: &caustic_scales,
                seed,
                pass,
            };
            let maps = (&mut global, &mut caustics);
            splits += chunk.trace(start..end, maps, &mut scratch, &mut reports);
            let bytes = global.memory_bytes() + caustics.memory_bytes();
            if used.fetch_add(bytes, Ordering::Relaxed) + bytes > settings.max_map_bytes {
                over.store(true, Ordering::Relaxed);
                return None;
            }
            Some((global, caustics, splits, reports))
        })
        .collect();
    if over.load(Ordering::Relaxed) {
        return Err(TraceStop::OverBudget);
    }
    let count = |pick: fn(&ChunkResult) -> usize| results.iter().flatten().map(pick).sum::<usize>();
    let mut reports = Vec::with_capacity(count(|r| r.3.len()));
    let mut splits = 0;
    let (mut globals, mut caustic_batches) = (Vec::new(), Vec::new());
    for r in results {
        let (g, c, s, rep) = r.ok_or(TraceStop::Cancelled)?;
        globals.push(g);
        caustic_batches.push(c);
        splits += s;
        reports.extend_from_slice(&rep);
    }
    if cancel.load(Ordering::Relaxed) {
        return Err(TraceStop::Cancelled);
    }
    // The chunks in order, each map in one allocation, copied on every thread.
    let (global, caustics) = rayon::join(
        || PhotonBatch::concat(settings.record, &scene.grid, globals),
        || PhotonBatch::concat(settings.record, &scene.grid, caustic_batches),
    );
    let (global, caustic_map) = rayon::join(
        || PhotonMap::build(global),
        || caustic.then(|| PhotonMap::build(caustics)),
    );
    Ok(PhotonPass {
        global,
        caustic: caustic_map,
        emitted: settings.photons as u64,
        caustic_emitted: (caustic_photons - settings.photons) as u64,
        caustic_aimed: aimed,
        splits,
        reports,
    })
}

/// A chunk's global and caustic photons, splits and reports.
type ChunkResult = (PhotonBatch, PhotonBatch, u64, Vec<u32>);

/// What a chunk's photons reuse: the path stack, spare flux buffers (a path's buffer
/// goes back here when it ends, and split pieces come from here) and a texel buffer. No
/// allocation per photon once the chunk's first few photons have sized them.
#[derive(Default)]
struct TraceScratch {
    stack: Vec<Path>,
    spare: Vec<Vec<f32>>,
    texel: Vec<f32>,
    /// A global photon's flux scaled for its caustic record.
    scaled: Vec<f32>,
}

/// What a chunk of photons is traced with.
struct Chunk<'a> {
    scene: &'a SpectralScene,
    settings: &'a PhotonSettings,
    caustic: bool,
    /// The global photons' role, then the caustic-only photons'.
    roles: [Role; 2],
    /// Per role and light, the factor from a photon's flux to its caustic record's.
    caustic_scales: &'a [Vec<f32>; 2],
    seed: u64,
    pass: u64,
}

impl Chunk<'_> {
    /// Traces photons `ids` into `maps`; returns their dispersive splits. On a CPU with
    /// AVX this runs a copy compiled for it (the same operations in the same order, so the
    /// same photons to the bit; see [`crate::render::gather::Gather::block`]).
    fn trace(
        &self,
        ids: std::ops::Range<usize>,
        maps: (&mut PhotonBatch, &mut PhotonBatch),
        scratch: &mut TraceScratch,
        reports: &mut Vec<u32>,
    ) -> u64 {
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::has_avx() {
            // SAFETY: the CPU has AVX (checked just above).
            return unsafe { self.trace_avx(ids, maps, scratch, reports) };
        }
        self.trace_in(ids, maps, scratch, reports)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn trace_avx(
        &self,
        ids: std::ops::Range<usize>,
        maps: (&mut PhotonBatch, &mut PhotonBatch),
        scratch: &mut TraceScratch,
        reports: &mut Vec<u32>,
    ) -> u64 {
        self.trace_in(ids, maps, scratch, reports)
    }

    #[inline(always)]
    fn trace_in(
        &self,
        ids: std::ops::Range<usize>,
        (global, caustics): (&mut PhotonBatch, &mut PhotonBatch),
        scratch: &mut TraceScratch,
        reports: &mut Vec<u32>,
    ) -> u64 {
        let mut splits = 0;
        for i in ids {
            let mut rng = Rng::stream(self.seed, self.pass, i as u64, Purpose::Photon);
            let r = usize::from(i >= self.settings.photons);
            let role = (self.roles[r], &self.caustic_scales[r][..]);
            let maps = (&mut *global, &mut *caustics);
            let (scene, settings) = (self.scene, self.settings);
            let (s, report) =
                trace_one(scene, settings, self.caustic, role, &mut rng, maps, scratch);
            splits += s;
            reports.extend(report);
        }
        splits
    }
}

/// Emits and traces one photon; returns the number of dispersive splits and, for a
/// learning light's global photon, its report ([`adaptive::report`]).
#[inline(always)]
fn trace_one(
    scene: &SpectralScene,
    settings: &PhotonSettings,
    caustic: bool,
    (role, caustic_scales): (Role, &[f32]),
    rng: &mut Rng,
    (global, caustics): (&mut PhotonBatch, &mut PhotonBatch),
    scratch: &mut TraceScratch,
) -> (u64, Option<u32>) {
    let TraceScratch {
        stack,
        spare,
        texel,
        scaled,
    } = scratch;
    let mut flux = spare.pop().unwrap_or_default();
    let among = role.emitted_among;
    let adapt = settings.adapt.as_ref().filter(|_| role.global);
    let cells = adapt.map(|a| &*a.cells);
    let lights = &scene.lights;
    let Some(start) = lights.emit_into(
        &scene.tris,
        &scene.accel,
        among,
        role.aimed,
        cells,
        rng,
        &mut flux,
    ) else {
        spare.push(flux);
        return (0, None);
    };
    let (origin, dir, light) = (start.origin, start.dir, start.light);
    // Where this photon's cell is counted: whether any of its records is seen.
    let visible = adapt.filter(|_| start.cell.is_some()).map(|a| &*a.visible);
    let mut useful = false;
    let caustic_scale = caustic_scales[light];
    stack.push(Path {
        origin,
        dir,
        flux,
        depth: 0,
        diffuse_seen: false,
        specular_seen: false,
        from_diffuse: false,
        lambda_u: None,
        single: None,
    });
    let grid = &scene.grid;
    let mut splits = 0;
    while let Some(mut path) = stack.pop() {
        while path.depth < settings.max_bounces {
            let Some(hit) = scene.intersect(path.origin, path.dir) else {
                break;
            };
            let (p, n, nf, ns) = (hit.p, hit.n, hit.nf, hit.ns);
            path.depth += 1;
            let mat = scene.material(&hit);
            mat.absorb_inside(&hit, &mut path.flux);
            match &mat.kind {
                SurfaceKind::Diffuse { reflectance } => {
                    let caustic_path = caustic && path.specular_seen && !path.diffuse_seen;
                    // A photon's record at `scale` times its flux: a split photon's one
                    // bin, else the vector (scaled in `scaled` when it must be).
                    let code = scene.normal_code(&hit);
                    let mut store = |map: &mut PhotonBatch, scale: f32| match path.single {
                        Some(b) => {
                            let n = path.flux.len();
                            map.push_single(grid, p, code, b, path.flux[b] * scale, n)
                        }
                        None if scale == 1.0 => map.push(grid, p, code, &path.flux),
                        None => {
                            scaled.clear();
                            scaled.extend(path.flux.iter().map(|f| f * scale));
                            map.push(grid, p, code, scaled)
                        }
                    };
                    if !role.global {
                        if caustic_path {
                            store(caustics, caustic_scale);
                        }
                        break;
                    }
                    let before = global.len();
                    store(global, 1.0);
                    if let Some(v) = visible {
                        useful = useful || v.contains(p, nf);
                    }
                    if settings.incoming {
                        // Light a final-gather ray could find here came straight off a
                        // diffuse surface (see `IncomingCode`). Light through glass or off
                        // mirrors is left out too: a final-gather ray sent back along it
                        // would follow one wavelength through dispersive glass, and bring
                        // colour noise where it was meant to bring light.
                        let code = if path.from_diffuse {
                            IncomingCode::from_travel(path.dir)
                        } else {
                            IncomingCode::NONE
                        };
                        global.tag_incoming(before, code);
                    }
                    if caustic_path {
                        store(caustics, caustic_scale);
                    }
                    let reflectance = scene.reflectance_at(mat, reflectance, &hit, texel);
                    let survives = match path.single {
                        Some(b) => russian_roulette_single(
                            &mut path.flux[b],
                            reflectance[b],
                            rng.next_f32(),
                        ),
                        None => russian_roulette(&mut path.flux, reflectance, rng.next_f32()),
                    };
                    if !survives {
                        break;
                    }
                    path.diffuse_seen = true;
                    path.from_diffuse = true;
                    path.dir = cosine_hemisphere(nf, rng.next_2d());
                    path.origin = scene.accel.offset(p, nf, path.dir);
                }
                SurfaceKind::Mirror { reflectance, alpha } => {
                    let u = micro_sample(*alpha, rng);
                    let Some((dir, cos, w)) = metal_bounce(*alpha, path.dir, nf, ns, u) else {
                        break;
                    };
                    let reflectance = scene.reflectance_at(mat, reflectance, &hit, texel);
                    if !russian_roulette_metal(&mut path.flux, reflectance, cos, w, rng.next_f32())
                    {
                        break;
                    }
                    path.specular_seen = true;
                    path.from_diffuse = false;
                    path.dir = dir;
                    path.origin = scene.accel.offset(p, nf, path.dir);
                }
                SurfaceKind::Dielectric {
                    eta,
                    eta_edges,
                    dispersive,
                    alpha,
                } => {
                    let single = path.single.or_else(|| spd::single_nonzero(&path.flux));
                    if *dispersive && single.is_none() {
                        // Split here; the pieces continue from this same hit.
                        splits += 1;
                        path.depth -= 1;
                        let s = settings.dispersion_split;
                        split_dispersive_with(&path.flux, s, rng, spare, |flux, single| {
                            stack.push(Path {
                                origin: path.origin,
                                dir: path.dir,
                                flux,
                                depth: path.depth,
                                diffuse_seen: path.diffuse_seen,
                                specular_seen: path.specular_seen,
                                from_diffuse: false,
                                lambda_u: None,
                                single,
                            })
                        });
                        break;
                    }
                    let bin = single.unwrap_or(0);
                    let e = path_eta(eta, eta_edges, *dispersive, bin, &mut path.lambda_u, rng);
                    let u = micro_sample(*alpha, rng);
                    let Some((ev, w)) =
                        dielectric_bounce(*alpha, path.dir, n, ns, e, u, rng.next_f32())
                    else {
                        break;
                    };
                    if w < 1.0 {
                        let u = rng.next_f32();
                        let survives = match path.single {
                            Some(b) => russian_roulette_single(&mut path.flux[b], w, u),
                            None => russian_roulette_scalar(&mut path.flux, w, u),
                        };
                        if !survives {
                            break;
                        }
                    }
                    path.specular_seen = true;
                    path.from_diffuse = false;
                    path.dir = ev.dir;
                    path.origin = scene.accel.offset(p, n, path.dir);
                }
            }
        }
        spare.push(path.flux);
    }
    let report = start.cell.map(|c| adaptive::report(light, c, useful));
    (splits, report)
}

/// The two numbers a rough surface samples its microfacet normal with; none drawn for a
/// smooth one (so smooth scenes keep their random sequences).
#[inline]
pub(crate) fn micro_sample(alpha: f32, rng: &mut Rng) -> [f32; 2] {
    if alpha > 0.0 { rng.next_2d() } else { [0.0; 2] }
}

/// Splits a multi-bin flux into single-bin fluxes (see the module docs).
pub fn split_dispersive(flux: &[f32], max_split: usize, rng: &mut Rng) -> Vec<Vec<f32>> {
    let mut pieces = Vec::new();
    split_dispersive_with(flux, max_split, rng, &mut Vec::new(), |p, _| pieces.push(p));
    pieces
}

/// [`split_dispersive`], each piece handed to `emit` in a buffer taken from `spare`
/// (allocated only when `spare` is empty), with its one non-zero bin (None if its flux
/// is zero).
fn split_dispersive_with(
    flux: &[f32],
    max_split: usize,
    rng: &mut Rng,
    spare: &mut Vec<Vec<f32>>,
    mut emit: impl FnMut(Vec<f32>, Option<usize>),
) {
    let n = flux.len();
    let mut piece = |bin: usize, value: f32| {
        let mut f = spare.pop().unwrap_or_default();
        f.clear();
        f.resize(n, 0.0);
        f[bin] = value;
        emit(f, (value != 0.0).then_some(bin));
    };
    let nonzero = flux.iter().filter(|&&v| v > 0.0).count();
    let s = max_split.max(1);
    if nonzero <= s {
        for (i, &v) in flux.iter().enumerate() {
            if v > 0.0 {
                piece(i, v);
            }
        }
        return;
    }
    let total: f64 = flux.iter().map(|&v| v.max(0.0) as f64).sum();
    let xi = rng.next_f32() as f64;
    let share = (total / s as f64) as f32;
    // The strata's targets rise with k: one walk up the CDF finds every bin.
    let mut bin = 0usize;
    let mut upto = flux[0].max(0.0) as f64;
    for k in 0..s {
        let target = (k as f64 + xi) / s as f64 * total;
        while upto <= target && bin + 1 < n {
            bin += 1;
            upto += flux[bin].max(0.0) as f64;
        }
        piece(bin, share);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tracers_avx_copy_stores_what_the_portable_one_does_to_the_bit() {
        // The prism at 100 bins (dispersive splits, caustic photons), compact, and the
        // Cornell box at 20 bins, full: the same photons, records and splits either way.
        if !crate::cpu::has_avx() {
            eprintln!("this CPU has no AVX: only the portable copy runs");
            return;
        }
        for (name, bins, record) in [
            ("prism", 100, Record::Compact),
            ("cornell-box", 20, Record::Full),
        ] {
            let scene = crate::scene::load_builtin(name).unwrap();
            let scene =
                SpectralScene::new(&scene, crate::spectral::BinGrid::with_bins(bins).unwrap());
            let settings = PhotonSettings {
                caustic_factor: 4,
                ..PhotonSettings::new(2_000, record)
            };
            // The prism's ceiling panel aims its caustic-only photons at the glass.
            let (_, roles, scales) = roles(2_000, 4, &scene.lights);
            assert_eq!(scene.lights.aims(), name == "prism", "{name}");
            let chunk = Chunk {
                scene: &scene,
                settings: &settings,
                caustic: scene.has_specular,
                roles,
                caustic_scales: &scales,
                seed: 7,
                pass: 3,
            };
            let run = |avx: bool| {
                let mut maps = [0, 1].map(|_| PhotonBatch::new(record, &scene.grid));
                let [g, c] = &mut maps;
                let mut scratch = TraceScratch::default();
                let splits = if avx {
                    // SAFETY: the CPU has AVX (checked above).
                    unsafe { chunk.trace_avx(0..8_000, (g, c), &mut scratch, &mut Vec::new()) }
                } else {
                    chunk.trace_in(0..8_000, (g, c), &mut scratch, &mut Vec::new())
                };
                (format!("{maps:?}"), splits, maps[0].len() + maps[1].len())
            };
            let (avx, portable) = (run(true), run(false));
            assert!(portable.2 > 1_000, "{name}: {} photons stored", portable.2);
            assert!(name != "prism" || portable.1 > 0, "{name}: no splits");
            assert!(avx == portable, "{name}: the copies differ");
        }
    }

    #[test]
    fn splitting_conserves_flux_for_every_bin_count() {
        let mut rng = Rng::stream(9, 0, 0, Purpose::Photon);
        for n in [1usize, 2, 4, 100, 1000] {
            let flux: Vec<f32> = (0..n).map(|i| 1.0 + (i % 7) as f32).collect();
            let total: f64 = flux.iter().map(|&v| v as f64).sum();
            for s in [1usize, 4, 16, 2000] {
                let parts = split_dispersive(&flux, s, &mut rng);
                assert_eq!(parts.len(), n.min(s));
                let sum: f64 = parts.iter().flatten().map(|&v| v as f64).sum();
                assert!(
                    (sum - total).abs() <= 1e-5 * total,
                    "n={n} s={s}: {sum} vs {total}"
                );
                for p in &parts {
                    assert!(spd::single_nonzero(p).is_some(), "each piece is one bin");
                }
            }
        }
    }

    #[test]
    fn stratified_splitting_is_unbiased_per_bin() {
        let n = 10;
        let flux: Vec<f32> = (0..n).map(|i| (i as f32 + 1.0).powi(2)).collect();
        let mut mean = vec![0.0f64; n];
        let trials = 20_000;
        for t in 0..trials {
            let mut rng = Rng::stream(1, 0, t, Purpose::Photon);
            for p in split_dispersive(&flux, 3, &mut rng) {
                for (m, v) in mean.iter_mut().zip(&p) {
                    *m += *v as f64 / trials as f64;
                }
            }
        }
        // Each bin's per-trial value is Σ/S with probability p = S·f/Σ (else 0): allow 4σ.
        let total: f64 = flux.iter().map(|&v| v as f64).sum();
        let share = total / 3.0;
        for (m, f) in mean.iter().zip(&flux) {
            let p = (3.0 * *f as f64 / total).min(1.0);
            let sigma = share * (p * (1.0 - p) / trials as f64).sqrt();
            assert!(
                (m - *f as f64).abs() < 4.0 * sigma + 1e-9,
                "{m} vs {f} (σ {sigma})"
            );
        }
    }
}
