//! The local map of scan registration (`registration.rs`): world points in voxels,
//! at most a few per voxel, in one flat array of fixed-size blocks, and the search
//! for a point's nearest map point in the 27 voxels around it.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use nalgebra::{Isometry3, Point3, Vector3};

/// `f64::floor` is a libm call on baseline x86-64.
fn floor(x: f64) -> i32 {
    let t = x as i32;
    t - ((t as f64) > x) as i32
}

/// Voxel indices packed 21 bits each. Indices beyond +-2^20 wrap; the local map and a
/// scan span far fewer voxels, so no two voxels in use share a key.
pub(super) fn pack(v: [u64; 3]) -> u64 {
    const MASK: u64 = (1 << 21) - 1;
    ((v[0] & MASK) << 42) | ((v[1] & MASK) << 21) | (v[2] & MASK)
}

/// Packed keys need only their bits mixed; SipHash took longer than the search.
#[derive(Default)]
pub(super) struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        let h = (self.0 ^ (self.0 >> 31)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        h ^ (h >> 29)
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = self.0.rotate_left(8) ^ b as u64;
        }
    }
    fn write_u64(&mut self, key: u64) {
        self.0 = key;
    }
}

pub(super) type KeyHash = BuildHasherDefault<KeyHasher>;

/// The local map: up to `capacity` world points per voxel, in fixed-size blocks of one
/// flat array, so that neither adding nor searching allocates per voxel.
pub(super) struct VoxelMap {
    pub(super) voxel_size_m: f64,
    capacity: usize,
    /// A point nearer than this to one in its voxel adds nothing (KISS-ICP: the
    /// spacing of `capacity` points spread over a voxel face).
    min_spacing2_m2: f64,
    /// The 27 voxel offsets, the voxel itself first and corners last: near voxels
    /// shrink the search radius early, so that more far ones are skipped.
    neighbours: [[i32; 3]; 27],
    block_of: HashMap<u64, u32, KeyHash>,
    keys: Vec<u64>,
    counts: Vec<u32>,
    points: Vec<Vector3<f64>>,
}

impl VoxelMap {
    pub(super) fn new(voxel_size_m: f64, capacity: usize) -> Self {
        let offset = |i: usize| [i / 9, i / 3 % 3, i % 3].map(|c| c as i32 - 1);
        let mut neighbours = std::array::from_fn(offset);
        neighbours.sort_by_key(|o| o.iter().filter(|&&c| c != 0).count());
        let capacity = capacity.max(1);
        Self {
            voxel_size_m,
            capacity,
            min_spacing2_m2: voxel_size_m * voxel_size_m / capacity as f64,
            neighbours,
            block_of: HashMap::default(),
            keys: Vec::new(),
            counts: Vec::new(),
            points: Vec::new(),
        }
    }

    pub(super) fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    fn voxel(&self, p: &Vector3<f64>) -> [i32; 3] {
        [0, 1, 2].map(|a| floor(p[a] / self.voxel_size_m))
    }

    pub(super) fn add(
        &mut self,
        points_in_sensor: &[Vector3<f64>],
        world_from_sensor: &Isometry3<f64>,
    ) {
        let c = self.capacity;
        for p in points_in_sensor {
            let p = (world_from_sensor * Point3::from(*p)).coords;
            let (key, new_block) = (pack(self.voxel(&p).map(|v| v as u64)), self.keys.len());
            let block = *self.block_of.entry(key).or_insert(new_block as u32) as usize;
            if block == new_block {
                self.keys.push(key);
                self.counts.push(0);
                self.points.extend(std::iter::repeat_n(p, c));
            }
            let count = self.counts[block] as usize;
            let near = |q: &Vector3<f64>| (q - p).norm_squared() < self.min_spacing2_m2;
            if count < c && !self.points[block * c..block * c + count].iter().any(near) {
                self.points[block * c + count] = p;
                self.counts[block] += 1;
            }
        }
    }

    /// Drops the voxels whose first point is `max_range_m` or more from `centre`.
    pub(super) fn remove_beyond(&mut self, centre: &Vector3<f64>, max_range_m: f64) {
        let (mut block, c) = (0, self.capacity);
        while block < self.keys.len() {
            if (self.points[block * c] - centre).norm() < max_range_m {
                block += 1;
                continue;
            }
            // The last block fills the hole: only its index entry changes.
            let last = self.keys.len() - 1;
            self.block_of.remove(&self.keys[block]);
            if block != last {
                (self.keys[block], self.counts[block]) = (self.keys[last], self.counts[last]);
                self.points.copy_within(last * c..(last + 1) * c, block * c);
                self.block_of.insert(self.keys[block], block as u32);
            }
            self.keys.pop();
            self.counts.pop();
            self.points.truncate(last * c);
        }
    }

    /// The nearest map point in the 27 voxels around `p`, if nearer than `gate_m`,
    /// and a clearance: no other map point is nearer `p` than that.
    pub(super) fn nearest(&self, p: &Vector3<f64>, gate_m: f64) -> (Option<Vector3<f64>>, f64) {
        let (v, base) = (self.voxel_size_m, self.voxel(p));
        // Distances from p to the lower and the upper faces of its voxel.
        let below = p - Vector3::from(base.map(|b| b as f64 * v));
        let above = Vector3::repeat(v) - below;
        // Points outside the 27 voxels are at least this far.
        let reach_m = v + below.min().min(above.min());
        // Pruning by the second nearest, not the nearest, yields the clearance.
        let (mut best2, mut second2, mut best) = (f64::INFINITY, gate_m * gate_m, None);
        for offset in &self.neighbours {
            let gap = |a: usize| [below[a], 0.0, above[a]][(offset[a] + 1) as usize];
            if gap(0).powi(2) + gap(1).powi(2) + gap(2).powi(2) >= second2 {
                continue;
            }
            let voxel = [0, 1, 2].map(|a| base[a].wrapping_add(offset[a]) as u64);
            let Some(&block) = self.block_of.get(&pack(voxel)) else {
                continue;
            };
            let start = block as usize * self.capacity;
            for q in &self.points[start..start + self.counts[block as usize] as usize] {
                let d2 = (q - p).norm_squared();
                if d2 < best2 {
                    (second2, best2, best) = (second2.min(best2), d2, Some(*q));
                } else if d2 < second2 {
                    second2 = d2;
                }
            }
        }
        match best2 < second2 {
            true => (best, second2.sqrt().min(reach_m)),
            false => (None, 0.0),
        }
    }
}
