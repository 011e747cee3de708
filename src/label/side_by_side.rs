//! The side-by-side picture of `render-rgb --side-by-side K` (`rgb/side_by_side.png`): one row per
//! frame, three panels — the RGB frame; the mask's outlines (and a light tint per building) over it;
//! the clutter/occluder layer, i.e. what hides what: each clutter layer in its own flat colour
//! ([`layer_colour`]), buildings grey, the rest the darkened RGB — so a person can judge realism and
//! alignment at a glance.
//!
//! The layer panel is an ID render of the buildings plus every clutter layer, each layer under its own
//! pseudo-ID counted down from the top of the 24-bit range (never a building ID of a real area, see
//! [`LAYER_ID_BASE`]), with the frame's exact intrinsics and pose, so it lines up with the masks.

use std::path::{Path, PathBuf};

use super::overlay::{contact_sheet, overlay_ids, read_rgb_png, write_rgb_png, RgbImage};
use super::stage::StageError;
use crate::render::{RenderOptions, Renderer, View};
use crate::scene::clutter::ClutterLayer;
use crate::scene::{BuildingId, IdMap, PreparedScene, MAX_BUILDING_ID};

/// Pseudo-ID of clutter layer `k` (in [`ClutterLayer::ALL`] order) in the layer panel's render:
/// `LAYER_ID_BASE - k`.
pub const LAYER_ID_BASE: u32 = MAX_BUILDING_ID;
/// Width of one panel in the picture, pixels.
pub const PANEL_WIDTH_PX: u32 = 320;

/// The flat colour of a clutter layer in the layer panel (sRGB).
pub fn layer_colour(layer: ClutterLayer) -> [u8; 3] {
    match layer {
        ClutterLayer::Roads => [95, 95, 110],
        ClutterLayer::Markings => [255, 255, 255],
        ClutterLayer::Pavements => [185, 170, 140],
        ClutterLayer::GroundCover => [80, 170, 70],
        ClutterLayer::Trees => [20, 105, 35],
        ClutterLayer::Cars => [235, 60, 50],
        ClutterLayer::Rooftop => [70, 160, 235],
    }
}

/// One frame of the picture: its view, its RGB frame and its mask.
#[derive(Debug, Clone)]
pub struct SideFrame {
    /// Frame name.
    pub name: String,
    /// Its intrinsics and pose.
    pub view: View,
    /// The RGB frame (`rgb/<frame>.png`).
    pub rgb_png: PathBuf,
    /// The ID map (`masks/<frame>.png`).
    pub mask_png: PathBuf,
}

/// Writes the picture of `frames` (those whose RGB frame exists; at most `k`) to `out` (atomically).
/// A missing mask is rendered from the scene with the default occluders. Returns the frames shown.
///
/// # Errors
/// [`StageError`] when a PNG cannot be read or written or the GPU fails.
pub fn write_side_by_side(
    out: &Path,
    scene: &PreparedScene,
    renderer: &Renderer,
    frames: &[SideFrame],
    k: usize,
) -> Result<usize, StageError> {
    let mut layered = scene.mesh.clone();
    for (n, layer) in ClutterLayer::ALL.iter().enumerate() {
        if let Some(m) = scene.clutter.layer(*layer) {
            let id = BuildingId::new(LAYER_ID_BASE - n as u32).expect("below the 24-bit cap");
            let base = layered.positions_m.len() as u32;
            layered.positions_m.extend_from_slice(&m.positions_m);
            layered.building_ids.extend(std::iter::repeat_n(id, m.positions_m.len()));
            layered.indices.extend(m.indices.iter().map(|i| i + base));
        }
    }
    let gpu_layers = renderer.upload(&layered)?;
    let mut tiles = Vec::new();
    let mut shown = 0;
    for f in frames.iter().filter(|f| f.rgb_png.is_file()).take(k) {
        let rgb = read_rgb_png(&f.rgb_png)?;
        let mask = match IdMap::read_png(&f.mask_png) {
            Ok(m) => m,
            Err(_) => {
                let mesh = super::stage::occluded_mesh(scene, &ClutterLayer::DEFAULT_OCCLUDERS);
                let gpu = renderer.upload(&mesh)?;
                renderer.render(&gpu, &f.view, &RenderOptions::default())?.ids
            }
        };
        let layers = renderer.render(&gpu_layers, &f.view, &RenderOptions::default())?.ids;
        tiles.push(rgb.clone());
        tiles.push(overlay_ids(&mask, &rgb, 0.2));
        tiles.push(layer_panel(&layers, &rgb));
        shown += 1;
    }
    if shown == 0 {
        return Ok(0);
    }
    write_rgb_png(out, &contact_sheet(&tiles, 3, PANEL_WIDTH_PX))?;
    Ok(shown)
}

/// Clutter layers in their colours, buildings grey, elsewhere the RGB frame at a third of its
/// brightness (resampled nearest to the ID map's size).
fn layer_panel(ids: &IdMap, rgb: &RgbImage) -> RgbImage {
    let (w, h) = (ids.width(), ids.height());
    let mut out = RgbImage::filled(w, h, [0, 0, 0]);
    for y in 0..h {
        for x in 0..w {
            let id = ids.get(x, y).get();
            let k = LAYER_ID_BASE.wrapping_sub(id) as usize;
            let c = if id == 0 {
                let bx = ((x as u64 * rgb.width as u64) / w as u64) as u32;
                let by = ((y as u64 * rgb.height as u64) / h as u64) as u32;
                let i = 3 * (by as usize * rgb.width as usize + bx as usize);
                [rgb.rgb[i] / 3, rgb.rgb[i + 1] / 3, rgb.rgb[i + 2] / 3]
            } else if k < ClutterLayer::ALL.len() {
                layer_colour(ClutterLayer::ALL[k])
            } else {
                [150, 150, 150]
            };
            let i = 3 * (y as usize * w as usize + x as usize);
            out.rgb[i..i + 3].copy_from_slice(&c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layer_panel_colours_layers_buildings_and_background() {
        let ids = IdMap::from_raw(4, 1, vec![0, 5, LAYER_ID_BASE - 4, LAYER_ID_BASE]).unwrap();
        let rgb = RgbImage::filled(4, 1, [90, 60, 30]);
        let p = layer_panel(&ids, &rgb);
        assert_eq!(&p.rgb[0..3], &[30, 20, 10]);
        assert_eq!(&p.rgb[3..6], &[150, 150, 150]);
        assert_eq!(&p.rgb[6..9], &layer_colour(ClutterLayer::Trees));
        assert_eq!(&p.rgb[9..12], &layer_colour(ClutterLayer::Roads));
    }

    #[test]
    fn layer_colours_differ() {
        let set: std::collections::BTreeSet<[u8; 3]> =
            ClutterLayer::ALL.iter().map(|l| layer_colour(*l)).collect();
        assert_eq!(set.len(), ClutterLayer::ALL.len());
    }
}
