//! `insgen init`: a commented scene file (`scenes/<area>.toml`) written from the files of a new area.
//!
//! Each input (a file, a folder or a glob; see [`super::sources`]) becomes one `[[sources]]` entry
//! whose `path` is the input as typed, rewritten relative to the scene file's folder (absolute inputs
//! stay absolute). The files are surveyed as `insgen inspect` does ([`super::survey`]): the format and
//! CRS each reader finds, the extent, and its centre, which becomes `[origin]` — the origin `prepare`
//! would take itself, pinned so that adding files later does not move the area's frame. The file also
//! gets `[geoid]` for the heights the CRS has, an attribution the user must fill in, and camera
//! sampling hints scaled to the extent (from the camera stage, through [`InitPlan::sampling_hints`]).
//!
//! The text is parsed back with [`SceneConfig::parse`] and its sources expanded again before it is
//! written (atomically), so what `init` writes is a file `prepare` takes as it is. An existing file
//! is kept unless the plan says `force`.

use std::fmt::Write as _;
use std::path::{Component, Path, PathBuf};

use crate::geo::HeightKind;
use crate::lod::Format;
use crate::util::{self, FileError, Progress};

use super::config::{SceneConfig, Split};
use super::sources::{self, SourcesError};
use super::survey::{self, FileSurvey, Survey, SurveyOptions};
use super::SceneError;

/// Text that marks a value the user must fill in before publishing a dataset; `prepare` warns while
/// the attribution still starts with it.
pub const TODO: &str = "TODO:";

/// What `insgen init` is asked to do.
#[derive(Debug, Clone)]
pub struct InitPlan {
    /// The area's name (the scene file's stem).
    pub name: String,
    /// The scene file to write.
    pub scene_file: PathBuf,
    /// The inputs as typed: files, folders or globs, relative to `base` unless absolute.
    pub inputs: Vec<PathBuf>,
    /// The folder relative inputs start from (the working directory).
    pub base: PathBuf,
    /// The area's split.
    pub split: Split,
    /// A CRS for files that declare none (or to override theirs).
    pub crs: Option<String>,
    /// The reader for every file (`None`: from each name).
    pub format: Option<Format>,
    /// The LoD to read.
    pub lod: Option<String>,
    /// Replace an existing scene file.
    pub force: bool,
    /// The `[sampling]` part of the file for an area of this west–east and south–north size in
    /// metres (the camera stage's [`crate::camera::hints::sampling_hints`], passed in because the
    /// scene stage comes first); `None` writes none.
    pub sampling_hints: Option<fn([f64; 2]) -> String>,
}

/// Why `init` wrote nothing.
#[derive(Debug, thiserror::Error)]
pub enum InitError {
    /// The scene file exists and `force` was not given.
    #[error("{} exists; pass --force to replace it", path.display())]
    Exists {
        /// The scene file.
        path: PathBuf,
    },
    /// The name cannot name an area (a folder of the work directory and the scene file's stem).
    #[error("area name {name:?}: use letters, digits, `-`, `_` and `.`, not starting with `.`")]
    Name {
        /// The name given.
        name: String,
    },
    /// An input names no file to read.
    #[error("{}", input.display())]
    Input {
        /// The input as typed.
        input: PathBuf,
        /// What it names (or does not).
        #[source]
        source: SourcesError,
    },
    /// The files of one input are in different CRSs: one `[[sources]]` entry cannot say how to read them.
    #[error(
        "{}: the files are in different CRSs ({}); give each CRS its own input (a folder or a glob per \
         CRS), or --crs to read them all in one",
        input.display(),
        crs.iter().map(|(c, f)| format!("{c}: {}", f.display())).collect::<Vec<_>>().join("; ")
    )]
    MixedCrs {
        /// The input as typed.
        input: PathBuf,
        /// Each CRS with its first file.
        crs: Vec<(String, PathBuf)>,
    },
    /// A file declares no CRS and none was given.
    #[error("{}: the file declares no CRS; pass --crs EPSG:NNNN (the CRS of its coordinates)", file.display())]
    NoCrs {
        /// The file.
        file: PathBuf,
    },
    /// The inputs hold no building.
    #[error("no building in {} file(s) of {}", files, inputs)]
    NoBuildings {
        /// Files read.
        files: usize,
        /// The inputs, as typed.
        inputs: String,
    },
    /// Reading or placing a file failed, or the written text would not parse (a bug).
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// Writing the scene file failed.
    #[error(transparent)]
    File(#[from] FileError),
}

/// What `init` wrote.
#[derive(Debug, Clone)]
pub struct InitReport {
    /// The scene file written.
    pub scene_file: PathBuf,
    /// Its text.
    pub text: String,
    /// The survey of all files, in input order.
    pub survey: Survey,
    /// Files per input.
    pub files_per_input: Vec<usize>,
}

/// Surveys the inputs and writes the scene file (see the module doc).
///
/// # Errors
/// [`InitError`]: an existing file without `force`, a bad name, an input naming nothing, mixed CRSs
/// within an input, no building, a file that cannot be read or placed, a failed write.
pub fn init(plan: &InitPlan, progress: &dyn Progress) -> Result<InitReport, InitError> {
    let ok_name = !plan.name.is_empty()
        && !plan.name.starts_with('.')
        && plan.name.chars().all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c));
    if !ok_name {
        return Err(InitError::Name { name: plan.name.clone() });
    }
    if plan.scene_file.exists() && !plan.force {
        return Err(InitError::Exists { path: plan.scene_file.clone() });
    }
    let inputs = collapse_shell_globs(&plan.base, &plan.inputs, plan.format);
    let plan = &InitPlan { inputs, ..plan.clone() };
    let mut files = Vec::new();
    let mut files_per_input = Vec::new();
    for input in &plan.inputs {
        let found = sources::expand(&plan.base, input, plan.format)
            .map_err(|source| InitError::Input { input: input.clone(), source })?;
        files_per_input.push(found.len());
        files.extend(found);
    }
    let opts = SurveyOptions { lod: plan.lod.clone(), crs: plan.crs.clone(), format: plan.format };
    let survey = survey::survey(&files, &opts, progress)?;
    if let Some(f) = survey.files.iter().find(|f| f.crs.is_none()) {
        return Err(InitError::NoCrs { file: f.file.clone() });
    }
    if survey.buildings == 0 {
        let inputs = plan.inputs.iter().map(|i| i.display().to_string()).collect::<Vec<_>>().join(", ");
        return Err(InitError::NoBuildings { files: files.len(), inputs });
    }
    let mut groups = Vec::new();
    let mut start = 0;
    for (input, n) in plan.inputs.iter().zip(&files_per_input) {
        let group = &survey.files[start..start + n];
        start += n;
        let mut crs: Vec<(String, PathBuf)> = Vec::new();
        for f in group {
            let c = f.crs.clone().expect("checked above: every file has a CRS");
            if !crs.iter().any(|(k, _)| k == &c) {
                crs.push((c, f.file.clone()));
            }
        }
        if crs.len() > 1 {
            return Err(InitError::MixedCrs { input: input.clone(), crs });
        }
        groups.push((input.clone(), group));
    }
    let text = render(plan, &survey, &groups);
    let cfg = SceneConfig::parse(&text, &plan.scene_file)?;
    // The scene file's folder must exist for its relative paths (`../data`) to resolve.
    if let Some(dir) = plan.scene_file.parent().filter(|d| !d.as_os_str().is_empty()) {
        util::create_dir_all(dir)?;
    }
    for i in 0..cfg.sources.len() {
        cfg.source_files(&plan.scene_file, i)?;
    }
    util::write_atomic::<InitError, _>(&plan.scene_file, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes()).map_err(|e| FileError::new("writing", &plan.scene_file, e).into())
    })?;
    Ok(InitReport { scene_file: plan.scene_file.clone(), text, survey, files_per_input })
}

/// The inputs with every run of two or more files that is exactly what `<folder>/*.<ext>` matches
/// (a glob the shell expanded before `init` saw it) replaced by that glob, so that the scene file
/// keeps one `[[sources]]` per glob, as if it had been quoted.
fn collapse_shell_globs(base: &Path, inputs: &[PathBuf], format: Option<Format>) -> Vec<PathBuf> {
    let key = |p: &Path| -> Option<(PathBuf, String)> {
        let full = base.join(p);
        if sources::is_glob(p) || !full.is_file() {
            return None;
        }
        let ext = p.file_name()?.to_str()?.rsplit_once('.')?.1.to_string();
        Some((p.parent()?.to_path_buf(), ext))
    };
    let mut out = Vec::new();
    let mut i = 0;
    while i < inputs.len() {
        let Some(k) = key(&inputs[i]) else {
            out.push(inputs[i].clone());
            i += 1;
            continue;
        };
        let run = inputs[i..].iter().take_while(|p| key(p).as_ref() == Some(&k)).count();
        let glob = k.0.join(format!("*.{}", k.1));
        let given: std::collections::BTreeSet<PathBuf> =
            inputs[i..i + run].iter().map(|p| normalize(&base.join(p))).collect();
        let matched =
            sources::expand(base, &glob, format).ok().map(|m| m.iter().map(|p| normalize(p)).collect());
        if run > 1 && matched.as_ref() == Some(&given) {
            log::info!(
                "{} files of {} are what {} matches: written as that glob",
                run,
                k.0.display(),
                glob.display()
            );
            out.push(glob);
        } else {
            out.extend(inputs[i..i + run].iter().cloned());
        }
        i += run;
    }
    out
}

/// A TOML string literal.
fn quoted(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

/// The scene file's text.
fn render(plan: &InitPlan, survey: &Survey, groups: &[(PathBuf, &[FileSurvey])]) -> String {
    let mut t = String::new();
    let n_files = survey.files.len();
    let lods = survey.lod.iter().map(|(k, v)| format!("LoD{k}: {v}")).collect::<Vec<_>>().join(", ");
    let _ = writeln!(
        t,
        "# Area {:?}, written by `insgen init` from {n_files} file(s): {} buildings ({lods}).",
        plan.name, survey.buildings
    );
    let _ = writeln!(t, "# Check it, fill in the TODO, then run `insgen prepare --area {}`.", plan.name);
    let _ = writeln!(t, "# Keys: README \"Your own city\", and the doc of src/scene/config.rs.");
    let _ = writeln!(t, "name = {}", quoted(&plan.name));
    let _ = writeln!(
        t,
        "split = {}  # train | val | test: which split of a dataset this area's frames go to",
        quoted(plan.split.as_str())
    );
    let crs = survey.crs.join(", ");
    let _ = writeln!(
        t,
        "description = {}",
        quoted(&format!("{}: {} buildings ({crs})", plan.name, survey.buildings))
    );
    let _ = writeln!(t, "# Who made the 3D model and under which licence: copied into every dataset card.");
    let _ = writeln!(
        t,
        "attribution = {}",
        quoted(&format!("{TODO} the model's maker and licence (e.g. 3D city model © City of X, CC BY 4.0)"))
    );
    for (input, files) in groups {
        render_source(&mut t, plan, input, files);
    }
    render_geoid_origin(&mut t, survey);
    if let (Some(hints), Some(size_m)) = (plan.sampling_hints, survey.size_m) {
        t.push_str(&hints(size_m));
    }
    t
}

fn render_source(t: &mut String, plan: &InitPlan, input: &Path, files: &[FileSurvey]) {
    let first = &files[0];
    let buildings: usize = files.iter().map(|f| f.buildings).sum();
    let mut formats: Vec<String> = files.iter().map(|f| format!("{:?}", f.format).to_lowercase()).collect();
    formats.sort();
    formats.dedup();
    let _ = writeln!(
        t,
        "\n# {}: {} file(s), {buildings} buildings, {}",
        input.display(),
        files.len(),
        formats.join(" + ")
    );
    let _ = writeln!(t, "# CRS: {}", first.frame);
    let _ = writeln!(t, "[[sources]]");
    let path = scene_relative(&plan.base, input, &plan.scene_file);
    let kind = if sources::is_glob(input) {
        "a glob: the matching files, sorted"
    } else if files.len() > 1 || plan.base.join(input).is_dir() {
        "a folder: every file inside a reader takes, sorted"
    } else {
        "relative to this file"
    };
    let _ = writeln!(t, "path = {}  # {kind}", quoted(&path.to_string_lossy()));
    if let Some(f) = plan.format {
        let _ = writeln!(
            t,
            "format = {}",
            quoted(&format!("{f:?}").to_lowercase().replace("tiles3d", "3dtiles"))
        );
    }
    match (&plan.crs, &first.crs_declared) {
        (Some(c), _) => {
            let _ = writeln!(t, "crs = {}  # from --crs", quoted(c));
        }
        (None, Some(d)) => {
            let _ = writeln!(
                t,
                "# crs = {}  # the files declare {d}; set crs only to override it",
                quoted(first.crs.as_deref().unwrap_or(d))
            );
        }
        (None, None) => {}
    }
    match &plan.lod {
        Some(l) => {
            let _ = writeln!(t, "lod = {}", quoted(l));
        }
        None => {
            let _ = writeln!(t, "# lod = \"2\"  # default: the highest LoD the files have (≤ 2.2)");
        }
    }
    if let Some(r) = files.iter().find_map(|f| f.relative_heights.as_ref()) {
        let _ = writeln!(
            t,
            "# {} building(s) start at z ≈ 0 m although their {} is not 0: heights above the ground?\n\
             # If so, uncomment:\n# heights = \"above_ground\"\n# ground_attribute = {}",
            r.buildings,
            r.attribute,
            quoted(&r.attribute)
        );
    }
}

fn render_geoid_origin(t: &mut String, survey: &Survey) {
    let orthometric = survey.files.iter().any(|f| f.heights == HeightKind::Orthometric);
    let _ = writeln!(t, "\n[geoid]");
    if orthometric {
        let _ = writeln!(
            t,
            "# The heights are orthometric: EGM96 turns them into ellipsoidal heights. \"proj\" uses the\n\
             # CRS's national geoid grid when PROJ has it installed (see README, Geo-referencing).\nmodel = \"egm96\""
        );
    } else {
        let _ = writeln!(t, "model = \"none\"  # the heights are ellipsoidal already");
    }
    let (Some(e), Some(c), Some(size)) = (survey.extent_deg, survey.centre_deg, survey.size_m) else {
        return;
    };
    let _ = writeln!(
        t,
        "\n# The centre of the buildings' extent, the default origin of `prepare`, pinned so that more files\n\
         # later do not move the area's frame. h_m (ellipsoidal) defaults to the median building base.\n\
         [origin]\nlat_deg = {:.8}\nlon_deg = {:.8}",
        c.lat_deg, c.lon_deg
    );
    let _ = writeln!(
        t,
        "\n# Optional: keep only the buildings inside (default: all). The extent, {:.0} m × {:.0} m:\n\
         # [area]\n# bbox_deg = [{:.7}, {:.7}, {:.7}, {:.7}]  # lon_min, lat_min, lon_max, lat_max",
        size[0], size[1], e.lon_min_deg, e.lat_min_deg, e.lon_max_deg, e.lat_max_deg
    );
}

/// `input` (relative to `base` unless absolute) as the scene file at `scene_file` names it: relative
/// to the scene file's folder when the input was relative, else as given.
pub fn scene_relative(base: &Path, input: &Path, scene_file: &Path) -> PathBuf {
    if input.is_absolute() {
        return input.to_path_buf();
    }
    let target = normalize(&base.join(input));
    let dir = normalize(&base.join(scene_file.parent().unwrap_or(Path::new(""))));
    let (t, d): (Vec<Component>, Vec<Component>) =
        (target.components().collect(), dir.components().collect());
    let common = t.iter().zip(&d).take_while(|(a, b)| a == b).count();
    let mut out = PathBuf::new();
    for _ in common..d.len() {
        out.push("..");
    }
    for c in &t[common..] {
        out.push(c.as_os_str());
    }
    if out.as_os_str().is_empty() {
        out.push(".");
    }
    out
}

/// `p` without `.` components and with `..` applied to what precedes it (lexically: no file system
/// access, so globs and missing paths work too).
fn normalize(p: &Path) -> PathBuf {
    let mut out: Vec<Component> = Vec::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir if matches!(out.last(), Some(Component::Normal(_))) => {
                out.pop();
            }
            c => out.push(c),
        }
    }
    out.iter().map(|c| c.as_os_str()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::NoProgress;

    /// A 4 m cube as CityJSON, its south-west corner at `en_m` in `crs_url` (None: no CRS declared).
    fn cube(path: &Path, en_m: [f64; 2], crs_url: Option<&str>) {
        let meta =
            crs_url.map_or(String::new(), |u| format!("\"metadata\": {{\"referenceSystem\": \"{u}\"}},"));
        let text = format!(
            "{{\"type\": \"CityJSON\", \"version\": \"2.0\", {meta}\
             \"transform\": {{\"scale\": [0.001, 0.001, 0.001], \"translate\": [{}, {}, 0.0]}},\
             \"CityObjects\": {{\"c{}\": {{\"type\": \"Building\", \"geometry\": [{{\"type\": \"Solid\", \"lod\": \"2\", \
             \"boundaries\": [[[[0, 3, 2, 1]], [[4, 5, 6, 7]], [[0, 1, 5, 4]], [[1, 2, 6, 5]], [[2, 3, 7, 6]], \
             [[3, 0, 4, 7]]]]}}]}}}},\
             \"vertices\": [[0, 0, 0], [4000, 0, 0], [4000, 4000, 0], [0, 4000, 0], [0, 0, 3000], [4000, 0, 3000], \
             [4000, 4000, 3000], [0, 4000, 3000]]}}",
            en_m[0], en_m[1], en_m[0]
        );
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }

    const RD: &str = "https://www.opengis.net/def/crs/EPSG/0/7415";

    fn plan(dir: &Path, inputs: &[&str]) -> InitPlan {
        InitPlan {
            name: "city".into(),
            scene_file: dir.join("scenes/city.toml"),
            inputs: inputs.iter().map(PathBuf::from).collect(),
            base: dir.to_path_buf(),
            split: Split::Val,
            crs: None,
            format: None,
            lod: None,
            force: false,
            sampling_hints: None,
        }
    }

    mod writes {
        use super::*;

        #[test]
        fn origin_is_the_centre_of_the_extent_and_the_file_parses_back() {
            let d = tempfile::tempdir().unwrap();
            cube(&d.path().join("city/a.city.json"), [85_000.0, 447_000.0], Some(RD));
            cube(&d.path().join("city/sub/b.city.json"), [85_300.0, 447_200.0], Some(RD));
            let r = init(&plan(d.path(), &["city"]), &NoProgress).unwrap();
            assert_eq!(r.files_per_input, [2]);
            let cfg = SceneConfig::load(&r.scene_file).unwrap();
            assert_eq!((cfg.name.as_str(), cfg.split), ("city", Split::Val));
            assert_eq!(cfg.sources[0].path.as_deref(), Some(Path::new("../city")));
            assert_eq!(cfg.source_files(&r.scene_file, 0).unwrap().len(), 2);
            // The reference: the footprint corners of both cubes through PROJ (every vertex lies above
            // one of them), the centre of their latitude and longitude ranges.
            let tf = crate::geo::Crs::parse("EPSG:7415").unwrap().transform().unwrap();
            let mut lat = [f64::INFINITY, f64::NEG_INFINITY];
            let mut lon = [f64::INFINITY, f64::NEG_INFINITY];
            for (e, n) in [(85_000.0, 447_000.0), (85_300.0, 447_200.0)] {
                for (de, dn) in [(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)] {
                    let g =
                        tf.to_geodetic([e + de, n + dn, 0.0], crate::geo::AxisConvention::EastNorth).unwrap();
                    lat = [lat[0].min(g.lat_deg), lat[1].max(g.lat_deg)];
                    lon = [lon[0].min(g.lon_deg), lon[1].max(g.lon_deg)];
                }
            }
            let o = cfg.origin.unwrap();
            // init writes 8 decimals: within 5e-9° (≈ 0.5 mm) of the exact centre.
            assert!((o.lat_deg - 0.5 * (lat[0] + lat[1])).abs() <= 5e-9, "{o:?} vs {lat:?}");
            assert!((o.lon_deg - 0.5 * (lon[0] + lon[1])).abs() <= 5e-9, "{o:?} vs {lon:?}");
            assert!(o.h_m.is_none(), "prepare takes the median building base");
            assert_eq!(cfg.geoid.model, crate::scene::config::GeoidModel::Egm96, "EPSG:7415: NAP heights");
            assert!(r.text.contains("# crs = \"EPSG:7415\""), "{}", r.text);
        }

        #[test]
        fn an_existing_file_is_kept_unless_forced() {
            let d = tempfile::tempdir().unwrap();
            cube(&d.path().join("a.city.json"), [85_000.0, 447_000.0], Some(RD));
            let mut p = plan(d.path(), &["a.city.json"]);
            std::fs::create_dir_all(d.path().join("scenes")).unwrap();
            std::fs::write(&p.scene_file, "mine").unwrap();
            let e = init(&p, &NoProgress).unwrap_err();
            assert!(matches!(&e, InitError::Exists { path } if path == &p.scene_file), "{e}");
            assert_eq!(std::fs::read_to_string(&p.scene_file).unwrap(), "mine");
            p.force = true;
            init(&p, &NoProgress).unwrap();
            let cfg = SceneConfig::load(&p.scene_file).unwrap();
            assert_eq!(cfg.sources[0].path.as_deref(), Some(Path::new("../a.city.json")));
        }

        #[test]
        fn a_file_without_crs_takes_the_one_given() {
            let d = tempfile::tempdir().unwrap();
            cube(&d.path().join("a.city.json"), [85_000.0, 447_000.0], None);
            let mut p = plan(d.path(), &["a.city.json"]);
            let e = crate::util::error_chain(&init(&p, &NoProgress).unwrap_err());
            assert!(e.contains("a.city.json: the file declares no CRS") && e.contains("--crs"), "{e}");
            p.crs = Some("EPSG:7415".into());
            init(&p, &NoProgress).unwrap();
            let cfg = SceneConfig::load(&p.scene_file).unwrap();
            assert_eq!(cfg.sources[0].crs.as_deref(), Some("EPSG:7415"));
        }
    }

    mod errors {
        use super::*;

        #[test]
        fn mixed_crs_in_one_input_names_each_with_a_file() {
            let d = tempfile::tempdir().unwrap();
            cube(&d.path().join("mix/a.city.json"), [85_000.0, 447_000.0], Some(RD));
            cube(&d.path().join("mix/b.city.json"), [690_000.0, 5_335_000.0], Some("EPSG:25832"));
            let e = init(&plan(d.path(), &["mix/"]), &NoProgress).unwrap_err();
            let InitError::MixedCrs { input, crs } = &e else { panic!("{e:?}") };
            assert_eq!(input, Path::new("mix/"));
            assert_eq!(crs.iter().map(|(c, _)| c.as_str()).collect::<Vec<_>>(), ["EPSG:7415", "EPSG:25832"]);
            assert!(e.to_string().contains("b.city.json"), "{e}");
            assert!(!d.path().join("scenes/city.toml").exists());
            // One input per CRS works.
            init(&plan(d.path(), &["mix/a.city.json", "mix/b*.json"]), &NoProgress).unwrap();
        }

        #[test]
        fn inputs_naming_nothing_and_bad_names() {
            let d = tempfile::tempdir().unwrap();
            let e = init(&plan(d.path(), &["tiles/*.gml"]), &NoProgress).unwrap_err();
            assert!(matches!(&e, InitError::Input { source: SourcesError::NoMatch { .. }, .. }), "{e:?}");
            let chain = crate::util::error_chain(&e);
            assert!(chain.contains("tiles/*.gml: the pattern matches no file"), "{chain}");
            for bad in ["", ".hidden", "a/b", "a b"] {
                let mut p = plan(d.path(), &["x"]);
                p.name = bad.into();
                assert!(matches!(init(&p, &NoProgress), Err(InitError::Name { .. })), "{bad:?}");
            }
        }
    }

    mod paths {
        use super::*;

        #[test]
        fn files_the_shell_expanded_from_a_glob_become_that_glob() {
            let d = tempfile::tempdir().unwrap();
            for n in ["a", "b", "c"] {
                cube(&d.path().join(format!("t/{n}.city.json")), [85_000.0, 447_000.0], Some(RD));
            }
            let all: Vec<PathBuf> =
                ["t/a.city.json", "t/b.city.json", "t/c.city.json"].map(PathBuf::from).to_vec();
            assert_eq!(collapse_shell_globs(d.path(), &all, None), [PathBuf::from("t/*.json")]);
            // Two of three are not what the glob matches: kept as they are.
            assert_eq!(collapse_shell_globs(d.path(), &all[..2], None), &all[..2]);
            let r = init(&plan(d.path(), &["t/a.city.json", "t/b.city.json", "t/c.city.json"]), &NoProgress)
                .unwrap();
            let cfg = SceneConfig::load(&r.scene_file).unwrap();
            assert_eq!(cfg.sources.len(), 1);
            assert_eq!(cfg.sources[0].path.as_deref(), Some(Path::new("../t/*.json")));
        }

        #[test]
        fn inputs_are_named_from_the_scene_file() {
            let b = Path::new("/project");
            let s = Path::new("scenes/x.toml");
            assert_eq!(scene_relative(b, Path::new("data/city/"), s), Path::new("../data/city"));
            assert_eq!(scene_relative(b, Path::new("./data/*.gml"), s), Path::new("../data/*.gml"));
            assert_eq!(scene_relative(b, Path::new("../other/a.gml"), s), Path::new("../../other/a.gml"));
            assert_eq!(scene_relative(b, Path::new("/abs/a.gml"), s), Path::new("/abs/a.gml"));
            assert_eq!(scene_relative(b, Path::new("scenes/a.gml"), s), Path::new("a.gml"));
            assert_eq!(
                scene_relative(b, Path::new("a.gml"), Path::new("/elsewhere/x.toml")),
                Path::new("../project/a.gml")
            );
            assert_eq!(scene_relative(b, Path::new("scenes"), s), Path::new("."));
        }
    }
}
