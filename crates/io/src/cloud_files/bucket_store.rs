//! A site cloud's points by bucket (a square of half a tile), gathered in one pass
//! over the file and read back a bucket at a time. Up to [`MEMORY_POINTS`] points
//! are held in memory; past that, what has been gathered is appended to a temporary
//! file in `$TMPDIR` (unlinked at once, so nothing is left behind even by a crash)
//! and read back from it: memory stays bounded whatever the cloud's size, and a
//! cloud that fits never touches the disk. A bucket's points come back in the
//! order they were pushed.

use std::collections::HashMap;
use std::fs::File;
use std::io::Write;
use std::os::unix::fs::FileExt;
use std::path::PathBuf;

/// Points held in memory before they go to the temporary file: 80 MB of records.
const MEMORY_POINTS: usize = 1 << 22;
/// x, y, z, intensity (f32 bits) and label.
pub const WORDS_PER_POINT: usize = 5;

#[derive(Default)]
struct Bucket {
    /// Runs of points in the temporary file: byte offset and point count.
    spilled: Vec<(u64, u32)>,
    held: Vec<u32>,
    points: usize,
}

/// Points by bucket key.
#[derive(Default)]
pub struct BucketStore {
    buckets: HashMap<[i64; 2], Bucket>,
    held_points: usize,
    spill: Option<Spill>,
}

struct Spill {
    path: PathBuf,
    file: File,
    bytes: u64,
}

/// A failure of the temporary file, with where it is.
pub struct SpillError {
    pub path: PathBuf,
    pub error: std::io::Error,
}

impl BucketStore {
    /// Adds a point (x, y, z, intensity) and its label to bucket `key`.
    pub fn push(&mut self, key: [i64; 2], point: [f32; 4], label: u32) -> Result<(), SpillError> {
        let bucket = self.buckets.entry(key).or_default();
        bucket.held.extend(point.map(f32::to_bits));
        bucket.held.push(label);
        bucket.points += 1;
        self.held_points += 1;
        if self.held_points >= MEMORY_POINTS {
            self.spill()?;
        }
        Ok(())
    }

    /// Appends every held point to the temporary file, bucket by bucket.
    fn spill(&mut self) -> Result<(), SpillError> {
        if self.spill.is_none() {
            let path = std::env::temp_dir().join(format!(
                "travmap-site-{}-{:p}.points",
                std::process::id(),
                self
            ));
            let failed = |error| SpillError {
                path: path.clone(),
                error,
            };
            let file = File::options()
                .read(true)
                .write(true)
                .create_new(true)
                .open(&path)
                .map_err(failed)?;
            std::fs::remove_file(&path).map_err(failed)?;
            self.spill = Some(Spill {
                path,
                file,
                bytes: 0,
            });
        }
        let spill = self.spill.as_mut().expect("created above");
        let mut out = std::io::BufWriter::with_capacity(1 << 20, &spill.file);
        let mut bytes = Vec::new();
        for bucket in self.buckets.values_mut().filter(|b| !b.held.is_empty()) {
            bytes.clear();
            bytes.extend(bucket.held.iter().flat_map(|w| w.to_le_bytes()));
            out.write_all(&bytes).map_err(|error| SpillError {
                path: spill.path.clone(),
                error,
            })?;
            let points = (bucket.held.len() / WORDS_PER_POINT) as u32;
            bucket.spilled.push((spill.bytes, points));
            spill.bytes += bytes.len() as u64;
            // Let go, not just cleared: the memory is what spilling is for.
            bucket.held = Vec::new();
        }
        out.flush().map_err(|error| SpillError {
            path: spill.path.clone(),
            error,
        })?;
        self.held_points = 0;
        Ok(())
    }

    pub fn keys(&self) -> impl Iterator<Item = &[i64; 2]> {
        self.buckets.keys()
    }

    /// The number of points in bucket `key`.
    pub fn points(&self, key: &[i64; 2]) -> usize {
        self.buckets.get(key).map_or(0, |b| b.points)
    }

    /// Appends the records of bucket `key` ([`WORDS_PER_POINT`] words a point) to
    /// `out`.
    pub fn read(&self, key: &[i64; 2], out: &mut Vec<u32>) -> Result<(), SpillError> {
        let Some(bucket) = self.buckets.get(key) else {
            return Ok(());
        };
        if let Some(spill) = &self.spill {
            for &(offset, points) in &bucket.spilled {
                let start = out.len();
                out.resize(start + points as usize * WORDS_PER_POINT, 0);
                let mut bytes = vec![0u8; (out.len() - start) * 4];
                spill
                    .file
                    .read_exact_at(&mut bytes, offset)
                    .map_err(|error| SpillError {
                        path: spill.path.clone(),
                        error,
                    })?;
                for (word, b) in out[start..].iter_mut().zip(bytes.chunks_exact(4)) {
                    *word = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                }
            }
        }
        out.extend_from_slice(&bucket.held);
        Ok(())
    }

    /// The bytes in the temporary file (0 when the cloud fitted in memory).
    pub fn spilled_bytes(&self) -> u64 {
        self.spill.as_ref().map_or(0, |s| s.bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_come_back_by_bucket_in_order_from_memory_and_from_the_file() {
        let mut store = BucketStore::default();
        let point = |i: usize| [i as f32, -(i as f32), 0.5, 0.25];
        let key = |i: usize| [(i % 3) as i64, 0];
        let pushed = 2 * MEMORY_POINTS + 10;
        for i in 0..pushed {
            store.push(key(i), point(i), i as u32).ok().unwrap();
        }
        assert!(store.spilled_bytes() > 0);
        let mut out = Vec::new();
        for k in 0..3 {
            out.clear();
            store.read(&[k, 0], &mut out).ok().unwrap();
            let expected: Vec<usize> = (0..pushed).filter(|&i| key(i) == [k, 0]).collect();
            assert_eq!(store.points(&[k, 0]), expected.len());
            assert_eq!(out.len(), expected.len() * WORDS_PER_POINT);
            for (record, &i) in out.chunks_exact(WORDS_PER_POINT).zip(&expected) {
                assert_eq!(record[..4], point(i).map(f32::to_bits));
                assert_eq!(record[4], i as u32);
            }
        }
        out.clear();
        store.read(&[7, 7], &mut out).ok().unwrap();
        assert!(out.is_empty());
    }
}
