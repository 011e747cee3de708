//! Reading COCO results (prediction) files: a JSON list of
//! `{"image_id", "category_id", "segmentation": RLE, "score"[, "bbox"]}`, as written by detectron2,
//! mmdetection or `pycocotools` users, grouped per image for the localizer (`eval-loc`).
//!
//! The segmentation must be an RLE — compressed string (pycocotools' `rleToString` form) or
//! uncompressed counts. Polygons are rejected: an instance-alignment cost needs exact masks.
//! Validation reports every problem with its JSON path (`[12].segmentation.counts`), not only the
//! first. Masks stay run-length encoded until [`Prediction::mask`] decodes one.

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::Value;

use super::rle::Rle;
use super::CocoError;

/// Problems listed in one error at most (the count says how many there were).
const MAX_PROBLEMS: usize = 50;

/// One predicted instance.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// Position of the entry in the results file.
    pub index: usize,
    /// The predicted category.
    pub category_id: u32,
    /// Confidence (any finite number; higher = more confident).
    pub score: f64,
    /// The mask.
    pub rle: Rle,
    /// Bounding-box area in pixels²: `w × h` of the entry's `bbox` when given, else of the mask's box.
    pub bbox_area_px: f64,
}

impl Prediction {
    /// The mask as a row-major bitmap of 0/1 bytes, `height × width`.
    pub fn mask(&self) -> Vec<u8> {
        self.rle.decode()
    }

    /// Mask height and width in pixels.
    pub fn size(&self) -> [u32; 2] {
        self.rle.size
    }
}

/// A results file grouped by image.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Results {
    /// Predictions per `image_id`, in file order.
    pub by_image: BTreeMap<u64, Vec<Prediction>>,
}

impl Results {
    /// Number of predictions.
    pub fn len(&self) -> usize {
        self.by_image.values().map(Vec::len).sum()
    }

    /// Whether there are no predictions.
    pub fn is_empty(&self) -> bool {
        self.by_image.is_empty()
    }
}

/// Reads and validates a results file.
///
/// # Errors
/// [`CocoError::File`] when it cannot be read, [`CocoError::Json`] when it is not JSON,
/// [`CocoError::Invalid`] listing every problem with its JSON path.
pub fn read_results(path: &Path) -> Result<Results, CocoError> {
    let bytes = crate::util::read_file(path)?;
    parse_results(&bytes, path)
}

/// Parses and validates results from JSON bytes; `path` names the source in errors.
///
/// # Errors
/// As [`read_results`].
pub fn parse_results(bytes: &[u8], path: &Path) -> Result<Results, CocoError> {
    let value: Value = serde_json::from_slice(bytes).map_err(|e| CocoError::json(path, e))?;
    let mut problems: Vec<String> = Vec::new();
    let Value::Array(items) = value else {
        let mut p = format!("$: expected a JSON array of results, found {}", kind(&value));
        if value.get("annotations").is_some() {
            p.push_str(" (this looks like a COCO instances file, not a results file)");
        }
        return Err(CocoError::Invalid { path: path.to_path_buf(), problems: vec![p] });
    };
    let mut results = Results::default();
    let mut sizes: BTreeMap<u64, ([u32; 2], usize)> = BTreeMap::new();
    for (i, item) in items.iter().enumerate() {
        if let Some(pred) = parse_one(i, item, &mut problems) {
            let (image_id, pred) = pred;
            match sizes.get(&image_id) {
                Some(&(size, first)) if size != pred.rle.size => problems.push(format!(
                    "[{i}].segmentation.size: {:?} differs from {:?} of entry [{first}] for the same image_id \
                     {image_id}",
                    pred.rle.size, size
                )),
                Some(_) => {}
                None => {
                    sizes.insert(image_id, (pred.rle.size, i));
                }
            }
            results.by_image.entry(image_id).or_default().push(pred);
        }
    }
    if !problems.is_empty() {
        let n = problems.len();
        problems.truncate(MAX_PROBLEMS);
        if n > MAX_PROBLEMS {
            problems.push(format!("… and {} more", n - MAX_PROBLEMS));
        }
        return Err(CocoError::Invalid { path: path.to_path_buf(), problems });
    }
    Ok(results)
}

fn kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

fn uint(v: Option<&Value>, at: &str, problems: &mut Vec<String>) -> Option<u64> {
    match v {
        None => {
            problems.push(format!("{at}: missing"));
            None
        }
        Some(x) => match x.as_u64() {
            Some(n) => Some(n),
            None => {
                problems.push(format!("{at}: expected a non-negative integer, found {x}"));
                None
            }
        },
    }
}

fn parse_one(i: usize, item: &Value, problems: &mut Vec<String>) -> Option<(u64, Prediction)> {
    let before = problems.len();
    let Value::Object(obj) = item else {
        problems.push(format!("[{i}]: expected an object, found {}", kind(item)));
        return None;
    };
    let image_id = uint(obj.get("image_id"), &format!("[{i}].image_id"), problems);
    let category_id = uint(obj.get("category_id"), &format!("[{i}].category_id"), problems);
    if let Some(c) = category_id {
        if c == 0 || c > u32::MAX as u64 {
            problems.push(format!("[{i}].category_id: {c} is not a valid category id (1..=4294967295)"));
        }
    }
    let score = match obj.get("score") {
        None => {
            problems.push(format!("[{i}].score: missing"));
            None
        }
        Some(v) => match v.as_f64() {
            Some(s) if s.is_finite() => Some(s),
            _ => {
                problems.push(format!("[{i}].score: expected a finite number, found {v}"));
                None
            }
        },
    };
    let rle = match obj.get("segmentation") {
        None => {
            problems.push(format!("[{i}].segmentation: missing (only mask results are accepted)"));
            None
        }
        Some(Value::Array(_)) => {
            problems.push(format!(
                "[{i}].segmentation: polygons are not supported; give an RLE (pycocotools.mask.encode)"
            ));
            None
        }
        Some(Value::Object(seg)) => parse_rle(i, seg, problems),
        Some(v) => {
            problems.push(format!("[{i}].segmentation: expected an RLE object, found {}", kind(v)));
            None
        }
    };
    let bbox_area = match obj.get("bbox") {
        None => None,
        Some(v) => {
            let nums: Option<Vec<f64>> = v.as_array().map(|a| a.iter().filter_map(Value::as_f64).collect());
            match nums {
                Some(b) if b.len() == 4 && b.iter().all(|x| x.is_finite()) && b[2] >= 0.0 && b[3] >= 0.0 => {
                    Some(b[2] * b[3])
                }
                _ => {
                    problems.push(format!(
                        "[{i}].bbox: expected [x, y, width, height] with width, height ≥ 0, found {v}"
                    ));
                    None
                }
            }
        }
    };
    if problems.len() > before {
        return None;
    }
    let (image_id, category_id, score, rle) = (image_id?, category_id?, score?, rle?);
    let bbox_area_px = bbox_area.unwrap_or_else(|| {
        let b = rle.to_bbox();
        b[2] * b[3]
    });
    Some((image_id, Prediction { index: i, category_id: category_id as u32, score, rle, bbox_area_px }))
}

fn parse_rle(i: usize, seg: &serde_json::Map<String, Value>, problems: &mut Vec<String>) -> Option<Rle> {
    let size = match seg.get("size").and_then(Value::as_array) {
        Some(a)
            if a.len() == 2
                && a.iter().all(|v| v.as_u64().is_some_and(|n| n > 0 && n <= u32::MAX as u64)) =>
        {
            [a[0].as_u64()? as u32, a[1].as_u64()? as u32]
        }
        _ => {
            let found = seg.get("size").map(|v| v.to_string()).unwrap_or_else(|| "nothing".into());
            problems.push(format!(
                "[{i}].segmentation.size: expected [height, width] (positive integers), found {found}"
            ));
            return None;
        }
    };
    let parsed = match seg.get("counts") {
        Some(Value::String(s)) => Rle::from_string(s, size[0], size[1]),
        Some(Value::Array(a)) => {
            let counts: Option<Vec<u32>> =
                a.iter().map(|v| v.as_u64().filter(|&n| n <= u32::MAX as u64).map(|n| n as u32)).collect();
            match counts {
                Some(c) => Rle::from_counts(size, c),
                None => {
                    problems.push(format!(
                        "[{i}].segmentation.counts: uncompressed counts must be non-negative integers"
                    ));
                    return None;
                }
            }
        }
        other => {
            let found = other.map(kind).unwrap_or("nothing");
            problems.push(format!(
                "[{i}].segmentation.counts: expected a string or a list of runs, found {found}"
            ));
            return None;
        }
    };
    match parsed {
        Ok(r) => Some(r),
        Err(e) => {
            problems.push(format!("[{i}].segmentation.counts: {e}"));
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<Results, CocoError> {
        parse_results(s.as_bytes(), Path::new("preds.json"))
    }

    #[test]
    fn groups_by_image_and_decodes_both_rle_forms() {
        let r = parse(
            r#"[{"image_id": 2, "category_id": 1, "score": 0.9, "segmentation": {"size": [4, 5], "counts": "5220003"}},
                {"image_id": 1, "category_id": 1, "score": 0.5, "bbox": [0, 0, 2, 3],
                 "segmentation": {"size": [3, 3], "counts": [0, 1, 8]}},
                {"image_id": 2, "category_id": 1, "score": 0.1, "segmentation": {"size": [4, 5], "counts": "09"}}]"#,
        );
        let err = r.unwrap_err().to_string();
        // "09" is 0 + 9 pixels, not the 20 of a 4×5 image.
        assert!(err.contains("[2].segmentation.counts: counts sum to 9 pixels but size 4×5 has 20"), "{err}");
        let r = parse(
            r#"[{"image_id": 2, "category_id": 1, "score": 0.9, "segmentation": {"size": [4, 5], "counts": "5220003"}},
                {"image_id": 1, "category_id": 1, "score": 0.5, "bbox": [0, 0, 2, 3],
                 "segmentation": {"size": [3, 3], "counts": [0, 1, 8]}}]"#,
        )
        .unwrap();
        assert_eq!(r.len(), 2);
        let p2 = &r.by_image[&2][0];
        assert_eq!(p2.mask().iter().filter(|&&v| v == 1).count(), 6);
        // No bbox given: the mask's box, 3 × 2 px (golden rect_4x5).
        assert_eq!(p2.bbox_area_px, 6.0);
        let p1 = &r.by_image[&1][0];
        assert_eq!((p1.bbox_area_px, p1.score, p1.mask()[0]), (6.0, 0.5, 1));
    }

    #[test]
    fn reports_every_problem_with_its_path() {
        let err = parse(
            r#"[{"image_id": -1, "category_id": 1, "score": 1, "segmentation": {"size": [2, 2], "counts": "4"}},
                {"image_id": 1, "category_id": 0, "score": "high", "segmentation": [[0, 0, 1, 0, 1, 1]]},
                {"image_id": 1, "category_id": 1, "score": 1, "segmentation": {"size": [2], "counts": "4"}},
                {"image_id": 1, "category_id": 1, "score": 1, "segmentation": {"size": [2, 2], "counts": "4z"}},
                7]"#,
        )
        .unwrap_err();
        let CocoError::Invalid { path, problems } = err else { panic!("not Invalid: {err}") };
        assert_eq!(path, Path::new("preds.json"));
        let expected = [
            "[0].image_id: expected a non-negative integer, found -1",
            "[1].category_id: 0 is not a valid category id (1..=4294967295)",
            "[1].score: expected a finite number, found \"high\"",
            "[1].segmentation: polygons are not supported; give an RLE (pycocotools.mask.encode)",
            "[2].segmentation.size: expected [height, width] (positive integers), found [2]",
            "[3].segmentation.counts: compressed RLE has byte 0x7a ('z') at offset 1; only '0'..='o' are valid",
            "[4]: expected an object, found a number",
        ];
        assert_eq!(problems, expected);
    }

    #[test]
    fn an_instances_file_is_recognised() {
        let err = parse(r#"{"images": [], "annotations": []}"#).unwrap_err().to_string();
        assert!(err.contains("looks like a COCO instances file"), "{err}");
    }

    #[test]
    fn sizes_must_agree_within_an_image() {
        let err = parse(
            r#"[{"image_id": 1, "category_id": 1, "score": 1, "segmentation": {"size": [2, 2], "counts": "4"}},
                {"image_id": 1, "category_id": 1, "score": 1, "segmentation": {"size": [1, 4], "counts": "4"}}]"#,
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("[1].segmentation.size: [1, 4] differs from [2, 2] of entry [0]"), "{err}");
    }
}
