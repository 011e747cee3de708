//! Legends and scale bars: what each colour or mark of a picture means, and how long a distance is.

use super::text::{self, measure, Align, TextStyle};
use super::{Rgb, RgbImage, INK, WHITE};

/// The mark shown for one legend entry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Swatch {
    /// A filled square.
    Square(Rgb),
    /// A disc of `radius_px` with a one-pixel `outline`.
    Disc {
        /// Fill colour.
        fill: Rgb,
        /// Outline colour.
        outline: Rgb,
        /// Radius, pixels.
        radius_px: i64,
    },
    /// A horizontal line `width_px` thick.
    Line {
        /// Colour.
        colour: Rgb,
        /// Thickness, pixels.
        width_px: i64,
    },
    /// A colour ramp from the first colour (left) to the second (right).
    Ramp(Rgb, Rgb),
}

/// One legend entry.
#[derive(Debug, Clone, PartialEq)]
pub struct LegendItem {
    /// Its mark.
    pub swatch: Swatch,
    /// What the mark means.
    pub label: String,
}

impl LegendItem {
    /// An entry of `swatch` and `label`.
    pub fn new(swatch: Swatch, label: impl Into<String>) -> LegendItem {
        LegendItem { swatch, label: label.into() }
    }
}

/// Width of a swatch, pixels (ramps are wider).
fn swatch_w(s: &Swatch) -> i64 {
    match s {
        Swatch::Ramp(..) => 40,
        _ => 22,
    }
}

const GAP_PX: i64 = 8;
const PAD_PX: i64 = 8;

/// Size [width, height] of the framed legend [`RgbImage::legend`] draws: the items in rows of at most
/// `max_width_px` (one item per row when `max_width_px` is 0).
pub fn legend_size(items: &[LegendItem], size_px: f32, max_width_px: i64) -> [i64; 2] {
    let rows = legend_rows(items, size_px, max_width_px);
    let line = text::line_height(size_px).max(16);
    let w = rows.iter().map(|r| r.iter().map(|&(_, w)| w).sum::<i64>() - GAP_PX * 2).max().unwrap_or(0);
    [w.max(0) + 2 * PAD_PX, rows.len() as i64 * (line + 4) - 4 + 2 * PAD_PX]
}

/// Items per row with their widths (swatch, gap, label, and the gap to the next item).
fn legend_rows(items: &[LegendItem], size_px: f32, max_width_px: i64) -> Vec<Vec<(usize, i64)>> {
    let mut rows: Vec<Vec<(usize, i64)>> = vec![Vec::new()];
    let mut used = 0;
    for (i, it) in items.iter().enumerate() {
        let w = swatch_w(&it.swatch) + 6 + measure(&it.label, size_px)[0] + 2 * GAP_PX;
        let full = max_width_px == 0 || used + w - 2 * GAP_PX > max_width_px - 2 * PAD_PX;
        if !rows.last().is_some_and(Vec::is_empty) && full {
            rows.push(Vec::new());
            used = 0;
        }
        rows.last_mut().expect("one row at least").push((i, w));
        used += w;
    }
    rows
}

impl RgbImage {
    /// Draws a legend framed on white with its top-left corner at (x, y), the items in rows no wider
    /// than `max_width_px` (0: one item per row); returns [width, height] ([`legend_size`]).
    pub fn legend(
        &mut self,
        x: i64,
        y: i64,
        items: &[LegendItem],
        size_px: f32,
        max_width_px: i64,
    ) -> [i64; 2] {
        let [w, h] = legend_size(items, size_px, max_width_px);
        self.fill_rect(x, y, w, h, WHITE);
        self.stroke_rect(x, y, w, h, [160, 160, 160]);
        let line = text::line_height(size_px).max(16);
        for (r, row) in legend_rows(items, size_px, max_width_px).iter().enumerate() {
            let top = y + PAD_PX + r as i64 * (line + 4);
            let mut cx = x + PAD_PX;
            for &(i, wi) in row {
                let it = &items[i];
                self.swatch(cx, top + line / 2, &it.swatch);
                self.text(cx + swatch_w(&it.swatch) + 6, top, &it.label, TextStyle::new(size_px, INK));
                cx += wi;
            }
        }
        [w, h]
    }

    /// Draws a swatch with its left edge at `x`, centred vertically on `y_mid`.
    pub fn swatch(&mut self, x: i64, y_mid: i64, s: &Swatch) {
        let w = swatch_w(s);
        match *s {
            Swatch::Square(c) => {
                self.fill_rect(x + 4, y_mid - 7, 14, 14, c);
                self.stroke_rect(x + 4, y_mid - 7, 14, 14, INK);
            }
            Swatch::Disc { fill, outline, radius_px } => {
                self.disc(x + w / 2, y_mid, radius_px + 1, outline);
                self.disc(x + w / 2, y_mid, radius_px, fill);
            }
            Swatch::Line { colour, width_px } => {
                self.line([x, y_mid], [x + w - 1, y_mid], width_px, colour);
            }
            Swatch::Ramp(a, b) => {
                for k in 0..w {
                    let t = k as f32 / (w - 1).max(1) as f32;
                    let c = [0, 1, 2].map(|j| (a[j] as f32 + (b[j] as f32 - a[j] as f32) * t).round() as u8);
                    self.fill_rect(x + k, y_mid - 7, 1, 14, c);
                }
                self.stroke_rect(x, y_mid - 7, w, 14, INK);
            }
        }
    }

    /// Draws a scale bar `length_px` long with its left end at (x, y) (the bar's top), black and white
    /// halves, end ticks, and `label` (e.g. `200 m`) centred above it; returns [width, height] drawn,
    /// the label included.
    pub fn scale_bar(&mut self, x: i64, y: i64, length_px: i64, label: &str, size_px: f32) -> [i64; 2] {
        let [lw, lh] = measure(label, size_px);
        let bar_y = y + lh + 3;
        let half = length_px / 2;
        self.fill_rect(x, bar_y, length_px, 7, INK);
        self.fill_rect(x + half, bar_y + 1, length_px - half - 1, 5, WHITE);
        for tx in [x, x + half, x + length_px - 1] {
            self.fill_rect(tx, bar_y - 3, 1, 13, INK);
        }
        self.text(x + length_px / 2, y, label, TextStyle::new(size_px, INK).aligned(Align::Centre));
        [length_px.max(lw), lh + 13]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legend_rows_wrap_at_the_width_and_the_frame_holds_every_swatch() {
        let items = vec![
            LegendItem::new(Swatch::Square([200, 0, 0]), "train"),
            LegendItem::new(Swatch::Square([0, 200, 0]), "val"),
            LegendItem::new(Swatch::Square([0, 0, 200]), "test"),
        ];
        let [w1, h1] = legend_size(&items, text::TICK_PX, 10_000);
        let [w3, h3] = legend_size(&items, text::TICK_PX, 0);
        assert!(w1 > w3 && h3 > 2 * h1, "one row {w1}×{h1}, three rows {w3}×{h3}");
        let mut img = RgbImage::new(w1 as u32 + 4, h1 as u32 + 4, [250, 250, 250]);
        assert_eq!(img.legend(2, 2, &items, text::TICK_PX, 10_000), [w1, h1]);
        for c in [[200, 0, 0], [0, 200, 0], [0, 0, 200]] {
            let n = img.data.chunks_exact(3).filter(|p| *p == c).count();
            assert_eq!(n, 12 * 12, "{c:?}: a 14 px square inside a 1 px outline");
        }
        // Nothing outside the frame.
        assert!((0..img.width).all(|x| img.get(x, 0) == [250, 250, 250]));
    }

    #[test]
    fn scale_bar_is_as_long_as_asked() {
        let mut img = RgbImage::new(200, 50, WHITE);
        let [_, h] = img.scale_bar(10, 2, 120, "200 m", text::TICK_PX);
        let bar_y = 2 + h - 13 + 3 + 3; // a row inside the bar
        let black: Vec<u32> = (0..200).filter(|&x| img.get(x, bar_y as u32) == INK).collect();
        assert_eq!((black[0], *black.last().unwrap()), (10, 129));
    }
}
