//! The pass loop every front end drives: [`RenderSession::run`] renders passes until a
//! [`Stop`] rule or the observer says so, logging time, photons and (against an optional
//! reference) PSNR after every pass. The CLI, the report's runs and the viewer's worker all
//! go through it, so `prismap render --passes N` and the viewer after N passes agree.

use std::time::Instant;

use super::film::Image;
use super::session::{RenderError, RenderSession};
use super::settings::{SettingsError, out_of_range};
use crate::metrics::psnr;

/// When a run ends: after `passes` passes, or once `seconds` of rendering have passed
/// (at least one pass), whichever comes first; neither means "until the observer stops".
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stop {
    pub passes: Option<u64>,
    pub seconds: Option<f64>,
}

impl Stop {
    /// Passes rendered when the user gives neither a pass count nor a time.
    pub const DEFAULT_PASSES: u64 = 32;

    pub fn passes(n: u64) -> Self {
        Self {
            passes: Some(n),
            seconds: None,
        }
    }

    pub fn seconds(s: f64) -> Self {
        Self {
            passes: None,
            seconds: Some(s),
        }
    }

    /// Until the observer stops the run.
    pub fn never() -> Self {
        Self::default()
    }

    /// The CLI's rule: the given passes, or the given seconds, or 32 passes.
    pub fn from_flags(passes: Option<u64>, seconds: Option<f64>) -> Result<Self, SettingsError> {
        let stop = match (passes, seconds) {
            (None, None) => Self::passes(Self::DEFAULT_PASSES),
            (p, s) => Self {
                passes: p,
                seconds: s,
            },
        };
        stop.validate()?;
        Ok(stop)
    }

    pub fn validate(&self) -> Result<(), SettingsError> {
        if self.passes == Some(0) {
            return Err(out_of_range("--passes", 0, "at least one pass is needed"));
        }
        if let Some(s) = self.seconds
            && !(s.is_finite() && s > 0.0)
        {
            return Err(out_of_range("--seconds", s, "must be finite and > 0"));
        }
        Ok(())
    }
}

/// What the observer is told after each pass (one row of the error log).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PassRecord {
    pub pass: u64,
    /// Photon + gather seconds so far (render time, not wall time with I/O).
    pub seconds: f64,
    pub photons: u64,
    /// PSNR of the image so far against the run's reference, if it has one.
    pub psnr_db: Option<f64>,
}

/// Whether the run goes on after a pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    Continue,
    Stop,
}

/// An image to measure the error against after every pass (PSNR, the paper's equation 6,
/// on display values at `exposure`).
#[derive(Clone, Copy, Debug)]
pub struct ErrorReference<'a> {
    pub image: &'a Image,
    pub exposure: f32,
}

impl RenderSession {
    /// Renders passes until `stop` or until `observer` returns [`Flow::Stop`]; returns the
    /// per-pass log. Each pass but the last traces the next one's photons alongside its
    /// gather (the same maps that pass would trace itself; see [`RenderSession::run_pass`]).
    /// A size mismatch with the reference is an error before any pass.
    pub fn run(
        &mut self,
        stop: Stop,
        reference: Option<ErrorReference>,
        observer: &mut dyn FnMut(&RenderSession, &PassRecord) -> Flow,
    ) -> Result<Vec<PassRecord>, RenderError> {
        stop.validate()?;
        if let Some(r) = reference {
            let (w, h) = (self.settings().width, self.settings().height);
            if (r.image.width, r.image.height) != (w, h) {
                return Err(
                    crate::metrics::SizeMismatch(w, h, r.image.width, r.image.height).into(),
                );
            }
        }
        let started = Instant::now();
        let mut log = Vec::new();
        let passes = stop.passes.unwrap_or(u64::MAX);
        for i in 0..passes {
            // The next pass's photons are traced during this pass's gather when another
            // pass is expected: not after the last of a pass count, nor when the time
            // limit will likely have passed (the observer may still stop the run, and then
            // those maps go unused).
            let expected =
                |s: f64| started.elapsed().as_secs_f64() + self.stats().last_pass_seconds < s;
            let trace_next = i + 1 < passes && stop.seconds.is_none_or(expected);
            self.pass(trace_next)?;
            let st = self.stats();
            let record = PassRecord {
                pass: st.passes,
                seconds: st.photon_seconds + st.gather_seconds,
                photons: st.photons_emitted,
                psnr_db: match reference {
                    Some(r) => Some(psnr(&self.image(), r.image, r.exposure)?),
                    None => None,
                },
            };
            log.push(record);
            let flow = observer(self, &record);
            let timed_out = stop
                .seconds
                .is_some_and(|s| started.elapsed().as_secs_f64() >= s);
            if flow == Flow::Stop || timed_out {
                break;
            }
        }
        Ok(log)
    }
}

/// The error log as CSV: `pass,seconds,photons,psnr_db`.
pub fn error_csv(log: &[PassRecord]) -> String {
    let mut s = String::from("pass,seconds,photons,psnr_db\n");
    for r in log {
        let psnr = r.psnr_db.map_or(String::new(), |p| format!("{p:.4}"));
        s += &format!("{},{:.6},{},{psnr}\n", r.pass, r.seconds, r.photons);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::RenderSettings;
    use crate::scene;

    fn session() -> RenderSession {
        let s = RenderSettings {
            width: 8,
            height: 8,
            photons_per_pass: 500,
            ..RenderSettings::preview()
        };
        RenderSession::new(&scene::load_builtin("cornell-box").unwrap(), s).unwrap()
    }

    #[test]
    fn runs_stop_at_their_pass_count_or_when_the_observer_says() {
        let mut r = session();
        let log = r
            .run(Stop::passes(3), None, &mut |_, _| Flow::Continue)
            .unwrap();
        assert_eq!(log.iter().map(|p| p.pass).collect::<Vec<_>>(), [1, 2, 3]);
        assert!(
            log.windows(2)
                .all(|w| w[1].photons > w[0].photons && w[1].seconds >= w[0].seconds)
        );
        let mut seen = 0;
        let log = r
            .run(Stop::never(), None, &mut |_, p| {
                seen += 1;
                if p.pass == 5 {
                    Flow::Stop
                } else {
                    Flow::Continue
                }
            })
            .unwrap();
        assert_eq!((seen, log.len(), r.stats().passes), (2, 2, 5));
        // A time limit still renders at least one pass.
        let log = r
            .run(Stop::seconds(1e-9), None, &mut |_, _| Flow::Continue)
            .unwrap();
        assert_eq!(log.len(), 1);
    }

    /// Bit patterns of an image, to compare renders exactly.
    fn bits(image: &Image) -> Vec<[u32; 3]> {
        image.pixels.iter().map(|p| p.map(f32::to_bits)).collect()
    }

    #[test]
    fn tracing_the_next_pass_alongside_a_gather_changes_nothing() {
        // A run traces each next pass's photons during the gather before it; passes run
        // one by one trace their own. Same images and photons, bit for bit: with an ample
        // budget; with one that holds one pass's maps but not two (nothing is traced
        // ahead); and with one so tight that photons per pass are lowered.
        let scene = scene::load_builtin("prism").unwrap();
        let settings = |budget| RenderSettings {
            width: 24,
            height: 16,
            photons_per_pass: 20_000,
            photon_budget_bytes: budget,
            ..RenderSettings::default()
        };
        let mut one_pass = RenderSession::new(&scene, settings(None)).unwrap();
        one_pass.run_pass().unwrap();
        let maps = one_pass.memory().photon_maps;
        for budget in [None, Some(maps * 3 / 2), Some(maps / 10)] {
            let mut ahead = RenderSession::new(&scene, settings(budget)).unwrap();
            let mut alongside = Vec::new();
            let log = ahead
                .run(Stop::passes(4), None, &mut |s, _| {
                    let m = s.memory();
                    if let Some(b) = budget {
                        let both = m.photon_maps + m.next_pass_maps;
                        assert!(both <= b, "{both} bytes of maps > budget {b}");
                    }
                    alongside.push(m.next_pass_maps);
                    Flow::Continue
                })
                .unwrap();
            assert_eq!(log.len(), 4);
            let mut alone = RenderSession::new(&scene, settings(budget)).unwrap();
            for _ in 0..4 {
                alone.run_pass().unwrap();
            }
            assert_eq!(bits(&ahead.image()), bits(&alone.image()), "{budget:?}");
            let (a, b) = (ahead.stats(), alone.stats());
            assert_eq!(
                (a.photons_emitted, a.stored_caustic_total, &a.budget_note),
                (b.photons_emitted, b.stored_caustic_total, &b.budget_note)
            );
            assert_eq!(a.budget_note.is_some(), budget == Some(maps / 10));
            assert_eq!(b.photon_seconds_alongside, 0.0);
            // The last pass traces nothing ahead; the others do when two passes' maps fit.
            let room = budget.is_none();
            assert_eq!(alongside[3], 0);
            assert!(
                alongside[..3].iter().all(|&m| (m > 0) == room),
                "{alongside:?}"
            );
            assert_eq!(a.photon_seconds_alongside > 0.0, room);
        }
    }

    #[test]
    fn maps_traced_ahead_of_a_stopped_run_serve_the_next_pass() {
        // The viewer's case: a run stopped by its observer after a pass that traced the
        // next one's photons; the session goes on (here with run_pass) from those maps,
        // and the image is the one passes run one by one make.
        let scene = scene::load_builtin("prism").unwrap();
        let settings = RenderSettings {
            width: 24,
            height: 16,
            photons_per_pass: 20_000,
            ..RenderSettings::default()
        };
        let mut stopped = RenderSession::new(&scene, settings.clone()).unwrap();
        let log = stopped
            .run(Stop::passes(10), None, &mut |s, _| {
                if s.stats().passes == 2 {
                    Flow::Stop
                } else {
                    Flow::Continue
                }
            })
            .unwrap();
        assert_eq!(log.len(), 2);
        assert!(
            stopped.memory().next_pass_maps > 0,
            "pass 3's maps were traced"
        );
        stopped.run_pass().unwrap();
        assert_eq!(stopped.memory().next_pass_maps, 0);
        stopped.run_pass().unwrap();
        let mut alone = RenderSession::new(&scene, settings).unwrap();
        for _ in 0..4 {
            alone.run_pass().unwrap();
        }
        assert_eq!(bits(&stopped.image()), bits(&alone.image()));
        assert_eq!(
            stopped.stats().photons_emitted,
            alone.stats().photons_emitted
        );
    }

    #[test]
    fn the_error_log_measures_against_the_reference_and_refuses_another_size() {
        let mut r = session();
        let reference = r.image();
        let log = r
            .run(
                Stop::passes(2),
                Some(ErrorReference {
                    image: &reference,
                    exposure: 1.0,
                }),
                &mut |_, _| Flow::Continue,
            )
            .unwrap();
        assert!(log.iter().all(|p| p.psnr_db.is_some_and(f64::is_finite)));
        assert!(error_csv(&log).lines().count() == 3);
        let small = Image {
            width: 2,
            height: 2,
            pixels: vec![[0.0; 3]; 4],
        };
        let err = r
            .run(
                Stop::passes(1),
                Some(ErrorReference {
                    image: &small,
                    exposure: 1.0,
                }),
                &mut |_, _| Flow::Continue,
            )
            .unwrap_err();
        assert!(err.to_string().contains("2x2"), "{err}");
        assert!(
            Stop::from_flags(Some(0), None)
                .unwrap_err()
                .to_string()
                .contains("--passes")
        );
        assert!(Stop::from_flags(None, Some(f64::NAN)).is_err());
        assert_eq!(Stop::from_flags(None, None).unwrap(), Stop::passes(32));
    }
}
