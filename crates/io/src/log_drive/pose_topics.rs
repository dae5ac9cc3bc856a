//! Pose topics: `geometry_msgs/PoseStamped` and `PoseWithCovarianceStamped`, the
//! vehicle's pose in `header.frame_id` as a localisation (`amcl_pose`, Autoware's
//! pose estimators), a motion-capture system (`vrpn_client_node/*/pose`) or PX4
//! (`mavros/local_position/pose`) publishes it. They name no child frame, so the
//! vehicle's frame is taken to be the top of the clouds' chain of fixed mounts
//! (`base_link` above `velodyne` on /tf_static), or the clouds' frame itself when
//! nothing holds it. A frame has one parent: when /tf or an Odometry already moves
//! the clouds, the pose topics are not used. Poses that are no trajectory (a goal,
//! an initial pose) are left out, and several topics are not guessed between, unless
//! `--pose-topic` names one.

use std::collections::BTreeMap;

use nalgebra::Isometry3;

use super::transforms::{TransformError, TransformTree, isometry};
use travmap_formats::log_message::ros2_type_name;
use travmap_formats::ros::{
    MessageEncoding, PoseStamped, PoseWithCovarianceStamped, RosMessage, Transform,
};

pub const POSE_STAMPED: &str = PoseStamped::NAME;
pub const POSE_WITH_COVARIANCE_STAMPED: &str = "geometry_msgs/msg/PoseWithCovarianceStamped";
/// The message types read as the vehicle's pose.
pub const POSE_MESSAGES: [&str; 2] = [POSE_STAMPED, POSE_WITH_COVARIANCE_STAMPED];

/// How far before its first pose and past its last a topic poses clouds (as far as
/// a /tf edge is extrapolated).
const POSE_REACH_NS: u64 = 100_000_000;
/// The longest gap between poses, among the clouds, of a topic that poses them: a
/// goal or an initial pose (RViz's, nav2's) is no trajectory.
const POSE_GAP_NS: u64 = 1_000_000_000;

/// One pose topic's poses.
#[derive(Clone, Debug, Default)]
pub struct PoseTopic {
    /// Its message type (one of [`POSE_MESSAGES`]).
    pub type_name: String,
    /// The frame its poses are given in.
    pub frame: String,
    /// (stamp, frame_from_vehicle).
    pub samples: Vec<(u64, Isometry3<f64>)>,
}

impl PoseTopic {
    /// Adds one message of type `type_name` (one of [`POSE_MESSAGES`]).
    pub fn add(
        &mut self,
        type_name: &str,
        data: &[u8],
        encoding: MessageEncoding,
    ) -> Result<(), String> {
        let (header, pose) = if type_name == POSE_STAMPED {
            let message: PoseStamped = encoding.decode(data)?;
            (message.header, message.pose)
        } else {
            let message: PoseWithCovarianceStamped = encoding.decode(data)?;
            (message.header, message.pose.pose)
        };
        if !self.samples.is_empty() && header.frame_id != self.frame {
            return Err(format!(
                "the poses' frame changes from `{}` to `{}`",
                self.frame, header.frame_id
            ));
        }
        let transform = Transform {
            translation: pose.position,
            rotation: pose.orientation,
        };
        let pose = isometry(&transform).map_err(|e| e.to_string())?;
        self.type_name = type_name.to_string();
        self.frame = header.frame_id;
        self.samples.push((header.stamp.to_ns(), pose));
        Ok(())
    }
}

/// Why nothing recorded poses the clouds in `cloud_frame` (`root_frame` the root of
/// the transform tree above it), as a person reads it.
pub fn unposed(
    cloud_frame: &str,
    root_frame: &str,
    vehicle_poses: &VehiclePoses,
    has_transforms: bool,
) -> String {
    // Transforms, but none above the clouds' frame: often a driver's empty or
    // default frame_id.
    let held = match (root_frame == cloud_frame, cloud_frame.is_empty()) {
        (true, true) => " (the clouds' frame_id is empty: --lidar-frame names the LiDAR's frame)".to_string(),
        (true, false) if has_transforms => " (no transform is above it: --lidar-frame names the LiDAR's frame when the clouds' frame_id is not it)".to_string(),
        (true, false) => String::new(),
        (false, _) => format!(" (the transforms up to `{root_frame}` are fixed mounts)"),
    };
    let why = match vehicle_poses {
        VehiclePoses::Unusable(why) => format!("; {why}"),
        _ => String::new(),
    };
    format!(
        "no recorded pose moves the clouds' frame `{cloud_frame}`{held}: a moving /tf, an Odometry topic or one PoseStamped / PoseWithCovarianceStamped topic must link it to a world frame{why}"
    )
}

/// An error when `named` (`--pose-topic`) is not among the pose topics read,
/// listing the log's (`topics`: each topic's schema name).
pub fn named_pose_topic(
    named: Option<&str>,
    read: &BTreeMap<String, PoseTopic>,
    topics: &BTreeMap<String, String>,
) -> Result<(), String> {
    let Some(named) = named.filter(|topic| !read.contains_key(*topic)) else {
        return Ok(());
    };
    let found: Vec<String> = (topics.iter())
        .filter(|(_, schema)| POSE_MESSAGES.contains(&ros2_type_name(schema).as_ref()))
        .map(|(topic, schema)| format!("{topic} ({schema})"))
        .collect();
    let found = match found.is_empty() {
        true => "none".to_string(),
        false => found.join(", "),
    };
    Err(format!(
        "--pose-topic {named}: no PoseStamped or PoseWithCovarianceStamped topic of that name; the log's pose topics: {found}"
    ))
}

impl PoseTopic {
    /// Why these poses cannot pose clouds stamped `clouds_ns`: they must reach the
    /// first and the last cloud and leave no gap of over a second among them.
    fn unfit_for(&self, clouds_ns: &[u64]) -> Option<String> {
        let mut stamps: Vec<u64> = self.samples.iter().map(|s| s.0).collect();
        stamps.sort_unstable();
        let (Some(&first), Some(&last)) = (stamps.first(), stamps.last()) else {
            return Some("no pose".to_string());
        };
        let (Some(&first_cloud), Some(&last_cloud)) =
            (clouds_ns.iter().min(), clouds_ns.iter().max())
        else {
            return None;
        };
        let seconds = |ns: u64| ns as f64 * 1e-9;
        if first > first_cloud + POSE_REACH_NS || last + POSE_REACH_NS < last_cloud {
            return Some(format!(
                "{} poses from {:.3} to {:.3} s do not reach the clouds' {:.3} to {:.3} s",
                stamps.len(),
                seconds(first),
                seconds(last),
                seconds(first_cloud),
                seconds(last_cloud)
            ));
        }
        let gap = (stamps.windows(2))
            .filter(|pair| pair[1] > first_cloud && pair[0] < last_cloud)
            .map(|pair| pair[1] - pair[0])
            .max()
            .unwrap_or(0);
        (gap > POSE_GAP_NS).then(|| {
            format!(
                "{} poses with a gap of {:.1} s among the clouds (at most 1 s)",
                stamps.len(),
                seconds(gap)
            )
        })
    }
}

/// What the log's pose topics did for its clouds.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum VehiclePoses {
    /// No pose topic, or /tf or an Odometry already moves the clouds.
    #[default]
    NotUsed,
    /// One topic's poses pose the clouds; what the user is told.
    Used(String),
    /// Pose topics that cannot pose the clouds; why.
    Unusable(String),
}

/// Adds the one pose topic of `topics` that poses clouds stamped `clouds_ns` (the
/// one `--pose-topic` named, when `named`) to `transforms` as the edge from its frame
/// to the vehicle's (the root above `cloud_frame`) when no edge above `cloud_frame`
/// moves (see the module documentation); `transforms` is sorted again.
pub fn add_vehicle_poses(
    transforms: &mut TransformTree,
    cloud_frame: &str,
    topics: &BTreeMap<String, PoseTopic>,
    clouds_ns: &[u64],
    named: bool,
) -> Result<VehiclePoses, TransformError> {
    if topics.is_empty() || transforms.moves(cloud_frame)? {
        return Ok(VehiclePoses::NotUsed);
    }
    let (fit, unfit): (Vec<_>, Vec<_>) = (topics.iter())
        .map(|(name, topic)| (name, topic, topic.unfit_for(clouds_ns)))
        .partition(|(.., unfit)| named || unfit.is_none());
    let [(name, topic, _)] = fit[..] else {
        let why: Vec<String> = match fit.is_empty() {
            true => (unfit.iter())
                .map(|(name, _, why)| format!("{name}: {}", why.as_deref().unwrap_or("")))
                .collect(),
            false => vec![format!(
                "{} pose topics ({}): travmap cannot tell which is the vehicle's (--pose-topic to choose)",
                fit.len(),
                (fit.iter().map(|(name, ..)| name.as_str()))
                    .collect::<Vec<_>>()
                    .join(", ")
            )],
        };
        return Ok(VehiclePoses::Unusable(why.join("; ")));
    };
    let vehicle = transforms.root_above(cloud_frame)?;
    if topic.frame.is_empty() || transforms.root_above(&topic.frame)? == vehicle {
        return Ok(VehiclePoses::Unusable(format!(
            "the poses of {name} are given in `{}`, not in a frame above the vehicle's `{vehicle}`",
            topic.frame
        )));
    }
    for (stamp_ns, pose) in &topic.samples {
        transforms.add(&topic.frame, &vehicle, *stamp_ns, *pose, false);
    }
    transforms.sort();
    Ok(VehiclePoses::Used(format!(
        "poses from {name} ({}, {} poses): the pose of `{vehicle}` (the top of the clouds' frame's fixed mounts) in `{}`",
        topic.type_name,
        topic.samples.len(),
        topic.frame
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};
    use travmap_formats::ros::{Header, Pose, Quaternion, Time, Vector3, encode};

    fn pose_stamped(frame: &str, stamp_s: i32, x: f64) -> Vec<u8> {
        encode(
            &PoseStamped {
                header: Header {
                    stamp: Time {
                        sec: stamp_s,
                        nanosec: 0,
                    },
                    frame_id: frame.to_string(),
                },
                pose: Pose {
                    position: Vector3 { x, y: 0.0, z: 0.0 },
                    orientation: Quaternion {
                        x: 0.0,
                        y: 0.0,
                        z: 0.0,
                        w: 1.0,
                    },
                },
            },
            64,
        )
    }

    /// Clouds between the test topics' two poses.
    const CLOUDS_NS: [u64; 2] = [1_100_000_000, 1_900_000_000];

    fn topic(frame: &str) -> PoseTopic {
        let mut topic = PoseTopic::default();
        for (s, x) in [(1, 0.0), (2, 10.0)] {
            let data = pose_stamped(frame, s, x);
            topic
                .add(POSE_STAMPED, &data, MessageEncoding::Cdr)
                .unwrap();
        }
        topic
    }

    fn mounted() -> TransformTree {
        let mut tree = TransformTree::default();
        let mount =
            Isometry3::from_parts(Translation3::new(1.0, 0.0, 2.0), UnitQuaternion::identity());
        tree.add("base_link", "velodyne", 0, mount, true);
        tree.sort();
        tree
    }

    #[test]
    fn a_pose_topic_poses_the_top_of_the_clouds_mounts() {
        let mut tree = mounted();
        let topics = BTreeMap::from([("/pose".to_string(), topic("map"))]);
        let used = add_vehicle_poses(&mut tree, "velodyne", &topics, &CLOUDS_NS, false).unwrap();
        assert!(
            matches!(&used, VehiclePoses::Used(said) if said.contains("`base_link`") && said.contains("`map`")),
            "{used:?}"
        );
        // Halfway between the two poses, plus the mount.
        let pose = tree
            .ancestor_from("map", "velodyne", 1_500_000_000)
            .unwrap()
            .unwrap();
        assert!((pose.translation.vector - nalgebra::Vector3::new(6.0, 0.0, 2.0)).norm() < 1e-12);
    }

    #[test]
    fn recorded_motion_wins_and_ambiguity_is_said() {
        let topics = BTreeMap::from([("/pose".to_string(), topic("map"))]);
        let mut moving = mounted();
        moving.add("odom", "base_link", 0, Isometry3::identity(), false);
        moving.add(
            "odom",
            "base_link",
            1,
            Isometry3::translation(1.0, 0.0, 0.0),
            false,
        );
        moving.sort();
        assert_eq!(
            add_vehicle_poses(&mut moving, "velodyne", &topics, &CLOUDS_NS, false).unwrap(),
            VehiclePoses::NotUsed
        );
        let two = BTreeMap::from([
            ("/a".to_string(), topic("map")),
            ("/b".to_string(), topic("map")),
        ]);
        let said = add_vehicle_poses(&mut mounted(), "velodyne", &two, &CLOUDS_NS, false).unwrap();
        assert!(
            matches!(&said, VehiclePoses::Unusable(why) if why.contains("/a, /b")),
            "{said:?}"
        );
        let own = BTreeMap::from([("/pose".to_string(), topic("velodyne"))]);
        let said = add_vehicle_poses(&mut mounted(), "velodyne", &own, &CLOUDS_NS, false).unwrap();
        assert!(matches!(said, VehiclePoses::Unusable(_)), "{said:?}");
    }

    #[test]
    fn a_goal_or_an_initial_pose_is_no_trajectory() {
        let sparse = |stamps: &[i32]| {
            let mut topic = PoseTopic::default();
            for &s in stamps {
                let data = pose_stamped("map", s, 0.0);
                topic
                    .add(POSE_STAMPED, &data, MessageEncoding::Cdr)
                    .unwrap();
            }
            topic
        };
        // One pose (a goal), and poses 4 s apart around clouds 5 s long.
        let clouds = [2_000_000_000, 7_000_000_000];
        for (stamps, said) in [
            (
                &[3][..],
                "1 poses from 3.000 to 3.000 s do not reach the clouds' 2.000 to 7.000 s",
            ),
            (
                &[1, 5, 9][..],
                "3 poses with a gap of 4.0 s among the clouds",
            ),
        ] {
            let topics = BTreeMap::from([("/goal_pose".to_string(), sparse(stamps))]);
            let unused = add_vehicle_poses(&mut mounted(), "velodyne", &topics, &clouds, false);
            assert!(
                matches!(&unused, Ok(VehiclePoses::Unusable(why)) if why.contains(said) && why.starts_with("/goal_pose: ")),
                "{unused:?}"
            );
            // Named, it is used all the same.
            let named = add_vehicle_poses(&mut mounted(), "velodyne", &topics, &clouds, true);
            assert!(matches!(named, Ok(VehiclePoses::Used(_))), "{named:?}");
        }
        // Beside a trajectory, a goal does not make the choice ambiguous.
        let topics = BTreeMap::from([
            ("/goal_pose".to_string(), sparse(&[3])),
            ("/pose".to_string(), sparse(&[1, 2, 3, 4, 5, 6, 7, 8])),
        ]);
        let used = add_vehicle_poses(&mut mounted(), "velodyne", &topics, &clouds, false);
        assert!(
            matches!(&used, Ok(VehiclePoses::Used(said)) if said.starts_with("poses from /pose")),
            "{used:?}"
        );
    }

    #[test]
    fn poses_written_by_rosbags_rs_read() {
        // The fuzz seeds: messages of the shared all-types MCAP (rosbags-rs).
        let seeds = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
            .join("fuzz/seeds/ros_tf");
        for (file, type_name) in [
            ("rosbags_pose_stamped.cdr", POSE_STAMPED),
            (
                "rosbags_pose_with_covariance_stamped.cdr",
                POSE_WITH_COVARIANCE_STAMPED,
            ),
        ] {
            let data = std::fs::read(seeds.join(file)).unwrap();
            let mut topic = PoseTopic::default();
            topic.add(type_name, &data, MessageEncoding::Cdr).unwrap();
            assert_eq!(topic.frame, "test_frame");
            let (stamp_ns, pose) = topic.samples[0];
            assert_eq!(stamp_ns / 1_000_000_000, 1_749_315_324, "{file}");
            assert_eq!(
                pose.translation.vector,
                nalgebra::Vector3::new(1.0, 2.0, 3.0)
            );
        }
    }

    #[test]
    fn a_topic_whose_frame_changes_is_refused() {
        let mut topic = topic("map");
        let data = pose_stamped("odom", 3, 0.0);
        let error = topic
            .add(POSE_STAMPED, &data, MessageEncoding::Cdr)
            .unwrap_err();
        assert!(error.contains("`map` to `odom`"), "{error}");
    }
}
