//! Checks before any work: an output must not be (or replace) an input, its
//! directory must exist and take a new file, and it must not be a directory. Run
//! before the first frame is read, so a doomed run costs nothing and no input is
//! ever overwritten, however the paths are spelled (`./x/../d.mcap`, a symlinked
//! directory, a hard link).
//!
//! Also removes temporary files that a killed run (SIGKILL cannot be caught) left
//! beside the output.

use std::collections::HashSet;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

use crate::atomic::{TEMPORARY_INFIX, temporary_path, temporary_prefix};
use travmap_core::error::{Error, Result};
use travmap_io::listed_storage_files;

/// A file's identity on this machine: (device, inode).
type FileId = (u64, u64);

/// What travmap reads: every file of every input, by identity and by canonical path.
#[derive(Debug, Default)]
pub struct InputFiles {
    ids: Vec<(FileId, PathBuf)>,
    canonical: HashSet<PathBuf>,
    /// Every input directory and folder inside one, canonical; whether it is an
    /// input itself (a folder linked from inside one may lie anywhere).
    directories: Vec<(PathBuf, bool)>,
}

impl InputFiles {
    /// Every file of `paths`, a directory's files recursively. A path that does not
    /// exist is left out: opening it will say so.
    pub fn of(paths: &[&Path]) -> Self {
        let mut files = Self::default();
        for path in paths {
            files.add(path, 0);
        }
        files
    }

    fn add(&mut self, path: &Path, depth: usize) {
        let Ok(metadata) = std::fs::metadata(path) else {
            return;
        };
        let canonical = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
        if metadata.is_dir() {
            // A rosbag2 folder's metadata may name storage files outside it.
            for listed in listed_storage_files(path) {
                let inside =
                    std::fs::canonicalize(&listed).is_ok_and(|l| l.starts_with(&canonical));
                if !inside {
                    self.add(&listed, depth + 1);
                }
            }
            self.directories.push((canonical, depth == 0));
            // Sequence directories are two levels deep; a loop of links stops here.
            if depth < 4
                && let Ok(entries) = std::fs::read_dir(path)
            {
                for entry in entries.flatten() {
                    self.add(&entry.path(), depth + 1);
                }
            }
        } else {
            self.ids
                .push(((metadata.dev(), metadata.ino()), path.to_path_buf()));
            self.canonical.insert(canonical);
        }
    }

    /// The input `output` would overwrite, if any.
    fn aliased_by(&self, output: &Path) -> Option<PathBuf> {
        if let Ok(metadata) = std::fs::metadata(output) {
            let id = (metadata.dev(), metadata.ino());
            if let Some((_, input)) = self.ids.iter().find(|(i, _)| *i == id) {
                return Some(input.clone());
            }
        }
        let canonical = canonical_output(output)?;
        self.canonical.contains(&canonical).then_some(canonical)
    }

    /// The input directory (or folder of one) that is `dir` or holds it, if any, and
    /// whether it is an input itself.
    fn directory_holding(&self, dir: &Path) -> Option<(PathBuf, bool)> {
        let canonical = std::fs::canonicalize(dir).ok()?;
        self.directories
            .iter()
            .find(|(d, _)| canonical.starts_with(d))
            .cloned()
    }
}

/// The canonical path an output will have: its directory resolved, its name kept.
fn canonical_output(output: &Path) -> Option<PathBuf> {
    let dir = parent_dir(output);
    Some(std::fs::canonicalize(dir).ok()?.join(output.file_name()?))
}

fn parent_dir(path: &Path) -> &Path {
    path.parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

/// What the checks found that the user should hear about.
#[derive(Debug, Default)]
pub struct Preflight {
    /// Temporary files of dead travmap processes, removed.
    pub removed_stale: Vec<PathBuf>,
}

/// Checks that the file `output` can be written and replaces none of `inputs`: not
/// an input, nor inside an input directory's folders, nor a directory, a block
/// device or a write-protected file. A character device or FIFO is written straight
/// through, with nothing beside it.
pub fn check_output_file(output: &Path, inputs: &InputFiles) -> Result<Preflight> {
    // Unix tools' name for stdout would otherwise become a file named `-`.
    if output == Path::new("-") {
        return Err(Error::OutputIsSpecial {
            output: output.to_path_buf(),
            what: "the name some tools give stdout (travmap's is -o /dev/stdout)",
        });
    }
    if let Some(input) = inputs.aliased_by(output) {
        return Err(Error::OutputIsInput {
            output: output.to_path_buf(),
            input,
        });
    }
    if output.is_dir() {
        return Err(Error::OutputIsDirectory {
            output: output.to_path_buf(),
        });
    }
    // A device, a FIFO or a descriptor (/dev/stdout, /dev/fd/1, /proc/self/fd/1,
    // wherever the shell pointed it) is written straight through, nothing beside it.
    if crate::atomic::is_stream(output) {
        return Ok(Preflight::default());
    }
    if let Ok(metadata) = std::fs::metadata(output) {
        use std::os::unix::fs::{FileTypeExt, PermissionsExt};
        let kind = metadata.file_type();
        let special = match () {
            _ if kind.is_block_device() => Some("a block device"),
            _ if kind.is_socket() => Some("a socket"),
            _ => None,
        };
        if let Some(what) = special {
            return Err(Error::OutputIsSpecial {
                output: output.to_path_buf(),
                what,
            });
        }
        let mode = metadata.permissions().mode() & 0o777;
        if mode & 0o222 == 0 {
            return Err(Error::OutputWriteProtected {
                output: output.to_path_buf(),
                mode,
            });
        }
    }
    // Beside an input's own files is fine (a map next to calib.txt); in its folders
    // (velodyne/, labels/) the next run would read the output as data, and so it
    // would a log beside the storage files of a rosbag2 folder without metadata.yaml
    // (which reads every storage file it holds).
    let dir = parent_dir(output);
    if let (Some((input, is_input)), Ok(canonical_dir)) =
        (inputs.directory_holding(dir), std::fs::canonicalize(dir))
        && (canonical_dir != input || !is_input || read_as_storage(output, &input))
    {
        return Err(Error::OutputInsideInput {
            output: output.to_path_buf(),
            input,
        });
    }
    let write_error = |source| Error::Write {
        path: output.to_path_buf(),
        source,
    };
    if !dir.is_dir() {
        return Err(Error::NoOutputDirectory {
            output: output.to_path_buf(),
            directory: dir.to_path_buf(),
        });
    }
    let removed_stale = remove_stale_temporaries(output);
    // The temporary file is created beside the output: try it now, not after the work.
    let probe = temporary_path(output).map_err(write_error)?;
    std::fs::File::create(&probe).map_err(write_error)?;
    let _ = std::fs::remove_file(&probe);
    Ok(Preflight { removed_stale })
}

/// Storage files a rosbag2 folder without `metadata.yaml` reads, all of them.
const STORAGE_EXTENSIONS: [&str; 3] = ["db3", "mcap", "zstd"];

/// Whether `output`, written into the input folder `input`, would be read with it as
/// one of its storage files: `input` holds some and no `metadata.yaml` naming them.
fn read_as_storage(output: &Path, input: &Path) -> bool {
    let storage = |path: &Path| {
        path.extension()
            .is_some_and(|e| STORAGE_EXTENSIONS.iter().any(|s| e.eq_ignore_ascii_case(s)))
    };
    let holds_storage = || {
        std::fs::read_dir(input)
            .into_iter()
            .flatten()
            .flatten()
            .any(|entry| storage(&entry.path()))
    };
    storage(output) && !input.join("metadata.yaml").exists() && holds_storage()
}

/// Checks that no two of `outputs` name the same file, however spelled.
pub fn check_distinct_outputs(outputs: &[&Path]) -> Result<()> {
    let key = |path: &Path| canonical_output(path).unwrap_or_else(|| path.to_path_buf());
    for (i, first) in outputs.iter().enumerate() {
        if let Some(second) = outputs[i + 1..].iter().find(|o| key(o) == key(first)) {
            return Err(Error::SameOutputTwice {
                first: first.to_path_buf(),
                second: second.to_path_buf(),
            });
        }
    }
    Ok(())
}

/// Checks a directory that will receive one file per frame (`render --all`): it is
/// no input directory nor inside one, and it exists or its parent does (the
/// directory is made, as a file would be; missing parents are refused, as for any
/// output). Temporary pictures a killed run left in it are removed.
pub fn check_output_directory(output: &Path, inputs: &InputFiles) -> Result<Preflight> {
    let existing = if output.exists() {
        output
    } else {
        parent_dir(output)
    };
    if !existing.is_dir() {
        return Err(Error::NoOutputDirectory {
            output: output.to_path_buf(),
            directory: existing.to_path_buf(),
        });
    }
    if let Some((input, _)) = inputs.directory_holding(existing) {
        return Err(Error::OutputIsInput {
            output: output.to_path_buf(),
            input,
        });
    }
    Ok(Preflight {
        removed_stale: remove_stale_temporaries_in(output),
    })
}

/// Removes `.NAME.tmp-PID` files beside `output` whose process is gone.
fn remove_stale_temporaries(output: &Path) -> Vec<PathBuf> {
    let Some(name) = output.file_name() else {
        return Vec::new();
    };
    let prefix = temporary_prefix(&name.to_string_lossy());
    remove_dead_runs_files(parent_dir(output), |file| file.strip_prefix(&prefix))
}

/// Removes the temporary files (`.NAME.tmp-PID`, any NAME) in `dir` whose process
/// is gone: a killed `render --all`'s pictures.
fn remove_stale_temporaries_in(dir: &Path) -> Vec<PathBuf> {
    remove_dead_runs_files(dir, |file| {
        let hidden = file.strip_prefix('.')?;
        Some(&hidden[hidden.rfind(TEMPORARY_INFIX)? + TEMPORARY_INFIX.len()..])
    })
}

/// Removes the files of `dir` whose name `pid_of` reads a process id from, when that
/// process is gone.
fn remove_dead_runs_files(dir: &Path, pid_of: impl Fn(&str) -> Option<&str>) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut removed = Vec::new();
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let Some(pid) = file_name
            .to_str()
            .and_then(&pid_of)
            .and_then(|pid| pid.parse::<i32>().ok())
        else {
            continue;
        };
        if !process_is_alive(pid) && std::fs::remove_file(entry.path()).is_ok() {
            removed.push(entry.path());
        }
    }
    removed
}

fn process_is_alive(pid: i32) -> bool {
    // Signal 0 checks existence; EPERM means it exists under another user.
    // SAFETY: kill with signal 0 sends nothing.
    let result = unsafe { libc::kill(pid, 0) };
    result == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atomic::TEMPORARY_INFIX;

    #[test]
    fn a_log_beside_the_storage_of_a_rosbag2_folder_without_metadata_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let bag = dir.path().join("bag");
        std::fs::create_dir(&bag).unwrap();
        std::fs::write(bag.join("bag_0.db3"), b"storage").unwrap();
        let inputs = InputFiles::of(&[&bag]);
        // Read as a second storage file by the next run.
        let err = check_output_file(&bag.join("annotated.mcap"), &inputs).unwrap_err();
        assert!(
            err.to_string().contains("inside the input directory"),
            "{err}"
        );
        // A picture is no storage file; with metadata.yaml only what it names is read.
        check_output_file(&bag.join("map.png"), &inputs).unwrap();
        std::fs::write(
            bag.join("metadata.yaml"),
            b"rosbag2_bagfile_information: {}",
        )
        .unwrap();
        check_output_file(&bag.join("annotated.mcap"), &inputs).unwrap();
    }

    #[test]
    fn every_spelling_of_an_input_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let seq = dir.path().join("seq");
        std::fs::create_dir_all(seq.join("velodyne")).unwrap();
        let drive = dir.path().join("d.mcap");
        std::fs::write(&drive, b"drive").unwrap();
        std::fs::write(seq.join("velodyne/000000.bin"), b"scan").unwrap();
        std::fs::hard_link(&drive, dir.path().join("link.mcap")).unwrap();
        std::os::unix::fs::symlink(dir.path(), dir.path().join("via")).unwrap();
        let inputs = InputFiles::of(&[&drive, &seq]);
        for output in [
            drive.clone(),
            dir.path().join("seq/../d.mcap"),
            dir.path().join("via/d.mcap"),
            dir.path().join("link.mcap"),
            seq.join("velodyne/000000.bin"),
        ] {
            let err = check_output_file(&output, &inputs).unwrap_err().to_string();
            assert!(
                err.contains("would overwrite the input"),
                "{output:?}: {err}"
            );
        }
        assert!(check_output_file(&dir.path().join("new.mcap"), &inputs).is_ok());
        assert!(check_output_directory(&seq.join("pictures"), &inputs).is_err());
        assert!(check_output_directory(&dir.path().join("pictures"), &inputs).is_ok());
    }

    #[test]
    fn directories_and_missing_places_are_refused_before_work() {
        let dir = tempfile::tempdir().unwrap();
        let refusal = |output: &Path| {
            check_output_file(output, &InputFiles::default())
                .unwrap_err()
                .to_string()
        };
        let err = refusal(dir.path());
        assert!(err.contains("is a directory"), "{err}");
        let err = refusal(&dir.path().join("missing/x.mcap"));
        assert!(err.contains("does not exist"), "{err}");
    }

    #[test]
    fn temporaries_of_dead_processes_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let output = dir.path().join("x.mcap");
        // No process has pid 2^31 - 2; the test runner's parent is alive (not this
        // process, whose own temporary name the check itself uses).
        let dead = dir
            .path()
            .join(format!(".x.mcap{TEMPORARY_INFIX}2147483646"));
        // SAFETY: getppid has no preconditions.
        let parent = unsafe { libc::getppid() };
        let alive = dir.path().join(format!(".x.mcap{TEMPORARY_INFIX}{parent}"));
        std::fs::write(&dead, b"").unwrap();
        std::fs::write(&alive, b"").unwrap();
        let preflight = check_output_file(&output, &InputFiles::default()).unwrap();
        assert_eq!(preflight.removed_stale, std::slice::from_ref(&dead));
        assert!(!dead.exists() && alive.exists());
    }
}
