//! Helpers the equal-seed image comparisons share (`guided_gather.rs`, `glass_split.rs`).

use prismap_engine::metrics::psnr_of_pairs;
use prismap_engine::render::{Image, RenderSession, RenderSettings};
use prismap_engine::scene::Scene;

/// `scene` rendered with `settings` for `passes` passes.
pub fn render(scene: &Scene, settings: RenderSettings, passes: usize) -> Image {
    let mut session = RenderSession::new(scene, settings).unwrap();
    for _ in 0..passes {
        session.run_pass().unwrap();
    }
    session.image()
}

/// Mean luminance (Rec. 709 weights of linear sRGB) of `pixels`.
pub fn mean_luminance(pixels: &[[f32; 3]]) -> f64 {
    let sum: f64 = pixels
        .iter()
        .map(|p| 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64)
        .sum();
    sum / pixels.len() as f64
}

/// PSNR (the paper's equation 6) of `pixels` against `reference`, both at the exposure
/// that brings the reference's mean luminance to 0.18.
pub fn psnr_against(pixels: &[[f32; 3]], reference: &[[f32; 3]]) -> f64 {
    assert_eq!(pixels.len(), reference.len());
    let exposure = (0.18 / mean_luminance(reference)) as f32;
    psnr_of_pairs(pixels.len(), |i| (pixels[i], reference[i]), exposure)
}
