//! The gather pass, the film and the progressive session that drives both.

pub mod denoise;
pub mod film;
pub mod gather;
pub mod run;
pub mod session;
pub mod settings;

pub use denoise::{DenoiseParams, Guides};
pub use film::{Film, Image, SpectralFilm};
pub use run::{ErrorReference, Flow, PassRecord, Stop, error_csv};
pub use session::{MemoryReport, Probe, RenderError, RenderSession, RenderStats};
pub use settings::{RenderSettings, SettingsError};
