//! The examples of bywire's libraries (`cargo run -p bywire-examples --example NAME`):
//!
//! - `decode_log`: a candump log decoded with a DBC, signal by signal;
//! - `ads_socketcan`: the ADS side of the reference tug on a SocketCAN interface, on the
//!   real-time runner;
//! - `canopen_master`: a CANopen master walking a CiA 402 drive to Operation enabled, on the
//!   simulated runner;
//! - `simulated_tug`: the simulated tug driving its apron loop.
