//! `--lidar-calibration`: the calibration files given for packet topics.

use std::path::{Path, PathBuf};

/// The calibration files given for packet topics: each for one topic, or one for
/// every packet topic without its own.
#[derive(Clone, Debug, Default)]
pub struct LidarCalibrations {
    pub any_topic: Option<PathBuf>,
    pub by_topic: Vec<(String, PathBuf)>,
}

impl LidarCalibrations {
    /// `--lidar-calibration`'s values: `FILE` or `TOPIC=FILE`; at most one of each
    /// topic and one without.
    pub fn from_arguments(values: &[String]) -> Result<Self, String> {
        let mut calibrations = Self::default();
        for value in values {
            // A file whose name holds `=` is still a file.
            let named = (!Path::new(value).exists())
                .then(|| value.split_once('='))
                .flatten();
            match named {
                Some((topic, file)) => {
                    if calibrations.by_topic.iter().any(|(t, _)| t == topic) {
                        return Err(format!("two calibration files for {topic}"));
                    }
                    calibrations.by_topic.push((topic.into(), file.into()));
                }
                None if calibrations.any_topic.is_some() => {
                    return Err(
                        "two calibration files without a topic: give them as TOPIC=FILE".into(),
                    );
                }
                None => calibrations.any_topic = Some(value.into()),
            }
        }
        Ok(calibrations)
    }

    /// The file for packet topic `topic`: its own, else the one for every topic.
    pub fn for_topic(&self, topic: &str) -> Option<&Path> {
        (self.by_topic.iter())
            .find(|(t, _)| t == topic)
            .map(|(_, file)| file.as_path())
            .or(self.any_topic.as_deref())
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
        assert_eq!(
            calibrations.for_topic("/rear/packets"),
            Some(Path::new("rear.yaml"))
        );
        assert_eq!(
            calibrations.for_topic("/top/packets"),
            Some(Path::new("a=b.csv"))
        );
        assert_eq!(
            calibrations.for_topic("/front/packets"),
            Some(Path::new("any.yaml"))
        );
        assert_eq!(
            LidarCalibrations::default().for_topic("/front/packets"),
            None
        );
        let twice = ["a.yaml", "b.yaml"].map(String::from);
        let err = LidarCalibrations::from_arguments(&twice).unwrap_err();
        assert!(err.contains("give them as TOPIC=FILE"), "{err}");
        let twice = ["/a=a.yaml", "/a=b.yaml"].map(String::from);
        let err = LidarCalibrations::from_arguments(&twice).unwrap_err();
        assert!(err.contains("two calibration files for /a"), "{err}");
    }
}
