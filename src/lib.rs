//! prismap: the front ends over [`prismap_engine`] — the eframe viewer ([`app`]), the
//! speed-against-error report ([`report`]) and, in `main.rs`, the command line. They parse,
//! display and write; the engine renders (its modules are re-exported here, so
//! `prismap::render::RenderSession` is the engine's).
//!
//! ```text
//! prismap (this crate)      app/ (viewer), report/, main.rs (CLI: view | render | report | list)
//!   └─ prismap-engine       spectral, scene, geometry, materials, lights, sampling,
//!                           photon, render (RenderSession::run), output, metrics
//! ```

// `!(x > 0.0)` is written on purpose throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub use prismap_engine::{
    geometry, lights, materials, metrics, output, photon, render, sampling, scene, spectral,
};

pub mod app;
pub mod cli;
pub mod report;
