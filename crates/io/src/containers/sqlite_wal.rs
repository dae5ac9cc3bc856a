//! A `.db3` whose recording was not closed (the recorder killed, the machine off)
//! can hold its last messages in a write-ahead log beside it (`x.db3-wal`, as
//! rosbag2's `resilient` storage preset writes). An immutable open, which never
//! writes beside an input, does not read that log; so the file and its log are
//! copied into a temporary directory and the copy is read, which sees every
//! committed message. Inputs stay as they are.

use std::path::{Path, PathBuf};

use travmap_core::error::{Error, Result};

/// Where a `.db3`'s messages are read from.
pub struct Readable {
    pub path: PathBuf,
    /// The input itself, opened immutable; else a copy with its log.
    pub immutable: bool,
    pub notice: Option<String>,
    /// The copy, removed when dropped.
    _copy: Option<tempfile::TempDir>,
}

impl Readable {
    pub fn of(path: &Path) -> Result<Self> {
        let mut log = path.as_os_str().to_owned();
        log.push("-wal");
        let log = PathBuf::from(log);
        let log_bytes = std::fs::metadata(&log).map_or(0, |metadata| metadata.len());
        if log_bytes == 0 {
            return Ok(Self {
                path: path.to_path_buf(),
                immutable: true,
                notice: None,
                _copy: None,
            });
        }
        let copy = super::temporary_dir("travmap-db3-")?;
        let name = path.file_name().unwrap_or(path.as_os_str());
        let copied = copy.path().join(name);
        let mut copied_log = copied.as_os_str().to_owned();
        copied_log.push("-wal");
        for (from, to) in [(path, copied.as_path()), (&log, Path::new(&copied_log))] {
            std::fs::copy(from, to).map_err(|e| Error::LogContainer {
                path: path.to_path_buf(),
                problem: format!(
                    "copying {} to {} to read its write-ahead log failed: {e}",
                    from.display(),
                    to.display()
                ),
            })?;
        }
        let notice = format!(
            "{}: its write-ahead log ({}, {:.1} MB) holds messages not yet in the file (a recording that was not closed): both copied to {} to read them all (removed at exit)",
            path.display(),
            log.display(),
            log_bytes as f64 / 1e6,
            copy.path().display()
        );
        Ok(Self {
            path: copied,
            immutable: false,
            notice: Some(notice),
            _copy: Some(copy),
        })
    }
}
