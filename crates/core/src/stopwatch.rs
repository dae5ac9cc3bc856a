//! Wall-clock timing of the stages, in milliseconds.

use std::time::Instant;

/// Started at creation; [`Stopwatch::lap_ms`] reads and restarts it.
#[derive(Clone, Copy, Debug)]
pub struct Stopwatch(Instant);

impl Stopwatch {
    pub fn start() -> Self {
        Self(Instant::now())
    }

    /// Milliseconds since the start (or the last lap).
    pub fn elapsed_ms(&self) -> f64 {
        self.0.elapsed().as_secs_f64() * 1e3
    }

    /// Milliseconds since the start (or the last lap), and starts again.
    pub fn lap_ms(&mut self) -> f64 {
        let ms = self.elapsed_ms();
        self.0 = Instant::now();
        ms
    }
}

/// Runs `f` and returns its value with the milliseconds it took.
pub fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let watch = Stopwatch::start();
    let value = f();
    (value, watch.elapsed_ms())
}
