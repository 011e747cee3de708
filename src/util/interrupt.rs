//! Stopping long work between items on Ctrl-C.
//!
//! The CLI installs a SIGINT/SIGTERM handler that only sets a flag ([`request`]); the stages check it
//! between items ([`check`]) — between frames, queries, tiles — and return [`Interrupted`] up their
//! error chain. Files are written atomically (temporary file + rename), so an interrupted run leaves
//! every finished item complete and nothing half-written, and a rerun resumes. `main` maps the error to
//! exit status 130, the shell's convention for a process stopped by SIGINT.

use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

/// The work was stopped on request (Ctrl-C) between two items.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("interrupted (Ctrl-C); finished items are complete, rerun the same command to resume")]
pub struct Interrupted;

/// Asks running stages to stop at their next check (called from the signal handler: only an atomic
/// store, which is async-signal-safe).
pub fn request() {
    REQUESTED.store(true, Ordering::SeqCst);
}

/// Whether a stop was requested.
pub fn requested() -> bool {
    REQUESTED.load(Ordering::SeqCst)
}

/// Returns [`Interrupted`] once a stop was requested.
///
/// # Errors
/// [`Interrupted`] after [`request`].
pub fn check() -> Result<(), Interrupted> {
    if requested() {
        Err(Interrupted)
    } else {
        Ok(())
    }
}

/// Whether an error chain holds an [`Interrupted`] (for the exit status).
pub fn in_chain(err: &(dyn std::error::Error + 'static)) -> bool {
    let mut cur: Option<&(dyn std::error::Error + 'static)> = Some(err);
    while let Some(e) = cur {
        if e.downcast_ref::<Interrupted>().is_some() {
            return true;
        }
        cur = e.source();
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("frame f001")]
    struct Wrapper(#[source] Interrupted);

    // The flag itself is process-wide, so no test sets it: tests run in parallel with stages that
    // check it. The integration test `cli_interrupt` sends a real SIGINT to the binary.
    #[test]
    fn interrupted_is_found_anywhere_in_a_chain() {
        assert!(in_chain(&Wrapper(Interrupted)));
        assert!(in_chain(&Interrupted));
        assert!(!in_chain(&std::io::Error::other("x")));
    }
}
