//! Textured LoD models (issue 16, item 3): appearances read from CityGML and CityJSON, carried through
//! `prepare` into `scene.glb`, and rendered by Blender.
//!
//! Fixtures (`tests/fixtures/appearance/`, hand-made, see its README): two boxes in EPSG:7415, "tex"
//! (20 × 20 × 10 m) whose roof carries `quadrants_2x2.png` (red | green over blue | yellow) with
//! coordinates (0, 0) at its south-west corner and (1, 1) at its north-east corner, and "col"
//! (10 × 10 × 6 m) whose roof has the colour magenta; a third texture names an image that does not
//! exist. Expected values are worked out by hand from the files.
//!
//! - readers: per-vertex coordinates follow the cleaned rings, themes are listed in file order and the
//!   default is the first, `theme = …` picks another;
//! - `prepare`: the manifest counts textured/coloured faces and the missing image, the image is copied
//!   next to `scene.glb`, and the mesh, the building table and wgpu's ID masks are identical with
//!   appearances and with `appearance = false` (exact comparison of integer IDs);
//! - Blender (160 × 120, direct lighting, 1 sample): the pixel at the projection of each quadrant's
//!   centre shows that quadrant's colour (dominant channels, see [`classify`]), the coloured roof
//!   shows magenta;
//! - real data: PLATEAU files whose texture images are absent prepare, report every image missing and
//!   keep all buildings; Den Haag's CityJSON materials are read.

use std::path::{Path, PathBuf};

use crate::render_common;
use crate::util::{self, assert_schema, fixture, scratch_with_scenes};

use insgen::camera::{Intrinsics, Pose};
use insgen::lod::{self, FaceAppearance, Geometry, ReadOptions};
use insgen::scene::PreparedScene;

fn fixture_path(name: &str) -> PathBuf {
    fixture("appearance", name)
}

fn read(name: &str, theme: Option<&str>) -> lod::SourceModel {
    let opts = ReadOptions { theme: theme.map(str::to_string), ..ReadOptions::default() };
    lod::read_source(&fixture_path(name), None, &opts).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// The roof (the polygon whose vertices are all at the building's top) and its appearance.
fn roof(model: &lod::SourceModel, id: &str) -> (lod::Polygon, Option<FaceAppearance>) {
    let b = util::building(model, id);
    let Geometry::Polygons(ps) = &b.geometry else { panic!("{id}: polygons expected") };
    let top = ps.iter().flat_map(|p| p.exterior.iter()).map(|p| p[2]).fold(f64::MIN, f64::max);
    let k = ps.iter().position(|p| p.exterior.iter().all(|q| q[2] == top)).expect("a flat roof");
    (ps[k].clone(), b.appearance.get(k).cloned().flatten())
}

/// (u, v) the fixtures give each roof corner: u = (x − x0) / 20 m, v = (y − y0) / 20 m on "tex".
fn expected_uv(p: &[f64; 3]) -> [f64; 2] {
    [((p[0] - 85000.0) / 20.0).round(), ((p[1] - 447000.0) / 20.0).round()]
}

mod readers {
    use super::*;

    #[test]
    fn cityjson_texture_coordinates_follow_the_roof_vertices() {
        let m = read("textured_boxes_epsg_7415.city.json", None);
        assert_eq!(m.appearance.themes, ["rgbTexture", "winter", "colours"]);
        assert_eq!(m.appearance.texture_theme.as_deref(), Some("rgbTexture"));
        assert_eq!(m.appearance.material_theme.as_deref(), Some("colours"));
        assert_eq!((m.appearance.textured_faces, m.appearance.coloured_faces), (2, 1));
        assert_eq!(m.appearance.images.len(), 2);
        assert!(m.appearance.images[0].ends_with("appearance/quadrants_2x2.png"));
        let (poly, app) = roof(&m, "tex");
        let Some(FaceAppearance::Texture { image: 0, uv_exterior, uv_interiors }) = app else {
            panic!("tex roof: {app:?}")
        };
        assert!(uv_interiors.is_empty());
        assert_eq!(uv_exterior.len(), poly.exterior.len());
        for (p, uv) in poly.exterior.iter().zip(&uv_exterior) {
            assert_eq!(*uv, expected_uv(p), "vertex {p:?}");
        }
        assert_eq!(roof(&m, "col").1, Some(FaceAppearance::Colour { rgb: [1.0, 0.0, 1.0] }));
        // Untextured faces carry no appearance; "lost" refers to texture 1 (a missing file: counted by
        // `prepare`, not by the reader).
        let tex = util::building(&m, "tex");
        assert_eq!(tex.appearance.iter().filter(|a| a.is_some()).count(), 1);
        assert!(matches!(roof(&m, "lost").1, Some(FaceAppearance::Texture { image: 1, .. })));
    }

    #[test]
    fn cityjson_theme_option_picks_the_winter_theme() {
        let m = read("textured_boxes_epsg_7415.city.json", Some("winter"));
        assert_eq!(m.appearance.texture_theme.as_deref(), Some("winter"));
        let (poly, app) = roof(&m, "tex");
        let Some(FaceAppearance::Texture { uv_exterior, .. }) = app else { panic!("{app:?}") };
        // The winter theme turns the image by 180°: (u, v) → (1 − u, 1 − v).
        for (p, uv) in poly.exterior.iter().zip(&uv_exterior) {
            let e = expected_uv(p);
            assert_eq!(*uv, [1.0 - e[0], 1.0 - e[1]], "vertex {p:?}");
        }
        // `value: 1` colours every face of "col" grey; "lost" has no winter texture.
        let col = util::building(&m, "col");
        assert_eq!(col.appearance.len(), 6);
        assert!(col.appearance.iter().all(|a| *a == Some(FaceAppearance::Colour { rgb: [0.5, 0.5, 0.5] })));
        assert!(util::building(&m, "lost").appearance.is_empty());
        let none = lod::read_source(
            &fixture_path("textured_boxes_epsg_7415.city.json"),
            None,
            &ReadOptions { no_appearance: true, ..ReadOptions::default() },
        )
        .unwrap();
        assert!(none.buildings.iter().all(|b| b.appearance.is_empty()));
        assert_eq!(none.appearance, lod::ModelAppearance::default());
    }

    #[test]
    fn citygml_parameterized_texture_and_x3d_material() {
        let m = read("textured_boxes_epsg_7415.gml", None);
        assert_eq!(m.appearance.themes, ["rgbTexture", "winter"]);
        assert_eq!(m.appearance.texture_theme.as_deref(), Some("rgbTexture"));
        assert_eq!(m.appearance.material_theme.as_deref(), Some("rgbTexture"));
        assert_eq!((m.appearance.textured_faces, m.appearance.coloured_faces), (2, 1));
        assert_eq!(m.appearance.unusable_targets, 0);
        assert_eq!(m.appearance.images.len(), 2);
        assert!(m.appearance.images[1].ends_with("tex_appearance/absent_wall.jpg"));
        let (poly, app) = roof(&m, "tex");
        let Some(FaceAppearance::Texture { image: 0, uv_exterior, .. }) = app else { panic!("{app:?}") };
        // The ring's closing vertex (and its fifth coordinate pair) are gone; the four corners keep theirs.
        assert_eq!(poly.exterior.len(), 4);
        for (p, uv) in poly.exterior.iter().zip(&uv_exterior) {
            assert_eq!(*uv, expected_uv(p), "vertex {p:?}");
        }
        assert_eq!(roof(&m, "col").1, Some(FaceAppearance::Colour { rgb: [1.0, 0.0, 1.0] }));
    }

    #[test]
    fn citygml_theme_option_picks_materials_of_that_theme_only() {
        let m = read("textured_boxes_epsg_7415.gml", Some("winter"));
        assert_eq!(m.appearance.textured_faces, 0);
        assert_eq!(m.appearance.coloured_faces, 2);
        assert_eq!(roof(&m, "tex").1, Some(FaceAppearance::Colour { rgb: [0.9, 0.9, 0.9] }));
        let m = read("textured_boxes_epsg_7415.gml", Some("no such theme"));
        assert!(m.buildings.iter().all(|b| b.appearance.is_empty()));
        // `materials = false`: the textures stay, the colours go.
        for name in ["textured_boxes_epsg_7415.gml", "textured_boxes_epsg_7415.city.json"] {
            let opts = ReadOptions { no_materials: true, ..ReadOptions::default() };
            let m = lod::read_source(&fixture_path(name), None, &opts).unwrap();
            assert_eq!((m.appearance.textured_faces, m.appearance.coloured_faces), (2, 0), "{name}");
            assert_eq!(roof(&m, "col").1, None, "{name}");
        }
    }
}

/// A scene file for one fixture (constant geoid: the test needs no grid), optionally without
/// appearances or with a theme.
fn scene_toml(source: &Path, extra: &str) -> String {
    format!(
        "name = \"tex\"\nsplit = \"train\"\n\n[[sources]]\npath = \"{}\"\n{extra}\n\n[geoid]\nmodel = \"constant\"\n\
         undulation_m = 0.0\n",
        source.display()
    )
}

fn prepare(dir: &Path, source: &Path, extra: &str) -> (PathBuf, PreparedScene) {
    let scenes = scratch_with_scenes(&[("tex", scene_toml(source, extra))]);
    let out = dir.join("scene");
    insgen::scene::prepare::prepare(&scenes.path().join("scenes/tex.toml"), &out, &insgen::util::NoProgress)
        .unwrap_or_else(|e| panic!("prepare {}: {}", source.display(), util::error_chain(&e)));
    let scene = PreparedScene::load(&out).unwrap();
    (out, scene)
}

mod prepared {
    use super::*;

    #[test]
    fn manifest_counts_textures_and_the_missing_image() {
        let dir = tempfile::tempdir().unwrap();
        let (out, scene) = prepare(dir.path(), &fixture_path("textured_boxes_epsg_7415.city.json"), "");
        let a = scene.manifest.sources[0].appearance.as_ref().expect("appearance recorded");
        assert_eq!(a.texture_theme.as_deref(), Some("rgbTexture"));
        assert_eq!((a.textured_faces, a.coloured_faces, a.images, a.missing_images), (2, 1, 2, 1));
        assert!(a.missing_examples[0].contains("missing_facade.png (missing)"), "{:?}", a.missing_examples);
        let manifest: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("manifest.json")).unwrap()).unwrap();
        assert_schema("manifest.schema.json", &manifest);
        // The image is copied next to the GLB, which names it.
        let copied = out.join("textures/0001_quadrants_2x2.png");
        assert_eq!(
            std::fs::read(&copied).unwrap(),
            std::fs::read(fixture_path("quadrants_2x2.png")).unwrap()
        );
        let glb = std::fs::read(out.join("scene.glb")).unwrap();
        let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
        let doc: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
        assert_eq!(
            doc["asset"]["extras"]["appearance_materials"],
            serde_json::json!([{"texture": "textures/0001_quadrants_2x2.png"}, {"colour": [1.0, 0.0, 1.0]}])
        );
        assert_eq!(doc["images"][0]["uri"], "textures/0001_quadrants_2x2.png");
        let attrs = &doc["meshes"][0]["primitives"][0]["attributes"];
        assert!(attrs.get("TEXCOORD_0").is_some() && attrs.get("_APPEARANCE").is_some(), "{attrs}");
        // `export-tiles` takes the images along.
        let tiles = dir.path().join("tiles");
        insgen::export::tiles::write_scene_tileset(&out, &tiles).unwrap();
        assert!(tiles.join("textures/0001_quadrants_2x2.png").is_file());
        // Same inputs → same bytes.
        let dir2 = tempfile::tempdir().unwrap();
        let (out2, _) = prepare(dir2.path(), &fixture_path("textured_boxes_epsg_7415.city.json"), "");
        assert!(util::tree(&out) == util::tree(&out2), "a second prepare wrote different files");
    }

    /// The Khronos validator accepts the textured GLB (images resolved next to it): no errors, no
    /// warnings (infos only: unsupported EXT_ extensions, URIs in a GLB, the appearance materials that
    /// no primitive references).
    #[test]
    fn khronos_validator_accepts_the_textured_scene() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let have_node =
            std::process::Command::new("node").arg("--version").output().is_ok_and(|o| o.status.success());
        if !have_node || !root.join("node_modules/gltf-validator").exists() {
            assert!(!util::under_ci(), "CI: node or node_modules/gltf-validator is missing (run `npm ci`)");
            eprintln!("skipping: node or node_modules/gltf-validator is missing (run `npm ci`)");
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let (out, _) = prepare(dir.path(), &fixture_path("textured_boxes_epsg_7415.city.json"), "");
        let run = std::process::Command::new("node")
            .arg(root.join("scripts/validate_gltf.js"))
            .arg(out.join("scene.glb"))
            .output()
            .unwrap();
        assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
        let report: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
        let issues = &report["issues"];
        assert_eq!(
            (issues["numErrors"].as_u64(), issues["numWarnings"].as_u64()),
            (Some(0), Some(0)),
            "{issues:#}"
        );
    }

    /// Appearances change no building, triangle or mask: the scene prepared with them and with
    /// `appearance = false` has the same mesh and building table, and wgpu's ID renders of three views
    /// are identical pixel for pixel.
    #[test]
    fn id_masks_are_identical_with_and_without_appearances() {
        for name in ["textured_boxes_epsg_7415.city.json", "textured_boxes_epsg_7415.gml"] {
            let (d1, d2) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
            let (out1, with) = prepare(d1.path(), &fixture_path(name), "");
            let (out2, without) = prepare(d2.path(), &fixture_path(name), "appearance = false");
            assert!(with.manifest.sources[0].appearance.is_some());
            assert!(without.manifest.sources[0].appearance.is_none());
            assert!(!out2.join("textures").exists());
            assert_eq!(with.mesh, without.mesh, "{name}: meshes differ");
            assert_eq!(
                std::fs::read(out1.join("buildings.json")).unwrap(),
                std::fs::read(out2.join("buildings.json")).unwrap()
            );
            let r = render_common::renderer();
            let k = Intrinsics::from_hfov(160, 120, 60.0);
            let views: Vec<insgen::render::View> = [
                Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 80.0]),
                Pose::from_ypr_deg(30.0, 45.0, 0.0, [-40.0, -50.0, 60.0]),
                Pose::from_ypr_deg(200.0, 60.0, 3.0, [50.0, 40.0, 40.0]),
            ]
            .into_iter()
            .map(|pose| insgen::render::View { intrinsics: k, pose })
            .collect();
            let opts = insgen::render::RenderOptions::default();
            let a = r.render_batch(&r.upload(&with.mesh).unwrap(), &views, &opts).unwrap();
            let b = r.render_batch(&r.upload(&without.mesh).unwrap(), &views, &opts).unwrap();
            for (i, (x, y)) in a.iter().zip(&b).enumerate() {
                assert!(x.ids.raw().iter().any(|&v| v != 0), "{name} view {i} sees no building");
                assert!(x.ids.raw() == y.ids.raw(), "{name} view {i}: ID masks differ");
            }
        }
    }
}

/// Which reference colour a rendered pixel shows, by its dominant channels (a lit colour keeps its hue:
/// the sun and the sky ambient scale the channels by similar factors): a channel counts when it is
/// above 45 % of the brightest and the others are below 45 %.
fn classify(px: [u8; 3]) -> &'static str {
    let max = *px.iter().max().unwrap() as f64;
    if max < 30.0 {
        return "dark";
    }
    let on = px.map(|c| c as f64 > 0.45 * max);
    match on {
        [true, false, false] => "red",
        [false, true, false] => "green",
        [false, false, true] => "blue",
        [true, true, false] => "yellow",
        [true, false, true] => "magenta",
        _ => "other",
    }
}

mod blender {
    use super::*;
    use crate::blender_support::{blender_python, read_rgb_png};
    use insgen::blender::{render_frames, Engine, FrameRequest, Launcher, Mode, RenderPlan, SceneSource};
    use insgen::util::NoProgress;

    fn plan(python: &Path, dir: &Path, glb: PathBuf, ground_enu_m: f64) -> RenderPlan {
        RenderPlan {
            launcher: Launcher::Python { interpreter: python.to_path_buf() },
            mode: Mode::Rgb,
            engine: Engine::Cycles,
            rgb: insgen::blender::job::RgbSettings {
                samples: 1,
                denoise: false,
                denoise_quality: insgen::blender::job::DenoiseQuality::Fast,
                max_bounces: 0,
                lighting: insgen::blender::job::Lighting::Direct,
            },
            seed: 1,
            device: insgen::blender::job::Device::Cpu,
            threads: 2,
            exr: false,
            source: SceneSource::Lod { glb, enu_from_gltf: insgen::blender::tileset::ENU_FROM_SCENE_GLTF },
            look_seed: 3,
            // The colour test needs the exact texture colours: no weather, no camera effects.
            look: insgen::blender::look::LookRanges::plain(35.0),
            ground_enu_m,
            out_dir: dir.join("out"),
            work_dir: dir.join("work"),
            restart_every: 50,
            force: false,
            clip_start_m: 0.5,
            clip_end_m: 10_000.0,
            report_bounds: false,
            clutter_occluders: None,
            contrast: None,
        }
    }

    /// Renders the prepared fixture from 80 m above the centre, looking down, and checks the colour at
    /// the projection of each roof quadrant's centre and of the coloured roof's centre.
    fn check_colours(source: &str) {
        let Some(py) = blender_python() else { return };
        let dir = tempfile::tempdir().unwrap();
        let (out, scene) = prepare(dir.path(), &fixture_path(source), "");
        let p = plan(&py, dir.path(), out.join("scene.glb"), scene.manifest.ground_enu_m);
        let k = Intrinsics::from_hfov(160, 120, 60.0);
        let pose = Pose::from_ypr_deg(10.0, 0.0, 0.0, [0.0, 0.0, 80.0]);
        let frame = FrameRequest { name: "nadir".into(), intrinsics: k, pose };
        render_frames(&p, std::slice::from_ref(&frame), &NoProgress).unwrap();
        let (w, _h, rgb) = read_rgb_png(&p.out_dir.join("nadir.png"));
        let bbox = |id: &str| {
            let b = scene.buildings.iter().find(|b| b.source_id == id).unwrap();
            (b.bbox_min_enu_m, b.bbox_max_enu_m)
        };
        let sample = |e: f64, n: f64, up: f64| -> [u8; 3] {
            let px = k.project(pose.world_to_cam([e, n, up].into())).expect("in front of the camera");
            let (x, y) = (px[0].floor() as usize, px[1].floor() as usize);
            let i = 3 * (y * w as usize + x);
            [rgb[i], rgb[i + 1], rgb[i + 2]]
        };
        // The roof quadrants' centres at 1/4 and 3/4 of the box (EPSG:7415's grid is within 2° of ENU
        // here: 0.3 m off at most, inside the 10 m quadrants).
        let (lo, hi) = bbox("tex");
        let at = |fx: f64, fy: f64| sample(lo[0] + fx * (hi[0] - lo[0]), lo[1] + fy * (hi[1] - lo[1]), hi[2]);
        let got = [
            ("north-west", at(0.25, 0.75), "red"),
            ("north-east", at(0.75, 0.75), "green"),
            ("south-west", at(0.25, 0.25), "blue"),
            ("south-east", at(0.75, 0.25), "yellow"),
        ];
        let (lo, hi) = bbox("col");
        let col = sample(0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2]);
        for (where_, px, want) in got.iter().chain([("coloured roof", col, "magenta")].iter()) {
            eprintln!("{source}: {where_}: {px:?} → {}", classify(*px));
            assert_eq!(classify(*px), *want, "{source}: {where_} shows {px:?}");
        }
    }

    #[test]
    fn cityjson_texture_and_material_appear_in_the_blender_frame() {
        check_colours("textured_boxes_epsg_7415.city.json");
    }

    #[test]
    fn citygml_texture_and_material_appear_in_the_blender_frame() {
        check_colours("textured_boxes_epsg_7415.gml");
    }
}

mod real_data {
    use super::*;

    /// PLATEAU files reference textures that are not shipped: prepare succeeds, every building is kept,
    /// and every image is counted as missing (the faces keep the procedural look).
    #[test]
    fn plateau_textures_are_absent_counted_and_not_fatal() {
        for rel in [
            "jp_tokyo_plateau_citygml_fixtures/53392642_bldg_6697_op2.unity-sdk.gml",
            "jp_misc_plateau/52397519_bldg_6697_op.gml",
        ] {
            let Some(src) = util::shared_data(rel) else { continue };
            let model = lod::read_source(&src, None, &ReadOptions::default()).unwrap();
            assert!(model.appearance.textured_faces > 0, "{rel}: no textured face read");
            assert_eq!(model.appearance.texture_theme.as_deref(), Some("rgbTexture"));
            let dir = tempfile::tempdir().unwrap();
            let (out, scene) = prepare(dir.path(), &src, "");
            let a = scene.manifest.sources[0].appearance.as_ref().expect("appearance recorded");
            eprintln!(
                "{rel}: {} buildings, {} textured faces, {} of {} images missing, {} unusable targets",
                scene.manifest.buildings, a.textured_faces, a.missing_images, a.images, a.unusable_targets
            );
            assert!(a.images > 0 && a.missing_images == a.images, "{rel}: {a:?}");
            assert_eq!(scene.manifest.buildings, model.buildings.len() as u64);
            // Nothing to texture: the GLB is the one written without appearances.
            assert!(!out.join("textures").exists());
        }
    }

    #[test]
    fn den_haag_materials_are_read() {
        let Some(src) = util::shared_data("nl_denhaag_lod2/DenHaag_01.city.json") else { return };
        let model = lod::read_source(&src, None, &ReadOptions::default()).unwrap();
        eprintln!(
            "Den Haag: themes {:?}, {} coloured faces",
            model.appearance.themes, model.appearance.coloured_faces
        );
        assert_eq!(model.appearance.material_theme.as_deref(), Some(""));
        assert!(model.appearance.coloured_faces > 1000, "{:?}", model.appearance);
    }
}
