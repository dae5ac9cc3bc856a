//! Every output through a temporary file beside it, renamed into place when
//! complete: [`AtomicFile`] for one file, [`Staged`] for a command's several
//! outputs at once; temporaries are registered (`travmap_core::temporaries`) so an
//! interrupted run removes them, and a full disk is named as such.

use std::fs::File;
use std::path::{Path, PathBuf};

use parquet::errors::ParquetError;

use travmap_core::error::{Error, Result};
use travmap_core::temporaries;

/// What tells a temporary output from others: `.NAME.tmp-PID` beside `NAME`.
pub const TEMPORARY_INFIX: &str = ".tmp-";

/// The temporary file an output is written to: hidden, beside it, named after this
/// process so that a later run can tell a dead run's leftovers from a live one's.
pub fn temporary_path(path: &Path) -> std::io::Result<PathBuf> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path.file_name().ok_or_else(|| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "the output path has no file name",
        )
    })?;
    Ok(dir.join(format!(
        "{}{}",
        temporary_prefix(&name.to_string_lossy()),
        std::process::id()
    )))
}

/// The longest file name most filesystems hold, bytes.
const NAME_MAX: usize = 255;

/// How the temporary names of output `name` begin, up to the process id: `.NAME.tmp-`,
/// NAME cut (at a character) so that the whole fits in `NAME_MAX` with the largest
/// process id (a valid 253-byte name once could not be written).
pub fn temporary_prefix(name: &str) -> String {
    const LARGEST_PID_DIGITS: usize = 7;
    let room = NAME_MAX - 1 - TEMPORARY_INFIX.len() - LARGEST_PID_DIGITS;
    let mut end = name.len().min(room);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    format!(".{}{TEMPORARY_INFIX}", &name[..end])
}

/// An output being written under a temporary name beside it: [`AtomicFile::commit`]
/// renames it over the output; dropped uncommitted, it deletes the temporary file.
/// A character device or FIFO (`-o /dev/null`, a pipe) is written straight through,
/// as every Unix tool does: nothing is ever renamed over it.
pub struct AtomicFile {
    path: PathBuf,
    /// None when writing straight through to a device or FIFO.
    temporary_path: Option<PathBuf>,
    committed: bool,
}

/// Whether `path` is a character device, a FIFO or one of the process's open
/// descriptors (`/dev/stdout`), written straight through.
pub fn is_stream(path: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    names_a_descriptor(path)
        || std::fs::metadata(path)
            .is_ok_and(|m| m.file_type().is_char_device() || m.file_type().is_fifo())
}

/// Whether `path` is, or links through, an open descriptor (`/dev/stdout`,
/// `/dev/fd/N`, `/proc/self/fd/N`): renaming over it would replace the link with a
/// file instead of writing where the descriptor goes (a shell's redirection).
fn names_a_descriptor(path: &Path) -> bool {
    let mut path = path.to_path_buf();
    // As many links as the kernel follows.
    for _ in 0..40 {
        let in_descriptors = path.parent().is_some_and(|folder| {
            folder == Path::new("/dev/fd")
                || (folder.starts_with("/proc") && folder.file_name() == Some("fd".as_ref()))
        });
        if in_descriptors {
            return true;
        }
        match std::fs::read_link(&path) {
            Ok(target) => path = path.parent().unwrap_or(Path::new("/")).join(target),
            Err(_) => return false,
        }
    }
    false
}

/// How long a FIFO output waits for a process to open it for reading.
const FIFO_READER_WAIT: std::time::Duration = std::time::Duration::from_secs(10);

/// Opens a stream output. A descriptor is appended to (as the shell opened it:
/// `>` has emptied it, `>>` means after what is there); a FIFO that no process opens
/// to read within [`FIFO_READER_WAIT`] is an error, not a wait without end.
fn open_stream(path: &Path) -> std::io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    let started = std::time::Instant::now();
    let file = loop {
        let opened = std::fs::OpenOptions::new()
            .append(names_a_descriptor(path))
            .write(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(path);
        match opened {
            Err(e) if e.raw_os_error() == Some(libc::ENXIO) => {
                if started.elapsed() > FIFO_READER_WAIT {
                    return Err(std::io::Error::other(format!(
                        "a pipe (FIFO) that no process opened to read in {} s",
                        FIFO_READER_WAIT.as_secs()
                    )));
                }
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            opened => break opened?,
        }
    };
    // Blocking again, now that it is open: a slow reader is waited for.
    let fd = std::os::fd::AsRawFd::as_raw_fd(&file);
    // SAFETY: F_GETFL / F_SETFL on a descriptor this function owns.
    unsafe {
        let flags = libc::fcntl(fd, libc::F_GETFL);
        libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK);
    }
    Ok(file)
}

/// Flushes a written output to the disk; a device or FIFO has nothing to sync.
pub fn sync_output(file: &File) -> std::io::Result<()> {
    match file.metadata()?.file_type().is_file() {
        true => file.sync_all(),
        false => Ok(()),
    }
}

/// Bytes written between two requests to start writing back.
const WRITEBACK_BYTES: u64 = 8 << 20;

/// A file that asks the kernel to start writing its bytes to the disk every
/// `WRITEBACK_BYTES` (Linux's `sync_file_range`, which does not wait), so that the
/// `fsync` at the end finds most of them written: a large output's final sync went
/// from waiting on all of it (75 ms for annotate's 176 MB here, 4 ms with it) to its last part.
/// Elsewhere a plain file.
pub struct WritebackFile {
    file: File,
    written: u64,
    requested: u64,
}

impl WritebackFile {
    pub fn new(file: File) -> Self {
        Self {
            file,
            written: 0,
            requested: 0,
        }
    }

    pub fn into_inner(self) -> File {
        self.file
    }

    #[cfg(target_os = "linux")]
    fn start_writeback(&mut self) {
        use std::os::fd::AsRawFd;
        // SAFETY: a valid descriptor, a byte range of it; the call only starts I/O.
        // Its failure (a device or FIFO has no pages to write) is no error of ours:
        // the final fsync still syncs everything.
        unsafe {
            libc::sync_file_range(
                self.file.as_raw_fd(),
                self.requested as libc::off64_t,
                (self.written - self.requested) as libc::off64_t,
                libc::SYNC_FILE_RANGE_WRITE,
            );
        }
        self.requested = self.written;
    }

    #[cfg(not(target_os = "linux"))]
    fn start_writeback(&mut self) {}
}

impl std::io::Write for WritebackFile {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        let n = self.file.write(bytes)?;
        self.written += n as u64;
        if self.written - self.requested >= WRITEBACK_BYTES {
            self.start_writeback();
        }
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

impl AtomicFile {
    /// The guard and the temporary file to write.
    pub fn create(path: &Path) -> Result<(Self, File)> {
        let write_error = |source| Error::Write {
            path: path.to_path_buf(),
            source,
        };
        if is_stream(path) {
            let file = open_stream(path).map_err(write_error)?;
            let guard = Self {
                path: path.to_path_buf(),
                temporary_path: None,
                committed: false,
            };
            return Ok((guard, file));
        }
        let temporary_path = temporary_path(path).map_err(write_error)?;
        let file = File::create(&temporary_path).map_err(write_error)?;
        temporaries::track(&temporary_path);
        let guard = Self {
            path: path.to_path_buf(),
            temporary_path: Some(temporary_path),
            committed: false,
        };
        Ok((guard, file))
    }

    /// The output path (not the temporary one).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes in the temporary file so far.
    pub fn written_bytes(&self) -> u64 {
        let written = self.temporary_path.as_ref().map(std::fs::metadata);
        written.and_then(|m| m.ok()).map_or(0, |m| m.len())
    }

    /// Renames the written file over the output (the caller has flushed and synced it).
    pub fn commit(mut self) -> Result<()> {
        if let Some(temporary_path) = &self.temporary_path {
            std::fs::rename(temporary_path, &self.path).map_err(|source| Error::Write {
                path: self.path.clone(),
                source,
            })?;
            temporaries::forget(temporary_path);
        }
        self.committed = true;
        Ok(())
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if let (false, Some(temporary_path)) = (self.committed, &self.temporary_path) {
            let _ = std::fs::remove_file(temporary_path);
            temporaries::forget(temporary_path);
        }
    }
}

/// The error of a failed write to `output`'s temporary file: a full disk says so
/// with the bytes written (of `expected_bytes`, when known).
pub fn write_failure(
    path: &Path,
    output: &AtomicFile,
    error: Option<std::io::Error>,
    expected_bytes: Option<u64>,
) -> Error {
    match error {
        Some(source) if source.raw_os_error() == Some(libc::ENOSPC) => Error::NoSpace {
            path: path.to_path_buf(),
            written_bytes: output.written_bytes(),
            expected_bytes,
        },
        Some(source) => Error::Write {
            path: path.to_path_buf(),
            source,
        },
        None => Error::WriterStopped {
            path: path.to_path_buf(),
        },
    }
}

/// The error of a Parquet writer over `output`'s temporary file: the I/O error
/// inside it (a full disk among them) is reported as [`write_failure`] reports it.
pub fn parquet_failure(path: &Path, output: &AtomicFile, error: ParquetError) -> Error {
    match error {
        ParquetError::External(inner) => match inner.downcast::<std::io::Error>() {
            Ok(io) => write_failure(path, output, Some(*io), None),
            Err(other) => write_failure(path, output, Some(std::io::Error::other(other)), None),
        },
        other => write_failure(path, output, Some(std::io::Error::other(other)), None),
    }
}

/// Outputs written and synced under their temporary names, not yet in place: one
/// command's outputs appear together at [`Staged::commit`], or, if any of them
/// fails, none does.
#[derive(Default)]
pub struct Staged(Vec<AtomicFile>);

impl Staged {
    /// Writes `bytes` as `path`'s temporary file and syncs it.
    pub fn write(&mut self, path: &Path, bytes: &[u8]) -> Result<()> {
        use std::io::Write;
        let (guard, mut file) = AtomicFile::create(path)?;
        file.write_all(bytes)
            .and_then(|_| sync_output(&file))
            .map_err(|source| {
                write_failure(path, &guard, Some(source), Some(bytes.len() as u64))
            })?;
        self.0.push(guard);
        Ok(())
    }

    /// Adds an output its writer has flushed and synced.
    pub fn add(&mut self, output: AtomicFile) {
        self.0.push(output);
    }

    /// Renames every output into place.
    pub fn commit(self) -> Result<()> {
        self.0.into_iter().try_for_each(AtomicFile::commit)
    }
}

/// Writes `bytes` to `path` atomically.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut staged = Staged::default();
    staged.write(path, bytes)?;
    staged.commit()
}
