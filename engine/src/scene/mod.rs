//! Scene input: glTF 2.0 files → a validated, renderer-independent [`Scene`]; then
//! [`SpectralScene`] projects it onto a bin grid for one render configuration.
//!
//! Spectral inputs glTF cannot express go in `extras.prismap` (see `scenes/README.md`):
//! a named Sellmeier glass on a material, and an emission spectrum shape (blackbody
//! temperature, built-in illuminant, or measured SPD file) on a material or a light,
//! scaled to the luminance of the glTF emissive colour or light colour × intensity.

mod gltf_load;
mod spectral;

pub use crate::geometry::{SurfaceHit, TriData};
pub use crate::lights::{Light, LightKind, LightSet};
pub use gltf_load::{load, load_from_slice, parse_spd_csv};
pub use spectral::{SMaterial, SpectralScene, SurfaceKind};

use crate::spectral::{IorModel, Spectrum};
use glam::Vec3;

/// An error in a scene file; the message names the file, the element and the value.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{file}: cannot read the file: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
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
    /// A perfect mirror.
    Mirror { reflectance: Spectrum },
    /// A smooth dielectric (glass): Fresnel reflection and refraction, dispersive when
    /// its index depends on wavelength.
    Dielectric { ior: IorModel },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    pub kind: MaterialKind,
    /// Emitted radiance of the front face (glTF: counter-clockwise winding).
    pub emission: Option<Spectrum>,
}

#[derive(Clone, Debug, PartialEq)]
pub enum PunctualKind {
    Point,
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
    /// Radiant intensity per steradian, in the same units as emissive radiance.
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
    pub materials: Vec<Material>,
    pub lights: Vec<PunctualLight>,
    pub camera: Camera,
    /// Things that were approximated or skipped, for the user to see.
    pub warnings: Vec<String>,
}

impl Scene {
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
];

/// The scene the viewer and `prismap render` open when none is given.
pub const DEFAULT_SCENE: &str = "prism";

/// The bytes of a built-in scene, if `name` is one.
pub fn builtin(name: &str) -> Option<&'static [u8]> {
    BUILTIN.iter().find(|(n, _)| *n == name).map(|(_, b)| *b)
}

/// Loads a built-in scene by name ("prism", "cornell-box", "cornell-blackbody").
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
pub fn load_any(spec: &str) -> Result<Scene, SceneError> {
    let path = std::path::Path::new(spec);
    if !path.exists() && BUILTIN.iter().any(|(n, _)| *n == spec) {
        return load_builtin(spec);
    }
    load(path)
}
