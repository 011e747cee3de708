//! Figures: the one place that draws text and the furniture that explains a picture — titles, axis
//! labels and ticks, legends, scale bars, labelled boxes — on an 8-bit RGB raster.
//!
//! - [`RgbImage`]: the raster (pixels, rectangles, lines, discs, filled polygons, blending,
//!   nearest-neighbour scaling);
//!   its PNG reading and writing live with the stage that owns the files ([`crate::export::raster`]);
//! - [`text`]: text in DejaVu Sans (embedded, `assets/fonts/`), anti-aliased by [`ab_glyph`];
//! - [`chart`]: grouped bar charts with a title, axis labels, ticks with values on both axes, grid
//!   lines and a legend;
//! - [`legend`]: legends, scale bars and labelled boxes.
//!
//! Every stage that draws a figure (the flight plan of `sample`, the statistics of `export-coco`, the
//! overlays of `eval-loc`) draws its words, and its lines, discs and filled shapes, through here. Everything is integer placement plus `f32`
//! glyph coverage computed the same way every time: the same inputs give byte-identical pictures.

pub mod chart;
pub mod legend;
pub mod text;

pub use chart::{BarChart, ChartLayout, Series};
pub use legend::{LegendItem, Swatch};
pub use text::{Align, TextStyle};

/// RGB colour, 8 bits per channel.
pub type Rgb = [u8; 3];

/// Black text and axes.
pub const INK: Rgb = [20, 20, 20];
/// White.
pub const WHITE: Rgb = [255, 255, 255];
/// Grid lines and frames of secondary importance.
pub const GRID: Rgb = [222, 222, 222];

/// An 8-bit RGB image, row-major from the top row.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbImage {
    /// Pixels.
    pub width: u32,
    /// Pixels.
    pub height: u32,
    /// `width × height × 3` bytes.
    pub data: Vec<u8>,
}

impl RgbImage {
    /// An image filled with `colour`.
    pub fn new(width: u32, height: u32, colour: Rgb) -> Self {
        let data = colour.iter().copied().cycle().take(width as usize * height as usize * 3).collect();
        RgbImage { width, height, data }
    }

    /// The pixel at (x, y).
    ///
    /// # Panics
    /// When (x, y) is outside the image.
    pub fn get(&self, x: u32, y: u32) -> Rgb {
        let i = (y as usize * self.width as usize + x as usize) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    fn index(&self, x: i64, y: i64) -> Option<usize> {
        (x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height)
            .then(|| (y as usize * self.width as usize + x as usize) * 3)
    }

    /// Sets a pixel; coordinates outside the image are ignored.
    pub fn put(&mut self, x: i64, y: i64, c: Rgb) {
        if let Some(i) = self.index(x, y) {
            self.data[i..i + 3].copy_from_slice(&c);
        }
    }

    /// Blends `c` over a pixel with opacity `alpha` in [0, 1]; outside pixels are ignored.
    pub fn blend(&mut self, x: i64, y: i64, c: Rgb, alpha: f32) {
        if let Some(i) = self.index(x, y) {
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

    /// A filled disc of radius `r_px` centred on pixel (cx, cy).
    pub fn disc(&mut self, cx: i64, cy: i64, r_px: i64, c: Rgb) {
        for dy in -r_px..=r_px {
            for dx in -r_px..=r_px {
                if dx * dx + dy * dy <= r_px * r_px + r_px / 2 {
                    self.put(cx + dx, cy + dy, c);
                }
            }
        }
    }

    /// A line from pixel `a` to pixel `b` (Bresenham), `thickness_px` ≥ 1 wide (a disc per step).
    pub fn line(&mut self, a: [i64; 2], b: [i64; 2], thickness_px: i64, c: Rgb) {
        let (mut x0, mut y0) = (a[0], a[1]);
        let (dx, dy) = ((b[0] - x0).abs(), -(b[1] - y0).abs());
        let (sx, sy) = (if x0 < b[0] { 1 } else { -1 }, if y0 < b[1] { 1 } else { -1 });
        let mut err = dx + dy;
        let r = (thickness_px - 1) / 2;
        loop {
            if r == 0 {
                self.put(x0, y0, c);
            } else {
                self.disc(x0, y0, r, c);
            }
            if x0 == b[0] && y0 == b[1] {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x0 += sx;
            }
            if e2 <= dx {
                err += dx;
                y0 += sy;
            }
        }
    }

    /// Fills a polygon given in continuous pixel coordinates (x right, y down; the ring's last point
    /// joins its first): the pixels whose centre (x + 0.5, y + 0.5) lies inside by the even–odd rule.
    pub fn fill_polygon(&mut self, ring_px: &[[f64; 2]], c: Rgb) {
        let n = ring_px.len();
        for y in 0..self.height as i64 {
            let yc = y as f64 + 0.5;
            let mut xs: Vec<f64> = Vec::new();
            for i in 0..n {
                let (a, b) = (ring_px[i], ring_px[(i + 1) % n]);
                if (a[1] > yc) != (b[1] > yc) {
                    xs.push(a[0] + (yc - a[1]) / (b[1] - a[1]) * (b[0] - a[0]));
                }
            }
            xs.sort_by(f64::total_cmp);
            for pair in xs.chunks_exact(2) {
                // Pixels whose centre x + 0.5 lies in [x0, x1).
                let x_start = (pair[0] - 0.5).ceil().max(0.0) as i64;
                let x_end = ((pair[1] - 0.5).ceil() as i64).min(self.width as i64);
                for x in x_start..x_end {
                    self.put(x, y, c);
                }
            }
        }
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_resize_keeps_blocks() {
        let mut img = RgbImage::new(2, 2, [0, 0, 0]);
        img.put(1, 1, [9, 9, 9]);
        let big = img.resized(4, 4);
        assert_eq!(big.get(3, 3), [9, 9, 9]);
        assert_eq!(big.get(2, 2), [9, 9, 9]);
        assert_eq!(big.get(1, 1), [0, 0, 0]);
    }

    #[test]
    fn polygon_fill_samples_pixel_centres() {
        let mut img = RgbImage::new(10, 10, [0, 0, 0]);
        // A square with corners on pixel edges covers exactly the pixels inside: x 2..6, y 4..8.
        img.fill_polygon(&[[2.0, 4.0], [6.0, 4.0], [6.0, 8.0], [2.0, 8.0]], [9, 9, 9]);
        assert_eq!(img.data.chunks_exact(3).filter(|p| p[0] == 9).count(), 16);
        assert_eq!(img.get(2, 4), [9, 9, 9]);
        assert_eq!(img.get(5, 7), [9, 9, 9]);
        assert_eq!(img.get(1, 4), [0, 0, 0]);
        assert_eq!(img.get(2, 8), [0, 0, 0]);
    }

    #[test]
    fn lines_reach_both_ends_and_clip() {
        let mut img = RgbImage::new(10, 10, [0, 0, 0]);
        img.line([0, 0], [9, 9], 1, [5, 5, 5]);
        assert!((0..10).all(|k| img.get(k, k) == [5, 5, 5]));
        assert_eq!(img.data.chunks_exact(3).filter(|p| p[0] == 5).count(), 10);
        // Partly outside: drawn where inside, no panic.
        img.line([-5, 3], [20, 3], 3, [7, 7, 7]);
        assert!((0..10).all(|x| img.get(x, 2) == [7, 7, 7] && img.get(x, 4) == [7, 7, 7]));
    }
}
