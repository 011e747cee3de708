//! insgen's CRS layer and geoid against pyproj (the reference, from PyPI, with its own bundled PROJ).
//!
//! One Python process (`scripts/pyproj_reference.py`) draws, for every EPSG code below, 100 points
//! uniformly inside the CRS's area of use (seeded, so the run is deterministic), gives their source
//! coordinates in both axis orders, pyproj's WGS 84 latitude/longitude for them and pyproj's ECEF
//! (EPSG:4979 → EPSG:4978) of that position. insgen converts the same source coordinates with
//! `CrsTransform::to_geodetic_many` (both `AxisConvention`s) and `geodetic_to_ecef`.
//!
//! Tolerances: horizontal position 1 cm, measured in metres in the local ENU frame of pyproj's point;
//! ECEF 1 cm in the vertical and horizontally. Geoid undulation (EGM96 15') vs PROJ `vgridshift`
//! through pyproj: 1 mm. Measured errors are printed (`cargo test --test geo_pyproj -- --nocapture`).
//!
//! The interpreter is `$INSGEN_PYTHON`, else `<repo>/.venv/bin/python` (made by scripts/setup.sh).
//! When it or pyproj is missing the test prints why and passes, except under `CI=true`, where it fails.

use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};

use insgen::geo::{self, AxisConvention, Crs, EnuFrame, Geodetic, Geoid, GeoidGrid, HeightKind};
use serde::Deserialize;

/// Horizontal and vertical tolerance vs pyproj, metres.
const TOL_M: f64 = 0.01;
/// Geoid undulation tolerance vs PROJ vgridshift, metres.
const GEOID_TOL_M: f64 = 0.001;
const N_POINTS: usize = 100;
const SEED: u64 = 20_240_601;

#[derive(Deserialize)]
struct Answer {
    pyproj_version: String,
    proj_version: String,
    crs: Vec<CrsRef>,
    geoid: Option<GeoidRef>,
}

#[derive(Deserialize)]
struct CrsRef {
    code: u32,
    name: String,
    #[serde(rename = "type")]
    kind: String,
    horizontal_code: Option<u32>,
    height_factor: f64,
    operations: std::collections::BTreeMap<String, usize>,
    points: Vec<PointRef>,
}

#[derive(Deserialize)]
struct PointRef {
    authority: [f64; 3],
    east_north: [f64; 3],
    lat_deg: f64,
    lon_deg: f64,
    h_m: f64,
    ecef_m: [f64; 3],
}

#[derive(Deserialize)]
struct GeoidRef {
    undulation_m: Vec<f64>,
}

fn run_reference(py: &Path, request: &serde_json::Value) -> Answer {
    serde_json::from_value(run_reference_json(py, request))
        .unwrap_or_else(|e| panic!("reference output is not the expected JSON: {e}"))
}

/// Runs `scripts/pyproj_reference.py` on one request; its answer as JSON (other modules use the
/// `geoids` and `compound` parts).
pub fn run_reference_json(py: &Path, request: &serde_json::Value) -> serde_json::Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/pyproj_reference.py");
    let mut child = Command::new(py)
        .arg(&script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("starting {} {}: {e}", py.display(), script.display()));
    let body = serde_json::to_vec(request).expect("request serialises");
    child.stdin.take().expect("piped stdin").write_all(&body).expect("writing the request");
    let out = child.wait_with_output().expect("waiting for the reference script");
    assert!(
        out.status.success(),
        "{} failed ({}):\n{}",
        script.display(),
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("reference output is not the expected JSON: {e}"))
}

/// The EPSG codes under test: geographic 2D/3D, geocentric, compound, all 19 Japan Plane Rectangular
/// CSs, Dutch, Swiss and Chinese projected CRSs, a feet-based CRS, ETRS89 3D/geocentric and UTM 32N/33N
/// (German CityGML's AdV names resolve to them), and UTM
/// zones (every 7th north and south, the antimeridian zones, 54N, 31N, 33S).
fn codes() -> Vec<u32> {
    let mut c = vec![4326, 4979, 6697, 4978, 28992, 7415, 2056, 4547, 2230, 4937, 4936, 25832, 25833];
    c.extend(6669..=6687);
    for z in (1..=60).step_by(7).chain([31, 33, 54, 60]) {
        c.push(32600 + z);
        c.push(32700 + z);
    }
    c.sort_unstable();
    c.dedup();
    c
}

#[test]
fn crs_conversions_agree_with_pyproj() {
    let Some(py) = crate::util::python_with(&["pyproj"]) else { return };
    let codes = codes();
    let grid = Geoid::find_egm96();
    if grid.is_none() {
        crate::util::skip(
            "egm96_15.gtx is absent (Debian package proj-data); the geoid comparison is left out",
        );
    }
    // Geoid points: a golden-angle spiral over the globe plus Tokyo, Den Haag, Delft and the antimeridian.
    let mut geoid_pts: Vec<[f64; 2]> = (0..200)
        .map(|i| {
            let lat = (1.0 - 2.0 * (i as f64 + 0.5) / 200.0).asin().to_degrees();
            let lon = (i as f64 * 137.507_764_050_037_85).rem_euclid(360.0) - 180.0;
            [lat, lon]
        })
        .collect();
    geoid_pts.extend([[35.658, 139.7016], [52.08, 4.31], [52.01, 4.36], [0.0, 179.9], [-16.5, -179.95]]);

    let mut request = serde_json::json!({
        "seed": SEED,
        "n_points": N_POINTS,
        "codes": codes,
        // Same grid files on both sides (insgen's PROJ search path added to pyproj's).
        "extra_data_dirs": geo::crs::proj_search_paths(),
    });
    if let Some(g) = &grid {
        request["geoid"] = serde_json::json!({ "grid": g, "points": geoid_pts });
    }
    let answer = run_reference(&py, &request);
    println!(
        "reference: pyproj {} (PROJ {}); insgen linked against PROJ {}",
        answer.pyproj_version,
        answer.proj_version,
        geo::proj_version()
    );
    assert_eq!(answer.crs.len(), codes.len());

    println!(
        "{:>6} {:<12} {:>4} {:>11} {:>11} {:>11} {:>11}  operation (pyproj | insgen)",
        "EPSG", "kind", "n", "horiz_auth", "horiz_EN", "ecef_vert", "ecef_horiz"
    );
    let mut failures = Vec::new();
    for r in &answer.crs {
        let crs = Crs::from_epsg(r.code).unwrap_or_else(|e| panic!("EPSG:{}: {e}", r.code));
        // Structure as pyproj sees it.
        if let Some(h) = r.horizontal_code {
            assert_eq!(crs.horizontal_epsg, h, "EPSG:{} horizontal part", r.code);
        }
        assert!((crs.height_unit_m - r.height_factor).abs() < 1e-12, "EPSG:{} height unit", r.code);
        let want_heights = match r.kind.as_str() {
            "geocentric" | "geographic3d" | "projected3d" => HeightKind::Ellipsoidal,
            _ => HeightKind::Orthometric,
        };
        assert_eq!(crs.heights(), want_heights, "EPSG:{} ({})", r.code, r.name);
        assert_eq!(r.points.len(), N_POINTS);

        let tf = crs.transform().unwrap_or_else(|e| panic!("EPSG:{}: {e}", r.code));
        let auth_in: Vec<[f64; 3]> = r.points.iter().map(|p| p.authority).collect();
        let en_in: Vec<[f64; 3]> = r.points.iter().map(|p| p.east_north).collect();
        let auth =
            tf.to_geodetic_many(&auth_in, AxisConvention::Authority).expect("authority order converts");
        let en = tf.to_geodetic_many(&en_in, AxisConvention::EastNorth).expect("east/north order converts");

        let (mut max_h_auth, mut max_h_en, mut max_v, mut max_eh) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for (i, p) in r.points.iter().enumerate() {
            let reference = Geodetic::new(p.lat_deg, p.lon_deg, p.h_m);
            let frame = EnuFrame::new(reference);
            let ref_ecef_enu = frame.ecef_to_enu(p.ecef_m.into());
            for (g, max_h) in [(auth[i], &mut max_h_auth), (en[i], &mut max_h_en)] {
                // Horizontal: insgen's lat/lon at the reference height, distance in the tangent plane.
                let d = frame.geodetic_to_enu(Geodetic { h_m: p.h_m, ..g });
                *max_h = max_h.max(d[0].hypot(d[1]));
                // ECEF: insgen's geodetic → ECEF (its own height) vs pyproj's 4979 → 4978.
                let q = frame.ecef_to_enu(geo::geodetic_to_ecef(g).into());
                max_v = max_v.max((q[2] - ref_ecef_enu[2]).abs());
                max_eh = max_eh.max((q[0] - ref_ecef_enu[0]).hypot(q[1] - ref_ecef_enu[1]));
            }
        }
        let op_insgen =
            tf.operation_for(r.points[0].east_north, AxisConvention::EastNorth).unwrap_or_default();
        let op_pyproj: Vec<&str> = r.operations.keys().map(String::as_str).collect();
        println!(
            "{:>6} {:<12} {:>4} {:>11.3e} {:>11.3e} {:>11.3e} {:>11.3e}  {} | {}",
            r.code,
            r.kind,
            r.points.len(),
            max_h_auth,
            max_h_en,
            max_v,
            max_eh,
            op_pyproj.join(" / "),
            op_insgen
        );
        if max_h_auth > TOL_M || max_h_en > TOL_M || max_v > TOL_M || max_eh > TOL_M {
            failures.push(format!(
                "EPSG:{} {}: horizontal {max_h_auth:.4} / {max_h_en:.4} m, ECEF vertical {max_v:.4} m, \
                 ECEF horizontal {max_eh:.4} m",
                r.code, r.name
            ));
        }
    }
    assert!(failures.is_empty(), "beyond {TOL_M} m vs pyproj:\n{}", failures.join("\n"));

    if let (Some(path), Some(g)) = (grid, answer.geoid) {
        let geoid = Geoid::Grid(GeoidGrid::load_gtx(&path).expect("EGM96 grid loads"));
        assert_eq!(g.undulation_m.len(), geoid_pts.len());
        let mut max_err: f64 = 0.0;
        for (&[lat, lon], &want) in geoid_pts.iter().zip(&g.undulation_m) {
            let n = geoid.try_undulation_m(lat, lon).expect("EGM96 covers the globe");
            let err = (n - want).abs();
            max_err = max_err.max(err);
            assert!(err <= GEOID_TOL_M, "({lat}, {lon}): insgen N = {n} m, pyproj vgridshift {want} m");
        }
        println!(
            "geoid EGM96 15' vs pyproj vgridshift: {} points, max |ΔN| = {max_err:.3e} m",
            geoid_pts.len()
        );
    }
}
