//! The gather pass: camera rays through specular chains to the first diffuse hit, where
//! radiance = direct light (light sampling) + caustics (caustic map) + indirect light
//! (final gathering over the global map, as in Jensen's photon mapping). With zero final
//! gather rays the global map is shown directly (all light from one density estimate).
//! Neighbouring pixels may pool their final-gather rays ([`Gather::block`]).

use glam::Vec3;

use crate::geometry::SurfaceHit;
use crate::materials::microfacet::{Frame, Ggx, reflection_lobe, schlick};
use crate::materials::{
    attenuate_metal, dielectric_bounce, fresnel_dielectric, metal_bounce, roulette_when_faint,
};
use crate::photon::irradiance::GuideMemo;
use crate::photon::trace::micro_sample;
use crate::photon::{IrradianceCache, Kernel, PhotonMap, guide};
use crate::sampling::{Purpose, Rng, cosine_hemisphere, kronecker, r2, sobol02};
use crate::scene::{SpectralScene, SurfaceKind, path_eta};
use crate::spectral::spd;

/// What one pass's gather needs.
pub struct Gather<'a> {
    pub scene: &'a SpectralScene,
    pub global: &'a PhotonMap,
    pub caustic: Option<&'a PhotonMap>,
    /// The global map's precomputed irradiance, read by final-gather rays (None: they
    /// run their own density estimates).
    pub irradiance: Option<&'a IrradianceCache>,
    /// How the global and caustic maps' density estimates choose photons.
    pub global_kernel: Kernel,
    pub caustic_kernel: Kernel,
    /// Smallest radius a density estimate divides by (scene-scaled).
    pub r_min: f32,
    pub final_gather_rays: u32,
    /// Whether pixels rendered together by [`Gather::block`] pool their final-gather rays
    /// (see there).
    pub pool_gather: bool,
    /// How far pooled hits may lie apart this pass, in pixel footprints: [`POOL_REACH`]
    /// shrunk with the passes as the photon radius is (Knaus & Zwicker's r_k/r_1), so that
    /// the blur pooling adds to indirect light fades as the photon maps' does and the
    /// render stays consistent (from about 700 passes on only hits under a footprint apart
    /// pool).
    pub pool_reach: f32,
    /// Camera rays per pixel per pass; the final-gather rays are shared among them.
    pub camera_samples: u32,
    /// Wavelengths a camera sample follows past its first dispersive glass (see
    /// [`Gather::pixel`]; 1: one, picked ∝ throughput).
    pub glass_split: u32,
    /// Safety cap on a path's specular bounces (Russian roulette ends paths first).
    pub max_bounces: u32,
    /// How far from the pixel's caustic estimate, as a fraction of its radius, another
    /// of the pixel's camera samples on the same surface reads it instead of estimating
    /// anew ([`CAUSTIC_REUSE`]; 0: every sample estimates its own).
    pub caustic_reuse: f32,
    /// tan(yfov / 2) of the scene's camera ([`camera_tan_half_fov`]): once per pass, not
    /// a libm call per pixel (1 % of a one-sample prism pass).
    pub tan_half_fov: f32,
    /// Whether [`Gather::block`] runs its AVX copy (only where [`crate::cpu::has_avx`];
    /// the same results either way).
    pub avx: bool,
}

/// [`Gather::caustic_reuse`]'s value.
pub const CAUSTIC_REUSE: f32 = 0.5;

/// How far apart two hits of a block may lie and still pool their final-gather rays, in
/// pixel footprints at the hit's distance along its camera path (stretched by 1/cos of the
/// incidence on the surface): a 2×2 block's samples lie within 2√2 footprints of each
/// other.
pub const POOL_REACH: f32 = 3.0;

/// Where a camera sample's diffuse hit lies, for pooling (see [`Gather::block`]).
#[derive(Clone, Copy, Debug)]
struct PoolHit {
    p: Vec3,
    nf: Vec3,
    /// How far another hit may lie and still share its rays (scene units).
    reach: f32,
}

/// A block pixel's final-gather bookkeeping this pass. Its N-bin sums live in
/// `Scratch::pool` at the pixel's slot: Σ of its samples' weights w = throughput·ρ/π,
/// Σ of its rays' radiance L, and Σ w⊙L (the unpooled estimate's numerator).
#[derive(Clone, Copy, Debug, Default)]
struct PixelPool {
    /// The first sample's hit, which the others are tested against.
    first: Option<PoolHit>,
    /// Samples that reached a diffuse surface, and whether all on the first's surface.
    hits: u32,
    uniform: bool,
    rays: u32,
}

/// Per-thread buffers of N bins (the result never depends on their prior content).
pub struct Scratch {
    throughput: Vec<f32>,
    tmp: Vec<f32>,
    acc: Vec<f32>,
    fg: Vec<f32>,
    /// A final-gather ray's throughput, result, search and texel buffers.
    ray: RayBuffers,
    /// The k-nearest search's candidates.
    found: Vec<(f32, u32)>,
    /// Textured reflectance at the camera hit.
    refl: Vec<f32>,
    /// The last k-nearest radius of each map's estimates in this row (unshrunk): the
    /// next pixel's search starts there. Reset per row so that results never depend on
    /// which thread rendered what.
    hints: [f32; 2],
    /// The pixel's caustic estimate so far in this pass: where it was made (point,
    /// normal, radius) and its irradiance (N bins, in `caustic_e`); see
    /// [`Gather::caustic_irradiance`]. Cleared per pixel.
    caustic_at: Option<(Vec3, Vec3, f32)>,
    caustic_e: Vec<f32>,
    /// The block's pixels' pooling bookkeeping, and their sums (3 × N bins a pixel: Σw,
    /// ΣL, Σw⊙L; see [`PixelPool`]).
    pixels: [PixelPool; 4],
    pool: Vec<f32>,
    /// The block slot of the pixel being rendered.
    slot: u8,
    /// The camera path's length so far, a pixel's footprint per unit of it, and how much
    /// the surface the path reached stretches it (1/cos of its incidence, at most 20).
    path_len: f32,
    footprint: f32,
    stretch: f32,
    /// The last final-gather guide looked up (reset per row).
    guide_memo: GuideMemo,
    /// The camera sample's state at its wavelength pick, and its throughput there, which
    /// its extra wavelengths start from (see [`Split`]).
    pick: Option<Pick>,
    pick_t: Vec<f32>,
}

/// How a camera sample follows dispersive glass. At the first dispersive interface a
/// path picks one bin ∝ its throughput (weight 1/p), so glass seen directly shows one
/// wavelength per sample: colour noise that fades only as 1/√samples. With `ways` > 1 the
/// sample follows `ways` wavelengths past that pick, at stratified points of the
/// throughput's distribution, each weighing 1/`ways`: the primary path, and `ways` − 1
/// extra ones that start from the primary's own state at its pick (the hit, the ray and
/// the throughput; [`Pick`]), so that all of them share the path before it, which the
/// primary counted once. Given that path, their average is an unbiased estimate of what
/// lies past the glass, with far less colour noise. Only the primary gathers indirect
/// light (final-gather rays, pooled or not), scaled by `ways`: one wavelength's gather,
/// chosen uniformly among them, is an unbiased estimate of their mean, and the gather is
/// the costly part.
#[derive(Clone, Copy, Debug)]
struct Split {
    ways: u32,
    /// An extra path: gathers no indirect light.
    sub: bool,
}

/// A camera path's state where it meets its first dispersive glass, before it picks a
/// wavelength there (its throughput is kept in `Scratch::pick_t`).
#[derive(Clone, Copy, Debug)]
struct Pick {
    hit: SurfaceHit,
    dir: Vec3,
    path_len: f32,
    /// Bounces left after this one.
    bounces: u32,
}

/// Where a camera path stands as it is followed (see [`Gather::follow`]).
#[derive(Clone, Copy, Debug)]
struct PathState {
    /// The path's stratified number for its wavelength pick, until it is used.
    spectral_u: Option<f32>,
    /// Where within its bin the path's wavelength lies, once picked.
    lambda_u: Option<f32>,
    picked: bool,
    bounces: u32,
}

/// What one final-gather ray works in.
struct RayBuffers {
    t: Vec<f32>,
    out: Vec<f32>,
    found: Vec<(f32, u32)>,
    texel: Vec<f32>,
}

impl Scratch {
    pub fn new(n: usize) -> Self {
        Self {
            throughput: vec![0.0; n],
            tmp: vec![0.0; n],
            acc: vec![0.0; n],
            fg: vec![0.0; n],
            ray: RayBuffers {
                t: vec![0.0; n],
                out: vec![0.0; n],
                found: Vec::new(),
                texel: Vec::new(),
            },
            found: Vec::new(),
            refl: Vec::new(),
            hints: [0.0; 2],
            caustic_at: None,
            caustic_e: vec![0.0; n],
            pixels: [PixelPool::default(); 4],
            pool: vec![0.0; 12 * n],
            slot: 0,
            path_len: 0.0,
            footprint: 0.0,
            stretch: 1.0,
            guide_memo: GuideMemo::default(),
            pick: None,
            pick_t: Vec::with_capacity(n),
        }
    }

    /// Forgets the radius hints: call at the start of every deterministic work unit.
    pub fn start_row(&mut self) {
        self.hints = [0.0; 2];
        self.guide_memo = GuideMemo::default();
    }

    /// Forgets the pixel's caustic estimate (a new pixel's samples share only theirs).
    fn start_pixel(&mut self) {
        self.caustic_at = None;
    }
}

/// Where a pixel's final-gather directions come from in one pass: a scrambled
/// (0,2)-sequence of its own ([`sobol02`]), continued from pass to pass, so that the
/// directions of many passes together cover the hemisphere evenly. Odd and even passes
/// follow two independently scrambled copies (pass 2k and 2k+1 take points k·rays … of
/// their copy): the film's noise estimate compares odd against even half-means and needs
/// them independent, which one sequence shared by both would not be (its halves
/// interleave and their errors cancel).
#[derive(Clone, Copy, Debug)]
pub struct GatherSequence {
    scramble: [u32; 2],
    first: u32,
    /// Final-gather rays of this camera sample.
    rays: u32,
    /// The direct-light sample's point on the light: an R2 sequence, one point a pass.
    light_offset: [f32; 2],
    light_index: u32,
    /// The camera ray's point within the pixel: a Kronecker sequence of its own (see
    /// [`pixel_jitter`]), one point a pass, same index as the light's.
    jitter_offset: [f32; 2],
    /// Where the camera ray's wavelength falls, when dispersive glass picks one: a 1-D
    /// low-discrepancy sequence of its own ([`spectral_point`]), same index as the light's, so
    /// that a pixel's samples over the passes spread over the spectrum instead of
    /// clumping (the colour noise of glass seen directly).
    spectral_offset: f32,
}

impl GatherSequence {
    /// `pass` counts from 0.
    pub fn for_pixel(seed: u64, pixel: u64, pass: u64, rays: u32, samples: u32) -> Self {
        let mut r = Rng::stream(seed, pass & 1, pixel, Purpose::Gather);
        Self {
            scramble: [r.next_u32(), r.next_u32()],
            first: (pass >> 1).wrapping_mul(rays as u64) as u32,
            rays,
            light_offset: r.next_2d(),
            light_index: (pass >> 1).wrapping_mul(samples.max(1) as u64) as u32,
            jitter_offset: r.next_2d(),
            spectral_offset: r.next_f32(),
        }
    }
}

impl Gather<'_> {
    /// The radiance of a block of up to 2×2 neighbouring pixels (each with its own
    /// sequence, random stream and output), their final-gather rays pooled: a pixel whose
    /// camera samples all reached one surface takes as its indirect irradiance π × the
    /// mean radiance of the rays of every such pixel of the block on the same surface
    /// within [`POOL_REACH`] pixel footprints (its own included), times each sample's own
    /// throughput and reflectance. Indirect light varies slowly along a surface, so the
    /// pixel's F rays then average like up to 4F, for the cost of F: the irradiance is
    /// blurred over about two pixels, on one surface only (texture, edges and caustics stay
    /// the pixel's own). A pixel whose samples reached different surfaces, or none, keeps
    /// its own rays' estimate, as without pooling. With `pool_gather` off this is
    /// [`Gather::pixel`] on each pixel.
    ///
    /// On a CPU with AVX the block runs in a copy of the camera path compiled for it
    /// ([`Self::block_avx`]): its loops over the bins take eight lanes instead of four.
    /// AVX alone fuses no multiply into an add and reorders no sum, so each bin gets the
    /// same operations in the same order and the result is the same to the bit (tested).
    pub fn block(
        &self,
        pixels: &[((u32, u32), GatherSequence)],
        size: (u32, u32),
        rngs: &mut [Rng],
        s: &mut Scratch,
        outs: &mut [Vec<f32>],
    ) {
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: `avx` is set only where the CPU has AVX (`crate::cpu::has_avx`).
            unsafe { self.block_avx(pixels, size, rngs, s, outs) };
            return;
        }
        self.block_in(pixels, size, rngs, s, outs);
    }

    /// [`Self::block`] compiled for AVX, the camera path inlined into it.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn block_avx(
        &self,
        pixels: &[((u32, u32), GatherSequence)],
        size: (u32, u32),
        rngs: &mut [Rng],
        s: &mut Scratch,
        outs: &mut [Vec<f32>],
    ) {
        self.block_in(pixels, size, rngs, s, outs);
    }

    /// [`Self::block`]'s body, inlined into each of its two copies.
    #[inline(always)]
    fn block_in(
        &self,
        pixels: &[((u32, u32), GatherSequence)],
        size: (u32, u32),
        rngs: &mut [Rng],
        s: &mut Scratch,
        outs: &mut [Vec<f32>],
    ) {
        debug_assert!(pixels.len() <= 4);
        if self.pool_gather {
            // The pixels' sums need no clearing: a pixel's first diffuse sample writes them
            // (see `shade_diffuse`), and a pixel with none is not read.
            s.pixels = [PixelPool::default(); 4];
            s.footprint = 2.0 * self.tan_half_fov / size.1 as f32;
        }
        let each = pixels.iter().zip(rngs.iter_mut().zip(outs.iter_mut()));
        for (i, (&(xy, fg), (rng, out))) in each.enumerate() {
            s.slot = i as u8;
            self.pixel(xy, size, rng, fg, s, out);
        }
        if self.pool_gather {
            self.resolve_shared(pixels.len(), s, outs);
        }
    }

    /// Adds each block pixel's final-gather light, pooled where it can be (see
    /// [`Self::block`]).
    #[inline(always)]
    fn resolve_shared(&self, count: usize, s: &mut Scratch, outs: &mut [Vec<f32>]) {
        let n = s.fg.len();
        let samples = self.camera_samples.max(1);
        // A pixel whose rays brought back a NaN or infinity keeps it to itself (the film
        // drops that one sample) rather than spreading it over the block.
        // (Only pixels with a diffuse sample have sums: the others' slots hold another
        // block's.)
        let mut finite = [false; 4];
        for (k, f) in finite.iter_mut().enumerate().take(count) {
            *f = s.pixels[k].hits > 0
                && s.pool[3 * n * k + n..3 * n * k + 2 * n]
                    .iter()
                    .all(|v| v.is_finite());
        }
        let pooled = |px: &PixelPool| px.uniform && px.hits == samples && px.rays > 0;
        for (slot, out) in outs.iter_mut().enumerate().take(count) {
            let me = s.pixels[slot];
            if me.hits == 0 {
                // No sample reached a diffuse surface: no final-gather light.
                continue;
            }
            let sums = &s.pool[3 * n * slot..3 * n * (slot + 1)];
            let (w, rest) = sums.split_at(n);
            let wl = &rest[n..];
            let Some(a) = me.first.filter(|_| pooled(&me)) else {
                // Its own rays, each weighing 1/F of the pixel (as without pooling).
                let scale = std::f32::consts::PI / self.final_gather_rays.max(1) as f32;
                spd::add_scaled(out, wl, scale);
                continue;
            };
            s.tmp.fill(0.0);
            let mut rays = 0;
            for (k, px) in s.pixels.iter().enumerate().take(count) {
                let lends = k == slot
                    || (finite[k] && px.first.is_some_and(|b| pooled(px) && shares_rays(&a, &b)));
                if lends {
                    let l = &s.pool[3 * n * k + n..3 * n * k + 2 * n];
                    spd::add_scaled(&mut s.tmp, l, 1.0);
                    rays += px.rays;
                }
            }
            // (1/S) Σ over samples of w ⊙ π ΣL / rays.
            let scale = std::f32::consts::PI / (rays as f32 * samples as f32);
            for ((o, w), l) in out.iter_mut().zip(w).zip(&s.tmp) {
                *o += w * l * scale;
            }
        }
    }

    /// Radiance (N bins) arriving at the camera through pixel (px, py): the mean of
    /// `camera_samples` rays through points of the pixel's own low-discrepancy sequence
    /// ([`pixel_jitter`]), continued from pass to pass.
    #[inline(always)]
    pub fn pixel(
        &self,
        (px, py): (u32, u32),
        (width, height): (u32, u32),
        rng: &mut Rng,
        fg: GatherSequence,
        s: &mut Scratch,
        out: &mut [f32],
    ) {
        out.fill(0.0);
        s.start_pixel();
        let samples = self.camera_samples.max(1);
        let camera = &self.scene.camera;
        let tan_y = self.tan_half_fov;
        let mut first = fg.first;
        for k in 0..samples {
            let rays = fg.rays / samples + u32::from(k < fg.rays % samples);
            let sample = GatherSequence {
                first,
                rays,
                light_index: fg.light_index.wrapping_add(k),
                ..fg
            };
            first = first.wrapping_add(rays);
            let [jx, jy] = pixel_jitter(sample.light_index, fg.jitter_offset);
            let (x, y) = (px as f32 + jx, py as f32 + jy);
            let dir = camera_dir_with(camera, tan_y, x, y, width, height);
            let spectral_u = spectral_point(sample.light_index, fg.spectral_offset);
            let ways = self.glass_split.max(1);
            let origin = self.scene.camera.position;
            let primary = Split { ways, sub: false };
            self.radiance(origin, dir, spectral_u, rng, sample, s, out, primary);
            // Past dispersive glass the sample follows `ways` wavelengths, stratified over
            // the throughput's distribution: the other ones start where the primary
            // picked its own (see [`Split`]; `s.pick` is kept only when there are more).
            if s.pick.is_some() {
                for i in 1..ways {
                    let u = spectral_u + i as f32 / ways as f32;
                    let u = within_unit(if u >= 1.0 { u - 1.0 } else { u });
                    let sub = Split { ways, sub: true };
                    self.resume_at_pick(u, rng, sample, s, out, sub);
                }
            }
        }
        if samples > 1 {
            spd::scale(out, 1.0 / samples as f32);
        }
    }

    /// Radiance along a camera ray, added to `out`. `spectral_u` (uniform in [0, 1))
    /// chooses the wavelength if dispersive glass splits the path. With `split.ways` > 1
    /// the path keeps its state at that pick in `s.pick` for the extra wavelengths
    /// ([`Self::resume_at_pick`]; see [`Split`]).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn radiance(
        &self,
        origin: Vec3,
        dir: Vec3,
        spectral_u: f32,
        rng: &mut Rng,
        fg: GatherSequence,
        s: &mut Scratch,
        out: &mut [f32],
        split: Split,
    ) {
        s.throughput.fill(1.0);
        s.path_len = 0.0;
        s.pick = None;
        let state = PathState {
            spectral_u: Some(spectral_u),
            lambda_u: None,
            picked: false,
            bounces: self.max_bounces,
        };
        self.follow(origin, dir, state, rng, fg, s, out, split)
    }

    /// One of a split sample's extra wavelengths (see [`Split`]): the primary path's
    /// state at its pick (`s.pick`), picked again at `spectral_u`, its throughput a
    /// 1/ways share, followed from there. It counts only what lies past the pick and
    /// gathers no indirect light.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn resume_at_pick(
        &self,
        spectral_u: f32,
        rng: &mut Rng,
        fg: GatherSequence,
        s: &mut Scratch,
        out: &mut [f32],
        split: Split,
    ) {
        let Some(pick) = s.pick else {
            return;
        };
        s.throughput.copy_from_slice(&s.pick_t);
        s.path_len = pick.path_len;
        let mat = self.scene.material(&pick.hit);
        let (mut lambda_u, mut u) = (None, Some(spectral_u));
        let (t, texel) = (&mut s.throughput, &mut s.refl);
        let next = self.specular_bounce(
            &mat.kind,
            &pick.hit,
            pick.dir,
            t,
            texel,
            (&mut lambda_u, &mut u),
            rng,
        );
        spd::scale(&mut s.throughput, 1.0 / split.ways as f32);
        let Some((origin, dir)) = next else {
            return;
        };
        let state = PathState {
            spectral_u: None,
            lambda_u,
            picked: true,
            bounces: pick.bounces,
        };
        self.follow(origin, dir, state, rng, fg, s, out, split);
    }

    /// Follows a camera path from `origin` along `dir` in `state` (the throughput in
    /// `s.throughput`), adding what it meets to `out`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn follow(
        &self,
        mut origin: Vec3,
        mut dir: Vec3,
        state: PathState,
        rng: &mut Rng,
        fg: GatherSequence,
        s: &mut Scratch,
        out: &mut [f32],
        split: Split,
    ) {
        let scene = self.scene;
        let PathState {
            mut spectral_u,
            mut lambda_u,
            mut picked,
            bounces,
        } = state;
        for bounce in 0..bounces {
            let Some(hit) = scene.intersect(origin, dir) else {
                // An escaping path sees the sky, if the scene has one.
                if let Some(sky) = &scene.environment {
                    for ((o, t), l) in out.iter_mut().zip(&s.throughput).zip(sky) {
                        *o += t * l;
                    }
                }
                return;
            };
            let (p, nf, front) = (hit.p, hit.nf, hit.front);
            s.path_len += (p - origin).length();
            let mat = scene.material(&hit);
            mat.absorb_inside(&hit, &mut s.throughput);
            // Emitters seen directly or through specular surfaces.
            if front {
                let mut buf = std::mem::take(&mut s.refl);
                if let Some(e) = scene.emission_at(mat, &hit, &mut buf) {
                    for ((o, t), l) in out.iter_mut().zip(&s.throughput).zip(e) {
                        *o += t * l;
                    }
                }
                s.refl = buf;
            }
            match &mat.kind {
                SurfaceKind::Diffuse { reflectance } => {
                    let mut buf = std::mem::take(&mut s.refl);
                    let reflectance = scene.reflectance_at(mat, reflectance, &hit, &mut buf);
                    s.stretch = 1.0 / dir.dot(nf).abs().max(0.05);
                    // Past a split the throughput carries 1/ways: the primary path's
                    // final gather, the only one, is scaled back up (see [`Split`]).
                    let gather = match (split.sub, picked) {
                        (true, _) => None,
                        (false, true) => Some(split.ways as f32),
                        (false, false) => Some(1.0),
                    };
                    self.shade_diffuse(p, nf, hit.ns, reflectance, rng, fg, s, gather);
                    // Lambertian radiance ρ E / π, times the path's throughput, in one
                    // pass over the bins.
                    debug_assert_eq!(reflectance.len(), s.acc.len());
                    let inv_pi = std::f32::consts::FRAC_1_PI;
                    let light = s.throughput.iter().zip(&s.acc).zip(reflectance);
                    for (o, ((t, e), r)) in out.iter_mut().zip(light) {
                        *o += t * (e * r * inv_pi);
                    }
                    s.refl = buf;
                    return;
                }
                kind => {
                    self.rough_highlight(kind, &hit, dir, rng, s, out);
                    let unpicked = spectral_u.is_some();
                    // The state the extra wavelengths start from, if this bounce picks
                    // one (see [`Split`]).
                    if unpicked
                        && split.ways > 1
                        && matches!(
                            kind,
                            SurfaceKind::Dielectric {
                                dispersive: true,
                                ..
                            }
                        )
                    {
                        s.pick_t.clear();
                        s.pick_t.extend_from_slice(&s.throughput);
                        s.pick = Some(Pick {
                            hit,
                            dir,
                            path_len: s.path_len,
                            bounces: bounces - bounce - 1,
                        });
                    }
                    let (t, texel) = (&mut s.throughput, &mut s.refl);
                    let wl = (&mut lambda_u, &mut spectral_u);
                    let next = self.specular_bounce(kind, &hit, dir, t, texel, wl, rng);
                    if unpicked && spectral_u.is_none() {
                        picked = true;
                        if split.ways > 1 {
                            spd::scale(&mut s.throughput, 1.0 / split.ways as f32);
                        }
                    } else if unpicked {
                        // No pick here (a single-bin throughput): no extra wavelengths.
                        s.pick = None;
                    }
                    match next {
                        Some((o, d)) => (origin, dir) = (o, d),
                        None => return,
                    }
                }
            }
        }
    }

    /// The highlight of punctual and distant lights on a rough metal or glass, added to
    /// `out` (times the path's throughput). No ray can hit those lights, so only light
    /// sampling sees them; area lights and the sky are left to the sampled bounce (which
    /// counts the emission it hits), so nothing is counted twice. Rough glass reflects
    /// them here; light refracted through rough glass from a punctual light is not seen by
    /// the camera (the caustic map still carries it to diffuse surfaces).
    fn rough_highlight(
        &self,
        kind: &SurfaceKind,
        hit: &SurfaceHit,
        dir: Vec3,
        rng: &mut Rng,
        s: &mut Scratch,
        out: &mut [f32],
    ) {
        let alpha = match kind {
            SurfaceKind::Mirror { alpha, .. } | SurfaceKind::Dielectric { alpha, .. } => *alpha,
            SurfaceKind::Diffuse { .. } => 0.0,
        };
        if alpha <= 0.0 {
            return;
        }
        let lights = &self.scene.lights;
        let Some(sample) =
            lights.sample_direct(&self.scene.tris, &self.scene.accel, hit.p, hit.nf, rng)
        else {
            return;
        };
        if !lights.is_delta(sample.light) {
            return;
        }
        let frame = Frame::new(hit.ns);
        let (wo, wi) = (frame.to_local(-dir), frame.to_local(sample.dir));
        let Some((lobe, cos_h)) = reflection_lobe(Ggx { alpha }, wo, wi) else {
            return;
        };
        // Irradiance per unit spectrum is weight·cos θ; the lobe already holds cos θi (on
        // the shading normal), so the light's spectrum is scaled by weight·lobe.
        let scale = sample.weight * lobe;
        let l = lights.spectrum(sample.light);
        match kind {
            SurfaceKind::Mirror { reflectance, .. } => {
                let mut buf = std::mem::take(&mut s.refl);
                let mat = self.scene.material(hit);
                let reflectance = self.scene.reflectance_at(mat, reflectance, hit, &mut buf);
                for (i, o) in out.iter_mut().enumerate() {
                    *o += s.throughput[i] * l[i] * scale * schlick(reflectance[i], cos_h);
                }
                s.refl = buf;
            }
            SurfaceKind::Dielectric { eta, .. } => {
                for (i, o) in out.iter_mut().enumerate() {
                    let e = eta[i.min(eta.len() - 1)];
                    let (a, b) = if hit.front { (1.0, e) } else { (e, 1.0) };
                    let f = fresnel_dielectric(cos_h, a, b);
                    *o += s.throughput[i] * l[i] * scale * f;
                }
            }
            SurfaceKind::Diffuse { .. } => {}
        }
    }

    /// Irradiance at a diffuse point the camera sees, into `s.acc` (the caller turns it
    /// into radiance with the surface's reflectance).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn shade_diffuse(
        &self,
        p: Vec3,
        nf: Vec3,
        ns: Vec3,
        reflectance: &[f32],
        rng: &mut Rng,
        fg: GatherSequence,
        s: &mut Scratch,
        gather: Option<f32>,
    ) {
        if self.final_gather_rays == 0 {
            // Direct visualisation of the global map: all light in one estimate.
            self.density(
                self.global,
                p,
                nf,
                self.global_kernel,
                &mut s.hints[0],
                &mut s.found,
                &mut s.acc,
            );
            return;
        }
        // Direct light by light sampling.
        let scene = self.scene;
        let [u, v] = r2(fg.light_index, fg.light_offset);
        let u_light = [rng.next_f32(), u, v];
        // Written straight into the sum, which it overwrites bin by bin (as `density` above
        // clears it first): the values of adding it to zeros, without two passes over the
        // bins (only a zero's sign could differ).
        (scene.lights).direct(&scene.tris, &scene.accel, p, nf, ns, u_light, &mut s.acc);
        // Caustics from the caustic map (irradiance, like the other two terms).
        if let Some(cm) = self.caustic {
            self.caustic_irradiance(cm, p, nf, s);
            spd::add_scaled(&mut s.acc, &s.caustic_e, 1.0);
        }
        // The extra wavelengths of a split sample gather no indirect light: the
        // primary's final gather, scaled by `boost`, stands for all of them.
        let Some(boost) = gather else {
            return;
        };
        // Indirect light: final gather. Cosine sampling makes each ray's weight ρ, i.e.
        // irradiance π·mean(L), so it joins the other irradiance terms. The pixel's rays
        // are shared out among its camera samples (`fg.rays` of them here) and every ray
        // weighs the same, π·S/F (the pixel divides by S), so that any split — a sample
        // with no ray among them — estimates the pixel's indirect light without bias.
        // Pooled: the rays' radiance waits for the block (see [`Gather::block`]).
        if self.pool_gather {
            self.gather_rays(p, (nf, ns), rng, fg, s);
            let n = s.fg.len();
            let slot = s.slot as usize;
            let hit = PoolHit {
                p,
                nf,
                reach: self.pool_reach * s.path_len * s.footprint * s.stretch,
            };
            let px = &mut s.pixels[slot];
            let first_sample = px.hits == 0;
            match px.first {
                None => {
                    px.first = Some(hit);
                    px.uniform = true;
                }
                Some(first) => px.uniform &= shares_rays(&first, &hit),
            }
            px.hits += 1;
            px.rays += fg.rays;
            let sums = &mut s.pool[3 * n * slot..3 * n * (slot + 1)];
            let (w_sum, rest) = sums.split_at_mut(n);
            let (l_sum, wl_sum) = rest.split_at_mut(n);
            let inv_pi = std::f32::consts::FRAC_1_PI;
            let terms = s.throughput.iter().zip(reflectance).zip(&s.fg);
            let sums = w_sum
                .iter_mut()
                .zip(l_sum.iter_mut())
                .zip(wl_sum.iter_mut());
            // The pixel's first diffuse sample starts its sums (what adding to zeros
            // gives; a block does not clear them), the others add to them.
            let inv_pi = inv_pi * boost;
            if first_sample {
                for (((t, r), l), ((ws, ls), wls)) in terms.zip(sums) {
                    let w = t * r * inv_pi;
                    *ws = w;
                    *ls = *l;
                    *wls = w * l;
                }
            } else {
                for (((t, r), l), ((ws, ls), wls)) in terms.zip(sums) {
                    let w = t * r * inv_pi;
                    *ws += w;
                    *ls += l;
                    *wls += w * l;
                }
            }
            return;
        }
        if fg.rays > 0 {
            self.gather_rays(p, (nf, ns), rng, fg, s);
            let samples = self.camera_samples.max(1) as f32;
            let weight = std::f32::consts::PI * samples / self.final_gather_rays as f32;
            spd::add_scaled(&mut s.acc, &s.fg, weight * boost);
        }
    }

    /// The summed radiance of the sample's `fg.rays` final-gather rays from `p`, into
    /// `s.fg`: directions from the pixel's sequence, cosine-distributed about the shading
    /// normal `ns` — or, where the irradiance cache has a guide for `p`, drawn from the
    /// guide and each ray's radiance weighed by the cosine density over the guide's
    /// ([`guide::warp`]), which keeps the sum an estimate of the same irradiance / π. A direction below the geometric surface (`nf`, the side seen; only
    /// where smooth shading tilts `ns` away from it) brings nothing back.
    #[inline(always)]
    fn gather_rays(
        &self,
        p: Vec3,
        (nf, ns): (Vec3, Vec3),
        rng: &mut Rng,
        fg: GatherSequence,
        s: &mut Scratch,
    ) {
        s.fg.fill(0.0);
        if fg.rays == 0 {
            return;
        }
        // Where the photons here came from, if the cache knows (see `photon::guide`).
        let guide = (self.irradiance).and_then(|c| c.guide_at(p, nf, &mut s.guide_memo));
        for j in 0..fg.rays {
            let u = sobol02(fg.first.wrapping_add(j), fg.scramble);
            let (u, weight) = match guide {
                Some(g) => guide::warp(g, u),
                None => (u, 1.0),
            };
            let dir = cosine_hemisphere(ns, u);
            if ns != nf && !(dir.dot(nf) > 0.0) {
                continue;
            }
            let origin = self.scene.accel.offset(p, nf, dir);
            self.final_gather_ray(origin, dir, weight, rng, &mut s.ray, &mut s.fg);
        }
    }

    /// Radiance along a final-gather ray from the global map at its first diffuse hit
    /// (through mirrors and glass), times `weight`, added to `acc`. Emitters are not counted: direct light
    /// and caustics have their own estimates.
    #[inline(always)]
    fn final_gather_ray(
        &self,
        mut origin: Vec3,
        mut dir: Vec3,
        weight: f32,
        rng: &mut Rng,
        b: &mut RayBuffers,
        acc: &mut [f32],
    ) {
        let scene = self.scene;
        let RayBuffers {
            t,
            out,
            found,
            texel,
        } = b;
        t.fill(1.0);
        let mut lambda_u = None;
        for _ in 0..self.max_bounces {
            let Some(hit) = scene.intersect(origin, dir) else {
                return;
            };
            let (p, nf) = (hit.p, hit.nf);
            let mat = scene.material(&hit);
            mat.absorb_inside(&hit, t);
            match &mat.kind {
                SurfaceKind::Diffuse { reflectance } => {
                    // The irradiance E: a cached point's own N floats where the cache
                    // keeps them (no copy), else decoded or estimated into `out`. No cache
                    // point within the search cap means (almost surely) fewer than a
                    // handful of photons there: the ray adds nothing, rather than paying a
                    // full search for it.
                    let e: &[f32] = match self.irradiance {
                        Some(c) => match c.nearest(p, nf) {
                            None => return,
                            // Beyond the nearest point's reach (next to a bright
                            // patch, see `Reading::Outside`): an estimate of its own.
                            Some(i) if !c.covers(i, p) => {
                                let mut hint = c.hint(i, p);
                                let kernel = self.global_kernel;
                                self.density(self.global, p, nf, kernel, &mut hint, found, out);
                                out
                            }
                            Some(i) => match c.value(i) {
                                Some(v) => v,
                                None => {
                                    c.value_into(&self.scene.grid, i, out);
                                    out
                                }
                            },
                        },
                        None => {
                            let mut hint = 0.0;
                            let kernel = self.global_kernel;
                            self.density(self.global, p, nf, kernel, &mut hint, found, out);
                            out
                        }
                    };
                    let reflectance = scene.reflectance_at(mat, reflectance, &hit, texel);
                    // ρ E / π times the ray's throughput, added to the sum in one pass
                    // over the bins.
                    debug_assert_eq!(reflectance.len(), e.len());
                    debug_assert_eq!(acc.len(), e.len());
                    // The ray's weight (1 unguided) joins 1/π: not the throughput, whose
                    // size decides the roulette at rough bounces.
                    let k = std::f32::consts::FRAC_1_PI * weight;
                    let terms = e.iter().zip(reflectance.iter().zip(t.iter()));
                    for (a, (e, (r, t))) in acc.iter_mut().zip(terms) {
                        *a += *e * r * t * k;
                    }
                    return;
                }
                kind => match self.specular_bounce(
                    kind,
                    &hit,
                    dir,
                    t,
                    texel,
                    (&mut lambda_u, &mut None),
                    rng,
                ) {
                    Some((o, d)) => (origin, dir) = (o, d),
                    None => return,
                },
            }
        }
    }

    /// Continues a radiance path through a mirror or glass hit: updates the throughput
    /// `t` and returns the new ray, or None when the path ends.
    ///
    /// - At dispersive glass one bin is picked ∝ throughput, weight 1/p, so the estimate
    ///   stays unbiased, and the path's wavelength is drawn within that bin (once per
    ///   path: [`path_eta`]).
    /// - A transmitted ray's throughput scales by (ηi/ηt)², ηi on the side the ray comes
    ///   from: radiance/η² is what is conserved across an interface, so radiance in glass
    ///   seen from air is divided by n² (pbrt-v4's `ft /= Sqr(etap)` in radiance mode).
    ///   Photons carry flux, which is not scaled (importance transport).
    /// - At a metal (Fresnel · microfacet weight) and at rough glass (its weight) the
    ///   throughput is scaled, and a path that has grown faint plays Russian roulette
    ///   ([`roulette_when_faint`]), so paths end by absorption rather than by a cap.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn specular_bounce(
        &self,
        kind: &SurfaceKind,
        hit: &SurfaceHit,
        dir: Vec3,
        t: &mut [f32],
        texel: &mut Vec<f32>,
        (lambda_u, spectral_u): (&mut Option<f32>, &mut Option<f32>),
        rng: &mut Rng,
    ) -> Option<(Vec3, Vec3)> {
        let (p, n, nf, ns) = (hit.p, hit.n, hit.nf, hit.ns);
        let next = match kind {
            SurfaceKind::Diffuse { .. } => return None,
            SurfaceKind::Mirror { reflectance, alpha } => {
                let u = micro_sample(*alpha, rng);
                let (d, cos, w) = metal_bounce(*alpha, dir, nf, ns, u)?;
                let mat = self.scene.material(hit);
                let reflectance = self.scene.reflectance_at(mat, reflectance, hit, texel);
                if !attenuate_metal(t, reflectance, cos, w, rng.next_f32()) {
                    return None;
                }
                (self.scene.accel.offset(p, nf, d), d)
            }
            SurfaceKind::Dielectric {
                eta,
                eta_edges,
                dispersive,
                alpha,
            } => {
                let bin = match (dispersive, spd::single_nonzero(t)) {
                    (_, Some(bin)) => bin,
                    (false, None) => 0,
                    (true, None) => {
                        // The camera path's own stratified number, else a random one; the
                        // pick's remainder places the wavelength within its bin.
                        let u = spectral_u.take().unwrap_or_else(|| rng.next_f32());
                        let (bin, within) = pick_bin(t, u)?;
                        lambda_u.get_or_insert(within);
                        let total = spd::sum(t);
                        t.fill(0.0);
                        t[bin] = total;
                        bin
                    }
                };
                let e = path_eta(eta, eta_edges, *dispersive, bin, lambda_u, rng);
                let u = micro_sample(*alpha, rng);
                let (ev, w) = dielectric_bounce(*alpha, dir, n, ns, e, u, rng.next_f32())?;
                if w < 1.0 && !roulette_when_faint_after(t, w, rng.next_f32()) {
                    return None;
                }
                if ev.transmitted {
                    spd::scale(t, ev.eta_ratio * ev.eta_ratio);
                }
                (self.scene.accel.offset(p, n, ev.dir), ev.dir)
            }
        };
        (spd::max(t) > 0.0).then_some(next)
    }

    /// The caustic map's irradiance at `p` (facing `nf`) into `s.caustic_e`. A pixel's
    /// camera samples lie within a pixel of each other, and where the caustic estimate's
    /// radius spans several pixels their estimates sum nearly the same photons: a sample
    /// whose hit lies on the same surface within [`CAUSTIC_REUSE`] of the radius of the
    /// pixel's estimate so far reads that estimate instead of searching again. The sample
    /// that made it is a point of the pixel's own low-discrepancy sequence, spread over
    /// the pixel as the passes go on, so the pixel still averages the estimate over its
    /// area; only its spread within one pass is lost, which the kernel's width (at least
    /// twice the offsets shared across) makes small. At one camera sample a pixel, or where
    /// the radius is under two pixels' footprint, every sample estimates its own as before.
    #[inline(always)]
    fn caustic_irradiance(&self, cm: &PhotonMap, p: Vec3, nf: Vec3, s: &mut Scratch) {
        if let Some((p0, n0, r0)) = s.caustic_at {
            let d = p - p0;
            let (d2, h) = (d.length_squared(), d.dot(n0));
            let reach = self.caustic_reuse * r0;
            if d2 <= reach * reach && h * h <= d2 / 64.0 + 1e-12 && nf.dot(n0) >= 0.999 {
                return;
            }
        }
        let kernel = self.caustic_kernel;
        let r = self.density(
            cm,
            p,
            nf,
            kernel,
            &mut s.hints[1],
            &mut s.found,
            &mut s.caustic_e,
        );
        s.caustic_at = Some((p, nf, r));
    }

    /// A density estimate of irradiance (N bins, Σ flux / (π r²)) into `out`, its search starting at `hint`
    /// (the previous estimate's k-nearest radius; 0 for the kernel's own start), which it
    /// updates. Returns the radius it divided by.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn density(
        &self,
        map: &PhotonMap,
        p: Vec3,
        nf: Vec3,
        kernel: Kernel,
        hint: &mut f32,
        found: &mut Vec<(f32, u32)>,
        out: &mut [f32],
    ) -> f32 {
        out.fill(0.0);
        let kernel = kernel.starting_at(*hint);
        let e = map.estimate(&self.scene.grid, p, nf, kernel, found, out);
        *hint = e.r_k;
        let r = e.r.max(self.r_min);
        spd::scale(out, 1.0 / (std::f32::consts::PI * r * r));
        r
    }
}

/// Whether hit `b` lies on hit `a`'s surface close enough to lend it its final-gather rays:
/// within both reaches, in `a`'s tangent plane (as the caustic estimate's reuse tests) and
/// facing the same way within 8°.
fn shares_rays(a: &PoolHit, b: &PoolHit) -> bool {
    let d = b.p - a.p;
    let (d2, h) = (d.length_squared(), d.dot(a.nf));
    let reach = a.reach.min(b.reach);
    d2 <= reach * reach && h * h <= d2 / 64.0 + 1e-12 && a.nf.dot(b.nf) >= 0.99
}

/// The direction of camera `c`'s ray through image position (x, y) of a width × height
/// image, in pixels (may be fractional).
pub fn camera_dir(c: &crate::scene::Camera, x: f32, y: f32, width: u32, height: u32) -> Vec3 {
    camera_dir_with(c, camera_tan_half_fov(c), x, y, width, height)
}

/// tan(yfov / 2) of camera `c`, the factor [`camera_dir_with`] takes.
pub fn camera_tan_half_fov(c: &crate::scene::Camera) -> f32 {
    (0.5 * c.yfov).tan()
}

/// [`camera_dir`] with the camera's tan(yfov / 2) computed once by the caller.
fn camera_dir_with(
    c: &crate::scene::Camera,
    tan_y: f32,
    x: f32,
    y: f32,
    width: u32,
    height: u32,
) -> Vec3 {
    let aspect = width as f32 / height as f32;
    let sx = (2.0 * x / width as f32 - 1.0) * tan_y * aspect;
    let sy = (1.0 - 2.0 * y / height as f32) * tan_y;
    (c.forward + c.right * sx + c.up * sy).normalize()
}

/// `t` *= `w`, then [`roulette_when_faint`].
fn roulette_when_faint_after(t: &mut [f32], w: f32, u: f32) -> bool {
    spd::scale(t, w);
    roulette_when_faint(t, u)
}

/// A bin drawn with probability ∝ `t` by inverting its distribution at `u` ∈ [0, 1), and
/// where `u` fell within the bin's share (uniform in [0, 1) given the bin, so it can place
/// the wavelength within the bin without a random number of its own).
fn pick_bin(t: &[f32], u: f32) -> Option<(usize, f32)> {
    let total = spd::sum(t);
    if !(total > 0.0) {
        return None;
    }
    let target = u * total;
    let mut acc = 0.0;
    let mut last = None;
    for (i, &v) in t.iter().enumerate() {
        if v > 0.0 {
            let before = acc;
            acc += v;
            last = Some(i);
            if acc > target {
                return Some((i, within_unit((target - before) / v)));
            }
        }
    }
    // Rounding left the target past the last share: the top of the last bin.
    last.map(|i| (i, within_unit(1.0)))
}

/// `x` clamped into [0, 1).
fn within_unit(x: f32) -> f32 {
    x.clamp(0.0, 1.0 - f32::EPSILON / 2.0)
}

/// Point `i` of the 1-D Kronecker sequence of step √2 − 1 rotated by `offset`
/// (Cranley–Patterson), for the camera path's wavelength: any first n points leave at most
/// two in each of n equal intervals. The step is chosen against the sequences it runs beside
/// at the same index — the pixel's and the light's Kronecker steps and the final-gather
/// (0,2)-sequence — so that the wavelength follows none of them: 1/φ₄ is an integer
/// relation away from the pixel's R4 steps, the golden ratio lies 0.011 from one of them,
/// and radical inverses (base 3 or 5) line up with the (0,2)-sequence's second coordinate
/// (test `a_pixels_wavelengths_cover_the_spectrum_evenly_and_follow_no_other_sequence`).
#[inline]
fn spectral_point(i: u32, offset: f32) -> f32 {
    kronecker(i, std::f64::consts::SQRT_2 - 1.0, offset)
}

/// Point `i` of a 2-D Kronecker sequence rotated by `offset`, for the camera ray's
/// position within its pixel. Its steps are the third and fourth of Roberts' R4 sequence
/// (powers of 1/φ₄, φ₄ the real root of x⁵ = x + 1), not R2's: the light sample follows R2
/// at the same index, and two R2 copies would be the same lattice shifted, so the
/// sub-pixel position and the point on the light would move in lock step.
#[inline]
fn pixel_jitter(i: u32, offset: [f32; 2]) -> [f32; 2] {
    const A: [f64; 2] = [0.628_706_721_037_808_6, 0.538_597_257_223_610_1];
    [kronecker(i, A[0], offset[0]), kronecker(i, A[1], offset[1])]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A gather over these maps with both kernels `kernel`, 4 rays and 4 camera samples,
    /// unpooled.
    fn test_gather<'a>(
        scene: &'a SpectralScene,
        global: &'a PhotonMap,
        caustic: Option<&'a PhotonMap>,
        kernel: Kernel,
    ) -> Gather<'a> {
        Gather {
            scene,
            global,
            caustic,
            irradiance: None,
            global_kernel: kernel,
            caustic_kernel: kernel,
            r_min: 1e-6,
            final_gather_rays: 4,
            pool_gather: false,
            pool_reach: POOL_REACH,
            camera_samples: 4,
            glass_split: 1,
            max_bounces: 16,
            caustic_reuse: CAUSTIC_REUSE,
            tan_half_fov: camera_tan_half_fov(&scene.camera),
            avx: crate::cpu::has_avx(),
        }
    }

    /// The Cornell box on 2 bins and an empty photon map, for the pooling tests (their
    /// sums are set by hand).
    fn two_bin_box() -> (SpectralScene, PhotonMap) {
        use crate::spectral::BinGrid;
        let scene = crate::scene::load_builtin("cornell-box").unwrap();
        let scene = SpectralScene::new(&scene, BinGrid::with_bins(2).unwrap());
        let record = crate::photon::record::Record::Full;
        let empty = PhotonMap::build(crate::photon::PhotonBatch::new(record, &scene.grid));
        (scene, empty)
    }

    /// A pooled gather of 2 camera samples and 2 rays a pixel.
    fn pooling_gather<'a>(scene: &'a SpectralScene, empty: &'a PhotonMap) -> Gather<'a> {
        Gather {
            final_gather_rays: 2,
            pool_gather: true,
            camera_samples: 2,
            glass_split: 1,
            ..test_gather(scene, empty, None, Kernel::adaptive(8, 1.0, 1.0, 1.0))
        }
    }

    #[test]
    fn a_block_pools_its_uniform_pixels_rays_exactly_and_keeps_a_nan_at_home() {
        // Four pixels of 2 camera samples and 2 rays each, hand-set: 0, 1 and 3 on one
        // plane (1's rays brought back a NaN), 2 across an edge (its samples on two walls).
        let (scene, empty) = two_bin_box();
        let gather = pooling_gather(&scene, &empty);
        let mut s = Scratch::new(2);
        let hit = |x: f32, nf: Vec3| PoolHit {
            p: Vec3::new(x, 0.0, 0.0),
            nf,
            reach: 1.0,
        };
        let px = |first, uniform| PixelPool {
            first: Some(first),
            hits: 2,
            uniform,
            rays: 2,
        };
        s.pixels = [
            px(hit(0.0, Vec3::Z), true),
            px(hit(0.3, Vec3::Z), true),
            px(hit(0.5, Vec3::X), false),
            px(hit(0.6, Vec3::Z), true),
        ];
        // Per pixel: Σw, ΣL, Σw⊙L (2 bins each).
        let sums: [[f32; 6]; 4] = [
            [1.0, 2.0, 4.0, 8.0, 3.0, 5.0],
            [1.0, 1.0, f32::NAN, 0.0, f32::NAN, 0.0],
            [2.0, 2.0, 6.0, 6.0, 7.0, 9.0],
            [0.5, 0.5, 2.0, 4.0, 1.0, 1.0],
        ];
        s.pool = sums.concat();
        let mut outs = vec![vec![0.0f32; 2]; 4];
        gather.resolve_shared(4, &mut s, &mut outs);
        let pi = std::f32::consts::PI;
        // Pixel 0 pools itself and 3 (not 1's NaN, not 2 across the edge): 4 rays, 2
        // samples: Σw ⊙ π (ΣL₀ + ΣL₃) / (4·2).
        let expect0 = [1.0 * pi * 6.0 / 8.0, 2.0 * pi * 12.0 / 8.0];
        for (o, e) in outs[0].iter().zip(expect0) {
            assert!((o - e).abs() < 1e-5 * e, "{:?} vs {expect0:?}", outs[0]);
        }
        // Pixel 2 keeps its own rays' estimate: Σw⊙L · π/F.
        assert_eq!(outs[2], vec![7.0 * pi / 2.0, 9.0 * pi / 2.0]);
        // Pixel 1's NaN stays in pixel 1.
        assert!(outs[1][0].is_nan());
        assert!(
            outs[0]
                .iter()
                .chain(&outs[2])
                .chain(&outs[3])
                .all(|v| v.is_finite())
        );
    }

    #[test]
    fn a_pixel_without_a_diffuse_sample_reads_no_sums_left_by_another_block() {
        // The block's sums are not cleared between blocks: pixels 1 and 3 saw no diffuse
        // surface, so their slots still hold another block's values (NaN here); pixel 0
        // pools with pixel 2 only, and 1 and 3 get no final-gather light.
        let (scene, empty) = two_bin_box();
        let gather = pooling_gather(&scene, &empty);
        let mut s = Scratch::new(2);
        let seen = |x: f32| PixelPool {
            first: Some(PoolHit {
                p: Vec3::new(x, 0.0, 0.0),
                nf: Vec3::Z,
                reach: 1.0,
            }),
            hits: 2,
            uniform: true,
            rays: 2,
        };
        s.pixels = [
            seen(0.0),
            PixelPool::default(),
            seen(0.2),
            PixelPool::default(),
        ];
        let stale = [f32::NAN; 6];
        let sums: [[f32; 6]; 4] = [
            [1.0, 1.0, 2.0, 2.0, 2.0, 2.0],
            stale,
            [1.0, 1.0, 4.0, 4.0, 4.0, 4.0],
            stale,
        ];
        s.pool = sums.concat();
        let mut outs = vec![vec![0.0f32; 2]; 4];
        gather.resolve_shared(4, &mut s, &mut outs);
        let pi = std::f32::consts::PI;
        // Σw ⊙ π (ΣL₀ + ΣL₂) / (4 rays · 2 samples).
        let e = pi * 6.0 / 8.0;
        for o in &outs[0] {
            assert!((o - e).abs() < 1e-5 * e, "{:?}", outs[0]);
        }
        assert_eq!(outs[1], vec![0.0, 0.0]);
        assert_eq!(outs[3], vec![0.0, 0.0]);
    }

    #[test]
    fn hits_pool_rays_on_their_own_surface_and_side_within_reach_only() {
        let at = |p: Vec3, nf: Vec3, reach: f32| PoolHit { p, nf, reach };
        let a = at(Vec3::ZERO, Vec3::Z, 1.0);
        let near = at(Vec3::new(0.7, 0.0, 0.0), Vec3::Z, 1.0);
        assert!(shares_rays(&a, &a) && shares_rays(&a, &near) && shares_rays(&near, &a));
        let cases = [
            (at(Vec3::new(1.2, 0.0, 0.0), Vec3::Z, 1.0), "beyond reach"),
            (
                at(Vec3::new(0.7, 0.0, 0.0), Vec3::Z, 0.5),
                "beyond the other's reach",
            ),
            (
                at(Vec3::new(0.7, 0.0, 0.0), -Vec3::Z, 1.0),
                "the other side",
            ),
            (
                at(Vec3::new(0.7, 0.0, 0.0), Vec3::X, 1.0),
                "a perpendicular wall",
            ),
            (
                at(Vec3::new(0.5, 0.0, 0.1), Vec3::Z, 1.0),
                "a parallel surface above",
            ),
            (
                at(
                    Vec3::new(0.5, 0.0, 0.0),
                    Vec3::new(0.0, 0.2, 1.0).normalize(),
                    1.0,
                ),
                "a surface tilted 11°",
            ),
        ];
        for (b, what) in cases {
            assert!(!shares_rays(&a, &b), "{what}");
        }
    }

    /// Points `start..start + n` of the pixel sequence at `offset`.
    fn run(start: u32, n: u32, offset: [f32; 2]) -> Vec<[f32; 2]> {
        (start..start + n)
            .map(|i| pixel_jitter(i, offset))
            .collect()
    }

    #[test]
    fn any_run_of_pixel_points_covers_the_pixel_evenly() {
        // A pixel's camera rays over 64 consecutive samples, any offset, any start: every
        // box [0, a) × [0, b) on a 16 × 16 grid holds 64·a·b points to within 7 (64
        // independent uniform points stray by up to 15 over the same boxes and trials).
        let mut rng = Rng::stream(7, 0, 0, Purpose::Camera);
        for _ in 0..16 {
            let offset = rng.next_2d();
            let points = run(rng.next_u32() % 100_000, 64, offset);
            assert!(points.iter().flatten().all(|v| (0.0..1.0).contains(v)));
            for a in (1..=16).map(|i| i as f32 / 16.0) {
                for b in (1..=16).map(|i| i as f32 / 16.0) {
                    let n = points.iter().filter(|p| p[0] < a && p[1] < b).count() as f32;
                    assert!(
                        (n - 64.0 * a * b).abs() <= 7.0,
                        "box {a} × {b}: {n} points, offset {offset:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_point_in_the_pixel_does_not_follow_the_point_on_the_light() {
        // Both run at the same index with independent offsets. Two copies of R2 would be
        // one lattice shifted: a pixel coordinate against the light's same coordinate
        // would lie on a few lines (x' = x + c mod 1), leaving most of the unit square
        // empty. The pixel's own steps fill it: over 256 points every cell of a 4 × 4 grid
        // of (pixel coordinate, light coordinate) holds at least 8 (16 expected).
        let cells = |pairs: &mut dyn Iterator<Item = (f32, f32)>| {
            let mut c = [0u32; 16];
            for (x, y) in pairs {
                c[(x * 4.0) as usize * 4 + (y * 4.0) as usize] += 1;
            }
            c
        };
        let mut rng = Rng::stream(8, 0, 0, Purpose::Camera);
        for _ in 0..16 {
            let (o_pixel, o_light) = (rng.next_2d(), rng.next_2d());
            for a in 0..2 {
                for b in 0..2 {
                    let c = cells(
                        &mut (0..256).map(|i| (pixel_jitter(i, o_pixel)[a], r2(i, o_light)[b])),
                    );
                    assert!(c.iter().all(|&n| n >= 8), "dims {a}, {b}: {c:?}");
                }
                // The check can tell: a second R2 copy leaves cells empty.
                let c = cells(&mut (0..256).map(|i| (r2(i, o_pixel)[a], r2(i, o_light)[a])));
                assert!(c.contains(&0), "dim {a}: {c:?}");
            }
        }
    }

    #[test]
    fn the_bin_pick_inverts_the_throughput_and_its_remainder_is_uniform_in_the_bin() {
        // Bins of weight 0, 1, 3, 0, 4 (total 8), picked at 8 000 evenly spaced u: each
        // positive bin 1 000 times its weight (to within one), and within each bin the
        // remainders fall one in each of its own count's equal intervals (to within one).
        let t = [0.0, 1.0, 3.0, 0.0, 4.0];
        let m = 8000;
        let mut within: [Vec<f32>; 5] = Default::default();
        for j in 0..m {
            let (bin, w) = pick_bin(&t, (j as f32 + 0.5) / m as f32).unwrap();
            assert!((0.0..1.0).contains(&w), "{w}");
            within[bin].push(w);
        }
        for (bin, ws) in within.iter_mut().enumerate() {
            let want = t[bin] / 8.0 * m as f32;
            assert!(
                (ws.len() as f32 - want).abs() <= 1.0,
                "bin {bin}: {}",
                ws.len()
            );
            ws.sort_by(f32::total_cmp);
            let n = ws.len() as f32;
            for (k, w) in ws.iter().enumerate() {
                assert!(
                    (w - (k as f32 + 0.5) / n).abs() <= 1.5 / n,
                    "bin {bin}: {k}th {w}"
                );
            }
        }
        // The top of the range stays in the last positive bin, below 1; nothing to pick
        // from gives no bin.
        let (bin, w) = pick_bin(&t, 1.0 - f32::EPSILON / 2.0).unwrap();
        assert!(bin == 4 && w < 1.0, "{bin} {w}");
        assert_eq!(pick_bin(&[0.0; 4], 0.5), None);
    }

    #[test]
    fn a_pixels_wavelengths_cover_the_spectrum_evenly_and_follow_no_other_sequence() {
        let mut rng = Rng::stream(9, 0, 0, Purpose::Camera);
        for _ in 0..16 {
            let offset = rng.next_f32();
            // The first n points for any n ≤ 300: at most two in each of n equal intervals
            // (independent uniform points put 4 to 6 in the fullest interval at these n).
            for n in 2..=300u32 {
                let mut c = vec![0u32; n as usize];
                for i in 0..n {
                    let u = spectral_point(i, offset);
                    assert!((0.0..1.0).contains(&u), "{u}");
                    c[((u * n as f32) as usize).min(n as usize - 1)] += 1;
                }
                let most = *c.iter().max().unwrap();
                assert!(most <= 2, "n {n}: {most}");
            }
            // Against the pixel's, the light's and the final-gather sequences at the same
            // index (as when a camera sample carries one final-gather ray): every cell of a
            // 4 × 4 grid of (wavelength, other coordinate) over 256 points holds at least 8.
            let (o_pixel, o_light) = (rng.next_2d(), rng.next_2d());
            let scramble = [rng.next_u32(), rng.next_u32()];
            for a in 0..2 {
                let others: [&dyn Fn(u32) -> f32; 3] = [
                    &|i| pixel_jitter(i, o_pixel)[a],
                    &|i| r2(i, o_light)[a],
                    &|i| sobol02(i, scramble)[a],
                ];
                for (which, other) in others.iter().enumerate() {
                    let mut c = [0u32; 16];
                    for i in 0..256 {
                        let (x, y) = (spectral_point(i, offset), other(i));
                        c[((x * 4.0) as usize).min(3) * 4 + ((y * 4.0) as usize).min(3)] += 1;
                    }
                    assert!(c.iter().all(|&n| n >= 8), "sequence {which} dim {a}: {c:?}");
                }
            }
        }
    }

    #[test]
    fn a_pixels_samples_share_its_caustic_estimate_only_on_its_surface_within_reach() {
        // Uniform caustic photons on z = 0 (E = 4): an estimate at p0 is shared by a hit
        // within half its radius on the same plane and side, and made anew beyond that,
        // on a perpendicular wall through the same point, on a parallel surface a small
        // gap above, and in the next pixel.
        use crate::photon::map::tests::uniform_unit_square;
        use crate::photon::record::Record;
        use crate::scene::load_builtin;
        use crate::spectral::BinGrid;
        let grid = BinGrid::with_bins(4).unwrap();
        let scene = SpectralScene::new(&load_builtin("prism").unwrap(), grid.clone());
        let map = uniform_unit_square(&grid, Record::Full, 4);
        let empty = PhotonMap::build(crate::photon::PhotonBatch::new(Record::Full, &grid));
        let kernel = Kernel {
            k: 48,
            r_max: 0.2,
            r_start: 0.03,
            shrink: 1.0,
        };
        let gather = test_gather(&scene, &empty, Some(&map), kernel);
        let mut s = Scratch::new(4);
        let p0 = Vec3::new(0.5, 0.5, 0.0);
        gather.caustic_irradiance(&map, p0, Vec3::Z, &mut s);
        let (_, _, r0) = s.caustic_at.unwrap();
        // About √(47/(4π)) ≈ 0.019 for 48 photons at 40 000 per unit area.
        assert!((0.012..0.03).contains(&r0), "{r0}");
        let e0 = s.caustic_e.clone();
        assert!((e0[0] / 4.0 - 1.0).abs() < 0.35, "{e0:?}");
        let made_at = |s: &Scratch| s.caustic_at.unwrap().0;
        // Same plane, within reach: shared (the estimate and where it was made unchanged).
        let near = p0 + Vec3::new(0.45 * r0, 0.0, 0.0);
        gather.caustic_irradiance(&map, near, Vec3::Z, &mut s);
        assert_eq!((made_at(&s), &s.caustic_e), (p0, &e0));
        // A normal tilted 0.03 rad still counts as the same surface.
        let tilted = |t: f32| Vec3::new(0.0, t, 1.0).normalize();
        let beside = p0 + Vec3::new(0.2 * r0, 0.0, 0.0);
        gather.caustic_irradiance(&map, beside, tilted(0.03), &mut s);
        assert_eq!((made_at(&s), &s.caustic_e), (p0, &e0));
        // Each of these makes its own estimate, after a fresh one at p0.
        let own = [
            (p0 + Vec3::new(0.55 * r0, 0.0, 0.0), Vec3::Z, "beyond reach"),
            (beside, Vec3::X, "a perpendicular wall"),
            (beside, tilted(0.05), "a 0.05 rad tilt"),
            (beside, -Vec3::Z, "the other side"),
            (
                beside + Vec3::new(0.0, 0.0, 0.1 * r0),
                Vec3::Z,
                "a surface 0.1 r above",
            ),
        ];
        for (p, n, what) in own {
            s.start_pixel();
            gather.caustic_irradiance(&map, p0, Vec3::Z, &mut s);
            gather.caustic_irradiance(&map, p, n, &mut s);
            assert_eq!(made_at(&s), p, "{what}: shared the estimate at p0");
        }
        // A new pixel estimates anew even at the same point.
        s.start_pixel();
        gather.caustic_irradiance(&map, near, Vec3::Z, &mut s);
        assert_eq!(made_at(&s), near);
        // With sharing off every sample estimates its own.
        let unshared = Gather {
            caustic_reuse: 0.0,
            ..gather
        };
        s.start_pixel();
        unshared.caustic_irradiance(&map, p0, Vec3::Z, &mut s);
        unshared.caustic_irradiance(&map, near, Vec3::Z, &mut s);
        assert_eq!(made_at(&s), near);
    }
}
