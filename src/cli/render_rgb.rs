//! `insgen render-rgb`: RGB frames with Blender, pixel-aligned with the masks, and the alignment check.

use std::path::PathBuf;

use anyhow::{bail, Context};

use crate::blender::job::{DenoiseQuality, Device, Lighting, RgbSettings};
use crate::blender::look::{LookRanges, LookStyle, SunRange};
use crate::blender::tileset::SelectOptions;
use crate::blender::{render_frames, Engine, FrameRequest, Launcher, Mode, RenderPlan, SceneSource};
use crate::geo::{EnuFrame, Geodetic};
use crate::scene::artifact::{Manifest, GLB_FILE, MANIFEST_FILE};
use crate::util::ShardSpec;

/// Render engine choice on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum EngineArg {
    /// Path tracing on the CPU (default).
    Cycles,
    /// Fast preview shading with flat per-building colours.
    Workbench,
}

/// Cycles device choice on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DeviceArg {
    /// The best GPU backend Blender reports, else the CPU.
    Auto,
    /// The CPU (default).
    Cpu,
    /// NVIDIA GPUs through CUDA.
    Cuda,
    /// NVIDIA RTX GPUs through OptiX.
    Optix,
    /// AMD GPUs through HIP.
    Hip,
    /// Intel GPUs through oneAPI.
    Oneapi,
}

impl From<DeviceArg> for Device {
    fn from(d: DeviceArg) -> Device {
        match d {
            DeviceArg::Auto => Device::Auto,
            DeviceArg::Cpu => Device::Cpu,
            DeviceArg::Cuda => Device::Cuda,
            DeviceArg::Optix => Device::Optix,
            DeviceArg::Hip => Device::Hip,
            DeviceArg::Oneapi => Device::Oneapi,
        }
    }
}

/// Denoiser quality on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DenoiseQualityArg {
    /// Fastest: FAST denoising and prefilter.
    Fast,
    /// BALANCED denoising with the FAST prefilter.
    Balanced,
    /// Best and slowest: HIGH denoising with the ACCURATE prefilter.
    High,
}

/// Light transport of the procedural look (`--lighting`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LightingArg {
    /// Sun with hard shadows, sky ambient and glass reflections as emission: noise-free but for
    /// anti-aliasing, so 1 sample + fast denoiser (the default).
    Direct,
    /// Path tracing with sky light and bounces: softer, costlier (2 samples + balanced denoiser).
    Path,
}

impl From<LightingArg> for Lighting {
    fn from(l: LightingArg) -> Lighting {
        match l {
            LightingArg::Direct => Lighting::Direct,
            LightingArg::Path => Lighting::Path,
        }
    }
}

impl From<DenoiseQualityArg> for DenoiseQuality {
    fn from(q: DenoiseQualityArg) -> DenoiseQuality {
        match q {
            DenoiseQualityArg::Fast => DenoiseQuality::Fast,
            DenoiseQualityArg::Balanced => DenoiseQuality::Balanced,
            DenoiseQualityArg::High => DenoiseQuality::High,
        }
    }
}

/// The per-frame look on the command line (`--look`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LookArg {
    /// Sun from a date and time, clear/hazy/overcast skies, haze, exposure and white-balance jitter and
    /// camera effects, drawn per frame and recorded (the default).
    Varied,
    /// One sun per area and seed, a clear sky, no haze and no camera effects.
    Plain,
}

/// A closed range `A..B` of numbers (`A..A` or a single `A` for a constant).
fn parse_range(s: &str) -> Result<[f64; 2], String> {
    let (a, b) = s.split_once("..").unwrap_or((s, s));
    let num = |t: &str| {
        t.trim().parse::<f64>().map_err(|_| format!("{t:?} is not a number in {s:?} (expected A..B)"))
    };
    let (a, b) = (num(a)?, num(b)?);
    if !(a.is_finite() && b.is_finite() && a <= b) {
        return Err(format!("{s:?}: expected an increasing range A..B"));
    }
    Ok([a, b])
}

/// Three non-negative weights `CLEAR,HAZY,OVERCAST`.
fn parse_weights(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>().map_err(|_| format!("{t:?} is not a number in {s:?}")))
        .collect::<Result<_, _>>()?;
    match v[..] {
        [a, b, c] if v.iter().all(|w| w.is_finite() && *w >= 0.0) && a + b + c > 0.0 => Ok([a, b, c]),
        _ => Err(format!("{s:?}: expected three weights CLEAR,HAZY,OVERCAST, ≥ 0, not all 0")),
    }
}

/// Renders RGB frames with Blender for a camera's poses.
///
/// Reads <workdir>/<area>/scene/{scene.glb,manifest.json} and <workdir>/<area>/<camera>/poses.jsonl;
/// writes <workdir>/<area>/<camera>/rgb/<frame>.png (and <frame>.exr with --exr). Each frame uses exactly
/// the intrinsics and pose of its mask, so RGB and masks are pixel-aligned. Frames whose PNG already
/// exists and decodes are skipped (use --force to redo them).
///
/// With --check-alignment, Blender renders building IDs instead (float32 EXR, alignment/<frame>.ids.exr),
/// which are compared with masks/<frame>.png: per-building IoU, report in alignment/report.{md,json};
/// the command fails when the median IoU is below 0.995 or the 5th percentile below 0.98.
///
/// Blender is the bpy module in .venv-blender (scripts/setup.sh installs it), or --blender-python /
/// INSGEN_BLENDER_PYTHON, or a Blender binary via --blender / INSGEN_BLENDER.
#[derive(Debug, Clone, clap::Args)]
#[command(
    after_long_help = "Examples:\n  insgen render-rgb --area demo --camera cam2 --limit 4 --samples 16\n  \
insgen render-rgb --area demo --camera cam2 --shard 0/2 & insgen render-rgb --area demo --camera cam2 --shard 1/2\n  \
insgen render-rgb --area demo --camera cam2 --shard auto   # in a Slurm job array\n  \
insgen render-rgb --area demo --camera cam2 --check-alignment --limit 10"
)]
pub struct Args {
    /// Area name (a directory under the workdir).
    #[arg(long, value_name = "NAME")]
    pub area: String,
    /// Camera whose poses to render: a preset (cam1, cam2, cam3), the camera's name, or the camera
    /// TOML file given to `sample`.
    #[arg(long, value_name = "PRESET|NAME|FILE", value_parser = super::parse_camera_dir)]
    pub camera: String,
    /// Render only frames whose index in poses.jsonl is i modulo N (0 ≤ i < N).
    ///
    /// `auto` takes i and N from a Slurm job array; `auto/N` takes i from a Slurm array or a
    /// Kubernetes Indexed Job (JOB_COMPLETION_INDEX) and N as given.
    #[arg(long, value_name = "i/N|auto|auto/N")]
    pub shard: Option<ShardSpec>,
    /// Cycles samples per pixel [default: 1 procedural direct, 2 procedural path, 3 tileset].
    ///
    /// The defaults were chosen by measurement (bench/rgb_quality.md): each reaches ≥ 35 dB PSNR
    /// against the converged render of its look; unlit photogrammetry needs samples only for
    /// anti-aliasing.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub samples: Option<u32>,
    /// Light transport of the procedural look (ignored for tilesets, which are shown unlit).
    #[arg(long, value_enum, value_name = "MODEL", default_value_t = LightingArg::Direct)]
    pub lighting: LightingArg,
    /// Cycles device: auto picks the best GPU Blender reports (OptiX, CUDA, HIP, oneAPI), else the CPU.
    #[arg(long, value_enum, value_name = "DEVICE", default_value_t = DeviceArg::Cpu)]
    pub device: DeviceArg,
    /// Render engine.
    #[arg(long, value_enum, default_value_t = EngineArg::Cycles)]
    pub engine: EngineArg,
    /// Also write a linear float32 EXR per frame.
    #[arg(long)]
    pub exr: bool,
    /// Render building IDs and compare them with the masks instead of rendering RGB.
    #[arg(long)]
    pub check_alignment: bool,
    /// Clutter layers that hide buildings in the --check-alignment ID render.
    ///
    /// Same syntax and default as `render-masks --occluders`; give both commands the same list. RGB
    /// frames always show every clutter layer.
    #[arg(
        long,
        value_name = "LAYERS",
        default_value = "trees,cars",
        value_parser = super::render_masks::parse_occluders
    )]
    pub occluders: super::render_masks::LayerList,
    /// After rendering RGB, write rgb/side_by_side.png showing K frames.
    ///
    /// One row per frame: the RGB frame, the mask outlines over it, and the clutter/occluder layer
    /// (each clutter layer in a flat colour, buildings grey). Uses masks/<frame>.png when it exists.
    #[arg(long, value_name = "K", default_value_t = 0)]
    pub side_by_side: usize,
    /// Start a fresh Blender process every N frames (bounds memory).
    #[arg(long, value_name = "N", default_value_t = 50, value_parser = clap::value_parser!(u32).range(1..))]
    pub restart_every: u32,
    /// Re-render frames whose outputs already exist.
    #[arg(long)]
    pub force: bool,
    /// Render at most N frames (after sharding).
    #[arg(long, value_name = "N")]
    pub limit: Option<usize>,
    /// Seed of the sampling, the sun and the per-building materials.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub seed: u32,
    /// Per-frame look: `varied` draws sun, sky, haze, exposure, white balance and camera effects per frame
    /// (recorded in rgb/<frame>.render.json and the COCO image record); `plain` keeps one clear look.
    #[arg(long, value_enum, value_name = "STYLE", default_value_t = LookArg::Varied)]
    pub look: LookArg,
    /// Days of the year the sun is drawn from (varied look; the sun's position follows the area's latitude).
    #[arg(long, value_name = "A..B", default_value = "1..365", value_parser = parse_range, hide_short_help = true)]
    pub sun_days: [f64; 2],
    /// Local solar time the sun is drawn from, hours (draws with the sun below 15° are redrawn).
    #[arg(long, value_name = "A..B", default_value = "7..18", value_parser = parse_range, hide_short_help = true)]
    pub sun_hours: [f64; 2],
    /// Draw the sun's azimuth (degrees clockwise from north) from this range instead of a date and time
    /// (needs --sun-elevation).
    #[arg(long, value_name = "A..B", value_parser = parse_range, requires = "sun_elevation", hide_short_help = true)]
    pub sun_azimuth: Option<[f64; 2]>,
    /// Draw the sun's elevation (degrees) from this range instead of a date and time (needs --sun-azimuth).
    #[arg(long, value_name = "A..B", value_parser = parse_range, requires = "sun_azimuth", hide_short_help = true)]
    pub sun_elevation: Option<[f64; 2]>,
    /// Relative weights of clear, hazy and overcast skies.
    #[arg(long, value_name = "C,H,O", default_value = "0.5,0.3,0.2", value_parser = parse_weights, hide_short_help = true)]
    pub skies: [f64; 3],
    /// No vignetting, blur or sensor noise (sun, sky, haze, exposure and white balance still vary).
    #[arg(long, hide_short_help = true)]
    pub no_camera_effects: bool,
    /// Re-encode each frame as JPEG with a quality drawn from this range (the PNG holds the decoded JPEG).
    #[arg(long, value_name = "A..B", value_parser = parse_range, hide_short_help = true)]
    pub jpeg_quality: Option<[f64; 2]>,
    /// Draw each building's colours independently, even when it touches another building (by default the
    /// procedural look gives touching buildings different lightness bands, so every shared wall shows).
    #[arg(long, hide_short_help = true)]
    pub no_neighbour_contrast: bool,
    /// Render a photogrammetry 3D Tiles tileset (tileset.json) instead of the procedural LoD look.
    #[arg(long, value_name = "FILE")]
    pub tileset: Option<PathBuf>,
    /// Screen-space error in pixels above which tiles are refined.
    #[arg(long, value_name = "PX", default_value_t = 16.0, hide_short_help = true)]
    pub max_sse: f64,
    /// Render threads (0 = all cores).
    #[arg(long, value_name = "N", default_value_t = 0, hide_short_help = true)]
    pub threads: u32,
    /// Do not denoise RGB renders (the default for tilesets).
    #[arg(long, hide_short_help = true, overrides_with = "denoise")]
    pub no_denoise: bool,
    /// Denoise RGB renders (the default for the procedural look).
    #[arg(long, hide_short_help = true, overrides_with = "no_denoise")]
    pub denoise: bool,
    /// OpenImageDenoise quality [default: fast direct, balanced path].
    #[arg(long, value_enum, value_name = "Q", hide_short_help = true)]
    pub denoise_quality: Option<DenoiseQualityArg>,
    /// Light bounces (0 = direct light only) [default: 0 direct and tileset, 2 path].
    #[arg(long, value_name = "N", hide_short_help = true)]
    pub max_bounces: Option<u32>,
    /// Minimum union in pixels for a building to enter the alignment statistics.
    #[arg(long, value_name = "PX", default_value_t = 64, hide_short_help = true)]
    pub min_union: u64,
    /// Blender executable to run (`blender -b -P …`) instead of the bpy venv.
    #[arg(long, value_name = "FILE", hide_short_help = true)]
    pub blender: Option<PathBuf>,
    /// Python interpreter with the bpy module.
    #[arg(long, value_name = "FILE", hide_short_help = true)]
    pub blender_python: Option<PathBuf>,
}

/// Paths and settings resolved from the flags, before any work starts.
struct Plan {
    camera_dir: PathBuf,
    frames: Vec<FrameRequest>,
    render: RenderPlan,
}

fn plan(args: &Args, global: &super::Global) -> anyhow::Result<Plan> {
    let area_dir = global.workdir.join(&args.area);
    let scene_dir = area_dir.join(crate::layout::SCENE_DIR);
    let camera_dir = area_dir.join(&args.camera);
    let poses_path = camera_dir.join(crate::layout::POSES_FILE);
    if !poses_path.is_file() {
        bail!(
            "{} does not exist; sample the poses first: insgen sample --area {} --camera {}",
            poses_path.display(),
            args.area,
            args.camera
        );
    }
    let manifest_path = scene_dir.join(MANIFEST_FILE);
    if !manifest_path.is_file() {
        bail!(
            "{} does not exist; prepare the scene first: insgen prepare --area {}",
            manifest_path.display(),
            args.area
        );
    }
    let manifest: Manifest = serde_json::from_slice(&crate::util::read_file(&manifest_path)?)
        .with_context(|| format!("{}: not a scene manifest", manifest_path.display()))?;
    let records = crate::camera::record::read_jsonl(&poses_path)?;
    let shard = super::resolve_shard(args.shard)?;
    let mut frames: Vec<FrameRequest> = records
        .iter()
        .enumerate()
        .filter(|(i, _)| shard.contains(*i))
        .map(|(_, r)| FrameRequest { name: r.name.clone(), intrinsics: r.view.intrinsics, pose: r.pose() })
        .collect();
    if let Some(n) = args.limit {
        frames.truncate(n);
    }
    let roots = [std::env::current_dir().unwrap_or_default(), PathBuf::from(env!("CARGO_MANIFEST_DIR"))];
    let launcher = Launcher::find(args.blender.as_deref(), args.blender_python.as_deref(), &roots)?;
    let source = match (&args.tileset, args.check_alignment) {
        (Some(t), false) => {
            let o = manifest.origin;
            SceneSource::Tileset {
                tileset: t.clone(),
                enu: EnuFrame::new(Geodetic::new(o.lat_deg, o.lon_deg, o.h_m)),
                select: SelectOptions { max_sse_px: args.max_sse },
            }
        }
        // The masks come from the LoD model, so the alignment check always renders it.
        _ => SceneSource::Lod {
            glb: scene_dir.join(GLB_FILE),
            enu_from_gltf: crate::util::row_major::rows(&crate::scene::PreparedScene::enu_from_scene_gltf(
                &manifest,
            )),
        },
    };
    let (mode, out_dir) = if args.check_alignment {
        (Mode::Ids, camera_dir.join("alignment"))
    } else {
        (Mode::Rgb, camera_dir.join(crate::layout::RGB_DIR))
    };
    let defaults = source.default_rgb_settings(args.lighting.into());
    let look = look_ranges(args, manifest.origin.lat_deg)?;
    let render = RenderPlan {
        launcher,
        mode,
        engine: match args.engine {
            EngineArg::Cycles => Engine::Cycles,
            EngineArg::Workbench if args.check_alignment => Engine::Cycles,
            EngineArg::Workbench => Engine::Workbench,
        },
        rgb: RgbSettings {
            samples: args.samples.unwrap_or(defaults.samples),
            denoise: match (args.denoise, args.no_denoise) {
                (true, _) => true,
                (_, true) => false,
                _ => defaults.denoise,
            },
            denoise_quality: args.denoise_quality.map(Into::into).unwrap_or(defaults.denoise_quality),
            max_bounces: args.max_bounces.unwrap_or(defaults.max_bounces),
            lighting: defaults.lighting,
        },
        seed: args.seed,
        device: args.device.into(),
        threads: args.threads,
        exr: args.exr,
        source,
        look_seed: crate::util::fnv1a_seeded(0, &args.area) ^ args.seed as u64,
        look,
        ground_enu_m: manifest.ground_enu_m,
        out_dir,
        work_dir: camera_dir.join(crate::layout::BLENDER_DIR),
        restart_every: args.restart_every as usize,
        force: args.force,
        clip_start_m: 0.5,
        clip_end_m: 100_000.0,
        report_bounds: false,
        clutter_occluders: Some(args.occluders.0.clone()),
        contrast: None,
    };
    let render = RenderPlan { contrast: neighbour_contrast(args, &render, &scene_dir)?, ..render };
    Ok(Plan { camera_dir, frames, render })
}

/// The contrast classes of touching buildings, for RGB renders of the procedural look unless
/// `--no-neighbour-contrast`; logged with the touching pairs they leave unseparated.
fn neighbour_contrast(
    args: &Args,
    render: &RenderPlan,
    scene_dir: &std::path::Path,
) -> anyhow::Result<Option<crate::blender::look::BuildingContrast>> {
    if args.no_neighbour_contrast
        || render.mode != Mode::Rgb
        || !matches!(render.source, SceneSource::Lod { .. })
    {
        return Ok(None);
    }
    // Only the mesh is needed (plan adjacency does not move with an alignment correction).
    let glb = scene_dir.join(GLB_FILE);
    let mesh = match crate::scene::glb::read_glb(&glb) {
        Ok(m) => m,
        Err(e) => {
            log::warn!("neighbour contrast off: {}", crate::util::error_chain(&e));
            return Ok(None);
        }
    };
    let (contrast, (same, pairs)) = crate::blender::look::BuildingContrast::of_mesh(&mesh);
    log::info!(
        "neighbour contrast: {} buildings in {} classes, {pairs} touching pairs, {same} of them in the same class",
        contrast.building_classes.len(),
        contrast.classes
    );
    Ok(Some(contrast))
}

/// The look ranges of the flags at the area's latitude.
fn look_ranges(args: &Args, latitude_deg: f64) -> anyhow::Result<LookRanges> {
    let mut r = LookRanges::defaults(latitude_deg);
    if args.look == LookArg::Plain {
        r.style = LookStyle::Plain;
    }
    let whole = |name: &str, [a, b]: [f64; 2]| -> anyhow::Result<[u32; 2]> {
        if a.fract() != 0.0 || b.fract() != 0.0 || a < 0.0 || b > 366.0 {
            bail!("--{name} {a}..{b}: expected whole numbers");
        }
        Ok([a as u32, b as u32])
    };
    r.sun = match (args.sun_azimuth, args.sun_elevation) {
        (Some(azimuth_deg), Some(elevation_deg)) => SunRange::Angles { azimuth_deg, elevation_deg },
        _ => SunRange::Dates {
            latitude_deg,
            days: whole("sun-days", args.sun_days)?,
            solar_hours: args.sun_hours,
            min_elevation_deg: 15.0,
        },
    };
    r.sky_weights = args.skies;
    r.camera_effects = !args.no_camera_effects;
    r.jpeg_quality = match args.jpeg_quality {
        Some(q) => {
            let [a, b] = whole("jpeg-quality", q)?;
            Some([a.min(255) as u8, b.min(255) as u8])
        }
        None => None,
    };
    if let Err(e) = r.check() {
        bail!("render-rgb: {e}");
    }
    Ok(r)
}

/// Runs `insgen render-rgb`.
pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let plan = plan(args, global)?;
    if plan.frames.is_empty() {
        log::warn!("no frames selected (shard/limit leave nothing to render)");
        return Ok(());
    }
    let printer = global.printer();
    let r = &plan.render.rgb;
    printer.status(format!(
        "render-rgb: {} lighting, {} samples, denoise {}, {} bounce(s), device {}",
        match plan.render.source {
            SceneSource::Lod { .. } => r.lighting.name(),
            SceneSource::Tileset { .. } => "unlit",
        },
        r.samples,
        if r.denoise { format!("on ({:?})", r.denoise_quality).to_lowercase() } else { "off".into() },
        r.max_bounces,
        plan.render.device.name()
    ));
    let summary = render_frames(&plan.render, &plan.frames, &printer.progress())?;
    let n = summary.rendered.len().max(1) as f64;
    let mean = summary.rendered.iter().map(|t| t.seconds).sum::<f64>() / n;
    let mean_cpu = summary.rendered.iter().map(|t| t.cpu_seconds).sum::<f64>() / n;
    // The median leaves out each Blender process's first frame (scene sync, BVH, textures) once there
    // are a few frames: what a long run costs per frame.
    let median = |f: fn(&crate::blender::run::FrameTiming) -> f64| {
        let mut v: Vec<f64> = summary.rendered.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let (median_s, median_cpu) = (median(|t| t.seconds), median(|t| t.cpu_seconds));
    let mut devices = summary.devices.clone();
    devices.dedup();
    printer.status(format!(
        "render-rgb: {} frame(s) rendered ({mean:.2} s/frame, {mean_cpu:.2} CPU s/frame in Blender; median \
         {median_s:.2} s, {median_cpu:.2} CPU s), {} already done, {} Blender process(es) on {}",
        summary.rendered.len(),
        summary.skipped.len(),
        summary.setup_seconds.len(),
        if devices.is_empty() { "-".to_string() } else { devices.join(", ") }
    ));
    for (ext, n) in &summary.skipped_contents {
        printer.status(format!(
            "render-rgb: skipped {n} tile content(s) of type .{ext} (not importable by Blender)"
        ));
    }
    if !args.check_alignment {
        if args.side_by_side > 0 {
            side_by_side(args, global, &plan)?;
        }
        return Ok(());
    }
    let camera = crate::layout::CameraDir::new(&plan.camera_dir);
    let report = crate::blender::align::check_frames(&plan.render, &plan.frames, &camera, args.min_union)?;
    let dir = &plan.render.out_dir;
    let fmt = |v: Option<f64>| v.map(|x| format!("{x:.4}")).unwrap_or_else(|| "n/a".into());
    printer.summary(format!(
        "alignment: median IoU {}, p5 {}, {} pairs over {} frames, pixel agreement {:.5} → {}",
        fmt(report.median_iou),
        fmt(report.p5_iou),
        report.pairs_counted,
        report.frames,
        report.pixel_agreement,
        dir.join(crate::blender::align::REPORT_MD).display()
    ));
    if !report.pass {
        bail!(
            "alignment below target (median ≥ {}, p5 ≥ {}); see {}",
            report.target_median_iou,
            report.target_p5_iou,
            dir.join(crate::blender::align::REPORT_MD).display()
        );
    }
    Ok(())
}

/// Writes `rgb/side_by_side.png` for the first `--side-by-side` frames of the plan.
fn side_by_side(args: &Args, global: &super::Global, plan: &Plan) -> anyhow::Result<()> {
    use crate::label::side_by_side::{write_side_by_side, SideFrame};
    let scene_dir = global.workdir.join(&args.area).join(crate::layout::SCENE_DIR);
    let scene = crate::scene::PreparedScene::load(&scene_dir)
        .with_context(|| format!("loading {}", scene_dir.display()))?;
    let renderer = crate::render::Renderer::new().context("setting up the GPU renderer")?;
    let rgb_dir = plan.camera_dir.join(crate::layout::RGB_DIR);
    let frames: Vec<SideFrame> = plan
        .frames
        .iter()
        .map(|f| SideFrame {
            name: f.name.clone(),
            view: crate::render::View { intrinsics: f.intrinsics, pose: f.pose },
            rgb_png: rgb_dir.join(format!("{}.png", f.name)),
            mask_png: plan.camera_dir.join(crate::layout::MASKS_DIR).join(format!("{}.png", f.name)),
        })
        .collect();
    let out = rgb_dir.join("side_by_side.png");
    let shown = write_side_by_side(&out, &scene, &renderer, &frames, args.side_by_side)
        .with_context(|| format!("writing {}", out.display()))?;
    global.printer().summary(format!("side-by-side picture of {shown} frame(s) → {}", out.display()));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Wrap {
        #[command(flatten)]
        args: Args,
    }

    fn parse(extra: &[&str]) -> Result<Args, clap::Error> {
        let mut v = vec!["x", "--area", "demo", "--camera", "cam2"];
        v.extend_from_slice(extra);
        Wrap::try_parse_from(v).map(|w| w.args)
    }

    #[test]
    fn defaults() {
        let a = parse(&[]).unwrap();
        assert_eq!((a.samples, a.engine, a.restart_every, a.seed), (None, EngineArg::Cycles, 50, 0));
        assert_eq!(a.device, DeviceArg::Cpu);
        assert!(!a.denoise && !a.no_denoise && a.denoise_quality.is_none() && a.max_bounces.is_none());
        assert!(!a.exr && !a.check_alignment && !a.force && a.shard.is_none() && a.limit.is_none());
    }

    #[test]
    fn shard_flag() {
        assert_eq!(
            parse(&["--shard", "1/3"]).unwrap().shard,
            Some(ShardSpec::Fixed(crate::util::Shard { index: 1, count: 3 }))
        );
        assert_eq!(parse(&["--shard", "auto/4"]).unwrap().shard, Some(ShardSpec::Auto { count: Some(4) }));
        assert!(parse(&["--shard", "3/3"]).is_err());
    }

    #[test]
    fn engine_and_counts() {
        let a = parse(&["--engine", "workbench", "--samples", "8", "--restart-every", "5", "--limit", "2"])
            .unwrap();
        assert_eq!(
            (a.engine, a.samples, a.restart_every, a.limit),
            (EngineArg::Workbench, Some(8), 5, Some(2))
        );
        assert!(parse(&["--samples", "0"]).is_err());
        assert!(parse(&["--restart-every", "0"]).is_err());
        assert!(parse(&["--engine", "eevee"]).is_err());
    }

    #[test]
    fn device_flag() {
        for (word, want) in [
            ("auto", DeviceArg::Auto),
            ("cpu", DeviceArg::Cpu),
            ("cuda", DeviceArg::Cuda),
            ("optix", DeviceArg::Optix),
            ("hip", DeviceArg::Hip),
            ("oneapi", DeviceArg::Oneapi),
        ] {
            assert_eq!(parse(&["--device", word]).unwrap().device, want);
            assert_eq!(Device::from(want).name(), word);
        }
        assert!(parse(&["--device", "metal"]).is_err());
    }

    #[test]
    fn denoise_flags_override_each_other() {
        let a = parse(&["--no-denoise", "--denoise"]).unwrap();
        assert!(a.denoise && !a.no_denoise);
        let a =
            parse(&["--denoise", "--no-denoise", "--denoise-quality", "high", "--max-bounces", "3"]).unwrap();
        assert!(!a.denoise && a.no_denoise);
        assert_eq!((a.denoise_quality, a.max_bounces), (Some(DenoiseQualityArg::High), Some(3)));
    }

    #[test]
    fn switches_and_paths() {
        let a = parse(&[
            "--exr",
            "--check-alignment",
            "--force",
            "--tileset",
            "t/tileset.json",
            "--max-sse",
            "8",
        ])
        .unwrap();
        assert!(a.exr && a.check_alignment && a.force);
        assert_eq!(a.tileset, Some(PathBuf::from("t/tileset.json")));
        assert_eq!(a.max_sse, 8.0);
        let a = parse(&[
            "--blender",
            "/opt/blender",
            "--blender-python",
            "/p/python",
            "--no-denoise",
            "--min-union",
            "10",
        ])
        .unwrap();
        assert_eq!(a.blender, Some(PathBuf::from("/opt/blender")));
        assert_eq!(a.blender_python, Some(PathBuf::from("/p/python")));
        assert!(a.no_denoise);
        assert_eq!(a.min_union, 10);
    }

    #[test]
    fn missing_inputs_name_the_command_to_run() {
        let dir = tempfile::tempdir().unwrap();
        let global = super::super::Global {
            workdir: dir.path().to_path_buf(),
            scenes: "scenes".into(),
            verbose: 0,
            quiet: true,
            no_progress: true,
            log_every: 30.0,
        };
        let e = run(&parse(&[]).unwrap(), &global).unwrap_err().to_string();
        assert!(e.contains("insgen sample --area demo --camera cam2"), "{e}");
        std::fs::create_dir_all(dir.path().join("demo/cam2")).unwrap();
        std::fs::write(dir.path().join("demo/cam2/poses.jsonl"), "").unwrap();
        let e = run(&parse(&[]).unwrap(), &global).unwrap_err().to_string();
        assert!(e.contains("insgen prepare --area demo"), "{e}");
    }
}
