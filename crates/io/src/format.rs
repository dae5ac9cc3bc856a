//! What an input is, by its content: the magic bytes of a file, the layout of a
//! directory. Guessing from the name (or reading any file as MCAP) gave false
//! diagnoses; this names what a file is even when travmap cannot read it.

use std::io::Read;
use std::path::{Path, PathBuf};

use travmap_core::error::{Error, Result};

/// An input format travmap reads: [`detect`] is the one place that decides.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputFormat {
    /// A KITTI odometry / SemanticKITTI sequence directory (or a directory that is
    /// no other kind: reading it as one names what is missing).
    Kitti,
    /// A folder of `.pcd` or KITTI-style `.bin` scans.
    ScanFolder,
    /// An MCAP file, ROS 2 (CDR) or ROS 1 messages.
    Mcap,
    /// A ROS 1 bag, format 2.0.
    Bag,
    /// A rosbag2 sqlite3 file (`.db3`).
    Sqlite,
    /// A rosbag2 directory: `metadata.yaml` and its storage files.
    Rosbag2,
    /// A packet capture (classic pcap or pcapng) of LiDAR packets.
    Pcap,
    /// One saved point cloud (a SLAM or survey map): a site, read as tiles by
    /// `travmap map`, and no drive for the other commands.
    SiteCloud(SiteCloudFormat),
}

impl InputFormat {
    /// How a person would name it.
    pub fn describe(self) -> &'static str {
        match self {
            InputFormat::Kitti => "a KITTI sequence directory",
            InputFormat::ScanFolder => "a folder of scans",
            InputFormat::Mcap => "an MCAP file",
            InputFormat::Bag => "a ROS 1 bag",
            InputFormat::Sqlite => "a rosbag2 sqlite3 file",
            InputFormat::Rosbag2 => "a rosbag2 directory",
            InputFormat::Pcap => "a pcap capture",
            InputFormat::SiteCloud(SiteCloudFormat::Pcd) => SINGLE_PCD,
            InputFormat::SiteCloud(SiteCloudFormat::Ply) => SINGLE_PLY,
            InputFormat::SiteCloud(SiteCloudFormat::Las) => SINGLE_LAS,
        }
    }
}

/// What travmap reads, for the errors that refuse something else.
pub const READABLE: &str = "travmap reads KITTI / SemanticKITTI sequence directories, MCAP files (ROS 2 or ROS 1 messages), ROS 1 bags (format 2.0), rosbag2 directories (sqlite3 or MCAP storage), rosbag2 .db3 files, pcap / pcapng captures of LiDAR packets and folders of .pcd / .bin scans";

/// The first bytes of a ROS 1 bag of format 2.0.
pub const BAG_MAGIC: &[u8] = b"#ROSBAG V2.0\n";

/// Formats known by their first bytes, readable (`Ok`) or named in a refusal (`Err`).
/// How a PCD file begins: with its comment line, straight with its version, or (as
/// ouster-cli writes them, with no version) with its fields.
const PCD_MAGICS: [&[u8]; 3] = [b"# .PCD", b"VERSION ", b"FIELDS "];
const SINGLE_PCD: &str = "a single PCD point cloud (`travmap map` reads one as a site map; a folder of .pcd scans is a drive: put them in one)";
/// How a PLY file begins.
const PLY_MAGICS: [&[u8]; 2] = [b"ply\n", b"ply\r\n"];
const SINGLE_PLY: &str = "a single PLY point cloud (`travmap map` reads one as a site map)";
/// How a LAS or LAZ file begins.
const LAS_MAGIC: &[u8] = b"LASF";
const SINGLE_LAS: &str = "a single LAS / LAZ point cloud (`travmap map` reads one as a site map)";

/// The kinds of one saved point cloud `travmap map` reads as a site.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SiteCloudFormat {
    Pcd,
    Ply,
    /// LAS or LAZ.
    Las,
}

const MAGICS: &[(&[u8], std::result::Result<InputFormat, &str>)] = &[
    (b"\x89MCAP0\r\n", Ok(InputFormat::Mcap)),
    (BAG_MAGIC, Ok(InputFormat::Bag)),
    (b"SQLite format 3\0", Ok(InputFormat::Sqlite)),
    (b"\xd4\xc3\xb2\xa1", Ok(InputFormat::Pcap)),
    (b"\xa1\xb2\xc3\xd4", Ok(InputFormat::Pcap)),
    (b"\x4d\x3c\xb2\xa1", Ok(InputFormat::Pcap)),
    (b"\xa1\xb2\x3c\x4d", Ok(InputFormat::Pcap)),
    (b"\x0a\x0d\x0d\x0a", Ok(InputFormat::Pcap)),
    (
        b"#ROSBAG V1.",
        Err(
            "a ROS 1 bag of format 1.x (before ROS C Turtle); `rosbag fix` or `rosbag reindex` brings it to 2.0",
        ),
    ),
    (b"\x89MCAP", Err("an MCAP file of a version other than 0")),
    (
        PCD_MAGICS[0],
        Ok(InputFormat::SiteCloud(SiteCloudFormat::Pcd)),
    ),
    (
        PCD_MAGICS[1],
        Ok(InputFormat::SiteCloud(SiteCloudFormat::Pcd)),
    ),
    (
        PCD_MAGICS[2],
        Ok(InputFormat::SiteCloud(SiteCloudFormat::Pcd)),
    ),
    (
        PLY_MAGICS[0],
        Ok(InputFormat::SiteCloud(SiteCloudFormat::Ply)),
    ),
    (
        PLY_MAGICS[1],
        Ok(InputFormat::SiteCloud(SiteCloudFormat::Ply)),
    ),
    (LAS_MAGIC, Ok(InputFormat::SiteCloud(SiteCloudFormat::Las))),
    (
        b"PAR1",
        Err("a Parquet file (a travmap dataset is an output, not a drive)"),
    ),
    (b"\x89PNG\r\n\x1a\n", Err("a PNG image")),
    (b"\xff\xd8\xff", Err("a JPEG image")),
    (b"BZh", Err("a bzip2-compressed file")),
    (
        b"\x28\xb5\x2f\xfd",
        Err("a zstd-compressed file (a compressed rosbag2 file? decompress it first)"),
    ),
    (b"\x1f\x8b", Err("a gzip-compressed file")),
    (b"PK\x03\x04", Err("a zip archive")),
    (b"\x7fELF", Err("an executable")),
];

/// The bytes of a data file a drive holds (a scan, its labels, an image): a pipe,
/// a device or a socket among them is refused by its kind before it is opened (a
/// FIFO no process writes blocked the open for ever).
pub fn read_data_file(path: &Path) -> Result<Vec<u8>> {
    refuse_special(path)?;
    std::fs::read(path).map_err(|e| Error::io(path, e))
}

/// Errors when `path` is a pipe, a device or a socket, naming which.
pub fn refuse_special(path: &Path) -> Result<()> {
    let kind = std::fs::metadata(path).map(|m| m.file_type());
    match kind.ok().as_ref().and_then(special_file) {
        Some(what) => Err(Error::Sequence {
            path: path.to_path_buf(),
            message: format!("{what}, not a file"),
        }),
        None => Ok(()),
    }
}

/// What a file that is neither a regular file nor a folder is, in words.
pub(crate) fn special_file(file_type: &std::fs::FileType) -> Option<&'static str> {
    use std::os::unix::fs::FileTypeExt;
    if file_type.is_fifo() {
        Some("a pipe (a FIFO, or a shell's <(...) or /dev/stdin)")
    } else if file_type.is_char_device() || file_type.is_block_device() {
        Some("a device")
    } else if file_type.is_socket() {
        Some("a socket")
    } else {
        None
    }
}

/// The format of `path`, or an error that says what it is instead: a file by its
/// first bytes, a directory by its layout.
pub fn detect(path: &Path) -> Result<InputFormat> {
    let metadata = match std::fs::metadata(path) {
        Ok(metadata) => metadata,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(Error::InputMissing {
                path: path.to_path_buf(),
            });
        }
        Err(e) => return Err(Error::io(path, e)),
    };
    // Opening a pipe with no writer blocks, and a stream cannot be memory-mapped:
    // what is not a file or a folder is refused before it is opened.
    if let Some(what) = special_file(&metadata.file_type()) {
        return Err(unsupported(
            path,
            format!(
                "{what}: travmap reads a log by memory-mapping it and reads it more than once; save the stream to a file first (e.g. `cat > drive.mcap`)"
            ),
        ));
    }
    if metadata.is_dir() {
        return directory_format(path);
    }
    let mut first = Vec::with_capacity(16);
    std::fs::File::open(path)
        .and_then(|file| file.take(16).read_to_end(&mut first))
        .map_err(|e| Error::io(path, e))?;
    for (magic, format) in MAGICS {
        if first.starts_with(magic) {
            return format.map_err(|what| unsupported(path, what.to_string()));
        }
    }
    let what = if first.is_empty() {
        "an empty file".to_string()
    } else if path.file_name().is_some_and(|name| name == "metadata.yaml") {
        return Err(unsupported(
            path,
            "the metadata of a rosbag2 directory: give the directory itself".into(),
        ));
    } else if path.extension().is_some_and(|e| e == "bin") {
        "a single file (a KITTI scan? give its sequence directory)".to_string()
    } else if first
        .iter()
        .all(|b| b.is_ascii_graphic() || b.is_ascii_whitespace())
    {
        "a text file".to_string()
    } else {
        let hex: Vec<String> = first.iter().take(8).map(|b| format!("{b:02x}")).collect();
        format!(
            "of a format travmap does not know (first bytes {})",
            hex.join(" ")
        )
    };
    Err(unsupported(path, what))
}

/// What a directory holds: a rosbag2 log, a KITTI sequence, a folder of scans; or,
/// refused with where to point instead, a folder of sequences or a dataset root.
fn directory_format(path: &Path) -> Result<InputFormat> {
    let storage = storage_files(path);
    if path.join("metadata.yaml").is_file() {
        return Ok(InputFormat::Rosbag2);
    }
    if !storage.is_empty() {
        // Without its metadata, a folder is one recording only where its files are
        // named as rosbag2 splits one (NAME_0.mcap, NAME_1.mcap, ...): separate logs
        // side by side are not one drive.
        return match one_recordings_files(&storage) {
            true => Ok(InputFormat::Rosbag2),
            false => {
                let names: Vec<String> = (storage.iter().take(4))
                    .filter_map(|f| Some(f.file_name()?.to_string_lossy().into_owned()))
                    .collect();
                Err(unsupported(
                    path,
                    format!(
                        "a folder of {} separate logs ({}{}), not one rosbag2 recording (whose files are NAME_0.mcap, NAME_1.mcap, ..., or listed in its metadata.yaml): give each log as an input of its own, e.g. {}",
                        storage.len(),
                        names.join(", "),
                        if storage.len() > 4 { ", ..." } else { "" },
                        storage[0].display()
                    ),
                ))
            }
        };
    }
    if is_sequence(path) {
        return Ok(InputFormat::Kitti);
    }
    let misplaced = |message: String| {
        Err(Error::Sequence {
            path: path.to_path_buf(),
            message,
        })
    };
    if let Some(first) = subdirectories(path).into_iter().find(|d| is_sequence(d)) {
        return misplaced(format!(
            "a folder of sequences, not one: point at one of them, e.g. {}",
            first.display()
        ));
    }
    let sequences = path.join("sequences");
    if sequences.is_dir() {
        let example = subdirectories(&sequences)
            .into_iter()
            .find(|d| is_sequence(d));
        return misplaced(format!(
            "a dataset root: point at one sequence, e.g. {}",
            example.unwrap_or_else(|| sequences.join("00")).display()
        ));
    }
    if holds_scans(path) {
        return Ok(InputFormat::ScanFolder);
    }
    // With its scans, read as a sequence: it names the file it misses.
    if path.join("velodyne").is_dir() {
        return Ok(InputFormat::Kitti);
    }
    let what = match std::fs::read_dir(path).map(|mut entries| entries.next().is_none()) {
        Ok(true) => "an empty folder",
        _ => {
            "a folder of no input travmap reads (not a KITTI sequence: no velodyne/ folder of scans)"
        }
    };
    Err(unsupported(path, what.into()))
}

/// Whether storage files found without a `metadata.yaml` are one recording's: one
/// file, or the numbered splits of one name.
fn one_recordings_files(files: &[PathBuf]) -> bool {
    let split_of = |file: &PathBuf| -> Option<String> {
        let name = file.file_name()?.to_str()?;
        let name = name.strip_suffix(".zstd").unwrap_or(name);
        let stem = name.rsplit_once('.')?.0;
        let (bag, index) = stem.rsplit_once('_')?;
        index.parse::<u64>().ok().map(|_| bag.to_string())
    };
    match files {
        [_] => true,
        [first, rest @ ..] => {
            let bag = split_of(first);
            bag.is_some() && rest.iter().all(|file| split_of(file) == bag)
        }
        [] => false,
    }
}

/// Whether `dir` is a KITTI sequence: its scans, and its calibration or poses (a
/// LiDAR alone, as nuScenes-lidarseg's conversions lay it out, has no calib.txt).
pub fn is_sequence(dir: &Path) -> bool {
    dir.join("velodyne").is_dir()
        && (dir.join("calib.txt").is_file() || dir.join("poses.txt").is_file())
}

fn subdirectories(path: &Path) -> Vec<PathBuf> {
    let entries = std::fs::read_dir(path).into_iter().flatten().flatten();
    let mut dirs: Vec<_> = entries.map(|e| e.path()).filter(|p| p.is_dir()).collect();
    dirs.sort();
    dirs
}

/// The kind of scan a folder of scans holds, by its name's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScanFormat {
    Pcd,
    Bin,
}

/// What `path` is as one scan of a folder of scans.
pub fn scan_format(path: &Path) -> Option<ScanFormat> {
    match path.extension()?.to_str()? {
        "pcd" => Some(ScanFormat::Pcd),
        "bin" => Some(ScanFormat::Bin),
        _ => None,
    }
}

/// Whether `dir` holds scans.
fn holds_scans(dir: &Path) -> bool {
    std::fs::read_dir(dir)
        .is_ok_and(|entries| entries.flatten().any(|e| scan_format(&e.path()).is_some()))
}

/// The error that refuses `path`, detected as `format`, where it cannot be read.
pub fn refuse(path: &Path, format: InputFormat) -> Error {
    unsupported(path, format.describe().to_string())
}

fn unsupported(path: &Path, what: String) -> Error {
    Error::UnsupportedInput {
        path: path.to_path_buf(),
        what,
        readable: READABLE,
    }
}

/// A rosbag2 directory's storage files (`.db3`, `.mcap`, either `.zstd`) in the order rosbag2
/// writes them: `bag_0`, `bag_1`, ... `bag_10` by the number after the last `_`,
/// then by name. How a directory without `metadata.yaml` is read.
pub fn storage_files(directory: &Path) -> Vec<PathBuf> {
    // The name without its storage extension (and `.zstd`, compressed whole).
    let stem = |path: &Path| {
        let name = path.file_name()?.to_str()?;
        let name = name.strip_suffix(".zstd").unwrap_or(name);
        name.strip_suffix(".db3")
            .or_else(|| name.strip_suffix(".mcap"))
            .map(str::to_string)
    };
    let entries = std::fs::read_dir(directory).into_iter().flatten().flatten();
    let mut files: Vec<PathBuf> = (entries.map(|entry| entry.path()))
        .filter(|path| path.is_file() && stem(path).is_some())
        .collect();
    // (bag name, index, stem) of `bag_3.db3`; a name without an index by itself.
    let key = |path: &PathBuf| -> (String, Option<u64>, String) {
        let stem = stem(path).unwrap_or_default();
        let indexed = (stem.rsplit_once('_'))
            .and_then(|(bag, n)| Some((bag.to_string(), n.parse::<u64>().ok()?)));
        match indexed {
            Some((bag, index)) => (bag, Some(index), stem),
            None => (stem.clone(), None, stem),
        }
    };
    files.sort_by_cached_key(key);
    files
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn storage_files_come_in_rosbag2s_order() {
        let dir = tempfile::tempdir().unwrap();
        for name in [
            "b_10.db3",
            "b_2.db3.zstd",
            "b_0.db3",
            "notes.txt",
            "a.mcap",
            "b_1.db3",
        ] {
            std::fs::write(dir.path().join(name), "").unwrap();
        }
        std::fs::create_dir(dir.path().join("c_0.db3")).unwrap();
        let names: Vec<_> = (storage_files(dir.path()).iter())
            .map(|path| path.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            names,
            ["a.mcap", "b_0.db3", "b_1.db3", "b_2.db3.zstd", "b_10.db3"]
        );
    }

    fn detect_bytes(name: &str, bytes: &[u8]) -> std::result::Result<InputFormat, String> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        detect(&path).map_err(|e| e.to_string())
    }

    #[test]
    fn formats_are_known_by_their_first_bytes_whatever_the_name() {
        assert_eq!(
            detect_bytes("x.bag", b"\x89MCAP0\r\nrest"),
            Ok(InputFormat::Mcap)
        );
        assert_eq!(
            detect_bytes("x.mcap", b"#ROSBAG V2.0\nrest"),
            Ok(InputFormat::Bag)
        );
        assert_eq!(
            detect_bytes("x", b"SQLite format 3\0rest"),
            Ok(InputFormat::Sqlite)
        );
        for (bytes, what) in [
            (&b"PAR1\x15\x04"[..], "a Parquet file"),
            (b"\x89PNG\r\n\x1a\n\0", "a PNG image"),
            (b"hello world\n", "a text file"),
            (b"", "an empty file"),
            (b"\x01\x02\x03", "first bytes 01 02 03"),
        ] {
            let err = detect_bytes("x.mcap", bytes).unwrap_err();
            assert!(err.contains(what) && err.contains("travmap reads"), "{err}");
        }
    }

    #[test]
    fn saved_clouds_are_sites_and_directories_are_told_by_their_layout() {
        for (bytes, kind) in [
            (&b"# .PCD v0.7"[..], SiteCloudFormat::Pcd),
            (b"VERSION .7\n", SiteCloudFormat::Pcd),
            (b"VERSION 0.7\n", SiteCloudFormat::Pcd),
            (b"FIELDS x y z reflectivity\n", SiteCloudFormat::Pcd),
            (b"ply\nformat", SiteCloudFormat::Ply),
            (b"LASF\0\0", SiteCloudFormat::Las),
        ] {
            assert_eq!(
                detect_bytes("cloud", bytes),
                Ok(InputFormat::SiteCloud(kind))
            );
        }
        let root = tempfile::tempdir().unwrap();
        let scans = root.path().join("scans");
        std::fs::create_dir(&scans).unwrap();
        std::fs::write(scans.join("000000.bin"), [0u8; 16]).unwrap();
        assert_eq!(detect(&scans).unwrap(), InputFormat::ScanFolder);
        let sequence = root.path().join("sequences/00");
        std::fs::create_dir_all(sequence.join("velodyne")).unwrap();
        std::fs::write(sequence.join("calib.txt"), "").unwrap();
        assert_eq!(detect(&sequence).unwrap(), InputFormat::Kitti);
        let err = detect(root.path()).unwrap_err().to_string();
        assert!(
            err.contains("a dataset root: point at one sequence"),
            "{err}"
        );
        let err = detect(&root.path().join("sequences"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("a folder of sequences, not one"), "{err}");
    }

    #[test]
    fn directories_are_rosbag2_with_metadata_else_kitti_and_missing_paths_say_so() {
        let dir = tempfile::tempdir().unwrap();
        // An empty folder is said to be one, not read as a sequence missing its files.
        let err = detect(dir.path()).unwrap_err().to_string();
        assert!(err.contains("is an empty folder"), "{err}");
        std::fs::create_dir(dir.path().join("velodyne")).unwrap();
        assert_eq!(detect(dir.path()).unwrap(), InputFormat::Kitti);
        std::fs::write(dir.path().join("metadata.yaml"), "x").unwrap();
        assert_eq!(detect(dir.path()).unwrap(), InputFormat::Rosbag2);
        let err = detect(&dir.path().join("nope.mcap"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("nope.mcap") && err.contains("does not exist"),
            "{err}"
        );
    }
}
