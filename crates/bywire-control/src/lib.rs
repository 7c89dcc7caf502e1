//! # bywire-control: the controllers and estimators of a drive-by-wire vehicle
//!
//! Each axis of a drive-by-wire vehicle closes its own loop on setpoints from the ADS; the
//! hydraulic steering of the reference tug adds a valve dead zone, gear backlash and actuator
//! saturation. This crate has the pieces, all `no_std`, allocation-free in every `step` and
//! `update`, with time passed in as `dt` in seconds:
//!
//! - [`pid`]: PID with derivative on measurement and its filter, output limits, anti-windup by
//!   clamping or back-calculation, feed-forward, bumpless manual/automatic transfer.
//! - [`stages`]: dead-zone compensation, setpoint rate limiting and backlash compensation,
//!   composable around any controller.
//! - [`plant`]: small plant models (lags, integrator, dead zone, backlash, saturation) for tests,
//!   tuning experiments and the simulator.
//! - [`tuning`]: Ziegler–Nichols (ultimate gain and period from a sustained-oscillation
//!   experiment) with its rule table, relay (Åström–Hägglund) auto-tuning, and twiddle.
//! - [`metrics`]: step-response metrics from a recorded response.
//! - [`kinematics`]: differential drive, bicycle, swerve / independent 4-wheel steer (normal,
//!   crab, tank turn) and odometry.
//! - [`path`]: pure pursuit and Stanley for Ackermann and 4WS.
//! - [`ekf`]: an extended Kalman filter fusing wheel odometry, IMU and GNSS with innovation
//!   gating.
//!
//! ```
//! use bywire_control::pid::{Pid, PidConfig};
//! let mut pid = Pid::new(PidConfig { kp: 2.0, ki: 1.0, ..PidConfig::default() });
//! let u = pid.step(0.01, 1.0, 0.0, 0.0);
//! assert!(u > 0.0);
//! ```
#![no_std]

pub mod ekf;
pub mod kinematics;
pub mod metrics;
pub mod path;
pub mod pid;
pub mod plant;
pub mod stages;
pub mod tuning;

/// Float functions without std (through `libm`), in one place.
pub(crate) mod math {
    pub fn sin(x: f64) -> f64 {
        libm::sin(x)
    }
    pub fn cos(x: f64) -> f64 {
        libm::cos(x)
    }
    pub fn tan(x: f64) -> f64 {
        libm::tan(x)
    }
    pub fn atan(x: f64) -> f64 {
        libm::atan(x)
    }
    pub fn atan2(y: f64, x: f64) -> f64 {
        libm::atan2(y, x)
    }
    pub fn sqrt(x: f64) -> f64 {
        libm::sqrt(x)
    }
    pub fn hypot(x: f64, y: f64) -> f64 {
        libm::hypot(x, y)
    }
    pub fn exp(x: f64) -> f64 {
        libm::exp(x)
    }

    /// An angle wrapped to (−π, π].
    pub fn wrap_angle(a: f64) -> f64 {
        let two_pi = 2.0 * core::f64::consts::PI;
        let wrapped = a - two_pi * libm::floor((a + core::f64::consts::PI) / two_pi);
        // floor puts exactly −π at −π; move it to +π so the range is (−π, π].
        if wrapped <= -core::f64::consts::PI {
            wrapped + two_pi
        } else {
            wrapped
        }
    }
}
