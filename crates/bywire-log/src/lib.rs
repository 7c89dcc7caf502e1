//! # bywire-log: CAN logs
//!
//! - [`candump`]: the candump log format, `(1699999999.123456) can0 123#DEADBEEF`, read as a
//!   stream of records with errors naming the line and column, written byte-identical to
//!   `candump -L` (or with nanoseconds).
//! - [`asc`]: Vector ASC logs, read and written as python-can and can-utils do.
//! - `mcap` (feature `mcap`): MCAP files of ROS 2 `can_msgs/msg/Frame`, as ros2_socketcan
//!   records them.
//! - [`blf`]: Vector BLF (zlib log containers; classic, FD and error objects).
//! - [`mf4`]: ASAM MDF 4 bus logging (`CAN_DataFrame` groups), as python-can and asammdf
//!   write it.
//! - [`trc`]: PEAK TRC logs (1.0 to 2.1 read, 2.1 written).
//! - `parquet` (feature `parquet`): raw frames as a Parquet table, read and written, and decoded
//!   tables (one per message, typed signal columns) as a partitioned dataset.
//! - [`pcapng`]: pcapng captures of SocketCAN frames (Wireshark's LINKTYPE_CAN_SOCKETCAN).
//! - [`format`](mod@format): the formats by extension or content, each with a reader and a writer.
//! - [`screen`]: candump's screen form, `  can0  123   [4]  DE AD BE EF`, written as candump
//!   prints it and read back (for tools that take either form on standard input).
//!
//! - [`lines`]: text lines in bounded memory (too long or not UTF-8: reported with the line's
//!   number, and reading goes on).
//! - [`merge`]: several logs as one, in time order (streaming).
//! - [`pacing`]: when to replay each record (recorded pace, a speed factor, long gaps skipped).
//!
//! Readers hold one line at a time, so logs of any size stream in bounded memory, and no input
//! can make them panic (property-tested).

//! ```
//! let log = "(1700000000.000100) can0 123#DEADBEEF\n(1700000000.000200) can1 1ABCDEF0##1112233\n";
//! let records: Vec<_> = bywire_log::Reader::new(log.as_bytes()).collect::<Result<_, _>>().unwrap();
//! assert_eq!(records.len(), 2);
//! assert_eq!((records[0].interface.as_str(), records[0].frame.data()), ("can0", &[0xDE, 0xAD, 0xBE, 0xEF][..]));
//! assert!(records[1].frame.is_fd());
//! ```

pub mod asc;
#[cfg(feature = "parquet")]
pub mod batches;
pub mod blf;
pub mod calendar;
pub mod candump;
mod fields;
pub mod format;
pub mod lines;
#[cfg(feature = "mcap")]
pub mod mcap;
pub mod merge;
pub mod mf4;
pub mod options;
pub mod pacing;
#[cfg(feature = "parquet")]
pub mod parquet;
pub mod pcapng;
pub mod recorder;
#[cfg(feature = "mcap")]
pub mod rosbag2;
pub mod screen;
pub mod stats;
pub mod trc;

pub use candump::{LogError, LogErrorKind, LogRecord, LogRecordRef, Precision, Reader, Writer};
pub use screen::{FrameView, View};
