//! The binary as a batch system and a person at a terminal see it: Ctrl-C stops between frames with
//! exit status 130 and leaves only complete files, a rerun finishes the job, batch logs get periodic
//! progress lines, and a headless run prints no driver noise.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::util::{repo_scene, scratch_with_scenes};

/// A scratch directory with the demo area prepared and `count` grid poses of a small camera sampled
/// (480×270, so the masks take a few seconds in all).
fn demo_with_poses(count: u32) -> tempfile::TempDir {
    let dir = scratch_with_scenes(&[("demo", repo_scene("demo"))]);
    let run = |args: &[&str]| {
        let o = crate::util::insgen(dir.path(), args);
        assert!(o.status.success(), "{args:?}: {}", crate::util::stderr(&o));
    };
    run(&["prepare", "--area", "demo"]);
    // cam2's field of view at a quarter of its pixels.
    std::fs::write(
        dir.path().join("small.toml"),
        "name = \"small\"\nwidth_px = 480\nheight_px = 270\nsensor_width_mm = 6.4\nsensor_height_mm = 3.6\n\
         hfov_deg = 25.0\nstrategy = \"grid\"\n",
    )
    .unwrap();
    run(&["sample", "--area", "demo", "--camera", "small.toml", "--count", &count.to_string()]);
    dir
}

fn masks(dir: &Path) -> Vec<String> {
    let m = dir.join("runs/demo/small/masks");
    let mut v: Vec<String> = std::fs::read_dir(&m)
        .map(|r| r.filter_map(|e| e.ok()).map(|e| e.file_name().to_string_lossy().into_owned()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn ctrl_c_stops_between_frames_with_130_and_a_rerun_completes() {
    let dir = demo_with_poses(120);
    let mut child = Command::new(env!("CARGO_BIN_EXE_insgen"))
        .args(["render-masks", "--area", "demo", "--camera", "small", "--no-progress"])
        .current_dir(dir.path())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("insgen starts");
    // Wait for the first finished frames, then interrupt as a terminal's Ctrl-C would.
    let started = Instant::now();
    while masks(dir.path()).iter().filter(|n| n.ends_with(".instances.json")).count() < 3 {
        assert!(started.elapsed() < Duration::from_secs(120), "no frame written within 2 minutes");
        if let Some(status) = child.try_wait().unwrap() {
            panic!("render-masks ended before it was interrupted: {status}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let pid = child.id().to_string();
    assert!(Command::new("kill").args(["-INT", &pid]).status().unwrap().success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "stderr: {err}");
    assert!(err.contains("interrupted (Ctrl-C)"), "{err}");
    let after_stop = masks(dir.path());
    assert!(
        after_stop.iter().all(|n| !n.starts_with(".insgen-tmp-")),
        "temporary files left: {after_stop:?}"
    );
    let done = after_stop.iter().filter(|n| n.ends_with(".instances.json")).count();
    assert!(done < 120, "the stop came too late to test anything ({done} frames done)");
    // Every frame listed has its PNG, and every PNG decodes.
    for n in after_stop.iter().filter(|n| n.ends_with(".png")) {
        insgen::scene::IdMap::read_png(&dir.path().join("runs/demo/small/masks").join(n))
            .expect("complete PNG");
    }
    // The rerun does the rest only.
    let o = crate::util::insgen(dir.path(), &["render-masks", "--area", "demo", "--camera", "small", "-v"]);
    assert!(o.status.success(), "{}", crate::util::stderr(&o));
    assert_eq!(masks(dir.path()).iter().filter(|n| n.ends_with(".instances.json")).count(), 120);
}

#[test]
fn a_batch_log_gets_progress_lines_and_no_driver_noise() {
    let dir = demo_with_poses(12);
    // stderr is a pipe here, as in a Slurm log: lines, not a bar; --log-every 0 prints one per frame.
    let o = Command::new(env!("CARGO_BIN_EXE_insgen"))
        .args(["render-masks", "--area", "demo", "--camera", "small", "--log-every", "0"])
        .current_dir(dir.path())
        .env_remove("NODEVICE_SELECT")
        .env_remove("XDG_RUNTIME_DIR")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("frames: ")).collect();
    assert!(lines.len() >= 12, "{err}");
    assert!(lines.last().unwrap().starts_with("frames: 12/12 (100.0 %)"), "{err}");
    assert!(!err.contains("XDG_RUNTIME_DIR"), "driver noise on a headless run: {err}");
    assert!(!err.contains('\r'), "a bar was drawn into a log: {err:?}");
}

#[test]
fn slurm_array_shards_merge_into_what_one_process_writes() {
    let dir = demo_with_poses(10);
    let cwd = dir.path();
    for shard in ["task0", "task1"] {
        let ok = Command::new("cp").args(["-r", "runs", shard]).current_dir(cwd).status().unwrap();
        assert!(ok.success());
    }
    // One process.
    let run = |args: &[&str]| {
        let o = crate::util::insgen(cwd, args);
        assert!(o.status.success(), "{args:?}: {}", crate::util::stderr(&o));
        o
    };
    run(&["render-masks", "--area", "demo", "--camera", "small", "--preview", "0"]);
    run(&["export-coco", "--label-only"]);
    // Two tasks of a Slurm job array submitted as --array=1-2, each in its own (node-local) workdir.
    for (task, workdir) in [("1", "task0"), ("2", "task1")] {
        let o = Command::new(env!("CARGO_BIN_EXE_insgen"))
            .args(["--workdir", workdir, "-v", "render-masks", "--area", "demo", "--camera", "small"])
            .args(["--preview", "0", "--shard", "auto"])
            .env("SLURM_ARRAY_TASK_ID", task)
            .env("SLURM_ARRAY_TASK_MIN", "1")
            .env("SLURM_ARRAY_TASK_MAX", "2")
            .env("RUST_LOG", "info")
            .current_dir(cwd)
            .output()
            .unwrap();
        let err = crate::util::stderr(&o);
        assert!(o.status.success(), "{err}");
        let index = task.parse::<u32>().unwrap() - 1;
        assert!(err.contains(&format!("shard {index}/2 (from the Slurm job array)")), "{err}");
    }
    let frames = |w: &str| crate::util::tree(&cwd.join(w).join("demo/small/masks")).len();
    assert_eq!(frames("task0") + frames("task1"), frames("runs"), "the shards split the frames");
    assert!(frames("task0") > 0 && frames("task1") > 0);
    // A shard of another run (here: other poses) conflicts, and a refused merge writes nothing.
    let poses = cwd.join("task1/demo/small/poses.jsonl");
    let original = std::fs::read(&poses).unwrap();
    std::fs::write(&poses, b"{}\n").unwrap();
    let o = crate::util::insgen(cwd, &["merge", "--workdir", "merged", "task0", "task1"]);
    let err = crate::util::stderr(&o);
    assert!(!o.status.success() && err.contains("differ between the work directories"), "{err}");
    assert!(err.contains("poses.jsonl"), "{err}");
    assert!(!cwd.join("merged").exists(), "a refused merge writes nothing");
    std::fs::write(&poses, original).unwrap();
    // The merge, then the export, equal the single process's byte for byte.
    run(&["merge", "--workdir", "merged", "task0", "task1"]);
    run(&["--workdir", "merged", "export-coco", "--label-only"]);
    let single = crate::util::tree(&cwd.join("runs/demo"));
    let merged = crate::util::tree(&cwd.join("merged/demo"));
    assert_eq!(single.keys().collect::<Vec<_>>(), merged.keys().collect::<Vec<_>>());
    for (k, v) in &single {
        assert!(merged[k] == *v, "{} differs after the merge", k.display());
    }
    for split in ["train", "val", "test"] {
        let name = format!("instances_{split}.json");
        let a = std::fs::read(cwd.join("runs/coco").join(&name)).unwrap();
        let b = std::fs::read(cwd.join("merged/coco").join(&name)).unwrap();
        assert!(a == b, "{name} differs between one process and the merged shards");
    }
}

/// Processes (other than this test) whose command line mentions `needle`.
fn processes_mentioning(needle: &str) -> Vec<String> {
    let me = std::process::id().to_string();
    let mut found = Vec::new();
    for e in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if !name.bytes().all(|b| b.is_ascii_digit()) || name == me {
            continue;
        }
        if let Ok(cmd) = std::fs::read(e.path().join("cmdline")) {
            let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
            if cmd.contains(needle) {
                found.push(format!("{name}: {cmd}"));
            }
        }
    }
    found
}

/// A real SIGINT to `render-rgb` (to insgen alone, as `kill -INT` from a batch system would; a terminal's
/// Ctrl-C also reaches Blender, which process.rs handles the same way): the frame in progress finishes or
/// is dropped, Blender is stopped, the exit status is 130, no temporary or half-written file is left, and a
/// rerun renders only the rest.
#[test]
fn ctrl_c_stops_render_rgb_with_130_and_a_rerun_completes() {
    let Some(py) = crate::blender_support::blender_python() else { return };
    let n = 8;
    let dir = demo_with_poses(n);
    let rgb_dir = dir.path().join("runs/demo/small/rgb");
    let pngs = || -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(&rgb_dir)
            .map(|r| r.filter_map(|e| e.ok()).map(|e| e.file_name().to_string_lossy().into_owned()).collect())
            .unwrap_or_default();
        v.sort();
        v
    };
    let args = |extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> =
            ["render-rgb", "--area", "demo", "--camera", "small", "--samples", "1", "--no-denoise"]
                .iter()
                .map(|s| s.to_string())
                .collect();
        a.extend(["--blender-python".to_string(), py.display().to_string()]);
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let mut child = Command::new(env!("CARGO_BIN_EXE_insgen"))
        .args(args(&["--no-progress"]))
        .current_dir(dir.path())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("insgen starts");
    let started = Instant::now();
    while !pngs().iter().any(|n| n.ends_with(".png") && !n.starts_with(".insgen-tmp-")) {
        assert!(started.elapsed() < Duration::from_secs(300), "no RGB frame within 5 minutes");
        if let Some(status) = child.try_wait().unwrap() {
            panic!("render-rgb ended before it was interrupted: {status}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let pid = child.id().to_string();
    assert!(Command::new("kill").args(["-INT", &pid]).status().unwrap().success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "stderr: {err}");
    assert!(err.contains("interrupted (Ctrl-C)"), "{err}");
    let scratch = dir.path().display().to_string();
    let left = processes_mentioning(&scratch);
    assert!(left.is_empty(), "Blender outlived render-rgb: {left:?}");
    let after = pngs();
    assert!(after.iter().all(|n| !n.starts_with(".insgen-tmp-")), "temporary files left: {after:?}");
    let done: Vec<&String> = after.iter().filter(|n| n.ends_with(".png")).collect();
    assert!(
        !done.is_empty() && done.len() < n as usize,
        "the stop came too late to test anything: {after:?}"
    );
    for png in &done {
        // Every finished frame decodes and has its render metadata.
        insgen::export::raster::read_png_rgb(&rgb_dir.join(png)).expect("complete PNG");
        let meta = rgb_dir.join(png.replace(".png", ".render.json"));
        assert!(meta.is_file(), "{} without its metadata", png);
    }
    // The rerun renders the rest only.
    let o = crate::util::insgen(dir.path(), &args(&[]).iter().map(String::as_str).collect::<Vec<_>>());
    let err = crate::util::stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains(&format!("{} already done", done.len())), "{err}");
    assert_eq!(pngs().iter().filter(|n| n.ends_with(".png")).count(), n as usize);
}

/// Search settings small enough for a test (a few hundred hypotheses per query at 160 px): the
/// merge is checked, not the localizer.
const FAST_EVAL: &[&str] = &[
    "eval-loc",
    "--area",
    "demo",
    "--camera",
    "small",
    "--oracle",
    "--render-width",
    "160",
    "--coarse-width",
    "80",
    "--iterations",
    "3",
    "--coarse-xy",
    "5/5",
    "--coarse-z",
    "0/0",
    "--coarse-yaw",
    "2.5/2.5",
    "--overlays",
    "3",
];

/// The keys of an eval-loc line or summary that are wall-clock times: they differ between any two
/// runs, sharded or not.
const TIMINGS: &[&str] = &[
    "seconds",
    "setup_seconds",
    "median_seconds_per_query",
    "median_setup_seconds",
    "hypotheses_per_second",
];

fn without_timings(mut v: serde_json::Value) -> serde_json::Value {
    if let Some(m) = v.as_object_mut() {
        for k in TIMINGS {
            m.remove(*k);
        }
        // Each search stage's wall-clock seconds (its hypothesis count stays).
        if let Some(stages) = m.get_mut("stages").and_then(|s| s.as_object_mut()) {
            for stage in stages.values_mut() {
                if let Some(st) = stage.as_object_mut() {
                    st.remove("seconds");
                }
            }
        }
    }
    v
}

fn json_lines(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())))
        .unwrap()
}

/// Issue 39: a generated city has no file to hash, so `prepare` records the seed and parameters that
/// define it, and the export carries them on to the COCO files, the manifest and the dataset card.
#[test]
fn the_card_of_a_demo_export_names_the_seed_that_defines_its_city() {
    let dir = demo_with_poses(2);
    let cwd = dir.path();
    for args in [
        &["render-masks", "--area", "demo", "--camera", "small", "--preview", "0"][..],
        &["export-coco", "--label-only"],
    ] {
        let o = crate::util::insgen(cwd, args);
        assert!(o.status.success(), "{args:?}: {}", crate::util::stderr(&o));
    }
    let scene = json(&cwd.join("runs/demo/scene/manifest.json"));
    crate::util::assert_schema("manifest.schema.json", &scene);
    let recorded = &scene["sources"][0]["procedural"];
    // scenes/demo.toml: seed 2026 at EPSG:6677 (-3400 m, -38300 m), the other parameters defaulted.
    assert_eq!(recorded["spec"]["seed"], 2026, "{recorded}");
    assert_eq!(recorded["spec"]["blocks_x"], 10, "{recorded}");
    assert_eq!(recorded["origin"], serde_json::json!({"easting_m": -3400.0, "northing_m": -38300.0}));
    let coco = json(&cwd.join("runs/coco/instances_train.json"));
    crate::util::assert_schema("coco_instances.schema.json", &coco);
    assert_eq!(&coco["info"]["areas"][0]["sources"][0]["procedural"], recorded);
    let manifest = json(&cwd.join("runs/coco/dataset.json"));
    crate::util::assert_schema("dataset.schema.json", &manifest);
    assert_eq!(&manifest["areas"][0]["sources"][0]["procedural"], recorded);
    let card = std::fs::read_to_string(cwd.join("runs/coco/README.md")).unwrap();
    assert!(
        card.contains(
            "  - `procedural`: procedural (insgen's embedded demo city generator; no source file to hash — \
             these parameters define the city: seed 2026; 10 × 10 blocks of 80 m, streets 14 m wide, \
             avenues 30 m wide every 4 streets, grid rotated 17°; ground at 3 m; 5 tower blocks, 2 plazas; \
             heights: low-rise 6–25 m, mid-rise 25–60 m, towers 80–200 m; centre EPSG:6677 E -3400 m N -38300 m)\n"
        ),
        "{card}"
    );
    // A label-only export has no photos to load: no Hugging Face front matter.
    assert!(card.starts_with("# Building-instance dataset"), "{card}");
}

/// Issue 19: `export-coco --shard` and `eval-loc --shard` write parts that `insgen merge` combines into
/// the files one process writes — the COCO files, statistics and figures byte for byte; the
/// localization results and poses in query order, equal but for the wall-clock times, with the summary
/// recomputed from the combined results.
#[test]
fn sharded_export_and_eval_merge_into_what_one_process_writes() {
    let dir = demo_with_poses(7);
    let cwd = dir.path();
    for shard in ["task0", "task1"] {
        let ok = Command::new("cp").args(["-r", "runs", shard]).current_dir(cwd).status().unwrap();
        assert!(ok.success());
    }
    let run = |args: &[&str]| {
        let o = crate::util::insgen(cwd, args);
        assert!(o.status.success(), "{args:?}: {}", crate::util::stderr(&o));
        o
    };
    // One process.
    run(&["render-masks", "--area", "demo", "--camera", "small", "--preview", "0"]);
    run(&["export-coco", "--label-only"]);
    run(FAST_EVAL);
    // Two shards, each in its own work directory; eval-loc as task 1 of a Kubernetes Indexed Job.
    for (k, workdir) in [(0, "task0"), (1, "task1")] {
        let shard = format!("{k}/2");
        run(&["--workdir", workdir, "render-masks", "--area", "demo", "--camera", "small", "--preview", "0"]
            .iter()
            .copied()
            .chain(["--shard", &shard])
            .collect::<Vec<_>>());
        run(&["--workdir", workdir, "export-coco", "--label-only", "--shard", &shard]);
        let o = Command::new(env!("CARGO_BIN_EXE_insgen"))
            .args(["--workdir", workdir])
            .args(FAST_EVAL)
            .args(["--shard", "auto/2"])
            .env("JOB_COMPLETION_INDEX", k.to_string())
            .env("RUST_LOG", "info")
            .current_dir(cwd)
            .output()
            .unwrap();
        let err = crate::util::stderr(&o);
        assert!(o.status.success(), "{err}");
        assert!(err.contains(&format!("shard {k}/2 (from the Kubernetes Indexed Job)")), "{err}");
    }
    let loc = Path::new("demo/small/loc/oracle");
    // Shard 0 of 7 queries holds 4 of them, shard 1 the other 3.
    assert_eq!(json_lines(&cwd.join("task0").join(loc).join("parts/0-of-2/results.jsonl")).len(), 4);
    assert_eq!(json_lines(&cwd.join("task1").join(loc).join("parts/1-of-2/results.jsonl")).len(), 3);
    assert!(!cwd.join("task0/coco/instances_train.json").exists(), "a shard writes a part, not the export");
    // The parts' markers follow schemas/part.schema.json.
    for marker in [
        cwd.join("task0/coco/parts/0-of-2/part.json"),
        cwd.join("task1/coco/parts/1-of-2/part.json"),
        cwd.join("task0").join(loc).join("parts/0-of-2/part.json"),
        cwd.join("task1").join(loc).join("parts/1-of-2/part.json"),
    ] {
        crate::util::assert_schema("part.schema.json", &json(&marker));
    }

    // A part missing: refused, nothing written.
    let o = crate::util::insgen(cwd, &["merge", "--workdir", "lonely", "task0"]);
    let err = crate::util::stderr(&o);
    assert!(!o.status.success() && err.contains("shard(s) 1/2 of the export are missing"), "{err}");
    assert!(!cwd.join("lonely").exists(), "a refused merge writes nothing");

    run(&["merge", "--workdir", "merged", "task0", "task1"]);
    let (single, merged) = (cwd.join("runs"), cwd.join("merged"));
    assert!(!merged.join("coco/parts").exists() && !merged.join(loc).join("parts").exists());
    // COCO: the files, the statistics and the figures byte for byte.
    let coco = crate::util::tree(&single.join("coco"));
    for (name, bytes) in &coco {
        let n = name.to_string_lossy();
        if n == "dataset.json" || n == "README.md" {
            continue; // they quote the command log, which differs (see below)
        }
        assert!(
            std::fs::read(merged.join("coco").join(name)).ok().as_ref() == Some(bytes),
            "coco/{n} differs between one process and the merged shards"
        );
    }
    assert!(coco.contains_key(Path::new("instances_train.json")) && coco.contains_key(Path::new("stats.md")));
    // The manifest equals but for the command log (the shards' commands, not the single run's).
    let manifest = |root: &Path| {
        let mut m = json(&root.join("coco/dataset.json"));
        m.as_object_mut().unwrap().remove("commands");
        m
    };
    assert_eq!(manifest(&single), manifest(&merged));
    // eval-loc: the poses and overlays byte for byte; results and summary but for the times.
    let (a, b) = (crate::util::tree(&single.join(loc)), crate::util::tree(&merged.join(loc)));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, bytes) in &a {
        let n = name.to_string_lossy();
        if n.starts_with("est_poses_") || n.starts_with("overlays/") {
            assert!(b[name] == *bytes, "{n} differs between one process and the merged shards");
        }
    }
    assert_eq!(a.keys().filter(|k| k.starts_with("overlays")).count(), 3);
    let strip = |v: Vec<serde_json::Value>| v.into_iter().map(without_timings).collect::<Vec<_>>();
    let merged_results = json_lines(&merged.join(loc).join("results.jsonl"));
    assert_eq!(merged_results.len(), 7);
    assert_eq!(strip(json_lines(&single.join(loc).join("results.jsonl"))), strip(merged_results.clone()));
    let summary = json(&merged.join(loc).join("summary.json"));
    assert_eq!(
        without_timings(json(&single.join(loc).join("summary.json"))),
        without_timings(summary.clone())
    );
    // The summary's times are those of the combined results (recomputed, not taken from a part).
    let secs: Vec<f64> = merged_results.iter().map(|r| r["seconds"].as_f64().unwrap()).collect();
    assert_eq!(
        summary["median_seconds_per_query"].as_f64(),
        Some(insgen::loc::metrics::median_or_nan(&secs))
    );
    let table = |root: &Path| {
        let md = std::fs::read_to_string(root.join(loc).join("summary.md")).unwrap();
        // Line 1 names the directory, line 3 gives the times.
        md.lines()
            .enumerate()
            .filter(|(i, _)| *i != 0 && *i != 2)
            .map(|(_, l)| l.to_string())
            .collect::<Vec<_>>()
    };
    assert_eq!(table(&single), table(&merged));

    // Parts of another run are refused before anything is written: an evaluation already in the
    // destination that the parts do not combine into…
    let results = merged.join(loc).join("results.jsonl");
    let other_run = std::fs::read_to_string(&results).unwrap().replacen("\"seconds\":", "\"seconds\":1", 1);
    std::fs::write(&results, &other_run).unwrap();
    // The command log records every command, the refused merge too; everything else stays.
    let outputs = |root: &Path| {
        let mut t = crate::util::tree(root);
        t.remove(Path::new("commands.jsonl"));
        t
    };
    let before = outputs(&merged);
    let o = crate::util::insgen(cwd, &["merge", "--workdir", "merged", "task0", "task1"]);
    let err = crate::util::stderr(&o);
    assert!(!o.status.success() && err.contains("conflict with existing ones"), "{err}");
    assert!(err.contains("results.jsonl"), "{err}");
    assert!(outputs(&merged) == before, "a refused merge changes nothing");
    // …eval-loc parts of runs with another seed or map perturbation (same tag, so the same
    // directory), named with the option that differs…
    let part1 = cwd.join("task1").join(loc).join("parts/1-of-2");
    let saved = crate::util::tree(&part1);
    for (extra, differs) in [
        (&["--seed", "7"][..], "seed: 0 vs 7"),
        (&["--map-height-sigma", "2", "--tag", "oracle"][..], "map.perturbation"),
    ] {
        let args: Vec<&str> = ["--workdir", "task1"]
            .iter()
            .chain(FAST_EVAL)
            .chain(extra)
            .copied()
            .chain(["--shard", "1/2"])
            .collect();
        run(&args);
        let o = crate::util::insgen(cwd, &["merge", "--workdir", "other", "task0", "task1"]);
        let err = crate::util::stderr(&o);
        assert!(!o.status.success() && err.contains("are parts of different runs"), "{extra:?}: {err}");
        assert!(err.contains(differs), "{extra:?}: {err}");
        assert!(err.contains("task0/") && err.contains("task1/"), "both parts named: {err}");
        assert!(!cwd.join("other").exists(), "a refused merge writes nothing");
    }
    for (name, bytes) in saved {
        std::fs::write(part1.join(name), bytes).unwrap();
    }
    // …and a COCO part exported with other options.
    run(&["--workdir", "task1", "export-coco", "--label-only", "--per-building", "--shard", "1/2"]);
    let o = crate::util::insgen(cwd, &["merge", "--workdir", "other", "task0", "task1"]);
    let err = crate::util::stderr(&o);
    assert!(!o.status.success() && err.contains("was exported with other options than shard 0/2"), "{err}");
    assert!(!cwd.join("other").exists(), "a refused merge writes nothing");
}

/// Issue 19: `sample --shard` splits the list of areas; the shards' work directories merge into what
/// one process writes for all the areas.
#[test]
fn sharded_sample_of_several_areas_merges_into_what_one_process_writes() {
    let dir = scratch_with_scenes(&[("demo", repo_scene("demo")), ("demo-val", repo_scene("demo-val"))]);
    let cwd = dir.path();
    let run = |args: &[&str]| {
        let o = crate::util::insgen(cwd, args);
        assert!(o.status.success(), "{args:?}: {}", crate::util::stderr(&o));
        o
    };
    run(&["prepare", "--area", "demo", "--area", "demo-val"]);
    for shard in ["task0", "task1"] {
        let ok = Command::new("cp").args(["-r", "runs", shard]).current_dir(cwd).status().unwrap();
        assert!(ok.success());
    }
    let sample = ["sample", "--area", "demo", "--area", "demo-val", "--camera", "cam2", "--count", "5"];
    run(&sample);
    for (k, workdir) in [(0, "task0"), (1, "task1")] {
        let shard = format!("{k}/2");
        let args: Vec<&str> =
            ["--workdir", workdir].iter().chain(&sample).copied().chain(["--shard", &shard]).collect();
        run(&args);
    }
    // Each shard sampled its area only.
    assert!(cwd.join("task0/demo/cam2/poses.jsonl").is_file() && !cwd.join("task0/demo-val/cam2").exists());
    assert!(cwd.join("task1/demo-val/cam2/poses.jsonl").is_file() && !cwd.join("task1/demo/cam2").exists());
    run(&["merge", "--workdir", "merged", "task0", "task1"]);
    for area in ["demo", "demo-val"] {
        let single = crate::util::tree(&cwd.join("runs").join(area));
        let merged = crate::util::tree(&cwd.join("merged").join(area));
        assert_eq!(single.keys().collect::<Vec<_>>(), merged.keys().collect::<Vec<_>>());
        for (k, v) in &single {
            assert!(merged[k] == *v, "{area}/{} differs after the merge", k.display());
        }
    }
    let e = crate::util::insgen(cwd, &["sample", "--area", "demo", "--area", "demo", "--camera", "cam2"]);
    assert!(
        crate::util::stderr(&e).contains("--area \"demo\" is given twice"),
        "{}",
        crate::util::stderr(&e)
    );
}
