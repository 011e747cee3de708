//! A tiny RGB raster for report figures: PNG in/out, filled rectangles, blending, a 3×5 pixel font,
//! nearest-neighbour scaling and grouped bar charts. Enough for histograms and contact sheets without a
//! plotting library.

use std::path::Path;

use super::error::ImageProblem;
use super::CocoError;

/// An 8-bit RGB image, row-major.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbImage {
    /// Pixels.
    pub width: u32,
    /// Pixels.
    pub height: u32,
    /// `width × height × 3` bytes.
    pub data: Vec<u8>,
}

/// RGB colour.
pub type Rgb = [u8; 3];

impl RgbImage {
    /// An image filled with `colour`.
    pub fn new(width: u32, height: u32, colour: Rgb) -> Self {
        let data = colour.iter().copied().cycle().take(width as usize * height as usize * 3).collect();
        RgbImage { width, height, data }
    }

    /// The pixel at (x, y).
    pub fn get(&self, x: u32, y: u32) -> Rgb {
        let i = (y as usize * self.width as usize + x as usize) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// Sets a pixel; coordinates outside the image are ignored.
    pub fn put(&mut self, x: i64, y: i64, c: Rgb) {
        if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
            let i = (y as usize * self.width as usize + x as usize) * 3;
            self.data[i..i + 3].copy_from_slice(&c);
        }
    }

    /// Blends `c` over a pixel with opacity `alpha` in [0, 1]; outside pixels are ignored.
    pub fn blend(&mut self, x: i64, y: i64, c: Rgb, alpha: f32) {
        if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
            let i = (y as usize * self.width as usize + x as usize) * 3;
            for (d, &s) in self.data[i..i + 3].iter_mut().zip(&c) {
                let v = *d as f32 * (1.0 - alpha) + s as f32 * alpha;
                *d = v.round().clamp(0.0, 255.0) as u8;
            }
        }
    }

    /// Fills the rectangle `[x, x + w) × [y, y + h)` (clipped).
    pub fn fill_rect(&mut self, x: i64, y: i64, w: i64, h: i64, c: Rgb) {
        for yy in y.max(0)..(y + h).min(self.height as i64) {
            for xx in x.max(0)..(x + w).min(self.width as i64) {
                self.put(xx, yy, c);
            }
        }
    }

    /// Draws a one-pixel rectangle outline.
    pub fn stroke_rect(&mut self, x: i64, y: i64, w: i64, h: i64, c: Rgb) {
        self.fill_rect(x, y, w, 1, c);
        self.fill_rect(x, y + h - 1, w, 1, c);
        self.fill_rect(x, y, 1, h, c);
        self.fill_rect(x + w - 1, y, 1, h, c);
    }

    /// Copies `src` with its top-left corner at (x, y) (clipped).
    pub fn paste(&mut self, src: &RgbImage, x: i64, y: i64) {
        for sy in 0..src.height {
            for sx in 0..src.width {
                self.put(x + sx as i64, y + sy as i64, src.get(sx, sy));
            }
        }
    }

    /// Nearest-neighbour resampling to `width × height` (sampling at pixel centres).
    pub fn resized(&self, width: u32, height: u32) -> RgbImage {
        let mut out = RgbImage::new(width, height, [0, 0, 0]);
        if self.width == 0 || self.height == 0 {
            return out;
        }
        for y in 0..height {
            let sy = (((y as f64 + 0.5) * self.height as f64 / height as f64) as u32).min(self.height - 1);
            for x in 0..width {
                let sx = (((x as f64 + 0.5) * self.width as f64 / width as f64) as u32).min(self.width - 1);
                let c = self.get(sx, sy);
                out.put(x as i64, y as i64, c);
            }
        }
        out
    }

    /// Writes `text` in the 3×5 font, each font pixel `scale × scale`, top-left at (x, y). Lower-case
    /// letters are drawn as capitals; characters without a glyph as a blank.
    pub fn text(&mut self, x: i64, y: i64, text: &str, scale: i64, c: Rgb) {
        let mut cx = x;
        for ch in text.chars() {
            let rows = glyph(ch.to_ascii_uppercase());
            for (ry, row) in rows.iter().enumerate() {
                for rx in 0..3 {
                    if row & (0b100 >> rx) != 0 {
                        self.fill_rect(cx + rx * scale, y + ry as i64 * scale, scale, scale, c);
                    }
                }
            }
            cx += 4 * scale;
        }
    }

    /// Encodes as an 8-bit RGB PNG.
    ///
    /// # Errors
    /// [`CocoError::PngEncode`] naming `path` (which is only used in the message).
    pub fn to_png(&self, path: &Path) -> Result<Vec<u8>, CocoError> {
        encode_png_rgb(&self.data, self.width, self.height, path)
    }

    /// Writes the image as a PNG atomically.
    ///
    /// # Errors
    /// Encoding or I/O errors naming `path`.
    pub fn save(&self, path: &Path) -> Result<(), CocoError> {
        let bytes = self.to_png(path)?;
        crate::util::write_bytes_atomic(path, &bytes)?;
        Ok(())
    }
}

/// Width in pixels of `text` drawn at `scale`.
pub fn text_width(text: &str, scale: i64) -> i64 {
    (text.chars().count() as i64 * 4 - 1).max(0) * scale
}

/// Encodes an 8-bit RGB buffer as PNG (fast lossless settings).
///
/// # Errors
/// [`CocoError::PngEncode`] naming `path`.
pub fn encode_png_rgb(rgb: &[u8], width: u32, height: u32, path: &Path) -> Result<Vec<u8>, CocoError> {
    let enc_err = |source| CocoError::PngEncode { path: path.to_path_buf(), source };
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, width, height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        let mut w = enc.write_header().map_err(enc_err)?;
        w.write_image_data(rgb).map_err(enc_err)?;
        w.finish().map_err(enc_err)?;
    }
    Ok(bytes)
}

/// Reads any non-interlaced or interlaced PNG (grey, palette, RGB, with or without alpha, 1–16 bits) as
/// 8-bit RGB; alpha is dropped.
///
/// # Errors
/// [`CocoError::File`] or [`CocoError::PngDecode`] naming `path`.
pub fn read_png_rgb(path: &Path) -> Result<RgbImage, CocoError> {
    let bytes = crate::util::read_file(path)?;
    let dec_err = |source| CocoError::PngDecode { path: path.to_path_buf(), source };
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder.read_info().map_err(dec_err)?;
    let mut buf = vec![0u8; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).map_err(dec_err)?;
    let channels = match info.color_type {
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        // EXPAND turns palettes into RGB(A); keep a clear error should that ever change.
        png::ColorType::Indexed => {
            return Err(CocoError::Image { path: path.to_path_buf(), problem: ImageProblem::Palette })
        }
    };
    let (w, h) = (info.width as usize, info.height as usize);
    let mut data = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        let row = &buf[y * info.line_size..y * info.line_size + w * channels];
        for p in row.chunks_exact(channels) {
            match channels {
                1 | 2 => data.extend_from_slice(&[p[0], p[0], p[0]]),
                _ => data.extend_from_slice(&p[..3]),
            }
        }
    }
    Ok(RgbImage { width: info.width, height: info.height, data })
}

/// A well-separated colour for an integer key (golden-ratio hue walk), for instance overlays.
pub fn palette(key: u64) -> Rgb {
    let hue = (key as f64 * 0.618_033_988_749_895).fract();
    hsv_to_rgb(hue, 0.75, 0.95)
}

fn hsv_to_rgb(h: f64, s: f64, v: f64) -> Rgb {
    let i = (h * 6.0).floor();
    let f = h * 6.0 - i;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - f * s), v * (1.0 - (1.0 - f) * s));
    let (r, g, b) = match i as i64 % 6 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [(r * 255.0).round() as u8, (g * 255.0).round() as u8, (b * 255.0).round() as u8]
}

/// One series of a grouped bar chart.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend label.
    pub name: String,
    /// Bar colour.
    pub colour: Rgb,
    /// One value per category.
    pub values: Vec<f64>,
}

/// Draws a grouped bar chart: one group per category label, one bar per series, a y axis from 0 to the
/// largest value with the maximum written at the top, a legend and a title.
pub fn bar_chart(title: &str, categories: &[String], series: &[Series]) -> RgbImage {
    const S: i64 = 2; // font scale
    let n_cat = categories.len().max(1) as i64;
    let n_ser = series.len().max(1) as i64;
    let bar_w = if n_cat * n_ser > 60 { 4 } else { 10 };
    // Few categories: make room for every label; many: label every k-th (below).
    let widest = categories.iter().map(|c| text_width(c, S)).max().unwrap_or(0);
    let group_w = if n_cat <= 12 { (n_ser * bar_w + 8).max(widest + 12) } else { n_ser * bar_w + 8 };
    let (left, right, top, bottom) = (70i64, 20i64, 50i64, 60i64);
    let plot_h = 260i64;
    let width = (left + right + n_cat * group_w).max(360);
    let height = top + plot_h + bottom;
    let mut img = RgbImage::new(width as u32, height as u32, [255, 255, 255]);
    let black = [0, 0, 0];
    img.text(10, 10, title, S, black);
    let max = series.iter().flat_map(|s| s.values.iter().copied()).fold(0.0f64, f64::max);
    // Axes.
    img.fill_rect(left - 1, top, 1, plot_h + 1, black);
    img.fill_rect(left - 1, top + plot_h, width - left - right + 1, 1, black);
    let max_label = format_count(max);
    img.text(left - 6 - text_width(&max_label, S), top, &max_label, S, black);
    img.fill_rect(left - 5, top, 4, 1, black);
    img.text(left - 6 - text_width("0", S), top + plot_h - 5 * S, "0", S, black);
    for (ci, cat) in categories.iter().enumerate() {
        let gx = left + ci as i64 * group_w + 4;
        for (si, s) in series.iter().enumerate() {
            let v = s.values.get(ci).copied().unwrap_or(0.0);
            let h = if max > 0.0 { (v / max * plot_h as f64).round() as i64 } else { 0 };
            let h = if v > 0.0 { h.max(1) } else { h };
            let bars_x = gx + (group_w - 8 - n_ser * bar_w) / 2;
            img.fill_rect(bars_x + si as i64 * bar_w, top + plot_h - h, bar_w - 1, h, s.colour);
        }
        // Label every category when they fit, else every k-th.
        let every = ((text_width(cat, S) + 6) / group_w + 1).max(1) as usize;
        if ci % every == 0 {
            let tx = gx + (group_w - 8 - text_width(cat, S)) / 2;
            img.text(tx, top + plot_h + 6, cat, S, black);
        }
    }
    // Legend.
    let mut lx = left;
    for s in series {
        img.fill_rect(lx, height - 20, 12, 10, s.colour);
        img.text(lx + 16, height - 20, &s.name, S, black);
        lx += 16 + text_width(&s.name, S) + 20;
    }
    img
}

fn format_count(v: f64) -> String {
    if v.fract() == 0.0 {
        format!("{}", v as u64)
    } else {
        format!("{v:.2}")
    }
}

/// 3×5 glyphs, one row per entry, bit 2 = left column.
fn glyph(c: char) -> [u8; 5] {
    match c {
        '0' => [0b111, 0b101, 0b101, 0b101, 0b111],
        '1' => [0b010, 0b110, 0b010, 0b010, 0b111],
        '2' => [0b111, 0b001, 0b111, 0b100, 0b111],
        '3' => [0b111, 0b001, 0b111, 0b001, 0b111],
        '4' => [0b101, 0b101, 0b111, 0b001, 0b001],
        '5' => [0b111, 0b100, 0b111, 0b001, 0b111],
        '6' => [0b111, 0b100, 0b111, 0b101, 0b111],
        '7' => [0b111, 0b001, 0b010, 0b010, 0b010],
        '8' => [0b111, 0b101, 0b111, 0b101, 0b111],
        '9' => [0b111, 0b101, 0b111, 0b001, 0b111],
        'A' => [0b010, 0b101, 0b111, 0b101, 0b101],
        'B' => [0b110, 0b101, 0b110, 0b101, 0b110],
        'C' => [0b011, 0b100, 0b100, 0b100, 0b011],
        'D' => [0b110, 0b101, 0b101, 0b101, 0b110],
        'E' => [0b111, 0b100, 0b110, 0b100, 0b111],
        'F' => [0b111, 0b100, 0b110, 0b100, 0b100],
        'G' => [0b011, 0b100, 0b101, 0b101, 0b011],
        'H' => [0b101, 0b101, 0b111, 0b101, 0b101],
        'I' => [0b111, 0b010, 0b010, 0b010, 0b111],
        'J' => [0b001, 0b001, 0b001, 0b101, 0b010],
        'K' => [0b101, 0b101, 0b110, 0b101, 0b101],
        'L' => [0b100, 0b100, 0b100, 0b100, 0b111],
        'M' => [0b101, 0b111, 0b111, 0b101, 0b101],
        'N' => [0b110, 0b101, 0b101, 0b101, 0b101],
        'O' => [0b010, 0b101, 0b101, 0b101, 0b010],
        'P' => [0b110, 0b101, 0b110, 0b100, 0b100],
        'Q' => [0b010, 0b101, 0b101, 0b110, 0b011],
        'R' => [0b110, 0b101, 0b110, 0b101, 0b101],
        'S' => [0b011, 0b100, 0b010, 0b001, 0b110],
        'T' => [0b111, 0b010, 0b010, 0b010, 0b010],
        'U' => [0b101, 0b101, 0b101, 0b101, 0b111],
        'V' => [0b101, 0b101, 0b101, 0b101, 0b010],
        'W' => [0b101, 0b101, 0b111, 0b111, 0b101],
        'X' => [0b101, 0b101, 0b010, 0b101, 0b101],
        'Y' => [0b101, 0b101, 0b010, 0b010, 0b010],
        'Z' => [0b111, 0b001, 0b010, 0b100, 0b111],
        '-' => [0b000, 0b000, 0b111, 0b000, 0b000],
        '_' => [0b000, 0b000, 0b000, 0b000, 0b111],
        '.' => [0b000, 0b000, 0b000, 0b000, 0b010],
        ',' => [0b000, 0b000, 0b000, 0b010, 0b100],
        ':' => [0b000, 0b010, 0b000, 0b010, 0b000],
        '/' => [0b001, 0b001, 0b010, 0b100, 0b100],
        '%' => [0b101, 0b001, 0b010, 0b100, 0b101],
        '<' => [0b001, 0b010, 0b100, 0b010, 0b001],
        '>' => [0b100, 0b010, 0b001, 0b010, 0b100],
        '=' => [0b000, 0b111, 0b000, 0b111, 0b000],
        '+' => [0b000, 0b010, 0b111, 0b010, 0b000],
        '(' => [0b001, 0b010, 0b010, 0b010, 0b001],
        ')' => [0b100, 0b010, 0b010, 0b010, 0b100],
        '#' => [0b101, 0b111, 0b101, 0b111, 0b101],
        '*' => [0b000, 0b101, 0b010, 0b101, 0b000],
        '^' => [0b010, 0b101, 0b000, 0b000, 0b000],
        _ => [0; 5],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trip_through_the_generic_reader() {
        let mut img = RgbImage::new(5, 4, [10, 20, 30]);
        img.put(4, 3, [200, 100, 0]);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.png");
        img.save(&p).unwrap();
        assert_eq!(read_png_rgb(&p).unwrap(), img);
    }

    #[test]
    fn chart_bars_are_proportional() {
        let s = Series { name: "a".into(), colour: [255, 0, 0], values: vec![10.0, 5.0] };
        let img = bar_chart("t", &["x".into(), "y".into()], &[s]);
        // Only the plot area (y in 50..=310): the legend square below it is red too.
        let count_red = |x0: u32| (50..=310).filter(|&y| img.get(x0, y) == [255, 0, 0]).count();
        // Bars start at left + 4 and groups are 1·10 + 8 = 18 px wide; the plot is 260 px tall.
        assert_eq!(count_red(70 + 4 + 2), 260);
        assert_eq!(count_red(70 + 18 + 4 + 2), 130);
    }

    #[test]
    fn nearest_resize_keeps_blocks() {
        let mut img = RgbImage::new(2, 2, [0, 0, 0]);
        img.put(1, 1, [9, 9, 9]);
        let big = img.resized(4, 4);
        assert_eq!(big.get(3, 3), [9, 9, 9]);
        assert_eq!(big.get(2, 2), [9, 9, 9]);
        assert_eq!(big.get(1, 1), [0, 0, 0]);
    }
}
