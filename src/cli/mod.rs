//! The `insgen` command line: argument definitions (clap derive) and one `run` function per command.
//!
//! Each command lives in its own file with an `Args` struct and a `run(&Args, &Global)` function; the
//! library stages it calls never see clap types. Errors are `anyhow` chains printed once by `main`.
//!
//! Exit codes: 0 success, 1 failure (the cause chain is printed on stderr), 2 usage error (clap).

pub mod progress;
pub mod render_rgb;

use std::path::PathBuf;

use clap::{Parser, Subcommand};

/// Synthetic building-instance datasets for UAV visual localization against LoD city models.
#[derive(Debug, Parser)]
#[command(name = "insgen", version, about, max_term_width = 100)]
#[command(after_long_help = "Typical run:\n  insgen prepare --area demo\n  insgen sample --area demo --camera cam2\n  \
insgen render-masks --area demo --camera cam2\n  insgen export-coco\n\nOr all at once on the embedded city: insgen demo")]
pub struct Cli {
    #[command(flatten)]
    pub global: Global,
    #[command(subcommand)]
    pub command: Command,
}

/// Options shared by every command.
#[derive(Debug, Clone, clap::Args)]
pub struct Global {
    /// Directory where all outputs go (one sub-directory per area).
    #[arg(long, global = true, value_name = "DIR", default_value = "runs")]
    pub workdir: PathBuf,
    /// Directory holding the area definitions (`<area>.toml`).
    #[arg(long, global = true, value_name = "DIR", default_value = "scenes")]
    pub scenes: PathBuf,
    /// Print more (repeat for debug logs); RUST_LOG overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// Print only errors.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// Hide progress bars.
    #[arg(long, global = true)]
    pub no_progress: bool,
}

impl Global {
    /// The progress reporter for this run.
    pub fn progress(&self) -> progress::Bar {
        use std::io::IsTerminal;
        let visible = !self.quiet && !self.no_progress && self.verbose == 0 && std::io::stderr().is_terminal();
        progress::Bar::new(visible)
    }
}

#[derive(Debug, Subcommand)]
pub enum Command {}

/// Runs the parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {}
}
