//! Running Blender: finding it, starting one process per job, relaying its protocol lines, and turning
//! a failure into an error that says what to do.
//!
//! Two launchers: a Python interpreter with the `bpy` module (`<repo>/.venv-blender/bin/python`, made by
//! `scripts/setup_blender.sh`) running `render_rgb.py JOB`, or a Blender binary running
//! `blender -b --factory-startup -P render_rgb.py -- JOB`. Stdout and stderr are piped and drained
//! concurrently (stderr on its own thread), so a chatty Blender never blocks on a full pipe. Stdout lines
//! starting with `INSGEN ` are protocol events ([`Event`]); every other line is Blender's own logging,
//! logged at debug level and kept (the last [`TAIL_LINES`]) for the error report.

use std::collections::VecDeque;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use serde::Deserialize;

use super::error::{BlenderError, ProcessFailure, ProtocolError};

/// Environment variable naming a Python interpreter that can `import bpy`.
pub const ENV_PYTHON: &str = "INSGEN_BLENDER_PYTHON";
/// Environment variable naming a Blender binary (takes precedence over the venv when set).
pub const ENV_BLENDER: &str = "INSGEN_BLENDER";
/// The venv `scripts/setup_blender.sh` creates, relative to the repository root.
pub const VENV_PYTHON: &str = ".venv-blender/bin/python";
/// Prefix of protocol lines on the script's stdout.
pub const PROTOCOL_PREFIX: &str = "INSGEN ";
/// How many trailing log lines a failure report keeps.
pub const TAIL_LINES: usize = 40;

/// How Blender is started.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Launcher {
    /// A Python interpreter with the `bpy` module installed.
    Python {
        /// The interpreter's path.
        interpreter: PathBuf,
    },
    /// A Blender executable, run in background mode.
    Blender {
        /// The Blender executable's path.
        binary: PathBuf,
    },
}

impl Launcher {
    /// Finds Blender: an explicit binary, an explicit interpreter, `$INSGEN_BLENDER`,
    /// `$INSGEN_BLENDER_PYTHON`, then `.venv-blender/bin/python` under each of `roots` (in order).
    ///
    /// # Errors
    /// [`BlenderError::NotFound`] listing what was tried.
    pub fn find(
        blender: Option<&Path>,
        python: Option<&Path>,
        roots: &[PathBuf],
    ) -> Result<Launcher, BlenderError> {
        let mut tried = Vec::new();
        let mut check = |p: &Path, what: &str| {
            if p.is_file() {
                true
            } else {
                tried.push(format!("{what} {} (not a file)", p.display()));
                false
            }
        };
        if let Some(b) = blender {
            if check(b, "--blender") {
                return Ok(Launcher::Blender { binary: b.to_path_buf() });
            }
        }
        if let Some(p) = python {
            if check(p, "--blender-python") {
                return Ok(Launcher::Python { interpreter: p.to_path_buf() });
            }
        }
        if blender.is_some() || python.is_some() {
            return Err(BlenderError::NotFound { given_only: true, tried });
        }
        if let Some(b) = std::env::var_os(ENV_BLENDER).filter(|v| !v.is_empty()) {
            let b = PathBuf::from(b);
            if check(&b, ENV_BLENDER) {
                return Ok(Launcher::Blender { binary: b });
            }
        }
        if let Some(p) = std::env::var_os(ENV_PYTHON).filter(|v| !v.is_empty()) {
            let p = PathBuf::from(p);
            if check(&p, ENV_PYTHON) {
                return Ok(Launcher::Python { interpreter: p });
            }
        }
        for root in roots {
            let p = root.join(VENV_PYTHON);
            if check(&p, "venv") {
                return Ok(Launcher::Python { interpreter: p });
            }
        }
        Err(BlenderError::NotFound { given_only: false, tried })
    }

    /// The command running `script` on `job`.
    pub fn command(&self, script: &Path, job: &Path) -> Command {
        match self {
            Launcher::Python { interpreter } => {
                let mut c = Command::new(interpreter);
                c.arg(script).arg(job);
                c
            }
            Launcher::Blender { binary } => {
                let mut c = Command::new(binary);
                c.args(["-b", "--factory-startup", "-noaudio", "--python-exit-code", "1", "-P"])
                    .arg(script)
                    .arg("--")
                    .arg(job);
                c
            }
        }
    }
}

/// A protocol event printed by the script.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// The scene is built; `device` is the Cycles device chosen (`CPU`, `OPTIX`, `CUDA`, …; `None` for
    /// Workbench), `blender` Blender's version; `bounds` (when the job asked) gives each model's ENU
    /// bounds [min, max] in metres.
    Ready {
        /// Models imported.
        models: usize,
        /// Seconds spent building the scene.
        seconds: f64,
        /// The Cycles device chosen (`None` for Workbench).
        device: Option<String>,
        /// Blender's version string.
        blender: Option<String>,
        /// Each model's ENU bounds [min, max], metres, when the job asked (`None` for a model without geometry).
        bounds: Option<Vec<Option<[[f64; 3]; 2]>>>,
    },
    /// A frame's files are written to its temporary paths; wall-clock seconds and CPU seconds (all
    /// threads of the process) spent on it.
    Done {
        /// The frame.
        frame: String,
        /// Wall-clock seconds spent on it.
        seconds: f64,
        /// CPU seconds spent on it (all threads).
        cpu_seconds: f64,
    },
    /// The script failed (it exits non-zero afterwards).
    Error {
        /// The script's message.
        message: String,
        /// The frame being rendered, when known.
        frame: Option<String>,
    },
}

#[derive(Deserialize)]
struct ReadyJson {
    models: usize,
    seconds: f64,
    #[serde(default)]
    device: Option<String>,
    #[serde(default)]
    blender: Option<String>,
    #[serde(default)]
    bounds: Option<Vec<Option<[[f64; 3]; 2]>>>,
}

#[derive(Deserialize)]
struct EventJson {
    #[serde(default)]
    ready: Option<ReadyJson>,
    #[serde(default)]
    done: Option<String>,
    #[serde(default)]
    seconds: Option<f64>,
    #[serde(default)]
    cpu_seconds: Option<f64>,
    #[serde(default)]
    error: Option<String>,
    #[serde(default)]
    frame: Option<String>,
}

/// Parses one stdout line: `None` for ordinary log lines, `Some(Err(_))` for a malformed protocol line.
pub fn parse_event(line: &str) -> Option<Result<Event, ProtocolError>> {
    let body = line.strip_prefix(PROTOCOL_PREFIX)?;
    let ev: EventJson = match serde_json::from_str(body) {
        Ok(e) => e,
        Err(source) => return Some(Err(ProtocolError::Malformed { line: body.to_string(), source })),
    };
    Some(if let Some(r) = ev.ready {
        Ok(Event::Ready {
            models: r.models,
            seconds: r.seconds,
            device: r.device,
            blender: r.blender,
            bounds: r.bounds,
        })
    } else if let Some(frame) = ev.done {
        Ok(Event::Done {
            frame,
            seconds: ev.seconds.unwrap_or(f64::NAN),
            cpu_seconds: ev.cpu_seconds.unwrap_or(f64::NAN),
        })
    } else if let Some(message) = ev.error {
        Ok(Event::Error { message, frame: ev.frame })
    } else {
        Err(ProtocolError::Unknown { line: body.to_string() })
    })
}

/// Hints for known failure signatures in the captured output.
pub fn hint_for(log: &[String], launcher: &Launcher) -> Option<String> {
    let has = |s: &str| log.iter().any(|l| l.contains(s));
    if has("No module named 'bpy'") || has("cannot import bpy") {
        let who = match launcher {
            Launcher::Python { interpreter } => interpreter.display().to_string(),
            Launcher::Blender { binary } => binary.display().to_string(),
        };
        return Some(format!(
            "bpy cannot be imported by {who}: run scripts/setup.sh (it creates .venv-blender with bpy 5.0.1 \
             for CPython 3.11), or point INSGEN_BLENDER_PYTHON at an interpreter that has bpy"
        ));
    }
    if has("cannot open shared object file") {
        return Some(
            "a system library Blender needs is missing: install libxrender1 libxxf86vm1 libxfixes3 libxi6 \
             libxkbcommon0 libsm6 libgl1 (apt-get install …), then retry"
                .into(),
        );
    }
    if has("is not available on this addon version") || has("Extension") && has("not available") {
        return Some(
            "the glTF importer rejected a required extension of a model: check the tile content's \
             extensionsRequired (insgen strips CESIUM_RTC; others must be supported by Blender's importer)"
                .into(),
        );
    }
    if has("MemoryError") || has("std::bad_alloc") || has("Killed") {
        return Some(
            "Blender ran out of memory: lower --restart-every, or render fewer tiles per frame (--max-sse)"
                .into(),
        );
    }
    if has("Unable to open") || has("No such file or directory") {
        return Some("a file named in the job could not be opened: check the paths in the job file".into());
    }
    None
}

/// Quotes a command for display.
pub fn display_command(cmd: &Command) -> String {
    let quote = |s: &std::ffi::OsStr| {
        let s = s.to_string_lossy();
        if s.is_empty() || s.contains(|c: char| c.is_whitespace() || "'\"$`\\".contains(c)) {
            format!("'{}'", s.replace('\'', "'\\''"))
        } else {
            s.into_owned()
        }
    };
    std::iter::once(quote(cmd.get_program())).chain(cmd.get_args().map(quote)).collect::<Vec<_>>().join(" ")
}

struct Tail {
    lines: VecDeque<String>,
}

impl Tail {
    fn new() -> Self {
        Tail { lines: VecDeque::with_capacity(TAIL_LINES) }
    }
    fn push(&mut self, line: String) {
        if self.lines.len() == TAIL_LINES {
            self.lines.pop_front();
        }
        self.lines.push_back(line);
    }
}

/// Makes the child get SIGKILL when insgen dies, however it dies. Without it a SIGKILLed `render-rgb`
/// (a batch system's hard limit, the OOM killer) leaves Blender rendering on, writing its temporary
/// frames after the rerun has cleaned up or into the frames the rerun renders.
///
/// The death signal follows the thread that spawned the child; `run_job` waits for the child on that
/// thread, so the thread outlives it.
#[cfg(target_os = "linux")]
fn die_with_parent(cmd: &mut Command) {
    use std::os::unix::process::CommandExt;
    let parent = std::process::id() as libc::pid_t;
    // SAFETY: between fork and exec only async-signal-safe calls (prctl, getppid, _exit) run.
    unsafe {
        cmd.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL as libc::c_ulong) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            // insgen died between fork and prctl: the signal will not come.
            if libc::getppid() != parent {
                libc::_exit(1);
            }
            Ok(())
        });
    }
}

#[cfg(not(target_os = "linux"))]
fn die_with_parent(_cmd: &mut Command) {}

fn kill(child: &mut Child) {
    // The child may already have exited; either way it must not outlive the error.
    let _ = child.kill();
    let _ = child.wait();
}

/// Drains stderr on its own thread into a shared tail, so the tail can be read even when the process is
/// killed and some grandchild keeps the pipe open (the thread then ends on its own).
fn drain_stderr(
    stderr: std::process::ChildStderr,
) -> (std::sync::Arc<std::sync::Mutex<Tail>>, std::thread::JoinHandle<()>) {
    let err_tail = std::sync::Arc::new(std::sync::Mutex::new(Tail::new()));
    let err_thread = {
        let err_tail = std::sync::Arc::clone(&err_tail);
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines() {
                match line {
                    Ok(l) => {
                        log::debug!("blender stderr: {l}");
                        if let Ok(mut t) = err_tail.lock() {
                            t.push(l);
                        }
                    }
                    Err(_) => break,
                }
            }
        })
    };
    (err_tail, err_thread)
}

/// What the stdout of a Blender process told, read to its end (or until the process was killed).
struct Relayed {
    /// The last lines that were not protocol lines.
    out_tail: Tail,
    /// The message and frame of a reported `error` event.
    reported: Option<(String, Option<String>)>,
    /// Whether the `ready` line came.
    ready: bool,
    /// The last frame reported done.
    current: Option<String>,
    /// The error `on_event` returned (the process was then killed).
    relay_error: Option<BlenderError>,
    /// The malformed protocol line (the process was then killed).
    protocol_error: Option<ProtocolError>,
}

/// Reads Blender's stdout line by line, handing every protocol event to `on_event`; kills the process
/// on a malformed protocol line or an error from `on_event`.
fn relay_stdout(
    stdout: std::process::ChildStdout,
    child: &mut Child,
    on_event: &mut impl FnMut(Event) -> Result<(), BlenderError>,
) -> Relayed {
    let mut r = Relayed {
        out_tail: Tail::new(),
        reported: None,
        ready: false,
        current: None,
        relay_error: None,
        protocol_error: None,
    };
    for line in BufReader::new(stdout).lines() {
        let line = match line {
            Ok(l) => l,
            Err(_) => break,
        };
        match parse_event(&line) {
            None => {
                log::debug!("blender: {line}");
                r.out_tail.push(line);
            }
            Some(Err(e)) => {
                r.protocol_error = Some(e);
                kill(child);
                break;
            }
            Some(Ok(ev)) => {
                match &ev {
                    Event::Ready { .. } => r.ready = true,
                    Event::Done { frame, .. } => r.current = Some(frame.clone()),
                    Event::Error { message, frame } => r.reported = Some((message.clone(), frame.clone())),
                }
                if let Err(e) = on_event(ev) {
                    r.relay_error = Some(e);
                    kill(child);
                    break;
                }
            }
        }
    }
    r
}

/// Runs one job: starts the process, hands every protocol event to `on_event` as it arrives, and waits.
///
/// When `on_event` returns an error (e.g. an output failed verification) the process is killed and that
/// error returned. A non-zero exit, a reported `error` event, or an exit without any `ready` line becomes
/// [`BlenderError::Failed`] with the command, status, stderr tail and a hint.
///
/// # Errors
/// [`BlenderError::Spawn`], [`BlenderError::Failed`], or whatever `on_event` returns.
pub fn run_job(
    launcher: &Launcher,
    script: &Path,
    job: &Path,
    mut on_event: impl FnMut(Event) -> Result<(), BlenderError>,
) -> Result<(), BlenderError> {
    let mut cmd = launcher.command(script, job);
    cmd.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped());
    cmd.env("PYTHONUNBUFFERED", "1").env("PYTHONDONTWRITEBYTECODE", "1");
    die_with_parent(&mut cmd);
    let shown = display_command(&cmd);
    log::debug!("running {shown}");
    let mut child = cmd.spawn().map_err(|source| BlenderError::Spawn {
        hint: (source.kind() == std::io::ErrorKind::NotFound)
            .then(|| "the interpreter or Blender binary does not exist: run scripts/setup.sh".to_string()),
        command: shown.clone(),
        source,
    })?;
    let stderr = child.stderr.take().expect("stderr was piped above");
    let stdout = child.stdout.take().expect("stdout was piped above");
    let (err_tail, err_thread) = drain_stderr(stderr);
    let Relayed { out_tail, reported, ready, current, relay_error, protocol_error } =
        relay_stdout(stdout, &mut child, &mut on_event);
    if let Some(e) = relay_error {
        return Err(e);
    }
    let status =
        child.wait().map_err(|source| BlenderError::Spawn { command: shown.clone(), hint: None, source })?;
    let killed = protocol_error.is_some();
    if !status.success() && crate::util::interrupt::requested() {
        // Ctrl-C reached Blender too (same process group): the frame in progress is lost, finished
        // ones are in place; stop like every other stage does.
        return Err(BlenderError::Interrupted(crate::util::interrupt::Interrupted));
    }
    if !killed {
        let _ = err_thread.join();
    }
    let err_lines: Vec<String> =
        err_tail.lock().map(|t| t.lines.iter().cloned().collect()).unwrap_or_default();
    let failed = !status.success() || reported.is_some() || protocol_error.is_some() || !ready;
    if !failed {
        return Ok(());
    }
    let mut tail: Vec<String> = out_tail.lines.into_iter().collect();
    tail.extend(err_lines);
    if tail.len() > TAIL_LINES {
        tail.drain(..tail.len() - TAIL_LINES);
    }
    let status_text = match (status.code(), &protocol_error, ready) {
        (_, Some(_), _) => "a protocol error".into(),
        (Some(0), None, false) => "exit status 0 but without building the scene (no ready line)".into(),
        (Some(c), _, _) => format!("exit status {c}"),
        (None, _, _) => signal_text(&status),
    };
    let (message, frame) = match reported {
        Some((m, f)) => (Some(m), f),
        // The frame after the last finished one was in progress.
        None => (None, current.map(|c| format!("after {c}"))),
    };
    let mut log_lines = tail.clone();
    if let Some(m) = &message {
        log_lines.push(m.clone());
    }
    let hint = hint_for(&log_lines, launcher);
    Err(BlenderError::Failed(Box::new(ProcessFailure {
        protocol: protocol_error,
        command: shown,
        status: status_text,
        frame,
        message,
        stderr_tail: tail,
        hint,
    })))
}

#[cfg(unix)]
fn signal_text(status: &std::process::ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match status.signal() {
        Some(9) => "signal 9 (killed; out of memory?)".into(),
        Some(s) => format!("signal {s}"),
        None => "an unknown status".into(),
    }
}

#[cfg(not(unix))]
fn signal_text(_status: &std::process::ExitStatus) -> String {
    "an unknown status".into()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn protocol_lines() {
        assert!(parse_event("12:00 | INFO: glTF import").is_none());
        assert_eq!(
            parse_event(r#"INSGEN {"done": "f_0001", "seconds": 1.5, "cpu_seconds": 2.75}"#)
                .map(|r| r.unwrap()),
            Some(Event::Done { frame: "f_0001".into(), seconds: 1.5, cpu_seconds: 2.75 })
        );
        assert_eq!(
            parse_event(r#"INSGEN {"ready": {"models": 2, "seconds": 0.5}}"#).map(|r| r.unwrap()),
            Some(Event::Ready { models: 2, seconds: 0.5, device: None, blender: None, bounds: None })
        );
        assert_eq!(
            parse_event(r#"INSGEN {"error": "boom", "frame": null}"#).map(|r| r.unwrap()),
            Some(Event::Error { message: "boom".into(), frame: None })
        );
        assert!(matches!(parse_event("INSGEN {not json"), Some(Err(_))));
        assert!(matches!(parse_event(r#"INSGEN {"other": 1}"#), Some(Err(_))));
    }

    #[test]
    fn hints() {
        let py = Launcher::Python { interpreter: "/x/python".into() };
        let h = hint_for(&["ModuleNotFoundError: No module named 'bpy'".into()], &py).unwrap();
        assert!(h.contains("scripts/setup.sh") && h.contains("/x/python"), "{h}");
        assert!(hint_for(
            &["Error: Extension CESIUM_RTC is not available on this addon version".into()],
            &py
        )
        .unwrap()
        .contains("extension"));
        assert_eq!(hint_for(&["all fine".into()], &py), None);
    }

    #[test]
    fn find_prefers_explicit_and_reports_what_was_tried() {
        let dir = tempfile::tempdir().unwrap();
        let py = dir.path().join(VENV_PYTHON);
        std::fs::create_dir_all(py.parent().unwrap()).unwrap();
        std::fs::write(&py, "").unwrap();
        let missing = dir.path().join("nope");
        let e = Launcher::find(None, Some(&missing), &[dir.path().to_path_buf()]).unwrap_err().to_string();
        assert!(e.contains("nope") && e.contains("setup.sh"), "{e}");
        assert_eq!(Launcher::find(Some(&py), None, &[]).unwrap(), Launcher::Blender { binary: py.clone() });
    }

    #[cfg(unix)]
    mod fake_blender {
        use super::*;

        /// A fake "Python" (a shell script) standing in for Blender, to test the plumbing.
        fn fake(dir: &Path, body: &str) -> Launcher {
            use std::os::unix::fs::PermissionsExt;
            let p = dir.join("fake-python");
            std::fs::write(&p, format!("#!/bin/sh\n{body}\n")).unwrap();
            std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755)).unwrap();
            Launcher::Python { interpreter: p }
        }

        #[test]
        fn events_are_relayed_in_order() {
            let dir = tempfile::tempdir().unwrap();
            let l = fake(
                dir.path(),
                r#"echo 'INFO: noise'
echo 'INSGEN {"ready": {"models": 1, "seconds": 0.1}}'
echo 'some stderr' >&2
echo 'INSGEN {"done": "a", "seconds": 0.2}'
echo 'INSGEN {"done": "b", "seconds": 0.3, "cpu_seconds": 0.5}'"#,
            );
            let mut seen = Vec::new();
            run_job(&l, Path::new("script.py"), Path::new("job.json"), |e| {
                seen.push(e);
                Ok(())
            })
            .unwrap();
            assert_eq!(seen.len(), 3);
            assert_eq!(seen[2], Event::Done { frame: "b".into(), seconds: 0.3, cpu_seconds: 0.5 });
        }

        #[test]
        fn failure_reports_command_status_tail_and_hint() {
            let dir = tempfile::tempdir().unwrap();
            let l = fake(
                dir.path(),
                r#"echo 'Traceback (most recent call last):' >&2
echo "ModuleNotFoundError: No module named 'bpy'" >&2
exit 3"#,
            );
            let e =
                run_job(&l, Path::new("/s/render rgb.py"), Path::new("/j/job.json"), |_| Ok(())).unwrap_err();
            let text = e.to_string();
            assert!(text.contains("fake-python '/s/render rgb.py' /j/job.json"), "{text}");
            assert!(text.contains("exit status 3"), "{text}");
            assert!(
                text.contains("No module named 'bpy'") && text.contains("hint: bpy cannot be imported"),
                "{text}"
            );
            assert!(text.contains("stderr (last 2 lines)") && text.contains(&"-".repeat(78)), "{text}");
        }

        #[test]
        fn reported_error_names_the_frame() {
            let dir = tempfile::tempdir().unwrap();
            let l = fake(
                dir.path(),
                r#"echo 'INSGEN {"ready": {"models": 1, "seconds": 0.1}}'
echo 'INSGEN {"error": "RuntimeError: render failed", "frame": "f7"}'
exit 1"#,
            );
            let e = run_job(&l, Path::new("s.py"), Path::new("j.json"), |_| Ok(())).unwrap_err().to_string();
            assert!(e.contains("frame \"f7\"") && e.contains("render failed"), "{e}");
            assert!(e.contains("<stderr is empty>"), "{e}");
        }

        #[test]
        fn relay_error_kills_and_wins() {
            let dir = tempfile::tempdir().unwrap();
            let l = fake(
                dir.path(),
                r#"echo 'INSGEN {"ready": {"models": 1, "seconds": 0.1}}'
echo 'INSGEN {"done": "a", "seconds": 0.2}'
sleep 30"#,
            );
            let t0 = std::time::Instant::now();
            let e = run_job(&l, Path::new("s.py"), Path::new("j.json"), |ev| match ev {
                Event::Done { frame, .. } => Err(BlenderError::Output {
                    frame,
                    path: "x.png".into(),
                    source: crate::blender::error::OutputError::NotReported,
                }),
                _ => Ok(()),
            })
            .unwrap_err();
            assert!(matches!(e, BlenderError::Output { .. }));
            assert!(t0.elapsed().as_secs() < 20, "the child was not killed");
        }

        #[test]
        fn malformed_protocol_line_keeps_its_cause() {
            let dir = tempfile::tempdir().unwrap();
            let l = fake(dir.path(), "echo 'INSGEN {oops'\nsleep 30");
            let e = run_job(&l, Path::new("s.py"), Path::new("j.json"), |_| Ok(())).unwrap_err();
            assert!(e.to_string().contains("a protocol error"), "{e}");
            let cause = std::error::Error::source(&e).expect("the protocol error is the source");
            assert!(cause.to_string().contains("malformed protocol line"), "{cause}");
            assert!(std::error::Error::source(cause).is_some(), "the JSON error is kept");
        }

        #[test]
        fn missing_interpreter_is_a_spawn_error() {
            let l = Launcher::Python { interpreter: "/no/such/python".into() };
            let e = run_job(&l, Path::new("s.py"), Path::new("j.json"), |_| Ok(())).unwrap_err().to_string();
            assert!(e.contains("/no/such/python") && e.contains("setup.sh"), "{e}");
        }
    }
}
