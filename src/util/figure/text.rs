//! Text on an [`RgbImage`]: one line at a time in DejaVu Sans, anti-aliased.
//!
//! The font is `assets/fonts/DejaVuSans.ttf` (DejaVu fonts 2.37, unmodified), compiled into the
//! binary, so a figure looks the same on every machine and needs no system font. Its licence (the
//! Bitstream Vera licence; DejaVu's changes are public domain) allows embedding and redistribution
//! with the notice, which is `assets/fonts/LICENSE-DejaVu.txt`.
//!
//! Layout is a single line: each glyph's advance plus the font's kerning, glyphs placed at fractional
//! pen positions on a baseline rounded to a whole pixel. Coverage comes from [`ab_glyph`]'s outline
//! rasteriser (`f32`, the same operations every time), so equal text gives equal pixels.
//!
//! # Units
//! Sizes are the font's pixel height (`size_px`: ascent − descent ≈ 1.16 × the cap height … roughly
//! the em); positions are whole pixels, `y` the top of the line box.

use std::sync::OnceLock;

use ab_glyph::{Font, FontRef, GlyphId, PxScale, ScaleFont};

use super::{Rgb, RgbImage};

/// The embedded font file.
pub const FONT_TTF: &[u8] =
    include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), "/assets/fonts/DejaVuSans.ttf"));

/// Title size, px.
pub const TITLE_PX: f32 = 20.0;
/// Axis labels and panel captions, px.
pub const LABEL_PX: f32 = 15.0;
/// Tick values and legend entries, px.
pub const TICK_PX: f32 = 13.0;

fn font() -> &'static FontRef<'static> {
    static FONT: OnceLock<FontRef<'static>> = OnceLock::new();
    // The bytes are compiled in and parse (`tests::the_embedded_font_parses`).
    FONT.get_or_init(|| FontRef::try_from_slice(FONT_TTF).expect("the embedded DejaVu Sans parses"))
}

/// Horizontal alignment of a line relative to its `x`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Align {
    /// `x` is the left edge.
    #[default]
    Left,
    /// `x` is the centre.
    Centre,
    /// `x` is the right edge.
    Right,
}

/// How a line of text is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TextStyle {
    /// Pixel height of the font (see the module's units).
    pub size_px: f32,
    /// Colour of the glyphs.
    pub colour: Rgb,
    /// Where `x` is on the line.
    pub align: Align,
}

impl TextStyle {
    /// Left-aligned text of `size_px` in `colour`.
    pub const fn new(size_px: f32, colour: Rgb) -> TextStyle {
        TextStyle { size_px, colour, align: Align::Left }
    }

    /// The same style with another alignment.
    pub const fn aligned(self, align: Align) -> TextStyle {
        TextStyle { align, ..self }
    }
}

/// The glyphs of one line and their pen positions (px from the line's left), and its advance (px).
fn layout(text: &str, size_px: f32) -> (Vec<(GlyphId, f32)>, f32) {
    let f = font().as_scaled(PxScale::from(size_px));
    let mut pen = 0.0f32;
    let mut prev: Option<GlyphId> = None;
    let mut glyphs = Vec::with_capacity(text.len());
    for ch in text.chars() {
        let id = f.glyph_id(ch);
        if let Some(p) = prev {
            pen += f.kern(p, id);
        }
        glyphs.push((id, pen));
        pen += f.h_advance(id);
        prev = Some(id);
    }
    (glyphs, pen)
}

/// Size of the line box of `text` at `size_px`: [width, height] in whole pixels (the height is the
/// font's ascent − descent, the same for every text of that size).
pub fn measure(text: &str, size_px: f32) -> [i64; 2] {
    let (_, advance) = layout(text, size_px);
    [advance.ceil() as i64, line_height(size_px)]
}

/// Height of a line box at `size_px`, whole pixels.
pub fn line_height(size_px: f32) -> i64 {
    let f = font().as_scaled(PxScale::from(size_px));
    (f.ascent() - f.descent()).ceil() as i64
}

/// The coverage (0–1) of a line of text in its own box, row-major, [`measure`]'s size.
struct Coverage {
    width: i64,
    height: i64,
    alpha: Vec<f32>,
}

fn rasterise(text: &str, size_px: f32) -> Coverage {
    let (glyphs, _) = layout(text, size_px);
    let [width, height] = measure(text, size_px);
    let scale = PxScale::from(size_px);
    let baseline = font().as_scaled(scale).ascent().round();
    let mut alpha = vec![0f32; (width.max(0) * height) as usize];
    for (id, pen_x) in glyphs {
        let glyph = id.with_scale_and_position(scale, ab_glyph::point(pen_x, baseline));
        let Some(outline) = font().outline_glyph(glyph) else { continue };
        let b = outline.px_bounds();
        let (ox, oy) = (b.min.x as i64, b.min.y as i64);
        outline.draw(|gx, gy, c| {
            let (x, y) = (ox + gx as i64, oy + gy as i64);
            if x >= 0 && y >= 0 && x < width && y < height {
                let a = &mut alpha[(y * width + x) as usize];
                *a = (*a + c).min(1.0);
            }
        });
    }
    Coverage { width, height, alpha }
}

impl RgbImage {
    /// Draws one line of `text` with the top of its line box at `y` and `x` placed by `style.align`;
    /// returns the line box drawn as [left, top, width, height] in pixels.
    pub fn text(&mut self, x: i64, y: i64, text: &str, style: TextStyle) -> [i64; 4] {
        let cov = rasterise(text, style.size_px);
        let left = match style.align {
            Align::Left => x,
            Align::Centre => x - cov.width / 2,
            Align::Right => x - cov.width,
        };
        for cy in 0..cov.height {
            for cx in 0..cov.width {
                let a = cov.alpha[(cy * cov.width + cx) as usize];
                if a > 0.0 {
                    self.blend(left + cx, y + cy, style.colour, a);
                }
            }
        }
        [left, y, cov.width, cov.height]
    }

    /// Draws one line of `text` turned a quarter counter-clockwise (reading upwards, as a y-axis
    /// label), centred vertically on `y_centre`, with the top of its letters towards `x_left`; returns
    /// the box drawn as [left, top, width, height].
    pub fn text_upwards(&mut self, x_left: i64, y_centre: i64, text: &str, style: TextStyle) -> [i64; 4] {
        let cov = rasterise(text, style.size_px);
        let top = y_centre - cov.width / 2;
        for cy in 0..cov.height {
            for cx in 0..cov.width {
                let a = cov.alpha[(cy * cov.width + cx) as usize];
                if a > 0.0 {
                    // (cx, cy) in the line box → column cy from the left, row (width − 1 − cx).
                    self.blend(x_left + cy, top + cov.width - 1 - cx, style.colour, a);
                }
            }
        }
        [x_left, top, cov.height, cov.width]
    }

    /// Draws `text` on a filled box (`pad_px` around the line box) whose top-left corner is (x, y);
    /// returns the box as [left, top, width, height].
    pub fn text_on(
        &mut self,
        x: i64,
        y: i64,
        text: &str,
        style: TextStyle,
        bg: Rgb,
        pad_px: i64,
    ) -> [i64; 4] {
        let [w, h] = measure(text, style.size_px);
        let bw = w + 2 * pad_px;
        let bh = h + 2 * pad_px;
        self.fill_rect(x, y, bw, bh, bg);
        self.text(x + pad_px, y + pad_px, text, style.aligned(Align::Left));
        [x, y, bw, bh]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pixels that differ from white, as their bounding box [x0, y0, x1, y1] (inclusive) and count.
    fn ink(img: &RgbImage) -> ([i64; 4], usize) {
        let mut b = [i64::MAX, i64::MAX, i64::MIN, i64::MIN];
        let mut n = 0;
        for y in 0..img.height as i64 {
            for x in 0..img.width as i64 {
                if img.get(x as u32, y as u32) != [255, 255, 255] {
                    b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
                    n += 1;
                }
            }
        }
        (b, n)
    }

    #[test]
    fn the_embedded_font_parses_and_has_the_symbols_figures_use() {
        let f = FontRef::try_from_slice(FONT_TTF).unwrap();
        for c in "0123456789 mpx°²×≤≥–·↑✓✗ABCabc()%".chars() {
            assert_ne!(f.glyph_id(c).0, 0, "{c:?} has no glyph");
        }
    }

    #[test]
    fn a_label_inks_pixels_inside_its_box_only() {
        let mut img = RgbImage::new(200, 60, [255, 255, 255]);
        let style = TextStyle::new(LABEL_PX, [0, 0, 0]);
        let [l, t, w, h] = img.text(20, 10, "12.5 m, 3°", style);
        assert_eq!((l, t), (20, 10));
        assert_eq!([w, h], measure("12.5 m, 3°", LABEL_PX));
        let (b, n) = ink(&img);
        assert!(n > 60, "{n} inked pixels");
        assert!(
            b[0] >= l && b[1] >= t && b[2] < l + w && b[3] < t + h,
            "ink {b:?} outside box {l},{t},{w},{h}"
        );
        // The ink spans most of the box: a 10-character label at 15 px is wide, cap height ≈ 11 px.
        assert!(b[2] - b[0] > w * 8 / 10 && b[3] - b[1] >= 10, "{b:?} in {w}×{h}");
        // Dark pixels are there (the glyph stems), not only anti-aliased grey.
        assert!(img.data.chunks_exact(3).any(|p| p[0] < 40));
    }

    #[test]
    fn alignment_moves_the_box_and_the_same_text_gives_the_same_bytes() {
        let draw = |align: Align| {
            let mut img = RgbImage::new(240, 30, [255, 255, 255]);
            let b =
                img.text(120, 5, "instances per image", TextStyle::new(TICK_PX, [0, 0, 0]).aligned(align));
            (img, b)
        };
        let (a, ba) = draw(Align::Centre);
        let (a2, _) = draw(Align::Centre);
        assert_eq!(a.data, a2.data, "deterministic");
        let (_, bl) = draw(Align::Left);
        let (_, br) = draw(Align::Right);
        assert_eq!(bl[0], 120);
        assert_eq!(br[0] + br[2], 120);
        assert_eq!(ba[0], 120 - ba[2] / 2);
    }

    #[test]
    fn upward_text_is_the_line_turned_a_quarter() {
        let style = TextStyle::new(LABEL_PX, [0, 0, 0]);
        let [w, h] = measure("images", LABEL_PX);
        let mut flat = RgbImage::new(w as u32, h as u32, [255, 255, 255]);
        flat.text(0, 0, "images", style);
        let mut up = RgbImage::new(h as u32, w as u32, [255, 255, 255]);
        let b = up.text_upwards(0, w / 2, "images", style);
        assert_eq!(b, [0, w / 2 - w / 2, h, w]);
        for y in 0..h as u32 {
            for x in 0..w as u32 {
                assert_eq!(flat.get(x, y), up.get(y, w as u32 - 1 - x));
            }
        }
    }
}
