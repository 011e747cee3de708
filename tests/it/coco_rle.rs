//! RLE against pycocotools: the golden vectors in `../shared/fixtures/coco_rle_golden.json` (made with
//! pycocotools 2.0) and a live comparison with `pycocotools.mask` through `scripts/coco_check.py encode`.
//!
//! Strings are compared byte for byte, areas and boxes exactly (pycocotools returns integral floats).
//! Python is found through `INSGEN_PYTHON` (default `<repo>/.venv/bin/python`); when it or the fixture is
//! missing the test prints why and skips, unless `CI=true`, where it fails.

use insgen::export::polygon::mask_to_polygons;
use insgen::export::rle::{encode, encode_labels, Rle};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::Value;

fn u32s(v: &Value) -> Vec<u32> {
    v.as_array().expect("array").iter().map(|x| x.as_u64().expect("uint") as u32).collect()
}

fn f64s(v: &Value) -> Vec<f64> {
    v.as_array().expect("array").iter().map(|x| x.as_f64().expect("number")).collect()
}

#[test]
fn golden_vectors_from_pycocotools() {
    let Some(path) = crate::util::shared_fixture("coco_rle_golden.json") else { return };
    let golden: Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let mut checked = 0;
    for (name, case) in golden.as_object().unwrap() {
        let Some(size) = case.get("size") else { continue };
        let (h, w) = (size[0].as_u64().unwrap() as u32, size[1].as_u64().unwrap() as u32);
        let counts = u32s(&case["uncompressed"]);
        let compressed = case["compressed"].as_str().unwrap();
        // Parsing pycocotools' string gives its counts; writing them gives its string back.
        let parsed = Rle::from_string(compressed, h, w).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(parsed.counts, counts, "{name}: counts");
        assert_eq!(parsed.to_string(), compressed, "{name}: string");
        assert_eq!(parsed.area(), case["area"].as_u64().unwrap(), "{name}: area");
        assert_eq!(parsed.to_bbox().to_vec(), f64s(&case["bbox"]), "{name}: bbox");
        if let Some(rows) = case.get("mask_rows") {
            let mask: Vec<u8> =
                rows.as_array().unwrap().iter().flat_map(|r| u32s(r).into_iter().map(|v| v as u8)).collect();
            let ours = encode(&mask, h, w).unwrap();
            assert_eq!(ours, parsed, "{name}: encoding the mask");
            assert_eq!(ours.decode(), mask, "{name}: decoding");
        } else {
            // No mask given (random_37x53_seed0): the decode → encode round trip must be exact.
            assert_eq!(encode(&parsed.decode(), h, w).unwrap(), parsed, "{name}: round trip");
        }
        checked += 1;
    }
    assert!(checked >= 6, "only {checked} golden RLE cases found");
    // Polygon goldens: pycocotools rasterises the pixel-corner square (0,0)–(2,2) onto pixels 0..=1, so
    // our tracer's polygon of that block is one it maps back exactly.
    let block = &golden["poly_0_0_to_2_2"];
    let mask: Vec<u8> =
        block.as_array().unwrap().iter().flat_map(|r| u32s(r).into_iter().map(|v| v as u8)).collect();
    assert_eq!(mask_to_polygons(&mask, 6, 6), vec![vec![0.0, 0.0, 2.0, 0.0, 2.0, 2.0, 0.0, 2.0]]);
}

/// A named row-major mask for the live comparison.
struct Case {
    name: String,
    h: u32,
    w: u32,
    mask: Vec<u8>,
}

fn random_cases() -> Vec<Case> {
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let mut cases = Vec::new();
    let mut add = |name: String, h: u32, w: u32, mask: Vec<u8>| cases.push(Case { name, h, w, mask });
    for &(h, w) in &[(1, 1), (1, 37), (41, 1), (7, 9), (64, 48), (120, 160)] {
        let n = (h * w) as usize;
        add(format!("empty_{h}x{w}"), h, w, vec![0; n]);
        add(format!("full_{h}x{w}"), h, w, vec![1; n]);
        let mut first = vec![0; n];
        first[0] = 1;
        add(format!("first_{h}x{w}"), h, w, first);
        let mut last = vec![0; n];
        last[n - 1] = 1;
        add(format!("last_{h}x{w}"), h, w, last);
        let mut single = vec![0; n];
        single[rng.gen_range(0..n)] = 1;
        add(format!("single_{h}x{w}"), h, w, single);
        for &d in &[0.02, 0.5, 0.97] {
            add(format!("random{d}_{h}x{w}"), h, w, (0..n).map(|_| rng.gen_bool(d) as u8).collect());
        }
    }
    // Real-ish building masks: blocks, a courtyard, a rotated block, on a 480×640 frame (large runs,
    // multi-group LEB128 counts and negative differences).
    let (h, w) = (480u32, 640u32);
    for k in 0..6 {
        let mut m = vec![0u8; (h * w) as usize];
        let (x0, y0) = (rng.gen_range(0..w - 100), rng.gen_range(0..h - 100));
        let (bw, bh) = (rng.gen_range(20..300).min(w - x0), rng.gen_range(20..300).min(h - y0));
        let angle: f64 = rng.gen_range(0.0..1.5);
        let (s, c) = angle.sin_cos();
        let (cx, cy) = (x0 as f64 + bw as f64 / 2.0, y0 as f64 + bh as f64 / 2.0);
        for y in 0..h {
            for x in 0..w {
                let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
                let (u, v) = if k % 2 == 0 { (dx, dy) } else { (c * dx + s * dy, -s * dx + c * dy) };
                let inside = u.abs() <= bw as f64 / 2.0 && v.abs() <= bh as f64 / 2.0;
                let court = k % 3 == 0 && u.abs() <= bw as f64 / 5.0 && v.abs() <= bh as f64 / 5.0;
                m[(y * w + x) as usize] = (inside && !court) as u8;
            }
        }
        add(format!("building{k}_{h}x{w}"), h, w, m);
    }
    cases
}

#[test]
fn live_pycocotools_encode_decode_merge_agree() {
    let Some(py) = crate::util::python_with(&["numpy", "pycocotools"]) else { return };
    let cases = random_cases();
    let dir = tempfile::tempdir().unwrap();
    let mut blob = Vec::new();
    let mut index = Vec::new();
    let ours: Vec<Rle> = cases.iter().map(|c| encode(&c.mask, c.h, c.w).unwrap()).collect();
    for (c, r) in cases.iter().zip(&ours) {
        index.push(serde_json::json!({"name": c.name, "h": c.h, "w": c.w, "offset": blob.len(), "ours": r.to_string()}));
        blob.extend_from_slice(&c.mask);
    }
    // Merge groups: masks of the same size.
    let groups: Vec<Vec<usize>> = vec![
        (0..cases.len()).filter(|&i| cases[i].name.ends_with("_64x48")).collect(),
        (0..cases.len()).filter(|&i| cases[i].name.starts_with("building")).collect(),
        (0..cases.len()).filter(|&i| cases[i].name.ends_with("_1x37")).take(2).collect(),
    ];
    let merges: Vec<Vec<&str>> =
        groups.iter().map(|g| g.iter().map(|&i| cases[i].name.as_str()).collect()).collect();
    std::fs::write(dir.path().join("masks.bin"), &blob).unwrap();
    std::fs::write(
        dir.path().join("index.json"),
        serde_json::to_vec(&serde_json::json!({"masks": index, "merges": merges})).unwrap(),
    )
    .unwrap();
    let (masks_path, index_path) = (dir.path().join("masks.bin"), dir.path().join("index.json"));
    let v =
        crate::util::coco_check(&py, &["encode", masks_path.to_str().unwrap(), index_path.to_str().unwrap()]);
    let theirs = v["masks"].as_array().unwrap();
    assert_eq!(theirs.len(), cases.len());
    for ((c, r), t) in cases.iter().zip(&ours).zip(theirs) {
        assert_eq!(t["name"].as_str().unwrap(), c.name);
        assert_eq!(r.to_string(), t["counts"].as_str().unwrap(), "{}: compressed string", c.name);
        assert_eq!(r.size.to_vec(), u32s(&t["size"]), "{}: size", c.name);
        assert_eq!(r.area(), t["area"].as_u64().unwrap(), "{}: area", c.name);
        assert_eq!(r.to_bbox().to_vec(), f64s(&t["bbox"]), "{}: bbox", c.name);
        assert_eq!(t["pycocotools_decodes_ours_to_input"], Value::Bool(true), "{}: decode", c.name);
        // And our decoder reads pycocotools' string back to the mask.
        let back = Rle::from_string(t["counts"].as_str().unwrap(), c.h, c.w).unwrap();
        assert_eq!(back.decode(), c.mask, "{}: our decode of their string", c.name);
    }
    let merged = v["merges"].as_array().unwrap();
    for (g, m) in groups.iter().zip(merged) {
        let rles: Vec<Rle> = g.iter().map(|&i| ours[i].clone()).collect();
        assert_eq!(Rle::union(&rles).unwrap().to_string(), m["union"].as_str().unwrap(), "union of {g:?}");
        assert_eq!(
            Rle::intersection(&rles).unwrap().to_string(),
            m["intersection"].as_str().unwrap(),
            "intersection of {g:?}"
        );
    }
}

#[test]
fn all_at_once_encoding_equals_per_mask_encoding_on_a_label_image() {
    // Independent of Python: encode_labels must give, for every label, exactly encode(labels == k).
    let (h, w) = (90u32, 130u32);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let mut labels = vec![0u32; (h * w) as usize];
    for k in 1..=25u32 {
        let (x0, y0) = (rng.gen_range(0..w), rng.gen_range(0..h));
        let (bw, bh) = (rng.gen_range(1..60), rng.gen_range(1..60));
        for y in y0..(y0 + bh).min(h) {
            for x in x0..(x0 + bw).min(w) {
                labels[(y * w + x) as usize] = k;
            }
        }
    }
    let all = encode_labels(&labels, h, w, 25).unwrap();
    for (k, r) in all.iter().enumerate() {
        let m: Vec<u8> = labels.iter().map(|&l| (l == k as u32 + 1) as u8).collect();
        assert_eq!(*r, encode(&m, h, w).unwrap(), "label {}", k + 1);
    }
}
