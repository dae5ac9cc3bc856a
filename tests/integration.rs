//! travmap's integration tests, one binary (as ripgrep's): each module runs the
//! `travmap` binary on real data from `../shared/data` (skipping with the reason
//! printed where it is absent) or checks a fast path of the library against a slow
//! obvious one. `cargo test --release --test integration MODULE::` runs one module.

mod common;

mod adaptation;
mod appearance;
mod architecture;
mod bad_input;
mod brute_force;
mod cli;
mod dataset;
mod drive_map;
mod far_from_origin;
mod feature_groups;
mod foxglove;
mod golden;
mod hesai;
mod json_output;
mod labelling;
mod mcap;
mod multi_lidar;
mod nav2;
mod nebula_packets;
mod never_lose_a_byte;
mod odometry;
mod ouster;
mod pcap;
mod pictures;
mod provenance;
mod python;
mod readme;
mod real_frames;
mod robosense;
mod robustness;
mod ros_logs;
mod site_map;
mod velodyne;
mod viewer;
