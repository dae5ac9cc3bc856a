//! `travmap.open`: a drive read as the command line reads it, its frames handed to
//! Python one at a time with their points as NumPy arrays.

use std::ops::Range;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use numpy::ndarray::{Array2, Array3};
use numpy::{PyArray1, PyArray2, PyArray3};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyRange, PyRangeMethods};
use travmap_core::Config;
use travmap_core::config_sources::{AssemblyError, ConfigSources, Spelling};
use travmap_core::frame::Frame as ReadFrame;
use travmap_io::{
    LidarCalibrations, LidarFrames, LogOptions, MergedTopics, SourceOptions, WORLD_FRAME,
};
use travmap_run::DriveRun;
use travmap_run::opening::{open_selection, parse_frame_range, scan_rate_hz};

use crate::stream::Stream;
use crate::{Failure, shape_error};

/// The keywords `open` and `run` take: the command line's flags by their long names,
/// and `images` (whether camera images are decoded), the module's own.
const KEYWORDS: [&str; 12] = [
    "config",
    "set",
    "poses",
    "cloud_topic",
    "lidar_calibration",
    "lidar_frame",
    "world_frame",
    "camera_topic",
    "pose_topic",
    "rate",
    "keep_going",
    "images",
];

/// How a drive is opened: the configuration, how its input is read, which frames,
/// and whether camera images are decoded (None: as the caller decides).
pub(crate) struct Opening {
    pub(crate) config: Config,
    options: SourceOptions,
    frames: Option<Range<usize>>,
    images: Option<bool>,
}

impl Opening {
    /// The keywords of `open` (the command line's flags by their long names).
    pub(crate) fn of(
        frames: Option<&Bound<'_, PyAny>>,
        settings: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let text = |key: &str| -> PyResult<Option<String>> {
            settings
                .and_then(|s| s.get_item(key).transpose())
                .transpose()?
                .filter(|value| !value.is_none())
                .map(|value| value.extract())
                .transpose()
        };
        // A flag the command line repeats: one text or a list of them.
        let texts = |key: &str| -> PyResult<Vec<String>> {
            let Some(value) = settings
                .and_then(|s| s.get_item(key).transpose())
                .transpose()?
            else {
                return Ok(Vec::new());
            };
            if value.is_none() {
                Ok(Vec::new())
            } else if let Ok(one) = value.extract::<String>() {
                Ok(vec![one])
            } else {
                value.extract()
            }
        };
        if let Some(settings) = settings {
            for key in settings.keys() {
                let key: String = key.extract()?;
                if !KEYWORDS.contains(&key.as_str()) {
                    return Err(pyo3::exceptions::PyTypeError::new_err(format!(
                        "unexpected keyword argument '{key}' (known: {})",
                        KEYWORDS.join(", ")
                    )));
                }
            }
        }
        let config = configuration(
            text("config")?.map(PathBuf::from),
            &assignments(settings)?,
            text("poses")?,
        )?;
        let (cloud_topic, merged_topics) = MergedTopics::from_arguments(&texts("cloud_topic")?);
        let flag = |flag: &str, problem: String| Failure::usage(format!("{flag}: {problem}"));
        let log = LogOptions {
            cloud_topic,
            merged_topics,
            world_frame: text("world_frame")?,
            camera_topic: text("camera_topic")?,
            pose_topic: text("pose_topic")?,
            lidar_calibrations: LidarCalibrations::from_arguments(&texts("lidar_calibration")?)
                .map_err(|problem| flag("lidar_calibration", problem))?,
            lidar_frames: LidarFrames::from_arguments(&texts("lidar_frame")?)
                .map_err(|problem| flag("lidar_frame", problem))?,
        };
        let flag_value = |key: &str| settings.and_then(|s| s.get_item(key).ok().flatten());
        let options = SourceOptions {
            poses: config.integration.poses,
            keep_going: flag_value("keep_going").map_or(Ok(false), |v| v.is_truthy())?,
            log,
            rate_hz: (flag_value("rate").map(|v| v.extract::<f64>()).transpose()?)
                .map(|hz| {
                    scan_rate_hz(hz)
                        .map_err(|expected| Failure::usage(format!("rate: {expected}, got {hz:?}")))
                })
                .transpose()?,
            site_tile_m: None,
        };
        let images = flag_value("images").map(|v| v.is_truthy()).transpose()?;
        Ok(Self {
            config,
            options,
            frames: frames.map(frame_range).transpose()?.flatten(),
            images,
        })
    }

    /// Opens `path` as every command does, its drive surveyed as a run needs;
    /// `images` decodes camera images unless the keyword said otherwise.
    pub(crate) fn open(self, path: PathBuf, images: bool, labels: bool) -> PyResult<Drive> {
        let Opening {
            config,
            options,
            frames,
            images: asked,
        } = self;
        let notices = Mutex::new(Vec::new());
        let heard = |remark: travmap_run::opening::Remark, text: &str| {
            let mut notices = notices.lock().unwrap_or_else(|p| p.into_inner());
            notices.push(format!("{}: {text}", remark.word()));
        };
        let selection = Python::attach(|py| {
            py.detach(|| -> Result<DriveRun, Failure> {
                let mut selection =
                    open_selection(&path, frames, &options, asked.unwrap_or(images), &heard)?;
                selection.source.set_read_labels(labels);
                let notice = |text: &str| heard(travmap_run::opening::Remark::Notice, text);
                selection.survey(&config, &notice)?;
                Ok(selection)
            })
        })?;
        Ok(Drive {
            selection: Arc::new(selection),
            config,
            notices: notices.into_inner().unwrap_or_else(|p| p.into_inner()),
        })
    }
}

/// The configuration: `file`'s or the defaults, then each assignment, then
/// `poses`; mistakes in them are usage errors, as on the command line.
fn configuration(
    file: Option<PathBuf>,
    assignments: &[String],
    poses: Option<String>,
) -> Result<Config, Failure> {
    let poses = poses.map(|poses| format!("integration.poses={poses}"));
    let assignments: Vec<String> = assignments.iter().cloned().chain(poses).collect();
    let sources = ConfigSources {
        file: file.as_deref(),
        assignments: &assignments,
        model: None,
        spelling: Spelling {
            assignment: "set",
            model: "model=",
        },
    };
    match sources.assemble() {
        Ok(assembled) => Ok(assembled.config),
        Err(AssemblyError::File(error)) => Err(error.into()),
        Err(AssemblyError::Usage(message)) => Err(Failure::usage(message)),
    }
}

/// `set={"grid.size_m": 24}` or `set=["grid.size_m=24"]`, as `SECTION.KEY=VALUE`.
fn assignments(settings: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<String>> {
    let Some(set) = settings
        .and_then(|s| s.get_item("set").transpose())
        .transpose()?
    else {
        return Ok(Vec::new());
    };
    if let Ok(table) = set.cast::<PyDict>() {
        return table
            .iter()
            .map(|(key, value)| {
                let value = if let Ok(flag) = value.extract::<bool>() {
                    flag.to_string()
                } else {
                    value.str()?.to_string()
                };
                Ok(format!("{}={value}", key.str()?))
            })
            .collect();
    }
    if let Ok(one) = set.extract::<String>() {
        return Ok(vec![one]);
    }
    set.extract().map_err(|_| {
        pyo3::exceptions::PyTypeError::new_err(format!(
            "set={}: a dict ({{\"grid.size_m\": 24}}) or a list of \"section.key=value\" texts",
            set.repr().map(|r| r.to_string()).unwrap_or_default()
        ))
    })
}

/// `frames=`: None (every frame), a frame number, a `range` (step 1) or the
/// command line's `A..B` / `A..=B` / `A..`.
fn frame_range(frames: &Bound<'_, PyAny>) -> PyResult<Option<Range<usize>>> {
    if frames.is_none() {
        return Ok(None);
    }
    if let Ok(n) = frames.extract::<i64>() {
        return match usize::try_from(n) {
            Ok(n) => Ok(Some(n..n + 1)),
            Err(_) => Err(Failure::usage(format!("frames={n}: frame numbers start at 0")).into()),
        };
    }
    if let Ok(text) = frames.extract::<String>() {
        return parse_frame_range(&text)
            .map(Some)
            .map_err(|problem| Failure::usage(problem).into());
    }
    if let Ok(range) = frames.cast::<PyRange>() {
        let (start, stop, step) = (range.start()?, range.stop()?, range.step()?);
        if step == 1 && start >= 0 && stop > start {
            return Ok(Some(start as usize..stop as usize));
        }
        return Err(Failure::usage(format!(
            "frames=range({start}, {stop}, {step}): give a range of consecutive frames, step 1, that selects at least one"
        ))
        .into());
    }
    Err(pyo3::exceptions::PyTypeError::new_err(format!(
        "frames={}: None, a frame number, a range, or text as on the command line (\"A..B\", \"A..=B\", \"A..\")",
        frames.repr()?
    )))
}

/// Opens a drive: a KITTI / SemanticKITTI sequence directory, a recorded log (MCAP,
/// ROS 1 bag, rosbag2 directory or .db3, pcap capture) or a folder of scans: any
/// input the `travmap` command reads.
///
/// frames: None (every frame), a frame number, a range, or "A..B" / "A..=B" / "A..".
/// Keywords are the command line's flags by their long names: config (a TOML file),
/// set ({"grid.size_m": 24} or ["grid.size_m=24"]), poses, cloud_topic,
/// lidar_calibration, lidar_frame (text or a list of them), world_frame,
/// camera_topic, pose_topic, rate (Hz), keep_going; images=False skips decoding
/// camera images. Raises TravmapError with the command line's message.
#[pyfunction]
#[pyo3(signature = (path, frames=None, **settings))]
pub(crate) fn open(
    path: PathBuf,
    frames: Option<&Bound<'_, PyAny>>,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<Drive> {
    Opening::of(frames, settings)?.open(path, true, true)
}

/// A drive opened: its frames in order (iterate it), how many (`len`), and what
/// opening it noticed.
#[pyclass(module = "travmap", frozen)]
pub struct Drive {
    pub(crate) selection: Arc<DriveRun>,
    pub(crate) config: Config,
    notices: Vec<String>,
}

#[pymethods]
impl Drive {
    fn __len__(&self) -> usize {
        self.frame_numbers().len()
    }

    fn __iter__(&self) -> Frames {
        let selection = self.selection.clone();
        Frames(Stream::spawn(selection.clone(), move |sender| {
            for frame in selection.source.read(&selection.frames) {
                if !sender.send(frame?) {
                    break;
                }
            }
            Ok(())
        }))
    }

    fn __repr__(&self) -> String {
        format!(
            "<travmap.Drive {} ({}, {} frames)>",
            self.selection.source.path().display(),
            self.selection.source.kind().name(),
            self.__len__()
        )
    }

    /// The input's path.
    #[getter]
    fn path(&self) -> PathBuf {
        self.selection.source.path().to_path_buf()
    }

    /// What kind of input it is (a KITTI sequence, a recorded log, ...).
    #[getter]
    fn kind(&self) -> &'static str {
        self.selection.source.kind().name()
    }

    /// The numbers of the frames it hands on, in order.
    #[getter]
    fn frames(&self) -> Vec<usize> {
        self.frame_numbers()
    }

    /// What the command line would print as `notice: ...` or `warning: ...` on
    /// opening it (how it is read, what does not apply to it).
    #[getter]
    fn notices(&self) -> Vec<String> {
        self.notices.clone()
    }

    /// Frames left out as unreadable so far (`keep_going=True`): (frame, reason).
    #[getter]
    fn skipped(&self) -> Vec<(usize, String)> {
        let skipped = self.selection.source.skipped();
        skipped.into_iter().map(|s| (s.frame, s.reason)).collect()
    }

    /// Parts of the input lost beside whole frames (a recording cut short).
    #[getter]
    fn lost(&self) -> Vec<String> {
        self.selection.source.lost().to_vec()
    }

    /// The frame the poses are in (`world_from_sensor` maps into it).
    #[getter]
    fn world_frame(&self) -> String {
        match self.selection.source.world_frame() {
            "" => WORLD_FRAME.to_string(),
            frame => frame.to_string(),
        }
    }
}

impl Drive {
    fn frame_numbers(&self) -> Vec<usize> {
        self.selection.source.frames_in(&self.selection.frames)
    }
}

/// The frames of a drive as they are read.
#[pyclass(module = "travmap", frozen)]
pub struct Frames(Stream<ReadFrame>);

#[pymethods]
impl Frames {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&self, py: Python<'_>) -> PyResult<Option<Frame>> {
        self.0
            .next(py)?
            .map(|frame| Frame::of(py, frame))
            .transpose()
    }
}

/// One LiDAR scan as read: its points in the sensor frame, its pose and stamp, its
/// labels and camera image where the input has them.
#[pyclass(module = "travmap", frozen)]
pub struct Frame {
    /// The frame's number in its drive.
    #[pyo3(get)]
    index: usize,
    /// Nanoseconds since the drive began (a log's own clock for recorded logs).
    #[pyo3(get)]
    stamp_ns: u64,
    /// N x 4 float32: x, y, z (metres, in the sensor frame) and remission (0..1
    /// where usable, else 0).
    #[pyo3(get)]
    points: Py<PyAny>,
    /// N uint32 SemanticKITTI labels (lower 16 bits class), or None.
    #[pyo3(get)]
    labels: Py<PyAny>,
    /// 4 x 4 float64: the sensor's pose in the world frame.
    #[pyo3(get)]
    world_from_sensor: Py<PyAny>,
    /// H x W x 3 uint8 RGB camera image, or None.
    #[pyo3(get)]
    image: Py<PyAny>,
    /// 3 x 4 float64: homogeneous sensor coordinates to homogeneous pixels (a
    /// rectified image), or None.
    #[pyo3(get)]
    image_from_sensor: Py<PyAny>,
    /// Points the reader dropped as no return (NaN, infinite, at the origin).
    #[pyo3(get)]
    dropped_points: usize,
    /// The remission scale found: unit, byte, missing or unknown.
    #[pyo3(get)]
    remission: String,
    /// The cloud topics merged into this scan (several sensors), else empty.
    #[pyo3(get)]
    sensors: Vec<String>,
}

impl Frame {
    fn of(py: Python<'_>, frame: ReadFrame) -> PyResult<Self> {
        let count = frame.points_in_velodyne.len();
        let points = Array2::from_shape_vec((count, 4), frame.points_in_velodyne.into_flattened())
            .map_err(shape_error)?;
        let none = || py.None();
        let labels = frame.labels.map_or_else(none, |labels| {
            PyArray1::from_vec(py, labels).into_any().unbind()
        });
        let (image, image_from_sensor) = match frame.camera {
            Some(camera) => {
                let (w, h) = (camera.image.width as usize, camera.image.height as usize);
                let pixels =
                    Array3::from_shape_vec((h, w, 3), camera.image.rgb).map_err(shape_error)?;
                let projection =
                    Array2::from_shape_fn((3, 4), |(r, c)| camera.image_from_velodyne[(r, c)]);
                (
                    PyArray3::from_owned_array(py, pixels).into_any().unbind(),
                    PyArray2::from_owned_array(py, projection)
                        .into_any()
                        .unbind(),
                )
            }
            None => (none(), none()),
        };
        Ok(Self {
            index: frame.index,
            stamp_ns: frame.stamp_ns,
            points: PyArray2::from_owned_array(py, points).into_any().unbind(),
            labels,
            world_from_sensor: pose_array(py, &frame.world_from_velodyne),
            image,
            image_from_sensor,
            dropped_points: frame.dropped_points,
            remission: remission_word(frame.remission),
            sensors: frame.sensors,
        })
    }
}

#[pymethods]
impl Frame {
    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let points = self.points.bind(py).len()?;
        Ok(format!(
            "<travmap.Frame {} at {} ns: {points} points>",
            self.index, self.stamp_ns
        ))
    }
}

/// A pose as a 4 x 4 float64 array.
pub(crate) fn pose_array(py: Python<'_>, pose: &nalgebra::Isometry3<f64>) -> Py<PyAny> {
    let matrix = pose.to_homogeneous();
    let rows = Array2::from_shape_fn((4, 4), |(r, c)| matrix[(r, c)]);
    PyArray2::from_owned_array(py, rows).into_any().unbind()
}

/// The remission scale as the JSON output writes it (`unit`, `byte`, ...).
pub(crate) fn remission_word(scale: travmap_core::frame::RemissionScale) -> String {
    match serde_json::to_value(scale) {
        Ok(serde_json::Value::String(word)) => word,
        other => unreachable!("a remission scale is written as a word, not {other:?}"),
    }
}
