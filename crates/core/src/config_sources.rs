//! Where a configuration comes from, in the one order every front end uses: the
//! defaults, then a TOML file, then each assignment (`--set`, `set=`), then the model
//! chosen by name (`--model`, `model=`), which beats the others and says so when
//! they named another.

use std::path::{Path, PathBuf};

use crate::config::{Config, ModelChoice};
use crate::error::Error;
use crate::option_files::{TEXT_MAX_BYTES, read_option_text};

/// What a front end was given to configure a run with.
#[derive(Clone, Copy, Default)]
pub struct ConfigSources<'a> {
    /// A TOML file of settings.
    pub file: Option<&'a Path>,
    /// `section.key=value` assignments, in order.
    pub assignments: &'a [String],
    /// The model by name (`road`, `offroad` or a file's path).
    pub model: Option<&'a str>,
    /// How the front end spells its assignments and its model in errors and notices
    /// (`--set` and `--model`; `set=` and `model=`).
    pub spelling: Spelling,
}

/// How a front end spells the assignment and the model it takes.
#[derive(Clone, Copy)]
pub struct Spelling {
    pub assignment: &'static str,
    pub model: &'static str,
}

impl Default for Spelling {
    fn default() -> Self {
        Self {
            assignment: "--set",
            model: "--model",
        }
    }
}

/// The effective configuration, and what is said of how it was assembled.
pub struct Assembled {
    pub config: Config,
    /// The model chosen by name differs from the one the file or an assignment
    /// named: the chosen one is used, and this says so.
    pub model_notice: Option<String>,
    /// Where the model used was named, when a file or an assignment named it
    /// (`classifier.model = "m.json" of robot.toml`): its errors say so.
    pub model_named_by: Option<String>,
}

/// Why a configuration could not be assembled: a file that cannot be read (an
/// error of the input), or a mistake in what was given (a usage error).
#[derive(Debug)]
pub enum AssemblyError {
    File(Error),
    Usage(String),
}

impl From<Error> for AssemblyError {
    fn from(error: Error) -> Self {
        AssemblyError::File(error)
    }
}

impl ConfigSources<'_> {
    /// The effective configuration (checked: [`Config::ready`]).
    pub fn assemble(&self) -> Result<Assembled, AssemblyError> {
        let spelling = self.spelling;
        let (mut config, mut model_named_by) = match self.file {
            Some(path) => {
                let file = read_toml_file(path)?;
                let named = file.names_model.then(|| {
                    format!(
                        "classifier.model = \"{}\" of {}",
                        file.config.classifier.model,
                        path.display()
                    )
                });
                (file.config, named)
            }
            None => (Config::default(), None),
        };
        for assignment in self.assignments {
            config.set(assignment).map_err(|e| {
                AssemblyError::Usage(format!("{} {assignment}: {e}", spelling.assignment))
            })?;
            let key = assignment.split_once('=').map_or("", |(key, _)| key.trim());
            if key == "classifier.model" {
                model_named_by = Some(format!("{} {assignment}", spelling.assignment));
            }
        }
        let mut model_notice = None;
        if let Some(text) = self.model {
            let named_by = model_named_by.take();
            let chosen = ModelChoice::named(text).map_err(|problem| {
                AssemblyError::Usage(format!("{} {text:?}: {problem}", spelling.model))
            })?;
            if let Some(named_by) = named_by.filter(|_| config.classifier.model != chosen) {
                model_notice = Some(format!(
                    "{} {text} is used, not the {named_by}",
                    spelling.model
                ));
            }
            config.classifier.model = chosen;
        }
        config
            .ready()
            .map_err(|e| AssemblyError::Usage(e.to_string()))?;
        Ok(Assembled {
            config,
            model_notice,
            model_named_by,
        })
    }
}

/// A configuration file read: its settings, with the paths in it taken from its
/// own folder (as cargo reads its config files), and whether it names the model.
pub struct ConfigFile {
    pub config: Config,
    pub names_model: bool,
}

/// Reads a TOML configuration file (see [`ConfigFile`]).
pub fn read_toml_file(path: &Path) -> crate::error::Result<ConfigFile> {
    let text = read_option_text(path, TEXT_MAX_BYTES)?;
    let invalid = |e: &dyn std::fmt::Display| Error::Config(format!("{}: {e}", path.display()));
    let table: toml::Table = toml::from_str(&text).map_err(|e| invalid(&e))?;
    let names_model = (table.get("classifier"))
        .and_then(|classifier| classifier.get("model"))
        .is_some();
    let mut config: Config = table.try_into().map_err(|e| invalid(&e))?;
    let folder = path.parent().unwrap_or(Path::new(""));
    let from_folder = |relative: &mut PathBuf| {
        if relative.is_relative() {
            *relative = folder.join(&*relative);
        }
    };
    if let ModelChoice::File(model) = &mut config.classifier.model {
        from_folder(model);
    }
    if let Some(label_map) = &mut config.ground_truth.label_map {
        from_folder(label_map);
    }
    Ok(ConfigFile {
        config,
        names_model,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::LabelRule;

    #[test]
    fn the_model_named_beats_the_configurations_and_says_so_once() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("c.toml");
        std::fs::write(&file, "[classifier]\nmodel = \"road\"\n").unwrap();
        let assembled = ConfigSources {
            file: Some(&file),
            model: Some("offroad"),
            ..Default::default()
        }
        .assemble()
        .unwrap();
        assert_eq!(
            assembled.config.classifier.model,
            ModelChoice::Embedded(LabelRule::Offroad)
        );
        let notice = assembled.model_notice.unwrap();
        assert!(
            notice.starts_with("--model offroad is used, not the classifier.model = \"road\" of"),
            "{notice}"
        );
        let sets = ["classifier.model=road".to_string()];
        let assembled = ConfigSources {
            assignments: &sets,
            model: Some("offroad"),
            ..Default::default()
        }
        .assemble()
        .unwrap();
        assert_eq!(
            assembled.model_notice.as_deref(),
            Some("--model offroad is used, not the --set classifier.model=road")
        );
        // The same model twice, or only by default: nothing to say.
        let assembled = ConfigSources {
            model: Some("road"),
            ..Default::default()
        }
        .assemble()
        .unwrap();
        assert!(assembled.model_notice.is_none());
    }

    #[test]
    fn an_empty_model_name_is_a_usage_error() {
        let sources = ConfigSources {
            model: Some(""),
            ..Default::default()
        };
        match sources.assemble() {
            Err(AssemblyError::Usage(message)) => assert!(
                message.contains("road, offroad or a model file's path"),
                "{message}"
            ),
            _ => panic!("an empty model name must be refused"),
        }
    }

    #[test]
    fn paths_in_a_config_file_are_read_from_its_folder() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("robot")).unwrap();
        let file = dir.path().join("robot/c.toml");
        std::fs::write(
            &file,
            "[classifier]\nmodel = \"m.json\"\n[ground_truth]\nlabel_map = \"map.toml\"\n",
        )
        .unwrap();
        let read = read_toml_file(&file).unwrap();
        assert!(read.names_model);
        assert_eq!(
            read.config.classifier.model,
            ModelChoice::File(dir.path().join("robot/m.json"))
        );
        assert_eq!(
            read.config.ground_truth.label_map,
            Some(dir.path().join("robot/map.toml"))
        );
    }
}
