//! Stage 1, integration (METHOD.md section 2): a scan moved into the drive frame (the
//! world moved to the drive's first pose, [`DriveFrame`]) with its own pose, keeping
//! its sensor origin, plus the ground plane of the integrated cloud.
//!
//! Input: a [`Frame`] and its pose in the drive frame. Output: a [`DriveScan`]; the
//! [`IntegrationWindow`] keeps the last n of them and [`ground_normal`] fits the
//! plane of their union.
//!
//! [`DriveFrame`]: travmap_core::posing::DriveFrame

use std::sync::Arc;

use nalgebra::Isometry3;

use travmap_core::config::RemissionScaling;
use travmap_core::frame::Frame;
use travmap_core::geometry::Moments;

/// One scan in the drive frame.
#[derive(Clone, Debug)]
pub struct DriveScan {
    pub index: usize,
    pub stamp_ns: u64,
    /// Shared with the results of the frames that integrate it.
    pub points_in_drive: Arc<Vec<[f32; 3]>>,
    /// Where the sensor was when it took this scan; curvity measures ranges from it.
    pub sensor_in_drive: [f64; 3],
    pub labels: Option<Vec<u32>>,
    /// Remission per point on a 0..1 scale, when the input's is usable.
    pub remission: Option<Vec<f32>>,
    /// Points whose remission was NaN or infinite: then the scan has none usable
    /// (one such value would make every remission feature of its cells NaN).
    pub non_finite_remission: usize,
    /// Moments of `points_in_drive`, so that the plane of several scans costs O(1).
    pub moments: Moments,
}

/// Moves every point of `frame` into the drive frame by `drive_from_velodyne` (the
/// pose is applied in f64), its remission kept where `scaling` can use it and it is
/// finite at every point.
pub fn scan_to_drive(
    frame: Frame,
    drive_from_velodyne: &Isometry3<f64>,
    scaling: RemissionScaling,
) -> DriveScan {
    let m = drive_from_velodyne.to_homogeneous();
    // A loop with no call in it: around `push`'s (or a closure's) the sums went
    // through memory at every point, each waiting for the last one's store.
    let mut moments = Moments::default();
    let mut points_in_drive = vec![[0f32; 3]; frame.points_in_velodyne.len()];
    for (p, out) in frame.points_in_velodyne.iter().zip(&mut points_in_drive) {
        let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64);
        let w = [
            m[(0, 0)] * x + m[(0, 1)] * y + m[(0, 2)] * z + m[(0, 3)],
            m[(1, 0)] * x + m[(1, 1)] * y + m[(1, 2)] * z + m[(1, 3)],
            m[(2, 0)] * x + m[(2, 1)] * y + m[(2, 2)] * z + m[(2, 3)],
        ];
        moments.add(w);
        *out = [w[0] as f32, w[1] as f32, w[2] as f32];
    }
    let points_in_drive = Arc::new(points_in_drive);
    let remission: Option<Vec<f32>> = (frame.remission.is_usable(scaling))
        .then(|| frame.points_in_velodyne.iter().map(|p| p[3]).collect());
    let non_finite_remission = remission.as_deref().map_or(0, count_non_finite);
    DriveScan {
        index: frame.index,
        stamp_ns: frame.stamp_ns,
        points_in_drive,
        sensor_in_drive: [m[(0, 3)], m[(1, 3)], m[(2, 3)]],
        labels: frame.labels,
        remission: remission.filter(|_| non_finite_remission == 0),
        non_finite_remission,
        moments,
    }
}

/// How many of `values` are NaN or infinite: first whether any is, in a pass that
/// vectorises (an exponent of all ones is what NaN and infinity share), then the
/// count where one is (a scan of valid remission costs the one pass).
fn count_non_finite(values: &[f32]) -> usize {
    const EXPONENT: u32 = 0x7f80_0000;
    let special = |v: &f32| v.to_bits() & EXPONENT == EXPONENT;
    let any = values.iter().fold(false, |any, v| any | special(v));
    match any {
        true => values.iter().filter(|v| special(v)).count(),
        false => 0,
    }
}

/// KITTI's HDL-64E remission at the 95th percentile of a scan (0.52-0.55 on the
/// shipped scans): where `features.remission_scale = "scan_p95"` brings every scan.
pub const REFERENCE_REMISSION_P95: f32 = 0.54;

/// Scales a scan's remission so that its 95th percentile is
/// [`REFERENCE_REMISSION_P95`] (a scan without remission, or with none above 0, is
/// left as it is).
pub fn scale_remission_to_reference(scan: &mut DriveScan) {
    let Some(remission) = scan.remission.as_mut() else {
        return;
    };
    if remission.is_empty() {
        return;
    }
    let mut sorted = remission.clone();
    let at = (sorted.len() * 95 / 100).min(sorted.len() - 1);
    let p95 = *sorted.select_nth_unstable_by(at, f32::total_cmp).1;
    if p95 > 0.0 {
        let factor = REFERENCE_REMISSION_P95 / p95;
        remission.iter_mut().for_each(|r| *r *= factor);
    }
}

/// Bins of the remission histogram that [`rank_remission`] reads ranks from.
const RANK_BINS: usize = 1024;

/// Replaces each point's remission by its rank among the scan's, on 0..1: the share
/// of the scan's returns below it (a bin of 1/1024 of the scan's range apart, its
/// points sharing the bin's middle rank). A scale every sensor shares, whatever its
/// calibration; a histogram, not a sort, so it costs three passes over the scan.
pub fn rank_remission(scan: &mut DriveScan) {
    let Some(remission) = scan.remission.as_mut() else {
        return;
    };
    let largest = largest_finite(remission);
    if remission.len() < 2 || largest <= 0.0 {
        return;
    }
    // A multiply, not a divide, per point; NaN and negatives fall in bin 0 (a NaN
    // casts to 0), infinities in the last. Cast through u32: from f32 that is one
    // instruction, to usize several.
    let bins_per_remission = RANK_BINS as f32 / largest;
    let bin_of =
        |r: f32| (r * bins_per_remission).clamp(0.0, (RANK_BINS - 1) as f32) as u32 as usize;
    // Four histograms, a point to each in turn: with one, neighbouring points of the
    // same bin (most are) wait for each other's count to be stored (twice as slow).
    let mut counts = [[0u32; RANK_BINS]; 4];
    let quads = remission.chunks_exact(4);
    for &r in quads.remainder() {
        counts[0][bin_of(r)] += 1;
    }
    for quad in quads {
        for (lane, &r) in quad.iter().enumerate() {
            counts[lane][bin_of(r)] += 1;
        }
    }
    // Each bin's middle rank: the points below it and half of its own.
    let n = remission.len() as f32;
    let mut below = 0u32;
    let mut ranks = [0f32; RANK_BINS];
    for (bin, rank) in ranks.iter_mut().enumerate() {
        let count: u32 = counts.iter().map(|histogram| histogram[bin]).sum();
        *rank = (below as f32 + 0.5 * count as f32) / n;
        below += count;
    }
    for r in remission.iter_mut() {
        *r = ranks[bin_of(*r)];
    }
}

/// The largest finite value of `values`, at least 0. Eight running maxima, so that
/// the compiler keeps them in one vector register (a single one waits on itself).
fn largest_finite(values: &[f32]) -> f32 {
    const LANES: usize = 8;
    let larger = |a: f32, r: f32| if r > a && r < f32::INFINITY { r } else { a };
    let mut lanes = [0f32; LANES];
    let chunks = values.chunks_exact(LANES);
    let rest = chunks.remainder();
    for chunk in chunks {
        for (lane, &r) in lanes.iter_mut().zip(chunk) {
            *lane = larger(*lane, r);
        }
    }
    rest.iter().chain(&lanes).copied().fold(0.0, larger)
}

/// The scans a frame integrates: its own and those of the n - 1 frames before it
/// (METHOD.md section 2). The one place that says which scans those are, which frame
/// to start reading at to fill the window, and when a window starts afresh.
#[derive(Clone, Debug)]
pub struct IntegrationWindow {
    /// n, the scans integrated per frame.
    scans_per_frame: usize,
    /// Ascending frame indices; the last n - 1 once a batch is processed.
    scans: Vec<DriveScan>,
}

impl IntegrationWindow {
    pub fn new(scans_per_frame: usize) -> Self {
        Self {
            scans_per_frame,
            scans: Vec::new(),
        }
    }

    /// The first frame to read so that frame `first` has a full window.
    pub fn warm_up_start(&self, first: usize) -> usize {
        first.saturating_sub(self.scans_per_frame - 1)
    }

    /// The first frame of a selection starting at `first` whose window lies inside it.
    pub fn first_full(&self, first: usize) -> usize {
        first + self.scans_per_frame - 1
    }

    /// Whether a frame `index` starts afresh: it is not after the newest scan (a new
    /// pass over the sequence).
    pub fn restarts_at(&self, index: usize) -> bool {
        self.scans.last().is_some_and(|last| last.index >= index)
    }

    pub fn clear(&mut self) {
        self.scans.clear();
    }

    /// Adds scans of ascending frames after the newest one.
    pub fn extend(&mut self, scans: impl IntoIterator<Item = DriveScan>) {
        self.scans.extend(scans);
    }

    /// Every scan held, ascending.
    pub fn scans(&self) -> &[DriveScan] {
        &self.scans
    }

    /// The window of the scan at position `at` of [`Self::scans`]: it and the scans
    /// of the n - 1 frames before it that are held.
    pub fn window_of(&self, at: usize) -> &[DriveScan] {
        let current = self.scans[at].index;
        let start = self.scans[..=at]
            .iter()
            .rposition(|s| s.index + self.scans_per_frame <= current)
            .map_or(0, |p| p + 1);
        &self.scans[start..=at]
    }

    /// Drops the scans no later frame integrates.
    pub fn forget_old(&mut self) {
        if let Some(newest) = self.scans.last().map(|s| s.index) {
            let n = self.scans_per_frame;
            self.scans.retain(|s| s.index + n > newest);
        }
    }
}

/// Unit normal (z >= 0) of the plane fitted by least squares to all points of
/// `scans`: the ground-plane normal that zeta difference projects on (section 4).
pub fn ground_normal(scans: &[DriveScan]) -> [f64; 3] {
    let mut all = Moments::default();
    for scan in scans {
        all.merge(&scan.moments);
    }
    all.covariance().smallest_eigen().normal
}

#[cfg(test)]
mod tests {
    #[test]
    fn ranks_are_the_same_on_any_scale_of_one_order() {
        let scan = |scale: f32| DriveScan {
            index: 0,
            stamp_ns: 0,
            points_in_drive: Arc::new(vec![[0.0; 3]; 4]),
            sensor_in_drive: [0.0; 3],
            labels: None,
            remission: Some(vec![0.1 * scale, 0.4 * scale, 0.2 * scale, 0.4 * scale]),
            non_finite_remission: 0,
            moments: Moments::default(),
        };
        let (mut unit, mut byte) = (scan(1.0), scan(255.0));
        rank_remission(&mut unit);
        rank_remission(&mut byte);
        assert_eq!(unit.remission, byte.remission);
        // The lowest of four below none (1/8), the two highest share 3/4.
        assert_eq!(unit.remission.unwrap(), vec![0.125, 0.75, 0.375, 0.75]);
    }

    use super::*;

    #[test]
    fn pose_moves_points_and_origin() {
        // 90 degrees about z (velodyne x becomes drive y), 10 m along x.
        let drive_from_velodyne = nalgebra::Isometry3::new(
            nalgebra::Vector3::new(10.0, 0.0, 0.0),
            nalgebra::Vector3::new(0.0, 0.0, std::f64::consts::FRAC_PI_2),
        );
        let frame = Frame {
            index: 4,
            stamp_ns: 7,
            world_from_velodyne: drive_from_velodyne,
            points_in_velodyne: vec![[1.0, 0.0, 2.0, 0.5], [0.0, 1.0, 0.0, 0.1]],
            remission: travmap_core::frame::RemissionScale::Unit,
            labels: None,
            camera: None,
            dropped_points: 0,
            sensors: Vec::new(),
        };
        let scan = scan_to_drive(frame, &drive_from_velodyne, RemissionScaling::AsRead);
        let expected = [[10.0, 1.0, 2.0], [9.0, 0.0, 0.0]];
        for (p, e) in scan.points_in_drive.iter().zip(expected) {
            assert!(p.iter().zip(e).all(|(a, b)| (a - b).abs() < 1e-6), "{p:?}");
        }
        assert_eq!(scan.sensor_in_drive, [10.0, 0.0, 0.0]);
        assert_eq!(scan.moments.count, 2);
        assert_eq!(scan.remission, Some(vec![0.5, 0.1]));
    }

    #[test]
    fn a_scan_with_a_nan_or_infinite_remission_has_none_usable() {
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let frame = Frame {
                index: 0,
                stamp_ns: 0,
                world_from_velodyne: nalgebra::Isometry3::identity(),
                points_in_velodyne: vec![[1.0, 0.0, 2.0, 0.5], [0.0, 1.0, 0.0, bad]],
                remission: travmap_core::frame::RemissionScale::Unit,
                labels: None,
                camera: None,
                dropped_points: 0,
                sensors: Vec::new(),
            };
            let pose = frame.world_from_velodyne;
            let scan = scan_to_drive(frame, &pose, RemissionScaling::ScanRank);
            assert_eq!((scan.remission, scan.non_finite_remission), (None, 1));
            assert_eq!(scan.points_in_drive.len(), 2, "the points stay");
        }
    }

    fn scan(index: usize) -> DriveScan {
        DriveScan {
            index,
            stamp_ns: 0,
            points_in_drive: Arc::default(),
            sensor_in_drive: [0.0; 3],
            labels: None,
            remission: None,
            non_finite_remission: 0,
            moments: Moments::default(),
        }
    }

    #[test]
    fn window_holds_the_last_n_frames_even_across_gaps() {
        let mut window = IntegrationWindow::new(3);
        assert_eq!(window.warm_up_start(5), 3);
        assert_eq!(window.warm_up_start(1), 0);
        assert_eq!(window.first_full(5), 7);
        window.extend([2, 3, 5, 6].map(scan));
        let indices = |scans: &[DriveScan]| scans.iter().map(|s| s.index).collect::<Vec<_>>();
        assert_eq!(indices(window.window_of(1)), [2, 3]);
        // Frame 4 is missing: the window of 5 is 3..=5, so only 3 and 5.
        assert_eq!(indices(window.window_of(2)), [3, 5]);
        assert_eq!(indices(window.window_of(3)), [5, 6]);
        window.forget_old();
        assert_eq!(indices(window.scans()), [5, 6]);
        assert!(window.restarts_at(6) && window.restarts_at(0) && !window.restarts_at(7));
    }
}
