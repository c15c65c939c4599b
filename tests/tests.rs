//! tacmesh's integration tests: one binary, driving the real `tacmesh` executable.

mod util;

mod cli_errors;
mod cli_help;
mod daemon;
mod offline_pipeline;
mod physics_ready;
mod protocol;
mod real_scans;
mod real_scenes;
mod reliability;
mod replay;
mod security;
mod systemd;
#[cfg(feature = "zenoh")]
mod zenoh;
