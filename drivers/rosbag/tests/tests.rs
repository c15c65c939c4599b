//! Integration tests of tacmesh-rosbag, one binary (see STYLE.md).

mod corruption;
mod real_bag;
mod replay;
mod synthetic;
mod util;
