//! The `insgen` command line: argument definitions (clap derive) and one `run` function per command.
//!
//! Each command lives in its own file with an `Args` struct and a `run(&Args, &Global)` function; the
//! library stages it calls never see clap types. Errors are `anyhow` chains printed once by `main`.
//!
//! Exit codes: 0 success, 1 failure (the cause chain is printed on stderr), 2 usage error (clap), 130
//! stopped by Ctrl-C between items.

pub mod align;
pub mod completions;
pub mod demo;
pub mod eval_loc;
pub mod export_coco;
pub mod export_hf;
pub mod export_panoptic;
pub mod export_tiles;
pub mod export_yolo;
pub mod init;
pub mod inspect;
pub mod merge;
pub mod prepare;
pub mod progress;
pub mod render_masks;
pub mod render_rgb;
pub mod sample;
pub mod stats;
pub mod verify;

use std::path::PathBuf;

use anyhow::Context;
use clap::{Parser, Subcommand};

/// Synthetic building-instance datasets for UAV visual localization against LoD city models.
#[derive(Debug, Parser)]
#[command(name = "insgen", version, about, max_term_width = 100)]
#[command(
    after_long_help = "Typical run (your own city: `insgen init NAME FOLDER` writes scenes/NAME.toml; use --area NAME):\n  \
insgen prepare --area demo\n  insgen sample --area demo --camera cam2\n  \
insgen render-masks --area demo --camera cam2\n  insgen render-rgb --area demo --camera cam2\n  \
insgen export-coco\n  insgen verify runs/coco\n\nOr all at once on the embedded city: insgen demo\n\n\
Other formats: insgen export-panoptic, insgen export-yolo, insgen export-hf, insgen export-tiles --area demo\n\
Shell completions and man pages: insgen completions bash, insgen man --out target/man"
)]
pub struct Cli {
    /// Options every command takes (`--workdir`, `--scenes`, `-v`, `-q`, …).
    #[command(flatten)]
    pub global: Global,
    /// The command to run, with its own options.
    #[command(subcommand)]
    pub command: Command,
}

/// Options shared by every command.
#[derive(Debug, Clone, clap::Args)]
pub struct Global {
    /// Directory where all outputs go (one sub-directory per area).
    #[arg(long, global = true, value_name = "DIR", default_value = "runs")]
    pub workdir: PathBuf,
    /// Directory holding the area definitions (`<area>.toml`).
    #[arg(long, global = true, value_name = "DIR", default_value = "scenes")]
    pub scenes: PathBuf,
    /// Print more (repeat for debug logs); RUST_LOG overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// Print only errors.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// Hide progress bars and progress lines.
    #[arg(long, global = true)]
    pub no_progress: bool,
    /// When stderr is not a terminal (a batch log), print a progress line every this many seconds.
    #[arg(long, global = true, value_name = "SECONDS", default_value_t = 30.0, hide_short_help = true)]
    pub log_every: f64,
}

impl Global {
    /// The output policy of this run (see [`progress::Printer`]).
    pub fn printer(&self) -> progress::Printer {
        progress::Printer::from_global(self)
    }
}

// One value per process, parsed once: the size difference between variants costs nothing.
#[allow(clippy::large_enum_variant)]
/// The `insgen` commands, one variant each, with the options of that command.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Write a commented scene file for a new area from its building-model files.
    Init(init::Args),
    /// Read an area's LoD models and write its instanced scene (GLB + manifest + building table).
    Prepare(prepare::Args),
    /// Run the whole pipeline on the embedded procedural demo city.
    Demo(demo::Args),
    /// Sample UAV camera poses (ground truth and priors) over an area.
    Sample(sample::Args),
    /// Render pixel-exact instance-ID masks (wgpu) for an area's sampled poses.
    RenderMasks(render_masks::Args),
    /// Render photoreal RGB frames with Blender (bpy) at the sampled poses.
    RenderRgb(render_rgb::Args),
    /// Export COCO instance annotations per geographic split.
    ExportCoco(export_coco::Args),
    /// Dataset statistics (per split) with histograms and contact sheets.
    Stats(stats::Args),
    /// Localize queries with the instance-silhouette localizer and report recall.
    EvalLoc(eval_loc::Args),
    /// Summarise a building-model file or a prepared area.
    Inspect(inspect::Args),
    /// Check an exported dataset against its manifest (files, sizes, masks, RGB frames).
    Verify(verify::Args),
    /// Merge the work directories of shards (job-array tasks) into --workdir.
    Merge(merge::Args),
    /// Export COCO panoptic segmentation from a COCO export.
    ExportPanoptic(export_panoptic::Args),
    /// Export YOLO segmentation labels (Ultralytics) from a COCO export.
    ExportYolo(export_yolo::Args),
    /// Write the Hugging Face `datasets` image-folder metadata of a COCO export.
    ExportHf(export_hf::Args),
    /// Write a prepared area as a 3D Tiles 1.1 tileset placed on the globe.
    ExportTiles(export_tiles::Args),
    /// Measure and correct the LoD model's offset from a photogrammetry tileset.
    Align(align::Args),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    Completions(completions::CompletionsArgs),
    /// Write man pages generated from these definitions.
    Man(completions::ManArgs),
}

impl Command {
    /// The subcommand as typed (`render-masks`).
    pub fn name(&self) -> &'static str {
        match self {
            Command::Init(_) => "init",
            Command::Prepare(_) => "prepare",
            Command::Demo(_) => "demo",
            Command::Sample(_) => "sample",
            Command::RenderMasks(_) => "render-masks",
            Command::RenderRgb(_) => "render-rgb",
            Command::ExportCoco(_) => "export-coco",
            Command::Stats(_) => "stats",
            Command::EvalLoc(_) => "eval-loc",
            Command::Inspect(_) => "inspect",
            Command::Verify(_) => "verify",
            Command::Merge(_) => "merge",
            Command::ExportPanoptic(_) => "export-panoptic",
            Command::ExportYolo(_) => "export-yolo",
            Command::ExportHf(_) => "export-hf",
            Command::ExportTiles(_) => "export-tiles",
            Command::Align(_) => "align",
            Command::Completions(_) => "completions",
            Command::Man(_) => "man",
        }
    }
}

/// Runs the parsed command line `argv` and, for commands that write into the workdir, logs it in
/// `<workdir>/commands.jsonl` (the dataset manifest's provenance; see [`crate::util::provenance`]).
pub fn run_logged(cli: Cli, argv: &[String]) -> anyhow::Result<()> {
    let logged = !matches!(
        cli.command,
        Command::Demo(_)
            | Command::Init(_)
            | Command::Inspect(_)
            | Command::Verify(_)
            | Command::Completions(_)
            | Command::Man(_)
    );
    let workdir = cli.global.workdir.clone();
    let name = cli.command.name().to_string();
    let started = std::time::Instant::now();
    let result = run(cli);
    if logged && workdir.is_dir() {
        use crate::util::provenance::{self, CommandRecord};
        let record = CommandRecord {
            argv: argv.to_vec(),
            command: name,
            ok: result.is_ok(),
            seconds: started.elapsed().as_secs_f64(),
            insgen_version: provenance::VERSION.into(),
            git_commit: provenance::GIT_COMMIT.into(),
        };
        if let Err(e) = provenance::append_command(&workdir, &record) {
            log::warn!("cannot log the command: {}", crate::util::error_chain(&e));
        }
    }
    result
}

/// Runs the parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    let g = &cli.global;
    match &cli.command {
        Command::Init(a) => init::run(a, g),
        Command::Prepare(a) => prepare::run(a, g),
        Command::Demo(a) => demo::run(a, g),
        Command::Sample(a) => sample::run(a, g),
        Command::RenderMasks(a) => render_masks::run(a, g),
        Command::RenderRgb(a) => render_rgb::run(a, g),
        Command::ExportCoco(a) => export_coco::run(a, g),
        Command::Stats(a) => stats::run(a, g),
        Command::EvalLoc(a) => eval_loc::run(a, g),
        Command::Inspect(a) => inspect::run(a, g),
        Command::Verify(a) => verify::run(a, g),
        Command::Merge(a) => merge::run(a, g),
        Command::ExportPanoptic(a) => export_panoptic::run(a, g),
        Command::ExportYolo(a) => export_yolo::run(a, g),
        Command::ExportHf(a) => export_hf::run(a, g),
        Command::ExportTiles(a) => export_tiles::run(a, g),
        Command::Align(a) => align::run(a, g),
        Command::Completions(a) => completions::run_completions(a, g),
        Command::Man(a) => completions::run_man(a, g),
    }
}

/// `--camera` of the stages after `sample`: a preset (`cam2`), the camera's name (its directory under
/// the area, e.g. `cam2-quarter`) or the camera TOML file `sample` was given, resolved to that name.
pub(crate) fn parse_camera_dir(arg: &str) -> Result<String, String> {
    if !crate::camera::CameraSpec::names_a_file(arg) {
        return Ok(arg.to_string());
    }
    crate::camera::CameraSpec::resolve(arg).map(|spec| spec.name).map_err(|e| crate::util::error_chain(&e))
}

/// The shard a `--shard` asks for: fixed, or from the scheduler's environment (logged with its
/// source, so a task's log says which part of the work it did).
pub(crate) fn resolve_shard(spec: Option<crate::util::ShardSpec>) -> anyhow::Result<crate::util::Shard> {
    let Some(spec) = spec else { return Ok(crate::util::Shard::default()) };
    let (shard, from) = spec.resolve(|k| std::env::var(k).ok()).context("--shard")?;
    if let Some(scheduler) = from {
        log::info!("shard {shard} (from the {scheduler})");
    }
    Ok(shard)
}

/// Parsing one subcommand's flags together with the global ones, as the binary does — for the
/// commands' unit tests.
/// Logs what the export left out and how many images and annotations each split got.
pub(crate) fn log_coco_export(plan: &crate::export::ExportPlan, ex: &crate::export::coco::Export) {
    if ex.frames_without_masks > 0 {
        log::warn!(
            "{} frame(s) in poses.jsonl have no ID map or instance file yet and were skipped; run \
             `insgen render-masks` for them",
            ex.frames_without_masks
        );
    }
    for m in &ex.frames_without_rgb {
        log::warn!(
            "{}/{}: {} labelled frame(s) have no RGB frame{} and were left out; render them with `insgen \
             render-rgb --area {} --camera {}`{}",
            m.area,
            m.camera,
            m.frames,
            if m.broken.is_empty() {
                String::new()
            } else {
                format!(
                    " (broken: {})",
                    m.broken.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
                )
            },
            m.area,
            m.camera,
            if plan.label_only { "" } else { ", or export labels alone with --label-only" }
        );
    }
    let d = ex.dropped;
    if d.small + d.low_visibility + d.truncated + d.empty_images > 0 {
        log::info!(
            "filtered out: {} small, {} barely visible, {} truncated annotations; {} empty images",
            d.small,
            d.low_visibility,
            d.truncated,
            d.empty_images
        );
    }
    if d.low_consistency_images > 0 {
        log::warn!(
            "{} frame(s) scored below --min-consistency {} (LoD model vs tileset) and were left out",
            d.low_consistency_images,
            plan.filters.min_consistency.unwrap_or(0.0)
        );
    }
    for (split, ds) in &ex.datasets {
        log::info!("{split}: {} images, {} annotations", ds.images.len(), ds.annotations.len());
    }
}

#[cfg(test)]
pub(crate) mod testing {
    use clap::Parser;

    #[derive(Debug, Parser)]
    pub(crate) struct Parsed<A: clap::Args> {
        #[command(flatten)]
        pub global: super::Global,
        #[command(flatten)]
        pub args: A,
    }

    /// `argv` without the program name.
    pub(crate) fn parse<A: clap::Args>(argv: &[&str]) -> Result<Parsed<A>, clap::Error> {
        Parsed::try_parse_from(std::iter::once("insgen").chain(argv.iter().copied()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn cli_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn every_command_shows_examples_in_long_help() {
        let mut cmd = Cli::command();
        for sub in cmd.get_subcommands_mut() {
            let name = sub.get_name().to_string();
            let help = sub.render_long_help().to_string();
            assert!(
                help.contains("Example") && help.contains(&format!("insgen {name}")),
                "`insgen {name} --help` shows no example:\n{help}"
            );
        }
    }

    #[test]
    fn prepare_parses_areas() {
        let cli = Cli::try_parse_from(["insgen", "prepare", "--area", "demo", "--area", "tokyo"]).unwrap();
        match cli.command {
            Command::Prepare(a) => assert_eq!(a.areas, ["demo", "tokyo"]),
            _ => panic!("wrong command"),
        }
        assert!(Cli::try_parse_from(["insgen", "prepare"]).is_err());
    }
}
