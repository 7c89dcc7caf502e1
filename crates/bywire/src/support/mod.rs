//! What the commands share: bus arguments, DBC and profile loading with diagnostics, numeric
//! options, files written atomically, the interrupt flag, who may reach a server, the live web
//! and Foxglove server, the simulator's servers, ROS 2 nodes. No command imports another.

pub mod access;
pub mod busarg;
pub mod dbc;
pub mod files;
pub mod interrupt;
pub mod live;
pub mod logs;
pub mod numbers;
pub mod progress;
#[cfg(feature = "ros2")]
pub mod ros2;
pub mod signals;
pub mod sim_serve;
pub mod sim_web;
pub mod vehicles;
pub mod words;
