//! The prepared scene as a 3D Tiles 1.1 tileset, so that CesiumJS (or any 3D Tiles viewer) shows it
//! where it belongs on the globe.
//!
//! Takes in a prepared scene directory (`scene.glb`, `manifest.json`, `buildings.json`); hands on a
//! folder (by default `<workdir>/<area>/scene/tileset/`) holding:
//! - `tileset.json` (3D Tiles 1.1): one root tile, `refine` REPLACE, geometric error 0 (a leaf), a
//!   `box` bounding volume in the area's ENU frame (the mesh bounds, padded by 1 cm for f32 rounding),
//!   and `transform` = the manifest's `ecef_from_enu` (column-major, as the spec stores matrices);
//!   the tileset's geometric error is the box diagonal (at least 1 m), so viewers draw the root from
//!   afar; `extras.insgen` carries the area name, split, origin, building count and attributions;
//! - `scene.glb`: a byte copy of the prepared scene, with its `EXT_mesh_features` feature IDs (the
//!   building IDs) and `EXT_structural_metadata` property table (`source_id` per building) kept, so a
//!   viewer can pick a building and show its source identity.
//!
//! # Frames
//! `scene.glb` is y-up, as glTF requires: glTF (x, y, z) = ENU (east, up, −north). 3D Tiles is z-up
//! and applies the fixed y-up → z-up rotation (+90° about x: (x, y, z) ↦ (x, −z, y)) to glTF content
//! before the tile transform, which gives back ENU (east, north, up). So a vertex `p` of `scene.glb`
//! lands at ECEF `ecef_from_enu · Y2Z · p`, exactly where `prepare` put it. Bounding volumes are in the
//! tile frame (ENU, z-up) and are not rotated.
//!
//! # References
//! 3D Tiles 1.1 specification (OGC 22-025r4): "Coordinate Reference System", "Tile transforms"
//! ("glTF transforms" — the y-up to z-up rotation), "Bounding volumes", "geometricError", "refine".

use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::util::FileError;

use crate::scene::artifact::{PreparedScene, GLB_FILE};
use crate::scene::SceneError;

/// Default folder name of the tileset inside a scene directory.
pub use crate::layout::TILESET_DIR;
/// The tileset JSON's file name.
pub const TILESET_FILE: &str = "tileset.json";

/// Padding of the bounding box around the mesh bounds, metres: covers the f32 rounding of positions
/// (≤ 0.25 mm at 2 km from the origin) many times over.
const BOX_PADDING_M: f64 = 0.01;

/// Errors of the tileset export.
#[derive(Debug, thiserror::Error)]
pub enum TilesetExportError {
    /// The prepared scene cannot be loaded.
    #[error("loading the prepared scene in {}", dir.display())]
    Scene {
        /// The scene directory.
        dir: PathBuf,
        /// Boxed: a scene error is large and this one is rare.
        #[source]
        source: Box<SceneError>,
    },
    /// The scene has no triangles: there is nothing to place on the globe.
    #[error("{}: the scene has no triangles; nothing to write", dir.display())]
    Empty {
        /// The scene directory.
        dir: PathBuf,
    },
    /// Writing a file failed.
    #[error(transparent)]
    File(#[from] FileError),
}

/// What [`write_scene_tileset`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct TilesetSummary {
    /// `tileset.json`.
    pub tileset: PathBuf,
    /// The content GLB.
    pub content: PathBuf,
    /// The root bounding box in ENU metres: centre and half sizes (east, north, up).
    pub centre_enu_m: [f64; 3],
    /// Half sizes of the root box (east, north, up), metres.
    pub half_size_m: [f64; 3],
}

/// Writes the tileset of the prepared scene in `scene_dir` into `out_dir`.
///
/// # Errors
/// [`TilesetExportError::Scene`] when the scene cannot be loaded (with the hint to run `prepare`),
/// [`TilesetExportError::Empty`] for a scene without triangles, [`TilesetExportError::File`] naming
/// the file that could not be read or written.
pub fn write_scene_tileset(scene_dir: &Path, out_dir: &Path) -> Result<TilesetSummary, TilesetExportError> {
    // The GLB is copied as prepared, so its bounds are the prepared ones; an alignment correction goes
    // into the root transform (ecef_from_lod_corrected = ecef_from_enu · correction).
    let scene = PreparedScene::load_as_prepared(scene_dir)
        .map_err(|e| TilesetExportError::Scene { dir: scene_dir.to_path_buf(), source: Box::new(e) })?;
    let Some((lo, hi)) = scene.mesh.bounds_m() else {
        return Err(TilesetExportError::Empty { dir: scene_dir.to_path_buf() });
    };
    let (lo, hi) = (DVec3::from(lo.map(f64::from)), DVec3::from(hi.map(f64::from)));
    let centre = (lo + hi) / 2.0;
    let half = (hi - lo) / 2.0 + DVec3::splat(BOX_PADDING_M);
    let glb = crate::util::read_file(&scene_dir.join(GLB_FILE))?;
    // The tileset's own error: the box diagonal, so that a viewer draws the root from far away.
    let tileset_error_m = (2.0 * half.length()).max(1.0);
    let m = &scene.manifest;
    let tileset = serde_json::json!({
        "asset": {"version": "1.1", "generator": format!("insgen {}", env!("CARGO_PKG_VERSION"))},
        "geometricError": tileset_error_m,
        "root": {
            "boundingVolume": {"box": [
                centre.x, centre.y, centre.z,
                half.x, 0.0, 0.0,
                0.0, half.y, 0.0,
                0.0, 0.0, half.z]},
            "geometricError": 0.0,
            "refine": "REPLACE",
            // 3D Tiles stores matrices column-major.
            "transform": m
                .alignment
                .as_ref()
                .map_or(m.ecef_from_enu, |a| a.ecef_from_lod_corrected)
                .to_cols_array(),
            "content": {"uri": GLB_FILE},
        },
        "extras": {"insgen": {
            "area": m.area,
            "split": m.split,
            "origin": m.origin,
            "buildings": m.buildings,
            "attributions": m.attributions,
        }},
    });
    let content = out_dir.join(GLB_FILE);
    crate::util::write_bytes_atomic(&content, &glb)?;
    copy_textures(scene_dir, out_dir)?;
    let path = out_dir.join(TILESET_FILE);
    crate::util::write_json_atomic(&path, &tileset)?;
    Ok(TilesetSummary {
        tileset: path,
        content,
        centre_enu_m: centre.to_array(),
        half_size_m: half.to_array(),
    })
}

/// Copies the scene's texture images (`textures/`, written by `prepare` for textured LoD models and
/// named by `scene.glb`) next to the exported GLB, sorted by name.
fn copy_textures(scene_dir: &Path, out_dir: &Path) -> Result<(), crate::util::FileError> {
    use crate::scene::appearance::TEXTURES_DIR;
    let from = scene_dir.join(TEXTURES_DIR);
    let Ok(entries) = std::fs::read_dir(&from) else { return Ok(()) };
    let mut files: Vec<std::path::PathBuf> =
        entries.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.is_file()).collect();
    files.sort();
    let to = out_dir.join(TEXTURES_DIR);
    crate::util::create_dir_all(&to)?;
    for f in files {
        let bytes = crate::util::read_file(&f)?;
        if let Some(name) = f.file_name() {
            crate::util::write_bytes_atomic(&to.join(name), &bytes)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_scene_names_the_directory_and_the_fix() {
        let dir = tempfile::tempdir().unwrap();
        let e = write_scene_tileset(dir.path(), &dir.path().join("t")).unwrap_err();
        let chain = crate::util::error_chain(&e);
        assert!(
            chain.starts_with(&format!("loading the prepared scene in {}", dir.path().display())),
            "{chain}"
        );
        assert!(chain.contains("insgen prepare"), "{chain}");
    }
}
