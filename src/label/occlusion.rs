//! Masks that respect what a photogrammetry tileset shows (issue 17, items 2 and 3): the LoD ID map
//! and depth of a frame are compared, pixel by pixel, with the depth of the tileset rendered by the
//! same renderer at the same view (the tileset's triangles uploaded as one more mesh).
//!
//! For a pixel of LoD building `b` at depth `d_lod` where the tileset surface is at `d_tiles` (0 = the
//! tileset shows nothing), with threshold `t`:
//! - `d_tiles > 0` and `d_tiles < d_lod − t`: something the LoD model lacks (a tree, a crane, an
//!   unmodelled structure) stands in front: the pixel is **occluded** and leaves the instance (id 0;
//!   with [`OcclusionMode::Ignore`] it is also listed in the ignore mask);
//! - `d_tiles == 0` or `d_tiles > d_lod + t`: the tileset sees past the LoD building: the building is
//!   not there (demolished, misplaced): counted as **behind** for `b`, the pixel stays;
//! - otherwise the two models **agree** at the pixel.
//!
//! The per-frame consistency score is `agree / (LoD building pixels)`: 1 when the tileset confirms
//! every LoD pixel, lower when the LoD model is shifted (its silhouette lands on ground or other
//! buildings at other depths) or occluded.
//!
//! `render-masks --tileset` applies it to every frame before instances are computed (see
//! [`crate::label::stage`]) and records an [`OcclusionRecord`] in each frame's instance list.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::scene::{BuildingId, IdError, IdMap};

/// What happens to occluded pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OcclusionMode {
    /// Removed from the instance (background).
    Remove,
    /// Removed from the instance and marked in an ignore mask (for COCO-style `ignore` regions).
    Ignore,
}

/// Per-building counts of one frame, pixels.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct BuildingOcclusion {
    /// LoD pixels before the comparison.
    pub lod_px: u64,
    /// Pixels removed because the tileset shows something in front.
    pub occluded_px: u64,
    /// Pixels where the tileset sees past the building (nothing there, or far behind).
    pub behind_px: u64,
}

/// The result for one frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameOcclusion {
    /// Occluded pixels (all buildings), pixels where the tileset sees past the LoD, and agreeing ones.
    pub occluded_px: u64,
    /// Pixels where the tileset sees past the LoD surface (farther than the threshold behind it).
    pub behind_px: u64,
    /// LoD building pixels where the tileset agrees within the threshold.
    pub agree_px: u64,
    /// `agree_px / LoD building pixels` (1 for a frame without buildings).
    pub consistency: f64,
    /// Per building, its counts.
    pub buildings: BTreeMap<BuildingId, BuildingOcclusion>,
}

/// A building counts as [`BuildingRecord::see_through`] when more than this fraction of its LoD
/// pixels see past it (the tileset shows ground or something far behind): demolished or misplaced.
pub const SEE_THROUGH_FRACTION: f64 = 0.5;

/// Per-building counts as recorded in a frame's instance list.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct BuildingRecord {
    /// The building.
    pub building_id: BuildingId,
    /// LoD pixels before the comparison, pixels removed as occluded, pixels where the tileset sees
    /// past the building.
    pub lod_px: u64,
    /// Pixels removed as occluded (the tileset shows something in front).
    pub occluded_px: u64,
    /// Pixels where the tileset sees past the LoD surface (farther than the threshold behind it).
    pub behind_px: u64,
    /// More than [`SEE_THROUGH_FRACTION`] of the LoD pixels see past the building.
    pub see_through: bool,
}

/// What `render-masks --tileset` records per frame (`occlusion` in `<frame>.instances.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OcclusionRecord {
    /// The tileset the depth came from ([`crate::lod::tiles3d::fingerprint`]: a SHA-256 over its JSON
    /// files and its contents' names and sizes), the mode and the threshold: part of the frame's
    /// fingerprint (a resumed run re-renders frames made with other settings or another tileset).
    pub tileset_sha256: String,
    /// Remove occluded pixels, or also mark them in `<frame>.ignore.png`.
    pub mode: OcclusionMode,
    /// How far in front of the LoD surface the tileset must be for a pixel to count as occluded, metres.
    pub threshold_m: f32,
    /// Totals over the frame's LoD building pixels (see the module doc).
    pub occluded_px: u64,
    /// Pixels where the tileset sees past the LoD surface (farther than the threshold behind it).
    pub behind_px: u64,
    /// LoD building pixels where the tileset agrees within the threshold.
    pub agree_px: u64,
    /// `agree_px / LoD building pixels`, 1 without buildings.
    pub consistency: f64,
    /// Every LoD building of the frame, by ID (also the ones the tileset hides entirely).
    pub buildings: Vec<BuildingRecord>,
}

impl OcclusionRecord {
    /// The record of one frame's [`FrameOcclusion`].
    pub fn new(tileset_sha256: &str, mode: OcclusionMode, threshold_m: f32, f: &FrameOcclusion) -> Self {
        OcclusionRecord {
            tileset_sha256: tileset_sha256.to_string(),
            mode,
            threshold_m,
            occluded_px: f.occluded_px,
            behind_px: f.behind_px,
            agree_px: f.agree_px,
            consistency: f.consistency,
            buildings: f
                .buildings
                .iter()
                .map(|(&building_id, b)| BuildingRecord {
                    building_id,
                    lod_px: b.lod_px,
                    occluded_px: b.occluded_px,
                    behind_px: b.behind_px,
                    see_through: b.lod_px > 0 && b.behind_px as f64 > SEE_THROUGH_FRACTION * b.lod_px as f64,
                })
                .collect(),
        }
    }
}

/// Errors of [`occlude`].
#[derive(Debug, thiserror::Error)]
pub enum OcclusionError {
    /// The LoD render and the tileset render have different pixel counts.
    #[error("LoD and tileset depth differ in size: {lod} vs {tiles} pixels")]
    SizeMismatch {
        /// Pixels of the LoD depth map.
        lod: usize,
        /// Pixels of the tileset depth map.
        tiles: usize,
    },
    /// The occlusion threshold (metres) is negative or not finite.
    #[error("occlusion threshold {0} m must be a finite number ≥ 0")]
    Threshold(f32),
    /// The LoD ID map is not an ID map.
    #[error(transparent)]
    Ids(#[from] IdError),
}

/// Compares a frame's LoD IDs and depth with the tileset's depth (see the module doc); returns the
/// final ID map, the ignore mask (with [`OcclusionMode::Ignore`]) and the counts.
///
/// # Errors
/// [`OcclusionError`] when the buffers differ in size or the threshold is not a distance.
pub fn occlude(
    ids: &IdMap,
    lod_depth_m: &[f32],
    tiles_depth_m: &[f32],
    threshold_m: f32,
    mode: OcclusionMode,
) -> Result<(IdMap, Option<Vec<bool>>, FrameOcclusion), OcclusionError> {
    let n = ids.ids().len();
    if lod_depth_m.len() != n || tiles_depth_m.len() != n {
        return Err(OcclusionError::SizeMismatch {
            lod: lod_depth_m.len().min(n),
            tiles: tiles_depth_m.len(),
        });
    }
    if !(threshold_m.is_finite() && threshold_m >= 0.0) {
        return Err(OcclusionError::Threshold(threshold_m));
    }
    let mut out = ids.ids().to_vec();
    let mut ignore = (mode == OcclusionMode::Ignore).then(|| vec![false; n]);
    let mut f = FrameOcclusion {
        occluded_px: 0,
        behind_px: 0,
        agree_px: 0,
        consistency: 1.0,
        buildings: BTreeMap::new(),
    };
    let mut lod_px = 0u64;
    for i in 0..n {
        let b = out[i];
        if b.is_background() {
            continue;
        }
        lod_px += 1;
        let (dl, dt) = (lod_depth_m[i], tiles_depth_m[i]);
        let e = f.buildings.entry(b).or_default();
        e.lod_px += 1;
        if dt > 0.0 && dt < dl - threshold_m {
            e.occluded_px += 1;
            f.occluded_px += 1;
            out[i] = BuildingId::BACKGROUND;
            if let Some(m) = ignore.as_mut() {
                m[i] = true;
            }
        } else if dt <= 0.0 || dt > dl + threshold_m {
            e.behind_px += 1;
            f.behind_px += 1;
        } else {
            f.agree_px += 1;
        }
    }
    if lod_px > 0 {
        f.consistency = f.agree_px as f64 / lod_px as f64;
    }
    Ok((IdMap::new(ids.width(), ids.height(), out)?, ignore, f))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(v: &[u32]) -> IdMap {
        IdMap::new(v.len() as u32, 1, v.iter().map(|&i| BuildingId::new(i).unwrap()).collect()).unwrap()
    }

    #[test]
    fn classifies_each_pixel() {
        // Pixels: background; b1 with a tree 10 m in front; b1 agreeing; b1 with nothing in the
        // tileset; b2 with the tileset 20 m behind; b2 within the threshold (1 m behind).
        let ids = map(&[0, 1, 1, 1, 2, 2]);
        let lod = [0.0, 50.0, 50.0, 50.0, 60.0, 60.0];
        let tiles = [30.0, 40.0, 50.2, 0.0, 80.0, 61.0];
        let (out, ignore, f) = occlude(&ids, &lod, &tiles, 1.5, OcclusionMode::Ignore).unwrap();
        assert_eq!(out.ids().iter().map(|b| b.get()).collect::<Vec<_>>(), [0, 0, 1, 1, 2, 2]);
        assert_eq!(ignore.unwrap(), [false, true, false, false, false, false]);
        assert_eq!((f.occluded_px, f.behind_px, f.agree_px), (1, 2, 2));
        assert_eq!(f.consistency, 2.0 / 5.0);
        let b1 = f.buildings[&BuildingId::new(1).unwrap()];
        assert_eq!((b1.lod_px, b1.occluded_px, b1.behind_px), (3, 1, 1));
    }

    #[test]
    fn the_record_flags_buildings_that_are_mostly_seen_through() {
        // b1: 2 of 3 pixels see past it; b2: 1 of 2 (not more than half).
        let ids = map(&[1, 1, 1, 2, 2]);
        let lod = [50.0; 5];
        let tiles = [0.0, 90.0, 50.0, 0.0, 50.0];
        let f = occlude(&ids, &lod, &tiles, 1.5, OcclusionMode::Remove).unwrap().2;
        let r = OcclusionRecord::new("abc", OcclusionMode::Remove, 1.5, &f);
        assert_eq!((r.behind_px, r.agree_px, r.occluded_px), (3, 2, 0));
        assert_eq!(r.buildings.iter().map(|b| b.see_through).collect::<Vec<_>>(), [true, false]);
        let back: OcclusionRecord = serde_json::from_value(serde_json::to_value(&r).unwrap()).unwrap();
        assert_eq!(back, r);
    }

    #[test]
    fn bad_sizes_and_thresholds_are_errors() {
        let ids = map(&[1, 1]);
        assert!(occlude(&ids, &[1.0], &[1.0, 1.0], 1.0, OcclusionMode::Remove).is_err());
        assert!(occlude(&ids, &[1.0, 1.0], &[1.0, 1.0], f32::NAN, OcclusionMode::Remove).is_err());
    }
}
