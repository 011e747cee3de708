//! `insgen demo`: the whole pipeline on the embedded procedural city (scenes/demo*.toml), nothing to
//! download. Each step is the same command a user would type; they are run in order and each one's
//! outputs feed the next.

use anyhow::Context;
use clap::Parser;

use super::{Cli, Global};

/// Runs prepare → sample → render-masks → render-rgb (when Blender's bpy is installed) → export-coco →
/// eval-loc on the demo districts: demo (train), demo-val (val) and demo-test (held out).
///
/// Every labelled frame gets its RGB render, so the COCO dataset at the end lists photos only. The
/// default camera is cam2 at a quarter of its resolution (<scenes>/cameras/cam2-quarter.toml, 480×270),
/// which keeps the whole demo within a few minutes on 2 CPU cores; --camera cam2 renders full frames
/// (about 20 CPU seconds each).
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen demo\n  insgen demo --no-rgb --count 8 --queries 2\n  \
insgen --workdir demo-runs demo --camera cam1")]
pub struct Args {
    /// Camera preset, or a camera TOML file [default: <scenes>/cameras/cam2-quarter.toml].
    #[arg(long, value_name = "PRESET|FILE")]
    pub camera: Option<String>,
    /// Poses sampled per district.
    #[arg(long, value_name = "N", default_value_t = 8)]
    pub count: u32,
    /// Queries localized on the held-out district.
    #[arg(long, value_name = "N", default_value_t = 6)]
    pub queries: u32,
    /// Skip the Blender RGB step even when bpy is installed.
    #[arg(long)]
    pub no_rgb: bool,
}

fn step(global: &Global, words: &[&str]) -> anyhow::Result<()> {
    let mut argv: Vec<String> = vec!["insgen".into()];
    argv.extend(words.iter().map(|s| s.to_string()));
    argv.push("--workdir".into());
    argv.push(global.workdir.display().to_string());
    argv.push("--scenes".into());
    argv.push(global.scenes.display().to_string());
    if global.quiet {
        argv.push("-q".into());
    }
    if global.no_progress {
        argv.push("--no-progress".into());
    }
    argv.push("--log-every".into());
    argv.push(global.log_every.to_string());
    global.printer().status(format!("==> {}", argv[..1 + words.len()].join(" ")));
    let cli = Cli::try_parse_from(&argv).with_context(|| format!("demo step `{}`", words.join(" ")))?;
    super::run_logged(cli, &argv).with_context(|| format!("demo step `{}`", words.join(" ")))
}

/// File name of the demo's default camera under `<scenes>/cameras/`.
pub const DEFAULT_CAMERA_FILE: &str = "cam2-quarter.toml";

/// Runs `insgen demo`.
pub fn run(args: &Args, global: &Global) -> anyhow::Result<()> {
    let districts = ["demo", "demo-val", "demo-test"];
    let count = args.count.to_string();
    // `sample` takes a preset or a file; the later steps take the camera's name (its directory).
    let camera_arg = match &args.camera {
        Some(c) => c.clone(),
        None => global.scenes.join("cameras").join(DEFAULT_CAMERA_FILE).display().to_string(),
    };
    let camera_name = crate::camera::CameraSpec::resolve(&camera_arg)
        .with_context(|| format!("demo camera {camera_arg}"))?
        .name;
    let camera = camera_name.as_str();
    let roots =
        [std::env::current_dir().unwrap_or_default(), std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))];
    let rgb = !args.no_rgb && crate::blender::Launcher::find(None, None, &roots).is_ok();
    if !args.no_rgb && !rgb {
        global.printer().status(
            "==> skipping render-rgb: no Blender found (scripts/setup.sh installs .venv-blender); export-coco \
             then lists no image (--label-only keeps the labels)",
        );
    }
    for d in districts {
        step(global, &["prepare", "--area", d])?;
        step(global, &["sample", "--area", d, "--camera", &camera_arg, "--count", &count])?;
        step(global, &["render-masks", "--area", d, "--camera", camera, "--preview", "4"])?;
        if rgb {
            // Every labelled frame, at render-rgb's measured defaults.
            step(global, &["render-rgb", "--area", d, "--camera", camera])?;
        }
    }
    if rgb {
        step(global, &["export-coco"])?;
    } else {
        step(global, &["export-coco", "--label-only"])?;
    }
    let q = args.queries.to_string();
    step(
        global,
        &[
            "eval-loc",
            "--area",
            "demo-test",
            "--camera",
            camera,
            "--oracle",
            "--limit",
            &q,
            "--cost",
            "instance",
            "--cost",
            "semantic",
            "--render-width",
            "320",
            "--coarse-width",
            "160",
        ],
    )?;
    global.printer().status(format!(
        "==> done: scenes, poses, masks and previews under {0}/<area>/, COCO under {0}/coco/, localization report \
         under {0}/demo-test/{1}/loc/",
        global.workdir.display(),
        camera
    ));
    Ok(())
}
