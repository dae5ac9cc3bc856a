//! `--keep-going`: frames whose input is unreadable, skipped and recorded instead of
//! ending the run.

use travmap_core::error::{Error, Result};

/// A frame left out because its input was unreadable (`--keep-going`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Skip {
    pub frame: usize,
    pub reason: String,
}

/// `reason` without its clause telling to pass --keep-going: a bracket holding it,
/// or from the comma or semicolon before it to the clause's end.
fn without_keep_going_hint(reason: &str) -> String {
    let mut said = reason.to_string();
    while let Some(at) = said.find("--keep-going") {
        let start = said[..at].rfind(['(', ';', ',']).unwrap_or(at);
        let closing: &[char] = match said[start..].starts_with('(') {
            true => &[')'],
            false => &[';', ')'],
        };
        let end = said[at..].find(closing).map_or(said.len(), |e| at + e);
        let end = end + usize::from(said[start..].starts_with('(') && end < said.len());
        said.replace_range(start..end, "");
    }
    said.trim_end().to_string()
}

/// The error of a command that read no frame of `inputs` (in words), so that
/// `output` is not written: with the skips (the first one's reason), or that none
/// was selected. Every command says it so.
pub fn nothing_read(output: &std::path::Path, inputs: String, skipped: &[Skip]) -> Error {
    Error::NothingWritten {
        path: output.to_path_buf(),
        inputs,
        why: why_none_read(skipped),
    }
}

/// Why a run read no frame, in words: the skips (the first one's reason), or that
/// none was selected.
fn why_none_read(skipped: &[Skip]) -> String {
    match skipped.first() {
        Some(first) => format!(
            "{} skipped; frame {}: {}",
            skipped.len(),
            first.frame,
            first.reason
        ),
        None => "none selected".into(),
    }
}

/// Whether a frame whose input is unreadable stops the run (the default) or is
/// skipped and recorded, and the record.
#[derive(Clone, Debug, Default)]
pub struct SkipLog {
    keep_going: bool,
    skipped: std::sync::Arc<std::sync::Mutex<Vec<Skip>>>,
    /// What of the input could not be read beside whole frames (a recording cut
    /// short), in words: read on past, with or without --keep-going, and counted.
    lost: Vec<String>,
}

impl SkipLog {
    /// An empty record; `keep_going` false: the first unreadable frame ends the run.
    pub fn new(keep_going: bool) -> Self {
        Self {
            keep_going,
            skipped: Default::default(),
            lost: Vec::new(),
        }
    }

    /// Records a part of the input that could not be read (`why`, in words).
    pub fn record_lost(&mut self, why: String) {
        self.lost.push(why);
    }

    /// The parts of the input that could not be read, besides skipped frames.
    pub fn lost(&self) -> &[String] {
        &self.lost
    }

    /// Records `error` for `frame` when keeping going, else returns it.
    pub fn handle(&self, frame: usize, error: Error) -> Result<()> {
        if !self.keep_going {
            return Err(error);
        }
        // The whole chain: "cannot read x.bin: No such file or directory".
        let mut reason = error.to_string();
        let mut cause = std::error::Error::source(&error);
        while let Some(inner) = cause {
            reason.push_str(&format!(": {inner}"));
            cause = inner.source();
        }
        // The error's advice to pass --keep-going is moot here: it was passed.
        let reason = without_keep_going_hint(&reason);
        if let Ok(mut skipped) = self.skipped.lock()
            && !skipped
                .iter()
                .any(|s| s.frame == frame && s.reason == reason)
        {
            // Passes over the same input (passthrough, then the method) report a frame once.
            skipped.push(Skip { frame, reason });
        }
        Ok(())
    }

    pub fn keeps_going(&self) -> bool {
        self.keep_going
    }

    /// The frames skipped, by frame number (frames are read on several threads, so
    /// they are met in no fixed order).
    pub fn skipped(&self) -> Vec<Skip> {
        let mut skipped = self.skipped.lock().map(|s| s.clone()).unwrap_or_default();
        skipped.sort_by_key(|s| s.frame);
        skipped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_skip_says_its_reason_without_the_advice_to_keep_going() {
        for (reason, said) in [
            (
                "x.bin: 0 bytes, no points: a scan file that was never written (--keep-going skips it)",
                "x.bin: 0 bytes, no points: a scan file that was never written",
            ),
            (
                "frame 0: 7 points left; scans take --poses none (each scan alone), --keep-going skips the scans that do not register",
                "frame 0: 7 points left; scans take --poses none (each scan alone)",
            ),
            (
                "no return: nothing to map (a failed sensor?); --keep-going skips the frame",
                "no return: nothing to map (a failed sensor?)",
            ),
            (
                "chunk at 7 is damaged (bad CRC): it is lost (--keep-going reads on past it)",
                "chunk at 7 is damaged (bad CRC): it is lost",
            ),
        ] {
            assert_eq!(without_keep_going_hint(reason), said);
        }
    }
}
