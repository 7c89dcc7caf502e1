//! One module per subcommand: its arguments and a `run` that calls the libraries and prints.

pub mod bittiming;
pub mod bridge;
pub mod busload;
pub mod canopen;
pub mod check;
pub mod dataset;
pub mod dbc;
pub mod dump;
pub mod gen;
pub mod isotp;
pub mod latency;
pub mod log;
pub mod monitor;
pub mod play;
pub mod plot;
#[cfg(feature = "ros2")]
pub mod ros2;
pub mod secoc;
pub mod send;
pub mod serve;
pub mod sim;
pub mod slcan_adapter;
pub mod sniff;
pub mod uds;
pub mod vehicle;
pub mod wire;
