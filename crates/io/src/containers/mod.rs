//! Log containers: ROS 1 bags, rosbag2 folders and their SQLite or MCAP storage,
//! packet captures, and the [`log::Log`] that reads any of them as one stream.

pub mod bag;
pub mod bag_messages;
pub mod log;
pub mod pcap;
pub mod rosbag2;
pub mod sqlite;
pub(crate) mod sqlite_wal;

use travmap_core::error::{Error, Result};
use travmap_core::temporaries;

/// A temporary folder in `$TMPDIR` (a decompressed storage file, a database copied
/// with its WAL), registered so that a signal's handler removes it: the folder's
/// own `Drop` does not run when the process exits there. Its registration outlives
/// it, harmlessly: its random name is not reused.
pub(crate) fn temporary_dir(prefix: &str) -> Result<tempfile::TempDir> {
    let dir = tempfile::Builder::new()
        .prefix(prefix)
        .tempdir()
        .map_err(|e| Error::io(std::env::temp_dir(), e))?;
    temporaries::track(dir.path());
    Ok(dir)
}
