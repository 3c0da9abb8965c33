//! Writing results: PNG (sRGB-encoded, 8 bit), OpenEXR (linear sRGB, f32) and the stats
//! JSON. Every file is written to a temporary name beside the target and renamed, so an
//! interrupted write never leaves a corrupt file under the real name.

mod stats;

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::render::Image;
use crate::spectral::color::srgb8;
pub use stats::{MemoryStats, PhotonStats, RadiusStats, SecondsStats, Stats};

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

/// How linear radiance becomes display values.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ToneMap {
    /// Exposure, then clip at 1.
    #[default]
    Clamp,
    /// Exposure, then x / (1 + x) per channel.
    Reinhard,
}

impl ToneMap {
    #[inline]
    pub fn apply(self, v: f32) -> f32 {
        match self {
            ToneMap::Clamp => v,
            ToneMap::Reinhard => v.max(0.0) / (1.0 + v.max(0.0)),
        }
    }
}

/// 8-bit sRGB pixels, RGB interleaved (exposure and tone map applied).
pub fn to_display8(image: &Image, exposure: f32, tone: ToneMap) -> Vec<u8> {
    image
        .pixels
        .iter()
        .flat_map(|p| p.map(|v| srgb8(tone.apply(v * exposure))))
        .collect()
}

/// 8-bit sRGB pixels (exposure applied, clamped).
pub fn to_srgb8(image: &Image, exposure: f32) -> Vec<u8> {
    to_display8(image, exposure, ToneMap::Clamp)
}

pub fn write_png(path: &Path, image: &Image, exposure: f32) -> Result<(), OutputError> {
    let bytes = to_srgb8(image, exposure);
    write_png8(path, &bytes, image.width, image.height)
}

/// Writes 8-bit pixels as a PNG, atomically: RGB when `bytes` holds 3 per pixel, RGBA
/// when it holds 4.
pub fn write_png8(path: &Path, bytes: &[u8], width: u32, height: u32) -> Result<(), OutputError> {
    let pixels = width as usize * height as usize;
    let colour = match bytes.len().checked_div(pixels) {
        Some(3) => image::ExtendedColorType::Rgb8,
        Some(4) => image::ExtendedColorType::Rgba8,
        _ => {
            let message = format!("{} bytes for {width}x{height} pixels", bytes.len());
            return Err(write_err(path, message));
        }
    };
    write_atomic(path, |tmp| {
        image::save_buffer_with_format(tmp, bytes, width, height, colour, image::ImageFormat::Png)
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

/// Writes a value as JSON, pretty-printed.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<(), OutputError> {
    write_atomic(path, |tmp| {
        let mut f = std::fs::File::create(tmp).map_err(|e| e.to_string())?;
        serde_json::to_writer_pretty(&mut f, value).map_err(|e| e.to_string())?;
        f.write_all(b"\n").map_err(|e| e.to_string())
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
