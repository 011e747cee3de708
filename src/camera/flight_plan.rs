//! `flight_plan.png`: a top view (north up) of the area with the sampled cameras, under a title (area,
//! camera, number of poses, nadir/tilted counts, sampling, frame size) and above a scale bar with its
//! length in metres and a legend of every mark.
//!
//! The map, back to front:
//! - the area polygon, filled pale green, outlined dark green;
//! - the buildings: the scene mesh's triangles projected to the ground and rasterised with the highest
//!   point per pixel, shaded from light grey (ground level) to dark slate (tallest roof); without a mesh,
//!   the building boxes of `buildings.json`;
//! - each sequence's path (consecutive camera positions joined, one colour per sequence);
//! - each camera's heading: a line with an arrowhead in its view direction, longer the more it is
//!   tilted;
//! - each camera as a disc (blue with a white rim, radius 4: nadir; orange with a dark rim, radius 5:
//!   tilted more than 1°).
//!
//! The scale bar's length (a round number of metres), the `metres_per_px` of the map and where the map
//! lies in the picture are also in the PNG's `tEXt` chunks. The map is an [`RgbImage`] drawn with
//! [`crate::util::figure`]'s integer-exact primitives (lines, discs, scanline polygon fill; the roofs'
//! triangles are rasterised here), and the words go through the same module, so the picture is
//! byte-identical for identical inputs.

use std::io::Write;
use std::path::Path;

use super::{CameraError, PoseRecord};
use crate::scene::PreparedScene;
use crate::util::figure::legend::legend_size;
use crate::util::figure::{text, Align, LegendItem, Rgb, RgbImage, Swatch, TextStyle, INK, WHITE};

/// Longest side of the picture, pixels.
pub const MAX_SIDE_PX: u32 = 1600;

const OUTSIDE: Rgb = [250, 250, 250];
const INSIDE: Rgb = [232, 240, 226];
const OUTLINE: Rgb = [40, 120, 40];
const NADIR: Rgb = [30, 90, 200];
const TILTED: Rgb = [225, 110, 20];
/// Building shading: the lowest roof …
const RAMP_LOW: Rgb = [205, 205, 210];
/// … and the highest.
const RAMP_HIGH: Rgb = [45, 55, 90];
const PATHS: [Rgb; 6] =
    [[200, 40, 120], [20, 140, 160], [150, 90, 20], [100, 60, 180], [30, 150, 60], [190, 60, 40]];

/// The map: a raster of [`crate::util::figure`] with its world (ENU) → pixel mapping, north up.
pub struct Map {
    /// The map's pixels; lines, discs and the area's fill are drawn with [`RgbImage`]'s primitives.
    pub image: RgbImage,
    /// ENU (east, north) of the top-left corner of the picture, metres.
    top_left_m: [f64; 2],
    /// Pixels per metre.
    scale_px_per_m: f64,
}

impl Map {
    /// A map covering [min, max] (ENU metres) with the longest side `max_side_px`, filled with `bg`.
    pub fn new(min_m: [f64; 2], max_m: [f64; 2], max_side_px: u32, bg: Rgb) -> Self {
        let extent = (max_m[0] - min_m[0]).max(max_m[1] - min_m[1]).max(1.0);
        let scale = max_side_px as f64 / extent;
        let width_px = (((max_m[0] - min_m[0]) * scale).ceil() as u32).clamp(1, max_side_px);
        let height_px = (((max_m[1] - min_m[1]) * scale).ceil() as u32).clamp(1, max_side_px);
        let image = RgbImage::new(width_px, height_px, bg);
        Map { image, top_left_m: [min_m[0], max_m[1]], scale_px_per_m: scale }
    }

    /// Metres per pixel.
    pub fn metres_per_px(&self) -> f64 {
        1.0 / self.scale_px_per_m
    }

    /// ENU (east, north) metres → continuous pixel coordinates (x right, y down).
    pub fn to_px(&self, p_m: [f64; 2]) -> [f64; 2] {
        [
            (p_m[0] - self.top_left_m[0]) * self.scale_px_per_m,
            (self.top_left_m[1] - p_m[1]) * self.scale_px_per_m,
        ]
    }
}

/// The pixel containing the continuous position `p_px`; far-off (or non-finite) positions are clamped
/// to ±10⁶ px so that a line towards them stays a bounded number of steps.
fn pixel(p_px: [f64; 2]) -> [i64; 2] {
    p_px.map(|v| v.clamp(-1.0e6, 1.0e6).floor() as i64)
}

/// Per-pixel highest ground-projected building point (ENU up, metres), NaN where no building is.
fn building_heights(map: &Map, scene: &PreparedScene) -> Vec<f64> {
    let (w, h) = (map.image.width as i64, map.image.height as i64);
    let mut top = vec![f64::NAN; (w * h) as usize];
    let mut put = |x: i64, y: i64, z: f64| {
        if x >= 0 && y >= 0 && x < w && y < h {
            let t = &mut top[(y * w + x) as usize];
            if t.is_nan() || z > *t {
                *t = z;
            }
        }
    };
    let mesh = &scene.mesh;
    if mesh.triangle_count() > 0 {
        for tri in mesh.indices.chunks_exact(3) {
            let v = [0, 1, 2].map(|k| mesh.positions_m.get(tri[k] as usize).copied());
            let [Some(a), Some(b), Some(c)] = v else { continue };
            let [pa, pb, pc] = [a, b, c].map(|p| map.to_px([p[0] as f64, p[1] as f64]));
            let area = (pb[0] - pa[0]) * (pc[1] - pa[1]) - (pb[1] - pa[1]) * (pc[0] - pa[0]);
            if area.abs() < 1e-9 || !area.is_finite() {
                // A wall seen from above: it covers no pixel centre of its own.
                continue;
            }
            let x0 = pa[0].min(pb[0]).min(pc[0]).floor().max(0.0) as i64;
            let x1 = (pa[0].max(pb[0]).max(pc[0]).ceil() as i64).min(w - 1);
            let y0 = pa[1].min(pb[1]).min(pc[1]).floor().max(0.0) as i64;
            let y1 = (pa[1].max(pb[1]).max(pc[1]).ceil() as i64).min(h - 1);
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let q = [x as f64 + 0.5, y as f64 + 0.5];
                    let w0 = ((pb[0] - q[0]) * (pc[1] - q[1]) - (pb[1] - q[1]) * (pc[0] - q[0])) / area;
                    let w1 = ((pc[0] - q[0]) * (pa[1] - q[1]) - (pc[1] - q[1]) * (pa[0] - q[0])) / area;
                    let w2 = 1.0 - w0 - w1;
                    if w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0 {
                        put(x, y, w0 * a[2] as f64 + w1 * b[2] as f64 + w2 * c[2] as f64);
                    }
                }
            }
        }
    } else {
        for b in &scene.buildings {
            let p0 = map.to_px([b.bbox_min_enu_m[0], b.bbox_max_enu_m[1]]);
            let p1 = map.to_px([b.bbox_max_enu_m[0], b.bbox_min_enu_m[1]]);
            if !(p0[0].is_finite() && p0[1].is_finite() && p1[0].is_finite() && p1[1].is_finite()) {
                continue;
            }
            let (xa, xb) = ((p0[0] - 0.5).ceil().max(0.0) as i64, ((p1[0] - 0.5).ceil() as i64).min(w));
            let (ya, yb) = ((p0[1] - 0.5).ceil().max(0.0) as i64, ((p1[1] - 0.5).ceil() as i64).min(h));
            for y in ya..yb {
                for x in xa..xb {
                    put(x, y, b.bbox_max_enu_m[2]);
                }
            }
        }
    }
    top
}

/// A round scale-bar length (1, 2 or 5 × 10ⁿ metres) near a fifth of `width_m`.
pub fn scale_bar_m(width_m: f64) -> f64 {
    let target = (width_m / 5.0).max(1.0);
    let p = 10f64.powf(target.log10().floor());
    [5.0, 2.0, 1.0].into_iter().map(|k| k * p).find(|&v| v <= target).unwrap_or(p)
}

/// Height of the title band above the map, px.
const HEADER_PX: i64 = 64;
/// Narrowest picture, px (a tall, narrow area still gets a readable legend).
const MIN_WIDTH_PX: i64 = 960;
/// Radius of a nadir camera's disc, px (tilted ones are one larger).
const NADIR_R_PX: i64 = 4;

/// A drawn flight plan: the picture and where its map is.
pub struct FlightPlan {
    /// The picture: title band, map, legend and scale bar.
    pub image: RgbImage,
    /// The map inside the picture.
    pub map: Map,
    /// Column of the map's left edge in the picture, px.
    pub map_left_px: i64,
    /// Row of the map's top edge in the picture, px.
    pub map_top_px: i64,
    /// The scale bar's length, metres.
    pub scale_bar_m: f64,
}

/// The map's extent: the area polygon and the cameras, padded.
fn extent(scene: &PreparedScene, poses: &[PoseRecord]) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    let mut grow = |p: [f64; 2]| {
        if p[0].is_finite() && p[1].is_finite() {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    };
    scene.manifest.area_polygon_enu_m.iter().for_each(|p| grow(*p));
    for r in poses {
        let c = r.pose().centre_m;
        grow([c[0], c[1]]);
    }
    if !(lo[0].is_finite() && hi[0].is_finite()) {
        lo = [-50.0, -50.0];
        hi = [50.0, 50.0];
    }
    let pad = 0.04 * (hi[0] - lo[0]).max(hi[1] - lo[1]) + 20.0;
    ([lo[0] - pad, lo[1] - pad], [hi[0] + pad, hi[1] + pad])
}

/// Draws the map: area, buildings shaded by height, flight lines, cameras and their headings. Returns
/// the map and the roof heights above ground of the shading's ends (metres), `None` without
/// buildings.
fn draw_map(scene: &PreparedScene, poses: &[PoseRecord]) -> (Map, Option<[f64; 2]>) {
    let m = &scene.manifest;
    let (lo, hi) = extent(scene, poses);
    let mut map = Map::new(lo, hi, MAX_SIDE_PX, OUTSIDE);
    let ring_px: Vec<[f64; 2]> = m.area_polygon_enu_m.iter().map(|p| map.to_px(*p)).collect();
    if ring_px.len() >= 3 {
        map.image.fill_polygon(&ring_px, INSIDE);
    }
    let tops = building_heights(&map, scene);
    let (z_lo, z_hi) = tops
        .iter()
        .filter(|z| !z.is_nan())
        .fold((m.ground_enu_m, f64::NEG_INFINITY), |(a, b), &z| (a.min(z), b.max(z)));
    let span = (z_hi - z_lo).max(1.0);
    for (i, z) in tops.iter().enumerate() {
        if z.is_nan() {
            continue;
        }
        let t = ((z - z_lo) / span).clamp(0.0, 1.0);
        let lerp = |a: f64, b: f64| (a + (b - a) * t).round() as u8;
        let c = [
            lerp(RAMP_LOW[0] as f64, RAMP_HIGH[0] as f64),
            lerp(RAMP_LOW[1] as f64, RAMP_HIGH[1] as f64),
            lerp(RAMP_LOW[2] as f64, RAMP_HIGH[2] as f64),
        ];
        map.image.data[3 * i..3 * i + 3].copy_from_slice(&c);
    }
    for i in 0..ring_px.len() {
        map.image.line(pixel(ring_px[i]), pixel(ring_px[(i + 1) % ring_px.len()]), 3, OUTLINE);
    }
    // Sequence paths.
    for w in poses.windows(2) {
        if w[0].sequence == w[1].sequence && w[1].index == w[0].index + 1 {
            let (a, b) = (w[0].pose().centre_m, w[1].pose().centre_m);
            let col = PATHS[w[0].sequence as usize % PATHS.len()];
            map.image.line(pixel(map.to_px([a[0], a[1]])), pixel(map.to_px([b[0], b[1]])), 3, col);
        }
    }
    // Headings first: a line from the camera in its view direction, longer the more it is tilted,
    // with an arrowhead. Then tilted cameras (larger discs), then nadir ones on top, so that a nadir
    // and a tilted pose at one grid node both stay visible. Each disc has a contrasting rim.
    for r in poses {
        let c = r.pose().centre_m;
        let at = map.to_px([c[0], c[1]]);
        let len_px = NADIR_R_PX as f64 + 9.0 + 20.0 * r.geo.pitch_deg.to_radians().sin().abs();
        let yaw = r.geo.yaw_deg.to_radians();
        let tip = [at[0] + len_px * yaw.sin(), at[1] - len_px * yaw.cos()];
        map.image.line(pixel(at), pixel(tip), 3, INK);
        for side in [-1.0, 1.0] {
            let back = yaw + side * 2.6;
            map.image.line(pixel(tip), pixel([tip[0] + 7.0 * back.sin(), tip[1] - 7.0 * back.cos()]), 3, INK);
        }
    }
    for nadir_pass in [false, true] {
        for r in poses.iter().filter(|r| (r.geo.pitch_deg <= 1.0) == nadir_pass) {
            let c = r.pose().centre_m;
            let [x, y] = pixel(map.to_px([c[0], c[1]]));
            if nadir_pass {
                map.image.disc(x, y, NADIR_R_PX + 1, WHITE);
                map.image.disc(x, y, NADIR_R_PX, NADIR);
            } else {
                map.image.disc(x, y, NADIR_R_PX + 2, INK);
                map.image.disc(x, y, NADIR_R_PX + 1, TILTED);
            }
        }
    }
    let heights = z_hi.is_finite().then_some([z_lo - m.ground_enu_m, z_hi - m.ground_enu_m]);
    (map, heights)
}

/// What the legend explains: each mark of the map that is in it.
fn legend_items(poses: &[PoseRecord], heights: Option<[f64; 2]>) -> Vec<LegendItem> {
    let nadir = poses.iter().filter(|r| r.geo.pitch_deg <= 1.0).count();
    let mut items = Vec::new();
    if nadir > 0 {
        let swatch = Swatch::Disc { fill: NADIR, outline: WHITE, radius_px: NADIR_R_PX };
        items.push(LegendItem::new(swatch, "nadir camera (pitch ≤ 1°)"));
    }
    if nadir < poses.len() {
        let swatch = Swatch::Disc { fill: TILTED, outline: INK, radius_px: NADIR_R_PX + 1 };
        items.push(LegendItem::new(swatch, "tilted camera (pitch > 1°)"));
    }
    if !poses.is_empty() {
        let swatch = Swatch::Line { colour: INK, width_px: 3 };
        items.push(LegendItem::new(swatch, "heading (view direction; longer = more tilted)"));
    }
    if poses.windows(2).any(|w| w[0].sequence == w[1].sequence && w[1].index == w[0].index + 1) {
        items.push(LegendItem::new(
            Swatch::Line { colour: PATHS[0], width_px: 3 },
            "flight line (one colour per sequence)",
        ));
    }
    items.push(LegendItem::new(Swatch::Line { colour: OUTLINE, width_px: 3 }, "area polygon"));
    if let Some([lo, hi]) = heights {
        let label = format!("building roofs, {lo:.0} m to {hi:.0} m above ground");
        items.push(LegendItem::new(Swatch::Ramp(RAMP_LOW, RAMP_HIGH), label));
    }
    items
}

/// Draws the flight plan of `poses` over `scene`: a title band (area, camera, poses), the map (north
/// up) and below it a scale bar with its length and a legend of every mark.
pub fn draw_flight_plan(scene: &PreparedScene, poses: &[PoseRecord]) -> FlightPlan {
    let (map, heights) = draw_map(scene, poses);
    let (mw, mh) = (map.image.width as i64, map.image.height as i64);
    let width = mw.max(MIN_WIDTH_PX);
    let bar_m = scale_bar_m(mw as f64 * map.metres_per_px());
    let bar_px = (bar_m / map.metres_per_px()).round() as i64;
    let items = legend_items(poses, heights);
    let legend_x = 12 + bar_px.max(60) + 32;
    let [_, leg_h] = legend_size(&items, text::TICK_PX, width - legend_x - 12);
    let footer = leg_h.max(40) + 24;
    let height = HEADER_PX + mh + footer;
    let mut img = RgbImage::new(width as u32, height as u32, WHITE);
    let map_left = (width - mw) / 2;
    img.paste(&map.image, map_left, HEADER_PX);
    img.stroke_rect(map_left, HEADER_PX, mw, mh, [170, 170, 170]);
    // Title band.
    let nadir = poses.iter().filter(|r| r.geo.pitch_deg <= 1.0).count();
    let camera = poses.first().map_or("no camera", |r| r.preset.as_str());
    let title =
        format!("Flight plan: area {} · camera {camera} · {} poses", scene.manifest.area, poses.len());
    img.text(12, 8, &title, TextStyle::new(text::TITLE_PX, INK));
    let mut sub = format!("{nadir} nadir, {} tilted", poses.len() - nadir);
    if let Some(r) = poses.first() {
        let k = &r.view.intrinsics;
        sub.push_str(
            &format!(" · {:?} sampling · frames {} × {} px", r.trajectory, k.width_px, k.height_px)
                .to_lowercase(),
        );
    }
    sub.push_str(" · top view, north up");
    img.text(
        12,
        8 + text::line_height(text::TITLE_PX) + 4,
        &sub,
        TextStyle::new(text::LABEL_PX, [70, 70, 70]),
    );
    img.text(width - 14, 10, "↑ N", TextStyle::new(text::TITLE_PX, INK).aligned(Align::Right));
    // Scale bar and legend under the map.
    let foot = HEADER_PX + mh + 12;
    img.scale_bar(12, foot, bar_px, &format!("{bar_m} m"), text::LABEL_PX);
    img.legend(legend_x, foot, &items, text::TICK_PX, width - legend_x - 12);
    FlightPlan { image: img, map, map_left_px: map_left, map_top_px: HEADER_PX, scale_bar_m: bar_m }
}

/// Draws and writes `flight_plan.png` atomically. Its `tEXt` chunks hold `Title`, `scale_bar_m`,
/// `metres_per_px` and where the map is in the picture (`map_left_px`, `map_top_px`).
///
/// # Errors
/// [`CameraError::File`] for I/O, [`CameraError::Png`] for encoding.
pub fn write_flight_plan(
    path: &Path,
    scene: &PreparedScene,
    poses: &[PoseRecord],
) -> Result<(), CameraError> {
    let plan = draw_flight_plan(scene, poses);
    let text = [
        ("Title", format!("insgen flight plan: {} ({} frames)", scene.manifest.area, poses.len())),
        ("scale_bar_m", format!("{}", plan.scale_bar_m)),
        ("metres_per_px", format!("{}", plan.map.metres_per_px())),
        ("map_left_px", format!("{}", plan.map_left_px)),
        ("map_top_px", format!("{}", plan.map_top_px)),
    ];
    crate::util::write_atomic(path, |w| {
        encode_png(&plan.image, w, &text)
            .map_err(|source| CameraError::Png { path: path.to_path_buf(), source })
    })
}

/// Encodes `img` as an 8-bit RGB PNG with the given `tEXt` entries.
fn encode_png<W: Write>(img: &RgbImage, w: W, text: &[(&str, String)]) -> Result<(), png::EncodingError> {
    let mut enc = png::Encoder::new(w, img.width, img.height);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    for (k, v) in text {
        enc.add_text_chunk(k.to_string(), v.clone())?;
    }
    let mut writer = enc.write_header()?;
    writer.write_image_data(&img.data)?;
    writer.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_bars_are_round() {
        assert_eq!(scale_bar_m(1000.0), 200.0);
        assert_eq!(scale_bar_m(2600.0), 500.0);
        assert_eq!(scale_bar_m(430.0), 50.0);
        assert_eq!(scale_bar_m(3.0), 1.0);
    }

    #[test]
    fn map_is_north_up_and_fills_the_area() {
        let mut map = Map::new([0.0, 0.0], [10.0, 10.0], 10, [0, 0, 0]);
        assert_eq!(map.metres_per_px(), 1.0);
        // Square from (2, 2) to (6, 6) metres = pixels x 2..6, y 4..8 (north up).
        let ring: Vec<[f64; 2]> =
            [[2.0, 2.0], [6.0, 2.0], [6.0, 6.0], [2.0, 6.0]].iter().map(|p| map.to_px(*p)).collect();
        map.image.fill_polygon(&ring, [9, 9, 9]);
        assert_eq!(map.image.data.chunks_exact(3).filter(|p| p[0] == 9).count(), 16);
        assert_eq!(map.image.get(2, 4), [9, 9, 9]);
        assert_eq!(map.image.get(1, 4), [0, 0, 0]);
        assert_eq!(map.image.get(2, 8), [0, 0, 0]);
    }

    #[test]
    fn far_off_positions_are_clamped() {
        assert_eq!(pixel([2.7, -0.2]), [2, -1]);
        assert_eq!(pixel([f64::INFINITY, -1.0e12]), [1_000_000, -1_000_000]);
    }
}
