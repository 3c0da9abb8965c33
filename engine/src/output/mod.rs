//! Writing results: PNG (sRGB-encoded, 8 bit), OpenEXR (linear sRGB, f32) and the stats
//! JSON. Every file is written to a temporary name beside the target and renamed, so an
//! interrupted write never leaves a corrupt file under the real name.

mod spectral_exr;
mod stats;

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::render::Image;
use crate::spectral::color::srgb8;
pub use spectral_exr::{
    SpectralImage, channel_name, parse_channel_name, read_spectral_exr, write_spectral_exr,
};
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

/// An exposure that shows `image` well: the log-average luminance maps to 0.18 (middle
/// grey, Reinhard's key), but never so bright that the brightest 1 % of pixels clip.
/// 1 for a black image. Applies to display (PNG, the viewer); EXR stays linear.
pub fn auto_exposure(image: &Image) -> f32 {
    metered_exposure(image, None)
}

/// [`auto_exposure`] metered without the pixels in `skip` (true: an emitter seen
/// directly, which may clip as it does in a photograph); then only the brightest 0.1 %
/// of the other pixels may clip, so a small bright caustic (a rainbow on a dark stage)
/// keeps its colours.
pub fn auto_exposure_skipping(image: &Image, skip: &[bool]) -> f32 {
    metered_exposure(image, Some(skip))
}

fn metered_exposure(image: &Image, skip: Option<&[bool]>) -> f32 {
    let counted = |i: usize| skip.is_none_or(|s| !s.get(i).copied().unwrap_or(false));
    let n_counted = (0..image.pixels.len()).filter(|&i| counted(i)).count();
    let mut y: Vec<f32> = image
        .pixels
        .iter()
        .enumerate()
        .filter(|(i, _)| counted(*i))
        .map(|(_, p)| luminance_of(*p))
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    if y.is_empty() {
        return 1.0;
    }
    // Pixels at or near black count at a floor, so a mostly dark stage keeps its key.
    let floor = 1e-4 * y.iter().cloned().fold(0.0f32, f32::max);
    let n = n_counted.max(1) as f64;
    let log_sum: f64 = y.iter().map(|v| (v.max(floor) as f64).ln()).sum::<f64>()
        + (n - y.len() as f64) * (floor as f64).ln();
    let log_avg = (log_sum / n).exp() as f32;
    let percentile = if skip.is_some() { 0.999 } else { 0.99 };
    let k = ((y.len() - 1) as f64 * percentile) as usize;
    let (_, p99, _) = y.select_nth_unstable_by(k, f32::total_cmp);
    let by_key = 0.18 / log_avg;
    let by_highlights = 0.95 / *p99;
    let e = by_key.min(by_highlights);
    if e.is_finite() && e > 0.0 { e } else { 1.0 }
}

/// The fraction of pixels with a channel above 1 after `exposure` (clipped on display).
pub fn clipped_fraction(image: &Image, exposure: f32) -> f64 {
    if image.pixels.is_empty() {
        return 0.0;
    }
    let clipped = image
        .pixels
        .iter()
        .filter(|p| p.iter().any(|v| v * exposure > 1.0))
        .count();
    clipped as f64 / image.pixels.len() as f64
}

/// A warning when more than `CLIP_WARNING` of the pixels clip at `exposure`.
pub fn clipping_warning(image: &Image, exposure: f32) -> Option<String> {
    let f = clipped_fraction(image, exposure);
    (f > CLIP_WARNING).then(|| {
        format!(
            "{:.1} % of the pixels clip at exposure {exposure:.3e}: lower --exposure (or leave it out for automatic exposure), or write EXR for the linear values",
            100.0 * f
        )
    })
}

/// Clipped pixels above this fraction get a warning.
pub const CLIP_WARNING: f64 = 0.03;

fn luminance_of(p: [f32; 3]) -> f32 {
    0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]
}

/// 8-bit sRGB pixels, RGB interleaved (exposure and tone map applied).
pub fn to_display8(image: &Image, exposure: f32, tone: ToneMap) -> Vec<u8> {
    let mut out = vec![0u8; 3 * image.pixels.len()];
    for (o, p) in out.chunks_exact_mut(3).zip(&image.pixels) {
        for (o, &v) in o.iter_mut().zip(p) {
            *o = srgb8(tone.apply(v * exposure));
        }
    }
    out
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

/// Linear sRGB, 32-bit float, no exposure applied. Blocks are written in increasing
/// order (the crate's default leaves the order to whichever compression thread finishes
/// first), so the same image always makes the same file, byte for byte.
pub fn write_exr(path: &Path, image: &Image) -> Result<(), OutputError> {
    use exr::prelude::*;
    let (w, h) = (image.width as usize, image.height as usize);
    write_atomic(path, |tmp| {
        let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
            let p = image.pixels[y * w + x];
            (p[0], p[1], p[2])
        });
        let encoding = Encoding {
            line_order: LineOrder::Increasing,
            ..Encoding::FAST_LOSSLESS
        };
        Image::from_encoded_channels((w, h), encoding, channels)
            .write()
            .to_file(tmp)
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
    fn auto_exposure_keys_the_scene_and_keeps_highlights() {
        // A uniform image of luminance 2 is keyed to 0.18.
        let flat = Image {
            width: 4,
            height: 4,
            pixels: vec![[2.0; 3]; 16],
        };
        assert!((auto_exposure(&flat) - 0.09).abs() < 1e-4);
        // Photometric scale: the same picture 54 351× brighter gets 1/54 351 of the exposure.
        let mut scene: Vec<[f32; 3]> = (0..400).map(|i| [0.01 + i as f32 * 1e-3; 3]).collect();
        scene[7] = [5.0; 3];
        let a = Image {
            width: 20,
            height: 20,
            pixels: scene.clone(),
        };
        let b = Image {
            width: 20,
            height: 20,
            pixels: scene.iter().map(|p| p.map(|v| v * 54_351.0)).collect(),
        };
        let (ea, eb) = (auto_exposure(&a), auto_exposure(&b));
        assert!(((ea / eb) / 54_351.0 - 1.0).abs() < 1e-3, "{ea} {eb}");
        // No more than 1 % of the pixels clip at the automatic exposure.
        assert!(clipped_fraction(&b, eb) <= 0.01 + 1e-9);
        assert!(clipping_warning(&b, 1.0).is_some() && clipping_warning(&b, eb).is_none());
        let black = Image {
            width: 2,
            height: 2,
            pixels: vec![[0.0; 3]; 4],
        };
        assert_eq!(auto_exposure(&black), 1.0);
    }

    #[test]
    fn the_same_image_makes_the_same_exr_file() {
        // Many tiles compressed in parallel: the file must not depend on which thread
        // finished first (it once did: blocks in completion order).
        let (w, h) = (520u32, 300u32);
        let mut rng = crate::sampling::Rng::stream(5, 0, 0, crate::sampling::Purpose::Camera);
        let image = Image {
            width: w,
            height: h,
            pixels: (0..w * h)
                .map(|_| [rng.next_f32(), rng.next_f32(), 0.5])
                .collect(),
        };
        let dir = std::env::temp_dir().join(format!("prismap-exr-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("same.exr");
        write_exr(&path, &image).unwrap();
        let first = std::fs::read(&path).unwrap();
        let meta = exr::meta::MetaData::read_from_file(&path, false).unwrap();
        assert_eq!(
            meta.headers[0].line_order,
            exr::meta::attribute::LineOrder::Increasing
        );
        for _ in 0..6 {
            write_exr(&path, &image).unwrap();
            assert!(std::fs::read(&path).unwrap() == first, "EXR bytes changed");
        }
        assert_eq!(read_exr(&path).unwrap(), image);
        std::fs::remove_dir_all(&dir).unwrap();
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
