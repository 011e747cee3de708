//! Throughput of the geo chain the scene stage runs per vertex: source CRS → WGS84 (PROJ, single
//! point and batch), geoid undulation (EGM96 15'), geodetic → ECEF → ENU.
//!
//! Inputs: 10 000 points of a 2 km × 2 km Tokyo block in EPSG:6677 (JGD2011 / Japan Plane Rectangular
//! CS IX, X north, Y east) with heights 30–250 m. Each case is timed best of 7 runs
//! after a warm-up; run with `cargo bench --bench ecef_enu` (or `--profile dev` to skip the release build).

use std::hint::black_box;
use std::time::{Duration, Instant};

use insgen::geo::{geodetic_to_ecef, AxisConvention, Crs, EnuFrame, Geodetic, Geoid, GeoidGrid};

const N: usize = 10_000;

/// Deterministic points around Shibuya in EPSG:6677 (authority order X = northing, Y = easting).
fn points_6677() -> Vec<[f64; 3]> {
    (0..N)
        .map(|i| {
            let (u, v) = ((i % 100) as f64 / 100.0, (i / 100) as f64 / 100.0);
            [-38_900.0 + 2_000.0 * u, -8_900.0 + 2_000.0 * v, 30.0 + 220.0 * ((i * 37) % 100) as f64 / 100.0]
        })
        .collect()
}

/// Runs `f` once to warm up, then 7 times, and prints the best time per point.
fn time(name: &str, mut f: impl FnMut()) {
    f();
    let best = (0..7)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed()
        })
        .min()
        .unwrap_or(Duration::ZERO);
    let ns_per_point = best.as_secs_f64() * 1e9 / N as f64;
    println!("{name:<28} {ns_per_point:>10.1} ns/point {:>12.2} Mpoints/s", 1e3 / ns_per_point);
}

fn main() {
    let pts = points_6677();
    let tf = Crs::from_epsg(6677).expect("EPSG:6677 is in proj.db").transform().expect("PROJ operation");
    let geo = tf.to_geodetic_many(&pts, AxisConvention::Authority).expect("points convert");
    let frame = EnuFrame::new(geo[0]);

    println!("geo chain, {N} points");
    time("to_geodetic_many_6677", || {
        black_box(tf.to_geodetic_many(black_box(&pts), AxisConvention::Authority).expect("converts"));
    });
    time("to_geodetic_single_6677", || {
        let mut acc = 0.0;
        for p in black_box(&pts) {
            acc += tf.to_geodetic(*p, AxisConvention::Authority).expect("converts").lat_deg;
        }
        black_box(acc);
    });
    if let Some(path) = Geoid::find_egm96() {
        let geoid = Geoid::Grid(GeoidGrid::load_gtx(&path).expect("EGM96 grid loads"));
        time("egm96_undulation", || {
            let mut acc = 0.0;
            for q in black_box(&geo) {
                acc += geoid.undulation_m(q.lat_deg, q.lon_deg);
            }
            black_box(acc);
        });
    } else {
        eprintln!("egm96_15.gtx not found: geoid bench skipped");
    }
    time("geodetic_to_ecef_to_enu", || {
        let mut acc = [0.0f64; 3];
        for q in black_box(&geo) {
            let e = frame.ecef_to_enu(geodetic_to_ecef(Geodetic { h_m: q.h_m + 36.7, ..*q }).into());
            acc = [acc[0] + e[0], acc[1] + e[1], acc[2] + e[2]];
        }
        black_box(acc);
    });
}
