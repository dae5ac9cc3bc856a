//! Where reading meets the method: a [`Selection`] is a [`Source`] and the frames
//! of it to use, and [`Selection::run`] feeds them through a [`Pipeline`].

use std::ops::Range;

use crate::config::Config;
use crate::error::{Error, Result};
use crate::io::Source;
use crate::method::classifier::SvmModel;
use crate::method::pipeline::{FrameResult, Pipeline};
use crate::stopwatch::Stopwatch;

/// A drive and the frames of it to use.
pub struct Selection {
    pub source: Source,
    pub frames: Range<usize>,
    /// Give each result its scan's SHA-256 (`FrameResult::scan_sha256`): costs a
    /// few milliseconds a frame, so only where a frame's identity matters.
    pub fingerprint_scans: bool,
}

impl Selection {
    pub fn new(source: Source, frames: Range<usize>) -> Self {
        Self {
            source,
            frames,
            fingerprint_scans: false,
        }
    }

    /// Runs the pipeline over the selected frames, reading the n - 1 frames before
    /// the first one to fill the window, and hands each result to `on_frame`, which
    /// may return its own error type (the binary's, say).
    pub fn run<E: From<Error>>(
        &self,
        config: &Config,
        model: Option<&SvmModel>,
        mut on_frame: impl FnMut(FrameResult) -> Result<(), E>,
    ) -> Result<(), E> {
        let mut pipeline = Pipeline::new(config)?;
        let first = self.frames.start;
        let frames = pipeline.window().warm_up_start(first)..self.frames.end;
        // Reading time: from the end of one frame's work to the arrival of the next.
        let mut reading = Stopwatch::start();
        for frame in self.source.read(&frames) {
            let frame = frame?;
            let read_ms = reading.lap_ms();
            if frame.index < first {
                pipeline.warm_up(frame);
            } else {
                let scan_sha256 = self.fingerprint_scans.then(|| frame.content_sha256());
                let mut result = pipeline.process_frame(frame, model);
                result.timings.read_ms = read_ms;
                result.scan_sha256 = scan_sha256;
                on_frame(result)?;
            }
            reading.lap_ms();
        }
        Ok(())
    }

    /// The input and the frames of it, as a person reads them.
    pub fn describe(&self) -> String {
        let last = self.source.frames_in(&self.frames).last().copied();
        match last {
            Some(last) => format!(
                "{} frames {}..={}",
                self.source.path().display(),
                self.frames.start,
                last
            ),
            None => format!("{} (no frames in range)", self.source.path().display()),
        }
    }
}
