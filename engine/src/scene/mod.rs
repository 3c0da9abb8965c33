//! Scene input: glTF 2.0 files → a validated, renderer-independent [`Scene`]; then
//! [`SpectralScene`] projects it onto a bin grid for one render configuration.
//!
//! Spectral inputs glTF cannot express go in `extras.prismap` (see `scenes/README.md`):
//! a named Sellmeier glass on a material, and an emission spectrum shape (blackbody
//! temperature, built-in illuminant, or measured SPD file) on a material or a light,
//! scaled to the luminance of the glTF emissive colour or light colour × intensity.

mod coverage;
mod gltf_load;
mod spectral;
pub mod texture;

pub use crate::geometry::{SurfaceHit, TriData};
pub use crate::lights::{Light, LightKind, LightSet};
pub use gltf_load::{load, load_from_slice, parse_spd_csv};
pub use spectral::{SMaterial, SpectralScene, SurfaceKind, eta_in_bin, path_eta};

use crate::spectral::{IorModel, Spectrum};
use glam::Vec3;

/// An error in a scene file; the message names the file, the element and the value.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{file}: cannot read the file: {reason}")]
    Io {
        file: String,
        /// The OS error, kept out of the error chain so it is printed once.
        reason: std::io::Error,
    },
    #[error("{file}: {element}: {message}")]
    Invalid {
        file: String,
        element: String,
        message: String,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub enum MaterialKind {
    /// Lambertian reflection.
    Diffuse { reflectance: Spectrum },
    /// A metal: a perfect mirror of reflectance `reflectance` when `roughness` is 0, else
    /// a GGX microfacet metal with Schlick's Fresnel from that reflectance (glTF's metal).
    /// `roughness` is glTF's perceptual roughness: the GGX α is its square.
    Mirror {
        reflectance: Spectrum,
        roughness: f32,
    },
    /// A dielectric (glass): Fresnel reflection and refraction, dispersive when its index
    /// depends on wavelength; smooth when `roughness` is 0, else a GGX rough dielectric
    /// (Walter et al. 2007).
    Dielectric { ior: IorModel, roughness: f32 },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    pub kind: MaterialKind,
    /// Emitted radiance of the front face (glTF: counter-clockwise winding).
    pub emission: Option<Spectrum>,
    /// Absorption inside a glass (glTF `KHR_materials_volume`), if any.
    pub volume: Option<Volume>,
    /// glTF `baseColorTexture`: the reflectance is the factor's colour times the texel's.
    pub base_color_texture: Option<texture::TextureRef>,
    /// glTF `emissiveTexture`: the emission is the factor's spectrum filtered by the
    /// texel's (see [`crate::scene::SpectralScene::emission_at`]).
    pub emissive_texture: Option<texture::TextureRef>,
    /// Some primitive of this material has vertex colours (glTF `COLOR_0`): its base
    /// colour is multiplied per hit by the colour interpolated between the triangle's
    /// corners (glTF: factor × texture × `COLOR_0`; see [`Scene::triangle_colors`]).
    pub vertex_colors: bool,
    /// glTF alphaMode MASK or BLEND: holes where factor × the base-colour texture's alpha
    /// is below the cutoff, or partial cover by that alpha (see [`AlphaMask`]).
    pub alpha_mask: Option<AlphaMask>,
    /// glTF `normalTexture` (a tangent-space normal map, stored linear) and its scale:
    /// it tilts the shading normal per hit (see [`crate::scene::SpectralScene::intersect`]).
    pub normal_texture: Option<(texture::TextureRef, f32)>,
}

/// A material's coverage by alpha = factor × the base-colour texture's alpha: a cut-out
/// (glTF alphaMode MASK) or see-through blending (BLEND).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlphaMask {
    /// glTF alphaCutoff (default 0.5): alpha below it is a hole (MASK only).
    pub cutoff: f32,
    /// The base colour factor's alpha.
    pub factor: f32,
    /// BLEND: the surface covers a fraction alpha of each point, so a ray passes it with
    /// probability 1 − alpha (stochastic transparency: light through it is scaled by
    /// 1 − alpha on average, unbent and uncoloured, as glTF's blending means).
    pub blend: bool,
}

/// Beer–Lambert absorption inside a closed glass: after `distance` scene units inside,
/// the light that is left has the colour `color` (glTF's attenuationColor and
/// attenuationDistance), so σ(λ) = −ln c(λ) / distance per wavelength.
#[derive(Clone, Debug, PartialEq)]
pub struct Volume {
    /// Linear-sRGB transmittance colour after `distance`, upsampled like a reflectance.
    pub color: [f64; 3],
    pub distance: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub enum PunctualKind {
    Point,
    /// A distant light (glTF "directional", Blender's Sun): parallel light travelling
    /// along `direction`.
    Directional {
        direction: Vec3,
    },
    /// Cone about `direction`, angles in radians (glTF's smooth falloff between them).
    Spot {
        direction: Vec3,
        inner: f32,
        outer: f32,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct PunctualLight {
    pub name: String,
    pub position: Vec3,
    pub kind: PunctualKind,
    /// Point and spot: intensity (luminance Y in candela, lm/sr); directional: irradiance
    /// on a surface facing the light (Y in lux, lm/m²). Emissive radiance is in nits
    /// (cd/m²): glTF's photometric units, one consistent scale.
    pub intensity: Spectrum,
}

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub position: Vec3,
    /// Unit vectors: viewing direction, image up, image right.
    pub forward: Vec3,
    pub up: Vec3,
    pub right: Vec3,
    /// Full vertical field of view in radians.
    pub yfov: f32,
    /// Width / height the camera was made for (glTF `aspectRatio`), if it says.
    pub aspect: Option<f32>,
}

impl Camera {
    /// A camera at `position` looking at `target`.
    pub fn look_at(position: Vec3, target: Vec3, up: Vec3, yfov: f32) -> Self {
        let forward = (target - position).normalize();
        let right = forward.cross(up).normalize();
        let up = right.cross(forward);
        Self {
            position,
            forward,
            up,
            right,
            yfov,
            aspect: None,
        }
    }
}

/// A loaded scene, before projection onto bins.
#[derive(Clone, Debug)]
pub struct Scene {
    /// File stem ("cornell-box").
    pub name: String,
    pub triangles: Vec<[Vec3; 3]>,
    /// Material index of each triangle.
    pub triangle_material: Vec<u32>,
    /// Per-vertex shading normals of each triangle (glTF `NORMAL`, unit, world space), in
    /// triangle order; empty when no mesh has any (then geometric normals shade). A
    /// triangle without them repeats its geometric normal.
    pub shading_normals: Vec<[Vec3; 3]>,
    /// Per-vertex texture coordinates (glTF `TEXCOORD_0`) of each triangle, in triangle
    /// order; empty when no mesh has any.
    pub triangle_uvs: Vec<[glam::Vec2; 3]>,
    /// Per-vertex linear RGB colours (glTF `COLOR_0`, alpha dropped, clamped to [0, 1])
    /// of each triangle, in triangle order; empty when no mesh has any. A triangle
    /// without them is white.
    pub triangle_colors: Vec<[Vec3; 3]>,
    /// Per-vertex tangents (glTF `TANGENT`: world-space xyz, handedness ±1 in w) of each
    /// triangle, in triangle order; empty when no mesh has any. Zero where a triangle has
    /// none (its normal map's frame then comes from its texture coordinates).
    pub triangle_tangents: Vec<[glam::Vec4; 3]>,
    pub materials: Vec<Material>,
    pub lights: Vec<PunctualLight>,
    /// Radiance of a uniform sky around the scene (seen where rays escape), if any: what a
    /// file with no light at all is lit by.
    pub environment: Option<Spectrum>,
    pub camera: Camera,
    /// Things that were approximated or skipped, for the user to see.
    pub warnings: Vec<String>,
}

impl Scene {
    /// The bin count this scene needs, and why (the viewer's "auto" and `render`'s default):
    /// 100 with dispersive glass (single-wavelength photons: fine bins make a smooth
    /// rainbow, and compact storage keeps them lossless at any N), 20 with a spectral
    /// light and no dispersion (enough to resolve its shape), else 8 (RGB inputs only:
    /// spectral and RGB agree at any N).
    pub fn auto_bins(&self) -> (usize, String) {
        let dispersive = self.materials.iter().any(
            |m| matches!(&m.kind, MaterialKind::Dielectric { ior, .. } if ior.is_dispersive()),
        );
        let spectral_light = self
            .materials
            .iter()
            .filter_map(|m| m.emission.as_ref())
            .chain(self.lights.iter().map(|l| &l.intensity))
            .any(|s| !matches!(s, Spectrum::Illuminant(_)));
        if dispersive {
            (100, "100 bins: dispersive glass splits light into single wavelengths; fine bins give a smooth rainbow, and compact storage keeps those photons lossless at any N".to_string())
        } else if spectral_light {
            (20, "20 bins: a spectral light (blackbody or measured) without dispersion; 20 bins resolve its shape".to_string())
        } else {
            (8, "8 bins: only RGB inputs and no dispersion, so spectral and RGB agree at any N (the paper's Cornell box); 8 bins suffice".to_string())
        }
    }

    /// An image size for this scene's camera: `height` rows and the camera's aspect ratio
    /// (square when the camera does not say).
    pub fn image_size(&self, height: u32) -> (u32, u32) {
        let aspect = self.camera.aspect.unwrap_or(1.0);
        let width = (height as f32 * aspect).round().clamp(1.0, 16_384.0) as u32;
        (width, height)
    }

    /// Axis-aligned bounds of the geometry.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for t in &self.triangles {
            for v in t {
                lo = lo.min(*v);
                hi = hi.max(*v);
            }
        }
        (lo, hi)
    }
}

/// Scenes compiled into the binary, so the program runs from any directory.
pub const BUILTIN: &[(&str, &[u8])] = &[
    ("prism", include_bytes!("../../../scenes/prism.gltf")),
    (
        "cornell-box",
        include_bytes!("../../../scenes/cornell-box.gltf"),
    ),
    (
        "cornell-blackbody",
        include_bytes!("../../../scenes/cornell-blackbody.gltf"),
    ),
    (
        "cornell-f11",
        include_bytes!("../../../scenes/cornell-f11.gltf"),
    ),
];

/// The scene the viewer and `prismap render` open when none is given.
pub const DEFAULT_SCENE: &str = "prism";

/// The bytes of a built-in scene, if `name` is one.
pub fn builtin(name: &str) -> Option<&'static [u8]> {
    BUILTIN.iter().find(|(n, _)| *n == name).map(|(_, b)| *b)
}

/// Loads a built-in scene by name ("prism", "cornell-box", "cornell-blackbody", "cornell-f11").
pub fn load_builtin(name: &str) -> Result<Scene, SceneError> {
    let (stem, bytes) =
        BUILTIN
            .iter()
            .find(|(n, _)| *n == name)
            .ok_or_else(|| SceneError::Invalid {
                file: format!("builtin:{name}"),
                element: "name".to_string(),
                message: format!(
                    "no built-in scene '{name}' (built in: {})",
                    BUILTIN
                        .iter()
                        .map(|(n, _)| *n)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })?;
    let mut scene = load_from_slice(bytes, &format!("builtin:{stem}"), None)?;
    scene.name = stem.to_string();
    Ok(scene)
}

/// Loads a scene file, or a built-in scene when `spec` names one and no such file exists.
/// A name that is neither gets the closest built-in names suggested.
pub fn load_any(spec: &str) -> Result<Scene, SceneError> {
    let path = std::path::Path::new(spec);
    if !path.exists() {
        if builtin(spec).is_some() {
            return load_builtin(spec);
        }
        let names: Vec<&str> = BUILTIN.iter().map(|(n, _)| *n).collect();
        let close: Vec<&str> = names
            .iter()
            .copied()
            .filter(|n| n.contains(spec) || spec.contains(n) || edit_distance(n, spec) <= 3)
            .collect();
        let hint = if close.is_empty() {
            String::new()
        } else {
            format!("did you mean '{}'? ", close.join("' or '"))
        };
        return Err(SceneError::Invalid {
            file: spec.to_string(),
            element: "file".to_string(),
            message: format!(
                "no such file, and no built-in scene of that name ({hint}built in: {}; a scene file is .gltf or .glb)",
                names.join(", ")
            ),
        });
    }
    load(path)
}

/// Levenshtein distance, for "did you mean".
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != *cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}
