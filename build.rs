//! Records the git commit the binary is built from (`INSGEN_GIT_COMMIT`, with `-dirty` when the work
//! tree has uncommitted changes to tracked files), for the dataset manifest. Outside a git checkout (a
//! source tarball) it is `unknown`.

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    let commit = git(&["rev-parse", "HEAD"]).unwrap_or_else(|| "unknown".into());
    let dirty = git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
    println!("cargo:rustc-env=INSGEN_GIT_COMMIT={commit}{}", if dirty { "-dirty" } else { "" });
    // Rebuild when HEAD moves or the index changes (a commit, a checkout, a staged edit).
    if let Some(dir) = git(&["rev-parse", "--absolute-git-dir"]) {
        println!("cargo:rerun-if-changed={dir}/HEAD");
        println!("cargo:rerun-if-changed={dir}/index");
    }
    // Branch refs live in the common directory (shared by worktrees).
    if let (Some(common), Some(r)) = (
        git(&["rev-parse", "--path-format=absolute", "--git-common-dir"]),
        git(&["symbolic-ref", "-q", "HEAD"]),
    ) {
        let reference = std::path::Path::new(&common).join(&r);
        if reference.exists() {
            println!("cargo:rerun-if-changed={}", reference.display());
        }
    }
    println!("cargo:rerun-if-changed=build.rs");
}
