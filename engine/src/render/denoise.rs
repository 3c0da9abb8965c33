//! A denoised *view* for exploring (issue #13): the edge-avoiding à-trous wavelet filter
//! of Dammertz, Sewtz, Hanika & Lensch (2010), guided by the first hit's normal, position
//! and albedo, with the per-pixel variance the film's odd and even passes give (as SVGF,
//! Schied et al. 2017, steers the colour weight). It only ever makes a display image: the
//! film, saves, probes and every error figure stay raw.
//!
//! A few passes of a 5 × 5 B3-spline kernel with holes (step 1, 2, 4, 8: a 29-pixel
//! footprint for 100 taps a pixel; fewer on small images, see [`DenoiseParams::for_size`]); each tap is weighted by how alike the two pixels'
//! surfaces are — normals (cosine¹²⁸), distance from the centre pixel's tangent plane (in
//! units of the pixel footprint there) and albedo — and by how alike their colours are
//! relative to the noise expected in them. Colour is divided by albedo first and
//! multiplied back after, so textures stay sharp.

use glam::Vec3;
use rayon::prelude::*;

use super::film::Image;
use crate::scene::SpectralScene;
use crate::scene::SurfaceKind;

/// One pixel's guides: shading normal, position, depth, albedo.
type GuideTexel = (Vec3, Vec3, f32, [f32; 3]);

/// What the camera sees first through each pixel's centre.
#[derive(Clone, Debug)]
pub struct Guides {
    pub width: u32,
    pub height: u32,
    /// Shading normal facing the camera (zero where the ray escapes).
    pub normal: Vec<Vec3>,
    pub position: Vec<Vec3>,
    /// Distance from the camera (0 where the ray escapes).
    pub depth: Vec<f32>,
    /// Linear-sRGB albedo: the diffuse reflectance (texture included) under a flat white
    /// light; 1 for mirrors, glass and emitters.
    pub albedo: Vec<[f32; 3]>,
    /// Radians per pixel (the footprint of a pixel at depth d is d × this).
    pub pixel_angle: f32,
}

impl Guides {
    pub fn of(scene: &SpectralScene, width: u32, height: u32) -> Self {
        let cam = scene.camera;
        let white = vec![1.0f32; scene.bins()];
        let rows: Vec<Vec<GuideTexel>> = (0..height)
            .into_par_iter()
            .map(|y| {
                let mut scratch = Vec::new();
                (0..width)
                    .map(|x| {
                        let d = super::gather::camera_dir(
                            &cam,
                            x as f32 + 0.5,
                            y as f32 + 0.5,
                            width,
                            height,
                        );
                        let Some(hit) = scene.intersect(cam.position, d) else {
                            return (Vec3::ZERO, Vec3::ZERO, 0.0, [0.0; 3]);
                        };
                        let mat = scene.material(&hit);
                        let albedo = match &mat.kind {
                            SurfaceKind::Diffuse { reflectance } if mat.emission.is_none() => {
                                let r = scene.reflectance_at(mat, reflectance, &hit, &mut scratch);
                                let mut lit = white.clone();
                                for (l, v) in lit.iter_mut().zip(r) {
                                    *l *= v;
                                }
                                // Relative to white's own colour on this grid.
                                let w = scene.grid.to_linear_srgb(&white);
                                let c = scene.grid.to_linear_srgb(&lit);
                                [0, 1, 2].map(|k| (c[k] / w[k].max(1e-6)).clamp(0.0, 1.0))
                            }
                            _ => [1.0; 3],
                        };
                        (hit.ns, hit.p, hit.t, albedo)
                    })
                    .collect()
            })
            .collect();
        let n = (width * height) as usize;
        let (mut normal, mut position, mut depth, mut albedo) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for (nm, p, t, a) in rows.into_iter().flatten() {
            normal.push(nm);
            position.push(p);
            depth.push(t);
            albedo.push(a);
        }
        Self {
            width,
            height,
            normal,
            position,
            depth,
            albedo,
            pixel_angle: 2.0 * (0.5 * cam.yfov).tan() / height as f32,
        }
    }
}

/// The filter's strengths.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DenoiseParams {
    /// Passes of the 5 × 5 kernel (step doubles each pass).
    pub iterations: u32,
    /// Colour weight: differences this many standard deviations apart weigh e⁻¹.
    pub sigma_colour: f32,
    /// Normal weight exponent.
    pub normal_power: i32,
    /// Tangent-plane distance, in pixel footprints × step, that weighs e⁻¹.
    pub sigma_plane: f32,
    /// Albedo difference (per channel) that weighs e⁻¹.
    pub sigma_albedo: f32,
}

impl DenoiseParams {
    /// The defaults with the footprint scaled to the image: 2^(iterations+1) + 1 pixels,
    /// about a sixteenth of the shorter side (tuned on the Cornell box: wider footprints
    /// flatten the real gradients of light across a wall).
    pub fn for_size(width: u32, height: u32) -> Self {
        let side = width.min(height).max(1) as f32;
        Self {
            iterations: (side.log2().round() as i32 - 4).clamp(1, 5) as u32,
            ..Self::default()
        }
    }
}

impl Default for DenoiseParams {
    fn default() -> Self {
        Self {
            iterations: 4,
            sigma_colour: 4.0,
            normal_power: 128,
            sigma_plane: 1.0,
            sigma_albedo: 0.1,
        }
    }
}

const B3: [f32; 5] = [1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0];

fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// The denoised image of `image`, with `variance` the per-pixel variance of its
/// luminance (None: 10 % of the pixel's luminance, squared, is assumed).
pub fn denoise(
    image: &Image,
    variance: Option<&[f32]>,
    guides: &Guides,
    params: DenoiseParams,
) -> Image {
    let (w, h) = (image.width as usize, image.height as usize);
    assert_eq!((guides.width as usize, guides.height as usize), (w, h));
    let albedo = &guides.albedo;
    let demod =
        |i: usize, c: [f32; 3]| -> [f32; 3] { [0, 1, 2].map(|k| c[k] / albedo[i][k].max(0.01)) };
    let mut colour: Vec<[f32; 3]> = image
        .pixels
        .iter()
        .enumerate()
        .map(|(i, &c)| demod(i, c))
        .collect();
    let mut var: Vec<f32> = match variance {
        Some(v) => (0..w * h)
            .map(|i| {
                let a = luminance(albedo[i]).max(0.01);
                v[i] / (a * a)
            })
            .collect(),
        None => colour
            .iter()
            .map(|c| (0.1 * luminance(*c)).powi(2))
            .collect(),
    };
    for it in 0..params.iterations {
        let step = 1usize << it;
        let (next, next_var): (Vec<[f32; 3]>, Vec<f32>) = (0..h)
            .into_par_iter()
            .flat_map_iter(|y| {
                let (colour, var) = (&colour, &var);
                (0..w).map(move |x| {
                    let i = y * w + x;
                    let (np, xp, dp) = (guides.normal[i], guides.position[i], guides.depth[i]);
                    let cp = colour[i];
                    let lp = luminance(cp);
                    let sd = var[i].max(0.0).sqrt() * params.sigma_colour + 1e-6;
                    let footprint =
                        (dp * guides.pixel_angle * step as f32).max(1e-6) * params.sigma_plane;
                    let (mut sum, mut wsum, mut vsum) = ([0.0f32; 3], 0.0f32, 0.0f32);
                    for (j, hy) in B3.iter().enumerate() {
                        let qy = y as isize + (j as isize - 2) * step as isize;
                        if qy < 0 || qy >= h as isize {
                            continue;
                        }
                        for (k, hx) in B3.iter().enumerate() {
                            let qx = x as isize + (k as isize - 2) * step as isize;
                            if qx < 0 || qx >= w as isize {
                                continue;
                            }
                            let q = qy as usize * w + qx as usize;
                            let mut wt = hx * hy;
                            if q != i {
                                let nq = guides.normal[q];
                                if (dp > 0.0) != (guides.depth[q] > 0.0) {
                                    continue;
                                }
                                if dp > 0.0 {
                                    let cos = np.dot(nq).max(0.0);
                                    wt *= cos.powi(params.normal_power);
                                    let plane = np.dot(guides.position[q] - xp).abs();
                                    wt *= (-plane / footprint).exp();
                                    let da: f32 =
                                        (0..3).map(|c| (albedo[i][c] - albedo[q][c]).powi(2)).sum();
                                    wt *= (-da / (params.sigma_albedo * params.sigma_albedo)).exp();
                                }
                                let dl = (lp - luminance(colour[q])).abs();
                                wt *= (-dl / sd).exp();
                            }
                            if !(wt > 0.0) {
                                continue;
                            }
                            for c in 0..3 {
                                sum[c] += wt * colour[q][c];
                            }
                            wsum += wt;
                            vsum += wt * wt * var[q];
                        }
                    }
                    // The centre tap always weighs in, so wsum > 0.
                    (sum.map(|v| v / wsum), vsum / (wsum * wsum))
                })
            })
            .unzip();
        colour = next;
        var = next_var;
    }
    Image {
        width: image.width,
        height: image.height,
        pixels: colour
            .iter()
            .enumerate()
            .map(|(i, c)| [0, 1, 2].map(|k| c[k] * albedo[i][k].max(0.01)))
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat_guides(w: u32, h: u32, split: Option<u32>) -> Guides {
        let n = (w * h) as usize;
        Guides {
            width: w,
            height: h,
            // Two planes meeting at column `split`, at right angles.
            normal: (0..n)
                .map(|i| match split {
                    Some(s) if (i as u32 % w) >= s => Vec3::X,
                    _ => Vec3::Z,
                })
                .collect(),
            position: (0..n)
                .map(|i| {
                    Vec3::new(
                        (i as u32 % w) as f32 * 0.01,
                        (i as u32 / w) as f32 * 0.01,
                        1.0,
                    )
                })
                .collect(),
            depth: vec![1.0; n],
            albedo: vec![[0.5; 3]; n],
            pixel_angle: 0.01,
        }
    }

    fn noisy(w: u32, h: u32, value: impl Fn(u32) -> f32, amp: f32) -> Image {
        let mut rng = crate::sampling::Rng::stream(5, 0, 0, crate::sampling::Purpose::Camera);
        Image {
            width: w,
            height: h,
            pixels: (0..w * h)
                .map(|i| {
                    let [a, _] = rng.next_2d();
                    let v = value(i % w) * (1.0 + amp * (2.0 * a - 1.0));
                    [v; 3]
                })
                .collect(),
        }
    }

    #[test]
    fn a_constant_image_stays_constant() {
        let g = flat_guides(32, 24, None);
        let img = Image {
            width: 32,
            height: 24,
            pixels: vec![[0.3, 0.2, 0.1]; 32 * 24],
        };
        let out = denoise(&img, None, &g, DenoiseParams::default());
        for p in &out.pixels {
            for c in 0..3 {
                assert!((p[c] - img.pixels[0][c]).abs() < 1e-6, "{p:?}");
            }
        }
    }

    #[test]
    fn noise_goes_and_an_edge_between_surfaces_stays() {
        // Left plane 1.0, right plane (another normal) 0.2, ±30 % noise: the filtered
        // image is much closer to the truth, and the columns either side of the edge keep
        // their own side's value.
        let (w, h, s) = (48u32, 32u32, 24u32);
        let truth = |x: u32| if x < s { 1.0 } else { 0.2 };
        let img = noisy(w, h, truth, 0.3);
        let var: Vec<f32> = (0..w * h)
            .map(|i| (0.3 * truth(i % w) / 3f32.sqrt()).powi(2))
            .collect();
        let g = flat_guides(w, h, Some(s));
        let out = denoise(&img, Some(&var), &g, DenoiseParams::default());
        let rms = |im: &Image| {
            let e: f32 = (0..w * h)
                .map(|i| (im.pixels[i as usize][0] - truth(i % w)).powi(2))
                .sum();
            (e / (w * h) as f32).sqrt()
        };
        let (before, after) = (rms(&img), rms(&out));
        assert!(after < 0.35 * before, "rms {before} → {after}");
        for y in 4..h - 4 {
            let left = out.pixels[(y * w + s - 1) as usize][0];
            let right = out.pixels[(y * w + s) as usize][0];
            assert!(
                (left - 1.0).abs() < 0.15,
                "row {y}: left of the edge {left}"
            );
            assert!(
                (right - 0.2).abs() < 0.05,
                "row {y}: right of the edge {right}"
            );
        }
    }
}
