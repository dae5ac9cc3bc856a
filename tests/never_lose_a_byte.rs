//! No command, with any flag, changes an input; outputs appear whole or not at all:
//! `-o` aimed at every input however spelled, signals, a killed run's leftovers, a
//! full disk.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{arg, clean_failure, travmap};
use sha2::{Digest, Sha256};

/// SHA-256 of every file below `root` (links followed), by path.
fn digests(root: &Path) -> BTreeMap<PathBuf, String> {
    let mut out = BTreeMap::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(path) = stack.pop() {
        let metadata = std::fs::symlink_metadata(&path).unwrap();
        if metadata.is_symlink() && path.is_dir() {
            continue; // a link to a directory already walked
        }
        if path.is_dir() {
            for entry in std::fs::read_dir(&path).unwrap() {
                stack.push(entry.unwrap().path());
            }
        } else {
            let bytes = std::fs::read(&path).unwrap();
            let digest: String = Sha256::digest(&bytes)
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect();
            out.insert(path, digest);
        }
    }
    out
}

/// A copy of the first three shipped frames (labels too), a drive converted from
/// it, a model and a config file: every kind of input a command reads.
fn inputs(sample: &Path, dir: &Path) -> (PathBuf, PathBuf, PathBuf, PathBuf) {
    let seq = dir.join("seq");
    for sub in ["velodyne", "labels"] {
        std::fs::create_dir_all(seq.join(sub)).unwrap();
    }
    for name in ["calib.txt", "poses.txt", "times.txt"] {
        std::fs::copy(sample.join(name), seq.join(name)).unwrap();
    }
    for i in 0..3 {
        for (sub, ext) in [("velodyne", "bin"), ("labels", "label")] {
            let name = format!("{sub}/{i:06}.{ext}");
            std::fs::copy(sample.join(&name), seq.join(&name)).unwrap();
        }
    }
    let drive = dir.join("d.mcap");
    crate::common::write_output("convert", &seq, &drive, &[]);
    let model = dir.join("model.json");
    std::fs::write(&model, travmap_model()).unwrap();
    let config = dir.join("config.toml");
    std::fs::write(&config, "[grid]\nmin_points = 2\n").unwrap();
    (seq, drive, model, config)
}

fn travmap_model() -> Vec<u8> {
    travmap_method::classifier::SvmModel::embedded(travmap_core::config::LabelRule::Road)
        .unwrap()
        .to_json()
}

#[test]
fn no_writing_command_can_overwrite_any_of_its_inputs() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (seq, drive, model, config) = inputs(&sample, dir.path());
    std::fs::create_dir_all(dir.path().join("x")).unwrap();
    std::os::unix::fs::symlink(dir.path(), dir.path().join("via")).unwrap();
    std::fs::hard_link(&drive, dir.path().join("hard.mcap")).unwrap();
    let before = digests(dir.path());

    // The drive spelled otherwise, and files inside the sequence directory.
    let drive_spellings = [
        drive.clone(),
        dir.path().join("x/../d.mcap"),
        dir.path().join("via/d.mcap"),
        dir.path().join("hard.mcap"),
    ];
    let seq_files = [
        seq.join("calib.txt"),
        seq.join("velodyne/000001.bin"),
        seq.join("labels/000002.label"),
        dir.path().join("via/seq/poses.txt"),
    ];
    let (seq, drive, model, config) = (arg(&seq), arg(&drive), arg(&model), arg(&config));
    let with_model = ["--model", model, "--config", config, "-q"];
    // Each writing command, its arguments, and every output that is one of its inputs.
    let commands: Vec<(Vec<&str>, Vec<&Path>)> = vec![
        (
            vec!["convert", seq, "-q"],
            seq_files.iter().map(PathBuf::as_path).collect(),
        ),
        (
            [&["annotate", drive][..], &with_model].concat(),
            drive_spellings
                .iter()
                .map(PathBuf::as_path)
                .chain([Path::new(model), Path::new(config)])
                .collect(),
        ),
        (
            [&["annotate", seq][..], &with_model].concat(),
            seq_files.iter().map(PathBuf::as_path).collect(),
        ),
        (
            [&["dataset", drive, seq][..], &with_model].concat(),
            drive_spellings
                .iter()
                .chain(&seq_files)
                .map(PathBuf::as_path)
                .chain([Path::new(model), Path::new(config)])
                .collect(),
        ),
        (
            vec!["train", seq, drive, "--config", config, "-q"],
            drive_spellings
                .iter()
                .chain(&seq_files)
                .map(PathBuf::as_path)
                .chain([Path::new(config)])
                .collect(),
        ),
        (
            [&["render", drive, "--frame", "2"][..], &with_model].concat(),
            drive_spellings
                .iter()
                .map(PathBuf::as_path)
                .chain([Path::new(model), Path::new(config)])
                .collect(),
        ),
    ];
    for (args, targets) in &commands {
        for target in targets {
            let mut args = args.clone();
            args.extend(["-o", arg(target)]);
            let out = travmap(&args);
            assert_eq!(out.status.code(), Some(1), "{args:?}");
            let err = crate::common::stderr(&out);
            assert!(err.contains("would overwrite the input"), "{args:?}: {err}");
        }
    }
    // A directory of pictures inside an input directory.
    let err = clean_failure(travmap(&[
        "render",
        seq,
        "--all",
        "-o",
        &format!("{seq}/velodyne"),
    ]));
    assert!(err.contains("would overwrite the input"), "{err}");
    assert_eq!(digests(dir.path()), before, "an input changed");
}

#[test]
fn outputs_that_cannot_be_written_are_refused_before_any_work() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let seq = arg(&sample);
    let directory = dir.path().join("a-directory");
    std::fs::create_dir_all(&directory).unwrap();
    let started = Instant::now();
    let err = clean_failure(travmap(&["train", seq, "-o", arg(&directory)]));
    assert!(err.contains("is a directory"), "{err}");
    let missing = dir.path().join("missing/m.json");
    let err = clean_failure(travmap(&["train", seq, "-o", arg(&missing)]));
    assert!(err.contains("does not exist"), "{err}");
    // Training takes seconds: refusing took no training.
    assert!(
        started.elapsed() < Duration::from_secs(3),
        "{:?}",
        started.elapsed()
    );
}

/// Starts a conversion of a long sequence into `out_dir`, waits until its temporary
/// file exists, and sends `signal`. None when it finished first.
fn interrupt_conversion(sample: &Path, dir: &Path, signal: &str) -> Option<(i32, PathBuf)> {
    let long = crate::common::long_sequence(sample, dir, 200);
    let out_dir = dir.join("out");
    std::fs::create_dir_all(&out_dir).unwrap();
    let output = out_dir.join("drive.mcap");
    let mut child = Command::new(env!("CARGO_BIN_EXE_travmap"))
        .args(["convert", arg(&long), "-o", arg(&output), "-q"])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let started = Instant::now();
    let has_temporary = || {
        std::fs::read_dir(&out_dir)
            .unwrap()
            .any(|e| e.unwrap().file_name().to_string_lossy().contains(".tmp-"))
    };
    while !has_temporary() && started.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(150));
    let sent = Command::new("kill")
        .args([&format!("-{signal}"), &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let status = child.wait().unwrap();
    if status.success() {
        eprintln!("skipping {signal}: the conversion finished before the signal");
        return None;
    }
    use std::os::unix::process::ExitStatusExt;
    Some((status.code().or(status.signal()).unwrap(), out_dir))
}

#[test]
fn sigint_sigterm_and_sighup_remove_the_temporary_output() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    for (signal, code) in [("INT", 130), ("TERM", 143), ("HUP", 129)] {
        let dir = tempfile::tempdir().unwrap();
        let Some((status, out_dir)) = interrupt_conversion(&sample, dir.path(), signal) else {
            continue;
        };
        assert_eq!(status, code, "SIG{signal}");
        let left: Vec<_> = std::fs::read_dir(&out_dir).unwrap().collect();
        assert!(left.is_empty(), "SIG{signal} left {left:?}");
    }
}

/// `kill -INT` of `bench --tools` (the parent alone, as a job scheduler may send it)
/// stops the tool it is timing and removes their temporary folder.
#[test]
fn a_signal_to_bench_stops_its_tools_and_removes_their_folder() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let long = crate::common::long_sequence(&sample, dir.path(), 200);
    let tmp = dir.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let mut bench = Command::new(env!("CARGO_BIN_EXE_travmap"))
        .args(["bench", arg(&long), "--tools", "--repeats", "1", "-q"])
        .env("TMPDIR", &tmp)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let children = || {
        let tasks = std::fs::read_dir(format!("/proc/{}/task", bench.id())).unwrap();
        tasks
            .flat_map(|task| std::fs::read_to_string(task.unwrap().path().join("children")))
            .flat_map(|list| {
                let pids: Vec<u32> = list.split_whitespace().flat_map(str::parse).collect();
                pids
            })
            .collect::<Vec<u32>>()
    };
    let started = Instant::now();
    let mut tools = children();
    while tools.is_empty() && started.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(5));
        tools = children();
    }
    assert!(!tools.is_empty(), "bench started no tool");
    std::thread::sleep(Duration::from_millis(100));
    let sent = Command::new("kill")
        .args(["-INT", &bench.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let status = bench.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    for tool in tools {
        // Gone, or a zombie its new parent has not yet reaped.
        let state = std::fs::read_to_string(format!("/proc/{tool}/stat")).unwrap_or_default();
        let alive = state
            .rsplit_once(')')
            .is_some_and(|(_, rest)| !rest.trim_start().starts_with(['Z', 'X']));
        assert!(!alive, "tool {tool} still runs: {state}");
    }
    let left: Vec<_> = std::fs::read_dir(&tmp).unwrap().collect();
    assert!(left.is_empty(), "left {left:?}");
}

#[test]
fn the_next_run_removes_what_a_killed_run_left() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let Some((status, out_dir)) = interrupt_conversion(&sample, dir.path(), "KILL") else {
        return;
    };
    assert_eq!(status, 9, "killed by SIGKILL");
    let stale: Vec<_> = std::fs::read_dir(&out_dir).unwrap().collect();
    assert_eq!(
        stale.len(),
        1,
        "SIGKILL cannot be caught: its temporary file stays"
    );
    let output = out_dir.join("drive.mcap");
    let out = travmap(&[
        "convert",
        arg(&sample),
        "--frames",
        "0..2",
        "-o",
        arg(&output),
        "-q",
    ]);
    let err = crate::common::stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("left by a travmap run that was killed"),
        "{err}"
    );
    let left: Vec<_> = std::fs::read_dir(&out_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, ["drive.mcap"]);
}

/// A storage file a rosbag2 folder's metadata names outside the folder
/// (`../outside.db3`) is an input like the folder's own: an output over it is refused
/// (it was replaced).
#[test]
fn a_storage_file_the_metadata_names_outside_the_bag_is_an_input() {
    let fixture = crate::common::nebula_fixture("helios16p/rosbag2_2023_08_03-11_02_46");
    let dir = tempfile::tempdir().unwrap();
    let (bag, outside) = (dir.path().join("bag"), dir.path().join("outside.db3"));
    std::fs::create_dir(&bag).unwrap();
    std::fs::copy(fixture.join("rosbag2_2023_08_03-11_02_46_0.db3"), &outside).unwrap();
    let metadata = std::fs::read_to_string(fixture.join("metadata.yaml")).unwrap();
    let metadata = metadata.replace("rosbag2_2023_08_03-11_02_46_0.db3", "../outside.db3");
    std::fs::write(bag.join("metadata.yaml"), metadata).unwrap();
    let before = std::fs::read(&outside).unwrap();
    let out = travmap(&["convert", arg(&bag), "-o", arg(&outside)]);
    assert_eq!(out.status.code(), Some(1));
    let err = crate::common::stderr(&out);
    assert!(
        err.contains("would overwrite the input") && err.contains("../outside.db3"),
        "{err}"
    );
    assert!(
        std::fs::read(&outside).unwrap() == before,
        "the input was replaced"
    );
}

/// The pictures a killed `render --all` left in its folder are removed by the next
/// run into it (they once stayed for good); a live run's are left alone.
#[test]
fn a_killed_render_alls_temporary_pictures_are_removed_by_the_next() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let pictures = dir.path().join("pictures");
    std::fs::create_dir(&pictures).unwrap();
    // A process id above the kernel's largest is never alive; this test's is.
    let dead = pictures.join(".000003.png.tmp-2147483646");
    let alive = pictures.join(format!(".000004.png.tmp-{}", std::process::id()));
    for file in [&dead, &alive] {
        std::fs::write(file, b"half a picture").unwrap();
    }
    let out = travmap(&["render", arg(&sample), "--all", "-o", arg(&pictures), "-q"]);
    let err = crate::common::stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("removed") && err.contains(".000003.png.tmp-2147483646"),
        "{err}"
    );
    assert!(!dead.exists() && alive.exists());
    assert!(pictures.join("000003.png").exists());
}

/// A tmpfs of `size` mounted on a new temporary directory, or None (with the
/// reason printed) where mounting is not allowed.
fn small_tmpfs(size: &str) -> Option<tempfile::TempDir> {
    let small = tempfile::tempdir().unwrap();
    let mounted = Command::new("mount")
        .args([
            "-t",
            "tmpfs",
            "-o",
            &format!("size={size}"),
            "tmpfs",
            arg(small.path()),
        ])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !mounted {
        eprintln!("skipping: cannot mount a small tmpfs here (not root?)");
        return None;
    }
    Some(small)
}

#[test]
fn a_full_disk_is_named_and_leaves_nothing() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    // A 1 MiB file system: the conversion of six scans (8.8 MB) fills it.
    let Some(small) = small_tmpfs("1m") else {
        return;
    };
    let output = small.path().join("drive.mcap");
    let out = travmap(&["convert", arg(&sample), "-o", arg(&output), "-q"]);
    let left: Vec<_> = std::fs::read_dir(small.path()).unwrap().collect();
    let _ = Command::new("umount").arg(small.path()).status();
    let err = clean_failure(out);
    assert!(err.contains("no space left on device (wrote"), "{err}");
    assert!(left.is_empty(), "left {left:?}");
}

#[test]
fn a_full_disk_leaves_nothing_of_any_command_with_several_outputs() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    // 16 KiB: two or three of render's 2 KB pictures and the map's PNG fit, the
    // rest does not; a few of man's 20 pages.
    let Some(small) = small_tmpfs("16k") else {
        return;
    };
    let at = |name: &str| small.path().join(name);
    let runs: [Vec<String>; 4] = [
        vec!["man".into(), "-o".into(), arg(&at("pages")).into()],
        vec![
            "render".into(),
            "--all".into(),
            "-o".into(),
            arg(&at("pictures")).into(),
        ],
        vec![
            "map".into(),
            "-o".into(),
            arg(&at("m.png")).into(),
            "--cells".into(),
            arg(&at("m.parquet")).into(),
        ],
        vec![
            "dataset".into(),
            "-o".into(),
            arg(&at("cells.parquet")).into(),
        ],
    ];
    let mut failures = Vec::new();
    for run in &runs {
        let mut args: Vec<&str> = vec![run[0].as_str()];
        if run[0] != "man" {
            args.push(arg(&sample));
        }
        args.extend(run[1..].iter().map(String::as_str));
        if run[0] != "man" {
            args.push("-q");
        }
        let out = travmap(&args);
        let left: Vec<_> = std::fs::read_dir(small.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        failures.push((run[0].clone(), out, left));
    }
    let _ = Command::new("umount").arg(small.path()).status();
    for (command, out, left) in failures {
        let err = clean_failure(out);
        assert!(
            err.contains("no space left on device (wrote")
                && err.contains("nothing was left behind"),
            "{command}: {err}"
        );
        assert!(!err.contains("External"), "{command}: {err}");
        assert!(left.is_empty(), "{command} left {left:?}");
    }
}

#[test]
fn a_closed_stdout_ends_quietly() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    // `travmap run ... | head -c 1`: the reader goes away after one byte.
    let mut child = Command::new(env!("CARGO_BIN_EXE_travmap"))
        .args(["run", arg(&sample), "--ascii"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = child.stdout.take().unwrap();
    let mut one = [0u8; 1];
    std::io::Read::read_exact(&mut stdout, &mut one).unwrap();
    drop(stdout);
    let out = child.wait_with_output().unwrap();
    use std::os::unix::process::ExitStatusExt;
    assert_eq!(
        out.status.signal(),
        Some(13),
        "ended by SIGPIPE, as `cat` is"
    );
    assert!(
        out.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `-o` at a character device or a FIFO writes straight through, as `> /dev/null`
/// does: the device stays a device (it was once replaced by a 15 MB regular file).
#[test]
fn devices_and_fifos_are_written_through_not_replaced() {
    use std::os::unix::fs::FileTypeExt;
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    // A private null device (mknod needs root; elsewhere the system's /dev/null).
    let null = dir.path().join("null");
    let made = Command::new("mknod")
        .args([arg(&null), "c", "1", "3"])
        .status()
        .is_ok_and(|s| s.success());
    let null = if made {
        null
    } else {
        PathBuf::from("/dev/null")
    };
    for command in ["annotate", "convert", "map", "dataset"] {
        crate::common::write_output(command, &sample, &null, &[]);
        let kind = std::fs::metadata(&null).unwrap().file_type();
        assert!(
            kind.is_char_device(),
            "{command} replaced {}",
            null.display()
        );
    }
    // A FIFO: the reader gets the whole file.
    let fifo = dir.path().join("fifo");
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read(fifo).unwrap())
    };
    crate::common::write_output("convert", &sample, &fifo, &[]);
    let bytes = reader.join().unwrap();
    assert!(bytes.starts_with(b"\x89MCAP0\r\n") && bytes.ends_with(b"\x89MCAP0\r\n"));
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        2,
        "nothing beside them"
    );
}

/// `-o /dev/stdout` (here a link of our own to `/proc/self/fd/1`) with stdout
/// redirected to a file writes into that file and leaves the link a link (it was
/// once replaced by a regular file); a FIFO no process reads is an error, not a hang.
#[test]
fn descriptors_are_written_through_and_a_fifo_without_reader_is_an_error() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let stdout_link = dir.path().join("stdout");
    std::os::unix::fs::symlink("/proc/self/fd/1", &stdout_link).unwrap();
    let redirected = dir.path().join("redirected.mcap");
    let status = Command::new(env!("CARGO_BIN_EXE_travmap"))
        .args(["convert", arg(&sample), "-o", arg(&stdout_link), "-q"])
        .stdout(std::fs::File::create(&redirected).unwrap())
        .status()
        .unwrap();
    assert!(status.success());
    assert!(
        std::fs::symlink_metadata(&stdout_link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    let bytes = std::fs::read(&redirected).unwrap();
    assert!(bytes.starts_with(b"\x89MCAP0\r\n") && bytes.ends_with(b"\x89MCAP0\r\n"));
    // The descriptors' own names, whose folders no file can be created in (a probe
    // for the temporary file once failed there).
    for name in ["/dev/fd/1", "/proc/self/fd/1"] {
        let status = Command::new(env!("CARGO_BIN_EXE_travmap"))
            .args([
                "convert",
                arg(&sample),
                "-o",
                name,
                "-q",
                "--frames",
                "0..2",
            ])
            .stdout(std::fs::File::create(&redirected).unwrap())
            .status()
            .unwrap();
        assert!(status.success(), "{name}");
        let bytes = std::fs::read(&redirected).unwrap();
        assert!(bytes.ends_with(b"\x89MCAP0\r\n"), "{name}");
    }

    let fifo = dir.path().join("fifo");
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let err = clean_failure(travmap(&["convert", arg(&sample), "-o", arg(&fifo), "-q"]));
    crate::common::assert_contains(&err, &["fifo", "no process opened to read"]);
}

/// Outputs that would lose something are refused before any work: two outputs of
/// one command naming one file, an output inside an input's folders, a
/// write-protected file.
#[test]
fn outputs_that_would_lose_something_are_refused() {
    use std::os::unix::fs::PermissionsExt;
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let picture = dir.path().join("m.png");
    let same = dir.path().join(".").join("m.png");
    let err = clean_failure(travmap(&[
        "map",
        arg(&sample),
        "-o",
        arg(&picture),
        "--cells",
        arg(&same),
    ]));
    crate::common::assert_contains(&err, &["name the same file"]);
    assert!(!picture.exists());

    let copy = crate::common::long_sequence(&sample, dir.path(), 6);
    let inside = copy.join("velodyne").join("m.png");
    let err = clean_failure(travmap(&["map", arg(&copy), "-o", arg(&inside)]));
    crate::common::assert_contains(
        &err,
        &["is inside the input directory", "choose another -o"],
    );
    // Beside the input's own files is fine.
    crate::common::write_output("map", &copy, &copy.join("m.png"), &[]);

    let protected = dir.path().join("protected.png");
    std::fs::write(&protected, b"keep me").unwrap();
    std::fs::set_permissions(&protected, std::fs::Permissions::from_mode(0o444)).unwrap();
    let err = clean_failure(travmap(&["map", arg(&sample), "-o", arg(&protected)]));
    crate::common::assert_contains(&err, &["write-protected (mode 444)"]);
    assert_eq!(std::fs::read(&protected).unwrap(), b"keep me");

    // A LiDAR calibration is read too: no command writes over it.
    let calibration = dir.path().join("vlp16.yaml");
    std::fs::write(&calibration, b"lasers: []\n").unwrap();
    for command in ["convert", "annotate", "map", "odometry"] {
        let err = clean_failure(travmap(&[
            command,
            arg(&sample),
            "--lidar-calibration",
            arg(&calibration),
            "-o",
            arg(&calibration),
        ]));
        crate::common::assert_contains(&err, &["would overwrite the input", "vlp16.yaml"]);
        assert_eq!(
            std::fs::read(&calibration).unwrap(),
            b"lasers: []\n",
            "{command}"
        );
    }
}

/// One pose 10^6 m off the others would make the drive map a dense image of 10^13
/// cells (it panicked on 32-bit pixel arithmetic, or aborted allocating 6.2 TB): the
/// map, its nav2 copy and the annotated file's OccupancyGrid are refused by size,
/// naming the extent, and nothing is left behind.
#[test]
fn a_pose_far_from_the_rest_is_refused_by_the_maps_size() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let drive = crate::common::long_sequence(&sample, dir.path(), 6);
    let poses = std::fs::read_to_string(drive.join("poses.txt")).unwrap();
    let mut lines: Vec<String> = poses.lines().map(str::to_string).collect();
    let mut values: Vec<f64> = lines[3]
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    values[3] += 1e6;
    lines[3] = values
        .iter()
        .map(f64::to_string)
        .collect::<Vec<_>>()
        .join(" ");
    std::fs::write(drive.join("poses.txt"), lines.join("\n") + "\n").unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    for (command, output, extra) in [
        ("map", "m.png", vec!["--nav2", "m.yaml"]),
        ("annotate", "a.mcap", vec![]),
    ] {
        let extra: Vec<String> = extra
            .iter()
            .map(|e| match e.ends_with(".yaml") {
                true => out.join(e).display().to_string(),
                false => e.to_string(),
            })
            .collect();
        let output = out.join(output);
        let mut args = vec![command, arg(&drive), "-o", arg(&output)];
        args.extend(extra.iter().map(String::as_str));
        let err = clean_failure(travmap(&args));
        crate::common::assert_contains(
            &err,
            &[
                "999981 m",
                "more than the 268435456 one image may hold",
                "far from the rest",
            ],
        );
        assert_eq!(
            std::fs::read_dir(&out).unwrap().count(),
            0,
            "{command} left a file"
        );
    }
}

/// `-o -` is refused (it made a file named `-`), and an output whose name is 253
/// bytes long is written (its temporary name was refused as too long).
#[test]
fn odd_output_names_are_refused_or_written() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_travmap"))
        .args(["map", arg(&sample), "-o", "-", "-q"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let err = clean_failure(out);
    crate::common::assert_contains(&err, &["travmap's is -o /dev/stdout"]);
    assert!(!dir.path().join("-").exists());
    let long = dir.path().join(format!("{}.png", "m".repeat(249)));
    crate::common::write_output("map", &sample, &long, &[]);
    assert!(long.exists());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        1,
        "nothing beside it"
    );
}

/// An output into an input's folder that is a link to another place (a velodyne/
/// kept on another disk) is refused as the folder itself would be (the next run
/// read the new file as a scan).
#[test]
fn an_output_into_a_linked_folder_of_an_input_is_refused() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let drive = crate::common::long_sequence(&sample, dir.path(), 6);
    let scans = dir.path().join("scans-elsewhere");
    std::fs::rename(drive.join("velodyne"), &scans).unwrap();
    std::os::unix::fs::symlink(&scans, drive.join("velodyne")).unwrap();
    let inside = drive.join("velodyne").join("m.png");
    let err = clean_failure(travmap(&["map", arg(&drive), "-o", arg(&inside)]));
    crate::common::assert_contains(
        &err,
        &["is inside the input directory", "choose another -o"],
    );
    assert!(!scans.join("m.png").exists());
    crate::common::write_output("map", &drive, &drive.join("m.png"), &[]);
}

/// `render --all` interrupted: its pictures are written by several workers, and one
/// could make its temporary file after the clean-up ran (16 of 27 runs left one), and
/// the folder the run made stayed. Neither stays now, whenever the signal comes.
#[test]
fn an_interrupted_render_all_leaves_no_picture_and_no_folder() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let long = crate::common::long_sequence(&sample, dir.path(), 200);
    for (attempt, (signal, delay_ms)) in [("INT", 0), ("TERM", 40), ("INT", 120), ("TERM", 250)]
        .into_iter()
        .enumerate()
    {
        let frames = dir.path().join(format!("frames-{attempt}"));
        let mut child = Command::new(env!("CARGO_BIN_EXE_travmap"))
            .args(["render", arg(&long), "--all", "-o", arg(&frames), "-q"])
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let started = Instant::now();
        let has_temporary = || {
            std::fs::read_dir(&frames).is_ok_and(|mut entries| {
                entries.any(|e| e.unwrap().file_name().to_string_lossy().contains(".tmp-"))
            })
        };
        while !has_temporary() && started.elapsed() < Duration::from_secs(20) {
            std::thread::sleep(Duration::from_millis(2));
        }
        std::thread::sleep(Duration::from_millis(delay_ms));
        let sent = Command::new("kill")
            .args([&format!("-{signal}"), &child.id().to_string()])
            .status()
            .unwrap();
        assert!(sent.success());
        let status = child.wait().unwrap();
        if status.success() {
            continue;
        }
        // Workers may still be unwinding when the process ends: look once it has.
        assert!(
            !frames.exists(),
            "SIG{signal} after {delay_ms} ms left {:?}",
            std::fs::read_dir(&frames).map(|d| d.count())
        );
    }
}
