//! A site map's input: one saved point cloud (a SLAM or survey map, a merged drive)
//! in its own world frame with no trajectory, read by the method as frames: square
//! tiles the size of the grid, half a grid apart, each seen from a virtual sensor at
//! its centre, [`SENSOR_HEIGHT_M`] above the tile's ground.
//!
//! Tiles overlap by half, so every cell lies in the inner half of some tile, and the
//! drive map's fusion weighs each observation by its distance from the tile's
//! sensor: a cell near a tile's edge (where the outlier filter sees fewer
//! neighbours) counts less than the same cell near another tile's centre. A cell
//! holds every point the map has there, not the last n scans of a drive: a map made
//! of many passes is denser than the 3-scan window the model was trained on, and
//! `integration.scans` is 1 (the tile is the whole window).
//!
//! The file is read once, a chunk at a time, into a `BucketStore` (points by
//! bucket of half a tile; past a bound, in a temporary file), and each tile is read
//! back from its four buckets when it is the method's turn: memory stays bounded
//! whatever the cloud's size.

use std::ops::Range;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use super::bucket_store::{BucketStore, SpillError, WORDS_PER_POINT};
use super::las::stream_las;
use super::pcd::stream_pcd;
use super::ply::stream_ply;
use crate::format::SiteCloudFormat;
use crate::payloads::cloud::{raw_cloud_points, remission_scale};
use travmap_core::error::{Error, Result};
use travmap_core::frame::{Frame, RemissionScale};
use travmap_formats::ros::PointCloud2;

/// The frame the tiles' points are in, as written to MCAP.
pub const SENSOR_FRAME: &str = "site";
/// The virtual sensor's height above a tile's ground: KITTI's Velodyne mount, the
/// height the embedded model's scans were taken from.
pub const SENSOR_HEIGHT_M: f64 = 1.73;
/// A tile's ground: this quantile of its points' heights.
const GROUND_QUANTILE: f64 = 0.05;
/// Tiles with fewer points are not read.
const MIN_TILE_POINTS: usize = 50;
/// Tiles are stamped this far apart, for outputs that need times.
const TILE_PERIOD_NS: u64 = 100_000_000;

struct Tile {
    sensor_in_world: [f64; 3],
    /// The 2 x 2 buckets (half a tile square each) the tile covers.
    buckets: [[i64; 2]; 4],
}

/// An opened site cloud and its tiles.
pub struct SiteCloud {
    path: PathBuf,
    points: usize,
    /// Points by bucket of half a tile, as the file holds them (intensity unscaled).
    store: BucketStore,
    labelled: bool,
    remission: RemissionScale,
    /// Brings the file's intensity to the 0..1 scale.
    remission_factor: f32,
    tiles: Vec<Tile>,
    tile_m: f64,
    /// Where the points' origin lies in the file's coordinates (LAS: a local origin
    /// that keeps float32 precise; else zero), and the CRS the file names.
    origin_m: [f64; 3],
    crs_wkt: Option<String>,
    /// Points of a LAS / LAZ file left out for a non-finite coordinate.
    dropped: usize,
}

impl SiteCloud {
    /// Reads the PCD, PLY or LAS / LAZ file at `path` (of `format`, as
    /// [`crate::format::detect`] found it) and cuts it into tiles of `grid_size_m`.
    pub fn open(path: &Path, format: SiteCloudFormat, grid_size_m: f64) -> Result<Self> {
        let fail = |message: String| Error::Sequence {
            path: path.to_path_buf(),
            message,
        };
        let spill_failed = |e: SpillError| {
            fail(format!(
                "keeping the cloud's points in the temporary file {} (TMPDIR picks its place): {}",
                e.path.display(),
                e.error
            ))
        };
        let step = grid_size_m / 2.0;
        let key = |p: &[f32; 4]| [p[0], p[1]].map(|v| (v as f64 / step).floor() as i64);
        let mut store = BucketStore::default();
        let (mut points, mut labelled, mut largest_intensity) = (0usize, false, 0.0f32);
        let mut intensity_datatype = None;
        let mut spilled: Option<SpillError> = None;
        let mut keep =
            |batch: &[[f32; 4]], labels: Option<&[u32]>| -> std::result::Result<(), String> {
                for (i, p) in batch.iter().enumerate() {
                    if let Err(e) = store.push(key(p), *p, labels.map_or(0, |l| l[i])) {
                        let message = e.error.to_string();
                        spilled = Some(e);
                        return Err(message);
                    }
                }
                points += batch.len();
                Ok(())
            };
        let mut keep_cloud = |chunk: &PointCloud2| {
            let (read, datatype) = raw_cloud_points(chunk)?;
            intensity_datatype = datatype;
            labelled = read.labels.is_some();
            largest_intensity = read
                .points
                .iter()
                .map(|p| p[3])
                .fold(largest_intensity, f32::max);
            keep(&read.points, read.labels.as_deref())
        };
        let read = match format {
            SiteCloudFormat::Las => stream_las(path, &mut |batch| {
                largest_intensity = batch.iter().map(|p| p[3]).fold(largest_intensity, f32::max);
                keep(batch, None)
            })
            .map(|place| Some((place.origin_m, place.crs_wkt, place.dropped))),
            SiteCloudFormat::Ply => stream_ply(path, &mut keep_cloud).map(|()| None),
            SiteCloudFormat::Pcd => stream_pcd(path, &mut keep_cloud).map(|()| None),
        };
        if let Some(e) = spilled {
            return Err(spill_failed(e));
        }
        let place = read.map_err(fail)?;
        // LAS intensity is of an unknown scale (see `las.rs`), whatever its values.
        let (remission, remission_factor) = match &place {
            Some(_) if largest_intensity > 0.0 => {
                (RemissionScale::Unknown, 1.0 / largest_intensity)
            }
            Some(_) => (RemissionScale::Missing, 0.0),
            None => remission_scale(intensity_datatype, largest_intensity),
        };
        let (origin_m, crs_wkt, dropped) = place.unwrap_or(([0.0; 3], None, 0));
        if points == 0 {
            return Err(fail("the cloud holds no point".into()));
        }
        // A tile is the 2 x 2 buckets around a corner.
        let mut corners: Vec<[i64; 2]> = store
            .keys()
            .flat_map(|&[x, y]| [[x, y], [x + 1, y], [x, y + 1], [x + 1, y + 1]])
            .collect();
        corners.sort_unstable();
        corners.dedup();
        let mut tiles = Vec::new();
        let (mut records, mut heights) = (Vec::new(), Vec::new());
        for [cx, cy] in corners {
            let tile_buckets = [[cx - 1, cy - 1], [cx, cy - 1], [cx - 1, cy], [cx, cy]];
            if tile_buckets.iter().map(|b| store.points(b)).sum::<usize>() < MIN_TILE_POINTS {
                continue;
            }
            records.clear();
            for bucket in &tile_buckets {
                store.read(bucket, &mut records).map_err(spill_failed)?;
            }
            heights.clear();
            heights.extend(
                records
                    .chunks_exact(WORDS_PER_POINT)
                    .map(|r| f32::from_bits(r[2])),
            );
            let at = ((heights.len() - 1) as f64 * GROUND_QUANTILE) as usize;
            let ground = *heights.select_nth_unstable_by(at, f32::total_cmp).1 as f64;
            tiles.push(Tile {
                sensor_in_world: [cx as f64 * step, cy as f64 * step, ground + SENSOR_HEIGHT_M],
                buckets: tile_buckets,
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            points,
            store,
            labelled,
            remission,
            remission_factor,
            tiles,
            tile_m: grid_size_m,
            origin_m,
            crs_wkt,
            dropped,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The cloud's local origin in the file's coordinates and the CRS the file
    /// names, when the file is georeferenced (LAS / LAZ); None otherwise.
    pub fn georeference(&self) -> Option<([f64; 3], Option<&str>)> {
        (self.origin_m != [0.0; 3] || self.crs_wkt.is_some())
            .then_some((self.origin_m, self.crs_wkt.as_deref()))
    }

    /// What the reader made of the cloud, for the user to hear.
    pub fn notice(&self) -> String {
        let mut notice = format!(
            "{}: one point cloud of {} points, read as {} tiles of {} m (half a tile apart), each seen from {SENSOR_HEIGHT_M} m above its ground",
            self.path.display(),
            self.points,
            self.tiles.len(),
            self.tile_m
        );
        if self.origin_m != [0.0; 3] {
            let [x, y, z] = self.origin_m;
            notice += &format!(
                "; the map's frame is the file's coordinates minus ({x}, {y}, {z}), which keeps float32 precise"
            );
        }
        if self.dropped > 0 {
            notice += &format!(
                "; {} points without finite coordinates left out",
                self.dropped
            );
        }
        let spilled = self.store.spilled_bytes();
        if spilled > 0 {
            notice += &format!(
                "; {} MB of its points kept in a temporary file in {} (TMPDIR) so memory stays bounded",
                spilled >> 20,
                std::env::temp_dir().display()
            );
        }
        if let Some(wkt) = &self.crs_wkt {
            let name = wkt.split('"').nth(1).unwrap_or(wkt);
            notice += &format!(" (the file's CRS: {name})");
        }
        notice
    }

    pub fn frames_in(&self, range: &Range<usize>) -> Vec<usize> {
        (range.start.min(self.tiles.len())..range.end.min(self.tiles.len())).collect()
    }

    /// Each tile's virtual sensor pose in the cloud's frame.
    pub fn poses(&self) -> Vec<(usize, Isometry3<f64>)> {
        (0..self.tiles.len()).map(|i| (i, self.pose(i))).collect()
    }

    fn pose(&self, index: usize) -> Isometry3<f64> {
        let [x, y, z] = self.tiles[index].sensor_in_world;
        Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::identity())
    }

    /// Tile `index` as a frame: its points relative to its sensor.
    pub fn read_frame(&self, index: usize) -> Result<Frame> {
        let tile = &self.tiles[index];
        let mut records = Vec::new();
        for bucket in &tile.buckets {
            self.store
                .read(bucket, &mut records)
                .map_err(|e| Error::Sequence {
                    path: self.path.clone(),
                    message: format!(
                        "reading tile {index} back from the temporary file {}: {}",
                        e.path.display(),
                        e.error
                    ),
                })?;
        }
        let [x, y, z] = tile.sensor_in_world;
        let relative = |v: u32, origin: f64| (f32::from_bits(v) as f64 - origin) as f32;
        let points_in_velodyne = records
            .chunks_exact(WORDS_PER_POINT)
            .map(|r| {
                [
                    relative(r[0], x),
                    relative(r[1], y),
                    relative(r[2], z),
                    f32::from_bits(r[3]) * self.remission_factor,
                ]
            })
            .collect();
        let labels = self.labelled.then(|| {
            records
                .chunks_exact(WORDS_PER_POINT)
                .map(|r| r[4])
                .collect()
        });
        Ok(Frame {
            index,
            stamp_ns: index as u64 * TILE_PERIOD_NS,
            world_from_velodyne: self.pose(index),
            points_in_velodyne,
            remission: self.remission,
            labels,
            camera: None,
            dropped_points: 0,
            sensors: Vec::new(),
        })
    }
}
