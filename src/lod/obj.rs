//! Wavefront OBJ reader: an untextured city mesh plus a JSON sidecar that geo-references it.
//!
//! OBJ has no notion of a CRS, of an origin shift or of which axis is up, so every OBJ needs a
//! *sidecar* file next to it ([`ObjSidecar`], JSON Schema in `schemas/obj_sidecar.schema.json`):
//!
//! ```json
//! { "crs": "EPSG:6677", "offset": [-5000.0, -35000.0, 0.0], "axes": "z_up" }
//! ```
//!
//! The sidecar of `city.obj` is `city.obj.json`, or else `city.json` (the first that exists).
//! A file's vertex `(x, y, z)` becomes the CRS coordinate `axes(x, y, z) + offset`, where `z_up` keeps
//! the vertex as it is and `y_up` (Blender/glTF-style exports) maps it to `(x, −z, y)`; the result is
//! easting/longitude first ([`AxisConvention::EastNorth`]) whatever the CRS authority says.
//!
//! # Buildings
//! OBJ carries no building IDs, so buildings are the connected components of the face graph
//! ([`split_connected`]), with ids `"<file name>#cc<N>"` numbered from 0 in the order of their first
//! face. Connectivity follows the file's own vertex indices across the whole file; `o`/`g` object and
//! group names (and materials) are ignored on purpose: exporters routinely put a whole district in one
//! object, or cut one building into per-material groups, so names are not a reliable building
//! identity, while shared vertices are. Set [`ReadOptions::weld_tolerance_m`] to also connect
//! vertices that are duplicated rather than shared.
//!
//! Faces are triangulated as fans by tobj (convex polygons, as city-model exports produce).
//! Coordinates are parsed as f64 (tobj's `use_f64` feature), so projected coordinates keep
//! millimetres.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::error::{ObjProblem, SyntaxProblem};
use super::split::split_connected;
use super::{
    AxisConvention, Frame, Geometry, LodError, ReadOptions, ReadStats, SourceBuilding, SourceModel, TriMesh,
};

/// Which way is up in the OBJ file's vertex coordinates.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObjAxes {
    /// `(x, y, z)` = (east, north, up) — GIS exports, CityGML/CityJSON conversions.
    #[default]
    ZUp,
    /// `(x, y, z)` = (east, up, south) — Blender's default OBJ export, glTF-style; mapped to
    /// `(x, −z, y)`.
    YUp,
}

/// The geo-referencing of one OBJ file, read from its sidecar JSON (`<file>.obj.json` or `<file>.json`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjSidecar {
    /// CRS of `vertex + offset`, e.g. `"EPSG:6677"` (JGD2011 / Japan Plane Rectangular CS IX).
    /// `None` leaves the choice to the scene file's `crs`.
    #[serde(default)]
    pub crs: Option<String>,
    /// Added to every (axis-corrected) vertex, in CRS units (metres for projected CRSs);
    /// default `[0, 0, 0]`.
    #[serde(default)]
    pub offset: [f64; 3],
    /// Up axis of the file's vertex coordinates; default `z_up`.
    #[serde(default)]
    pub axes: ObjAxes,
    /// LoD to report for the buildings (e.g. `"2"`); default `"unknown"`.
    #[serde(default)]
    pub lod: Option<String>,
}

/// The sidecar files looked for next to `obj_path`, in order: `<file>.obj.json`, then `<stem>.json`.
pub fn sidecar_candidates(obj_path: &Path) -> [PathBuf; 2] {
    let mut with_json = obj_path.as_os_str().to_owned();
    with_json.push(".json");
    [PathBuf::from(with_json), obj_path.with_extension("json")]
}

/// Reads the sidecar of `obj_path` (see [`sidecar_candidates`]).
///
/// # Errors
/// [`LodError::Invalid`] naming the OBJ and the paths tried when there is no sidecar (with an example
/// to copy); [`LodError::Malformed`] naming the sidecar when it is not valid sidecar JSON.
pub fn find_sidecar(obj_path: &Path) -> Result<(PathBuf, ObjSidecar), LodError> {
    let candidates = sidecar_candidates(obj_path);
    let Some(found) = candidates.iter().find(|p| p.is_file()) else {
        return Err(LodError::invalid(
            obj_path,
            "sidecar",
            ObjProblem::NoSidecar { tried: candidates.clone() },
        ));
    };
    let bytes = crate::util::read_file(found)?;
    let sidecar: ObjSidecar = serde_json::from_slice(&bytes)
        .map_err(|e| LodError::unparsable(found, SyntaxProblem::ObjSidecar, e))?;
    if let Some(bad) = sidecar.offset.iter().find(|c| !c.is_finite()) {
        return Err(LodError::invalid(found, "offset", ObjProblem::Offset { value: *bad }));
    }
    Ok((found.clone(), sidecar))
}

/// Reads an OBJ file with its sidecar (see the module docs).
///
/// # Errors
/// A missing or invalid sidecar, an unreadable or unparsable OBJ, a non-finite vertex, an invalid
/// weld tolerance, or an OBJ without faces — each naming the file.
pub fn read(path: &Path, opts: &ReadOptions) -> Result<SourceModel, LodError> {
    let (_, sidecar) = find_sidecar(path)?;
    read_with_sidecar(path, &sidecar, opts)
}

/// Reads an OBJ file geo-referenced by `sidecar` (given by the caller instead of a sidecar file,
/// e.g. from a scene file).
///
/// # Errors
/// As [`read`], except for the sidecar lookup.
pub fn read_with_sidecar(
    path: &Path,
    sidecar: &ObjSidecar,
    opts: &ReadOptions,
) -> Result<SourceModel, LodError> {
    opts.check_weld_tolerance(path)?;
    let bytes = crate::util::read_file(path)?;
    let text = String::from_utf8_lossy(&bytes);
    let (mesh, stats) = parse_obj(&text, sidecar, path)?;
    if mesh.triangles.is_empty() {
        return Err(LodError::invalid(path, "faces", ObjProblem::NoFaces));
    }
    let file_name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let lod = sidecar.lod.clone().unwrap_or_else(|| "unknown".to_string());
    let buildings = split_connected(&mesh, opts.weld_tolerance_m)
        .into_iter()
        .enumerate()
        .map(|(n, part)| SourceBuilding {
            source_id: format!("{file_name}#cc{n}"),
            lod: lod.clone(),
            measured_height_m: None,
            ground_heights_m: Vec::new(),
            geometry: Geometry::Mesh(part),
            appearance: Vec::new(),
        })
        .collect();
    Ok(SourceModel {
        path: path.to_path_buf(),
        frame: Frame::Crs { name: sidecar.crs.clone(), axes: AxisConvention::EastNorth },
        buildings,
        stats,
        appearance: Default::default(),
    })
}

/// Parses OBJ text into one mesh in CRS coordinates (axes applied, offset added).
///
/// `o`, `g`, `usemtl` and `mtllib` lines are dropped before tobj sees the text, so that tobj keeps the
/// whole file as one model indexed by the file's own vertex numbers (it would otherwise re-index each
/// object separately and lose the vertices objects share) and never tries to open material files.
/// `path` names the file in errors.
fn parse_obj(text: &str, sidecar: &ObjSidecar, path: &Path) -> Result<(TriMesh, ReadStats), LodError> {
    let mut filtered = String::with_capacity(text.len());
    for line in text.lines() {
        let keyword = line.split_whitespace().next().unwrap_or("");
        if !matches!(keyword, "o" | "g" | "usemtl" | "mtllib") {
            filtered.push_str(line);
            filtered.push('\n');
        }
    }
    // All four fields of tobj's LoadOptions without its `merging`/`reordering` features (off here).
    let load =
        tobj::LoadOptions { single_index: false, triangulate: true, ignore_points: true, ignore_lines: true };
    let (models, _materials) = tobj::load_obj_buf(&mut Cursor::new(filtered.as_bytes()), &load, |_| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .map_err(|e| LodError::unparsable(path, SyntaxProblem::Obj, e))?;

    let mut mesh = TriMesh::default();
    let mut stats = ReadStats::default();
    for model in &models {
        let base = mesh.positions.len() as u32;
        // `as f64` is a no-op with tobj's `use_f64` feature and a widening otherwise.
        #[allow(clippy::unnecessary_cast)]
        for (k, v) in model.mesh.positions.chunks_exact(3).enumerate() {
            let local = [v[0] as f64, v[1] as f64, v[2] as f64];
            if local.iter().any(|c| !c.is_finite()) {
                let at = format!("vertex {} of object {:?}", k + 1, model.name);
                return Err(LodError::invalid(path, at, ObjProblem::Vertex { position: local }));
            }
            let axed = match sidecar.axes {
                ObjAxes::ZUp => local,
                ObjAxes::YUp => [local[0], -local[2], local[1]],
            };
            let o = sidecar.offset;
            mesh.positions.push([axed[0] + o[0], axed[1] + o[1], axed[2] + o[2]]);
        }
        for t in model.mesh.indices.chunks_exact(3) {
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                stats.degenerate_faces += 1;
                continue;
            }
            mesh.triangles.push([base + t[0], base + t[1], base + t[2]]);
        }
    }
    stats.faces = mesh.triangles.len() as u64;
    Ok((mesh, stats))
}

#[cfg(test)]
mod tests {
    use super::*;

    mod parse {
        use super::*;

        #[test]
        fn groups_do_not_cut_shared_vertices() {
            // Two groups sharing vertices 2 and 3 by index: one component.
            let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 2 0\n\
                       o roof\nf 1 2 3\ng wall\nusemtl brick\nf 3 4 1\nf 3 5 4\n";
            let (mesh, stats) = parse_obj(obj, &ObjSidecar::default(), Path::new("t.obj")).unwrap();
            assert_eq!(mesh.triangles.len(), 3);
            assert_eq!(stats.faces, 3);
            assert_eq!(split_connected(&mesh, None).len(), 1);
        }

        #[test]
        fn quads_are_triangulated_and_axes_applied() {
            let obj = "v 1 2 3\nv 2 2 3\nv 2 5 3\nv 1 5 3\nf 1 2 3 4\n";
            let sidecar =
                ObjSidecar { offset: [100.0, 200.0, 10.0], axes: ObjAxes::YUp, ..Default::default() };
            let (mesh, _) = parse_obj(obj, &sidecar, Path::new("t.obj")).unwrap();
            assert_eq!(mesh.triangles.len(), 2);
            // (x, y, z) = (1, 2, 3) → (x, −z, y) = (1, −3, 2) → + offset.
            assert!(mesh.positions.contains(&[101.0, 197.0, 12.0]));
        }

        #[test]
        fn degenerate_faces_counted() {
            let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nf 1 1 2\n";
            let (mesh, stats) = parse_obj(obj, &ObjSidecar::default(), Path::new("t.obj")).unwrap();
            assert_eq!(mesh.triangles.len(), 1);
            assert_eq!(stats.degenerate_faces, 1);
        }

        #[test]
        fn out_of_range_index_is_an_error() {
            let obj = "v 0 0 0\nv 1 0 0\nf 1 2 7\n";
            let e = parse_obj(obj, &ObjSidecar::default(), Path::new("t.obj")).unwrap_err();
            assert!(
                matches!(e, LodError::Malformed { source: Some(crate::lod::ParseError::Obj(_)), .. }),
                "{e:?}"
            );
            assert!(crate::util::error_chain(&e).starts_with("t.obj: cannot parse OBJ: "), "{e}");
        }

        #[test]
        fn large_coordinates_keep_millimetres() {
            let obj =
                "v 512345.678 3912345.678 40.001\nv 512346 3912345.678 40\nv 512346 3912346 40\nf 1 2 3\n";
            let (mesh, _) = parse_obj(obj, &ObjSidecar::default(), Path::new("t.obj")).unwrap();
            assert_eq!(mesh.positions[0], [512345.678, 3912345.678, 40.001]);
        }
    }

    mod sidecar {
        use super::*;

        #[test]
        fn candidates() {
            let c = sidecar_candidates(Path::new("/d/city.obj"));
            assert_eq!(c[0], PathBuf::from("/d/city.obj.json"));
            assert_eq!(c[1], PathBuf::from("/d/city.json"));
        }

        #[test]
        fn defaults_and_unknown_fields() {
            let s: ObjSidecar = serde_json::from_str(r#"{"crs": "EPSG:6677"}"#).unwrap();
            assert_eq!(s.offset, [0.0; 3]);
            assert_eq!(s.axes, ObjAxes::ZUp);
            assert!(serde_json::from_str::<ObjSidecar>(r#"{"crs": "EPSG:6677", "ofset": [1,2,3]}"#).is_err());
            assert!(serde_json::from_str::<ObjSidecar>(r#"{"axes": "x_up"}"#).is_err());
        }
    }
}
