//! Reading a small file that an option names (a model, a configuration, a label map,
//! a LiDAR calibration): a device (`/dev/zero`, `/dev/urandom`) or a socket is
//! refused before it is read; a pipe (`<(...)`, `/dev/stdin`) is read for what it
//! holds, and one no process writes is refused instead of blocking the open for
//! ever; nothing is read past a bound.

use std::io::Read;
use std::path::Path;

use crate::error::{Error, Result};

/// The bound of a model file (a large hybrid model is tens of MB).
pub const MODEL_MAX_BYTES: u64 = 1 << 30;
/// The bound of a text file of settings or a calibration.
pub const TEXT_MAX_BYTES: u64 = 64 << 20;

/// The bytes of the file at `path`, at most `max_bytes` of them.
pub fn read_option_file(path: &Path, max_bytes: u64) -> Result<Vec<u8>> {
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    let refuse = |problem: String| Error::OptionFile {
        path: path.to_path_buf(),
        problem,
    };
    let failed = |e: std::io::Error| refuse(e.to_string());
    let kind = std::fs::metadata(path).map_err(failed)?.file_type();
    if kind.is_char_device() || kind.is_block_device() || kind.is_socket() {
        return Err(refuse("a device or a socket, not a file".into()));
    }
    if kind.is_dir() {
        return Err(refuse("a folder, not a file".into()));
    }
    // Without O_NONBLOCK, opening a FIFO waits for a writer; with it the open returns
    // at once, and once the flag is cleared a FIFO without a writer reads as empty.
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(failed)?;
    if kind.is_fifo() {
        use std::os::fd::AsRawFd;
        let fd = file.as_raw_fd();
        // SAFETY: F_GETFL and F_SETFL on a descriptor this function owns.
        let cleared = unsafe {
            let flags = libc::fcntl(fd, libc::F_GETFL);
            flags >= 0 && libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK) == 0
        };
        if !cleared {
            return Err(failed(std::io::Error::last_os_error()));
        }
    }
    let mut bytes = Vec::new();
    file.take(max_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(failed)?;
    if kind.is_fifo() && bytes.is_empty() {
        return Err(refuse(
            "a pipe that gave nothing (no process writes it): save the file, or pass it as <(command)".into(),
        ));
    }
    if bytes.len() as u64 > max_bytes {
        return Err(refuse(format!(
            "larger than {} MiB: not a file travmap reads here",
            max_bytes >> 20
        )));
    }
    Ok(bytes)
}

/// [`read_option_file`] as UTF-8 text.
pub fn read_option_text(path: &Path, max_bytes: u64) -> Result<String> {
    let bytes = read_option_file(path, max_bytes)?;
    String::from_utf8(bytes).map_err(|e| {
        Error::io(
            path,
            std::io::Error::other(format!(
                "not UTF-8 text (byte {})",
                e.utf8_error().valid_up_to()
            )),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_are_refused_and_files_read_within_their_bound() {
        let err = read_option_file(Path::new("/dev/zero"), 1 << 20).unwrap_err();
        assert!(err.to_string().contains("a device"), "{err}");
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("m.json");
        std::fs::write(&file, vec![b'x'; 100]).unwrap();
        assert_eq!(read_option_file(&file, 100).unwrap().len(), 100);
        let err = read_option_file(&file, 99).unwrap_err().to_string();
        assert!(err.contains("larger than"), "{err}");
        assert!(read_option_file(dir.path(), 100).is_err());
    }

    #[test]
    fn a_fifo_without_a_writer_is_refused_and_one_with_a_writer_reads_whole() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        let name = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: mkfifo on a new path of this test's own folder.
        assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o600) }, 0);
        let err = read_option_file(&fifo, 1 << 20).unwrap_err().to_string();
        assert!(err.contains("gave nothing"), "{err}");
        // A shell's <(...): a pipe another process wrote, read through /proc/self/fd.
        let mut fds = [0; 2];
        // SAFETY: pipe fills the two descriptors; each is closed below.
        assert_eq!(unsafe { libc::pipe(fds.as_mut_ptr()) }, 0);
        let written = b"grid.size_m = 24\n";
        // SAFETY: a write of a buffer this test owns to the pipe's write end.
        let count = unsafe { libc::write(fds[1], written.as_ptr().cast(), written.len()) };
        assert_eq!(count as usize, written.len());
        // SAFETY: the write end, no longer used.
        unsafe { libc::close(fds[1]) };
        let text = read_option_file(Path::new(&format!("/proc/self/fd/{}", fds[0])), 1 << 20);
        // SAFETY: the read end, no longer used.
        unsafe { libc::close(fds[0]) };
        let text = text.unwrap();
        assert_eq!(text, b"grid.size_m = 24\n");
    }
}
