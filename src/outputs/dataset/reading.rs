//! Cell datasets read back: the labelled rows of a `travmap dataset` file (or one
//! rewritten by pyarrow, DuckDB or Polars) into a [`TrainingSet`], after checking
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
    CONFIG_KEY, FORMAT, FORMAT_1, FORMAT_KEY, MAX_READ_GROUP_ROWS, ROW_GROUP_ROWS,
    appearance_columns, feature_settings, schema,
};
use crate::Config;
use crate::config::written_before_groups;
use crate::error::{Error, Result, contain_panics};
use crate::method::features::feature_names;
use crate::training::TrainingSet;

fn read_error(path: &Path, message: impl std::fmt::Display) -> Error {
    Error::Dataset {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// Reads a whole column of a row group: its present values, and per row whether
/// it is present (all true for a required column).
fn read_column<T: DataType>(
    group: &dyn RowGroupReader,
    index: usize,
    rows: usize,
) -> parquet::errors::Result<(Vec<T::T>, Vec<bool>)>
where
    T::T: Default + Clone,
{
    let mut values = Vec::with_capacity(rows.min(ROW_GROUP_ROWS));
    let mut levels = Vec::with_capacity(rows.min(ROW_GROUP_ROWS));
    contained(|| {
        let mut reader: ColumnReaderImpl<T> =
            parquet::column::reader::get_typed_column_reader(group.get_column_reader(index)?);
        let mut read = 0;
        while read < rows {
            let (records, _, _) =
                reader.read_records(rows - read, Some(&mut levels), None, &mut values)?;
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
    let present = if levels.is_empty() {
        vec![true; rows]
    } else {
        levels.iter().map(|&l| l > 0).collect::<Vec<_>>()
    };
    let present_count = present.iter().filter(|&&p| p).count();
    if present.len() != rows || values.len() != present_count {
        return Err(parquet::errors::ParquetError::General(format!(
            "a column of {rows} rows gave {} levels and {} values for {present_count} present rows",
            present.len(),
            values.len()
        )));
    }
    Ok((values, present))
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

/// Reads a whole column of a row group that must have a value in every row.
fn read_required<T: DataType>(
    group: &dyn RowGroupReader,
    index: usize,
    rows: usize,
) -> parquet::errors::Result<Vec<T::T>>
where
    T::T: Default + Clone,
{
    let (values, present) = read_column::<T>(group, index, rows)?;
    match present.iter().position(|&p| !p) {
        None => Ok(values),
        Some(row) => Err(parquet::errors::ParquetError::General(format!(
            "column `{}` is null in row {row} of its row group; travmap needs a value in every row",
            group.metadata().column(index).column_path().string()
        ))),
    }
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
    // In memory: the parquet crate reads a `File` with many small unbuffered reads,
    // millions of them on some corrupt page headers (15 s for a 26 kB file). The
    // rows take more memory than the compressed file does anyway.
    let data = std::fs::read(path).map_err(|e| Error::io(path, e))?;
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
    let mut added = 0;
    for g in 0..reader.num_row_groups() {
        let group = contained(|| reader.get_row_group(g)).map_err(fail)?;
        // Columns are read whole, so a corrupt count must not size them.
        let rows = usize::try_from(group.metadata().num_rows())
            .ok()
            .filter(|&rows| rows <= MAX_READ_GROUP_ROWS)
            .ok_or_else(|| {
                read_error(
                    path,
                    format!(
                        "row group {g} declares {} rows; travmap reads groups of 0 to {MAX_READ_GROUP_ROWS}",
                        group.metadata().num_rows()
                    ),
                )
            })?;
        let x_m = read_required::<DoubleType>(group.as_ref(), 5, rows).map_err(fail)?;
        let y_m = read_required::<DoubleType>(group.as_ref(), 6, rows).map_err(fail)?;
        let mut features = Vec::with_capacity(feature_count);
        for f in 0..feature_count {
            features.push(read_required::<FloatType>(group.as_ref(), 8 + f, rows).map_err(fail)?);
        }
        let mut appearance = Vec::with_capacity(appearance_len);
        let mut seen = vec![true; rows];
        for a in 0..appearance_len {
            let (values, present) =
                read_column::<FloatType>(group.as_ref(), 8 + feature_count + a, rows)
                    .map_err(fail)?;
            // Values are packed over the present rows; spread them back.
            let mut spread = vec![0.0f32; rows];
            let mut next = values.into_iter();
            for (row, &p) in present.iter().enumerate() {
                if p {
                    spread[row] = next.next().unwrap_or_default();
                } else {
                    seen[row] = false;
                }
            }
            appearance.push(spread);
        }
        let truth_column = 8
            + feature_count
            + appearance_len
            + match labels {
                Labels::GroundTruth => 0,
                // After the ground truth, the prediction and the footprint.
                Labels::Pseudo => 3,
            };
        let (truth, labelled) =
            read_column::<BoolType>(group.as_ref(), truth_column, rows).map_err(fail)?;
        let mut truth = truth.into_iter();
        let mut row_features = vec![0.0f32; feature_count];
        let mut row_appearance = vec![0.0f32; appearance_len];
        for row in 0..rows {
            if !labelled[row] {
                continue;
            }
            let traversable = truth.next().unwrap_or_default();
            for (f, column) in features.iter().enumerate() {
                row_features[f] = column[row];
            }
            for (a, column) in appearance.iter().enumerate() {
                row_appearance[a] = column[row];
            }
            let appearance = (seen[row] && appearance_len > 0).then_some(&row_appearance[..]);
            set.push(&row_features, appearance, traversable, [x_m[row], y_m[row]]);
            added += 1;
        }
    }
    Ok(added)
}
