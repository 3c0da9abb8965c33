//! Physics through the whole photon mapper: a furnace with a closed-form answer.

use glam::Vec3;
use prismap::photon::Storage;
use prismap::render::{RenderSession, RenderSettings};
use prismap::scene::{Camera, Material, MaterialKind, Scene};
use prismap::spectral::Spectrum;
use prismap::spectral::color::luminance;

/// A closed box whose inner walls all emit `le` and reflect `rho` (inward normals).
fn furnace(le: f64, rho: f64) -> Scene {
    let (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
    let c = |x: bool, y: bool, z: bool| {
        Vec3::new(
            if x { hi.x } else { lo.x },
            if y { hi.y } else { lo.y },
            if z { hi.z } else { lo.z },
        )
    };
    // Each face as a quad (p, q, r, s); triangles are then wound to face inwards.
    let faces = [
        [
            c(false, false, false),
            c(false, true, false),
            c(true, true, false),
            c(true, false, false),
        ],
        [
            c(false, false, true),
            c(true, false, true),
            c(true, true, true),
            c(false, true, true),
        ],
        [
            c(false, false, false),
            c(false, false, true),
            c(false, true, true),
            c(false, true, false),
        ],
        [
            c(true, false, false),
            c(true, true, false),
            c(true, true, true),
            c(true, false, true),
        ],
        [
            c(false, false, false),
            c(true, false, false),
            c(true, false, true),
            c(false, false, true),
        ],
        [
            c(false, true, false),
            c(false, true, true),
            c(true, true, true),
            c(true, true, false),
        ],
    ];
    let mut triangles = Vec::new();
    for f in faces {
        triangles.push([f[0], f[1], f[2]]);
        triangles.push([f[0], f[2], f[3]]);
    }
    for t in &mut triangles {
        let n = (t[1] - t[0]).cross(t[2] - t[0]);
        let centre = (t[0] + t[1] + t[2]) / 3.0;
        if n.dot(-centre) < 0.0 {
            t.swap(1, 2);
        }
    }
    Scene {
        name: "furnace".into(),
        triangle_material: vec![0; triangles.len()],
        triangles,
        materials: vec![Material {
            name: "wall".into(),
            kind: MaterialKind::Diffuse {
                reflectance: Spectrum::Constant(rho),
            },
            emission: Some(Spectrum::Constant(le)),
        }],
        lights: vec![],
        camera: Camera::look_at(
            Vec3::new(0.1, 0.05, 0.0),
            Vec3::new(0.3, 0.2, 1.0),
            Vec3::Y,
            1.2,
        ),
        warnings: vec![],
    }
}

#[test]
fn furnace_converges_to_le_over_one_minus_rho_at_every_storage() {
    // Radiance inside a closed uniform enclosure: L = Le / (1 − ρ) = 1 (luminance).
    let scene = furnace(0.5, 0.5);
    for (storage, bins) in [
        (Storage::Full, 16),
        (Storage::Compact, 16),
        (Storage::Compact, 4),
        (Storage::Rgb, 3),
    ] {
        for fg in [0, 8] {
            let s = RenderSettings {
                bins,
                storage,
                width: 24,
                height: 24,
                photons_per_pass: 30_000,
                final_gather_rays: fg,
                max_depth: 64,
                ..RenderSettings::default()
            };
            let mut session = RenderSession::new(&scene, s).unwrap();
            for _ in 0..4 {
                session.run_pass().unwrap();
            }
            let img = session.image();
            let mean: f64 = img
                .pixels
                .iter()
                .map(|p| luminance(p.map(f64::from)))
                .sum::<f64>()
                / img.pixels.len() as f64;
            println!("{storage:?} {bins} bins fg {fg}: mean luminance {mean:.4}");
            assert!(
                (mean - 1.0).abs() < 0.03,
                "{storage:?} {bins} fg {fg}: {mean}"
            );
        }
    }
}
