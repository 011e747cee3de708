//! The procedural demo city: determinism, size, geometric validity (planar, open rings, watertight
//! extrusions, no overlapping footprints), courtyards, shared walls, heights, the CRS and origin, and a
//! top-view PNG for eyeballing (written to `target/test-output/`, not committed).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use insgen::geo::AxisConvention;
use insgen::lod::{Frame, Geometry, Polygon, SourceBuilding, SourceModel};
use insgen::scene::procedural::{default_spec, generate, PlaneOrigin, ProceduralSpec, DEMO_CRS};

fn city() -> SourceModel {
    generate(&default_spec(), PlaneOrigin::TOKYO_BAY).unwrap()
}

fn polygons(b: &SourceBuilding) -> &[Polygon] {
    match &b.geometry {
        Geometry::Polygons(p) => p,
        Geometry::Mesh(_) => panic!("{}: expected LoD1 polygons", b.source_id),
    }
}

fn rings(p: &Polygon) -> impl Iterator<Item = &Vec<[f64; 3]>> {
    std::iter::once(&p.exterior).chain(p.interiors.iter())
}

/// Newell's normal of a ring (not normalised; its length is twice the area).
fn newell(r: &[[f64; 3]]) -> [f64; 3] {
    let mut n = [0.0; 3];
    for i in 0..r.len() {
        let (a, b) = (r[i], r[(i + 1) % r.len()]);
        n[0] += (a[1] - b[1]) * (a[2] + b[2]);
        n[1] += (a[2] - b[2]) * (a[0] + b[0]);
        n[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    n
}

fn is_wall(p: &Polygon) -> bool {
    p.exterior.len() == 4
        && p.exterior[0][2] == p.exterior[1][2]
        && p.exterior[2][2] == p.exterior[3][2]
        && p.exterior[0][2] < p.exterior[2][2]
}

/// Even-odd point-in-polygon over all rings (half-open crossing rule, so a point on an edge shared by
/// two footprints falls in exactly one of them).
fn inside(p: &Polygon, x: f64, y: f64) -> bool {
    let mut c = false;
    for r in rings(p) {
        for i in 0..r.len() {
            let (a, b) = (r[i], r[(i + 1) % r.len()]);
            if (a[1] > y) != (b[1] > y) && x < a[0] + (y - a[1]) * (b[0] - a[0]) / (b[1] - a[1]) {
                c = !c;
            }
        }
    }
    c
}

/// The roof polygon (the highest horizontal face).
fn roof(b: &SourceBuilding) -> &Polygon {
    polygons(b)
        .iter()
        .filter(|p| p.exterior.iter().all(|v| v[2] == p.exterior[0][2]))
        .max_by(|a, b| a.exterior[0][2].total_cmp(&b.exterior[0][2]))
        .unwrap()
}

mod determinism {
    use super::*;

    #[test]
    fn same_spec_same_city_and_other_seed_other_city() {
        let a = city();
        let b = city();
        assert_eq!(a, b);
        let c = generate(&ProceduralSpec { seed: 99, ..default_spec() }, PlaneOrigin::TOKYO_BAY).unwrap();
        assert_ne!(a.buildings, c.buildings);
    }

    #[test]
    fn source_ids_are_zero_padded_unique_and_in_order() {
        let m = city();
        let ids: Vec<&str> = m.buildings.iter().map(|b| b.source_id.as_str()).collect();
        assert_eq!(ids[0], "demo_b0001");
        let mut sorted = ids.clone();
        sorted.sort();
        assert_eq!(sorted, ids, "sorting by source_id keeps the generation order");
        assert_eq!(ids.iter().collect::<BTreeSet<_>>().len(), ids.len());
        // More than 9999 buildings widen the padding, so sorting still holds.
        let big = generate(
            &ProceduralSpec {
                blocks_x: 50,
                blocks_y: 25,
                tower_blocks: 0,
                plaza_blocks: 0,
                ..default_spec()
            },
            PlaneOrigin::TOKYO_BAY,
        )
        .unwrap();
        assert!(big.buildings.len() > 9999, "{} buildings", big.buildings.len());
        assert_eq!(big.buildings[0].source_id, "demo_b00001");
        assert!(big.buildings.windows(2).all(|w| w[0].source_id < w[1].source_id));
    }
}

mod size_and_frame {
    use super::*;

    #[test]
    fn default_city_has_hundreds_of_buildings() {
        let m = city();
        let faces: usize = m.buildings.iter().map(|b| polygons(b).len()).sum();
        eprintln!("default demo city: {} buildings, {} faces", m.buildings.len(), faces);
        assert!((300..=1500).contains(&m.buildings.len()), "{} buildings", m.buildings.len());
        assert_eq!(m.stats.faces, faces as u64);
    }

    #[test]
    fn coordinates_are_epsg_6677_east_north_around_the_origin() {
        let m = city();
        assert_eq!(m.frame, Frame::Crs { name: Some(DEMO_CRS.to_string()), axes: AxisConvention::EastNorth });
        let o = PlaneOrigin::TOKYO_BAY;
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for b in &m.buildings {
            for p in polygons(b) {
                for r in rings(p) {
                    for v in r {
                        for k in 0..3 {
                            lo[k] = lo[k].min(v[k]);
                            hi[k] = hi[k].max(v[k]);
                        }
                    }
                }
            }
        }
        // 10 blocks of ≤ 96 m plus streets: well within ±1 km of the origin, centred on it.
        for (k, c) in [(0, o.easting_m), (1, o.northing_m)] {
            assert!(lo[k] > c - 1000.0 && hi[k] < c + 1000.0, "axis {k}: [{}, {}] vs {c}", lo[k], hi[k]);
            assert!(((lo[k] + hi[k]) / 2.0 - c).abs() < 100.0, "axis {k} is not centred");
        }
        assert_eq!(lo[2], default_spec().ground_height_m);
    }

    /// The documented geodetic position of the origin, checked with pyproj (EPSG:6677 → EPSG:4326).
    #[test]
    fn tokyo_bay_origin_is_where_the_doc_says() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let python = std::env::var_os("INSGEN_PYTHON")
            .map(PathBuf::from)
            .unwrap_or_else(|| root.join(".venv/bin/python"));
        if !python.exists() {
            if std::env::var("CI").map(|v| v == "true").unwrap_or(false) {
                panic!("CI: no Python at {} (set INSGEN_PYTHON)", python.display());
            }
            eprintln!("skipping: no Python at {} (set INSGEN_PYTHON)", python.display());
            return;
        }
        let o = PlaneOrigin::TOKYO_BAY;
        // EPSG:6677's authority order is (X northing, Y easting).
        let code = format!(
            "from pyproj import Transformer\n\
             t = Transformer.from_crs('EPSG:6677', 'EPSG:4326')\n\
             lat, lon = t.transform({}, {})\n\
             print(repr(lat), repr(lon))",
            o.northing_m, o.easting_m
        );
        let out = std::process::Command::new(&python).arg("-c").arg(code).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let text = String::from_utf8(out.stdout).unwrap();
        let v: Vec<f64> = text.split_whitespace().map(|s| s.parse().unwrap()).collect();
        // The values quoted in PlaneOrigin::TOKYO_BAY's doc, to their 6 decimals (≈ 0.1 m).
        assert!((v[0] - 35.654777).abs() < 1e-6, "lat {}", v[0]);
        assert!((v[1] - 139.795783).abs() < 1e-6, "lon {}", v[1]);
    }
}

mod validity {
    use super::*;

    #[test]
    fn every_polygon_is_planar_open_and_non_degenerate() {
        let m = city();
        for b in &m.buildings {
            for (k, p) in polygons(b).iter().enumerate() {
                let n = newell(&p.exterior);
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                assert!(len > 1.0, "{} face {k}: area {} m²", b.source_id, len / 2.0);
                let unit = n.map(|c| c / len);
                let d0: f64 = (0..3).map(|i| unit[i] * p.exterior[0][i]).sum();
                for r in rings(p) {
                    assert!(r.len() >= 3, "{} face {k}: {} points", b.source_id, r.len());
                    assert_ne!(r.first(), r.last(), "{} face {k}: rings are stored open", b.source_id);
                    let distinct: BTreeSet<[u64; 3]> = r.iter().map(|v| v.map(f64::to_bits)).collect();
                    assert_eq!(distinct.len(), r.len(), "{} face {k}: repeated vertex", b.source_id);
                    for v in r {
                        assert!(v.iter().all(|c| c.is_finite()));
                        // Off-plane distance: 1 µm (f64 rounding of rotated coordinates is ~1e-10 m).
                        let d: f64 = (0..3).map(|i| unit[i] * v[i]).sum::<f64>() - d0;
                        assert!(
                            d.abs() < 1e-6,
                            "{} face {k}: vertex {v:?} is {d} m off the plane",
                            b.source_id
                        );
                    }
                    // No collinear consecutive triples (they would be degenerate wall quads later).
                    for i in 0..r.len() {
                        let (a, bb, c) = (r[i], r[(i + 1) % r.len()], r[(i + 2) % r.len()]);
                        let [a, bb, c] = [a, bb, c].map(glam::DVec3::from);
                        let s = (bb - a).cross(c - bb).length();
                        assert!(s > 1e-6, "{} face {k}: collinear vertices at {i}", b.source_id);
                    }
                }
                // Holes wind against the exterior (same plane, opposite normals).
                for h in &p.interiors {
                    let nh = newell(h);
                    assert!(
                        (0..3).map(|i| nh[i] * n[i]).sum::<f64>() < 0.0,
                        "{} face {k}: hole winding",
                        b.source_id
                    );
                }
            }
        }
    }

    /// Every building is a closed, consistently oriented surface: each directed edge of every ring is
    /// matched by exactly one opposite edge within the same building.
    #[test]
    fn every_building_is_watertight_with_outward_normals() {
        let m = city();
        for b in &m.buildings {
            let mut edges: BTreeMap<([u64; 3], [u64; 3]), i32> = BTreeMap::new();
            for p in polygons(b) {
                for r in rings(p) {
                    for i in 0..r.len() {
                        let (a, c) = (r[i].map(f64::to_bits), r[(i + 1) % r.len()].map(f64::to_bits));
                        *edges.entry((a, c)).or_default() += 1;
                    }
                }
            }
            for ((a, c), n) in &edges {
                assert_eq!(*n, 1, "{}: directed edge used {n} times", b.source_id);
                assert_eq!(edges.get(&(*c, *a)), Some(&1), "{}: open edge", b.source_id);
            }
            // Outward: the roof faces up, the ground down.
            let polys = polygons(b);
            let top = polys.iter().map(|p| p.exterior[0][2]).fold(f64::MIN, f64::max);
            let bottom = polys.iter().map(|p| p.exterior[0][2]).fold(f64::MAX, f64::min);
            for p in polys.iter().filter(|p| !is_wall(p)) {
                let nz = newell(&p.exterior)[2];
                if p.exterior[0][2] == top {
                    assert!(nz > 0.0, "{}: roof faces down", b.source_id);
                } else {
                    assert_eq!(p.exterior[0][2], bottom);
                    assert!(nz < 0.0, "{}: ground faces up", b.source_id);
                }
            }
        }
    }

    #[test]
    fn footprints_do_not_overlap() {
        let m = city();
        // Sample the plane every 0.5 m: no sample may lie in two footprints.
        let roofs: Vec<&Polygon> = m.buildings.iter().map(roof).collect();
        let bbox: Vec<[f64; 4]> = roofs
            .iter()
            .map(|p| {
                let xs = p.exterior.iter().map(|v| v[0]);
                let ys = p.exterior.iter().map(|v| v[1]);
                [
                    xs.clone().fold(f64::MAX, f64::min),
                    ys.clone().fold(f64::MAX, f64::min),
                    xs.fold(f64::MIN, f64::max),
                    ys.fold(f64::MIN, f64::max),
                ]
            })
            .collect();
        let (x0, y0) = (
            bbox.iter().map(|b| b[0]).fold(f64::MAX, f64::min),
            bbox.iter().map(|b| b[1]).fold(f64::MAX, f64::min),
        );
        let (x1, y1) = (
            bbox.iter().map(|b| b[2]).fold(f64::MIN, f64::max),
            bbox.iter().map(|b| b[3]).fold(f64::MIN, f64::max),
        );
        let step = 0.5;
        let (nx, ny) = (((x1 - x0) / step) as usize + 1, ((y1 - y0) / step) as usize + 1);
        let mut owner = vec![u32::MAX; nx * ny];
        for (k, (p, bb)) in roofs.iter().zip(&bbox).enumerate() {
            let (i0, i1) = (((bb[0] - x0) / step) as usize, (((bb[2] - x0) / step) as usize + 1).min(nx));
            let (j0, j1) = (((bb[1] - y0) / step) as usize, (((bb[3] - y0) / step) as usize + 1).min(ny));
            for j in j0..j1 {
                for i in i0..i1 {
                    let (x, y) = (x0 + (i as f64 + 0.25) * step, y0 + (j as f64 + 0.25) * step);
                    if inside(p, x, y) {
                        let o = &mut owner[j * nx + i];
                        assert!(
                            *o == u32::MAX,
                            "{} and {} overlap at ({x}, {y})",
                            m.buildings[*o as usize].source_id,
                            m.buildings[k].source_id
                        );
                        *o = k as u32;
                    }
                }
            }
        }
    }
}

mod city_features {
    use super::*;

    #[test]
    fn courtyard_buildings_have_holes_in_roof_and_ground_and_inner_walls() {
        let m = city();
        let mut courtyards = 0;
        for b in &m.buildings {
            let polys = polygons(b);
            let holed: Vec<&Polygon> = polys.iter().filter(|p| !p.interiors.is_empty()).collect();
            if holed.is_empty() {
                continue;
            }
            courtyards += 1;
            assert_eq!(holed.len(), 2, "{}: roof and ground carry the hole", b.source_id);
            let ring_edges: usize = rings(holed[0]).map(Vec::len).sum();
            let walls = polys.iter().filter(|p| is_wall(p)).count();
            assert_eq!(walls, ring_edges, "{}: one wall per edge of outer and inner rings", b.source_id);
            // The inner walls face the courtyard: their normal points towards the hole's centroid.
            let hole = &holed[0].interiors[0];
            let c =
                hole.iter().fold([0.0; 2], |a, v| [a[0] + v[0], a[1] + v[1]]).map(|s| s / hole.len() as f64);
            let hole_xy: BTreeSet<[u64; 2]> = hole.iter().map(|v| [v[0].to_bits(), v[1].to_bits()]).collect();
            for w in polys.iter().filter(|p| is_wall(p)) {
                let on_hole = w.exterior.iter().all(|v| hole_xy.contains(&[v[0].to_bits(), v[1].to_bits()]));
                if on_hole {
                    let n = newell(&w.exterior);
                    let to_c = [c[0] - w.exterior[0][0], c[1] - w.exterior[0][1]];
                    assert!(n[0] * to_c[0] + n[1] * to_c[1] > 0.0, "{}: inner wall faces away", b.source_id);
                }
            }
        }
        eprintln!("{courtyards} courtyard buildings");
        assert!(courtyards >= 3, "{courtyards} courtyard buildings");
    }

    #[test]
    fn terraced_neighbours_share_wall_faces() {
        let m = city();
        // Base segment of each wall (bit patterns) → (building, wall height).
        type Segment = ([u64; 2], [u64; 2]);
        let mut walls: BTreeMap<Segment, Vec<(usize, f64)>> = BTreeMap::new();
        for (k, b) in m.buildings.iter().enumerate() {
            for w in polygons(b).iter().filter(|p| is_wall(p)) {
                let a = [w.exterior[0][0].to_bits(), w.exterior[0][1].to_bits()];
                let c = [w.exterior[1][0].to_bits(), w.exterior[1][1].to_bits()];
                walls.entry((a, c)).or_default().push((k, w.exterior[2][2]));
            }
        }
        let (mut shared, mut identical) = (0, 0);
        let mut pairs = BTreeSet::new();
        for ((a, c), here) in &walls {
            if let Some(there) = walls.get(&(*c, *a)) {
                for &(k1, h1) in here {
                    for &(k2, h2) in there {
                        assert_ne!(k1, k2, "a building with two opposite walls on one segment");
                        shared += 1;
                        if h1 == h2 {
                            identical += 1;
                        }
                        pairs.insert((k1.min(k2), k1.max(k2)));
                    }
                }
            }
        }
        eprintln!(
            "{} shared wall faces ({} of equal height) between {} pairs",
            shared / 2,
            identical / 2,
            pairs.len()
        );
        assert!(pairs.len() >= 100, "{} neighbour pairs share a wall", pairs.len());
        assert!(identical / 2 >= 20, "{} fully coincident wall faces (row houses)", identical / 2);
    }

    #[test]
    fn heights_span_low_rise_to_towers() {
        let m = city();
        let spec = default_spec();
        let mut heights = Vec::new();
        for b in &m.buildings {
            let zs = polygons(b).iter().flat_map(|p| p.exterior.iter().map(|v| v[2]));
            let (lo, hi) = zs.fold((f64::MAX, f64::MIN), |(l, h), z| (l.min(z), h.max(z)));
            let h = hi - lo;
            assert_eq!(lo, spec.ground_height_m, "{}: base on the ground", b.source_id);
            assert_eq!(Some(h), b.measured_height_m, "{}", b.source_id);
            assert_eq!(b.lod, "1");
            heights.push(h);
        }
        let towers = heights.iter().filter(|&&h| h >= 80.0).count();
        let low = heights.iter().filter(|&&h| h <= 25.0).count();
        let mid = heights.iter().filter(|&&h| h > 25.0 && h < 80.0).count();
        eprintln!(
            "{low} low-rise, {mid} mid-rise, {towers} towers; max {} m",
            heights.iter().fold(0.0f64, |a, &b| a.max(b))
        );
        assert!(heights.iter().all(|&h| (3.0..=200.0).contains(&h)));
        assert!(towers >= spec.tower_blocks as usize && towers <= 2 * spec.tower_blocks as usize);
        assert!(low > heights.len() / 2, "mostly low-rise: {low} of {}", heights.len());
        assert!(mid >= 30, "{mid} mid-rise");
    }
}

mod top_view {
    use super::*;

    /// Area of the convex hull (Andrew's monotone chain), m².
    fn hull_area(pts: &[[f64; 2]]) -> f64 {
        let mut p = pts.to_vec();
        p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
        let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
            (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
        };
        let mut hull: Vec<[f64; 2]> = Vec::new();
        for pass in 0..2 {
            let start = hull.len();
            let it: Box<dyn Iterator<Item = &[f64; 2]>> =
                if pass == 0 { Box::new(p.iter()) } else { Box::new(p.iter().rev()) };
            for &q in it {
                while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0 {
                    hull.pop();
                }
                hull.push(q);
            }
            hull.pop();
        }
        (0..hull.len())
            .map(|i| {
                let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
                a[0] * b[1] - b[0] * a[1]
            })
            .sum::<f64>()
            / 2.0
    }

    #[test]
    fn hull_of_a_square_with_inner_points() {
        let pts = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0], [1.0, 1.0], [0.5, 1.5], [1.0, 0.0]];
        assert_eq!(hull_area(&pts), 4.0);
    }

    /// Renders the city from above (1 px = 0.5 m; roofs shaded by height, outlines dark, streets grey)
    /// with the test's own rasteriser and writes `target/test-output/procedural_topview.png`.
    #[test]
    fn writes_a_top_view_png() {
        let m = city();
        let roofs: Vec<(&Polygon, f64)> =
            m.buildings.iter().map(|b| (roof(b), b.measured_height_m.unwrap())).collect();
        let all = roofs.iter().flat_map(|(p, _)| p.exterior.iter());
        let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for v in all {
            x0 = x0.min(v[0]);
            y0 = y0.min(v[1]);
            x1 = x1.max(v[0]);
            y1 = y1.max(v[1]);
        }
        let step = 1.0;
        let margin = 10.0;
        let (w, h) = (((x1 - x0 + 2.0 * margin) / step) as usize, ((y1 - y0 + 2.0 * margin) / step) as usize);
        let mut owner = vec![u32::MAX; w * h];
        for (k, (p, _)) in roofs.iter().enumerate() {
            let xs = p.exterior.iter().map(|v| v[0]);
            let ys = p.exterior.iter().map(|v| v[1]);
            let (bx0, bx1) = (xs.clone().fold(f64::MAX, f64::min), xs.fold(f64::MIN, f64::max));
            let (by0, by1) = (ys.clone().fold(f64::MAX, f64::min), ys.fold(f64::MIN, f64::max));
            let (i0, i1) = (((bx0 - x0 + margin) / step) as usize, ((bx1 - x0 + margin) / step) as usize + 1);
            let (j0, j1) = (((by0 - y0 + margin) / step) as usize, ((by1 - y0 + margin) / step) as usize + 1);
            for j in j0..j1.min(h) {
                for i in i0..i1.min(w) {
                    let (x, y) =
                        (x0 - margin + (i as f64 + 0.5) * step, y0 - margin + (j as f64 + 0.5) * step);
                    if inside(p, x, y) {
                        owner[(h - 1 - j) * w + i] = k as u32; // north up
                    }
                }
            }
        }
        let mut rgb = vec![0u8; w * h * 3];
        for j in 0..h {
            for i in 0..w {
                let o = owner[j * w + i];
                let px = &mut rgb[(j * w + i) * 3..(j * w + i) * 3 + 3];
                if o == u32::MAX {
                    px.copy_from_slice(&[170, 170, 165]);
                    continue;
                }
                let edge = [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)].iter().any(|(di, dj)| {
                    let (ii, jj) = (i as i64 + di, j as i64 + dj);
                    ii < 0
                        || jj < 0
                        || ii >= w as i64
                        || jj >= h as i64
                        || owner[jj as usize * w + ii as usize] != o
                });
                if edge {
                    px.copy_from_slice(&[30, 30, 30]);
                    continue;
                }
                // Height ramp: low = warm light, towers = dark blue.
                let t = (roofs[o as usize].1 / 200.0).sqrt().clamp(0.0, 1.0);
                px.copy_from_slice(&[
                    (250.0 - 210.0 * t) as u8,
                    (235.0 - 160.0 * t) as u8,
                    (200.0 - 40.0 * t) as u8,
                ]);
            }
        }
        let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-output/procedural_topview.png");
        std::fs::create_dir_all(out.parent().unwrap()).unwrap();
        let file = std::io::BufWriter::new(std::fs::File::create(&out).unwrap());
        let mut enc = png::Encoder::new(file, w as u32, h as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.write_header().unwrap().write_image_data(&rgb).unwrap();
        eprintln!("wrote {} ({w} × {h} px, 1 px = {step} m)", out.display());
        // Built-up fraction of the city's convex hull (the rotated street grid), from the rendering.
        let pts: Vec<[f64; 2]> =
            roofs.iter().flat_map(|(p, _)| p.exterior.iter().map(|v| [v[0], v[1]])).collect();
        let hull_m2 = hull_area(&pts);
        let built_m2 = owner.iter().filter(|&&o| o != u32::MAX).count() as f64 * step * step;
        let covered = built_m2 / hull_m2;
        eprintln!("built-up fraction of the city's hull: {:.0} %", covered * 100.0);
        assert!(covered > 0.3 && covered < 0.7, "a dense city with streets: {covered}");
    }
}
