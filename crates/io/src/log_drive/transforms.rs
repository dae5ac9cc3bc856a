//! The transform tree of a drive: `/tf`, `/tf_static`, Odometry and pose-topic
//! samples per edge, each edge interpolated at a stamp (linear, slerp) and composed
//! up the tree.
//! ROS names frames child -> parent; a pose here is `parent_from_child`.

use std::collections::HashMap;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

pub use travmap_core::error::TransformError;
use travmap_formats::ros::Transform;

/// A transform sample is used up to this far past either end of its edge's record.
const EXTRAPOLATION_NS: u64 = 100_000_000;

/// More frames than any real transform tree stacks: a longer chain is a cycle.
const MAX_DEPTH: usize = 64;

/// Parent and transform samples of one frame in the transform tree.
#[derive(Clone, Debug, Default)]
struct Edge {
    parent: String,
    /// (stamp, parent_from_child), sorted by stamp; one sample for static edges.
    samples: Vec<(u64, Isometry3<f64>)>,
    is_static: bool,
    /// Recorded more than once and always the same: a fixed mount re-published on
    /// /tf (ROS 1's `static_transform_publisher`, Foxglove loggers, nuScenes'
    /// MCAPs), held past either end of its record as a static one is.
    constant: bool,
}

/// Every edge of a drive's tree, by child frame.
#[derive(Clone, Debug, Default)]
pub struct TransformTree {
    edges: HashMap<String, Edge>,
}

impl TransformTree {
    /// Adds `parent_from_child` at `stamp_ns`; call [`Self::sort`] once all are in.
    pub fn add(
        &mut self,
        parent: &str,
        child: &str,
        stamp_ns: u64,
        pose: Isometry3<f64>,
        is_static: bool,
    ) {
        let edge = self.edges.entry(child.to_string()).or_default();
        edge.parent = parent.to_string();
        edge.is_static = is_static;
        edge.samples.push((stamp_ns, pose));
    }

    /// Every frame that has a parent.
    pub fn children(&self) -> impl Iterator<Item = &str> + Clone {
        self.edges.keys().map(String::as_str)
    }

    /// Orders every edge's samples by stamp.
    pub fn sort(&mut self) {
        for edge in self.edges.values_mut() {
            edge.samples.sort_by_key(|s| s.0);
            edge.constant = edge.samples.len() > 1
                && (edge.samples.windows(2)).all(|pair| pair[0].1 == pair[1].1);
        }
    }

    /// The root of the tree above `frame` (`frame` itself when it has no parent).
    pub fn root_above(&self, frame: &str) -> Result<String, TransformError> {
        let mut current = frame;
        for _ in 0..=MAX_DEPTH {
            match self.edges.get(current) {
                Some(edge) => current = &edge.parent,
                None => return Ok(current.to_string()),
            }
        }
        Err(TransformError::Cycle {
            frame: frame.to_string(),
        })
    }

    /// Whether an edge on the way up from `frame` moves: one that is neither static
    /// nor recorded the same every time.
    pub fn moves(&self, frame: &str) -> Result<bool, TransformError> {
        let mut current = frame;
        for _ in 0..=MAX_DEPTH {
            match self.edges.get(current) {
                Some(edge) if !(edge.is_static || edge.constant) => return Ok(true),
                Some(edge) => current = &edge.parent,
                None => return Ok(false),
            }
        }
        Err(TransformError::Cycle {
            frame: frame.to_string(),
        })
    }

    /// The frame just below `ancestor` on the way up from `frame`; None when
    /// `ancestor` is not above `frame`.
    pub fn child_below(&self, ancestor: &str, frame: &str) -> Option<String> {
        let mut current = frame;
        for _ in 0..=MAX_DEPTH {
            let edge = self.edges.get(current)?;
            if edge.parent == ancestor {
                return Some(current.to_string());
            }
            current = &edge.parent;
        }
        None
    }

    /// `ancestor_from_frame` at `stamp_ns`, composed up the tree; None when
    /// `ancestor` is not above `frame`.
    pub fn ancestor_from(
        &self,
        ancestor: &str,
        frame: &str,
        stamp_ns: u64,
    ) -> Result<Option<Isometry3<f64>>, TransformError> {
        let mut current = frame;
        let mut pose = Isometry3::identity();
        for _ in 0..=MAX_DEPTH {
            if current == ancestor {
                return Ok(Some(pose));
            }
            let Some(edge) = self.edges.get(current) else {
                return Ok(None);
            };
            pose = edge_at(current, edge, stamp_ns)? * pose;
            current = &edge.parent;
        }
        Err(TransformError::Cycle {
            frame: frame.to_string(),
        })
    }
}

/// `parent_from_child` of one edge at `stamp_ns`: the sample at that stamp, or
/// interpolated between the two around it (linear, slerp).
fn edge_at(child: &str, edge: &Edge, stamp_ns: u64) -> Result<Isometry3<f64>, TransformError> {
    let samples = &edge.samples;
    let held = edge.is_static || edge.constant;
    if (held || samples.len() == 1)
        && let Some((t, pose)) = samples.first()
        && (held || t.abs_diff(stamp_ns) <= EXTRAPOLATION_NS)
    {
        return Ok(*pose);
    }
    let after = samples.partition_point(|s| s.0 < stamp_ns);
    if let Some(&(t, pose)) = samples.get(after)
        && t == stamp_ns
    {
        return Ok(pose);
    }
    match (after.checked_sub(1).map(|i| samples[i]), samples.get(after)) {
        (Some((t0, p0)), Some(&(t1, p1))) => {
            let s = (stamp_ns - t0) as f64 / (t1 - t0) as f64;
            Ok(p0.lerp_slerp(&p1, s))
        }
        (Some((t0, p0)), None) if stamp_ns - t0 <= EXTRAPOLATION_NS => Ok(p0),
        (None, Some(&(t1, p1))) if t1 - stamp_ns <= EXTRAPOLATION_NS => Ok(p1),
        _ => Err(TransformError::NoSample {
            parent: edge.parent.clone(),
            child: child.to_string(),
            stamp_ns,
            first_ns: samples.first().map_or(0, |s| s.0),
            last_ns: samples.last().map_or(0, |s| s.0),
        }),
    }
}

/// The rigid pose of a ROS transform; an error for non-finite values or a
/// quaternion too short to normalise, which would turn every point into NaN.
pub fn isometry(t: &Transform) -> Result<Isometry3<f64>, TransformError> {
    let (p, r) = (&t.translation, &t.rotation);
    let q = Quaternion::new(r.w, r.x, r.y, r.z);
    let finite = [p.x, p.y, p.z, r.w, r.x, r.y, r.z]
        .iter()
        .all(|v| v.is_finite());
    if !finite || q.norm() < 1e-6 {
        return Err(TransformError::NotRigid {
            x: p.x,
            y: p.y,
            z: p.z,
            qw: r.w,
            qx: r.x,
            qy: r.y,
            qz: r.z,
        });
    }
    // Unit quaternions as written (travmap's own) are used as they are, so that a
    // converted KITTI pose comes back bit-identical.
    let rotation = if (q.norm() - 1.0).abs() < 1e-12 {
        UnitQuaternion::new_unchecked(q)
    } else {
        UnitQuaternion::new_normalize(q)
    };
    Ok(Isometry3::from_parts(
        Translation3::new(p.x, p.y, p.z),
        rotation,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    const SECOND_NS: u64 = 1_000_000_000;

    fn moved(x: f64) -> Isometry3<f64> {
        Isometry3::translation(x, 0.0, 0.0)
    }

    fn tree(samples: &[(u64, f64)]) -> TransformTree {
        let mut tree = TransformTree::default();
        for &(stamp_ns, x) in samples {
            tree.add("base_link", "lidar", stamp_ns, moved(x), false);
        }
        tree.sort();
        tree
    }

    fn x_at(tree: &TransformTree, stamp_ns: u64) -> Result<f64, TransformError> {
        let pose = tree.ancestor_from("base_link", "lidar", stamp_ns)?.unwrap();
        Ok(pose.translation.x)
    }

    #[test]
    fn a_moving_edge_is_interpolated_and_not_extrapolated_past_100_ms() {
        let tree = tree(&[(SECOND_NS, 1.0), (2 * SECOND_NS, 3.0)]);
        assert_eq!(x_at(&tree, SECOND_NS + SECOND_NS / 4).unwrap(), 1.5);
        assert_eq!(x_at(&tree, 2 * SECOND_NS + SECOND_NS / 20).unwrap(), 3.0);
        let late = x_at(&tree, 3 * SECOND_NS).unwrap_err();
        assert!(matches!(late, TransformError::NoSample { .. }), "{late}");
        // One sample: only near it.
        let once = self::tree(&[(SECOND_NS, 1.0)]);
        assert_eq!(x_at(&once, SECOND_NS + SECOND_NS / 20).unwrap(), 1.0);
        assert!(x_at(&once, 2 * SECOND_NS).is_err());
    }

    #[test]
    fn an_edge_recorded_the_same_every_time_is_held_as_a_static_one() {
        // A mount published on /tf at keyframes (nuScenes, every 0.5 s): clouds
        // before the first and after the last keep it.
        let tree = tree(&[(SECOND_NS, 2.0), (SECOND_NS + SECOND_NS / 2, 2.0)]);
        for stamp_ns in [0, SECOND_NS, 5 * SECOND_NS] {
            assert_eq!(x_at(&tree, stamp_ns).unwrap(), 2.0);
        }
        let mut on_tf_static = TransformTree::default();
        on_tf_static.add("base_link", "lidar", SECOND_NS, moved(2.0), true);
        on_tf_static.sort();
        assert_eq!(x_at(&on_tf_static, 9 * SECOND_NS).unwrap(), 2.0);
    }
}
