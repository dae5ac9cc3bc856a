//! Entry points of the cargo fuzz targets in `fuzz/`, and of the corpus replay and
//! mutation tests in `tests/`: the readers' targets of `travmap-io` (its `fuzzing`
//! feature) and two more over the public faces of the other crates (a model file, a
//! cell dataset). Each feeds arbitrary bytes to one
//! parser of untrusted input. Any result is fine, an error or a value; a panic, an
//! abort or an allocation out of proportion to the input is a bug.

pub use travmap_io::fuzzing::*;

use travmap_core::Config;
use travmap_method::classifier::SvmModel;

use travmap_method::training_set::TrainingSet;
use travmap_outputs::dataset::reading::{Labels, read_training_rows};

/// The readers' targets, which come first.
const READERS: usize = travmap_io::fuzzing::TARGETS.len();

/// Every target by name: the fuzz target `NAME` calls `TARGETS[NAME]`, and its seed
/// corpus is `fuzz/seeds/NAME/`. The readers' targets, then `model` and
/// `dataset_file`.
pub const TARGETS: [(&str, Target); READERS + 2] = {
    let mut all = [("model", model as Target); READERS + 2];
    let mut i = 0;
    while i < READERS {
        all[i] = travmap_io::fuzzing::TARGETS[i];
        i += 1;
    }
    all[READERS + 1] = ("dataset_file", dataset_file);
    all
};

const NAMED: &str = "fuzzed";

/// A cell dataset (Parquet) read back as training rows, as `train` reads it.
pub fn dataset_file(data: &[u8]) {
    with_file(data, "parquet", |path| {
        let mut set = TrainingSet::default();
        // The seeds were extracted with the paper's 20 features: reading them so
        // lets the fuzzer past the settings check into the column readers.
        let mut config = Config::default();
        config.features.groups.clear();
        let _ = read_training_rows(path, &config, &mut set, Labels::GroundTruth);
    });
}

/// A model file, and one prediction with what it loaded.
pub fn model(data: &[u8]) {
    if let Ok(model) = SvmModel::from_json(data, NAMED) {
        let mut scratch = model.scratch();
        let _ = model.decision_value(&vec![0.5; model.dimension()], &mut scratch);
    }
}
