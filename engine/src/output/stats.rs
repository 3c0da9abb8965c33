//! The stats of a finished render, typed: written as the stats JSON (`--stats`, schema in
//! the README) and read back by the report, so a renamed field is a compile error or a
//! parse error, never a silent zero.

use serde::{Deserialize, Serialize};

use crate::render::{Image, RenderSession};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    pub scene: String,
    pub bins: usize,
    pub storage: String,
    pub size: [u32; 2],
    pub passes: u64,
    pub seed: u64,
    pub photons_per_pass: usize,
    pub final_gather_rays: u32,
    /// Camera rays a pixel a pass (absent from stats written before session 7: 1).
    #[serde(default = "one")]
    pub camera_samples: u32,
    /// Whether neighbouring pixels pooled their final-gather rays (absent from stats
    /// written before session 19, which did not: false).
    #[serde(default)]
    pub fg_pool: bool,
    /// Whether final-gather rays were guided by the photons (absent from stats written
    /// before session 34, which were not: false).
    #[serde(default)]
    pub fg_guide: bool,
    /// Wavelengths each camera sample followed past dispersive glass (absent from stats
    /// written before session 34: 1).
    #[serde(default = "one")]
    pub glass_split: u32,
    pub photons: PhotonStats,
    pub memory_bytes: MemoryStats,
    pub bytes_per_photon: f64,
    pub photons_last_pass: u64,
    pub radius: RadiusStats,
    pub seconds: SecondsStats,
    pub nonfinite_pixels: usize,
    /// The film's own noise estimate at the image's automatic exposure (PSNR of the mean
    /// against its expectation, [`crate::render::Film::noise_psnr`]); None before 2 passes.
    pub noise_psnr_db: Option<f64>,
    pub peak_rss_bytes: Option<u64>,
    pub dropped_samples: u64,
    pub skipped: Vec<String>,
    pub warnings: Vec<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PhotonStats {
    pub emitted: u64,
    /// Photons emitted for the caustic map only (`--caustic-factor`).
    #[serde(default)]
    pub caustic_emitted: u64,
    /// Whether lights aimed those photons at the glass and mirrors.
    #[serde(default)]
    pub caustic_aimed: bool,
    /// How many spheres around the glass and mirrors they were aimed at (0: not aimed).
    #[serde(default)]
    pub caustic_targets: u32,
    pub stored_global: u64,
    pub stored_caustic: u64,
    pub spike_records: u64,
    pub stored_global_total: u64,
    pub stored_caustic_total: u64,
    pub spike_records_total: u64,
    pub dispersion_splits: u64,
    /// Whether the last pass's Suns, point lights or spots emitted by learned tables
    /// (absent from stats written before session 35: false).
    #[serde(default)]
    pub emission_adapted: bool,
    /// Of the last pass's photons from those lights, the share that reached a surface the
    /// camera sees (null where no light learns).
    #[serde(default)]
    pub emission_useful_share: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MemoryStats {
    pub global_map: usize,
    pub caustic_map: usize,
    pub photon_maps: usize,
    pub irradiance_cache: usize,
    /// The next pass's photon maps, when a run stopped after they were traced alongside
    /// its last gather (0 otherwise).
    #[serde(default)]
    pub next_pass_maps: usize,
    pub film: usize,
    pub bvh: usize,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RadiusStats {
    pub global: f32,
    pub caustic: f32,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SecondsStats {
    /// Waiting for photon maps before a gather (each pass but the first traces the next
    /// one's photons during its gather, so this is mostly the first pass's tracing).
    pub photon_pass: f64,
    /// Gathering, with the next pass's tracing where it ran alongside.
    pub gather_pass: f64,
    /// Of `gather_pass`, the wall time of the tracing that ran alongside.
    #[serde(default)]
    pub photon_alongside: f64,
    pub total: f64,
}

impl Stats {
    /// The stats of `session` after its last pass; `image` is its developed image and
    /// `total_seconds` the wall time of the whole command.
    pub fn of(session: &RenderSession, image: &Image, total_seconds: f64) -> Self {
        let st = session.stats();
        let mem = session.memory();
        let s = session.settings();
        Self {
            scene: session.scene().name.clone(),
            bins: session.scene().bins(),
            storage: s.storage.name().to_string(),
            size: [s.width, s.height],
            passes: st.passes,
            seed: s.seed,
            photons_per_pass: s.photons_per_pass,
            final_gather_rays: s.final_gather_rays,
            camera_samples: s.camera_samples,
            fg_pool: s.pools_gather(),
            fg_guide: s.guides_gather(),
            glass_split: s.glass_split,
            photons: PhotonStats {
                emitted: st.photons_emitted,
                caustic_emitted: st.caustic_photons_emitted,
                caustic_aimed: st.caustic_photons_aimed,
                caustic_targets: st.caustic_targets,
                stored_global: st.stored_global,
                stored_caustic: st.stored_caustic,
                spike_records: st.spike_records,
                stored_global_total: st.stored_global_total,
                stored_caustic_total: st.stored_caustic_total,
                spike_records_total: st.spike_records_total,
                dispersion_splits: st.dispersion_splits,
                emission_adapted: st.emission_adapted,
                emission_useful_share: st.emission_useful_share,
            },
            memory_bytes: MemoryStats {
                global_map: mem.global_map,
                caustic_map: mem.caustic_map,
                photon_maps: mem.photon_maps,
                irradiance_cache: mem.irradiance_cache,
                next_pass_maps: mem.next_pass_maps,
                film: mem.film,
                bvh: mem.bvh,
            },
            bytes_per_photon: session.bytes_per_photon(),
            photons_last_pass: st.photons_last_pass,
            radius: RadiusStats {
                global: st.r_global,
                caustic: st.r_caustic,
            },
            seconds: SecondsStats {
                photon_pass: st.photon_seconds,
                gather_pass: st.gather_seconds,
                photon_alongside: st.photon_seconds_alongside,
                total: total_seconds,
            },
            nonfinite_pixels: image
                .pixels
                .iter()
                .filter(|p| p.iter().any(|v| !v.is_finite()))
                .count(),
            noise_psnr_db: session
                .film()
                .noise_psnr(crate::output::auto_exposure(image))
                .filter(|v| v.is_finite()),
            peak_rss_bytes: crate::metrics::peak_rss_bytes(),
            dropped_samples: session.film().dropped_samples(),
            skipped: session.skipped(),
            warnings: session.scene().warnings.clone(),
        }
    }

    /// Photons stored in the last pass's maps (global + caustic).
    pub fn stored_photons(&self) -> u64 {
        self.photons.stored_global + self.photons.stored_caustic
    }

    /// Render time: photon + gather passes.
    pub fn render_seconds(&self) -> f64 {
        self.seconds.photon_pass + self.seconds.gather_pass
    }
}

fn one() -> u32 {
    1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::RenderSettings;

    #[test]
    fn stats_round_trip_through_json_and_a_missing_key_is_an_error() {
        let scene = crate::scene::load_builtin("cornell-box").unwrap();
        let s = RenderSettings {
            width: 8,
            height: 8,
            photons_per_pass: 500,
            ..RenderSettings::preview()
        };
        let mut r = RenderSession::new(&scene, s).unwrap();
        r.run_pass().unwrap();
        let stats = Stats::of(&r, &r.image(), 0.5);
        let json = serde_json::to_string(&stats).unwrap();
        assert_eq!(serde_json::from_str::<Stats>(&json).unwrap(), stats);
        assert_eq!(stats.photons.emitted, 500);
        let renamed = json.replace("\"emitted\"", "\"emited\"");
        let err = serde_json::from_str::<Stats>(&renamed)
            .unwrap_err()
            .to_string();
        assert!(err.contains("emitted"), "{err}");
    }
}
