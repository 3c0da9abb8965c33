//! The report's figures: convergence curves and error against memory (plotters, with
//! egui's embedded Ubuntu font so no system fonts are needed), and the images side by
//! side with difference heat maps.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;

use super::{Report, ReportError, Run};
use crate::output::read_exr;
use crate::render::Image;
use crate::spectral::color::srgb8;

fn font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            epaint_default_fonts::UBUNTU_LIGHT,
        );
    });
}

fn err(e: impl std::fmt::Display) -> ReportError {
    ReportError::Plot(e.to_string())
}

/// A stable colour per (storage, bins).
fn colour(storage: &str, bins: usize) -> RGBColor {
    let i = super::BINS.iter().position(|b| *b == bins).unwrap_or(0);
    match storage {
        "rgb" => RGBColor(0, 0, 0),
        "full" => {
            let c = Palette99::pick(2 * i).to_rgba();
            RGBColor(c.0, c.1, c.2)
        }
        _ => {
            let c = Palette99::pick(2 * i + 1).to_rgba();
            RGBColor(c.0, c.1, c.2)
        }
    }
}

/// PSNR against rendering time, one curve per configuration (equal-time runs).
pub fn convergence(report: &Report, scene: &str, runs: &[Run]) -> Result<(), ReportError> {
    font();
    let path = report.out.join(format!("convergence-{scene}.png"));
    let chosen: Vec<&Run> = runs
        .iter()
        .filter(|r| {
            r.scene == scene
                && r.mode == "equal-time"
                && (r.storage == "rgb" || [4, 8, 20, 100].contains(&r.bins))
        })
        .filter(|r| !r.curve.is_empty())
        .collect();
    let finite = |v: f64| v.is_finite();
    let ys: Vec<f64> = chosen
        .iter()
        .flat_map(|r| r.curve.iter().map(|c| c.1))
        .filter(|v| finite(*v))
        .collect();
    let xs: Vec<f64> = chosen
        .iter()
        .flat_map(|r| r.curve.iter().map(|c| c.0))
        .collect();
    let (ymin, ymax) = ys.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, v| {
        (a.0.min(*v), a.1.max(*v))
    });
    let xmax = xs.iter().cloned().fold(0.0, f64::max).max(1e-3);
    let root = BitMapBackend::new(&path, (900, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("{scene}: error against time (higher is better)"),
            ("sans-serif", 24),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..xmax * 1.02, (ymin - 1.0).min(ymax - 2.0)..ymax + 1.0)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("rendering time (s)")
        .y_desc("PSNR against the reference (dB)")
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(err)?;
    for r in chosen {
        let c = colour(&r.storage, r.bins);
        let label = if r.storage == "rgb" {
            "rgb".to_string()
        } else {
            format!("{} {}", r.storage, r.bins)
        };
        let style = if r.storage == "compact" {
            c.stroke_width(2)
        } else {
            c.stroke_width(1)
        };
        chart
            .draw_series(LineSeries::new(
                r.curve.iter().filter(|p| p.1.is_finite()).cloned(),
                style,
            ))
            .map_err(err)?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .position(SeriesLabelPosition::LowerRight)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

/// PSNR against photon-map bytes at equal photons: full storage climbs to the right as
/// bins grow, compact stays put.
pub fn memory(report: &Report, scene: &str, runs: &[Run]) -> Result<(), ReportError> {
    font();
    let path = report.out.join(format!("memory-{scene}.png"));
    let pts: Vec<&Run> = runs
        .iter()
        .filter(|r| r.scene == scene && r.mode == "equal-photons" && r.psnr_db.is_finite())
        .collect();
    if pts.is_empty() {
        return Ok(());
    }
    let (xmin, xmax) = pts.iter().fold((f64::INFINITY, 0.0f64), |a, r| {
        let mb = r.photon_map_bytes as f64 / 1e6;
        (a.0.min(mb), a.1.max(mb))
    });
    let (ymin, ymax) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, r| {
        (a.0.min(r.psnr_db), a.1.max(r.psnr_db))
    });
    let root = BitMapBackend::new(&path, (900, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("{scene}: error against photon-map memory (equal photons)"),
            ("sans-serif", 24),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(
            (xmin * 0.8..xmax * 1.25).log_scale(),
            (ymin - 2.0)..(ymax + 2.0),
        )
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("photon maps (MB, log scale)")
        .y_desc("PSNR (dB)")
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(err)?;
    for (storage, c) in [("full", RED), ("compact", BLUE), ("rgb", BLACK)] {
        let series: Vec<(f64, f64, usize)> = pts
            .iter()
            .filter(|r| r.storage == storage)
            .map(|r| (r.photon_map_bytes as f64 / 1e6, r.psnr_db, r.bins))
            .collect();
        chart
            .draw_series(
                series
                    .iter()
                    .map(|&(x, y, _)| Circle::new((x, y), 5, c.filled())),
            )
            .map_err(err)?
            .label(storage)
            .legend(move |(x, y)| Circle::new((x + 8, y), 5, c.filled()));
        if storage != "rgb" {
            chart
                .draw_series(series.iter().map(|&(x, y, b)| {
                    EmptyElement::at((x, y))
                        + Text::new(
                            format!("{b}"),
                            (7, -16),
                            ("sans-serif", 13).into_font().color(&c),
                        )
                }))
                .map_err(err)?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

fn display(img: &Image, x: u32, y: u32) -> [u8; 3] {
    img.get(x, y).map(srgb8)
}

/// Reference, full 8 bins, compact 8 bins and RGB side by side (top), and the heat maps
/// of their display difference to the reference ×4 (bottom; black = equal).
pub fn images(report: &Report, scene: &str, reference: &Image) -> Result<(), ReportError> {
    let names = ["full-8", "compact-8", "rgb-3"];
    let mut imgs = vec![("reference".to_string(), reference.clone())];
    for n in names {
        let p = report
            .runs_dir()
            .join(format!("{scene}-equal-photons-{n}.exr"));
        if Path::new(&p).exists() {
            imgs.push((n.to_string(), read_exr(&p).map_err(err)?));
        }
    }
    let (w, h) = (reference.width, reference.height);
    let gap = 4;
    let cols = imgs.len() as u32;
    let mut out =
        image::RgbImage::from_pixel(cols * (w + gap), 2 * (h + gap), image::Rgb([255, 255, 255]));
    for (i, (_, img)) in imgs.iter().enumerate() {
        let ox = i as u32 * (w + gap);
        for y in 0..h {
            for x in 0..w {
                out.put_pixel(ox + x, y, image::Rgb(display(img, x, y)));
                if i > 0 {
                    let a = display(img, x, y);
                    let b = display(reference, x, y);
                    let d = (0..3)
                        .map(|c| (a[c] as f32 - b[c] as f32).abs())
                        .fold(0.0, f32::max)
                        / 255.0;
                    out.put_pixel(ox + x, h + gap + y, image::Rgb(heat((d * 4.0).min(1.0))));
                }
            }
        }
    }
    out.save(report.out.join(format!("images-{scene}.png")))
        .map_err(err)?;
    Ok(())
}

/// Black → red → yellow → white.
fn heat(t: f32) -> [u8; 3] {
    let r = (t * 3.0).min(1.0);
    let g = (t * 3.0 - 1.0).clamp(0.0, 1.0);
    let b = (t * 3.0 - 2.0).clamp(0.0, 1.0);
    [r, g, b].map(|v| (v * 255.0) as u8)
}
