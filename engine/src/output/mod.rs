//! Writing results: PNG (sRGB-encoded, 8 bit), OpenEXR (linear sRGB, f32) and the stats
//! JSON. Every file is written to a temporary name beside the target and renamed, so an
//! interrupted write never leaves a corrupt file under the real name.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::render::Image;
use crate::spectral::color::srgb_encode;

#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{path}: {message}")]
    Write { path: String, message: String },
    #[error("{path}: unknown image format (use .png or .exr)")]
    UnknownFormat { path: String },
}

fn write_err(path: &Path, e: impl std::fmt::Display) -> OutputError {
    OutputError::Write {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// A temporary path in the same folder (so the rename is atomic on one filesystem).
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{}.tmp", std::process::id()))
}

/// Writes `bytes` via a temporary file and a rename.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), OutputError> {
    let tmp = temp_path(path);
    if let Err(e) = write(&tmp) {
        let _ = std::fs::remove_file(&tmp);
        return Err(write_err(path, e));
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        write_err(path, e)
    })
}

/// 8-bit sRGB pixels (exposure applied, clamped).
pub fn to_srgb8(image: &Image, exposure: f32) -> Vec<u8> {
    image
        .pixels
        .iter()
        .flat_map(|p| p.map(|v| (srgb_encode(v * exposure) * 255.0 + 0.5) as u8))
        .collect()
}

pub fn write_png(path: &Path, image: &Image, exposure: f32) -> Result<(), OutputError> {
    let bytes = to_srgb8(image, exposure);
    write_atomic(path, |tmp| {
        image::save_buffer_with_format(
            tmp,
            &bytes,
            image.width,
            image.height,
            image::ExtendedColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .map_err(|e| e.to_string())
    })
}

/// Linear sRGB, 32-bit float, no exposure applied.
pub fn write_exr(path: &Path, image: &Image) -> Result<(), OutputError> {
    let (w, h) = (image.width as usize, image.height as usize);
    write_atomic(path, |tmp| {
        exr::prelude::write_rgb_file(tmp, w, h, |x, y| {
            let p = image.pixels[y * w + x];
            (p[0], p[1], p[2])
        })
        .map_err(|e| e.to_string())
    })
}

/// Writes PNG or EXR by the file's extension.
pub fn write_image(path: &Path, image: &Image, exposure: f32) -> Result<(), OutputError> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("png") => write_png(path, image, exposure),
        Some("exr") => write_exr(path, image),
        _ => Err(OutputError::UnknownFormat {
            path: path.display().to_string(),
        }),
    }
}

/// Reads an EXR written by [`write_exr`] (for tests and reports).
pub fn read_exr(path: &Path) -> Result<Image, OutputError> {
    use exr::prelude::*;
    let img = read_first_rgba_layer_from_file(
        path,
        |res, _| {
            (
                res.width(),
                res.height(),
                vec![[0f32; 3]; res.width() * res.height()],
            )
        },
        |(w, _, px), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = [r, g, b]
        },
    )
    .map_err(|e| write_err(path, e))?;
    let (w, h, pixels) = img.layer_data.channel_data.pixels;
    Ok(crate::render::Image {
        width: w as u32,
        height: h as u32,
        pixels,
    })
}

/// Writes a JSON value, pretty-printed.
pub fn write_json(path: &Path, value: &serde_json::Value) -> Result<(), OutputError> {
    write_atomic(path, |tmp| {
        let mut f = std::fs::File::create(tmp).map_err(|e| e.to_string())?;
        serde_json::to_writer_pretty(&mut f, value).map_err(|e| e.to_string())?;
        f.write_all(b"\n").map_err(|e| e.to_string())
    })
}

/// The stats JSON of a finished render (schema in the README).
pub fn stats_json(
    session: &crate::render::RenderSession,
    image: &Image,
    total_seconds: f64,
) -> serde_json::Value {
    let st = session.stats();
    let mem = session.memory();
    let s = session.settings();
    let nonfinite = image
        .pixels
        .iter()
        .filter(|p| p.iter().any(|v| !v.is_finite()))
        .count();
    serde_json::json!({
        "scene": session.scene().name,
        "bins": session.scene().bins(),
        "storage": s.storage.name(),
        "size": [s.width, s.height],
        "passes": st.passes,
        "seed": s.seed,
        "photons_per_pass": s.photons_per_pass,
        "final_gather_rays": s.final_gather_rays,
        "photons": {
            "emitted": st.photons_emitted,
            "stored_global": st.stored_global,
            "stored_caustic": st.stored_caustic,
            "spike_records": st.spike_records,
            "stored_global_total": st.stored_global_total,
            "stored_caustic_total": st.stored_caustic_total,
            "spike_records_total": st.spike_records_total,
            "dispersion_splits": st.dispersion_splits,
        },
        "memory_bytes": {
            "global_map": mem.global_map,
            "caustic_map": mem.caustic_map,
            "photon_maps": mem.photon_maps,
            "film": mem.film,
            "bvh": mem.bvh,
        },
        "bytes_per_photon": session.bytes_per_photon(),
        "photons_last_pass": st.photons_last_pass,
        "radius": {"global": st.r_global, "caustic": st.r_caustic},
        "seconds": {
            "photon_pass": st.photon_seconds,
            "gather_pass": st.gather_seconds,
            "total": total_seconds,
        },
        "nonfinite_pixels": nonfinite,
        "peak_rss_bytes": crate::metrics::peak_rss_bytes(),
        "dropped_samples": session.film().dropped_samples(),
        "skipped": session.skipped(),
        "warnings": session.scene().warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(v: f32) -> Image {
        Image {
            width: 4,
            height: 2,
            pixels: vec![[v, v * 0.5, v * 0.25]; 8],
        }
    }

    #[test]
    fn exr_round_trips_and_png_writes() {
        let dir = std::env::temp_dir().join(format!("prismap-out-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let exr = dir.join("a.exr");
        write_image(&exr, &img(0.7), 1.0).unwrap();
        assert_eq!(read_exr(&exr).unwrap(), img(0.7));
        let png = dir.join("a.png");
        write_image(&png, &img(0.7), 1.0).unwrap();
        assert!(std::fs::metadata(&png).unwrap().len() > 0);
        assert!(write_image(&dir.join("a.bmp"), &img(0.7), 1.0).is_err());
        // An unwritable target leaves nothing behind.
        let bad = dir.join("missing-folder").join("x.png");
        assert!(write_image(&bad, &img(0.7), 1.0).is_err());
        assert!(!bad.exists());
        let leftovers = std::fs::read_dir(&dir).unwrap().filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .ends_with(".tmp")
        });
        assert_eq!(leftovers.count(), 0);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
