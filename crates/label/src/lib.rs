//! `travmap label`: a person answers, on a page served on 127.0.0.1, the cells a
//! model is least sure of ([`travmap_run::labelling`] chooses them), and the labels
//! file keeps every answer as it is given (`travmap_outputs::labels`). `train
//! --prior` learns a model for the robot from it.

mod server;
mod session;
mod views;

pub use server::{Served, serve};
pub use session::{Answerer, Progress, Session};
