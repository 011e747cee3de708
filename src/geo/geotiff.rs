//! Reads the one grid of a PROJ GeoTIFF vertical-shift file (the rules are in [`super::geoid`]'s module
//! doc), following PROJ 9's `GTiffDataset::nextGrid` and `GTiffVGridShiftSet::open` (src/grids.cpp).
//!
//! Hands on the node extent in degrees and the values south row first, as the GTX reader does, so
//! one interpolation serves both formats.
//!
//! # References
//! - PROJ, *Geodetic TIFF grids (GTG)*, <https://proj.org/specifications/geodetictiffgrids.html>.
//! - OGC GeoTIFF 1.1 (19-008r4): `ModelPixelScale` 33550, `ModelTiepoint` 33922, `ModelTransformation`
//!   34264, `GeoKeyDirectory` 34735 (`GTModelTypeGeoKey` 1024, `GTRasterTypeGeoKey` 1025); GDAL's
//!   `GDAL_METADATA` 42112 and `GDAL_NODATA` 42113.

use std::io::Cursor;

use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::{PlanarConfiguration, Tag};

use super::error::GeoTiffError;

/// A decoded grid: nodes `[west, south]` + steps, `rows × cols` values south row first.
pub(crate) struct TiffGrid {
    pub west_deg: f64,
    pub south_deg: f64,
    pub dlon_deg: f64,
    pub dlat_deg: f64,
    pub rows: usize,
    pub cols: usize,
    pub values_m: Vec<f32>,
    /// The `GDAL_NODATA` value, if the file has one.
    pub nodata: Option<f32>,
}

/// Whether `bytes` start with a TIFF or BigTIFF signature (either byte order).
pub(crate) fn is_tiff(bytes: &[u8]) -> bool {
    matches!(bytes.get(..4), Some(b"II*\0" | b"MM\0*" | b"II+\0" | b"MM\0+"))
}

const GT_MODEL_TYPE: u16 = 1024;
const GT_RASTER_TYPE: u16 = 1025;
const MODEL_TYPE_PROJECTED: u16 = 1;
const MODEL_TYPE_GEOGRAPHIC: u16 = 2;
const RASTER_PIXEL_IS_AREA: u16 = 1;
const GDAL_METADATA: u16 = 42112;
const MODEL_TRANSFORMATION: u16 = 34264;
/// PROJ's smallest accepted node spacing, 1e-10 rad, in degrees.
const MIN_RES_DEG: f64 = 1e-10 * 180.0 / std::f64::consts::PI;
/// `NewSubfileType` bit 0: a reduced-resolution version (overview) of another image.
const REDUCED_RESOLUTION: u32 = 1;
/// `NewSubfileType` bit 1: one page of a multi-page file (PROJ accepts it for subgrids).
const FILETYPE_PAGE: u32 = 2;

/// One `<Item>` of `GDAL_METADATA`.
struct MetaItem {
    name: String,
    sample: Option<usize>,
    role: Option<String>,
    value: String,
}

/// Parses GDAL's `<GDALMetadata><Item name=".." sample=".." role="..">value</Item>…` XML (GDAL writes
/// it in this one flat shape; attribute values and text are unescaped for the five XML entities).
fn metadata_items(xml: &str) -> Vec<MetaItem> {
    fn unescape(s: &str) -> String {
        s.replace("&lt;", "<")
            .replace("&gt;", ">")
            .replace("&quot;", "\"")
            .replace("&apos;", "'")
            .replace("&amp;", "&")
    }
    fn attr(tag: &str, name: &str) -> Option<String> {
        let at = tag.find(&format!(" {name}=\""))? + name.len() + 3;
        let len = tag[at..].find('"')?;
        Some(unescape(&tag[at..at + len]))
    }
    let mut items = Vec::new();
    for chunk in xml.split("<Item").skip(1) {
        let Some(gt) = chunk.find('>') else { continue };
        let tag = format!(" {}", &chunk[..gt]);
        let Some(end) = chunk[gt..].find("</Item>") else { continue };
        items.push(MetaItem {
            name: attr(&tag, "name").unwrap_or_default(),
            sample: attr(&tag, "sample").and_then(|v| v.trim().parse().ok()),
            role: attr(&tag, "role"),
            value: unescape(chunk[gt + 1..gt + end].trim()),
        });
    }
    items
}

/// The decoder over the file's bytes.
type Dec<'a> = Decoder<Cursor<&'a [u8]>>;

/// A [`GeoTiffError::Tiff`] at `what` (a tag or a step).
fn tiff_err(what: &'static str) -> impl FnOnce(tiff::TiffError) -> GeoTiffError {
    move |source| GeoTiffError::Tiff { what, source }
}

/// Decodes the grid (the caller names the file in its error).
pub(crate) fn read(bytes: &[u8]) -> Result<TiffGrid, GeoTiffError> {
    let mut dec = Decoder::new(Cursor::new(bytes))
        .map_err(tiff_err("not a readable TIFF"))?
        .with_limits(Limits::unlimited());
    let (cols, rows, spp) = image_shape(&mut dec)?;
    let pixel_is_area = geo_keys(&mut dec)?;
    let nodes = node_extent(&mut dec, pixel_is_area, cols, rows)?;
    let band = geoid_band(&mut dec, spp)?;
    let values_m = read_values(&mut dec, &band, nodes.bottom_up, rows, cols, spp)?;
    check_no_subgrids(&mut dec)?;
    Ok(TiffGrid {
        west_deg: nodes.west_deg,
        south_deg: nodes.south_deg,
        dlon_deg: nodes.h_res_deg,
        dlat_deg: nodes.v_res_deg.abs(),
        rows,
        cols,
        values_m,
        nodata: band.nodata,
    })
}

/// The first image's columns, rows and samples per pixel; it must be a full-resolution grid.
fn image_shape(dec: &mut Dec) -> Result<(usize, usize, usize), GeoTiffError> {
    let subfile: u32 =
        dec.find_tag_unsigned(Tag::NewSubfileType).map_err(tiff_err("NewSubfileType"))?.unwrap_or(0);
    if subfile != 0 && subfile != FILETYPE_PAGE {
        return Err(GeoTiffError::SubfileType { subfile });
    }
    let (width, height) = dec.dimensions().map_err(tiff_err("image size"))?;
    let (cols, rows) = (width as usize, height as usize);
    if cols == 0 || rows == 0 {
        return Err(GeoTiffError::EmptyImage { width_px: width, height_px: height });
    }
    let spp: usize =
        dec.find_tag_unsigned(Tag::SamplesPerPixel).map_err(tiff_err("SamplesPerPixel"))?.unwrap_or(1);
    if spp == 0 {
        return Err(GeoTiffError::NoSamples);
    }
    Ok((cols, rows, spp))
}

/// GeoKeys: the model type must be geographic; returns whether the raster type is "pixel is area".
fn geo_keys(dec: &mut Dec) -> Result<bool, GeoTiffError> {
    let mut pixel_is_area = false;
    if let Some(v) = dec.find_tag(Tag::GeoKeyDirectoryTag).map_err(tiff_err("GeoKeyDirectory"))? {
        let keys = v.into_u16_vec().map_err(tiff_err("GeoKeyDirectory"))?;
        if keys.len() < 4 || keys.len() % 4 != 0 {
            return Err(GeoTiffError::GeoKeyCount { count: keys.len() });
        }
        if keys[0] != 1 {
            return Err(GeoTiffError::GeoKeyVersion { major: keys[0] });
        }
        for k in keys[4..].chunks_exact(4) {
            match (k[0], k[3]) {
                (GT_MODEL_TYPE, MODEL_TYPE_GEOGRAPHIC) => {}
                (GT_MODEL_TYPE, MODEL_TYPE_PROJECTED) => return Err(GeoTiffError::Projected),
                (GT_MODEL_TYPE, t) => return Err(GeoTiffError::ModelType { model_type: t }),
                (GT_RASTER_TYPE, t) => pixel_is_area = t == RASTER_PIXEL_IS_AREA,
                _ => {}
            }
        }
    }
    Ok(pixel_is_area)
}

/// The f64 values of a tag, if present.
fn f64s(dec: &mut Dec, tag: Tag, name: &'static str) -> Result<Option<Vec<f64>>, GeoTiffError> {
    match dec.find_tag(tag).map_err(tiff_err(name))? {
        Some(v) => Ok(Some(v.into_f64_vec().map_err(tiff_err(name))?)),
        None => Ok(None),
    }
}

/// Where the grid's nodes lie, degrees.
struct NodeExtent {
    west_deg: f64,
    south_deg: f64,
    h_res_deg: f64,
    /// Negative when the rows run south to north.
    v_res_deg: f64,
    /// Whether the first row is the southernmost.
    bottom_up: bool,
}

/// Georeferencing, in degrees: west/north of node (0, 0) and the steps (v_res < 0: bottom-up), from
/// `ModelTransformation` or `ModelPixelScale` + `ModelTiepoint`, checked for consistency.
fn node_extent(
    dec: &mut Dec,
    pixel_is_area: bool,
    cols: usize,
    rows: usize,
) -> Result<NodeExtent, GeoTiffError> {
    let (mut west, mut north, h_res, v_res) =
        match f64s(dec, Tag::Unknown(MODEL_TRANSFORMATION), "ModelTransformation")? {
            Some(m) if m.len() == 16 => {
                if m[1] != 0.0 || m[4] != 0.0 {
                    return Err(GeoTiffError::Rotation);
                }
                (m[3], m[7], m[0], -m[5])
            }
            _ => {
                let scale = f64s(dec, Tag::ModelPixelScaleTag, "ModelPixelScale")?
                    .ok_or(GeoTiffError::MissingTag { tag: "ModelPixelScale" })?;
                if scale.len() != 3 {
                    return Err(GeoTiffError::TagLength {
                        tag: "ModelPixelScale",
                        count: scale.len(),
                        expected: "3",
                    });
                }
                let tie = f64s(dec, Tag::ModelTiepointTag, "ModelTiepoint")?
                    .ok_or(GeoTiffError::MissingTag { tag: "ModelTiepoint" })?;
                if tie.len() != 6 {
                    return Err(GeoTiffError::TagLength {
                        tag: "ModelTiepoint",
                        count: tie.len(),
                        expected: "6 (one tiepoint)",
                    });
                }
                (tie[3] - tie[0] * scale[0], tie[4] + tie[1] * scale[1], scale[0], scale[1])
            }
        };
    if pixel_is_area {
        west += 0.5 * h_res;
        north -= 0.5 * v_res;
    }
    let east = west + h_res * (cols as f64 - 1.0);
    let mut south = north - v_res * (rows as f64 - 1.0);
    let bottom_up = v_res < 0.0;
    if bottom_up {
        std::mem::swap(&mut north, &mut south);
    }
    let ok = [west, east, north, south, h_res, v_res].iter().all(|v| v.is_finite())
        && west.abs() <= 720.0
        && east.abs() <= 720.0
        && north.abs() <= 180.0 + 1e-3
        && south.abs() <= 180.0 + 1e-3
        && west < east
        && south < north
        && h_res > MIN_RES_DEG
        && v_res.abs() > MIN_RES_DEG;
    if !ok {
        return Err(GeoTiffError::Georeferencing {
            west_deg: west,
            east_deg: east,
            south_deg: south,
            north_deg: north,
            h_res_deg: h_res,
            v_res_deg: v_res,
        });
    }
    Ok(NodeExtent { west_deg: west, south_deg: south, h_res_deg: h_res, v_res_deg: v_res, bottom_up })
}

/// The band holding the geoid and how its values are stored.
struct GeoidBand {
    /// Sample index within a pixel.
    band: usize,
    /// Value = stored × scale + offset (GDAL's `scale` and `offset` roles).
    scale: f64,
    offset: f64,
    /// The `GDAL_NODATA` value, if the file has one.
    nodata: Option<f32>,
}

/// Band selection and scale/offset from `GDAL_METADATA`, nodata from `GDAL_NODATA`.
fn geoid_band(dec: &mut Dec, spp: usize) -> Result<GeoidBand, GeoTiffError> {
    let items = match dec.find_tag(Tag::Unknown(GDAL_METADATA)).map_err(tiff_err("GDAL_METADATA"))? {
        Some(v) => metadata_items(&v.into_string().map_err(tiff_err("GDAL_METADATA"))?),
        None => Vec::new(),
    };
    let descriptions: Vec<&MetaItem> = items
        .iter()
        .filter(|i| i.name == "DESCRIPTION" && i.role.as_deref() == Some("description"))
        .collect();
    let band =
        match descriptions.iter().find(|i| i.value == "geoid_undulation" || i.value == "vertical_offset") {
            Some(i) => i.sample.unwrap_or(0),
            None if descriptions.is_empty() => 0,
            None => {
                let names = descriptions.iter().map(|i| i.value.clone()).collect();
                return Err(GeoTiffError::NoGeoidBand { names });
            }
        };
    if band >= spp {
        return Err(GeoTiffError::BandOutOfRange { band, samples_per_pixel: spp });
    }
    let role_value = |role: &str| {
        items
            .iter()
            .find(|i| i.role.as_deref() == Some(role) && i.sample == Some(band))
            .and_then(|i| i.value.parse::<f64>().ok())
    };
    let (scale, offset) = (role_value("scale").unwrap_or(1.0), role_value("offset").unwrap_or(0.0));
    let nodata: Option<f32> = match dec.find_tag(Tag::GdalNodata).map_err(tiff_err("GDAL_NODATA"))? {
        Some(v) => {
            let text = v.into_string().map_err(tiff_err("GDAL_NODATA"))?;
            let t = text.trim_end_matches('\0').trim();
            Some(t.parse::<f64>().map_err(|_| GeoTiffError::Nodata { text: t.to_string() })? as f32)
        }
        None => None,
    };
    Ok(GeoidBand { band, scale, offset, nodata })
}

/// The geoid band's values, metres, south row first, scale and offset applied (not to nodata values).
fn read_values(
    dec: &mut Dec,
    b: &GeoidBand,
    bottom_up: bool,
    rows: usize,
    cols: usize,
    spp: usize,
) -> Result<Vec<f32>, GeoTiffError> {
    let GeoidBand { band, scale, offset, nodata } = *b;
    let planar = dec
        .find_tag_unsigned::<u16>(Tag::PlanarConfiguration)
        .map_err(tiff_err("PlanarConfiguration"))?
        .and_then(PlanarConfiguration::from_u16)
        .unwrap_or(PlanarConfiguration::Chunky);
    let mut data = DecodingResult::F32(Vec::new());
    dec.read_image_to_buffer(&mut data).map_err(tiff_err("reading the samples"))?;
    let n = rows * cols;
    let all: Vec<f64> = match data {
        DecodingResult::F32(v) => v.into_iter().map(f64::from).collect(),
        DecodingResult::F64(v) => v,
        _ => return Err(GeoTiffError::IntegerSamples),
    };
    let at = |i: usize| -> Option<f64> {
        match planar {
            PlanarConfiguration::Planar => all.get(band * n + i).copied(),
            _ => all.get(i * spp + band).copied(),
        }
    };
    if at(n - 1).is_none() {
        return Err(GeoTiffError::TooFewSamples { found: all.len(), rows, cols, samples_per_pixel: spp });
    }
    let mut values_m = vec![0f32; n];
    for y_tiff in 0..rows {
        let y_from_bottom = if bottom_up { y_tiff } else { rows - 1 - y_tiff };
        for x in 0..cols {
            let v = at(y_tiff * cols + x).expect("length checked above") as f32;
            // PROJ applies scale/offset only to values that are not nodata.
            let is_nodata = nodata == Some(v);
            values_m[y_from_bottom * cols + x] =
                if is_nodata { v } else { (f64::from(v) * scale + offset) as f32 };
        }
    }
    Ok(values_m)
}

/// Further IFDs: overviews are fine, more full-resolution grids (PROJ subgrids) are not.
fn check_no_subgrids(dec: &mut Dec) -> Result<(), GeoTiffError> {
    let mut ifd = 1;
    while dec.more_images() {
        dec.next_image().map_err(|source| GeoTiffError::Ifd { ifd, source })?;
        let t: u32 = dec.find_tag_unsigned(Tag::NewSubfileType).ok().flatten().unwrap_or(0);
        if t & REDUCED_RESOLUTION == 0 {
            return Err(GeoTiffError::Subgrid { ifd });
        }
        ifd += 1;
    }
    Ok(())
}
