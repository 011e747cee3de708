//! `index.html`: the export in a browser — what the dataset is (images and annotations per split and
//! per area), the statistics table, the charts, a contact sheet of annotated frames per area, the
//! flight plan of every camera, and links to the dataset card, the manifest and the COCO files.
//!
//! The page is static HTML with inline CSS: no script, no font or file from the network, and every
//! link and image relative to the export folder, so the page works from `file://` and keeps working
//! after the folder is moved or archived. The figures it shows beside the statistics report's are
//! written into the folder: `figures/<area>/contact_sheet.png` (drawn here) and
//! `figures/<area>/<camera>/flight_plan.png` (copied from the work directory, where `sample` drew
//! it; a camera without one is named on the page instead).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::coco::Split;
use super::format::Dataset;
use super::manifest::DatasetManifest;
use super::stats::{self, Stats};
use super::table::{escape_html, Table};
use super::CocoError;
use crate::layout::{
    ExportDir, WorkDir, CARD_FILE, CONTACT_SHEET_FILE, DATASET_FILE, STATS_JSON_FILE, STATS_MD_FILE,
};

/// Frames on each area's contact sheet (at most; fewer when `--contact-sheet` asks for fewer).
pub const FRAMES_PER_AREA: usize = 8;

/// What the page shows besides the manifest and the statistics.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
struct Figures {
    /// The report's charts: (file name, caption).
    charts: Vec<(String, String)>,
    /// The report's contact sheet of all splits, when drawn.
    contact_sheet: Option<String>,
    /// Per area (in manifest order): its contact sheet's name, when drawn.
    area_sheets: Vec<(String, Option<String>)>,
    /// Per (area, camera): the flight plan's name in the export, or `None` when the work directory
    /// has none.
    flight_plans: Vec<(String, String, Option<String>)>,
}

/// Where [`write_index`] finds each camera's flight plan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlightPlans<'a> {
    /// In the work directory at this path, where `sample` drew them: each is copied into the export
    /// (`export-coco`, `merge`).
    WorkDir(&'a Path),
    /// Already in the export, where the export that wrote it copied them: kept as they are (`insgen
    /// stats`, which may run on a folder moved away from its work directory).
    InExport,
}

/// Draws each area's contact sheet, places each camera's flight plan in the export (`flight_plans`),
/// and writes `index.html` (see the module doc) into `out_dir`; `names_root` is the directory the COCO
/// files' names are relative to, `contact_sheet_images` the report's `--contact-sheet` (0: no contact
/// sheets). Returns the files written.
///
/// # Errors
/// The manifest (`dataset.json`, written before) unreadable; I/O and PNG errors naming the file.
pub fn write_index(
    out_dir: &Path,
    names_root: &Path,
    flight_plans: FlightPlans,
    datasets: &[(Split, &Dataset)],
    stats: &Stats,
    contact_sheet_images: usize,
) -> Result<Vec<PathBuf>, CocoError> {
    let out = ExportDir::new(out_dir);
    let manifest_path = out.manifest();
    let bytes = crate::util::read_file(&manifest_path)?;
    let manifest: DatasetManifest =
        serde_json::from_slice(&bytes).map_err(|e| CocoError::json(&manifest_path, e))?;
    let mut written = Vec::new();
    let mut figures = Figures {
        charts: stats::charts(stats).into_iter().map(|(file, c)| (file.to_string(), c.title)).collect(),
        contact_sheet: (contact_sheet_images > 0).then(|| CONTACT_SHEET_FILE.to_string()),
        ..Figures::default()
    };
    let per_area = contact_sheet_images.min(FRAMES_PER_AREA);
    for a in &manifest.areas {
        let sheet = match Split::parse(&a.split) {
            Some(split) if per_area > 0 => {
                let name = ExportDir::contact_sheet_name(&a.name);
                let path = out_dir.join(&name);
                let of_split: Vec<(Split, &Dataset)> =
                    datasets.iter().filter(|(s, _)| *s == split).copied().collect();
                stats::area_contact_sheet(&of_split, &a.name, names_root, per_area)?.save(&path)?;
                written.push(path);
                Some(name)
            }
            _ => None,
        };
        figures.area_sheets.push((a.name.clone(), sheet));
        for c in &a.cameras {
            let placed = place_flight_plan(out_dir, flight_plans, &a.name, &c.name, &mut written)?;
            figures.flight_plans.push((a.name.clone(), c.name.clone(), placed));
        }
    }
    let html = index_html(&manifest, stats, &figures, &present(out_dir));
    let path = out.index();
    crate::util::write_bytes_atomic(&path, html.as_bytes())?;
    written.push(path);
    Ok(written)
}

/// The flight plan of `area`/`camera` in the export (its name there), copied from the work directory
/// (and added to `written`) or found in the export; `None` when there is none.
fn place_flight_plan(
    out_dir: &Path,
    flight_plans: FlightPlans,
    area: &str,
    camera: &str,
    written: &mut Vec<PathBuf>,
) -> Result<Option<String>, CocoError> {
    let name = ExportDir::flight_plan_name(area, camera);
    let to = out_dir.join(&name);
    match flight_plans {
        FlightPlans::WorkDir(workdir) => {
            let from = WorkDir::new(workdir).area(area).camera(camera).flight_plan();
            if !from.is_file() {
                log::warn!(
                    "index.html: no flight plan at {} (run `insgen sample` to draw it)",
                    from.display()
                );
                return Ok(None);
            }
            crate::util::write_bytes_atomic(&to, &crate::util::read_file(&from)?)?;
            written.push(to);
            Ok(Some(name))
        }
        FlightPlans::InExport => {
            if to.is_file() {
                Ok(Some(name))
            } else {
                log::info!("index.html: the export holds no flight plan for {area} / {camera}");
                Ok(None)
            }
        }
    }
}

/// Which of the report's optional files are in `dir` (so the page links only to what exists).
fn present(dir: &Path) -> Vec<String> {
    [CARD_FILE, DATASET_FILE, STATS_MD_FILE, STATS_JSON_FILE]
        .into_iter()
        .filter(|f| dir.join(f).is_file())
        .map(str::to_string)
        .collect()
}

/// A relative link to `name` (a `/`-separated name inside the export): each segment percent-encoded
/// but for unreserved characters, so any area or camera name makes a valid relative URL.
pub fn href(name: &str) -> String {
    let mut s = String::with_capacity(name.len());
    for (i, seg) in name.split('/').enumerate() {
        if i > 0 {
            s.push('/');
        }
        for b in seg.bytes() {
            if b.is_ascii_alphanumeric() || b"-._~".contains(&b) {
                s.push(b as char);
            } else {
                let _ = write!(s, "%{b:02X}");
            }
        }
    }
    s
}

const STYLE: &str = "body{font-family:'DejaVu Sans',Verdana,sans-serif;margin:24px auto;max-width:1320px;\
padding:0 16px;color:#1a1a1a;line-height:1.45}h1{margin-bottom:4px}h2{border-bottom:1px solid #ccc;\
padding-bottom:4px;margin-top:36px}table{border-collapse:collapse;margin:8px 0;font-size:14px}\
th,td{border:1px solid #ccc;padding:4px 8px;text-align:left;vertical-align:top}th{background:#f2f2f2}\
.n{text-align:right}figure{margin:12px 0 24px}figure img{max-width:100%;height:auto;border:1px solid #ddd}\
figcaption{color:#444;font-size:14px}nav a{margin-right:14px}.note{color:#555;font-size:14px}\
code{background:#f4f4f4;padding:0 3px}\
.plans{display:grid;grid-template-columns:repeat(auto-fill,minmax(400px,1fr));gap:16px}.plans figure{margin:0}";

/// The page.
fn index_html(m: &DatasetManifest, stats: &Stats, fig: &Figures, present: &[String]) -> String {
    let images: u64 = m.files.iter().map(|f| f.images).sum();
    let annotations: u64 = m.files.iter().map(|f| f.annotations).sum();
    let mut s = String::new();
    let _ = write!(
        s,
        "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>Building-instance dataset: {images} images, {annotations} annotations</title>\n\
         <style>{STYLE}</style>\n</head>\n<body>\n<h1>Building-instance dataset</h1>\n"
    );
    let commit =
        if m.tool.git_commit.is_empty() { String::new() } else { format!(", commit {}", m.tool.git_commit) };
    let _ = writeln!(
        s,
        "<p>Aerial (UAV) frames of {} area(s) with one instance mask per visible building: <b>{images} images</b>, \
         <b>{annotations} annotations</b>, one category (<code>building</code>). Made by insgen {}{}.</p>",
        m.areas.len(),
        escape_html(&m.tool.version),
        escape_html(&commit)
    );
    s.push_str("<nav>");
    let describe = |f: &str| match f {
        CARD_FILE => "dataset card",
        DATASET_FILE => "manifest",
        STATS_MD_FILE => "statistics report",
        _ => "statistics (JSON)",
    };
    for f in present {
        let _ = write!(s, "<a href=\"{}\">{} (<code>{}</code>)</a>", href(f), describe(f), escape_html(f));
    }
    s.push_str("</nav>\n<nav>");
    for (id, name) in [
        ("splits", "Splits"),
        ("areas", "Areas and cameras"),
        ("statistics", "Statistics"),
        ("charts", "Charts"),
        ("contact-sheets", "Contact sheets"),
        ("flight-plans", "Flight plans"),
        ("sources", "Sources and licences"),
    ] {
        let _ = write!(s, "<a href=\"#{id}\">{name}</a>");
    }
    s.push_str("</nav>\n");
    s.push_str(&splits_section(m));
    s.push_str(&areas_section(m, stats));
    let _ = writeln!(
        s,
        "<h2 id=\"statistics\">Statistics</h2>\n{}<p class=\"note\">{}</p>",
        stats::splits_table(stats).html(),
        escape_html(stats::SIZE_CLASSES_NOTE)
    );
    s.push_str("<h2 id=\"charts\">Charts</h2>\n");
    for (file, caption) in &fig.charts {
        s.push_str(&figure(file, caption));
    }
    s.push_str(&figures_section(m, fig));
    s.push_str(&sources_section(m));
    s.push_str("</body>\n</html>\n");
    s
}

/// `<figure>` of an image in the export with its caption.
fn figure(file: &str, caption: &str) -> String {
    format!(
        "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{}</figcaption></figure>\n",
        href(file),
        escape_html(caption),
        escape_html(caption)
    )
}

/// `<figure>` of an image shown smaller than it is, linked to itself at full size.
fn thumbnail(file: &str, caption: &str) -> String {
    format!(
        "<figure><a href=\"{0}\"><img src=\"{0}\" alt=\"{1}\"></a><figcaption>{1} (click for full size)\
         </figcaption></figure>\n",
        href(file),
        escape_html(caption)
    )
}

fn splits_section(m: &DatasetManifest) -> String {
    let mut t = Table::new(&[
        ("split", false),
        ("COCO file", false),
        ("images", true),
        ("annotations", true),
        ("areas", false),
    ]);
    for f in &m.files {
        let areas: Vec<&str> =
            m.areas.iter().filter(|a| a.split == f.split).map(|a| a.name.as_str()).collect();
        t.push(vec![
            f.split.clone(),
            f.path.clone(),
            f.images.to_string(),
            f.annotations.to_string(),
            areas.join(", "),
        ]);
    }
    let mut html = t.html();
    // The file names become links (the table escapes its cells; the names are in the manifest).
    for f in &m.files {
        let cell = format!("<td>{}</td>", escape_html(&f.path));
        let link =
            format!("<td><a href=\"{}\"><code>{}</code></a></td>", href(&f.path), escape_html(&f.path));
        html = html.replacen(&cell, &link, 1);
    }
    format!("<h2 id=\"splits\">Splits</h2>\n<p class=\"note\">Splits are geographic: all images of an area are in one split.</p>\n{html}")
}

fn areas_section(m: &DatasetManifest, stats: &Stats) -> String {
    let mut t = Table::new(&[
        ("area", false),
        ("split", false),
        ("camera", false),
        ("frame size (px)", true),
        ("images", true),
        ("annotations", true),
        ("buildings seen / in model", true),
    ]);
    for a in &m.areas {
        let seen =
            stats.areas.iter().find(|x| x.area == a.name).map(|x| {
                format!("{} / {} ({:.0} %)", x.buildings_seen, x.buildings_total, 100.0 * x.coverage)
            });
        for c in &a.cameras {
            t.push(vec![
                format!("{}{}", a.name, if a.held_out { " (held out)" } else { "" }),
                a.split.clone(),
                super::card::camera_and_preset(&c.name, &c.preset),
                format!("{} × {}", c.width_px, c.height_px),
                c.images.to_string(),
                c.annotations.to_string(),
                seen.clone().unwrap_or_else(|| "—".into()),
            ]);
        }
    }
    format!("<h2 id=\"areas\">Areas and cameras</h2>\n{}", t.html())
}

fn figures_section(m: &DatasetManifest, fig: &Figures) -> String {
    let mut s = String::from(
        "<h2 id=\"contact-sheets\">Contact sheets</h2>\n<p class=\"note\">Annotated frames: \
         each building's masks filled and outlined in its own colour over the photo.</p>\n",
    );
    for (area, sheet) in &fig.area_sheets {
        let split = m.areas.iter().find(|a| &a.name == area).map_or("", |a| a.split.as_str());
        match sheet {
            Some(file) => s.push_str(&figure(file, &format!("{area} ({split} split): annotated frames"))),
            None => {
                let _ = writeln!(
                    s,
                    "<p class=\"note\">{}: no contact sheet (<code>--contact-sheet 0</code>).</p>",
                    escape_html(area)
                );
            }
        }
    }
    if let Some(file) = &fig.contact_sheet {
        s.push_str(&figure(file, "Frames of every split"));
    }
    s.push_str(
        "<h2 id=\"flight-plans\">Flight plans</h2>\n<p class=\"note\">Top views (north up) of each camera's \
         sampled poses over its area, drawn by <code>insgen sample</code>.</p>\n",
    );
    let missing: Vec<String> = fig
        .flight_plans
        .iter()
        .filter(|f| f.2.is_none())
        .map(|(area, camera, _)| format!("{} / {}", escape_html(area), escape_html(camera)))
        .collect();
    if !missing.is_empty() {
        let _ = writeln!(
            s,
            "<p class=\"note\">No flight plan in the work directory for: {}.</p>",
            missing.join(", ")
        );
    }
    s.push_str("<div class=\"plans\">\n");
    for (area, camera, file) in &fig.flight_plans {
        if let Some(file) = file {
            s.push_str(&thumbnail(file, &format!("{area} / {camera}")));
        }
    }
    s.push_str("</div>\n");
    s
}

fn sources_section(m: &DatasetManifest) -> String {
    let mut s = String::from("<h2 id=\"sources\">Sources, licences and attributions</h2>\n<ul>\n");
    for a in &m.areas {
        let attribution = if a.attributions.is_empty() {
            "no attribution given".to_string()
        } else {
            a.attributions.join("; ")
        };
        let _ = write!(s, "<li><b>{}</b>: {}<ul>", escape_html(&a.name), escape_html(&attribution));
        for src in &a.sources {
            let line = super::card::source_line(src).replace('`', "");
            let _ = write!(s, "<li>{}</li>", escape_html(&line));
        }
        s.push_str("</ul></li>\n");
    }
    s.push_str("</ul>\n<p class=\"note\">The masks and images derive from these models: use them under the sources' \
         licences, with their attributions.</p>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn links_are_relative_and_encoded() {
        assert_eq!(href("figures/demo/cam2/flight_plan.png"), "figures/demo/cam2/flight_plan.png");
        assert_eq!(href("figures/my area/cam#1/x.png"), "figures/my%20area/cam%231/x.png");
        assert_eq!(href("figures/東京/a.png"), "figures/%E6%9D%B1%E4%BA%AC/a.png");
    }
}
