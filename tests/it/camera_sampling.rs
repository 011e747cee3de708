//! Pose sampling on a synthetic box city: ranges, smoothness, determinism, projection, priors, errors.
//!
//! References are independent of the code under test: point-in-polygon and clearance by brute force
//! in `camera_support`, a hand-written pinhole projection from yaw/pitch, and the noise model's own
//! parameters for the prior statistics.

use crate::camera_support;

use camera_support as cs;
use insgen::camera::config::{PriorNoise, SamplingConfig};
use insgen::camera::prior::make_priors;
use insgen::camera::sample::{sample_area, write_sample, SampleOutput};
use insgen::camera::{CameraError, Pose, PoseRecord, Trajectory};
use insgen::geo::EnuFrame;
use insgen::util::NoProgress;

fn run(
    camera: &str,
    strategy: Trajectory,
    cfg: &SamplingConfig,
    count: Option<usize>,
    seed: u64,
) -> SampleOutput {
    let scene = cs::city();
    sample_area(&scene, &cs::with_strategy(camera, strategy), cfg, count, seed, &NoProgress)
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Checks shared by every strategy: inside the polygon, clearance above nearby boxes, height range.
fn check_common(out: &SampleOutput, cfg: &SamplingConfig, height_range_m: [f64; 2]) {
    assert_inside(out, &cs::area_polygon());
    for r in &out.poses {
        let c = r.pose().centre_m;
        let agl = c[2] - cs::GROUND_M;
        assert!((agl - r.height_above_ground_m).abs() < 1e-9);
        assert!(
            agl >= height_range_m[0] - 1e-9 && agl <= height_range_m[1] + 1e-9,
            "{}: {agl} m above ground outside {height_range_m:?}",
            r.name
        );
        let top = cs::tallest_near([c[0], c[1]], cfg.clearance_radius_m);
        assert!(
            c[2] >= top + cfg.clearance_m - 1e-9,
            "{}: {} m is within the clearance over {top} m",
            r.name,
            c[2]
        );
        assert!(r.geo.roll_deg.abs() < 1e-6, "{}: roll {}", r.name, r.geo.roll_deg);
        let seen = r.visible_buildings.expect("sample records the buildings in view");
        assert!(seen >= cfg.min_visible_buildings, "{}: {seen} buildings in view", r.name);
        let cells = r.covered_frame_cells.expect("sample records the cells its buildings cover");
        assert!((cfg.min_covered_cells..=16).contains(&cells), "{}: {cells} cells", r.name);
        let off = r.off_map_share.expect("sample records the share of the view beyond the map");
        assert!((0.0..=cfg.max_off_map_share).contains(&off), "{}: {off} of the view beyond the map", r.name);
    }
    assert_eq!(out.poses.len(), out.priors.len());
    assert_eq!(out.stats.accepted as usize, out.poses.len());
}

/// Every pose inside `poly`.
fn assert_inside(out: &SampleOutput, poly: &[[f64; 2]]) {
    for r in &out.poses {
        let c = r.pose().centre_m;
        assert!(cs::inside(poly, [c[0], c[1]]), "{} outside the area at {c:?}", r.name);
    }
}

mod grid {
    use super::*;

    #[test]
    fn views_with_too_few_buildings_are_counted_and_refused() {
        // No view of the box city can show 10 000 buildings: every candidate that passes the other
        // checks is refused as seeing too few, and the error says which setting to lower.
        let cfg = SamplingConfig { min_visible_buildings: 10_000, ..SamplingConfig::default() };
        let scene = cs::city();
        let e =
            sample_area(&scene, &cs::with_strategy("cam2", Trajectory::Grid), &cfg, Some(3), 1, &NoProgress)
                .expect_err("no view qualifies");
        let msg = e.to_string();
        assert!(msg.contains("min_visible_buildings (now 10000)"), "{msg}");
        // With the default, the same run succeeds and counts what it refused.
        let out = run("cam2", Trajectory::Grid, &SamplingConfig::default(), Some(3), 1);
        assert_eq!(
            out.stats.candidates,
            out.stats.accepted
                + out.stats.rejected_outside
                + out.stats.rejected_clearance
                + out.stats.rejected_visibility
                + out.stats.rejected_few_buildings
                + out.stats.rejected_filled
                + out.stats.rejected_off_map
                + out.stats.rejected_crowded,
            "{:?}",
            out.stats
        );
    }

    #[test]
    fn views_whose_buildings_crowd_into_few_cells_are_counted_and_refused() {
        // The area reaches to within 240 m of the box city's edge: lattice nodes near it looking out
        // (45° down from 200–500 m) see the city in part of the frame and open ground in the rest.
        // The default keeps them; asking for buildings in all 16 cells refuses them and counts them.
        let keep_all = run("cam2", Trajectory::Grid, &SamplingConfig::default(), None, 1);
        assert_eq!(keep_all.stats.rejected_crowded, 0);
        let cfg = SamplingConfig { min_covered_cells: 16, ..SamplingConfig::default() };
        let spread = run("cam2", Trajectory::Grid, &cfg, None, 1);
        // Each lattice node draws other heights and yaws until a view qualifies: as many views, more
        // candidates.
        assert!(spread.stats.rejected_crowded > 0, "{:?}", spread.stats);
        assert_eq!(spread.poses.len(), keep_all.poses.len());
        assert!(spread.poses.iter().all(|r| r.covered_frame_cells == Some(16)));
        assert!(keep_all.poses.iter().any(|r| r.covered_frame_cells < Some(16)));
        assert!(spread.stats.candidates > keep_all.stats.candidates, "{:?}", spread.stats);
        // From 5 km every view shows the city in part of the frame at most: none qualifies, and the
        // error names the setting.
        let mut high = SamplingConfig {
            min_building_fraction: 0.0,
            min_visible_buildings: 0,
            max_off_map_share: 1.0,
            ..cfg
        };
        high.grid.height_range_m = [5000.0, 5000.0];
        let scene = cs::city();
        let e =
            sample_area(&scene, &cs::with_strategy("cam2", Trajectory::Grid), &high, Some(3), 1, &NoProgress)
                .expect_err("no view qualifies");
        assert!(e.to_string().contains("lower min_covered_cells (now 16 of 16)"), "{e}");
        assert_eq!(
            spread.stats.candidates,
            spread.stats.accepted
                + spread.stats.rejected_outside
                + spread.stats.rejected_clearance
                + spread.stats.rejected_visibility
                + spread.stats.rejected_few_buildings
                + spread.stats.rejected_filled
                + spread.stats.rejected_off_map
                + spread.stats.rejected_crowded,
            "{:?}",
            spread.stats
        );
    }

    #[test]
    fn views_filled_by_buildings_are_counted_and_refused() {
        // Issue 40: a frame filled by roofs and walls shows almost no outline to localize from. The box
        // city's 28–46 m blocks, 12–117 m tall, stand 60 m apart; from 200–220 m, 45° down, their walls
        // fill 61–99 % of the census rays. Keeping every view, some exceed the default cap (0.8); the
        // default refuses those, counts them, and each lattice node draws other heights and yaws until
        // a view qualifies (as many views, more candidates).
        let mut low = SamplingConfig::default();
        low.grid.pitch_deg = vec![45.0];
        low.grid.height_range_m = [200.0, 220.0];
        let keep_all = run(
            "cam2",
            Trajectory::Grid,
            &SamplingConfig { max_building_fraction: 1.0, ..low.clone() },
            None,
            1,
        );
        assert_eq!(keep_all.stats.rejected_filled, 0, "{:?}", keep_all.stats);
        let share = |r: &PoseRecord| r.building_fraction.expect("sample records the share");
        assert!(keep_all.poses.iter().any(|r| share(r) > 0.9), "some view is mostly buildings");
        assert_eq!(low.max_building_fraction, 0.8, "the default cap");
        let capped = run("cam2", Trajectory::Grid, &low, None, 1);
        assert!(capped.stats.rejected_filled > 0, "{:?}", capped.stats);
        assert!(capped.poses.iter().all(|r| (0.15..=0.8).contains(&share(r))));
        assert_eq!(capped.poses.len(), keep_all.poses.len());
        assert!(capped.stats.candidates > keep_all.stats.candidates, "{:?}", capped.stats);
        assert_eq!(
            capped.stats.candidates,
            capped.stats.accepted
                + capped.stats.rejected_outside
                + capped.stats.rejected_clearance
                + capped.stats.rejected_visibility
                + capped.stats.rejected_few_buildings
                + capped.stats.rejected_filled
                + capped.stats.rejected_off_map
                + capped.stats.rejected_crowded,
            "{:?}",
            capped.stats
        );
        // A cap below every view's share: none qualifies, and the error names the setting.
        let none = SamplingConfig { min_building_fraction: 0.0, max_building_fraction: 0.01, ..low };
        let e = sample_area(
            &cs::city(),
            &cs::with_strategy("cam2", Trajectory::Grid),
            &none,
            Some(3),
            1,
            &NoProgress,
        )
        .expect_err("no view qualifies");
        assert!(e.to_string().contains("raise max_building_fraction (now 0.01)"), "{e}");
        // The default cap ([`DEFAULT_MAX_BUILDING_FRACTION`]) and the minimum: a cap below the
        // minimum is a configuration error naming both.
        assert_eq!(SamplingConfig::default().max_building_fraction, 0.8);
        let bad =
            SamplingConfig::from_scene_toml("[sampling]\nmax_building_fraction = 0.1\n", None).unwrap_err();
        assert!(bad.to_string().contains("max_building_fraction = 0.1"), "{bad}");
        assert!(bad.to_string().contains("min_building_fraction (0.15)"), "{bad}");
    }

    #[test]
    fn views_that_look_past_the_map_are_counted_and_refused() {
        // The box city ends 240–300 m beyond the area's edges: from 400–500 m, 60° off nadir, the
        // centre of a view lands 690–870 m ahead, and a view looking out from near an edge sees
        // mostly the open plain around the city. The default refuses views beyond the map for more
        // than half their rays (each lattice node draws other heights and yaws instead); 1 keeps them.
        // The box city's walls fill most views this steep (its blocks are far taller than wide apart):
        // the building-share cap is off here, this test is about the map's edge.
        let mut steep = SamplingConfig { max_building_fraction: 1.0, ..SamplingConfig::default() };
        steep.grid.pitch_deg = vec![60.0];
        steep.grid.height_range_m = [400.0, 500.0];
        let everything = SamplingConfig { max_off_map_share: 1.0, ..steep.clone() };
        let all = run("cam2", Trajectory::Grid, &everything, None, 1);
        assert_eq!(all.stats.rejected_off_map, 0, "{:?}", all.stats);
        assert!(
            all.poses.iter().any(|r| r.off_map_share.unwrap() > 0.5),
            "some view of the unrestricted lattice looks past the city"
        );
        let on_map = run("cam2", Trajectory::Grid, &steep, None, 1);
        assert!(on_map.stats.rejected_off_map > 0, "{:?}", on_map.stats);
        assert!(on_map.poses.iter().all(|r| r.off_map_share.unwrap() <= 0.5));
        assert_eq!(on_map.poses.len(), all.poses.len());
        // From 5 km every view is mostly plain: none qualifies, and the error names the setting.
        let mut high =
            SamplingConfig { min_building_fraction: 0.0, min_visible_buildings: 0, ..Default::default() };
        high.grid.height_range_m = [5000.0, 5000.0];
        let scene = cs::city();
        let e =
            sample_area(&scene, &cs::with_strategy("cam2", Trajectory::Grid), &high, Some(3), 1, &NoProgress)
                .expect_err("no view qualifies");
        assert!(e.to_string().contains("raise max_off_map_share (now 0.5)"), "{e}");
    }

    #[test]
    fn lattice_heights_view_angles() {
        let mut cfg = SamplingConfig::default();
        cfg.grid.spacing_m = 150.0;
        let out = run("cam2", Trajectory::Grid, &cfg, None, 1);
        check_common(&out, &cfg, [200.0, 500.0]);
        // Every pose sits on the 150 m lattice cell-centred in the polygon's 1200 × 900 m bounding box:
        // 8 × 6 nodes from (−525, −375) (hand computation: −600 + (1200 − 7 · 150) / 2 = −525).
        for r in &out.poses {
            let c = r.pose().centre_m;
            for (v, o) in [(c[0], -525.0), (c[1], -375.0)] {
                let k = (v - o) / 150.0;
                assert!((k - k.round()).abs() < 1e-9, "{} off the lattice: {c:?}", r.name);
            }
            assert!(
                r.geo.pitch_deg.abs() < 1e-9 || (r.geo.pitch_deg - 45.0).abs() < 1e-9,
                "pitch {}",
                r.geo.pitch_deg
            );
            assert_eq!(r.index, 0);
        }
        // Lattice nodes inside the L, counted independently; both view angles are tried at each.
        let nodes: usize = (0..8)
            .flat_map(|i| (0..6).map(move |j| [-525.0 + 150.0 * i as f64, -375.0 + 150.0 * j as f64]))
            .filter(|p| cs::inside(&cs::area_polygon(), *p))
            .count();
        let candidates = 2 * nodes;
        assert!(
            out.poses.len() <= candidates && out.poses.len() * 10 >= candidates * 8,
            "{} of {candidates}",
            out.poses.len()
        );
        let nadir = out.poses.iter().filter(|r| r.geo.pitch_deg < 1.0).count();
        assert!(nadir > 0 && nadir < out.poses.len());
        // The tower (top 260 m above ground) forces higher flights right next to it.
        for r in &out.poses {
            let c = r.pose().centre_m;
            let t = cs::TOWER_CENTRE_M;
            if ((c[0] - t[0]).powi(2) + (c[1] - t[1]).powi(2)).sqrt() < 20.0 {
                assert!(r.height_above_ground_m >= cs::TOWER_TOP_M - cs::GROUND_M + cfg.clearance_m - 1e-9);
            }
        }
    }

    #[test]
    fn count_and_yaw_set() {
        let mut cfg = SamplingConfig::default();
        cfg.grid.yaw_deg = vec![0.0, 90.0, 180.0, 270.0];
        let out = run("cam2", Trajectory::Grid, &cfg, Some(250), 5);
        assert_eq!(out.poses.len(), 250);
        check_common(&out, &cfg, [200.0, 500.0]);
        for r in &out.poses {
            let y = r.geo.yaw_deg;
            assert!([0.0, 90.0, 180.0, 270.0, 360.0].iter().any(|v| (y - v).abs() < 1e-6), "yaw {y}");
        }
        // 250 is more than the (node, view angle) pairs of the 100 m lattice (88 nodes inside the L:
        // 12 × 9 from (−550, −400), less the 5 × 4 in the cut-away corner, whose edge y = 100 holds a
        // row of nodes that counts as outside), so later rounds reuse nodes at new heights and yaws.
        let nodes = (0..12)
            .flat_map(|i| (0..9).map(move |j| [-550.0 + 100.0 * i as f64, -400.0 + 100.0 * j as f64]))
            .filter(|p| cs::inside(&cs::area_polygon(), *p))
            .count();
        assert_eq!(nodes, 88);
        assert!(out.poses.len() > 2 * nodes);
        let names: std::collections::BTreeSet<&str> = out.poses.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names.len(), 250, "frame names must be unique");
    }

    #[test]
    fn nodes_that_placed_nothing_are_not_retried() {
        // The polygon runs 1.8 km east of the box city over empty land, where no view sees enough
        // buildings. 400 and 600 views need more rounds than the nodes that see buildings give in one;
        // a node whose attempts were all refused in a round is not tried again, so the later rounds
        // cost about one candidate per view. (Retried, the empty nodes' 30 attempts each cost about 28
        // candidates per extra view.)
        let mut poly = cs::area_polygon();
        poly[1][0] = 2400.0;
        poly[2][0] = 2400.0;
        let scene = cs::city_with(poly.clone(), true);
        // Without the building-share cap: the box city's walls fill many views, and this test counts
        // the candidates of the nodes that see buildings.
        let cfg = SamplingConfig { max_building_fraction: 1.0, ..SamplingConfig::default() };
        let run = |count: usize| {
            let out = sample_area(
                &scene,
                &cs::with_strategy("cam2", Trajectory::Grid),
                &cfg,
                Some(count),
                4,
                &NoProgress,
            )
            .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(out.poses.len(), count);
            assert_inside(&out, &poly);
            out.stats.candidates
        };
        let (c400, c600) = (run(400), run(600));
        assert!(c600 - c400 < 3 * 200, "200 more views cost {} candidates", c600 - c400);
    }
}

mod regular {
    use super::*;

    #[test]
    fn survey_lines() {
        let mut cfg = SamplingConfig::default();
        cfg.regular.line_heading_deg = Some(30.0);
        let out = run("cam3", Trajectory::Regular, &cfg, None, 2);
        check_common(&out, &cfg, [400.0, 500.0]);
        assert!(out.stats.sequences >= 6, "{:?}", out.stats);
        // Across-track unit vector of lines heading 30° clockwise from north.
        let across = [30f64.to_radians().cos(), -30f64.to_radians().sin()];
        let mut offsets = Vec::new();
        let mut by_seq: std::collections::BTreeMap<u32, Vec<&PoseRecord>> = Default::default();
        for r in &out.poses {
            by_seq.entry(r.sequence).or_default().push(r);
        }
        for (seq, frames) in &by_seq {
            let first = frames[0];
            assert!(first.geo.pitch_deg.abs() < 1e-9 || (first.geo.pitch_deg - 45.0).abs() < 1e-9);
            // Yaw follows the track: 30° or 210°, constant on the line, as are height and tilt.
            assert!(
                (first.geo.yaw_deg - 30.0).abs() < 1e-6 || (first.geo.yaw_deg - 210.0).abs() < 1e-6,
                "{}",
                first.geo.yaw_deg
            );
            for w in frames.windows(2) {
                assert_eq!(w[1].index, w[0].index + 1, "sequence {seq}");
                assert!((w[1].geo.yaw_deg - w[0].geo.yaw_deg).abs() < 1e-6);
                assert!((w[1].geo.pitch_deg - w[0].geo.pitch_deg).abs() < 1e-9);
                assert!((w[1].geo.h_m - w[0].geo.h_m).abs() < 0.01, "height changes along a line");
                let (a, b) = (w[0].pose().centre_m, w[1].pose().centre_m);
                // The next frame is 50 m ahead in the flight (yaw) direction.
                let yaw = w[0].geo.yaw_deg.to_radians();
                assert!(
                    (b[0] - a[0] - 50.0 * yaw.sin()).abs() < 1e-6
                        && (b[1] - a[1] - 50.0 * yaw.cos()).abs() < 1e-6
                );
            }
            let c = first.pose().centre_m;
            offsets.push(c[0] * across[0] + c[1] * across[1]);
        }
        // Lines are 150 m apart across track.
        offsets.sort_by(f64::total_cmp);
        for w in offsets.windows(2) {
            let k = (w[1] - w[0]) / 150.0;
            assert!((k - k.round()).abs() < 1e-6, "line offsets {offsets:?}");
        }
        // Both view angles were flown.
        assert!(
            out.poses.iter().any(|r| r.geo.pitch_deg < 1.0)
                && out.poses.iter().any(|r| r.geo.pitch_deg > 44.0)
        );
    }

    #[test]
    fn count_repeats_passes() {
        let cfg = SamplingConfig::default();
        let out = run("cam3", Trajectory::Regular, &cfg, Some(400), 3);
        assert_eq!(out.poses.len(), 400);
        check_common(&out, &cfg, [400.0, 500.0]);
    }

    #[test]
    fn a_pass_that_places_nothing_does_not_end_the_survey() {
        // A 300 × 200 m area and strict views (60 % building pixels): two lines of a few frames each
        // per pass, so a pass whose shifted lines see too little places no run of two frames. The
        // sampler flies on while passes place frames within 16 fruitless passes and the budget
        // (before, the first fruitless pass ended the run at 12 of 40 frames).
        let poly = vec![[-150.0, -100.0], [150.0, -100.0], [150.0, 100.0], [-150.0, 100.0]];
        let scene = cs::city_with(poly.clone(), true);
        let cfg = SamplingConfig { min_building_fraction: 0.6, ..SamplingConfig::default() };
        let out = sample_area(
            &scene,
            &cs::with_strategy("cam3", Trajectory::Regular),
            &cfg,
            Some(40),
            1,
            &NoProgress,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(out.poses.len(), 40);
        check_common(&out, &cfg, [400.0, 500.0]);
        assert_inside(&out, &poly);
        // More passes than one per view angle were flown: lines off the centred layout.
        let across: std::collections::BTreeSet<i64> =
            out.poses.iter().map(|r| (r.pose().centre_m[1] * 1000.0).round() as i64).collect();
        assert!(across.len() > 2, "line offsets {across:?}");
    }
}

mod irregular {
    use super::*;

    fn wrap(d: f64) -> f64 {
        (d + 180.0).rem_euclid(360.0) - 180.0
    }

    #[test]
    fn smooth_bounded_flights() {
        let cfg = SamplingConfig::default();
        let ic = &cfg.irregular;
        let out = run("cam1", Trajectory::Irregular, &cfg, Some(400), 4);
        assert_eq!(out.poses.len(), 400);
        check_common(&out, &cfg, ic.height_range_m);
        let mut pitch_lo = f64::INFINITY;
        let mut pitch_hi = f64::NEG_INFINITY;
        let mut prev_turn: Option<(u32, f64)> = None;
        for r in &out.poses {
            assert!(r.geo.pitch_deg >= -1e-9 && r.geo.pitch_deg <= 70.0 + 1e-9, "pitch {}", r.geo.pitch_deg);
            pitch_lo = pitch_lo.min(r.geo.pitch_deg);
            pitch_hi = pitch_hi.max(r.geo.pitch_deg);
        }
        for w in out.poses.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            if a.sequence != b.sequence {
                prev_turn = None;
                continue;
            }
            assert_eq!(b.index, a.index + 1);
            let (ca, cb) = (a.pose().centre_m, b.pose().centre_m);
            let step = ((cb[0] - ca[0]).powi(2) + (cb[1] - ca[1]).powi(2)).sqrt();
            assert!((step - ic.frame_spacing_m).abs() < 1e-6, "speed: {step} m per frame");
            assert!((cb[2] - ca[2]).abs() <= ic.max_climb_m_per_frame + 1e-9, "climb {}", cb[2] - ca[2]);
            assert!((b.geo.pitch_deg - a.geo.pitch_deg).abs() <= ic.max_pitch_deg_per_frame + 1e-9);
            let turn = wrap(b.geo.yaw_deg - a.geo.yaw_deg);
            assert!(turn.abs() <= ic.max_turn_deg_per_frame + 1e-6, "turn {turn}° per frame");
            // The displacement points along the new heading (the camera looks where it flies).
            let dir = (cb[0] - ca[0]).atan2(cb[1] - ca[1]).to_degrees();
            assert!(wrap(dir - b.geo.yaw_deg).abs() < 1e-6, "heading {} vs track {dir}", b.geo.yaw_deg);
            if let Some((seq, t)) = prev_turn {
                if seq == a.sequence {
                    assert!(
                        (turn - t).abs() <= ic.max_turn_change_deg_per_frame + 1e-6,
                        "turn rate jumps {t} → {turn}"
                    );
                }
            }
            prev_turn = Some((a.sequence, turn));
        }
        // The tilt sweeps (nearly) the whole configured range.
        assert!(pitch_lo < 10.0 && pitch_hi > 60.0, "tilt range seen: [{pitch_lo}, {pitch_hi}]");
        // Sequences are runs of at least min_sequence_frames (the last may be cut by --count).
        let mut lens: std::collections::BTreeMap<u32, usize> = Default::default();
        for r in &out.poses {
            *lens.entry(r.sequence).or_default() += 1;
        }
        let last = *lens.keys().last().unwrap();
        for (s, n) in &lens {
            assert!(*s == last || *n >= ic.min_sequence_frames as usize, "sequence {s} has {n} frames");
        }
    }
}

mod determinism {
    use super::*;

    fn files(dir: &std::path::Path) -> Vec<(String, Vec<u8>)> {
        let mut v = Vec::new();
        for sub in ["", "colmap"] {
            let d = dir.join(sub);
            let mut names: Vec<_> =
                std::fs::read_dir(&d).unwrap().filter_map(|e| e.ok()).map(|e| e.path()).collect();
            names.sort();
            for p in names.into_iter().filter(|p| p.is_file()) {
                v.push((p.strip_prefix(dir).unwrap().display().to_string(), std::fs::read(&p).unwrap()));
            }
        }
        v
    }

    #[test]
    fn same_seed_same_bytes() {
        let scene = cs::city();
        let cfg = SamplingConfig::default();
        let cam = cs::preset("cam1");
        let tmp = tempfile::tempdir().unwrap();
        let mut runs = Vec::new();
        for (k, seed) in [(0, 11u64), (1, 11), (2, 12)] {
            let out = sample_area(&scene, &cam, &cfg, Some(60), seed, &NoProgress).unwrap();
            let dir = tmp.path().join(format!("run{k}"));
            let written = write_sample(&dir, &scene, &out).unwrap();
            assert_eq!(written.len(), 8);
            runs.push(files(&dir));
        }
        assert_eq!(runs[0].len(), 8);
        assert_eq!(runs[0], runs[1], "same seed must give byte-identical files");
        let poses = |r: &Vec<(String, Vec<u8>)>| r.iter().find(|f| f.0 == "poses.jsonl").unwrap().1.clone();
        assert_ne!(poses(&runs[0]), poses(&runs[2]), "another seed must give other poses");
    }

    #[test]
    fn prior_noise_does_not_move_poses() {
        let scene = cs::city();
        let mut cfg = SamplingConfig::default();
        let a = sample_area(&scene, &cs::preset("cam2"), &cfg, Some(30), 3, &NoProgress).unwrap();
        cfg.prior.sigma_enu_m = [20.0, 20.0, 20.0];
        let b = sample_area(&scene, &cs::preset("cam2"), &cfg, Some(30), 3, &NoProgress).unwrap();
        assert_eq!(a.poses, b.poses);
        assert_ne!(a.priors, b.priors);
        for (p, q) in a.poses.iter().zip(&a.priors) {
            assert_eq!((&p.name, p.sequence, p.index), (&q.name, q.sequence, q.index));
        }
    }
}

mod projection {
    use super::*;

    /// Hand-written pinhole projection from yaw/pitch (roll 0), independent of `camera::pose`:
    /// forward f = (sin ψ sin θ, cos ψ sin θ, −cos θ), right r = (cos ψ, −sin ψ, 0), down d = f × r.
    /// `k` = [fx, fy, cx, cy] in pixels.
    fn pinhole(k: [f64; 4], yaw_deg: f64, pitch_deg: f64, c: [f64; 3], p: [f64; 3]) -> [f64; 2] {
        let [fx, fy, cx, cy] = k;
        let (sy, cyw) = yaw_deg.to_radians().sin_cos();
        let (sp, cp) = pitch_deg.to_radians().sin_cos();
        let f = [sy * sp, cyw * sp, -cp];
        let r = [cyw, -sy, 0.0];
        let d = [f[1] * r[2] - f[2] * r[1], f[2] * r[0] - f[0] * r[2], f[0] * r[1] - f[1] * r[0]];
        let q = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
        let dot = |a: [f64; 3]| a[0] * q[0] + a[1] * q[1] + a[2] * q[2];
        [cx + fx * dot(r) / dot(f), cy + fy * dot(d) / dot(f)]
    }

    #[test]
    fn nadir_corner_by_hand() {
        // cam2 straight down from 500 m over the origin, north up; roof corner (10, 20, 100):
        // depth 400 m, u = 960 + f · 10/400, v = 540 − f · 20/400, f = 960 / tan 12.5°.
        let cam = cs::preset("cam2");
        let pose = Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 500.0]);
        let f = 960.0 / 12.5f64.to_radians().tan();
        let uv = cam.project_enu(&pose, [10.0, 20.0, 100.0]).unwrap();
        assert!(
            (uv[0] - (960.0 + f * 0.025)).abs() < 1e-9 && (uv[1] - (540.0 - f * 0.05)).abs() < 1e-9,
            "{uv:?}"
        );
        assert!(cam.project_enu(&pose, [0.0, 0.0, 600.0]).is_none(), "a point above the camera is behind it");
    }

    #[test]
    fn sampled_views_project_building_corners_like_a_hand_pinhole() {
        let cfg = SamplingConfig::default();
        let out = run("cam1", Trajectory::Irregular, &cfg, Some(40), 9);
        let cam = cs::preset("cam1");
        let k = cam.intrinsics;
        let index = insgen::camera::visibility::BuildingIndex::new(&cs::city().buildings);
        let mut checked = 0;
        for r in &out.poses {
            let pose = r.pose();
            for (lo, hi) in cs::boxes() {
                let corner = [hi[0], hi[1], hi[2]];
                let Some(uv) = cam.project_enu(&pose, corner) else { continue };
                if !(0.0..k.width_px as f64).contains(&uv[0]) || !(0.0..k.height_px as f64).contains(&uv[1]) {
                    continue;
                }
                let kk = [k.fx_px, k.fy_px, k.cx_px, k.cy_px];
                let hand = pinhole(kk, r.geo.yaw_deg, r.geo.pitch_deg, pose.centre_m.to_array(), corner);
                assert!(
                    (uv[0] - hand[0]).abs() < 1e-6 && (uv[1] - hand[1]).abs() < 1e-6,
                    "{uv:?} vs {hand:?}"
                );
                // The viewing ray through the pixel of the box centre's top hits a building box.
                let top_centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, hi[2]];
                if let Some(px) = cam.project_enu(&pose, top_centre) {
                    let d = insgen::camera::visibility::pixel_ray_enu(&k, &pose, px[0], px[1]);
                    assert!(index.ray_hits_building(pose.centre_m.to_array(), d));
                }
                checked += 1;
            }
        }
        assert!(checked > 100, "only {checked} corners in view");
    }
}

mod priors {
    use super::*;

    fn mean_sd(v: &[f64]) -> (f64, f64) {
        let n = v.len() as f64;
        let m = v.iter().sum::<f64>() / n;
        (m, (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt())
    }

    #[test]
    fn statistics_match_the_noise_model() {
        // 2000 ground-truth poses at 45° tilt (so yaw/pitch/roll are far from the nadir singularity).
        let enu = EnuFrame::new(cs::origin());
        let k = cs::preset("cam2").intrinsics;
        let truth: Vec<PoseRecord> = (0..2000)
            .map(|i| {
                let pose =
                    Pose::from_ypr_deg((i as f64 * 37.0) % 360.0, 45.0, 0.0, [i as f64 % 300.0, 50.0, 400.0]);
                PoseRecord::new(
                    format!("f{i}"),
                    "a",
                    "cam2",
                    Trajectory::Grid,
                    i,
                    0,
                    k,
                    &pose,
                    &enu,
                    cs::GROUND_M,
                )
            })
            .collect();
        let noise = PriorNoise {
            sigma_enu_m: [5.0, 8.0, 3.0],
            sigma_ypr_deg: [2.0, 1.0, 0.5],
            bias_enu_m: [1.0, -2.0, 0.5],
            bias_ypr_deg: [0.5, 0.0, -0.3],
        };
        let prior = make_priors(&truth, &noise, 42, &enu, cs::GROUND_M);
        let mut d: [Vec<f64>; 6] = Default::default();
        for (t, p) in truth.iter().zip(&prior) {
            let (ct, cp) = (t.pose().centre_m, p.pose().centre_m);
            for a in 0..3 {
                d[a].push(cp[a] - ct[a]);
            }
            d[3].push((p.geo.yaw_deg - t.geo.yaw_deg + 180.0).rem_euclid(360.0) - 180.0);
            d[4].push(p.geo.pitch_deg - t.geo.pitch_deg);
            d[5].push(p.geo.roll_deg - t.geo.roll_deg);
        }
        let sigma = [noise.sigma_enu_m, noise.sigma_ypr_deg].concat();
        let bias = [noise.bias_enu_m, noise.bias_ypr_deg].concat();
        for a in 0..6 {
            let (m, s) = mean_sd(&d[a]);
            // Standard error of the mean σ/√2000 = 2.2 % of σ: allow 4 of them; σ within 5 %.
            assert!(
                (m - bias[a]).abs() < 4.0 * sigma[a] / 2000f64.sqrt(),
                "axis {a}: mean {m} vs bias {}",
                bias[a]
            );
            assert!((s / sigma[a] - 1.0).abs() < 0.05, "axis {a}: sd {s} vs σ {}", sigma[a]);
        }
    }
}

mod errors {
    use super::*;

    #[test]
    fn empty_polygon() {
        let scene = cs::city_with(vec![[0.0, 0.0], [10.0, 0.0]], false);
        let e = sample_area(&scene, &cs::preset("cam2"), &SamplingConfig::default(), None, 0, &NoProgress)
            .unwrap_err();
        assert!(matches!(e, CameraError::Area { .. }), "{e}");
        assert!(e.to_string().contains("2 vertices"), "{e}");
    }

    #[test]
    fn impossible_height_range() {
        let mut cfg = SamplingConfig::default();
        cfg.irregular.height_range_m = [500.0, 200.0];
        let e = sample_area(&cs::city(), &cs::preset("cam1"), &cfg, Some(5), 0, &NoProgress).unwrap_err();
        assert_eq!(
            e.to_string(),
            "invalid [sampling] configuration:\n  - irregular.height_range_m = [500, 200]: impossible height range: \
             the minimum is above the maximum"
        );
    }

    #[test]
    fn heights_below_the_buildings_are_reported() {
        // Every point is within 40 m of a block at least 12 m tall: with 50 m clearance no height up to
        // 60 m above ground is allowed anywhere.
        let mut cfg = SamplingConfig::default();
        cfg.grid.height_range_m = [20.0, 60.0];
        let e = sample_area(&cs::city(), &cs::preset("cam2"), &cfg, Some(10), 0, &NoProgress).unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, CameraError::TooFewPoses { placed: 0, wanted: 10, .. }), "{msg}");
        assert!(
            msg.contains("too close to buildings") && msg.contains("raise the grid height range"),
            "{msg}"
        );
    }

    #[test]
    fn no_grid_node_fits() {
        let mut cfg = SamplingConfig::default();
        cfg.grid.spacing_m = 100.0;
        cfg.grid.margin_m = 500.0;
        let e = sample_area(&cs::city(), &cs::preset("cam2"), &cfg, None, 0, &NoProgress).unwrap_err();
        assert!(e.to_string().contains("no grid node fits"), "{e}");
    }
}
