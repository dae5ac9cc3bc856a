//! Datasets: one Parquet row per predictable cell per frame, with every feature,
//! the ground truth and the prediction, for training across many logs and for
//! analysis in pyarrow, DuckDB or Polars; [`reading`] reads the labelled cells
//! back into a training set.
//!
//! Columns, in order (docs/guide.md "Parquet cell tables" lists them with units):
//! `source`, `frame`, `stamp_ns`, `row`, `col`, `x_m`, `y_m`, `points`, the 20
//! geometric features by name (float), the appearance values `hue_0..`,
//! `saturation_0..`, `value_0..` (float, null where no camera ever saw the cell),
//! `ground_truth_traversable` and `predicted_traversable` (boolean, null without
//! labels / without a model), `footprint` (boolean: the vehicle drove over the cell)
//! and `pseudo_label` (boolean, null where the drive says nothing: the self-label of
//! adaptation, `method/self_labels.rs`). The key-value metadata `travmap.config`
//! holds the configuration the rows were computed with, as JSON; reading checks it.
//! Files of format 1 (before the last two columns) are read too.

mod columns;
pub mod reading;

use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use parquet::basic::{Compression, ZstdLevel};
use parquet::data_type::ByteArray;
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::types::ColumnPath;

use columns::{RowGroupColumns, write_column};

use crate::atomic::{
    AtomicFile, WritebackFile, parquet_failure, sync_output, write_atomically, write_failure,
};
use travmap_core::Config;
use travmap_core::config::FeatureGroup;
use travmap_core::error::{Error, Result};
use travmap_io::{Skip, nothing_read};
use travmap_method::features::feature_names;
use travmap_method::grid::CellClass;
use travmap_method::pipeline::FrameResult;

/// Rows per row group: about 18 MB of columns in memory at a time (four frames of
/// the 36 m training grid). 2^17 rows peaked 55 MB higher on 60 frames; smaller
/// groups cost memory too, as the writer keeps every group's metadata for the
/// footer (docs/speed.md: memory).
const ROW_GROUP_ROWS: usize = 1 << 15;
/// The columns written with a dictionary: those with few distinct values per row
/// group. The features, almost all distinct, fit the writer's dictionary whole
/// (1 MB a column chunk), which then doubled their size: without it, the shipped
/// drive's 60-frame file is 26 % smaller (69.6 -> 51.1 MB) and written in 0.88x the
/// time (docs/guide.md "Parquet cell tables").
const DICTIONARY_COLUMNS: [&str; 6] = ["source", "frame", "stamp_ns", "row", "col", "points"];
/// Rows read back per batch, from each column of a row group at once: memory stays
/// this small whatever size of group a writer chose (pyarrow's are 2^20 rows).
const READ_BATCH_ROWS: usize = 1 << 13;
/// The most values (rows x columns) a dataset may declare per byte of file. Real
/// cell tables hold about one (1.6 in travmap's zstd file of the shipped drive); run-length
/// encoding lets a damaged or made-up file declare billions of rows in a few bytes,
/// which must not fill memory or run for hours.
const MAX_VALUES_PER_FILE_BYTE: usize = 1 << 10;

const CONFIG_KEY: &str = "travmap.config";
/// Metadata: the SHA-256 of the labelled scans, a JSON list (absent when unknown).
const SCANS_KEY: &str = "travmap.labelled_scans";
const FORMAT_KEY: &str = "travmap.format";
/// The model whose predictions the file holds (`model` in `--json`): name, SHA-256, rule.
const MODEL_KEY: &str = "travmap.model";
const FORMAT: &str = "travmap-cells 2";
/// The format before `footprint` and `pseudo_label`, still read.
const FORMAT_1: &str = "travmap-cells 1";
/// Columns format 2 added after `predicted_traversable`.
const SELF_LABEL_COLUMNS: [&str; 2] = [
    "REQUIRED BOOLEAN footprint",
    "OPTIONAL BOOLEAN pseudo_label",
];

/// Names of the appearance columns for `config`'s buckets.
pub fn appearance_columns(config: &Config) -> Vec<String> {
    let a = &config.appearance;
    let named = |name: &'static str, n: u32| (0..n).map(move |i| format!("{name}_{i}"));
    named("hue", a.hue_bins)
        .chain(named("saturation", a.saturation_bins))
        .chain(named("value", a.value_bins))
        .collect()
}

/// The message type of the cell table: `features` and `appearance` are the value
/// columns' names; `self_labels` false for format 1.
fn schema(features: &[String], appearance: &[String], self_labels: bool) -> String {
    let mut fields = vec![
        "REQUIRED BYTE_ARRAY source (STRING)".to_string(),
        "REQUIRED INT64 frame".into(),
        "REQUIRED INT64 stamp_ns".into(),
        "REQUIRED INT32 row".into(),
        "REQUIRED INT32 col".into(),
        "REQUIRED DOUBLE x_m".into(),
        "REQUIRED DOUBLE y_m".into(),
        "REQUIRED INT32 points".into(),
    ];
    fields.extend(features.iter().map(|n| format!("REQUIRED FLOAT {n}")));
    fields.extend(appearance.iter().map(|n| format!("OPTIONAL FLOAT {n}")));
    fields.push("OPTIONAL BOOLEAN ground_truth_traversable".into());
    fields.push("OPTIONAL BOOLEAN predicted_traversable".into());
    if self_labels {
        fields.extend(SELF_LABEL_COLUMNS.map(String::from));
    }
    format!("message travmap_cells {{ {}; }}", fields.join("; "))
}

/// Where a dataset goes: one Parquet file, or a folder of part files that
/// pyarrow.dataset, DuckDB and Polars read as one table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DatasetFiles {
    File,
    /// `part-00000.parquet`, ... of whole frames, a part closed once it holds
    /// `rows_per_part` rows or more: each part's footer, the writer's memory that
    /// grows with the rows, stays this small however long the drive.
    Parts {
        rows_per_part: u64,
    },
}

/// Rows a part holds by default: 2^20 (about 230 frames of the 36 m training grid,
/// 60 MB of zstd Parquet).
pub const DEFAULT_ROWS_PER_PART: u64 = 1 << 20;

/// The name of part `index` of a dataset folder.
fn part_name(index: usize) -> String {
    format!("part-{index:05}.parquet")
}

/// Whether `name` is a part file's (`part-NNNNN.parquet`).
fn is_part_name(name: &str) -> bool {
    name.strip_prefix("part-")
        .and_then(|rest| rest.strip_suffix(".parquet"))
        .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
}

/// The file in a dataset folder that lists its parts: the parts a later run may
/// replace are the ones an earlier run listed, never a file it did not write.
/// Readers pass it over (pyarrow.dataset ignores names starting with `_`, and it is
/// not `.parquet`).
pub const MANIFEST_NAME: &str = "_travmap_dataset.json";

/// The parts a dataset folder's manifest lists, in order (None: no manifest).
fn listed_parts(dir: &Path) -> Result<Option<Vec<PathBuf>>> {
    let path = dir.join(MANIFEST_NAME);
    let text = match std::fs::read_to_string(&path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(Error::io(&path, e)),
    };
    let invalid = |message: String| Error::Dataset {
        path: path.clone(),
        message,
    };
    let manifest: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| invalid(format!("not a dataset manifest: {e}")))?;
    let names = (manifest.get("parts").and_then(|p| p.as_array()))
        .ok_or_else(|| invalid("a dataset manifest lists its `parts`".into()))?;
    names
        .iter()
        .map(|name| match name.as_str().filter(|n| is_part_name(n)) {
            Some(name) => Ok(Some(dir.join(name))),
            None => Err(invalid(format!("{name} is not a part file's name"))),
        })
        .collect::<Result<Option<Vec<_>>>>()
}

/// The `.parquet` files of `dir`, sorted.
fn parquet_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|entry| entry.ok())
        .map(|entry| entry.path())
        .filter(|path| path.extension().is_some_and(|e| e == "parquet"))
        .collect();
    files.sort();
    Ok(files)
}

/// The part files of the dataset folder `dir`, in order: those its manifest lists,
/// or (a folder written before manifests) its `part-NNNNN.parquet` files.
pub fn part_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let parts = match listed_parts(dir)? {
        Some(parts) => parts,
        None => (parquet_files(dir)?.into_iter())
            .filter(|path| (path.file_name().and_then(|n| n.to_str())).is_some_and(is_part_name))
            .collect(),
    };
    if parts.is_empty() {
        return Err(Error::Dataset {
            path: dir.to_path_buf(),
            message: "a folder without part-NNNNN.parquet files: not a dataset `travmap dataset -o DIR/` wrote".into(),
        });
    }
    Ok(parts)
}

/// Before any work: a dataset folder may hold only the parts an earlier dataset run
/// listed. Other Parquet files would be read as part of the table by
/// pyarrow.dataset, DuckDB and Polars, and a run that replaced them would destroy
/// what it did not write.
pub fn check_dataset_folder(dir: &Path) -> Result<()> {
    if !dir.is_dir() {
        return Ok(());
    }
    let listed = listed_parts(dir)?.unwrap_or_default();
    let others: Vec<String> = (parquet_files(dir)?.into_iter())
        .filter(|path| !listed.contains(path))
        .filter_map(|path| path.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    if others.is_empty() {
        return Ok(());
    }
    let shown: Vec<&str> = others.iter().take(5).map(String::as_str).collect();
    Err(Error::Dataset {
        path: dir.to_path_buf(),
        message: format!(
            "the folder holds {} Parquet {} this travmap did not write ({}{}): readers of the folder would take {} as part of the dataset, and travmap replaces only parts it listed in {MANIFEST_NAME}; write the dataset to an empty or new folder, or move {} away",
            others.len(),
            if others.len() == 1 { "file" } else { "files" },
            shown.join(", "),
            if others.len() > shown.len() {
                ", ..."
            } else {
                ""
            },
            if others.len() == 1 { "it" } else { "them" },
            if others.len() == 1 { "it" } else { "them" },
        ),
    })
}

/// The Parquet file being written: one dataset file, or one part of a folder.
struct FileWriter {
    writer: SerializedFileWriter<BufWriter<WritebackFile>>,
    output: AtomicFile,
    rows: u64,
    /// The SHA-256 of every labelled scan whose cells the file holds, so that a
    /// model trained on it knows its training scans by content.
    labelled_scans: Vec<String>,
}

/// A cell dataset being written; atomically, like every output: a folder's parts
/// appear together when the last is complete, and replace the parts of an earlier
/// dataset there.
pub struct DatasetWriter {
    path: PathBuf,
    layout: DatasetFiles,
    schema: Arc<parquet::schema::types::Type>,
    properties: Arc<WriterProperties>,
    file: Option<FileWriter>,
    /// Parts complete and synced, not yet in place.
    written: Vec<AtomicFile>,
    columns: RowGroupColumns,
    appearance_len: usize,
    summary: DatasetSummary,
    /// Key-value metadata each file gets at its end, besides travmap's own.
    extra_metadata: Vec<KeyValue>,
}

/// What a dataset holds, for the summary.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct DatasetSummary {
    pub rows: u64,
    pub frames: u64,
    pub labelled_rows: u64,
    pub rows_with_appearance: u64,
    /// Rows the vehicle drove over, and rows with a self-label.
    pub footprint_rows: u64,
    pub pseudo_labelled_rows: u64,
    /// The files written: the dataset file, or every part of the folder.
    #[serde(skip)]
    pub files: Vec<PathBuf>,
}

impl DatasetWriter {
    /// A dataset at `path` (a folder that exists, for [`DatasetFiles::Parts`]);
    /// `model` records the model that predicted its cells, if one did (JSON).
    pub fn create(
        path: &Path,
        config: &Config,
        layout: DatasetFiles,
        model: Option<String>,
    ) -> Result<Self> {
        let appearance = appearance_columns(config);
        let features = feature_names(&config.features.groups);
        let schema =
            parquet::schema::parser::parse_message_type(&schema(&features, &appearance, true))
                .expect("the cell schema parses");
        let config_json = serde_json::to_string(config).expect("config serialises");
        let mut metadata = vec![
            KeyValue::new(FORMAT_KEY.into(), FORMAT.to_string()),
            KeyValue::new(CONFIG_KEY.into(), config_json),
        ];
        metadata.extend(model.map(|model| KeyValue::new(MODEL_KEY.into(), model)));
        let mut properties = WriterProperties::builder()
            .set_compression(Compression::ZSTD(ZstdLevel::default()))
            .set_created_by(concat!("travmap ", env!("CARGO_PKG_VERSION")).into())
            .set_key_value_metadata(Some(metadata))
            .set_dictionary_enabled(false);
        for column in DICTIONARY_COLUMNS {
            properties = properties.set_column_dictionary_enabled(ColumnPath::from(column), true);
        }
        let mut writer = Self {
            path: path.to_path_buf(),
            layout,
            schema: Arc::new(schema),
            properties: Arc::new(properties.build()),
            file: None,
            written: Vec::new(),
            columns: RowGroupColumns::new(features.len(), appearance.len()),
            appearance_len: appearance.len(),
            summary: DatasetSummary::default(),
            extra_metadata: Vec::new(),
        };
        // A single file is created before any work, so that an output that cannot
        // be written is said at once.
        if layout == DatasetFiles::File {
            writer.open_file()?;
        }
        Ok(writer)
    }

    fn open_file(&mut self) -> Result<&mut FileWriter> {
        if self.file.is_none() {
            let path = match self.layout {
                DatasetFiles::File => self.path.clone(),
                DatasetFiles::Parts { .. } => self.path.join(part_name(self.written.len())),
            };
            let (output, file) = AtomicFile::create(&path)?;
            let writer = SerializedFileWriter::new(
                BufWriter::with_capacity(1 << 20, WritebackFile::new(file)),
                self.schema.clone(),
                self.properties.clone(),
            )
            .map_err(|e| parquet_failure(&path, &output, e))?;
            self.file = Some(FileWriter {
                writer,
                output,
                rows: 0,
                labelled_scans: Vec::new(),
            });
        }
        Ok(self.file.as_mut().expect("opened above"))
    }

    /// Adds `key` = `value` to the metadata of every file written from here on.
    pub fn append_metadata(&mut self, key: &str, value: String) {
        self.extra_metadata.push(KeyValue::new(key.into(), value));
    }

    /// Appends the predictable cells of one frame, each with its ground truth.
    pub fn push_frame(&mut self, source: &str, result: &FrameResult) -> Result<()> {
        let truth = |cell: usize| class_of(&result.ground_truth, cell);
        let cells = (0..result.layout.cell_count()).filter(|&i| result.features.predictable[i]);
        self.push_rows(source, result, cells.map(|cell| (cell, truth(cell))))
    }

    /// Appends cells of one frame a person labelled (`travmap label`): each with its
    /// label as its ground truth.
    pub fn push_labelled(
        &mut self,
        source: &str,
        result: &FrameResult,
        labels: &[(usize, bool)],
    ) -> Result<()> {
        let cells = labels
            .iter()
            .filter(|(cell, _)| result.features.predictable[*cell]);
        self.push_rows(
            source,
            result,
            cells.map(|&(cell, label)| (cell, Some(label))),
        )
    }

    /// Appends rows of one frame: its `cells`, each with its ground truth.
    fn push_rows(
        &mut self,
        source: &str,
        result: &FrameResult,
        cells: impl Iterator<Item = (usize, Option<bool>)>,
    ) -> Result<()> {
        if result.features.dimension != self.columns.features.len() {
            return Err(Error::Dataset {
                path: self.path.clone(),
                message: format!(
                    "{source} frame {}: no usable remission (intensity) for the remission columns; extract without them (--set features.groups=[\"context\"])",
                    result.index
                ),
            });
        }
        let file = self.open_file()?;
        if let (Some(sha), Some(_)) = (&result.scan_sha256, &result.ground_truth) {
            file.labelled_scans.push(sha.clone());
        }
        let source = ByteArray::from(source);
        // A frame adds at most a row per cell.
        self.columns
            .reserve(ROW_GROUP_ROWS - 1 + result.layout.cell_count());
        let c = &mut self.columns;
        let summary = &mut self.summary;
        summary.frames += 1;
        for (cell, truth) in cells {
            let (col, row) = result.layout.col_row(cell);
            let [x_m, y_m] = result.layout.cell_centre_in_world(cell);
            c.source.push(source.clone());
            c.frame.push(result.index as i64);
            c.stamp_ns.push(result.stamp_ns as i64);
            c.row.push(row as i32);
            c.col.push(col as i32);
            c.x_m.push(x_m);
            c.y_m.push(y_m);
            c.points.push(result.cells.point_count(cell) as i32);
            for (column, &value) in c.features.iter_mut().zip(result.features.cell(cell)) {
                column.push(value);
            }
            match result.features.appearance(cell) {
                Some(values) if values.len() == self.appearance_len => {
                    c.appearance_defined.push(1);
                    summary.rows_with_appearance += 1;
                    for (column, &value) in c.appearance.iter_mut().zip(values) {
                        column.push(value);
                    }
                }
                _ => c.appearance_defined.push(0),
            }
            summary.labelled_rows += truth.is_some() as u64;
            summary.rows += 1;
            c.ground_truth.push(truth);
            c.predicted.push(class_of(&result.filtered, cell));
            let footprint = result.footprint.as_ref().is_some_and(|(f, _)| f[cell]);
            let pseudo = result.self_labels.as_ref().and_then(|l| l[cell]);
            summary.footprint_rows += footprint as u64;
            summary.pseudo_labelled_rows += pseudo.is_some() as u64;
            c.footprint.push(footprint);
            c.pseudo_label.push(pseudo);
        }
        let part_rows = self.file.as_ref().map_or(0, |f| f.rows) + self.columns.len() as u64;
        match self.layout {
            DatasetFiles::Parts { rows_per_part } if part_rows >= rows_per_part => {
                self.close_file()?
            }
            _ if self.columns.len() >= ROW_GROUP_ROWS => self.flush()?,
            _ => {}
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        let rows = self.columns.len();
        let Some(file) = self.file.as_mut().filter(|_| rows > 0) else {
            return Ok(());
        };
        let columns = &self.columns;
        let path = file.output.path().to_path_buf();
        let output = &file.output;
        let fail = |e| parquet_failure(&path, output, e);
        let mut group = file.writer.next_row_group().map_err(fail)?;
        let mut index = 0;
        while let Some(mut column) = group.next_column().map_err(fail)? {
            write_column(column.untyped(), columns, index).map_err(fail)?;
            column.close().map_err(fail)?;
            index += 1;
        }
        group.close().map_err(fail)?;
        file.rows += rows as u64;
        self.columns.clear();
        Ok(())
    }

    /// Writes the file's last row group and footer and syncs it, to be renamed into
    /// place with the others.
    fn close_file(&mut self) -> Result<()> {
        self.flush()?;
        let Some(mut file) = self.file.take() else {
            return Ok(());
        };
        for pair in &self.extra_metadata {
            file.writer.append_key_value_metadata(pair.clone());
        }
        if !file.labelled_scans.is_empty() {
            let scans = serde_json::to_string(&file.labelled_scans).expect("strings serialise");
            (file.writer).append_key_value_metadata(KeyValue::new(SCANS_KEY.into(), scans));
        }
        let path = file.output.path().to_path_buf();
        let output = &file.output;
        let written = file
            .writer
            .into_inner()
            .map_err(|e| parquet_failure(&path, output, e))?
            .into_inner()
            .map_err(|e| write_failure(&path, output, Some(e.into_error()), None))?
            .into_inner();
        sync_output(&written).map_err(|source| write_failure(&path, output, Some(source), None))?;
        self.written.push(file.output);
        Ok(())
    }

    /// Writes the last row group and footer, then renames the file (or every part)
    /// into place, removing a folder's parts of an earlier dataset; `inputs` and
    /// their `skipped` frames say why, when no frame was read.
    pub fn finish(self, inputs: &str, skipped: &[Skip]) -> Result<DatasetSummary> {
        if self.summary.frames == 0 {
            return Err(nothing_read(&self.path, inputs.to_string(), skipped));
        }
        self.finish_even_empty()
    }

    /// [`Self::finish`], a table of no rows included (a labels file of skips alone).
    pub fn finish_even_empty(mut self) -> Result<DatasetSummary> {
        self.close_file()?;
        let files: Vec<PathBuf> = self
            .written
            .iter()
            .map(|f| f.path().to_path_buf())
            .collect();
        let earlier = match self.layout {
            DatasetFiles::Parts { .. } => listed_parts(&self.path)?.unwrap_or_default(),
            DatasetFiles::File => Vec::new(),
        };
        self.written.into_iter().try_for_each(AtomicFile::commit)?;
        if let DatasetFiles::Parts { .. } = self.layout {
            let names: Vec<String> = (files.iter())
                .filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect();
            let manifest = serde_json::json!({"format": FORMAT, "parts": names});
            write_atomically(
                &self.path.join(MANIFEST_NAME),
                format!("{manifest}\n").as_bytes(),
            )?;
            // An earlier dataset's parts this one did not replace.
            for stale in earlier.iter().filter(|path| !files.contains(path)) {
                match std::fs::remove_file(stale) {
                    Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                        return Err(Error::io(stale, e));
                    }
                    _ => {}
                }
            }
        }
        self.summary.files = files;
        Ok(self.summary)
    }
}

/// A grid's class of `cell` as a nullable boolean (traversable), None where it is
/// unknown or there is no grid.
fn class_of(grid: &Option<Vec<CellClass>>, cell: usize) -> Option<bool> {
    grid.as_ref().and_then(|g| match g[cell] {
        CellClass::Traversable => Some(true),
        CellClass::NonTraversable => Some(false),
        CellClass::Unknown => None,
    })
}

/// The settings that decide a cell's features and label: a dataset made with
/// others cannot train a model used with these.
fn feature_settings(config: &Config) -> serde_json::Value {
    let truth = &config.ground_truth;
    // Presets under one rule mean the same ground whatever dataset's ids they read
    // (SemanticKITTI's and nuScenes' road rules train one model); explicit lists
    // and label maps are compared by what they count.
    // Lists equal to the preset's (as older configurations wrote them) are the preset.
    let classes = truth.classes();
    let preset_classes = truth.labels.classes(truth.rule);
    let preset = truth.label_map.is_none()
        && classes.traversable == preset_classes.traversable
        && classes.ignored == preset_classes.ignored;
    let counted = match preset {
        true => serde_json::json!({ "rule": truth.rule }),
        false => serde_json::json!({
            "traversable_classes": classes.traversable,
            "ignored_classes": classes.ignored,
        }),
    };
    // The remission scale means nothing without remission features.
    let mut features = config.features.clone();
    if !features.groups.contains(&FeatureGroup::Remission) {
        features.remission_scale = Default::default();
    }
    serde_json::json!({
        "integration": config.integration,
        "grid.cell_size_m": config.grid.cell_size_m,
        "grid.min_points": config.grid.min_points,
        "features": features,
        "appearance": config.appearance,
        "ground_truth": {
            "min_points": truth.min_points,
            "min_non_traversable_points": truth.min_non_traversable_points,
            "counted": counted,
        },
    })
}

#[cfg(test)]
mod tests {
    use std::fs::File;

    use super::reading::read_training_rows;
    use super::*;
    use travmap_method::training_set::TrainingSet;

    /// A file with the cell schema as `edit` changes it and travmap's metadata.
    fn write_with_schema(path: &Path, config: &Config, edit: impl Fn(String) -> String) {
        let features = feature_names(&config.features.groups);
        let schema = edit(schema(&features, &appearance_columns(config), true));
        let schema = parquet::schema::parser::parse_message_type(&schema).unwrap();
        let properties = WriterProperties::builder()
            .set_key_value_metadata(Some(vec![
                KeyValue::new(FORMAT_KEY.into(), FORMAT.to_string()),
                KeyValue::new(CONFIG_KEY.into(), serde_json::to_string(config).unwrap()),
            ]))
            .build();
        let file = File::create(path).unwrap();
        SerializedFileWriter::new(file, Arc::new(schema), Arc::new(properties))
            .unwrap()
            .close()
            .unwrap();
    }

    #[test]
    fn a_column_of_another_type_is_refused_before_it_is_read() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cells.parquet");
        let config = Config::default();
        let read = |path: &Path| {
            read_training_rows(
                path,
                &config,
                &mut TrainingSet::default(),
                reading::Labels::GroundTruth,
            )
            .map_err(|e| e.to_string())
        };
        write_with_schema(&path, &config, |s| s);
        assert_eq!(read(&path), Ok(0));
        write_with_schema(&path, &config, |s| {
            s.replace("REQUIRED DOUBLE x_m", "REQUIRED INT64 x_m")
        });
        let err = read(&path).unwrap_err();
        assert!(
            err.contains("cells.parquet")
                && err.contains("column 5 is `x_m INT64`; expected `x_m DOUBLE`"),
            "{err}"
        );
        write_with_schema(&path, &config, |s| {
            s.replace("; OPTIONAL BOOLEAN pseudo_label", "")
        });
        let err = read(&path).unwrap_err();
        assert!(err.contains("column 122 is `(none)`; expected `pseudo_label BOOLEAN` (122 columns, expected 123)"), "{err}");
    }

    /// A file with the cell schema and `rows` rows in one group: column `c` of row
    /// `r` holds `value(r, c)`; the labels are present where `labelled(r)`,
    /// traversable in even rows; appearance in every row.
    fn write_rows(
        path: &Path,
        config: &Config,
        rows: usize,
        value: impl Fn(usize, usize) -> f64,
        labelled: impl Fn(usize) -> bool,
    ) {
        use parquet::column::writer::ColumnWriter;
        let features = feature_names(&config.features.groups);
        let schema = schema(&features, &appearance_columns(config), true);
        let schema = parquet::schema::parser::parse_message_type(&schema).unwrap();
        let properties = WriterProperties::builder()
            .set_key_value_metadata(Some(vec![
                KeyValue::new(FORMAT_KEY.into(), FORMAT.to_string()),
                KeyValue::new(CONFIG_KEY.into(), serde_json::to_string(config).unwrap()),
            ]))
            // As a compact writer would: the constant pages of a made-up file shrink
            // to nothing, as a fuzzer's do.
            .set_compression(Compression::ZSTD(ZstdLevel::default()))
            .set_data_page_row_count_limit(usize::MAX)
            .build();
        let file = File::create(path).unwrap();
        let mut writer =
            SerializedFileWriter::new(file, Arc::new(schema), Arc::new(properties)).unwrap();
        let optional: Vec<bool> = (writer.schema_descr().columns().iter())
            .map(|column| column.max_def_level() > 0)
            .collect();
        let mut group = writer.next_row_group().unwrap();
        let mut c = 0;
        let label_levels: Vec<i16> = (0..rows).map(|r| labelled(r) as i16).collect();
        let labelled: Vec<usize> = (0..rows).filter(|&r| labelled(r)).collect();
        while let Some(mut column) = group.next_column().unwrap() {
            let all_levels = vec![1i16; rows];
            let levels = |optional: bool| optional.then_some(&all_levels[..]);
            let optional = optional[c];
            match column.untyped() {
                ColumnWriter::ByteArrayColumnWriter(w) => {
                    w.write_batch(&vec![ByteArray::from("t"); rows], None, None)
                }
                ColumnWriter::Int64ColumnWriter(w) => {
                    let values: Vec<i64> = (0..rows).map(|r| value(r, c) as i64).collect();
                    w.write_batch(&values, None, None)
                }
                ColumnWriter::Int32ColumnWriter(w) => {
                    let values: Vec<i32> = (0..rows).map(|r| value(r, c) as i32).collect();
                    w.write_batch(&values, None, None)
                }
                ColumnWriter::DoubleColumnWriter(w) => {
                    let values: Vec<f64> = (0..rows).map(|r| value(r, c)).collect();
                    w.write_batch(&values, None, None)
                }
                ColumnWriter::FloatColumnWriter(w) => {
                    let values: Vec<f32> = (0..rows).map(|r| value(r, c) as f32).collect();
                    w.write_batch(&values, levels(optional), None)
                }
                ColumnWriter::BoolColumnWriter(w) if optional => {
                    let values: Vec<bool> = labelled.iter().map(|r| r % 2 == 0).collect();
                    w.write_batch(&values, Some(&label_levels), None)
                }
                ColumnWriter::BoolColumnWriter(w) => w.write_batch(&vec![false; rows], None, None),
                _ => unreachable!("the cell schema has no other column type"),
            }
            .unwrap();
            column.close().unwrap();
            c += 1;
        }
        group.close().unwrap();
        writer.close().unwrap();
    }

    #[test]
    fn row_groups_are_read_in_batches_row_for_row() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cells.parquet");
        let config = Config::default();
        let rows = 2 * READ_BATCH_ROWS + 7;
        let value = |r: usize, c: usize| r as f64 / 1000.0 + c as f64;
        write_rows(&path, &config, rows, value, |r| r % 3 != 0);
        let mut set = TrainingSet::for_features(&config);
        let added =
            read_training_rows(&path, &config, &mut set, reading::Labels::GroundTruth).unwrap();
        let labelled: Vec<usize> = (0..rows).filter(|r| r % 3 != 0).collect();
        assert_eq!(added, labelled.len());
        let dimension = set.dimension;
        assert_eq!(dimension, feature_names(&config.features.groups).len());
        for (i, &r) in labelled.iter().enumerate() {
            assert_eq!(set.traversable[i], r % 2 == 0, "row {r}");
            assert_eq!(set.centre_in_world[i], [value(r, 5), value(r, 6)]);
            let features = &set.features[i * dimension..(i + 1) * dimension];
            let expected: Vec<f32> = (0..dimension).map(|f| value(r, 8 + f) as f32).collect();
            assert_eq!(features, expected, "row {r}");
            let appearance = set.appearance_row[i].expect("every row has appearance");
            let at = appearance * set.appearance_len;
            assert_eq!(
                set.appearance[at],
                value(r, 8 + dimension) as f32,
                "row {r}"
            );
        }
    }

    #[test]
    fn a_file_declaring_far_more_rows_than_its_bytes_can_hold_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cells.parquet");
        let mut config = Config::default();
        // One value per row: run-length encoding holds a million rows in a few bytes.
        config.features.groups.clear();
        let rows = 1 << 20;
        write_rows(&path, &config, rows, |_, _| 0.5, |_| true);
        let bytes = std::fs::metadata(&path).unwrap().len();
        let err = read_training_rows(
            &path,
            &config,
            &mut TrainingSet::default(),
            reading::Labels::GroundTruth,
        )
        .map(|_| bytes)
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("cells.parquet")
                && err.contains(&format!("row group 0 declares {rows} rows"))
                && err.contains(&format!("values per byte of a {bytes}-byte file")),
            "{err}"
        );
    }
}
