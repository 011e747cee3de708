//! The `insgen` binary: parse the command line, run it, print the error chain once.
//!
//! Exit status: 0 success, 1 failure (the cause chain on one stderr line), 2 usage error (clap),
//! 130 stopped by Ctrl-C (SIGINT/SIGTERM) between items.

#![warn(missing_docs)]

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // Mesa's Vulkan device-select layer prints "XDG_RUNTIME_DIR is invalid or not set" on every
    // headless run; it only orders GPUs for display servers, and wgpu picks its adapter itself. Set
    // before any thread exists (set_var is only sound while the process is single-threaded).
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
    let argv: Vec<String> = std::env::args().collect();
    let cli = insgen::cli::Cli::parse_from(&argv);
    let level = if cli.global.quiet {
        "error"
    } else {
        match cli.global.verbose {
            0 => "warn,insgen=info",
            1 => "info",
            _ => "debug",
        }
    };
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or(level))
        .format_timestamp(None)
        .format_target(false)
        .init();
    // Ctrl-C asks the stages to stop between items (util::interrupt); a second one ends the process.
    let _ = ctrlc::set_handler(|| {
        if insgen::util::interrupt::requested() {
            std::process::exit(130);
        }
        insgen::util::interrupt::request();
    });
    match insgen::cli::run_logged(cli, &argv) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            // A closed pipe (e.g. `insgen inspect | head`) is not a failure.
            if err.chain().any(|c| {
                c.downcast_ref::<std::io::Error>().is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
            }) {
                return ExitCode::SUCCESS;
            }
            eprintln!("error: {err:#}");
            if err.chain().any(insgen::util::interrupt::in_chain) || insgen::util::interrupt::requested() {
                return ExitCode::from(130);
            }
            ExitCode::FAILURE
        }
    }
}
