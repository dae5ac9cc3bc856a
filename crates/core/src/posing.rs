//! How a drive's scans are posed in the world, decided once per source by
//! [`decide`]: by the input's own poses, by scan registration, or each scan alone.
//! Readers say what they record ([`PoseRecord`]); the pipeline's posing stage
//! (`method/pipeline.rs`, stage 0) applies the answer; everything else asks the
//! source for its [`Posing`].

use std::path::Path;

use nalgebra::{Isometry3, Translation3};

use crate::config::PoseSource;
use crate::error::{Error, Result};

/// How a source's scans are posed in the world.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Posing {
    /// By the input's own poses (`poses.txt`, /tf, Odometry).
    Recorded,
    /// By the method's registration stage, scan after scan.
    Registration,
    /// Not at all: each scan alone in its own frame (an integration window of one).
    Alone,
}

impl Posing {
    /// As a person reads it (the `poses` metadata of annotated files).
    pub fn describe(self) -> &'static str {
        match self {
            Posing::Recorded => "recorded",
            Posing::Registration => "estimated by scan registration",
            Posing::Alone => "none: each scan alone",
        }
    }
}

/// The frame the method keeps a drive in: the world moved so that the drive's first
/// recorded pose is at its origin (no rotation). Coordinates in it stay as small as
/// the drive is long, so the method's f32 points and its sums of squares keep their
/// precision however far the world's origin lies (UTM, a national grid, an MGRS
/// square), and the cell lattice, anchored at this origin, moves with the drive: the
/// same drive moved by any distance maps to the same cells. Every output gives the
/// world's coordinates.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DriveFrame {
    /// The drive frame's origin in the world, metres.
    pub origin_in_world: [f64; 3],
}

impl DriveFrame {
    /// The drive frame whose origin is at `origin_in_world`.
    pub fn at(origin_in_world: [f64; 3]) -> Self {
        Self { origin_in_world }
    }

    /// `drive_from_x` of a `world_from_x`.
    pub fn from_world(&self, world_from_x: &Isometry3<f64>) -> Isometry3<f64> {
        let [x, y, z] = self.origin_in_world;
        Translation3::new(-x, -y, -z) * world_from_x
    }

    /// `world_from_x` of a `drive_from_x`.
    pub fn to_world(&self, drive_from_x: &Isometry3<f64>) -> Isometry3<f64> {
        let [x, y, z] = self.origin_in_world;
        Translation3::new(x, y, z) * drive_from_x
    }

    /// A point of the drive frame in the world.
    pub fn point_in_world(&self, point_in_drive: [f64; 3]) -> [f64; 3] {
        let o = self.origin_in_world;
        [
            o[0] + point_in_drive[0],
            o[1] + point_in_drive[1],
            o[2] + point_in_drive[2],
        ]
    }
}

/// What a source records to pose its scans.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PoseRecord {
    /// Poses that reach the scans' frame.
    Reaches,
    /// None that reach them; why, as a person reads it.
    Missing(String),
}

/// A source's posing and what the user is told about it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Decision {
    pub posing: Posing,
    /// Said when the poses are not what the user would assume (`auto` fell back to
    /// registration).
    pub notice: Option<String>,
}

/// The one rule from `--poses` and what the source at `path` records to its posing:
/// `registration` and `none` are taken as asked; the recorded poses where they
/// reach the scans; `auto` without them falls back to registration with a notice,
/// `tf` / `odometry` without them are refused.
pub fn decide(path: &Path, requested: PoseSource, record: &PoseRecord) -> Result<Decision> {
    let posing = match (requested, record) {
        (PoseSource::Registration, _) => Posing::Registration,
        (PoseSource::None, _) => Posing::Alone,
        (_, PoseRecord::Reaches) => Posing::Recorded,
        (PoseSource::Auto, PoseRecord::Missing(why)) => {
            return Ok(Decision {
                posing: Posing::Registration,
                notice: Some(format!(
                    "{}: {why}: poses estimated by scan registration (--poses to choose)",
                    path.display()
                )),
            });
        }
        (requested, PoseRecord::Missing(why)) => {
            return Err(Error::NoPose {
                path: path.to_path_buf(),
                requested: requested.name(),
                why: why.clone(),
            });
        }
    };
    Ok(Decision {
        posing,
        notice: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_request_meets_every_record_once() {
        let path = Path::new("drive");
        let missing = PoseRecord::Missing("no poses here".into());
        let posing = |requested, record: &PoseRecord| {
            decide(path, requested, record).map(|d| (d.posing, d.notice.is_some()))
        };
        for record in [&PoseRecord::Reaches, &missing] {
            assert_eq!(
                posing(PoseSource::Registration, record).unwrap(),
                (Posing::Registration, false)
            );
            assert_eq!(
                posing(PoseSource::None, record).unwrap(),
                (Posing::Alone, false)
            );
        }
        for requested in [PoseSource::Auto, PoseSource::Tf, PoseSource::Odometry] {
            assert_eq!(
                posing(requested, &PoseRecord::Reaches).unwrap(),
                (Posing::Recorded, false)
            );
        }
        assert_eq!(
            posing(PoseSource::Auto, &missing).unwrap(),
            (Posing::Registration, true)
        );
        let refusal = decide(path, PoseSource::Tf, &missing)
            .unwrap_err()
            .to_string();
        assert!(
            refusal.contains("--poses tf: no poses here")
                && refusal.contains("--poses registration"),
            "{refusal}"
        );
    }
}
