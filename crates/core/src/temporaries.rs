//! Temporary files and folders a run makes (outputs being written beside their
//! final names, decompressed logs, copies of a database and its WAL) and the child
//! processes it starts (`bench --tools`' timed tools), registered so that an
//! interrupted run stops and removes them: a signal's handler calls [`clean_up`],
//! which no `Drop` would run.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, Instant};

static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The running children, and whether the run is being cleaned up (a child started
/// after that is stopped at once).
static CHILDREN: Mutex<(Vec<u32>, bool)> = Mutex::new((Vec::new(), false));

/// How long [`clean_up`] waits for stopped children to exit (each removes its own
/// temporaries first) before removing the folders they wrote into.
const CHILD_GRACE: Duration = Duration::from_secs(3);

/// Registers a child process until [`forget_child`].
pub fn track_child(pid: u32) {
    if let Ok(mut children) = CHILDREN.lock() {
        children.0.push(pid);
        if children.1 {
            terminate(pid);
        }
    }
}

/// Unregisters a child that has exited.
pub fn forget_child(pid: u32) {
    if let Ok(mut children) = CHILDREN.lock() {
        children.0.retain(|&p| p != pid);
    }
}

/// Registers a temporary file or folder until [`forget`]; once [`clean_up`] has
/// begun it is removed at once (a worker thread that made it after the clean-up ran
/// would otherwise leave it behind).
pub fn track(path: &Path) {
    if cleaning_up() {
        remove(path);
        return;
    }
    if let Ok(mut paths) = TEMPORARIES.lock() {
        paths.push(path.to_path_buf());
    }
    // The clean-up may have begun, and removed what was registered, meanwhile.
    if cleaning_up() {
        remove(path);
    }
}

/// Unregisters `path` (renamed into place, or removed by its owner).
pub fn forget(path: &Path) {
    if let Ok(mut paths) = TEMPORARIES.lock() {
        paths.retain(|p| p != path);
    }
}

/// Whether [`clean_up`] has begun: an error from a child it stopped is no error of
/// the run's.
pub fn cleaning_up() -> bool {
    CHILDREN.lock().is_ok_and(|children| children.1)
}

/// Stops every registered child (SIGTERM: it removes its own temporaries and exits),
/// waits for them a while, then removes every registered file and folder (from a
/// signal's handler).
pub fn clean_up() {
    let children = match CHILDREN.lock() {
        Ok(mut children) => {
            children.1 = true;
            children.0.clone()
        }
        Err(_) => Vec::new(),
    };
    children.iter().for_each(|&pid| terminate(pid));
    let deadline = Instant::now() + CHILD_GRACE;
    while children.iter().any(|&pid| running(pid)) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    remove_all();
}

fn terminate(pid: u32) {
    if let Ok(pid) = libc::pid_t::try_from(pid) {
        // SAFETY: kill has no memory effects; `pid` is a child this process started
        // and has not reaped (it is forgotten once waited for).
        unsafe {
            libc::kill(pid, libc::SIGTERM);
        }
    }
}

/// Whether process `pid` still runs (exists and is not a zombie awaiting its wait).
fn running(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|stat| {
        // `pid (command) state ...`: the command may hold spaces and parentheses.
        stat.rsplit_once(')')
            .is_some_and(|(_, rest)| !rest.trim_start().starts_with(['Z', 'X']))
    })
}

/// Removes every registered file and folder.
fn remove_all() {
    if let Ok(paths) = TEMPORARIES.lock() {
        paths.iter().for_each(|path| remove(path));
    }
}

fn remove(path: &Path) {
    match path.is_dir() {
        true => std::fs::remove_dir_all(path).ok(),
        false => std::fs::remove_file(path).ok(),
    };
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
        // Another test of this process may have begun the clean-up already, which
        // removes what is tracked from then on at once: `kept` is made again.
        std::fs::write(&kept, b"x").unwrap();
        clean_up();
        assert!(!file.exists() && !folder.exists() && kept.exists());
        forget(&file);
        forget(&folder);
    }

    #[test]
    fn a_registered_child_is_stopped() {
        let mut child = std::process::Command::new("sleep")
            .arg("30")
            .spawn()
            .unwrap();
        track_child(child.id());
        clean_up();
        let status = child.wait().unwrap();
        assert!(!status.success(), "{status:?}");
        forget_child(child.id());
    }
}
