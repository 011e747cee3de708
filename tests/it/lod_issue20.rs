//! Issue 20: readers that say what is really wrong. Each test is one case of the issue, on a hand-made
//! fixture (tests/fixtures/{citygml,cityjson}/README.md) or a few bytes written here; expected counts
//! are worked out by hand from the fixtures.

use std::path::PathBuf;

use insgen::lod::{citygml, cityjson, read_source, ReadOptions};

use crate::util::{insgen, read_error, repo, stderr, stdout};

fn fx(dir: &str, name: &str) -> PathBuf {
    crate::util::fixture(dir, name)
}

fn scratch_file(name: &str, bytes: &[u8]) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join(name);
    std::fs::write(&p, bytes).unwrap();
    (dir, p)
}

/// 256 bytes of a fixed pseudo-random sequence (an LCG), as a corrupt download would be.
fn random_bytes() -> Vec<u8> {
    let mut x = 20u32;
    (0..256)
        .map(|_| {
            x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (x >> 24) as u8
        })
        .collect()
}

mod wrong_format {
    use super::*;

    #[test]
    fn random_bytes_as_citygml_are_not_xml() {
        let (_d, p) = scratch_file("city.gml", &random_bytes());
        let e = read_error(read_source(&p, None, &ReadOptions::default()));
        assert!(e.contains("not XML") && e.contains("no CityModel element"), "{e}");
        assert!(!e.contains("no buildings with geometry"), "{e}");
    }

    #[test]
    fn another_xml_root_is_no_city_model() {
        let e = read_error(citygml::read(&fx("citygml", "not_citygml_root.gml"), &ReadOptions::default()));
        assert!(e.contains("root element <kml>") && e.contains("no CityModel element"), "{e}");
    }

    #[test]
    fn cityjson_named_gml_says_json() {
        let json = std::fs::read(fx("cityjson", "cube_epsg_7415.city.json")).unwrap();
        let (_d, p) = scratch_file("city.gml", &json);
        let e = read_error(read_source(&p, None, &ReadOptions::default()));
        assert!(e.contains("not XML: the file holds JSON (CityJSON"), "{e}");
    }

    #[test]
    fn citygml_named_json_says_xml() {
        let xml = std::fs::read(fx("citygml", "bad_degenerate_ring.gml")).unwrap();
        let (_d, p) = scratch_file("city.json", &xml);
        let e = read_error(read_source(&p, None, &ReadOptions::default()));
        assert!(e.contains("not JSON: the file holds XML (CityGML?"), "{e}");
        let (_d, p) = scratch_file("city.json", &random_bytes());
        let e = read_error(cityjson::read(&p, &ReadOptions::default()));
        assert!(e.contains("not JSON: the file holds binary data"), "{e}");
        let (_d, p) = scratch_file("empty.json", b"");
        let e = read_error(cityjson::read(&p, &ReadOptions::default()));
        assert!(e.contains("not JSON: the file is empty"), "{e}");
    }
}

mod unusable_coordinates {
    use super::*;

    #[test]
    fn cityjson_1e300_used_only_by_a_road_is_counted_and_warned() {
        let p = fx("cityjson", "road_1e300_unused.city.json");
        let m = cityjson::read(&p, &ReadOptions::default()).unwrap();
        assert_eq!(m.buildings.len(), 1);
        assert_eq!(m.stats.bad_coordinates_unused, 1, "vertex 5 only");
        let out = insgen(&repo(), &["inspect", p.to_str().unwrap()]);
        assert!(out.status.success(), "{}", stderr(&out));
        let err = stderr(&out);
        assert!(
            err.contains("1 vertex coordinate(s) are not finite or beyond ±1e9 (first: vertices[5] = [1e297, 447000, 0])"),
            "{err}"
        );
        assert!(
            stdout(&out).contains("\nunused:     1 bad coordinate(s) outside any building (ignored)\n"),
            "{}",
            stdout(&out)
        );
    }

    #[test]
    fn citygml_nan_and_1e300_in_a_road_are_counted_and_warned() {
        let p = fx("citygml", "road_nan_coordinate.gml");
        let m = citygml::read(&p, &ReadOptions::default()).unwrap();
        assert_eq!(m.buildings.len(), 1);
        assert_eq!(m.stats.bad_coordinates_unused, 2, "NaN and 1e300");
        let out = insgen(&repo(), &["inspect", p.to_str().unwrap()]);
        assert!(out.status.success(), "{}", stderr(&out));
        assert!(stderr(&out).contains("2 coordinate value(s) outside any building"), "{}", stderr(&out));
    }
}

mod lod0 {
    use super::*;

    #[test]
    fn citygml_footprint_is_read_when_nothing_better_exists() {
        let m = citygml::read(&fx("citygml", "lod0_footprints.gml"), &ReadOptions::default()).unwrap();
        let b = crate::util::building(&m, "footprint_only");
        assert_eq!(b.lod, "0");
        assert_eq!(crate::util::polygons(b).len(), 1);
        let b = crate::util::building(&m, "lod1_with_degenerate_footprint");
        assert_eq!(b.lod, "1");
        assert_eq!(m.stats.degenerate_faces, 0);
        assert_eq!(m.stats.degenerate_faces_unused, 1, "the LoD0 footprint with 2 distinct points");
        // Forced.
        let opts = ReadOptions { lod: Some("0".into()), ..Default::default() };
        let m = citygml::read(&fx("citygml", "lod0_footprints.gml"), &opts).unwrap();
        assert_eq!(m.buildings.len(), 1, "the degenerate footprint leaves the second building empty");
        assert_eq!(m.stats.degenerate_faces, 1);
    }

    #[test]
    fn cityjson_lod0_is_read_when_nothing_better_exists() {
        let m = cityjson::read(&fx("cityjson", "lod0_only.city.json"), &ReadOptions::default()).unwrap();
        assert_eq!(crate::util::building(&m, "footprint_only").lod, "0");
        assert_eq!(crate::util::building(&m, "lod1_and_bad_lod0").lod, "1.2");
        assert_eq!(m.stats.degenerate_faces_unused, 1);
    }
}

mod inspect {
    use super::*;

    #[test]
    fn unknown_epsg_fails_like_prepare() {
        let p = fx("cityjson", "cube_unknown_epsg_999999.city.json");
        let out = insgen(&repo(), &["inspect", p.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(1), "{}", stdout(&out));
        let err = stderr(&out);
        assert!(err.contains("EPSG/0/999999") && err.contains("cube_unknown_epsg_999999.city.json"), "{err}");
    }

    #[test]
    fn known_crs_is_described_and_triangles_counted() {
        let p = fx("cityjson", "cube_epsg_7415.city.json");
        let out = insgen(&repo(), &["inspect", p.to_str().unwrap()]);
        assert!(out.status.success(), "{}", stderr(&out));
        let text = stdout(&out);
        // 6 quads, 2 triangles each (V + 2H − 2 = 4 − 2).
        assert!(text.contains("triangles:  12\n"), "{text}");
        assert!(text.contains("EPSG:7415") && text.contains("orthometric heights"), "{text}");
    }

    #[test]
    fn closed_pipe_is_not_a_panic() {
        use std::io::Read;
        use std::process::{Command, Stdio};
        let p = fx("cityjson", "transform_parts.city.json");
        let mut child = Command::new(env!("CARGO_BIN_EXE_insgen"))
            .args(["inspect", p.to_str().unwrap()])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take()); // the reader goes away, like `| head -0`
        let mut err = String::new();
        child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
        let status = child.wait().unwrap();
        assert!(status.success() && !err.contains("panicked"), "{status:?}: {err}");
    }
}

mod relative_heights {
    use super::*;

    fn scene(extra: &str) -> String {
        let src = fx("cityjson", "relative_heights_terrain.city.json");
        format!(
            "name = \"rel\"\n\n[[sources]]\npath = \"{}\"\n{extra}\n\n[geoid]\nmodel = \"constant\"\nundulation_m = 0.0\n\n\
             [origin]\nlat_deg = 52.0\nlon_deg = 4.36\nh_m = 0.0\n",
            src.display()
        )
    }

    fn prepare(extra: &str) -> (std::process::Output, Option<serde_json::Value>, Option<serde_json::Value>) {
        let dir = crate::util::scratch_with_scenes(&[("rel", scene(extra))]);
        let out = insgen(dir.path(), &["--workdir", "runs", "prepare", "--area", "rel"]);
        let read = |f: &str| {
            std::fs::read(dir.path().join("runs/rel/scene").join(f))
                .ok()
                .map(|b| serde_json::from_slice(&b).unwrap())
        };
        (out, read("manifest.json"), read("buildings.json"))
    }

    fn min_up_m(buildings: &serde_json::Value, id: &str) -> f64 {
        let b = buildings.as_array().unwrap().iter().find(|b| b["source_id"] == id).unwrap();
        b["bbox_min_enu_m"][2].as_f64().unwrap()
    }

    #[test]
    fn detected_and_reported_by_the_reader_and_inspect() {
        let p = fx("cityjson", "relative_heights_terrain.city.json");
        let m = cityjson::read(&p, &ReadOptions::default()).unwrap();
        assert_eq!(crate::util::building(&m, "a").ground_heights_m, vec![("TerrainHeight".to_string(), 2.4)]);
        assert_eq!(crate::util::building(&m, "b").ground_heights_m, vec![("TerrainHeight".to_string(), 3.1)]);
        let r = insgen::lod::relative_heights(&m).unwrap();
        assert_eq!((r.buildings, r.with_ground_attribute, r.attribute.as_str()), (2, 2, "TerrainHeight"));
        let out = insgen(&repo(), &["inspect", p.to_str().unwrap()]);
        let text = stdout(&out);
        assert!(
            text.contains(
                "heights:    2 of 2 buildings start at z ≈ 0 m although their TerrainHeight is not 0"
            ),
            "{text}"
        );
        // Absolute models are not flagged.
        let m = cityjson::read(&fx("cityjson", "cube_epsg_7415.city.json"), &ReadOptions::default()).unwrap();
        assert_eq!(insgen::lod::relative_heights(&m), None);
    }

    #[test]
    fn prepare_warns_and_above_ground_adds_the_attribute() {
        let (out, manifest, plain) = prepare("");
        assert!(out.status.success(), "{}", stderr(&out));
        assert!(
            stderr(&out).contains("set heights = \"above_ground\" and ground_attribute = \"TerrainHeight\""),
            "{}",
            stderr(&out)
        );
        assert!(manifest.unwrap()["sources"][0].get("heights").is_none());
        let plain = plain.unwrap();

        let (out, manifest, lifted) =
            prepare("heights = \"above_ground\"\nground_attribute = \"TerrainHeight\"");
        assert!(out.status.success(), "{}", stderr(&out));
        assert!(!stderr(&out).contains("look relative"), "{}", stderr(&out));
        let manifest = manifest.unwrap();
        assert_eq!(
            manifest["sources"][0]["heights"],
            "above_ground: + TerrainHeight per building (2 buildings)"
        );
        crate::util::assert_schema("manifest.schema.json", &manifest);
        let lifted = lifted.unwrap();
        // The same place, the ground added: 2.4 m and 3.1 m higher (1 mm: ENU up vs ellipsoidal height
        // over 1 km).
        for (id, lift_m) in [("a", 2.4), ("b", 3.1)] {
            let d = min_up_m(&lifted, id) - min_up_m(&plain, id);
            assert!((d - lift_m).abs() < 1e-3, "{id}: lifted by {d} m, expected {lift_m} m");
        }

        let (out, manifest, lifted) = prepare("heights = \"above_ground\"\nground_height_m = 1.5");
        assert!(out.status.success(), "{}", stderr(&out));
        assert_eq!(manifest.unwrap()["sources"][0]["heights"], "above_ground: + 1.5 m");
        let d = min_up_m(&lifted.unwrap(), "a") - min_up_m(&plain, "a");
        assert!((d - 1.5).abs() < 1e-3, "{d}");
    }

    #[test]
    fn ground_settings_without_above_ground_are_refused() {
        let (out, _, _) = prepare("ground_attribute = \"TerrainHeight\"");
        assert_eq!(out.status.code(), Some(1));
        assert!(stderr(&out).contains("need heights = \"above_ground\""), "{}", stderr(&out));
    }
}
