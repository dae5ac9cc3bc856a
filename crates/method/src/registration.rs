//! LiDAR odometry: each scan is registered to a local map of the previous ones, after
//! KISS-ICP (Vizzo, Guadagnino, Mersch, Wiesmann, Behley and Stachniss, "KISS-ICP: In
//! Defense of Point-to-Point ICP", IEEE RA-L 8(2), 2023; reference implementation
//! github.com/PRBonn/kiss-icp, whose 1.3 defaults are the defaults here).
//!
//! Per scan: range filter; two voxel downsamplings keeping the first point per voxel
//! (half a map voxel for the points that enter the map, 1.5 map voxels for the points
//! registered); a constant-velocity prediction; point-to-point ICP against the map
//! (nearest neighbour in the 27 voxels around a point, Geman-McClure weights,
//! Gauss-Newton on SE(3)) with gate and kernel from the adaptive threshold; then the
//! map takes the scan and drops voxels beyond the maximum range. No deskewing: the
//! scans carry no per-point time.
//!
//! Written from the paper and KISS-ICP's description. Departures that keep its answer:
//! the neighbour search skips voxels that cannot hold a nearer point and is skipped for
//! points whose correspondence provably stands (`align`); Gauss-Newton linearises about
//! the sensor, which keeps the normal equations well conditioned far from the origin.
//! Additions: failure checks (`RegistrationError`); a refused scan changes nothing but
//! the prediction of the next one, which spans the time it took.

use std::collections::HashSet;

use nalgebra::{Isometry3, Matrix3, Matrix6, UnitQuaternion, Vector3, Vector6};

use crate::voxel_map::{KeyHash, VoxelMap, pack};
pub use travmap_core::config::RegistrationConfig;
pub use travmap_core::error::{Divergence, RegistrationError, RegistrationStats};

/// Fewest points a scan must keep for registration after range filtering and
/// downsampling. Six fix a pose in theory; a hundred keep a lone wall from trying.
pub const MIN_POINTS: usize = 100;
/// Fewest registered points that must end with a map point within the gate, as a
/// fraction. Consecutive KITTI scans match 97%; a scan 100 m off 12%, noise 11%.
const MIN_MATCHED_FRACTION: f64 = 0.25;

/// Scan-to-map odometry over a sequence of scans.
pub struct Odometry {
    config: RegistrationConfig,
    map: VoxelMap,
    /// Sum of squares and count of the model deviations so far, seeded with the
    /// initial threshold: the adaptive threshold is their RMS.
    deviation_sum2_m2: f64,
    deviation_count: usize,
    world_from_sensor: Isometry3<f64>,
    /// The motion per scan when the last one registered, which predicts the next.
    previous_from_sensor: Isometry3<f64>,
    /// Scans refused since the last registered one.
    refused: u32,
    stats: RegistrationStats,
    scratch: Scratch,
}

/// Buffers kept from scan to scan.
#[derive(Default)]
struct Scratch {
    seen_voxels: HashSet<u64, KeyHash>,
    map_points_in_sensor: Vec<Vector3<f64>>,
    source_in_sensor: Vec<Vector3<f64>>,
    cache: Vec<Cached>,
}

impl Odometry {
    /// `config` should have passed `validate`.
    pub fn new(config: RegistrationConfig) -> Self {
        let voxel_m = config.effective_voxel_size_m();
        Self {
            map: VoxelMap::new(voxel_m, config.max_points_per_voxel),
            deviation_sum2_m2: config.initial_threshold_m.powi(2),
            deviation_count: 1,
            config,
            world_from_sensor: Isometry3::identity(),
            previous_from_sensor: Isometry3::identity(),
            refused: 0,
            stats: RegistrationStats::default(),
            scratch: Scratch::default(),
        }
    }

    /// The pose of the last registered scan.
    pub fn world_from_sensor(&self) -> Isometry3<f64> {
        self.world_from_sensor
    }

    /// What the last successful registration saw.
    pub fn last_stats(&self) -> RegistrationStats {
        self.stats
    }

    /// The adaptive threshold, metres; the correspondence gate is three times it.
    pub fn threshold_m(&self) -> f64 {
        (self.deviation_sum2_m2 / self.deviation_count as f64).sqrt()
    }

    /// Registers one scan, points `[x, y, z, remission]` in the sensor frame (metres;
    /// remission unused; non-finite points skipped) and returns its world_from_sensor,
    /// starting from the motion of the scans before it. The first scan that
    /// registers defines the world: its pose is the identity.
    pub fn register(
        &mut self,
        points_in_sensor: &[[f32; 4]],
    ) -> Result<Isometry3<f64>, RegistrationError> {
        // Refused scans took their time too (scans are taken to be evenly spaced).
        let steps = self.refused + 1;
        let step = self.previous_from_sensor;
        let predicted = (0..steps).fold(self.world_from_sensor, |pose, _| pose * step);
        self.register_from(points_in_sensor, predicted)
    }

    /// Registers one scan as [`Self::register`] does, starting from `predicted`
    /// instead: a recorded pose to refine (the first scan's is taken as it is, and
    /// places the map in the recorded world).
    pub fn register_from(
        &mut self,
        points_in_sensor: &[[f32; 4]],
        predicted: Isometry3<f64>,
    ) -> Result<Isometry3<f64>, RegistrationError> {
        self.downsample(points_in_sensor);
        let Scratch {
            map_points_in_sensor: map_points,
            source_in_sensor: source,
            ..
        } = &self.scratch;
        let (points, needed) = (source.len(), MIN_POINTS);
        // Before the map starts, a scan too sparse to start it (the part of a turn a
        // packet log began with) is where the drive starts: posed there, left out of
        // the map, not a failure.
        if points < needed && self.map.is_empty() {
            return Ok(predicted);
        }
        if points < needed {
            self.refused += 1;
            return Err(RegistrationError::TooFewPoints { points, needed });
        }
        if self.map.is_empty() {
            self.world_from_sensor = predicted;
            self.map.add(map_points, &predicted);
            (self.stats.points, self.refused) = (points, 0);
            return Ok(predicted);
        }

        let sigma_m = self.threshold_m();
        let steps = self.refused + 1;
        let (world_from_sensor, seen, failure) = align(
            &self.map,
            &mut self.scratch,
            predicted,
            sigma_m,
            &self.config,
        );
        let lost = (seen.matched as f64) < MIN_MATCHED_FRACTION * points as f64;
        if let Some(cause) = failure.or(lost.then_some(Divergence::LostMap)) {
            self.refused += 1;
            return Err(RegistrationError::Diverged { cause, seen });
        }

        // KISS-ICP's model error: the deviation's translation plus the largest
        // displacement its rotation causes within range.
        let deviation = predicted.inverse() * world_from_sensor;
        let turn_m = 2.0 * self.config.max_range_m * (deviation.rotation.angle() / 2.0).sin();
        let model_error_m = deviation.translation.vector.norm() + turn_m;
        if model_error_m > self.config.min_motion_m {
            self.deviation_sum2_m2 += model_error_m * model_error_m;
            self.deviation_count += 1;
        }
        self.map
            .add(&self.scratch.map_points_in_sensor, &world_from_sensor);
        let sensor_m = world_from_sensor.translation.vector;
        self.map.remove_beyond(&sensor_m, self.config.max_range_m);
        let moved = self.world_from_sensor.inverse() * world_from_sensor;
        let share = 1.0 / steps as f64;
        let per_step = moved.rotation.powf(share);
        self.previous_from_sensor = match steps {
            1 => moved,
            _ => Isometry3::from_parts((moved.translation.vector * share).into(), per_step),
        };
        (self.world_from_sensor, self.refused) = (world_from_sensor, 0);
        self.stats = seen;
        Ok(world_from_sensor)
    }

    /// Fills the map points (half-voxel grid) and from them the registered points
    /// (1.5-voxel grid), keeping the first point met in each voxel.
    fn downsample(&mut self, points_in_sensor: &[[f32; 4]]) {
        let voxel_m = self.map.voxel_size_m;
        let min2 = self.config.min_range_m.powi(2);
        let max2 = self.config.max_range_m.powi(2);
        let in_range = points_in_sensor.iter().filter_map(|p| {
            let p = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            // NaN fails both comparisons, infinity the second.
            (p.norm_squared() > min2 && p.norm_squared() < max2).then_some(p)
        });
        let s = &mut self.scratch;
        let (seen, map_points) = (&mut s.seen_voxels, &mut s.map_points_in_sensor);
        first_per_voxel(in_range, 0.5 * voxel_m, seen, map_points);
        let map_points = s.map_points_in_sensor.iter().copied();
        first_per_voxel(map_points, 1.5 * voxel_m, seen, &mut s.source_in_sensor);
    }
}

fn first_per_voxel(
    points: impl Iterator<Item = Vector3<f64>>,
    voxel_m: f64,
    seen: &mut HashSet<u64, KeyHash>,
    kept: &mut Vec<Vector3<f64>>,
) {
    seen.clear();
    kept.clear();
    let (inverse_m, mut previous) = (1.0 / voxel_m, None);
    for p in points {
        // Adding 1.5 * 2^52 leaves round(x) in the low mantissa bits: floor(x) except at
        // integers, a third faster than `floor`; any partition into voxels will do here.
        const ROUND: f64 = 6_755_399_441_055_744.0;
        let key = pack([0, 1, 2].map(|a| (p[a] * inverse_m - 0.5 + ROUND).to_bits()));
        // Successive points of a spinning scan mostly share a voxel; one equal to the
        // previous point's is in the set already.
        if previous != Some(key) && seen.insert(key) {
            kept.push(p);
        }
        previous = Some(key);
    }
}

/// A registered point's correspondence, kept across ICP iterations.
#[derive(Clone, Copy, Default)]
struct Cached {
    map_point: Option<Vector3<f64>>,
    clearance_m: f64,
    /// `align`'s motion totals when the search ran.
    motion_at_search: (f64, f64),
}

/// Gauss-Newton normal equations of point-to-point ICP as weighted moments of the
/// points (relative to the sensor) and residuals; the 6x6 system follows from them in
/// closed form. The Jacobian of a residual is [I, -[p]x] for p relative to the sensor.
#[derive(Clone, Copy, Default)]
struct NormalEquations {
    matched: usize,
    weight: f64,
    points: Vector3<f64>,
    outer: Matrix3<f64>,
    residuals: Vector3<f64>,
    torques: Vector3<f64>,
}

impl NormalEquations {
    /// The update: translation, and rotation vector about the sensor.
    fn solve(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let mut h = Matrix6::zeros();
        let skew = self.points.cross_matrix();
        h.fixed_view_mut::<3, 3>(0, 0).fill_diagonal(self.weight);
        h.fixed_view_mut::<3, 3>(0, 3).copy_from(&-skew);
        h.fixed_view_mut::<3, 3>(3, 0).copy_from(&skew);
        let rotational = Matrix3::from_diagonal_element(self.outer.trace()) - self.outer;
        h.fixed_view_mut::<3, 3>(3, 3).copy_from(&rotational);
        let g = Vector6::from_iterator(self.residuals.iter().chain(&self.torques).copied());
        let dx = h.cholesky()?.solve(&-g);
        let finite = dx.iter().all(|v| v.is_finite());
        finite.then(|| (dx.fixed_rows::<3>(0).into(), dx.fixed_rows::<3>(3).into()))
    }
}

/// RMS distance a rigid motion moves a point set, in O(1) from the set's moments:
/// E|(R - I)q + t|^2 = tr((2I - R - R^T) E[qq^T]) + 2t.(R - I)E[q] + |t|^2.
fn rms_shift_m(points: &[Vector3<f64>]) -> impl Fn(&Isometry3<f64>) -> f64 {
    let n = points.len().max(1) as f64;
    let mean = points.iter().sum::<Vector3<f64>>() / n;
    let outer = points
        .iter()
        .map(|q| q * q.transpose())
        .sum::<Matrix3<f64>>()
        / n;
    move |motion| {
        let r = motion.rotation.to_rotation_matrix().into_inner();
        let (t, i) = (motion.translation.vector, Matrix3::<f64>::identity());
        let rotated2 = ((2.0 * i - r - r.transpose()) * outer).trace();
        (rotated2 + 2.0 * t.dot(&((r - i) * mean)) + t.norm_squared())
            .max(0.0)
            .sqrt()
    }
}

/// Point-to-point ICP of the registered points against the map from `predicted`, with
/// gate 3 sigma and kernel sigma: the estimate, what was seen, and why it failed.
///
/// A point that moved less than `clearance - distance to its correspondence` since its
/// last search keeps that correspondence: no other map point can have come nearer.
/// After the first iterations the updates are millimetres and nearly all points keep
/// theirs, so this gives the full search's answer in a fraction of its time. An update
/// moves a point at range r by at most |dt| + 2 sin(|dw|/2) r; running sums of the two
/// terms bound the motion since any iteration.
fn align(
    map: &VoxelMap,
    scratch: &mut Scratch,
    predicted: Isometry3<f64>,
    sigma_m: f64,
    config: &RegistrationConfig,
) -> (Isometry3<f64>, RegistrationStats, Option<Divergence>) {
    let Scratch {
        source_in_sensor: source,
        cache,
        ..
    } = scratch;
    let (gate_m, points) = (3.0 * sigma_m, source.len());
    let mut seen = RegistrationStats {
        points,
        gate_m,
        ..Default::default()
    };
    let (mut world_from_sensor, shift_m) = (predicted, rms_shift_m(source));
    cache.clear();
    cache.resize(points, Cached::default());
    let mut motion = (0.0, 0.0);
    while seen.iterations < config.max_iterations {
        seen.iterations += 1;
        let rotation = world_from_sensor.rotation.to_rotation_matrix();
        let sensor_m = world_from_sensor.translation.vector;
        // Run on two threads over chunks of points, this loop made the whole
        // registration no faster on the two shared cores it was measured on.
        let mut total = NormalEquations::default();
        for (q, c) in source.iter().zip(cache.iter_mut()) {
            let relative = rotation * q;
            let p = relative + sensor_m;
            let moved_m =
                motion.0 - c.motion_at_search.0 + (motion.1 - c.motion_at_search.1) * q.norm();
            let kept = c.map_point.filter(|m| {
                let d_m = (p - m).norm();
                // 1e-9 m covers rounding; the second test keeps m within the 27 voxels.
                d_m + moved_m + 1e-9 < c.clearance_m && d_m < map.voxel_size_m
            });
            let Some(m) = kept.or_else(|| {
                let (map_point, clearance_m) = map.nearest(&p, gate_m);
                let motion_at_search = motion;
                *c = Cached {
                    map_point,
                    clearance_m,
                    motion_at_search,
                };
                map_point
            }) else {
                continue;
            };
            let residual = p - m;
            // Geman-McClure as KISS-ICP writes it: sigma^2 / (sigma + e^2)^2.
            let w = sigma_m * sigma_m / (sigma_m + residual.norm_squared()).powi(2);
            total.matched += 1;
            total.weight += w;
            total.points += w * relative;
            total.outer += w * relative * relative.transpose();
            total.residuals += w * residual;
            total.torques += w * relative.cross(&residual);
        }
        seen.matched = total.matched;
        if total.matched < 3 {
            return (world_from_sensor, seen, Some(Divergence::LostMap));
        }
        let Some((translation, turn)) = total.solve() else {
            return (world_from_sensor, seen, Some(Divergence::Degenerate));
        };
        motion.0 += translation.norm();
        motion.1 += 2.0 * (turn.norm() / 2.0).sin();
        // The rotation turns about the sensor, so the sensor moves by the translation.
        let rotation = UnitQuaternion::from_scaled_axis(turn) * world_from_sensor.rotation;
        world_from_sensor = Isometry3::from_parts((sensor_m + translation).into(), rotation);
        // Checked at every step, so that noise fails in a few iterations, not hundreds.
        seen.shift_m = shift_m(&(predicted.inverse() * world_from_sensor));
        if seen.shift_m > gate_m {
            return (world_from_sensor, seen, Some(Divergence::JumpTooLarge));
        }
        if translation.norm_squared() + turn.norm_squared() < config.convergence.powi(2) {
            return (world_from_sensor, seen, None);
        }
    }
    (world_from_sensor, seen, Some(Divergence::NotConverged))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    type Outcome = Result<Isometry3<f64>, RegistrationError>;

    /// A 40 x 30 x 6 m room with three 4 m square pillars: a jittered 2 m grid on every
    /// face, thinned so that no two points are within 0.9 m. Every point then has its
    /// own half-metre voxel and enters the map, and the true pose matches each
    /// registered point exactly.
    fn room() -> Vec<Vector3<f64>> {
        let mut seed = 0x9E37_79B9_7F4A_7C15_u64;
        let mut jitter = move || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 0.6 - 0.3
        };
        let mut boxes: Vec<([f64; 3], [f64; 3])> = vec![([-20.0, -15.0, -1.8], [20.0, 15.0, 4.2])];
        for [x, y] in [[5.0, 3.0], [-9.0, -7.0], [2.0, -11.0]] {
            boxes.push(([x, y, -1.8], [x + 4.0, y + 4.0, 4.2]));
        }
        let mut points: Vec<Vector3<f64>> = Vec::new();
        for ((lo, hi), k) in boxes.iter().flat_map(|b| (0..6).map(move |k| (b, k))) {
            let (u, v) = ((k + 1) % 3, (k + 2) % 3);
            let cells = |a: usize| ((hi[a] - lo[a]) / 2.0).round() as usize;
            for (i, j) in (0..cells(u)).flat_map(|i| (0..cells(v)).map(move |j| (i, j))) {
                let mut p = Vector3::repeat([lo, hi][k / 3][k % 3]);
                let at = |a: usize, i: usize| (i as f64 + 0.5) / cells(a) as f64;
                p[u] = lo[u] + (hi[u] - lo[u]) * at(u, i) + jitter();
                p[v] = lo[v] + (hi[v] - lo[v]) * at(v, j) + jitter();
                if points.iter().all(|q| (p - q).norm() > 0.9) {
                    points.push(p);
                }
            }
        }
        points
    }

    fn scan(world: &[Vector3<f64>], world_from_sensor: &Isometry3<f64>) -> Vec<[f32; 4]> {
        let sensor_from_world = world_from_sensor.inverse();
        let in_sensor = world.iter().map(|p| sensor_from_world * Point3::from(*p));
        in_sensor
            .map(|p| [p.x as f32, p.y as f32, p.z as f32, 0.5])
            .collect()
    }

    fn pose(x_m: f64, y_m: f64, yaw_deg: f64) -> Isometry3<f64> {
        let roll = 0.2_f64.to_radians();
        let rotation = UnitQuaternion::from_euler_angles(roll, 0.0, yaw_deg.to_radians());
        Isometry3::from_parts(Vector3::new(x_m, y_m, 0.02).into(), rotation)
    }

    fn run(scans: &[Vec<[f32; 4]>], config: RegistrationConfig) -> (Odometry, Vec<Outcome>) {
        let mut odometry = Odometry::new(config);
        let outcomes = scans.iter().map(|s| odometry.register(s)).collect();
        (odometry, outcomes)
    }

    fn in_room(poses: &[Isometry3<f64>]) -> Vec<Vec<[f32; 4]>> {
        let world = room();
        poses.iter().map(|t| scan(&world, t)).collect()
    }

    fn assert_near(estimate: &Outcome, truth: &Isometry3<f64>) {
        let error = truth.inverse() * estimate.as_ref().unwrap();
        let mm = error.translation.vector.norm() * 1e3;
        let deg = error.rotation.angle().to_degrees();
        assert!(mm < 1.0 && deg < 0.01, "off by {mm} mm, {deg} deg");
    }

    fn divergence(outcome: &Outcome) -> (Divergence, RegistrationStats) {
        match outcome {
            Err(RegistrationError::Diverged { cause, seen }) => (*cause, *seen),
            _ => panic!("{outcome:?}"),
        }
    }

    #[test]
    fn a_known_motion_is_recovered_in_a_synthetic_room() {
        let step = pose(0.35, -0.1, 1.5);
        let truths = [0, 1, 2, 3].map(|n| (0..n).fold(Isometry3::identity(), |t, _| t * step));
        let (odometry, estimates) = run(&in_room(&truths), RegistrationConfig::default());
        for (estimate, truth) in estimates.iter().zip(&truths) {
            assert_near(estimate, truth);
        }
        let seen = odometry.last_stats();
        assert_eq!(seen.matched, seen.points, "{seen:?}");
    }

    #[test]
    fn kept_correspondences_are_those_a_fresh_search_finds() {
        let scans = in_room(&[Isometry3::identity(), pose(0.5, 0.2, 2.0)]);
        let (mut odometry, _) = run(&scans[..1], RegistrationConfig::default());
        odometry.downsample(&scans[1]);
        let (mut config, mut before) = (RegistrationConfig::default(), Isometry3::identity());
        for iterations in 1..=8 {
            config.max_iterations = iterations;
            let s = &mut odometry.scratch;
            let (after, ..) = align(&odometry.map, s, Isometry3::identity(), 2.0, &config);
            // The cache holds the correspondences of the last iteration, made at `before`.
            let rotation = before.rotation.to_rotation_matrix();
            for (q, c) in s.source_in_sensor.iter().zip(&s.cache) {
                let p = rotation * q + before.translation.vector;
                assert_eq!(c.map_point, odometry.map.nearest(&p, 6.0).0);
            }
            let searched_at = s.cache.iter().map(|c| c.motion_at_search.0);
            let latest = searched_at.clone().fold(0.0, f64::max);
            let kept = searched_at.filter(|&m| m < latest).count();
            assert!(
                iterations < 5 || 2 * kept > s.cache.len(),
                "{iterations}: {kept}"
            );
            before = after;
        }
    }

    #[test]
    fn scans_too_sparse_before_the_map_starts_are_where_the_drive_starts() {
        let mut scans = in_room(&[pose(0.0, 0.0, 0.0), pose(1.0, 2.0, 30.0)]);
        scans[0].truncate(40);
        let far_away = Isometry3::translation(0.0, 0.0, 500.0);
        scans.insert(1, scan(&room(), &far_away));
        let (_, outcomes) = run(&scans, RegistrationConfig::default());
        // Neither starts the map: the third scan does, where they are.
        let start = Ok(Isometry3::identity());
        assert_eq!(outcomes, [start.clone(), start.clone(), start]);
    }

    #[test]
    fn a_refused_scan_is_bridged_at_the_same_velocity() {
        let step = pose(0.35, -0.1, 1.5);
        let truths = [0, 1, 2, 3].map(|n| (0..n).fold(Isometry3::identity(), |t, _| t * step));
        let mut scans = in_room(&truths);
        scans[2].truncate(10);
        let (odometry, outcomes) = run(&scans, RegistrationConfig::default());
        assert!(matches!(
            outcomes[2],
            Err(RegistrationError::TooFewPoints { .. })
        ));
        assert_near(&outcomes[3], &truths[3]);
        // The prediction spanned the refused scan, so it was right at once.
        assert_eq!(odometry.last_stats().iterations, 1);
    }

    #[test]
    fn non_finite_points_are_skipped() {
        let clean = in_room(&[Isometry3::identity(), pose(0.3, 0.0, 1.0)]);
        let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
        let mut dirty = clean.clone();
        dirty[0] = (clean[0].iter().enumerate())
            .flat_map(|(i, p)| [*p, [bad[i % 3], 1.0, 2.0, 0.0], [1.0, 2.0, bad[i % 3], 0.0]])
            .collect();
        let config = RegistrationConfig::default();
        assert_eq!(run(&clean, config.clone()).1, run(&dirty, config).1);
    }

    #[test]
    fn a_jump_of_100_m_diverges_and_leaves_the_odometry_as_it_was() {
        let jump = Isometry3::translation(-100.0, 0.0, 0.0);
        let truth = pose(0.4, 0.1, 1.0);
        let scans = in_room(&[Isometry3::identity(), jump, truth]);
        let (_, outcomes) = run(&scans, RegistrationConfig::default());
        let (cause, seen) = divergence(&outcomes[1]);
        assert_eq!((cause, seen.matched), (Divergence::LostMap, 0));
        assert_near(&outcomes[2], &truth);
    }

    #[test]
    fn noise_diverges() {
        let mut seed = 7_u64;
        let mut uniform = move |scale: f32| {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            ((seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * scale
        };
        let mut scans = in_room(&[Isometry3::identity()]);
        scans.push(
            (0..3000)
                .map(|_| [uniform(60.0), uniform(60.0), uniform(10.0), 0.0])
                .collect(),
        );
        // Noise drifts for hundreds of iterations before it fails; the cap keeps the
        // debug-build test short.
        let config = RegistrationConfig {
            max_iterations: 40,
            ..Default::default()
        };
        divergence(&run(&scans, config).1[1]);
    }

    #[test]
    fn a_correction_beyond_the_gate_is_a_jump() {
        // A turn of 3 degrees moves the points 0.8 m RMS: ICP, led by the points near
        // the sensor, walks past a 0.5 m gate; the default 6 m gate accepts it.
        let truth = pose(0.0, 0.0, 3.0);
        let scans = in_room(&[Isometry3::identity(), truth]);
        let config = RegistrationConfig {
            initial_threshold_m: 0.5 / 3.0,
            ..Default::default()
        };
        let (cause, seen) = divergence(&run(&scans, config).1[1]);
        assert!(
            cause == Divergence::JumpTooLarge && seen.shift_m > seen.gate_m,
            "{seen:?}"
        );
        assert_near(&run(&scans, RegistrationConfig::default()).1[1], &truth);
    }

    #[test]
    fn the_configuration_reads_and_checks() {
        let config: RegistrationConfig = serde_json::from_str(r#"{"max_range_m": 50}"#).unwrap();
        assert_eq!(config.effective_voxel_size_m(), 0.5);
        assert_eq!(config.validate(), Ok(()));
        let typo = serde_json::from_str::<RegistrationConfig>(r#"{"max_rnage_m": 50}"#);
        assert!(typo.is_err());
        let bad = RegistrationConfig {
            min_range_m: 200.0,
            ..Default::default()
        };
        assert!(bad.validate().unwrap_err().contains("min_range_m"));
    }
}
