//! glTF 2.0 → [`Scene`]. Never panics on user input: every failure is a [`SceneError`]
//! naming the file, the element and the value; `catch_unwind` around the `gltf` crate is
//! the backstop for its known panics on malformed data.

use std::path::{Component, Path};
use std::sync::Arc;

use glam::{Mat4, Vec3};
use serde::Deserialize;

use super::{Camera, Material, MaterialKind, PunctualKind, PunctualLight, Scene, SceneError};
use crate::geometry::triangle_normal;
use crate::spectral::tables::{PiecewiseLinear, fl11, parse_numeric_csv};
use crate::spectral::{IorModel, Spectrum};

/// Extensions this loader understands (anything else in `extensionsRequired` is refused).
const SUPPORTED_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_ior",
    "KHR_materials_transmission",
    "KHR_materials_volume",
    "KHR_materials_dispersion",
    "KHR_texture_transform",
];

/// What a material extension that prismap does not read (listed in `extensionsUsed`,
/// not required) would have added: the look the render goes without.
const IGNORED_MATERIAL_EXTENSIONS: &[(&str, &str)] = &[
    (
        "KHR_materials_specular",
        "the specular strength and tint (dielectric F0 from the IOR is used)",
    ),
    ("KHR_materials_clearcoat", "the clear lacquer layer"),
    ("KHR_materials_sheen", "the cloth sheen"),
    ("KHR_materials_iridescence", "the thin-film iridescence"),
    ("KHR_materials_anisotropy", "the anisotropic highlights"),
    (
        "KHR_materials_unlit",
        "unlit shading (the surfaces are lit)",
    ),
    (
        "KHR_materials_diffuse_transmission",
        "light through thin diffuse surfaces (leaves, paper)",
    ),
    (
        "KHR_materials_variants",
        "material variants (the default materials are used)",
    ),
    (
        "KHR_materials_pbrSpecularGlossiness",
        "the specular-glossiness material (its base is not read)",
    ),
];

/// One warning per extension the file uses but prismap does not read (and does not
/// need: an unsupported required one is an error, see [`check_required_names`]).
fn ignored_extensions(doc: &gltf::Document) -> Vec<String> {
    let required: Vec<&str> = doc.extensions_required().collect();
    doc.extensions_used()
        .filter(|e| !SUPPORTED_EXTENSIONS.contains(e) && !required.contains(e))
        .map(|e| {
            match IGNORED_MATERIAL_EXTENSIONS
                .iter()
                .find(|(name, _)| *name == e)
            {
                Some((_, what)) => {
                    format!("extensionsUsed: '{e}' is not read: rendered without {what}")
                }
                None => format!("extensionsUsed: '{e}' is not read and is ignored"),
            }
        })
        .collect()
}

/// Deepest node hierarchy accepted (deeper is almost surely a cycle).
const MAX_NODE_DEPTH: usize = 64;

/// The part of `extras` this program reads: `{"prismap": {...}}`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct PrismapExtras {
    /// A named Sellmeier glass (see `assets/data/glass_sellmeier.csv`).
    glass: Option<String>,
    emission: Option<EmissionExtras>,
}

/// The spectral shape of an emitter; its luminance comes from the glTF colour.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct EmissionExtras {
    blackbody_k: Option<f64>,
    /// A built-in illuminant: "D65", "E" or "FL11".
    illuminant: Option<String>,
    /// A CSV file (wavelength_nm,value), relative to the glTF file.
    spd_csv: Option<String>,
}

struct Ctx<'a> {
    file: &'a str,
    base: Option<&'a Path>,
}

impl Ctx<'_> {
    fn err(&self, element: impl Into<String>, message: impl Into<String>) -> SceneError {
        SceneError::Invalid {
            file: self.file.to_string(),
            element: element.into(),
            message: message.into(),
        }
    }
}

/// Loads a `.gltf` or `.glb` file.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|reason| SceneError::Io {
        file: file.clone(),
        reason,
    })?;
    let name = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".to_string());
    let mut scene = load_from_slice(&bytes, &file, path.parent())?;
    scene.name = name;
    Ok(scene)
}

/// Loads glTF from memory; `base` resolves external buffers and SPD files (None: only
/// embedded data is allowed).
pub fn load_from_slice(bytes: &[u8], file: &str, base: Option<&Path>) -> Result<Scene, SceneError> {
    let ctx = Ctx { file, base };
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| load_inner(bytes, &ctx))) {
        Ok(result) => result,
        Err(_) => Err(ctx.err("document", "malformed glTF (the glTF reader failed on it)")),
    }
}

fn load_inner(bytes: &[u8], ctx: &Ctx) -> Result<Scene, SceneError> {
    // The gltf crate refuses unknown required extensions as "invalid": say which and why first.
    check_required_names(&peek_required_extensions(bytes), ctx)?;
    let gltf = parse_document(bytes, ctx)?;
    let doc = &gltf.document;
    check_extensions(doc, ctx)?;
    check_buffers(doc, ctx)?;
    let buffers = gltf::import_buffers(doc, ctx.base, gltf.blob.clone())
        .map_err(|e| ctx.err("buffers", e.to_string()))?;
    let root = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| ctx.err("scenes", "the file has no scene"))?;
    let mut walk = Walk {
        ctx,
        doc,
        buffers: &buffers,
        material_map: vec![None; doc.materials().len() + 1],
        camera: None,
        degenerate: 0,
        out: Scene {
            name: "scene".to_string(),
            triangles: Vec::new(),
            triangle_material: Vec::new(),
            shading_normals: Vec::new(),
            triangle_uvs: Vec::new(),
            triangle_colors: Vec::new(),
            triangle_tangents: Vec::new(),
            materials: Vec::new(),
            lights: Vec::new(),
            environment: None,
            camera: Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, 0.8),
            warnings: ignored_extensions(doc),
        },
    };
    walk.nodes(root)?;
    walk.finish()
}

/// The document, or an error that says what the file is when it is not glTF.
fn parse_document(bytes: &[u8], ctx: &Ctx) -> Result<gltf::Gltf, SceneError> {
    if bytes.is_empty() {
        return Err(ctx.err("document", "the file is empty"));
    }
    gltf::Gltf::from_slice(bytes).map_err(|e| {
        let head = String::from_utf8_lossy(&bytes[..bytes.len().min(512)]);
        let first = head.trim_start();
        let looks_obj = ctx.file.to_ascii_lowercase().ends_with(".obj")
            || first.lines().take(20).any(|l| {
                let l = l.trim_start();
                l.starts_with("v ") || l.starts_with("vn ") || l.starts_with("mtllib ")
            });
        let message = if looks_obj {
            "this is a Wavefront OBJ file, not glTF: export glTF 2.0 (.gltf or .glb) instead, e.g. in Blender with File → Export → glTF 2.0".to_string()
        } else if !(first.starts_with('{') || bytes.starts_with(b"glTF")) {
            format!("not a glTF 2.0 file (neither JSON nor GLB): {e}")
        } else {
            e.to_string()
        };
        ctx.err("document", message)
    })
}

/// Extensions that compress or re-encode data this loader cannot read: valid glTF, but
/// unsupported, and a re-export without them works.
const UNSUPPORTED_ENCODINGS: &[(&str, &str)] = &[
    (
        "KHR_draco_mesh_compression",
        "Draco mesh compression (Blender: uncheck Compression when exporting)",
    ),
    (
        "EXT_meshopt_compression",
        "meshoptimizer compression (re-export without it, e.g. gltfpack without -c)",
    ),
    (
        "KHR_mesh_quantization",
        "quantized vertex attributes (re-export with float positions)",
    ),
    ("KHR_texture_basisu", "Basis Universal textures"),
    ("EXT_texture_webp", "WebP textures"),
];

/// `extensionsRequired` read straight from the JSON (of a .gltf, or of a .glb's first
/// chunk), before the gltf crate's validation.
fn peek_required_extensions(bytes: &[u8]) -> Vec<String> {
    let json = if bytes.starts_with(b"glTF") && bytes.len() >= 20 {
        let len = u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]) as usize;
        &bytes[20..(20usize.saturating_add(len)).min(bytes.len())]
    } else {
        bytes
    };
    serde_json::from_slice::<serde_json::Value>(json)
        .ok()
        .and_then(|v| {
            v.get("extensionsRequired")?.as_array().map(|a| {
                a.iter()
                    .filter_map(|e| e.as_str().map(str::to_string))
                    .collect()
            })
        })
        .unwrap_or_default()
}

fn check_extensions(doc: &gltf::Document, ctx: &Ctx) -> Result<(), SceneError> {
    let names: Vec<String> = doc.extensions_required().map(str::to_string).collect();
    check_required_names(&names, ctx)
}

fn check_required_names(names: &[String], ctx: &Ctx) -> Result<(), SceneError> {
    for ext in names.iter().map(String::as_str) {
        if let Some((_, what)) = UNSUPPORTED_ENCODINGS.iter().find(|(e, _)| *e == ext) {
            return Err(ctx.err(
                "extensionsRequired",
                format!("the file is valid glTF, but it requires '{ext}': {what}, which prismap cannot read yet"),
            ));
        }
        if !SUPPORTED_EXTENSIONS.contains(&ext) {
            return Err(ctx.err(
                "extensionsRequired",
                format!(
                    "unsupported required extension '{ext}' (prismap reads {})",
                    SUPPORTED_EXTENSIONS.join(", ")
                ),
            ));
        }
    }
    Ok(())
}

/// External buffers: relative paths inside the scene's folder, and present.
fn check_buffers(doc: &gltf::Document, ctx: &Ctx) -> Result<(), SceneError> {
    for buffer in doc.buffers() {
        let gltf::buffer::Source::Uri(uri) = buffer.source() else {
            continue;
        };
        let element = format!("buffers[{}]", buffer.index());
        check_relative_uri(uri, ctx, &element)?;
        if uri.starts_with("data:") {
            continue;
        }
        let Some(base) = ctx.base else {
            return Err(ctx.err(
                element,
                format!("external buffer '{uri}' but no folder to read it from"),
            ));
        };
        let decoded = percent_decode(uri);
        let path = base.join(&decoded);
        if !path.is_file() {
            return Err(ctx.err(
                element,
                format!(
                    "the external buffer '{uri}' is missing (looked for {}): keep the .bin file beside the .gltf, or export a single .glb",
                    path.display()
                ),
            ));
        }
    }
    Ok(())
}

/// A per-vertex attribute's values at triangle `tri`'s three corners, if it has one.
fn corners<T: Copy>(attr: &Option<Vec<T>>, tri: &[u32]) -> Option<[T; 3]> {
    attr.as_ref().map(|a| [0, 1, 2].map(|k| a[tri[k] as usize]))
}

/// Appends a triangle's attribute to a per-triangle list that exists only once some
/// triangle has the attribute: earlier triangles are filled with `default` then.
fn push_per_triangle<T: Copy>(
    list: &mut Vec<T>,
    triangles_before: usize,
    value: Option<T>,
    default: T,
) {
    match value {
        Some(v) => {
            list.resize(triangles_before, default);
            list.push(v);
        }
        None if !list.is_empty() => list.push(default),
        None => {}
    }
}

/// Where a material reads a texture: a colour texture's `Info`, or a normal texture
/// (which has no `KHR_texture_transform` accessor in the gltf crate, and holds data, not
/// sRGB colour).
enum TexSource<'a> {
    Colour(gltf::texture::Info<'a>),
    Normal(gltf::material::NormalTexture<'a>),
}

/// A texture from a glTF texture reference: decoded (PNG or JPEG, at most
/// `MAX_TEXTURE_SIDE` a side), colour sRGB-decoded to linear (normal maps kept as
/// stored), with its sampler and transform.
fn read_texture(
    source: TexSource,
    field: &str,
    buffers: &[gltf::buffer::Data],
    ctx: &Ctx,
    element: &str,
    warnings: &mut Vec<String>,
    keep_alpha: bool,
) -> Result<super::texture::TextureRef, SceneError> {
    use super::texture::{MAX_TEXTURE_SIDE, Texture, TextureRef, Wrap, uv_transform};
    let (tex, tex_coord, texture_transform, srgb) = match &source {
        TexSource::Colour(info) => (
            info.texture(),
            info.tex_coord(),
            info.texture_transform(),
            true,
        ),
        TexSource::Normal(n) => (n.texture(), n.tex_coord(), None, false),
    };
    // The gltf crate reads KHR_texture_transform only on colour textures: a normal
    // texture's is read from its JSON.
    let normal_transform = match &source {
        TexSource::Normal(n) => n.extension_value("KHR_texture_transform").map(|v| {
            let pair = |key: &str, default: [f32; 2]| -> [f32; 2] {
                v.get(key)
                    .and_then(|a| a.as_array())
                    .filter(|a| a.len() == 2)
                    .and_then(|a| Some([a[0].as_f64()? as f32, a[1].as_f64()? as f32]))
                    .unwrap_or(default)
            };
            let rotation = v.get("rotation").and_then(|r| r.as_f64()).unwrap_or(0.0) as f32;
            (pair("offset", [0.0; 2]), rotation, pair("scale", [1.0; 2]))
        }),
        TexSource::Colour(_) => None,
    };
    let el = format!("{element}.{field} (textures[{}])", tex.index());
    let bytes: Vec<u8> = match tex.source().source() {
        gltf::image::Source::View { view, .. } => {
            let data = buffers
                .get(view.buffer().index())
                .ok_or_else(|| ctx.err(&el, "image buffer missing"))?;
            let end = view.offset().checked_add(view.length());
            match end {
                Some(end) if end <= data.0.len() => data.0[view.offset()..end].to_vec(),
                _ => return Err(ctx.err(&el, "image buffer view out of range")),
            }
        }
        gltf::image::Source::Uri { uri, .. } => {
            if let Some(rest) = uri.strip_prefix("data:") {
                let b64 = rest.split_once(',').map(|(_, d)| d).unwrap_or_default();
                use base64::Engine as _;
                base64::engine::general_purpose::STANDARD
                    .decode(b64)
                    .map_err(|e| ctx.err(&el, format!("image data URI: {e}")))?
            } else {
                check_relative_uri(uri, ctx, &el)?;
                let base = ctx
                    .base
                    .ok_or_else(|| ctx.err(&el, "external image but no folder to read it from"))?;
                let path = base.join(percent_decode(uri));
                std::fs::read(&path)
                    .map_err(|e| ctx.err(&el, format!("image '{}': {e}", path.display())))?
            }
        }
    };
    let mut reader = image::ImageReader::new(std::io::Cursor::new(&bytes))
        .with_guessed_format()
        .map_err(|e| ctx.err(&el, e.to_string()))?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_TEXTURE_SIDE);
    limits.max_image_height = Some(MAX_TEXTURE_SIDE);
    reader.limits(limits);
    let decoded = reader.decode().map_err(|e| {
        ctx.err(
            &el,
            format!("cannot decode the image (PNG and JPEG are read): {e}"),
        )
    })?;
    // Alpha is linear in glTF (only the colour is sRGB-encoded).
    let alpha = if keep_alpha && decoded.color().has_alpha() {
        decoded
            .to_rgba8()
            .pixels()
            .map(|p| p.0[3] as f32 / 255.0)
            .collect()
    } else {
        Vec::new()
    };
    let img = decoded.to_rgb8();
    let decode = |v: u8| {
        if srgb {
            crate::spectral::color::srgb_decode(v as f32 / 255.0)
        } else {
            v as f32 / 255.0
        }
    };
    let texels = img.pixels().map(|p| p.0.map(decode)).collect();
    let sampler = tex.sampler();
    let wrap = |w: gltf::texture::WrappingMode| match w {
        gltf::texture::WrappingMode::ClampToEdge => Wrap::Clamp,
        gltf::texture::WrappingMode::MirroredRepeat => Wrap::Mirror,
        gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
    };
    let linear = !matches!(
        sampler.mag_filter(),
        Some(gltf::texture::MagFilter::Nearest)
    );
    let transform = match texture_transform {
        Some(t) => {
            if t.tex_coord().is_some_and(|c| c != 0) {
                warnings.push(format!(
                    "{el}: KHR_texture_transform texCoord ignored (TEXCOORD_0 used)"
                ));
            }
            uv_transform(t.offset(), t.rotation(), t.scale())
        }
        None => match normal_transform {
            Some((offset, rotation, scale)) => uv_transform(offset, rotation, scale),
            None => glam::Mat3::IDENTITY,
        },
    };
    if tex_coord != 0 {
        warnings.push(format!(
            "{el}: texCoord {tex_coord} ignored (TEXCOORD_0 used)"
        ));
    }
    Ok(TextureRef {
        texture: std::sync::Arc::new(Texture {
            width: img.width(),
            height: img.height(),
            texels,
            alpha,
            wrap: (wrap(sampler.wrap_s()), wrap(sampler.wrap_t())),
            linear,
        }),
        transform,
    })
}

/// `%20` and friends in a URI, as the gltf crate decodes them (bytes, so any UTF-8 is
/// safe; a malformed escape is kept as written).
fn percent_decode(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let hex = |b: u8| (b as char).to_digit(16).map(|d| d as u8);
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let escaped = (bytes[i] == b'%' && i + 2 < bytes.len())
            .then(|| Some(hex(bytes[i + 1])? * 16 + hex(bytes[i + 2])?))
            .flatten();
        match escaped {
            Some(v) => {
                out.push(v);
                i += 3;
            }
            None => {
                out.push(bytes[i]);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The node walk: meshes, lights and the first camera, in document order.
struct Walk<'a> {
    ctx: &'a Ctx<'a>,
    doc: &'a gltf::Document,
    buffers: &'a [gltf::buffer::Data],
    /// glTF material index → ours; the default material goes last.
    material_map: Vec<Option<u32>>,
    camera: Option<Camera>,
    degenerate: usize,
    out: Scene,
}

impl Walk<'_> {
    fn nodes(&mut self, root: gltf::Scene) -> Result<(), SceneError> {
        // Depth-first in document order (children pushed in reverse so they pop in order).
        let mut stack: Vec<(gltf::Node, Mat4, usize)> =
            root.nodes().map(|n| (n, Mat4::IDENTITY, 0)).collect();
        stack.reverse();
        while let Some((node, parent, depth)) = stack.pop() {
            let element = format!("nodes[{}]", node.index());
            if depth > MAX_NODE_DEPTH {
                return Err(self
                    .ctx
                    .err(element, "node hierarchy deeper than 64 (a cycle?)"));
            }
            let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
            if !world.is_finite() {
                return Err(self.ctx.err(element, "transform is not finite"));
            }
            if let Some(mesh) = node.mesh() {
                for prim in mesh.primitives() {
                    self.primitive(&mesh, &prim, &world)?;
                }
            }
            if let Some(light) = node.light() {
                let l = read_light(&light, &world, self.ctx, &mut self.out.warnings)?;
                self.out.lights.push(l);
            }
            if let (Some(cam), None) = (node.camera(), &self.camera) {
                self.camera = Some(read_camera(&cam, &world, self.ctx, &mut self.out.warnings)?);
            }
            let children: Vec<_> = node.children().collect();
            for child in children.into_iter().rev() {
                stack.push((child, world, depth + 1));
            }
        }
        Ok(())
    }

    fn material_index(&mut self, m: &gltf::Material) -> Result<u32, SceneError> {
        let slot = m.index().unwrap_or(self.doc.materials().len());
        if let Some(i) = self.material_map[slot] {
            return Ok(i);
        }
        let material = read_material(m, self.buffers, self.ctx, &mut self.out.warnings)?;
        self.out.materials.push(material);
        let i = (self.out.materials.len() - 1) as u32;
        self.material_map[slot] = Some(i);
        Ok(i)
    }

    /// A primitive's `COLOR_0` (linear RGB per vertex, alpha dropped) checked, or None
    /// when it has none (or not one per vertex). A non-finite colour is an error naming the
    /// vertex; colours outside [0, 1] are clamped, with a warning. Marks the material as
    /// vertex-coloured, and warns where its kind cannot use them.
    fn vertex_colors(
        &mut self,
        colors: Option<Vec<Vec3>>,
        pel: &str,
        vertices: usize,
        mat_index: u32,
    ) -> Result<Option<Vec<Vec3>>, SceneError> {
        let Some(mut colors) = colors else {
            return Ok(None);
        };
        if colors.len() != vertices {
            self.out.warnings.push(format!(
                "{pel}: COLOR_0 has {} colours for {vertices} vertices: ignored",
                colors.len()
            ));
            return Ok(None);
        }
        if let Some((i, c)) = colors.iter().enumerate().find(|(_, c)| !c.is_finite()) {
            return Err(self.ctx.err(
                format!("{pel}.COLOR_0[{i}]"),
                format!("value {c} is not finite"),
            ));
        }
        let outside = colors
            .iter()
            .filter(|c| c.min_element() < 0.0 || c.max_element() > 1.0)
            .count();
        if outside > 0 {
            self.out.warnings.push(format!(
                "{pel}: {outside} COLOR_0 colours outside [0, 1] clamped (glTF vertex colours are linear multipliers of the base colour)"
            ));
            for c in &mut colors {
                *c = c.clamp(Vec3::ZERO, Vec3::ONE);
            }
        }
        let material = &mut self.out.materials[mat_index as usize];
        let uses = match &material.kind {
            MaterialKind::Diffuse { reflectance } | MaterialKind::Mirror { reflectance, .. } => {
                matches!(reflectance, Spectrum::Reflectance(_))
            }
            MaterialKind::Dielectric { .. } => false,
        };
        if !uses {
            let what = if matches!(material.kind, MaterialKind::Dielectric { .. }) {
                "a glass"
            } else {
                "a spectral reflectance (from the extras)"
            };
            let warning = format!(
                "{pel}: COLOR_0 ignored: material \"{}\" is {what}, which vertex colours do not tint",
                material.name
            );
            if !self.out.warnings.contains(&warning) {
                self.out.warnings.push(warning);
            }
            return Ok(None);
        }
        material.vertex_colors = true;
        Ok(Some(colors))
    }

    fn primitive(
        &mut self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        world: &Mat4,
    ) -> Result<(), SceneError> {
        let ctx = self.ctx;
        let pel = format!("meshes[{}].primitives[{}]", mesh.index(), prim.index());
        if prim.mode() != gltf::mesh::Mode::Triangles {
            self.out.warnings.push(format!(
                "{pel}: mode {:?} skipped (only triangles are rendered)",
                prim.mode()
            ));
            return Ok(());
        }
        let mat_index = self.material_index(&prim.material())?;
        let buffers = self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let positions: Vec<Vec3> = reader
            .read_positions()
            .ok_or_else(|| ctx.err(&pel, "no POSITION attribute"))?
            .map(Vec3::from)
            .collect();
        if let Some((i, p)) = positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(ctx.err(
                format!("{pel}.POSITION[{i}]"),
                format!("value {p} is not finite"),
            ));
        }
        let indices: Vec<u32> = match reader.read_indices() {
            Some(ix) => ix.into_u32().collect(),
            None => (0..positions.len() as u32).collect(),
        };
        if !indices.len().is_multiple_of(3) {
            return Err(ctx.err(
                &pel,
                format!("{} indices is not a multiple of 3", indices.len()),
            ));
        }
        if let Some(bad) = indices.iter().find(|&&i| i as usize >= positions.len()) {
            return Err(ctx.err(
                format!("{pel}.indices"),
                format!("index {bad} out of range for {} vertices", positions.len()),
            ));
        }
        // Shading normals: glTF NORMAL through the inverse transpose; a missing, zero or
        // non-finite one falls back to the triangle's geometric normal.
        let normals: Option<Vec<Vec3>> = reader
            .read_normals()
            .map(|it| it.map(Vec3::from).collect())
            .filter(|n: &Vec<Vec3>| n.len() == positions.len());
        let normal_matrix = glam::Mat3::from_mat4(*world).inverse().transpose();
        let uvs: Option<Vec<[f32; 2]>> = reader
            .read_tex_coords(0)
            .map(|t| t.into_f32().collect())
            .filter(|t: &Vec<[f32; 2]>| t.len() == positions.len());
        // TANGENT (xyz, handedness w) into world space: a tangent transforms as a vector,
        // and a mirroring transform flips the handedness. A broken set is dropped, with a warning.
        let linear = glam::Mat3::from_mat4(*world);
        let flip = if linear.determinant() < 0.0 {
            -1.0
        } else {
            1.0
        };
        let tangents: Option<Vec<glam::Vec4>> = reader.read_tangents().map(|t| {
            t.map(|[x, y, z, w]| {
                let v = linear * Vec3::new(x, y, z);
                glam::Vec4::new(v.x, v.y, v.z, w.signum() * flip)
            })
            .collect()
        });
        let tangents = match tangents {
            Some(t) if t.len() != positions.len() || !t.iter().all(|v| v.is_finite()) => {
                self.out.warnings.push(format!(
                    "{pel}: TANGENT ignored (not one finite tangent per vertex): a normal map takes its frame from the texture coordinates"
                ));
                None
            }
            t => t,
        };
        let colors = reader
            .read_colors(0)
            .map(|c| c.into_rgb_f32().map(Vec3::from).collect());
        let colors = self.vertex_colors(colors, &pel, positions.len(), mat_index)?;
        for tri in indices.chunks_exact(3) {
            let t = [0, 1, 2].map(|k| world.transform_point3(positions[tri[k] as usize]));
            if t.iter().any(|v| !v.is_finite()) {
                return Err(ctx.err(&pel, "transformed vertex is not finite"));
            }
            let (twice_area, geometric) = triangle_normal(&t);
            if twice_area == 0.0 {
                self.degenerate += 1;
                continue;
            }
            if let Some(ns) = &normals {
                let shade = [0, 1, 2].map(|k| {
                    let n = (normal_matrix * ns[tri[k] as usize]).normalize_or_zero();
                    if n.is_finite() && n != Vec3::ZERO {
                        n
                    } else {
                        geometric
                    }
                });
                // Earlier triangles had none: give them their geometric normals.
                while self.out.shading_normals.len() < self.out.triangles.len() {
                    let g = triangle_normal(&self.out.triangles[self.out.shading_normals.len()]).1;
                    self.out.shading_normals.push([g; 3]);
                }
                self.out.shading_normals.push(shade);
            } else if !self.out.shading_normals.is_empty() {
                self.out.shading_normals.push([geometric; 3]);
            }
            let uv = corners(&uvs, tri).map(|c| c.map(glam::Vec2::from));
            let filled = self.out.triangles.len();
            push_per_triangle(
                &mut self.out.triangle_uvs,
                filled,
                uv,
                [glam::Vec2::ZERO; 3],
            );
            push_per_triangle(
                &mut self.out.triangle_tangents,
                filled,
                corners(&tangents, tri),
                [glam::Vec4::ZERO; 3],
            );
            push_per_triangle(
                &mut self.out.triangle_colors,
                filled,
                corners(&colors, tri),
                [Vec3::ONE; 3],
            );
            self.out.triangles.push(t);
            self.out.triangle_material.push(mat_index);
        }
        Ok(())
    }

    /// Checks what the whole scene needs: triangles, some light (else the default sky),
    /// a camera (else one framing the bounds).
    fn finish(mut self) -> Result<Scene, SceneError> {
        let out = &mut self.out;
        if self.degenerate > 0 {
            out.warnings.push(format!(
                "{} degenerate (zero-area) triangles skipped",
                self.degenerate
            ));
        }
        if out.triangles.is_empty() {
            return Err(self.ctx.err("meshes", "the scene has no triangles"));
        }
        let emissive = out
            .triangle_material
            .iter()
            .any(|&m| out.materials[m as usize].emission.is_some());
        if !emissive && out.lights.is_empty() {
            out.environment = Some(Spectrum::illuminant([1.0, 1.0, 1.0]));
            out.warnings.push(
                "the scene has no light (no emissive material, no KHR_lights_punctual light): it is lit by a default uniform white (D65) sky of luminance 1, as glTF viewers do; add a light to light it yourself".to_string(),
            );
        }
        out.camera = match self.camera {
            Some(c) => c,
            None => {
                out.warnings
                    .push("no camera in the scene: framing its bounds".to_string());
                let (lo, hi) = out.bounds();
                let c = 0.5 * (lo + hi);
                let r = 0.5 * (hi - lo).length().max(1e-3);
                Camera::look_at(
                    c + Vec3::new(0.0, 0.3 * r, 2.4 * r),
                    c,
                    Vec3::Y,
                    45f32.to_radians(),
                )
            }
        };
        Ok(self.out)
    }
}

/// Refuses absolute paths and `..` in external references (they could read outside the
/// scene's folder).
fn check_relative_uri(uri: &str, ctx: &Ctx, element: &str) -> Result<(), SceneError> {
    if uri.starts_with("data:") {
        return Ok(());
    }
    let p = Path::new(uri);
    if p.is_absolute()
        || uri.contains("://")
        || p.components()
            .any(|c| matches!(c, Component::ParentDir | Component::Prefix(_)))
    {
        return Err(ctx.err(
            element,
            format!("uri '{uri}' must be a relative path inside the scene's folder"),
        ));
    }
    Ok(())
}

fn parse_extras(
    raw: &gltf::json::Extras,
    ctx: &Ctx,
    element: &str,
) -> Result<PrismapExtras, SceneError> {
    let Some(raw) = raw else {
        return Ok(PrismapExtras::default());
    };
    let value: serde_json::Value = serde_json::from_str(raw.get())
        .map_err(|e| ctx.err(format!("{element}.extras"), e.to_string()))?;
    match value.get("prismap") {
        None => Ok(PrismapExtras::default()),
        Some(v) => serde_json::from_value(v.clone())
            .map_err(|e| ctx.err(format!("{element}.extras.prismap"), e.to_string())),
    }
}

fn finite_rgb(rgb: [f32; 3], ctx: &Ctx, element: &str, what: &str) -> Result<[f64; 3], SceneError> {
    if rgb.iter().any(|v| !v.is_finite() || *v < 0.0) {
        return Err(ctx.err(element, format!("{what} {rgb:?} must be finite and ≥ 0")));
    }
    Ok(rgb.map(f64::from))
}

/// The emission spectrum: the glTF colour's luminance, the extras' spectral shape.
fn emission_spectrum(
    rgb: [f64; 3],
    extras: Option<&EmissionExtras>,
    ctx: &Ctx,
    element: &str,
) -> Result<Spectrum, SceneError> {
    let Some(e) = extras else {
        return Ok(Spectrum::illuminant(rgb));
    };
    let el = format!("{element}.extras.prismap.emission");
    let set = [
        e.blackbody_k.is_some(),
        e.illuminant.is_some(),
        e.spd_csv.is_some(),
    ];
    if set.iter().filter(|&&b| b).count() != 1 {
        return Err(ctx.err(el, "give exactly one of blackbody_k, illuminant, spd_csv"));
    }
    // The luminance of the emitter the RGB colour alone would give.
    let luminance = Spectrum::illuminant(rgb).luminance();
    let normalise = |shape: Spectrum, what: &str| -> Result<Spectrum, SceneError> {
        let y = shape.luminance();
        if !(y.is_finite() && y > 0.0) {
            return Err(ctx.err(&el, format!("{what} has no visible luminance")));
        }
        Ok(Spectrum::Scaled(luminance / y, Arc::new(shape)))
    };
    if let Some(k) = e.blackbody_k {
        return Spectrum::blackbody(k, luminance)
            .map_err(|err| ctx.err(format!("{el}.blackbody_k"), err.to_string()));
    }
    if let Some(name) = &e.illuminant {
        let shape = match name.to_ascii_uppercase().as_str() {
            "D65" => Spectrum::illuminant([1.0, 1.0, 1.0]),
            "E" => Spectrum::Constant(1.0),
            "FL11" | "F11" => Spectrum::Table(Arc::new(fl11().clone())),
            _ => {
                return Err(ctx.err(
                    format!("{el}.illuminant"),
                    format!("unknown illuminant '{name}' (known: D65, E, FL11)"),
                ));
            }
        };
        return normalise(shape, name);
    }
    let rel = e.spd_csv.as_deref().unwrap_or_default();
    check_relative_uri(rel, ctx, &format!("{el}.spd_csv"))?;
    let path = ctx
        .base
        .map(|b| b.join(rel))
        .ok_or_else(|| ctx.err(format!("{el}.spd_csv"), "no folder to read it from"))?;
    let table = read_spd_csv(&path)
        .map_err(|m| ctx.err(format!("{el}.spd_csv"), format!("{}: {m}", path.display())))?;
    normalise(Spectrum::Table(Arc::new(table)), rel)
}

/// Reads a measured SPD: `wavelength_nm,value` rows, increasing wavelengths, values ≥ 0.
pub fn read_spd_csv(path: &Path) -> Result<PiecewiseLinear, String> {
    let text = std::fs::read_to_string(path).map_err(|e| e.to_string())?;
    parse_spd_csv(&text)
}

pub fn parse_spd_csv(text: &str) -> Result<PiecewiseLinear, String> {
    let rows = parse_numeric_csv(text, 2).map_err(|e| e.to_string())?;
    let (xs, ys): (Vec<f64>, Vec<f64>) = rows.iter().map(|r| (r[0], r[1])).unzip();
    if let Some((i, v)) = ys.iter().enumerate().find(|(_, v)| **v < 0.0) {
        return Err(format!("value {v} at data row {} is negative", i + 1));
    }
    PiecewiseLinear::new(xs, ys).map_err(|e| e.to_string())
}

fn read_material(
    m: &gltf::Material,
    buffers: &[gltf::buffer::Data],
    ctx: &Ctx,
    warnings: &mut Vec<String>,
) -> Result<Material, SceneError> {
    let element = match m.index() {
        Some(i) => format!("materials[{i}]"),
        None => "default material".to_string(),
    };
    let name = m
        .name()
        .map(str::to_string)
        .unwrap_or_else(|| element.clone());
    let extras = parse_extras(m.extras(), ctx, &element)?;
    let pbr = m.pbr_metallic_roughness();
    let base = pbr.base_color_factor();
    let base_rgb = finite_rgb(
        [base[0], base[1], base[2]],
        ctx,
        &element,
        "baseColorFactor",
    )?;
    let masked = m.alpha_mode() == gltf::material::AlphaMode::Mask;
    let blended = m.alpha_mode() == gltf::material::AlphaMode::Blend;
    let normal_texture = match m.normal_texture() {
        Some(n) => {
            let scale = n.scale();
            if !scale.is_finite() {
                return Err(ctx.err(
                    format!("{element}.normalTexture.scale"),
                    format!("value {scale} is not finite"),
                ));
            }
            let t = read_texture(
                TexSource::Normal(n),
                "normalTexture",
                buffers,
                ctx,
                &element,
                warnings,
                false,
            )?;
            Some((t, scale))
        }
        None => None,
    };
    let base_color_texture = match pbr.base_color_texture() {
        Some(info) => Some(read_texture(
            TexSource::Colour(info),
            "baseColorTexture",
            buffers,
            ctx,
            &element,
            warnings,
            masked || blended,
        )?),
        None => None,
    };
    for (what, present) in [
        (
            "metallicRoughnessTexture",
            pbr.metallic_roughness_texture().is_some(),
        ),
        ("occlusionTexture", m.occlusion_texture().is_some()),
        (
            "KHR_materials_transmission.transmissionTexture",
            m.transmission()
                .is_some_and(|t| t.transmission_texture().is_some()),
        ),
    ] {
        if present {
            warnings.push(format!(
                "{element} '{name}': {what} ignored (its factor is used)"
            ));
        }
    }
    // Cut-outs (MASK: leaves, fences) have holes where alpha = factor × texel alpha is
    // below the cutoff; see-through blending (BLEND; Blender: Alpha below 1 or an image's
    // alpha into it) lets a fraction 1 − alpha through.
    let alpha_mask = if masked || blended {
        let cutoff = m.alpha_cutoff().unwrap_or(0.5);
        if !cutoff.is_finite() {
            return Err(ctx.err(
                format!("{element}.alphaCutoff"),
                format!("value {cutoff} is not finite"),
            ));
        }
        let factor = base[3];
        if !factor.is_finite() {
            return Err(ctx.err(
                format!("{element}.pbrMetallicRoughness.baseColorFactor[3]"),
                format!("value {factor} is not finite"),
            ));
        }
        Some(super::AlphaMask {
            cutoff,
            factor,
            blend: blended,
        })
    } else {
        None
    };
    let transmission = m
        .transmission()
        .map(|t| t.transmission_factor())
        .unwrap_or(0.0);
    if let Some(n) = m.ior()
        && !(n == 0.0 || (n.is_finite() && n >= 1.0))
    {
        return Err(ctx.err(
            format!("{element}.KHR_materials_ior.ior"),
            format!("{n} is not a valid index of refraction (glTF allows 0 or a value ≥ 1; glass is about 1.5)"),
        ));
    }
    // glTF's special ior 0: reflection without refraction (Fresnel F0 = 1).
    let ior_zero = m.ior() == Some(0.0) && extras.glass.is_none();
    let (metallic, roughness) = (pbr.metallic_factor(), pbr.roughness_factor());
    for (field, v) in [("metallicFactor", metallic), ("roughnessFactor", roughness)] {
        if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
            return Err(ctx.err(
                format!("{element}.pbrMetallicRoughness.{field}"),
                format!("{v} is outside [0, 1]"),
            ));
        }
    }
    let kind = if ior_zero {
        warnings.push(format!(
            "{element} '{name}': ior 0 (full reflection) rendered as a metal of its base colour"
        ));
        MaterialKind::Mirror {
            reflectance: Spectrum::reflectance(base_rgb),
            roughness,
        }
    } else if transmission > 0.0 || extras.glass.is_some() {
        let ior = read_glass(m, &extras, transmission, ctx, (&element, &name), warnings)?;
        if metallic > 0.0 {
            warnings.push(format!(
                "{element} '{name}': metallicFactor {metallic} on a transmissive material ignored (rendered as glass)"
            ));
        }
        MaterialKind::Dielectric { ior, roughness }
    } else if metallic >= 0.5 {
        if metallic < 1.0 {
            warnings.push(format!(
                "{element} '{name}': metallicFactor {metallic} rendered as a pure metal (1)"
            ));
        }
        MaterialKind::Mirror {
            reflectance: Spectrum::reflectance(base_rgb),
            roughness,
        }
    } else {
        if m.index().is_some() {
            if metallic > 0.0 {
                warnings.push(format!(
                    "{element} '{name}': metallicFactor {metallic} rendered as a non-metal (0)"
                ));
            }
            if roughness < 0.5 {
                warnings.push(format!(
                    "{element} '{name}': roughnessFactor {roughness}: the glossy coat of a non-metal is not rendered (Lambertian only)"
                ));
            }
        }
        MaterialKind::Diffuse {
            reflectance: Spectrum::reflectance(base_rgb),
        }
    };
    let emission = read_emission(m, &extras, ctx, (&element, &name), warnings)?;
    // An emissive texture only matters where the factor emits (glTF multiplies them).
    let emissive_texture = match (m.emissive_texture(), &emission) {
        (Some(info), Some(_)) => Some(read_texture(
            TexSource::Colour(info),
            "emissiveTexture",
            buffers,
            ctx,
            &element,
            warnings,
            false,
        )?),
        _ => None,
    };
    let volume = read_volume(m, &kind, ctx, &element)?;
    Ok(Material {
        name,
        kind,
        emission,
        volume,
        base_color_texture,
        emissive_texture,
        vertex_colors: false,
        alpha_mask,
        normal_texture,
    })
}

/// The index of refraction of a transmissive material: a named Sellmeier glass from the
/// extras, else `KHR_materials_ior` with `KHR_materials_dispersion` (Abbe form).
fn read_glass(
    m: &gltf::Material,
    extras: &PrismapExtras,
    transmission: f32,
    ctx: &Ctx,
    (element, name): (&str, &str),
    warnings: &mut Vec<String>,
) -> Result<IorModel, SceneError> {
    let element = element.to_string();
    if transmission > 0.0 && transmission < 1.0 {
        warnings.push(format!(
            "{element} '{name}': transmission {transmission} rendered as clear glass"
        ));
    }
    let ior = if let Some(glass) = &extras.glass {
        IorModel::glass(glass)
            .map_err(|e| ctx.err(format!("{element}.extras.prismap.glass"), e.to_string()))?
    } else {
        let n = m.ior().unwrap_or(1.5) as f64;
        let dispersion = m
            .extension_value("KHR_materials_dispersion")
            .and_then(|v| v.get("dispersion"))
            .map(|v| {
                v.as_f64().ok_or_else(|| {
                    ctx.err(
                        format!("{element}.KHR_materials_dispersion.dispersion"),
                        format!("{v} is not a number"),
                    )
                })
            })
            .transpose()?
            .unwrap_or(0.0);
        if !(dispersion.is_finite() && dispersion >= 0.0) {
            return Err(ctx.err(
                format!("{element}.KHR_materials_dispersion.dispersion"),
                format!("{dispersion} must be finite and ≥ 0"),
            ));
        }
        if dispersion > 0.0 && m.volume().is_none() {
            warnings.push(format!(
                "{element} '{name}': KHR_materials_dispersion without KHR_materials_volume (glTF then means a thin-walled surface, where dispersion has no effect); rendered as a solid dispersive glass"
            ));
        }
        if dispersion > 0.0 {
            // glTF: V_d = 20 / dispersion.
            IorModel::abbe(n, 20.0 / dispersion)
        } else {
            IorModel::constant(n)
        }
        .map_err(|e| ctx.err(format!("{element}.ior"), e.to_string()))?
    };
    ior.validate(360.0, 830.0)
        .map_err(|e| ctx.err(&element, e.to_string()))?;
    Ok(ior)
}

/// `KHR_materials_volume` attenuation of a glass; None when it absorbs nothing (or the
/// material is not a glass).
fn read_volume(
    m: &gltf::Material,
    kind: &MaterialKind,
    ctx: &Ctx,
    element: &str,
) -> Result<Option<super::Volume>, SceneError> {
    let Some(v) = m.volume() else {
        return Ok(None);
    };
    let distance = v.attenuation_distance() as f64;
    let color = finite_rgb(
        v.attenuation_color(),
        ctx,
        element,
        "KHR_materials_volume.attenuationColor",
    )?;
    if !(distance > 0.0) {
        return Err(ctx.err(
            format!("{element}.KHR_materials_volume.attenuationDistance"),
            format!("{distance} must be > 0"),
        ));
    }
    let absorbs = distance.is_finite() && color.iter().any(|&c| c < 1.0);
    Ok(
        (absorbs && matches!(kind, MaterialKind::Dielectric { .. })).then_some(super::Volume {
            color: color.map(|c| c.min(1.0)),
            distance,
        }),
    )
}

/// The emission of a material: `emissiveFactor × KHR_materials_emissive_strength`, shaped
/// by the extras' spectrum if any.
fn read_emission(
    m: &gltf::Material,
    extras: &PrismapExtras,
    ctx: &Ctx,
    (element, name): (&str, &str),
    warnings: &mut Vec<String>,
) -> Result<Option<Spectrum>, SceneError> {
    let strength = m.emissive_strength().unwrap_or(1.0);
    if !(strength.is_finite() && strength >= 0.0) {
        return Err(ctx.err(
            format!("{element}.KHR_materials_emissive_strength"),
            format!("{strength} must be finite and ≥ 0"),
        ));
    }
    let e = finite_rgb(m.emissive_factor(), ctx, element, "emissiveFactor")?;
    let rgb = e.map(|v| v * strength as f64);
    let emission = if rgb.iter().any(|&v| v > 0.0) {
        Some(emission_spectrum(
            rgb,
            extras.emission.as_ref(),
            ctx,
            element,
        )?)
    } else {
        if extras.emission.is_some() {
            warnings.push(format!(
                "{element} '{name}': extras emission ignored (emissiveFactor is black)"
            ));
        }
        None
    };
    Ok(emission)
}

fn read_light(
    light: &gltf::khr_lights_punctual::Light,
    world: &Mat4,
    ctx: &Ctx,
    warnings: &mut Vec<String>,
) -> Result<PunctualLight, SceneError> {
    let element = format!("KHR_lights_punctual.lights[{}]", light.index());
    let name = light
        .name()
        .map(str::to_string)
        .unwrap_or_else(|| element.clone());
    let intensity = light.intensity();
    if !(intensity.is_finite() && intensity >= 0.0) {
        return Err(ctx.err(
            &element,
            format!("intensity {intensity} must be finite and ≥ 0"),
        ));
    }
    let color = finite_rgb(light.color(), ctx, &element, "color")?;
    let rgb = color.map(|c| c * intensity as f64);
    let extras = parse_extras(light.extras(), ctx, &element)?;
    let spectrum = emission_spectrum(rgb, extras.emission.as_ref(), ctx, &element)?;
    let position = world.transform_point3(Vec3::ZERO);
    // Spot and directional lights shine along the node's −Z.
    let direction = world.transform_vector3(-Vec3::Z).normalize_or_zero();
    if light.range().is_some() {
        warnings.push(format!(
            "{element} '{name}': range ignored (light falls off as 1/d², as physics has it)"
        ));
    }
    let kind = match light.kind() {
        gltf::khr_lights_punctual::Kind::Point => PunctualKind::Point,
        gltf::khr_lights_punctual::Kind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } => {
            if !(outer_cone_angle > 0.0 && outer_cone_angle <= std::f32::consts::FRAC_PI_2) {
                return Err(ctx.err(
                    &element,
                    format!("outerConeAngle {outer_cone_angle} must be in (0, π/2]"),
                ));
            }
            if !(inner_cone_angle >= 0.0 && inner_cone_angle < outer_cone_angle) {
                return Err(ctx.err(
                    &element,
                    format!("innerConeAngle {inner_cone_angle} must be in [0, outerConeAngle)"),
                ));
            }
            if direction == Vec3::ZERO {
                return Err(ctx.err(&element, "spot direction is degenerate (zero scale?)"));
            }
            PunctualKind::Spot {
                direction,
                inner: inner_cone_angle,
                outer: outer_cone_angle,
            }
        }
        gltf::khr_lights_punctual::Kind::Directional => {
            if direction == Vec3::ZERO {
                return Err(ctx.err(
                    &element,
                    format!("directional light '{name}': direction is degenerate (zero scale?)"),
                ));
            }
            PunctualKind::Directional { direction }
        }
    };
    Ok(PunctualLight {
        name,
        position,
        kind,
        intensity: spectrum,
    })
}

fn read_camera(
    cam: &gltf::Camera,
    world: &Mat4,
    ctx: &Ctx,
    warnings: &mut Vec<String>,
) -> Result<Camera, SceneError> {
    let element = format!("cameras[{}]", cam.index());
    let (yfov, aspect) = match cam.projection() {
        gltf::camera::Projection::Perspective(p) => (p.yfov(), p.aspect_ratio()),
        gltf::camera::Projection::Orthographic(o) => {
            warnings.push(format!(
                "{element}: orthographic camera rendered as a 45° perspective"
            ));
            (45f32.to_radians(), Some(o.xmag() / o.ymag()))
        }
    };
    let aspect = match aspect {
        Some(a) if a.is_finite() && (1e-3..=1e3).contains(&a) => Some(a),
        Some(a) => {
            return Err(ctx.err(
                &element,
                format!("aspectRatio {a} must be a positive, finite width/height"),
            ));
        }
        None => None,
    };
    if !(yfov.is_finite() && yfov > 1e-4 && yfov < std::f32::consts::PI - 1e-4) {
        return Err(ctx.err(&element, format!("yfov {yfov} must be in (0, π)")));
    }
    let position = world.transform_point3(Vec3::ZERO);
    let forward = world.transform_vector3(-Vec3::Z).normalize_or_zero();
    let up = world.transform_vector3(Vec3::Y).normalize_or_zero();
    let right = forward.cross(up).normalize_or_zero();
    if right == Vec3::ZERO {
        return Err(ctx.err(&element, "camera transform is degenerate"));
    }
    Ok(Camera {
        position,
        forward,
        up: right.cross(forward),
        right,
        yfov,
        aspect,
    })
}

#[cfg(test)]
mod tests {
    use super::percent_decode;

    #[test]
    fn percent_decoding_never_panics() {
        assert_eq!(percent_decode("my%20scene.bin"), "my scene.bin");
        assert_eq!(percent_decode("ü%C3%BC.bin"), "üü.bin");
        for s in ["%", "%2", "%zz", "a%é", "%%", "é%"] {
            percent_decode(s);
        }
        assert_eq!(percent_decode("100%"), "100%");
    }
}
