//! Contact sheets for eyeballing ID maps (`masks/preview_XX.png`): each frame's buildings in
//! hash-palette colours blended over the RGB frame when one exists, else over a shading computed from
//! the rendered depth (surface normals from back-projected neighbours, Lambert light), with dark
//! outlines where the ID changes. Tiles are nearest-neighbour downscaled so IDs never mix.

use std::path::Path;

use crate::camera::Intrinsics;
use crate::scene::IdMap;
use crate::util::FileError;

/// Errors of preview writing.
#[derive(Debug, thiserror::Error)]
pub enum OverlayError {
    /// Reading the RGB frame or writing the preview failed.
    #[error(transparent)]
    File(#[from] FileError),
    /// The RGB frame is not a PNG.
    #[error("{}: cannot decode the RGB frame", path.display())]
    Decode {
        /// The RGB frame.
        path: std::path::PathBuf,
        /// The PNG decoder's error.
        #[source]
        source: png::DecodingError,
    },
    /// The RGB frame's colour type is none of RGB, RGBA, grey, grey + alpha.
    #[error("{}: unsupported PNG layout for an RGB frame ({color:?})", path.display())]
    Unsupported {
        /// The RGB frame.
        path: std::path::PathBuf,
        /// Its colour type.
        color: png::ColorType,
    },
    /// The RGB frame is not 8 bits per channel (or its data does not fill its size).
    #[error("{}: unsupported PNG layout for an RGB frame ({color:?} at {bit_depth:?} bits)", path.display())]
    BitDepth {
        /// The RGB frame.
        path: std::path::PathBuf,
        /// Its colour type.
        color: png::ColorType,
        /// Its bit depth.
        bit_depth: png::BitDepth,
    },
    /// The preview PNG cannot be encoded.
    #[error("encoding the preview failed")]
    Encode(#[source] png::EncodingError),
}

/// An 8-bit RGB image, row-major.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbImage {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Row-major R, G, B bytes.
    pub rgb: Vec<u8>,
}

impl RgbImage {
    /// An image of one colour.
    pub fn filled(width: u32, height: u32, colour: [u8; 3]) -> Self {
        RgbImage { width, height, rgb: colour.repeat(width as usize * height as usize) }
    }

    fn get(&self, x: u32, y: u32) -> [u8; 3] {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    fn put(&mut self, x: u32, y: u32, c: [u8; 3]) {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        self.rgb[i..i + 3].copy_from_slice(&c);
    }
}

/// A bright, well-separated colour for a building ID (0, the background, is black): a 32-bit integer
/// hash (the murmur3 finaliser) picks hue, saturation and value, so neighbouring IDs differ visibly.
pub fn palette(id: u32) -> [u8; 3] {
    if id == 0 {
        return [0, 0, 0];
    }
    let mut h = id;
    h ^= h >> 16;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^= h >> 16;
    let hue = (h % 360) as f64;
    let sat = 0.55 + 0.4 * ((h >> 9) & 0xff) as f64 / 255.0;
    let val = 0.75 + 0.25 * ((h >> 17) & 0xff) as f64 / 255.0;
    hsv_to_rgb(hue, sat, val)
}

fn hsv_to_rgb(hue_deg: f64, s: f64, v: f64) -> [u8; 3] {
    let c = v * s;
    let hp = hue_deg / 60.0;
    let x = c * (1.0 - (hp % 2.0 - 1.0).abs());
    let (r, g, b) = match hp as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = v - c;
    [r, g, b].map(|t| ((t + m) * 255.0).round().clamp(0.0, 255.0) as u8)
}

/// Grey shading of a depth map (metres along the optical axis, 0 = nothing): normals from the
/// back-projected right and lower neighbours, lit from the upper left of the camera; background is
/// dark grey.
pub fn shade_depth(depth_m: &[f32], k: &Intrinsics) -> RgbImage {
    let (w, h) = (k.width_px, k.height_px);
    let mut out = RgbImage::filled(w, h, [40, 40, 40]);
    let at = |x: u32, y: u32| -> Option<[f64; 3]> {
        let z = *depth_m.get(y as usize * w as usize + x as usize)? as f64;
        if z <= 0.0 {
            return None;
        }
        let (u, v) = (x as f64 + 0.5, y as f64 + 0.5);
        Some([z * (u - k.cx_px) / k.fx_px, z * (v - k.cy_px) / k.fy_px, z])
    };
    // Light direction in camera axes (towards the camera, from the upper left), normalised.
    let l = {
        let v = [-0.4f64, -0.6, -1.0];
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|c| c / n)
    };
    for y in 0..h {
        for x in 0..w {
            let Some(p) = at(x, y) else { continue };
            let px = if x + 1 < w { at(x + 1, y) } else { None };
            let py = if y + 1 < h { at(x, y + 1) } else { None };
            let shade = match (px, py) {
                (Some(a), Some(b)) => {
                    let du = [a[0] - p[0], a[1] - p[1], a[2] - p[2]];
                    let dv = [b[0] - p[0], b[1] - p[1], b[2] - p[2]];
                    let n = [
                        du[1] * dv[2] - du[2] * dv[1],
                        du[2] * dv[0] - du[0] * dv[2],
                        du[0] * dv[1] - du[1] * dv[0],
                    ];
                    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                    if len > 0.0 {
                        0.3 + 0.7 * ((n[0] * l[0] + n[1] * l[1] + n[2] * l[2]) / len).abs()
                    } else {
                        0.6
                    }
                }
                _ => 0.6,
            };
            let g = (shade * 230.0).round().clamp(0.0, 255.0) as u8;
            out.put(x, y, [g, g, g]);
        }
    }
    out
}

/// Buildings in palette colours blended (`alpha` of the colour) over `backdrop`, with a dark outline on
/// pixels whose right or lower neighbour has another ID. `backdrop` is resampled (nearest) to the ID
/// map's size when it differs.
pub fn overlay_ids(map: &IdMap, backdrop: &RgbImage, alpha: f64) -> RgbImage {
    let (ids, width, height) = (map.raw(), map.width(), map.height());
    let mut out = RgbImage::filled(width, height, [0, 0, 0]);
    for y in 0..height {
        for x in 0..width {
            let bx = ((x as u64 * backdrop.width as u64) / width as u64) as u32;
            let by = ((y as u64 * backdrop.height as u64) / height as u64) as u32;
            let bg = backdrop.get(bx.min(backdrop.width - 1), by.min(backdrop.height - 1));
            let i = y as usize * width as usize + x as usize;
            let id = ids[i];
            let edge =
                (x + 1 < width && ids[i + 1] != id) || (y + 1 < height && ids[i + width as usize] != id);
            let c = if edge {
                [10, 10, 10]
            } else if id == 0 {
                bg
            } else {
                let p = palette(id);
                [0, 1, 2].map(|k| ((1.0 - alpha) * bg[k] as f64 + alpha * p[k] as f64).round() as u8)
            };
            out.put(x, y, c);
        }
    }
    out
}

/// Nearest-neighbour resize (pixel centres map to pixel centres).
pub fn resize_nearest(img: &RgbImage, width: u32, height: u32) -> RgbImage {
    let mut out = RgbImage::filled(width, height, [0, 0, 0]);
    for y in 0..height {
        let sy = (((y as f64 + 0.5) * img.height as f64 / height as f64) as u32).min(img.height - 1);
        for x in 0..width {
            let sx = (((x as f64 + 0.5) * img.width as f64 / width as f64) as u32).min(img.width - 1);
            out.put(x, y, img.get(sx, sy));
        }
    }
    out
}

/// Lays tiles out in a grid of `columns`, each scaled to `tile_width_px` (keeping its aspect ratio),
/// separated by 4 px of dark grey.
pub fn contact_sheet(tiles: &[RgbImage], columns: u32, tile_width_px: u32) -> RgbImage {
    const GAP: u32 = 4;
    let columns = columns.max(1);
    let scaled: Vec<RgbImage> = tiles
        .iter()
        .map(|t| {
            let h = ((t.height as u64 * tile_width_px as u64) / t.width.max(1) as u64).max(1) as u32;
            resize_nearest(t, tile_width_px, h)
        })
        .collect();
    let tile_h = scaled.iter().map(|t| t.height).max().unwrap_or(1);
    let rows = (scaled.len() as u32).div_ceil(columns).max(1);
    let cols = (scaled.len() as u32).clamp(1, columns);
    let mut sheet =
        RgbImage::filled(GAP + cols * (tile_width_px + GAP), GAP + rows * (tile_h + GAP), [25, 25, 25]);
    for (n, t) in scaled.iter().enumerate() {
        let (c, r) = (n as u32 % columns, n as u32 / columns);
        let (x0, y0) = (GAP + c * (tile_width_px + GAP), GAP + r * (tile_h + GAP));
        for y in 0..t.height {
            for x in 0..t.width {
                sheet.put(x0 + x, y0 + y, t.get(x, y));
            }
        }
    }
    sheet
}

/// Reads an 8-bit PNG as RGB (grey, grey+alpha and RGBA are converted; alpha is dropped).
///
/// # Errors
/// [`OverlayError::File`], [`OverlayError::Decode`], [`OverlayError::Unsupported`] or [`OverlayError::BitDepth`],
/// naming `path`.
pub fn read_rgb_png(path: &Path) -> Result<RgbImage, OverlayError> {
    let bytes = crate::util::read_file(path)?;
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader =
        decoder.read_info().map_err(|source| OverlayError::Decode { path: path.to_path_buf(), source })?;
    let mut buf = vec![0u8; reader.output_buffer_size()];
    let frame = reader
        .next_frame(&mut buf)
        .map_err(|source| OverlayError::Decode { path: path.to_path_buf(), source })?;
    let data = &buf[..frame.buffer_size()];
    let rgb: Vec<u8> = match frame.color_type {
        png::ColorType::Rgb => data.to_vec(),
        png::ColorType::Rgba => data.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect(),
        png::ColorType::Grayscale => data.iter().flat_map(|&g| [g, g, g]).collect(),
        png::ColorType::GrayscaleAlpha => data.chunks_exact(2).flat_map(|p| [p[0], p[0], p[0]]).collect(),
        other => {
            return Err(OverlayError::Unsupported { path: path.to_path_buf(), color: other });
        }
    };
    if frame.bit_depth != png::BitDepth::Eight
        || rgb.len() != 3 * frame.width as usize * frame.height as usize
    {
        return Err(OverlayError::BitDepth {
            path: path.to_path_buf(),
            color: frame.color_type,
            bit_depth: frame.bit_depth,
        });
    }
    Ok(RgbImage { width: frame.width, height: frame.height, rgb })
}

/// Writes an RGB image as PNG atomically (default compression: previews are small and read by people).
///
/// # Errors
/// [`OverlayError::Encode`] or [`OverlayError::File`] naming `path`.
pub fn write_rgb_png(path: &Path, img: &RgbImage) -> Result<(), OverlayError> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, img.width, img.height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().map_err(OverlayError::Encode)?;
        w.write_image_data(&img.rgb).map_err(OverlayError::Encode)?;
        w.finish().map_err(OverlayError::Encode)?;
    }
    crate::util::write_bytes_atomic(path, &out)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn palette_is_deterministic_bright_and_background_black() {
        assert_eq!(palette(0), [0, 0, 0]);
        assert_eq!(palette(12345), palette(12345));
        for id in 1..200 {
            let c = palette(id);
            assert!(c.iter().copied().max().unwrap() >= 190, "{id}: {c:?} too dark");
        }
        // Consecutive IDs get different colours.
        let distinct: std::collections::BTreeSet<[u8; 3]> = (1..100).map(palette).collect();
        assert!(distinct.len() >= 95, "{}", distinct.len());
    }

    #[test]
    fn overlay_blends_and_outlines() {
        // 4×1: background, building 7, building 7, background over a flat grey backdrop.
        let bg = RgbImage::filled(4, 1, [100, 100, 100]);
        let out = overlay_ids(&IdMap::from_raw(4, 1, vec![0, 7, 7, 0]).unwrap(), &bg, 0.5);
        // Pixel 0 borders building 7 on its right: outline.
        assert_eq!(out.get(0, 0), [10, 10, 10]);
        // Pixel 1: half palette, half grey (hand computation).
        let p = palette(7);
        assert_eq!(out.get(1, 0), [0, 1, 2].map(|k| ((100.0 + p[k] as f64) / 2.0).round() as u8));
        // Pixel 3: background, last pixel, no neighbour: the backdrop.
        assert_eq!(out.get(3, 0), [100, 100, 100]);
    }

    #[test]
    fn flat_ground_facing_the_camera_shades_uniformly() {
        let k = Intrinsics { width_px: 8, height_px: 6, fx_px: 10.0, fy_px: 10.0, cx_px: 4.0, cy_px: 3.0 };
        let depth = vec![50.0f32; 48];
        let img = shade_depth(&depth, &k);
        let inner: std::collections::BTreeSet<[u8; 3]> =
            (0..5).flat_map(|y| (0..7).map(move |x| (x, y))).map(|(x, y)| img.get(x, y)).collect();
        assert_eq!(inner.len(), 1, "{inner:?}");
        let zero = shade_depth(&[0.0; 48], &k);
        assert_eq!(zero.get(3, 3), [40, 40, 40]);
    }

    #[test]
    fn contact_sheet_layout() {
        let tiles = vec![RgbImage::filled(20, 10, [255, 0, 0]); 5];
        let s = contact_sheet(&tiles, 3, 10);
        // 3 columns × 2 rows of 10×5 tiles with 4 px gaps.
        assert_eq!((s.width, s.height), (4 + 3 * 14, 4 + 2 * 9));
        assert_eq!(s.get(4, 4), [255, 0, 0]);
        assert_eq!(s.get(0, 0), [25, 25, 25]);
    }

    #[test]
    fn rgb_png_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.png");
        let img = RgbImage { width: 2, height: 1, rgb: vec![1, 2, 3, 4, 5, 6] };
        write_rgb_png(&p, &img).unwrap();
        assert_eq!(read_rgb_png(&p).unwrap(), img);
    }
}
