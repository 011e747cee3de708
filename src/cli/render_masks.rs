//! `insgen render-masks`: instance-ID maps and instance lists for every sampled frame.

use std::path::PathBuf;

use anyhow::{bail, Context};

use crate::label::occlusion::OcclusionMode;
use crate::label::stage::{
    self, MaskPlan, TilesetOcclusion, DEFAULT_MIN_AREA_PX, DEFAULT_OCCLUSION_THRESHOLD_M,
};
use crate::label::Connectivity;
use crate::scene::clutter::ClutterLayer;

/// `--connectivity`: the pixel neighbourhood of instances ([`Connectivity`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ConnectivityArg {
    /// Edge neighbours only.
    #[value(name = "4")]
    Four,
    /// Edge and corner neighbours (default: a building's diagonal-touching pixels stay one instance).
    #[default]
    #[value(name = "8")]
    Eight,
}

impl From<ConnectivityArg> for Connectivity {
    fn from(c: ConnectivityArg) -> Self {
        match c {
            ConnectivityArg::Four => Connectivity::Four,
            ConnectivityArg::Eight => Connectivity::Eight,
        }
    }
}
use crate::render::{DepthRange, RendererChoice, Workload};
use crate::scene::PreparedScene;
use crate::util::ShardSpec;

/// Render instance masks: reads <workdir>/<area>/scene and <camera>/poses.jsonl, writes
/// <camera>/masks/<frame>.png (24-bit RGB building IDs) and <frame>.instances.json.
///
/// Every frame is rendered with exactly its intrinsics and pose (wgpu; a software Vulkan rasteriser
/// such as lavapipe is enough). The ID map stores the building ID losslessly: R = bits 16–23,
/// G = bits 8–15, B = bits 0–7, 0 = background. Connected components of each building give the
/// instances (box, area, truncation at the border, visible pixels of the building).
///
/// Frames whose outputs already exist and verify are skipped, so an interrupted run can simply be
/// started again; --shard splits the work across processes or machines.
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen render-masks --area tokyo --camera cam2\n  \
insgen render-masks --area tokyo --camera cam2 --shard 0/4 --depth\n  \
insgen render-masks --area tokyo --camera cam1 --limit 20 --preview 12 --force")]
pub struct Args {
    /// Area name (a prepared scene under <workdir>/<area>/scene).
    #[arg(long, value_name = "NAME")]
    pub area: String,

    /// Camera whose poses to render (<workdir>/<area>/<camera>/poses.jsonl): a preset, the camera's
    /// name, or the camera TOML file given to `sample`.
    #[arg(long, value_name = "PRESET|NAME|FILE", value_parser = super::parse_camera_dir)]
    pub camera: String,

    /// Render only frames whose line index in poses.jsonl is ≡ I (mod N).
    ///
    /// `auto` takes I and N from a Slurm job array (SLURM_ARRAY_TASK_*); `auto/N` takes I from a
    /// Slurm array or a Kubernetes Indexed Job (JOB_COMPLETION_INDEX) and N as given.
    #[arg(long, value_name = "I/N|auto|auto/N")]
    pub shard: Option<ShardSpec>,

    /// Pixel connectivity of instances (8 keeps diagonal-touching pixels together).
    #[arg(long, value_name = "4|8", value_enum, default_value = "8")]
    pub connectivity: ConnectivityArg,

    /// Leave components smaller than this out of the instance lists.
    ///
    /// They stay in the ID map. The default drops one-to-few-pixel slivers along silhouettes.
    #[arg(long, value_name = "PIXELS", default_value_t = DEFAULT_MIN_AREA_PX)]
    pub min_area: u64,

    /// Add visible_fraction per instance (one extra render per visible building).
    ///
    /// visible_fraction = visible pixels of the building / pixels it covers in the frame when rendered
    /// alone.
    #[arg(long)]
    pub visible_fraction: bool,

    /// Also write <frame>.depth.exr (float32 Z, metres along the optical axis, 0 = no building).
    #[arg(long)]
    pub depth: bool,

    /// Write contact sheets masks/preview_XX.png showing K frames.
    ///
    /// Building colours are blended over rgb/<frame>.png when it exists, else over a shading of the
    /// rendered depth.
    #[arg(long, value_name = "K", default_value_t = 0)]
    pub preview: usize,

    /// Re-render frames whose outputs already exist.
    #[arg(long)]
    pub force: bool,

    /// Render at most N frames (of this shard).
    #[arg(long, value_name = "N")]
    pub limit: Option<usize>,

    /// Near clipping plane.
    #[arg(long, value_name = "METERS", default_value_t = 0.1, hide_short_help = true)]
    pub near: f64,

    /// Far clipping plane.
    #[arg(long, value_name = "METERS", default_value_t = 10_000.0, hide_short_help = true)]
    pub far: f64,

    /// Clutter layers that hide buildings (drawn as background, ID 0).
    ///
    /// A comma-separated list of roads, markings, pavements, ground_cover, trees, cars, rooftop, or
    /// `all` / `none`. Only layers the prepared scene holds matter (`insgen prepare` writes them unless
    /// --no-clutter). A building behind a tree then has no mask pixels there, and visible_fraction and
    /// the COCO area follow. Use the same list for `render-rgb --occluders` so that
    /// --check-alignment compares like with like. Rooftop units are left out by default: they belong to
    /// the building they stand on (`rooftop` makes them punch holes in its mask).
    #[arg(long, value_name = "LAYERS", default_value = "trees,cars", value_parser = parse_occluders)]
    pub occluders: LayerList,

    /// Photogrammetry tileset (tileset.json) whose surface hides LoD buildings.
    ///
    /// Its finest level is read into the area's ENU frame, uploaded once, and its depth rendered at
    /// every frame. Building pixels where the tileset lies in front of the LoD surface by more than
    /// --occlusion-threshold-m (trees, cranes, unmodelled structures) leave the instance before
    /// instances are computed; each <frame>.instances.json records an `occlusion` block with the
    /// occluded / behind / agreeing pixel counts, the consistency score and per-building counts.
    #[arg(long, value_name = "FILE")]
    pub tileset: Option<PathBuf>,

    /// What happens to occluded pixels: removed, or removed and listed in <frame>.ignore.png.
    #[arg(long, value_name = "remove|ignore", value_enum, default_value = "remove", requires = "tileset")]
    pub occlusion: OcclusionArg,

    /// How far in front of the LoD surface the tileset must be for a pixel to count as occluded.
    #[arg(long, value_name = "METERS", default_value_t = DEFAULT_OCCLUSION_THRESHOLD_M, requires = "tileset")]
    pub occlusion_threshold_m: f32,

    /// Renderer: auto (wgpu on any adapter, lavapipe included), gpu, or cpu [default: auto].
    ///
    /// cpu renders with the localizer's CPU rasteriser, which needs no GPU but clips only at --near
    /// 0.1; it agrees with wgpu on all but a few edge pixels per frame. The choice is logged.
    #[arg(
        long,
        value_name = "auto|cpu|gpu",
        default_value = "auto",
        hide_default_value = true,
        hide_short_help = true
    )]
    pub renderer: RendererChoice,
}

/// `--occlusion`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum OcclusionArg {
    /// Occluded pixels become background.
    #[default]
    Remove,
    /// Occluded pixels become background and are written to masks/<frame>.ignore.png (255 = ignore).
    Ignore,
}

impl From<OcclusionArg> for OcclusionMode {
    fn from(a: OcclusionArg) -> Self {
        match a {
            OcclusionArg::Remove => OcclusionMode::Remove,
            OcclusionArg::Ignore => OcclusionMode::Ignore,
        }
    }
}

/// A comma-separated list of clutter layers, as one command-line value.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerList(pub Vec<ClutterLayer>);

/// Parses `--occluders`.
pub fn parse_occluders(s: &str) -> Result<LayerList, String> {
    crate::scene::clutter::parse_layers(s).map(LayerList).map_err(|e| e.to_string())
}

/// The plan and the scene directory, resolved from the arguments (no I/O).
fn plan(args: &Args, global: &super::Global) -> anyhow::Result<(MaskPlan, PathBuf)> {
    if !(args.near > 0.0 && args.far > args.near && args.far.is_finite()) {
        bail!("--near and --far must satisfy 0 < near < far, got near={} m far={} m", args.near, args.far);
    }
    let area_dir = global.workdir.join(&args.area);
    let mut plan = MaskPlan::new(area_dir.join(&args.camera));
    plan.connectivity = args.connectivity.into();
    plan.min_area_px = args.min_area;
    plan.visible_fraction = args.visible_fraction;
    plan.depth = args.depth;
    plan.preview = args.preview;
    plan.force = args.force;
    plan.shard = super::resolve_shard(args.shard)?;
    plan.limit = args.limit;
    plan.range = DepthRange { near_m: args.near, far_m: args.far };
    plan.occluders = args.occluders.0.clone();
    if let Some(path) = &args.tileset {
        let t = args.occlusion_threshold_m;
        if !(t.is_finite() && (0.0..=100.0).contains(&t)) {
            bail!("--occlusion-threshold-m {t}: expected 0 to 100 metres");
        }
        plan.tileset =
            Some(TilesetOcclusion { path: path.clone(), mode: args.occlusion.into(), threshold_m: t });
    }
    Ok((plan, area_dir.join(crate::layout::SCENE_DIR)))
}

/// Runs `insgen render-masks`.
///
/// # Errors
/// Missing inputs (with the command that makes them), GPU problems, and — after all other frames were
/// written — the list of frames that failed.
pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let (plan, scene_dir) = plan(args, global)?;
    if let Some(t) = &args.tileset {
        if !t.is_file() {
            bail!(
                "{}: no such tileset file (give the tileset.json of the photogrammetry model)",
                t.display()
            );
        }
    }
    if !scene_dir.is_dir() {
        bail!(
            "no prepared scene at {}; run `insgen prepare --area {}` first",
            scene_dir.display(),
            args.area
        );
    }
    let poses = plan.poses_path();
    if !poses.is_file() {
        bail!(
            "no poses at {}; run `insgen sample --area {} --camera {}` first",
            poses.display(),
            args.area,
            args.camera
        );
    }
    let scene =
        PreparedScene::load(&scene_dir).with_context(|| format!("loading {}", scene_dir.display()))?;
    let resolved = crate::render::resolve(args.renderer, Workload::Masks)
        .context("setting up the GPU renderer (`--renderer cpu` needs none)")?;
    log::info!("render-masks renders with {} ({})", resolved.renderer.record(), resolved.reason);
    let report = stage::render_masks(&plan, &scene, &*resolved.renderer, &global.printer().progress())
        .with_context(|| format!("rendering masks for {}", plan.camera_dir.display()))?;
    log::info!(
        "{} frames in shard {} of {}: {} rendered ({:.2} frames/s), {} already done, {} failed; {} instances; \
         outputs in {}",
        report.frames_selected,
        plan.shard,
        report.frames_total,
        report.rendered,
        report.frames_per_s,
        report.skipped,
        report.failed.len(),
        report.instances,
        plan.masks_dir().display()
    );
    for p in &report.previews {
        log::info!("preview: {}", p.display());
    }
    if !report.failed.is_empty() {
        for f in &report.failed {
            eprintln!("error: frame {}: {}", f.frame, f.error);
        }
        bail!("{} of {} frames failed (see above)", report.failed.len(), report.frames_selected);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        global: super::super::Global,
        #[command(flatten)]
        args: Args,
    }

    fn parse(extra: &[&str]) -> Result<Cli, clap::Error> {
        let mut argv = vec!["insgen", "--area", "tokyo", "--camera", "cam2"];
        argv.extend_from_slice(extra);
        Cli::try_parse_from(argv)
    }

    mod flags {
        use super::*;

        #[test]
        fn defaults() {
            let c = parse(&[]).unwrap();
            let a = &c.args;
            assert_eq!((a.area.as_str(), a.camera.as_str()), ("tokyo", "cam2"));
            assert_eq!(a.connectivity, ConnectivityArg::Eight);
            assert_eq!(a.min_area, DEFAULT_MIN_AREA_PX);
            assert!(!a.visible_fraction && !a.depth && !a.force);
            assert_eq!((a.preview, a.limit, a.shard), (0, None, None));
            assert_eq!(a.renderer, RendererChoice::Auto);
            assert_eq!(parse(&["--renderer", "cpu"]).unwrap().args.renderer, RendererChoice::Cpu);
        }

        #[test]
        fn area_and_camera_are_required() {
            assert!(Cli::try_parse_from(["insgen", "--area", "x"]).is_err());
            assert!(Cli::try_parse_from(["insgen", "--camera", "cam1"]).is_err());
        }

        #[test]
        fn camera_takes_the_preset_the_name_or_the_file_sample_was_given() {
            let camera = |c: &str| {
                Cli::try_parse_from(["insgen", "--area", "demo", "--camera", c]).map(|c| c.args.camera)
            };
            assert_eq!(camera("cam2").unwrap(), "cam2");
            assert_eq!(camera("cam2-quarter").unwrap(), "cam2-quarter");
            let file = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/cameras/cam2-quarter.toml");
            assert_eq!(camera(file).unwrap(), "cam2-quarter");
            let e = camera("no/such/camera.toml").unwrap_err().to_string();
            assert!(e.contains("no/such/camera.toml"), "{e}");
        }

        #[test]
        fn shard() {
            assert_eq!(
                parse(&["--shard", "2/5"]).unwrap().args.shard,
                Some(ShardSpec::Fixed(crate::util::Shard { index: 2, count: 5 }))
            );
            assert_eq!(
                parse(&["--shard", "auto"]).unwrap().args.shard,
                Some(ShardSpec::Auto { count: None })
            );
            let e = parse(&["--shard", "5/5"]).unwrap_err().to_string();
            assert!(e.contains("below the count"), "{e}");
        }

        #[test]
        fn connectivity() {
            assert_eq!(parse(&["--connectivity", "4"]).unwrap().args.connectivity, ConnectivityArg::Four);
            assert!(parse(&["--connectivity", "6"]).is_err());
        }

        #[test]
        fn min_area_preview_limit() {
            let a = parse(&["--min-area", "1", "--preview", "8", "--limit", "20"]).unwrap().args;
            assert_eq!((a.min_area, a.preview, a.limit), (1, 8, Some(20)));
        }

        #[test]
        fn switches() {
            let a = parse(&["--visible-fraction", "--depth", "--force"]).unwrap().args;
            assert!(a.visible_fraction && a.depth && a.force);
        }

        #[test]
        fn occluders() {
            use ClutterLayer::*;
            assert_eq!(parse(&[]).unwrap().args.occluders.0, vec![Trees, Cars]);
            assert_eq!(
                parse(&["--occluders", "trees,cars,rooftop"]).unwrap().args.occluders.0,
                vec![Trees, Cars, Rooftop]
            );
            assert_eq!(parse(&["--occluders", "none"]).unwrap().args.occluders.0, vec![]);
            assert_eq!(parse(&["--occluders", "cars,roads"]).unwrap().args.occluders.0, vec![Roads, Cars]);
            assert_eq!(parse(&["--occluders", "all"]).unwrap().args.occluders.0.len(), 7);
            let e = parse(&["--occluders", "bushes"]).unwrap_err().to_string();
            assert!(e.contains("unknown clutter layer \"bushes\""), "{e}");
        }

        #[test]
        fn tileset() {
            let c = parse(&[
                "--tileset",
                "t/tileset.json",
                "--occlusion",
                "ignore",
                "--occlusion-threshold-m",
                "2",
            ])
            .unwrap();
            let (p, _) = plan(&c.args, &c.global).unwrap();
            let t = p.tileset.unwrap();
            assert_eq!(t.path, PathBuf::from("t/tileset.json"));
            assert_eq!((t.mode, t.threshold_m), (OcclusionMode::Ignore, 2.0));
            let (p, _) = plan(&parse(&[]).unwrap().args, &parse(&[]).unwrap().global).unwrap();
            assert_eq!(p.tileset, None);
            let c = parse(&["--tileset", "t.json"]).unwrap();
            let t = plan(&c.args, &c.global).unwrap().0.tileset.unwrap();
            assert_eq!((t.mode, t.threshold_m), (OcclusionMode::Remove, DEFAULT_OCCLUSION_THRESHOLD_M));
            assert!(parse(&["--occlusion", "ignore"]).is_err(), "--occlusion needs --tileset");
            let c = parse(&["--tileset", "t.json", "--occlusion-threshold-m", "NaN"]).unwrap();
            assert!(plan(&c.args, &c.global).unwrap_err().to_string().contains("--occlusion-threshold-m"));
        }

        #[test]
        fn near_far() {
            let c = parse(&["--near", "1", "--far", "500"]).unwrap();
            let (p, scene) = plan(&c.args, &c.global).unwrap();
            assert_eq!(p.range, DepthRange { near_m: 1.0, far_m: 500.0 });
            assert_eq!(scene, PathBuf::from("runs/tokyo/scene"));
            assert_eq!(p.camera_dir, PathBuf::from("runs/tokyo/cam2"));
            let c = parse(&["--near", "5", "--far", "1"]).unwrap();
            assert!(plan(&c.args, &c.global).unwrap_err().to_string().contains("0 < near < far"));
        }
    }
}
