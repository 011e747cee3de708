//! Issue #20 item 4: national geoids — `.gtx` and GeoTIFF grids read by insgen, and PROJ's own
//! compound-CRS path (`[geoid] model = "proj"`) — against pyproj, with no third-party grid shipped.
//!
//! A synthetic undulation field over Japan (N = a + b·lat + c·lon + a Gaussian bump + a short-wave
//! ripple, metres; far from EGM96's ≈ 36.7 m near Tokyo so a wrong geoid shows) is written as a GTX file
//! and as GeoTIFFs in the shapes PROJ-data uses (PixelIsArea or PixelIsPoint, strips or tiles,
//! Deflate with the floating-point predictor, two bands with GDAL_METADATA naming the geoid one,
//! GDAL_NODATA), by a small TIFF writer below.
//!
//! References and tolerances:
//! - insgen's interpolation vs PROJ `vgridshift` through pyproj (`+proj=vgridshift +grids=FILE`):
//!   1 mm (both are bilinear on the same f32 nodes; the differences are f64 rounding, ~1e-12 m);
//! - the compound path: `insgen prepare` of a CityJSON cube in EPSG:6697 with the grid named
//!   `jp_gsi_gsigeo2011.tif` (the file PROJ's database wants for JGD2011 height, in both insgen's PROJ
//!   9.1 and pyproj's 9.5 `proj.db`) in a directory put first in `PROJ_DATA` for the child process
//!   only, vs pyproj `Transformer.from_crs(6697, 4979)` with the same directory: 1 mm in ECEF (the
//!   scene stores f32 ENU positions within ±10 m of the origin, ≈ 1 µm steps);
//! - without the grid: the EGM96 fallback, whose one warning line names the grid PROJ wanted.
//!
//! Measured errors are printed (`cargo test --test it geo_geoid -- --nocapture`).

use std::path::{Path, PathBuf};

use insgen::geo::{self, GeoidGrid};

use crate::geo_pyproj::run_reference_json;
use crate::util;

/// Tolerance vs PROJ/pyproj, metres.
const TOL_M: f64 = 0.001;

/// The grid file PROJ's database names for EPSG:6697 → EPSG:4979 (JGD2011 height, GSIGEO2011).
const GSIGEO_FILE: &str = "jp_gsi_gsigeo2011.tif";

/// The synthetic grid: nodes every `dlat` × `dlon` degrees from (`south`, `west`), south row first.
struct Synth {
    south: f64,
    west: f64,
    dlat: f64,
    dlon: f64,
    rows: usize,
    cols: usize,
    values: Vec<f32>,
}

/// The undulation field, metres (smooth, with a bump near Shibuya and a ripple of ≈ 0.3° wavelength so
/// that bilinear interpolation differs from the field itself).
fn field_m(lat: f64, lon: f64) -> f64 {
    let bump = 2.5 * (-((lat - 35.66).powi(2) + (lon - 139.70).powi(2)) / 0.02).exp();
    25.0 + 0.3 * (lat - 35.0) - 0.2 * (lon - 139.0) + bump + 0.4 * (lat * 20.0).sin() * (lon * 17.0).cos()
}

fn synth() -> Synth {
    // Japan, 0.05° × 0.075° (coarser than GSIGEO2011's 1' × 1.5', the same shape).
    let (south, west, dlat, dlon) = (20.0, 122.0, 0.05, 0.075);
    let (rows, cols) = (521, 427);
    let mut values = Vec::with_capacity(rows * cols);
    for r in 0..rows {
        for c in 0..cols {
            values.push(field_m(south + r as f64 * dlat, west + c as f64 * dlon) as f32);
        }
    }
    Synth { south, west, dlat, dlon, rows, cols, values }
}

fn write_gtx(path: &Path, g: &Synth) {
    let mut b = Vec::new();
    for v in [g.south, g.west, g.dlat, g.dlon] {
        b.extend_from_slice(&v.to_be_bytes());
    }
    b.extend_from_slice(&(g.rows as i32).to_be_bytes());
    b.extend_from_slice(&(g.cols as i32).to_be_bytes());
    for v in &g.values {
        b.extend_from_slice(&v.to_be_bytes());
    }
    std::fs::write(path, b).unwrap();
}

/// How to lay out a GeoTIFF grid.
#[derive(Clone, Copy, Debug)]
struct TiffShape {
    pixel_is_area: bool,
    /// Tile size in pixels, or strips of 16 rows.
    tile: Option<usize>,
    /// Deflate with the floating-point predictor (PROJ-data's choice), else uncompressed.
    deflate_fp: bool,
    /// Band 0 an "accuracy" band, band 1 the geoid (named in GDAL_METADATA).
    two_bands: bool,
    /// Set node (row 3, col 5) to −32768 and declare it GDAL_NODATA.
    nodata: bool,
}

/// Writes a little-endian GeoTIFF, north row first (TIFF's image order).
fn write_tiff(path: &Path, g: &Synth, shape: TiffShape) {
    let spp = if shape.two_bands { 2 } else { 1 };
    let (w, h) = (g.cols, g.rows);
    // Pixel (x, y_tiff) → the samples of node (row h−1−y, col x).
    let sample = |x: usize, y: usize, s: usize| -> f32 {
        let r = h - 1 - y;
        let geoid = if shape.nodata && r == 3 && x == 5 { -32768.0 } else { g.values[r * w + x] };
        match (shape.two_bands, s) {
            (true, 0) => 0.05,
            _ => geoid,
        }
    };
    let (cw, ch) = match shape.tile {
        Some(t) => (t, t),
        None => (w, 16),
    };
    let (nx, ny) = (w.div_ceil(cw), h.div_ceil(ch));
    let mut chunks: Vec<Vec<u8>> = Vec::new();
    for by in 0..ny {
        for bx in 0..nx {
            // Strips cover the last rows only; tiles are always full (padded).
            let rows_here = if shape.tile.is_some() { ch } else { ch.min(h - by * ch) };
            let mut raw = Vec::new();
            for yy in 0..rows_here {
                let mut row: Vec<f32> = Vec::new();
                for xx in 0..cw {
                    let (x, y) = (bx * cw + xx, by * ch + yy);
                    for s in 0..spp {
                        row.push(if x < w && y < h { sample(x, y, s) } else { 0.0 });
                    }
                }
                if shape.deflate_fp {
                    // TIFF Technical Note 3 predictor: bytes of each value big-endian, split into byte
                    // planes, then differenced with a stride of `spp` bytes.
                    let n = row.len();
                    let mut planes = vec![0u8; 4 * n];
                    for (i, v) in row.iter().enumerate() {
                        for (b, byte) in v.to_be_bytes().iter().enumerate() {
                            planes[b * n + i] = *byte;
                        }
                    }
                    for i in (spp..planes.len()).rev() {
                        planes[i] = planes[i].wrapping_sub(planes[i - spp]);
                    }
                    raw.extend_from_slice(&planes);
                } else {
                    for v in row {
                        raw.extend_from_slice(&v.to_le_bytes());
                    }
                }
            }
            if shape.deflate_fp {
                use std::io::Write;
                let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
                z.write_all(&raw).unwrap();
                raw = z.finish().unwrap();
            }
            chunks.push(raw);
        }
    }

    let mut file: Vec<u8> = b"II*\0\0\0\0\0".to_vec();
    let mut offsets = Vec::new();
    for c in &chunks {
        offsets.push(file.len() as u32);
        file.extend_from_slice(c);
        if file.len() % 2 == 1 {
            file.push(0);
        }
    }
    // (tag, type, count, little-endian value bytes)
    let shorts = |v: &[u16]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let longs = |v: &[u32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let doubles = |v: &[f64]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let ascii = |s: &str| {
        let mut b = s.as_bytes().to_vec();
        b.push(0);
        b
    };
    let (half_x, half_y) = if shape.pixel_is_area { (0.5 * g.dlon, 0.5 * g.dlat) } else { (0.0, 0.0) };
    let north = g.south + g.dlat * (h - 1) as f64;
    let mut entries: Vec<(u16, u16, u32, Vec<u8>)> = vec![
        (256, 4, 1, longs(&[w as u32])),
        (257, 4, 1, longs(&[h as u32])),
        (258, 3, spp as u32, shorts(&vec![32; spp])),
        (259, 3, 1, shorts(&[if shape.deflate_fp { 8 } else { 1 }])),
        (262, 3, 1, shorts(&[1])),
        (277, 3, 1, shorts(&[spp as u16])),
        (284, 3, 1, shorts(&[1])),
        (317, 3, 1, shorts(&[if shape.deflate_fp { 3 } else { 1 }])),
        (339, 3, spp as u32, shorts(&vec![3; spp])),
        (33550, 12, 3, doubles(&[g.dlon, g.dlat, 0.0])),
        (33922, 12, 6, doubles(&[0.0, 0.0, 0.0, g.west - half_x, north + half_y, 0.0])),
        (
            34735,
            3,
            16,
            shorts(&[
                1,
                1,
                0,
                3,
                1024,
                0,
                1,
                2,
                1025,
                0,
                1,
                if shape.pixel_is_area { 1 } else { 2 },
                2048,
                0,
                1,
                4326,
            ]),
        ),
    ];
    let counts: Vec<u32> = chunks.iter().map(|c| c.len() as u32).collect();
    match shape.tile {
        Some(t) => {
            entries.push((322, 4, 1, longs(&[t as u32])));
            entries.push((323, 4, 1, longs(&[t as u32])));
            entries.push((324, 4, offsets.len() as u32, longs(&offsets)));
            entries.push((325, 4, counts.len() as u32, longs(&counts)));
        }
        None => {
            entries.push((273, 4, offsets.len() as u32, longs(&offsets)));
            entries.push((278, 4, 1, longs(&[ch as u32])));
            entries.push((279, 4, counts.len() as u32, longs(&counts)));
        }
    }
    if shape.two_bands {
        let md = "<GDALMetadata><Item name=\"grid_name\">synthetic</Item>\
                  <Item name=\"DESCRIPTION\" sample=\"0\" role=\"description\">geoid_undulation_accuracy</Item>\
                  <Item name=\"DESCRIPTION\" sample=\"1\" role=\"description\">geoid_undulation</Item>\
                  <Item name=\"UNITTYPE\" sample=\"1\" role=\"unittype\">metre</Item></GDALMetadata>";
        let b = ascii(md);
        entries.push((42112, 2, b.len() as u32, b));
    }
    if shape.nodata {
        let b = ascii("-32768");
        entries.push((42113, 2, b.len() as u32, b));
    }
    entries.sort_by_key(|e| e.0);
    // Values longer than 4 bytes go before the IFD.
    let mut value_fields = Vec::new();
    for e in &entries {
        if e.3.len() > 4 {
            value_fields.push(Some(file.len() as u32));
            file.extend_from_slice(&e.3);
            if file.len() % 2 == 1 {
                file.push(0);
            }
        } else {
            value_fields.push(None);
        }
    }
    let ifd = file.len() as u32;
    file[4..8].copy_from_slice(&ifd.to_le_bytes());
    file.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    for (e, at) in entries.iter().zip(&value_fields) {
        file.extend_from_slice(&e.0.to_le_bytes());
        file.extend_from_slice(&e.1.to_le_bytes());
        file.extend_from_slice(&e.2.to_le_bytes());
        match at {
            Some(o) => file.extend_from_slice(&o.to_le_bytes()),
            None => {
                let mut v = e.3.clone();
                v.resize(4, 0);
                file.extend_from_slice(&v);
            }
        }
    }
    file.extend_from_slice(&0u32.to_le_bytes());
    std::fs::write(path, file).unwrap();
}

/// Points inside the grid: a seeded scatter, every node of a patch, points a hair inside and outside
/// node lines (cell edges), cell centres, and the nodata neighbourhood.
fn probe_points(g: &Synth) -> Vec<[f64; 2]> {
    let mut pts = Vec::new();
    let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let north = g.south + g.dlat * (g.rows - 1) as f64;
    let east = g.west + g.dlon * (g.cols - 1) as f64;
    for _ in 0..300 {
        pts.push([g.south + rnd() * (north - g.south), g.west + rnd() * (east - g.west)]);
    }
    for r in 300..304 {
        for c in 250..254 {
            let (lat, lon) = (g.south + r as f64 * g.dlat, g.west + c as f64 * g.dlon);
            // Fractions of a cell: on the node, a hair either side of its row and column lines, the centre.
            for (fl, fn_) in [(0.0, 0.0), (1e-7, 0.0), (-1e-7, 0.0), (0.0, 1e-7), (0.0, -1e-7), (0.5, 0.5)] {
                pts.push([lat + fl * g.dlat, lon + fn_ * g.dlon]);
            }
        }
    }
    // (Not the nodata node itself: there every remaining weight is ~0 and the result is rounding noise.)
    for (r, c) in [(3.5, 5.5), (2.5, 4.5), (3.0, 5.5), (2.9, 5.0)] {
        pts.push([g.south + r * g.dlat, g.west + c * g.dlon]);
    }
    // Tokyo (Shibuya), Osaka, the grid's corners.
    pts.extend([[35.658, 139.7016], [34.69, 135.50], [g.south, g.west], [north, east]]);
    pts
}

const SHAPES: [TiffShape; 4] = [
    TiffShape { pixel_is_area: true, tile: None, deflate_fp: true, two_bands: false, nodata: true },
    TiffShape { pixel_is_area: false, tile: None, deflate_fp: false, two_bands: false, nodata: false },
    TiffShape { pixel_is_area: true, tile: Some(256), deflate_fp: true, two_bands: true, nodata: true },
    TiffShape { pixel_is_area: false, tile: Some(64), deflate_fp: false, two_bands: true, nodata: false },
];

#[test]
fn gtx_and_geotiff_grids_agree_with_pyproj_vgridshift() {
    let dir = tempfile::tempdir().unwrap();
    let g = synth();
    let mut files: Vec<(PathBuf, String)> = Vec::new();
    let gtx = dir.path().join("synthetic.gtx");
    write_gtx(&gtx, &g);
    files.push((gtx, "gtx".into()));
    for (i, shape) in SHAPES.iter().enumerate() {
        let p = dir.path().join(format!("synthetic_{i}.tif"));
        write_tiff(&p, &g, *shape);
        files.push((p, format!("{shape:?}")));
    }
    let pts = probe_points(&g);

    // Without Python: every GeoTIFF layout reads to the GTX's values (but for the nodata node).
    let gtx_grid = GeoidGrid::load(&files[0].0).expect("GTX loads");
    for (p, label) in &files[1..] {
        let grid = GeoidGrid::load(p).unwrap_or_else(|e| panic!("{label}: {e}"));
        assert_eq!(grid.size(), (g.rows, g.cols), "{label}");
        for e in grid.extent_deg().iter().zip(gtx_grid.extent_deg()) {
            assert!((e.0 - e.1).abs() < 1e-9, "{label}: extent {:?}", grid.extent_deg());
        }
        for &[lat, lon] in pts.iter().filter(|p| p[0] > 21.0) {
            let (a, b) = (grid.undulation_m(lat, lon).unwrap(), gtx_grid.undulation_m(lat, lon).unwrap());
            assert!((a - b).abs() < 1e-9, "{label} ({lat}, {lon}): {a} vs {b}");
        }
    }

    let Some(py) = util::python_with(&["pyproj"]) else { return };
    let request = serde_json::json!({
        "geoids": files.iter().map(|(p, _)| serde_json::json!({"grid": p, "points": pts})).collect::<Vec<_>>(),
    });
    let answer = run_reference_json(&py, &request);
    let refs = answer["geoids"].as_array().expect("geoids answer");
    assert_eq!(refs.len(), files.len());
    for ((p, label), r) in files.iter().zip(refs) {
        let grid = GeoidGrid::load(p).unwrap();
        let want: Vec<f64> = serde_json::from_value(r["undulation_m"].clone()).unwrap();
        let mut max_err: f64 = 0.0;
        for (&[lat, lon], &n_ref) in pts.iter().zip(&want) {
            let n = grid.undulation_m(lat, lon).unwrap_or_else(|e| panic!("{label}: {e}"));
            let err = (n - n_ref).abs();
            max_err = max_err.max(err);
            assert!(err < TOL_M, "{label} ({lat}, {lon}): insgen {n} m, pyproj vgridshift {n_ref} m");
        }
        println!(
            "{} {label}: {} points vs pyproj {} vgridshift, max |ΔN| = {max_err:.3e} m",
            p.file_name().unwrap().to_string_lossy(),
            pts.len(),
            answer["proj_version"]
        );
    }
}

#[test]
fn unreadable_geotiffs_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let g = synth();
    let good = dir.path().join("good.tif");
    write_tiff(&good, &g, SHAPES[1]);
    let bytes = std::fs::read(&good).unwrap();
    let find = |needle: &[u8]| bytes.windows(needle.len()).position(|w| w == needle).expect("tag present");
    let patch = |at: usize, with: &[u8]| {
        let mut b = bytes.clone();
        b[at..at + with.len()].copy_from_slice(with);
        b
    };
    // GTModelTypeGeoKey = 2 (geographic) → 1 (projected): key 1024, 0, 1, value.
    let model_key = find(&[0x00, 0x04, 0, 0, 1, 0, 2, 0]);
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (patch(model_key + 6, &[1, 0]), "projected CRS"),
        (bytes[..bytes.len() / 3].to_vec(), "TIFF"),
        (b"II*\0garbage".to_vec(), "not a readable TIFF"),
    ];
    for (b, want) in cases {
        let p = dir.path().join("bad.tif");
        std::fs::write(&p, b).unwrap();
        let e = util::error_chain(&GeoidGrid::load(&p).unwrap_err());
        assert!(e.contains("bad.tif") && e.contains(want), "{e} (wanted {want:?})");
    }
    let p = dir.path().join("text.tif");
    std::fs::write(&p, "not a grid").unwrap();
    let e = GeoidGrid::load(&p).unwrap_err().to_string();
    assert!(e.contains("text.tif") && e.contains("neither a GTX grid"), "{e}");
}

/// A CityJSON cube (10 m × 10 m × 12 m) in EPSG:6697 (JGD2011 + JGD2011 height: lon, lat, H in
/// CityJSON's east/north order) at `lon`, `lat` with its base at H = 40 m.
fn cube_6697(lon: f64, lat: f64) -> (String, Vec<[f64; 3]>) {
    let (dlon, dlat) = (10.0 / 90_500.0, 10.0 / 111_000.0);
    let mut v = Vec::new();
    for z in [40.0, 52.0] {
        v.extend([[lon, lat, z], [lon + dlon, lat, z], [lon + dlon, lat + dlat, z], [lon, lat + dlat, z]]);
    }
    let json = serde_json::json!({
        "type": "CityJSON", "version": "2.0",
        "metadata": {"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/6697"},
        "CityObjects": {"cube": {"type": "Building", "geometry": [{"type": "Solid", "lod": "2", "boundaries": [[
            [[0, 3, 2, 1]], [[4, 5, 6, 7]], [[0, 1, 5, 4]], [[1, 2, 6, 5]], [[2, 3, 7, 6]], [[3, 0, 4, 7]]]]}]}},
        "vertices": v,
    });
    (json.to_string(), v)
}

/// `PROJ_DATA` for the child: `first`, then the directories the linked PROJ searches (proj.db).
fn proj_data_with(first: &Path) -> String {
    let mut dirs = vec![first.display().to_string()];
    dirs.extend(geo::crs::proj_search_paths().into_iter().filter(|d| Path::new(d).join("proj.db").is_file()));
    dirs.join(":")
}

/// Runs `insgen prepare` of a one-cube scene in EPSG:6697 with `[geoid] model = "proj"` and the given
/// PROJ_DATA; returns the scratch dir (kept alive), the cube's source vertices and the output.
fn prepare_proj_scene(
    proj_data: &str,
    sources: usize,
) -> (tempfile::TempDir, Vec<[f64; 3]>, std::process::Output) {
    let dir = tempfile::tempdir().unwrap();
    let mut scene = String::from("name = \"jp\"\n");
    let mut verts = Vec::new();
    for i in 0..sources {
        let (json, v) = cube_6697(139.7016 + 0.001 * i as f64, 35.658);
        let p = dir.path().join(format!("cube{i}.city.json"));
        std::fs::write(&p, json).unwrap();
        scene.push_str(&format!("\n[[sources]]\npath = \"{}\"\n", p.display()));
        verts.extend(v);
    }
    scene.push_str("\n[geoid]\nmodel = \"proj\"\n");
    std::fs::create_dir_all(dir.path().join("scenes")).unwrap();
    std::fs::write(dir.path().join("scenes/jp.toml"), scene).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_insgen"))
        .args(["--workdir", "runs", "--no-progress", "prepare", "--area", "jp"])
        .current_dir(dir.path())
        .env("RUST_LOG", "warn")
        .env("PROJ_DATA", proj_data)
        .env_remove("PROJ_LIB")
        .output()
        .expect("the insgen binary runs");
    (dir, verts, out)
}

fn grid_installed_system_wide() -> bool {
    geo::crs::proj_search_paths().iter().any(|d| Path::new(d).join(GSIGEO_FILE).is_file())
}

#[test]
fn compound_crs_heights_through_proj_with_a_national_grid_agree_with_pyproj() {
    let Some(py) = util::python_with(&["pyproj"]) else { return };
    let grids = tempfile::tempdir().unwrap();
    let g = synth();
    let grid_path = grids.path().join(GSIGEO_FILE);
    write_tiff(&grid_path, &g, SHAPES[0]);
    let (dir, verts, out) = prepare_proj_scene(&proj_data_with(grids.path()), 1);
    assert!(out.status.success(), "prepare failed:\n{}", util::stderr(&out));
    assert!(!util::stderr(&out).contains("national geoids differ"), "{}", util::stderr(&out));

    let scene = insgen::scene::PreparedScene::load(&dir.path().join("runs/jp/scene")).unwrap();
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("runs/jp/scene/manifest.json")).unwrap())
            .unwrap();
    util::assert_schema("manifest.schema.json", &manifest);
    let m = &scene.manifest;
    assert_eq!(m.geoid.model, "proj");
    assert!(m.geoid.proj_grids.iter().any(|p| p.ends_with(GSIGEO_FILE)), "{:?}", m.geoid);
    assert!(m.geoid.missing_grids.is_empty(), "{:?}", m.geoid);
    let op = m.geoid.proj_operation.clone().unwrap_or_default();
    assert!(!op.contains("ballpark vertical"), "{op}");
    assert!(m.sources[0].crs_chain.contains("PROJ:"), "{}", m.sources[0].crs_chain);
    // N at the origin equals the synthetic grid interpolated there (insgen's own GeoTIFF reader).
    let n_origin =
        GeoidGrid::load(&grid_path).unwrap().undulation_m(m.origin.lat_deg, m.origin.lon_deg).unwrap();
    assert!(
        (m.geoid.undulation_at_origin_m - n_origin).abs() < TOL_M,
        "{} vs {n_origin}",
        m.geoid.undulation_at_origin_m
    );
    assert!((n_origin - 36.7).abs() > 3.0, "the synthetic geoid must differ from EGM96 here: {n_origin}");

    let request = serde_json::json!({
        "extra_data_dirs": [grids.path()],
        "compound": {"code": 6697, "points": verts},
    });
    let answer = run_reference_json(&py, &request);
    let c = &answer["compound"];
    let pyproj_grids: Vec<String> = serde_json::from_value(c["grids"].clone()).unwrap();
    assert!(
        pyproj_grids.iter().any(|p| p.ends_with(GSIGEO_FILE)),
        "pyproj used {pyproj_grids:?}: {}",
        c["operation"]
    );
    let ref_ecef: Vec<[f64; 3]> = c["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| serde_json::from_value(p["ecef_m"].clone()).unwrap())
        .collect();

    // Every scene vertex (f32 ENU → ECEF) against its nearest pyproj vertex.
    let ecef_from_enu = m.ecef_from_enu;
    let mut max_err: f64 = 0.0;
    for p in &scene.mesh.positions_m {
        let q = ecef_from_enu.transform_point3(glam::DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64));
        let d = ref_ecef.iter().map(|r| (glam::DVec3::from(*r) - q).length()).fold(f64::INFINITY, f64::min);
        max_err = max_err.max(d);
    }
    println!(
        "EPSG:6697 heights via PROJ {} + synthetic {GSIGEO_FILE} vs pyproj (PROJ {}): {} vertices, max |ΔECEF| = \
         {max_err:.3e} m; operation: {op}",
        geo::proj_version(),
        answer["proj_version"],
        scene.mesh.positions_m.len()
    );
    assert!(max_err < TOL_M, "max |ΔECEF| {max_err} m");
}

#[test]
fn compound_crs_without_the_grid_falls_back_to_egm96_with_one_warning() {
    if grid_installed_system_wide() {
        util::skip(&format!(
            "{GSIGEO_FILE} is installed in PROJ's search path; the fallback cannot be tested"
        ));
        return;
    }
    let empty = tempfile::tempdir().unwrap();
    // Two sources in the same CRS: still one warning.
    let (dir, _, out) = prepare_proj_scene(&proj_data_with(empty.path()), 2);
    let err = util::stderr(&out);
    assert!(out.status.success(), "prepare failed:\n{err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.contains("national geoids differ")).collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].contains(GSIGEO_FILE) && lines[0].contains("EGM96"), "{}", lines[0]);
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("runs/jp/scene/manifest.json")).unwrap())
            .unwrap();
    util::assert_schema("manifest.schema.json", &manifest);
    assert_eq!(manifest["geoid"]["model"], "egm96", "{manifest}");
    assert_eq!(manifest["geoid"]["missing_grids"], serde_json::json!([GSIGEO_FILE]), "{manifest}");
    let n = manifest["geoid"]["undulation_at_origin_m"].as_f64().unwrap();
    assert!((36.0..38.0).contains(&n), "EGM96 near Tokyo is ≈ 36.7 m: {n}");
}
