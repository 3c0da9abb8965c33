//! Spectral core: the CIE and Smits tables, continuous spectra, the runtime bin grid,
//! colour conversion and index-of-refraction models.

pub mod blackbody;
pub mod color;
pub mod grid;
pub mod ior;
pub mod jakob_hanika;
pub mod smits;
pub mod spectrum;
pub mod tables;

pub use grid::{BinGrid, GridError, MAX_BINS, PAPER_BINS, Transport, spd};
pub use ior::IorModel;
pub use spectrum::{RgbSpectrum, Role, Spectrum, Upsampling};

#[cfg(test)]
mod tests;
