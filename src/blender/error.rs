//! Errors of the Blender stage: invalid jobs, unreadable tilesets and tiles, a Blender process that could
//! not start or failed, and outputs that did not verify.

use std::fmt;
use std::path::PathBuf;

use crate::lod::tiles3d::ContentError;
use crate::util::FileError;

/// One problem found in a job before Blender is started, with the JSON path where it sits.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JobIssue {
    /// Location in the job, e.g. `frames[3].exr` or `models[0].glb`.
    pub path: String,
    pub what: String,
}

impl fmt::Display for JobIssue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path, self.what)
    }
}

/// A Blender process that exited unsuccessfully (or broke the protocol), with what is needed to act.
#[derive(Debug)]
pub struct ProcessFailure {
    /// The command line as it would be typed (arguments quoted when needed).
    pub command: String,
    /// "exit status 1", "killed by signal 9", or a protocol problem when the exit status was 0.
    pub status: String,
    /// The frame being rendered when it failed, when known.
    pub frame: Option<String>,
    /// The message the script reported through the protocol (`{"error": …}`), when it did.
    pub message: Option<String>,
    /// The last lines of stderr (and of stdout lines that were not protocol lines).
    pub stderr_tail: Vec<String>,
    /// A hint for a recognised failure signature.
    pub hint: Option<String>,
}

/// Width of the divider lines around the captured stderr.
const DIVIDER_WIDTH: usize = 78;

impl fmt::Display for ProcessFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Blender failed: `{}` ended with {}", self.command, self.status)?;
        if let Some(frame) = &self.frame {
            write!(f, " while rendering frame {frame:?}")?;
        }
        if let Some(msg) = &self.message {
            write!(f, "\nreported error: {msg}")?;
        }
        if let Some(hint) = &self.hint {
            write!(f, "\nhint: {hint}")?;
        }
        let title = format!(" stderr (last {} lines) ", self.stderr_tail.len());
        let side = DIVIDER_WIDTH.saturating_sub(title.len()) / 2;
        write!(f, "\n{}{}{}", "-".repeat(side), title, "-".repeat(side))?;
        if self.stderr_tail.is_empty() {
            write!(f, "\n<stderr is empty>")?;
        }
        for line in &self.stderr_tail {
            write!(f, "\n{line}")?;
        }
        write!(f, "\n{}", "-".repeat(DIVIDER_WIDTH))
    }
}

/// Errors of [`crate::blender`].
#[derive(Debug, thiserror::Error)]
pub enum BlenderError {
    #[error(transparent)]
    File(#[from] FileError),
    /// The job (or the request it was built from) has problems; all of them are listed.
    #[error("invalid Blender job {}:\n  {}", path.display(), issues.iter().map(|i| i.to_string()).collect::<Vec<_>>().join("\n  "))]
    InvalidJob { path: PathBuf, issues: Vec<JobIssue> },
    /// The intrinsics cannot be reproduced by a Blender camera.
    #[error("camera for frame {frame:?}: {what}")]
    Camera { frame: String, what: String },
    /// A tileset (or one of its subtree files) is unreadable or breaks the 3D Tiles spec.
    #[error(transparent)]
    Tiles(#[from] crate::lod::LodError),
    /// A tileset JSON cannot be used for rendering.
    #[error("tileset {}: {what}", path.display())]
    Tileset { path: PathBuf, what: String },
    /// A selected tile's content (b3dm/glb/glTF/cmpt) cannot be turned into a GLB Blender imports: it
    /// is malformed, or of a kind or with an extension insgen refuses (named in `source`).
    #[error("tile content {} (tile {tile_at} of {})", content.display(), tileset.display())]
    Tile {
        content: PathBuf,
        tileset: PathBuf,
        /// JSON path of the tile in `tileset` (`root.children[2]`).
        tile_at: String,
        #[source]
        source: Box<ContentError>,
    },
    /// No interpreter with bpy or Blender binary was found.
    #[error("no Blender found: {what}\nhint: run scripts/setup.sh (it calls scripts/setup_blender.sh, which creates .venv-blender with bpy), or pass --blender-python PATH / --blender PATH, or set INSGEN_BLENDER_PYTHON / INSGEN_BLENDER")]
    NotFound { what: String },
    /// The Blender process could not be started.
    #[error("cannot start `{command}`{}", hint.as_ref().map(|h| format!("\nhint: {h}")).unwrap_or_default())]
    Spawn {
        command: String,
        hint: Option<String>,
        #[source]
        source: std::io::Error,
    },
    /// The Blender process failed.
    #[error("{0}")]
    Failed(Box<ProcessFailure>),
    /// Blender reported a frame done but its output is missing or wrong.
    #[error("frame {frame:?}: output {}: {what}", path.display())]
    Output { frame: String, path: PathBuf, what: String },
    /// An ID map (EXR from Blender, PNG from the mask renderer) is unreadable or not an ID map.
    #[error(transparent)]
    Ids(#[from] crate::scene::IdError),
    /// Two ID maps of one frame differ in size.
    #[error("{}: ID maps of different sizes, {}×{} vs {}×{}", path.display(), a[0], a[1], b[0], b[1])]
    SizeMismatch { path: PathBuf, a: [u32; 2], b: [u32; 2] },
}
