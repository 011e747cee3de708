//! `insgen verify DATASET`: checks an exported dataset (see [`crate::export::verify`]).

use std::path::PathBuf;

use anyhow::bail;

/// Checks a dataset against its manifest: every file present, decodable and of the size recorded,
/// every image an RGB frame, every annotation's mask equal to its building's in the ID map.
///
/// Reads DATASET/dataset.json, the COCO files it lists, their images and ID maps (through each file's
/// `info.image_root`). Writes nothing. Prints each problem with its file and exits with status 1 when
/// there is any.
#[derive(Debug, Clone, clap::Args)]
#[command(
    after_long_help = "Examples:\n  insgen verify runs/coco\n  insgen verify /data/uav-buildings -q && echo ok"
)]
pub struct Args {
    /// The dataset: `export-coco`'s output folder (`<workdir>/coco` by default), its `dataset.json`,
    /// or the work directory that holds it.
    #[arg(value_name = "DATASET")]
    pub dataset: PathBuf,
}

/// Runs `insgen verify`.
pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let printer = global.printer();
    let dir = crate::export::verify::dataset_dir(&args.dataset);
    if !dir.exists() {
        bail!(
            "{}: no such file or directory (give the export folder, its dataset.json or the work directory)",
            dir.display()
        );
    }
    let report = crate::export::verify::verify(&dir, &printer.progress());
    for p in &report.problems {
        eprintln!("problem: {p}");
    }
    printer.summary(format!(
        "{}: {} COCO file(s), {} images, {} annotations checked; {} problem(s)",
        dir.display(),
        report.coco_files,
        report.images,
        report.annotations,
        report.problems.len()
    ));
    if !report.problems.is_empty() {
        bail!("{}: {} problem(s) found (listed above)", dir.display(), report.problems.len());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(argv: &[&str]) -> Result<crate::cli::testing::Parsed<Args>, clap::Error> {
        crate::cli::testing::parse(argv)
    }

    #[test]
    fn the_dataset_is_a_required_positional() {
        assert_eq!(parse(&["runs/coco"]).unwrap().args.dataset, PathBuf::from("runs/coco"));
        assert!(parse(&[]).is_err());
    }
}
