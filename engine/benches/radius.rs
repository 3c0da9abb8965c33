//! The spot-lit stage's convergence with one fixed first-pass radius (the old estimator)
//! against per-query k-nearest radii: PSNR (the paper's equation 6) against a long render
//! of the scene, per pass and per second. Prints a markdown table for BENCHMARKS.md.
//!
//!     cargo bench -p prismap-engine --bench radius
//!
//! `PRISMAP_BENCH_REFERENCE_PASSES` (default 96) sets the reference's length.

/// The product's allocator (glibc's would add page faults the product does not have).
#[path = "../../src/allocator.rs"]
mod allocator;

use std::path::PathBuf;

use prismap_engine::render::session::next_radius_sq_factor;
use prismap_engine::render::{
    ErrorReference, Flow, PassRecord, RenderSession, RenderSettings, Stop,
};
use prismap_engine::scene;

fn main() {
    allocator::keep_freed_memory();
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/blender/spotlit-prism.glb");
    let s = scene::load(&path).expect("the fixture loads");
    let base = RenderSettings {
        width: 240,
        height: 135,
        photons_per_pass: 60_000,
        ..RenderSettings::default()
    };
    let reference_passes: u64 = std::env::var("PRISMAP_BENCH_REFERENCE_PASSES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(96);
    let mut reference = RenderSession::new(
        &s,
        RenderSettings {
            seed: 99,
            ..base.clone()
        },
    )
    .unwrap();
    reference
        .run(Stop::passes(reference_passes), None, &mut |_, _| {
            Flow::Continue
        })
        .unwrap();
    let reference_image = reference.image();
    // Display values at the reference's automatic exposure (the scene is photometric).
    let exposure = prismap_engine::output::auto_exposure(&reference_image);
    let passes = 24u64;
    let run = |settings: RenderSettings| -> (Vec<PassRecord>, f32, f32) {
        let mut r = RenderSession::new(&s, settings).unwrap();
        let log = r
            .run(
                Stop::passes(passes),
                Some(ErrorReference {
                    image: &reference_image,
                    exposure,
                }),
                &mut |_, _| Flow::Continue,
            )
            .unwrap();
        (log, r.stats().r_global, r.stats().r_caustic)
    };
    let (adaptive, r_g, r_c) = run(base.clone());
    let mut f = 1.0f64;
    for k in 1..passes {
        f = next_radius_sq_factor(f, k, base.alpha);
    }
    let shrink = f.sqrt() as f32;
    let (fixed, _, _) = run(RenderSettings {
        global_radius: Some(r_g / shrink),
        caustic_radius: Some(r_c / shrink),
        ..base.clone()
    });
    println!(
        "spotlit-prism.glb, 240×135, {} photons/pass, {} final-gather rays, 20 bins compact; reference: {reference_passes} adaptive passes (another seed); PSNR at the reference's automatic exposure {exposure:.3e}\n",
        base.photons_per_pass, base.final_gather_rays
    );
    println!("| pass | fixed radius: s | fixed: PSNR | adaptive: s | adaptive: PSNR |");
    println!("|---|---|---|---|---|");
    for (a, b) in fixed.iter().zip(&adaptive) {
        if a.pass == 1 || a.pass % 4 == 0 {
            println!(
                "| {} | {:.2} | {:.2} dB | {:.2} | {:.2} dB |",
                a.pass,
                a.seconds,
                a.psnr_db.unwrap_or(f64::NAN),
                b.seconds,
                b.psnr_db.unwrap_or(f64::NAN)
            );
        }
    }
}
