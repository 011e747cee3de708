//! RLE encoding speed: insgen vs `pycocotools.mask.encode` on the same instance masks, in one run.
//!
//! Builds a synthetic 1920×1080 (and 640×360) instance-label image — a few hundred overlapping
//! rectangles, rotated blocks, ellipses and courtyard buildings, split into connected components with
//! `label_components` — and times, best of several repetitions, single-threaded:
//! - insgen `encode_labels`: all components of the frame in one pass over the row-major label image;
//! - insgen `encode` per component from prepared row-major binary masks (what pycocotools does);
//! - pycocotools `mask.encode` of the prepared Fortran `(h, w, n)` stack (its best case), and of each
//!   `labels == k` mask built on the fly (the usual way it is called), via `scripts/coco_check.py bench`.
//!
//! The compressed strings of both sides are compared (the run fails if any differs), and the table is
//! written to `bench/rle_report.md`. Python comes from `INSGEN_PYTHON` (default `.venv/bin/python`);
//! without it only the Rust side is reported.
//!
//! Run: `cargo bench --bench rle`.

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use insgen::export::rle::{encode, encode_labels};
use insgen::label::{label_components, Connectivity};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A synthetic city frame: building IDs drawn back to front.
fn city_ids(width: u32, height: u32, buildings: u32, seed: u64) -> Vec<u32> {
    let (w, h) = (width as i64, height as i64);
    let mut ids = vec![0u32; (w * h) as usize];
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let scale = width as f64 / 1920.0;
    for b in 1..=buildings {
        let cx = rng.gen_range(0.0..w as f64);
        let cy = rng.gen_range(0.0..h as f64);
        let hw = rng.gen_range(12.0..90.0) * scale;
        let hh = rng.gen_range(12.0..90.0) * scale;
        let angle: f64 = rng.gen_range(0.0..std::f64::consts::PI);
        let kind = rng.gen_range(0..4);
        let (s, c) = angle.sin_cos();
        let r = (hw.max(hh) * 1.5) as i64 + 1;
        for y in (cy as i64 - r).max(0)..(cy as i64 + r).min(h) {
            for x in (cx as i64 - r).max(0)..(cx as i64 + r).min(w) {
                let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
                let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
                let inside = match kind {
                    0 => dx.abs() <= hw && dy.abs() <= hh,
                    1 => u.abs() <= hw && v.abs() <= hh,
                    2 => (u / hw).powi(2) + (v / hh).powi(2) <= 1.0,
                    // Courtyard: a ring.
                    _ => u.abs() <= hw && v.abs() <= hh && (u.abs() > 0.5 * hw || v.abs() > 0.5 * hh),
                };
                if inside {
                    ids[(y * w + x) as usize] = b;
                }
            }
        }
    }
    ids
}

fn best_of<T>(reps: usize, mut f: impl FnMut() -> T) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..reps {
        let t = Instant::now();
        black_box(f());
        best = best.min(t.elapsed().as_secs_f64());
    }
    best
}

fn python() -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let p =
        std::env::var_os("INSGEN_PYTHON").map(PathBuf::from).unwrap_or_else(|| root.join(".venv/bin/python"));
    let ok = Command::new(&p).args(["-c", "import pycocotools, numpy"]).output().map(|o| o.status.success());
    ok.unwrap_or(false).then_some(p)
}

struct Row {
    size: String,
    components: usize,
    ours_all_ms: f64,
    ours_each_ms: f64,
    py_stack_ms: Option<f64>,
    py_full_ms: Option<f64>,
    identical: Option<bool>,
}

fn run_case(width: u32, height: u32, buildings: u32, reps: usize, py: Option<&Path>) -> Row {
    let ids = city_ids(width, height, buildings, 42);
    let map = insgen::scene::IdMap::from_raw(width, height, ids).expect("24-bit synthetic IDs");
    let lab = label_components(&map, Connectivity::Eight);
    let n = lab.components.len();
    let ours_all =
        best_of(reps, || encode_labels(black_box(&lab.labels), height, width, n).expect("valid labels"));
    let masks: Vec<Vec<u8>> = (0..n).map(|k| lab.mask(k)).collect();
    let ours_each = best_of(reps, || {
        masks.iter().map(|m| encode(black_box(m), height, width).expect("valid mask")).collect::<Vec<_>>()
    });
    let ours: Vec<String> = encode_labels(&lab.labels, height, width, n)
        .expect("valid labels")
        .iter()
        .map(|r| r.to_string())
        .collect();
    let (mut py_stack_ms, mut py_full_ms, mut identical) = (None, None, None);
    if let Some(py) = py {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("labels.bin");
        let bytes: Vec<u8> = lab.labels.iter().flat_map(|l| l.to_le_bytes()).collect();
        std::fs::write(&path, bytes).expect("write labels");
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/coco_check.py");
        let out = Command::new(py)
            .arg(&script)
            .args(["bench", &path.display().to_string()])
            .args([height.to_string(), width.to_string(), n.to_string(), reps.to_string()])
            .output()
            .expect("run python");
        assert!(
            out.status.success(),
            "coco_check.py bench failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("bench JSON");
        py_stack_ms = v["encode_stack_s"].as_f64().map(|s| s * 1e3);
        py_full_ms = v["per_instance_from_labels_s"].as_f64().map(|s| s * 1e3);
        let theirs: Vec<String> = v["counts"]
            .as_array()
            .expect("counts")
            .iter()
            .map(|c| c.as_str().unwrap_or("").to_string())
            .collect();
        let same = theirs == ours;
        assert!(same, "RLE strings differ from pycocotools at {width}×{height}");
        identical = Some(same);
    }
    Row {
        size: format!("{width}×{height}"),
        components: n,
        ours_all_ms: ours_all * 1e3,
        ours_each_ms: ours_each * 1e3,
        py_stack_ms,
        py_full_ms,
        identical,
    }
}

fn main() {
    // `cargo bench` passes `--bench`; `cargo test --benches` runs this too: keep that cheap.
    let quick = !std::env::args().any(|a| a == "--bench");
    let py = python();
    let reps = if quick { 1 } else { 7 };
    let cases: &[(u32, u32, u32)] =
        if quick { &[(320, 180, 40)] } else { &[(1920, 1080, 300), (640, 360, 300)] };
    let rows: Vec<Row> = cases.iter().map(|&(w, h, b)| run_case(w, h, b, reps, py.as_deref())).collect();
    let fmt = |v: Option<f64>| v.map(|x| format!("{x:.2}")).unwrap_or_else(|| "—".into());
    let ratio = |a: Option<f64>, b: f64| a.map(|x| format!("{:.1}×", x / b)).unwrap_or_else(|| "—".into());
    let mut md = String::from(
        "# RLE encoding: insgen vs pycocotools\n\nWritten by `cargo bench --bench rle` (benches/rle.rs). Best of \
         several runs, one thread, same machine, same masks. Synthetic city frames (overlapping rectangles, \
         rotated blocks, ellipses, courtyards), 8-connected components.\n\n\
         - *insgen all-at-once*: `export::rle::encode_labels` — every component of the frame from the row-major \
         label image in one pass (what `export-coco` uses).\n\
         - *insgen per mask*: `export::rle::encode` of each prepared row-major binary mask.\n\
         - *pycocotools stack*: `pycocotools.mask.encode` of the prepared Fortran (h, w, n) stack — its best \
         case.\n\
         - *pycocotools from labels*: `encode(asfortranarray(labels == k))` per component, the usual call.\n\n\
         | frame | components | insgen all-at-once ms | insgen per mask ms | pycocotools stack ms | pycocotools \
         from labels ms | speed-up vs stack (all-at-once / per mask) | strings identical |\n\
         |---|---:|---:|---:|---:|---:|---|---|\n",
    );
    for r in &rows {
        md.push_str(&format!(
            "| {} | {} | {:.2} | {:.2} | {} | {} | {} / {} | {} |\n",
            r.size,
            r.components,
            r.ours_all_ms,
            r.ours_each_ms,
            fmt(r.py_stack_ms),
            fmt(r.py_full_ms),
            ratio(r.py_stack_ms, r.ours_all_ms),
            ratio(r.py_stack_ms, r.ours_each_ms),
            r.identical.map(|b| if b { "yes" } else { "NO" }).unwrap_or("not compared (no Python)"),
        ));
    }
    md.push_str(&format!(
        "\nBuild: {} (debug assertions {}); machine: {} logical CPUs, shared.\n",
        if cfg!(debug_assertions) {
            "test/dev-style profile with optimisation"
        } else {
            "bench profile (release)"
        },
        if cfg!(debug_assertions) { "on" } else { "off" },
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
    ));
    if py.is_none() {
        md.push_str("\npycocotools was not found (set INSGEN_PYTHON); only insgen was timed.\n");
    }
    print!("{md}");
    if !quick {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("bench/rle_report.md");
        insgen::util::write_bytes_atomic(&path, md.as_bytes()).expect("write bench/rle_report.md");
        eprintln!("wrote {}", path.display());
    }
}
