//! The photon pass and photon maps: tracing with full N-bin flux, splitting at
//! dispersive glass, storage in full / compact / RGB records, and kd-tree search.

pub mod guide;
pub mod irradiance;
pub mod kdtree;
pub mod map;
pub mod occupancy;
pub mod record;
pub mod trace;
pub mod visibility;

pub use irradiance::{IrradianceCache, Reading};
pub use map::{Estimate, Kernel, PhotonBatch, PhotonMap};
pub use record::{Record, Storage};
pub use trace::{PhotonPass, PhotonSettings, TraceStop, split_dispersive, trace_photons};
