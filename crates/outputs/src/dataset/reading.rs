//! Cell datasets read back: the labelled rows of a `travmap dataset` file or folder
//! of part files (or a file rewritten by pyarrow, DuckDB or Polars) into a [`TrainingSet`], after checking
//! that its cells were computed with the same feature settings. Column types are
//! checked before the parquet crate's typed readers (which panic on a mismatch),
//! and panics inside the parquet crate on corrupt files are contained as errors.

use std::path::Path;
use std::sync::Arc;

use parquet::column::reader::ColumnReaderImpl;
use parquet::data_type::DataType;
use parquet::file::reader::{FileReader, RowGroupReader};
use parquet::file::serialized_reader::SerializedFileReader;
use parquet::schema::types::SchemaDescriptor;

use super::{
    CONFIG_KEY, FORMAT, FORMAT_1, FORMAT_KEY, MAX_VALUES_PER_FILE_BYTE, READ_BATCH_ROWS, SCANS_KEY,
    appearance_columns, feature_settings, part_files, schema,
};
use travmap_core::Config;
use travmap_core::config::written_before_groups;
use travmap_core::error::{Error, Result, contain_panics};
use travmap_method::features::feature_names;
use travmap_method::training_set::TrainingSet;

fn read_error(path: &Path, message: impl std::fmt::Display) -> Error {
    Error::Dataset {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// One column of a row group, read a batch of rows at a time so that memory stays
/// the batch's whatever the group declares: the batch's present values, and per row
/// whether it is present.
struct ColumnBatches<T: DataType> {
    reader: ColumnReaderImpl<T>,
    index: usize,
    values: Vec<T::T>,
    levels: Vec<i16>,
    present: Vec<bool>,
}

impl<T: DataType> ColumnBatches<T>
where
    T::T: Default + Clone,
{
    fn open(group: &dyn RowGroupReader, index: usize) -> parquet::errors::Result<Self> {
        let reader = contained(|| {
            Ok(parquet::column::reader::get_typed_column_reader(
                group.get_column_reader(index)?,
            ))
        })?;
        Ok(Self {
            reader,
            index,
            values: Vec::with_capacity(READ_BATCH_ROWS),
            levels: Vec::with_capacity(READ_BATCH_ROWS),
            present: Vec::with_capacity(READ_BATCH_ROWS),
        })
    }

    /// Reads the next `rows` rows (at most [`READ_BATCH_ROWS`]).
    fn read(&mut self, rows: usize) -> parquet::errors::Result<()> {
        let Self {
            reader,
            values,
            levels,
            present,
            ..
        } = self;
        values.clear();
        levels.clear();
        contained(|| {
            let mut read = 0;
            while read < rows {
                let (records, _, _) =
                    reader.read_records(rows - read, Some(&mut *levels), None, &mut *values)?;
                if records == 0 {
                    return Err(parquet::errors::ParquetError::EOF(format!(
                        "{read} of {rows} rows"
                    )));
                }
                read += records;
            }
            Ok(())
        })?;
        // A required column has no levels: every row is present.
        present.clear();
        if levels.is_empty() {
            present.resize(rows, true);
        } else {
            present.extend(levels.iter().map(|&l| l > 0));
        }
        let present_count = present.iter().filter(|&&p| p).count();
        if present.len() != rows || values.len() != present_count {
            return Err(parquet::errors::ParquetError::General(format!(
                "a column of {rows} rows gave {} levels and {} values for {present_count} present rows",
                present.len(),
                values.len()
            )));
        }
        Ok(())
    }

    /// The batch's values of a column that must have a value in every row; `first_row`
    /// is the batch's first row in its row group, for the error.
    fn required(
        &self,
        group: &dyn RowGroupReader,
        first_row: usize,
    ) -> parquet::errors::Result<&[T::T]> {
        match self.present.iter().position(|&p| !p) {
            None => Ok(&self.values),
            Some(row) => Err(parquet::errors::ParquetError::General(format!(
                "column `{}` is null in row {} of its row group; travmap needs a value in every row",
                group.metadata().column(self.index).column_path().string(),
                first_row + row
            ))),
        }
    }
}

/// Runs a call into the parquet crate, which panics on some corrupt input rather
/// than returning an error (apache/arrow-rs#9742): the panic becomes an error.
fn contained<T>(call: impl FnOnce() -> parquet::errors::Result<T>) -> parquet::errors::Result<T> {
    contain_panics(call).unwrap_or_else(|panic| {
        Err(parquet::errors::ParquetError::General(format!(
            "corrupt Parquet file (the parquet reader stopped: {panic})"
        )))
    })
}

/// Which labels a training set takes from a dataset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Labels {
    /// `ground_truth_traversable`: the annotations.
    GroundTruth,
    /// `pseudo_label`: the drive's self-labels (`train --labels pseudo`).
    Pseudo,
}

/// Appends the rows of the dataset at `path` that have `labels` to `set`, after
/// checking that its cells were computed with `config`'s feature settings. Returns
/// the number of rows added.
pub fn read_training_rows(
    path: &Path,
    config: &Config,
    set: &mut TrainingSet,
    labels: Labels,
) -> Result<usize> {
    if path.is_dir() {
        return (part_files(path)?.iter())
            .map(|part| read_training_rows(part, config, set, labels))
            .sum();
    }
    // In memory: the parquet crate reads a `File` with many small unbuffered reads,
    // millions of them on some corrupt page headers (15 s for a 26 kB file). The
    // rows take more memory than the compressed file does anyway.
    let data = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let file_bytes = data.len();
    if !data.starts_with(b"PAR1") {
        return Err(read_error(
            path,
            format!(
                "begins with {:02x?}, not PAR1: not a Parquet file",
                &data[..data.len().min(4)]
            ),
        ));
    }
    let fail = |e: parquet::errors::ParquetError| read_error(path, e);
    let reader = contained(|| SerializedFileReader::new(bytes::Bytes::from(data))).map_err(fail)?;
    let metadata = reader.metadata().file_metadata();
    let value_of = |key: &str| {
        metadata
            .key_value_metadata()
            .and_then(|kv| kv.iter().find(|e| e.key == key))
            .and_then(|e| e.value.clone())
    };
    let self_labels = match value_of(FORMAT_KEY).as_deref() {
        Some(FORMAT) => true,
        Some(FORMAT_1) => false,
        other => {
            return Err(read_error(
                path,
                format!(
                    "not a travmap cell dataset (metadata {FORMAT_KEY} is {other:?}; expected {FORMAT:?})"
                ),
            ));
        }
    };
    if labels == Labels::Pseudo && !self_labels {
        return Err(read_error(
            path,
            format!(
                "a dataset of format {FORMAT_1:?} has no pseudo_label column; extract it again with this travmap"
            ),
        ));
    }
    let written: Config = value_of(CONFIG_KEY)
        .and_then(|json| serde_json::from_str::<serde_json::Value>(&json).ok())
        .and_then(|mut value| {
            written_before_groups(&mut value);
            serde_json::from_value(value).ok()
        })
        .ok_or_else(|| read_error(path, format!("no readable {CONFIG_KEY} metadata")))?;
    let (theirs, ours) = (feature_settings(&written), feature_settings(config));
    if theirs != ours {
        return Err(read_error(
            path,
            format!(
                "extracted with other feature settings: {theirs} (dataset) vs {ours} (now); pass the same --config / --set as for `travmap dataset`"
            ),
        ));
    }
    let feature_columns = feature_names(&config.features.groups);
    let feature_count = feature_columns.len();
    let expected = schema(&feature_columns, &appearance_columns(config), self_labels);
    let expected = parquet::schema::parser::parse_message_type(&expected).expect("schema parses");
    let expected = SchemaDescriptor::new(Arc::new(expected));
    // Name and physical type of every column. Other writers may annotate columns
    // differently or make every column nullable (Polars does); a null where travmap
    // needs a value is caught when the column is read. The typed column readers
    // below panic on a type they were not made for, so this check comes first.
    let layout = |descr: &SchemaDescriptor| -> Vec<String> {
        descr
            .columns()
            .iter()
            .map(|c| {
                let repeated = if c.max_rep_level() > 0 {
                    " (repeated)"
                } else {
                    ""
                };
                format!("{} {}{repeated}", c.name(), c.physical_type())
            })
            .collect()
    };
    let (columns, wanted) = (layout(metadata.schema_descr()), layout(&expected));
    if columns != wanted {
        let first = columns
            .iter()
            .zip(&wanted)
            .position(|(a, b)| a != b)
            .unwrap_or(columns.len().min(wanted.len()));
        return Err(read_error(
            path,
            format!(
                "column {first} is `{}`; expected `{}` ({} columns, expected {})",
                columns.get(first).map_or("(none)", String::as_str),
                wanted.get(first).map_or("(none)", String::as_str),
                columns.len(),
                wanted.len(),
            ),
        ));
    }

    use parquet::data_type::{BoolType, DoubleType, FloatType};
    let label_columns = if self_labels { 4 } else { 2 };
    let appearance_len = wanted.len() - 8 - label_columns - feature_count;
    let truth_column = 8
        + feature_count
        + appearance_len
        + match labels {
            Labels::GroundTruth => 0,
            // After the ground truth, the prediction and the footprint.
            Labels::Pseudo => 3,
        };
    let largest_values = file_bytes.saturating_mul(MAX_VALUES_PER_FILE_BYTE);
    let (mut declared_values, mut added) = (0usize, 0);
    let mut row_features = vec![0.0f32; feature_count];
    let mut row_appearance = vec![0.0f32; appearance_len];
    let mut appearance_next = vec![0usize; appearance_len];
    for g in 0..reader.num_row_groups() {
        let group = contained(|| reader.get_row_group(g)).map_err(fail)?;
        let group = group.as_ref();
        let declared = group.metadata().num_rows();
        declared_values = usize::try_from(declared)
            .ok()
            .and_then(|rows| rows.checked_mul(wanted.len()))
            .and_then(|values| values.checked_add(declared_values))
            .filter(|&values| values <= largest_values)
            .ok_or_else(|| {
                read_error(
                    path,
                    format!(
                        "row group {g} declares {declared} rows: with the groups before it, more than {MAX_VALUES_PER_FILE_BYTE} values per byte of a {file_bytes}-byte file (a damaged row count?)"
                    ),
                )
            })?;
        let rows = declared as usize;
        let open_floats = |columns: std::ops::Range<usize>| {
            columns
                .map(|c| ColumnBatches::<FloatType>::open(group, c))
                .collect::<parquet::errors::Result<Vec<_>>>()
                .map_err(fail)
        };
        let mut x_m = ColumnBatches::<DoubleType>::open(group, 5).map_err(fail)?;
        let mut y_m = ColumnBatches::<DoubleType>::open(group, 6).map_err(fail)?;
        let mut features = open_floats(8..8 + feature_count)?;
        let mut appearance = open_floats(8 + feature_count..8 + feature_count + appearance_len)?;
        let mut truth = ColumnBatches::<BoolType>::open(group, truth_column).map_err(fail)?;
        for first_row in (0..rows).step_by(READ_BATCH_ROWS) {
            let batch = READ_BATCH_ROWS.min(rows - first_row);
            x_m.read(batch).map_err(fail)?;
            y_m.read(batch).map_err(fail)?;
            for column in features.iter_mut().chain(appearance.iter_mut()) {
                column.read(batch).map_err(fail)?;
            }
            truth.read(batch).map_err(fail)?;
            let xs = x_m.required(group, first_row).map_err(fail)?;
            let ys = y_m.required(group, first_row).map_err(fail)?;
            let feature_values = features
                .iter()
                .map(|column| column.required(group, first_row))
                .collect::<parquet::errors::Result<Vec<_>>>()
                .map_err(fail)?;
            appearance_next.fill(0);
            let mut truth_next = 0;
            for row in 0..batch {
                // Optional values are packed over their column's present rows.
                let mut seen = appearance_len > 0;
                for (a, column) in appearance.iter().enumerate() {
                    if column.present[row] {
                        row_appearance[a] = column.values[appearance_next[a]];
                        appearance_next[a] += 1;
                    } else {
                        seen = false;
                    }
                }
                if !truth.present[row] {
                    continue;
                }
                let traversable = truth.values[truth_next];
                truth_next += 1;
                for (value, column) in row_features.iter_mut().zip(&feature_values) {
                    *value = column[row];
                }
                let appearance = seen.then_some(&row_appearance[..]);
                set.push(&row_features, appearance, traversable, [xs[row], ys[row]]);
                added += 1;
            }
        }
    }
    if let Some(scans) =
        value_of(SCANS_KEY).and_then(|json| serde_json::from_str::<Vec<String>>(&json).ok())
    {
        set.frame_sha256.extend(scans);
    }
    set.input_rows.push(set.len() - added..set.len());
    Ok(added)
}
