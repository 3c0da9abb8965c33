//! A [`Scene`] projected onto one bin grid: per-bin reflectances, indices and emission,
//! the BVH, the lights with their sampling distributions, and what the scene needs
//! (specular paths? dispersion?). Immutable and shared by every thread of a render.

use glam::Vec3;

use super::texture::TextureRef;
use super::{Material, MaterialKind, PunctualKind, PunctualLight, Scene};
use crate::geometry::{Accel, SurfaceHit, TriData, triangle_normal};
use crate::lights::{Light, LightKind, LightSet, MAX_TARGETS, Target};
use crate::photon::record::{NormalCode, oct_encode};
use crate::sampling::one_minus_cos;
use crate::spectral::{BinGrid, Role, Spectrum, Transport, spd};

/// Surface behaviour with per-bin data.
#[derive(Clone, Debug)]
pub enum SurfaceKind {
    Diffuse {
        reflectance: Vec<f32>,
    },
    /// `alpha`: GGX roughness (0: a perfect mirror reflecting `reflectance`; else the
    /// reflectance is Schlick's F0 per bin).
    Mirror {
        reflectance: Vec<f32>,
        alpha: f32,
    },
    /// `eta[i]`: index in bin i (at its centre); `dispersive`: whether the bins differ;
    /// `eta_edges[i]`, `eta_edges[i + 1]`: the index at bin i's edges (dispersive glass
    /// only: light refracts at a wavelength drawn within its bin, see [`eta_in_bin`]);
    /// `alpha`: GGX roughness (0: smooth).
    Dielectric {
        eta: Vec<f32>,
        eta_edges: Vec<f32>,
        dispersive: bool,
        alpha: f32,
    },
}

/// glTF's base colour where it varies: factor × texel × vertex colour, linear RGB.
#[derive(Clone, Debug)]
pub struct BaseColor {
    pub factor: [f32; 3],
    pub texture: Option<TextureRef>,
    /// Multiply by the colour interpolated between the triangle's corners
    /// ([`SpectralScene::triangle_colors`]).
    pub vertex_colors: bool,
}

#[derive(Clone, Debug)]
pub struct SMaterial {
    pub name: String,
    pub kind: SurfaceKind,
    pub emission: Option<Vec<f32>>,
    /// Absorption coefficient σ per bin inside a glass (per scene unit), if it absorbs.
    pub absorption: Option<Vec<f32>>,
    /// A base colour that varies over the surface (a texture, vertex colours or both),
    /// upsampled per hit; None: `kind`'s reflectance everywhere.
    pub base: Option<BaseColor>,
    /// An emissive texture: it filters `emission` per hit.
    pub emission_texture: Option<TextureRef>,
    /// A tangent-space normal map and its scale (glTF `normalTexture`).
    pub normal_map: Option<(TextureRef, f32)>,
}

impl SMaterial {
    /// A segment that ends on the back face of an absorbing glass ran inside it:
    /// Beer–Lambert over its length, into `t` (closed glass objects; a surface nested
    /// inside a glass does not know it is immersed).
    #[inline]
    pub fn absorb_inside(&self, hit: &SurfaceHit, t: &mut [f32]) {
        if let (false, Some(sigma)) = (hit.front, &self.absorption) {
            crate::materials::absorb(t, sigma, hit.t);
        }
    }
}

pub struct SpectralScene {
    pub name: String,
    pub grid: BinGrid,
    pub accel: Accel,
    pub tris: Vec<TriData>,
    /// Each triangle's geometric normal as a photon record stores it (the octahedral code),
    /// front and back: a photon's store reads it instead of encoding its hit's `nf`, the
    /// same normal exactly (see [`Self::normal_code`]).
    normal_codes: Vec<[u32; 2]>,
    /// Vertex shading normals per triangle (empty: flat shading everywhere).
    pub shading_normals: Vec<[Vec3; 3]>,
    /// Vertex texture coordinates per triangle (empty: none).
    pub triangle_uvs: Vec<[glam::Vec2; 3]>,
    /// Vertex colours (linear RGB) per triangle (empty: none).
    pub triangle_colors: Vec<[Vec3; 3]>,
    /// Per triangle, ∂p/∂u and −∂p/∂v (glTF's v runs down the image, a normal map's +y
    /// up it): the tangent frame of a normal map. Zero where no normal map applies or the
    /// texture coordinates are degenerate; empty when no material has a normal map.
    pub tangents: Vec<[Vec3; 2]>,
    /// The file's own vertex tangents per triangle (glTF `TANGENT`, see
    /// [`Scene::triangle_tangents`]): preferred to `tangents` where present.
    pub vertex_tangents: Vec<[glam::Vec4; 3]>,
    pub materials: Vec<SMaterial>,
    pub lights: LightSet,
    /// Radiance of the uniform sky, seen by camera paths that escape (None: black).
    pub environment: Option<Vec<f32>>,
    pub camera: super::Camera,
    pub bounds: (Vec3, Vec3),
    /// Total area of diffuse triangles (for the default gather radius).
    pub diffuse_area: f64,
    /// Whether any surface is specular (mirror or glass): else no caustic map is built.
    pub has_specular: bool,
    /// Whether any glass disperses on this grid: else no photon is ever split.
    pub has_dispersion: bool,
    pub warnings: Vec<String>,
}

impl SpectralScene {
    pub fn new(scene: &Scene, grid: BinGrid) -> Self {
        let mut warnings = scene.warnings.clone();
        let materials: Vec<SMaterial> = scene
            .materials
            .iter()
            .map(|m| project_material(m, &grid))
            .collect();
        let (tris, mut lights, diffuse_area) = triangles_and_area_lights(scene, &materials, &grid);
        let bounds = scene.bounds();
        let sphere = bounding_sphere(bounds);
        for l in &scene.lights {
            match punctual_light(l, &grid, sphere) {
                Some(light) => lights.push(light),
                None => warnings.push(format!("light '{}' is black and is skipped", l.name)),
            }
        }
        let environment = scene
            .environment
            .as_ref()
            .map(|e| grid.project(e, Role::Emission))
            .filter(|e| grid.to_xyz(e)[1] > 0.0);
        if let Some(e) = &environment {
            let (center, radius) = sphere;
            let y = grid.to_xyz(e)[1];
            let pi = std::f64::consts::PI;
            lights.push(Light {
                kind: LightKind::Environment { center, radius },
                spectrum: e.clone(),
                power: (y * 4.0 * pi * pi * (radius as f64).powi(2)) as f32,
            });
        }
        let has_specular = materials
            .iter()
            .any(|m| !matches!(m.kind, SurfaceKind::Diffuse { .. }));
        let has_dispersion = materials.iter().any(|m| {
            matches!(
                m.kind,
                SurfaceKind::Dielectric {
                    dispersive: true,
                    ..
                }
            )
        });
        let tangents = uv_tangents(scene, &materials);
        let mut accel = Accel::new(&scene.triangles);
        if let Some((holed, cutouts)) = AlphaCutouts::of(scene, &tris) {
            accel.set_cutouts(&holed, std::sync::Arc::new(cutouts));
        }
        let mut lights = LightSet::new(lights, &tris);
        lights.aim_at(&specular_targets(scene, &materials), &tris);
        Self {
            name: scene.name.clone(),
            accel,
            lights,
            environment,
            grid,
            normal_codes: tris
                .iter()
                .map(|t| [oct_encode(t.normal), oct_encode(-t.normal)])
                .collect(),
            tris,
            triangle_uvs: if scene.triangle_uvs.len() == scene.triangles.len() {
                scene.triangle_uvs.clone()
            } else {
                Vec::new()
            },
            tangents,
            vertex_tangents: if scene.triangle_tangents.len() == scene.triangles.len()
                && materials.iter().any(|m| m.normal_map.is_some())
            {
                scene.triangle_tangents.clone()
            } else {
                Vec::new()
            },
            triangle_colors: if scene.triangle_colors.len() == scene.triangles.len() {
                scene.triangle_colors.clone()
            } else {
                Vec::new()
            },
            shading_normals: if scene.shading_normals.len() == scene.triangles.len() {
                scene.shading_normals.clone()
            } else {
                Vec::new()
            },
            materials,
            camera: scene.camera,
            bounds,
            diffuse_area,
            has_specular,
            has_dispersion,
            warnings,
        }
    }

    pub fn bins(&self) -> usize {
        self.grid.len()
    }

    pub fn diagonal(&self) -> f32 {
        (self.bounds.1 - self.bounds.0).length()
    }

    /// The octahedral code of `hit.nf` (the code `oct_encode(hit.nf)` gives, read from a
    /// table: `nf` is the triangle's normal or its negation).
    #[inline]
    pub fn normal_code(&self, hit: &SurfaceHit) -> NormalCode {
        NormalCode(self.normal_codes[hit.prim as usize][usize::from(!hit.front)])
    }

    /// The closest surface along a ray, with its normals and material.
    #[inline]
    pub fn intersect(&self, origin: Vec3, dir: Vec3) -> Option<SurfaceHit> {
        let hit = self.accel.intersect(origin, dir, f32::INFINITY)?;
        let i = hit.prim as usize;
        let mut h = SurfaceHit::new(
            &self.tris[i],
            self.shading_normals.get(i),
            origin,
            dir,
            hit.t,
        );
        h.prim = hit.prim;
        self.apply_normal_map(&mut h);
        Some(h)
    }

    /// Tilts `h.ns` by its material's normal map, if it has one: the texel's
    /// tangent-space normal (2c − 1, x and y times the scale) in the frame of the
    /// triangle's tangents about the interpolated normal. A tilt past the geometric
    /// surface's horizon is not applied.
    fn apply_normal_map(&self, h: &mut SurfaceHit) {
        let Some((tex, scale)) = &self.materials[h.material as usize].normal_map else {
            return;
        };
        let i = h.prim as usize;
        let (Some(&[t, b]), Some(uv)) = (self.tangents.get(i), self.triangle_uvs.get(i)) else {
            return;
        };
        let (b1, b2) = h.bary;
        let b0 = 1.0 - b1 - b2;
        // The outward interpolated normal (ns faces the side the ray came from).
        let n = if h.front { h.ns } else { -h.ns };
        // The file's tangents, interpolated (glTF: bitangent = w · n × t), else the
        // triangle's own frame from its texture coordinates.
        let (t, b) = match self.vertex_tangents.get(i) {
            Some(vt) if vt.iter().all(|v| v.w != 0.0) => {
                let t = (vt[0] * b0 + vt[1] * b1 + vt[2] * b2).truncate();
                (t, n.cross(t) * vt[0].w)
            }
            _ => (t, b),
        };
        if t == Vec3::ZERO {
            return;
        }
        let c = tex.sample(uv[0] * b0 + uv[1] * b1 + uv[2] * b2);
        let m = Vec3::new(
            (2.0 * c[0] - 1.0) * scale,
            (2.0 * c[1] - 1.0) * scale,
            2.0 * c[2] - 1.0,
        );
        let t = (t - n * n.dot(t)).normalize_or_zero();
        let b = (b - n * n.dot(b) - t * t.dot(b)).normalize_or_zero();
        let tilted = (t * m.x + b * m.y + n * m.z).normalize_or_zero();
        let tilted = if h.front { tilted } else { -tilted };
        if tilted.is_finite() && tilted.dot(h.nf) > 0.0 {
            h.ns = tilted;
        }
    }

    /// The diffuse reflectance (N bins) at a hit: the material's own, or, for a textured
    /// material, factor × texel upsampled like any reflectance (Smits; on the RGB grid the
    /// colour itself), written into `scratch`.
    #[inline]
    pub fn reflectance_at<'a>(
        &'a self,
        mat: &'a SMaterial,
        reflectance: &'a [f32],
        hit: &SurfaceHit,
        scratch: &'a mut Vec<f32>,
    ) -> &'a [f32] {
        let Some(base) = &mat.base else {
            return reflectance;
        };
        let prim = hit.prim as usize;
        let (b1, b2) = hit.bary;
        let b0 = 1.0 - b1 - b2;
        let mut rgb = base.factor;
        let mut varies = false;
        // A texture without texture coordinates is not applied.
        if let (Some(tex), Some(uv)) = (&base.texture, self.triangle_uvs.get(prim)) {
            let texel = tex.sample(uv[0] * b0 + uv[1] * b1 + uv[2] * b2);
            rgb = [0, 1, 2].map(|c| rgb[c] * texel[c]);
            varies = true;
        }
        if let (true, Some(c)) = (base.vertex_colors, self.triangle_colors.get(prim)) {
            let vc = c[0] * b0 + c[1] * b1 + c[2] * b2;
            rgb = [rgb[0] * vc.x, rgb[1] * vc.y, rgb[2] * vc.z];
            varies = true;
        }
        if !varies {
            return reflectance;
        }
        let rgb = rgb.map(|c| c.clamp(0.0, 1.0));
        scratch.resize(self.grid.len(), 0.0);
        self.grid.upsample_reflectance_into(rgb, scratch);
        scratch
    }

    /// The emitted radiance (N bins) of `mat` at `hit`: its emission, filtered per bin by
    /// the emissive texel's spectrum (the texel's RGB upsampled like a reflectance, so a
    /// white texel leaves the emission as it is and glTF's factor × texture holds for
    /// every colour the upsampling reproduces). None when it emits nothing.
    pub fn emission_at<'a>(
        &'a self,
        mat: &'a SMaterial,
        hit: &SurfaceHit,
        scratch: &'a mut Vec<f32>,
    ) -> Option<&'a [f32]> {
        let e = mat.emission.as_deref()?;
        let (Some(tex), Some(uv)) = (
            &mat.emission_texture,
            self.triangle_uvs.get(hit.prim as usize),
        ) else {
            return Some(e);
        };
        let (b1, b2) = hit.bary;
        let texel = tex.sample(uv[0] * (1.0 - b1 - b2) + uv[1] * b1 + uv[2] * b2);
        texel_filter(&self.grid, texel, scratch);
        for (s, v) in scratch.iter_mut().zip(e) {
            *s *= v;
        }
        Some(scratch)
    }

    pub fn material(&self, hit: &SurfaceHit) -> &SMaterial {
        &self.materials[hit.material as usize]
    }
}

/// The index of a dispersive glass for light of bin `bin` at the wavelength a fraction
/// `u` ∈ [0, 1) across the bin (linear between the bin's edges: the index is smooth, a
/// Sellmeier curve bends by < 1e-5 inside a 20 nm bin). A bin stands for every wavelength
/// in it: refracting each photon (and camera path) at one drawn within its bin spreads
/// the bin over its own angular width — a continuous rainbow at any bin count — while
/// the flux stays in its bin. A path draws `u` once and keeps it through every interface.
/// Without edges (non-dispersive glass) it is the bin's index.
#[inline]
pub fn eta_in_bin(eta: &[f32], eta_edges: &[f32], bin: usize, u: f32) -> f32 {
    match (eta_edges.get(bin), eta_edges.get(bin + 1)) {
        (Some(&a), Some(&b)) => a + u * (b - a),
        _ => eta[bin.min(eta.len() - 1)],
    }
}

/// The index a path of bin `bin` meets at a glass: within the bin at the path's own
/// wavelength offset `lambda_u` (drawn at its first dispersive interface, kept after)
/// for dispersive glass, the bin's index otherwise. Shared by photons and camera paths.
#[inline]
pub fn path_eta(
    eta: &[f32],
    eta_edges: &[f32],
    dispersive: bool,
    bin: usize,
    lambda_u: &mut Option<f32>,
    rng: &mut crate::sampling::Rng,
) -> f32 {
    if dispersive {
        let u = *lambda_u.get_or_insert_with(|| rng.next_f32());
        eta_in_bin(eta, eta_edges, bin, u)
    } else {
        eta[bin]
    }
}

/// The normal-map tangent frames of `scene`'s triangles (see
/// [`SpectralScene::tangents`]); empty when no material has a normal map or no mesh has
/// texture coordinates.
fn uv_tangents(scene: &Scene, materials: &[SMaterial]) -> Vec<[Vec3; 2]> {
    if materials.iter().all(|m| m.normal_map.is_none())
        || scene.triangle_uvs.len() != scene.triangles.len()
    {
        return Vec::new();
    }
    scene
        .triangles
        .iter()
        .zip(&scene.triangle_uvs)
        .zip(&scene.triangle_material)
        .map(|((p, uv), &m)| {
            if materials[m as usize].normal_map.is_none() {
                return [Vec3::ZERO; 2];
            }
            let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
            let (d1, d2) = (uv[1] - uv[0], uv[2] - uv[0]);
            let det = d1.x * d2.y - d2.x * d1.y;
            if !(det.abs() > 1e-12) {
                return [Vec3::ZERO; 2];
            }
            let dpdu = (e1 * d2.y - e2 * d1.y) / det;
            let dpdv = (e2 * d1.x - e1 * d2.x) / det;
            if !(dpdu.is_finite() && dpdv.is_finite()) {
                return [Vec3::ZERO; 2];
            }
            [dpdu, -dpdv]
        })
        .collect()
}

/// The holes of cut-out and blended materials (glTF alphaMode MASK, BLEND), as the BVH
/// asks for them.
struct AlphaCutouts {
    /// Per scene triangle: its index in `tris`, or `u32::MAX` if it has no holes.
    slot: Vec<u32>,
    /// The holed triangles: geometry (for barycentrics), texture coordinates, mask.
    tris: Vec<(TriData, [glam::Vec2; 3], u32)>,
    /// Per material with holes: its test and the texture whose alpha it reads.
    masks: Vec<(super::AlphaMask, Option<TextureRef>)>,
}

impl AlphaCutouts {
    /// The scene's holes, with which triangles have them; None when none can have any.
    fn of(scene: &Scene, tris: &[TriData]) -> Option<(Vec<bool>, Self)> {
        let mut mask_of = vec![u32::MAX; scene.materials.len()];
        let mut masks = Vec::new();
        for (i, m) in scene.materials.iter().enumerate() {
            let Some(mask) = m.alpha_mask else { continue };
            let tex = m
                .base_color_texture
                .clone()
                .filter(|t| !t.texture.alpha.is_empty());
            // No alpha texture and a factor that covers everything: no hole anywhere.
            let covered = if mask.blend { 1.0 } else { mask.cutoff };
            if tex.is_none() && mask.factor >= covered {
                continue;
            }
            mask_of[i] = masks.len() as u32;
            masks.push((mask, tex));
        }
        if masks.is_empty() {
            return None;
        }
        let has_uvs = scene.triangle_uvs.len() == scene.triangles.len();
        let mut slot = vec![u32::MAX; tris.len()];
        let mut holed_tris = Vec::new();
        for (i, t) in tris.iter().enumerate() {
            let m = mask_of[t.material as usize];
            if m == u32::MAX {
                continue;
            }
            let uv = if has_uvs {
                scene.triangle_uvs[i]
            } else {
                [glam::Vec2::ZERO; 3]
            };
            slot[i] = holed_tris.len() as u32;
            holed_tris.push((*t, uv, m));
        }
        let holed = slot.iter().map(|&s| s != u32::MAX).collect();
        Some((
            holed,
            Self {
                slot,
                tris: holed_tris,
                masks,
            },
        ))
    }
}

impl crate::geometry::Cutouts for AlphaCutouts {
    fn passes(&self, prim: u32, p: Vec3) -> bool {
        let Some((tri, uv, m)) = self
            .slot
            .get(prim as usize)
            .and_then(|&s| self.tris.get(s as usize))
        else {
            return false;
        };
        let (mask, tex) = &self.masks[*m as usize];
        let mut alpha = mask.factor;
        if let Some(tex) = tex {
            let (b1, b2) = tri.barycentric(p);
            alpha *= tex.sample_alpha(uv[0] * (1.0 - b1 - b2) + uv[1] * b1 + uv[2] * b2);
        }
        if mask.blend {
            // Passes with probability 1 − alpha, decided by a hash of where the ray meets
            // the surface: the same for any thread count, fresh for every ray.
            return !(coverage_u(prim, p) < alpha);
        }
        // A NaN alpha (never from a checked file) is a hole, not a wall.
        !(alpha >= mask.cutoff)
    }
}

/// A number uniform in [0, 1) from a triangle and a point on it (a hash of their bits).
fn coverage_u(prim: u32, p: Vec3) -> f32 {
    let mut h = u64::from(prim) ^ 0x9e37_79b9_7f4a_7c15;
    for c in [p.x, p.y, p.z] {
        h ^= u64::from(c.to_bits());
        // splitmix64's finaliser.
        h = h.wrapping_add(0x9e37_79b9_7f4a_7c15);
        h = (h ^ (h >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        h = (h ^ (h >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        h ^= h >> 31;
    }
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// The GGX α of a glTF perceptual roughness (its square); 0 (smooth) below
/// [`crate::materials::microfacet::SMOOTH_ALPHA`].
pub fn ggx_alpha(roughness: f32) -> f32 {
    let a = roughness.clamp(0.0, 1.0).powi(2);
    if a < crate::materials::microfacet::SMOOTH_ALPHA {
        0.0
    } else {
        a
    }
}

/// Where `m`'s base colour varies over its surfaces (see [`BaseColor`]): a texture on
/// a diffuse or metal surface (whose factor is its RGB reflectance, or white beside a
/// spectral one), or vertex colours on an RGB reflectance (the loader marks only those).
fn base_color(m: &Material) -> Option<BaseColor> {
    let rgb = match &m.kind {
        MaterialKind::Diffuse { reflectance } | MaterialKind::Mirror { reflectance, .. } => {
            match reflectance {
                Spectrum::Reflectance(c) => Some(c.rgb.map(|c| c as f32)),
                _ => None,
            }
        }
        MaterialKind::Dielectric { .. } => return None,
    };
    let vertex_colors = m.vertex_colors && rgb.is_some();
    if m.base_color_texture.is_none() && !vertex_colors {
        return None;
    }
    Some(BaseColor {
        factor: rgb.unwrap_or([1.0; 3]),
        texture: m.base_color_texture.clone(),
        vertex_colors,
    })
}

/// A material's per-bin data on `grid`.
fn project_material(m: &Material, grid: &BinGrid) -> SMaterial {
    // Reflectances above 1 (Smits' basis reaches 1.0007) would add energy.
    let refl = |s| -> Vec<f32> {
        grid.project(s, Role::Reflectance)
            .into_iter()
            .map(|v| v.min(1.0))
            .collect()
    };
    let kind = match &m.kind {
        MaterialKind::Diffuse { reflectance } => SurfaceKind::Diffuse {
            reflectance: refl(reflectance),
        },
        MaterialKind::Mirror {
            reflectance,
            roughness,
        } => SurfaceKind::Mirror {
            reflectance: refl(reflectance),
            alpha: ggx_alpha(*roughness),
        },
        MaterialKind::Dielectric { ior, roughness } => {
            let eta: Vec<f32> = (0..grid.len())
                .map(|i| ior.eta(grid.ior_wavelength(i)) as f32)
                .collect();
            let dispersive = grid.transport() == Transport::Spectral
                && grid.len() > 1
                && ior.is_dispersive()
                && eta.iter().any(|&e| e != eta[0]);
            let eta_edges = if dispersive {
                (0..=grid.len())
                    .map(|i| {
                        let (lo, hi) = grid.bin_edges(i.min(grid.len() - 1));
                        ior.eta(if i < grid.len() { lo } else { hi }) as f32
                    })
                    .collect()
            } else {
                Vec::new()
            };
            SurfaceKind::Dielectric {
                eta,
                eta_edges,
                dispersive,
                alpha: ggx_alpha(*roughness),
            }
        }
    };
    SMaterial {
        name: m.name.clone(),
        kind,
        emission: m.emission.as_ref().map(|e| grid.project(e, Role::Emission)),
        base: base_color(m),
        emission_texture: m.emissive_texture.clone(),
        normal_map: m.normal_texture.clone(),
        absorption: m.volume.as_ref().map(|v| {
            grid.project(&Spectrum::reflectance(v.color), Role::Reflectance)
                .into_iter()
                .map(|c| -(c.clamp(1e-6, 1.0) as f64).ln() as f32 / v.distance as f32)
                .collect()
        }),
    }
}

/// A linear RGB texel as a per-bin filter in [0, 1] (the RGB itself on the RGB grid).
fn texel_filter(grid: &BinGrid, texel: [f32; 3], out: &mut Vec<f32>) {
    out.resize(grid.len(), 0.0);
    grid.upsample_reflectance_into(texel, out);
}

/// Texels averaged per emissive triangle (a stratified 16 × 16 pattern over it).
const EMITTER_TEXEL_SAMPLES: usize = 16;

/// What an emissive triangle emits as a light: its material's emission, filtered by the
/// emissive texture averaged over the triangle. Photons and light samples follow the
/// texture triangle by triangle; the camera sees every texel ([`SpectralScene::emission_at`]).
fn triangle_emission(
    e: &[f32],
    texture: Option<&TextureRef>,
    uv: Option<&[glam::Vec2; 3]>,
    grid: &BinGrid,
) -> Vec<f32> {
    let (Some(tex), Some(uv)) = (texture, uv) else {
        return e.to_vec();
    };
    let n = EMITTER_TEXEL_SAMPLES;
    let mut mean = vec![0.0f32; grid.len()];
    let mut filter = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let u = [(i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32];
            let (b1, b2) = crate::sampling::uniform_triangle(u);
            let at = uv[0] * (1.0 - b1 - b2) + uv[1] * b1 + uv[2] * b2;
            texel_filter(grid, tex.sample(at), &mut filter);
            spd::add_scaled(&mut mean, &filter, 1.0 / (n * n) as f32);
        }
    }
    spd::mul_assign(&mut mean, e);
    mean
}

/// The triangles with their precomputed data, an area light per emissive triangle of
/// positive area, and the total diffuse area.
fn triangles_and_area_lights(
    scene: &Scene,
    materials: &[SMaterial],
    grid: &BinGrid,
) -> (Vec<TriData>, Vec<Light>, f64) {
    let mut tris = Vec::with_capacity(scene.triangles.len());
    let mut lights = Vec::new();
    let mut diffuse_area = 0.0f64;
    for (i, (t, &m)) in scene
        .triangles
        .iter()
        .zip(&scene.triangle_material)
        .enumerate()
    {
        let (twice_area, normal) = triangle_normal(t);
        let area = 0.5 * twice_area;
        tris.push(TriData {
            v0: t[0],
            e1: t[1] - t[0],
            e2: t[2] - t[0],
            normal,
            area,
            material: m,
        });
        let mat = &materials[m as usize];
        if matches!(mat.kind, SurfaceKind::Diffuse { .. }) {
            diffuse_area += area as f64;
        }
        if let Some(e) = &mat.emission {
            let uv =
                (scene.triangle_uvs.len() == scene.triangles.len()).then(|| &scene.triangle_uvs[i]);
            let e = triangle_emission(e, mat.emission_texture.as_ref(), uv, grid);
            let y = grid.to_xyz(&e)[1];
            if area > 0.0 && y > 0.0 {
                lights.push(Light {
                    kind: LightKind::Area { tri: i as u32 },
                    spectrum: e,
                    power: (y * std::f64::consts::PI * area as f64) as f32,
                });
            }
        }
    }
    (tris, lights, diffuse_area)
}

/// Spheres around the mirror and glass triangles, at most [`MAX_TARGETS`], that together
/// hold every one: empty when there is none. They start as one group; the group whose
/// split saves the most r² is split at the widest gap between its triangles' centroids
/// along an axis, where the two spheres' r² sum to under 0.9 of its own (the r² a distant light's
/// or a far lamp's aimed photons spread over): glass objects apart from each other get a
/// sphere each, while a ball, a box or a square mirror stays one sphere (its halves'
/// spheres hold 1.25–2.5 times its r²).
fn specular_targets(scene: &Scene, materials: &[SMaterial]) -> Vec<Target> {
    let specular = |m: u32| {
        materials
            .get(m as usize)
            .is_some_and(|m| !matches!(m.kind, SurfaceKind::Diffuse { .. }))
    };
    let tris: Vec<[Vec3; 3]> = scene
        .triangles
        .iter()
        .zip(&scene.triangle_material)
        .filter(|(t, m)| specular(**m) && t.iter().all(|v| v.is_finite()))
        .map(|(t, _)| *t)
        .collect();
    if tris.is_empty() {
        return Vec::new();
    }
    let sphere = |group: &[usize]| {
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for v in group.iter().flat_map(|&i| &tris[i]) {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
        let center = 0.5 * (lo + hi);
        let radius = group
            .iter()
            .flat_map(|&i| &tris[i])
            .map(|v| v.distance(center))
            .fold(0.0f32, f32::max);
        let radius = radius * 1.001 + 1e-5 * (1.0 + center.abs().max_element());
        Target { center, radius }
    };
    let centroids: Vec<Vec3> = tris.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect();
    // A group's best split: the widest gap between neighbouring centroids along an axis
    // (among at most 4 096 of them), kept where the two spheres' r² sum to under 0.9 of
    // the group's; returns its gain in r² and the two halves.
    let best_split = |target: &Target, group: &[usize]| {
        let r2 = target.radius * target.radius;
        let mut best: Option<(f32, Vec<usize>, Vec<usize>)> = None;
        for axis in [0, 1, 2] {
            let step = group.len().div_ceil(4096).max(1);
            let mut keys: Vec<f32> = group
                .iter()
                .step_by(step)
                .map(|&i| centroids[i][axis])
                .collect();
            keys.sort_unstable_by(f32::total_cmp);
            let Some(cut) = keys
                .windows(2)
                .max_by(|a, b| (a[1] - a[0]).total_cmp(&(b[1] - b[0])))
                .filter(|w| w[1] > w[0])
                .map(|w| 0.5 * (w[0] + w[1]))
            else {
                continue;
            };
            let (below, above): (Vec<usize>, Vec<usize>) =
                group.iter().partition(|&&i| centroids[i][axis] < cut);
            if below.is_empty() || above.is_empty() {
                continue;
            }
            let cost = sphere(&below).radius.powi(2) + sphere(&above).radius.powi(2);
            if cost < 0.9 * r2 && best.as_ref().is_none_or(|b| r2 - cost > b.0) {
                best = Some((r2 - cost, below, above));
            }
        }
        best
    };
    // (sphere, triangles, best split); the split that saves the most r² goes first.
    let group_of = |group: Vec<usize>| {
        let target = sphere(&group);
        let split = best_split(&target, &group);
        (target, group, split)
    };
    let mut groups = vec![group_of((0..tris.len()).collect())];
    while groups.len() < MAX_TARGETS {
        let Some(g) = (0..groups.len())
            .filter(|&g| groups[g].2.is_some())
            .max_by(|&a, &b| {
                let gain = |g: usize| groups[g].2.as_ref().map_or(0.0, |s| s.0);
                gain(a).total_cmp(&gain(b))
            })
        else {
            break;
        };
        let Some((_, below, above)) = groups[g].2.take() else {
            break;
        };
        groups[g] = group_of(below);
        groups.push(group_of(above));
    }
    groups
        .into_iter()
        .map(|(target, _, _)| target)
        .filter(|t| t.center.is_finite() && t.radius.is_finite())
        .collect()
}

/// A sphere around the bounds, a little larger so that photons from a distant light or
/// the sky start outside every surface.
fn bounding_sphere((lo, hi): (Vec3, Vec3)) -> (Vec3, f32) {
    let center = 0.5 * (lo + hi);
    let radius = (0.5 * (hi - lo).length()).max(1e-3) * 1.01;
    (center, radius)
}

/// A point, spot or distant light on `grid`; None when it is black. A distant light's
/// photons start on a disc over the bounding sphere `(center, radius)`.
fn punctual_light(
    l: &PunctualLight,
    grid: &BinGrid,
    (center, radius): (Vec3, f32),
) -> Option<Light> {
    let spectrum = grid.project(&l.intensity, Role::Emission);
    let y = grid.to_xyz(&spectrum)[1];
    let (kind, solid_angle) = match l.kind {
        PunctualKind::Point => (
            LightKind::Point {
                position: l.position,
            },
            4.0 * std::f64::consts::PI,
        ),
        PunctualKind::Spot {
            direction,
            inner,
            outer,
        } => (
            LightKind::Spot {
                position: l.position,
                axis: direction,
                omc_outer: one_minus_cos(outer),
                omc_inner: one_minus_cos(inner.min(outer)),
            },
            2.0 * std::f64::consts::PI * one_minus_cos(outer) as f64,
        ),
        // Irradiance over the disc's area: the power that enters the bounding sphere.
        PunctualKind::Directional { direction } => (
            LightKind::Distant {
                dir: direction,
                center,
                radius,
            },
            std::f64::consts::PI * (radius as f64).powi(2),
        ),
    };
    (y > 0.0).then_some(Light {
        kind,
        spectrum,
        power: (y * solid_angle) as f32,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Purpose, Rng, uniform_sphere};

    /// The table's code is the code of the hit's own `nf`, on front and back faces, flat
    /// and smooth and normal-mapped triangles alike.
    #[test]
    fn a_hits_normal_code_is_the_code_of_its_facing_normal() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/blender");
        let scenes = [
            crate::scene::load_builtin("prism").unwrap(),
            crate::scene::load_builtin("cornell-box").unwrap(),
            crate::scene::load(&dir.join("normal-mapped.glb")).unwrap(),
            crate::scene::load(&dir.join("textured-glass.glb")).unwrap(),
        ];
        for scene in &scenes {
            let s = SpectralScene::new(scene, BinGrid::with_bins(4).unwrap());
            let (lo, hi) = s.bounds;
            let mut rng = Rng::stream(3, 0, 0, Purpose::Photon);
            let (mut front, mut back) = (0, 0);
            for _ in 0..4000 {
                let [a, b] = rng.next_2d();
                let o = lo + (hi - lo) * Vec3::new(a, b, rng.next_f32());
                let Some(hit) = s.intersect(o, uniform_sphere(rng.next_2d())) else {
                    continue;
                };
                assert_eq!(s.normal_code(&hit), NormalCode::from(hit.nf), "{}", s.name);
                if hit.front {
                    front += 1;
                } else {
                    back += 1;
                }
            }
            assert!(front > 100 && back > 20, "{}: {front} / {back}", s.name);
        }
    }
}
