//! What a child travmap is told to read an input as its parent does (`bench
//! --tools`, the `bench-tools` feature): the parent's own flags, handed on.

use std::ffi::OsString;

use super::{Inputs, Sensors, Settings};

impl Settings {
    /// The flags that give a child travmap this configuration (`bench --tools`).
    fn as_arguments(&self) -> Vec<OsString> {
        let sets = self.sets.iter().map(|set| ("--set", Some(set.into())));
        flags(
            [
                ("--config", self.config.clone().map(OsString::from)),
                ("--poses", self.poses.clone().map(OsString::from)),
            ]
            .into_iter()
            .chain(sets),
        )
    }
}

/// `--flag value` for every flag that has a value.
fn flags<'a>(pairs: impl IntoIterator<Item = (&'a str, Option<OsString>)>) -> Vec<OsString> {
    pairs
        .into_iter()
        .filter_map(|(flag, value)| Some([OsString::from(flag), value?]))
        .flatten()
        .collect()
}

impl Sensors {
    /// The flags that give a child travmap these topics and calibrations.
    fn arguments(&self) -> impl Iterator<Item = (&'static str, Option<OsString>)> + '_ {
        let topics = (self.cloud_topic.iter()).map(|t| ("--cloud-topic", Some(t.into())));
        let calibrations =
            (self.lidar_calibration.iter()).map(|file| ("--lidar-calibration", Some(file.into())));
        let frames = (self.lidar_frame.iter()).map(|frame| ("--lidar-frame", Some(frame.into())));
        topics.chain(calibrations).chain(frames)
    }
}

impl Inputs {
    /// The flags that make a child travmap read the input as this command does
    /// (`bench --tools`).
    pub fn child_flags(&self) -> travmap_bench::ChildFlags {
        travmap_bench::ChildFlags {
            frames: self.frames.clone(),
            sensors: flags(self.sensors.arguments()),
            reading: self.reading_arguments(),
            settings: self.settings.as_arguments(),
        }
    }

    /// The flags that make a child travmap read an input as this command does: the
    /// log's topics and world frame, the scan rate and the configuration; not
    /// `--frames`, which the caller adds where it applies.
    fn reading_arguments(&self) -> Vec<OsString> {
        let mut arguments = flags(self.sensors.arguments().chain([
            (
                "--world-frame",
                self.world_frame.clone().map(OsString::from),
            ),
            (
                "--camera-topic",
                self.camera_topic.clone().map(OsString::from),
            ),
            ("--pose-topic", self.pose_topic.clone().map(OsString::from)),
            ("--rate", self.rate.map(|hz| hz.to_string().into())),
        ]));
        arguments.extend(self.settings.as_arguments());
        arguments
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    /// A command's input arguments, as the command line gives them.
    #[derive(Parser)]
    struct Line {
        #[command(flatten)]
        inputs: Inputs,
    }

    #[test]
    fn a_child_reads_the_input_as_its_parent_does() {
        let line = Line::parse_from([
            "bench",
            "seq",
            "--frames",
            "2..=4",
            "--set",
            "grid.size_m=16",
            "--cloud-topic",
            "/points",
        ]);
        let flags = line.inputs.child_flags();
        let texts = |flags: &[OsString]| -> Vec<String> {
            flags
                .iter()
                .map(|f| f.to_string_lossy().into_owned())
                .collect()
        };
        assert_eq!(flags.frames, Some(2..5));
        assert_eq!(texts(&flags.sensors), ["--cloud-topic", "/points"]);
        assert_eq!(
            texts(&flags.reading),
            ["--cloud-topic", "/points", "--set", "grid.size_m=16"]
        );
        assert_eq!(texts(&flags.settings), ["--set", "grid.size_m=16"]);
    }
}
