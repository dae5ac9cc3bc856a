//! Work that hands on items one at a time from a thread of its own: Python takes
//! them as it iterates, releasing the interpreter while it waits, and an iteration
//! left early stops the work at its next item. What the work says of the drive at
//! its end (a poor fit, frames skipped) reaches Python as warnings when the
//! iteration ends.

use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Mutex};

use pyo3::prelude::*;
use travmap_run::DriveRun;

use crate::{Failure, warn, warn_incomplete};

/// Items made ahead of the one Python holds: enough to keep the work busy while
/// Python looks at a frame, few enough that a drive is never held whole.
const AHEAD: usize = 4;

/// What the work sends.
enum Sent<T> {
    Item(T),
    Failed(Failure),
    /// Notices of the drive, to warn with at the end.
    Said(Vec<String>),
}

/// Where the work sends its items; `send` says whether anyone still takes them.
pub(crate) struct Sender<T>(SyncSender<Sent<T>>);

impl<T> Sender<T> {
    pub(crate) fn send(&self, item: T) -> bool {
        self.0.send(Sent::Item(item)).is_ok()
    }

    /// Notices of the drive, said when the iteration ends.
    pub(crate) fn say(&self, notices: Vec<String>) {
        // Nobody listening: nobody to warn.
        let _ = self.0.send(Sent::Said(notices));
    }
}

/// The items of work over a drive running on its own thread, in order; then its
/// failure, if it failed, or its notices as warnings, with one more when the drive
/// completed with frames skipped or parts lost (where the command exits 3).
pub(crate) struct Stream<T> {
    items: Mutex<Receiver<Sent<T>>>,
    /// The drive read and what the work said of it, until its end is reached.
    ending: Mutex<Option<(Arc<DriveRun>, Vec<String>)>>,
}

impl<T: Send + 'static> Stream<T> {
    pub(crate) fn spawn(
        drive: Arc<DriveRun>,
        work: impl FnOnce(&Sender<T>) -> Result<(), Failure> + Send + 'static,
    ) -> Self {
        let (sender, receiver) = sync_channel(AHEAD);
        std::thread::spawn(move || {
            let sender = Sender(sender);
            if let Err(failure) = work(&sender) {
                // Nobody may be listening any more: then the failure has no one to tell.
                let _ = sender.0.send(Sent::Failed(failure));
            }
        });
        Self {
            items: Mutex::new(receiver),
            ending: Mutex::new(Some((drive, Vec::new()))),
        }
    }

    /// The next item, None when the work is done; waits without the interpreter.
    pub(crate) fn next(&self, py: Python<'_>) -> PyResult<Option<T>> {
        loop {
            let received = py.detach(|| {
                let receiver = (self.items.lock()).unwrap_or_else(|poisoned| poisoned.into_inner());
                receiver.recv()
            });
            let mut ending = self.ending.lock().unwrap_or_else(|p| p.into_inner());
            match received {
                Ok(Sent::Item(item)) => return Ok(Some(item)),
                Ok(Sent::Failed(failure)) => return Err(failure.into()),
                Ok(Sent::Said(notices)) => {
                    if let Some((_, said)) = ending.as_mut() {
                        said.extend(notices);
                    }
                }
                Err(_) => {
                    if let Some((drive, said)) = ending.take() {
                        said.iter().try_for_each(|notice| warn(py, notice))?;
                        warn_incomplete(py, &drive)?;
                    }
                    return Ok(None);
                }
            }
        }
    }
}
