//! Photogrammetry tilesets for RGB: pick the tiles the cameras see, turn them into plain GLBs Blender
//! imports, and place them in the area's ENU frame.
//!
//! The tileset is read by [`crate::lod::tiles3d`] (tileset JSON, external tilesets, transforms,
//! bounding volumes, implicit tiling, b3dm/glb/glTF/cmpt contents and their extensions); this module
//! only chooses tiles and prepares them. For each frame the tree is traversed as a 3D Tiles renderer
//! would: a tile is kept when its bounding volume (as a sphere) intersects the camera frustum, and
//! refined into its children while its screen-space error `geometricError · fy / distance` exceeds a
//! threshold (REPLACE drops the parent's content, ADD keeps it). External tilesets are loaded when a
//! visible tile reaches them. The union over a batch of frames becomes the job's model list, and each
//! frame lists the tiles it shows.
//!
//! Each chosen content is converted by [`crate::lod::tiles3d::plain::importable_glb`] into a GLB
//! without required extensions (Draco, meshopt and quantization decoded, `KHR_texture_transform` baked
//! into the UVs, WebP re-encoded as PNG; KTX2 refused by name), because Blender's importer reads
//! neither meshopt nor KTX2 and insgen's own decoders are tested. Image and material names are
//! prefixed per content, so tiles whose textures are all called `texture_0` stay apart.
//!
//! Placement (3D Tiles spec, "glTF transforms" and b3dm `RTC_CENTER`; CesiumJS applies the same order):
//! `ECEF = tile transform · translate(RTC_CENTER or CESIUM_RTC.center) · Y2Z · glTF`, where Y2Z turns
//! glTF's y-up into z-up, (x, y, z) → (x, −z, y) (identity when the tileset says `gltfUpAxis: "Z"`).
//! Hence `ENU_from_glTF = ENU_from_ECEF · tile transform · translate(rtc) · Y2Z`. The plain GLB holds
//! `translate(rtc) · Y2Z · glTF` computed in f64 relative to its centre `c`, so the job gets
//! `ENU_from_ECEF · tile transform · translate(c)`, whose translation is small (the tile's position
//! relative to the area origin): Blender's float32 matrices lose nothing.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{DMat4, DVec3};

use super::camera::Mat4;
use super::error::BlenderError;
use super::job::{JobModel, ModelKind};
use crate::camera::{Intrinsics, Pose};
use crate::geo::EnuFrame;
use crate::lod::tiles3d::{plain, Refine, Tile, Tileset, UpAxis};

/// ENU-from-glTF of the prepared `scene.glb`, whose glTF (x, y, z) = ENU (e, u, −n): the y-up to z-up
/// turn (x, y, z) → (x, −z, y). Row-major, as the job file stores it.
pub const ENU_FROM_SCENE_GLTF: Mat4 =
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

// ------------------------------------------------------------------------------------------ selection

/// Options of the tile selection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelectOptions {
    /// Largest screen-space error tolerated before a tile is refined, pixels (CesiumJS default: 16).
    pub max_sse_px: f64,
}

impl Default for SelectOptions {
    fn default() -> Self {
        SelectOptions { max_sse_px: 16.0 }
    }
}

/// One tile content chosen for rendering.
#[derive(Debug, Clone, PartialEq)]
pub struct SelectedTile {
    /// The content file (b3dm, glb, glTF or cmpt).
    pub content: PathBuf,
    /// The tileset JSON holding the tile, and the tile's JSON path in it (`root.children[2]`).
    pub tileset: PathBuf,
    /// The tile's JSON path in `tileset` (`root.children[2]`).
    pub tile_at: String,
    /// The tile's refinement.
    pub refine: Refine,
    /// ECEF-from-tile transform, all ancestors' transforms included.
    pub ecef_from_tile: DMat4,
    /// The up axis of the content's glTF.
    pub up_axis: UpAxis,
}

/// The tiles a set of cameras sees.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TileSelection {
    /// Distinct tile contents, in order of first use.
    pub tiles: Vec<SelectedTile>,
    /// For each camera, the indices into `tiles` it shows.
    pub per_frame: Vec<Vec<u32>>,
    /// Contents skipped because they cannot be rendered (pnts, i3dm, …), by extension.
    pub skipped: BTreeMap<String, u64>,
}

/// Whether a sphere (ENU) intersects the camera's viewing frustum (no far plane).
pub fn sphere_in_frustum(k: &Intrinsics, pose: &Pose, centre_enu_m: DVec3, radius_m: f64) -> bool {
    let p = pose.world_to_cam(centre_enu_m);
    // Inward normals of the planes through the camera centre bounding the image: x ≥ −cx/fx · z, etc.
    let planes = [
        DVec3::new(1.0, 0.0, k.cx_px / k.fx_px),
        DVec3::new(-1.0, 0.0, (k.width_px as f64 - k.cx_px) / k.fx_px),
        DVec3::new(0.0, 1.0, k.cy_px / k.fy_px),
        DVec3::new(0.0, -1.0, (k.height_px as f64 - k.cy_px) / k.fy_px),
        DVec3::Z,
    ];
    planes.iter().all(|n| n.dot(p) / n.length() >= -radius_m)
}

/// Chooses the tiles each camera sees, refining by screen-space error (see the module doc).
///
/// # Errors
/// [`BlenderError::Tiles`] naming the tileset file and the JSON path of every problem.
pub fn select_tiles(
    tileset: &Path,
    enu: &EnuFrame,
    cameras: &[(Intrinsics, Pose)],
    opts: &SelectOptions,
) -> Result<TileSelection, BlenderError> {
    let root = Tileset::load(tileset, DMat4::IDENTITY)?;
    let mut external: BTreeMap<(PathBuf, [u64; 16]), Tileset> = BTreeMap::new();
    let mut sel = TileSelection::default();
    let mut index: BTreeMap<(PathBuf, [u64; 16]), u32> = BTreeMap::new();
    let enu_ecef = enu.enu_from_ecef();
    for (k, pose) in cameras {
        let mut chosen: Vec<u32> = Vec::new();
        let mut walk = Walk {
            k,
            pose,
            opts,
            enu_ecef,
            external: &mut external,
            out: Vec::new(),
            skipped: &mut sel.skipped,
        };
        walk.visit(&root.root, &root, 0)?;
        for t in walk.out {
            let key = (t.content.clone(), bits(&t.ecef_from_tile));
            let i = *index.entry(key).or_insert_with(|| {
                sel.tiles.push(t);
                sel.tiles.len() as u32 - 1
            });
            if !chosen.contains(&i) {
                chosen.push(i);
            }
        }
        chosen.sort_unstable();
        sel.per_frame.push(chosen);
    }
    Ok(sel)
}

fn bits(m: &DMat4) -> [u64; 16] {
    m.to_cols_array().map(f64::to_bits)
}

/// Depth limit of external tileset nesting (guards against cycles and pathological trees).
const MAX_EXTERNAL_DEPTH: usize = 32;

struct Walk<'a> {
    k: &'a Intrinsics,
    pose: &'a Pose,
    opts: &'a SelectOptions,
    enu_ecef: DMat4,
    external: &'a mut BTreeMap<(PathBuf, [u64; 16]), Tileset>,
    out: Vec<SelectedTile>,
    skipped: &'a mut BTreeMap<String, u64>,
}

impl Walk<'_> {
    fn visit(&mut self, t: &Tile, ts: &Tileset, depth: usize) -> Result<(), BlenderError> {
        let (c_ecef, radius_m) = t.bounding_volume.world_sphere(&t.world_from_tile);
        let c = self.enu_ecef.transform_point3(c_ecef);
        if !sphere_in_frustum(self.k, self.pose, c, radius_m) {
            return Ok(());
        }
        let d = (self.pose.centre_m.distance(c) - radius_m).max(1e-3);
        let sse_px = t.geometric_error_m * self.k.fy_px / d;
        let refine = !t.children.is_empty() && sse_px > self.opts.max_sse_px;
        if !refine || t.refine == Refine::Add {
            self.take_contents(t, ts, depth)?;
        } else {
            // REPLACE: the children stand in for this tile, but external tilesets are its children too.
            for c in &t.contents {
                if c.is_external_tileset() {
                    self.visit_external(&c.file, &t.world_from_tile, depth)?;
                }
            }
        }
        if refine {
            for c in &t.children {
                self.visit(c, ts, depth)?;
            }
        }
        Ok(())
    }

    fn take_contents(&mut self, t: &Tile, ts: &Tileset, depth: usize) -> Result<(), BlenderError> {
        for c in &t.contents {
            if c.is_external_tileset() {
                self.visit_external(&c.file, &t.world_from_tile, depth)?;
                continue;
            }
            let ext = c.file.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
            match ext.as_str() {
                "i3dm" | "pnts" | "vctr" | "geom" => *self.skipped.entry(ext).or_insert(0) += 1,
                _ => self.out.push(SelectedTile {
                    content: c.file.clone(),
                    tileset: ts.path.clone(),
                    tile_at: t.at.clone(),
                    refine: t.refine,
                    ecef_from_tile: t.world_from_tile,
                    up_axis: ts.up,
                }),
            }
        }
        Ok(())
    }

    fn visit_external(&mut self, path: &Path, parent: &DMat4, depth: usize) -> Result<(), BlenderError> {
        if depth >= MAX_EXTERNAL_DEPTH {
            return Err(BlenderError::TilesetDepth {
                path: path.to_path_buf(),
                max_depth: MAX_EXTERNAL_DEPTH,
            });
        }
        // External tilesets are keyed by path and parent transform (the same file may hang under
        // differently transformed tiles).
        let key = (path.to_path_buf(), bits(parent));
        if !self.external.contains_key(&key) {
            let loaded = Tileset::load(path, *parent)?;
            self.external.insert(key.clone(), loaded);
        }
        // Taken out and put back so the walk can borrow `self` mutably meanwhile.
        let ts = self.external.remove(&key).expect("inserted above");
        let r = self.visit(&ts.root, &ts, depth + 1);
        self.external.insert(key, ts);
        r
    }
}

// ------------------------------------------------------------------------------------------ preparation

/// Turns a selected tile into a job model: converts its content into a plain GLB in `cache_dir`
/// (see the module doc) and computes ENU-from-glTF.
///
/// # Errors
/// I/O errors naming the file; [`BlenderError::Tile`] naming the content, the tile and what is wrong
/// (an extension insgen refuses is named).
pub fn prepare_tile(tile: &SelectedTile, enu: &EnuFrame, cache_dir: &Path) -> Result<JobModel, BlenderError> {
    use sha2::{Digest, Sha256};
    let path = &tile.content;
    let bytes = crate::util::read_file(path)?;
    let imp = plain::importable_glb(&bytes, path, tile.up_axis).map_err(|source| BlenderError::Tile {
        content: path.clone(),
        tileset: tile.tileset.clone(),
        tile_at: tile.tile_at.clone(),
        source: Box::new(source),
    })?;
    let abs = path.canonicalize().unwrap_or_else(|_| path.clone());
    let digest = hex::encode(&Sha256::digest(abs.to_string_lossy().as_bytes())[..8]);
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("tile");
    let out = cache_dir.join(format!("{digest}-{stem}.glb"));
    crate::util::write_bytes_atomic(&out, &imp.glb)?;
    let enu_from_plain = enu.enu_from_ecef() * tile.ecef_from_tile * imp.tile_from_plain;
    Ok(JobModel {
        glb: out,
        enu_from_gltf: crate::util::row_major::rows(&enu_from_plain),
        kind: ModelKind::Photogrammetry,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::Geodetic;

    fn frame() -> EnuFrame {
        EnuFrame::new(Geodetic::new(35.658, 139.70, 40.0))
    }

    #[test]
    fn enu_from_ecef_inverts_the_frame() {
        let enu = frame();
        let m = enu.enu_from_ecef();
        for p in [[0.0, 0.0, 0.0], [123.0, -456.0, 78.9], [-2000.0, 3000.0, -50.0]] {
            let ecef = enu.enu_to_ecef(DVec3::from_array(p));
            let back = m.transform_point3(ecef);
            assert!(back.distance(DVec3::from_array(p)) < 1e-6, "{p:?} → {back:?}");
        }
    }

    #[test]
    fn row_major_is_the_transpose_of_glam_columns() {
        let m = DMat4::from_translation(DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(crate::util::row_major::rows(&m)[0][3], 1.0);
        assert_eq!(crate::util::row_major::rows(&m)[2][3], 3.0);
        let y2z = UpAxis::Y.to_z_up();
        assert_eq!(crate::util::row_major::rows(&y2z), ENU_FROM_SCENE_GLTF);
    }

    #[test]
    fn frustum_test_nadir() {
        // Nadir camera 100 m up, 90° HFOV on a square image: the footprint is ±100 m.
        let k = Intrinsics::from_hfov(100, 100, 90.0);
        let pose = Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 100.0]);
        assert!(sphere_in_frustum(&k, &pose, DVec3::new(0.0, 0.0, 0.0), 1.0));
        assert!(sphere_in_frustum(&k, &pose, DVec3::new(99.0, 0.0, 0.0), 1.0));
        // 105 m east: outside by 5/√2 ≈ 3.5 m from the plane x = z; a 3 m sphere misses, a 4 m one hits.
        assert!(!sphere_in_frustum(&k, &pose, DVec3::new(105.0, 0.0, 0.0), 3.0));
        assert!(sphere_in_frustum(&k, &pose, DVec3::new(105.0, 0.0, 0.0), 4.0));
        // Behind the camera.
        assert!(!sphere_in_frustum(&k, &pose, DVec3::new(0.0, 0.0, 200.0), 50.0));
    }
}
