//! A panic inside a render pass: the viewer shows the error, stays usable, and the next
//! change restarts rendering. (Its own test binary: the fault switch is process-wide.)

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use prismap::app::{SceneSource, ViewerApp};
use prismap::photon::Storage;
use prismap::render::RenderSettings;
use prismap::render::session::INJECT_PANIC;

fn wait_until(h: &mut Harness<'static, ViewerApp>, what: &str, cond: impl Fn(&ViewerApp) -> bool) {
    let start = Instant::now();
    loop {
        h.step();
        if cond(h.state()) {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn a_panicking_pass_is_shown_and_the_next_change_recovers() {
    INJECT_PANIC.store(true, Ordering::SeqCst);
    let settings = RenderSettings {
        storage: Storage::Full,
        width: 32,
        height: 32,
        photons_per_pass: 2_000,
        final_gather_rays: 1,
        ..RenderSettings::default()
    };
    let app = ViewerApp::new(
        &egui::Context::default(),
        SceneSource::Builtin("cornell-box".into()),
        settings,
        None,
    );
    let mut h = Harness::builder()
        .with_size(egui::vec2(1400.0, 1000.0))
        .build_ui_state(|ui, app: &mut ViewerApp| app.ui(ui), app);
    wait_until(&mut h, "the error", |a| a.render_error().is_some());
    assert!(h.state().render_error().unwrap().contains("injected fault"));
    h.step();
    h.get_by_label_contains("injected fault");
    // The UI still works: a change restarts the worker, which renders again.
    INJECT_PANIC.store(false, Ordering::SeqCst);
    h.get_by_label("compact").click();
    h.step();
    wait_until(&mut h, "a pass after recovery", |a| {
        a.render_error().is_none()
            && a.snapshot
                .as_ref()
                .is_some_and(|s| !s.preview && s.stats.passes >= 1)
    });
}
