//! `insgen demo`: the whole pipeline on the embedded procedural city (scenes/demo*.toml), nothing to
//! download. Each step is the same command a user would type; they are run in order and each one's
//! outputs feed the next.

use anyhow::Context;
use clap::Parser;

use super::{Cli, Global};

/// Runs prepare → sample → render-masks → export-coco → eval-loc (→ render-rgb when Blender's bpy is
/// installed) on the demo districts: demo (train), demo-val (val) and demo-test (held out).
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen demo\n  insgen demo --no-rgb --count 8 --queries 2\n  \
insgen --workdir /tmp/demo-runs demo --camera cam1")]
pub struct Args {
    /// Camera preset for the demo.
    #[arg(long, value_name = "PRESET", default_value = "cam2")]
    pub camera: String,
    /// Poses sampled per district.
    #[arg(long, value_name = "N", default_value_t = 24)]
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

pub fn run(args: &Args, global: &Global) -> anyhow::Result<()> {
    let districts = ["demo", "demo-val", "demo-test"];
    let count = args.count.to_string();
    for d in districts {
        step(global, &["prepare", "--area", d])?;
        step(global, &["sample", "--area", d, "--camera", &args.camera, "--count", &count])?;
        step(global, &["render-masks", "--area", d, "--camera", &args.camera, "--preview", "4"])?;
    }
    let blender_python = std::path::Path::new(".venv-blender/bin/python");
    if !args.no_rgb && blender_python.exists() {
        // One frame at 16 samples: a cam2 frame at full resolution takes minutes on 2 cores
        // (bench/versus_blender.md); render more with `insgen render-rgb`.
        step(
            global,
            &["render-rgb", "--area", "demo", "--camera", &args.camera, "--limit", "1", "--samples", "16"],
        )?;
    } else if !args.no_rgb {
        global
            .printer()
            .status("==> skipping render-rgb: .venv-blender is missing (scripts/setup.sh installs it)");
    }
    step(global, &["export-coco"])?;
    let q = args.queries.to_string();
    step(
        global,
        &[
            "eval-loc",
            "--area",
            "demo-test",
            "--camera",
            &args.camera,
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
        args.camera
    ));
    Ok(())
}
