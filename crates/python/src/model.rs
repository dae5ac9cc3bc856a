//! `travmap.Model` and `travmap.run`: the method run over a drive, each frame's
//! grid handed to Python as NumPy arrays: the numbers `travmap run --json` prints.

use std::path::PathBuf;
use std::sync::Arc;

use numpy::ndarray::{Array2, Array3};
use numpy::{PyArray2, PyArray3};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use travmap_core::config::ModelChoice;
use travmap_core::error::Error;
use travmap_method::classifier::SvmModel;
use travmap_method::features::feature_names;
use travmap_method::grid::CellClass;
use travmap_method::layers::{Layer, layer_values};
use travmap_method::pipeline::{FrameResult, StageTimings};
use travmap_run::scoring::evaluation::Evaluation;
use travmap_run::scoring::remarks::{FitRemedies, drive_notices};

use crate::drive::{Drive, Opening, pose_array, remission_word};
use crate::stream::Stream;
use crate::{Failure, shape_error};

/// A traversability model: `"road"` (a car's road; the default) or `"offroad"` (a
/// robot that may also drive on grass, dirt and low vegetation), both compiled in,
/// or the path of a model file `travmap train` or `travmap adapt` wrote.
#[pyclass(module = "travmap", frozen)]
pub struct Model {
    model: Arc<SvmModel>,
    /// The name it is reported by (`embedded road model`, or the file's path).
    #[pyo3(get)]
    name: String,
}

#[pymethods]
impl Model {
    #[new]
    #[pyo3(signature = (model=None))]
    fn new(py: Python<'_>, model: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        match model {
            Some(model) => Self::named(py, model),
            None => Self::chosen(
                py,
                &ModelChoice::Embedded(travmap_core::config::LabelRule::Road),
            ),
        }
    }

    /// The model's grids of every frame of `drive` (a `travmap.open`ed drive), in
    /// order, as they are computed.
    fn run(&self, drive: &Drive) -> PyResult<Grids> {
        self.model
            .check_compatible(&drive.config, &self.name)
            .map_err(Failure::from)?;
        let (model, selection, config) = (
            self.model.clone(),
            drive.selection.clone(),
            drive.config.clone(),
        );
        Ok(Grids(Stream::spawn(selection.clone(), move |sender| {
            let mut evaluation = Evaluation::default();
            let ran = selection.run::<Stop>(&config, Some(&model), |result| {
                evaluation.add(&result);
                match sender.send(GridValues::of(result)) {
                    true => Ok(()),
                    false => Err(Stop::NoOneListens),
                }
            });
            match ran {
                Ok(()) => {
                    let remedies = FitRemedies::of(std::slice::from_ref(&*selection), false, None);
                    sender.say(drive_notices(
                        &evaluation.report(),
                        &model,
                        &config,
                        remedies,
                    ));
                    Ok(())
                }
                Err(Stop::NoOneListens) => Ok(()),
                Err(Stop::Failed(error)) => Err(Failure::of(&error)),
            }
        })))
    }

    /// Support vectors of the classifier.
    #[getter]
    fn support_vectors(&self) -> usize {
        self.model.support_vector_count()
    }

    /// The features the model reads, in order.
    #[getter]
    fn feature_names(&self) -> Vec<String> {
        self.model.feature_names()
    }

    /// Whether it reads camera appearance (a hybrid model).
    #[getter]
    fn uses_appearance(&self) -> bool {
        self.model.uses_appearance()
    }

    fn __repr__(&self) -> String {
        format!(
            "<travmap.Model {} ({} support vectors)>",
            self.name,
            self.model.support_vector_count()
        )
    }
}

/// How a run ended early: the method failed, or Python left the iteration.
enum Stop {
    Failed(Error),
    NoOneListens,
}

impl From<Error> for Stop {
    fn from(error: Error) -> Self {
        Stop::Failed(error)
    }
}

/// Runs `model` over the input at `path` (opened as `travmap.open` opens it, with
/// the same keywords) and yields each frame's grid, as `travmap run` does: camera
/// images are decoded only when the model reads them, labels not at all.
#[pyfunction]
#[pyo3(signature = (path, model=None, frames=None, **settings))]
pub(crate) fn run(
    py: Python<'_>,
    path: PathBuf,
    model: Option<&Bound<'_, PyAny>>,
    frames: Option<&Bound<'_, PyAny>>,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<Grids> {
    let opening = Opening::of(frames, settings)?;
    let model = match model {
        Some(model) if model.is_instance_of::<Model>() => model.cast::<Model>()?.get().clone(),
        Some(model) => Model::named(py, model)?,
        None => Model::chosen(py, &opening.config.classifier.model)?,
    };
    let images = model.model.reads_images(&opening.config);
    let drive = opening.open(path, images, false)?;
    model.run(&drive)
}

impl Model {
    /// The model `model` names: `road`, `offroad` or a model file's path; a
    /// TypeError names the argument when it is neither text nor a path.
    fn named(py: Python<'_>, model: &Bound<'_, PyAny>) -> PyResult<Self> {
        let named = match model.extract::<PathBuf>() {
            Ok(path) => path.to_string_lossy().into_owned(),
            Err(_) => {
                return Err(pyo3::exceptions::PyTypeError::new_err(format!(
                    "model={}: \"road\", \"offroad\" (compiled in) or a model file's path",
                    model.repr()?
                )));
            }
        };
        let choice = ModelChoice::named(&named).map_err(Failure::usage)?;
        if let ModelChoice::File(path) = &choice
            && !path.exists()
        {
            return Err(Failure::usage(format!(
                "model {named:?}: no such file; the compiled-in models are \"road\" and \"offroad\""
            ))
            .into());
        }
        Self::chosen(py, &choice)
    }

    fn chosen(py: Python<'_>, choice: &ModelChoice) -> PyResult<Self> {
        let (model, name) = py.detach(|| SvmModel::read(choice).map_err(Failure::from))?;
        Ok(Self {
            model: Arc::new(model),
            name,
        })
    }
}

impl Clone for Model {
    fn clone(&self) -> Self {
        Self {
            model: self.model.clone(),
            name: self.name.clone(),
        }
    }
}

/// The grids of a run, frame by frame, as they are computed: an iterator, each grid
/// handed out once (a second loop over the same Grids is empty; `list(...)` keeps
/// them).
#[pyclass(module = "travmap", frozen)]
pub struct Grids(Stream<GridValues>);

#[pymethods]
impl Grids {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&self, py: Python<'_>) -> PyResult<Option<Grid>> {
        self.0
            .next(py)?
            .map(|values| values.into_grid(py))
            .transpose()
    }
}

/// What of a frame's result reaches Python, taken on the run's thread (moved, not
/// copied) so that the interpreter only wraps it.
struct GridValues {
    result: FrameResult,
    classes: Vec<i8>,
    predicted: Vec<i8>,
    occupancy: Vec<i8>,
}

/// A cell's class as a number: 1 traversable, 0 not, -1 unknown.
fn class_number(class: CellClass) -> i8 {
    match class {
        CellClass::Traversable => 1,
        CellClass::NonTraversable => 0,
        CellClass::Unknown => -1,
    }
}

impl GridValues {
    fn of(result: FrameResult) -> Self {
        let numbers = |classes: Option<&Vec<CellClass>>, number: fn(CellClass) -> i8| {
            classes.map_or_else(Vec::new, |c| c.iter().map(|&class| number(class)).collect())
        };
        Self {
            classes: numbers(result.filtered.as_ref(), class_number),
            predicted: numbers(result.predicted.as_ref(), class_number),
            occupancy: numbers(result.filtered.as_ref(), CellClass::occupancy),
            result,
        }
    }

    fn into_grid(self, py: Python<'_>) -> PyResult<Grid> {
        let GridValues {
            result,
            classes,
            predicted,
            occupancy,
        } = self;
        let side = result.layout.cells_per_side;
        let square = |values: Vec<i8>| -> PyResult<Py<PyAny>> {
            let grid = Array2::from_shape_vec((side, side), values).map_err(shape_error)?;
            Ok(PyArray2::from_owned_array(py, grid).into_any().unbind())
        };
        let layer = |layer: Layer| -> PyResult<Py<PyAny>> {
            let values = layer_values(&result, layer, 0.0).unwrap_or_default();
            let grid = Array2::from_shape_vec((side, side), values).map_err(shape_error)?;
            Ok(PyArray2::from_owned_array(py, grid).into_any().unbind())
        };
        let probability = layer(Layer::Traversability)?;
        let elevation = layer(Layer::Elevation)?;
        let elevation_range = layer(Layer::ElevationRange)?;
        let unsure = layer(Layer::Unsure)?;
        let features = result.features;
        let dimension = features.dimension;
        let names = feature_names(&features.groups);
        let values = Array3::from_shape_vec((side, side, dimension), features.values)
            .map_err(shape_error)?;
        let predictable =
            Array2::from_shape_vec((side, side), features.predictable).map_err(shape_error)?;
        let margins = result.margins.unwrap_or_default();
        let decision = Array2::from_shape_vec((side, side), margins).map_err(shape_error)?;
        let [x, y] = result.layout.min_corner_in_world();
        Ok(Grid {
            index: result.index,
            stamp_ns: result.stamp_ns,
            cell_size_m: result.layout.cell_size_m,
            cells_per_side: side,
            min_corner_in_world: (x, y),
            occupancy: square(occupancy)?,
            traversable: square(classes)?,
            predicted: square(predicted)?,
            decision: PyArray2::from_owned_array(py, decision).into_any().unbind(),
            probability,
            elevation,
            elevation_range,
            unsure,
            predictable: PyArray2::from_owned_array(py, predictable)
                .into_any()
                .unbind(),
            features: PyArray3::from_owned_array(py, values).into_any().unbind(),
            feature_names: names,
            world_from_sensor: pose_array(py, &result.world_from_velodyne),
            timings: timings_dict(py, &result.timings)?,
            dropped_points: result.dropped_points,
            remission: remission_word(result.remission),
            without_remission: result.without_remission,
        })
    }
}

/// The stage timings as `run --json` writes them, ms by stage.
fn timings_dict(py: Python<'_>, timings: &StageTimings) -> PyResult<Py<PyAny>> {
    let dict = PyDict::new(py);
    if let Ok(serde_json::Value::Object(stages)) = serde_json::to_value(timings) {
        for (stage, ms) in stages {
            dict.set_item(stage, ms.as_f64())?;
        }
    }
    Ok(dict.into_any().unbind())
}

/// One frame's grid: square arrays indexed `[row, col]`, row 0 the southmost (min
/// y), col 0 the westmost (min x), as `run --json` lists its `cells` row by row;
/// `matplotlib.pyplot.imshow(grid.traversable, origin="lower", extent=grid.extent)`
/// draws it in world metres.
#[pyclass(module = "travmap", frozen)]
pub struct Grid {
    /// The frame's number in its drive.
    #[pyo3(get)]
    index: usize,
    #[pyo3(get)]
    stamp_ns: u64,
    #[pyo3(get)]
    cell_size_m: f64,
    #[pyo3(get)]
    cells_per_side: usize,
    /// World x, y (metres) of the grid's min corner.
    #[pyo3(get)]
    min_corner_in_world: (f64, f64),
    /// int8 occupancy after the outlier filter, as `run --json`'s `cells` and
    /// nav2's OccupancyGrid: 0 traversable, 100 not, -1 unknown (`cells` too).
    #[pyo3(get)]
    occupancy: Py<PyAny>,
    /// int8 after the outlier filter: 1 traversable, 0 not, -1 unknown (`classes`
    /// too).
    #[pyo3(get)]
    traversable: Py<PyAny>,
    /// int8 class as the classifier predicted it, before the filter.
    #[pyo3(get)]
    predicted: Py<PyAny>,
    /// float32 margin (decision value minus threshold; > 0 traversable), NaN where
    /// unpredictable.
    #[pyo3(get)]
    decision: Py<PyAny>,
    /// float32 P(traversable) by the model's calibration, before the filter; NaN
    /// where unpredictable.
    #[pyo3(get)]
    probability: Py<PyAny>,
    /// float32 world z of the ground under the cell (its lowest point of the
    /// frame's scan), metres; NaN where the scan has no point in it.
    #[pyo3(get)]
    elevation: Py<PyAny>,
    /// float32 highest minus lowest point of the cell over the window, metres; NaN
    /// where unpredictable.
    #[pyo3(get)]
    elevation_range: Py<PyAny>,
    /// float32 1 where the margin lies within 1 of the boundary (the fit report's
    /// unsure cells), 0 elsewhere, NaN where unpredictable.
    #[pyo3(get)]
    unsure: Py<PyAny>,
    /// bool: the cell had points enough for features.
    #[pyo3(get)]
    predictable: Py<PyAny>,
    /// float32 [row, col, feature], named by `feature_names`; 0 where unpredictable.
    #[pyo3(get)]
    features: Py<PyAny>,
    #[pyo3(get)]
    feature_names: Vec<String>,
    /// 4 x 4 float64: the sensor's pose (estimated when registration posed it).
    #[pyo3(get)]
    world_from_sensor: Py<PyAny>,
    /// Milliseconds by stage, as `run --json`'s `timings`.
    #[pyo3(get)]
    timings: Py<PyAny>,
    #[pyo3(get)]
    dropped_points: usize,
    #[pyo3(get)]
    remission: String,
    /// The window had no usable remission: the model's fallback classified it.
    #[pyo3(get)]
    without_remission: bool,
}

#[pymethods]
impl Grid {
    /// `occupancy`, by the name it had first.
    #[getter]
    fn cells(&self, py: Python<'_>) -> Py<PyAny> {
        self.occupancy.clone_ref(py)
    }

    /// `traversable`, by the name it had first.
    #[getter]
    fn classes(&self, py: Python<'_>) -> Py<PyAny> {
        self.traversable.clone_ref(py)
    }

    /// (x_min, x_max, y_min, y_max) in world metres, for `imshow(extent=...)`.
    #[getter]
    fn extent(&self) -> (f64, f64, f64, f64) {
        let (x, y) = self.min_corner_in_world;
        let size_m = self.cell_size_m * self.cells_per_side as f64;
        (x, x + size_m, y, y + size_m)
    }

    fn __repr__(&self) -> String {
        format!(
            "<travmap.Grid frame {}: {} x {} cells of {} m>",
            self.index, self.cells_per_side, self.cells_per_side, self.cell_size_m
        )
    }
}
