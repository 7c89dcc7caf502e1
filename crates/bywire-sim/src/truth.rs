//! The plant's true state beside what the buses show: `truth.csv` in a run's folder, one row
//! every 10 ms on the bus logs' clock, so a dataset built from the logs carries its ground
//! truth and a world model's prediction can be scored against it.
//!
//! The chassis is kinematic (the wheels roll where they point, no tyre model), so there is no
//! slip to record; the body's motion is the least-squares fit of the four wheels' states.

use std::io::{self, Write};

use bywire_core::Timestamp;
use bywire_log::candump::timestamp_text;
use bywire_log::Precision;

use crate::output::on_logs_clock;
use crate::record::TruthSample;

/// The columns, in order (units in the names).
pub const COLUMNS: [&str; 16] = [
    "t_s",
    "x_m",
    "y_m",
    "yaw_rad",
    "vx_m_s",
    "vy_m_s",
    "yaw_rate_rad_s",
    "wheel_angle_fl_deg",
    "wheel_angle_fr_deg",
    "wheel_angle_rl_deg",
    "wheel_angle_rr_deg",
    "wheel_speed_fl_m_s",
    "wheel_speed_fr_m_s",
    "wheel_speed_rl_m_s",
    "wheel_speed_rr_m_s",
    "steering_mode",
];

/// Write `truth` as CSV with a header row; numbers as Rust prints them (they read back equal).
/// Times are `start` on (since the Unix epoch), in seconds with six decimals as candump
/// writes them.
pub fn write_csv(truth: &[TruthSample], start: Timestamp, out: &mut impl Write) -> io::Result<()> {
    writeln!(out, "{}", COLUMNS.join(","))?;
    for s in truth {
        write!(
            out,
            "{},{},{},{},{},{},{}",
            timestamp_text(on_logs_clock(start, s.t), Precision::Micros),
            s.pose.x,
            s.pose.y,
            s.pose.yaw,
            s.twist.vx,
            s.twist.vy,
            s.twist.omega
        )?;
        for value in s.wheel_angles_deg.iter().chain(&s.wheel_speeds) {
            write!(out, ",{value}")?;
        }
        // normal, crab or tank; empty before the first command.
        match s.steering_mode {
            Some(mode) => writeln!(out, ",{mode}")?,
            None => writeln!(out, ",")?,
        }
    }
    Ok(())
}
