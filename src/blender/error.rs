//! Errors of the Blender stage: invalid jobs, unreadable tilesets and tiles, a Blender process that could
//! not start or failed, and outputs that did not verify.

use std::fmt;
use std::path::PathBuf;

use crate::camera::record::BadFrameName;
use crate::camera::Intrinsics;
use crate::lod::tiles3d::ContentError;
use crate::util::FileError;

/// One problem found in a job before Blender is started, with the JSON path where it sits.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {problem}")]
pub struct JobIssue {
    /// Location in the job, e.g. `frames[3].exr` or `models[0].glb`.
    pub path: String,
    /// What is wrong there.
    pub problem: JobProblem,
}

/// What is wrong at a place in a Blender job (see [`JobIssue`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JobProblem {
    /// The job's `format` is not this insgen's.
    #[error("is {found:?}, expected {expected:?}")]
    Format {
        /// `format` as written.
        found: String,
        /// The format insgen writes.
        expected: &'static str,
    },
    /// The job's `version` is not this insgen's.
    #[error("is {found}, expected {expected}")]
    Version {
        /// `version` as written.
        found: u32,
        /// The version insgen writes.
        expected: u32,
    },
    /// A count that must be at least 1 is 0 (`samples`, `restart_every`).
    #[error("must be at least 1")]
    Zero,
    /// ID renders asked of another engine than Cycles.
    #[error("ID renders need cycles (exact emission values)")]
    IdsNeedCycles,
    /// The job names no model.
    #[error("no model to render")]
    NoModel,
    /// The job names no frame.
    #[error("no frame to render")]
    NoFrame,
    /// A path that must be absolute is relative.
    #[error("{} is not an absolute path", path.display())]
    Relative {
        /// The path.
        path: PathBuf,
    },
    /// A model file that does not exist.
    #[error("{} does not exist or is not a file", path.display())]
    NoModelFile {
        /// The model file.
        path: PathBuf,
    },
    /// A matrix that is not finite and affine.
    #[error("must be a finite affine 4×4 matrix")]
    Matrix,
    /// A look number that is NaN or infinite.
    #[error("{value} is not finite")]
    NotFinite {
        /// The value.
        value: f64,
    },
    /// A frame's look that is not finite (or has a visibility ≤ 0).
    #[error("sun, sky, haze and exposure must be finite (visibility > 0)")]
    FrameLook,
    /// A frame name that cannot be a file stem.
    #[error("{0}: it cannot be a file name")]
    FrameName(BadFrameName),
    /// A frame name used twice.
    #[error("{name:?} appears twice")]
    DuplicateFrame {
        /// The name.
        name: String,
    },
    /// Intrinsics that are not a pinhole camera (an empty image, a focal length ≤ 0).
    #[error("{intrinsics:?} is not a valid pinhole")]
    Intrinsics {
        /// The intrinsics.
        intrinsics: Intrinsics,
    },
    /// A model index past the job's models.
    #[error("{index} is out of range (0..{models})")]
    ModelIndex {
        /// The index.
        index: u32,
        /// Models in the job.
        models: usize,
    },
    /// An output path the frame's mode needs is missing.
    #[error("missing output path")]
    NoOutput,
    /// An output path whose folder does not exist.
    #[error("directory of {} does not exist", path.display())]
    NoOutputDir {
        /// The output path.
        path: PathBuf,
    },
    /// The look ranges cannot be drawn from.
    #[error("{0}")]
    Look(LookError),
    /// The prepared scene's GLB does not exist.
    #[error("{} does not exist (run `insgen prepare` for the area first)", glb.display())]
    NoScene {
        /// The scene GLB.
        glb: PathBuf,
    },
    /// The tileset to render does not exist.
    #[error("{} does not exist", tileset.display())]
    NoTileset {
        /// The tileset JSON.
        tileset: PathBuf,
    },
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
    /// The malformed protocol line, when that is why the process was stopped.
    pub protocol: Option<ProtocolError>,
}

impl std::error::Error for ProcessFailure {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.protocol.as_ref().map(|p| p as &(dyn std::error::Error + 'static))
    }
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

/// Why a camera cannot be reproduced in Blender (see [`BlenderError::Camera`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraProblem {
    /// An empty image.
    #[error("image size {width_px}×{height_px} px is empty")]
    EmptyImage {
        /// Width, pixels.
        width_px: u32,
        /// Height, pixels.
        height_px: u32,
    },
    /// A focal length that is not finite and positive.
    #[error("{name} = {value_px} must be finite and positive")]
    Focal {
        /// `fx_px` or `fy_px`.
        name: &'static str,
        /// The value, pixels.
        value_px: f64,
    },
    /// A principal point coordinate that is not finite.
    #[error("{name} = {value_px} must be finite")]
    PrincipalPoint {
        /// `cx_px` or `cy_px`.
        name: &'static str,
        /// The value, pixels.
        value_px: f64,
    },
    /// A clip range that is not 0 < start < end.
    #[error("clip range [{start_m}, {end_m}] m is not 0 < start < end")]
    Clip {
        /// Clip start, metres.
        start_m: f64,
        /// Clip end, metres.
        end_m: f64,
    },
    /// A pixel aspect Blender cannot represent.
    #[error("fx/fy = {fx_over_fy} needs a pixel aspect beyond {max}")]
    PixelAspect {
        /// fx / fy.
        fx_over_fy: f64,
        /// The largest pixel aspect accepted.
        max: f64,
    },
    /// A principal point too far from the centre for Blender's lens shift.
    #[error(
        "principal point ({cx_px}, {cy_px}) px is too far from the image centre (shift {shift_x}, {shift_y})"
    )]
    Shift {
        /// x, pixels.
        cx_px: f64,
        /// y, pixels.
        cy_px: f64,
        /// Blender's shift_x it would need.
        shift_x: f64,
        /// Blender's shift_y it would need.
        shift_y: f64,
    },
}

/// A line on Blender's stdout that starts with the protocol prefix but is not a protocol event.
#[derive(Debug, thiserror::Error)]
pub enum ProtocolError {
    /// The JSON after the prefix does not parse.
    #[error("malformed protocol line {line:?}")]
    Malformed {
        /// The line as printed.
        line: String,
        /// The JSON parser's error.
        #[source]
        source: serde_json::Error,
    },
    /// The JSON parses but has none of the `ready`, `done`, `error` fields.
    #[error("protocol line {line:?} has no ready/done/error field")]
    Unknown {
        /// The line as printed.
        line: String,
    },
}

/// What is wrong with one output file of a frame (see [`BlenderError::Output`]).
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The file cannot be opened.
    #[error("cannot open it")]
    Open(#[source] std::io::Error),
    /// The file is not a PNG.
    #[error("not a PNG")]
    NotPng(#[source] png::DecodingError),
    /// The PNG is not 8-bit RGB.
    #[error("the PNG is {bit_depth:?} {color:?}, expected 8-bit RGB")]
    PngFormat {
        /// The PNG's bit depth.
        bit_depth: png::BitDepth,
        /// The PNG's colour type.
        color: png::ColorType,
    },
    /// The file does not decode as EXR.
    #[error("does not decode as EXR")]
    Exr(#[source] exr::error::Error),
    /// The EXR lacks a channel (named).
    #[error("the EXR has no {0} channel")]
    MissingChannel(&'static str),
    /// An EXR channel (named) is not float32.
    #[error("EXR channel {0} is not float32")]
    NotF32(&'static str),
    /// The EXR is not an ID map.
    #[error("not an ID map")]
    Ids(#[source] crate::scene::IdError),
    /// The image size differs from the camera's.
    #[error("is {width_px}×{height_px} px, expected {expected_width_px}×{expected_height_px}")]
    Size {
        /// Width found, pixels.
        width_px: u32,
        /// Height found, pixels.
        height_px: u32,
        /// Width expected, pixels.
        expected_width_px: u32,
        /// Height expected, pixels.
        expected_height_px: u32,
    },
    /// The camera effects failed (the source says how).
    #[error("applying the camera effects")]
    Effects(#[source] EffectsError),
    /// The PNG cannot be re-encoded after the camera effects.
    #[error("re-encoding the PNG")]
    EncodePng(#[source] png::EncodingError),
    /// The EXR cannot be re-encoded.
    #[error("re-encoding the EXR")]
    EncodeExr(#[source] exr::error::Error),
    /// No temporary file can be created next to the output.
    #[error("creating a temporary file next to it")]
    TempFile(#[source] std::io::Error),
    /// The temporary file cannot be renamed into place.
    #[error("renaming it into place")]
    Rename(#[source] tempfile::PathPersistError),
    /// The output cannot be written.
    #[error("writing it")]
    Write(#[source] FileError),
    /// Blender's temporary file cannot be removed.
    #[error("removing Blender's temporary file")]
    RemoveTmp(#[source] std::io::Error),
    /// Blender reported a frame the job does not have.
    #[error("Blender reported a frame that is not in the job")]
    NotInJob,
    /// Blender exited successfully without reporting the frame.
    #[error("Blender exited successfully without reporting this frame")]
    NotReported,
}

/// Errors of [`crate::blender`].
#[derive(Debug, thiserror::Error)]
pub enum BlenderError {
    /// A file could not be read or written.
    #[error(transparent)]
    File(#[from] FileError),
    /// The job (or the request it was built from) has problems; all of them are listed.
    #[error("invalid Blender job {}:\n  {}", path.display(), issues.iter().map(|i| i.to_string()).collect::<Vec<_>>().join("\n  "))]
    InvalidJob {
        /// The job file (or the work directory when no job was written).
        path: PathBuf,
        /// Every problem found.
        issues: Vec<JobIssue>,
    },
    /// The intrinsics cannot be reproduced by a Blender camera.
    #[error("camera for frame {frame:?}: {problem}")]
    Camera {
        /// The frame.
        frame: String,
        /// Why the camera cannot be reproduced.
        problem: CameraProblem,
    },
    /// A tileset (or one of its subtree files) is unreadable or breaks the 3D Tiles spec.
    #[error(transparent)]
    Tiles(#[from] crate::lod::LodError),
    /// External tilesets nest deeper than the renderer follows (a cycle, most likely).
    #[error("tileset {}: external tilesets nested deeper than {max_depth} (a cycle?)", path.display())]
    TilesetDepth {
        /// The tileset JSON one level too deep.
        path: PathBuf,
        /// The depth followed.
        max_depth: usize,
    },
    /// A selected tile's content (b3dm/glb/glTF/cmpt) cannot be turned into a GLB Blender imports: it
    /// is malformed, or of a kind or with an extension insgen refuses (named in `source`).
    #[error("tile content {} (tile {tile_at} of {})", content.display(), tileset.display())]
    Tile {
        /// The content file.
        content: PathBuf,
        /// The tileset JSON holding the tile.
        tileset: PathBuf,
        /// JSON path of the tile in `tileset` (`root.children[2]`).
        tile_at: String,
        /// What is wrong with the content.
        #[source]
        source: Box<ContentError>,
    },
    /// No interpreter with bpy or Blender binary was found.
    #[error("no Blender found: {}{}\nhint: run scripts/setup.sh (it calls scripts/setup_blender.sh, which creates .venv-blender with bpy), or pass --blender-python PATH / --blender PATH, or set INSGEN_BLENDER_PYTHON / INSGEN_BLENDER", if *given_only { "" } else { "tried " }, tried.join("; "))]
    NotFound {
        /// Whether the paths given on the command line were all that was tried.
        given_only: bool,
        /// Where insgen looked (each "`--blender` PATH (not a file)", "INSGEN_BLENDER PATH (not a file)", …).
        tried: Vec<String>,
    },
    /// The Blender process could not be started.
    #[error("cannot start `{command}`{}", hint.as_ref().map(|h| format!("\nhint: {h}")).unwrap_or_default())]
    Spawn {
        /// The command line as it would be typed.
        command: String,
        /// A hint for a recognised cause (the program does not exist).
        hint: Option<String>,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The Blender process failed.
    #[error(transparent)]
    Failed(Box<ProcessFailure>),
    /// Blender reported a frame done but its output is missing or wrong.
    #[error("frame {frame:?}: output {}", path.display())]
    Output {
        /// The frame.
        frame: String,
        /// The output file (its temporary path).
        path: PathBuf,
        /// What is wrong with it.
        #[source]
        source: OutputError,
    },
    /// An output directory does not accept new files.
    #[error("{} is not writable", dir.display())]
    NotWritable {
        /// The directory.
        dir: PathBuf,
        /// The error creating a probe file in it.
        #[source]
        source: std::io::Error,
    },
    /// Ctrl-C was pressed: the run stopped between frames (finished frames are complete).
    #[error("rendering stopped between frames")]
    Interrupted(#[from] crate::util::interrupt::Interrupted),
    /// The alignment check needs a frame's mask, which `render-masks` has not written yet.
    #[error(
        "{} does not exist; render the masks first: insgen render-masks with the same --area and --camera",
        path.display()
    )]
    MaskMissing {
        /// The mask the check looked for.
        path: PathBuf,
    },
    /// The render plan has no ID output for a frame the alignment check compares (the plan was
    /// made without `--check-alignment`).
    #[error("frame {frame:?}: the render plan writes no ID render to compare with its mask")]
    NoIdOutput {
        /// The frame.
        frame: String,
    },
    /// An ID map (EXR from Blender, PNG from the mask renderer) is unreadable or not an ID map.
    #[error(transparent)]
    Ids(#[from] crate::scene::IdError),
    /// Two ID maps of one frame differ in size.
    #[error("{}: ID maps of different sizes, {}×{} vs {}×{}", path.display(), a[0], a[1], b[0], b[1])]
    SizeMismatch {
        /// The frame's ID map.
        path: PathBuf,
        /// Width and height of the first map, pixels.
        a: [u32; 2],
        /// Width and height of the second map, pixels.
        b: [u32; 2],
    },
}

/// Look ranges that cannot be drawn from (see [`crate::blender::look::LookRanges::check`]), or a sun
/// that never rises high enough in them.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LookError {
    /// A range (`name`: "sun hours", "sun azimuth", "white balance", …) that is not finite or decreases.
    #[error("{name}: {}..{} is not an increasing finite range", range[0], range[1])]
    NotIncreasing {
        /// What the range is, as the flags name it.
        name: &'static str,
        /// The range as given (units of the quantity: hours, degrees, kelvin).
        range: [f64; 2],
    },
    /// The latitude the sun is computed at is outside −90..90°.
    #[error("latitude {latitude_deg}° is outside −90..90")]
    Latitude {
        /// The latitude given, degrees.
        latitude_deg: f64,
    },
    /// The days of the year are outside 1..366 or decrease.
    #[error("sun days {}..{} must lie in 1..366, increasing", days[0], days[1])]
    SunDays {
        /// First and last day of the year given.
        days: [u32; 2],
    },
    /// The solar hours are outside 0..24.
    #[error("sun hours {}..{} must lie in 0..24", solar_hours[0], solar_hours[1])]
    SunHours {
        /// First and last local solar time given, hours.
        solar_hours: [f64; 2],
    },
    /// The minimum sun elevation is outside −90..90°.
    #[error("minimum sun elevation {min_elevation_deg}° is outside −90..90")]
    MinElevation {
        /// The minimum elevation given, degrees.
        min_elevation_deg: f64,
    },
    /// The drawn sun elevations are outside 0..90°.
    #[error("sun elevation {}..{}° must lie in 0..90°", elevation_deg[0], elevation_deg[1])]
    SunElevation {
        /// The elevation range given, degrees.
        elevation_deg: [f64; 2],
    },
    /// A sky weight is negative or not finite, or they sum to 0.
    #[error("sky weights {weights:?} must be ≥ 0 with a positive sum")]
    SkyWeights {
        /// Weights of clear, hazy and overcast skies.
        weights: [f64; 3],
    },
    /// The exposure jitter is negative or not finite.
    #[error("exposure jitter {jitter_ev} must be ≥ 0")]
    ExposureJitter {
        /// The jitter given, stops.
        jitter_ev: f64,
    },
    /// The white balance range is outside 1000..40000 K.
    #[error("white balance {}..{} K must lie in 1000..40000 K", kelvin[0], kelvin[1])]
    WhiteBalance {
        /// The colour temperature range given, kelvin.
        kelvin: [f64; 2],
    },
    /// The JPEG quality range is outside 1..100 or decreases.
    #[error("JPEG quality {}..{} must lie in 1..100, increasing", quality[0], quality[1])]
    JpegQuality {
        /// The quality range given.
        quality: [u8; 2],
    },
    /// No draw of day and hour put the sun above the minimum elevation.
    #[error(
        "the sun does not rise {min_elevation_deg}° above the horizon on days {}..{} between {}h and {}h solar \
         time at latitude {latitude_deg:.2}°; widen --sun-days/--sun-hours or give --sun-azimuth/--sun-elevation",
        days[0],
        days[1],
        solar_hours[0],
        solar_hours[1]
    )]
    SunNeverUp {
        /// The latitude the sun was computed at, degrees.
        latitude_deg: f64,
        /// First and last day of the year drawn from.
        days: [u32; 2],
        /// First and last local solar time drawn from, hours.
        solar_hours: [f64; 2],
        /// The elevation the sun had to reach, degrees.
        min_elevation_deg: f64,
    },
}

/// Why the camera effects could not be applied to a frame (see
/// [`crate::blender::look::apply_camera_effects`]).
#[derive(Debug, thiserror::Error)]
pub enum EffectsError {
    /// The sensor noise's standard deviation is not usable (NaN).
    #[error("sensor noise σ {sigma} is not a valid standard deviation")]
    Noise {
        /// The noise standard deviation, 8-bit levels.
        sigma: f64,
        /// The distribution's refusal.
        #[source]
        source: rand_distr::NormalError,
    },
    /// The JPEG encoder failed.
    #[error("JPEG encoding at quality {quality}")]
    JpegEncode {
        /// The JPEG quality asked for.
        quality: u8,
        /// The codec's error.
        #[source]
        source: image::ImageError,
    },
    /// The re-encoded JPEG does not decode.
    #[error("JPEG decoding")]
    JpegDecode(#[source] image::ImageError),
}
