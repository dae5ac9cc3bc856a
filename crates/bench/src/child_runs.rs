//! Child processes timed as `bench --tools` times them: wall time, output size and
//! the child's own peak memory, on a given number of threads (one pinned to one
//! CPU), in a temporary directory of their own.

use std::ffi::OsString;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};

use anyhow::{Context, Result, bail};
use travmap_core::stopwatch::Stopwatch;
use travmap_core::temporaries;

/// One run of a child: its wall time, output size and peak memory.
#[derive(Debug)]
pub(crate) struct ChildRun {
    pub(crate) wall_s: f64,
    pub(crate) output_bytes: u64,
    pub(crate) peak_rss_mib: Option<f64>,
}

/// Runs `executable arguments` on `threads` rayon threads and times it; a child
/// that fails is an error naming the command, its exit status and the end of its
/// stderr. `output` (the file the child writes, if any) is removed first: a child
/// that replaced the last run's output would be timed freeing its blocks too (0.1 s
/// of a 0.65 s `annotate` here, for 160 MB on ext4).
pub(crate) fn run_child(
    executable: &Path,
    arguments: &[OsString],
    threads: usize,
    output: Option<&Path>,
) -> Result<ChildRun> {
    if let Some(output) = output {
        match std::fs::remove_file(output) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).with_context(|| format!("cannot remove {}", output.display()));
            }
            _ => {}
        }
    }
    let mut command = Command::new(executable);
    command
        .args(arguments)
        .env("RAYON_NUM_THREADS", threads.to_string())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    pin_to_cpus(&mut command, threads);
    stop_with_parent(&mut command);
    let watch = Stopwatch::start();
    let mut child = command
        .spawn()
        .with_context(|| format!("cannot start {command:?}"))?;
    // A signal to bench stops its tool too, or it would run on, writing.
    temporaries::track_child(child.id());
    let pid = child.id();
    // Read stderr until the child closes it, so a full pipe cannot stall it.
    let mut stderr = Vec::new();
    if let Some(mut pipe) = child.stderr.take() {
        pipe.read_to_end(&mut stderr)
            .with_context(|| format!("cannot read the stderr of {command:?}"))?;
    }
    let waited = wait_with_peak_rss(child);
    temporaries::forget_child(pid);
    let (status, peak_rss_mib) = waited.with_context(|| format!("cannot wait for {command:?}"))?;
    let wall_s = watch.elapsed_ms() * 1e-3;
    if !status.success() {
        let text = String::from_utf8_lossy(&stderr);
        let lines: Vec<&str> = text.lines().collect();
        let last = lines[lines.len().saturating_sub(5)..].join("\n");
        bail!("{command:?} failed ({status}); the end of its stderr:\n{last}");
    }
    let output_bytes = match output {
        Some(output) => std::fs::metadata(output)
            .with_context(|| format!("{command:?} wrote no {}", output.display()))?
            .len(),
        None => 0,
    };
    Ok(ChildRun {
        wall_s,
        output_bytes,
        peak_rss_mib,
    })
}

/// Seconds `dd conv=fsync` takes to write `bytes` (in whole MiB, at least one) into
/// `directory` and sync them: what the disk alone needs for an output of that size,
/// durable as travmap's outputs are. None where dd cannot run.
pub(crate) fn synced_write_seconds(directory: &Path, bytes: u64) -> Option<f64> {
    let file = directory.join("synced-write.bin");
    let mut of = OsString::from("of=");
    of.push(&file);
    let count = format!("count={}", bytes.div_ceil(1 << 20).max(1));
    let watch = Stopwatch::start();
    let status = Command::new("dd")
        .arg("if=/dev/zero")
        .arg(of)
        .args(["bs=1M", &count, "conv=fsync", "status=none"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status();
    let seconds = watch.elapsed_ms() * 1e-3;
    let _ = std::fs::remove_file(&file);
    status.ok()?.success().then_some(seconds)
}

/// Pins `command` to the first `threads` CPUs this process may use, so that a
/// one-thread row runs on one core: reading, writing and compressing have threads
/// of their own, which rayon's thread count alone would let spread.
#[cfg(target_os = "linux")]
/// The child gets SIGTERM when this process ends, whatever ends it: a signal that
/// arrives between the child's start and [`temporaries::track_child`] (or a SIGKILL)
/// left it running on, writing into a folder already removed.
#[cfg(target_os = "linux")]
fn stop_with_parent(command: &mut Command) {
    use std::os::unix::process::CommandExt;
    // SAFETY: between fork and exec the closure makes one system call, with no
    // allocation and no lock; bench starts its children from its main thread, which
    // lives until the process ends (the signal follows the thread that forked).
    unsafe {
        command.pre_exec(|| {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
            Ok(())
        });
    }
}

#[cfg(not(target_os = "linux"))]
fn stop_with_parent(_command: &mut Command) {}

fn pin_to_cpus(command: &mut Command, threads: usize) {
    use std::os::unix::process::CommandExt;
    let set_bytes = std::mem::size_of::<libc::cpu_set_t>();
    // SAFETY: all zeroes is an empty CPU set (a C array of integers), which
    // `sched_getaffinity` fills in; CPU_ISSET / CPU_SET index CPUs below
    // CPU_SETSIZE only.
    let pinned = unsafe {
        let mut allowed: libc::cpu_set_t = std::mem::zeroed();
        if libc::sched_getaffinity(0, set_bytes, &mut allowed) != 0 {
            return;
        }
        let mut pinned: libc::cpu_set_t = std::mem::zeroed();
        let allowed_cpus =
            (0..libc::CPU_SETSIZE as usize).filter(|&cpu| libc::CPU_ISSET(cpu, &allowed));
        for cpu in allowed_cpus.take(threads) {
            libc::CPU_SET(cpu, &mut pinned);
        }
        pinned
    };
    // SAFETY: between fork and exec the closure makes one system call on a set
    // built beforehand: no allocation, no lock.
    unsafe {
        command.pre_exec(move || {
            libc::sched_setaffinity(0, set_bytes, &pinned);
            Ok(())
        });
    }
}

#[cfg(not(target_os = "linux"))]
fn pin_to_cpus(_command: &mut Command, _threads: usize) {}

/// Waits for `child`; its exit status and its own peak resident set, MiB, from
/// `wait4`'s resource usage (`ru_maxrss`, KiB on Linux). None when that peak is no
/// higher than this process's own: std spawns with vfork (`posix_spawn`), and Linux
/// carries the parent's high-water mark into the child at `exec`, so such a figure
/// may be ours, not the child's.
#[cfg(target_os = "linux")]
fn wait_with_peak_rss(child: Child) -> std::io::Result<(ExitStatus, Option<f64>)> {
    use std::os::unix::process::ExitStatusExt;
    let pid = libc::pid_t::try_from(child.id()).map_err(std::io::Error::other)?;
    loop {
        let mut status = 0;
        // SAFETY: `pid` is a child of this process that nobody has waited for
        // (`child` is only dropped, never waited on, so std does not reap it);
        // `status` and `usage` are valid for writes, and all zeroes is a valid
        // `rusage` (a C struct of integers).
        let (reaped, usage) = unsafe {
            let mut usage: libc::rusage = std::mem::zeroed();
            (libc::wait4(pid, &mut status, 0, &mut usage), usage)
        };
        if reaped == pid {
            let child_kib = usage.ru_maxrss;
            let peak_rss_mib = own_peak_rss_kib()
                .is_none_or(|own_kib| child_kib > own_kib)
                .then(|| child_kib as f64 / 1024.0);
            return Ok((ExitStatus::from_raw(status), peak_rss_mib));
        }
        let error = std::io::Error::last_os_error();
        if error.kind() != std::io::ErrorKind::Interrupted {
            return Err(error);
        }
    }
}

/// This process's peak resident set so far, KiB (`VmHWM` of /proc/self/status).
#[cfg(target_os = "linux")]
fn own_peak_rss_kib() -> Option<libc::c_long> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find_map(|l| l.strip_prefix("VmHWM:"))?;
    line.trim().strip_suffix("kB")?.trim().parse().ok()
}

/// Waits for `child`; no peak resident set where `wait4` does not report one.
#[cfg(not(target_os = "linux"))]
fn wait_with_peak_rss(mut child: Child) -> std::io::Result<(ExitStatus, Option<f64>)> {
    Ok((child.wait()?, None))
}

/// A directory under the system's temporary directory, named with this process's
/// id, removed with everything in it when dropped.
pub(crate) struct TemporaryDirectory(pub(crate) PathBuf);

impl TemporaryDirectory {
    pub(crate) fn create() -> Result<Self> {
        let path = std::env::temp_dir().join(format!("travmap-bench-{}", std::process::id()));
        // Left by an earlier process with this id that was killed: nobody else's.
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir(&path)
            .with_context(|| format!("cannot create the directory {}", path.display()))?;
        temporaries::track(&path);
        Ok(Self(path))
    }
}

impl Drop for TemporaryDirectory {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
        temporaries::forget(&self.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn a_failing_tool_is_named_with_its_exit_status_and_last_words() {
        let script = ["-c", "echo first >&2; echo last words >&2; exit 3"].map(OsString::from);
        let dir = tempfile::tempdir().unwrap();
        let error = run_child(
            Path::new("/bin/sh"),
            &script,
            1,
            Some(&dir.path().join("out")),
        )
        .unwrap_err();
        let message = format!("{error:#}");
        for part in [
            "/bin/sh",
            "RAYON_NUM_THREADS",
            "exit status: 3",
            "last words",
        ] {
            assert!(message.contains(part), "{part:?} not in {message}");
        }
    }

    /// The last run's output is gone before the next child starts, so that no run
    /// is timed replacing it.
    #[cfg(unix)]
    #[test]
    fn each_child_starts_without_the_last_output() {
        let dir = tempfile::tempdir().unwrap();
        let output = dir.path().join("out");
        std::fs::write(&output, "the last run's output").unwrap();
        let arguments: [OsString; 3] = [
            "-c".into(),
            "test ! -e \"$0\" && echo new > \"$0\"".into(),
            output.clone().into(),
        ];
        let run = run_child(Path::new("/bin/sh"), &arguments, 1, Some(&output)).unwrap();
        assert_eq!(run.output_bytes, 4);
    }
}
