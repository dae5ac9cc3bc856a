//! How a drive's scans are posed in the world, decided once per source by
//! [`decide`]: by the input's own poses, by scan registration, or each scan alone.
//! Readers say what they record ([`PoseRecord`]); the pipeline's posing stage
//! (`method/pipeline.rs`, stage 0) applies the answer; everything else asks the
//! source for its [`Posing`].

use std::path::Path;

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
