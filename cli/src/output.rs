//! Where a command's files go, checked before its long work starts: a typo in an output path
//! should cost a second, not a finished evaluation (a 1000-episode rapier evaluation takes
//! minutes, `kumi report compare` more).

use std::path::Path;

use anyhow::{bail, Context, Result};

/// Makes the folder `dir` (and its parents) if it is missing; an error names it.
pub fn ensure_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))
}

/// Checks that `path` can name a file to write later: its folder exists and `path` is not a
/// folder (permissions are not checked). What `what` is (`--episodes`) goes into the error.
/// Nothing is created.
pub fn check_file(path: &Path, what: &str) -> Result<()> {
    if path.is_dir() {
        bail!("{what} {}: is a folder, not a file", path.display());
    }
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !parent.is_dir() {
        bail!(
            "{what} {}: {} is not an existing folder",
            path.display(),
            parent.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("kumi-output-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn a_file_in_an_existing_folder_passes_and_nothing_is_made() {
        let dir = scratch("ok");
        let path = dir.join("episodes.csv");
        check_file(&path, "--episodes").unwrap();
        assert!(!path.exists(), "the check must not create the file");
        check_file(Path::new("episodes.csv"), "--episodes").unwrap();
    }

    #[test]
    fn a_missing_folder_or_a_folder_for_a_file_is_refused_by_name() {
        let dir = scratch("bad");
        let missing = dir.join("nope").join("episodes.csv");
        let e = check_file(&missing, "--episodes").unwrap_err().to_string();
        assert!(
            e.contains("--episodes") && e.contains("not an existing folder"),
            "{e}"
        );
        let e = check_file(&dir, "--trace").unwrap_err().to_string();
        assert!(e.contains("--trace") && e.contains("is a folder"), "{e}");
    }

    #[test]
    fn ensure_dir_makes_nested_folders_and_names_what_it_cannot_make() {
        let dir = scratch("mk");
        ensure_dir(&dir.join("a").join("b")).unwrap();
        assert!(dir.join("a").join("b").is_dir());
        let file = dir.join("file");
        std::fs::write(&file, "x").unwrap();
        let e = ensure_dir(&file.join("sub")).unwrap_err().to_string();
        assert!(e.contains("creating") && e.contains("sub"), "{e}");
    }
}
