//! prismap: interactive spectral photon mapping.
//!
//! Data flows one way: scene file → [`scene::Scene`] → [`scene::SpectralScene`] (one bin
//! grid) → photon pass → photon maps (full / compact / RGB records) → gather pass →
//! film → PNG / EXR.
//!
//! ```
//! use prismap::{render::{RenderSession, RenderSettings}, scene};
//! let scene = scene::load_builtin("cornell-box").unwrap();
//! let settings = RenderSettings { width: 16, height: 16, photons_per_pass: 2_000, ..RenderSettings::preview() };
//! let mut session = RenderSession::new(&scene, settings).unwrap();
//! session.run_pass().unwrap();
//! assert_eq!(session.image().pixels.len(), 256);
//! ```

// `!(x > 0.0)` is written on purpose throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod app;
pub mod geometry;
pub mod lights;
pub mod materials;
pub mod metrics;
pub mod output;
pub mod photon;
pub mod render;
pub mod report;
pub mod sampling;
pub mod scene;
pub mod spectral;
