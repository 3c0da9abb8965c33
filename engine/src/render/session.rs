//! A progressive render: each pass traces fresh photons, builds the maps, gathers one
//! sample per pixel with the pass's radius, and adds the pass image to the film.
//!
//! **Consistency** (documented scheme): probabilistic progressive photon mapping (Knaus
//! & Zwicker 2011). Pass k uses radius r_k with r²ₖ₊₁ = r²ₖ·(k+α)/(k+1), so the bias of
//! each pass vanishes while the variance of the mean over passes still goes to zero: the
//! image converges to the right answer as passes grow. At most two passes' photon maps
//! live in memory at a time: the gathering pass's, and the next pass's while they are
//! traced alongside that gather (both within the photon budget).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use rayon::prelude::*;

use super::film::{Film, Image, SpectralFilm};
use super::gather::{Gather, GatherSequence, Scratch};
use super::settings::{RenderSettings, SettingsError, default_photon_budget};
use crate::lights::adaptive::EmissionLearner;
use crate::photon::trace::AdaptiveEmission;
use crate::photon::visibility::VisibleSurfaces;
use crate::photon::{
    IrradianceCache, Kernel, PhotonPass, PhotonSettings, Storage, TraceStop, trace_photons,
};
use crate::sampling::{Purpose, Rng};
use crate::scene::{Scene, SpectralScene};

/// Why a pass or a run did not finish.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RenderError {
    /// The cancel flag was raised; the film is unchanged.
    #[error("render cancelled")]
    Cancelled,
    /// Not even one photon's maps fit the photon budget.
    #[error(
        "the photon budget of {budget} bytes cannot hold the photon maps of a single photon; raise --photon-budget"
    )]
    OverBudget { budget: usize },
    #[error(transparent)]
    Settings(#[from] SettingsError),
    /// The error reference does not match the render.
    #[error("reference image: {0}")]
    Reference(#[from] crate::metrics::SizeMismatch),
}

/// A pass image (linear sRGB per pixel), the probed pixels' spectra, and every pixel's
/// spectrum when a spectral film is kept.
type PassImage = (Vec<[f32; 3]>, Vec<(usize, Vec<f32>)>, Vec<f32>);

/// The first pass's typical radii of the global and caustic maps, once measured (or set).
type FirstRadii = (Option<f32>, Option<f32>);

/// A pass's photon maps and what is derived from them before it gathers.
struct Prepared {
    maps: PhotonPass,
    /// Photons emitted (fewer than asked when the budget required).
    photons: usize,
    budget_note: Option<String>,
    /// The first-pass radii, once measured.
    r1: FirstRadii,
    kernels: (Kernel, Kernel),
    /// This pass's typical (median k-nearest) radii.
    typical: (f32, f32),
    irradiance: Option<IrradianceCache>,
    /// Wall seconds the tracing and preparing took.
    seconds: f64,
}

impl Prepared {
    /// Bytes of the photon maps.
    fn map_bytes(&self) -> usize {
        self.maps.global.memory_bytes() + self.maps.caustic.as_ref().map_or(0, |c| c.memory_bytes())
    }

    /// Photon-map bytes per emitted photon (what the budget scales by).
    fn bytes_per_emitted(&self) -> f64 {
        self.map_bytes() as f64 / self.photons.max(1) as f64
    }
}

/// Bytes of each part of a render, measured exactly.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct MemoryReport {
    pub global_map: usize,
    pub caustic_map: usize,
    pub photon_maps: usize,
    /// The global map's precomputed irradiance (final gathering only).
    pub irradiance_cache: usize,
    /// The next pass's photon maps, traced while this pass gathered and alive beside its
    /// maps until that pass starts (0 when none were); the two fit the photon budget.
    pub next_pass_maps: usize,
    pub film: usize,
    /// The ray search's bytes: the BVH, or a small scene's triangle blocks.
    pub bvh: usize,
    /// The scene is small enough to be searched without a BVH ([`crate::geometry::FLAT_MAX_TRIANGLES`]).
    #[serde(skip)]
    pub bvh_skipped: bool,
}

/// Running totals over all passes.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct RenderStats {
    pub passes: u64,
    pub photons_emitted: u64,
    /// Photons emitted for the caustic map only ([`RenderSettings::caustic_factor`]).
    pub caustic_photons_emitted: u64,
    /// Whether the latest pass aimed its caustic-only photons at the glass and mirrors.
    pub caustic_photons_aimed: bool,
    /// The spheres around the glass and mirrors those photons were aimed at (0 when not
    /// aimed; see [`crate::lights::LightSet::aim_at`]).
    pub caustic_targets: u32,
    /// Photons stored in the latest pass's maps.
    pub stored_global: u64,
    pub stored_caustic: u64,
    pub spike_records: u64,
    /// Totals over all passes.
    pub stored_global_total: u64,
    pub stored_caustic_total: u64,
    pub spike_records_total: u64,
    pub dispersion_splits: u64,
    /// Wall seconds spent waiting for photon maps before a gather: a pass whose maps were
    /// traced during the previous pass's gather (see [`RenderSession::run`]) waits none.
    pub photon_seconds: f64,
    /// Wall seconds of gathering, including the next pass's photon tracing where it ran
    /// alongside; `photon_seconds + gather_seconds` is the render's wall time.
    pub gather_seconds: f64,
    /// Of `gather_seconds`, the wall seconds the next pass's tracing took alongside (the
    /// two shared the cores).
    pub photon_seconds_alongside: f64,
    pub last_pass_seconds: f64,
    /// Typical (median k-nearest) gather radii of the latest pass; each query adapts its
    /// own radius to its k nearest photons.
    pub r_global: f32,
    pub r_caustic: f32,
    /// Photons emitted in the latest pass (fewer than asked when the budget required).
    pub photons_last_pass: u64,
    /// Why photons per pass were lowered, if they were.
    pub budget_note: Option<String>,
    /// Whether the latest pass emitted by learned tables ([`crate::lights::adaptive`]).
    pub emission_adapted: bool,
    /// Of the latest pass's photons from learning lights, the share that reached a
    /// surface the camera sees (None where no light learns).
    pub emission_useful_share: Option<f64>,
}

pub struct RenderSession {
    scene: Arc<SpectralScene>,
    settings: RenderSettings,
    film: Film,
    stats: RenderStats,
    /// First-pass radii once known, and the current r²/r₁² factor.
    r1_global: Option<f32>,
    r1_caustic: Option<f32>,
    radius_sq_factor: f64,
    memory: MemoryReport,
    cancel: Arc<AtomicBool>,
    /// Pixels whose spectra are kept (the probe): the only spectral film memory.
    probes: Vec<Probe>,
    /// Every pixel's spectrum, when asked for (see [`RenderSession::keep_spectra`]).
    spectra: Option<SpectralFilm>,
    /// Photon-map bytes per emitted photon in the latest pass (for the budget).
    bytes_per_emitted: Option<f64>,
    /// The next pass's maps, traced during the latest pass's gather.
    next: Option<Prepared>,
    /// Pixels whose centre sees an emitter directly (for exposure metering), once known.
    emitter_pixels: std::sync::OnceLock<Arc<Vec<bool>>>,
    /// The denoiser's guides (first hits through pixel centres), once asked for.
    guides: std::sync::OnceLock<Arc<super::denoise::Guides>>,
    /// How far, in caustic radii, a pixel's samples share its caustic estimate (see
    /// [`Gather::caustic_reuse`]); 0 in tests that compare against unshared estimates.
    caustic_reuse: f32,
    /// Whether the gather runs its AVX copy ([`Gather::avx`]): where the CPU has AVX;
    /// off in the test that compares the two.
    avx: bool,
    /// Learned emission's counts over the passes so far ([`crate::lights::adaptive`]):
    /// None when it is off or no light learns.
    learner: Option<EmissionLearner>,
    /// What the camera sees, probed before the first pass where a light learns.
    visible: Option<Arc<VisibleSurfaces>>,
}

/// The global map's search cap, in typical radii and as a fraction of the scene diagonal
/// (the larger wins).
const GLOBAL_CAP_TYPICAL: f32 = 8.0;
const GLOBAL_CAP_DIAGONAL: f32 = 0.02;
/// Final-gather rays read irradiance precomputed at every 16th global photon (Christensen
/// 1999 used a quarter). Measured against every 8th at the same passes: Cornell box 38.91
/// vs 38.87 dB, prism 34.84 vs 34.85 dB at 16 passes (against same-seed references, which
/// share those passes' noise), spot-lit stage 29.20 vs 29.36 dB at 24 passes (a reference
/// of another seed) — and each pass is cheaper, so per second every
/// 16th is as good or better (spot-lit stage: 29.20 dB at 5.8 s, every 8th ≈ 29.1 dB).
pub const PRECOMPUTE_EVERY: usize = 16;

/// The photon step of a pass's irradiance cache: [`PRECOMPUTE_EVERY`] at the first pass,
/// then in proportion to the pass's Knaus–Zwicker `shrink` (r_i / r_1), at least 1.
/// A final-gather ray reads its nearest point, and points sit at photons, which crowd
/// where irradiance is high: next to a bright patch the nearest point lies on the bright
/// side more often than not, by about half the dark side's point spacing. That bias does
/// not average out over passes (each pass's points are its own photons); it shrinks only
/// with the spacing. A fixed step left a sun-lit room's walls 7.5 % bright at 25 000
/// photons a pass after 20 passes and after 80 alike; a step falling as the radius
/// shrinks makes the spacing (√step photon spacings) go to 0 with it, so the cache's
/// bias goes as the density estimates' own (BENCHMARKS.md, session 36).
pub fn precompute_every(shrink: f32) -> usize {
    let step = PRECOMPUTE_EVERY as f32 * shrink;
    if step.is_finite() {
        (step.round() as usize).clamp(1, PRECOMPUTE_EVERY)
    } else {
        PRECOMPUTE_EVERY
    }
}

/// The caustic map's search cap, in typical radii: the radius shrinks where caustic
/// photons are dense (a sharper caustic) but does not widen beyond its start, so a query
/// far from every caustic costs one small search.
const CAUSTIC_CAP_TYPICAL: f32 = 1.2;

/// Fault injection for reliability tests: while set, every pass panics. Process-wide and
/// never set by the program itself; only the viewer's panic-recovery test uses it.
#[doc(hidden)]
pub static INJECT_PANIC: AtomicBool = AtomicBool::new(false);

/// The accumulated spectrum of one probed pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Probe {
    pub x: u32,
    pub y: u32,
    /// Sum over passes of the pixel's radiance per bin.
    pub sum: Vec<f64>,
    /// Passes summed.
    pub passes: u64,
}

impl Probe {
    /// Mean radiance per bin.
    pub fn mean(&self) -> Vec<f32> {
        let k = if self.passes > 0 {
            1.0 / self.passes as f64
        } else {
            0.0
        };
        self.sum.iter().map(|v| (v * k) as f32).collect()
    }
}

impl RenderSession {
    /// Validates the settings and projects the scene onto their bin grid.
    pub fn new(scene: &Scene, settings: RenderSettings) -> Result<Self, SettingsError> {
        settings.validate()?;
        let grid = settings.grid()?;
        let spectral = Arc::new(SpectralScene::new(scene, grid));
        Ok(Self::with_spectral_scene(spectral, settings))
    }

    /// Reuses an already projected scene (its grid must match the settings).
    pub fn with_spectral_scene(scene: Arc<SpectralScene>, settings: RenderSettings) -> Self {
        let film = Film::new(settings.width, settings.height);
        let memory = MemoryReport {
            film: film.memory_bytes(),
            bvh: scene.accel.memory_bytes(),
            bvh_skipped: !scene.accel.uses_bvh(),
            ..Default::default()
        };
        Self {
            r1_global: settings.global_radius,
            r1_caustic: settings.caustic_radius,
            scene,
            settings,
            film,
            stats: RenderStats::default(),
            radius_sq_factor: 1.0,
            memory,
            cancel: Arc::new(AtomicBool::new(false)),
            probes: Vec::new(),
            spectra: None,
            bytes_per_emitted: None,
            next: None,
            emitter_pixels: std::sync::OnceLock::new(),
            guides: std::sync::OnceLock::new(),
            caustic_reuse: super::gather::CAUSTIC_REUSE,
            avx: crate::cpu::has_avx(),
            learner: None,
            visible: None,
        }
        .learning()
    }

    /// This session with learned emission set up, where the settings ask for it and a
    /// light of the scene learns.
    fn learning(mut self) -> Self {
        if self.settings.adapt_emission {
            self.learner = EmissionLearner::new(&self.scene.lights);
        }
        self
    }

    /// Keeps the spectrum of these pixels from the next pass on (others are dropped;
    /// a pixel already probed keeps its sums).
    pub fn set_probes(&mut self, pixels: &[(u32, u32)]) {
        let n = self.scene.bins();
        let (w, h) = (self.settings.width, self.settings.height);
        let old = std::mem::take(&mut self.probes);
        self.probes = pixels
            .iter()
            .filter(|(x, y)| *x < w && *y < h)
            .map(|&(x, y)| {
                old.iter()
                    .find(|p| (p.x, p.y) == (x, y))
                    .cloned()
                    .unwrap_or(Probe {
                        x,
                        y,
                        sum: vec![0.0; n],
                        passes: 0,
                    })
            })
            .collect();
        self.memory.film = self.film.memory_bytes() + self.probe_bytes();
    }

    pub fn probes(&self) -> &[Probe] {
        &self.probes
    }

    /// Keeps every pixel's spectrum from the next pass on (for a spectral EXR), or stops
    /// and frees it. 4 bytes per bin per pixel.
    pub fn keep_spectra(&mut self, on: bool) {
        self.spectra = match (on, self.spectra.take()) {
            (true, Some(s)) => Some(s),
            (true, None) => Some(SpectralFilm::new(
                self.settings.width,
                self.settings.height,
                self.scene.bins(),
            )),
            (false, _) => None,
        };
        self.memory.film = self.film.memory_bytes() + self.probe_bytes();
    }

    /// The per-pixel spectra, when kept.
    pub fn spectral_film(&self) -> Option<&SpectralFilm> {
        self.spectra.as_ref()
    }

    fn probe_bytes(&self) -> usize {
        self.probes.iter().map(|p| p.sum.len() * 8).sum::<usize>()
            + self.spectra.as_ref().map_or(0, |s| s.memory_bytes())
    }

    pub fn scene(&self) -> &Arc<SpectralScene> {
        &self.scene
    }

    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    pub fn stats(&self) -> &RenderStats {
        &self.stats
    }

    pub fn memory(&self) -> MemoryReport {
        self.memory
    }

    pub fn film(&self) -> &Film {
        &self.film
    }

    pub fn image(&self) -> Image {
        self.film.develop()
    }

    /// A flag that stops the running pass when set (checked per photon chunk and per row).
    pub fn cancel_flag(&self) -> Arc<AtomicBool> {
        self.cancel.clone()
    }

    /// What this scene and these settings let the renderer skip.
    pub fn skipped(&self) -> Vec<String> {
        let mut s = Vec::new();
        if !self.scene.has_specular {
            s.push("caustic map: the scene has no specular (mirror or glass) surface".to_string());
        }
        if !self.scene.has_dispersion {
            s.push(match self.settings.storage {
                Storage::Rgb => {
                    "dispersion splitting: RGB transport uses the 550 nm index".to_string()
                }
                _ if self.scene.bins() == 1 => {
                    "dispersion splitting: one bin holds every wavelength, so glass has one index"
                        .to_string()
                }
                _ => "dispersion splitting: no dispersive glass in the scene".to_string(),
            });
        }
        if self.settings.final_gather_rays == 0 {
            s.push("final gathering: global map shown directly".to_string());
        }
        if let Some(note) = &self.stats.budget_note {
            s.push(note.clone());
        }
        if self.probes.is_empty() && self.spectra.is_none() {
            s.push("spectral film: nothing reads per-pixel spectra in this run".to_string());
        }
        s
    }

    /// Runs one pass (from the maps a [`RenderSession::run`] traced ahead for it, if it
    /// left some; they are the ones this pass would trace); on cancel (or when not even one
    /// photon fits the budget) the film is unchanged.
    pub fn run_pass(&mut self) -> Result<(), RenderError> {
        self.pass(false)
    }

    /// Runs one pass; with `trace_next`, the next pass's photons are traced (and its
    /// irradiance cache built) on the same threads while this pass gathers, so that
    /// neither phase's serial parts (kd-tree tops, the cache's thinning, the last rows)
    /// leave a core idle. The next pass then starts from those maps: they are the ones it
    /// would have traced itself (same seed, pass and photon count), so the images do not
    /// change. Only [`RenderSession::run`] asks for it, when another pass is expected.
    pub(super) fn pass(&mut self, trace_next: bool) -> Result<(), RenderError> {
        if INJECT_PANIC.load(Ordering::Relaxed) {
            panic!("injected fault (test)");
        }
        let start = Instant::now();
        let pass = self.film.passes() + 1;
        if self.learner.is_some() && self.visible.is_none() {
            let (w, h, seed) = (
                self.settings.width,
                self.settings.height,
                self.settings.seed,
            );
            self.visible = Some(Arc::new(VisibleSurfaces::probe(&self.scene, w, h, seed)));
        }
        let (prepared, overlapped) = match self.next.take() {
            Some(p) => {
                let seconds = p.seconds;
                (p, seconds)
            }
            None => {
                let learner = self.learner.as_ref();
                let (maps, photons, note) = self.trace_within_budget(pass, learner)?;
                let r1 = (self.r1_global, self.r1_caustic);
                let p = self.prepare(maps, photons, note, r1, self.radius_sq_factor, start);
                (p, 0.0)
            }
        };
        let photon_done = Instant::now();
        (self.r1_global, self.r1_caustic) = prepared.r1;
        let (global_kernel, caustic_kernel) = prepared.kernels;
        let gather = Gather {
            scene: &self.scene,
            global: &prepared.maps.global,
            caustic: prepared.maps.caustic.as_ref(),
            irradiance: prepared.irradiance.as_ref(),
            global_kernel,
            caustic_kernel,
            r_min: self.r_min(),
            final_gather_rays: self.settings.final_gather_rays,
            pool_gather: self.settings.pools_gather(),
            pool_reach: super::gather::POOL_REACH * (self.radius_sq_factor.sqrt() as f32),
            camera_samples: self.settings.camera_samples,
            glass_split: self.settings.glass_split,
            max_bounces: self.settings.max_bounces,
            caustic_reuse: self.caustic_reuse,
            tan_half_fov: super::gather::camera_tan_half_fov(&self.scene.camera),
            avx: self.avx,
        };
        let next_factor = next_radius_sq_factor(self.radius_sq_factor, pass, self.settings.alpha);
        // What the next pass emits by: the counts of every pass up to this one (kept only
        // if this pass completes, so a cancelled pass leaves no trace).
        let learned = self
            .learner
            .as_ref()
            .map(|l| l.learned(&prepared.maps.reports));
        let (gathered, next) = if trace_next {
            let this = &*self;
            let learned = learned.as_ref();
            rayon::join(
                || this.gather_image(&gather, pass),
                || this.trace_ahead(pass + 1, &prepared, next_factor, learned),
            )
        } else {
            (self.gather_image(&gather, pass), None)
        };
        let (image, probe_spectra, all_spectra) = gathered?;
        if let Some(l) = learned {
            // This pass emitted by the tables of the learner it replaces.
            self.stats.emission_adapted = self.learner.as_ref().is_some_and(|l| l.adapted());
            self.stats.emission_useful_share = l.useful_share();
            self.learner = Some(l);
        }
        self.film.add_pass(&image);
        self.add_probe_spectra(probe_spectra);
        if let Some(s) = &mut self.spectra {
            s.add_pass(&all_spectra);
        }
        let times = (start, photon_done, Instant::now());
        self.record_pass(&prepared, overlapped, times);
        self.memory.next_pass_maps = next.as_ref().map_or(0, Prepared::map_bytes);
        self.next = next;
        self.radius_sq_factor = next_factor;
        Ok(())
    }

    /// The smallest radius a density estimate divides by.
    fn r_min(&self) -> f32 {
        1e-6 * self.scene.diagonal().max(1e-6)
    }

    /// The photon budget in bytes (the settings', or the machine's default).
    fn budget(&self) -> usize {
        self.settings
            .photon_budget_bytes
            .unwrap_or_else(default_photon_budget)
    }

    /// Photons a pass first tries to emit: the settings', lowered to what the budget holds
    /// at the latest pass's bytes per emitted photon.
    fn photons_to_try(&self, bytes_per_emitted: Option<f64>) -> usize {
        let (asked, budget) = (self.settings.photons_per_pass, self.budget());
        match bytes_per_emitted {
            Some(b) if b > 0.0 => asked.min((budget as f64 / (1.1 * b)) as usize).max(1),
            _ => asked,
        }
    }

    fn photon_settings(
        &self,
        photons: usize,
        max_map_bytes: usize,
        learner: Option<&EmissionLearner>,
    ) -> PhotonSettings {
        let adapt = learner
            .zip(self.visible.as_ref())
            .map(|(l, v)| AdaptiveEmission {
                cells: l.cells(),
                visible: Arc::clone(v),
            });
        PhotonSettings {
            photons,
            record: self.settings.storage.record(),
            max_bounces: self.settings.max_bounces,
            dispersion_split: self.settings.dispersion_split,
            caustic_map: true,
            caustic_factor: self.settings.caustic_factor,
            max_map_bytes,
            incoming: self.settings.guides_gather(),
            adapt,
        }
    }

    /// Why photons per pass are below the settings', if they are.
    fn budget_note(&self, photons: usize) -> Option<String> {
        let asked = self.settings.photons_per_pass;
        (photons < asked).then(|| {
            format!(
                "photons per pass lowered from {asked} to {photons}: the photon maps must fit the budget of {:.1} MB",
                self.budget() as f64 / 1e6
            )
        })
    }

    /// Traces pass `pass`'s photons, lowering photons per pass to fit the photon-map
    /// budget: first from the previous pass's bytes per emitted photon, then by halving if
    /// a pass still overruns. Returns the maps, the photons emitted and the budget's note.
    fn trace_within_budget(
        &self,
        pass: u64,
        learner: Option<&EmissionLearner>,
    ) -> Result<(PhotonPass, usize, Option<String>), RenderError> {
        let budget = self.budget();
        let mut photons = self.photons_to_try(self.bytes_per_emitted);
        let maps = loop {
            let photon_settings = self.photon_settings(photons, budget, learner);
            let seed = self.settings.seed;
            match trace_photons(&self.scene, &photon_settings, seed, pass, &self.cancel) {
                Ok(m) => break m,
                Err(TraceStop::Cancelled) => return Err(RenderError::Cancelled),
                Err(TraceStop::OverBudget) if photons > 1 => photons /= 2,
                Err(TraceStop::OverBudget) => return Err(RenderError::OverBudget { budget }),
            }
        };
        Ok((maps, photons, self.budget_note(photons)))
    }

    /// Pass `pass`'s maps traced ahead, while `current` (the pass before it) gathers:
    /// exactly what [`Self::trace_within_budget`] would trace first after `current`, in
    /// the budget `current` leaves. None when that does not fit (the pass then traces
    /// for itself, halving as usual) or on cancel.
    fn trace_ahead(
        &self,
        pass: u64,
        current: &Prepared,
        radius_sq_factor: f64,
        learner: Option<&EmissionLearner>,
    ) -> Option<Prepared> {
        let start = Instant::now();
        let bytes_per_emitted = current.bytes_per_emitted();
        let photons = self.photons_to_try(Some(bytes_per_emitted));
        let left = self.budget().saturating_sub(current.map_bytes());
        if photons as f64 * bytes_per_emitted > left as f64 {
            return None; // would not fit beside this pass's maps: not worth trying
        }
        let settings = self.photon_settings(photons, left, learner);
        let maps = trace_photons(
            &self.scene,
            &settings,
            self.settings.seed,
            pass,
            &self.cancel,
        );
        let note = self.budget_note(photons);
        let prepared = self.prepare(
            maps.ok()?,
            photons,
            note,
            current.r1,
            radius_sq_factor,
            start,
        );
        // Cancelled while preparing: its cache may be missing.
        (!self.cancel.load(Ordering::Relaxed)).then_some(prepared)
    }

    /// What a pass derives from its photon maps before gathering: the first-pass radii
    /// (measured once), the kernels at this pass's shrink, and the irradiance cache that
    /// final-gather rays read.
    fn prepare(
        &self,
        maps: PhotonPass,
        photons: usize,
        budget_note: Option<String>,
        r1: FirstRadii,
        radius_sq_factor: f64,
        start: Instant,
    ) -> Prepared {
        let (r1, kernels, typical) = self.kernels(&maps, r1, radius_sq_factor);
        // Each map's occupancy grid for the cap its estimates search to, the two side by
        // side, now: built at a map's first estimate, one thread built it while the
        // gather's others waited.
        rayon::join(
            || maps.global.prepare_search(kernels.0.r_max),
            || {
                if let Some(c) = &maps.caustic {
                    c.prepare_search(kernels.1.r_max);
                }
            },
        );
        // Final-gather rays read precomputed irradiance (one density estimate per
        // `precompute_every` photons instead of one per ray).
        // None also when cancelled: the pass then stops at its first row.
        let irradiance = (self.settings.final_gather_rays > 0).then(|| {
            IrradianceCache::build(
                &maps.global,
                &self.scene.grid,
                Some(&*self.scene),
                kernels.0,
                precompute_every(kernels.0.shrink),
                self.r_min(),
                kernels.0.r_max,
                &self.cancel,
            )
        });
        let irradiance = irradiance.flatten();
        Prepared {
            maps,
            photons,
            budget_note,
            r1,
            kernels,
            typical,
            irradiance,
            seconds: start.elapsed().as_secs_f64(),
        }
    }

    /// A pass's density-estimate kernels. Each map's radius adapts per query to its
    /// k nearest photons (`global_k`, [`RenderSettings::caustic_neighbours`]), searched out to a cap, and shrinks
    /// with passes by the Knaus–Zwicker factor; a radius given in the settings is used as
    /// a fixed radius instead. The first pass also measures the median k-nearest distance
    /// over the photons (`typical`), which sets the caps and is reported. Returns the
    /// first-pass radii (`r1` with any still unknown measured on these maps), the kernels
    /// and this pass's typical radii.
    fn kernels(
        &self,
        maps: &PhotonPass,
        (mut r1_global, mut r1_caustic): FirstRadii,
        radius_sq_factor: f64,
    ) -> (FirstRadii, (Kernel, Kernel), (f32, f32)) {
        let scene = &self.scene;
        let fallback = || {
            let area = scene.diffuse_area.max(1e-12);
            let stored = maps.global.len().max(1) as f64;
            ((area * self.settings.global_k as f64) / (std::f64::consts::PI * stored)).sqrt() as f32
        };
        if r1_global.is_none() {
            r1_global = Some(
                maps.global
                    .typical_knn_radius(self.settings.global_k, 256)
                    .unwrap_or_else(fallback),
            );
        }
        if r1_caustic.is_none()
            && let Some(c) = &maps.caustic
        {
            r1_caustic = c.typical_knn_radius(self.settings.caustic_neighbours(), 256);
        }
        let diag = scene.diagonal().max(1e-6);
        let shrink = radius_sq_factor.sqrt() as f32;
        let typical_global = r1_global.unwrap_or_else(fallback);
        let typical_caustic = r1_caustic.unwrap_or(typical_global);
        // The caustic map's late-pass searches are folded (`Kernel::adaptive`: the same
        // expected estimate from a third of the neighbours); the global map's are not, as
        // folding them saved 6–8 % of the time on the prism but cost 0.25 dB at 48
        // passes, no gain per second (BENCHMARKS.md, session 14).
        let kernel = |fixed: Option<f32>, k: usize, typical: f32, cap: f32, fold: bool| {
            let (r_max, r_start) = (cap.max(1e-6 * diag), 1.2 * typical);
            match fixed {
                Some(r) => Kernel {
                    k: 0,
                    r_max: r,
                    r_start: r,
                    shrink,
                },
                None if fold => Kernel::adaptive(k, r_max, r_start, shrink),
                None => Kernel {
                    k,
                    r_max,
                    r_start,
                    shrink,
                },
            }
        };
        // Caps: dim regions of the global map need far more than the median radius (a
        // spot-lit scene's median is set by the spot); caustics stay sharp with a tight cap.
        // Each search starts at 1.2 typical radii.
        let global = kernel(
            self.settings.global_radius,
            self.settings.global_k,
            typical_global,
            (GLOBAL_CAP_TYPICAL * typical_global).max(GLOBAL_CAP_DIAGONAL * diag),
            false,
        );
        let caustic = kernel(
            self.settings.caustic_radius,
            self.settings.caustic_neighbours(),
            typical_caustic,
            CAUSTIC_CAP_TYPICAL * typical_caustic,
            true,
        );
        let typical = (typical_global * shrink, typical_caustic * shrink);
        ((r1_global, r1_caustic), (global, caustic), typical)
    }

    /// One sample per pixel, rows in parallel; returns the pass image (linear sRGB) and the
    /// probed pixels' spectra.
    fn gather_image(&self, gather: &Gather, pass: u64) -> Result<PassImage, RenderError> {
        let (w, h) = (self.settings.width, self.settings.height);
        let (seed, n) = (self.settings.seed, self.scene.bins());
        let rays = self.settings.final_gather_rays;
        let (cancel, probes, grid) = (&self.cancel, &self.probes, &self.scene.grid);
        let keep_all = self.spectra.is_some();
        // Pooled final gathering renders 2×2 blocks ([`Gather::block`]), their grid shifted
        // by a pixel across and down from pass to pass so that no pixel always pools with
        // the same neighbours; otherwise every block is one pixel.
        let side = if gather.pool_gather { 2 } else { 1 };
        let (ox, oy) = match side {
            2 => ((pass & 1) as u32, ((pass >> 1) & 1) as u32),
            _ => (0, 0),
        };
        let columns = spans(w, side, ox);
        // One task per row of blocks: rayon otherwise cuts the rows into a few long runs,
        // and when the costly rows (a caustic's) fall into one run its thread finishes alone.
        let rows: Vec<Option<PassImage>> = spans(h, side, oy)
            .into_par_iter()
            .with_max_len(1)
            .map_init(
                || {
                    let blocks = (side * side) as usize;
                    let outs = vec![vec![0.0f32; n]; blocks];
                    (Scratch::new(n), outs, Vec::new(), Vec::new())
                },
                |(scratch, outs, pixels, rngs), (y0, y1)| {
                    if cancel.load(Ordering::Relaxed) {
                        return None;
                    }
                    let count = ((y1 - y0) * w) as usize;
                    let mut spectra = Vec::new();
                    let mut all = vec![0.0f32; if keep_all { count * n } else { 0 }];
                    let mut image = vec![[0.0f32; 3]; count];
                    scratch.start_row();
                    for &(x0, x1) in &columns {
                        pixels.clear();
                        rngs.clear();
                        for y in y0..y1 {
                            for x in x0..x1 {
                                let index = (y as u64) * w as u64 + x as u64;
                                rngs.push(Rng::stream(seed, pass, index, Purpose::Camera));
                                let samples = gather.camera_samples;
                                let fg =
                                    GatherSequence::for_pixel(seed, index, pass - 1, rays, samples);
                                pixels.push(((x, y), fg));
                            }
                        }
                        let outs = &mut outs[..pixels.len()];
                        gather.block(pixels, (w, h), rngs, scratch, outs);
                        for (&((x, y), _), radiance) in pixels.iter().zip(outs.iter()) {
                            let i = ((y - y0) * w + x) as usize;
                            if let Some(k) = probes.iter().position(|p| (p.x, p.y) == (x, y)) {
                                spectra.push((k, radiance.clone()));
                            }
                            if keep_all {
                                all[i * n..(i + 1) * n].copy_from_slice(radiance);
                            }
                            image[i] = grid.to_linear_srgb(radiance);
                        }
                    }
                    Some((image, spectra, all))
                },
            )
            .collect();
        let mut image = Vec::with_capacity((w * h) as usize);
        let mut probe_spectra = Vec::new();
        let mut all_spectra = Vec::new();
        for r in rows {
            let (row, spectra, all) = r.ok_or(RenderError::Cancelled)?;
            image.extend(row);
            probe_spectra.extend(spectra);
            all_spectra.extend(all);
        }
        Ok((image, probe_spectra, all_spectra))
    }

    /// Adds a pass's probe spectra (same rule as the film: a non-finite sample is dropped).
    fn add_probe_spectra(&mut self, spectra: Vec<(usize, Vec<f32>)>) {
        for (k, spectrum) in spectra {
            let p = &mut self.probes[k];
            if spectrum.iter().all(|v| v.is_finite()) {
                for (s, v) in p.sum.iter_mut().zip(&spectrum) {
                    *s += *v as f64;
                }
            }
            p.passes += 1;
        }
    }

    /// Bookkeeping after a pass: counts, times, radii, memory.
    fn record_pass(
        &mut self,
        prepared: &Prepared,
        overlapped: f64,
        (start, photon_done, end): (Instant, Instant, Instant),
    ) {
        let maps = &prepared.maps;
        let st = &mut self.stats;
        st.passes = self.film.passes();
        st.photons_last_pass = prepared.photons as u64;
        st.budget_note = prepared.budget_note.clone();
        st.photons_emitted += maps.emitted;
        st.caustic_photons_emitted += maps.caustic_emitted;
        st.caustic_photons_aimed = maps.caustic_aimed;
        st.caustic_targets = if maps.caustic_aimed {
            self.scene.lights.targets().len() as u32
        } else {
            0
        };
        st.stored_global = maps.global.len() as u64;
        st.stored_caustic = maps.caustic.as_ref().map_or(0, |c| c.len() as u64);
        st.spike_records = maps.global.spike_records() as u64
            + maps
                .caustic
                .as_ref()
                .map_or(0, |c| c.spike_records() as u64);
        st.stored_global_total += st.stored_global;
        st.stored_caustic_total += st.stored_caustic;
        st.spike_records_total += st.spike_records;
        st.dispersion_splits += maps.splits;
        st.photon_seconds += (photon_done - start).as_secs_f64();
        st.gather_seconds += (end - photon_done).as_secs_f64();
        st.photon_seconds_alongside += overlapped;
        st.last_pass_seconds = (end - start).as_secs_f64();
        let (r_global, r_caustic) = prepared.typical;
        st.r_global = r_global;
        st.r_caustic = if maps.caustic.is_some() {
            r_caustic
        } else {
            0.0
        };
        self.memory.global_map = maps.global.memory_bytes();
        self.memory.caustic_map = maps.caustic.as_ref().map_or(0, |c| c.memory_bytes());
        self.memory.photon_maps = self.memory.global_map + self.memory.caustic_map;
        self.memory.irradiance_cache = prepared.irradiance.as_ref().map_or(0, |c| c.memory_bytes());
        self.bytes_per_emitted = Some(prepared.bytes_per_emitted());
    }

    /// Which pixels see an emitter directly through their centre (one ray each, cast once):
    /// what automatic exposure leaves out of its metering.
    pub fn emitter_pixels(&self) -> Arc<Vec<bool>> {
        self.emitter_pixels
            .get_or_init(|| {
                let (w, h) = (self.settings.width, self.settings.height);
                let scene = &self.scene;
                let cam = scene.camera;
                let mask = (0..h)
                    .into_par_iter()
                    .flat_map_iter(|y| {
                        (0..w).map(move |x| {
                            let d = super::gather::camera_dir(
                                &cam,
                                x as f32 + 0.5,
                                y as f32 + 0.5,
                                w,
                                h,
                            );
                            scene.intersect(cam.position, d).is_some_and(|hit| {
                                hit.front && scene.material(&hit).emission.is_some()
                            })
                        })
                    })
                    .collect();
                Arc::new(mask)
            })
            .clone()
    }

    /// The denoiser's guide buffers (computed once per session, in parallel).
    pub fn guides(&self) -> Arc<super::denoise::Guides> {
        self.guides
            .get_or_init(|| {
                Arc::new(super::denoise::Guides::of(
                    &self.scene,
                    self.settings.width,
                    self.settings.height,
                ))
            })
            .clone()
    }

    /// A denoised copy of the current image, for display only (see [`super::denoise`]).
    pub fn denoised(&self, params: super::denoise::DenoiseParams) -> Image {
        let variance = self.film.luminance_variance();
        super::denoise::denoise(&self.image(), variance.as_deref(), &self.guides(), params)
    }

    /// Bytes per stored photon in the latest pass (records + search structure).
    pub fn bytes_per_photon(&self) -> f64 {
        let stored = self.stats.stored_global + self.stats.stored_caustic;
        if stored == 0 {
            0.0
        } else {
            self.memory.photon_maps as f64 / stored as f64
        }
    }
}

/// `0..len` cut into runs of `side`, the first `offset` long when not 0 (the blocks of
/// [`RenderSession::gather_image`]).
fn spans(len: u32, side: u32, offset: u32) -> Vec<(u32, u32)> {
    let mut v = Vec::new();
    let mut start = 0;
    if offset > 0 && len > 0 {
        start = offset.min(len);
        v.push((0, start));
    }
    while start < len {
        let end = (start + side).min(len);
        v.push((start, end));
        start = end;
    }
    v
}

/// Knaus & Zwicker's schedule: r²ₖ₊₁/r₁² from r²ₖ/r₁² after pass k, kept in f64 (an f32
/// factor would stop shrinking long before 100 000 passes).
pub fn next_radius_sq_factor(factor: f64, pass: u64, alpha: f64) -> f64 {
    let k = pass as f64;
    factor * (k + alpha) / (k + 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_cover_every_index_once_from_any_offset() {
        assert_eq!(spans(5, 2, 1), vec![(0, 1), (1, 3), (3, 5)]);
        assert_eq!(spans(5, 2, 0), vec![(0, 2), (2, 4), (4, 5)]);
        assert_eq!(spans(3, 1, 0), vec![(0, 1), (1, 2), (2, 3)]);
        assert_eq!(spans(1, 2, 1), vec![(0, 1)]);
        assert!(spans(0, 2, 1).is_empty());
        for len in 0..9 {
            for (side, offset) in [(1, 0), (2, 0), (2, 1)] {
                let s = spans(len, side, offset);
                let flat: Vec<u32> = s.iter().flat_map(|&(a, b)| a..b).collect();
                assert_eq!(flat, (0..len).collect::<Vec<_>>(), "{len} {side} {offset}");
                assert!(s.iter().all(|&(a, b)| b > a && b - a <= side));
            }
        }
    }

    #[test]
    fn radius_shrinks_monotonically_and_stays_finite_over_100k_passes() {
        let mut f = 1.0f64;
        let mut prev = f;
        for k in 1..100_000u64 {
            f = next_radius_sq_factor(f, k, 2.0 / 3.0);
            assert!(f.is_finite() && f > 0.0 && f < prev);
            prev = f;
        }
        // r² ∝ k^(α−1): after 1e5 passes r²/r₁² ≈ Γ-ratio ~ 1e5^(−1/3) within a factor.
        let expected = 100_000f64.powf(-1.0 / 3.0);
        assert!(
            f > 0.5 * expected && f < 2.0 * expected,
            "{f} vs {expected}"
        );
    }

    #[test]
    fn the_gathers_avx_copy_renders_what_the_portable_one_does_to_the_bit() {
        // The prism at 100 bins (caustic map, irradiance cache, pooled rays, glass seen
        // directly), unpooled, and the Cornell box (also with the global map shown
        // directly), and Blender's textured glass: every pixel of every pass the same bits either way.
        if !crate::cpu::has_avx() {
            eprintln!("this CPU has no AVX: only the portable copy runs");
            return;
        }
        let blender = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenes/blender/textured-glass.glb");
        let cases = [
            (crate::scene::load_builtin("prism").unwrap(), 100, 4, true),
            (crate::scene::load_builtin("prism").unwrap(), 20, 4, false),
            (
                crate::scene::load_builtin("cornell-box").unwrap(),
                20,
                0,
                true,
            ),
            (crate::scene::load(&blender).unwrap(), 20, 4, true),
        ];
        for (scene, bins, fg, pool) in cases {
            let settings = RenderSettings {
                width: 64,
                height: 48,
                bins,
                final_gather_rays: fg,
                pool_gather: pool,
                photons_per_pass: 5_000,
                ..RenderSettings::default()
            };
            let render = |avx: bool| {
                let mut session = RenderSession::new(&scene, settings.clone()).unwrap();
                session.avx = avx;
                session.keep_spectra(true);
                let mut passes = Vec::new();
                for _ in 0..3 {
                    session.run_pass().unwrap();
                    // Every bin of every pixel, and the image developed from them.
                    let spectra = session.spectral_film().unwrap().develop();
                    let image = session.image();
                    let values = spectra
                        .into_iter()
                        .chain(image.pixels.into_iter().flatten());
                    passes.push(values.map(f32::to_bits).collect::<Vec<u32>>());
                }
                passes
            };
            let (avx, portable) = (render(true), render(false));
            let what = format!("{} bins, {fg} rays, pooled {pool}", settings.bins);
            assert!(
                portable[2].iter().any(|&b| f32::from_bits(b) > 0.0),
                "{what}: black"
            );
            assert!(avx == portable, "{what}: the copies differ");
        }
    }

    #[test]
    fn sharing_a_pixels_caustic_estimate_changes_the_prism_far_less_than_its_noise() {
        // The prism's rainbow at 256², 4 camera samples a pixel, with a caustic radius
        // three times the estimated one so that it spans several pixels and the samples
        // share estimates. The same seed traces the same photons, so shared against
        // unshared differs only by where in each pixel the estimate was made: far less
        // than another seed's noise, and the same mean.
        let scene = crate::scene::load_builtin("prism").unwrap();
        let settings = RenderSettings {
            width: 256,
            height: 256,
            bins: 8,
            caustic_radius: Some(0.006),
            ..RenderSettings::default()
        };
        let render = |seed: u64, reuse: f32| {
            let settings = RenderSettings {
                seed,
                ..settings.clone()
            };
            let mut session = RenderSession::new(&scene, settings).unwrap();
            session.caustic_reuse = reuse;
            for _ in 0..4 {
                session.run_pass().unwrap();
            }
            let image = session.image();
            let y =
                |p: &[f32; 3]| 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64;
            image.pixels.iter().map(y).collect::<Vec<f64>>()
        };
        let shared = render(1, super::super::gather::CAUSTIC_REUSE);
        let unshared = render(1, 0.0);
        let other_seed = render(2, 0.0);
        let mse = |a: &[f64], b: &[f64]| {
            a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.len() as f64
        };
        let mean = |a: &[f64]| a.iter().sum::<f64>() / a.len() as f64;
        let (sharing, noise) = (mse(&shared, &unshared), mse(&other_seed, &unshared));
        eprintln!(
            "MSE shared vs unshared {sharing:.3e}, another seed {noise:.3e}; means {} {} {}",
            mean(&shared),
            mean(&unshared),
            mean(&other_seed)
        );
        assert!(sharing > 0.0, "no sample shared an estimate");
        assert!(sharing < 0.1 * noise, "{sharing:.3e} against {noise:.3e}");
        assert!((mean(&shared) / mean(&unshared) - 1.0).abs() < 0.003);
    }
}
