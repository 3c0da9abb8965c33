//! Textures (issue #11): a base-colour texture is a spectral input like any colour.

use base64::Engine as _;
use prismap_engine::photon::Storage;
use prismap_engine::render::{RenderSession, RenderSettings};
use prismap_engine::scene;

/// Four linear colours in a 2×2 texture (sRGB-encoded in the PNG, as glTF stores colour).
const TEXELS: [[f32; 3]; 4] = [
    [0.8, 0.1, 0.1],
    [0.1, 0.6, 0.1],
    [0.1, 0.2, 0.7],
    [0.7, 0.7, 0.2],
];

fn png_2x2() -> Vec<u8> {
    let mut img = image::RgbImage::new(2, 2);
    for (i, c) in TEXELS.iter().enumerate() {
        let enc = c.map(prismap_engine::spectral::color::srgb8);
        img.put_pixel((i % 2) as u32, (i / 2) as u32, image::Rgb(enc));
    }
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .unwrap();
    bytes
}

/// A unit quad at z = 0 facing +z, UV (0,0) at its top left, the texture embedded as a
/// data URI, nearest filtering; a camera looking at it head-on; no light (the default sky).
fn textured_quad_gltf(extra_texture_info: &str) -> String {
    let mut bin = Vec::new();
    let pos: [[f32; 3]; 4] = [
        [-1.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
        [1.0, -1.0, 0.0],
        [-1.0, -1.0, 0.0],
    ];
    let uv: [[f32; 2]; 4] = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    for p in pos.iter().flatten().chain(uv.iter().flatten()) {
        bin.extend_from_slice(&p.to_le_bytes());
    }
    for i in [0u16, 3, 2, 0, 2, 1] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let b64 = base64::engine::general_purpose::STANDARD;
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0,1]}}],
        "nodes":[{{"mesh":0}},{{"camera":0,"translation":[0,0,2.5]}}],
        "cameras":[{{"type":"perspective","perspective":{{"yfov":0.6,"znear":0.01,"aspectRatio":1.0}}}}],
        "materials":[{{"pbrMetallicRoughness":{{"baseColorTexture":{{"index":0{extra_texture_info}}},"metallicFactor":0}}}}],
        "textures":[{{"source":0,"sampler":0}}],"samplers":[{{"magFilter":9728,"minFilter":9728}}],
        "images":[{{"uri":"data:image/png;base64,{png}"}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0,"TEXCOORD_0":1}},"indices":2,"material":0}}]}}],
        "buffers":[{{"byteLength":{len},"uri":"data:application/octet-stream;base64,{data}"}}],
        "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":48}},{{"buffer":0,"byteOffset":48,"byteLength":32}},{{"buffer":0,"byteOffset":80,"byteLength":12}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[-1,-1,0],"max":[1,1,0]}},
                     {{"bufferView":1,"componentType":5126,"count":4,"type":"VEC2"}},
                     {{"bufferView":2,"componentType":5123,"count":6,"type":"SCALAR"}}]}}"#,
        png = b64.encode(png_2x2()),
        len = bin.len(),
        data = b64.encode(&bin),
    )
}

/// `s` rendered at 32 × 32 on `bins` bins of `storage`, 5 000 photons and `fg`
/// final-gather rays a pass, after `passes` passes; with its bin grid.
fn render_32(
    s: &scene::Scene,
    storage: Storage,
    bins: usize,
    fg: u32,
    passes: usize,
) -> (
    prismap_engine::render::Image,
    prismap_engine::spectral::BinGrid,
) {
    let settings = RenderSettings {
        bins,
        storage,
        width: 32,
        height: 32,
        photons_per_pass: 5_000,
        final_gather_rays: fg,
        ..RenderSettings::default()
    };
    let mut r = RenderSession::new(s, settings).unwrap();
    for _ in 0..passes {
        r.run_pass().unwrap();
    }
    (r.image(), r.scene().grid.clone())
}

/// The colour a diffuse surface of linear RGB reflectance `rgb` shows under the default
/// white (D65) sky: `rgb` itself on the RGB grid, its upsampled spectrum's round trip on
/// a spectral one.
fn under_the_sky(grid: &prismap_engine::spectral::BinGrid, rgb: [f32; 3]) -> [f32; 3] {
    use prismap_engine::spectral::{Role, Spectrum, Transport};
    if grid.transport() == Transport::Rgb {
        return rgb;
    }
    let mut v = grid.project(
        &Spectrum::reflectance(rgb.map(f64::from)),
        Role::Reflectance,
    );
    let sky = grid.project(&Spectrum::illuminant([1.0; 3]), Role::Emission);
    prismap_engine::spectral::spd::mul_assign(&mut v, &sky);
    grid.to_linear_srgb(&v)
}

#[test]
fn a_textured_quad_seen_head_on_shows_its_texture() {
    // Under the default white (D65) sky a flat diffuse surface facing it has radiance ρ, so
    // each quarter of the quad shows its texel's colour: exactly on the RGB grid, and as
    // the colour of the texel's Smits spectrum under D65 on spectral grids (the RGB
    // round trip, off by up to 0.063 for this saturated blue) — within noise, 0.02.
    let s = scene::load_from_slice(textured_quad_gltf("").as_bytes(), "quad.gltf", None).unwrap();
    assert!(s.materials[0].base_color_texture.is_some());
    assert!(
        !s.warnings.iter().any(|w| w.contains("texture")),
        "{:?}",
        s.warnings
    );
    for (storage, bins) in [
        (Storage::Compact, 16),
        (Storage::Full, 16),
        (Storage::Rgb, 3),
    ] {
        let (img, grid) = render_32(&s, storage, bins, 16, 4);
        let round_trip = |rgb: [f32; 3]| under_the_sky(&grid, rgb);
        for (i, texel) in TEXELS.iter().enumerate() {
            let want = &round_trip(*texel);
            // The middle of each quarter of the view.
            let (x, y) = (8 + 16 * (i as u32 % 2), 8 + 16 * (i as u32 / 2));
            let got = img.get(x, y);
            println!("{storage:?}: texel {i}: {got:?} (texture {texel:?}, round trip {want:?})");
            for c in 0..3 {
                assert!(
                    (got[c] - want[c]).abs() < 0.02,
                    "{storage:?} texel {i}: {got:?} vs {want:?}"
                );
            }
        }
    }
}

#[test]
fn texture_transform_moves_the_texture_and_bad_images_are_named() {
    // KHR_texture_transform offset by half a texture: the quarters swap left and right.
    let shifted =
        textured_quad_gltf(r#","extensions":{"KHR_texture_transform":{"offset":[0.5,0]}}"#);
    let s = scene::load_from_slice(shifted.as_bytes(), "quad.gltf", None).unwrap();
    let t = s.materials[0].base_color_texture.as_ref().unwrap();
    let at = |u: f32, v: f32| t.sample(glam::Vec2::new(u, v));
    let close = |a: [f32; 3], b: [f32; 3]| (0..3).all(|c| (a[c] - b[c]).abs() < 0.01);
    let stored = |i: usize| {
        TEXELS[i].map(|v| {
            let e = prismap_engine::spectral::color::srgb8(v) as f32 / 255.0;
            prismap_engine::spectral::color::srgb_decode(e)
        })
    };
    assert!(close(at(0.25, 0.25), stored(1)), "{:?}", at(0.25, 0.25));
    assert!(close(at(0.75, 0.25), stored(0)), "{:?}", at(0.75, 0.25));
    // An image that is not one names the material and the texture.
    let text = textured_quad_gltf("");
    let start = text.find("data:image/png;base64,").unwrap() + "data:image/png;base64,".len();
    let end = start + text[start..].find('"').unwrap();
    let broken = format!("{}{}{}", &text[..start], "bm90IGFuIGltYWdl", &text[end..]);
    let e = scene::load_from_slice(broken.as_bytes(), "quad.gltf", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("materials[0].baseColorTexture") && e.contains("decode"),
        "{e}"
    );
}

/// The quad as an emitter: black base colour, emissiveFactor × emissiveTexture.
fn emissive_quad_gltf(factor: [f32; 3]) -> String {
    textured_quad_gltf("").replace(
        r#""pbrMetallicRoughness":{"baseColorTexture":{"index":0},"metallicFactor":0}"#,
        &format!(
            r#""pbrMetallicRoughness":{{"baseColorFactor":[0,0,0,1],"metallicFactor":0}},"emissiveFactor":[{},{},{}],"emissiveTexture":{{"index":0}}"#,
            factor[0], factor[1], factor[2]
        ),
    )
}

#[test]
fn an_emissive_texture_is_seen_texel_by_texel_and_lights_by_its_mean() {
    // Issue #11: glTF's emission is emissiveFactor × emissiveTexture. Seen head-on, each
    // quarter of the quad shows factor × texel (exactly on the RGB grid; through the
    // texel's spectrum times the factor's on spectral grids); as a light each triangle
    // emits its own mean texel, so the scene's emitted power follows the texture.
    let factor = [2.0f32, 2.0, 2.0];
    let text = emissive_quad_gltf(factor);
    assert!(text.contains("emissiveTexture"), "the replacement took");
    let s = scene::load_from_slice(text.as_bytes(), "quad.gltf", None).unwrap();
    assert!(s.materials[0].emissive_texture.is_some());
    assert!(
        s.environment.is_none(),
        "an emissive quad is a light: no default sky"
    );
    assert!(
        !s.warnings.iter().any(|w| w.contains("emissiveTexture")),
        "{:?}",
        s.warnings
    );
    for (storage, bins) in [(Storage::Compact, 16), (Storage::Rgb, 3)] {
        let settings = RenderSettings {
            bins,
            storage,
            width: 32,
            height: 32,
            photons_per_pass: 2_000,
            final_gather_rays: 4,
            ..RenderSettings::default()
        };
        let mut r = RenderSession::new(&s, settings).unwrap();
        r.run_pass().unwrap();
        let img = r.image();
        let grid = r.scene().grid.clone();
        let want = |rgb: [f32; 3]| -> [f32; 3] {
            use prismap_engine::spectral::{Role, Spectrum};
            if storage == Storage::Rgb {
                return [0, 1, 2].map(|c| rgb[c] * factor[c]);
            }
            let mut v = grid.project(
                &Spectrum::reflectance(rgb.map(f64::from)),
                Role::Reflectance,
            );
            let e = grid.project(&Spectrum::illuminant(factor.map(f64::from)), Role::Emission);
            prismap_engine::spectral::spd::mul_assign(&mut v, &e);
            grid.to_linear_srgb(&v)
        };
        for (i, texel) in TEXELS.iter().enumerate() {
            let want = want(*texel);
            let (x, y) = (8 + 16 * (i as u32 % 2), 8 + 16 * (i as u32 / 2));
            let got = img.get(x, y);
            println!("{storage:?}: texel {i}: {got:?} (want {want:?})");
            for c in 0..3 {
                assert!(
                    // 8-bit sRGB texels: a quantisation step is up to 0.5 % of the value.
                    (got[c] - want[c]).abs() < 0.01 * want[c].max(0.1),
                    "{storage:?} texel {i}: {got:?} vs {want:?}"
                );
            }
        }
        // The two triangles as lights: each emits the mean of the texels it covers.
        let lights = &r.scene().lights;
        let total: f32 = (0..2)
            .map(|i| grid.to_xyz(lights.spectrum(i))[1] as f32)
            .sum();
        let untextured = grid.to_xyz(&grid.project(
            &prismap_engine::spectral::Spectrum::illuminant(factor.map(f64::from)),
            prismap_engine::spectral::Role::Emission,
        ))[1] as f32;
        // Both triangles together cover the quad once: twice the mean texel luminance.
        let mean_y: f32 = TEXELS
            .iter()
            .map(|t| 0.2126 * t[0] + 0.7152 * t[1] + 0.0722 * t[2])
            .sum::<f32>()
            / 4.0;
        let ratio = total / (2.0 * mean_y * untextured);
        println!("{storage:?}: emitted luminance {ratio:.4} of factor × mean texel");
        assert!((ratio - 1.0).abs() < 0.05, "{storage:?}: {ratio}");
    }
}

#[test]
fn khronos_box_textured_renders_its_embedded_texture_on_a_rough_metal() {
    // Issue #11: Khronos BoxTextured (glTF-Embedded: buffer and a palette PNG as data
    // URIs). Its material sets only a base-colour texture, so glTF's defaults make it a
    // rough metal (metallic 1, roughness 1) whose F0 is the texture; it has no light (the
    // default sky, with a warning) and no camera (the bounds are framed, with a warning).
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes/khronos/BoxTextured.gltf");
    let s = scene::load(&path).unwrap();
    assert!(s.materials[0].base_color_texture.is_some());
    assert!(matches!(
        s.materials[0].kind,
        scene::MaterialKind::Mirror { roughness, .. } if roughness == 1.0
    ));
    assert!(
        s.warnings.iter().any(|w| w.contains("no light")),
        "{:?}",
        s.warnings
    );
    assert!(
        s.warnings.iter().any(|w| w.contains("no camera")),
        "{:?}",
        s.warnings
    );
    let settings = RenderSettings {
        width: 64,
        height: 64,
        photons_per_pass: 1_000,
        ..RenderSettings::preview()
    };
    let mut r = RenderSession::new(&s, settings).unwrap();
    for _ in 0..32 {
        r.run_pass().unwrap();
    }
    let img = r.image();
    // Mean colour of a 5×5 patch: the logo's sky (blue) above its hills (green).
    let patch = |cx: u32, cy: u32| {
        let mut m = [0.0f32; 3];
        for y in cy - 2..=cy + 2 {
            for x in cx - 2..=cx + 2 {
                for (c, v) in m.iter_mut().zip(img.get(x, y)) {
                    *c += v / 25.0;
                }
            }
        }
        m
    };
    let (sky, hills) = (patch(32, 20), patch(32, 48));
    println!("logo sky {sky:?}, hills {hills:?}");
    assert!(
        sky[2] > 1.3 * sky[1] && sky[2] > 1.5 * sky[0],
        "blue: {sky:?}"
    );
    assert!(
        hills[1] > 1.3 * hills[2] && hills[1] > 1.3 * hills[0],
        "green: {hills:?}"
    );
}

/// A unit quad at z = 0 facing +z of six vertices (two triangles that share none: lower
/// left TL-BL-BR, upper right TL-BR-TR) with `COLOR_0` given as `(bytes, componentType,
/// normalized, type)`, base colour factor `factor`, `material_extra` spliced into the
/// material; a camera head-on; no light (the default sky).
fn vertex_coloured_quad_gltf(
    colors: (&[u8], u32, bool, &str),
    factor: [f32; 3],
    material_extra: &str,
) -> String {
    let (tl, tr, br, bl) = (
        [-1.0f32, 1.0, 0.0],
        [1.0, 1.0, 0.0],
        [1.0, -1.0, 0.0],
        [-1.0, -1.0, 0.0],
    );
    let mut bin = Vec::new();
    for p in [tl, bl, br, tl, br, tr].iter().flatten() {
        bin.extend_from_slice(&p.to_le_bytes());
    }
    let color_offset = bin.len();
    bin.extend_from_slice(colors.0);
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let (component, normalized, kind) = (colors.1, colors.2, colors.3);
    let b64 = base64::engine::general_purpose::STANDARD;
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0,1]}}],
        "nodes":[{{"mesh":0}},{{"camera":0,"translation":[0,0,2.5]}}],
        "cameras":[{{"type":"perspective","perspective":{{"yfov":0.6,"znear":0.01,"aspectRatio":1.0}}}}],
        "materials":[{{"name":"painted","pbrMetallicRoughness":{{"baseColorFactor":[{f0},{f1},{f2},1],"metallicFactor":0}}{material_extra}}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0,"COLOR_0":1}},"material":0}}]}}],
        "buffers":[{{"byteLength":{len},"uri":"data:application/octet-stream;base64,{data}"}}],
        "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":72}},{{"buffer":0,"byteOffset":{color_offset},"byteLength":{color_len}}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":6,"type":"VEC3","min":[-1,-1,0],"max":[1,1,0]}},
                     {{"bufferView":1,"componentType":{component},"normalized":{normalized},"count":6,"type":"{kind}"}}]}}"#,
        f0 = factor[0],
        f1 = factor[1],
        f2 = factor[2],
        len = bin.len(),
        data = b64.encode(&bin),
        color_len = colors.0.len(),
    )
}

#[test]
fn vertex_colours_multiply_the_base_colour_as_blender_exports_them() {
    // glTF's base colour is factor × texture × COLOR_0. Blender writes painted colour
    // attributes as COLOR_0, unsigned-short normalised RGBA. The lower-left triangle's
    // corners are all (0.8, 0.1, 0.1), the upper-right's all (0.1, 0.2, 0.7); the factor
    // (0.5, 1, 1) halves red. Under the default sky each half shows its reflectance
    // (0.4, 0.1, 0.1) and (0.05, 0.2, 0.7): exactly on the RGB grid, through the
    // spectral round trip on 16 bins.
    let (a, b) = ([0.8f32, 0.1, 0.1], [0.1f32, 0.2, 0.7]);
    let mut bytes = Vec::new();
    for c in [a, a, a, b, b, b] {
        for v in [c[0], c[1], c[2], 1.0] {
            bytes.extend_from_slice(&((v * 65535.0).round() as u16).to_le_bytes());
        }
    }
    let factor = [0.5, 1.0, 1.0];
    let text = vertex_coloured_quad_gltf((&bytes, 5123, true, "VEC4"), factor, "");
    let s = scene::load_from_slice(text.as_bytes(), "painted.gltf", None).unwrap();
    assert!(s.materials[0].vertex_colors, "{:?}", s.warnings);
    assert_eq!(s.triangle_colors.len(), 2);
    assert!(
        s.warnings.iter().all(|w| !w.contains("COLOR_0")),
        "{:?}",
        s.warnings
    );
    for (storage, bins) in [(Storage::Compact, 16), (Storage::Rgb, 3)] {
        let (img, grid) = render_32(&s, storage, bins, 16, 4);
        let round_trip = |rgb: [f32; 3]| under_the_sky(&grid, rgb);
        for (name, colour, (x, y)) in [("lower left", a, (6, 26)), ("upper right", b, (26, 6))] {
            let want = round_trip([0, 1, 2].map(|c| colour[c] * factor[c]));
            let got = img.get(x, y);
            println!("{storage:?} {name}: {got:?} (want {want:?})");
            for c in 0..3 {
                assert!(
                    (got[c] - want[c]).abs() < 0.02,
                    "{storage:?} {name}: {got:?} vs {want:?}"
                );
            }
        }
    }
}

#[test]
fn bad_vertex_colours_are_named_and_glass_ignores_them_with_a_warning() {
    // Float RGB colours: a NaN is an error naming the vertex; 1.5 is clamped with a
    // warning; on a glass (KHR_materials_transmission) they are ignored, with a warning.
    let floats = |values: [[f32; 3]; 6]| -> Vec<u8> {
        values
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect()
    };
    let mut values = [[0.5f32; 3]; 6];
    values[4][1] = f32::NAN;
    let text = vertex_coloured_quad_gltf((&floats(values), 5126, false, "VEC3"), [1.0; 3], "");
    let e = scene::load_from_slice(text.as_bytes(), "painted.gltf", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("painted.gltf") && e.contains("COLOR_0[4]") && e.contains("NaN"),
        "{e}"
    );
    values[4][1] = 1.5;
    let text = vertex_coloured_quad_gltf((&floats(values), 5126, false, "VEC3"), [1.0; 3], "");
    let s = scene::load_from_slice(text.as_bytes(), "painted.gltf", None).unwrap();
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("1 COLOR_0 colours outside [0, 1] clamped")),
        "{:?}",
        s.warnings
    );
    assert_eq!(s.triangle_colors[1][1], glam::Vec3::new(0.5, 1.0, 0.5));
    let glass = r#","extensions":{"KHR_materials_transmission":{"transmissionFactor":1}}"#;
    let text = vertex_coloured_quad_gltf(
        (&floats([[0.5; 3]; 6]), 5126, false, "VEC3"),
        [1.0; 3],
        glass,
    );
    let s = scene::load_from_slice(text.as_bytes(), "painted.gltf", None).unwrap();
    assert!(!s.materials[0].vertex_colors);
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("COLOR_0 ignored") && w.contains("\"painted\" is a glass")),
        "{:?}",
        s.warnings
    );
}

#[test]
fn blenders_painted_colour_attributes_load_as_vertex_colours() {
    // scenes/blender/vertex-painted.glb (make_blender_fixtures.py, Blender 5.0): a cube
    // painted one colour per face (corner domain) and a smooth ico sphere with a colour
    // per vertex, each through a Color Attribute node into the Base Color.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes/blender/vertex-painted.glb");
    let s = scene::load(&path).unwrap();
    assert!(
        s.warnings.iter().all(|w| !w.contains("COLOR_0")),
        "{:?}",
        s.warnings
    );
    let painted: Vec<&str> = s
        .materials
        .iter()
        .filter(|m| m.vertex_colors)
        .map(|m| m.name.as_str())
        .collect();
    assert_eq!(painted, ["face paint", "gradient paint"]);
    assert_eq!(s.triangle_colors.len(), s.triangles.len());
    // The cube's triangles: each has one colour at all three corners, and there are the
    // six face colours (linear, as painted).
    let faces = [
        [0.8, 0.1, 0.1],
        [0.1, 0.6, 0.1],
        [0.1, 0.2, 0.7],
        [0.7, 0.7, 0.2],
        [0.6, 0.2, 0.6],
        [0.2, 0.6, 0.6],
    ];
    let cube = s
        .materials
        .iter()
        .position(|m| m.name == "face paint")
        .unwrap() as u32;
    let mut seen = [false; 6];
    for (t, c) in s.triangle_colors.iter().enumerate() {
        if s.triangle_material[t] != cube {
            continue;
        }
        assert!(c[0] == c[1] && c[1] == c[2], "triangle {t}: {c:?}");
        let k = faces
            .iter()
            .position(|f| (0..3).all(|i| (c[0][i] - f[i]).abs() < 2e-3))
            .unwrap_or_else(|| panic!("triangle {t}: colour {:?} is no face's", c[0]));
        seen[k] = true;
    }
    assert_eq!(seen, [true; 6]);
    // The ground has none: white.
    let ground = s.materials.iter().position(|m| m.name == "ground").unwrap() as u32;
    let t = s
        .triangle_material
        .iter()
        .position(|&m| m == ground)
        .unwrap();
    assert_eq!(s.triangle_colors[t], [glam::Vec3::ONE; 3]);
}

#[test]
fn masks_load_as_cut_outs_and_blends_as_partial_cover() {
    // Blender writes alphaMode MASK for clipped alpha (leaves, fences) and BLEND for
    // Alpha below 1 (veils, decals): both load as a coverage test, without warnings.
    let white = [[255u8; 4]; 6].concat();
    let load = |extra: &str| {
        let text = vertex_coloured_quad_gltf((&white, 5121, true, "VEC4"), [1.0; 3], extra);
        scene::load_from_slice(text.as_bytes(), "leaf.gltf", None).unwrap()
    };
    for (extra, want) in [
        (
            r#","alphaMode":"MASK","alphaCutoff":0.3"#,
            Some(scene::AlphaMask {
                cutoff: 0.3,
                factor: 1.0,
                blend: false,
            }),
        ),
        (
            r#","alphaMode":"BLEND""#,
            Some(scene::AlphaMask {
                cutoff: 0.5,
                factor: 1.0,
                blend: true,
            }),
        ),
        ("", None),
    ] {
        let s = load(extra);
        assert!(
            s.warnings.iter().all(|w| !w.contains("alpha")),
            "{:?}",
            s.warnings
        );
        assert_eq!(s.materials[0].alpha_mask, want, "{extra}");
    }
}

/// [`textured_quad_gltf`]'s quad with an RGBA texture: black texels of alpha `alpha`
/// (row-major 2×2), and alphaMode MASK.
fn masked_quad_gltf(alpha: [u8; 4]) -> String {
    let mut img = image::RgbaImage::new(2, 2);
    for (i, a) in alpha.iter().enumerate() {
        img.put_pixel((i % 2) as u32, (i / 2) as u32, image::Rgba([0, 0, 0, *a]));
    }
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let b64 = base64::engine::general_purpose::STANDARD;
    let text = textured_quad_gltf("");
    let start = text.find("data:image/png;base64,").unwrap() + "data:image/png;base64,".len();
    let end = start + text[start..].find('"').unwrap();
    let text = format!("{}{}{}", &text[..start], b64.encode(png), &text[end..]);
    text.replace(
        r#""metallicFactor":0}"#,
        r#""metallicFactor":0},"alphaMode":"MASK""#,
    )
}

#[test]
fn alpha_mask_cut_outs_let_rays_and_light_through_their_holes() {
    // A black quad under the default sky (radiance 1), its texture's alpha 1, 0 / 0, 1
    // (cutoff 0.5): through the two holes the camera sees the sky, the two solid quarters
    // are black. Photons, shadow rays and camera rays all go through the same test.
    let s = scene::load_from_slice(
        masked_quad_gltf([255, 0, 0, 255]).as_bytes(),
        "leaf.gltf",
        None,
    )
    .unwrap();
    assert!(s.materials[0].alpha_mask.is_some());
    assert!(
        s.warnings.iter().all(|w| !w.contains("alphaMode")),
        "{:?}",
        s.warnings
    );
    let (img, _) = render_32(&s, Storage::Compact, 8, 4, 2);
    let lum = |p: [f32; 3]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
    for (i, hole) in [false, true, true, false].into_iter().enumerate() {
        let (x, y) = (8 + 16 * (i as u32 % 2), 8 + 16 * (i as u32 / 2));
        let l = lum(img.get(x, y));
        println!("quarter {i}: luminance {l} (hole {hole})");
        if hole {
            assert!((l - 1.0).abs() < 0.02, "quarter {i}: {l}, the sky expected");
        } else {
            assert!(l < 0.01, "quarter {i}: {l}, black expected");
        }
    }
}

#[test]
fn blenders_alpha_clipped_leaf_loads_as_a_cut_out_with_its_holes() {
    // scenes/blender/cut-out-leaves.glb (make_blender_fixtures.py, Blender 5.0): an image's
    // alpha through Math Greater Than 0.5 into Alpha exports as alphaMode MASK; the packed
    // 32×32 image keeps its alpha: exactly the texels of its four round holes are below 0.5.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes/blender/cut-out-leaves.glb");
    let s = scene::load(&path).unwrap();
    assert!(
        s.warnings.iter().all(|w| !w.contains("alpha")),
        "{:?}",
        s.warnings
    );
    let leaf = s.materials.iter().find(|m| m.name == "leaf").unwrap();
    assert_eq!(
        leaf.alpha_mask,
        Some(scene::AlphaMask {
            cutoff: 0.5,
            factor: 1.0,
            blend: false,
        })
    );
    let tex = &leaf.base_color_texture.as_ref().unwrap().texture;
    let holes = tex.alpha.iter().filter(|&&a| a < 0.5).count();
    let expected = (0..32 * 32i32)
        .filter(|i| {
            let (x, y) = (i % 32, i / 32);
            [8, 24].iter().any(|cx| {
                [8, 24]
                    .iter()
                    .any(|cy| (x - cx).pow(2) + (y - cy).pow(2) < 25)
            })
        })
        .count();
    assert_eq!(holes, expected);
}

#[test]
fn a_normal_texture_loads_linear_with_its_scale() {
    // glTF normalTexture: data, not colour, so its bytes are read as they are (the colour
    // textures' sRGB decoding would bend every normal), with its scale; a non-finite scale is an error naming the file.
    let text = textured_quad_gltf("").replace(
        r#""pbrMetallicRoughness":{"baseColorTexture":{"index":0},"metallicFactor":0}"#,
        r#""pbrMetallicRoughness":{"metallicFactor":0},"normalTexture":{"index":0,"scale":0.7}"#,
    );
    assert!(text.contains("normalTexture"));
    let s = scene::load_from_slice(text.as_bytes(), "bumpy.gltf", None).unwrap();
    assert!(
        s.warnings.iter().all(|w| !w.contains("normalTexture")),
        "{:?}",
        s.warnings
    );
    let (tex, scale) = s.materials[0].normal_texture.as_ref().unwrap();
    assert_eq!(*scale, 0.7);
    for (got, c) in tex.texture.texels.iter().zip(TEXELS) {
        let want = c.map(|v| prismap_engine::spectral::color::srgb8(v) as f32 / 255.0);
        assert_eq!(*got, want);
    }
    // KHR_texture_transform on a normal texture (Blender: a Mapping node) moves it too.
    let moved = text.replace(
        r#""scale":0.7}"#,
        r#""scale":0.7,"extensions":{"KHR_texture_transform":{"offset":[0.5,0],"rotation":0.25,"scale":[2,3]}}}"#,
    );
    assert_ne!(moved, text);
    let s = scene::load_from_slice(moved.as_bytes(), "bumpy.gltf", None).unwrap();
    let (tex, _) = s.materials[0].normal_texture.as_ref().unwrap();
    assert_eq!(
        tex.transform,
        prismap_engine::scene::texture::uv_transform([0.5, 0.0], 0.25, [2.0, 3.0])
    );
    // JSON has no NaN; an overflowing number is its nearest way to write a non-finite one.
    let bad = text.replace(r#""scale":0.7"#, r#""scale":1e999"#);
    let e = scene::load_from_slice(bad.as_bytes(), "bumpy.gltf", None)
        .unwrap_err()
        .to_string();
    println!("{e}");
    assert!(e.contains("bumpy.gltf"), "{e}");
}

#[test]
fn blenders_normal_map_gets_the_same_frame_from_its_tangents_and_its_texture_coordinates() {
    // scenes/blender/normal-mapped.glb (make_blender_fixtures.py, Blender 5.0): a Normal
    // Map node exports as normalTexture, here with a TANGENT attribute. The frame prismap
    // builds from the texture coordinates alone (for files without tangents, Blender's
    // default) is, on the plane, ∂p/∂u and −∂p/∂v: perpendicular, in the plane, and the
    // same as the file's tangents.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes/blender/normal-mapped.glb");
    let s = scene::load(&path).unwrap();
    assert!(
        s.warnings.iter().all(|w| !w.contains("normal")),
        "{:?}",
        s.warnings
    );
    assert!(s.materials[0].normal_texture.is_some());
    let ss = prismap_engine::scene::SpectralScene::new(
        &s,
        prismap_engine::spectral::BinGrid::with_bins(4).unwrap(),
    );
    assert_eq!(ss.tangents.len(), s.triangles.len());
    for (i, [t, b]) in ss.tangents.iter().enumerate() {
        let n = ss.tris[i].normal;
        assert!(t.length() > 0.0 && b.length() > 0.0, "triangle {i}");
        for v in [t, b] {
            assert!(
                v.normalize().dot(n).abs() < 1e-5,
                "triangle {i}: {v} off the plane"
            );
        }
        assert!(
            t.normalize().dot(b.normalize()).abs() < 1e-5,
            "triangle {i}"
        );
    }
}

#[test]
fn a_blended_veil_lets_one_minus_alpha_of_the_sky_through() {
    // alphaMode BLEND: a black quad whose texture's alpha is 0.2, 0.4 / 0.6, 0.8 before the
    // default sky (radiance 1) covers that fraction of each point, so each quarter shows
    // 1 − alpha of the sky (stochastic transparency: within noise, 0.03).
    let alpha = [51u8, 102, 153, 204];
    let text = masked_quad_gltf(alpha).replace(r#""alphaMode":"MASK""#, r#""alphaMode":"BLEND""#);
    let s = scene::load_from_slice(text.as_bytes(), "veil.gltf", None).unwrap();
    assert!(s.materials[0].alpha_mask.is_some_and(|m| m.blend));
    let (img, _) = render_32(&s, Storage::Compact, 8, 4, 8);
    let lum = |p: [f32; 3]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
    for (i, a) in alpha.iter().enumerate() {
        // The mean over the quarter's inner 12 × 12 pixels.
        let (x0, y0) = (2 + 16 * (i as u32 % 2), 2 + 16 * (i as u32 / 2));
        let mut sum = 0.0;
        for y in y0..y0 + 12 {
            for x in x0..x0 + 12 {
                sum += lum(img.get(x, y));
            }
        }
        let mean = sum / 144.0;
        let want = 1.0 - *a as f32 / 255.0;
        println!("quarter {i}: {mean:.4} (1 − alpha = {want:.4})");
        assert!(
            (mean - want).abs() < 0.03,
            "quarter {i}: {mean} against {want}"
        );
    }
}

#[test]
fn material_extensions_prismap_does_not_read_are_named_with_what_the_render_lacks() {
    // Blender writes KHR_materials_specular, _clearcoat, _sheen… in extensionsUsed; each
    // that prismap ignores is named once, with the look it goes without.
    let white = [[255u8; 4]; 6].concat();
    let text = vertex_coloured_quad_gltf((&white, 5121, true, "VEC4"), [1.0; 3], "").replacen(
        r#"{"asset""#,
        r#"{"extensionsUsed":["KHR_materials_clearcoat","KHR_texture_transform","EXT_example_unknown"],"asset""#,
        1,
    );
    let s = scene::load_from_slice(text.as_bytes(), "coat.gltf", None).unwrap();
    let named: Vec<&String> = s
        .warnings
        .iter()
        .filter(|w| w.starts_with("extensionsUsed"))
        .collect();
    assert_eq!(named.len(), 2, "{:?}", s.warnings);
    assert!(named[0].contains("KHR_materials_clearcoat") && named[0].contains("clear lacquer"));
    assert!(named[1].contains("EXT_example_unknown") && named[1].contains("ignored"));
}

#[test]
fn broken_tangents_are_dropped_with_a_warning() {
    // A TANGENT attribute with a NaN: the loader names the primitive and keeps going
    // (normal maps then take their frame from the texture coordinates).
    let mut t = [[1.0f32, 0.0, 0.0, 1.0]; 6];
    t[2][1] = f32::NAN;
    let bytes: Vec<u8> = t.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    let text = vertex_coloured_quad_gltf((&bytes, 5126, false, "VEC4"), [1.0; 3], "")
        .replace(r#""COLOR_0":1"#, r#""TANGENT":1"#);
    let s = scene::load_from_slice(text.as_bytes(), "bent.gltf", None).unwrap();
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("meshes[0].primitives[0]") && w.contains("TANGENT ignored")),
        "{:?}",
        s.warnings
    );
    assert!(s.triangle_tangents.is_empty());
    // The same tangents without the NaN are kept, one per corner.
    t[2][1] = 0.0;
    let bytes: Vec<u8> = t.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    let text = vertex_coloured_quad_gltf((&bytes, 5126, false, "VEC4"), [1.0; 3], "")
        .replace(r#""COLOR_0":1"#, r#""TANGENT":1"#);
    let s = scene::load_from_slice(text.as_bytes(), "bent.gltf", None).unwrap();
    assert_eq!(s.triangle_tangents.len(), 2);
    assert!(
        s.warnings.iter().all(|w| !w.contains("TANGENT")),
        "{:?}",
        s.warnings
    );
}
