//! Work that hands on items one at a time from a thread of its own: Python takes
//! them as it iterates, releasing the interpreter while it waits, and an iteration
//! left early stops the work at its next item.

use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Mutex};

use pyo3::prelude::*;
use travmap_run::DriveRun;

use crate::{Failure, warn_incomplete};

/// Items made ahead of the one Python holds: enough to keep the work busy while
/// Python looks at a frame, few enough that a drive is never held whole.
const AHEAD: usize = 4;

/// Where the work sends its items; `send` says whether anyone still takes them.
pub(crate) struct Sender<T>(SyncSender<Result<T, Failure>>);

impl<T> Sender<T> {
    pub(crate) fn send(&self, item: T) -> bool {
        self.0.send(Ok(item)).is_ok()
    }
}

/// The items of work over a drive running on its own thread, in order; then its
/// failure, if it failed, or a warning when the drive completed with frames
/// skipped or parts lost (where the command exits 3).
pub(crate) struct Stream<T> {
    items: Mutex<Receiver<Result<T, Failure>>>,
    /// The drive read, until its end has been looked at.
    drive: Mutex<Option<Arc<DriveRun>>>,
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
                let _ = sender.0.send(Err(failure));
            }
        });
        Self {
            items: Mutex::new(receiver),
            drive: Mutex::new(Some(drive)),
        }
    }

    /// The next item, None when the work is done; waits without the interpreter.
    pub(crate) fn next(&self, py: Python<'_>) -> PyResult<Option<T>> {
        let received = py.detach(|| {
            let receiver = (self.items.lock()).unwrap_or_else(|poisoned| poisoned.into_inner());
            receiver.recv()
        });
        match received {
            Ok(Ok(item)) => Ok(Some(item)),
            Ok(Err(failure)) => Err(failure.into()),
            Err(_) => {
                let ended = (self.drive.lock().unwrap_or_else(|p| p.into_inner())).take();
                ended.map_or(Ok(()), |drive| warn_incomplete(py, &drive))?;
                Ok(None)
            }
        }
    }
}
