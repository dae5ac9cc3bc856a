//! The labels file of `travmap label`: the cells a person answered, as a cell table
//! that `train` reads like any `dataset` file (the same columns; the answer is the
//! cell's `ground_truth_traversable`, the model's call its `predicted_traversable`),
//! and pyarrow, DuckDB and Polars read as they are. What was asked, skipped and by
//! whom is its `travmap.labels` metadata. Rewritten whole, atomically, after every
//! answer: closing the page or a signal loses no answer given.

use std::path::Path;

use parquet::file::reader::{FileReader, SerializedFileReader};
use serde::{Deserialize, Serialize};

use crate::dataset::{DatasetFiles, DatasetWriter};
use travmap_core::Config;
use travmap_core::error::{Error, Result, contain_panics};
use travmap_method::pipeline::FrameResult;

/// The metadata key of what was asked.
const LABELS_KEY: &str = "travmap.labels";

/// A person's answer about one cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Answer {
    Traversable,
    NotTraversable,
    /// Asked, and not answered: the person could not tell.
    Skip,
}

impl Answer {
    /// The label it gives the cell, if any.
    pub fn label(self) -> Option<bool> {
        match self {
            Answer::Traversable => Some(true),
            Answer::NotTraversable => Some(false),
            Answer::Skip => None,
        }
    }
}

/// A cell answered, by where it is in its drive: the input, the frame's number and
/// the cell's row and column on the training grid.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct CellAt {
    pub source: String,
    pub frame: usize,
    pub row: usize,
    pub col: usize,
}

/// What the labels file says of itself (its `travmap.labels` metadata).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LabelsRecord {
    /// `person` (the page) or `ground truth` (`--answers-from-ground-truth`).
    pub answered_by: String,
    /// How the cells were chosen: `margin` (least sure first) or `random`.
    pub asked_by: String,
    /// The model that asked (its name, SHA-256 and rule: `--json`'s `model`).
    pub model: serde_json::Value,
    /// The cells asked about, in the order they were asked.
    pub asked: Vec<CellAt>,
    /// Asked cells the person skipped.
    pub skipped: Vec<CellAt>,
}

/// A frame's answers to write: the frame's result (for the cells' features) and its
/// labelled cells.
pub struct FrameAnswers<'a> {
    pub source: &'a str,
    pub result: &'a FrameResult,
    pub labels: Vec<(usize, bool)>,
}

/// Writes the labels file at `path` (replacing it atomically): every frame's
/// labelled cells, `record` in its metadata, `model` the asking model's record.
pub fn write_labels(
    path: &Path,
    config: &Config,
    model: &serde_json::Value,
    frames: &[FrameAnswers],
    record: &LabelsRecord,
) -> Result<()> {
    let mut writer =
        DatasetWriter::create(path, config, DatasetFiles::File, Some(model.to_string()))?;
    writer.append_metadata(
        LABELS_KEY,
        serde_json::to_string(record).expect("a record serialises"),
    );
    for frame in frames {
        writer.push_labelled(frame.source, frame.result, &frame.labels)?;
    }
    // A file of skips alone still records them: it holds no frame's cells.
    writer.finish_even_empty()?;
    Ok(())
}

/// The answers a labels file holds: each labelled cell with its label, then the
/// skipped ones; and its record. Refused, saying why, when the file is not one
/// `travmap label` wrote.
pub fn read_labels(path: &Path) -> Result<(Vec<(CellAt, Answer)>, LabelsRecord)> {
    let fail = |message: String| Error::Dataset {
        path: path.to_path_buf(),
        message,
    };
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let read = contain_panics(|| -> std::result::Result<_, String> {
        let reader = SerializedFileReader::new(file).map_err(|e| e.to_string())?;
        let metadata = reader.metadata().file_metadata();
        let record = (metadata.key_value_metadata().into_iter().flatten())
            .find(|kv| kv.key == LABELS_KEY)
            .and_then(|kv| kv.value.clone())
            .ok_or_else(|| {
                format!("no {LABELS_KEY} metadata: not a labels file `travmap label` wrote")
            })?;
        let record: LabelsRecord =
            serde_json::from_str(&record).map_err(|e| format!("{LABELS_KEY}: {e}"))?;
        let columns = metadata.schema_descr();
        let index = |name: &str| {
            (0..columns.num_columns())
                .find(|&i| columns.column(i).name() == name)
                .ok_or_else(|| format!("no column {name}"))
        };
        let [source, frame, row, col, truth] =
            ["source", "frame", "row", "col", "ground_truth_traversable"].map(index);
        let (source, frame, row, col, truth) = (source?, frame?, row?, col?, truth?);
        let mut answers = Vec::new();
        for row_read in reader.get_row_iter(None).map_err(|e| e.to_string())? {
            use parquet::record::RowAccessor;
            let values = row_read.map_err(|e| e.to_string())?;
            let at = CellAt {
                source: values
                    .get_string(source)
                    .map_err(|e| e.to_string())?
                    .clone(),
                frame: usize::try_from(values.get_long(frame).map_err(|e| e.to_string())?)
                    .map_err(|e| e.to_string())?,
                row: usize::try_from(values.get_int(row).map_err(|e| e.to_string())?)
                    .map_err(|e| e.to_string())?,
                col: usize::try_from(values.get_int(col).map_err(|e| e.to_string())?)
                    .map_err(|e| e.to_string())?,
            };
            let label = match values.get_bool(truth) {
                Ok(true) => Answer::Traversable,
                Ok(false) => Answer::NotTraversable,
                Err(_) => return Err(format!("a cell without its label: {at:?}")),
            };
            answers.push((at, label));
        }
        answers.extend(record.skipped.iter().map(|at| (at.clone(), Answer::Skip)));
        Ok((answers, record))
    });
    match read {
        Ok(Ok(read)) => Ok(read),
        Ok(Err(message)) | Err(message) => Err(fail(message)),
    }
}
