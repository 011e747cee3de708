//! Camera files: presets and custom TOML, COLMAP round trip, pose-record representations (checked
//! against pyproj), JSON Schemas, the flight-plan picture and the `sample` command's planning.

use crate::camera_support;

use std::path::{Path, PathBuf};

use camera_support as cs;
use insgen::camera::colmap::{read_cameras_txt, read_images_txt};
use insgen::camera::config::SamplingConfig;
use insgen::camera::record::read_jsonl;
use insgen::camera::sample::{sample_area, write_sample, SampleOutput};
use insgen::camera::{CameraError, CameraSpec, Pose, Trajectory};
use insgen::geo::{ecef_to_geodetic, geodetic_to_ecef, EnuFrame, Geodetic};
use insgen::util::NoProgress;

/// Largest element-wise difference of two rotation matrices (≈ the angle between them in radians for
/// small angles). Used instead of `rotation_error_deg`, whose arccos cannot resolve angles below
/// ~1e-6° in f64.
fn rot_diff(a: &Pose, b: &Pose) -> f64 {
    let mut d: f64 = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            d = d.max((a.r_world_from_cam.col(j)[i] - b.r_world_from_cam.col(j)[i]).abs());
        }
    }
    d
}

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

fn sampled(camera: &str, count: usize) -> (tempfile::TempDir, SampleOutput) {
    let scene = cs::city();
    let out =
        sample_area(&scene, &cs::preset(camera), &SamplingConfig::default(), Some(count), 21, &NoProgress)
            .unwrap_or_else(|e| panic!("{e}"));
    let tmp = tempfile::tempdir().unwrap();
    write_sample(tmp.path(), &scene, &out).unwrap();
    (tmp, out)
}

mod presets {
    use super::*;

    #[test]
    fn focal_lengths_from_fov_and_sensor() {
        // Paper table; hand computations: f_px = (W/2) / tan(hfov/2) = f_mm · W / sensor_w.
        // cam2/cam3: 960 / tan 12.5° = 4330.28 px (≈ 4330.0), 11.88 mm / tan 12.5° = 53.5872 mm;
        // cam1: 800 / tan 22.5° = 1931.37 px, 8 mm / tan 22.5° = 19.3137 mm.
        let expect = [
            ("cam1", 1600, 1200, 1931.37, 19.3137),
            ("cam2", 1920, 1080, 4330.28, 53.5872),
            ("cam3", 1920, 1080, 4330.28, 53.5872),
        ];
        for (name, w, h, f_px, f_mm) in expect {
            let c = CameraSpec::preset(name).unwrap();
            let k = c.intrinsics;
            assert_eq!((k.width_px, k.height_px), (w, h), "{name}");
            assert!((k.fx_px - f_px).abs() < 0.01 && (k.fy_px - f_px).abs() < 0.01, "{name}: {k:?}");
            assert!((c.focal_mm - f_mm).abs() < 1e-4, "{name}: {} mm", c.focal_mm);
            assert_eq!((k.cx_px, k.cy_px), (w as f64 / 2.0, h as f64 / 2.0), "{name}");
        }
    }

    #[test]
    fn example_camera_file() {
        let c = CameraSpec::load(&repo("scenes/cameras/example.toml")).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.name, "survey4k");
        assert_eq!(c.strategy, Trajectory::Irregular);
        // f = 4.5 mm over 1.6 µm pixels = 2812.5 px; hFOV = 2 atan(3.2 / 4.5) = 70.84°.
        assert!((c.intrinsics.fx_px - 2812.5).abs() < 1e-9 && (c.intrinsics.fy_px - 2812.5).abs() < 1e-9);
        assert!((c.hfov_deg - 2.0 * (3.2f64 / 4.5).atan().to_degrees()).abs() < 1e-9);
        assert_eq!(c.distortion.unwrap().k1, -0.0123);
        assert_eq!(CameraSpec::resolve(repo("scenes/cameras/example.toml").to_str().unwrap()).unwrap(), c);
    }

    #[test]
    fn missing_camera_file_names_it() {
        let e = CameraSpec::resolve("no/such/camera.toml").unwrap_err().to_string();
        assert!(e.contains("no/such/camera.toml"), "{e}");
    }
}

mod colmap {
    use super::*;

    #[test]
    fn written_model_reads_back_exactly() {
        let (tmp, out) = sampled("cam2", 25);
        let cams = read_cameras_txt(&tmp.path().join("colmap/cameras.txt")).unwrap();
        assert_eq!(cams.len(), 1);
        assert_eq!((cams[0].camera_id, cams[0].model.as_str()), (1, "PINHOLE"));
        assert_eq!(cams[0].intrinsics().unwrap(), out.camera.intrinsics);
        let images = read_images_txt(&tmp.path().join("colmap/images.txt")).unwrap();
        assert_eq!(images.len(), out.poses.len());
        for (i, (im, r)) in images.iter().zip(&out.poses).enumerate() {
            assert_eq!(im.image_id as usize, i + 1);
            assert_eq!(im.camera_id, 1);
            assert_eq!(im.name, format!("{}.png", r.name));
            // Shortest round-trip formatting: the numbers come back bit for bit.
            assert_eq!(im.qvec, r.view.colmap_qvec);
            assert_eq!(im.tvec, r.view.colmap_tvec);
            let (a, b) = (im.pose(), r.pose());
            assert!(
                a.translation_error_m(&b) < 1e-9 && rot_diff(&a, &b) < 1e-12,
                "{} m {}",
                a.translation_error_m(&b),
                rot_diff(&a, &b)
            );
        }
    }

    #[test]
    fn lodloc_lists() {
        let tmp = tempfile::tempdir().unwrap();
        let q = tmp.path().join("queries.txt");
        std::fs::write(
            &q,
            "q1.jpg PINHOLE 1920 1080 4330 4330 960 540\nq2.jpg SIMPLE_PINHOLE 640 480 500 320 240\n",
        )
        .unwrap();
        let list = insgen::camera::colmap::read_query_list(&q).unwrap();
        assert_eq!(list.len(), 2);
        assert_eq!(list[1].1.intrinsics().unwrap().fy_px, 500.0);
        let pose = Pose::from_ypr_deg(10.0, 20.0, 0.0, [1.0, 2.0, 300.0]);
        let im = insgen::camera::colmap::ColmapImage::from_pose(0, 0, "q1.jpg", &pose);
        let p = tmp.path().join("poses.txt");
        std::fs::write(&p, insgen::camera::colmap::format_pose_list(std::slice::from_ref(&im))).unwrap();
        assert_eq!(insgen::camera::colmap::read_pose_list(&p).unwrap(), vec![im]);
        std::fs::write(&p, "q1.jpg 1 0 0\n").unwrap();
        let e = insgen::util::error_chain(&insgen::camera::colmap::read_pose_list(&p).unwrap_err());
        assert!(e.ends_with("poses.txt:1: expected NAME QW QX QY QZ TX TY TZ, got \"q1.jpg 1 0 0\""), "{e}");
    }
}

mod records {
    use super::*;

    #[test]
    fn all_representations_agree() {
        let (tmp, out) = sampled("cam1", 40);
        let enu = EnuFrame::new(cs::origin());
        let back = read_jsonl(&tmp.path().join("poses.jsonl")).unwrap();
        assert_eq!(back, out.poses, "JSON lines must round-trip exactly");
        for r in &back {
            let pose = r.pose();
            // ENU 4×4 ↔ COLMAP.
            let from_colmap = Pose::from_colmap(r.view.colmap_qvec, r.view.colmap_tvec);
            assert!(pose.translation_error_m(&from_colmap) < 1e-9 && rot_diff(&pose, &from_colmap) < 1e-12);
            // ENU ↔ ECEF.
            let ecef = enu.enu_to_ecef(pose.centre_m);
            assert!((0..3).all(|k| (ecef[k] - r.ecef_m[k]).abs() < 1e-6), "{ecef:?} {:?}", r.ecef_m);
            let c = enu.ecef_to_enu(r.ecef_m.into());
            assert!((0..3).all(|k| (c[k] - pose.centre_m[k]).abs() < 1e-6));
            // ECEF ↔ lat/lon/h.
            let e2 =
                geodetic_to_ecef(Geodetic { lat_deg: r.geo.lat_deg, lon_deg: r.geo.lon_deg, h_m: r.geo.h_m });
            assert!((0..3).all(|k| (e2[k] - r.ecef_m[k]).abs() < 1e-6));
            let g = ecef_to_geodetic(r.ecef_m);
            assert!((g.lat_deg - r.geo.lat_deg).abs() < 1e-10 && (g.h_m - r.geo.h_m).abs() < 1e-6);
            // ENU ↔ yaw/pitch/roll.
            let from_ypr = Pose::from_ypr_deg(r.geo.yaw_deg, r.geo.pitch_deg, r.geo.roll_deg, pose.centre_m);
            assert!(
                rot_diff(&pose, &from_ypr) < 1e-12,
                "{}: ypr {:?}",
                r.name,
                (r.geo.yaw_deg, r.geo.pitch_deg)
            );
            // The rotation block is orthonormal with determinant +1.
            let det = pose.r_world_from_cam.determinant();
            assert!((det - 1.0).abs() < 1e-12);
            // Heights: ellipsoidal h ≈ origin h + ENU up (the curvature drop is r²/2R < 0.2 m within 1.5 km).
            assert!((r.geo.h_m - (cs::origin().h_m + pose.centre_m[2])).abs() < 0.2);
        }
    }

    #[test]
    fn geodetic_fields_match_pyproj() {
        let Some(py) = crate::util::python_with(&["pyproj"]) else { return };
        let (_tmp, out) = sampled("cam2", 10);
        let pts: Vec<String> = out.poses.iter().map(|r| format!("{:?}", r.ecef_m)).collect();
        let script = format!(
            "from pyproj import Transformer\nt = Transformer.from_crs('EPSG:4978', 'EPSG:4979', always_xy=True)\n\
             for x, y, z in [{}]:\n    lon, lat, h = t.transform(x, y, z)\n    print(repr(lat), repr(lon), repr(h))\n",
            pts.join(", ")
        );
        let o = std::process::Command::new(&py).arg("-c").arg(&script).output().expect("running python");
        assert!(o.status.success(), "pyproj failed:\n{}", String::from_utf8_lossy(&o.stderr));
        let text = String::from_utf8(o.stdout).unwrap();
        for (line, r) in text.lines().zip(&out.poses) {
            let v: Vec<f64> = line.split_whitespace().map(|t| t.parse().unwrap()).collect();
            // 1e-9° ≈ 0.1 mm; 1 mm in height.
            assert!(
                (v[0] - r.geo.lat_deg).abs() < 1e-9
                    && (v[1] - r.geo.lon_deg).abs() < 1e-9
                    && (v[2] - r.geo.h_m).abs() < 1e-3,
                "{line} vs {r:?}"
            );
        }
        assert_eq!(text.lines().count(), out.poses.len());
    }

    #[test]
    fn bad_jsonl_line_is_located() {
        let tmp = tempfile::tempdir().unwrap();
        let p = tmp.path().join("poses.jsonl");
        std::fs::write(&p, "\n{\"name\": 3}\n").unwrap();
        let e = read_jsonl(&p).unwrap_err();
        assert!(matches!(e, CameraError::Jsonl { line: 2, .. }), "{e}");
    }
}

mod schemas {
    use super::*;

    fn schema(name: &str) -> jsonschema::Validator {
        let text = std::fs::read_to_string(repo(&format!("schemas/{name}"))).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        jsonschema::validator_for(&v).unwrap()
    }

    #[test]
    fn pose_and_prior_lines_validate() {
        let (tmp, out) = sampled("cam3", 20);
        let val = schema("poses.schema.json");
        for file in ["poses.jsonl", "priors.jsonl"] {
            let text = std::fs::read_to_string(tmp.path().join(file)).unwrap();
            assert_eq!(text.lines().count(), out.poses.len());
            for line in text.lines() {
                let v: serde_json::Value = serde_json::from_str(line).unwrap();
                let errs: Vec<String> = val.iter_errors(&v).map(|e| e.to_string()).collect();
                assert!(errs.is_empty(), "{file}: {errs:?}");
            }
        }
        // The schema is not vacuous: a wrong trajectory, a missing field and an extra field fail.
        let mut v: serde_json::Value = serde_json::to_value(&out.poses[0]).unwrap();
        v["trajectory"] = "spiral".into();
        assert!(!val.is_valid(&v));
        let mut v: serde_json::Value = serde_json::to_value(&out.poses[0]).unwrap();
        v.as_object_mut().unwrap().remove("colmap_qvec");
        assert!(!val.is_valid(&v));
        let mut v: serde_json::Value = serde_json::to_value(&out.poses[0]).unwrap();
        v["extra"] = 1.into();
        assert!(!val.is_valid(&v));
    }

    #[test]
    fn camera_files_validate() {
        let val = schema("camera.schema.json");
        let text = std::fs::read_to_string(repo("scenes/cameras/example.toml")).unwrap();
        let t: toml::Value = toml::from_str(&text).unwrap();
        let v = serde_json::to_value(&t).unwrap();
        let errs: Vec<String> = val.iter_errors(&v).map(|e| e.to_string()).collect();
        assert!(errs.is_empty(), "{errs:?}");
        // Schema and reader agree on rejecting these.
        for bad in [
            "name = \"cam2\"\nwidth_px = 10\nheight_px = 10\nsensor_width_mm = 1\nsensor_height_mm = 1\nhfov_deg = 40\n",
            "name = \"x\"\nwidth_px = 10\nheight_px = 10\nsensor_width_mm = 1\nsensor_height_mm = 1\n",
            "name = \"x\"\nwidth_px = 10\nheight_px = 10\nsensor_width_mm = 1\nsensor_height_mm = 1\nhfov_deg = 40\nzoom = 2\n",
        ] {
            let v = serde_json::to_value(toml::from_str::<toml::Value>(bad).unwrap()).unwrap();
            assert!(!val.is_valid(&v), "schema accepts {bad:?}");
            assert!(CameraSpec::from_toml_str(bad, Path::new("bad.toml")).is_err(), "reader accepts {bad:?}");
        }
    }
}

mod flight_plan {
    use super::*;

    fn decode(path: &Path) -> (u32, u32, Vec<u8>, Vec<(String, String)>) {
        let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
        let mut reader = dec.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgb);
        let text = reader
            .info()
            .uncompressed_latin1_text
            .iter()
            .map(|t| (t.keyword.clone(), t.text.clone()))
            .collect();
        (info.width, info.height, buf, text)
    }

    #[test]
    fn picture_shows_buildings_polygon_and_cameras() {
        let (tmp, out) = sampled("cam2", 30);
        let (w, h, rgb, text) = decode(&tmp.path().join("flight_plan.png"));
        assert_eq!(w.max(h), 1600);
        let value = |k: &str| -> f64 { text.iter().find(|t| t.0 == k).unwrap().1.parse().unwrap() };
        let mpp = value("metres_per_px");
        // Map extent: polygon bbox (1200 × 900 m) padded by 4 % of 1200 m + 20 m per side, 1600 px wide,
        // under the title band.
        assert!((mpp - (1200.0 + 2.0 * 68.0) / 1600.0).abs() < 1e-9, "{mpp}");
        let (left, top) = (value("map_left_px") as usize, value("map_top_px") as usize);
        assert_eq!(left, 0);
        assert!(top > 40, "a title band of {top} px");
        let map_h = ((900.0 + 2.0 * 68.0) / mpp).ceil() as u32;
        assert!(h > top as u32 + map_h + 40, "a legend and scale bar below the map: {h} px tall");
        let px = |e: f64, n: f64| -> [u8; 3] {
            let (x, y) = (left + ((e + 668.0) / mpp) as usize, top + ((518.0 - n) / mpp) as usize);
            let i = 3 * (y * w as usize + x);
            [rgb[i], rgb[i + 1], rgb[i + 2]]
        };
        assert_eq!(value("scale_bar_m"), 200.0, "a fifth of the 1336 m wide map, rounded down to 1-2-5");
        // Nadir cameras are drawn last (blue disc at their position); tilted ones show as orange rings.
        let nadir = out.poses.iter().rev().find(|r| r.geo.pitch_deg <= 1.0).expect("a nadir pose");
        let c = nadir.pose().centre_m;
        assert_eq!(px(c[0], c[1]), [30, 90, 200]);
        let in_map = &rgb[3 * top * w as usize..3 * (top + map_h as usize) * w as usize];
        assert!(in_map.chunks_exact(3).any(|p| p == [225, 110, 20]), "no tilted camera drawn");
        // The title band and the legend hold text (dark anti-aliased pixels on white).
        let dark = |rows: std::ops::Range<usize>| {
            rgb[3 * rows.start * w as usize..3 * rows.end * w as usize]
                .chunks_exact(3)
                .filter(|p| p[0] < 90)
                .count()
        };
        assert!(dark(0..top) > 500, "title");
        assert!(dark(top + map_h as usize..h as usize) > 1000, "scale bar and legend");
        // A building pixel has the ramp colour (205, 205, 210) → (45, 55, 90) at some t in [0, 1].
        let on_ramp = |p: &[u8]| {
            let t = (205.0 - p[0] as f64) / 160.0;
            (-0.01..=1.01).contains(&t)
                && (p[1] as f64 - (205.0 - 150.0 * t)).abs() <= 1.0
                && (p[2] as f64 - (210.0 - 120.0 * t)).abs() <= 1.0
        };
        // Shaded pixels of the map only (the legend shows the ramp too).
        let shaded = in_map.chunks_exact(3).filter(|p| on_ramp(p)).count() as f64;
        let (e0, e1, n0, n1) = (-668.0, -668.0 + w as f64 * mpp, 518.0 - map_h as f64 * mpp, 518.0);
        let footprint: f64 = cs::boxes()
            .iter()
            .map(|(lo, hi)| {
                ((hi[0].min(e1) - lo[0].max(e0)).max(0.0)) * ((hi[1].min(n1) - lo[1].max(n0)).max(0.0))
            })
            .sum();
        let expect_px = footprint / (mpp * mpp);
        assert!((shaded / expect_px - 1.0).abs() < 0.1, "{shaded} shaded pixels vs {expect_px} expected");
        // The tower (tallest) is the darkest building.
        let tower = px(cs::TOWER_CENTRE_M[0] + 10.0, cs::TOWER_CENTRE_M[1] - 10.0);
        assert_eq!(tower, [45, 55, 90], "tower colour");
    }

    #[test]
    fn boxes_stand_in_for_a_missing_mesh() {
        let scene = cs::city_with(cs::area_polygon(), false);
        let out =
            sample_area(&scene, &cs::preset("cam3"), &SamplingConfig::default(), Some(10), 1, &NoProgress)
                .unwrap();
        let tmp = tempfile::tempdir().unwrap();
        let p = tmp.path().join("fp.png");
        insgen::camera::flight_plan::write_flight_plan(&p, &scene, &out.poses).unwrap();
        let (_, _, rgb, _) = decode(&p);
        assert!(rgb.chunks_exact(3).any(|p| p == [45, 55, 90]), "the tower box is drawn");
    }
}

mod cli {
    use super::*;
    use insgen::cli::sample::{execute, Args, Plan};
    use insgen::cli::Global;

    fn global(workdir: &Path, scenes: &Path) -> Global {
        Global {
            workdir: workdir.into(),
            scenes: scenes.into(),
            verbose: 0,
            quiet: true,
            no_progress: true,
            log_every: 30.0,
        }
    }

    fn args(area: &str, camera: &str) -> Args {
        Args {
            areas: vec![area.into()],
            camera: camera.into(),
            count: Some(12),
            seed: 3,
            strategy: None,
            shard: None,
        }
    }

    /// The plan of the one area of `a`.
    fn plan_of(a: &Args, g: &Global) -> anyhow::Result<Plan> {
        Plan::for_area(&a.areas[0], a, g)
    }

    #[test]
    fn unknown_area_lists_what_exists() {
        let tmp = tempfile::tempdir().unwrap();
        let (work, scenes) = (tmp.path().join("runs"), tmp.path().join("scenes"));
        std::fs::create_dir_all(work.join("tokyo/scene")).unwrap();
        std::fs::write(work.join("tokyo/scene/manifest.json"), "{}").unwrap();
        std::fs::create_dir_all(&scenes).unwrap();
        std::fs::write(scenes.join("delft.toml"), "").unwrap();
        std::fs::write(scenes.join("tokyo.toml"), "").unwrap();
        let e = plan_of(&args("delft", "cam2"), &global(&work, &scenes)).unwrap_err();
        let msg = format!("{e:#}");
        assert!(msg.starts_with("unknown area \"delft\": no prepared scene at"), "{msg}");
        assert!(
            msg.contains(": tokyo\n")
                && msg.contains(": delft, tokyo")
                && msg.contains("insgen prepare --area delft"),
            "{msg}"
        );
    }

    #[test]
    fn unknown_camera_lists_presets_and_sampling_table_is_read() {
        let tmp = tempfile::tempdir().unwrap();
        let (work, scenes) = (tmp.path().join("runs"), tmp.path().join("scenes"));
        std::fs::create_dir_all(work.join("boxcity/scene")).unwrap();
        std::fs::write(work.join("boxcity/scene/manifest.json"), "{}").unwrap();
        std::fs::create_dir_all(&scenes).unwrap();
        let e = plan_of(&args("boxcity", "cam9"), &global(&work, &scenes)).unwrap_err();
        assert!(format!("{e:#}").contains("expected one of the presets cam1, cam2, cam3"), "{e:#}");

        std::fs::write(
            scenes.join("boxcity.toml"),
            "[area]\nname = \"x\"\n[sampling.regular]\nline_spacing_m = 120.0\n",
        )
        .unwrap();
        let mut a = args("boxcity", "cam2");
        a.strategy = Some(Trajectory::Regular);
        let plan = plan_of(&a, &global(&work, &scenes)).unwrap();
        assert_eq!(plan.config.regular.line_spacing_m, 120.0);
        assert_eq!(plan.camera.strategy, Trajectory::Regular);
        assert_eq!(plan.out_dir, work.join("boxcity/cam2"));
        let out = execute(&plan, &cs::city(), &NoProgress).unwrap();
        assert_eq!(out.poses.len(), 12);
        for f in [
            "poses.jsonl",
            "priors.jsonl",
            "colmap/cameras.txt",
            "colmap/images.txt",
            "colmap/points3D.txt",
            "camera.json",
            "sampling.json",
            "flight_plan.png",
        ] {
            assert!(plan.out_dir.join(f).is_file(), "{f} missing");
        }

        std::fs::write(scenes.join("boxcity.toml"), "[sampling.grid]\nheight_range_m = [300.0, 100.0]\n")
            .unwrap();
        let e = plan_of(&args("boxcity", "cam2"), &global(&work, &scenes)).unwrap_err();
        assert!(
            format!("{e:#}")
                .contains("boxcity.toml:\n  - grid.height_range_m = [300, 100]: impossible height range"),
            "{e:#}"
        );
    }
}
