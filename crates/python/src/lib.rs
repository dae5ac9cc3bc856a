//! The native part of travmap's Python module (`travmap._travmap`; the package
//! `python/travmap/` re-exports it): a drive opened as the command line opens it
//! (`drive`), a model run over it (`model`). Frames and grids come from a
//! thread of their own (`stream`) while Python holds no lock it needs, and reach
//! Python as NumPy arrays that own the library's buffers: no copy per point or cell.

mod drive;
mod model;
mod stream;

use pyo3::prelude::*;

pyo3::create_exception!(
    travmap,
    TravmapError,
    pyo3::exceptions::PyException,
    "What the command line reports as `error: ...`, with its exit code: 1 an error \
     (nothing written), 2 a mistake in the arguments or settings, 3 completed with \
     frames skipped (`keep_going=True`)."
);

pyo3::create_exception!(
    travmap,
    TravmapWarning,
    pyo3::exceptions::PyUserWarning,
    "What the command says of a drive on stderr: a poor fit to the model, remission \
     it could not use, labels of ids the label set does not define; or that it was \
     read to its end with frames skipped (`keep_going=True`) or parts of it lost (a \
     recording cut short), where the command completes with exit code 3."
);

/// Warns when `drive` completed with frames skipped or parts lost, as the command
/// line exits 3 then: a silent shorter result would look complete.
pub(crate) fn warn_incomplete(py: Python<'_>, drive: &travmap_run::DriveRun) -> PyResult<()> {
    let (skipped, lost) = (drive.source.skipped().len(), drive.source.lost().len());
    if skipped + lost == 0 {
        return Ok(());
    }
    warn(
        py,
        &format!(
            "{}: completed with {skipped} skipped frame(s) and {lost} lost part(s) of the input (Drive.skipped and Drive.lost say which)",
            drive.source.path().display()
        ),
    )
}

/// A `TravmapWarning` saying `notice`.
pub(crate) fn warn(py: Python<'_>, notice: &str) -> PyResult<()> {
    let message = std::ffi::CString::new(notice).unwrap_or_default();
    PyErr::warn(py, &py.get_type::<TravmapWarning>(), &message, 1)
}

/// A failure as the command line reports it: the message after `error: ` and the
/// exit code.
#[derive(Debug)]
pub(crate) struct Failure {
    message: String,
    exit_code: u8,
}

impl Failure {
    /// An error of reading or running (exit code 1), with the causes it carries.
    pub(crate) fn of(error: &dyn std::error::Error) -> Self {
        let mut message = error.to_string();
        let mut cause = error.source();
        while let Some(error) = cause {
            message = format!("{message}: {error}");
            cause = error.source();
        }
        Self {
            message,
            exit_code: 1,
        }
    }

    /// A mistake in the arguments or settings (exit code 2).
    pub(crate) fn usage(message: String) -> Self {
        Self {
            message,
            exit_code: 2,
        }
    }
}

impl From<Failure> for PyErr {
    fn from(failure: Failure) -> Self {
        Python::attach(|py| {
            let error = TravmapError::new_err(failure.message);
            // Setting an attribute on a fresh exception cannot fail.
            let _ = error.value(py).setattr("exit_code", failure.exit_code);
            error
        })
    }
}

impl From<travmap_core::Error> for Failure {
    fn from(error: travmap_core::Error) -> Self {
        Failure::of(&error)
    }
}

/// A buffer that does not fill the array it was to become (a reader's bug, never
/// the input's): an error, not a crash of the interpreter.
pub(crate) fn shape_error(error: numpy::ndarray::ShapeError) -> PyErr {
    pyo3::exceptions::PyRuntimeError::new_err(format!("an array of the wrong shape: {error}"))
}

#[pymodule]
fn _travmap(module: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = module.py();
    module.add("TravmapError", py.get_type::<TravmapError>())?;
    module.add("TravmapWarning", py.get_type::<TravmapWarning>())?;
    module.add_class::<drive::Drive>()?;
    module.add_class::<drive::Frame>()?;
    module.add_class::<drive::Frames>()?;
    module.add_class::<model::Model>()?;
    module.add_class::<model::Grid>()?;
    module.add_class::<model::Grids>()?;
    module.add_function(wrap_pyfunction!(drive::open, module)?)?;
    module.add_function(wrap_pyfunction!(model::run, module)?)?;
    Ok(())
}
