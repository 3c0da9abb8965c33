//! The gather pass, the film and the progressive session that drives both.

pub mod film;
pub mod gather;
pub mod session;
pub mod settings;

pub use film::{Film, Image};
pub use session::{MemoryReport, Probe, RenderSession, RenderStats};
pub use settings::{RenderSettings, SettingsError};
