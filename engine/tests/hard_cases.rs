//! Numerical hard cases (issue #5), each named for what it proves. See TESTING.md.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use glam::Vec3;
use prismap_engine::materials::{refract, scatter_dielectric};
use prismap_engine::photon::{PhotonBatch, PhotonMap, Record, Storage};
use prismap_engine::render::{RenderSession, RenderSettings};
use prismap_engine::sampling::chi2::chi2_p_value;
use prismap_engine::sampling::{Purpose, Rng, uniform_triangle};
use prismap_engine::scene::{self, Camera, Material, MaterialKind, Scene};
use prismap_engine::spectral::{BinGrid, IorModel, Spectrum};

fn small(storage: Storage, bins: usize) -> RenderSettings {
    RenderSettings {
        bins,
        storage,
        width: 24,
        height: 24,
        photons_per_pass: 5_000,
        final_gather_rays: 2,
        ..RenderSettings::default()
    }
}

#[test]
fn camera_inside_glass_renders_finite() {
    // The camera sits inside the prism: every ray starts in glass, exits through TIR-prone faces.
    let mut s = scene::load_builtin("prism").unwrap();
    s.camera = Camera::look_at(
        Vec3::new(0.0, 0.1, 0.0),
        Vec3::new(0.0, 0.1, 1.0),
        Vec3::Y,
        1.0,
    );
    for (storage, bins) in [
        (Storage::Full, 16),
        (Storage::Compact, 100),
        (Storage::Rgb, 3),
    ] {
        let mut r = RenderSession::new(&s, small(storage, bins)).unwrap();
        for _ in 0..2 {
            r.run_pass().unwrap();
        }
        assert_eq!(r.film().dropped_samples(), 0, "{storage:?}");
        // Finite everywhere; luminance never negative (spectral colours outside the sRGB
        // gamut legitimately have negative channels until display).
        for p in r.image().pixels {
            assert!(p.iter().all(|v| v.is_finite()), "{p:?}");
            let y = prismap_engine::spectral::color::luminance(p.map(f64::from));
            assert!(y >= -1e-4, "{storage:?}: luminance {y}");
        }
    }
}

#[test]
fn glass_never_adds_energy_total_internal_reflection_included() {
    // Photon flux through a smooth dielectric is only redirected (importance transport):
    // over many random incidences, from either side, the direction stays unit and
    // transmission happens only where Snell allows it.
    let mut rng = Rng::stream(3, 0, 0, Purpose::Photon);
    let n = Vec3::Z;
    for _ in 0..100_000 {
        let [u, v] = rng.next_2d();
        let cos = u.max(1e-7);
        let d_in = Vec3::new((1.0 - cos * cos).sqrt(), 0.0, -cos);
        let d = if v < 0.5 { d_in } else { -d_in }; // from inside half the time
        let eta = 1.0 + 0.9 * rng.next_f32();
        let ev = scatter_dielectric(d, n, eta, rng.next_f32());
        assert!(ev.dir.is_finite() && (ev.dir.length() - 1.0).abs() < 1e-4);
        if d.dot(n) > 0.0 && ev.transmitted {
            // Leaving the glass: allowed only below the critical angle.
            let sin_i = (1.0 - d.dot(n).powi(2)).sqrt();
            assert!(
                eta * sin_i < 1.0 + 1e-4,
                "transmitted beyond the critical angle"
            );
        }
    }
}

#[test]
fn dispersion_deviation_per_bin_follows_snell_with_sellmeier() {
    // Each bin refracts with the glass's Sellmeier index at its centre wavelength.
    let glass = IorModel::glass("N-SF11").unwrap();
    for bins in [1usize, 2, 4, 100, 1000] {
        let grid = BinGrid::with_bins(bins).unwrap();
        let mut s = scene::load_builtin("prism").unwrap();
        s.lights.truncate(1);
        let spectral = prismap_engine::scene::SpectralScene::new(&s, grid.clone());
        let eta = spectral
            .materials
            .iter()
            .find_map(|m| match &m.kind {
                prismap_engine::scene::SurfaceKind::Dielectric { eta, .. } => Some(eta.clone()),
                _ => None,
            })
            .unwrap();
        assert_eq!(eta.len(), bins);
        let d = Vec3::new(0.6, 0.0, -0.8);
        let mut previous: Option<f32> = None;
        for (i, e) in eta.iter().enumerate() {
            let want = glass.eta(grid.centers()[i]) as f32;
            assert!((e - want).abs() < 1e-6);
            let t = refract(d, Vec3::Z, 1.0 / e).unwrap();
            assert!((0.6 - e * t.x).abs() < 1e-5, "Snell: sin θi = n sin θt");
            // Longer wavelength, lower index, less bending: the refracted angle grows.
            if let Some(p) = previous {
                assert!(t.x >= p - 1e-7);
            }
            previous = Some(t.x);
        }
    }
}

#[test]
fn zero_and_non_finite_flux_is_never_stored() {
    let grid = BinGrid::with_bins(8).unwrap();
    for storage in [Storage::Full, Storage::Compact] {
        let mut b = PhotonBatch::new(storage.record(), &grid);
        b.push(&grid, Vec3::ZERO, Vec3::Z, &[0.0; 8]);
        b.push(
            &grid,
            Vec3::ZERO,
            Vec3::Z,
            &[f32::NAN, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        b.push(
            &grid,
            Vec3::ZERO,
            Vec3::Z,
            &[f32::INFINITY, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert!(b.is_empty(), "{storage:?}");
        b.push(
            &grid,
            Vec3::ZERO,
            Vec3::Z,
            &[0.0, 0.0, 1e-40, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(b.len(), 1, "a denormal spike is still light");
    }
}

#[test]
fn photons_far_outside_the_scene_and_empty_maps_are_harmless() {
    let grid = BinGrid::with_bins(4).unwrap();
    let mut b = PhotonBatch::new(Record::Compact, &grid);
    for p in [
        Vec3::splat(1e30),
        Vec3::splat(-1e30),
        Vec3::new(1e-30, 0.0, 0.0),
    ] {
        b.push(&grid, p, Vec3::Z, &[1.0, 0.0, 0.0, 0.0]);
    }
    let map = PhotonMap::build(b);
    let mut out = vec![0.0; 4];
    assert_eq!(map.gather(&grid, Vec3::ZERO, Vec3::Z, 1.0, &mut out), 1);
    assert_eq!(
        map.gather(&grid, Vec3::splat(1e30), Vec3::Z, 1e10, &mut out),
        1
    );
    let empty = PhotonMap::build(PhotonBatch::new(Record::Full, &grid));
    assert_eq!(empty.gather(&grid, Vec3::ZERO, Vec3::Z, 1e9, &mut out), 0);
    assert_eq!(empty.typical_knn_radius(10, 10), None);
}

#[test]
fn zero_area_light_is_skipped_and_power_unchanged() {
    let mut s = scene::load_builtin("cornell-box").unwrap();
    let light_mat = s
        .materials
        .iter()
        .position(|m| m.emission.is_some())
        .unwrap() as u32;
    let before: f32 = prismap_engine::scene::SpectralScene::new(&s, BinGrid::with_bins(8).unwrap())
        .lights
        .iter()
        .map(|l| l.power)
        .sum();
    // Add emissive degenerate triangles (collinear and duplicate vertices).
    s.triangles.push([Vec3::ZERO, Vec3::X, 2.0 * Vec3::X]);
    s.triangles.push([Vec3::Y, Vec3::Y, Vec3::Y]);
    s.triangle_material.extend([light_mat, light_mat]);
    let spectral = prismap_engine::scene::SpectralScene::new(&s, BinGrid::with_bins(8).unwrap());
    let after: f32 = spectral.lights.iter().map(|l| l.power).sum();
    assert_eq!(before, after);
    let mut r = RenderSession::new(&s, small(Storage::Compact, 8)).unwrap();
    r.run_pass().unwrap();
    assert_eq!(r.film().dropped_samples(), 0);
}

#[test]
fn uniform_triangle_sampling_passes_chi_square() {
    // Light sampling picks points uniformly on triangles: 10×10 barycentric cells.
    let mut rng = Rng::stream(11, 0, 0, Purpose::Photon);
    let cells = 10;
    let mut counts = vec![0f64; cells * cells];
    let n = 400_000;
    for _ in 0..n {
        let (b1, b2) = uniform_triangle(rng.next_2d());
        assert!(b1 >= 0.0 && b2 >= 0.0 && b1 + b2 <= 1.0 + 1e-6);
        // Map the triangle to the unit square (b1 + b2 ≤ 1 → fold) so cells have equal area.
        let (x, y) = (b1, b2);
        let i = ((x * cells as f32) as usize).min(cells - 1);
        let j = ((y * cells as f32) as usize).min(cells - 1);
        counts[i * cells + j] += 1.0;
    }
    // Expected: the area of each cell inside the triangle x + y ≤ 1, times n × 2.
    let mut stat = 0.0;
    let mut dof = 0;
    for i in 0..cells {
        for j in 0..cells {
            let area = cell_area_under_diagonal(i, j, cells);
            let e = area * 2.0 * n as f64;
            if e < 5.0 {
                assert!(
                    counts[i * cells + j] <= 5.0 + 10.0 * e,
                    "samples outside the triangle"
                );
                continue;
            }
            stat += (counts[i * cells + j] - e).powi(2) / e;
            dof += 1;
        }
    }
    let p = chi2_p_value(stat, dof - 1);
    assert!(p > 1e-3, "p = {p}");
}

fn cell_area_under_diagonal(i: usize, j: usize, cells: usize) -> f64 {
    // Area of [i, i+1]×[j, j+1]/cells inside x + y ≤ 1, by supersampling.
    let m = 64;
    let mut inside = 0;
    for a in 0..m {
        for b in 0..m {
            let x = (i as f64 + (a as f64 + 0.5) / m as f64) / cells as f64;
            let y = (j as f64 + (b as f64 + 0.5) / m as f64) / cells as f64;
            if x + y <= 1.0 {
                inside += 1;
            }
        }
    }
    inside as f64 / (m * m) as f64 / (cells * cells) as f64
}

#[test]
fn wavelength_splitting_picks_bins_in_proportion_to_flux_chi_square() {
    // The wavelength sampler: stratified single-bin splits, counted per bin.
    let flux: Vec<f32> = (0..12).map(|i| 1.0 + ((i * 7) % 5) as f32).collect();
    let total: f64 = flux.iter().map(|&v| v as f64).sum();
    let mut counts = vec![0f64; flux.len()];
    let trials = 50_000;
    for t in 0..trials {
        let mut rng = Rng::stream(5, 0, t, Purpose::Photon);
        for piece in prismap_engine::photon::split_dispersive(&flux, 1, &mut rng) {
            let bin = piece.iter().position(|v| *v > 0.0).unwrap();
            counts[bin] += 1.0;
        }
    }
    let stat: f64 = counts
        .iter()
        .zip(&flux)
        .map(|(c, f)| {
            let e = trials as f64 * *f as f64 / total;
            (c - e).powi(2) / e
        })
        .sum();
    let p = chi2_p_value(stat, flux.len() - 1);
    assert!(p > 1e-3, "p = {p}");
}

#[test]
fn cancelling_a_pass_stops_it_promptly_and_leaves_the_film_unchanged() {
    let s = scene::load_builtin("cornell-box").unwrap();
    let settings = RenderSettings {
        width: 256,
        height: 256,
        photons_per_pass: 400_000,
        final_gather_rays: 16,
        ..RenderSettings::default()
    };
    let mut r = RenderSession::new(&s, settings).unwrap();
    let flag: Arc<AtomicBool> = r.cancel_flag();
    let t = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(150));
        let at = Instant::now();
        flag.store(true, Ordering::Relaxed);
        at
    });
    let result = r.run_pass();
    let stopped = Instant::now();
    let cancelled_at = t.join().unwrap();
    assert!(result.is_err(), "the pass was cancelled");
    let latency = stopped.duration_since(cancelled_at);
    println!(
        "cancel → pass stopped: {:.1} ms",
        latency.as_secs_f64() * 1e3
    );
    // One photon chunk or one image row: milliseconds. A generous bound for a noisy machine.
    assert!(latency < Duration::from_millis(500), "{latency:?}");
    assert_eq!(r.film().passes(), 0);
    assert!(r.image().pixels.iter().all(|p| *p == [0.0; 3]));
}

#[test]
fn mutated_scene_files_never_panic() {
    // A seeded corpus of byte mutations of the shipped scenes (the bounded stand-in for a
    // fuzzing run): every one must come back as Ok or as an error, never a panic.
    let seeds: Vec<Vec<u8>> = scene::BUILTIN.iter().map(|(_, b)| b.to_vec()).collect();
    let mut rng = Rng::stream(2024, 0, 0, Purpose::Photon);
    let mut errors = 0;
    for case in 0..600 {
        let mut bytes = seeds[case % seeds.len()].clone();
        let edits = 1 + (rng.next_u32() % 8) as usize;
        for _ in 0..edits {
            let at = rng.next_u32() as usize % bytes.len();
            match rng.next_u32() % 4 {
                0 => bytes[at] = rng.next_u32() as u8,
                1 => bytes[at] = b"0123456789-.e,:[]{}\""[rng.next_u32() as usize % 20],
                2 => bytes.truncate(at.max(1)),
                _ => {
                    let len = (rng.next_u32() % 16) as usize;
                    let chunk: Vec<u8> = bytes[at..(at + len).min(bytes.len())].to_vec();
                    bytes.splice(at..at, chunk);
                }
            }
        }
        let result =
            std::panic::catch_unwind(|| scene::load_from_slice(&bytes, "mutant.gltf", None));
        match result {
            Ok(Ok(_)) => {}
            Ok(Err(e)) => {
                errors += 1;
                assert!(e.to_string().starts_with("mutant.gltf"), "{e}");
            }
            Err(_) => panic!("case {case} panicked through the loader"),
        }
    }
    assert!(
        errors > 100,
        "the mutations must break most files ({errors})"
    );
}

#[test]
fn a_black_clamped_negative_emitter_renders_finite_and_black() {
    let s = Scene {
        name: "dark".into(),
        triangles: vec![[Vec3::ZERO, Vec3::X, Vec3::Y]],
        triangle_material: vec![0],
        shading_normals: vec![],
        triangle_uvs: vec![],
        triangle_colors: vec![],
        triangle_tangents: vec![],
        materials: vec![Material {
            name: "m".into(),
            kind: MaterialKind::Diffuse {
                reflectance: Spectrum::reflectance([0.5; 3]),
            },
            emission: Some(Spectrum::reflectance([-1.0, -1.0, -1.0])),
            volume: None,
            base_color_texture: None,
            emissive_texture: None,
            vertex_colors: false,
            alpha_mask: None,
            normal_texture: None,
        }],
        lights: vec![],
        camera: Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, 1.0),
        environment: None,
        warnings: vec![],
    };
    // A black (clamped negative) emitter gives no light: rendering is finite and black.
    let mut r = RenderSession::new(&s, small(Storage::Compact, 8)).unwrap();
    r.run_pass().unwrap();
    assert!(r.image().pixels.iter().all(|p| *p == [0.0; 3]));
}

#[test]
fn photon_maps_never_exceed_the_budget_and_photons_adapt() {
    let s = scene::load_builtin("cornell-box").unwrap();
    let budget = 300_000;
    for storage in [Storage::Full, Storage::Compact] {
        let settings = RenderSettings {
            photons_per_pass: 100_000,
            photon_budget_bytes: Some(budget),
            ..small(storage, 100)
        };
        let mut r = RenderSession::new(&s, settings).unwrap();
        for _ in 0..3 {
            r.run_pass().unwrap();
            assert!(
                r.memory().photon_maps <= budget,
                "{storage:?}: {} > {budget}",
                r.memory().photon_maps
            );
            assert!(r.stats().photons_last_pass < 100_000);
        }
        assert!(
            r.skipped()
                .iter()
                .any(|n| n.contains("photons per pass lowered")),
            "{:?}",
            r.skipped()
        );
        println!(
            "{storage:?}: {} photons per pass fit {budget} bytes",
            r.stats().photons_last_pass
        );
    }
    // A budget below the minimum is refused, naming the flag the user sets it with.
    let bad = RenderSettings {
        photon_budget_bytes: Some(10),
        ..small(Storage::Compact, 8)
    };
    assert!(
        bad.validate()
            .unwrap_err()
            .to_string()
            .contains("--photon-budget")
    );
}

#[test]
fn aim_targets_cover_coincident_degenerate_far_and_scattered_glass() {
    // The prism plus hard specular geometry: 5 000 triangles collapsed onto one point, a
    // collinear sliver 40 m away, and twenty small glass tetrahedra in a row. The aim
    // targets stay at most 8 finite spheres that hold every specular vertex, and a pass
    // renders finite pixels with its caustic-only photons aimed.
    let mut s = scene::load_builtin("prism").unwrap();
    let glass = s
        .materials
        .iter()
        .position(|m| matches!(m.kind, MaterialKind::Dielectric { .. }))
        .unwrap() as u32;
    let mut add = |t: [Vec3; 3]| {
        s.triangles.push(t);
        s.triangle_material.push(glass);
    };
    let p = Vec3::new(0.5, 0.05, 0.5);
    for _ in 0..5_000 {
        add([p, p, p]);
    }
    add([
        Vec3::new(40.0, 0.1, 0.0),
        Vec3::new(40.5, 0.1, 0.0),
        Vec3::new(41.0, 0.1, 0.0),
    ]);
    for i in 0..20 {
        let o = Vec3::new(-1.0 + 0.1 * i as f32, 0.02, -0.6);
        let (a, b, c, d) = (
            o,
            o + 0.03 * Vec3::X,
            o + 0.03 * Vec3::Z,
            o + 0.03 * Vec3::Y,
        );
        for t in [[a, c, b], [a, b, d], [b, c, d], [c, a, d]] {
            add(t);
        }
    }
    let spectral = scene::SpectralScene::new(&s, BinGrid::with_bins(8).unwrap());
    let targets = spectral.lights.targets();
    println!("{} targets: {targets:?}", targets.len());
    assert!((1..=8).contains(&targets.len()), "{targets:?}");
    for t in targets {
        assert!(
            t.center.is_finite() && t.radius.is_finite() && t.radius > 0.0,
            "{t:?}"
        );
    }
    for (tri, &m) in s.triangles.iter().zip(&s.triangle_material) {
        if m == glass {
            for v in tri {
                assert!(
                    targets.iter().any(|t| v.distance(t.center) <= t.radius),
                    "{v} outside every target {targets:?}"
                );
            }
        }
    }
    assert!(spectral.lights.aims(), "the ceiling panel aims");
    let mut r = RenderSession::new(&s, small(Storage::Compact, 8)).unwrap();
    r.run_pass().unwrap();
    assert_eq!(r.film().dropped_samples(), 0);
    assert!(r.stats().caustic_photons_aimed);
}
