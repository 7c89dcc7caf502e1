//! A PID controller for the control path.
//!
//! - The derivative acts on the measurement, not the error, so a setpoint step does not kick
//!   the output; a first-order filter (time constant `derivative_filter`) tames noise.
//! - The integral is stored as its contribution to the output (already multiplied by `ki`), so
//!   retuning `ki` does not bump the output.
//! - Anti-windup by clamping (conditional integration: stop integrating while the output is
//!   saturated and the error would drive it further) or back-calculation (bleed the integral by
//!   the saturation excess over a tracking time).
//! - Manual mode passes an operator's output through while the integral tracks it, so the
//!   switch back to automatic is bumpless.
//! - A non-finite input or a non-positive `dt` changes nothing: the last output is held.

/// How the integral is kept from winding up while the output is saturated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AntiWindup {
    /// Integrate always (for comparison; windup happens).
    None,
    /// Conditional integration: hold the integral while saturated in the error's direction.
    Clamping,
    /// Feed the saturation excess back into the integral with this tracking time constant (s);
    /// √(Ti·Td) or Ti/2 are usual choices.
    BackCalculation {
        /// Tracking time constant, seconds (> 0).
        tracking_time: f64,
    },
}

/// Gains and limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidConfig {
    /// Proportional gain.
    pub kp: f64,
    /// Integral gain (per second).
    pub ki: f64,
    /// Derivative gain (seconds).
    pub kd: f64,
    /// Time constant of the derivative's first-order filter, seconds (0: unfiltered).
    pub derivative_filter: f64,
    /// Lowest output.
    pub output_min: f64,
    /// Highest output.
    pub output_max: f64,
    /// Anti-windup method.
    pub anti_windup: AntiWindup,
}

impl Default for PidConfig {
    /// P with gain 1, unlimited output, clamping anti-windup.
    fn default() -> Self {
        PidConfig {
            kp: 1.0,
            ki: 0.0,
            kd: 0.0,
            derivative_filter: 0.0,
            output_min: f64::NEG_INFINITY,
            output_max: f64::INFINITY,
            anti_windup: AntiWindup::Clamping,
        }
    }
}

/// Who sets the output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mode {
    /// The controller.
    Automatic,
    /// An operator (or another controller), with this output.
    Manual(f64),
}

/// A PID controller's state.
#[derive(Debug, Clone, PartialEq)]
pub struct Pid {
    config: PidConfig,
    mode: Mode,
    integral: f64,
    derivative: f64,
    last_measurement: Option<f64>,
    output: f64,
}

impl Pid {
    /// A controller at rest, in automatic mode.
    pub fn new(config: PidConfig) -> Self {
        Pid {
            config,
            mode: Mode::Automatic,
            integral: 0.0,
            derivative: 0.0,
            last_measurement: None,
            output: 0.0,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &PidConfig {
        &self.config
    }

    /// Change gains or limits without a bump (the integral is kept as an output contribution).
    pub fn set_config(&mut self, config: PidConfig) {
        self.config = config;
    }

    /// Hand the output to an operator (`Mode::Manual`) or take it back (`Mode::Automatic`).
    pub fn set_mode(&mut self, mode: Mode) {
        self.mode = mode;
    }

    /// The current mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The last output.
    pub fn output(&self) -> f64 {
        self.output
    }

    /// The integral term's contribution to the output.
    pub fn integral(&self) -> f64 {
        self.integral
    }

    /// Forget the history (integral, derivative, last output).
    pub fn reset(&mut self) {
        *self = Pid {
            mode: self.mode,
            ..Pid::new(self.config)
        };
    }

    fn clamp(&self, u: f64) -> f64 {
        u.max(self.config.output_min).min(self.config.output_max)
    }

    /// One control step `dt` seconds after the last: the new output.
    pub fn step(&mut self, dt: f64, setpoint: f64, measurement: f64, feedforward: f64) -> f64 {
        let valid = dt > 0.0
            && dt.is_finite()
            && setpoint.is_finite()
            && measurement.is_finite()
            && feedforward.is_finite();
        if !valid {
            return self.output;
        }
        let c = self.config;
        let error = setpoint - measurement;
        // Derivative of −measurement, through a backward-Euler first-order filter.
        let raw = match self.last_measurement {
            Some(last) => -(measurement - last) / dt,
            None => 0.0,
        };
        let alpha = dt / (c.derivative_filter.max(0.0) + dt);
        self.derivative += alpha * (raw - self.derivative);
        self.last_measurement = Some(measurement);
        let proportional = c.kp * error;
        let derivative = c.kd * self.derivative;
        if let Mode::Manual(manual) = self.mode {
            // Track: the integral that would give this output, for a bumpless return.
            let manual = self.clamp(manual);
            self.integral = manual - proportional - derivative - feedforward;
            self.output = manual;
            return manual;
        }
        let increment = c.ki * error * dt;
        match c.anti_windup {
            AntiWindup::None => self.integral += increment,
            AntiWindup::Clamping => {
                let unsaturated =
                    proportional + self.integral + increment + derivative + feedforward;
                let excess = unsaturated - self.clamp(unsaturated);
                // Integrate unless saturated and the error pushes further into the limit.
                if excess == 0.0 || excess * increment < 0.0 {
                    self.integral += increment;
                }
            }
            AntiWindup::BackCalculation { tracking_time } => {
                let unsaturated = proportional + self.integral + derivative + feedforward;
                let excess = unsaturated - self.clamp(unsaturated);
                let tracking = if tracking_time > 0.0 {
                    excess / tracking_time * dt
                } else {
                    excess
                };
                self.integral += increment - tracking;
            }
        }
        self.output = self.clamp(proportional + self.integral + derivative + feedforward);
        self.output
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn terms_add_up() {
        let mut pid = Pid::new(PidConfig {
            kp: 2.0,
            ki: 10.0,
            kd: 0.5,
            ..PidConfig::default()
        });
        // First step: P + I (no derivative without a previous measurement) + feed-forward.
        let u = pid.step(0.1, 1.0, 0.0, 0.25);
        assert!((u - (2.0 + 1.0 + 0.25)).abs() < 1e-12, "{u}");
        // Measurement rises by 0.2 in 0.1 s: derivative −2/s × 0.5.
        let u = pid.step(0.1, 1.0, 0.2, 0.0);
        assert!((u - (1.6 + 1.8 - 1.0)).abs() < 1e-12, "{u}");
    }

    #[test]
    fn setpoint_steps_do_not_kick_the_derivative() {
        let mut pid = Pid::new(PidConfig {
            kp: 0.0,
            kd: 1.0,
            ..PidConfig::default()
        });
        pid.step(0.01, 0.0, 0.0, 0.0);
        assert_eq!(pid.step(0.01, 100.0, 0.0, 0.0), 0.0);
    }

    #[test]
    fn the_derivative_filter_smooths() {
        let config = PidConfig {
            kp: 0.0,
            kd: 1.0,
            ..PidConfig::default()
        };
        let mut raw = Pid::new(config);
        let mut filtered = Pid::new(PidConfig {
            derivative_filter: 0.1,
            ..config
        });
        for pid in [&mut raw, &mut filtered] {
            pid.step(0.01, 0.0, 0.0, 0.0);
        }
        let (r, f) = (
            raw.step(0.01, 0.0, 1.0, 0.0),
            filtered.step(0.01, 0.0, 1.0, 0.0),
        );
        assert_eq!(r, -100.0);
        assert!((f - (-100.0 * 0.01 / 0.11)).abs() < 1e-9, "{f}");
    }

    #[test]
    fn bad_inputs_hold_the_last_output() {
        let mut pid = Pid::new(PidConfig {
            ki: 1.0,
            ..PidConfig::default()
        });
        let u = pid.step(0.1, 1.0, 0.0, 0.0);
        for (dt, sp, pv) in [
            (0.0, 1.0, 0.0),
            (-1.0, 1.0, 0.0),
            (0.1, f64::NAN, 0.0),
            (0.1, 1.0, f64::INFINITY),
        ] {
            assert_eq!(pid.step(dt, sp, pv, 0.0), u);
        }
        assert_eq!(pid.integral(), 0.1);
    }

    #[test]
    fn manual_to_automatic_is_bumpless() {
        let mut pid = Pid::new(PidConfig {
            kp: 1.0,
            ki: 2.0,
            ..PidConfig::default()
        });
        pid.set_mode(Mode::Manual(3.0));
        for _ in 0..10 {
            assert_eq!(pid.step(0.01, 1.0, 0.4, 0.0), 3.0);
        }
        pid.set_mode(Mode::Automatic);
        let u = pid.step(0.01, 1.0, 0.4, 0.0);
        // Only one step's integral increment away from the manual output.
        assert!((u - 3.0).abs() < 2.0 * 0.6 * 0.01 + 1e-12, "{u}");
    }
}
