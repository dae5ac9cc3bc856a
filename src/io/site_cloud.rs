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
//! The cloud is read whole into memory (16 bytes a point, 4 more with labels).

use std::ops::Range;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use super::cloud::cloud_points;
use super::pcd::parse_pcd;
use super::skips::SkipLog;
use crate::error::{Error, Result};
use crate::frame::{Frame, RemissionScale};

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
    points: Vec<u32>,
}

/// An opened site cloud and its tiles.
pub struct SiteCloud {
    path: PathBuf,
    points: Vec<[f32; 4]>,
    labels: Option<Vec<u32>>,
    remission: RemissionScale,
    tiles: Vec<Tile>,
    tile_m: f64,
    pub(super) skips: SkipLog,
}

impl SiteCloud {
    /// Reads the PCD at `path` and cuts it into tiles of `grid_size_m`.
    pub fn open(path: &Path, grid_size_m: f64) -> Result<Self> {
        let fail = |message: String| Error::Sequence {
            path: path.to_path_buf(),
            message,
        };
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let cloud = parse_pcd(&bytes, SENSOR_FRAME).map_err(fail)?;
        let read = cloud_points(&cloud).map_err(fail)?;
        if read.points.is_empty() {
            return Err(fail("the cloud holds no point".into()));
        }
        let step = grid_size_m / 2.0;
        let key = |v: f32| (v as f64 / step).floor() as i64;
        // Buckets of step x step metres; a tile is the 2 x 2 buckets around a corner.
        let mut buckets: std::collections::HashMap<[i64; 2], Vec<u32>> = Default::default();
        for (i, p) in read.points.iter().enumerate() {
            buckets
                .entry([key(p[0]), key(p[1])])
                .or_default()
                .push(i as u32);
        }
        let mut corners: Vec<[i64; 2]> = buckets
            .keys()
            .flat_map(|&[x, y]| [[x, y], [x + 1, y], [x, y + 1], [x + 1, y + 1]])
            .collect();
        corners.sort_unstable();
        corners.dedup();
        let mut tiles = Vec::new();
        for [cx, cy] in corners {
            let points: Vec<u32> = [[cx - 1, cy - 1], [cx, cy - 1], [cx - 1, cy], [cx, cy]]
                .iter()
                .filter_map(|b| buckets.get(b))
                .flatten()
                .copied()
                .collect();
            if points.len() < MIN_TILE_POINTS {
                continue;
            }
            let mut heights: Vec<f32> =
                points.iter().map(|&i| read.points[i as usize][2]).collect();
            let at = ((heights.len() - 1) as f64 * GROUND_QUANTILE) as usize;
            let ground = *heights.select_nth_unstable_by(at, f32::total_cmp).1 as f64;
            tiles.push(Tile {
                sensor_in_world: [cx as f64 * step, cy as f64 * step, ground + SENSOR_HEIGHT_M],
                points,
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            points: read.points,
            labels: read.labels,
            remission: read.remission,
            tiles,
            tile_m: grid_size_m,
            skips: SkipLog::default(),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What the reader made of the cloud, for the user to hear.
    pub fn notice(&self) -> String {
        format!(
            "{}: one point cloud of {} points, read as {} tiles of {} m (half a tile apart), each seen from {SENSOR_HEIGHT_M} m above its ground",
            self.path.display(),
            self.points.len(),
            self.tiles.len(),
            self.tile_m
        )
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
        let [x, y, z] = tile.sensor_in_world;
        let points_in_velodyne = tile
            .points
            .iter()
            .map(|&i| {
                let p = self.points[i as usize];
                let relative = |v: f32, origin: f64| (v as f64 - origin) as f32;
                [
                    relative(p[0], x),
                    relative(p[1], y),
                    relative(p[2], z),
                    p[3],
                ]
            })
            .collect();
        let labels = self
            .labels
            .as_ref()
            .map(|labels| tile.points.iter().map(|&i| labels[i as usize]).collect());
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
