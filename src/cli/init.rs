//! `insgen init`: write a commented scene file for a new area from its building-model files.

use std::path::PathBuf;

use anyhow::Context;

use super::Global;
use crate::lod::Format;
use crate::scene::config::Split;
use crate::scene::init::{init, InitPlan};

/// The geographic split of the new area.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum SplitArg {
    /// Training data.
    #[default]
    Train,
    /// Validation data.
    Val,
    /// Test data.
    Test,
}

/// A reader, for files whose names do not say it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FormatArg {
    /// CityGML.
    Citygml,
    /// CityJSON or CityJSONSeq.
    Cityjson,
    /// Wavefront OBJ with a JSON sidecar.
    Obj,
    /// 3D Tiles.
    #[value(name = "3dtiles")]
    Tiles3d,
}

impl From<FormatArg> for Format {
    fn from(f: FormatArg) -> Format {
        match f {
            FormatArg::Citygml => Format::CityGml,
            FormatArg::Cityjson => Format::CityJson,
            FormatArg::Obj => Format::Obj,
            FormatArg::Tiles3d => Format::Tiles3d,
        }
    }
}

/// Writes a commented scene file for a new area from its building-model files.
///
/// Reads the SOURCE files (CityGML, CityJSON, OBJ, 3D Tiles; a folder means every file inside a reader
/// takes, a quoted glob such as 'udx/bldg/*.gml' the files it matches), detects format and CRS as
/// `insgen inspect` does, and writes <scenes>/<NAME>.toml: one [[sources]] per SOURCE (paths relative
/// to the scene file), [origin] at the centre of the buildings' extent, [geoid] for their heights, an
/// attribution to fill in, and camera sampling hints. `insgen prepare --area NAME` takes the file as
/// it is. An existing file is kept unless --force.
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen init munich data/munich/\n  \
insgen init chiyoda 'plateau/udx/bldg/*.gml'      # quote globs: the scene file keeps the pattern\n  \
insgen init rotterdam-val tiles/ --split val\n  \
insgen init old-town model.obj --crs EPSG:25832\n  \
insgen --scenes my-scenes init campus lod2/ --force")]
pub struct Args {
    /// The area's name: the scene file's stem and the work directory's folder.
    #[arg(value_name = "NAME")]
    pub name: String,
    /// Building-model files, folders or quoted globs; one [[sources]] entry each.
    #[arg(value_name = "SOURCE", required = true)]
    pub sources: Vec<PathBuf>,
    /// Which split of a dataset the area's frames go to.
    #[arg(long, value_enum, value_name = "SPLIT", default_value_t = SplitArg::Train)]
    pub split: SplitArg,
    /// CRS of files that declare none (or to override theirs), e.g. EPSG:25832.
    #[arg(long, value_name = "CRS")]
    pub crs: Option<String>,
    /// Reader for files whose names do not say it.
    #[arg(long, value_enum, value_name = "FORMAT")]
    pub format: Option<FormatArg>,
    /// LoD to read (e.g. 2, 1.2); default: the highest the files have.
    #[arg(long, value_name = "LOD")]
    pub lod: Option<String>,
    /// Write the scene file here instead of <scenes>/<NAME>.toml (its stem must be NAME).
    #[arg(long, value_name = "FILE", hide_short_help = true)]
    pub out: Option<PathBuf>,
    /// Replace an existing scene file.
    #[arg(long)]
    pub force: bool,
}

impl Args {
    /// The plan: the scene file's path, the inputs from the working directory.
    pub fn plan(&self, global: &Global) -> anyhow::Result<InitPlan> {
        let scene_file =
            self.out.clone().unwrap_or_else(|| global.scenes.join(format!("{}.toml", self.name)));
        if scene_file.file_stem().and_then(|s| s.to_str()) != Some(self.name.as_str()) {
            anyhow::bail!("--out {}: a scene file's name must be {}.toml", scene_file.display(), self.name);
        }
        Ok(InitPlan {
            name: self.name.clone(),
            scene_file,
            inputs: self.sources.clone(),
            base: std::env::current_dir().context("the working directory")?,
            split: match self.split {
                SplitArg::Train => Split::Train,
                SplitArg::Val => Split::Val,
                SplitArg::Test => Split::Test,
            },
            crs: self.crs.clone(),
            format: self.format.map(Format::from),
            lod: self.lod.clone(),
            force: self.force,
            sampling_hints: Some(crate::camera::hints::sampling_hints),
        })
    }
}

/// Runs `insgen init`.
pub fn run(args: &Args, global: &Global) -> anyhow::Result<()> {
    let plan = args.plan(global)?;
    let printer = global.printer();
    let report = init(&plan, &printer.progress()).with_context(|| format!("insgen init {}", plan.name))?;
    let s = &report.survey;
    let centre = s.centre_deg.expect("init refuses sources without buildings");
    let size = s.size_m.expect("as the centre");
    printer.summary(format!(
        "{}: {} buildings in {} file(s), {}, {:.0} m × {:.0} m around {:.6}° N {:.6}° E\n\
         next: fill in `attribution`, check with `insgen inspect {}`, then `insgen prepare --area {}`",
        report.scene_file.display(),
        s.buildings,
        s.files.len(),
        s.crs.join(" + "),
        size[0],
        size[1],
        centre.lat_deg,
        centre.lon_deg,
        plan.inputs.iter().map(|i| shell_word(&i.to_string_lossy())).collect::<Vec<_>>().join(" "),
        plan.name
    ));
    Ok(())
}

/// `s` quoted for a POSIX shell when it holds anything but plain path characters.
fn shell_word(s: &str) -> String {
    if s.chars().all(|c| c.is_ascii_alphanumeric() || "/._-+:,@".contains(c)) {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::testing::parse;

    #[test]
    fn name_and_sources_are_required() {
        assert!(parse::<Args>(&["x"]).is_err());
        let p = parse::<Args>(&["x", "a/", "b/*.gml", "--split", "val", "--crs", "EPSG:25832"]).unwrap();
        assert_eq!(p.args.sources, [PathBuf::from("a/"), PathBuf::from("b/*.gml")]);
        let plan = p.args.plan(&p.global).unwrap();
        assert_eq!(plan.scene_file, PathBuf::from("scenes/x.toml"));
        assert_eq!((plan.split, plan.crs.as_deref()), (Split::Val, Some("EPSG:25832")));
        assert!(!plan.force);
    }

    #[test]
    fn out_must_carry_the_name() {
        let p = parse::<Args>(&["x", "a", "--out", "elsewhere/y.toml"]).unwrap();
        let e = p.args.plan(&p.global).unwrap_err().to_string();
        assert!(e.contains("must be x.toml"), "{e}");
        let p = parse::<Args>(&["--scenes", "s", "x", "a", "--format", "3dtiles"]).unwrap();
        let plan = p.args.plan(&p.global).unwrap();
        assert_eq!((plan.scene_file, plan.format), (PathBuf::from("s/x.toml"), Some(Format::Tiles3d)));
    }

    #[test]
    fn globs_are_quoted_in_the_next_command() {
        assert_eq!(shell_word("data/x.gml"), "data/x.gml");
        assert_eq!(shell_word("data/*.gml"), "'data/*.gml'");
    }
}
