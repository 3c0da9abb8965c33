//! The interactive viewer (eframe/egui). The UI owns no rendering state: it sends
//! commands to the [`worker::Worker`] and shows the newest snapshot it publishes.
//!
//! Split by concern: this file holds the state and the logic (commands, restarts,
//! capture), `panels.rs` draws the controls, statistics, memory and probe panels,
//! `orbit.rs` turns mouse drags into camera moves.

pub mod compare;
mod orbit;
pub mod panels;
pub use panels::format_bytes;
pub mod worker;
pub use worker::{PoolInfo, WORKER_NICE};

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use crate::photon::Storage;
use crate::render::{Image, RenderSettings};
use crate::scene::{self, Scene};
use orbit::Orbit;
use worker::{Command, Snapshot, Worker};

/// How soon after the worker's news the window repaints: not zero, which egui answers
/// with two frames instead of one.
const WAKE_DELAY: std::time::Duration = std::time::Duration::from_millis(1);

/// The scripted capture's poll for its pass count: only a safety net, since the worker's
/// news wakes the frame that checks it.
const CAPTURE_POLL: std::time::Duration = std::time::Duration::from_millis(500);

pub use crate::output::ToneMap;

/// What a panel asks the viewer to do. Panels push actions while they draw; the viewer
/// applies them after the frame (the egui demo app's and rerun's habit), so drawing never
/// changes the state it is drawing from.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    Open(SceneSource),
    OpenDialog,
    SetPaused(bool),
    /// Restart refinement with the current settings and view.
    Restart,
    /// Back to the scene's own camera.
    ResetView,
    /// Save the image as "png" or "exr".
    Save(&'static str),
    SetProbe((u32, u32)),
    PinProbe,
    Unpin((u32, u32)),
    /// Export the probe at this pixel as CSV.
    ExportProbe((u32, u32)),
    /// Freeze the shown image and probe spectra as compare mode's "A".
    Freeze,
    /// Leave compare mode.
    Unfreeze,
}

/// A request to save a screenshot of the window after some passes, then quit.
#[derive(Clone, Debug)]
pub struct Capture {
    pub path: PathBuf,
    pub after_passes: u64,
    /// Compare mode first: freeze the image as "A" after the passes, switch to this
    /// storage, render as many passes again, then take the screenshot.
    pub compare_with: Option<Storage>,
}

/// Where the scene came from, for the scene list.
#[derive(Clone, Debug, PartialEq)]
pub enum SceneSource {
    Builtin(String),
    File(PathBuf),
}

impl SceneSource {
    pub fn label(&self) -> String {
        match self {
            SceneSource::Builtin(n) => format!("{n} (built in)"),
            SceneSource::File(p) => p.display().to_string(),
        }
    }

    fn load(&self) -> Result<Scene, scene::SceneError> {
        match self {
            SceneSource::Builtin(n) => scene::load_builtin(n),
            SceneSource::File(p) => scene::load(p),
        }
    }
}

/// Memory readings over time, for the history plot.
#[derive(Clone, Copy, Debug)]
pub struct MemorySample {
    pub seconds: f64,
    pub photon_maps: f64,
    pub resident: f64,
}

pub struct ViewerApp {
    worker: Worker,
    source: SceneSource,
    scene: Arc<Scene>,
    orbit: Orbit,
    pub settings: RenderSettings,
    pub auto_bins: bool,
    auto_reason: String,
    /// Actions the panels asked for during this frame.
    actions: Vec<Action>,
    pub exposure: f32,
    /// Exposure follows each new image ([`crate::output::auto_exposure`]) until the user
    /// sets one.
    pub auto_exposure: bool,
    pub tone: ToneMap,
    pub paused: bool,
    texture: Option<egui::TextureHandle>,
    shown: Option<(u64, bool, u64, bool)>,
    shown_tone: (f32, ToneMap),
    pub snapshot: Option<Snapshot>,
    /// The probed pixel and up to three pinned ones.
    pub probe: Option<(u32, u32)>,
    pub pinned: Vec<(u32, u32)>,
    /// Compare mode's frozen "A" (None: not comparing), how it is shown, and how the live
    /// image agrees with it.
    pub compare: Option<compare::Frozen>,
    pub compare_view: compare::CompareView,
    /// Where A gives way to B, as a fraction of the image's width.
    pub compare_split: f32,
    /// The difference view's gain.
    pub compare_gain: f32,
    pub agreement: Option<compare::Agreement>,
    compare_texture: Option<egui::TextureHandle>,
    memory_history: VecDeque<MemorySample>,
    pub status: String,
    /// Whether `status` reports a failure (shown in red).
    pub status_is_error: bool,
    pub save_dir: PathBuf,
    /// Whether the worker keeps every pixel's spectrum (for "Save spectral EXR").
    pub keep_spectra: bool,
    /// Whether the image shown is the denoised view (display only).
    pub denoise_view: bool,
    /// Whether the keyboard help is open (F1 or ?).
    pub show_help: bool,
    /// The noise level (PSNR of the "noise left" estimate, dB) that counts as converged.
    pub target_db: f64,
    /// Pause when the target is reached.
    pub stop_at_target: bool,
    /// When the current render first reached the target: (generation, passes, seconds).
    pub target_reached: Option<(u64, u64, f64)>,
    capture: Option<Capture>,
    capture_done: Arc<AtomicBool>,
    capture_requested: bool,
    capture_error: Arc<Mutex<Option<String>>>,
    scene_files: Vec<PathBuf>,
    path_input: String,
    /// An open-file dialog running on its own thread (the UI never waits on it).
    file_dialog: Option<std::sync::mpsc::Receiver<Option<PathBuf>>>,
    started: Instant,
    /// When the last setting changed, and how long until its first image arrived.
    changed_at: Instant,
    pub first_image_latency: Option<f64>,
    pub last_restart_generation: u64,
}

impl ViewerApp {
    /// A viewer on `source`, rendering with `settings`; `repaint` wakes the UI.
    pub fn new(
        ctx: &egui::Context,
        source: SceneSource,
        settings: RenderSettings,
        capture: Option<Capture>,
    ) -> Self {
        let repaint_ctx = ctx.clone();
        // One frame for each piece of news. `request_repaint` paints two (egui's margin for
        // responses that arrive a frame late); a new image needs only the frame that uploads
        // it, and a software-rendered window spends a third of the CPU on frames otherwise.
        let worker = Worker::spawn(move || repaint_ctx.request_repaint_after(WAKE_DELAY));
        let (scene, status) = match source.load() {
            Ok(s) => (s, String::new()),
            Err(e) => (
                scene::load_builtin(scene::DEFAULT_SCENE).expect("the built-in scene loads"),
                format!("{e}; showing the built-in scene"),
            ),
        };
        let source = if status.is_empty() {
            source
        } else {
            SceneSource::Builtin(scene::DEFAULT_SCENE.to_string())
        };
        let mut app = Self {
            worker,
            orbit: Orbit::new(&scene),
            scene: Arc::new(scene),
            source,
            settings,
            auto_bins: false,
            auto_reason: String::new(),
            actions: Vec::new(),
            exposure: 1.0,
            auto_exposure: true,
            tone: ToneMap::Clamp,
            paused: false,
            texture: None,
            shown: None,
            shown_tone: (1.0, ToneMap::Clamp),
            snapshot: None,
            probe: None,
            pinned: Vec::new(),
            compare: None,
            compare_view: compare::CompareView::Split,
            compare_split: 0.5,
            compare_gain: 8.0,
            agreement: None,
            compare_texture: None,
            memory_history: VecDeque::new(),
            status_is_error: !status.is_empty(),
            status,
            save_dir: default_save_dir(),
            keep_spectra: false,
            denoise_view: false,
            show_help: false,
            target_db: DEFAULT_TARGET_DB,
            stop_at_target: false,
            target_reached: None,
            capture_requested: false,
            capture,
            capture_done: Arc::new(AtomicBool::new(false)),
            capture_error: Arc::new(Mutex::new(None)),
            scene_files: list_scene_files(Path::new("scenes")),
            path_input: String::new(),
            file_dialog: None,
            started: Instant::now(),
            changed_at: Instant::now(),
            first_image_latency: None,
            last_restart_generation: 0,
        };
        if let Some(c) = &app.capture {
            app.worker.send(Command::StopAfter(Some(c.after_passes)));
        }
        app.restart();
        app
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    pub fn source(&self) -> &SceneSource {
        &self.source
    }

    /// Marks the bin count as the scene's automatic choice (it already is: the caller set
    /// it from [`Scene::auto_bins`]), so the panel shows "auto" with its reason and a new scene
    /// picks its own.
    pub fn keep_auto_bins(&mut self) {
        let (bins, why) = self.scene.auto_bins();
        if bins != self.settings.bins {
            self.settings.bins = bins;
            self.auto_bins = true;
            self.restart();
        }
        self.auto_bins = true;
        self.auto_reason = why;
    }

    /// Restarts rendering with the current scene, camera and settings.
    pub fn restart(&mut self) {
        if self.auto_bins {
            let (bins, why) = self.scene.auto_bins();
            self.settings.bins = bins;
            self.auto_reason = why;
        }
        let mut scene = (*self.scene).clone();
        scene.camera = self.orbit.camera();
        self.last_restart_generation = self.worker.start(Arc::new(scene), self.settings.clone());
        self.send_probes();
        self.changed_at = Instant::now();
        self.first_image_latency = None;
        self.snapshot = None;
    }

    fn send_probes(&self) {
        let mut p: Vec<(u32, u32)> = self.pinned.clone();
        if let Some(c) = self.probe
            && !p.contains(&c)
        {
            p.push(c);
        }
        self.worker.send(Command::Probes(p));
    }

    /// Opens another scene; on failure keeps the current one and says why.
    pub fn open(&mut self, source: SceneSource) {
        match source.load() {
            Ok(s) => {
                self.orbit = Orbit::new(&s);
                // The image takes the new camera's shape, at the same height.
                (self.settings.width, self.settings.height) = s.image_size(self.settings.height);
                self.scene = Arc::new(s);
                self.source = source;
                self.probe = None;
                self.pinned.clear();
                self.note(format!("opened {}", self.source.label()));
                self.restart();
            }
            Err(e) => self.fail(e.to_string()),
        }
    }

    /// An image size of `height` rows in the scene camera's shape.
    pub fn scene_image_size(&self, height: u32) -> (u32, u32) {
        self.scene.image_size(height)
    }

    /// Stop refining after `passes` passes (None: refine until paused).
    pub fn stop_after(&self, passes: Option<u64>) {
        self.worker.send(Command::StopAfter(passes));
    }

    /// Opens the system's file dialog on a thread; the choice is picked up by `ui`.
    pub fn open_dialog(&mut self, ctx: &egui::Context) {
        if self.file_dialog.is_some() {
            return;
        }
        let (tx, rx) = std::sync::mpsc::channel();
        let ctx = ctx.clone();
        let spawned = std::thread::Builder::new()
            .name("prismap-open".into())
            .spawn(move || {
                let choice = rfd::FileDialog::new()
                    .add_filter("glTF scene", &["gltf", "glb"])
                    .set_directory(std::env::current_dir().unwrap_or_default())
                    .pick_file();
                let _ = tx.send(choice);
                ctx.request_repaint();
            });
        match spawned {
            Ok(_) => self.file_dialog = Some(rx),
            Err(e) => self.fail(format!("cannot open a file dialog: {e}")),
        }
    }

    fn poll_dialog(&mut self) {
        let Some(rx) = &self.file_dialog else { return };
        match rx.try_recv() {
            Ok(Some(path)) => {
                self.file_dialog = None;
                self.open(SceneSource::File(path));
            }
            Ok(None) => {
                self.file_dialog = None;
                self.note(
                    "no file chosen (no file dialog on this system? type a path or drop a file)",
                );
            }
            Err(std::sync::mpsc::TryRecvError::Empty) => {}
            Err(std::sync::mpsc::TryRecvError::Disconnected) => self.file_dialog = None,
        }
    }

    pub fn set_paused(&mut self, paused: bool) {
        self.paused = paused;
        self.worker.send(Command::Pause(paused));
    }

    /// Probes pixel (x, y): its spectrum is kept from now on.
    pub fn set_probe(&mut self, pixel: (u32, u32)) {
        self.probe = Some(pixel);
        self.send_probes();
    }

    pub fn pin_probe(&mut self) {
        if let Some(p) = self.probe
            && !self.pinned.contains(&p)
        {
            if self.pinned.len() == 3 {
                self.pinned.remove(0);
            }
            self.pinned.push(p);
            self.send_probes();
        }
    }

    pub fn unpin(&mut self, p: (u32, u32)) {
        self.pinned.retain(|q| *q != p);
        self.send_probes();
    }

    /// The render worker's threads and priority (None until its pool is up).
    pub fn worker_pool(&self) -> Option<PoolInfo> {
        self.worker.pool()
    }

    /// Error of the current render, if it failed.
    pub fn render_error(&self) -> Option<String> {
        self.worker.error()
    }

    /// Shows the denoised view (or the raw image again). Display only: saves, probes and
    /// every error figure keep reading the raw film.
    pub fn set_denoise_view(&mut self, on: bool) {
        self.denoise_view = on;
        self.worker.send(worker::Command::Denoise(on));
        self.shown_tone = (f32::NAN, self.tone); // re-upload what is shown
    }

    /// Keeps (or frees) every pixel's spectrum from the next pass on.
    pub fn set_keep_spectra(&mut self, on: bool) {
        self.keep_spectra = on;
        self.worker.send(worker::Command::KeepSpectra(on));
    }

    /// Saves the current image as PNG (display values), EXR (linear) or spectral EXR in
    /// `save_dir`.
    pub fn save(&mut self, ext: &str) -> Result<PathBuf, String> {
        let snap = self.snapshot.as_ref().ok_or("nothing rendered yet")?;
        std::fs::create_dir_all(&self.save_dir)
            .map_err(|e| format!("{}: {e}", self.save_dir.display()))?;
        let stem = match &self.source {
            SceneSource::Builtin(n) => n.clone(),
            SceneSource::File(p) => p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
        };
        let name = format!(
            "{stem}-{}-{}-{}p.{ext}",
            if self.settings.storage == Storage::Rgb {
                "rgb".to_string()
            } else {
                format!("{}bins", snap.bins)
            },
            self.settings.storage.name(),
            snap.stats.passes
        );
        let path = self.save_dir.join(name);
        let result = match ext {
            "png" => {
                let bytes = tone_map(&snap.image, self.exposure, self.tone);
                crate::output::write_png8(&path, &bytes, snap.image.width, snap.image.height)
            }
            "spectral.exr" => match &snap.spectra {
                Some(spectra) => crate::output::write_spectral_exr(&path, spectra, &snap.image),
                None => {
                    return Err("tick \"Keep spectra\" and let a pass finish first".to_string());
                }
            },
            _ => crate::output::write_exr(&path, &snap.image),
        };
        result.map_err(|e| e.to_string())?;
        self.note(format!("saved {}", path.display()));
        Ok(path)
    }

    /// Pulls the newest snapshot and uploads it to the texture when it is new.
    fn poll(&mut self, ctx: &egui::Context) {
        if let Some(s) = self.worker.latest() {
            // The quick preview and the first full pass both count one pass: `preview` tells
            // them apart, or the first full pass would never be shown.
            let key = (
                s.generation,
                s.preview,
                s.stats.passes,
                s.denoised.is_some(),
            );
            if self.shown != Some(key) {
                if self.first_image_latency.is_none() {
                    self.first_image_latency = Some(self.changed_at.elapsed().as_secs_f64());
                }
                self.memory_history.push_back(MemorySample {
                    seconds: self.started.elapsed().as_secs_f64(),
                    photon_maps: s.memory.photon_maps as f64,
                    resident: crate::metrics::resident_bytes().unwrap_or(0) as f64,
                });
                while self.memory_history.len() > 600 {
                    self.memory_history.pop_front();
                }
                self.shown = Some(key);
                if self.auto_exposure {
                    self.exposure = s.auto_exposure;
                }
                self.check_target(&s);
                self.snapshot = Some(s);
                self.upload(ctx);
            }
        }
        if self.shown_tone != (self.exposure, self.tone) && self.snapshot.is_some() {
            self.upload(ctx);
        }
    }

    /// Marks the pass where the noise estimate first reaches the target (and pauses, if
    /// asked). A new render (a new generation) starts unmarked.
    fn check_target(&mut self, s: &worker::Snapshot) {
        if self
            .target_reached
            .is_some_and(|(g, _, _)| g != s.generation)
        {
            self.target_reached = None;
        }
        let reached = !s.preview && s.noise_psnr_db.is_some_and(|db| db >= self.target_db);
        if reached && self.target_reached.is_none() {
            self.target_reached = Some((s.generation, s.stats.passes, s.since_start));
            if self.stop_at_target && !self.paused {
                self.set_paused(true);
                self.note(format!(
                    "target {:.0} dB reached after {} passes ({:.1} s): paused (space resumes)",
                    self.target_db, s.stats.passes, s.since_start
                ));
            }
        }
    }

    /// Whether the shown render has reached the noise target.
    pub fn target_is_reached(&self) -> bool {
        match (&self.target_reached, &self.snapshot) {
            (Some((g, _, _)), Some(s)) => *g == s.generation,
            _ => false,
        }
    }

    fn upload(&mut self, ctx: &egui::Context) {
        let Some(s) = &self.snapshot else { return };
        let shown = match (&s.denoised, self.denoise_view) {
            (Some(d), true) => d,
            _ => &s.image,
        };
        let bytes = tone_map(shown, self.exposure, self.tone);
        let img = egui::ColorImage::from_rgb([shown.width as usize, shown.height as usize], &bytes);
        match &mut self.texture {
            Some(t) => t.set(img, egui::TextureOptions::NEAREST),
            None => {
                self.texture = Some(ctx.load_texture("render", img, egui::TextureOptions::NEAREST))
            }
        }
        self.shown_tone = (self.exposure, self.tone);
        self.update_compare(ctx);
    }

    /// Compare mode's texture (A as displayed, or the difference) and agreement, after a
    /// new image, exposure, view or gain.
    pub fn update_compare(&mut self, ctx: &egui::Context) {
        let (Some(a), Some(s)) = (&self.compare, &self.snapshot) else {
            self.agreement = None;
            return;
        };
        let (w, h) = (a.image.width as usize, a.image.height as usize);
        self.agreement = compare::agreement(&a.image, &s.image, self.exposure);
        let bytes = match self.compare_view {
            compare::CompareView::Split => Some(tone_map(&a.image, self.exposure, self.tone)),
            compare::CompareView::Difference => {
                compare::difference_display(&a.image, &s.image, self.exposure, self.compare_gain)
            }
        };
        let Some(bytes) = bytes else {
            self.compare_texture = None;
            return;
        };
        let img = egui::ColorImage::from_rgb([w, h], &bytes);
        match &mut self.compare_texture {
            Some(t) => t.set(img, egui::TextureOptions::NEAREST),
            None => {
                self.compare_texture =
                    Some(ctx.load_texture("compare", img, egui::TextureOptions::NEAREST))
            }
        }
    }

    pub fn compare_texture(&self) -> Option<&egui::TextureHandle> {
        self.compare_texture.as_ref()
    }

    /// Freezes the shown image and its probes' spectra as "A".
    pub fn freeze(&mut self) {
        let Some(s) = &self.snapshot else {
            self.note("nothing to freeze yet: wait for the first pass");
            return;
        };
        let storage = self.settings.storage;
        let bins = if storage == Storage::Rgb {
            String::new()
        } else {
            format!(", {} bins", s.bins)
        };
        self.compare = Some(compare::Frozen {
            label: format!("{}{bins}, {} passes", storage.name(), s.stats.passes),
            image: s.image.clone(),
            probes: s
                .probes
                .iter()
                .map(|p| compare::FrozenProbe {
                    pixel: (p.x, p.y),
                    wavelengths: s.wavelengths.clone(),
                    spectrum: p.mean(),
                })
                .collect(),
        });
    }

    /// The scripted capture: screenshot once enough passes are shown, then close.
    fn drive_capture(&mut self, ctx: &egui::Context) {
        let Some(c) = &self.capture else { return };
        if self.capture_done.load(Ordering::SeqCst) {
            if let Some(e) = self
                .capture_error
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .take()
            {
                eprintln!("error: {e}");
                std::process::exit(1);
            }
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            return;
        }
        let passes = self.snapshot.as_ref().map_or(0, |s| s.stats.passes);
        let current = self
            .snapshot
            .as_ref()
            .is_some_and(|s| s.generation == self.last_restart_generation && !s.preview);
        if let Some(storage) = c.compare_with
            && self.compare.is_none()
        {
            if current && passes >= c.after_passes {
                self.freeze();
                self.settings.storage = storage;
                self.restart();
            }
            ctx.request_repaint_after(CAPTURE_POLL);
            return;
        }
        if !self.capture_requested && current && passes >= c.after_passes {
            self.capture_requested = true;
            let path = c.path.clone();
            let done = self.capture_done.clone();
            let err = self.capture_error.clone();
            let ctx2 = ctx.clone();
            ctx.request_screenshot(move |img| {
                let [w, h] = img.size;
                let rgba: Vec<u8> = img.pixels.iter().flat_map(|c| c.to_array()).collect();
                let r = crate::output::write_png8(&path, &rgba, w as u32, h as u32);
                if let Err(e) = r {
                    *err.lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(e.to_string());
                }
                done.store(true, Ordering::SeqCst);
                ctx2.request_repaint();
            });
            ctx.request_repaint();
            return;
        }
        // The worker's news repaints, and each new pass is checked in its frame; this slow
        // poll is only a safety net, so that a software-rendered window does not spend a
        // core on frames nobody needs.
        ctx.request_repaint_after(CAPTURE_POLL);
    }

    /// The whole UI for one frame.
    pub fn ui(&mut self, ui: &mut egui::Ui) {
        let ctx = ui.ctx().clone();
        self.poll(&ctx);
        self.poll_dialog();
        // Scenes dropped on the window.
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .collect()
        });
        if let Some(p) = dropped.into_iter().find(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| e.eq_ignore_ascii_case("gltf") || e.eq_ignore_ascii_case("glb"))
        }) {
            self.open(SceneSource::File(p));
        }
        self.shortcuts(&ctx);
        panels::controls(self, ui);
        panels::statistics(self, ui);
        panels::probe(self, ui);
        panels::image(self, ui);
        panels::help(self, &ctx);
        self.apply_actions(&ctx);
        self.drive_capture(&ctx);
    }

    /// Keyboard shortcuts (when no text field has the keyboard): space pauses or resumes,
    /// R restarts, V resets the view, S saves a PNG, E an EXR, 1 / 2 / 3 switch to full /
    /// compact / RGB storage, A picks the bins automatically, F freezes "A" for compare
    /// mode (and leaves it), D shows the denoised view (or the raw image).
    fn shortcuts(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        use egui::Key;
        let pressed = |k: Key| ctx.input(|i| i.key_pressed(k) && i.modifiers.is_none());
        if pressed(Key::Space) {
            self.act(Action::SetPaused(!self.paused));
        }
        if pressed(Key::R) {
            self.act(Action::Restart);
        }
        if pressed(Key::V) {
            self.act(Action::ResetView);
        }
        if pressed(Key::S) {
            self.act(Action::Save("png"));
        }
        if pressed(Key::E) {
            self.act(Action::Save("exr"));
        }
        if pressed(Key::D) {
            self.set_denoise_view(!self.denoise_view);
        }
        if pressed(Key::F1)
            || ctx.input(|i| {
                i.events
                    .iter()
                    .any(|e| matches!(e, egui::Event::Text(t) if t == "?"))
            })
        {
            self.show_help = !self.show_help;
        }
        if pressed(Key::Escape) {
            self.show_help = false;
        }
        for (k, s) in [
            (Key::Num1, Storage::Full),
            (Key::Num2, Storage::Compact),
            (Key::Num3, Storage::Rgb),
            (Key::Num4, Storage::Packed),
            (Key::Num5, Storage::Spiked),
        ] {
            if pressed(k) && self.settings.storage != s {
                self.settings.storage = s;
                self.act(Action::Restart);
            }
        }
        if pressed(Key::F) {
            self.act(if self.compare.is_some() {
                Action::Unfreeze
            } else {
                Action::Freeze
            });
        }
        if pressed(Key::A) && !self.auto_bins {
            self.auto_bins = true;
            self.act(Action::Restart);
        }
    }

    /// Shows `text` in the status line.
    pub fn note(&mut self, text: impl Into<String>) {
        self.status = text.into();
        self.status_is_error = false;
    }

    /// Shows `text` in the status line as a failure (in red).
    pub fn fail(&mut self, text: impl Into<String>) {
        self.status = text.into();
        self.status_is_error = true;
    }

    /// Queues an action for the end of the frame.
    pub fn act(&mut self, action: Action) {
        if !self.actions.contains(&action) {
            self.actions.push(action);
        }
    }

    /// Applies the frame's actions in the order they were asked for.
    fn apply_actions(&mut self, ctx: &egui::Context) {
        for action in std::mem::take(&mut self.actions) {
            match action {
                Action::Open(source) => self.open(source),
                Action::OpenDialog => self.open_dialog(ctx),
                Action::SetPaused(p) => self.set_paused(p),
                Action::Restart => self.restart(),
                Action::ResetView => {
                    self.orbit = Orbit::new(&self.scene);
                    self.restart();
                }
                Action::Save(ext) => {
                    if let Err(e) = self.save(ext) {
                        self.fail(format!("save failed: {e}"));
                    }
                }
                Action::SetProbe(p) => self.set_probe(p),
                Action::PinProbe => self.pin_probe(),
                Action::Unpin(p) => self.unpin(p),
                Action::Freeze => {
                    self.freeze();
                    self.update_compare(ctx);
                }
                Action::Unfreeze => {
                    self.compare = None;
                    self.compare_texture = None;
                    self.agreement = None;
                }
                Action::ExportProbe(p) => match panels::export_probe_csv(self, p) {
                    Ok(path) => self.note(format!("saved {}", path.display())),
                    Err(e) => self.fail(format!("CSV export failed: {e}")),
                },
            }
        }
    }

    pub fn memory_history(&self) -> &VecDeque<MemorySample> {
        &self.memory_history
    }
}

impl eframe::App for ViewerApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        ViewerApp::ui(self, ui);
    }
}

/// Display bytes (RGB8, sRGB-encoded) of a linear image.
pub fn tone_map(image: &Image, exposure: f32, tone: ToneMap) -> Vec<u8> {
    crate::output::to_display8(image, exposure, tone)
}

/// The `.gltf`/`.glb` files in a folder and its subfolders one level down (fixtures,
/// Blender exports, samples), sorted, without the built-in scenes' own files (the list
/// shows those once, as built-ins).
pub fn list_scene_files(dir: &Path) -> Vec<PathBuf> {
    let builtin = |p: &Path| {
        p.parent() == Some(dir)
            && p.file_stem()
                .and_then(|s| s.to_str())
                .is_some_and(|s| scene::builtin(s).is_some())
    };
    let mut v: Vec<PathBuf> = scene_files_in(dir);
    if let Ok(rd) = std::fs::read_dir(dir) {
        for sub in rd
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_dir())
        {
            v.extend(scene_files_in(&sub));
        }
    }
    v.retain(|p| !builtin(p));
    v.sort();
    v
}

/// The `.gltf`/`.glb` files directly in `dir`.
fn scene_files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.extension()
                        .and_then(|e| e.to_str())
                        .is_some_and(|e| e == "gltf" || e == "glb")
                })
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Runs the viewer in a native window. Fails (without panicking) where no display is
/// available.
pub fn run_native(
    source: SceneSource,
    settings: RenderSettings,
    auto_bins: bool,
    capture: Option<Capture>,
    probe: Option<(u32, u32)>,
) -> Result<(), String> {
    if !display_available() {
        return Err("no display available (DISPLAY and WAYLAND_DISPLAY are unset): use `prismap render` for a headless render".to_string());
    }
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_inner_size([1280.0, 800.0])
            .with_title("prismap")
            .with_drag_and_drop(true),
        ..Default::default()
    };
    eframe::run_native(
        "prismap",
        options,
        Box::new(move |cc| {
            let mut app = ViewerApp::new(&cc.egui_ctx, source, settings, capture);
            if auto_bins {
                app.keep_auto_bins();
            }
            if let Some(p) = probe {
                app.set_probe(p);
            }
            Ok(Box::new(app))
        }),
    )
    .map_err(|e| {
        format!("cannot open the viewer window: {e}. Use `prismap render` for a headless render.")
    })
}

/// Whether a window can be opened (X11 or Wayland on Linux; assumed elsewhere).
pub fn display_available() -> bool {
    if cfg!(target_os = "linux") {
        std::env::var_os("DISPLAY").is_some_and(|v| !v.is_empty())
            || std::env::var_os("WAYLAND_DISPLAY").is_some_and(|v| !v.is_empty())
    } else {
        true
    }
}

/// The default noise target: 40 dB of "noise left" (the level at which the paper's
/// comparisons call an image clean).
pub const DEFAULT_TARGET_DB: f64 = 40.0;

/// Where the viewer saves: the user's pictures folder (`$XDG_PICTURES_DIR`, else
/// `~/Pictures` when it exists) in a `prismap` subfolder, else the working folder — never
/// the project's own `screenshots/`.
pub fn default_save_dir() -> PathBuf {
    let pictures = std::env::var_os("XDG_PICTURES_DIR")
        .map(PathBuf::from)
        .filter(|p| p.is_dir())
        .or_else(|| {
            std::env::var_os("HOME")
                .map(|h| PathBuf::from(h).join("Pictures"))
                .filter(|p| p.is_dir())
        });
    match pictures {
        Some(p) => p.join("prismap"),
        None => std::env::current_dir().unwrap_or_else(|_| PathBuf::from(".")),
    }
}
