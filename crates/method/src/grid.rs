//! Stage 2, grid (METHOD.md section 3): the integrated points that fall in the square
//! grid around the sensor, sorted by cell.
//!
//! Input: the window of [`DriveScan`]s and the sensor position. Output: [`CellPoints`],
//! flat arrays in cell order (a counting sort, two passes, no per-cell allocation).
//! The grid is axis-aligned with the world and its corner is snapped to a multiple of
//! the cell size from the drive frame's origin, so a cell keeps its identity from
//! frame to frame.

use crate::integration::DriveScan;
use travmap_core::posing::DriveFrame;

/// The label of a cell, predicted or ground truth.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CellClass {
    /// Too few points to predict (or no ground truth).
    Unknown,
    Traversable,
    NonTraversable,
}

impl CellClass {
    /// The class a classifier margin says: traversable above 0, not traversable
    /// at or below, unknown for NaN (no prediction).
    pub fn of_margin(margin: f32) -> Self {
        if margin.is_nan() {
            CellClass::Unknown
        } else if margin > 0.0 {
            CellClass::Traversable
        } else {
            CellClass::NonTraversable
        }
    }

    /// One character per cell for text pictures of a grid.
    pub fn symbol(self) -> char {
        match self {
            CellClass::Unknown => ' ',
            CellClass::Traversable => '.',
            CellClass::NonTraversable => '#',
        }
    }

    /// The `nav_msgs/OccupancyGrid` value of a cell: 0 free (traversable), 100
    /// occupied, -1 unknown; also the cells of `run --json`.
    pub fn occupancy(self) -> i8 {
        match self {
            CellClass::Unknown => -1,
            CellClass::Traversable => 0,
            CellClass::NonTraversable => 100,
        }
    }
}

/// Where the grid lies: on the drive's lattice of cells, which is anchored at the
/// drive frame's origin ([`DriveFrame`]), so a cell keeps its key from frame to frame
/// and the same drive moved anywhere in the world has the same cells.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridLayout {
    pub cell_size_m: f64,
    pub cells_per_side: usize,
    /// Lattice key (`floor(x / r)`, `floor(y / r)` in the drive frame) of cell
    /// (col 0, row 0).
    pub first_cell_key: [i64; 2],
    /// The frame the method's points are in, and where it lies in the world.
    pub drive: DriveFrame,
}

impl GridLayout {
    /// The grid of `cells_per_side` cells centred on `centre_in_drive` (x, y); its
    /// corner is a whole number of cells from the drive frame's origin.
    pub fn centred_on(
        centre_in_drive: [f64; 2],
        drive: DriveFrame,
        cell_size_m: f64,
        cells_per_side: usize,
    ) -> Self {
        let half = (cells_per_side / 2) as i64;
        let key = |v: f64| (v / cell_size_m).floor() as i64 - half;
        Self {
            cell_size_m,
            cells_per_side,
            first_cell_key: [key(centre_in_drive[0]), key(centre_in_drive[1])],
            drive,
        }
    }

    pub fn cell_count(&self) -> usize {
        self.cells_per_side * self.cells_per_side
    }

    /// Drive-frame x, y of the grid's min corner: where the method's points are
    /// measured from.
    pub fn min_corner_in_drive(&self) -> [f64; 2] {
        self.first_cell_key.map(|k| k as f64 * self.cell_size_m)
    }

    /// World x, y of the grid's min corner.
    pub fn min_corner_in_world(&self) -> [f64; 2] {
        let [x, y] = self.min_corner_in_drive();
        let [ox, oy, _] = self.drive.origin_in_world;
        [ox + x, oy + y]
    }

    /// Cell index (`row * cells_per_side + col`, col along world x) of a point
    /// given relative to the min corner, or None outside the grid.
    #[inline]
    pub fn cell_of_local(&self, x_m: f64, y_m: f64) -> Option<usize> {
        // Truncation is floor on the non-negative side, and unlike `floor` it stays
        // an instruction on baseline x86-64 (no SSE4.1): this runs for every point.
        let col = x_m / self.cell_size_m;
        let row = y_m / self.cell_size_m;
        let l = self.cells_per_side as f64;
        if col >= 0.0 && row >= 0.0 && col < l && row < l {
            // In 0..l, so through u32 the same values: a saturating conversion to
            // u32 is half the instructions of one to usize.
            Some(row as u32 as usize * self.cells_per_side + col as u32 as usize)
        } else {
            None
        }
    }

    /// (col, row) of a cell index.
    pub fn col_row(&self, cell: usize) -> (usize, usize) {
        (cell % self.cells_per_side, cell / self.cells_per_side)
    }

    /// Lattice key of a cell index: the cell's identity across the drive's frames.
    pub fn cell_key(&self, cell: usize) -> [i64; 2] {
        let (col, row) = self.col_row(cell);
        [
            self.first_cell_key[0] + col as i64,
            self.first_cell_key[1] + row as i64,
        ]
    }

    /// Drive-frame x, y of a cell's centre.
    pub fn cell_centre_in_drive(&self, cell: usize) -> [f64; 2] {
        self.cell_key(cell)
            .map(|k| (k as f64 + 0.5) * self.cell_size_m)
    }

    /// World x, y of a cell's centre.
    pub fn cell_centre_in_world(&self, cell: usize) -> [f64; 2] {
        let [x, y] = self.cell_centre_in_drive(cell);
        let [ox, oy, _] = self.drive.origin_in_world;
        [ox + x, oy + y]
    }

    /// A point of [`CellPoints::points_in_grid`] (x, y from the min corner, z in the
    /// drive frame) in the world.
    pub fn grid_point_in_world(&self, p: [f32; 3]) -> [f64; 3] {
        let [x, y] = self.min_corner_in_drive();
        self.drive
            .point_in_world([x + p[0] as f64, y + p[1] as f64, p[2] as f64])
    }
}

/// The in-grid points of the integrated cloud, sorted by cell.
#[derive(Clone, Debug)]
pub struct CellPoints {
    pub layout: GridLayout,
    /// Cell `c` holds points `cell_start[c]..cell_start[c + 1]`.
    pub cell_start: Vec<u32>,
    /// x, y relative to the grid's min corner, z as in the drive frame, metres.
    pub points_in_grid: Vec<[f32; 3]>,
    /// Distance of each point from the sensor origin of its own scan, metres.
    pub range_m: Vec<f32>,
    /// Per-point labels, present when every scan of the window has them.
    pub labels: Option<Vec<u32>>,
    /// Per-point remission (0..1), present when every scan of the window has it.
    pub remission: Option<Vec<f32>>,
    /// The last `newest_per_cell[c]` points of cell `c` are from the window's
    /// newest scan (a cell's points come in the order of the scans).
    pub newest_per_cell: Vec<u32>,
}

impl CellPoints {
    pub fn cell_range(&self, cell: usize) -> std::ops::Range<usize> {
        self.cell_start[cell] as usize..self.cell_start[cell + 1] as usize
    }

    pub fn point_count(&self, cell: usize) -> usize {
        self.cell_range(cell).len()
    }

    /// The points of `cell` from the window's newest scan.
    fn newest_range(&self, cell: usize) -> std::ops::Range<usize> {
        let all = self.cell_range(cell);
        all.end - self.newest_per_cell[cell] as usize..all.end
    }

    /// What a frame's result keeps of these points once the method is done with them;
    /// the rest goes back into `buffers` for the next frame.
    pub fn kept_for_outputs(self, buffers: &mut GridBuffers) -> KeptCellPoints {
        let cell_count = self.layout.cell_count();
        let mut newest_start = Vec::with_capacity(cell_count + 1);
        newest_start.push(0);
        let newest: u32 = self.newest_per_cell.iter().sum();
        let mut newest_points_in_grid = Vec::with_capacity(newest as usize);
        for cell in 0..cell_count {
            newest_points_in_grid.extend_from_slice(&self.points_in_grid[self.newest_range(cell)]);
            newest_start.push(newest_points_in_grid.len() as u32);
        }
        buffers.points_in_grid = self.points_in_grid;
        buffers.range_m = self.range_m;
        if let Some(labels) = self.labels {
            buffers.labels = labels;
        }
        if let Some(remission) = self.remission {
            buffers.remission = remission;
        }
        KeptCellPoints {
            cell_start: self.cell_start,
            newest_start,
            newest_points_in_grid,
        }
    }
}

/// The grid stage's buffers, kept from one frame to the next: taken fresh, their
/// pages were faulted in again every frame, a quarter of the stage's time here
/// (0.4-0.5 ms of 1.9).
#[derive(Debug, Default)]
pub struct GridBuffers {
    /// (cell, point) of each in-grid point, scan by scan; its length is the most a
    /// frame has needed, not this frame's count.
    in_grid: Vec<(u32, u32)>,
    points_in_grid: Vec<[f32; 3]>,
    range_m: Vec<f32>,
    labels: Vec<u32>,
    remission: Vec<f32>,
}

/// `buffer` at `len` elements, each slot to be written by the caller: only slots it
/// never held are filled (with `value`), so that the frame's points are not written
/// twice (clearing 2.5 MB a frame here).
fn sized<T: Clone>(mut buffer: Vec<T>, len: usize, value: T) -> Vec<T> {
    buffer.truncate(len);
    buffer.resize(len, value);
    buffer
}

/// What a frame's result keeps of its [`CellPoints`]: each cell's point count and
/// the points of the window's newest scan (annotate's cloud). Whole windows of
/// points kept for every frame in flight to the outputs were most of the process's
/// memory, and let its peak grow with the length of the drive.
#[derive(Clone, Debug)]
pub struct KeptCellPoints {
    /// Cell `c` held `cell_start[c + 1] - cell_start[c]` points of the window.
    cell_start: Vec<u32>,
    /// Cell `c`'s newest points are `newest_start[c]..newest_start[c + 1]`.
    newest_start: Vec<u32>,
    /// x, y relative to the grid's min corner, z as in the drive frame, metres.
    newest_points_in_grid: Vec<[f32; 3]>,
}

impl KeptCellPoints {
    /// The window's points in `cell`.
    pub fn point_count(&self, cell: usize) -> usize {
        (self.cell_start[cell + 1] - self.cell_start[cell]) as usize
    }

    /// The window's points in the grid.
    pub fn window_points(&self) -> usize {
        self.cell_start.last().map_or(0, |&n| n as usize)
    }

    /// The newest scan's points in `cell`.
    pub fn newest(&self, cell: usize) -> &[[f32; 3]] {
        let range = self.newest_start[cell] as usize..self.newest_start[cell + 1] as usize;
        &self.newest_points_in_grid[range]
    }

    /// The newest scan's points in the grid.
    pub fn newest_len(&self) -> usize {
        self.newest_points_in_grid.len()
    }
}

/// Sorts the points of `scans` that fall inside `layout` into cells, in `buffers`
/// (given back by [`CellPoints::kept_for_outputs`]).
pub fn grid_points(
    scans: &[DriveScan],
    layout: GridLayout,
    buffers: &mut GridBuffers,
) -> CellPoints {
    let [min_x, min_y] = layout.min_corner_in_drive();
    let cell_count = layout.cell_count();

    // Pass 1: the cell of every in-grid point, and the count per cell.
    // (cell, point), written by position into a buffer kept long enough for the next
    // scan: with `push`, whose growing is a call, the loop's values went through
    // memory at every point. Scan s's are `in_grid[scan_start[s]..scan_start[s + 1]]`.
    let in_grid = &mut buffers.in_grid;
    let mut found = 0;
    let mut scan_start = Vec::with_capacity(scans.len() + 1);
    let mut counts = vec![0u32; cell_count];
    let mut newest_per_cell = vec![0u32; cell_count];
    for (s, scan) in scans.iter().enumerate() {
        scan_start.push(found);
        let room = found + scan.points_in_drive.len();
        if in_grid.len() < room {
            in_grid.resize(room, (0, 0));
        }
        for (i, p) in scan.points_in_drive.iter().enumerate() {
            if let Some(cell) = layout.cell_of_local(p[0] as f64 - min_x, p[1] as f64 - min_y) {
                counts[cell] += 1;
                in_grid[found] = (cell as u32, i as u32);
                found += 1;
            }
        }
        if s + 1 == scans.len() {
            for &(cell, _) in &in_grid[scan_start[s]..found] {
                newest_per_cell[cell as usize] += 1;
            }
        }
    }
    scan_start.push(found);
    let mut cell_start = vec![0u32; cell_count + 1];
    for c in 0..cell_count {
        cell_start[c + 1] = cell_start[c] + counts[c];
    }

    // Pass 2: scatter the in-grid points into cell order.
    let with_labels = scans.iter().all(|s| s.labels.is_some());
    let with_remission = scans.iter().all(|s| s.remission.is_some());
    let n = found;
    let mut remission = if with_remission {
        sized(std::mem::take(&mut buffers.remission), n, 0.0)
    } else {
        Vec::new()
    };
    let mut points_in_grid = sized(std::mem::take(&mut buffers.points_in_grid), n, [0.0; 3]);
    let mut range_m = sized(std::mem::take(&mut buffers.range_m), n, 0.0);
    let mut labels = if with_labels {
        sized(std::mem::take(&mut buffers.labels), n, 0)
    } else {
        Vec::new()
    };
    // Scan by scan, so that what a point needs of its scan is at hand, not looked up
    // through the scan's index at every point.
    let mut next = cell_start.clone();
    for (s, scan) in scans.iter().enumerate() {
        let points = &scan.points_in_drive[..];
        let o = scan.sensor_in_drive;
        let scan_labels = scan.labels.as_deref().filter(|_| with_labels);
        let scan_remission = scan.remission.as_deref().filter(|_| with_remission);
        for &(cell, i) in &buffers.in_grid[scan_start[s]..scan_start[s + 1]] {
            let i = i as usize;
            let at = next[cell as usize] as usize;
            next[cell as usize] += 1;
            let p = points[i];
            let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64);
            points_in_grid[at] = [(x - min_x) as f32, (y - min_y) as f32, p[2]];
            range_m[at] =
                ((x - o[0]).powi(2) + (y - o[1]).powi(2) + (z - o[2]).powi(2)).sqrt() as f32;
            if let Some(scan_labels) = scan_labels {
                labels[at] = scan_labels[i];
            }
            if let Some(scan_remission) = scan_remission {
                remission[at] = scan_remission[i];
            }
        }
    }
    CellPoints {
        layout,
        cell_start,
        points_in_grid,
        range_m,
        labels: with_labels.then_some(labels),
        remission: with_remission.then_some(remission),
        newest_per_cell,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_core::geometry::Moments;

    fn scan(points: Vec<[f32; 3]>, origin: [f64; 3]) -> DriveScan {
        DriveScan {
            index: 0,
            stamp_ns: 0,
            labels: Some((0..points.len() as u32).collect()),
            remission: None,
            points_in_drive: points.into(),
            sensor_in_drive: origin,
            non_finite_remission: 0,
            moments: Moments::default(),
        }
    }

    #[test]
    fn layout_is_snapped_and_centred() {
        let drive = DriveFrame::at([5e6, -3e5, 40.0]);
        let layout = GridLayout::centred_on([10.13, -3.9], drive, 0.4, 30);
        // floor(10.13 / 0.4) = 25, floor(-3.9 / 0.4) = -10, minus 15 cells.
        assert_eq!(layout.first_cell_key, [10, -25]);
        let [x, y] = layout.min_corner_in_drive();
        assert!((x - 4.0).abs() < 1e-12 && (y + 10.0).abs() < 1e-12);
        // The world's corner is the drive frame's origin away.
        assert_eq!(layout.min_corner_in_world(), [5e6 + x, -3e5 + y]);
        // The sensor lies inside the grid, in cell (15, 15).
        let cell = layout.cell_of_local(10.13 - x, -3.9 - y).unwrap();
        assert_eq!(layout.col_row(cell), (15, 15));
        assert_eq!(layout.cell_key(cell), [25, -10]);
        let [cx, cy] = layout.cell_centre_in_world(cell);
        assert!((cx - (5e6 + 10.2)).abs() < 1e-6 && (cy - (-3e5 - 3.8)).abs() < 1e-6);
        // Moving the sensor by less than a cell keeps every key.
        let moved = GridLayout::centred_on([10.2, -3.7], drive, 0.4, 30);
        assert_eq!(moved, layout);
    }

    #[test]
    fn points_are_sorted_into_cells_and_outside_points_dropped() {
        let layout = GridLayout::centred_on([0.0, 0.0], DriveFrame::default(), 1.0, 4); // x, y in [-2, 2)
        let a = scan(
            vec![[0.5, 0.5, 1.0], [5.0, 0.0, 0.0], [-1.5, -1.5, 2.0]],
            [0.0; 3],
        );
        let b = scan(vec![[0.6, 0.4, 3.0]], [0.5, 0.5, 0.0]);
        let cells = grid_points(&[a, b], layout, &mut GridBuffers::default());
        assert_eq!(cells.points_in_grid.len(), 3);
        let c = layout.cell_of_local(2.5, 2.5).unwrap();
        assert_eq!(cells.point_count(c), 2);
        let r = cells.cell_range(c);
        assert_eq!(cells.points_in_grid[r.start], [2.5, 2.5, 1.0]);
        // b, the newest scan, holds the cell's second point.
        assert_eq!(cells.newest_range(c), r.start + 1..r.end);
        assert_eq!(cells.labels.as_ref().unwrap()[r.start..r.end], [0, 0]);
        // The second point of the cell came from scan b: its range is from b's origin.
        assert!((cells.range_m[r.start + 1] - (0.01f32 + 0.01 + 9.0).sqrt()).abs() < 1e-5);
        assert_eq!(
            cells.point_count(layout.cell_of_local(0.5, 0.5).unwrap()),
            1
        );
        // A result keeps every cell's count and only the newest scan's points.
        let kept = cells.clone().kept_for_outputs(&mut GridBuffers::default());
        assert_eq!(kept.window_points(), 3);
        assert_eq!(kept.newest_len(), 1);
        for cell in 0..layout.cell_count() {
            assert_eq!(kept.point_count(cell), cells.point_count(cell));
            let newest = if cell == c {
                &[[2.6f32, 2.4, 3.0]][..]
            } else {
                &[]
            };
            assert_eq!(kept.newest(cell), newest);
        }
    }

    #[test]
    fn a_window_with_one_unlabelled_scan_has_no_labels() {
        let layout = GridLayout::centred_on([0.0, 0.0], DriveFrame::default(), 1.0, 4);
        let labelled = scan(vec![[0.5, 0.5, 1.0]], [0.0; 3]);
        let mut unlabelled = scan(vec![[0.6, 0.4, 3.0]], [0.0; 3]);
        unlabelled.labels = None;
        assert!(
            grid_points(&[labelled, unlabelled], layout, &mut GridBuffers::default())
                .labels
                .is_none()
        );
    }
}
