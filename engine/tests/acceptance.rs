//! Issue #2's acceptance checks, run on the shipped scenes.

use prismap_engine::metrics::psnr;
use prismap_engine::photon::Storage;
use prismap_engine::render::{RenderSession, RenderSettings};
use prismap_engine::scene;

fn settings(bins: usize, storage: Storage) -> RenderSettings {
    RenderSettings {
        bins,
        storage,
        width: 64,
        height: 64,
        photons_per_pass: 40_000,
        final_gather_rays: 4,
        seed: 7,
        ..RenderSettings::default()
    }
}

fn render(scene: &scene::Scene, s: RenderSettings, passes: usize) -> RenderSession {
    let mut session = RenderSession::new(scene, s).unwrap();
    for _ in 0..passes {
        session.run_pass().unwrap();
    }
    session
}

#[test]
fn cornell_compact_storage_is_flat_in_bins_and_full_grows() {
    let scene = scene::load_builtin("cornell-box").unwrap();
    let bpp = |bins, storage| render(&scene, settings(bins, storage), 1).bytes_per_photon();
    let (c4, c100) = (bpp(4, Storage::Compact), bpp(100, Storage::Compact));
    let (f4, f100) = (bpp(4, Storage::Full), bpp(100, Storage::Full));
    println!("bytes/photon: compact 4 → {c4}, 100 → {c100}; full 4 → {f4}, 100 → {f100}");
    assert!(
        (c100 - c4).abs() <= 0.1 * c4,
        "compact grows: {c4} → {c100}"
    );
    assert!(f100 >= 10.0 * f4, "full: {f4} → {f100}");
}

#[test]
fn cornell_compact_matches_full_to_40_db_and_builds_no_caustic_map() {
    let scene = scene::load_builtin("cornell-box").unwrap();
    for bins in [4, 20] {
        let full = render(&scene, settings(bins, Storage::Full), 2);
        let compact = render(&scene, settings(bins, Storage::Compact), 2);
        let db = psnr(&full.image(), &compact.image(), 1.0).unwrap();
        println!("cornell-box {bins} bins: compact vs full PSNR {db:.2} dB");
        assert!(db >= 40.0, "{bins} bins: {db} dB");
        assert_eq!(compact.memory().caustic_map, 0);
        assert_eq!(compact.stats().stored_caustic, 0);
        assert!(
            compact
                .skipped()
                .iter()
                .any(|s| s.starts_with("caustic map"))
        );
    }
}

#[test]
fn prism_stores_spikes_and_compact_caustics_equal_full_bit_for_bit() {
    use prismap_engine::photon::{PhotonSettings, trace_photons};
    use prismap_engine::scene::SpectralScene;
    use std::sync::atomic::AtomicBool;
    let scene = scene::load_builtin("prism").unwrap();
    for bins in [20, 100] {
        let spectral = SpectralScene::new(
            &scene,
            prismap_engine::spectral::BinGrid::with_bins(bins).unwrap(),
        );
        assert!(spectral.has_dispersion && spectral.has_specular);
        let pass = |storage| {
            let ps = PhotonSettings::new(20_000, Storage::record(storage));
            trace_photons(&spectral, &ps, 3, 1, &AtomicBool::new(false)).unwrap()
        };
        let full = pass(Storage::Full);
        let compact = pass(Storage::Compact);
        let (fc, cc) = (full.caustic.unwrap(), compact.caustic.unwrap());
        assert!(cc.len() > 1000, "caustic photons: {}", cc.len());
        assert_eq!(fc.len(), cc.len());
        assert_eq!(
            cc.spike_records(),
            cc.len(),
            "every caustic photon is single-wavelength"
        );
        let (mut a, mut b) = (vec![0.0f32; bins], vec![0.0f32; bins]);
        for i in 0..cc.len() {
            assert_eq!(fc.positions()[i], cc.positions()[i]);
            fc.flux_of(&spectral.grid, i, &mut a);
            cc.flux_of(&spectral.grid, i, &mut b);
            assert!(
                a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "photon {i}: {a:?} vs {b:?}"
            );
        }
    }
}

/// The brightest 7×7 neighbourhood (the rainbow is the brightest extended feature; a
/// blur keeps single-pixel fireflies on the glass from winning).
fn brightest_region(img: &prismap_engine::render::Image) -> (u32, u32) {
    let lum = |x: u32, y: u32| {
        let p = img.get(x, y);
        p[0] + p[1] + p[2]
    };
    let mut best = (0.0f32, 0, 0);
    for y in 3..img.height - 3 {
        for x in 3..img.width - 3 {
            let mut s = 0.0;
            for dy in 0..7 {
                for dx in 0..7 {
                    s += lum(x + dx - 3, y + dy - 3);
                }
            }
            if s > best.0 {
                best = (s, x, y);
            }
        }
    }
    (best.1, best.2)
}

/// Centroid (x, y) of pixels within `r` of `c` whose colour passes `pick`.
fn centroid(
    img: &prismap_engine::render::Image,
    c: (u32, u32),
    r: u32,
    pick: impl Fn([f32; 3]) -> bool,
) -> Option<(f64, f64, usize)> {
    let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
    for y in c.1.saturating_sub(r)..(c.1 + r).min(img.height) {
        for x in c.0.saturating_sub(r)..(c.0 + r).min(img.width) {
            if pick(img.get(x, y)) {
                sx += x as f64;
                sy += y as f64;
                n += 1;
            }
        }
    }
    (n > 0).then(|| (sx / n as f64, sy / n as f64, n))
}

#[test]
fn prism_rainbow_runs_from_red_to_violet_in_the_image() {
    let scene = scene::load_builtin("prism").unwrap();
    let s = RenderSettings {
        bins: 60,
        storage: Storage::Compact,
        width: 160,
        height: 160,
        photons_per_pass: 60_000,
        final_gather_rays: 2,
        ..RenderSettings::default()
    };
    let img = render(&scene, s, 3).image();
    let c = brightest_region(&img);
    // The band is about a third of the view wide (the first-look camera), its brightest
    // part near the yellow end: look that far around it.
    let r = img.width / 3;
    let bright = |p: [f32; 3]| p[0] + p[1] + p[2] > 0.3;
    let red = centroid(&img, c, r, |p| {
        bright(p) && p[0] > 2.0 * p[1] && p[0] > 2.0 * p[2]
    })
    .expect("red pixels");
    let green = centroid(&img, c, r, |p| {
        bright(p) && p[1] > 1.3 * p[0] && p[1] > 1.3 * p[2]
    })
    .expect("green pixels");
    let violet = centroid(&img, c, r, |p| {
        bright(p) && p[2] > 1.5 * p[1] && p[2] > 0.5 * p[0] && p[0] > 0.15 * p[2]
    })
    .expect("violet pixels");
    println!("red {red:?} green {green:?} violet {violet:?}");
    // Green lies between red and violet along the band, and the ends are apart.
    let (dx, dy) = (violet.0 - red.0, violet.1 - red.1);
    let len2 = dx * dx + dy * dy;
    assert!(len2.sqrt() > 5.0, "colours are not separated");
    let t = ((green.0 - red.0) * dx + (green.1 - red.1) * dy) / len2;
    assert!(
        t > 0.15 && t < 0.85,
        "green is not between red and violet: t = {t}"
    );
}

#[test]
fn same_seed_gives_the_same_image_on_one_and_two_threads() {
    let scene = scene::load_builtin("prism").unwrap();
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let s = RenderSettings {
                width: 48,
                height: 40,
                photons_per_pass: 15_000,
                ..settings(16, Storage::Compact)
            };
            render(&scene, s, 2).image()
        })
    };
    let (a, b, c) = (run(1), run(2), run(3));
    assert!(
        a.pixels
            .iter()
            .zip(&b.pixels)
            .all(|(p, q)| p.map(f32::to_bits) == q.map(f32::to_bits))
    );
    assert!(
        a.pixels
            .iter()
            .zip(&c.pixels)
            .all(|(p, q)| p.map(f32::to_bits) == q.map(f32::to_bits))
    );
}

#[test]
fn what_is_skipped_is_said_for_the_right_reason() {
    // Issue #13: at 1 bin the prism was said to have "no dispersive glass".
    let skipped = |scene: &str, bins: usize| {
        let s = scene::load_builtin(scene).unwrap();
        let settings = RenderSettings {
            bins,
            width: 8,
            height: 8,
            ..RenderSettings::preview()
        };
        RenderSession::new(&s, settings)
            .unwrap()
            .skipped()
            .join("; ")
    };
    let one = skipped("prism", 1);
    assert!(one.contains("one bin"), "{one}");
    assert!(!skipped("prism", 20).contains("dispersion splitting"));
    assert!(skipped("cornell-box", 20).contains("no dispersive glass"));
}

#[test]
fn the_films_noise_estimate_tracks_the_error_against_a_reference() {
    // Issue #13's convergence read-out, checked against a real reference: the Cornell box
    // at 64², its noise estimate (odd against even passes, no reference) against the PSNR
    // against a long render of another seed. The reference has noise of its own (its own
    // estimate); the two combine as independent errors. The estimate measures noise only:
    // it reads above the real figure by the bias the radius still carries — 4.5 dB after 8
    // passes here, 3.0 after 32, 0.8 after 96 — and never below it. (Final-gather
    // directions follow a (0,2)-sequence per pixel; the estimate holds because odd and even
    // passes follow independent copies of it.)
    let scene = scene::load_builtin("cornell-box").unwrap();
    let s = RenderSettings {
        width: 64,
        height: 64,
        photons_per_pass: 20_000,
        final_gather_rays: 4,
        ..RenderSettings::default()
    };
    let reference = render(
        &scene,
        RenderSettings {
            seed: 77,
            ..s.clone()
        },
        160,
    );
    let ref_noise = reference.film().noise_psnr(1.0).unwrap();
    let reference = reference.image();
    let mut r = RenderSession::new(&scene, s).unwrap();
    let mut gaps = Vec::new();
    for passes in [8u64, 32, 96] {
        while r.film().passes() < passes {
            r.run_pass().unwrap();
        }
        let est = r.film().noise_psnr(1.0).unwrap();
        // Independent errors add: the expected PSNR against the reference from noise alone.
        let both = -10.0 * (10f64.powf(-est / 10.0) + 10f64.powf(-ref_noise / 10.0)).log10();
        let real = psnr(&r.image(), &reference, 1.0).unwrap();
        println!(
            "{passes} passes: noise estimate {est:.2} dB (with the reference's {ref_noise:.2}: {both:.2}), against the reference {real:.2} dB"
        );
        assert!(
            real < both + 0.5,
            "{passes} passes: the estimate reads below the real error"
        );
        gaps.push(both - real);
    }
    assert!(
        gaps[2] < 1.0,
        "after 96 passes noise is what is left: {gaps:?}"
    );
    assert!(gaps[0] > gaps[2], "the bias shrinks with passes: {gaps:?}");
}

#[test]
fn the_denoised_view_is_closer_to_the_converged_image_and_leaves_the_film_raw() {
    // Issue #13: the optional denoised display. On the Cornell box after 2 passes it must
    // be nearer a 48-pass reference of another seed than the raw image is, in
    // milliseconds, and the film (what saves and error figures read) is untouched.
    // Measured (4 camera samples a pass, the defaults since session 7): raw 27.41 dB,
    // denoised 29.57 dB; after 1 pass 25.10 → 26.36, after 4 passes 31.13 → 31.74 (the
    // rest of the error is the radius' bias, which no filter removes). At one camera
    // sample a pass, as in session 4: 4 passes 27.58 → 29.49. Since session 19 the
    // defaults pool final-gather rays between neighbouring pixels, which takes part of the
    // noise the filter took: raw 28.74 dB, denoised 29.71 dB (without pooling 27.41 →
    // 29.57, still checked below).
    use prismap_engine::render::DenoiseParams;
    let scene = scene::load_builtin("cornell-box").unwrap();
    let reference = render(
        &scene,
        RenderSettings {
            seed: 99,
            ..settings(8, Storage::Compact)
        },
        48,
    )
    .image();
    let session = render(&scene, settings(8, Storage::Compact), 2);
    let raw = session.image();
    let start = std::time::Instant::now();
    let denoised = session.denoised(DenoiseParams::for_size(64, 64));
    let ms = start.elapsed().as_secs_f64() * 1e3;
    let (p_raw, p_denoised) = (
        psnr(&raw, &reference, 1.0).unwrap(),
        psnr(&denoised, &reference, 1.0).unwrap(),
    );
    println!(
        "2 passes: raw {p_raw:.2} dB, denoised {p_denoised:.2} dB ({ms:.1} ms, guides included)"
    );
    assert!(
        p_denoised > p_raw + 0.6,
        "raw {p_raw} vs denoised {p_denoised}"
    );
    assert_eq!(session.image(), raw, "denoising never touches the film");
    let unpooled = RenderSettings {
        pool_gather: false,
        ..settings(8, Storage::Compact)
    };
    let session = render(&scene, unpooled, 2);
    let raw = session.image();
    let denoised = session.denoised(DenoiseParams::for_size(64, 64));
    let (p_raw, p_denoised) = (
        psnr(&raw, &reference, 1.0).unwrap(),
        psnr(&denoised, &reference, 1.0).unwrap(),
    );
    assert!(
        p_denoised > p_raw + 1.5,
        "unpooled: raw {p_raw} vs denoised {p_denoised}"
    );
}

#[test]
fn packed_records_take_19_bytes_and_lose_under_a_tenth_of_a_db() {
    // Issue #14: compact records in 32 bits. Same seed, same photons: against a reference
    // of another seed the packed image's PSNR is within 0.1 dB of the compact one's, the
    // two images are far closer to each other than to the reference, and the maps are
    // 19/29 the size.
    for (name, bins, passes) in [("cornell-box", 8, 6), ("prism", 40, 4)] {
        let scene = scene::load_builtin(name).unwrap();
        let reference = render(
            &scene,
            RenderSettings {
                seed: 77,
                ..settings(bins, Storage::Compact)
            },
            4 * passes,
        )
        .image();
        let compact = render(&scene, settings(bins, Storage::Compact), passes);
        let packed = render(&scene, settings(bins, Storage::Packed), passes);
        let (pc, pp) = (
            psnr(&compact.image(), &reference, 1.0).unwrap(),
            psnr(&packed.image(), &reference, 1.0).unwrap(),
        );
        let between = psnr(&packed.image(), &compact.image(), 1.0).unwrap();
        let (mc, mp) = (
            compact.memory().photon_maps as f64,
            packed.memory().photon_maps as f64,
        );
        println!(
            "{name}: compact {pc:.3} dB, packed {pp:.3} dB, packed vs compact {between:.1} dB; maps {:.2} → {:.2} MB ({:.3})",
            mc / 1e6,
            mp / 1e6,
            mp / mc
        );
        assert!((pc - pp).abs() < 0.1, "{name}: {pc} vs {pp}");
        assert!(between > pc + 15.0, "{name}: {between}");
        assert!((mp / mc - 19.0 / 29.0).abs() < 0.01, "{name}: {}", mp / mc);
    }
}

#[test]
fn spiked_records_keep_a_fluorescent_lamps_lines_that_compact_ones_smooth_away() {
    // Issue #14: the paper's compact records cannot represent a spiky light. The Cornell
    // box lit by CIE F11: same seed and photons, the spiked image is much closer to the
    // full-record image than the compact one is; under the smooth light of the plain box
    // the spike is kept only where it helps, so it costs nothing in error; the maps are
    // 37/29 the size of compact ones.
    let versus_full = |name: &str| {
        let scene = scene::load_builtin(name).unwrap();
        let full = render(&scene, settings(20, Storage::Full), 4).image();
        let mut out = Vec::new();
        for storage in [Storage::Compact, Storage::Spiked] {
            let r = render(&scene, settings(20, storage), 4);
            out.push((
                psnr(&r.image(), &full, 1.0).unwrap(),
                r.memory().photon_maps as f64,
            ));
        }
        println!(
            "{name}: against full records, compact {:.2} dB, spiked {:.2} dB; maps ×{:.3}",
            out[0].0,
            out[1].0,
            out[1].1 / out[0].1
        );
        (out[0], out[1])
    };
    let ((c, mc), (s, ms)) = versus_full("cornell-f11");
    assert!(s > c + 2.0, "F11: spiked {s} against compact {c}");
    assert!((ms / mc - 37.0 / 29.0).abs() < 0.01, "{}", ms / mc);
    let ((c, _), (s, _)) = versus_full("cornell-box");
    assert!(s > c - 0.2, "smooth light: spiked {s} against compact {c}");
}
