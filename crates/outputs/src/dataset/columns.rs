//! The rows of one row group of a cell dataset, by column, and how each column is
//! written.

use parquet::column::writer::ColumnWriter;
use parquet::data_type::ByteArray;

/// A nullable column: values of the present rows, and 1 / 0 per row.
#[derive(Default)]
pub(super) struct Nullable<T> {
    pub(super) values: Vec<T>,
    pub(super) defined: Vec<i16>,
}

impl<T> Nullable<T> {
    pub(super) fn push(&mut self, value: Option<T>) {
        self.defined.push(value.is_some() as i16);
        self.values.extend(value);
    }
}

/// The rows of one row group, by column.
#[derive(Default)]
pub(super) struct RowGroupColumns {
    pub(super) source: Vec<ByteArray>,
    pub(super) frame: Vec<i64>,
    pub(super) stamp_ns: Vec<i64>,
    pub(super) row: Vec<i32>,
    pub(super) col: Vec<i32>,
    pub(super) x_m: Vec<f64>,
    pub(super) y_m: Vec<f64>,
    pub(super) points: Vec<i32>,
    pub(super) features: Vec<Vec<f32>>,
    pub(super) appearance: Vec<Vec<f32>>,
    /// Whether each row has appearance values (all of them or none).
    pub(super) appearance_defined: Vec<i16>,
    pub(super) ground_truth: Nullable<bool>,
    pub(super) predicted: Nullable<bool>,
    pub(super) footprint: Vec<bool>,
    pub(super) pseudo_label: Nullable<bool>,
}

impl RowGroupColumns {
    pub(super) fn new(feature_count: usize, appearance_len: usize) -> Self {
        Self {
            features: vec![Vec::new(); feature_count],
            appearance: vec![Vec::new(); appearance_len],
            ..Default::default()
        }
    }

    pub(super) fn len(&self) -> usize {
        self.frame.len()
    }

    /// Room for `rows` rows in every column, exactly. A row group ends with the frame
    /// that takes it past its size, so doubling grew the columns to twice the rows they
    /// ever hold: 35-47 MB of them on the training grid.
    pub(super) fn reserve(&mut self, rows: usize) {
        self.each_buffer(&mut |buffer| buffer.reserve_rows(rows));
    }

    /// Empties every column, keeping its buffer for the next row group: regrowing
    /// some 80 columns from nothing for every group left the allocator's arenas
    /// fragmented, and the process growing with the drive.
    pub(super) fn clear(&mut self) {
        self.each_buffer(&mut |buffer| buffer.clear_rows());
    }

    /// `f` on every buffer of every column (a nullable column has two).
    fn each_buffer(&mut self, f: &mut dyn FnMut(&mut dyn RowBuffer)) {
        let fixed: [&mut dyn RowBuffer; 10] = [
            &mut self.source,
            &mut self.frame,
            &mut self.stamp_ns,
            &mut self.row,
            &mut self.col,
            &mut self.x_m,
            &mut self.y_m,
            &mut self.points,
            &mut self.appearance_defined,
            &mut self.footprint,
        ];
        fixed.into_iter().for_each(&mut *f);
        for column in self.features.iter_mut().chain(&mut self.appearance) {
            f(column);
        }
        for nullable in [
            &mut self.ground_truth,
            &mut self.predicted,
            &mut self.pseudo_label,
        ] {
            f(&mut nullable.values);
            f(&mut nullable.defined);
        }
    }
}

/// A column's buffer, whatever its values.
trait RowBuffer {
    fn reserve_rows(&mut self, rows: usize);
    fn clear_rows(&mut self);
}

impl<T> RowBuffer for Vec<T> {
    fn reserve_rows(&mut self, rows: usize) {
        self.reserve_exact(rows.saturating_sub(self.len()));
    }

    fn clear_rows(&mut self) {
        self.clear();
    }
}

/// Writes column `index` of the schema from `columns`.
pub(super) fn write_column(
    writer: &mut ColumnWriter<'_>,
    columns: &RowGroupColumns,
    index: usize,
) -> parquet::errors::Result<()> {
    let features = 8..8 + columns.features.len();
    let appearance = features.end..features.end + columns.appearance.len();
    let written = match writer {
        ColumnWriter::ByteArrayColumnWriter(w) => w.write_batch(&columns.source, None, None),
        ColumnWriter::Int64ColumnWriter(w) => {
            let values = [&columns.frame, &columns.stamp_ns][index - 1];
            w.write_batch(values, None, None)
        }
        ColumnWriter::Int32ColumnWriter(w) => {
            let values = match index {
                3 => &columns.row,
                4 => &columns.col,
                _ => &columns.points,
            };
            w.write_batch(values, None, None)
        }
        ColumnWriter::DoubleColumnWriter(w) => {
            let values = [&columns.x_m, &columns.y_m][index - 5];
            w.write_batch(values, None, None)
        }
        ColumnWriter::FloatColumnWriter(w) if features.contains(&index) => {
            w.write_batch(&columns.features[index - features.start], None, None)
        }
        ColumnWriter::FloatColumnWriter(w) if appearance.contains(&index) => w.write_batch(
            &columns.appearance[index - appearance.start],
            Some(&columns.appearance_defined),
            None,
        ),
        ColumnWriter::BoolColumnWriter(w) => match index - appearance.end {
            0 => w.write_batch(
                &columns.ground_truth.values,
                Some(&columns.ground_truth.defined),
                None,
            ),
            1 => w.write_batch(
                &columns.predicted.values,
                Some(&columns.predicted.defined),
                None,
            ),
            2 => w.write_batch(&columns.footprint, None, None),
            _ => w.write_batch(
                &columns.pseudo_label.values,
                Some(&columns.pseudo_label.defined),
                None,
            ),
        },
        _ => unreachable!("column {index} is not in the cell schema"),
    };
    written.map(|_| ())
}
