//! The indicatif implementation of [`crate::util::Progress`], and the `-q/-v/--no-progress` policy.
//!
//! Bars go to stderr, are hidden when stderr is not a terminal, when `--no-progress` or `-q` is given,
//! and in verbose mode (so they never interleave with log lines).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::sync::Mutex;

use crate::util::Progress;

/// A progress bar on stderr.
pub struct Bar {
    bar: Mutex<Option<ProgressBar>>,
    visible: bool,
}

impl Bar {
    pub fn new(visible: bool) -> Self {
        Bar { bar: Mutex::new(None), visible }
    }
}

impl Progress for Bar {
    fn start(&self, len: u64, what: &str) {
        let pb = ProgressBar::new(len);
        if !self.visible {
            pb.set_draw_target(ProgressDrawTarget::hidden());
        }
        let style = ProgressStyle::with_template(&format!(
            "{{spinner}} {what:>10} [{{elapsed_precise}}] {{wide_bar}} {{pos}}/{{len}} ({{per_sec}}, eta {{eta}}) {{msg}}"
        ))
        .unwrap_or_else(|_| ProgressStyle::default_bar());
        pb.set_style(style);
        if let Ok(mut slot) = self.bar.lock() {
            if let Some(old) = slot.take() {
                old.finish_and_clear();
            }
            *slot = Some(pb);
        }
    }

    fn inc(&self, n: u64) {
        if let Ok(slot) = self.bar.lock() {
            if let Some(pb) = slot.as_ref() {
                pb.inc(n);
            }
        }
    }

    fn message(&self, msg: &str) {
        if let Ok(slot) = self.bar.lock() {
            if let Some(pb) = slot.as_ref() {
                pb.set_message(msg.to_string());
            }
        }
    }

    fn finish(&self) {
        if let Ok(mut slot) = self.bar.lock() {
            if let Some(pb) = slot.take() {
                pb.finish();
            }
        }
    }
}
