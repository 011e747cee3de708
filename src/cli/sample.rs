//! `insgen sample`: camera poses for one prepared area and one camera.
//!
//! Reads `<workdir>/<area>/scene/` (written by `insgen prepare`) and the optional `[sampling]` table of
//! `<scenes>/<area>.toml`; writes `<workdir>/<area>/<camera>/` (poses.jsonl, priors.jsonl,
//! colmap/{cameras,images,points3D}.txt, camera.json, sampling.json, flight_plan.png). The flags become a
//! [`Plan`] per area (paths resolved, camera looked up, settings validated) before any work starts.
//!
//! Sharding (`--shard i/N`) splits the list of `--area`s, not the poses of one area: an area's sampler
//! is one random stream of candidates, accepted or rejected in turn and joined into sequences, so the
//! pose at index k depends on every candidate before it and no shard could produce its indices without
//! running the others' first. Each area's files depend only on that area, the camera and the seed, so
//! the shards of a list of areas write exactly what one process writes for the whole list.

use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::camera::sample::{sample_area, write_sample, SampleOutput};
use crate::camera::{CameraSpec, SamplingConfig, Trajectory};
use crate::scene::PreparedScene;
use crate::util::Progress;

/// Sample camera poses (grid, regular or irregular flights) over a prepared area.
///
/// Reads <workdir>/<area>/scene/ (from `insgen prepare`) and the optional [sampling] table of
/// <scenes>/<area>.toml; writes <workdir>/<area>/<camera>/poses.jsonl, priors.jsonl,
/// colmap/{cameras,images,points3D}.txt, camera.json, sampling.json and flight_plan.png.
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen sample --area demo --camera cam2\n  \
insgen sample --area demo --area demo-val --area demo-test --camera cam2 --shard auto/3\n  \
insgen sample --area demo --camera cam1 --count 300 --seed 7\n  \
insgen sample --area demo --camera scenes/cameras/example.toml --strategy regular")]
pub struct Args {
    /// Area to sample (a prepared scene under <workdir>/<area>/scene); repeat for several.
    #[arg(long = "area", value_name = "NAME", required = true)]
    pub areas: Vec<String>,
    /// Camera: a preset (cam1, cam2, cam3) or a camera TOML file.
    ///
    /// cam1: 1600×1200, 45° hFOV (irregular flights); cam2: 1920×1080, 25° (grid); cam3: as cam2
    /// (regular survey lines). A custom camera file follows schemas/camera.schema.json.
    #[arg(long, value_name = "PRESET|FILE")]
    pub camera: String,
    /// Number of poses [default: the strategy's natural coverage].
    #[arg(long, value_name = "N")]
    pub count: Option<usize>,
    /// Random seed; the same seed gives byte-identical files. Each frame's prior error is drawn from
    /// the seed and the frame's name, so areas sampled with one seed get independent priors.
    #[arg(long, value_name = "SEED", default_value_t = 0)]
    pub seed: u64,
    /// Strategy: grid, regular or irregular [default: the camera's].
    #[arg(long, value_name = "STRATEGY", value_parser = parse_strategy)]
    pub strategy: Option<Trajectory>,
    /// Sample only this shard of the --area list (I/N, or auto from a Slurm/Kubernetes job array).
    ///
    /// The areas at positions ≡ I (mod N) of the list as given. Each area is sampled whole, as by
    /// one process: its poses depend on its own random stream only.
    #[arg(long, value_name = "I/N|auto")]
    pub shard: Option<crate::util::ShardSpec>,
}

fn parse_strategy(s: &str) -> Result<Trajectory, crate::camera::record::UnknownTrajectory> {
    s.parse()
}

/// The validated run: what `sample` will read and write.
#[derive(Debug, Clone)]
pub struct Plan {
    /// The area.
    pub area: String,
    /// `<workdir>/<area>/scene`.
    pub scene_dir: PathBuf,
    /// `<workdir>/<area>/<camera>`.
    pub out_dir: PathBuf,
    /// The camera, with `strategy` already overridden by `--strategy`.
    pub camera: CameraSpec,
    /// Poses to sample (`--count`); `None`: full coverage.
    pub count: Option<usize>,
    /// Random seed.
    pub seed: u64,
    /// The `[sampling]` settings.
    pub config: SamplingConfig,
    /// The scene file the `[sampling]` table came from, if there was one.
    pub config_file: Option<PathBuf>,
}

impl Plan {
    /// Resolves and checks the flags for `area` (one of `args.areas`).
    ///
    /// # Errors
    /// An unknown area (listing the prepared areas and scene files), an unknown camera (listing the
    /// presets), an invalid camera file or `[sampling]` table.
    pub fn for_area(area: &str, args: &Args, global: &super::Global) -> anyhow::Result<Plan> {
        let given = area;
        let area = area.trim();
        if area.is_empty() || area.contains(['/', '\\']) || area == "." || area == ".." {
            anyhow::bail!("--area {given:?}: expected an area name (as in <scenes>/<area>.toml), not a path");
        }
        let scene_dir = global.workdir.join(area).join(crate::layout::SCENE_DIR);
        let manifest = scene_dir.join(crate::scene::artifact::MANIFEST_FILE);
        if !manifest.is_file() {
            anyhow::bail!("{}", unknown_area_message(area, &global.workdir, &global.scenes, &manifest));
        }
        let mut camera =
            CameraSpec::resolve(&args.camera).with_context(|| format!("--camera {}", args.camera))?;
        if let Some(s) = args.strategy {
            camera.strategy = s;
        }
        if args.count == Some(0) {
            anyhow::bail!("--count 0: ask for at least one pose (or leave --count out for full coverage)");
        }
        let scene_file = global.scenes.join(format!("{area}.toml"));
        let (config, config_file) = if scene_file.is_file() {
            let text = std::fs::read_to_string(&scene_file)
                .with_context(|| format!("reading {}", scene_file.display()))?;
            (SamplingConfig::from_scene_toml(&text, Some(&scene_file))?, Some(scene_file))
        } else {
            log::info!("{} not found: using the default [sampling] settings", scene_file.display());
            (SamplingConfig::default(), None)
        };
        let out_dir = global.workdir.join(area).join(&camera.name);
        Ok(Plan {
            area: area.to_string(),
            scene_dir,
            out_dir,
            camera,
            count: args.count,
            seed: args.seed,
            config,
            config_file,
        })
    }
}

/// The error text for an area without a prepared scene.
fn unknown_area_message(area: &str, workdir: &Path, scenes: &Path, manifest: &Path) -> String {
    let list = |dir: &Path, keep: &dyn Fn(&Path) -> Option<String>| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .map(|rd| rd.filter_map(|e| e.ok()).filter_map(|e| keep(&e.path())).collect())
            .unwrap_or_default();
        v.sort();
        v
    };
    let prepared = list(workdir, &|p| {
        p.join(crate::layout::SCENE_DIR)
            .join(crate::scene::artifact::MANIFEST_FILE)
            .is_file()
            .then(|| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .flatten()
    });
    let defined = list(scenes, &|p| {
        (p.extension().is_some_and(|e| e == "toml") && p.is_file())
            .then(|| p.file_stem().map(|n| n.to_string_lossy().into_owned()))
            .flatten()
    });
    let show = |v: &[String]| if v.is_empty() { "none".to_string() } else { v.join(", ") };
    let mut msg = format!("unknown area {area:?}: no prepared scene at {}", manifest.display());
    msg.push_str(&format!("\n  prepared areas in {}: {}", workdir.display(), show(&prepared)));
    msg.push_str(&format!("\n  area files in {}: {}", scenes.display(), show(&defined)));
    if defined.iter().any(|d| d == area) {
        msg.push_str(&format!("\n  run `insgen prepare --area {area}` first"));
    }
    msg
}

/// Samples and writes the outputs of `plan` for an already loaded scene.
///
/// # Errors
/// Sampling errors (impossible settings, too few valid poses) and write errors, with context.
pub fn execute(plan: &Plan, scene: &PreparedScene, progress: &dyn Progress) -> anyhow::Result<SampleOutput> {
    if scene.manifest.area != plan.area {
        log::warn!(
            "{}: the manifest names area {:?}, sampling it as {:?}",
            plan.scene_dir.display(),
            scene.manifest.area,
            plan.area
        );
    }
    let out = sample_area(scene, &plan.camera, &plan.config, plan.count, plan.seed, progress)
        .with_context(|| format!("sampling {} poses for area {}", plan.camera.name, plan.area))?;
    write_sample(&plan.out_dir, scene, &out)
        .with_context(|| format!("writing the sampled poses to {}", plan.out_dir.display()))?;
    Ok(out)
}

/// The plans of `shard`'s areas (positions ≡ i mod N of `args.areas`), all checked before any runs.
///
/// # Errors
/// An area given twice; the errors of [`Plan::for_area`].
pub fn plans(args: &Args, global: &super::Global, shard: crate::util::Shard) -> anyhow::Result<Vec<Plan>> {
    let mut seen = std::collections::BTreeSet::new();
    if let Some(twice) = args.areas.iter().find(|a| !seen.insert(a.trim())) {
        anyhow::bail!("--area {twice:?} is given twice");
    }
    args.areas
        .iter()
        .enumerate()
        .filter(|(i, _)| shard.contains(*i))
        .map(|(_, area)| Plan::for_area(area, args, global))
        .collect()
}

/// Runs `insgen sample`.
pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let shard = super::resolve_shard(args.shard)?;
    let plans = plans(args, global, shard)?;
    if plans.is_empty() {
        log::warn!("shard {shard} of {} area(s) holds none: nothing to sample", args.areas.len());
    }
    for plan in &plans {
        run_plan(plan, global)?;
    }
    Ok(())
}

/// Samples one area and prints its summary.
fn run_plan(plan: &Plan, global: &super::Global) -> anyhow::Result<()> {
    let scene = PreparedScene::load(&plan.scene_dir)
        .with_context(|| format!("loading the prepared scene of area {}", plan.area))?;
    let printer = global.printer();
    let out = execute(plan, &scene, &printer.progress())?;
    let s = &out.stats;
    printer.summary(format!(
        "{}: {} {} poses in {} sequences ({} candidates) → {}; prior median error {:.1} m / {:.2}°",
        plan.area,
        s.accepted,
        out.strategy,
        s.sequences,
        s.candidates,
        plan.out_dir.display(),
        s.prior_median_translation_m,
        s.prior_median_rotation_deg
    ));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct T {
        #[command(flatten)]
        args: Args,
    }

    #[test]
    fn flags_parse() {
        let t = T::try_parse_from(["x", "--area", "demo", "--camera", "cam1", "--count", "5", "--seed", "9"])
            .unwrap();
        assert_eq!((t.args.areas.as_slice(), t.args.camera.as_str()), (&["demo".to_string()][..], "cam1"));
        assert_eq!((t.args.count, t.args.seed, t.args.strategy, t.args.shard), (Some(5), 9, None, None));
        let t = T::try_parse_from(["x", "--area", "a", "--area", "b", "--camera", "cam2", "--shard", "1/2"])
            .unwrap();
        assert_eq!(t.args.areas, ["a", "b"]);
        assert_eq!(
            t.args.shard,
            Some(crate::util::ShardSpec::Fixed(crate::util::Shard { index: 1, count: 2 }))
        );
        let t =
            T::try_parse_from(["x", "--area", "a", "--camera", "c.toml", "--strategy", "regular"]).unwrap();
        assert_eq!(t.args.strategy, Some(Trajectory::Regular));
        let e =
            T::try_parse_from(["x", "--area", "a", "--camera", "cam1", "--strategy", "spiral"]).unwrap_err();
        assert!(e.to_string().contains("expected one of grid, regular, irregular"), "{e}");
        assert!(T::try_parse_from(["x", "--camera", "cam1"]).is_err());
    }
}
