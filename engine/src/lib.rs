//! prismap-engine: spectral photon mapping with no GUI, plotting or CLI dependencies.
//!
//! Each module owns one stage, and data flows one way:
//!
//! ```text
//! scene file ─ scene::load ─▶ Scene ─ SpectralScene::new(grid) ─▶ SpectralScene
//!   ─ photon::trace_photons ─▶ PhotonMap (full | compact | rgb records)
//!   ─ render::gather ─▶ Film ─ output ─▶ PNG / EXR / stats JSON
//! ```
//!
//! - [`spectral`]: the bin grid, CIE tables, continuous spectra, Smits, colour, IOR.
//! - [`scene`]: glTF → validated [`scene::Scene`] → [`scene::SpectralScene`] on one grid.
//! - [`geometry`], [`materials`], [`lights`], [`sampling`]: rays and the BVH, scattering,
//!   emission and falloff, random streams and warps.
//! - [`photon`]: the photon pass, records, maps. [`render`]: the gather, the film, and
//!   [`render::RenderSession`], which owns the pass loop for every front end.
//! - [`output`]: images and stats. [`metrics`]: PSNR, CIEDE2000, memory.
//!
//! ```
//! use prismap_engine::render::{RenderSession, RenderSettings};
//! use prismap_engine::scene;
//! let scene = scene::load_builtin("cornell-box").unwrap();
//! let settings = RenderSettings { width: 16, height: 16, photons_per_pass: 2_000, ..RenderSettings::preview() };
//! let mut session = RenderSession::new(&scene, settings).unwrap();
//! session.run_pass().unwrap();
//! assert_eq!(session.image().pixels.len(), 256);
//! ```

// `!(x > 0.0)` is written on purpose throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod cpu;
pub mod geometry;
pub mod lights;
pub mod materials;
pub mod metrics;
pub mod output;
pub mod photon;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod spectral;
