//! The repository's own metadata as its readers see it: CITATION.cff against the Citation File Format
//! schema, the licence files Cargo.toml names, and the relative links of the documentation.

use std::path::Path;
use std::process::Command;

use crate::util::{python_with, repo, skip};

fn check_citation(py: &Path, root: &Path) -> std::process::Output {
    let wheels = repo().join(".venv/share/insgen-cff");
    Command::new(py)
        .arg(repo().join("scripts/check_citation.py"))
        .arg(root)
        .arg(wheels)
        .output()
        .expect("run check_citation.py")
}

#[test]
fn citation_file_is_valid_cff_and_agrees_with_cargo_toml_and_the_licence_files() {
    let Some(py) = python_with(&["yaml", "jsonschema"]) else { return };
    if !repo().join(".venv/share/insgen-cff").is_dir() {
        return skip("the CFF schema wheel is not in .venv/share/insgen-cff (run scripts/setup.sh)");
    }
    let out = check_citation(&py, &repo());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "CITATION.cff check failed:\n{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("CITATION.cff valid"), "{text}");

    // The check can fail: a copy with an unknown key, another version and no Apache licence file.
    let dir = tempfile::tempdir().unwrap();
    let cff = std::fs::read_to_string(repo().join("CITATION.cff")).unwrap();
    let broken = cff.replacen("cff-version: 1.2.0", "cff-version: 1.2.0\npublisher: nobody", 1);
    let broken = broken.replacen("\nversion: ", "\nversion: 9.9.9-", 1);
    std::fs::write(dir.path().join("CITATION.cff"), broken).unwrap();
    std::fs::copy(repo().join("Cargo.toml"), dir.path().join("Cargo.toml")).unwrap();
    std::fs::copy(repo().join("LICENSE-MIT"), dir.path().join("LICENSE-MIT")).unwrap();
    let out = check_citation(&py, dir.path());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(!out.status.success(), "a broken CITATION.cff passed:\n{text}");
    assert!(text.contains("'publisher' was unexpected"), "{text}");
    assert!(text.contains("version 9.9.9-"), "{text}");
    assert!(text.contains("LICENSE-APACHE: no licence file"), "{text}");
}

/// Relative link targets of a Markdown text: `](target)` with no scheme, without `#fragment`.
fn relative_links(markdown: &str) -> Vec<String> {
    let mut links = Vec::new();
    let mut rest = markdown;
    while let Some(at) = rest.find("](") {
        rest = &rest[at + 2..];
        let Some(end) = rest.find(')') else { break };
        let target = rest[..end].split('#').next().unwrap_or("").trim();
        let external = target.contains("://") || target.starts_with("mailto:");
        if !target.is_empty() && !external && !target.contains(' ') {
            links.push(target.to_string());
        }
    }
    links
}

#[test]
fn every_relative_link_in_the_documentation_resolves() {
    let mut docs = vec![repo().join("README.md"), repo().join("ARCHITECTURE.md")];
    if let Ok(entries) = std::fs::read_dir(repo().join("docs")) {
        let mut more: Vec<_> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
        more.retain(|p| p.extension().is_some_and(|e| e == "md"));
        more.sort();
        docs.extend(more);
    }
    let mut broken = Vec::new();
    let mut checked = 0;
    for doc in &docs {
        let text = std::fs::read_to_string(doc).unwrap();
        for link in relative_links(&text) {
            checked += 1;
            if !doc.parent().unwrap().join(&link).exists() {
                broken.push(format!("{}: {link}", doc.display()));
            }
        }
    }
    assert!(checked > 0, "no relative links found in {docs:?}");
    assert!(broken.is_empty(), "links to missing files:\n{}", broken.join("\n"));
    assert_eq!(
        relative_links("see [a](x.md#y), [b](https://e.org) and [c](../d/e.png)"),
        ["x.md", "../d/e.png"]
    );
}
