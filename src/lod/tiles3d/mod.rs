//! 3D Tiles 1.0/1.1 reader: a `tileset.json` (or one `.b3dm`/`.glb` content) → buildings in ECEF.
//!
//! Pipeline: [`tileset`] reads and validates tileset JSON into a [`Tile`] tree (transforms,
//! bounding volumes, ADD/REPLACE, external tilesets, [`implicit`] tiling, gzip) and lists the
//! contents to read; [`content`] decodes each one — [`b3dm`] containers (feature and batch tables,
//! `RTC_CENTER`), cmpt composites, GLB/glTF via [`gltf`] (node transforms, `CESIUM_RTC`, y-up →
//! z-up, [`draco`] for `KHR_draco_mesh_compression`, [`meshopt`] for `EXT_meshopt_compression`,
//! `KHR_mesh_quantization`, `EXT_mesh_features` and [`metadata`] for `EXT_structural_metadata`) —
//! and groups triangles per feature. Contents are decoded in parallel and assembled in traversal
//! order, so the output does not depend on thread timing. [`plain`] turns one content into a GLB
//! without required extensions (textures and UVs included) for Blender (tilesets are written by
//! `crate::export`). The Blender stage (`blender::tileset`) uses [`Tileset`]
//! for its per-frame tile selection: this module is the one reader of 3D Tiles in insgen.
//!
//! # Errors
//! Decoders return a [`ContentError`] saying what is wrong where inside the file (a JSON path such
//! as `meshes[0].primitives[1].attributes["POSITION"]`, byte counts, the refused extension), with
//! the JSON, I/O, gzip, Draco, meshopt or WebP error as its source ([`error`]); the tileset reader
//! wraps it with the file and tile ([`LodError::Tile`], [`LodError::Tiles3d`],
//! [`LodError::Subtree`]).
//!
//! # Buildings
//! One [`SourceBuilding`] per feature: the feature ID (`_BATCHID`, or `_FEATURE_ID_n` of
//! `EXT_mesh_features`) selects a row of the batch/property table whose `gml_id` (see
//! [`features::ID_PROPERTIES`]) is the building's `source_id`. Features with the same id in several
//! contents are merged into one building. LoD comes from `_lod`/`lod` (else `"unknown"`), the
//! measured height from `bldg:measuredHeight`/`measuredHeight`/`height`. A feature without an id gets
//! `"<content>#batch<N>"`; geometry without feature IDs is split into connected components
//! ([`crate::lod::split::split_connected`], honouring [`ReadOptions::weld_tolerance_m`]) with ids
//! `"<content>#cc<N>"`, where `<content>` is the content's path relative to the root tileset.
//! Components are found per content, so an ID-less mesh cut by tile boundaries stays cut there.
//! [`ReadOptions::lod`] is ignored: a tileset holds one geometry per feature.
//!
//! # Frame
//! Positions are ECEF metres ([`Frame::Ecef`]): for a vertex `p` of a node with global matrix `N`,
//! `tile transforms · RTC_CENTER · CESIUM_RTC · (y-up → z-up) · N · p`, all in f64. A `.b3dm`/`.glb`
//! read on its own has an identity tile transform.
//!
//! i3dm and pnts contents (instanced models, point clouds) are skipped and counted in
//! [`TilesReport::unsupported_contents`].

pub(crate) mod b3dm;
pub(crate) mod content;
pub(crate) mod draco;
pub mod error;
pub mod features;
pub mod gltf;
pub(crate) mod implicit;
pub(crate) mod meshopt;
pub(crate) mod metadata;
pub mod plain;
pub mod tileset;

pub use error::{
    AccessorProblem, ContentError, DracoMeshError, GltfIssue, GltfProblem, MeshoptError, UriError, WebpError,
};
pub use gltf::UpAxis;
pub use tileset::{BoundingVolume, ContentRef, Refine, Tile, Tileset};

use std::collections::BTreeMap;
use std::path::Path;

use glam::DMat4;
use rayon::prelude::*;

use super::split::split_connected;
use super::{Frame, Geometry, LodError, ReadOptions, ReadStats, SourceBuilding, SourceModel};
use content::append;
use tileset::ContentJob;

/// Most features one batch or property table may list (a building id is 24 bits wide anyway); a
/// larger count is taken as a corrupt header rather than allocated.
pub(crate) const MAX_FEATURES: usize = 1 << 24;

/// Largest decompressed size of one gzip-compressed tile content or tileset JSON, bytes (a guard
/// against decompression bombs; real tiles are a few MB).
pub const MAX_GUNZIPPED_BYTES: u64 = 1 << 30;

/// The bytes themselves, or their gunzipped form when they start with the gzip magic (`1f 8b`):
/// some servers and exporters store tile contents and tileset JSON gzip-compressed.
///
/// # Errors
/// [`ContentError::Gunzip`] when the gzip stream is corrupt, [`ContentError::GunzipTooLarge`] when it
/// inflates past [`MAX_GUNZIPPED_BYTES`].
pub(crate) fn maybe_gunzip(bytes: &[u8]) -> Result<std::borrow::Cow<'_, [u8]>, ContentError> {
    use std::io::Read;
    if !bytes.starts_with(&[0x1f, 0x8b]) {
        return Ok(std::borrow::Cow::Borrowed(bytes));
    }
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(bytes)
        .take(MAX_GUNZIPPED_BYTES + 1)
        .read_to_end(&mut out)
        .map_err(ContentError::Gunzip)?;
    if out.len() as u64 > MAX_GUNZIPPED_BYTES {
        return Err(ContentError::GunzipTooLarge { limit: MAX_GUNZIPPED_BYTES });
    }
    Ok(std::borrow::Cow::Owned(out))
}

/// What a tileset read did besides producing buildings (logged by [`read`]).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct TilesReport {
    /// Tileset JSON files read (the root and any external tilesets).
    pub tilesets_read: u64,
    /// Tile contents decoded (cmpt inner tiles counted individually).
    pub contents_read: u64,
    /// Contents of REPLACE tiles with children, superseded by their children and not read.
    pub contents_refined_away: u64,
    /// i3dm/pnts contents skipped.
    pub unsupported_contents: u64,
    /// glTF primitives skipped because they are points or lines.
    pub skipped_primitives: u64,
    /// Triangles whose three vertices carry different feature IDs (assigned by the first vertex).
    pub mixed_feature_triangles: u64,
    /// Triangles on the `nullFeatureId` of `EXT_mesh_features` (dropped).
    pub null_feature_triangles: u64,
    /// Features whose id had already been seen in an earlier content and were merged into it.
    pub merged_features: u64,
    /// Buildings obtained by splitting ID-less geometry into connected components.
    pub connected_component_buildings: u64,
}

/// Reads a tileset (`tileset.json`, following external tilesets) or a single `.b3dm`/`.glb`/`.cmpt`
/// content into buildings in ECEF (see the module docs); the [`TilesReport`] is logged.
///
/// # Errors
/// [`LodError`] naming the tileset or content file and what is wrong: [`LodError::Tile`] (tileset,
/// tile, URI and content file) or [`LodError::Tiles3d`] (a content read on its own) around the
/// [`ContentError`]; nothing is returned when any content fails.
pub fn read(path: &Path, opts: &ReadOptions) -> Result<SourceModel, LodError> {
    let (model, report) = read_with_report(path, opts)?;
    log::info!(
        "{}: {} buildings from {} contents ({} tileset files, {} refined-away contents skipped)",
        path.display(),
        model.buildings.len(),
        report.contents_read,
        report.tilesets_read,
        report.contents_refined_away
    );
    if report.mixed_feature_triangles > 0 {
        log::warn!(
            "{}: {} triangles have vertices of different features; each was given to its first vertex's",
            path.display(),
            report.mixed_feature_triangles
        );
    }
    if report.unsupported_contents > 0 {
        log::warn!("{}: skipped {} i3dm/pnts contents", path.display(), report.unsupported_contents);
    }
    Ok(model)
}

/// A SHA-256 (hex) naming a tileset as insgen reads it, for the fingerprints of outputs made from it
/// (occlusion-aware masks, `align` records): the bytes of every tileset JSON that references a content
/// insgen reads, then each such content's path (relative to the root tileset's folder) and byte size,
/// in traversal order. No content is read, so it stays cheap on large tilesets; a tile replaced by
/// another of exactly the same size goes unnoticed. A single content file (`.b3dm`, `.glb`, …) is
/// hashed whole.
///
/// # Errors
/// As the traversal of [`read`]: the tileset (or an external one) is unreadable or invalid, or a
/// content file is missing ([`LodError`] naming it).
pub fn fingerprint(path: &Path) -> Result<String, LodError> {
    use sha2::{Digest, Sha256};
    if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")) {
        return crate::util::sha256_file(path).map_err(LodError::from);
    }
    let t = tileset::traverse(path)?;
    let mut h = Sha256::new();
    let mut jsons: Vec<&Path> = vec![path];
    for job in &t.jobs {
        if let Some(by) = &job.referenced_by {
            if !jsons.contains(&by.tileset.as_path()) {
                jsons.push(&by.tileset);
            }
        }
    }
    for json in jsons {
        h.update(crate::util::read_file(json)?);
    }
    for job in &t.jobs {
        let size = std::fs::metadata(&job.file)
            .map_err(|e| LodError::File(crate::util::FileError::new("reading the size of", &job.file, e)))?
            .len();
        h.update(format!("{}\0{size}\n", job.label).as_bytes());
    }
    Ok(hex::encode(h.finalize()))
}

/// As [`read`], also returning the [`TilesReport`].
///
/// # Errors
/// As [`read`].
pub fn read_with_report(path: &Path, opts: &ReadOptions) -> Result<(SourceModel, TilesReport), LodError> {
    opts.check_weld_tolerance(path)?;
    let mut report = TilesReport::default();
    let jobs = content_jobs(path, &mut report)?;
    // Decode in parallel; keep traversal order and report the first failure in that order.
    let decoded: Vec<Result<content::DecodedContent, LodError>> = jobs
        .par_iter()
        .map(|job| {
            let bytes = crate::util::read_file(&job.file)?;
            maybe_gunzip(&bytes)
                .and_then(|bytes| content::decode(&bytes, &job.file, &job.label, job.world_from_tile, job.up))
                .map_err(|e| job.error(e))
        })
        .collect();
    let mut set = BuildingSet::default();
    let mut counters = content::Counters::default();
    for (job, result) in jobs.iter().zip(decoded) {
        let c = result?;
        counters.add(&c.counters);
        for f in c.features {
            set.add_feature(f, &mut report);
        }
        if !c.idless.triangles.is_empty() {
            for (n, part) in split_connected(&c.idless, opts.weld_tolerance_m).into_iter().enumerate() {
                report.connected_component_buildings += 1;
                set.add_component(format!("{}#cc{n}", job.label), part);
            }
        }
    }
    report.contents_read = counters.contents_read;
    report.unsupported_contents = counters.unsupported_contents;
    report.skipped_primitives = counters.skipped_primitives;
    report.mixed_feature_triangles = counters.mixed_feature_triangles;
    report.null_feature_triangles = counters.null_feature_triangles;
    let stats = ReadStats {
        buildings_without_geometry: counters.features_without_geometry,
        degenerate_faces: counters.degenerate_triangles,
        faces: counters.triangles,
        ..Default::default()
    };
    let model = SourceModel {
        path: path.to_path_buf(),
        frame: Frame::Ecef,
        buildings: set.buildings,
        stats,
        appearance: Default::default(),
    };
    Ok((model, report))
}

/// The contents to read: those a tileset JSON references (traversed, with its counts added to
/// `report`), or the one content file `path`.
fn content_jobs(path: &Path, report: &mut TilesReport) -> Result<Vec<ContentJob>, LodError> {
    let is_json = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("json"));
    if is_json {
        let t = tileset::traverse(path)?;
        report.tilesets_read = t.tilesets_read;
        report.contents_refined_away = t.contents_skipped;
        return Ok(t.jobs);
    }
    let label = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    Ok(vec![ContentJob {
        file: path.to_path_buf(),
        label,
        referenced_by: None,
        world_from_tile: DMat4::IDENTITY,
        up: gltf::UpAxis::Y,
    }])
}

/// The buildings assembled so far, with the index of each source id (features with the same id in
/// several contents are merged).
#[derive(Default)]
struct BuildingSet {
    buildings: Vec<SourceBuilding>,
    index_of: BTreeMap<String, usize>,
}

impl BuildingSet {
    /// Adds a feature as a new building, or merges it into the building with its id (its mesh
    /// appended, a missing LoD or measured height filled in).
    fn add_feature(&mut self, f: content::DecodedFeature, report: &mut TilesReport) {
        match self.index_of.get(&f.source_id) {
            Some(&k) => {
                report.merged_features += 1;
                let b = &mut self.buildings[k];
                if b.lod == "unknown" {
                    if let Some(lod) = f.lod {
                        b.lod = lod;
                    }
                }
                b.measured_height_m = b.measured_height_m.or(f.measured_height_m);
                if let Geometry::Mesh(m) = &mut b.geometry {
                    append(m, &f.mesh);
                }
            }
            None => {
                self.index_of.insert(f.source_id.clone(), self.buildings.len());
                self.buildings.push(SourceBuilding {
                    source_id: f.source_id,
                    lod: f.lod.unwrap_or_else(|| "unknown".to_string()),
                    measured_height_m: f.measured_height_m,
                    ground_heights_m: Vec::new(),
                    geometry: Geometry::Mesh(f.mesh),
                    appearance: Vec::new(),
                });
            }
        }
    }

    /// Adds a connected component of ID-less geometry as building `id`.
    fn add_component(&mut self, id: String, mesh: super::TriMesh) {
        self.index_of.insert(id.clone(), self.buildings.len());
        self.buildings.push(SourceBuilding {
            source_id: id,
            lod: "unknown".to_string(),
            measured_height_m: None,
            ground_heights_m: Vec::new(),
            geometry: Geometry::Mesh(mesh),
            appearance: Vec::new(),
        });
    }
}

#[cfg(test)]
mod fingerprint_tests {
    use super::*;

    fn write(dir: &Path, name: &str, bytes: &[u8]) {
        std::fs::write(dir.join(name), bytes).unwrap();
    }

    /// A root tileset with one content and an external tileset with another, contents not decodable
    /// (the fingerprint never reads them).
    fn tileset(dir: &Path) -> std::path::PathBuf {
        let tile = |uri: &str| {
            format!(
                r#"{{"asset":{{"version":"1.1"}},"geometricError":10,"root":{{"boundingVolume":{{"sphere":[0,0,0,100]}},
                "geometricError":0,"refine":"ADD","content":{{"uri":"{uri}"}},"children":[]}}}}"#
            )
        };
        write(dir, "sub.json", tile("b.glb").as_bytes());
        let root = r#"{"asset":{"version":"1.1"},"geometricError":10,"root":{"boundingVolume":{"sphere":[0,0,0,100]},
            "geometricError":5,"refine":"ADD","content":{"uri":"a.b3dm"},
            "children":[{"boundingVolume":{"sphere":[0,0,0,50]},"geometricError":0,"content":{"uri":"sub.json"}}]}}"#;
        write(dir, "tileset.json", root.as_bytes());
        write(dir, "a.b3dm", b"b3dm-not-decoded");
        write(dir, "b.glb", b"glTF-not-decoded");
        dir.join("tileset.json")
    }

    #[test]
    fn fingerprint_follows_the_jsons_and_the_contents_names_and_sizes() {
        let d = tempfile::tempdir().unwrap();
        let path = tileset(d.path());
        let base = fingerprint(&path).unwrap();
        assert_eq!(base.len(), 64);
        assert_eq!(fingerprint(&path).unwrap(), base, "same files, same fingerprint");
        // Same size, other bytes: not seen (documented limit).
        write(d.path(), "b.glb", b"glTF-NOT-decoded");
        assert_eq!(fingerprint(&path).unwrap(), base);
        // A content of another size, inside the external tileset.
        write(d.path(), "b.glb", b"glTF-not-decoded, longer");
        let changed = fingerprint(&path).unwrap();
        assert_ne!(changed, base);
        // The external tileset's JSON itself.
        let sub = std::fs::read_to_string(d.path().join("sub.json")).unwrap();
        write(d.path(), "sub.json", sub.replace("\"geometricError\":0", "\"geometricError\":0.5").as_bytes());
        assert_ne!(fingerprint(&path).unwrap(), changed);
        // A missing content is an error naming it.
        std::fs::remove_file(d.path().join("a.b3dm")).unwrap();
        let e = crate::util::error_chain(&fingerprint(&path).unwrap_err());
        assert!(e.contains("a.b3dm"), "{e}");
    }
}
