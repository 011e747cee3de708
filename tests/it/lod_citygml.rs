//! CityGML 2.0 reader: hand-made fixtures (tests/fixtures/citygml/, expected values worked out by
//! hand from the files) and the real PLATEAU files in ../shared/data (expected counts from an
//! independent plain-text scan of each file, written in this test).

use std::path::{Path, PathBuf};

use insgen::lod::{
    citygml, clean_ring, read_source, AxisConvention, Frame, LodError, ReadOptions, SourceModel,
};

use crate::util::{building, polygons as polys, read_error as err_text, shared_data};

fn fixture(name: &str) -> PathBuf {
    crate::util::fixture("citygml", name)
}

fn read(path: &Path, lod: Option<&str>) -> Result<SourceModel, LodError> {
    citygml::read(path, &ReadOptions { lod: lod.map(str::to_string), ..ReadOptions::default() })
}

mod fixtures {
    use super::*;

    /// Default LoD: bA at LoD2 through xlink:href (each polygon once), bB folded from its two parts
    /// (LoD2 part + LoD1 fallback part), bC at LoD1; the road is skipped.
    #[test]
    fn parts_courtyard_xlink_default_lod() {
        let m = read(&fixture("parts_courtyard_xlink.gml"), None).unwrap();
        let ids: Vec<&str> = m.buildings.iter().map(|b| b.source_id.as_str()).collect();
        assert_eq!(ids, ["bA", "bB", "bC"], "BuildingParts must not become buildings");
        assert_eq!(
            m.frame,
            Frame::Crs {
                name: Some("http://www.opengis.net/def/crs/EPSG/0/6677".into()),
                axes: AxisConvention::Authority
            }
        );
        assert_eq!(m.stats.skipped_non_building, 1, "the road");
        assert_eq!(m.stats.degenerate_faces, 1, "bA's two-point wall");
        assert_eq!(m.stats.buildings_without_geometry, 0);
        assert_eq!(m.stats.faces, 6 + 8 + 2);

        let a = building(&m, "bA");
        assert_eq!(a.lod, "2");
        assert_eq!(a.measured_height_m, Some(12.5));
        let p = polys(a);
        assert_eq!(
            p.len(),
            6,
            "ground, 4 walls, roof: referenced by lod2Solid and defined in boundedBy, once each"
        );
        // Order: as the lod2Solid references them; closing point removed.
        assert_eq!(
            p[0].exterior,
            vec![[0.0, 0.0, 0.0], [0.0, 10.0, 0.0], [10.0, 10.0, 0.0], [10.0, 0.0, 0.0]]
        );
        assert_eq!(p[1].exterior, vec![[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 0.0, 7.0], [0.0, 0.0, 7.0]]);
        // LoD2 walls reach 7 m (LoD1 box: 6 m), so these are not the LoD1 faces.
        assert!(p[1..5].iter().all(|w| w.exterior.iter().any(|v| v[2] == 7.0)));
        let roof = &p[5];
        assert_eq!(roof.exterior.len(), 4);
        assert!(roof.exterior.iter().all(|v| v[2] == 7.0));
        assert_eq!(roof.interiors.len(), 1, "the courtyard stays, the collinear hole is dropped");
        assert_eq!(
            roof.interiors[0],
            vec![[4.0, 4.0, 7.0], [4.0, 6.0, 7.0], [6.0, 6.0, 7.0], [6.0, 4.0, 7.0]]
        );

        let b = building(&m, "bB");
        assert_eq!(b.lod, "2");
        assert_eq!(b.measured_height_m, None, "a part's measuredHeight is not the building's");
        let p = polys(b);
        assert_eq!(p.len(), 2 + 6, "part bB-1 at LoD2 + part bB-2 falling back to LoD1");
        // gml:pos lists; closing point removed.
        assert_eq!(p[0].exterior, vec![[12.0, 0.0, 0.0], [16.0, 0.0, 0.0], [16.0, 0.0, 5.0]]);
        assert_eq!(
            p[1].exterior,
            vec![[12.0, 0.0, 5.0], [16.0, 0.0, 5.0], [16.0, 4.0, 5.0], [12.0, 4.0, 5.0]]
        );
        // srsDimension="3" inherited from gml:Solid; gml:Shell walked.
        assert_eq!(
            p[2].exterior,
            vec![[16.0, 0.0, 0.0], [16.0, 4.0, 0.0], [20.0, 4.0, 0.0], [20.0, 0.0, 0.0]]
        );
        assert!(p[2..].iter().all(|f| f.exterior.iter().all(|v| (16.0..=20.0).contains(&v[0]))));

        let c = building(&m, "bC");
        assert_eq!(c.lod, "1");
        let p = polys(c);
        assert_eq!(p.len(), 2);
        // srsDimension="2": z = 0.
        assert_eq!(
            p[0].exterior,
            vec![[22.0, 22.0, 0.0], [28.0, 22.0, 0.0], [28.0, 28.0, 0.0], [22.0, 28.0, 0.0]]
        );
        // gml:coordinates "x,y,z x,y,z".
        assert_eq!(p[1].exterior, vec![[22.0, 22.0, 4.0], [28.0, 22.0, 4.0], [28.0, 28.0, 4.0]]);
    }

    #[test]
    fn forced_lod1_takes_lod1_only() {
        let m = read(&fixture("parts_courtyard_xlink.gml"), Some("1")).unwrap();
        let got: Vec<(&str, &str, usize)> =
            m.buildings.iter().map(|b| (b.source_id.as_str(), b.lod.as_str(), polys(b).len())).collect();
        assert_eq!(got, [("bA", "1", 6), ("bB", "1", 6), ("bC", "1", 2)]);
        // bA's LoD1 box is 6 m high.
        assert!(polys(&m.buildings[0]).iter().flat_map(|p| &p.exterior).all(|v| v[2] == 0.0 || v[2] == 6.0));
        assert_eq!(m.stats.degenerate_faces, 0);
        assert_eq!(m.stats.faces, 14);
    }

    #[test]
    fn forced_lod2_skips_buildings_without_it() {
        let m = read(&fixture("parts_courtyard_xlink.gml"), Some("2")).unwrap();
        let got: Vec<(&str, &str, usize)> =
            m.buildings.iter().map(|b| (b.source_id.as_str(), b.lod.as_str(), polys(b).len())).collect();
        assert_eq!(got, [("bA", "2", 6), ("bB", "2", 2)], "no LoD1 fallback when LoD2 is forced");
        assert_eq!(m.stats.buildings_without_geometry, 1, "bC has LoD1 only");
        assert_eq!(m.stats.degenerate_faces, 1);
    }

    #[test]
    fn unsupported_lod_option_is_an_error() {
        let msg = err_text(read(&fixture("parts_courtyard_xlink.gml"), Some("2.2")));
        assert!(msg.contains("parts_courtyard_xlink.gml") && msg.contains("\"2.2\""), "{msg}");
    }

    #[test]
    fn read_source_dispatches_gml_to_citygml() {
        let m = read_source(&fixture("parts_courtyard_xlink.gml"), None, &ReadOptions::default()).unwrap();
        assert_eq!(m.buildings.len(), 3);
    }

    /// A vertex far outside the document envelope (latitude 135.51 in a 35.5–35.6 file) drops its
    /// polygon, counted with the degenerate faces; the building keeps its other faces.
    #[test]
    fn stray_coordinate_drops_the_face() {
        let m = read(&fixture("stray_coordinate.gml"), None).unwrap();
        assert_eq!(m.buildings.len(), 1);
        assert_eq!(polys(&m.buildings[0]).len(), 2);
        assert_eq!(m.stats.degenerate_faces, 1);
        assert!(polys(&m.buildings[0]).iter().flat_map(|p| &p.exterior).all(|v| v[0] < 90.0));
        assert_eq!(m.frame, Frame::Crs { name: Some("EPSG:6697".into()), axes: AxisConvention::Authority });
    }
}

/// German state LoD2 tiles name their CRS in the AdV register (`urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH`),
/// not by EPSG code: a hand-made tile in that style reads and prepares as its EPSG compound does.
mod adv_crs {
    use super::*;
    use crate::util::insgen;

    const ADV: &str = "urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH";

    #[test]
    fn a_german_tile_reads_with_its_adv_name() {
        let m = read(&fixture("adv_utm32_dhhn2016.gml"), None).unwrap();
        let ids: Vec<&str> = m.buildings.iter().map(|b| b.source_id.as_str()).collect();
        assert_eq!(ids, ["DEXX_LOD2_gable", "DEXX_LOD2_part"], "the BuildingPart folds into its building");
        assert_eq!(m.frame, Frame::Crs { name: Some(ADV.into()), axes: AxisConvention::Authority });
        let gable = building(&m, "DEXX_LOD2_gable");
        assert_eq!((gable.lod.as_str(), polys(gable).len()), ("2", 7), "ground, 4 walls, 2 roof planes");
        assert_eq!(polys(building(&m, "DEXX_LOD2_part")).len(), 6);
        let crs = ::insgen::geo::Crs::parse(ADV).unwrap();
        assert_eq!((crs.horizontal_epsg, crs.vertical_epsg), (25832, Some(7837)));
    }

    /// Prepared as it is and with the EPSG compound given in the scene file: the same buildings at the
    /// same places, and the manifest names the CRS by its EPSG codes.
    #[test]
    fn prepare_places_it_as_its_epsg_compound() {
        let src = fixture("adv_utm32_dhhn2016.gml");
        let scene = |crs: &str| {
            format!(
                "name = \"de\"\n\n[[sources]]\npath = \"{}\"\n{crs}\n\n[geoid]\nmodel = \"constant\"\n\
                 undulation_m = 47.0\n",
                src.display()
            )
        };
        let prepared = |crs: &str| {
            let dir = crate::util::scratch_with_scenes(&[("de", scene(crs))]);
            let out = insgen(dir.path(), &["--workdir", "runs", "prepare", "--area", "de"]);
            assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
            let read = |f: &str| -> serde_json::Value {
                serde_json::from_slice(&std::fs::read(dir.path().join("runs/de/scene").join(f)).unwrap())
                    .unwrap()
            };
            (read("manifest.json"), read("buildings.json"))
        };
        let (manifest, buildings) = prepared("");
        let chain = manifest["sources"][0]["crs_chain"].as_str().unwrap();
        assert!(chain.contains("EPSG:25832+7837"), "{chain}");
        // Origin at the buildings' centre: lat 48.1306°, lon 11.5672° (inspect; pyproj agrees to 1e-8°).
        let origin = &manifest["origin"];
        assert!((origin["lat_deg"].as_f64().unwrap() - 48.1306).abs() < 1e-3, "{origin}");
        assert!((origin["lon_deg"].as_f64().unwrap() - 11.5672).abs() < 1e-3, "{origin}");
        let (_, explicit) = prepared("crs = \"urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::7837\"");
        assert_eq!(buildings, explicit);
        // The gable's ridge stands 11 m above its ground, whatever the frame.
        let gable =
            buildings.as_array().unwrap().iter().find(|b| b["source_id"] == "DEXX_LOD2_gable").unwrap();
        let up = |i: usize| gable[["bbox_min_enu_m", "bbox_max_enu_m"][i]][2].as_f64().unwrap();
        assert!((up(1) - up(0) - 11.0).abs() < 0.01, "{gable}");
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
    fn truncated_xml() {
        let msg = bad("bad_truncated.gml");
        assert!(msg.contains("truncated XML") && msg.contains("line 21"), "{msg}");
        assert!(msg.contains("\"cut\""), "names the building being read: {msg}");
    }

    #[test]
    fn nan_coordinate() {
        let msg = bad("bad_nan_coordinate.gml");
        assert!(msg.contains("nan_building") && msg.contains("NaN") && msg.contains("not finite"), "{msg}");
        assert!(msg.contains("line 13"), "{msg}");
    }

    #[test]
    fn huge_coordinate() {
        let msg = bad("bad_1e300_coordinate.gml");
        assert!(msg.contains("huge_building") && msg.contains("1e300") && msg.contains("beyond"), "{msg}");
    }

    #[test]
    fn empty_building() {
        let msg = bad("bad_empty_building.gml");
        assert!(
            msg.contains("no buildings with geometry") && msg.contains("1 building(s) found, 1 without"),
            "{msg}"
        );
    }

    #[test]
    fn degenerate_only_ring() {
        let msg = bad("bad_degenerate_ring.gml");
        assert!(
            msg.contains("no buildings with geometry")
                && msg.contains("1 whose LoD 0, 1 or 2 surfaces are all degenerate"),
            "{msg}"
        );
        assert!(msg.contains("1 face(s) dropped"), "{msg}");
    }

    #[test]
    fn poslist_not_a_multiple_of_the_dimension() {
        let msg = bad("bad_poslist_length.gml");
        assert!(
            msg.contains("short_poslist") && msg.contains("11 number(s)") && msg.contains("3-D"),
            "{msg}"
        );
    }

    #[test]
    fn missing_file() {
        let msg = err_text(read(Path::new("no/such/file.gml"), None));
        assert!(msg.contains("no/such/file.gml"), "{msg}");
    }

    #[test]
    fn mismatched_end_tag() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("mismatch.gml");
        std::fs::write(&p, "<core:CityModel>\n<core:cityObjectMember>\n</core:CityModel>\n").unwrap();
        let msg = err_text(read(&p, None));
        assert!(msg.contains("mismatch.gml") && msg.contains("malformed XML at line 3"), "{msg}");
    }
}

mod rings {
    use super::*;

    #[test]
    fn closing_point_and_duplicates_removed() {
        let r =
            clean_ring(vec![[0., 0., 0.], [1., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 0., 0.]]).unwrap();
        assert_eq!(r, vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.]]);
        // Duplicate closing points and a duplicate across the wrap-around.
        let r = clean_ring(vec![
            [0., 0., 0.],
            [0., 0., 0.],
            [1., 0., 0.],
            [1., 1., 0.],
            [0., 0., 0.],
            [0., 0., 0.],
        ]);
        assert_eq!(r.unwrap(), vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.]]);
    }

    #[test]
    fn degenerate_rings_are_rejected() {
        assert_eq!(clean_ring(vec![[0., 0., 0.], [1., 0., 0.], [0., 0., 0.]]), None, "2 distinct points");
        assert_eq!(clean_ring(vec![[0., 0., 0.], [1., 1., 1.], [2., 2., 2.]]), None, "collinear");
        assert_eq!(
            clean_ring(vec![[0., 0., 0.], [1., 0., 0.], [0., 0., 0.], [1., 0., 0.]]),
            None,
            "back and forth"
        );
        assert_eq!(clean_ring(vec![]), None);
        // Collinear in EPSG:6697 degrees: rounding noise must not pass for area.
        let (lat, lon) = (35.532665125662916, 139.7952788378548);
        let d = 1.234567e-5;
        let line = vec![[lat, lon, 3.9], [lat + d, lon + 2.0 * d, 3.9], [lat + 3.0 * d, lon + 6.0 * d, 3.9]];
        assert_eq!(clean_ring(line), None);
    }

    #[test]
    fn small_real_faces_are_kept() {
        // A 1 m × 1 m roof in degrees (1e-5° ≈ 1 m) near Tokyo.
        let (lat, lon, d) = (35.5326, 139.7952, 1e-5);
        let roof = vec![[lat, lon, 10.], [lat + d, lon, 10.], [lat + d, lon + d, 10.], [lat, lon + d, 10.]];
        assert_eq!(clean_ring(roof.clone()).unwrap(), roof);
        // A 5 cm wide, 20 m high wall in RD metres.
        let (x, y) = (85000.0, 447000.0);
        let wall = vec![[x, y, 0.], [x + 0.05, y, 0.], [x + 0.05, y, 20.], [x, y, 20.]];
        assert_eq!(clean_ring(wall.clone()).unwrap(), wall);
    }
}

/// Independent reference for the PLATEAU files: a plain-text scan (no XML parser) of each
/// `<bldg:Building ` chunk, split into parts at `<bldg:BuildingPart `.
mod text_scan {
    /// Blocks between `<bldg:TAG>` and `</bldg:TAG>`.
    fn blocks<'a>(text: &'a str, tag: &str) -> Vec<&'a str> {
        let (open, close) = (format!("<bldg:{tag}>"), format!("</bldg:{tag}>"));
        let mut out = Vec::new();
        let mut rest = text;
        while let Some(s) = rest.find(&open) {
            let after = &rest[s + open.len()..];
            let Some(e) = after.find(&close) else { break };
            out.push(&after[..e]);
            rest = &after[e + close.len()..];
        }
        out
    }

    fn count_polygons(text: &str, tags: &[&str]) -> usize {
        tags.iter().flat_map(|t| blocks(text, t)).map(|b| b.matches("<gml:Polygon").count()).sum()
    }

    /// Number of `<bldg:Building ` elements and the number of polygons the reader should look at
    /// (kept + dropped) by default: per building component, its LoD2 surfaces (lod2MultiSurface and
    /// lod2Geometry blocks; PLATEAU lod2Solids only reference them) if any component has some, else
    /// its LoD1 solid's polygons.
    pub fn buildings_and_faces(text: &str) -> (usize, usize) {
        let chunks: Vec<&str> = text.split("<bldg:Building ").skip(1).collect();
        let mut faces = 0;
        for chunk in &chunks {
            let mut comps: Vec<&str> = chunk.split("<bldg:BuildingPart ").collect();
            if comps.len() > 1 && count_polygons(comps[0], &["lod1Solid", "lod2MultiSurface"]) == 0 {
                comps.remove(0);
            }
            for comp in comps {
                let n2 = count_polygons(comp, &["lod2MultiSurface", "lod2Geometry"]);
                let n1 = count_polygons(comp, &["lod1Solid"]);
                faces += if n2 > 0 { n2 } else { n1 };
            }
        }
        (chunks.len(), faces)
    }

    /// The numbers of the first `<gml:posList>` inside the first `<bldg:lod1Solid>`.
    pub fn first_lod1_poslist(text: &str) -> Vec<f64> {
        let solid = &blocks(text, "lod1Solid")[0];
        let s = solid.find("<gml:posList>").unwrap() + "<gml:posList>".len();
        let e = solid[s..].find("</gml:posList>").unwrap();
        solid[s..s + e].split_whitespace().map(|t| t.parse().unwrap()).collect()
    }
}

mod real_data {
    use super::*;

    fn check_against_text_scan(path: &Path) -> SourceModel {
        let text = std::fs::read_to_string(path).unwrap();
        let (n_buildings, n_faces) = text_scan::buildings_and_faces(&text);
        let m = read(path, None).unwrap_or_else(|e| panic!("{e}"));
        eprintln!(
            "{}: {} buildings (text scan {n_buildings}), faces {} + dropped {} (text scan {n_faces}), lods {:?}",
            path.display(),
            m.buildings.len(),
            m.stats.faces,
            m.stats.degenerate_faces,
            m.buildings.iter().fold(std::collections::BTreeMap::new(), |mut acc, b| {
                *acc.entry(b.lod.clone()).or_insert(0) += 1;
                acc
            })
        );
        assert_eq!(m.buildings.len(), n_buildings, "{}", path.display());
        assert_eq!(m.stats.buildings_without_geometry, 0);
        assert_eq!((m.stats.faces + m.stats.degenerate_faces) as usize, n_faces, "{}", path.display());
        let mut ids: Vec<&str> = m.buildings.iter().map(|b| b.source_id.as_str()).collect();
        assert!(ids.iter().all(|id| text.contains(&format!("<bldg:Building gml:id=\"{id}\""))));
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), m.buildings.len(), "unique ids");
        assert_eq!(
            m.frame,
            Frame::Crs {
                name: Some("http://www.opengis.net/def/crs/EPSG/0/6697".into()),
                axes: AxisConvention::Authority
            }
        );
        // EPSG:6697 axis order: latitude, longitude, height (Japan).
        for b in &m.buildings {
            for p in polys(b) {
                for v in p.exterior.iter().chain(p.interiors.iter().flatten()) {
                    assert!(
                        (20.0..50.0).contains(&v[0]) && (120.0..155.0).contains(&v[1]),
                        "{}: {v:?}",
                        b.source_id
                    );
                }
            }
        }
        m
    }

    /// Niiza: exactly 657 LoD1 buildings, each with its gml:id.
    #[test]
    fn niiza_657_buildings() {
        let Some(path) = shared_data("jp_niiza_plateau_lod1/53395404_bldg_6697_op.gml") else { return };
        let m = check_against_text_scan(&path);
        assert_eq!(m.buildings.len(), 657);
        assert!(m.buildings.iter().all(|b| b.lod == "1" && b.source_id.starts_with("uuid_")));
        assert!(m.buildings.iter().all(|b| b.measured_height_m.is_some()));
        let first = &m.buildings[0];
        assert_eq!(first.source_id, "uuid_EBE7C667-9BE2-4743-9D73-A6AF75ED2191");
        assert_eq!(first.measured_height_m, Some(3.9));
        // First LoD1 face, exactly as written (minus the closing point).
        let text = std::fs::read_to_string(&path).unwrap();
        let nums = text_scan::first_lod1_poslist(&text);
        let expected: Vec<[f64; 3]> =
            nums.chunks(3).map(|c| [c[0], c[1], c[2]]).take(nums.len() / 3 - 1).collect();
        assert_eq!(polys(first)[0].exterior, expected);
    }

    #[test]
    fn tokyo_fixtures_parse() {
        let Some(dir) = shared_data("jp_tokyo_plateau_citygml_fixtures") else { return };
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "gml"))
            .collect();
        files.sort();
        assert_eq!(files.len(), 6);
        for f in files {
            check_against_text_scan(&f);
        }
    }

    /// 53392633: building bldg_7263c902… has a GroundSurface whose first/last vertex has latitude
    /// 135.53 (35.53 elsewhere). That polygon is dropped; the 5 other LoD2 faces stay.
    #[test]
    fn tokyo_stray_coordinate_is_dropped() {
        let Some(path) =
            shared_data("jp_tokyo_plateau_citygml_fixtures/53392633_bldg_6697_2_op.plateau-builder.gml")
        else {
            return;
        };
        let m = read(&path, None).unwrap();
        assert_eq!(m.stats.degenerate_faces, 1);
        let b = building(&m, "bldg_7263c902-41e5-44bd-bce1-4d308a26d9da");
        assert_eq!(b.lod, "2");
        assert_eq!(polys(b).len(), 5, "roof + 4 walls; the ground surface with the stray vertex is dropped");
        // LoD1 of the same building is clean and complete.
        let m1 = read(&path, Some("1")).unwrap();
        assert_eq!(polys(building(&m1, "bldg_7263c902-41e5-44bd-bce1-4d308a26d9da")).len(), 6);
        assert_eq!(m1.stats.degenerate_faces, 0);
    }

    #[test]
    fn misc_plateau_parse_and_fold_parts() {
        let Some(dir) = shared_data("jp_misc_plateau") else { return };
        let yokosuka = check_against_text_scan(&dir.join("52397519_bldg_6697_op.gml"));
        assert_eq!(yokosuka.buildings.len(), 13);
        // The museum: a Building with two BuildingParts, read as one building under the parent's id.
        let museum = building(&yokosuka, "bldg_16418b2d-dc75-4731-ae04-90bbef1d66fe");
        assert!(!polys(museum).is_empty());
        for part in ["bldg_0e947699-9ee6-412f-98d2-6dafb177a681", "bldg_a9dcefad-63a0-4fa0-b666-84125640e7a4"]
        {
            assert!(yokosuka.buildings.iter().all(|b| b.source_id != part));
        }
        let sapporo = check_against_text_scan(&dir.join("64413325_bldg_6697_op.gml"));
        assert_eq!(sapporo.buildings.len(), 25);
    }
}
