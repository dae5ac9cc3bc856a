//! Temporary files and folders a run makes (outputs being written beside their
//! final names, decompressed logs, copies of a database and its WAL), registered
//! so that an interrupted run removes them: a signal's handler calls
//! [`remove_all`], which no `Drop` would run.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Registers a temporary file or folder until [`forget`].
pub fn track(path: &Path) {
    if let Ok(mut paths) = TEMPORARIES.lock() {
        paths.push(path.to_path_buf());
    }
}

/// Unregisters `path` (renamed into place, or removed by its owner).
pub fn forget(path: &Path) {
    if let Ok(mut paths) = TEMPORARIES.lock() {
        paths.retain(|p| p != path);
    }
}

/// Removes every registered file and folder (from a signal's handler).
pub fn remove_all() {
    if let Ok(paths) = TEMPORARIES.lock() {
        for path in paths.iter() {
            match path.is_dir() {
                true => std::fs::remove_dir_all(path).ok(),
                false => std::fs::remove_file(path).ok(),
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registered_files_and_folders_are_removed_and_forgotten_ones_kept() {
        let dir = tempfile::tempdir().unwrap();
        let (file, folder, kept) = (
            dir.path().join("a.tmp"),
            dir.path().join("decompressed"),
            dir.path().join("k"),
        );
        std::fs::write(&file, b"x").unwrap();
        std::fs::create_dir_all(folder.join("inner")).unwrap();
        std::fs::write(&kept, b"x").unwrap();
        for path in [&file, &folder, &kept] {
            track(path);
        }
        forget(&kept);
        remove_all();
        assert!(!file.exists() && !folder.exists() && kept.exists());
        forget(&file);
        forget(&folder);
    }
}
