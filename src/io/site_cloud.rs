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
//! The cloud is read whole into memory: 16 bytes a point (4 more with labels) and 4
//! for its bucket, after the file and its decoded copy are let go.

use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use super::cloud::{CloudPoints, cloud_points};
use super::format::{SiteCloudFormat, site_cloud_format};
use super::las::read_las;
use super::pcd::parse_pcd_up_to;
use super::ply::parse_ply;
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
    /// The 2 x 2 buckets (half a tile square each) the tile covers.
    buckets: [[i64; 2]; 4],
}

/// An opened site cloud and its tiles.
pub struct SiteCloud {
    path: PathBuf,
    points: Vec<[f32; 4]>,
    labels: Option<Vec<u32>>,
    remission: RemissionScale,
    /// Point indices by bucket of half a tile.
    buckets: HashMap<[i64; 2], Vec<u32>>,
    tiles: Vec<Tile>,
    tile_m: f64,
    /// Where the points' origin lies in the file's coordinates (LAS: a local origin
    /// that keeps float32 precise; else zero), and the CRS the file names.
    origin_m: [f64; 3],
    crs_wkt: Option<String>,
    pub(super) skips: SkipLog,
}

impl SiteCloud {
    /// Reads the PCD, PLY or LAS / LAZ file at `path` and cuts it into tiles of
    /// `grid_size_m`.
    pub fn open(path: &Path, grid_size_m: f64) -> Result<Self> {
        let fail = |message: String| Error::Sequence {
            path: path.to_path_buf(),
            message,
        };
        // The file and its decoded cloud are let go before the tiles are made.
        let mut origin = None;
        let mut read_cloud = || -> Result<CloudPoints> {
            let cloud = match site_cloud_format(path) {
                Some(SiteCloudFormat::Las) => {
                    let las = read_las(path).map_err(fail)?;
                    origin = Some((las.origin_m, las.crs_wkt));
                    return Ok(las.points);
                }
                Some(SiteCloudFormat::Ply) => {
                    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
                    parse_ply(&bytes, SENSOR_FRAME)
                }
                _ => {
                    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
                    // A compressed PCD may hold more than it measures; not a thousandfold.
                    let largest = (bytes.len().saturating_mul(8)).max(1 << 30);
                    parse_pcd_up_to(&bytes, SENSOR_FRAME, largest)
                }
            };
            cloud_points(&cloud.map_err(fail)?).map_err(fail)
        };
        let read = read_cloud()?;
        let (origin_m, crs_wkt) = origin.unwrap_or(([0.0; 3], None));
        if read.points.is_empty() {
            return Err(fail("the cloud holds no point".into()));
        }
        let step = grid_size_m / 2.0;
        let key = |v: f32| (v as f64 / step).floor() as i64;
        // Buckets of step x step metres; a tile is the 2 x 2 buckets around a corner.
        let mut buckets: HashMap<[i64; 2], Vec<u32>> = HashMap::new();
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
        let mut heights = Vec::new();
        for [cx, cy] in corners {
            let tile_buckets = [[cx - 1, cy - 1], [cx, cy - 1], [cx - 1, cy], [cx, cy]];
            heights.clear();
            heights.extend(
                tile_buckets
                    .iter()
                    .filter_map(|b| buckets.get(b))
                    .flatten()
                    .map(|&i| read.points[i as usize][2]),
            );
            if heights.len() < MIN_TILE_POINTS {
                continue;
            }
            let at = ((heights.len() - 1) as f64 * GROUND_QUANTILE) as usize;
            let ground = *heights.select_nth_unstable_by(at, f32::total_cmp).1 as f64;
            tiles.push(Tile {
                sensor_in_world: [cx as f64 * step, cy as f64 * step, ground + SENSOR_HEIGHT_M],
                buckets: tile_buckets,
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            points: read.points,
            labels: read.labels,
            remission: read.remission,
            buckets,
            tiles,
            tile_m: grid_size_m,
            origin_m,
            crs_wkt,
            skips: SkipLog::default(),
        })
    }

    /// The points of tile `index`, by their place in the cloud.
    fn tile_points(&self, index: usize) -> impl Iterator<Item = usize> + '_ {
        self.tiles[index]
            .buckets
            .iter()
            .filter_map(|b| self.buckets.get(b))
            .flatten()
            .map(|&i| i as usize)
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
            self.points.len(),
            self.tiles.len(),
            self.tile_m
        );
        if self.origin_m != [0.0; 3] {
            let [x, y, z] = self.origin_m;
            notice += &format!(
                "; the map's frame is the file's coordinates minus ({x}, {y}, {z}), which keeps float32 precise"
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
        let [x, y, z] = self.tiles[index].sensor_in_world;
        let points_in_velodyne = self
            .tile_points(index)
            .map(|i| {
                let p = self.points[i];
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
            .map(|labels| self.tile_points(index).map(|i| labels[i]).collect());
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
