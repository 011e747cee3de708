//! `insgen completions` and `insgen man`: shell completions and man pages, generated from the clap
//! definitions so that they always match `--help`.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::CommandFactory;

/// Print a shell completion script on stdout.
///
/// Generated from the same definitions as `--help`, so every command, flag and value list is there.
#[derive(Debug, Clone, clap::Args)]
#[command(
    after_long_help = "Examples:\n  insgen completions bash > ~/.local/share/bash-completion/completions/insgen\n  \
insgen completions zsh > ~/.zfunc/_insgen\n  \
insgen completions fish > ~/.config/fish/completions/insgen.fish"
)]
pub struct CompletionsArgs {
    /// The shell: bash, elvish, fish, powershell or zsh.
    #[arg(value_name = "SHELL")]
    pub shell: clap_complete::Shell,
}

/// Runs `completions`.
pub fn run_completions(args: &CompletionsArgs, _global: &super::Global) -> anyhow::Result<()> {
    let mut cmd = super::Cli::command();
    let mut out = std::io::stdout().lock();
    clap_complete::generate(args.shell, &mut cmd, "insgen", &mut out);
    out.flush().context("writing the completion script to stdout")?;
    Ok(())
}

/// Write man pages (roff): insgen.1 and one insgen-<command>.1 per command.
///
/// Without --out, prints insgen.1 on stdout.
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen man --out target/man && man -l target/man/insgen.1\n  \
insgen man | man -l -")]
pub struct ManArgs {
    /// Directory for insgen.1 and the per-command pages.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

/// The roff man pages of the command line: `(file name, text)`, insgen.1 first.
///
/// # Errors
/// When clap_mangen fails to render (an I/O error on an in-memory buffer: not expected).
pub fn man_pages() -> std::io::Result<Vec<(String, Vec<u8>)>> {
    let mut cmd = super::Cli::command();
    cmd.build();
    let mut pages = Vec::new();
    let mut buf = Vec::new();
    clap_mangen::Man::new(cmd.clone()).render(&mut buf)?;
    pages.push(("insgen.1".to_string(), buf));
    // `build` adds clap's own `help` subcommand, which needs no page.
    for sub in cmd.get_subcommands().filter(|s| s.get_name() != "help") {
        let name = format!("insgen-{}", sub.get_name());
        let mut buf = Vec::new();
        clap_mangen::Man::new(sub.clone().name(name.clone())).render(&mut buf)?;
        pages.push((format!("{name}.1"), buf));
    }
    Ok(pages)
}

/// Runs `man`.
pub fn run_man(args: &ManArgs, global: &super::Global) -> anyhow::Result<()> {
    let pages = man_pages().context("rendering the man pages")?;
    match &args.out {
        None => {
            let mut out = std::io::stdout().lock();
            out.write_all(&pages[0].1).context("writing insgen.1 to stdout")?;
            out.flush().context("writing insgen.1 to stdout")?;
        }
        Some(dir) => {
            for (name, text) in &pages {
                crate::util::write_bytes_atomic(&dir.join(name), text)?;
            }
            global.printer().summary(format!("wrote {} man pages into {}", pages.len(), dir.display()));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::{Cli, Command};
    use super::*;
    use clap::Parser;

    #[test]
    fn completions_takes_a_known_shell() {
        let cli = Cli::try_parse_from(["insgen", "completions", "zsh"]).unwrap();
        match cli.command {
            Command::Completions(a) => assert_eq!(a.shell, clap_complete::Shell::Zsh),
            _ => panic!("wrong command"),
        }
        assert!(Cli::try_parse_from(["insgen", "completions", "tcsh"]).is_err());
        assert!(Cli::try_parse_from(["insgen", "completions"]).is_err());
    }

    #[test]
    fn man_takes_an_optional_directory() {
        let cli = Cli::try_parse_from(["insgen", "man", "--out", "m"]).unwrap();
        match cli.command {
            Command::Man(a) => assert_eq!(a.out, Some(PathBuf::from("m"))),
            _ => panic!("wrong command"),
        }
        let cli = Cli::try_parse_from(["insgen", "man"]).unwrap();
        assert!(matches!(cli.command, Command::Man(ManArgs { out: None })));
    }

    #[test]
    fn bash_completion_knows_every_command() {
        let mut buf = Vec::new();
        clap_complete::generate(clap_complete::Shell::Bash, &mut Cli::command(), "insgen", &mut buf);
        let text = String::from_utf8(buf).unwrap();
        for sub in Cli::command().get_subcommands() {
            assert!(text.contains(sub.get_name()), "{} missing from the bash completion", sub.get_name());
        }
    }

    #[test]
    fn man_pages_cover_every_command_with_its_examples() {
        let pages = man_pages().unwrap();
        assert_eq!(pages.len(), 1 + Cli::command().get_subcommands().count());
        let (name, text) = &pages[0];
        assert_eq!(name, "insgen.1");
        let text = String::from_utf8_lossy(text);
        assert!(text.starts_with(".ie \\n(.g .ds Aq"), "{}", &text[..80.min(text.len())]);
        assert!(text.contains(".TH insgen 1"), "no title header");
        let prepare = pages.iter().find(|(n, _)| n == "insgen-prepare.1").unwrap();
        assert!(String::from_utf8_lossy(&prepare.1).contains("insgen prepare \\-\\-area demo"));
    }
}
