//! Values given per LiDAR topic on the command line: `--lidar-calibration` (files)
//! and `--lidar-frame` (frame names), each `TOPIC=VALUE` for one topic, or a
//! `VALUE` alone for every LiDAR topic without its own.

use std::path::{Path, PathBuf};

/// Values for LiDAR topics: each for one topic, or one for every topic without its
/// own.
#[derive(Clone, Debug, Default)]
pub struct ByTopic<V> {
    pub any_topic: Option<V>,
    pub by_topic: Vec<(String, V)>,
}

/// `--lidar-calibration`: packet topics' calibration files.
pub type LidarCalibrations = ByTopic<PathBuf>;

/// `--lidar-frame`: the frame a cloud or packet topic's points are in, for logs
/// whose clouds name none, or the wrong one (the `frame_id` a driver left empty or
/// at its default), and for packets, which name none (an Ouster's, a capture's).
pub type LidarFrames = ByTopic<String>;

impl<V: Clone> ByTopic<V> {
    /// A flag's values, each `TOPIC=VALUE` or `VALUE` (`what`: the noun and the
    /// placeholder, "frame" and "FRAME"), at most one of each topic and one without.
    /// A value for which `whole` holds is never split at its `=`.
    fn parse(
        values: &[String],
        (what, placeholder): (&str, &str),
        whole: impl Fn(&str) -> bool,
    ) -> Result<Self, String>
    where
        V: for<'a> From<&'a str>,
    {
        let mut parsed = Self {
            any_topic: None,
            by_topic: Vec::new(),
        };
        for argument in values {
            match (!whole(argument))
                .then(|| argument.split_once('='))
                .flatten()
            {
                Some((topic, named)) => {
                    if parsed.by_topic.iter().any(|(t, _)| t == topic) {
                        return Err(format!("two {what}s for {topic}"));
                    }
                    parsed.by_topic.push((topic.into(), V::from(named)));
                }
                None if parsed.any_topic.is_some() => {
                    return Err(format!(
                        "two {what}s without a topic: give them as TOPIC={placeholder}"
                    ));
                }
                None => parsed.any_topic = Some(V::from(argument.as_str())),
            }
        }
        Ok(parsed)
    }

    /// The value for LiDAR topic `topic`: its own, else the one for every topic.
    pub fn for_topic(&self, topic: &str) -> Option<&V> {
        (self.by_topic.iter())
            .find(|(t, _)| t == topic)
            .map(|(_, value)| value)
            .or(self.any_topic.as_ref())
    }
}

impl LidarCalibrations {
    /// `--lidar-calibration`'s values: `FILE` or `TOPIC=FILE`.
    pub fn from_arguments(values: &[String]) -> Result<Self, String> {
        // A file whose name holds `=` is still a file.
        let exists = |value: &str| Path::new(value).exists();
        let what = ("calibration file", "FILE");
        ByTopic::parse(values, what, exists)
    }

    /// Every calibration file named: inputs that no output may replace.
    pub fn files(&self) -> impl Iterator<Item = &Path> {
        let by_topic = self.by_topic.iter().map(|(_, file)| file.as_path());
        self.any_topic.as_deref().into_iter().chain(by_topic)
    }
}

impl LidarFrames {
    /// `--lidar-frame`'s values: `FRAME` or `TOPIC=FRAME` (a frame id holds no `=`).
    pub fn from_arguments(values: &[String]) -> Result<Self, String> {
        let frames = ByTopic::parse(values, ("frame", "FRAME"), |_| false)?;
        let empty = (frames.any_topic.iter()).chain(frames.by_topic.iter().map(|(_, f)| f));
        match empty.into_iter().any(String::is_empty) {
            true => Err("an empty frame: name the frame the points are in".into()),
            false => Ok(frames),
        }
    }

    /// The frame given for each of `topics` (the LiDAR topics read, in order); an
    /// error when a topic named is not among them. A FRAME alone may place one of
    /// them only: two sensors in one frame would be
    /// merged as if mounted in one place.
    pub fn frames_for(&self, topics: &[&str]) -> Result<Vec<Option<String>>, String> {
        if let Some((topic, _)) =
            (self.by_topic.iter()).find(|(t, _)| !topics.contains(&t.as_str()))
        {
            return Err(format!(
                "--lidar-frame {topic}=...: {topic} is not a LiDAR topic being read (those are {}; --cloud-topic chooses them)",
                topics.join(", ")
            ));
        }
        let frames = topics.iter().map(|t| self.for_topic(t).cloned()).collect();
        let own = |topic: &&str| self.by_topic.iter().any(|(t, _)| t == topic);
        let shared: Vec<&str> = topics.iter().filter(|t| !own(t)).copied().collect();
        match (&self.any_topic, shared.as_slice()) {
            (Some(frame), [_, _, ..]) => Err(format!(
                "--lidar-frame {frame} would place {} LiDAR topics ({}) in one frame: give each its own as TOPIC=FRAME",
                shared.len(),
                shared.join(", ")
            )),
            _ => Ok(frames),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn calibration_files_are_for_their_topic_or_for_every_topic() {
        let values = [
            "/rear/packets=rear.yaml",
            "any.yaml",
            "/top/packets=a=b.csv",
        ];
        let calibrations = LidarCalibrations::from_arguments(&values.map(String::from)).unwrap();
        let file = |topic| calibrations.for_topic(topic).map(PathBuf::as_path);
        assert_eq!(file("/rear/packets"), Some(Path::new("rear.yaml")));
        assert_eq!(file("/top/packets"), Some(Path::new("a=b.csv")));
        assert_eq!(file("/front/packets"), Some(Path::new("any.yaml")));
        assert_eq!(
            LidarCalibrations::default().for_topic("/front/packets"),
            None
        );
        let twice = ["a.yaml", "b.yaml"].map(String::from);
        let err = LidarCalibrations::from_arguments(&twice).unwrap_err();
        assert!(
            err.contains("two calibration files without a topic: give them as TOPIC=FILE"),
            "{err}"
        );
        let twice = ["/a=a.yaml", "/a=b.yaml"].map(String::from);
        let err = LidarCalibrations::from_arguments(&twice).unwrap_err();
        assert!(err.contains("two calibration files for /a"), "{err}");
    }

    #[test]
    fn frames_are_for_the_topics_read_and_name_no_other() {
        let values = ["velodyne", "/rear_points=rear"].map(String::from);
        let frames = LidarFrames::from_arguments(&values).unwrap();
        let read = frames.frames_for(&["/points", "/rear_points"]);
        assert_eq!(
            read.unwrap(),
            [Some("velodyne".to_string()), Some("rear".to_string())]
        );
        let err = frames.frames_for(&["/points"]).unwrap_err();
        assert!(
            err.contains("/rear_points is not a LiDAR topic being read (those are /points;"),
            "{err}"
        );
        let err = (frames.frames_for(&["/points", "/rear_points", "/top"])).unwrap_err();
        assert!(
            err.contains(
                "--lidar-frame velodyne would place 2 LiDAR topics (/points, /top) in one frame"
            ),
            "{err}"
        );
        assert_eq!(
            LidarFrames::default().frames_for(&["/points"]).unwrap(),
            [None]
        );
        for bad in [&["a", "b"][..], &["/p="], &[""]] {
            let bad: Vec<String> = bad.iter().map(|s| s.to_string()).collect();
            assert!(LidarFrames::from_arguments(&bad).is_err(), "{bad:?}");
        }
    }
}
