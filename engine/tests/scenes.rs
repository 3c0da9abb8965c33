//! The shipped scenes load as specified, and broken scene files give clear errors.

use std::path::PathBuf;

use glam::Vec3;
use prismap_engine::scene::{self, MaterialKind, SceneError};
use prismap_engine::spectral::Spectrum;

fn root() -> PathBuf {
    // The workspace root: scenes/ and tests/fuzz/ live there, beside engine/.
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn cornell_box_matches_the_reference_numbers_exactly() {
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(root().join("scenes/cornell_box.json")).unwrap(),
    )
    .unwrap();
    let scene = scene::load(&root().join("scenes/cornell-box.gltf")).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let v = |a: &serde_json::Value| {
        Vec3::new(
            a[0].as_f64().unwrap() as f32,
            a[1].as_f64().unwrap() as f32,
            a[2].as_f64().unwrap() as f32,
        )
    };
    // Every quad (p, a, b) is two triangles (p, p+a, p+a+b), (p, p+a+b, p+b).
    let mut quads: Vec<(Vec3, Vec3, Vec3, String)> = json["quads"]
        .as_array()
        .unwrap()
        .iter()
        .map(|q| {
            (
                v(&q["p"]),
                v(&q["a"]),
                v(&q["b"]),
                q["material"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    let l = &json["light"];
    quads.push((v(&l["p"]), v(&l["a"]), v(&l["b"]), "light".into()));
    assert_eq!(scene.triangles.len(), 2 * quads.len());
    for (i, (p, a, b, mat)) in quads.iter().enumerate() {
        let t0 = scene.triangles[2 * i];
        let want = [*p, *p + *a, *p + *a + *b];
        for k in 0..3 {
            assert!(
                (t0[k] - want[k]).abs().max_element() < 1e-3,
                "quad {i}: {t0:?} vs {want:?}"
            );
        }
        let m = &scene.materials[scene.triangle_material[2 * i] as usize];
        assert_eq!(&m.name, mat);
        if mat != "light" {
            let rgb: Vec<f64> = json["materials"][mat]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            let MaterialKind::Diffuse {
                reflectance: Spectrum::Reflectance(got),
            } = &m.kind
            else {
                panic!("{mat} is diffuse")
            };
            let got = got.rgb;
            for c in 0..3 {
                assert!((got[c] - rgb[c]).abs() < 1e-6, "{mat}: {got:?} vs {rgb:?}");
            }
        }
    }
    // The light: RGB radiance (17, 12, 4), emitting downwards.
    let light = scene.materials.iter().find(|m| m.name == "light").unwrap();
    let Some(Spectrum::Illuminant(c)) = &light.emission else {
        panic!("light emission")
    };
    let rgb = c.rgb;
    for (g, w) in rgb.iter().zip([17.0, 12.0, 4.0]) {
        assert!((g - w).abs() < 1e-4, "{rgb:?}");
    }
    // Camera: at (278, 273, −800) looking along +z, 39.3077° field of view (square image).
    let c = scene.camera;
    assert!((c.position - Vec3::new(278.0, 273.0, -800.0)).length() < 1e-3);
    assert!((c.forward - Vec3::Z).length() < 1e-5);
    assert!((c.up - Vec3::Y).length() < 1e-5);
    assert!(
        (c.right - -Vec3::X).length() < 1e-5,
        "world +x is image left"
    );
    assert!((c.yfov.to_degrees() - 39.3077).abs() < 1e-3);
}

#[test]
fn blackbody_box_has_the_same_luminance_as_the_rgb_box() {
    let rgb = scene::load_builtin("cornell-box").unwrap();
    let bb = scene::load_builtin("cornell-blackbody").unwrap();
    let emission = |s: &scene::Scene| s.materials.iter().find_map(|m| m.emission.clone()).unwrap();
    let (a, b) = (emission(&rgb), emission(&bb));
    assert!(
        matches!(b, Spectrum::Blackbody { kelvin, .. } if kelvin == 3000.0),
        "{b:?}"
    );
    let (ya, yb) = (a.luminance(), b.luminance());
    assert!((ya - yb).abs() < 1e-3 * ya, "{ya} vs {yb}");
}

#[test]
fn prism_is_dispersive_real_glass_lit_by_a_small_spot() {
    let s = scene::load_builtin("prism").unwrap();
    let glass = s
        .materials
        .iter()
        .find(|m| matches!(m.kind, MaterialKind::Dielectric { .. }))
        .unwrap();
    let MaterialKind::Dielectric { ior, .. } = &glass.kind else {
        unreachable!()
    };
    assert!(ior.describe().contains("N-SF11"), "{}", ior.describe());
    assert!(ior.is_dispersive());
    assert_eq!(s.lights.len(), 1, "one spot light");
    assert!(matches!(s.lights[0].kind, scene::PunctualKind::Spot { outer, .. } if outer < 0.02));
}

fn error_of(text: &str) -> String {
    match scene::load_from_slice(text.as_bytes(), "test.gltf", None) {
        Ok(_) => panic!("should fail: {text}"),
        Err(e) => e.to_string(),
    }
}

fn cornell_text() -> String {
    std::fs::read_to_string(root().join("scenes/cornell-box.gltf")).unwrap()
}

#[test]
fn broken_files_get_errors_naming_file_element_and_value() {
    // Missing file.
    let e = scene::load(&root().join("scenes/no-such-scene.gltf")).unwrap_err();
    assert!(matches!(e, SceneError::Io { .. }));
    assert!(e.to_string().contains("no-such-scene.gltf"), "{e}");
    // Empty, truncated and garbage input.
    assert!(error_of("").contains("empty"));
    let text = cornell_text();
    let truncated = &text[..text.len() / 2];
    assert!(
        error_of(truncated).starts_with("test.gltf: document"),
        "{}",
        error_of(truncated)
    );
    assert!(error_of("{ not json").starts_with("test.gltf"));
    assert!(
        scene::load_from_slice(b"glTF\x02\x00\x00\x00\xff\xff\xff\xff", "x.glb", None).is_err()
    );
    // An unknown glass names the material, the field and the value.
    let bad = text.replace(
        "\"name\": \"white\",",
        "\"name\": \"white\", \"extensions\": {\"KHR_materials_transmission\": {\"transmissionFactor\": 1}}, \"extras\": {\"prismap\": {\"glass\": \"unobtainium\"}},",
    );
    let e = error_of(&bad);
    assert!(
        e.contains("materials[0]") && e.contains("glass") && e.contains("unobtainium"),
        "{e}"
    );
    // A negative colour.
    let e = error_of(&text.replacen("0.73,", "-0.73,", 1));
    assert!(e.contains("baseColorFactor") && e.contains("-0.73"), "{e}");
    // An unsupported required extension.
    let e = error_of(&text.replacen(
        "\"extensionsUsed\"",
        "\"extensionsRequired\": [\"EXT_unknown\"], \"extensionsUsed\"",
        1,
    ));
    assert!(e.contains("EXT_unknown"), "{e}");
    // No light at all: lit by the default sky, and told so.
    let dark = text.replace("\"emissiveFactor\"", "\"_emissiveFactor\"");
    let s = scene::load_from_slice(dark.as_bytes(), "test.gltf", None).unwrap();
    assert!(s.environment.is_some());
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("no light") && w.contains("sky")),
        "{:?}",
        s.warnings
    );
    // A bad blackbody temperature.
    let bb = std::fs::read_to_string(root().join("scenes/cornell-blackbody.gltf")).unwrap();
    let e = error_of(&bb.replace("\"blackbody_k\": 3000", "\"blackbody_k\": -5"));
    assert!(e.contains("blackbody_k") && e.contains("-5"), "{e}");
    // A misspelt extras field is refused, not ignored.
    let e = error_of(&bb.replace("\"blackbody_k\"", "\"blackbody_kelvin\""));
    assert!(e.contains("blackbody_kelvin"), "{e}");
}

#[test]
fn files_from_other_tools_get_errors_that_say_what_to_do() {
    let dir = std::env::temp_dir().join(format!("prismap-scenes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A .gltf whose .bin is missing names the buffer file and where it was looked for.
    let gltf = r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[]}],"buffers":[{"byteLength":36,"uri":"scene.bin"}]}"#;
    std::fs::write(dir.join("scene.gltf"), gltf).unwrap();
    let e = scene::load(&dir.join("scene.gltf"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("buffers[0]") && e.contains("scene.bin") && e.contains("missing"),
        "{e}"
    );
    // An OBJ file is called one, with what to export instead.
    std::fs::write(
        dir.join("model.obj"),
        "# Blender\nmtllib model.mtl\no Cube\nv 1 1 1\nv 1 -1 1\n",
    )
    .unwrap();
    let e = scene::load(&dir.join("model.obj")).unwrap_err().to_string();
    assert!(
        e.contains("model.obj") && e.contains("OBJ") && e.contains("glTF"),
        "{e}"
    );
    // A missing file is named once (the OS error is not repeated as a source).
    let e = scene::load(&dir.join("nothing.gltf")).unwrap_err();
    assert!(std::error::Error::source(&e).is_none(), "{e}");
    // A misspelt built-in name suggests the right one.
    let e = scene::load_any("cornell").unwrap_err().to_string();
    assert!(
        e.contains("cornell-box") && e.contains("did you mean"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
    let text = cornell_text();
    // Draco-compressed meshes: valid, but not readable here, and how to re-export.
    let e = error_of(&text.replacen(
        "\"extensionsUsed\"",
        "\"extensionsRequired\": [\"KHR_draco_mesh_compression\"], \"extensionsUsed\"",
        1,
    ));
    assert!(
        e.contains("valid glTF")
            && e.contains("KHR_draco_mesh_compression")
            && e.contains("Compression"),
        "{e}"
    );
    // An index of refraction glTF does not allow.
    let glass = text.replacen(
        "\"name\": \"white\",",
        "\"name\": \"white\", \"extensions\": {\"KHR_materials_ior\": {\"ior\": -1.5}},",
        1,
    );
    let e = error_of(&glass);
    assert!(
        e.contains("materials[0]") && e.contains("ior") && e.contains("-1.5"),
        "{e}"
    );
}

#[test]
fn out_of_range_indices_and_non_finite_positions_are_rejected() {
    use base64::Engine as _;
    // One triangle, positions given in a data URI; indices reference vertex 7 of 3.
    let doc = |positions: [f32; 9], indices: [u16; 3]| {
        let mut bytes = Vec::new();
        for p in positions {
            bytes.extend_from_slice(&p.to_le_bytes());
        }
        for i in indices {
            bytes.extend_from_slice(&i.to_le_bytes());
        }
        bytes.extend_from_slice(&[0, 0]);
        let b64 = base64::engine::general_purpose::STANDARD.encode(&bytes);
        format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
            "nodes":[{{"mesh":0}}],
            "materials":[{{"emissiveFactor":[1,1,1]}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1,"material":0}}]}}],
            "buffers":[{{"byteLength":{len},"uri":"data:application/octet-stream;base64,{b64}"}}],
            "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}},{{"buffer":0,"byteOffset":36,"byteLength":6}}],
            "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
                         {{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}}]}}"#,
            len = bytes.len()
        )
    };
    let good = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    assert!(scene::load_from_slice(doc(good, [0, 1, 2]).as_bytes(), "t.gltf", None).is_ok());
    let e = error_of(&doc(good, [0, 1, 7]));
    assert!(e.contains("indices") && e.contains('7'), "{e}");
    let mut nan = good;
    nan[4] = f32::NAN;
    let e = error_of(&doc(nan, [0, 1, 2]));
    assert!(e.contains("POSITION") && e.contains("NaN"), "{e}");
    // All triangles degenerate: nothing left to render.
    let flat = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0];
    assert!(error_of(&doc(flat, [0, 1, 2])).contains("no triangles"));
}

#[test]
fn external_paths_outside_the_scene_folder_are_refused() {
    let text = r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[]}],"buffers":[{"byteLength":4,"uri":"../../etc/passwd"}]}"#;
    let e = scene::load_from_slice(text.as_bytes(), "t.gltf", Some(&root()))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("buffers[0]") && e.contains("../../etc/passwd"),
        "{e}"
    );
}

#[test]
fn measured_spd_csv_shapes_an_emitter_and_bad_tables_are_named() {
    use prismap_engine::scene::parse_spd_csv;
    // Parsing: header and comment skipped; unsorted, duplicate, negative, short rejected.
    let t = parse_spd_csv("# lamp\nwavelength_nm,value\n400,1\n500,2\n600,0.5\n").unwrap();
    assert_eq!(t.xs(), &[400.0, 500.0, 600.0]);
    assert!(
        parse_spd_csv("400,1\n390,2\n")
            .unwrap_err()
            .contains("increase")
    );
    assert!(
        parse_spd_csv("400,1\n400,2\n")
            .unwrap_err()
            .contains("increase")
    );
    assert!(
        parse_spd_csv("400,1\n500,-2\n")
            .unwrap_err()
            .contains("negative")
    );
    assert!(parse_spd_csv("400,1\n").is_err());
    assert!(
        parse_spd_csv("400,1,3\n500,2,3\n")
            .unwrap_err()
            .contains("columns")
    );
    assert!(
        parse_spd_csv("400,abc\n500,1\n")
            .unwrap_err()
            .contains("abc")
    );
    // Through the loader: the Cornell light with a measured spike-ish lamp.
    let dir = std::env::temp_dir().join(format!("prismap-spd-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("lamp.csv"),
        "wavelength_nm,value\n540,0\n545,10\n550,0\n",
    )
    .unwrap();
    let text = cornell_text().replace(
        "\"name\": \"light\",",
        "\"name\": \"light\", \"extras\": {\"prismap\": {\"emission\": {\"spd_csv\": \"lamp.csv\"}}},",
    );
    std::fs::write(dir.join("lamp.gltf"), &text).unwrap();
    let s = scene::load(&dir.join("lamp.gltf")).unwrap();
    let e = s.materials.iter().find_map(|m| m.emission.clone()).unwrap();
    // Same luminance as the RGB light, all of it near 545 nm.
    let rgb = Spectrum::illuminant([17.0, 12.0, 4.0]).luminance();
    assert!((e.luminance() - rgb).abs() < 1e-6 * rgb);
    assert_eq!(e.eval(600.0), 0.0);
    assert!(e.eval(545.0) > 0.0);
    // A missing CSV names the field and the file.
    std::fs::write(
        dir.join("missing.gltf"),
        text.replace("lamp.csv", "nope.csv"),
    )
    .unwrap();
    let err = scene::load(&dir.join("missing.gltf"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("spd_csv") && err.contains("nope.csv"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn fuzzer_crash_inputs_are_errors_not_panics() {
    // Inputs on which the fuzzer found the `gltf` crate panicking (tests/fuzz/regressions).
    let dir = root().join("tests/fuzz/regressions");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let bytes = std::fs::read(&path).unwrap();
        let result =
            std::panic::catch_unwind(|| scene::load_from_slice(&bytes, "crash.gltf", None));
        let err = result
            .expect("no panic escapes the loader")
            .expect_err("malformed input is an error");
        assert!(err.to_string().starts_with("crash.gltf"), "{err}");
        n += 1;
    }
    assert!(n >= 1);
}

#[test]
fn metallic_roughness_maps_honestly_and_warns_per_material() {
    // Issue #11: what each glTF metallic-roughness combination renders as, and a warning
    // that names the material and the field wherever the model is approximated.
    let text = cornell_text();
    let with = |pbr: &str, ext: &str| {
        let t = text.replacen(
            "\"metallicFactor\": 0.0,\n    \"roughnessFactor\": 1.0",
            pbr,
            1,
        );
        let t = t.replacen(
            "\"name\": \"white\",",
            &format!("\"name\": \"white\",{ext}"),
            1,
        );
        scene::load_from_slice(t.as_bytes(), "test.gltf", None).unwrap()
    };
    let first = |s: &scene::Scene| s.materials[0].kind.clone();
    // A rough metal.
    let s = with("\"metallicFactor\": 1.0, \"roughnessFactor\": 0.4", "");
    assert!(
        matches!(first(&s), MaterialKind::Mirror { roughness, .. } if roughness == 0.4),
        "{:?}",
        first(&s)
    );
    assert!(
        !s.warnings.iter().any(|w| w.contains("'white'")),
        "{:?}",
        s.warnings
    );
    // A partly metallic material is rendered as a pure metal, and told so.
    let s = with("\"metallicFactor\": 0.7, \"roughnessFactor\": 0.4", "");
    assert!(matches!(first(&s), MaterialKind::Mirror { .. }));
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("materials[0] 'white'") && w.contains("metallicFactor 0.7")),
        "{:?}",
        s.warnings
    );
    // A glossy plastic loses its coat: Lambertian, with a warning naming roughnessFactor.
    let s = with("\"metallicFactor\": 0.0, \"roughnessFactor\": 0.1", "");
    assert!(matches!(first(&s), MaterialKind::Diffuse { .. }));
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("'white'") && w.contains("roughnessFactor 0.1")),
        "{:?}",
        s.warnings
    );
    // Rough glass keeps its roughness (it used to be dropped without a word).
    let s = with(
        "\"metallicFactor\": 0.0, \"roughnessFactor\": 0.5",
        " \"extensions\": {\"KHR_materials_transmission\": {\"transmissionFactor\": 1}},",
    );
    assert!(
        matches!(first(&s), MaterialKind::Dielectric { roughness, .. } if roughness == 0.5),
        "{:?}",
        first(&s)
    );
    // Out-of-range factors are errors naming the field and the value.
    let t = text.replacen("\"roughnessFactor\": 1.0", "\"roughnessFactor\": 1.5", 1);
    let e = error_of(&t);
    assert!(
        e.contains("materials[0]") && e.contains("roughnessFactor") && e.contains("1.5"),
        "{e}"
    );
}
