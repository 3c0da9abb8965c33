//! The render worker: its own thread driving its own rayon pool. The UI sends
//! [`Command`]s; after each pass the worker publishes only the newest [`Snapshot`] and
//! asks for a repaint. The UI never waits on a pass: a new `Start` raises the running
//! session's cancel flag, so the old pass stops within one photon chunk or image row, and
//! a generation number keeps any late result out of the new image.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender, TryRecvError};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::render::{
    Flow, Image, MemoryReport, Probe, RenderError, RenderSession, RenderSettings, RenderStats, Stop,
};
use crate::scene::Scene;

pub enum Command {
    /// Start rendering from scratch (cancels whatever runs).
    Start {
        scene: Arc<Scene>,
        settings: RenderSettings,
        generation: u64,
    },
    Pause(bool),
    /// Pixels whose spectra to keep.
    Probes(Vec<(u32, u32)>),
    /// Stop after `passes` passes (None: run until paused or restarted).
    StopAfter(Option<u64>),
    /// Keep every pixel's spectrum (for a spectral EXR), or free it.
    KeepSpectra(bool),
    /// Add a denoised display image to each snapshot (the film stays raw).
    Denoise(bool),
}

/// What the UI shows after a pass.
#[derive(Clone)]
pub struct Snapshot {
    pub generation: u64,
    pub image: Arc<Image>,
    pub stats: RenderStats,
    pub memory: MemoryReport,
    pub bytes_per_photon: f64,
    pub bins: usize,
    pub wavelengths: Vec<f64>,
    pub srgb_weights: Vec<[f32; 3]>,
    pub probes: Vec<Probe>,
    pub skipped: Vec<String>,
    pub warnings: Vec<String>,
    /// Pixels that see an emitter directly (left out of automatic exposure).
    pub emitter_pixels: Arc<Vec<bool>>,
    /// Seconds from the `Start` to this snapshot.
    pub since_start: f64,
    /// A quick low-resolution first image shown right after a change
    /// (see [`RenderSettings::quick_preview_of`]).
    pub preview: bool,
    /// The film's noise estimate (PSNR against its own expectation) at the image's
    /// automatic exposure; None before 2 passes.
    pub noise_psnr_db: Option<f64>,
    /// `image`'s automatic exposure (emitters seen directly left out where the mask fits
    /// it), metered here on the worker so that the UI thread need not per image.
    pub auto_exposure: f32,
    /// Every pixel's spectrum, when the user asked to keep them.
    pub spectra: Option<Arc<crate::output::SpectralImage>>,
    /// The denoised display image, when the user asked for it.
    pub denoised: Option<Arc<Image>>,
}

/// Nearest-neighbour upscale of a preview to the full image size.
fn upscale(img: &Image, width: u32, height: u32) -> Image {
    let mut pixels = Vec::with_capacity((width * height) as usize);
    for y in 0..height {
        let sy = (y as u64 * img.height as u64 / height as u64) as u32;
        for x in 0..width {
            let sx = (x as u64 * img.width as u64 / width as u64) as u32;
            pixels.push(img.get(sx, sy));
        }
    }
    Image {
        width,
        height,
        pixels,
    }
}

/// Shared state between the worker and the UI.
#[derive(Default)]
struct Shared {
    snapshot: Mutex<Option<Snapshot>>,
    error: Mutex<Option<(u64, String)>>,
    /// The render pool's threads and whether they run below the UI's priority, once the
    /// pool is up.
    pool: Mutex<Option<PoolInfo>>,
}

/// How the worker renders: its thread count and priority.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PoolInfo {
    pub threads: usize,
    /// The render threads run at nice [`WORKER_NICE`], below the UI thread.
    pub below_ui: bool,
}

pub struct Worker {
    tx: Sender<Command>,
    shared: Arc<Shared>,
    /// Cancel flag of the session currently running (swapped at each start).
    cancel: Arc<Mutex<Arc<AtomicBool>>>,
    generation: Arc<AtomicU64>,
    thread: Option<JoinHandle<()>>,
}

impl Worker {
    /// Starts the worker thread; `repaint` is called whenever there is news.
    pub fn spawn(repaint: impl Fn() + Send + Sync + 'static) -> Self {
        let (tx, rx) = mpsc::channel();
        let shared = Arc::new(Shared::default());
        let cancel = Arc::new(Mutex::new(Arc::new(AtomicBool::new(false))));
        let generation = Arc::new(AtomicU64::new(0));
        let thread = {
            let shared = shared.clone();
            let cancel = cancel.clone();
            let generation = generation.clone();
            std::thread::Builder::new()
                .name("prismap-render".into())
                .spawn(move || run(rx, shared, cancel, generation, repaint))
                .ok()
        };
        Self {
            tx,
            shared,
            cancel,
            generation,
            thread,
        }
    }

    /// Starts a new render; returns its generation.
    pub fn start(&self, scene: Arc<Scene>, settings: RenderSettings) -> u64 {
        let generation = self.generation.fetch_add(1, Ordering::SeqCst) + 1;
        // Stop the running pass now; the worker picks the new job up right after.
        self.cancel
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .store(true, Ordering::Relaxed);
        let _ = self.tx.send(Command::Start {
            scene,
            settings,
            generation,
        });
        generation
    }

    pub fn send(&self, c: Command) {
        let _ = self.tx.send(c);
    }

    /// The newest snapshot, if it belongs to the current generation.
    pub fn latest(&self) -> Option<Snapshot> {
        let g = self.generation.load(Ordering::SeqCst);
        self.shared
            .snapshot
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .as_ref()
            .filter(|s| s.generation == g)
            .cloned()
    }

    /// An error of the current generation (a failed or panicking pass).
    pub fn error(&self) -> Option<String> {
        let g = self.generation.load(Ordering::SeqCst);
        self.shared
            .error
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .as_ref()
            .filter(|(eg, _)| *eg == g)
            .map(|(_, e)| e.clone())
    }

    pub fn generation(&self) -> u64 {
        self.generation.load(Ordering::SeqCst)
    }

    /// The render pool's threads and priority (None until the worker has started it).
    pub fn pool(&self) -> Option<PoolInfo> {
        *self
            .shared
            .pool
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.cancel
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .store(true, Ordering::Relaxed);
        // Closing the channel ends the loop.
        let (tx, _) = mpsc::channel();
        drop(std::mem::replace(&mut self.tx, tx));
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

struct Job {
    session: RenderSession,
    generation: u64,
    started: Instant,
}

/// Nice value of the render threads: well below the UI thread's 0, so that the
/// scheduler runs the UI first whenever it has a frame to build.
pub const WORKER_NICE: i32 = 10;

/// Lowers the calling thread's scheduling priority to [`WORKER_NICE`] (Linux, where a
/// thread has its own nice value); false where that is not possible.
pub fn lower_thread_priority() -> bool {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: gettid and setpriority take plain integers and touch no memory.
        let tid = unsafe { libc::gettid() } as libc::id_t;
        let current = unsafe { libc::getpriority(libc::PRIO_PROCESS, tid) };
        unsafe { libc::setpriority(libc::PRIO_PROCESS, tid, WORKER_NICE.max(current)) == 0 }
    }
    #[cfg(not(target_os = "linux"))]
    {
        false
    }
}

/// Render threads for `cores` cores: all of them when they run below the UI's priority,
/// else all but one.
pub fn worker_threads(cores: usize, lowered: bool) -> usize {
    if lowered {
        cores.max(1)
    } else {
        cores.saturating_sub(1).max(1)
    }
}

fn run(
    rx: Receiver<Command>,
    shared: Arc<Shared>,
    cancel_slot: Arc<Mutex<Arc<AtomicBool>>>,
    current: Arc<AtomicU64>,
    repaint: impl Fn() + Sync,
) {
    // Every core renders, at a lower priority than the UI thread, so a frame is never
    // queued behind a pass. Where a thread's priority cannot be lowered, one core is
    // left to the UI instead.
    let lowered = lower_thread_priority();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    // PRISMAP_VIEWER_THREADS=N overrides the count (for measuring the viewer).
    let max = crate::render::settings::MAX_THREADS;
    let threads = match std::env::var("PRISMAP_VIEWER_THREADS") {
        Ok(v) => match v.trim().parse::<usize>() {
            Ok(n) if (1..=max).contains(&n) => n,
            _ => {
                eprintln!(
                    "warning: PRISMAP_VIEWER_THREADS={v:?} is not a thread count from 1 to {max}; using {}",
                    worker_threads(cores, lowered)
                );
                worker_threads(cores, lowered)
            }
        },
        Err(_) => worker_threads(cores, lowered),
    };
    let pool = match rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("prismap-pass-{i}"))
        .start_handler(move |_| {
            if lowered {
                lower_thread_priority();
            }
        })
        .build()
    {
        Ok(p) => {
            *shared.pool.lock().unwrap_or_else(PoisonError::into_inner) = Some(PoolInfo {
                threads,
                below_ui: lowered,
            });
            p
        }
        Err(e) => {
            *shared.error.lock().unwrap_or_else(PoisonError::into_inner) = Some((
                current.load(Ordering::SeqCst),
                format!("cannot start worker threads: {e}"),
            ));
            repaint();
            return;
        }
    };
    // Behind a mutex: the pass observer reads it from inside the pool's `install`.
    let rx = Mutex::new(rx);
    let recv = || rx.lock().unwrap_or_else(PoisonError::into_inner);
    let mut job: Option<Job> = None;
    let mut paused = false;
    let mut probes: Vec<(u32, u32)> = Vec::new();
    let mut stop_after: Option<u64> = None;
    let mut keep_spectra = false;
    let mut denoise = false;
    // Commands that arrived during a run: the run stops after its pass to handle them.
    let mut inbox: Vec<Command> = Vec::new();
    loop {
        // Take every pending command; block only when there is nothing to render.
        let idle = paused
            || job.is_none()
            || stop_after
                .is_some_and(|n| job.as_ref().is_some_and(|j| j.session.stats().passes >= n));
        let first = if idle {
            match recv().recv_timeout(Duration::from_millis(200)) {
                Ok(c) => Some(c),
                Err(mpsc::RecvTimeoutError::Timeout) => None,
                Err(mpsc::RecvTimeoutError::Disconnected) => return,
            }
        } else {
            match recv().try_recv() {
                Ok(c) => Some(c),
                Err(TryRecvError::Empty) => None,
                Err(TryRecvError::Disconnected) => return,
            }
        };
        let mut pending: Vec<Command> = std::mem::take(&mut inbox);
        pending.extend(first);
        while let Ok(c) = recv().try_recv() {
            pending.push(c);
        }
        for c in pending {
            match c {
                Command::Start {
                    scene,
                    settings,
                    generation,
                } => {
                    if generation != current.load(Ordering::SeqCst) {
                        continue; // superseded before it started
                    }
                    let started = Instant::now();
                    let preview_settings = settings.quick_preview_of();
                    match pool.install(|| RenderSession::new(&scene, settings)) {
                        Ok(mut session) => {
                            // The quick first image, on the same (already projected) scene.
                            let mut quick = RenderSession::with_spectral_scene(
                                session.scene().clone(),
                                preview_settings,
                            );
                            *cancel_slot.lock().unwrap_or_else(PoisonError::into_inner) =
                                quick.cancel_flag();
                            let quick_result =
                                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                                    pool.install(|| quick.run_pass())
                                }));
                            if matches!(quick_result, Ok(Ok(())))
                                && generation == current.load(Ordering::SeqCst)
                            {
                                let full = session.settings();
                                let mut snap = snapshot(&quick, generation, started, false);
                                snap.image =
                                    Arc::new(upscale(&quick.image(), full.width, full.height));
                                snap.auto_exposure =
                                    metered_exposure(&snap.image, &snap.emitter_pixels);
                                snap.preview = true;
                                *shared
                                    .snapshot
                                    .lock()
                                    .unwrap_or_else(PoisonError::into_inner) = Some(snap);
                                repaint();
                            }
                            session.set_probes(&probes);
                            if session.scene().grid.smits().is_some() {
                                session.keep_spectra(keep_spectra);
                            }
                            *cancel_slot.lock().unwrap_or_else(PoisonError::into_inner) =
                                session.cancel_flag();
                            job = Some(Job {
                                session,
                                generation,
                                started,
                            });
                        }
                        Err(e) => {
                            job = None;
                            *shared.error.lock().unwrap_or_else(PoisonError::into_inner) =
                                Some((generation, e.to_string()));
                            repaint();
                        }
                    }
                }
                Command::Pause(p) => paused = p,
                Command::Probes(p) => {
                    probes = p;
                    if let Some(j) = &mut job {
                        j.session.set_probes(&probes);
                    }
                }
                Command::StopAfter(n) => stop_after = n,
                Command::Denoise(on) => {
                    denoise = on;
                    // Show it now on the image already rendered.
                    if let Some(j) = &job
                        && j.session.stats().passes > 0
                        && j.generation == current.load(Ordering::SeqCst)
                    {
                        let snap =
                            pool.install(|| snapshot(&j.session, j.generation, j.started, denoise));
                        *shared
                            .snapshot
                            .lock()
                            .unwrap_or_else(PoisonError::into_inner) = Some(snap);
                        repaint();
                    }
                }
                Command::KeepSpectra(on) => {
                    keep_spectra = on;
                    if let Some(j) = &mut job
                        && j.session.scene().grid.smits().is_some()
                    {
                        j.session.keep_spectra(on);
                    }
                }
            }
        }
        let Some(j) = &mut job else { continue };
        if paused || stop_after.is_some_and(|n| j.session.stats().passes >= n) {
            continue;
        }
        if j.generation != current.load(Ordering::SeqCst) {
            continue; // a newer Start is on its way
        }
        // Passes until a command arrives (or the pass limit); a panic inside is caught and
        // shown, and the next change restarts.
        let stop = Stop {
            passes: stop_after.map(|n| n.saturating_sub(j.session.stats().passes)),
            seconds: None,
        };
        let (generation, started) = (j.generation, j.started);
        // The observer runs inside the pool's `install`, which needs it to be Sync.
        let inbox_shared = Mutex::new(&mut inbox);
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            pool.install(|| {
                j.session.run(stop, None, &mut |s, _| {
                    if generation == current.load(Ordering::SeqCst) {
                        *shared
                            .snapshot
                            .lock()
                            .unwrap_or_else(PoisonError::into_inner) =
                            Some(snapshot(s, generation, started, denoise));
                        repaint();
                    }
                    let next = rx.lock().unwrap_or_else(PoisonError::into_inner).try_recv();
                    match next {
                        Ok(c) => {
                            inbox_shared
                                .lock()
                                .unwrap_or_else(PoisonError::into_inner)
                                .push(c);
                            Flow::Stop
                        }
                        Err(TryRecvError::Empty) => Flow::Continue,
                        Err(TryRecvError::Disconnected) => Flow::Stop,
                    }
                })
            })
        }));
        match result {
            Ok(Ok(_)) | Ok(Err(RenderError::Cancelled)) => {}
            Ok(Err(e)) => {
                *shared.error.lock().unwrap_or_else(PoisonError::into_inner) =
                    Some((generation, e.to_string()));
                job = None;
                repaint();
            }
            Err(panic) => {
                let msg = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_else(|| "unknown panic".to_string());
                *shared.error.lock().unwrap_or_else(PoisonError::into_inner) =
                    Some((generation, format!("the render pass failed: {msg}")));
                job = None;
                repaint();
            }
        }
    }
}

/// The automatic exposure of `image`, leaving out the pixels `emitters` marks when the
/// mask is the image's size.
fn metered_exposure(image: &Image, emitters: &[bool]) -> f32 {
    if emitters.len() == image.pixels.len() {
        crate::output::auto_exposure_skipping(image, emitters)
    } else {
        crate::output::auto_exposure(image)
    }
}

fn snapshot(s: &RenderSession, generation: u64, started: Instant, denoise: bool) -> Snapshot {
    let image = Arc::new(s.image());
    let exposure = metered_exposure(&image, &s.emitter_pixels());
    Snapshot {
        generation,
        noise_psnr_db: s.film().noise_psnr(exposure).filter(|v| v.is_finite()),
        auto_exposure: exposure,
        image,
        stats: s.stats().clone(),
        memory: s.memory(),
        bytes_per_photon: s.bytes_per_photon(),
        bins: s.scene().bins(),
        wavelengths: s.scene().grid.centers().to_vec(),
        srgb_weights: s.scene().grid.srgb_weights().to_vec(),
        probes: s.probes().to_vec(),
        skipped: s.skipped(),
        warnings: s.scene().warnings.clone(),
        emitter_pixels: s.emitter_pixels(),
        since_start: started.elapsed().as_secs_f64(),
        preview: false,
        denoised: denoise.then(|| {
            let (w, h) = (s.settings().width, s.settings().height);
            Arc::new(s.denoised(prismap_engine::render::DenoiseParams::for_size(w, h)))
        }),
        spectra: s.spectral_film().map(|f| {
            Arc::new(crate::output::SpectralImage {
                width: f.width(),
                height: f.height(),
                wavelengths: s.scene().grid.centers().to_vec(),
                values: f.develop(),
            })
        }),
    }
}
