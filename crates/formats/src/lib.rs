//! The message formats travmap reads and writes, whatever holds the messages: ROS 2
//! types and CDR ([`ros`], with ROS 1's wire format read into the same types),
//! Foxglove's schemas in protobuf or JSON ([`foxglove`] over [`protobuf`]), and MCAP
//! read *and* written ([`mcap`]). [`log_message`] is what every log container yields.
//! Nothing here knows a drive, a LiDAR or the method.

pub mod foxglove;
pub mod log_message;
pub mod mcap;
pub mod protobuf;
pub mod ros;
