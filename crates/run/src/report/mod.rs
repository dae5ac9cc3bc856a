//! What a run says, the same for every front end: the `--json` records a script
//! reads ([`json`], one convention for every command, schemas in `schemas/json/`)
//! and the text tables a person reads ([`tables`]). Building them is here; printing
//! them is the front end's.

pub mod json;
pub mod tables;
