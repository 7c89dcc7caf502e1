//! # bywire-data: logs to datasets
//!
//! What a data engineer makes of CAN logs, on top of `bywire-log`'s formats:
//!
//! - [`decoded`]: frames decoded with a DBC into one Arrow table per message (and channel),
//!   written as Parquet partitioned by message, a bounded number open at a time;
//! - [`long`]: a decoded table in long form (one row a signal value), as lakes store it;
//! - [`lake`]: a fleet's logs as a data lake (`vehicle=/date=/message=` folders, as Spark
//!   writes them), its files encoded by bywire's own Parquet encoder (delta and
//!   dictionary pages, snappy, zstd or gzip) for speed;
//! - [`table`]: a table of named columns written as Parquet (the dataset command's);
//! - [`dataset`]: a vehicle's log as rows at a fixed rate by role (commands, feedback,
//!   odometry), from its profile;
//! - [`latency`]: command-to-actuator latency and step metrics from a log, by role;
//! - [`truth`]: a simulator run's ground truth, looked up by time for a dataset's grid.
//!
//! ```
//! use bywire_data::lake::LakeCompression;
//! assert_eq!(LakeCompression::from_name("ZSTD"), Some(LakeCompression::Zstd));
//! assert_eq!(LakeCompression::from_name("lz4"), None);
//! ```

mod batch_file;
pub mod dataset;
pub mod decoded;
mod encode;
pub mod lake;
pub mod latency;
pub mod long;
pub mod table;
#[cfg(test)]
mod test_support;
mod thrift;
pub mod truth;
