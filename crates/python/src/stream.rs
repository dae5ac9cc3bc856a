//! Work that hands on items one at a time from a thread of its own: Python takes
//! them as it iterates, releasing the interpreter while it waits, and an iteration
//! left early stops the work at its next item.

use std::sync::Mutex;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};

use pyo3::prelude::*;

use crate::Failure;

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

/// The items of work running on its own thread, in order; then its failure, if it
/// failed.
pub(crate) struct Stream<T>(Mutex<Receiver<Result<T, Failure>>>);

impl<T: Send + 'static> Stream<T> {
    pub(crate) fn spawn(
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
        Self(Mutex::new(receiver))
    }

    /// The next item, None when the work is done; waits without the interpreter.
    pub(crate) fn next(&self, py: Python<'_>) -> PyResult<Option<T>> {
        let received = py.detach(|| {
            let receiver = self
                .0
                .lock()
                .unwrap_or_else(|poisoned| poisoned.into_inner());
            receiver.recv()
        });
        match received {
            Ok(Ok(item)) => Ok(Some(item)),
            Ok(Err(failure)) => Err(failure.into()),
            Err(_) => Ok(None),
        }
    }
}
