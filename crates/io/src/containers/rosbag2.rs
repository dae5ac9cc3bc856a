//! rosbag2 logs: a directory of `metadata.yaml` and its storage files (sqlite3 `.db3`,
//! read by [`super::sqlite`], or MCAP), read in the order the metadata lists them as
//! one drive, and how the bag is compressed.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::format::{InputFormat, detect, storage_files};
use travmap_core::error::{Error, Result};

/// The part of `metadata.yaml` that says where the messages are.
#[derive(Deserialize)]
struct Metadata {
    rosbag2_bagfile_information: Information,
}

#[derive(Deserialize)]
struct Information {
    #[serde(default)]
    storage_identifier: String,
    #[serde(default)]
    relative_file_paths: Vec<String>,
    #[serde(default)]
    compression_format: String,
    #[serde(default)]
    compression_mode: String,
}

/// How a rosbag2 bag is compressed, as its metadata says.
#[derive(PartialEq)]
enum Compression {
    None,
    /// Each message's data is a zstd frame (`--compression-mode message`).
    ZstdMessages,
    /// Each storage file is zstd-compressed whole (`--compression-mode file`).
    ZstdFiles,
}

impl Information {
    fn compression(&self) -> std::result::Result<Compression, String> {
        let (mode, format) = (&self.compression_mode, &self.compression_format);
        match (mode.to_lowercase().as_str(), format.as_str()) {
            ("" | "none", _) => Ok(Compression::None),
            ("message", "zstd") => Ok(Compression::ZstdMessages),
            ("file", "zstd") => Ok(Compression::ZstdFiles),
            _ => Err(format!(
                "the bag is compressed ({mode} mode, `{format}`); travmap reads uncompressed rosbag2 files and zstd compression (message or file mode): run `ros2 bag decompress` (or `ros2 bag convert`) on a copy first"
            )),
        }
    }
}

/// The storage files a rosbag2 directory's `metadata.yaml` lists, wherever they lie
/// (a path may leave the directory: `../outside.db3`); none when it has no metadata
/// or the metadata does not read.
pub fn listed_storage_files(directory: &Path) -> Vec<PathBuf> {
    let Ok(text) = std::fs::read_to_string(directory.join("metadata.yaml")) else {
        return Vec::new();
    };
    let Ok(metadata) = crate::yaml::from_str::<Metadata>(&text) else {
        return Vec::new();
    };
    let listed = metadata.rosbag2_bagfile_information.relative_file_paths;
    listed
        .iter()
        .map(|relative| directory.join(relative))
        .collect()
}

/// A rosbag2 directory: its storage files in order, each with its format (sqlite3
/// or MCAP), for [`super::log`] to open.
pub struct Rosbag2Directory {
    pub storage: Vec<(PathBuf, InputFormat)>,
    /// Each message's data is a zstd frame (`ros2 bag record --compression-mode
    /// message`).
    pub zstd_messages: bool,
    /// Where storage files compressed whole (`--compression-mode file`) were
    /// decompressed to: removed when the directory is dropped.
    pub decompressed: Option<tempfile::TempDir>,
    pub notice: Option<String>,
}

impl Rosbag2Directory {
    pub fn open(directory: &Path) -> Result<Self> {
        let metadata_path = directory.join("metadata.yaml");
        if !metadata_path.exists() {
            return Self::without_metadata(directory);
        }
        let problem = |problem: String| Error::LogContainer {
            path: metadata_path.clone(),
            problem,
        };
        let text =
            std::fs::read_to_string(&metadata_path).map_err(|e| Error::io(&metadata_path, e))?;
        let metadata: Metadata = crate::yaml::from_str(&text)
            .map_err(|e| problem(format!("not rosbag2 metadata: {e}")))?;
        let information = metadata.rosbag2_bagfile_information;
        let compression = information.compression().map_err(problem)?;
        let zstd_files = compression == Compression::ZstdFiles;
        if information.relative_file_paths.is_empty() {
            return Err(problem("it lists no storage files".into()));
        }
        let mut decompressed = None;
        let mut storage = Vec::new();
        for relative in &information.relative_file_paths {
            let mut path = directory.join(relative);
            if !path.exists() {
                return Err(problem(format!(
                    "it lists the storage file `{relative}`, which is missing ({})",
                    path.display()
                )));
            }
            if zstd_files && relative.ends_with(".zstd") {
                path = decompress_file(&path, &mut decompressed)?;
            }
            let format = detect(&path)?;
            if !matches!(format, InputFormat::Sqlite | InputFormat::Mcap) {
                return Err(problem(format!(
                    "its storage file `{relative}` is neither sqlite3 nor MCAP (storage `{}`)",
                    information.storage_identifier
                )));
            }
            storage.push((path, format));
        }
        Ok(Self {
            notice: decompressed_notice(&decompressed, &storage),
            storage,
            zstd_messages: compression == Compression::ZstdMessages,
            decompressed,
        })
    }

    /// A directory of storage files without `metadata.yaml` (a recording that was
    /// not closed, or copied without it): its files in rosbag2's order, each read as
    /// it says of itself (compression included, from the metadata each file keeps).
    fn without_metadata(directory: &Path) -> Result<Self> {
        let (mut storage, mut decompressed, mut names) = (Vec::new(), None, Vec::new());
        for mut path in storage_files(directory) {
            names.extend(
                path.file_name()
                    .map(|name| name.to_string_lossy().into_owned()),
            );
            if path.extension().is_some_and(|e| e == "zstd") {
                path = decompress_file(&path, &mut decompressed)?;
            }
            let format = detect(&path)?;
            if !matches!(format, InputFormat::Sqlite | InputFormat::Mcap) {
                return Err(Error::LogContainer {
                    path,
                    problem: "a storage file of a rosbag2 directory, but neither sqlite3 nor MCAP"
                        .into(),
                });
            }
            storage.push((path, format));
        }
        let notice = format!(
            "{}: no metadata.yaml (a recording that was not closed, or a copy without it): its storage files read in rosbag2's order, {}; `ros2 bag reindex` writes the metadata",
            directory.display(),
            names.join(", ")
        );
        let notices = [Some(notice), decompressed_notice(&decompressed, &storage)];
        Ok(Self {
            storage,
            zstd_messages: false,
            decompressed,
            notice: Some(notices.into_iter().flatten().collect::<Vec<_>>().join("; ")),
        })
    }
}

/// What is said of storage files decompressed into `decompressed`.
fn decompressed_notice(
    decompressed: &Option<tempfile::TempDir>,
    storage: &[(PathBuf, InputFormat)],
) -> Option<String> {
    let into = decompressed.as_ref()?;
    let bytes: u64 = (storage.iter())
        .filter(|(path, _)| path.starts_with(into.path()))
        .filter_map(|(path, _)| std::fs::metadata(path).ok())
        .map(|metadata| metadata.len())
        .sum();
    Some(format!(
        "the bag's storage files are zstd-compressed whole (file mode): decompressed to {} ({:.1} MB, removed at exit)",
        into.path().display(),
        bytes as f64 / 1e6
    ))
}

/// `compressed` (a storage file zstd-compressed whole) decompressed into a
/// temporary directory (made at the first), under its name without `.zstd`.
fn decompress_file(compressed: &Path, into: &mut Option<tempfile::TempDir>) -> Result<PathBuf> {
    let into = match into {
        Some(into) => into,
        empty => empty.insert(super::temporary_dir("travmap-rosbag2-")?),
    };
    let name = compressed.file_stem().unwrap_or(compressed.as_os_str());
    let path = into.path().join(name);
    let source = std::fs::File::open(compressed).map_err(|e| Error::io(compressed, e))?;
    let mut target = std::fs::File::create(&path).map_err(|e| Error::io(&path, e))?;
    let mut decoder =
        zstd::stream::read::Decoder::new(source).map_err(|e| Error::io(compressed, e))?;
    std::io::copy(&mut decoder, &mut target).map_err(|e| Error::LogContainer {
        path: compressed.to_path_buf(),
        problem: format!("it does not decompress (zstd) into {}: {e}", path.display()),
    })?;
    Ok(path)
}

/// Whether the copy of a bag's metadata a storage file keeps (rosbag2 Iron and
/// later, and `rosbags`, write one into each `.db3` and MCAP) says each message is
/// a zstd frame: how a file given without its directory is read. rosbag2 writes it
/// as `metadata.yaml` reads, `rosbags` without the outer key; text that is neither
/// says nothing.
pub(crate) fn says_zstd_messages(text: &str) -> std::result::Result<bool, String> {
    let information = crate::yaml::from_str::<Metadata>(text)
        .map(|metadata| metadata.rosbag2_bagfile_information)
        .or_else(|_| crate::yaml::from_str::<Information>(text));
    match information {
        Ok(information) => Ok(information.compression()? == Compression::ZstdMessages),
        Err(_) => Ok(false),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::containers::sqlite::own_metadata;

    #[test]
    fn compression_is_read_from_either_form_of_the_metadata() {
        let database = rusqlite::Connection::open_in_memory().unwrap();
        assert!(own_metadata(&database).is_none(), "no metadata table");
        let message = "compression_mode: MESSAGE\ncompression_format: zstd\n";
        database
            .execute_batch(
                "CREATE TABLE metadata(id INTEGER, metadata_version INTEGER, metadata TEXT)",
            )
            .unwrap();
        database
            .execute("INSERT INTO metadata VALUES (1, 9, ?1)", [message])
            .unwrap();
        assert_eq!(own_metadata(&database).as_deref(), Some(message));
        assert_eq!(says_zstd_messages(message), Ok(true));
        let wrapped = "rosbag2_bagfile_information:\n  compression_mode: message\n  compression_format: zstd\n";
        assert_eq!(says_zstd_messages(wrapped), Ok(true));
        // A file decompressed from file mode keeps the metadata of the compressed bag.
        let file = "compression_mode: FILE\ncompression_format: zstd\n";
        assert_eq!(says_zstd_messages(file), Ok(false));
        assert_eq!(says_zstd_messages("compression_mode: ''\n"), Ok(false));
        assert_eq!(says_zstd_messages("[not, metadata]"), Ok(false));
        let refused = says_zstd_messages("compression_mode: message\ncompression_format: lz4\n");
        assert!(refused.unwrap_err().contains("message mode, `lz4`"));
    }
}
