//! Throughput of the geo chain the scene stage runs per vertex: source CRS → WGS84 (PROJ, single
//! point and batch), geoid undulation (EGM96 15'), geodetic → ECEF → ENU.
//!
//! Inputs: 10 000 points of a 2 km × 2 km Tokyo block in EPSG:6677 (JGD2011 / Japan Plane Rectangular
//! CS IX, X north, Y east) with heights 30–250 m. Run with `cargo bench --bench ecef_enu`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
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

fn bench(c: &mut Criterion) {
    let pts = points_6677();
    let tf = Crs::from_epsg(6677).expect("EPSG:6677 is in proj.db").transform().expect("PROJ operation");
    let geo = tf.to_geodetic_many(&pts, AxisConvention::Authority).expect("points convert");
    let frame = EnuFrame::new(geo[0]);

    let mut g = c.benchmark_group("geo_chain");
    g.throughput(Throughput::Elements(N as u64));
    g.bench_function("to_geodetic_many_6677", |b| {
        b.iter(|| tf.to_geodetic_many(black_box(&pts), AxisConvention::Authority).expect("converts"))
    });
    g.bench_function("to_geodetic_single_6677", |b| {
        b.iter(|| {
            let mut acc = 0.0;
            for p in black_box(&pts) {
                acc += tf.to_geodetic(*p, AxisConvention::Authority).expect("converts").lat_deg;
            }
            black_box(acc)
        })
    });
    if let Some(path) = Geoid::find_egm96() {
        let geoid = Geoid::Grid(GeoidGrid::load_gtx(&path).expect("EGM96 grid loads"));
        g.bench_function("egm96_undulation", |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for q in black_box(&geo) {
                    acc += geoid.undulation_m(q.lat_deg, q.lon_deg);
                }
                black_box(acc)
            })
        });
    } else {
        eprintln!("egm96_15.gtx not found: geoid bench skipped");
    }
    g.bench_function("geodetic_to_ecef_to_enu", |b| {
        b.iter(|| {
            let mut acc = [0.0f64; 3];
            for q in black_box(&geo) {
                let e = frame.ecef_to_enu(geodetic_to_ecef(Geodetic { h_m: q.h_m + 36.7, ..*q }));
                acc = [acc[0] + e[0], acc[1] + e[1], acc[2] + e[2]];
            }
            black_box(acc)
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
