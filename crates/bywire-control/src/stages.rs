//! Stages that go around a controller: each fixes one nonlinearity of the actuator or
//! shapes the setpoint, and they compose by calling one after the other.
//!
//! ```
//! use bywire_control::stages::{DeadZoneCompensation, RateLimiter};
//! let mut limiter = RateLimiter::new(10.0, 10.0);
//! limiter.reset(0.0);
//! let compensate = DeadZoneCompensation { width: 0.2, threshold: 0.01 };
//! let setpoint = limiter.step(0.01, 5.0); // at most 0.1 per 10 ms
//! assert!((setpoint - 0.1).abs() < 1e-12);
//! assert!((compensate.apply(0.5) - 0.7).abs() < 1e-12);
//! ```

/// Inverts an actuator's dead zone: adds its width to any command beyond `threshold`, and
/// ramps linearly inside it so that small commands do not chatter across the gap.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeadZoneCompensation {
    /// The actuator's dead-zone half-width.
    pub width: f64,
    /// Commands smaller than this are scaled rather than jumped (≥ 0).
    pub threshold: f64,
}

impl DeadZoneCompensation {
    /// The command to give the actuator for desired effect `u`.
    pub fn apply(&self, u: f64) -> f64 {
        if u > self.threshold {
            u + self.width
        } else if u < -self.threshold {
            u - self.width
        } else if self.threshold > 0.0 {
            u * (self.threshold + self.width) / self.threshold
        } else {
            0.0
        }
    }
}

/// Limits how fast a value (a setpoint) may change, separately up and down (units per second).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateLimiter {
    /// Largest rise per second.
    pub rising: f64,
    /// Largest fall per second (positive).
    pub falling: f64,
    value: Option<f64>,
}

impl RateLimiter {
    /// A limiter that passes its first input through.
    pub fn new(rising: f64, falling: f64) -> Self {
        RateLimiter {
            rising,
            falling,
            value: None,
        }
    }

    /// Start from `value` (e.g. the measured position when a loop engages).
    pub fn reset(&mut self, value: f64) {
        self.value = Some(value);
    }

    /// The current value (`None` before the first input).
    pub fn value(&self) -> Option<f64> {
        self.value
    }

    /// Move towards `target` by at most the allowed change in `dt` seconds; the new value.
    /// Non-finite targets and non-positive `dt` hold the value.
    pub fn step(&mut self, dt: f64, target: f64) -> f64 {
        let Some(value) = self.value else {
            if target.is_finite() {
                self.value = Some(target);
                return target;
            }
            return 0.0;
        };
        if !(dt > 0.0 && target.is_finite()) {
            return value;
        }
        let next = target
            .min(value + self.rising.abs() * dt)
            .max(value - self.falling.abs() * dt);
        self.value = Some(next);
        next
    }
}

/// Compensates backlash in a position drive: when the command reverses, jump it across the
/// play so that the load starts moving at once. The direction changes only when the command
/// moves more than `threshold` the other way (hysteresis against noise).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BacklashCompensation {
    /// The play to cross.
    pub gap: f64,
    /// Movement that counts as a reversal.
    pub threshold: f64,
    direction: f64,
    anchor: Option<f64>,
}

impl BacklashCompensation {
    /// No direction known yet (no offset until the command first moves).
    pub fn new(gap: f64, threshold: f64) -> Self {
        BacklashCompensation {
            gap,
            threshold,
            direction: 0.0,
            anchor: None,
        }
    }

    /// The command to give the drive for desired load position `x`.
    pub fn apply(&mut self, x: f64) -> f64 {
        let anchor = *self.anchor.get_or_insert(x);
        let moved = x - anchor;
        if moved > self.threshold {
            self.direction = 1.0;
        } else if moved < -self.threshold {
            self.direction = -1.0;
        }
        // Follow the command in its direction of travel; keep the turning point otherwise.
        if moved * self.direction >= 0.0 || moved.abs() > self.threshold {
            self.anchor = Some(x);
        }
        x + self.direction * self.gap / 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rate_limiter_moves_at_its_rates() {
        let mut r = RateLimiter::new(2.0, 1.0);
        r.reset(0.0);
        let ups: [f64; 3] = core::array::from_fn(|_| r.step(0.1, 10.0));
        assert!((ups[2] - 0.6).abs() < 1e-12);
        let down = r.step(0.1, -10.0);
        assert!((down - 0.5).abs() < 1e-12);
        assert_eq!(r.step(0.1, 0.52), 0.52);
        assert_eq!(r.step(0.0, 5.0), 0.52);
    }

    #[test]
    fn dead_zone_compensation_is_continuous_and_inverts_the_zone() {
        let c = DeadZoneCompensation {
            width: 0.3,
            threshold: 0.05,
        };
        let zone = crate::plant::DeadZone { width: 0.3 };
        for u in [0.1, 0.5, -0.2, -1.0] {
            assert!((zone.apply(c.apply(u)) - u).abs() < 1e-12, "{u}");
        }
        assert!((c.apply(0.05) - 0.35).abs() < 1e-12);
        assert!((c.apply(0.025) - 0.175).abs() < 1e-12);
    }

    #[test]
    fn backlash_compensation_crosses_the_play_on_reversal() {
        let mut c = BacklashCompensation::new(1.0, 0.01);
        let mut play = crate::plant::Backlash { gap: 1.0, y: 0.0 };
        // Up to 2, then back down to 1: the load follows the command both ways.
        let path = [0.0, 0.5, 1.0, 1.5, 2.0, 1.5, 1.0];
        let load: [f64; 7] = core::array::from_fn(|i| play.apply(c.apply(path[i])));
        for (l, x) in load.iter().zip(path).skip(1) {
            assert!((l - x).abs() < 1e-12, "{load:?}");
        }
    }
}
