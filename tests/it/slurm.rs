//! A real Slurm: Debian's slurmctld + slurmd (with MUNGE) on localhost, started from a temporary
//! `slurm.conf`, runs `scripts/slurm/submit.sh` on the demo area as a 4-task job array; the merged
//! dataset must equal a single-process run byte for byte, and `resubmit.sh` must run only the task
//! whose shard is missing. Every daemon started is stopped by its PID, whatever the outcome.
//!
//! Needs root and the Debian package registry (scripts/slurm/install_local.sh installs the packages);
//! otherwise it is skipped with the reason, except under `CI=true`.
//!
//! Without Slurm, `submit.sh --dry-run` is checked for the job chain it would submit (the eval-loc
//! array included), and `task.sh`'s `loc` and `merge` stages for the commands they run, with a stand-in
//! for the insgen binary that records its arguments.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use crate::util::{repo, repo_scene, scratch_with_scenes};

/// A single-node cluster in a temporary directory; dropping it stops its daemons.
struct Cluster {
    dir: tempfile::TempDir,
    pid_files: Vec<PathBuf>,
}

impl Cluster {
    fn conf(&self) -> PathBuf {
        self.dir.path().join("slurm.conf")
    }

    fn start() -> Cluster {
        let dir = tempfile::tempdir().unwrap();
        let d = &dir.path().to_path_buf();
        for sub in ["spool", "state", "log", "munge"] {
            std::fs::create_dir_all(d.join(sub)).unwrap();
        }
        let mut cluster = Cluster { pid_files: Vec::new(), dir };
        // MUNGE with a key and socket of its own, so nothing of the machine's is touched.
        let key: Vec<u8> = (0..1024u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect();
        let key_file = d.join("munge/munge.key");
        std::fs::write(&key_file, key).unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&key_file, std::fs::Permissions::from_mode(0o600)).unwrap();
        let socket = d.join("munge/socket");
        cluster.pid_files.push(d.join("munge/munged.pid"));
        daemon(Command::new("munged").args([
            format!("--key-file={}", key_file.display()),
            format!("--socket={}", socket.display()),
            format!("--pid-file={}", d.join("munge/munged.pid").display()),
            format!("--log-file={}", d.join("munge/munged.log").display()),
            format!("--seed-file={}", d.join("munge/seed").display()),
            "--force".to_string(),
        ]));
        let host = String::from_utf8(Command::new("hostname").arg("-s").output().unwrap().stdout).unwrap();
        let host = host.trim();
        let cpus = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
        // Ports of this process's own, so a second run on the machine does not collide.
        let port = 20_000 + (std::process::id() % 20_000) as u16;
        let conf = format!(
            "ClusterName=insgentest\nSlurmctldHost={host}(127.0.0.1)\nSlurmctldPort={port}\nSlurmdPort={}\n\
             SlurmUser=root\nSlurmdUser=root\nAuthType=auth/munge\nAuthInfo=socket={}\nCredType=cred/munge\n\
             StateSaveLocation={d}/state\nSlurmdSpoolDir={d}/spool\nSlurmctldPidFile={d}/slurmctld.pid\n\
             SlurmdPidFile={d}/slurmd.pid\nSlurmctldLogFile={d}/log/slurmctld.log\nSlurmdLogFile={d}/log/slurmd.log\n\
             ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\nJobAcctGatherType=jobacct_gather/none\n\
             AccountingStorageType=accounting_storage/none\nSelectType=select/cons_tres\nSelectTypeParameters=CR_CPU\n\
             SchedulerType=sched/backfill\nMpiDefault=none\nReturnToService=2\nMailProg=/bin/true\n\
             NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} State=UNKNOWN\n\
             PartitionName=test Nodes=ALL Default=YES MaxTime=INFINITE State=UP\n",
            port + 1,
            socket.display(),
            d = d.display(),
        );
        std::fs::write(cluster.conf(), conf).unwrap();
        cluster.pid_files.push(d.join("slurmctld.pid"));
        daemon(Command::new("slurmctld").arg("-f").arg(cluster.conf()));
        cluster.pid_files.push(d.join("slurmd.pid"));
        daemon(Command::new("slurmd").arg("-f").arg(cluster.conf()));
        // Wait until the node takes jobs.
        let started = Instant::now();
        loop {
            let o = cluster.cmd("sinfo").args(["-h", "-o", "%t"]).output().unwrap();
            let state = String::from_utf8_lossy(&o.stdout).trim().to_string();
            if state == "idle" {
                break;
            }
            assert!(
                started.elapsed() < Duration::from_secs(60),
                "the node is not idle after 60 s (state {state:?}); slurmd log:\n{}",
                std::fs::read_to_string(d.join("log/slurmd.log")).unwrap_or_default()
            );
            std::thread::sleep(Duration::from_millis(300));
        }
        cluster
    }

    /// A Slurm client command talking to this cluster.
    fn cmd(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", self.conf());
        c
    }

    fn logs(&self, workdir: &Path) -> String {
        let mut out = String::new();
        for dir in [workdir.join("slurm/logs"), self.dir.path().join("log")] {
            let Ok(entries) = std::fs::read_dir(&dir) else { continue };
            for e in entries.flatten() {
                let text = std::fs::read_to_string(e.path()).unwrap_or_default();
                let tail: String = text
                    .lines()
                    .rev()
                    .take(15)
                    .collect::<Vec<_>>()
                    .into_iter()
                    .rev()
                    .collect::<Vec<_>>()
                    .join("\n");
                out.push_str(&format!("--- {}\n{tail}\n", e.path().display()));
            }
        }
        out
    }

    /// Waits until the queue is empty (bounded), or fails with the logs.
    fn wait_idle(&self, workdir: &Path, bound: Duration) {
        let started = Instant::now();
        loop {
            let o = self.cmd("squeue").args(["-h", "-o", "%i %t"]).output().unwrap();
            if o.status.success() && o.stdout.is_empty() {
                return;
            }
            assert!(
                started.elapsed() < bound,
                "jobs still queued after {bound:?}: {}\n{}",
                String::from_utf8_lossy(&o.stdout),
                self.logs(workdir)
            );
            std::thread::sleep(Duration::from_millis(500));
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        // slurmd, then slurmctld, then munged: each by the PID it wrote.
        for pid_file in self.pid_files.iter().rev() {
            if let Some(pid) =
                std::fs::read_to_string(pid_file).ok().and_then(|s| s.trim().parse::<u32>().ok())
            {
                let _ = Command::new("kill").arg(pid.to_string()).status();
                for _ in 0..50 {
                    if !Path::new(&format!("/proc/{pid}")).exists() {
                        break;
                    }
                    std::thread::sleep(Duration::from_millis(100));
                }
                if Path::new(&format!("/proc/{pid}")).exists() {
                    let _ = Command::new("kill").args(["-9", &pid.to_string()]).status();
                }
            }
        }
    }
}

/// Starts a daemon that forks into the background; fails with its output if it does not start.
fn daemon(cmd: &mut Command) {
    let o = cmd.output().unwrap_or_else(|e| panic!("starting {cmd:?}: {e}"));
    assert!(o.status.success(), "{cmd:?}: {}", String::from_utf8_lossy(&o.stderr));
}

/// Whether this machine can run the test, else why not.
fn cannot_run() -> Option<String> {
    let uid = Command::new("id").arg("-u").output().ok()?;
    if String::from_utf8_lossy(&uid.stdout).trim() != "0" {
        return Some("the Slurm test starts daemons as root and installs Debian packages; not root".into());
    }
    let o = Command::new("bash").arg(repo().join("scripts/slurm/install_local.sh")).output().ok()?;
    if !o.status.success() {
        return Some(format!("Slurm could not be installed: {}", String::from_utf8_lossy(&o.stderr)));
    }
    None
}

#[test]
fn a_slurm_job_array_makes_the_dataset_one_process_makes() {
    if let Some(why) = cannot_run() {
        crate::util::skip(&why);
        return;
    }
    let cluster = Cluster::start();
    let dir = scratch_with_scenes(&[("demo", repo_scene("demo"))]);
    let cwd = dir.path();
    std::fs::write(
        cwd.join("small.toml"),
        "name = \"small\"\nwidth_px = 480\nheight_px = 270\nsensor_width_mm = 6.4\nsensor_height_mm = 3.6\n\
         hfov_deg = 25.0\nstrategy = \"grid\"\n",
    )
    .unwrap();
    let bin = env!("CARGO_BIN_EXE_insgen");
    let submit = |script: &str, args: &[&str]| {
        let o = cluster
            .cmd("bash")
            .arg(repo().join("scripts/slurm").join(script))
            .args(args)
            .current_dir(cwd)
            .output()
            .unwrap();
        assert!(o.status.success(), "{script}: {}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let out = submit(
        "submit.sh",
        &[
            "--areas",
            "demo",
            "--camera",
            "small.toml",
            "--count",
            "12",
            "--tasks",
            "4",
            "--insgen",
            bin,
            "--workdir",
            "runs",
        ],
    );
    assert!(out.contains("submitted: prep"), "{out}");
    let workdir = cwd.join("runs");
    cluster.wait_idle(&workdir, Duration::from_secs(600));
    let logs = cluster.logs(&workdir);
    assert!(workdir.join("coco/instances_train.json").is_file(), "no dataset after the jobs ended:\n{logs}");
    for task in 0..4 {
        let log = std::fs::read_dir(workdir.join("slurm/logs"))
            .unwrap()
            .flatten()
            .find(|e| {
                e.file_name().to_string_lossy().starts_with("insgen-masks-")
                    && e.file_name().to_string_lossy().ends_with(&format!("_{task}.log"))
            })
            .unwrap_or_else(|| panic!("no log of masks task {task}:\n{logs}"));
        let text = std::fs::read_to_string(log.path()).unwrap();
        assert!(text.contains(&format!("shard {task}/4")), "task {task} did not log its shard:\n{text}");
    }

    // One process, same inputs.
    let run = |args: &[&str]| {
        let o = crate::util::insgen(cwd, args);
        assert!(o.status.success(), "{args:?}: {}", crate::util::stderr(&o));
    };
    for args in [
        &["--workdir", "single", "prepare", "--area", "demo"][..],
        &["--workdir", "single", "sample", "--area", "demo", "--camera", "small.toml", "--count", "12"],
        &["--workdir", "single", "render-masks", "--area", "demo", "--camera", "small", "--preview", "0"],
        &["--workdir", "single", "export-coco", "--label-only"],
    ] {
        run(args);
    }
    let same = |what: &str| {
        let (a, b) =
            (crate::util::tree(&cwd.join("single").join(what)), crate::util::tree(&workdir.join(what)));
        assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>(), "{what}: other files");
        for (k, v) in &a {
            assert!(b[k] == *v, "{what}/{} differs between one process and the Slurm array", k.display());
        }
    };
    same("demo/small/masks");
    for split in ["train", "val", "test"] {
        let name = format!("coco/instances_{split}.json");
        assert!(
            std::fs::read(cwd.join("single").join(&name)).unwrap()
                == std::fs::read(workdir.join(&name)).unwrap(),
            "{name} differs"
        );
    }

    // A lost task: resubmit.sh runs only that one, and the merge makes the same dataset again.
    std::fs::remove_dir_all(workdir.join(".shards/masks-2")).unwrap();
    std::fs::remove_file(workdir.join(".shards/masks-2.done")).unwrap();
    std::fs::remove_dir_all(workdir.join("coco")).unwrap();
    let out = submit("resubmit.sh", &["runs"]);
    assert!(out.contains("resubmitted masks tasks 2 as job"), "{out}");
    cluster.wait_idle(&workdir, Duration::from_secs(300));
    assert!(workdir.join(".shards/masks-2.done").exists(), "{}", cluster.logs(&workdir));
    same("demo/small/masks");
    let name = "coco/instances_train.json";
    assert!(
        std::fs::read(cwd.join("single").join(name)).unwrap() == std::fs::read(workdir.join(name)).unwrap(),
        "{name} differs after the resubmission"
    );
}

/// `submit.sh --dry-run --eval-loc oracle`: the scripts parse, the chain is prep → masks (after prep),
/// rgb (after prep), loc (each task after its masks task) → merge (after all three); the loc task runs
/// `eval-loc --shard auto/N` on its masks shard and the merge job merges the loc shards too.
#[test]
fn submit_dry_run_chains_an_eval_loc_array_into_the_merge() {
    let scripts = repo().join("scripts/slurm");
    for script in ["submit.sh", "task.sh", "resubmit.sh", "install_local.sh"] {
        let o = Command::new("bash").arg("-n").arg(scripts.join(script)).output().unwrap();
        assert!(o.status.success(), "{script}: {}", String::from_utf8_lossy(&o.stderr));
    }
    let dir = scratch_with_scenes(&[]);
    let cwd = dir.path();
    // A stand-in insgen that records each command line.
    let fake = cwd.join("fake-insgen");
    std::fs::write(&fake, format!("#!/bin/sh\necho \"$*\" >> {}\n", cwd.join("calls.txt").display()))
        .unwrap();
    let ok = Command::new("chmod").arg("+x").arg(&fake).status().unwrap();
    assert!(ok.success());
    let o = Command::new("bash")
        .arg(scripts.join("submit.sh"))
        .args(["--areas", "demo", "--camera", "small", "--tasks", "3", "--rgb", "--eval-loc", "oracle"])
        .args(["--loc-tag", "t", "--loc-args", "--cost instance --limit 6"])
        .args(["--loc-resources", "--cpus-per-task 8", "--insgen"])
        .arg(&fake)
        .args(["--workdir", "runs", "--dry-run"])
        .current_dir(cwd)
        .output()
        .unwrap();
    let (out, err) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{err}");
    assert!(
        out.contains("submitted: prep DRY-prep, masks DRY-masks, rgb DRY-rgb, loc DRY-loc, merge DRY-merge"),
        "{out}"
    );
    let line = |job: &str| {
        err.lines()
            .find(|l| l.contains(&format!("--job-name insgen-{job} ")))
            .unwrap_or_else(|| panic!("no {job} job:\n{err}"))
            .to_string()
    };
    assert!(line("masks").contains("--dependency afterok:DRY-prep --array 0-2"), "{err}");
    let loc = line("loc");
    assert!(loc.contains("--dependency aftercorr:DRY-masks --array 0-2 --cpus-per-task 8"), "{loc}");
    assert!(loc.trim_end().ends_with(" loc"), "{loc}");
    assert!(line("merge").contains("--dependency afterok:DRY-masks:DRY-rgb:DRY-loc"), "{err}");
    let config = cwd.join("runs/slurm/config.env");
    let conf = std::fs::read_to_string(&config).unwrap();
    assert!(conf.contains("LOC=oracle\nLOC_TAG=t\n"), "{conf}");

    // task.sh loc for array task 1, on the published masks shard 1.
    let runs = cwd.join("runs");
    std::fs::create_dir_all(runs.join("demo/scene")).unwrap();
    std::fs::create_dir_all(runs.join("demo/small")).unwrap();
    std::fs::write(runs.join("demo/small/poses.jsonl"), "").unwrap();
    std::fs::create_dir_all(runs.join(".shards/masks-1")).unwrap();
    std::fs::write(runs.join(".shards/masks-1.done"), "").unwrap();
    let task = |stage: &str, index: &str| {
        let o = Command::new("bash")
            .arg(scripts.join("task.sh"))
            .arg(&config)
            .arg(stage)
            .env("SLURM_ARRAY_TASK_ID", index)
            .env("TMPDIR", cwd.join("scratch"))
            .current_dir(cwd)
            .output()
            .unwrap();
        (
            o.status.success(),
            format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr)),
        )
    };
    let (ok, log) = task("loc", "1");
    assert!(ok, "{log}");
    let calls = std::fs::read_to_string(cwd.join("calls.txt")).unwrap();
    let masks = runs.join(".shards/masks-1/demo/small/masks");
    assert_eq!(
        calls,
        format!(
            "--workdir {}/insgen-loc-0-1 --no-progress eval-loc --area demo --camera small --oracle --masks {} \
             --tag t --cost instance --limit 6 --shard auto/3\n",
            cwd.join("scratch").display(),
            masks.display()
        )
    );
    assert!(
        runs.join(".shards/loc-1.done").exists() && !runs.join(".shards/loc-1/demo/scene").exists(),
        "{log}"
    );
    // Without its masks shard a loc task fails and publishes nothing.
    let (ok, log) = task("loc", "2");
    assert!(!ok && log.contains("masks shard 2 is not done"), "{log}");
    assert!(!runs.join(".shards/loc-2.done").exists());
    // The merge job merges every shard, the loc ones too.
    for shard in ["masks-0", "masks-2", "rgb-0", "rgb-1", "rgb-2", "loc-0", "loc-2"] {
        std::fs::create_dir_all(runs.join(".shards").join(shard)).unwrap();
        std::fs::write(runs.join(".shards").join(format!("{shard}.done")), "").unwrap();
    }
    std::fs::write(cwd.join("calls.txt"), "").unwrap();
    let (ok, log) = task("merge", "");
    assert!(ok, "{log}");
    let calls = std::fs::read_to_string(cwd.join("calls.txt")).unwrap();
    let r = runs.display().to_string();
    let r = r.as_str();
    let shards: Vec<String> = ["masks", "rgb", "loc"]
        .iter()
        .flat_map(|s| (0..3).map(move |i| format!("{r}/.shards/{s}-{i}")))
        .collect();
    let first = calls.lines().next().unwrap_or_default();
    assert_eq!(first, format!("--workdir {} merge {}", runs.display(), shards.join(" ")), "{calls}");
}
