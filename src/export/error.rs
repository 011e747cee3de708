//! Errors of the COCO stage. Every variant names the file concerned; causes stay in `#[source]`.

use std::path::PathBuf;

/// The cause chain on one line (one helper for the whole crate).
pub(crate) use crate::util::error_chain as chain_string;
use crate::util::FileError;

use super::rle::RleError;

/// What can go wrong while exporting, reading or summarising COCO files.
#[derive(Debug, thiserror::Error)]
pub enum CocoError {
    /// Reading, writing or listing a file failed.
    #[error(transparent)]
    File(#[from] FileError),
    /// A JSON file does not parse into the expected structure.
    #[error("{}: invalid JSON{}", path.display(), line.map(|l| format!(" at line {l}")).unwrap_or_default())]
    Json {
        path: PathBuf,
        /// 1-based line of a JSON-lines file, when the file is one.
        line: Option<usize>,
        #[source]
        source: serde_json::Error,
    },
    /// A PNG could not be decoded.
    #[error("{}: cannot decode PNG", path.display())]
    PngDecode {
        path: PathBuf,
        #[source]
        source: png::DecodingError,
    },
    /// A PNG could not be encoded.
    #[error("{}: cannot encode PNG", path.display())]
    PngEncode {
        path: PathBuf,
        #[source]
        source: png::EncodingError,
    },
    /// Stopped by Ctrl-C; nothing was written.
    #[error(transparent)]
    Interrupted(#[from] crate::util::interrupt::Interrupted),
    /// A pose file cannot be read.
    #[error(transparent)]
    Poses(#[from] crate::camera::CameraError),
    /// An instance-ID map cannot be read.
    #[error(transparent)]
    Ids(#[from] crate::scene::IdError),
    /// An image is not of a kind this stage reads.
    #[error("{}: {reason}", path.display())]
    Image { path: PathBuf, reason: String },
    /// The components recomputed from an ID map disagree with its `<frame>.instances.json`.
    #[error("{}: does not match its ID map {}: {reason}", instances.display(), id_map.display())]
    Mismatch { instances: PathBuf, id_map: PathBuf, reason: String },
    /// The working directory does not have the layout the export expects.
    #[error("{}: {reason}", path.display())]
    Layout { path: PathBuf, reason: String },
    /// A file has the right syntax but wrong content; each problem carries its JSON path.
    #[error("{}: {} problem(s):\n  {}", path.display(), problems.len(), problems.join("\n  "))]
    Invalid { path: PathBuf, problems: Vec<String> },
    /// An RLE could not be built or parsed.
    #[error("{}: {context}", path.display())]
    Rle {
        path: PathBuf,
        /// Where in the file (JSON path or frame) the RLE comes from.
        context: String,
        #[source]
        source: RleError,
    },
    /// The export would list no image at all; nothing was written. Names the command that fills the gap.
    #[error("{}: the export would list no image, so nothing was written: {}", workdir.display(), gap.advice())]
    EmptyExport { workdir: PathBuf, gap: EmptyGap },
    /// `--holdout` names an area that is not in the working directory.
    #[error("--holdout {area}: no such area under {}; areas found: {}", workdir.display(), available.join(", "))]
    UnknownHoldout { area: String, workdir: PathBuf, available: Vec<String> },
    /// Some frames failed; nothing was written. The first failure is the source, the others are listed.
    #[error(
        "{failed} of {total} frames could not be exported, so nothing was written{}\nfirst failure",
        list_others(others)
    )]
    Frames {
        failed: usize,
        total: usize,
        #[source]
        first: Box<CocoError>,
        /// The other failures, each with its cause chain.
        others: Vec<String>,
    },
    /// The parts shards wrote of an export do not make one export (missing or foreign parts).
    #[error("{}: {reason}", dir.display())]
    Parts { dir: PathBuf, reason: String },
    /// A filter needs data the instance files do not have.
    #[error("{}: {reason}", path.display())]
    MissingData { path: PathBuf, reason: String },
}

impl CocoError {
    pub(crate) fn json(path: &std::path::Path, source: serde_json::Error) -> Self {
        CocoError::Json { path: path.to_path_buf(), line: None, source }
    }
}

fn list_others(others: &[String]) -> String {
    const SHOWN: usize = 20;
    let mut s: String = others.iter().take(SHOWN).map(|o| format!("\n  - {o}")).collect();
    if others.len() > SHOWN {
        s.push_str(&format!("\n  - … and {} more", others.len() - SHOWN));
    }
    if !s.is_empty() {
        s.insert_str(0, "; other failures:");
    }
    s
}

/// Why an export came out empty, most actionable first.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EmptyGap {
    /// Labelled frames have no RGB frame yet (the first camera without them).
    NoRgb { area: String, camera: String, frames: u64 },
    /// Posed frames have no ID map yet.
    NoMasks { frames: u64 },
    /// Frames exist but the filters dropped every image: this many scored below `--min-consistency`,
    /// this many had no annotation left (and empty images are dropped).
    Filtered { low_consistency_images: u64, empty_images: u64 },
    /// No area holds a posed frame.
    NoFrames,
}

impl EmptyGap {
    /// The sentence that tells what to run.
    pub fn advice(&self) -> String {
        match self {
            EmptyGap::NoRgb { area, camera, frames } => format!(
                "{frames} labelled frame(s) of {area}/{camera} have no RGB photo; run `insgen render-rgb --area \
                 {area} --camera {camera}` (for every area and camera), or export the labels alone with \
                 `insgen export-coco --label-only`"
            ),
            EmptyGap::NoMasks { frames } => format!(
                "{frames} posed frame(s) have no ID map; run `insgen render-masks --area NAME --camera NAME` first"
            ),
            EmptyGap::Filtered { low_consistency_images, empty_images } => format!(
                "the filters left no image: {low_consistency_images} frame(s) scored below --min-consistency, \
                 {empty_images} image(s) had no annotation left (lower --min-consistency, --min-area or \
                 --min-visible-fraction, or keep empty images)"
            ),
            EmptyGap::NoFrames => "no area has posed frames; run `insgen sample --area NAME --camera C` first".into(),
        }
    }
}
