//! Geoid undulation N for orthometric → ellipsoidal heights: h = H + N.
//!
//! Takes a WGS84 latitude/longitude and hands on N in metres, from one of: nothing (heights already
//! ellipsoidal), a per-area constant, or a vertical grid PROJ can use — a `.gtx` grid such as EGM96
//! 15' (`egm96_15.gtx`, Debian package `proj-data`) or a GeoTIFF grid of PROJ-data / the PROJ CDN
//! (`jp_gsi_gsigeo2011.tif`, `nl_nsgi_nlgeo2018.tif`, …) — interpolated exactly as PROJ's `vgridshift`
//! does. (Letting PROJ itself pick a national geoid for a compound CRS is the other way, see
//! [`Crs::transform_with_heights`](super::Crs::transform_with_heights).)
//!
//! # GTX format
//! A 40-byte big-endian header — south latitude, west longitude, latitude step, longitude step (f64,
//! degrees, of the lower-left node), then rows and columns (i32) — followed by rows × columns
//! big-endian f32 values in metres, row by row from south to north, each row from west to east. Values
//! of −88.8888 (and anything beyond ±1000 m) mean "no data". A grid whose columns span 360° wraps around
//! in longitude (EGM96 15': 721 × 1440 nodes from −90° to 90° and −180° to 179.75°).
//!
//! # GeoTIFF format (as PROJ's `grids.cpp` reads it)
//! The first IFD (a full-resolution image, `NewSubfileType` 0) is the grid; further full-resolution
//! IFDs would be PROJ subgrids and are refused, reduced-resolution ones (overviews) are ignored.
//! Samples are float32 or float64, stripped or tiled, uncompressed or Deflate/LZW (with or without a
//! predictor), chunky or planar. The band used is the one whose `GDAL_METADATA` DESCRIPTION is
//! `geoid_undulation` or `vertical_offset`, else band 0; its `scale`/`offset` items are applied.
//! Georeferencing: `ModelTransformation` (no rotation) or `ModelPixelScale` + `ModelTiepoint`, in
//! degrees (`GTModelTypeGeoKey` must be geographic). `GTRasterTypeGeoKey` = PixelIsArea puts the nodes at
//! pixel centres (half a pixel in from the tiepoint); PixelIsPoint — and, as in PROJ, a file without
//! the key — puts them on the tiepoint grid. Rows run north to south unless the latitude scale is
//! negative. Nodes equal to `GDAL_NODATA`, or NaN, are "no data".
//!
//! # Interpolation
//! As PROJ 9 `read_vgrid_value` (src/grids.cpp): bilinear in the cell containing the point; at the
//! eastern edge of a world-wrapping grid the cell's east nodes are column 0; on the northern edge the
//! row is clamped; nodata nodes are left out and the remaining weights renormalised; a cell with no
//! valid node is an error.
//!
//! # References
//! - PROJ `vgridshift` and GTX documentation, <https://proj.org/operations/transformations/vgridshift.html>.
//! - Lemoine et al. (1998), *The Development of the Joint NASA GSFC and NIMA Geopotential Model EGM96*,
//!   NASA/TP-1998-206861.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::geotiff::is_tiff;
use super::GeoError;

/// The geoid model used for an area.
#[derive(Debug, Clone, PartialEq)]
pub enum Geoid {
    /// Heights are already ellipsoidal: N = 0.
    None,
    /// A constant undulation N in metres (h = H + N).
    Constant(f64),
    /// A gridded geoid model (EGM96 15', or another `.gtx` or GeoTIFF grid).
    Grid(GeoidGrid),
}

/// File name of the EGM96 15' grid in PROJ's data directory.
pub const EGM96_FILE_NAME: &str = "egm96_15.gtx";

impl Geoid {
    /// Undulation N (metres) at a WGS84 position: h = H + N.
    ///
    /// Infallible for the EGM96 grid, which covers the globe; for a regional grid a point outside it
    /// (or in a cell without data) gives NaN — use [`Geoid::try_undulation_m`] to get the error.
    ///
    /// # Units
    /// Degrees in, metres out.
    pub fn undulation_m(&self, lat_deg: f64, lon_deg: f64) -> f64 {
        self.try_undulation_m(lat_deg, lon_deg).unwrap_or(f64::NAN)
    }

    /// Undulation N (metres) at a WGS84 position, h = H + N.
    ///
    /// # Errors
    /// [`GeoError::Geoid`] when the position is not finite, lies outside a regional grid or in a cell
    /// without data.
    pub fn try_undulation_m(&self, lat_deg: f64, lon_deg: f64) -> Result<f64, GeoError> {
        match self {
            Geoid::None => Ok(0.0),
            Geoid::Constant(n) => Ok(*n),
            Geoid::Grid(g) => g.undulation_m(lat_deg, lon_deg),
        }
    }

    /// Finds the EGM96 15' grid: `egm96_15.gtx` in `$PROJ_DATA`, `$PROJ_LIB` (each may list several
    /// directories), `/usr/share/proj`, `/usr/local/share/proj`, then the linked PROJ's own search path.
    pub fn find_egm96() -> Option<PathBuf> {
        let mut dirs: Vec<PathBuf> = Vec::new();
        for var in ["PROJ_DATA", "PROJ_LIB"] {
            if let Some(v) = std::env::var_os(var) {
                dirs.extend(std::env::split_paths(&v));
            }
        }
        dirs.push("/usr/share/proj".into());
        dirs.push("/usr/local/share/proj".into());
        dirs.extend(super::pj::proj_search_paths().into_iter().map(PathBuf::from));
        dirs.into_iter().map(|d| d.join(EGM96_FILE_NAME)).find(|p| p.is_file())
    }

    /// A short name for manifests: "none", "constant", "egm96" (a grid loaded from `egm96*.gtx`) or
    /// "grid" (any other grid).
    pub fn name(&self) -> &'static str {
        match self {
            Geoid::None => "none",
            Geoid::Constant(_) => "constant",
            Geoid::Grid(g) => {
                let file =
                    g.path.file_name().map(|f| f.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
                if file.starts_with("egm96") {
                    "egm96"
                } else {
                    "grid"
                }
            }
        }
    }
}

/// How a grid marks nodes without data; each format has its own rule in PROJ.
#[derive(Debug, Clone, Copy, PartialEq)]
enum NoData {
    /// GTX: −88.8888, or anything beyond ±1000 m.
    Gtx,
    /// GeoTIFF: the `GDAL_NODATA` value if any, and NaN.
    Tiff(Option<f32>),
}

/// A geoid grid loaded from a PROJ `.gtx` or GeoTIFF file (values kept in memory; clones share them).
#[derive(Clone)]
pub struct GeoidGrid {
    path: PathBuf,
    nodata: NoData,
    /// Latitude of the southern row of nodes, degrees.
    south_deg: f64,
    /// Longitude of the western column of nodes, degrees (in [−180, 180)).
    west_deg: f64,
    /// Node spacing in latitude, degrees.
    dlat_deg: f64,
    /// Node spacing in longitude, degrees.
    dlon_deg: f64,
    rows: usize,
    cols: usize,
    /// rows × cols undulations in metres, south row first.
    values_m: Arc<[f32]>,
}

impl std::fmt::Debug for GeoidGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GeoidGrid")
            .field("path", &self.path)
            .field("south_deg", &self.south_deg)
            .field("west_deg", &self.west_deg)
            .field("dlat_deg", &self.dlat_deg)
            .field("dlon_deg", &self.dlon_deg)
            .field("rows", &self.rows)
            .field("cols", &self.cols)
            .finish_non_exhaustive()
    }
}

impl PartialEq for GeoidGrid {
    fn eq(&self, o: &Self) -> bool {
        self.path == o.path
            && self.nodata == o.nodata
            && (self.south_deg, self.west_deg, self.dlat_deg, self.dlon_deg)
                == (o.south_deg, o.west_deg, o.dlat_deg, o.dlon_deg)
            && (self.rows, self.cols) == (o.rows, o.cols)
            && (Arc::ptr_eq(&self.values_m, &o.values_m) || self.values_m == o.values_m)
    }
}

/// GTX header length in bytes.
const GTX_HEADER_LEN: usize = 40;

/// GTX's official nodata value.
const GTX_NODATA: f32 = -88.8888;

/// PROJ's tolerance (radians) deciding that a grid spans the whole world in longitude, in degrees.
const FULL_WORLD_TOL_DEG: f64 = 1e-10 * 180.0 / std::f64::consts::PI;

fn be_f64(b: &[u8], at: usize) -> f64 {
    f64::from_be_bytes(b[at..at + 8].try_into().expect("8-byte slice of a length-checked header"))
}

fn be_i32(b: &[u8], at: usize) -> i32 {
    i32::from_be_bytes(b[at..at + 4].try_into().expect("4-byte slice of a length-checked header"))
}

impl GeoidGrid {
    /// Loads a vertical grid as PROJ would: a file named `*.gtx` is a GTX grid, anything else must be
    /// a (Big)TIFF (formats in the module doc).
    ///
    /// # Errors
    /// [`GeoError::File`] if the file cannot be read; [`GeoError::Geoid`] naming the file and the
    /// problem if it is neither, or malformed, or a kind of TIFF that cannot be read as a geoid grid.
    pub fn load(path: &Path) -> Result<GeoidGrid, GeoError> {
        let is_gtx = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("gtx"));
        let bytes = crate::util::read_file(path)?;
        if is_gtx {
            Self::from_gtx_bytes(path, &bytes)
        } else if is_tiff(&bytes) {
            Self::from_tiff_bytes(path, &bytes)
        } else {
            Err(GeoError::Geoid {
                path: path.display().to_string(),
                why: "neither a GTX grid (named *.gtx) nor a GeoTIFF (no TIFF signature): PROJ vertical \
                      grids are .gtx or .tif files"
                    .into(),
            })
        }
    }

    /// Loads a `.gtx` grid (format in the module doc).
    ///
    /// # Errors
    /// [`GeoError::File`] if the file cannot be read; [`GeoError::Geoid`] naming the file if it is
    /// shorter than its header says, has a nonsensical header (non-positive sizes or steps, origin
    /// outside ±90°/±360°) or trailing bytes.
    pub fn load_gtx(path: &Path) -> Result<GeoidGrid, GeoError> {
        let bytes = crate::util::read_file(path)?;
        Self::from_gtx_bytes(path, &bytes)
    }

    /// Parses the bytes of a `.gtx` file; `path` is recorded and used in error messages.
    ///
    /// # Errors
    /// As [`GeoidGrid::load_gtx`].
    pub fn from_gtx_bytes(path: &Path, bytes: &[u8]) -> Result<GeoidGrid, GeoError> {
        let bad = |why: String| GeoError::Geoid { path: path.display().to_string(), why };
        if bytes.len() < GTX_HEADER_LEN {
            return Err(bad(format!(
                "{} bytes is too short for a GTX grid (the header alone is {GTX_HEADER_LEN})",
                bytes.len()
            )));
        }
        let (south_deg, mut west_deg) = (be_f64(bytes, 0), be_f64(bytes, 8));
        let (dlat_deg, dlon_deg) = (be_f64(bytes, 16), be_f64(bytes, 24));
        let (rows, cols) = (be_i32(bytes, 32), be_i32(bytes, 36));
        if !(south_deg.is_finite() && (-90.0..=90.0).contains(&south_deg)) {
            return Err(bad(format!("south latitude {south_deg} is not within ±90° (not a GTX file?)")));
        }
        if !(west_deg.is_finite() && (-360.0..=360.0).contains(&west_deg)) {
            return Err(bad(format!("west longitude {west_deg} is not within ±360° (not a GTX file?)")));
        }
        if !(dlat_deg.is_finite() && dlat_deg > 0.0 && dlon_deg.is_finite() && dlon_deg > 0.0) {
            return Err(bad(format!("grid steps {dlat_deg}° × {dlon_deg}° must be positive")));
        }
        if rows < 1 || cols < 1 {
            return Err(bad(format!("grid size {rows} rows × {cols} columns must be positive")));
        }
        let (rows, cols) = (rows as usize, cols as usize);
        let want = rows
            .checked_mul(cols)
            .and_then(|n| n.checked_mul(4))
            .and_then(|n| n.checked_add(GTX_HEADER_LEN))
            .ok_or_else(|| bad(format!("grid size {rows} × {cols} is too large")))?;
        if bytes.len() != want {
            return Err(bad(format!(
                "the header announces {rows} × {cols} values ({want} bytes with the header) but the file \
                 has {} bytes",
                bytes.len()
            )));
        }
        // Some GTX files are in 0..360; shift into −180..180 as PROJ does.
        if west_deg >= 180.0 {
            west_deg -= 360.0;
        }
        let values_m: Arc<[f32]> = bytes[GTX_HEADER_LEN..]
            .chunks_exact(4)
            .map(|c| f32::from_be_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        Ok(GeoidGrid {
            path: path.to_path_buf(),
            nodata: NoData::Gtx,
            south_deg,
            west_deg,
            dlat_deg,
            dlon_deg,
            rows,
            cols,
            values_m,
        })
    }

    /// Parses the bytes of a GeoTIFF vertical grid (rules in the module doc); `path` is recorded and
    /// used in error messages.
    ///
    /// # Errors
    /// [`GeoError::GeoTiff`] naming the file and what is wrong: not a TIFF, no georeferencing, a
    /// projected CRS, integer samples, several full-resolution grids, no geoid band, …
    pub fn from_tiff_bytes(path: &Path, bytes: &[u8]) -> Result<GeoidGrid, GeoError> {
        let g = super::geotiff::read(bytes)
            .map_err(|e| GeoError::GeoTiff { path: path.display().to_string(), source: Box::new(e) })?;
        Ok(GeoidGrid {
            path: path.to_path_buf(),
            nodata: NoData::Tiff(g.nodata),
            south_deg: g.south_deg,
            west_deg: g.west_deg,
            dlat_deg: g.dlat_deg,
            dlon_deg: g.dlon_deg,
            rows: g.rows,
            cols: g.cols,
            values_m: g.values_m.into(),
        })
    }

    /// The file the grid was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Number of node rows (latitudes) and columns (longitudes).
    pub fn size(&self) -> (usize, usize) {
        (self.rows, self.cols)
    }

    /// Node extent `[west, south, east, north]` in degrees (east/north are the last nodes).
    pub fn extent_deg(&self) -> [f64; 4] {
        [self.west_deg, self.south_deg, self.east_deg(), self.north_deg()]
    }

    fn east_deg(&self) -> f64 {
        self.west_deg + self.dlon_deg * (self.cols - 1) as f64
    }

    fn north_deg(&self) -> f64 {
        self.south_deg + self.dlat_deg * (self.rows - 1) as f64
    }

    /// Whether the columns span the full 360° of longitude (then longitudes wrap around).
    pub fn wraps_longitude(&self) -> bool {
        self.east_deg() - self.west_deg + self.dlon_deg >= 360.0 - FULL_WORLD_TOL_DEG
    }

    fn node(&self, ix: usize, iy: usize) -> f32 {
        self.values_m[iy * self.cols + ix]
    }

    /// Undulation N in metres at a WGS84 position (h = H + N), bilinear as PROJ's `vgridshift`.
    ///
    /// # Units
    /// Degrees in, metres out.
    ///
    /// # Errors
    /// [`GeoError::Geoid`] for a non-finite position, a position outside a regional grid, or a cell
    /// whose four nodes are all "no data".
    pub fn undulation_m(&self, lat_deg: f64, lon_deg: f64) -> Result<f64, GeoError> {
        let bad = |why: String| GeoError::Geoid { path: self.path.display().to_string(), why };
        if !(lat_deg.is_finite() && lon_deg.is_finite()) {
            return Err(bad(format!("position ({lat_deg}, {lon_deg}) is not finite")));
        }
        let (west, east, south, north) = (self.west_deg, self.east_deg(), self.south_deg, self.north_deg());
        if lat_deg < south || lat_deg > north {
            return Err(bad(format!("latitude {lat_deg}° is outside the grid ({south}° to {north}°)")));
        }
        let full_world = self.wraps_longitude();
        let w = self.cols as f64;
        let mut grid_x = (lon_deg - west) / self.dlon_deg;
        if lon_deg < west || lon_deg > east {
            if full_world {
                // Into [0, width): the first remainder lands in (−w, w), the second in [0, w).
                grid_x = ((grid_x + w) % w + w) % w;
            } else {
                let lon = if lon_deg < west { lon_deg + 360.0 } else { lon_deg - 360.0 };
                if lon < west || lon > east {
                    return Err(bad(format!(
                        "longitude {lon_deg}° is outside the grid ({west}° to {east}°)"
                    )));
                }
                grid_x = (lon - west) / self.dlon_deg;
            }
        }
        let grid_y = (lat_deg - south) / self.dlat_deg;
        let ix = grid_x.floor();
        let iy = grid_y.floor();
        let (fx, fy) = (grid_x - ix, grid_y - iy);
        // Clamp against rounding at the very edges (grid_x can only reach `cols` by rounding).
        let ix = (ix as usize).min(self.cols - 1);
        let iy = (iy as usize).min(self.rows - 1);
        let ix2 = if ix + 1 < self.cols {
            ix + 1
        } else if full_world {
            0
        } else {
            self.cols - 1
        };
        let iy2 = (iy + 1).min(self.rows - 1);

        let corners = [
            (self.node(ix, iy), 1.0 - fx - fy + fx * fy),
            (self.node(ix2, iy), fx - fx * fy),
            (self.node(ix, iy2), fy - fx * fy),
            (self.node(ix2, iy2), fx * fy),
        ];
        // PROJ's nodata tests: GTX: |v| > 1000 m or the GTX marker (a NaN node counts as nodata too);
        // GeoTIFF: the GDAL_NODATA value or NaN.
        let valid = |v: f32| match self.nodata {
            NoData::Gtx => (-1000.0..=1000.0).contains(&v) && v != GTX_NODATA,
            NoData::Tiff(nd) => !v.is_nan() && Some(v) != nd,
        };
        let n_valid = corners.iter().filter(|(v, _)| valid(*v)).count();
        match n_valid {
            0 => Err(bad(format!("no geoid data around ({lat_deg}°, {lon_deg}°)"))),
            4 => Ok(corners.iter().map(|&(v, wgt)| v as f64 * wgt).sum()),
            _ => {
                let (mut sum, mut total) = (0.0, 0.0);
                for &(v, wgt) in corners.iter().filter(|(v, _)| valid(*v)) {
                    sum += v as f64 * wgt;
                    total += wgt;
                }
                Ok(sum / total)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A GTX file in memory: header + values (row-major, south row first).
    fn gtx(south: f64, west: f64, dlat: f64, dlon: f64, rows: i32, cols: i32, values: &[f32]) -> Vec<u8> {
        let mut b = Vec::new();
        for v in [south, west, dlat, dlon] {
            b.extend_from_slice(&v.to_be_bytes());
        }
        b.extend_from_slice(&rows.to_be_bytes());
        b.extend_from_slice(&cols.to_be_bytes());
        for v in values {
            b.extend_from_slice(&v.to_be_bytes());
        }
        b
    }

    fn grid(bytes: &[u8]) -> GeoidGrid {
        GeoidGrid::from_gtx_bytes(Path::new("test.gtx"), bytes).unwrap()
    }

    mod synthetic {
        use super::*;

        #[test]
        fn nodes_and_bilinear_midpoints() {
            // 2 × 3 nodes at lat 10, 11 and lon 20, 21, 22: value = 10·row + col.
            let g = grid(&gtx(10.0, 20.0, 1.0, 1.0, 2, 3, &[0.0, 1.0, 2.0, 10.0, 11.0, 12.0]));
            assert!(!g.wraps_longitude());
            assert_eq!(g.extent_deg(), [20.0, 10.0, 22.0, 11.0]);
            for (lat, lon, want) in [
                (10.0, 20.0, 0.0),
                (11.0, 22.0, 12.0),
                (10.5, 20.5, 5.5),    // mean of 0, 1, 10, 11
                (10.25, 21.75, 4.25), // 1 + 0.75 + 2.5 (bilinear is linear along each axis here)
                (11.0, 21.5, 11.5),   // northern edge: row clamped
                (10.0, 22.0, 2.0),    // eastern edge of a regional grid: column clamped
            ] {
                let n = g.undulation_m(lat, lon).unwrap();
                assert!((n - want).abs() < 1e-12, "({lat}, {lon}): {n} vs {want}");
            }
        }

        #[test]
        fn outside_a_regional_grid_is_an_error() {
            let g = grid(&gtx(10.0, 20.0, 1.0, 1.0, 2, 3, &[0.0; 6]));
            for (lat, lon) in [(9.99, 21.0), (11.01, 21.0), (10.5, 19.9), (10.5, 22.1), (f64::NAN, 21.0)] {
                let e = g.undulation_m(lat, lon).unwrap_err().to_string();
                assert!(e.contains("test.gtx"), "{e}");
            }
            // Longitudes one turn away are the same place.
            assert!(g.undulation_m(10.5, 21.0 + 360.0).is_ok());
            assert!(g.undulation_m(10.5, 21.0 - 360.0).is_ok());
            assert!(Geoid::Grid(g).undulation_m(0.0, 0.0).is_nan());
        }

        #[test]
        fn world_grid_wraps_at_the_antimeridian() {
            // 2 rows × 4 columns every 90° from −180: the cell east of 90° ends at column 0 (= 180°).
            let v = [0.0, 1.0, 2.0, 3.0, 10.0, 11.0, 12.0, 13.0];
            let g = grid(&gtx(0.0, -180.0, 1.0, 90.0, 2, 4, &v));
            assert!(g.wraps_longitude());
            let at = |lat, lon| g.undulation_m(lat, lon).unwrap();
            assert!((at(0.0, 135.0) - 1.5).abs() < 1e-12); // halfway between col 3 (3) and col 0 (0)
            assert!((at(0.0, 180.0) - 0.0).abs() < 1e-12);
            assert!((at(0.0, -180.0) - 0.0).abs() < 1e-12);
            assert!((at(0.5, 540.0) - 5.0).abs() < 1e-12);
            assert!((at(0.0, -200.0) - at(0.0, 160.0)).abs() < 1e-12);
            assert!((at(1.0, 179.0) - at(1.0, -181.0)).abs() < 1e-12);
        }

        #[test]
        fn nodata_nodes_are_left_out() {
            let g = grid(&gtx(0.0, 0.0, 1.0, 1.0, 2, 2, &[GTX_NODATA, 2.0, 4.0, -9999.0]));
            // At the centre, valid nodes 2.0 and 4.0 have equal weights.
            assert!((g.undulation_m(0.5, 0.5).unwrap() - 3.0).abs() < 1e-12);
            let all = grid(&gtx(0.0, 0.0, 1.0, 1.0, 2, 2, &[GTX_NODATA; 4]));
            assert!(all.undulation_m(0.5, 0.5).unwrap_err().to_string().contains("no geoid data"));
        }

        #[test]
        fn origin_in_0_360_is_shifted() {
            let g = grid(&gtx(0.0, 200.0, 1.0, 1.0, 2, 2, &[1.0, 2.0, 3.0, 4.0]));
            assert_eq!(g.extent_deg()[0], -160.0);
            assert!((g.undulation_m(0.0, -159.0).unwrap() - 2.0).abs() < 1e-12);
        }

        #[test]
        fn malformed_files_are_errors_naming_the_file() {
            let good = gtx(0.0, 0.0, 1.0, 1.0, 2, 2, &[0.0; 4]);
            let cases: Vec<(Vec<u8>, &str)> = vec![
                (good[..20].to_vec(), "too short"),
                (good[..good.len() - 4].to_vec(), "announces 2 × 2"),
                ([good.clone(), vec![0; 4]].concat(), "announces 2 × 2"),
                (gtx(95.0, 0.0, 1.0, 1.0, 2, 2, &[0.0; 4]), "south latitude 95"),
                (gtx(0.0, 400.0, 1.0, 1.0, 2, 2, &[0.0; 4]), "west longitude 400"),
                (gtx(0.0, 0.0, 0.0, 1.0, 2, 2, &[0.0; 4]), "steps"),
                (gtx(0.0, 0.0, 1.0, f64::NAN, 2, 2, &[0.0; 4]), "steps"),
                (gtx(0.0, 0.0, 1.0, 1.0, 0, 2, &[]), "size"),
                (gtx(0.0, 0.0, 1.0, 1.0, -1, 2, &[]), "size"),
            ];
            for (bytes, want) in cases {
                let e = GeoidGrid::from_gtx_bytes(Path::new("/x/bad.gtx"), &bytes).unwrap_err().to_string();
                assert!(e.contains("/x/bad.gtx") && e.contains(want), "{e} (wanted {want:?})");
            }
            let e = GeoidGrid::load_gtx(Path::new("/nonexistent/egm.gtx")).unwrap_err().to_string();
            assert!(e.contains("/nonexistent/egm.gtx"), "{e}");
        }

        #[test]
        fn none_constant_and_names() {
            assert_eq!(Geoid::None.undulation_m(35.0, 139.0), 0.0);
            assert_eq!(Geoid::Constant(36.7).undulation_m(-80.0, 10.0), 36.7);
            assert_eq!(Geoid::Constant(-12.5).try_undulation_m(0.0, 0.0).unwrap(), -12.5);
            assert_eq!(Geoid::None.name(), "none");
            assert_eq!(Geoid::Constant(1.0).name(), "constant");
            let g = GeoidGrid::from_gtx_bytes(
                Path::new("/a/EGM96_15.gtx"),
                &gtx(0.0, 0.0, 1.0, 1.0, 1, 1, &[0.0]),
            )
            .unwrap();
            assert_eq!(Geoid::Grid(g.clone()).name(), "egm96");
            let g2 = GeoidGrid { path: "/a/gsigeo.gtx".into(), ..g.clone() };
            assert_eq!(Geoid::Grid(g2.clone()).name(), "grid");
            assert_eq!(g, g.clone());
            assert_ne!(g, g2);
        }
    }

    /// The real EGM96 grid against PROJ's own `vgridshift` (the linked PROJ library, in-process).
    mod egm96_vs_proj {
        use super::*;
        use crate::geo::pj::Context;

        fn egm96() -> Option<PathBuf> {
            let p = Geoid::find_egm96();
            if p.is_none() {
                if std::env::var("CI").map(|v| v == "true").unwrap_or(false) {
                    panic!("CI: egm96_15.gtx not found (Debian package proj-data)");
                }
                eprintln!("skipping: egm96_15.gtx not found (install proj-data)");
            }
            p
        }

        #[test]
        fn agrees_with_proj_vgridshift_within_a_millimetre() {
            let Some(path) = egm96() else { return };
            let grid = GeoidGrid::load_gtx(&path).unwrap();
            assert_eq!(grid.size(), (721, 1440));
            assert!(grid.wraps_longitude());
            let geoid = Geoid::Grid(grid);
            assert_eq!(geoid.name(), "egm96");

            // Deterministic worldwide points (a golden-angle spiral) plus edge cases.
            let mut pts: Vec<(f64, f64)> = (0..400)
                .map(|i| {
                    let lat = (1.0 - 2.0 * (i as f64 + 0.5) / 400.0).asin().to_degrees();
                    let lon = (i as f64 * 137.507_764_050_037_85).rem_euclid(360.0) - 180.0;
                    (lat, lon)
                })
                .collect();
            pts.extend([
                (35.658, 139.7016), // Tokyo (Shibuya)
                (52.08, 4.31),      // Den Haag
                (52.01, 4.36),      // Delft
                (46.95, 7.44),      // Bern
                (0.0, 179.9),       // just west of the antimeridian: the wrapping cell
                (-16.5, -179.95),   // Fiji, east side
                (12.3, 180.0),
                (89.99, 10.0), // top row (clamped)
                (90.0, -45.0),
                (-90.0, 0.0),
                (0.0, 0.0),
                (27.9881, 86.925), // Everest
            ]);

            let ctx = Context::new().unwrap();
            let op =
                ctx.create(&format!("+proj=vgridshift +grids={} +multiplier=1", path.display())).unwrap();
            let mut x: Vec<f64> = pts.iter().map(|p| p.1.to_radians()).collect();
            let mut y: Vec<f64> = pts.iter().map(|p| p.0.to_radians()).collect();
            let mut z = vec![0.0; pts.len()];
            ctx.trans(&op, false, &mut x, &mut y, &mut z).unwrap();

            let mut max_err_m: f64 = 0.0;
            for (i, &(lat, lon)) in pts.iter().enumerate() {
                let n = geoid.undulation_m(lat, lon);
                let err = (n - z[i]).abs();
                max_err_m = max_err_m.max(err);
                assert!(err < 1e-3, "({lat}, {lon}): insgen {n} m, PROJ {} m", z[i]);
            }
            eprintln!(
                "EGM96 vs PROJ {} vgridshift: {} points, max |ΔN| = {max_err_m:.2e} m",
                crate::geo::pj::proj_version(),
                pts.len()
            );
            // Known magnitudes: Tokyo ≈ 36.7 m, the Netherlands ≈ 43–44 m (h = H + N).
            let tokyo = geoid.undulation_m(35.658, 139.7016);
            let delft = geoid.undulation_m(52.01, 4.36);
            assert!((36.0..38.0).contains(&tokyo), "{tokyo}");
            assert!((42.0..45.0).contains(&delft), "{delft}");
        }
    }
}
