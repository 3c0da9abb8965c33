//! Colour that round-trips (issue #14): the colours a scene gives come back out of the
//! renderer — a 24-patch chart seen as emitters and as reflectors under D65, and the
//! Cornell box's light — with Jakob–Hanika upsampling, and how far Smits' (the paper's)
//! misses them.

use glam::Vec3;
use prismap_engine::photon::Storage;
use prismap_engine::render::{RenderSession, RenderSettings};
use prismap_engine::scene::{self, Camera, Material, MaterialKind, Scene};
use prismap_engine::spectral::{Spectrum, Upsampling};

/// The ColorChecker Classic's 24 patches as 8-bit sRGB (the values X-Rite publishes for
/// the chart under D65), row by row from dark skin to black.
const CHART: [(&str, [u8; 3]); 24] = [
    ("dark skin", [115, 82, 68]),
    ("light skin", [194, 150, 130]),
    ("blue sky", [98, 122, 157]),
    ("foliage", [87, 108, 67]),
    ("blue flower", [133, 128, 177]),
    ("bluish green", [103, 189, 170]),
    ("orange", [214, 126, 44]),
    ("purplish blue", [80, 91, 166]),
    ("moderate red", [193, 90, 99]),
    ("purple", [94, 60, 108]),
    ("yellow green", [157, 188, 64]),
    ("orange yellow", [224, 163, 46]),
    ("blue", [56, 61, 150]),
    ("green", [70, 148, 73]),
    ("red", [175, 54, 60]),
    ("yellow", [231, 199, 31]),
    ("magenta", [187, 86, 149]),
    ("cyan", [8, 133, 161]),
    ("white 9.5", [243, 243, 242]),
    ("neutral 8", [200, 200, 200]),
    ("neutral 6.5", [160, 160, 160]),
    ("neutral 5", [122, 122, 121]),
    ("neutral 3.5", [85, 85, 85]),
    ("black 2", [52, 52, 52]),
];

fn linear(c: u8) -> f64 {
    let v = c as f64 / 255.0;
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

const COLS: usize = 6;
const DIST: f32 = 10.0;
const W: u32 = 192;
const H: u32 = 128;

/// Patch `i`'s centre: a 6 × 4 grid of unit squares 1.2 apart at z = 10.
fn centre(i: usize) -> Vec3 {
    let (c, r) = ((i % COLS) as f32, (i / COLS) as f32);
    Vec3::new(-3.0 + 0.6 + 1.2 * c, 1.8 - 1.2 * r, DIST)
}

fn camera() -> Camera {
    let mut cam = Camera::look_at(Vec3::ZERO, Vec3::Z, Vec3::Y, 2.0 * (0.26f32).atan());
    cam.aspect = Some(W as f32 / H as f32);
    cam
}

/// The pixel patch `i`'s centre projects to (world +x is image left).
fn pixel(i: usize) -> (u32, u32) {
    let p = centre(i);
    let t = 0.26 * DIST;
    let nx = -p.x / (t * W as f32 / H as f32);
    let ny = p.y / t;
    (
        ((nx + 1.0) * 0.5 * W as f32) as u32,
        ((1.0 - ny) * 0.5 * H as f32) as u32,
    )
}

/// The chart: each patch a square facing the camera, made by `material(rgb)`.
fn chart(material: impl Fn([f64; 3]) -> (MaterialKind, Option<Spectrum>)) -> Scene {
    let mut triangles = Vec::new();
    let mut triangle_material = Vec::new();
    let mut materials = Vec::new();
    for (i, (name, srgb)) in CHART.iter().enumerate() {
        let (kind, emission) = material(srgb.map(linear));
        materials.push(Material {
            name: name.to_string(),
            kind,
            emission,
            volume: None,
            base_color_texture: None,
            emissive_texture: None,
            vertex_colors: false,
            alpha_mask: None,
            normal_texture: None,
        });
        let c = centre(i);
        let p = |x: f32, y: f32| c + Vec3::new(x, y, 0.0);
        // Counter-clockwise seen from −z (the camera): facing it.
        triangles.push([p(-0.5, -0.5), p(-0.5, 0.5), p(0.5, 0.5)]);
        triangles.push([p(-0.5, -0.5), p(0.5, 0.5), p(0.5, -0.5)]);
        triangle_material.extend([i as u32; 2]);
    }
    Scene {
        name: "chart".into(),
        triangles,
        triangle_material,
        shading_normals: vec![],
        triangle_uvs: vec![],
        triangle_colors: vec![],
        triangle_tangents: vec![],
        materials,
        lights: vec![],
        camera: camera(),
        environment: None,
        warnings: vec![],
    }
}

/// The mean linear sRGB of a 9 × 9 block at each patch's centre after `passes`.
fn render_chart(scene: &Scene, spectra: Upsampling, passes: usize) -> Vec<[f64; 3]> {
    let settings = RenderSettings {
        bins: 20,
        storage: Storage::Full,
        spectra,
        width: W,
        height: H,
        photons_per_pass: 20_000,
        final_gather_rays: 16,
        ..RenderSettings::default()
    };
    let mut r = RenderSession::new(scene, settings).unwrap();
    for _ in 0..passes {
        r.run_pass().unwrap();
    }
    let img = r.image();
    (0..CHART.len())
        .map(|i| {
            let (x0, y0) = pixel(i);
            let mut sum = [0.0f64; 3];
            for y in y0 - 4..=y0 + 4 {
                for x in x0 - 4..=x0 + 4 {
                    let v = img.get(x, y);
                    for c in 0..3 {
                        sum[c] += v[c] as f64 / 81.0;
                    }
                }
            }
            sum
        })
        .collect()
}

/// Per patch: the largest channel error against the patch's own colour.
fn errors(got: &[[f64; 3]]) -> Vec<f64> {
    CHART
        .iter()
        .zip(got)
        .map(|((_, srgb), g)| {
            let want = srgb.map(linear);
            (0..3).map(|c| (g[c] - want[c]).abs()).fold(0.0, f64::max)
        })
        .collect()
}

fn print_table(what: &str, jh: &[f64], smits: &[f64]) {
    println!("{what}: largest channel error per patch (linear sRGB, 0–1), jh | smits");
    for (i, (name, _)) in CHART.iter().enumerate() {
        println!("  {name:>14}: {:.4} | {:.4}", jh[i], smits[i]);
    }
}

#[test]
fn a_colour_chart_seen_as_emitters_keeps_its_colours() {
    // Emitters seen directly: no transport noise, only the upsampling and the 20 bins.
    let scene = chart(|rgb| {
        (
            MaterialKind::Diffuse {
                reflectance: Spectrum::Constant(0.0),
            },
            Some(Spectrum::illuminant(rgb)),
        )
    });
    let jh = errors(&render_chart(&scene, Upsampling::JakobHanika, 1));
    let smits = errors(&render_chart(&scene, Upsampling::Smits, 1));
    print_table("emitters", &jh, &smits);
    let worst = |e: &[f64]| e.iter().cloned().fold(0.0, f64::max);
    // Measured at 20 bins: jh worst < 0.0001 (the grid keeps an emitter's XYZ); Smits
    // worst 0.053 (yellow, its blue).
    assert!(worst(&jh) < 0.001, "jh worst {}", worst(&jh));
    assert!(worst(&smits) > 5.0 * worst(&jh));
}

#[test]
fn a_colour_chart_under_d65_reflects_its_colours() {
    // Diffuse patches side by side under a uniform D65 sky of radiance 1: each has radiance
    // ρ(λ)·D65, whose colour is the patch's own (with noise: 81 pixels averaged).
    let lit = |mut s: Scene| {
        s.environment = Some(Spectrum::illuminant([1.0; 3]));
        s
    };
    let scene = lit(chart(|rgb| {
        (
            MaterialKind::Diffuse {
                reflectance: Spectrum::reflectance(rgb),
            },
            None,
        )
    }));
    let jh = errors(&render_chart(&scene, Upsampling::JakobHanika, 6));
    let smits = errors(&render_chart(&scene, Upsampling::Smits, 6));
    print_table("reflectors under D65", &jh, &smits);
    // Measured: jh worst 0.0083 (red; 20 bins' mean of a steep spectrum, and noise),
    // Smits worst 0.059 (yellow).
    let worst = |e: &[f64]| e.iter().cloned().fold(0.0, f64::max);
    assert!(worst(&jh) < 0.012, "jh worst {}", worst(&jh));
    assert!(worst(&smits) > worst(&jh));
}

#[test]
fn the_cornell_light_renders_as_the_colour_it_was_given() {
    // The Cornell box's light, (17, 12, 4) in linear sRGB, seen directly: within 1 % per
    // channel with Jakob–Hanika; Smits' blue is 20 % high (issue #14). Measured: jh
    // (17.13, 12.08, 4.02) — the light's own diffuse reflectance adds the box's light
    // bounced back, +0.6 %, as in Mitsuba's (17.11, 12.07, 4.01); Smits (16.98, 12.08, 4.77).
    let scene = scene::load_any("cornell-box").unwrap();
    for spectra in Upsampling::ALL {
        let settings = RenderSettings {
            bins: 20,
            spectra,
            width: 128,
            height: 128,
            photons_per_pass: 10_000,
            ..RenderSettings::default()
        };
        let mut r = RenderSession::new(&scene, settings).unwrap();
        r.run_pass().unwrap();
        let img = r.image();
        // The light's underside covers rows 16–20 and columns 53–75 of the 128² view.
        let mut sum = [0.0f64; 3];
        for y in 17..=19 {
            for x in 60..=68 {
                let v = img.get(x, y);
                for c in 0..3 {
                    sum[c] += v[c] as f64 / 27.0;
                }
            }
        }
        let rel = [17.0, 12.0, 4.0];
        let err: Vec<f64> = (0..3).map(|c| sum[c] / rel[c] - 1.0).collect();
        println!(
            "{}: light renders as ({:.3}, {:.3}, {:.3}), relative error {:+.2} / {:+.2} / {:+.2} %",
            spectra.name(),
            sum[0],
            sum[1],
            sum[2],
            100.0 * err[0],
            100.0 * err[1],
            100.0 * err[2]
        );
        if spectra == Upsampling::JakobHanika {
            assert!(err.iter().all(|e| e.abs() < 0.01), "{sum:?}");
        } else {
            assert!(err[2] > 0.1, "Smits' blue is high: {sum:?}");
        }
    }
}

#[test]
fn a_spectral_exr_of_a_render_reads_back_as_the_film() {
    // `-o image.exr --spectral`: every bin of every pixel, and the RGB layers, written in
    // Fichet et al.'s layout and read back unchanged; each pixel's spectrum converts to
    // the RGB the film shows.
    use prismap_engine::output::{SpectralImage, read_spectral_exr, write_spectral_exr};
    let scene = scene::load_any("prism").unwrap();
    let settings = RenderSettings {
        bins: 12,
        width: 48,
        height: 27,
        photons_per_pass: 20_000,
        ..RenderSettings::default()
    };
    let mut r = RenderSession::new(&scene, settings).unwrap();
    r.keep_spectra(true);
    assert!(r.skipped().iter().all(|s| !s.starts_with("spectral film")));
    for _ in 0..2 {
        r.run_pass().unwrap();
    }
    let film = r.spectral_film().unwrap();
    assert_eq!(film.passes(), 2);
    let grid = r.scene().grid.clone();
    let spectra = SpectralImage {
        width: film.width(),
        height: film.height(),
        wavelengths: grid.centers().to_vec(),
        values: film.develop(),
    };
    let rgb = r.image();
    let path = std::env::temp_dir().join(format!("prismap-render-{}.exr", std::process::id()));
    write_spectral_exr(&path, &spectra, &rgb).unwrap();
    let (back, back_rgb) = read_spectral_exr(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    assert_eq!(back.values, spectra.values);
    assert_eq!(back.wavelengths.len(), 12);
    assert_eq!(back_rgb.as_ref(), Some(&rgb));
    let mut lit = 0;
    for y in 0..rgb.height {
        for x in 0..rgb.width {
            let from_spectrum = grid.to_linear_srgb(back.pixel(x, y));
            let shown = rgb.get(x, y);
            let scale = shown.iter().fold(1e-3f32, |m, v| m.max(v.abs()));
            for c in 0..3 {
                assert!(
                    (from_spectrum[c] - shown[c]).abs() <= 1e-4 * scale,
                    "({x},{y}): {from_spectrum:?} vs {shown:?}"
                );
            }
            lit += (shown[1] > 0.01) as usize;
        }
    }
    assert!(lit > 100, "{lit} lit pixels");
    // Freed on request.
    r.keep_spectra(false);
    assert!(r.spectral_film().is_none());
}
