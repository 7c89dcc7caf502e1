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
    /// Sine and cosine of one angle, as `sin` and `cos` give them, with one argument
    /// reduction.
    pub fn sin_cos(x: f64) -> (f64, f64) {
        libm::sincos(x)
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

    #[cfg(test)]
    mod tests {
        /// `sin_cos` is `sin` and `cos` to the bit (the models' results must not move when
        /// one replaces the other): tiny angles about where both switch to their shortcuts,
        /// every octant out to large angles, and the special values.
        #[test]
        fn sin_cos_is_sin_and_cos_to_the_bit() {
            let check = |x: f64| {
                let (sin, cos) = super::sin_cos(x);
                assert_eq!(sin.to_bits(), super::sin(x).to_bits(), "sin {x:e}");
                assert_eq!(cos.to_bits(), super::cos(x).to_bits(), "cos {x:e}");
            };
            for x in [0.0, -0.0, f64::INFINITY, f64::NAN, f64::MIN_POSITIVE] {
                check(x);
            }
            // From 2^-60 to 2^-20 in small ratios (through 2^-27·√2 and 2^-26).
            let mut tiny = libm::exp2(-60.0);
            while tiny < libm::exp2(-20.0) {
                check(tiny);
                check(-tiny);
                tiny *= 1.01;
            }
            // A quasi-random walk over ±1e6 rad, denser near the origin.
            let mut state = 0x9E37_79B9_7F4A_7C15u64;
            for _ in 0..200_000 {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                #[allow(clippy::cast_precision_loss)]
                let unit = (state >> 11) as f64 / (1u64 << 53) as f64;
                let scale = libm::exp10(unit * 12.0 - 6.0);
                check(scale * (unit - 0.5));
                check(-scale * unit);
            }
        }
    }
}
