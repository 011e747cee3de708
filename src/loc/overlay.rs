//! `overlays/<frame>.png` of `eval-loc`: what the localizer saw and what it found, for one query.
//!
//! Three panels, each the map's buildings rendered at one pose (one colour per building) with the
//! query's instance masks outlined in white over them: at the **prior** (where the search starts), at
//! the **estimate** (where it ended) and at the **truth** (the ground-truth pose). Where the outlines
//! fit the rendered buildings, the pose explains the query. Each panel is captioned with its pose's
//! error against the truth (metres, degrees); a title band names the query, the cost and whether the
//! estimate is a success at the paper's tightest threshold (both errors strictly below 2 m and 2°,
//! [`super::metrics::THRESHOLDS`]).

use std::path::Path;

use super::cost::Query;
use super::eval::{EvalError, QueryResult};
use super::metrics::{within_2m_2deg, THRESHOLDS};
use crate::camera::{Intrinsics, Pose};
use crate::render::cpu::Frame;
use crate::render::{IdScene, View};
use crate::util::figure::{text, Align, RgbImage, TextStyle, INK, WHITE};
use crate::util::{self, FileError};

/// Gap between panels, px.
const GAP_PX: i64 = 8;
/// Height of the title band, px.
const HEADER_PX: i64 = 60;
/// Height of the caption band under the panels, px.
const CAPTION_PX: i64 = 30;
/// Success and failure colours of the title.
const SUCCESS: [u8; 3] = [20, 130, 50];
const FAILURE: [u8; 3] = [190, 30, 30];

/// A building's colour in the panels (background dark).
fn palette(id: u32) -> [u8; 3] {
    if id == 0 {
        return [20, 20, 24];
    }
    let h = id.wrapping_mul(2_654_435_761);
    [(h >> 24) as u8 | 0x40, (h >> 16) as u8 | 0x40, (h >> 8) as u8 | 0x40]
}

/// The three panels' captions: the pose and its error against the truth.
fn captions(r: &QueryResult) -> [String; 3] {
    [
        format!("prior: {:.2} m, {:.2}° from truth", r.prior_translation_error_m, r.prior_rotation_error_deg),
        format!("estimate: {:.2} m, {:.2}° from truth", r.translation_error_m, r.rotation_error_deg),
        "truth: the ground-truth pose".to_string(),
    ]
}

/// The title: the query, the cost, and success or failure at the tightest threshold.
fn title(r: &QueryResult) -> (String, bool) {
    let (t_m, r_deg) = THRESHOLDS[0];
    let ok = within_2m_2deg(r.translation_error_m, r.rotation_error_deg);
    let verdict = if ok {
        format!("✓ success: estimate within {t_m} m and {r_deg}°")
    } else {
        format!("✗ failure: estimate not within {t_m} m and {r_deg}°")
    };
    let cost = format!("{:?}", r.cost).to_lowercase();
    (format!("Query {} · cost {cost} · {verdict}", r.name), ok)
}

/// Draws the overlay of one query: `poses` are the prior, the estimate and the truth, rendered from
/// `scene` at intrinsics `k` (the query's resolution); `q` the query's instances; `r` its result.
///
/// # Errors
/// [`EvalError::Render`] when the renderer fails.
pub fn draw_overlay(
    scene: &dyn IdScene,
    k: &Intrinsics,
    q: &Query,
    poses: [&Pose; 3],
    r: &QueryResult,
) -> Result<RgbImage, EvalError> {
    let (w, h) = (k.width_px as usize, k.height_px as usize);
    let mut qlab = vec![0u32; w * h];
    for (j, inst) in q.instances.iter().enumerate() {
        for p in inst.pixels() {
            qlab[p as usize] = j as u32 + 1;
        }
    }
    let total_w = 3 * w as i64 + 2 * GAP_PX;
    let mut img = RgbImage::new(total_w as u32, (HEADER_PX + h as i64 + CAPTION_PX) as u32, WHITE);
    let mut frame = Frame::default();
    let caption = TextStyle::new(text::LABEL_PX, INK).aligned(Align::Centre);
    for ((panel, pose), label) in poses.iter().enumerate().zip(captions(r)) {
        scene.render_into(&View { intrinsics: *k, pose: **pose }, &mut frame)?;
        let x0 = panel as i64 * (w as i64 + GAP_PX);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let edge = qlab[i] != 0 && super::morph::on_outline(i, w, h, |j| qlab[j]);
                let c = if edge { WHITE } else { palette(frame.ids[i]) };
                img.put(x0 + x as i64, HEADER_PX + y as i64, c);
            }
        }
        img.text(x0 + w as i64 / 2, HEADER_PX + h as i64 + 6, &label, caption);
    }
    let (line, ok) = title(r);
    img.text(10, 6, &line, TextStyle::new(text::TITLE_PX, if ok { SUCCESS } else { FAILURE }));
    let sub = format!(
        "white outlines: the query's {} instance masks; colours: the map's buildings rendered at each pose",
        q.instances.len()
    );
    img.text(10, 8 + text::line_height(text::TITLE_PX), &sub, TextStyle::new(text::TICK_PX, [70, 70, 70]));
    Ok(img)
}

/// Draws the overlay of one query ([`draw_overlay`]) and writes it to `<out_dir>/overlays/<name>.png`.
///
/// # Errors
/// As [`draw_overlay`]; I/O and encoding errors naming the file.
pub fn write_overlay(
    out_dir: &Path,
    scene: &dyn IdScene,
    k: &Intrinsics,
    q: &Query,
    poses: [&Pose; 3],
    r: &QueryResult,
) -> Result<(), EvalError> {
    let img = draw_overlay(scene, k, q, poses, r)?;
    let path = out_dir.join("overlays").join(format!("{}.png", r.name));
    let bytes = crate::export::raster::encode_png_rgb(&img.data, img.width, img.height, &path)
        .map_err(|e| FileError::new("encoding PNG", &path, std::io::Error::other(e)))?;
    util::write_bytes_atomic(&path, &bytes)?;
    Ok(())
}
