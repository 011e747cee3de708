//! How the CLI talks to the person or the batch system running it: one [`Printer`], derived once from
//! `-q/-v/--no-progress/--log-every` (uv's printer), and the [`crate::util::Progress`] it hands to stages.
//!
//! - Results and summaries go to stdout ([`Printer::summary`]), hidden by `-q`.
//! - Progress goes to stderr: an indicatif bar when stderr is a terminal; when it is not (a Slurm or CI
//!   log), a plain line every `--log-every` seconds with the count, the rate and the time left, so a
//!   batch log shows the job moving. `-q` and `--no-progress` hide both; `-v` hides the bar (log lines
//!   would tear it) but keeps the periodic lines.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::util::Progress;

/// Where progress goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ProgressMode {
    /// Nothing.
    Hidden,
    /// An indicatif bar on stderr (a terminal).
    Bar,
    /// A line on stderr every so often (a log file).
    Lines {
        /// Time between two lines.
        every: Duration,
    },
}

/// The output policy of one run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Printer {
    quiet: bool,
    progress: ProgressMode,
}

impl Printer {
    /// The policy for these flags; `stderr_is_terminal` is passed in so tests can choose it.
    pub fn new(
        quiet: bool,
        verbose: u8,
        no_progress: bool,
        log_every_s: f64,
        stderr_is_terminal: bool,
    ) -> Self {
        let progress = if quiet || no_progress {
            ProgressMode::Hidden
        } else if stderr_is_terminal && verbose == 0 {
            ProgressMode::Bar
        } else if stderr_is_terminal {
            // Verbose on a terminal: log lines go there already; a bar would tear them.
            ProgressMode::Hidden
        } else {
            ProgressMode::Lines { every: Duration::from_secs_f64(log_every_s.max(0.0)) }
        };
        Printer { quiet, progress }
    }

    /// The policy of the global flags, on this process's stderr.
    pub fn from_global(g: &super::Global) -> Self {
        Printer::new(g.quiet, g.verbose, g.no_progress, g.log_every, std::io::stderr().is_terminal())
    }

    /// Where progress goes.
    pub fn progress_mode(&self) -> ProgressMode {
        self.progress
    }

    /// Whether summaries are shown.
    pub fn is_quiet(&self) -> bool {
        self.quiet
    }

    /// Prints a result or summary on stdout (not with `-q`).
    pub fn summary(&self, text: impl std::fmt::Display) {
        if !self.quiet {
            println!("{text}");
        }
    }

    /// Prints a status line on stderr (not with `-q`): the step a composite command is on.
    pub fn status(&self, text: impl std::fmt::Display) {
        if !self.quiet {
            eprintln!("{text}");
        }
    }

    /// A progress reporter following this policy.
    pub fn progress(&self) -> Bar {
        Bar { mode: self.progress, state: Mutex::new(None) }
    }
}

struct Running {
    what: String,
    len: u64,
    done: u64,
    started: Instant,
    last_line: Instant,
    message: String,
    bar: Option<ProgressBar>,
}

/// The [`Progress`] of a [`Printer`]: a bar, periodic lines or nothing.
pub struct Bar {
    mode: ProgressMode,
    state: Mutex<Option<Running>>,
}

impl Bar {
    /// A reporter that shows nothing.
    pub fn hidden() -> Self {
        Bar { mode: ProgressMode::Hidden, state: Mutex::new(None) }
    }
}

/// `1h02m03s`, `4m05s` or `6s`.
fn duration_text(secs: f64) -> String {
    let s = secs.max(0.0).round() as u64;
    match (s / 3600, s / 60 % 60, s % 60) {
        (0, 0, s) => format!("{s}s"),
        (0, m, s) => format!("{m}m{s:02}s"),
        (h, m, s) => format!("{h}h{m:02}m{s:02}s"),
    }
}

/// The periodic line: `frames: 120/1000 (12.0 %), 4.10/s, 29s elapsed, eta 3m35s — recall 95 %`.
fn line(r: &Running) -> String {
    let elapsed = r.started.elapsed().as_secs_f64();
    let rate = if elapsed > 0.0 { r.done as f64 / elapsed } else { 0.0 };
    let pct = if r.len > 0 { 100.0 * r.done as f64 / r.len as f64 } else { 100.0 };
    let eta =
        if rate > 0.0 { duration_text((r.len.saturating_sub(r.done)) as f64 / rate) } else { "?".into() };
    let msg = if r.message.is_empty() { String::new() } else { format!(" — {}", r.message) };
    format!(
        "{}: {}/{} ({pct:.1} %), {rate:.2}/s, {} elapsed, eta {eta}{msg}",
        r.what,
        r.done,
        r.len,
        duration_text(elapsed)
    )
}

impl Progress for Bar {
    fn start(&self, len: u64, what: &str) {
        let bar = (self.mode == ProgressMode::Bar).then(|| {
            let pb = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
            let style = ProgressStyle::with_template(&format!(
                "{{spinner}} {what:>10} [{{elapsed_precise}}] {{wide_bar}} {{pos}}/{{len}} ({{per_sec}}, eta {{eta}}) {{msg}}"
            ))
            .unwrap_or_else(|_| ProgressStyle::default_bar());
            pb.set_style(style);
            pb
        });
        let now = Instant::now();
        if let Ok(mut slot) = self.state.lock() {
            if let Some(old) = slot.take().and_then(|r| r.bar) {
                old.finish_and_clear();
            }
            *slot = Some(Running {
                what: what.to_string(),
                len,
                done: 0,
                started: now,
                last_line: now,
                message: String::new(),
                bar,
            });
        }
    }

    fn inc(&self, n: u64) {
        if let Ok(mut slot) = self.state.lock() {
            if let Some(r) = slot.as_mut() {
                r.done += n;
                if let Some(pb) = &r.bar {
                    pb.inc(n);
                }
                if let ProgressMode::Lines { every } = self.mode {
                    if r.last_line.elapsed() >= every {
                        r.last_line = Instant::now();
                        eprintln!("{}", line(r));
                    }
                }
            }
        }
    }

    fn message(&self, msg: &str) {
        if let Ok(mut slot) = self.state.lock() {
            if let Some(r) = slot.as_mut() {
                r.message = msg.to_string();
                if let Some(pb) = &r.bar {
                    pb.set_message(msg.to_string());
                }
            }
        }
    }

    fn finish(&self) {
        if let Ok(mut slot) = self.state.lock() {
            if let Some(r) = slot.take() {
                if let Some(pb) = &r.bar {
                    pb.finish();
                }
                if matches!(self.mode, ProgressMode::Lines { .. }) && r.len > 0 {
                    eprintln!("{}", line(&r));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_policy_follows_the_flags_and_the_terminal() {
        let lines = ProgressMode::Lines { every: Duration::from_secs(30) };
        assert_eq!(Printer::new(false, 0, false, 30.0, true).progress_mode(), ProgressMode::Bar);
        assert_eq!(Printer::new(false, 0, false, 30.0, false).progress_mode(), lines);
        assert_eq!(Printer::new(false, 1, false, 30.0, false).progress_mode(), lines);
        assert_eq!(Printer::new(false, 1, false, 30.0, true).progress_mode(), ProgressMode::Hidden);
        assert_eq!(Printer::new(true, 0, false, 30.0, true).progress_mode(), ProgressMode::Hidden);
        assert_eq!(Printer::new(false, 0, true, 30.0, false).progress_mode(), ProgressMode::Hidden);
        assert!(Printer::new(true, 0, false, 30.0, false).is_quiet());
    }

    #[test]
    fn the_periodic_line_gives_count_rate_and_time_left() {
        let t0 = Instant::now() - Duration::from_secs(10);
        let r = Running {
            what: "frames".into(),
            len: 100,
            done: 25,
            started: t0,
            last_line: t0,
            message: "recall 95 %".into(),
            bar: None,
        };
        let l = line(&r);
        assert!(l.starts_with("frames: 25/100 (25.0 %), 2.5"), "{l}");
        assert!(l.contains("10s elapsed, eta 30s — recall 95 %"), "{l}");
        assert_eq!(duration_text(3725.0), "1h02m05s");
        assert_eq!(duration_text(65.0), "1m05s");
    }
}
