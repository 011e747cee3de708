//! COLMAP text models (`cameras.txt`, `images.txt`, `points3D.txt`) and the plain query/pose lists of
//! the public LoD-Loc code, written and read.
//!
//! Formats (COLMAP documentation, "Output format → Text format"):
//! - `cameras.txt`: `CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`, one camera per line;
//! - `images.txt`: two lines per image: `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`, then the
//!   `POINTS2D[]` line as (X, Y, POINT3D_ID) triples — empty here, since insgen has no 2-D points;
//! - `points3D.txt`: `POINT3D_ID X Y Z R G B ERROR TRACK[]` per point — written with its header and no
//!   point: the poses are known exactly, there is nothing to triangulate, and COLMAP and pycolmap
//!   refuse a model directory without this file (`Reconstruction.read_text` opens all three);
//! - lines starting with `#` are comments.
//!
//! The quaternion and translation are world-to-camera (x_cam = R(q) · x_world + t) with OpenCV camera
//! axes; the world frame is the area's ENU frame. Numbers are written in Rust's shortest round-trip
//! form, so reading a written file gives back the same f64 values exactly.
//!
//! The LoD-Loc lists (SPEC.md) are one image per line: intrinsics `NAME MODEL W H PARAMS[]`, poses
//! `NAME QW QX QY QZ TX TY TZ`.

use std::fmt::Write as _;
use std::path::Path;

use super::{CameraError, ColmapIssue, Intrinsics, Pose};

/// One camera of `cameras.txt` (or one line of a query list, whose id is then 0).
#[derive(Debug, Clone, PartialEq)]
pub struct ColmapCamera {
    /// `CAMERA_ID`.
    pub camera_id: u32,
    /// COLMAP model name (`PINHOLE`, `SIMPLE_PINHOLE`, `OPENCV`, …).
    pub model: String,
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Model parameters in COLMAP's order (PINHOLE: fx, fy, cx, cy in pixels).
    pub params: Vec<f64>,
}

impl ColmapCamera {
    /// A `PINHOLE` camera from intrinsics.
    pub fn pinhole(camera_id: u32, k: &Intrinsics) -> Self {
        ColmapCamera {
            camera_id,
            model: "PINHOLE".to_string(),
            width_px: k.width_px,
            height_px: k.height_px,
            params: vec![k.fx_px, k.fy_px, k.cx_px, k.cy_px],
        }
    }

    /// The pinhole intrinsics of a `PINHOLE` or `SIMPLE_PINHOLE` camera; `None` for models with
    /// distortion.
    pub fn intrinsics(&self) -> Option<Intrinsics> {
        let (w, h) = (self.width_px, self.height_px);
        match (self.model.as_str(), self.params.as_slice()) {
            ("PINHOLE", &[fx, fy, cx, cy]) => {
                Some(Intrinsics { width_px: w, height_px: h, fx_px: fx, fy_px: fy, cx_px: cx, cy_px: cy })
            }
            ("SIMPLE_PINHOLE", &[f, cx, cy]) => {
                Some(Intrinsics { width_px: w, height_px: h, fx_px: f, fy_px: f, cx_px: cx, cy_px: cy })
            }
            _ => None,
        }
    }
}

/// One image of `images.txt` (or one line of a pose list, whose ids are then 0).
#[derive(Debug, Clone, PartialEq)]
pub struct ColmapImage {
    /// `IMAGE_ID`.
    pub image_id: u32,
    /// World-to-camera rotation quaternion (qw, qx, qy, qz).
    pub qvec: [f64; 4],
    /// World-to-camera translation, metres.
    pub tvec: [f64; 3],
    /// `CAMERA_ID` of the camera that took it.
    pub camera_id: u32,
    /// Image file name (`NAME`).
    pub name: String,
}

impl ColmapImage {
    /// The image's record for `pose`.
    pub fn from_pose(image_id: u32, camera_id: u32, name: &str, pose: &Pose) -> Self {
        ColmapImage {
            image_id,
            qvec: pose.colmap_qvec(),
            tvec: pose.t_cam_from_world().to_array(),
            camera_id,
            name: name.to_string(),
        }
    }

    /// The pose (camera-to-world rotation and centre C = −Rᵀt).
    pub fn pose(&self) -> Pose {
        Pose::from_colmap(self.qvec, self.tvec)
    }
}

/// Number of parameters of each COLMAP camera model (src/colmap/sensor/models.h).
fn model_param_count(model: &str) -> Option<usize> {
    Some(match model {
        "SIMPLE_PINHOLE" => 3,
        "PINHOLE" => 4,
        "SIMPLE_RADIAL" | "SIMPLE_RADIAL_FISHEYE" => 4,
        "RADIAL" | "RADIAL_FISHEYE" | "FOV" => 5,
        "OPENCV" | "OPENCV_FISHEYE" => 8,
        "FULL_OPENCV" | "THIN_PRISM_FISHEYE" => 12,
        _ => return None,
    })
}

/// The text of a `cameras.txt` file.
pub fn format_cameras_txt(cameras: &[ColmapCamera]) -> String {
    let mut s = String::new();
    s.push_str("# Camera list with one line of data per camera:\n");
    s.push_str("#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n");
    let _ = writeln!(s, "# Number of cameras: {}", cameras.len());
    for c in cameras {
        let _ = write!(s, "{} {} {} {}", c.camera_id, c.model, c.width_px, c.height_px);
        for p in &c.params {
            let _ = write!(s, " {p}");
        }
        s.push('\n');
    }
    s
}

/// The text of an `images.txt` file (each image followed by an empty POINTS2D line).
pub fn format_images_txt(images: &[ColmapImage]) -> String {
    let mut s = String::new();
    s.push_str("# Image list with two lines of data per image:\n");
    s.push_str("#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n");
    s.push_str("#   POINTS2D[] as (X, Y, POINT3D_ID)\n");
    let _ = writeln!(s, "# Number of images: {}, mean observations per image: 0", images.len());
    for im in images {
        let [qw, qx, qy, qz] = im.qvec;
        let [tx, ty, tz] = im.tvec;
        let _ =
            writeln!(s, "{} {qw} {qx} {qy} {qz} {tx} {ty} {tz} {} {}", im.image_id, im.camera_id, im.name);
        s.push('\n');
    }
    s
}

/// The text of a `points3D.txt` file without points (the header COLMAP writes, zero counts), which
/// keeps every `images.txt` POINTS2D line (empty) consistent with it.
pub fn format_points3d_txt_empty() -> String {
    "# 3D point list with one line of data per point:\n\
     #   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n\
     # Number of points: 0, mean track length: 0\n"
        .to_string()
}

/// Writes an empty `points3D.txt` atomically (see [`format_points3d_txt_empty`]).
pub fn write_points3d_txt_empty(path: &Path) -> Result<(), CameraError> {
    Ok(crate::util::write_bytes_atomic(path, format_points3d_txt_empty().as_bytes())?)
}

/// Writes `cameras.txt` atomically.
pub fn write_cameras_txt(path: &Path, cameras: &[ColmapCamera]) -> Result<(), CameraError> {
    Ok(crate::util::write_bytes_atomic(path, format_cameras_txt(cameras).as_bytes())?)
}

/// Writes `images.txt` atomically.
pub fn write_images_txt(path: &Path, images: &[ColmapImage]) -> Result<(), CameraError> {
    Ok(crate::util::write_bytes_atomic(path, format_images_txt(images).as_bytes())?)
}

fn read_text(path: &Path) -> Result<String, CameraError> {
    let bytes = crate::util::read_file(path)?;
    String::from_utf8(bytes).map_err(|source| CameraError::NotUtf8 { path: path.into(), source })
}

/// The error for line `line` (1-based) of `path`.
fn at(path: &Path, line: usize) -> impl Fn(ColmapIssue) -> CameraError + '_ {
    move |source| CameraError::Colmap { path: path.into(), line, source }
}

/// The data lines of a one-record-per-line text (cameras.txt, the LoD-Loc lists): line number
/// (1-based), the trimmed line and its whitespace-separated fields; empty lines and `#` comments are
/// skipped.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(i, line)| {
        let line = line.trim();
        (!line.is_empty() && !line.starts_with('#')).then(|| (i + 1, line, line.split_whitespace().collect()))
    })
}

/// Reads a `cameras.txt` file.
///
/// # Errors
/// [`CameraError::Colmap`] with the line number for a malformed line, an unknown model, a wrong
/// parameter count or a duplicate camera id.
pub fn read_cameras_txt(path: &Path) -> Result<Vec<ColmapCamera>, CameraError> {
    parse_cameras_txt(&read_text(path)?, path)
}

/// Parses the text of a `cameras.txt` file; `path` is used in errors only.
pub fn parse_cameras_txt(text: &str, path: &Path) -> Result<Vec<ColmapCamera>, CameraError> {
    let mut out: Vec<ColmapCamera> = Vec::new();
    for (n, line, tok) in data_lines(text) {
        let (id, mut cam) =
            parse_camera_line(line, &tok, "CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]").map_err(at(path, n))?;
        cam.camera_id = parse_u32(id, "CAMERA_ID").map_err(at(path, n))?;
        if out.iter().any(|c| c.camera_id == cam.camera_id) {
            return Err(at(path, n)(ColmapIssue::DuplicateCamera(cam.camera_id)));
        }
        out.push(cam);
    }
    Ok(out)
}

/// A camera line, `<first> MODEL WIDTH HEIGHT PARAMS[]` (`expected` spells it for the error): the first
/// field (CAMERA_ID or NAME) and the camera, with id 0.
fn parse_camera_line<'a>(
    line: &str,
    tok: &[&'a str],
    expected: &'static str,
) -> Result<(&'a str, ColmapCamera), ColmapIssue> {
    if tok.len() < 4 {
        return Err(ColmapIssue::Fields { expected, line: line.to_string() });
    }
    let model = tok[1].to_string();
    let n = model_param_count(&model).ok_or_else(|| ColmapIssue::UnknownModel(model.clone()))?;
    let width_px = parse_u32(tok[2], "WIDTH")?;
    let height_px = parse_u32(tok[3], "HEIGHT")?;
    if width_px == 0 || height_px == 0 {
        return Err(ColmapIssue::EmptyImage { width_px, height_px });
    }
    let params = tok[4..].iter().map(|t| parse_f64(t, "PARAMS")).collect::<Result<Vec<f64>, _>>()?;
    if params.len() != n {
        return Err(ColmapIssue::ParamCount { model, expected: n, found: params.len() });
    }
    Ok((tok[0], ColmapCamera { camera_id: 0, model, width_px, height_px, params }))
}

/// Reads an `images.txt` file.
///
/// # Errors
/// [`CameraError::Colmap`] with the line number for a malformed image or POINTS2D line, a zero
/// quaternion or a duplicate image id.
pub fn read_images_txt(path: &Path) -> Result<Vec<ColmapImage>, CameraError> {
    parse_images_txt(&read_text(path)?, path)
}

/// Parses the text of an `images.txt` file; `path` is used in errors only.
pub fn parse_images_txt(text: &str, path: &Path) -> Result<Vec<ColmapImage>, CameraError> {
    let mut out: Vec<ColmapImage> = Vec::new();
    let mut expect_points = false;
    for (i, line) in text.lines().enumerate() {
        let err = at(path, i + 1);
        if line.starts_with('#') {
            continue;
        }
        let tok: Vec<&str> = line.split_whitespace().collect();
        if expect_points {
            // The POINTS2D line of the previous image: (X, Y, POINT3D_ID) triples, possibly none.
            expect_points = false;
            if !tok.len().is_multiple_of(3) || tok.iter().any(|t| t.parse::<f64>().is_err()) {
                let image_id = out.last().map_or(0, |im| im.image_id);
                return Err(err(ColmapIssue::Points2D { image_id, line: line.to_string() }));
            }
            continue;
        }
        if tok.is_empty() {
            continue;
        }
        if tok.len() < 10 {
            let expected = "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME";
            return Err(err(ColmapIssue::Fields { expected, line: line.to_string() }));
        }
        let image_id = parse_u32(tok[0], "IMAGE_ID").map_err(&err)?;
        let (qvec, tvec) = parse_pose_fields(&tok[1..8]).map_err(&err)?;
        let camera_id = parse_u32(tok[8], "CAMERA_ID").map_err(&err)?;
        // COLMAP names may contain spaces: the name is the rest of the line.
        let name = rest_after_tokens(line, 9);
        if out.iter().any(|im| im.image_id == image_id) {
            return Err(err(ColmapIssue::DuplicateImage(image_id)));
        }
        out.push(ColmapImage { image_id, qvec, tvec, camera_id, name });
        expect_points = true;
    }
    Ok(out)
}

/// Reads a LoD-Loc query list: `NAME MODEL WIDTH HEIGHT PARAMS[]` per line (camera ids are 0).
///
/// # Errors
/// [`CameraError::Colmap`] with the line number for a malformed line, an unknown model or a wrong
/// parameter count.
pub fn read_query_list(path: &Path) -> Result<Vec<(String, ColmapCamera)>, CameraError> {
    let text = read_text(path)?;
    data_lines(&text)
        .map(|(n, line, tok)| {
            let (name, cam) =
                parse_camera_line(line, &tok, "NAME MODEL WIDTH HEIGHT PARAMS[]").map_err(at(path, n))?;
            Ok((name.to_string(), cam))
        })
        .collect()
}

/// Reads a LoD-Loc pose list: `NAME QW QX QY QZ TX TY TZ` per line (ids are 0).
///
/// # Errors
/// [`CameraError::Colmap`] with the line number for a malformed line or a zero quaternion.
pub fn read_pose_list(path: &Path) -> Result<Vec<ColmapImage>, CameraError> {
    let text = read_text(path)?;
    data_lines(&text)
        .map(|(n, line, tok)| {
            if tok.len() != 8 {
                let expected = "NAME QW QX QY QZ TX TY TZ";
                return Err(at(path, n)(ColmapIssue::Fields { expected, line: line.to_string() }));
            }
            let (qvec, tvec) = parse_pose_fields(&tok[1..8]).map_err(at(path, n))?;
            Ok(ColmapImage { image_id: 0, qvec, tvec, camera_id: 0, name: tok[0].to_string() })
        })
        .collect()
}

/// Formats a LoD-Loc pose list line per image.
pub fn format_pose_list(images: &[ColmapImage]) -> String {
    let mut s = String::new();
    for im in images {
        let [qw, qx, qy, qz] = im.qvec;
        let [tx, ty, tz] = im.tvec;
        let _ = writeln!(s, "{} {qw} {qx} {qy} {qz} {tx} {ty} {tz}", im.name);
    }
    s
}

/// `QW QX QY QZ TX TY TZ` (exactly seven fields): the quaternion, which must not be zero, and the
/// translation.
fn parse_pose_fields(tok: &[&str]) -> Result<([f64; 4], [f64; 3]), ColmapIssue> {
    let names = ["QW", "QX", "QY", "QZ", "TX", "TY", "TZ"];
    let mut v = [0.0; 7];
    for k in 0..7 {
        v[k] = parse_f64(tok[k], names[k])?;
    }
    let qn = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + v[3] * v[3]).sqrt();
    if qn < 1e-12 {
        return Err(ColmapIssue::ZeroQuaternion);
    }
    Ok(([v[0], v[1], v[2], v[3]], [v[4], v[5], v[6]]))
}

fn parse_f64(t: &str, field: &'static str) -> Result<f64, ColmapIssue> {
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(ColmapIssue::NotFinite { field, value: t.to_string() }),
    }
}

fn parse_u32(t: &str, field: &'static str) -> Result<u32, ColmapIssue> {
    t.parse().map_err(|_| ColmapIssue::NotInteger { field, value: t.to_string() })
}

/// The part of `line` after its first `n` whitespace-separated tokens, trimmed.
fn rest_after_tokens(line: &str, n: usize) -> String {
    let mut rest = line.trim_start();
    for _ in 0..n {
        let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
        rest = rest[end..].trim_start();
    }
    rest.trim_end().to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::error_chain;

    #[test]
    fn malformed_lines_name_file_and_line() {
        let p = Path::new("m/cameras.txt");
        fn chain<T: std::fmt::Debug>(r: Result<T, CameraError>) -> String {
            error_chain(&r.unwrap_err())
        }
        let e = parse_cameras_txt("# c\n1 PINHOLE 10 10 1 2 3\n", p).unwrap_err();
        assert!(
            matches!(
                &e,
                CameraError::Colmap {
                    line: 2,
                    source: ColmapIssue::ParamCount { expected: 4, found: 3, .. },
                    ..
                }
            ),
            "{e:?}"
        );
        assert_eq!(error_chain(&e), "m/cameras.txt:2: model PINHOLE takes 4 parameters, found 3");
        let e = chain(parse_cameras_txt("1 FISHEYE9 10 10 1\n", p));
        assert_eq!(e, "m/cameras.txt:1: unknown camera model \"FISHEYE9\"");
        let e = chain(parse_cameras_txt("1 PINHOLE 10 10 1 2 3 4\n1 PINHOLE 10 10 1 2 3 4\n", p));
        assert_eq!(e, "m/cameras.txt:2: duplicate CAMERA_ID 1");
        let e = chain(parse_cameras_txt("x PINHOLE 10 10 1 2 3 4\n", p));
        assert_eq!(e, "m/cameras.txt:1: CAMERA_ID: \"x\" is not a valid non-negative integer");
        let p = Path::new("m/images.txt");
        let e = chain(parse_images_txt("1 1 0 0 0 0 0 0 1 a.png\n1 2\n", p));
        assert!(e.starts_with("m/images.txt:2: expected the POINTS2D line"), "{e}");
        let e = chain(parse_images_txt("1 0 0 0 0 0 0 0 1 a.png\n\n", p));
        assert_eq!(e, "m/images.txt:1: the quaternion (QW QX QY QZ) is zero");
        let e = chain(parse_images_txt("1 1 0 0 0 0 0 inf 1 a.png\n\n", p));
        assert_eq!(e, "m/images.txt:1: TZ: \"inf\" is not a finite number");
    }

    #[test]
    fn lists_name_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let q = dir.path().join("queries.txt");
        std::fs::write(&q, "# q\na.png PINHOLE 10 10 5 5 5 5\n\nb.png SIMPLE_PINHOLE 10 0 5 5 5\n").unwrap();
        let e = error_chain(&read_query_list(&q).unwrap_err());
        assert_eq!(e, format!("{}:4: image size 10×0 is empty", q.display()));
        std::fs::write(&q, "a.png PINHOLE 10 10 5 5 5 5\n").unwrap();
        assert_eq!(read_query_list(&q).unwrap()[0].1.params, [5.0; 4]);
        let g = dir.path().join("gt.txt");
        std::fs::write(&g, "a.png 1 0 0 0 1 2 3\nb.png 1 0 0\n").unwrap();
        let e = error_chain(&read_pose_list(&g).unwrap_err());
        assert_eq!(e, format!("{}:2: expected NAME QW QX QY QZ TX TY TZ, got \"b.png 1 0 0\"", g.display()));
        std::fs::write(&g, b"a.png \xff\n").unwrap();
        let e = read_pose_list(&g).unwrap_err();
        assert!(matches!(e, CameraError::NotUtf8 { .. }), "{e:?}");
    }

    #[test]
    fn empty_points3d_is_only_comments() {
        let text = format_points3d_txt_empty();
        assert_eq!(text.lines().count(), 3);
        assert!(text.lines().all(|l| l.starts_with('#')), "{text}");
        assert!(text.ends_with("# Number of points: 0, mean track length: 0\n"));
    }

    #[test]
    fn names_with_spaces_and_points_lines() {
        let text = "# x\n3 1 0 0 0 1 2 3 7 dir/my image.png\n10.5 20.5 -1 1 2 4\n";
        let ims = parse_images_txt(text, Path::new("i.txt")).unwrap();
        assert_eq!(ims.len(), 1);
        assert_eq!((ims[0].image_id, ims[0].camera_id, ims[0].name.as_str()), (3, 7, "dir/my image.png"));
    }
}
