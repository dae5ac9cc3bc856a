//! A labelling session: the questions, the answers given so far, and the labels file
//! they are saved to after every answer. Reopened on the same drives, model and
//! budget with the same file, it resumes where the person left off.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Serialize;
use travmap_core::Config;
use travmap_core::error::{Error, Result};
use travmap_method::grid::CellClass;
use travmap_outputs::labels::{
    Answer, CellAt, FrameAnswers, LabelsRecord, read_labels, write_labels,
};
use travmap_run::labelling::Questions;

/// Who answers a session's questions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Answerer {
    /// A person, on the page.
    Person,
    /// The drive's own ground truth, as a perfect labeller would (for studies).
    GroundTruth,
}

impl Answerer {
    fn word(self) -> &'static str {
        match self {
            Answerer::Person => "person",
            Answerer::GroundTruth => "ground truth",
        }
    }
}

/// How far a session has come.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Progress {
    /// Cells asked about, and how many of them were answered (labelled or skipped).
    pub asked: usize,
    pub answered: usize,
    pub skipped: usize,
    /// Cells labelled that were not asked about (painted on the page).
    pub painted: usize,
    /// Cells the labels file holds: asked and painted, labelled.
    pub labelled: usize,
}

/// The questions, the answers and where they are kept.
pub struct Session {
    pub questions: Questions,
    path: PathBuf,
    config: Config,
    model: serde_json::Value,
    asked_by: String,
    answerer: Answerer,
    /// Every answer, by (frame of the questions, cell).
    answers: BTreeMap<(usize, usize), Answer>,
    asked: BTreeMap<(usize, usize), usize>,
}

impl Session {
    /// A session over `questions` (asked by `model`, its `--json` record, on the grid
    /// of `config`, `asked_by` naming how) keeping its answers in `path`; what the
    /// file at `path` already holds is read back, and refused when it answers other
    /// questions.
    pub fn open(
        questions: Questions,
        path: &Path,
        config: &Config,
        model: serde_json::Value,
        asked_by: &str,
        answerer: Answerer,
    ) -> Result<Self> {
        let asked = (questions.cells.iter().enumerate())
            .map(|(i, c)| ((c.frame, c.cell), i))
            .collect();
        let mut session = Self {
            questions,
            path: path.to_path_buf(),
            config: config.clone(),
            model,
            asked_by: asked_by.to_string(),
            answerer,
            answers: BTreeMap::new(),
            asked,
        };
        if path.exists() {
            session.resume()?;
        }
        Ok(session)
    }

    /// Reads the answers of the file at `self.path` into the session.
    fn resume(&mut self) -> Result<()> {
        let (answers, record) = read_labels(&self.path)?;
        let refuse = |message: String| Error::Dataset {
            path: self.path.clone(),
            message,
        };
        if record.model.get("sha256") != self.model.get("sha256") {
            return Err(refuse(format!(
                "its answers were asked by another model ({}); give that model (--model) to go on with them, or write to another file (-o)",
                record
                    .model
                    .get("name")
                    .and_then(|n| n.as_str())
                    .unwrap_or("unnamed")
            )));
        }
        for (at, answer) in answers {
            let Some(key) = self.cell_at(&at) else {
                return Err(refuse(format!(
                    "it answers frame {} of {} (row {}, col {}), which this run does not ask about; give the drives, frames and --ask it was made with to go on with it, or write to another file (-o)",
                    at.frame, at.source, at.row, at.col
                )));
            };
            self.answers.insert(key, answer);
        }
        Ok(())
    }

    /// The (frame, cell) of the questions a stored cell is, if any.
    fn cell_at(&self, at: &CellAt) -> Option<(usize, usize)> {
        let frame = self
            .questions
            .frames
            .iter()
            .position(|f| f.source == at.source && f.result.index == at.frame)?;
        let layout = &self.questions.frames[frame].result.layout;
        let side = layout.cells_per_side;
        (at.row < side && at.col < side).then_some((frame, at.row * side + at.col))
    }

    /// Where a (frame, cell) of the questions is in its drive.
    fn at(&self, (frame, cell): (usize, usize)) -> CellAt {
        let asked = &self.questions.frames[frame];
        let (col, row) = asked.result.layout.col_row(cell);
        CellAt {
            source: asked.source.clone(),
            frame: asked.result.index,
            row,
            col,
        }
    }

    /// The answers so far, by (frame, cell).
    pub fn answers(&self) -> &BTreeMap<(usize, usize), Answer> {
        &self.answers
    }

    /// Whether (frame, cell) was asked about, and its place in the order asked.
    pub fn asked(&self, frame: usize, cell: usize) -> Option<usize> {
        self.asked.get(&(frame, cell)).copied()
    }

    /// Records an answer (None: takes one back) about a cell of a frame of the
    /// questions and saves the file; refused for a cell without features (nothing
    /// to learn from) or outside the frames.
    pub fn answer(
        &mut self,
        frame: usize,
        cell: usize,
        answer: Option<Answer>,
    ) -> Result<Progress> {
        let asked = self.questions.frames.get(frame).ok_or_else(|| {
            Error::Config(format!(
                "no frame {frame} among the {} asked about",
                self.questions.frames.len()
            ))
        })?;
        let predictable = asked.result.features.predictable.get(cell).copied();
        if predictable != Some(true) {
            return Err(Error::Config(format!(
                "cell {cell} of frame {frame} holds too few points to have features: nothing to learn from it"
            )));
        }
        match answer {
            Some(Answer::Skip) if self.asked(frame, cell).is_none() => {
                return Err(Error::Config(
                    "only a cell asked about can be skipped".into(),
                ));
            }
            Some(answer) => self.answers.insert((frame, cell), answer),
            None => self.answers.remove(&(frame, cell)),
        };
        self.save()?;
        Ok(self.progress())
    }

    /// Answers every asked cell from the drive's ground truth, as a perfect labeller
    /// would (a cell without ground truth is skipped), and saves the file.
    pub fn answer_from_ground_truth(&mut self) -> Result<Progress> {
        for cell in &self.questions.cells {
            let truth = (self.questions.frames[cell.frame]
                .result
                .ground_truth
                .as_ref())
            .map(|truth| truth[cell.cell]);
            let answer = match truth {
                Some(CellClass::Traversable) => Answer::Traversable,
                Some(CellClass::NonTraversable) => Answer::NotTraversable,
                Some(CellClass::Unknown) | None => Answer::Skip,
            };
            self.answers.insert((cell.frame, cell.cell), answer);
        }
        self.save()?;
        Ok(self.progress())
    }

    pub fn progress(&self) -> Progress {
        let mut progress = Progress {
            asked: self.questions.cells.len(),
            ..Default::default()
        };
        for (&key, answer) in &self.answers {
            let asked = self.asked.contains_key(&key);
            progress.answered += usize::from(asked);
            progress.skipped += usize::from(*answer == Answer::Skip);
            progress.painted += usize::from(!asked);
            progress.labelled += usize::from(answer.label().is_some());
        }
        progress
    }

    /// Writes every answer to the labels file, atomically.
    fn save(&self) -> Result<()> {
        let mut frames: Vec<FrameAnswers> = Vec::new();
        let mut skipped = Vec::new();
        for (&(frame, cell), answer) in &self.answers {
            let Some(label) = answer.label() else {
                skipped.push(self.at((frame, cell)));
                continue;
            };
            let asked = &self.questions.frames[frame];
            match frames.last_mut() {
                Some(last) if std::ptr::eq(last.result, &asked.result) => {
                    last.labels.push((cell, label))
                }
                _ => frames.push(FrameAnswers {
                    source: &asked.source,
                    result: &asked.result,
                    labels: vec![(cell, label)],
                }),
            }
        }
        let record = LabelsRecord {
            answered_by: self.answerer.word().into(),
            asked_by: self.asked_by.clone(),
            model: self.model.clone(),
            asked: (self.questions.cells.iter())
                .map(|c| self.at((c.frame, c.cell)))
                .collect(),
            skipped,
        };
        write_labels(&self.path, &self.config, &self.model, &frames, &record)
    }
}
