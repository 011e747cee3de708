//! PNG input and output of the figures' raster ([`RgbImage`], drawn by [`crate::util::figure`]: text,
//! charts, legends) and of RGB frames, and the instance palette of overlays.

use std::path::Path;

use super::error::ImageProblem;
use super::CocoError;

/// The raster of every figure ([`crate::util::figure::RgbImage`]); its PNG input and output are here.
pub use crate::util::figure::{Rgb, RgbImage};

impl RgbImage {
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
}
