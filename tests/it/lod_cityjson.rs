//! CityJSON / CityJSONSeq reader: hand-made fixtures (tests/fixtures/cityjson/, expected values
//! worked out by hand) and the real Dutch files in ../shared/data (expected values from an
//! independent `serde_json::Value` walk written in this test).

use std::path::{Path, PathBuf};

use insgen::lod::{cityjson, read_source, AxisConvention, Frame, LodError, ReadOptions, SourceModel};
use serde_json::Value;

use crate::util::{building, polygons as polys, read_error as err_text, shared_data};

fn fixture(name: &str) -> PathBuf {
    crate::util::fixture("cityjson", name)
}

fn read(path: &Path, lod: Option<&str>) -> Result<SourceModel, LodError> {
    cityjson::read(path, &ReadOptions { lod: lod.map(str::to_string), ..ReadOptions::default() })
}

/// Asserts two coordinates agree within 1e-9 m (quantised × 0.01 + translate in f64).
fn assert_close(a: [f64; 3], b: [f64; 3]) {
    assert!((0..3).all(|i| (a[i] - b[i]).abs() < 1e-9), "{a:?} != {b:?}");
}

fn assert_ring_close(a: &[[f64; 3]], b: &[[f64; 3]]) {
    assert_eq!(a.len(), b.len(), "{a:?} vs {b:?}");
    for (p, q) in a.iter().zip(b) {
        assert_close(*p, *q);
    }
}

mod fixtures {
    use super::*;

    /// transform_parts.city.json by hand (scale 0.01, translate 1000, 2000, 0):
    /// - B1: no own geometry; B1-p1 (child, LoD2.2 cube 4×4×3 m: 6 faces), B1-p2 (child, roof with a
    ///   courtyard hole), B1-p2-i1 (installation known only through `parents`): 8 faces;
    /// - B2: LoD1.2 box, LoD2.2 roof + a degenerate surface, LoD3 (ignored by default);
    /// - B3: GeometryInstance of a unit square, scaled ×2, lifted 5 m, at vertex 25 = (1020, 2000, 0);
    /// - R1: a road.
    fn check_default(m: &SourceModel) {
        let ids: Vec<&str> = m.buildings.iter().map(|b| b.source_id.as_str()).collect();
        assert_eq!(ids, ["B1", "B2", "B3"]);
        assert_eq!(m.stats.skipped_non_building, 1);
        assert_eq!(m.stats.degenerate_faces, 1);
        assert_eq!(m.stats.faces, 8 + 1 + 1);
        assert_eq!(m.stats.buildings_without_geometry, 0);

        let b1 = building(m, "B1");
        assert_eq!(b1.lod, "2.2");
        assert_eq!(b1.measured_height_m, Some(3.0));
        let p = polys(b1);
        assert_eq!(p.len(), 8);
        // Cube bottom [0,3,2,1] → vertices (0,0,0), (0,400,0), (400,400,0), (400,0,0) quantised.
        assert_ring_close(
            &p[0].exterior,
            &[[1000.0, 2000.0, 0.0], [1000.0, 2004.0, 0.0], [1004.0, 2004.0, 0.0], [1004.0, 2000.0, 0.0]],
        );
        let roof = &p[6];
        assert_ring_close(
            &roof.exterior,
            &[[1005.0, 2000.0, 3.0], [1009.0, 2000.0, 3.0], [1009.0, 2004.0, 3.0], [1005.0, 2004.0, 3.0]],
        );
        assert_eq!(roof.interiors.len(), 1);
        assert_ring_close(
            &roof.interiors[0],
            &[[1006.0, 2001.0, 3.0], [1006.0, 2003.0, 3.0], [1008.0, 2003.0, 3.0], [1008.0, 2001.0, 3.0]],
        );
        // The installation (through `parents` only).
        assert_ring_close(
            &p[7].exterior,
            &[[1005.0, 2000.0, 3.0], [1009.0, 2000.0, 3.0], [1005.0, 2000.0, 4.0]],
        );

        let b2 = building(m, "B2");
        assert_eq!(b2.lod, "2.2");
        assert_eq!(b2.measured_height_m, Some(7.5), "a numeric string is accepted");
        assert_eq!(polys(b2).len(), 1);
        assert_ring_close(
            &polys(b2)[0].exterior,
            &[[1010.0, 2000.0, 7.0], [1014.0, 2000.0, 7.0], [1014.0, 2004.0, 7.0], [1010.0, 2004.0, 7.0]],
        );

        let b3 = building(m, "B3");
        assert_eq!(b3.lod, "2", "the template's LoD");
        assert_eq!(polys(b3).len(), 1);
        // Template (0,0,0) (1,0,0) (1,1,0) (0,1,0) → ×2, +5 m up, + reference point (1020, 2000, 0).
        assert_ring_close(
            &polys(b3)[0].exterior,
            &[[1020.0, 2000.0, 5.0], [1022.0, 2000.0, 5.0], [1022.0, 2002.0, 5.0], [1020.0, 2002.0, 5.0]],
        );
    }

    #[test]
    fn transform_parents_children_default_lod() {
        let m = read(&fixture("transform_parts.city.json"), None).unwrap();
        assert_eq!(
            m.frame,
            Frame::Crs {
                name: Some("https://www.opengis.net/def/crs/EPSG/0/7415".into()),
                axes: AxisConvention::EastNorth
            }
        );
        check_default(&m);
    }

    /// The same model as CityJSONSeq (header line + one feature per building, vertices re-indexed
    /// per feature) reads to the same buildings.
    #[test]
    fn cityjsonseq_equals_cityjson() {
        let seq = read(&fixture("transform_parts.city.jsonl"), None).unwrap();
        check_default(&seq);
        let doc = read(&fixture("transform_parts.city.json"), None).unwrap();
        assert_eq!(seq.buildings, doc.buildings);
        assert_eq!(seq.stats, doc.stats);
        assert_eq!(seq.frame, doc.frame);
    }

    /// A CityJSONSeq under a `.json` name is recognised by its second line.
    #[test]
    fn cityjsonseq_detected_without_jsonl_extension() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("features.json");
        std::fs::copy(fixture("transform_parts.city.jsonl"), &p).unwrap();
        check_default(&read(&p, None).unwrap());
    }

    #[test]
    fn forced_lod_is_an_exact_match() {
        let m = read(&fixture("transform_parts.city.json"), Some("1.2")).unwrap();
        let got: Vec<(&str, &str, usize)> =
            m.buildings.iter().map(|b| (b.source_id.as_str(), b.lod.as_str(), polys(b).len())).collect();
        assert_eq!(got, [("B2", "1.2", 6)]);
        assert_eq!(m.stats.buildings_without_geometry, 2, "B1 and B3 have no LoD 1.2");
        // "3" is taken only when asked for; "2.0" matches the template's "2".
        let m = read(&fixture("transform_parts.city.json"), Some("3")).unwrap();
        assert_eq!(m.buildings.len(), 1);
        assert_eq!(polys(&m.buildings[0]).len(), 1);
        let m = read(&fixture("transform_parts.city.json"), Some("2.0")).unwrap();
        let ids: Vec<&str> = m.buildings.iter().map(|b| b.source_id.as_str()).collect();
        assert_eq!(ids, ["B3"]);
        assert_eq!(m.buildings[0].lod, "2", "as the file spells it");
    }

    /// CityJSON 1.1 without `transform` or CRS, with a numeric `lod` (as 1.0 wrote it): real-valued
    /// vertices are taken as they are.
    #[test]
    fn cityjson_1_1_untransformed_numeric_lod() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("v11.json");
        std::fs::write(
            &p,
            r#"{"type":"CityJSON","version":"1.1","CityObjects":{"b":{"type":"Building","geometry":[
               {"type":"MultiSurface","lod":2,"boundaries":[[[0,1,2]]]}]}},
               "vertices":[[85000.25,447000.5,1.0],[85010.25,447000.5,1.0],[85010.25,447010.5,1.0]]}"#,
        )
        .unwrap();
        let m = read(&p, None).unwrap();
        assert_eq!(m.frame, Frame::Crs { name: None, axes: AxisConvention::EastNorth });
        assert_eq!(m.buildings[0].lod, "2");
        assert_eq!(
            polys(&m.buildings[0])[0].exterior,
            vec![[85000.25, 447000.5, 1.0], [85010.25, 447000.5, 1.0], [85010.25, 447010.5, 1.0]]
        );
    }

    #[test]
    fn read_source_dispatches_json_to_cityjson() {
        let m = read_source(&fixture("transform_parts.city.json"), None, &ReadOptions::default()).unwrap();
        assert_eq!(m.buildings.len(), 3);
    }
}

/// Each bad file gives an error that names the file and the reason; none panics.
mod bad_input {
    use super::*;

    fn bad(name: &str) -> String {
        let msg = err_text(read(&fixture(name), None));
        assert!(msg.contains(name), "message must name the file: {msg}");
        msg
    }

    #[test]
    fn truncated_json() {
        let msg = bad("bad_truncated.json");
        assert!(msg.contains("truncated JSON") && msg.contains("line 244"), "{msg}");
    }

    #[test]
    fn vertex_index_out_of_range() {
        let msg = bad("bad_index_out_of_range.json");
        assert!(msg.contains("CityObjects[\"only\"].geometry[0].boundaries[1][0][2]"), "{msg}");
        assert!(msg.contains("vertex index 99 is out of range (vertices has 3 vertices)"), "{msg}");
    }

    #[test]
    fn huge_coordinate() {
        let msg = bad("bad_1e300_coordinate.json");
        assert!(msg.contains("CityObjects[\"only\"].geometry[0].boundaries[0][0][1]"), "{msg}");
        assert!(msg.contains("vertices[1]") && msg.contains("beyond"), "{msg}");
    }

    #[test]
    fn nan_coordinate() {
        // JSON has no NaN: the parser stops at it, with its position.
        let msg = bad("bad_nan_coordinate.json");
        assert!(msg.contains("malformed JSON at line") && msg.contains("expected value"), "{msg}");
    }

    #[test]
    fn empty_building() {
        let msg = bad("bad_empty_building.json");
        assert!(msg.contains("no buildings with geometry: 1 building(s) found, 1 without"), "{msg}");
    }

    #[test]
    fn degenerate_only_ring() {
        let msg = bad("bad_degenerate_ring.json");
        assert!(msg.contains("no buildings with geometry") && msg.contains("1 whose"), "{msg}");
        assert!(msg.contains("1 face(s) dropped"), "{msg}");
    }

    fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn wrong_boundary_depth_and_type() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(
            &dir,
            "depth.json",
            r#"{"type":"CityJSON","version":"2.0","CityObjects":{"a":{"type":"Building","geometry":[
               {"type":"Solid","lod":"2","boundaries":[[0,1,2]]}]}},"vertices":[[0,0,0],[1,0,0],[1,1,0]]}"#,
        );
        let msg = err_text(read(&p, None));
        assert!(
            msg.contains("CityObjects[\"a\"].geometry[0].boundaries") && msg.contains("depth 4"),
            "{msg}"
        );
        let p = write(&dir, "notcj.json", r#"{"type":"FeatureCollection","features":[]}"#);
        let msg = err_text(read(&p, None));
        assert!(msg.contains("not a CityJSON file"), "{msg}");
        let p = write(
            &dir,
            "negative.json",
            r#"{"type":"CityJSON","version":"2.0","CityObjects":{"a":{"type":"Building","geometry":[
               {"type":"MultiSurface","lod":"2","boundaries":[[[0,1,-2]]]}]}},"vertices":[[0,0,0],[1,0,0],[1,1,0]]}"#,
        );
        let msg = err_text(read(&p, None));
        assert!(msg.contains("vertex index -2 is negative") && msg.contains("line 2"), "{msg}");
    }

    #[test]
    fn truncated_cityjsonseq_line() {
        let dir = tempfile::tempdir().unwrap();
        let text = std::fs::read_to_string(fixture("transform_parts.city.jsonl")).unwrap();
        let cut = &text[..text.len() - 40];
        let p = write(&dir, "cut.city.jsonl", cut);
        let msg = err_text(read(&p, None));
        assert!(
            msg.contains("cut.city.jsonl") && msg.contains("truncated JSON") && msg.contains("line 5"),
            "{msg}"
        );
    }
}

/// Independent reference: walks the file as a `serde_json::Value` (no typed structs, no shared code).
mod value_walk {
    use super::*;

    pub struct Reference {
        pub buildings: usize,
        /// Surfaces of the chosen geometries (kept + degenerate), in total.
        pub surfaces: usize,
        pub first_building: String,
        /// Coordinates of the first ring of the first chosen surface of the first building.
        pub first_ring: Vec<[f64; 3]>,
    }

    fn surfaces_of(g: &Value) -> Vec<&Value> {
        fn list(v: &Value) -> Vec<&Value> {
            v.as_array().unwrap().iter().collect()
        }
        let b = &g["boundaries"];
        match g["type"].as_str().unwrap() {
            "MultiSurface" | "CompositeSurface" => list(b),
            "Solid" => list(b).into_iter().flat_map(list).collect(),
            "MultiSolid" | "CompositeSolid" => list(b).into_iter().flat_map(list).flat_map(list).collect(),
            other => panic!("unexpected geometry type {other}"),
        }
    }

    /// Buildings = `Building` objects; each takes its own and its `BuildingPart` children's geometry at
    /// the highest LoD ≤ 2.2 (the real files have one LoD per object or the same LoDs throughout).
    pub fn reference(path: &Path, lod: Option<&str>) -> Reference {
        let doc: Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
        let objects = doc["CityObjects"].as_object().unwrap();
        let scale: Vec<f64> =
            doc["transform"]["scale"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let translate: Vec<f64> =
            doc["transform"]["translate"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let vertices = doc["vertices"].as_array().unwrap();
        let mut r =
            Reference { buildings: 0, surfaces: 0, first_building: String::new(), first_ring: Vec::new() };
        let mut keys: Vec<&String> = objects.keys().collect();
        keys.sort(); // Value maps are sorted; the reader keeps file order, so compare sets, not order.
        for key in keys {
            let obj = &objects[key];
            if obj["type"] != "Building" {
                continue;
            }
            let mut members = vec![obj];
            for c in obj["children"].as_array().into_iter().flatten() {
                members.push(&objects[c.as_str().unwrap()]);
            }
            let geoms: Vec<&Value> =
                members.iter().flat_map(|m| m["geometry"].as_array().into_iter().flatten()).collect();
            let lod_of = |g: &Value| g["lod"].as_str().unwrap().parse::<f64>().unwrap();
            let chosen = match lod {
                Some(l) => l.parse::<f64>().unwrap(),
                None => geoms.iter().map(|g| lod_of(g)).filter(|&l| l <= 2.2).fold(f64::MIN, f64::max),
            };
            let chosen_geoms: Vec<&&Value> = geoms.iter().filter(|g| lod_of(g) == chosen).collect();
            if chosen_geoms.is_empty() {
                continue;
            }
            r.buildings += 1;
            for g in &chosen_geoms {
                r.surfaces += surfaces_of(g).len();
            }
            if r.first_building.is_empty() {
                r.first_building = key.clone();
                let ring = &surfaces_of(chosen_geoms[0])[0][0];
                r.first_ring = ring
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|i| {
                        let v = &vertices[i.as_u64().unwrap() as usize];
                        let c = |k: usize| v[k].as_f64().unwrap() * scale[k] + translate[k];
                        [c(0), c(1), c(2)]
                    })
                    .collect();
            }
        }
        r
    }
}

mod real_data {
    use super::*;

    fn check(path: &Path, lod: Option<&str>) -> SourceModel {
        let reference = value_walk::reference(path, lod);
        let m = read(path, lod).unwrap_or_else(|e| panic!("{e}"));
        eprintln!(
            "{}: {} buildings (reference {}), faces {} + dropped {} (reference {}), {} non-buildings skipped",
            path.display(),
            m.buildings.len(),
            reference.buildings,
            m.stats.faces,
            m.stats.degenerate_faces,
            reference.surfaces,
            m.stats.skipped_non_building
        );
        assert_eq!(m.buildings.len(), reference.buildings);
        assert_eq!((m.stats.faces + m.stats.degenerate_faces) as usize, reference.surfaces);
        let first = building(&m, &reference.first_building);
        // The reference ring is as in the file (CityJSON rings are open); the reader keeps it as is
        // unless it had consecutive duplicates.
        let same = |a: &[[f64; 3]]| {
            a.len() == reference.first_ring.len()
                && a.iter()
                    .zip(&reference.first_ring)
                    .all(|(p, q)| (0..3).all(|i| (p[i] - q[i]).abs() < 1e-9))
        };
        assert!(
            polys(first).iter().any(|p| same(&p.exterior)),
            "{}: no face with the reference ring {:?}",
            reference.first_building,
            reference.first_ring
        );
        let mut ids: Vec<&str> = m.buildings.iter().map(|b| b.source_id.as_str()).collect();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), m.buildings.len(), "unique ids");
        m
    }

    /// Den Haag: 844 buildings, the 1,653 BuildingParts folded in.
    #[test]
    fn denhaag_844_buildings() {
        let Some(path) = shared_data("nl_denhaag_lod2/DenHaag_01.city.json") else { return };
        let m = check(&path, None);
        assert_eq!(m.buildings.len(), 844);
        assert!(m.buildings.iter().all(|b| b.lod == "2"));
        assert_eq!(
            m.frame,
            Frame::Crs {
                name: Some("https://www.opengis.net/def/crs/EPSG/0/7415".into()),
                axes: AxisConvention::EastNorth
            }
        );
        assert_eq!(m.stats.skipped_non_building, 1, "the TINRelief");
    }

    #[test]
    fn delft_160_buildings() {
        let Some(path) = shared_data("nl_delft_lod1/delft.city.json") else { return };
        let m = check(&path, None);
        assert_eq!(m.buildings.len(), 160);
        assert!(m.buildings.iter().all(|b| b.lod == "1"));
        assert_eq!(m.stats.skipped_non_building, 570 - 160);
    }

    /// 3DBAG sample: 10 buildings at LoD 1.2 / 1.3 / 2.2; default 2.2; no CRS declared.
    #[test]
    fn bag3d_multilod() {
        let Some(path) = shared_data("nl_3dbag_multilod_sample/multi_lod.city.json") else { return };
        let m = check(&path, None);
        assert_eq!(m.buildings.len(), 10);
        assert!(m.buildings.iter().all(|b| b.lod == "2.2"));
        assert_eq!(m.frame, Frame::Crs { name: None, axes: AxisConvention::EastNorth });
        let m12 = check(&path, Some("1.2"));
        assert_eq!(m12.buildings.len(), 10);
        assert!(m12.buildings.iter().all(|b| b.lod == "1.2"));
        // RD New coordinates ('s-Hertogenbosch), easting first.
        for b in &m.buildings {
            for p in polys(b) {
                assert!(p.exterior.iter().all(
                    |v| (140_000.0..170_000.0).contains(&v[0]) && (400_000.0..430_000.0).contains(&v[1])
                ));
            }
        }
    }
}
