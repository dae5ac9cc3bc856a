pub(crate) mod chunks;
pub(crate) mod encoding;
pub mod messages;
pub mod records;
pub mod stored;
pub mod writer;
