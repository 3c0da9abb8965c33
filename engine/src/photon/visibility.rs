//! What the camera sees, coarsely: the cubes (and surface sides) that camera rays and one
//! diffuse bounce from them reach. A photon stored in one of them can light a pixel,
//! directly through the final gather's cache or as the light a final-gather ray finds;
//! one stored elsewhere (on a roof, behind the camera, beyond the view) mostly cannot.
//! Learned emission ([`crate::lights::adaptive`]) counts a photon as useful when any of
//! its records lands in one. The cubes only steer where photons are emitted, with every
//! photon's weight corrected for it: a cube missed here costs noise, never bias.

use std::collections::HashSet;
use std::hash::BuildHasherDefault;

use glam::Vec3;

use super::irradiance::{CellHasher, CellKey, cell_key};
use crate::materials::{dielectric_bounce, metal_bounce};
use crate::render::gather::camera_dir;
use crate::sampling::{Purpose, Rng, cosine_hemisphere};
use crate::scene::{SpectralScene, SurfaceKind};

/// Cubes along the scene's bounding diagonal.
const CUBES_ALONG_DIAGONAL: f32 = 64.0;
/// Camera rays across the image's width (rows follow its aspect).
const PROBE_COLUMNS: u32 = 96;
/// Diffuse bounces sent from each camera ray's diffuse hit (as final-gather rays are).
const BOUNCES: u32 = 4;
/// Mirror and glass bounces a probe follows before it gives up.
const MAX_SPECULAR: u32 = 8;

type KeySet = HashSet<CellKey, BuildHasherDefault<CellHasher>>;

/// The cubes of surfaces the camera sees, directly and one diffuse bounce away.
#[derive(Debug)]
pub struct VisibleSurfaces {
    inv_cell: f32,
    keys: KeySet,
}

impl VisibleSurfaces {
    /// Probes `scene` from its camera for a `width` × `height` image: a grid of
    /// jittered camera rays through mirrors and glass (one wavelength's index, the
    /// middle bin's) to their diffuse hit, and [`BOUNCES`] cosine rays from each.
    /// Deterministic for a seed.
    pub fn probe(scene: &SpectralScene, width: u32, height: u32, seed: u64) -> Self {
        let inv_cell = CUBES_ALONG_DIAGONAL / scene.diagonal().max(1e-12);
        let (w, h) = (width.max(1), height.max(1));
        let cols = PROBE_COLUMNS;
        let rows = ((PROBE_COLUMNS as f32 * h as f32 / w as f32).round() as u32).clamp(1, 4096);
        let mut keys = KeySet::default();
        for j in 0..rows {
            for i in 0..cols {
                let index = u64::from(j) * u64::from(cols) + u64::from(i);
                let mut rng = Rng::stream(seed, 0, index, Purpose::Visibility);
                let [a, b] = rng.next_2d();
                let x = (i as f32 + a) / cols as f32 * w as f32;
                let y = (j as f32 + b) / rows as f32 * h as f32;
                let dir = camera_dir(&scene.camera, x, y, w, h);
                let origin = scene.camera.position;
                let Some((p, nf)) = diffuse_hit(scene, origin, dir, &mut rng) else {
                    continue;
                };
                keys.insert(cell_key(p, nf, inv_cell));
                for _ in 0..BOUNCES {
                    let d = cosine_hemisphere(nf, rng.next_2d());
                    let o = scene.accel.offset(p, nf, d);
                    if let Some((q, nq)) = diffuse_hit(scene, o, d, &mut rng) {
                        keys.insert(cell_key(q, nq, inv_cell));
                    }
                }
            }
        }
        Self { inv_cell, keys }
    }

    /// Whether a surface at `p` facing `nf` (towards the light's side) is seen.
    #[inline]
    pub fn contains(&self, p: Vec3, nf: Vec3) -> bool {
        self.keys.contains(&cell_key(p, nf, self.inv_cell))
    }

    /// How many cubes (and sides) are seen.
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }
}

/// The first diffuse surface along a ray, through mirrors and glass: its point and
/// normal (facing the ray's side).
fn diffuse_hit(
    scene: &SpectralScene,
    mut origin: Vec3,
    mut dir: Vec3,
    rng: &mut Rng,
) -> Option<(Vec3, Vec3)> {
    for _ in 0..=MAX_SPECULAR {
        let hit = scene.intersect(origin, dir)?;
        match &scene.material(&hit).kind {
            SurfaceKind::Diffuse { .. } => return Some((hit.p, hit.nf)),
            SurfaceKind::Mirror { alpha, .. } => {
                let (d, _, _) = metal_bounce(*alpha, dir, hit.nf, hit.ns, rng.next_2d())?;
                dir = d;
                origin = scene.accel.offset(hit.p, hit.nf, dir);
            }
            SurfaceKind::Dielectric { eta, alpha, .. } => {
                let e = eta[eta.len() / 2];
                let (ev, _) = dielectric_bounce(
                    *alpha,
                    dir,
                    hit.n,
                    hit.ns,
                    e,
                    rng.next_2d(),
                    rng.next_f32(),
                )?;
                dir = ev.dir;
                origin = scene.accel.offset(hit.p, hit.n, dir);
            }
        }
    }
    None
}
