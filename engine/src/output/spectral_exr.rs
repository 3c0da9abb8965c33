//! Spectral OpenEXR after Fichet, Pacanowski & Wilkie, "An OpenEXR Layout for Spectral
//! Images" (JCGT 10(3), 2021): one f32 channel per bin named `S0.<wavelength>nm` (the
//! emissive Stokes-0 component; the wavelength is the bin's centre with a comma as the
//! decimal separator, as the layout specifies), the `spectralLayoutVersion` and
//! `emissiveUnits` attributes, and the linear-sRGB `R`, `G`, `B` channels beside them so
//! that any EXR viewer shows the picture. Values are the film's bin means: spectral
//! radiance in the scene's relative units (what the RGB layers are in).

use std::path::Path;

use exr::prelude::*;

use super::{OutputError, write_atomic, write_err};
use crate::render::Image as RgbImage;

/// A spectral image: `wavelengths.len()` values per pixel, row-major, top row first.
#[derive(Clone, Debug, PartialEq)]
pub struct SpectralImage {
    pub width: u32,
    pub height: u32,
    /// Bin centres, nm, increasing.
    pub wavelengths: Vec<f64>,
    pub values: Vec<f32>,
}

impl SpectralImage {
    pub fn pixel(&self, x: u32, y: u32) -> &[f32] {
        let n = self.wavelengths.len();
        let i = (y as usize * self.width as usize + x as usize) * n;
        &self.values[i..i + n]
    }
}

/// The layout's channel name of an emissive bin at `nm`: `S0.550nm`, `S0.371,75nm`.
pub fn channel_name(nm: f64) -> String {
    let text = format!("{nm:.6}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    format!("S0.{}nm", text.replace('.', ","))
}

/// The wavelength (nm) of an emissive channel name, if it is one (`S0.` + number + `nm`).
pub fn parse_channel_name(name: &str) -> Option<f64> {
    let number = name.strip_prefix("S0.")?.strip_suffix("nm")?;
    let v: f64 = number.replace(',', ".").parse().ok()?;
    (v.is_finite() && v > 0.0).then_some(v)
}

/// Writes `spectra` (and `rgb`, the same film developed to linear sRGB) to `path`.
pub fn write_spectral_exr(
    path: &Path,
    spectra: &SpectralImage,
    rgb: &RgbImage,
) -> std::result::Result<(), OutputError> {
    let (w, h) = (spectra.width as usize, spectra.height as usize);
    let n = spectra.wavelengths.len();
    if rgb.width != spectra.width
        || rgb.height != spectra.height
        || spectra.values.len() != w * h * n
    {
        return Err(write_err(path, "spectral and RGB images differ in size"));
    }
    let mut channels: Vec<AnyChannel<FlatSamples>> = (0..3)
        .map(|c| {
            let name = ["R", "G", "B"][c];
            let samples = rgb.pixels.iter().map(|p| p[c]).collect();
            AnyChannel::new(name, FlatSamples::F32(samples))
        })
        .collect();
    for (b, &nm) in spectra.wavelengths.iter().enumerate() {
        let samples = spectra.values.iter().skip(b).step_by(n).copied().collect();
        channels.push(AnyChannel::new(
            channel_name(nm).as_str(),
            FlatSamples::F32(samples),
        ));
    }
    // The layout's two attributes, one in each of the header's two maps: a map writes its
    // entries in a per-process random order, so two in one map would make the same render
    // a different file each run.
    let text = |v: &str| AttributeValue::Text(Text::from(v));
    let mut layer_attributes = LayerAttributes::default();
    (layer_attributes.other).insert(Text::from("emissiveUnits"), text("W.m^-2.sr^-1"));
    let layer = Layer::new(
        (w, h),
        layer_attributes,
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels.into()),
    );
    let mut image = Image::from_layer(layer);
    (image.attributes.other).insert(Text::from("spectralLayoutVersion"), text("1.0"));
    write_atomic(path, |tmp| {
        image.write().to_file(tmp).map_err(|e| e.to_string())
    })
}

/// Reads the spectral channels of a file in this layout (and its RGB, when present).
pub fn read_spectral_exr(
    path: &Path,
) -> std::result::Result<(SpectralImage, Option<RgbImage>), OutputError> {
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| write_err(path, e))?;
    let layer = image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let as_f32 = |s: &FlatSamples| -> Vec<f32> {
        match s {
            FlatSamples::F32(v) => v.clone(),
            FlatSamples::F16(v) => v.iter().map(|x| x.to_f32()).collect(),
            FlatSamples::U32(v) => v.iter().map(|&x| x as f32).collect(),
        }
    };
    let mut bins: Vec<(f64, Vec<f32>)> = Vec::new();
    let mut rgb: [Option<Vec<f32>>; 3] = [None, None, None];
    for ch in &layer.channel_data.list {
        let name = ch.name.to_string();
        if let Some(nm) = parse_channel_name(&name) {
            bins.push((nm, as_f32(&ch.sample_data)));
        } else if let Some(c) = ["R", "G", "B"].iter().position(|&n| n == name) {
            rgb[c] = Some(as_f32(&ch.sample_data));
        }
    }
    if bins.is_empty() {
        return Err(write_err(
            path,
            "no spectral channels (S0.<wavelength>nm) in this file",
        ));
    }
    bins.sort_by(|a, b| a.0.total_cmp(&b.0));
    let n = bins.len();
    let mut values = vec![0.0f32; w * h * n];
    for (b, (_, samples)) in bins.iter().enumerate() {
        for (i, v) in samples.iter().enumerate().take(w * h) {
            values[i * n + b] = *v;
        }
    }
    let rgb = match rgb {
        [Some(r), Some(g), Some(b)] => Some(RgbImage {
            width: w as u32,
            height: h as u32,
            pixels: (0..w * h).map(|i| [r[i], g[i], b[i]]).collect(),
        }),
        _ => None,
    };
    Ok((
        SpectralImage {
            width: w as u32,
            height: h as u32,
            wavelengths: bins.iter().map(|b| b.0).collect(),
            values,
        },
        rgb,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channel_names_follow_the_layout_and_parse_back() {
        assert_eq!(channel_name(550.0), "S0.550nm");
        assert_eq!(channel_name(371.75), "S0.371,75nm");
        assert_eq!(parse_channel_name("S0.371,75nm"), Some(371.75));
        assert_eq!(parse_channel_name("S0.550nm"), Some(550.0));
        assert_eq!(parse_channel_name("R"), None);
        assert_eq!(parse_channel_name("T.550nm"), None);
        assert_eq!(parse_channel_name("S0.abcnm"), None);
    }

    #[test]
    fn a_spectral_exr_reads_back_exactly() {
        let (w, h, n) = (5u32, 3u32, 7usize);
        let wavelengths: Vec<f64> = (0..n)
            .map(|i| 360.0 + 67.142857 * (i as f64 + 0.5))
            .collect();
        let values: Vec<f32> = (0..(w * h) as usize * n)
            .map(|i| (i as f32 * 0.37).sin().abs() * 3.0)
            .collect();
        let spectra = SpectralImage {
            width: w,
            height: h,
            wavelengths,
            values,
        };
        let rgb = RgbImage {
            width: w,
            height: h,
            pixels: (0..w * h).map(|i| [i as f32, 0.5, -1.0]).collect(),
        };
        let path =
            std::env::temp_dir().join(format!("prismap-spectral-{}.exr", std::process::id()));
        write_spectral_exr(&path, &spectra, &rgb).unwrap();
        // The same image makes the same file, every time (its header included).
        let bytes = std::fs::read(&path).unwrap();
        for _ in 0..8 {
            write_spectral_exr(&path, &spectra, &rgb).unwrap();
            assert!(std::fs::read(&path).unwrap() == bytes, "another file");
        }
        let (back, back_rgb) = read_spectral_exr(&path).unwrap();
        let header = read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_file(&path)
            .unwrap();
        std::fs::remove_file(&path).unwrap();
        // (A reader may file a single layer's attributes under the image or the layer.)
        let attribute = |key: &str| {
            let key = Text::from(key);
            let image_attr = header.attributes.other.get(&key);
            image_attr
                .or(header.layer_data.attributes.other.get(&key))
                .cloned()
        };
        let text = |v: &str| Some(AttributeValue::Text(Text::from(v)));
        assert_eq!(attribute("spectralLayoutVersion"), text("1.0"));
        assert_eq!(attribute("emissiveUnits"), text("W.m^-2.sr^-1"));
        assert_eq!(back.values, spectra.values);
        for (a, b) in back.wavelengths.iter().zip(&spectra.wavelengths) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
        assert_eq!(back_rgb.unwrap(), rgb);
    }
}
