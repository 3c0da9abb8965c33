//! Viewer responsiveness while rendering (issue #3): run with
//! `cargo bench --bench viewer` (PRISMAP_BENCH_SECONDS sets the length, default 30;
//! PRISMAP_BENCH_PHOTONS, _FG, _SAMPLES, _CAUSTIC_FACTOR, _BINS, _WIDTH and _HEIGHT the render settings;
//! without _BINS the bins are the viewer's own "auto" choice for the scene, as `prismap view`
//! runs it: 100 for the prism's dispersive glass).
//!
//! Drives the real `ViewerApp` headless through egui_kittest at ~60 Hz on the prism at
//! 512×512 and prints: UI frame time (CPU time to build the frame; GPU painting is not
//! included), time from a setting change to the first updated image, and passes per
//! second of the background worker.

/// The product's allocator (glibc's would add page faults the product does not have).
#[path = "../src/allocator.rs"]
mod allocator;

use std::time::{Duration, Instant};

use egui_kittest::Harness;
use prismap::app::{SceneSource, ViewerApp};
use prismap::photon::Storage;
use prismap::render::RenderSettings;

fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

fn main() {
    allocator::keep_freed_memory();
    let seconds: f64 = std::env::var("PRISMAP_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(30.0);
    // PRISMAP_BENCH_PHOTONS / _FG / _SAMPLES / _CAUSTIC_FACTOR / _BINS change the settings.
    let env = |name: &str, default: usize| {
        std::env::var(name)
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(default)
    };
    let defaults = RenderSettings::default();
    let bins: Option<usize> = std::env::var("PRISMAP_BENCH_BINS")
        .ok()
        .and_then(|s| s.parse().ok());
    let settings = RenderSettings {
        width: env("PRISMAP_BENCH_WIDTH", 512) as u32,
        height: env("PRISMAP_BENCH_HEIGHT", 512) as u32,
        photons_per_pass: env(
            "PRISMAP_BENCH_PHOTONS",
            RenderSettings::interactive().photons_per_pass,
        ),
        final_gather_rays: env("PRISMAP_BENCH_FG", defaults.final_gather_rays as usize) as u32,
        camera_samples: env("PRISMAP_BENCH_SAMPLES", defaults.camera_samples as usize) as u32,
        caustic_factor: env("PRISMAP_BENCH_CAUSTIC_FACTOR", defaults.caustic_factor),
        bins: bins.unwrap_or(defaults.bins),
        storage: Storage::Compact,
        ..defaults
    };
    let ctx = egui::Context::default();
    let mut app = ViewerApp::new(&ctx, SceneSource::Builtin("prism".into()), settings, None);
    if bins.is_none() {
        // The viewer's "auto" bins, as `prismap view` starts with them.
        app.keep_auto_bins();
    }
    let mut h = Harness::builder()
        .with_size(egui::vec2(1280.0, 800.0))
        .build_ui_state(|ui, app: &mut ViewerApp| app.ui(ui), app);
    let start = Instant::now();
    let mut frames = Vec::new();
    let mut latencies = Vec::new();
    let mut full_passes = Vec::new(); // (seconds of rendering, passes) per generation
    let mut change_at = Instant::now();
    let mut waiting = true;
    let mut generation_start = Instant::now();
    let mut last_passes = 0;
    // Per generation: when its first full pass showed, and (seconds, passes) from then to
    // its last pass seen: the start-up cost and the steady rate, told apart.
    let mut first_full: Option<f64> = None;
    let mut last_full_at = 0.0;
    let mut firsts = Vec::new();
    let mut steady = Vec::new();
    let mut next_change = Instant::now() + Duration::from_secs(6);
    while start.elapsed().as_secs_f64() < seconds {
        let t = Instant::now();
        h.step();
        frames.push(t.elapsed().as_secs_f64() * 1e3);
        let app = h.state();
        if let Some(s) = &app.snapshot {
            if waiting {
                latencies.push(change_at.elapsed().as_secs_f64() * 1e3);
                waiting = false;
            }
            if !s.preview && s.stats.passes > last_passes {
                let at = generation_start.elapsed().as_secs_f64();
                if first_full.is_none() {
                    first_full = Some(at);
                }
                last_passes = s.stats.passes;
                last_full_at = at;
            }
        }
        if Instant::now() >= next_change {
            full_passes.push((generation_start.elapsed().as_secs_f64(), last_passes));
            if let Some(t0) = first_full.take() {
                firsts.push(t0);
                steady.push((last_full_at - t0, last_passes.saturating_sub(1)));
            }
            let app = h.state_mut();
            app.settings.storage = if app.settings.storage == Storage::Compact {
                Storage::Full
            } else {
                Storage::Compact
            };
            app.restart();
            change_at = Instant::now();
            generation_start = change_at;
            waiting = true;
            last_passes = 0;
            next_change = Instant::now() + Duration::from_secs(6);
        }
        let spent = t.elapsed();
        if spent < Duration::from_millis(16) {
            std::thread::sleep(Duration::from_millis(16) - spent);
        }
    }
    full_passes.push((generation_start.elapsed().as_secs_f64(), last_passes));
    if let Some(t0) = first_full {
        firsts.push(t0);
        steady.push((last_full_at - t0, last_passes.saturating_sub(1)));
    }
    let n = frames.len();
    let med = percentile(&mut frames, 0.5);
    let p99 = percentile(&mut frames, 0.99);
    let (secs, passes) = full_passes
        .iter()
        .fold((0.0, 0u64), |a, b| (a.0 + b.0, a.1 + b.1));
    let used = &h.state().settings;
    let pool = h.state().worker_pool();
    println!(
        "viewer benchmark: prism {}×{}, {} photons/pass (caustic ×{}), {} final-gather rays, {} camera samples, {} bins, compact and full storage alternating (a restart every 6 s), {} worker threads{}",
        used.width,
        used.height,
        used.photons_per_pass,
        used.caustic_factor,
        used.final_gather_rays,
        used.camera_samples,
        used.bins,
        pool.map_or(0, |p| p.threads),
        if pool.is_some_and(|p| p.below_ui) {
            format!(
                " at nice {}, below the UI thread",
                prismap::app::WORKER_NICE
            )
        } else {
            " (one core left to the UI)".to_string()
        }
    );
    println!(
        "UI frame time over {n} frames: median {med:.2} ms, 99th percentile {p99:.2} ms (target median ≤ 16 ms)"
    );
    if !latencies.is_empty() {
        let lmed = percentile(&mut latencies.clone(), 0.5);
        let lmax = latencies.iter().cloned().fold(0.0, f64::max);
        println!(
            "setting change → first updated image over {} changes: median {lmed:.0} ms, max {lmax:.0} ms (target ≤ 150 ms)",
            latencies.len()
        );
    }
    println!(
        "full-quality passes per second: {:.2} ({passes} passes in {secs:.1} s of rendering)",
        passes as f64 / secs.max(1e-9)
    );
    if !firsts.is_empty() {
        let (ssecs, spasses) = steady
            .iter()
            .fold((0.0, 0u64), |a, b| (a.0 + b.0, a.1 + b.1));
        println!(
            "of which: first full pass {:.2} s after a restart (median of {}), then {:.2} passes per second ({spasses} passes in {ssecs:.1} s)",
            percentile(&mut firsts.clone(), 0.5),
            firsts.len(),
            spasses as f64 / ssecs.max(1e-9)
        );
    }
}
