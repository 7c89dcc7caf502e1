//! Small plant models: what the controllers are tested and tuned against, and what the
//! simulator builds actuators from. Each is stepped with the time since its last step.

use crate::math;

/// A single-input single-output dynamic system.
pub trait Plant {
    /// Advance `dt` seconds with input `u` held; the new output.
    fn step(&mut self, dt: f64, u: f64) -> f64;
    /// The current output.
    fn output(&self) -> f64;
}

/// `K / (τs + 1)`, discretised exactly for a held input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FirstOrder {
    /// Static gain.
    pub gain: f64,
    /// Time constant, seconds.
    pub time_constant: f64,
    /// Output.
    pub y: f64,
}

impl FirstOrder {
    /// At rest.
    pub fn new(gain: f64, time_constant: f64) -> Self {
        FirstOrder {
            gain,
            time_constant,
            y: 0.0,
        }
    }
}

impl Plant for FirstOrder {
    fn step(&mut self, dt: f64, u: f64) -> f64 {
        let a = if self.time_constant > 0.0 {
            1.0 - math::exp(-dt / self.time_constant)
        } else {
            1.0
        };
        self.y += a * (self.gain * u - self.y);
        self.y
    }

    fn output(&self) -> f64 {
        self.y
    }
}

/// `N` equal first-order lags in series: `K / (τs + 1)^N` (N = 3 is the classic tuning
/// benchmark, with ultimate gain `8/K` and ultimate period `2πτ/√3`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lag<const N: usize> {
    stages: [FirstOrder; N],
}

impl<const N: usize> Lag<N> {
    /// At rest; the whole gain is in the first stage.
    pub fn new(gain: f64, time_constant: f64) -> Self {
        let mut stages = [FirstOrder::new(1.0, time_constant); N];
        if let Some(first) = stages.first_mut() {
            first.gain = gain;
        }
        Lag { stages }
    }
}

impl<const N: usize> Plant for Lag<N> {
    fn step(&mut self, dt: f64, u: f64) -> f64 {
        let mut signal = u;
        for stage in &mut self.stages {
            signal = stage.step(dt, signal);
        }
        signal
    }

    fn output(&self) -> f64 {
        self.stages.last().map_or(0.0, |s| s.y)
    }
}

/// `K ωn² / (s² + 2ζωn s + ωn²)`, integrated with fixed substeps (semi-implicit Euler).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SecondOrder {
    /// Static gain.
    pub gain: f64,
    /// Natural frequency, rad/s.
    pub natural_frequency: f64,
    /// Damping ratio.
    pub damping: f64,
    /// Output.
    pub y: f64,
    /// Its rate.
    pub rate: f64,
}

impl SecondOrder {
    /// At rest.
    pub fn new(gain: f64, natural_frequency: f64, damping: f64) -> Self {
        SecondOrder {
            gain,
            natural_frequency,
            damping,
            y: 0.0,
            rate: 0.0,
        }
    }
}

impl Plant for SecondOrder {
    fn step(&mut self, dt: f64, u: f64) -> f64 {
        const SUBSTEPS: u32 = 10;
        let h = dt / f64::from(SUBSTEPS);
        let wn = self.natural_frequency;
        for _ in 0..SUBSTEPS {
            let accel = wn * wn * (self.gain * u - self.y) - 2.0 * self.damping * wn * self.rate;
            self.rate += h * accel;
            self.y += h * self.rate;
        }
        self.y
    }

    fn output(&self) -> f64 {
        self.y
    }
}

/// `K / s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Integrator {
    /// Gain.
    pub gain: f64,
    /// Output.
    pub y: f64,
}

impl Plant for Integrator {
    fn step(&mut self, dt: f64, u: f64) -> f64 {
        self.y += self.gain * u * dt;
        self.y
    }

    fn output(&self) -> f64 {
        self.y
    }
}

/// An input dead zone (a valve that does not open below a threshold): zero within
/// `±width`, shifted by `width` outside it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeadZone {
    /// Half-width of the dead zone.
    pub width: f64,
}

impl DeadZone {
    /// The output for input `u`.
    pub fn apply(&self, u: f64) -> f64 {
        if u > self.width {
            u - self.width
        } else if u < -self.width {
            u + self.width
        } else {
            0.0
        }
    }
}

/// Backlash (play in a gear train): the output follows the input only when the input pushes
/// on it from one side or the other, `gap` apart.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Backlash {
    /// Total play.
    pub gap: f64,
    /// Output position.
    pub y: f64,
}

impl Backlash {
    /// The output for input position `x`.
    pub fn apply(&mut self, x: f64) -> f64 {
        let half = self.gap / 2.0;
        if x - half > self.y {
            self.y = x - half;
        } else if x + half < self.y {
            self.y = x + half;
        }
        self.y
    }
}

/// Output limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Saturation {
    /// Lowest.
    pub min: f64,
    /// Highest.
    pub max: f64,
}

impl Saturation {
    /// `u` limited.
    pub fn apply(&self, u: f64) -> f64 {
        u.max(self.min).min(self.max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_order_reaches_63_percent_at_tau() {
        let mut p = FirstOrder::new(2.0, 0.5);
        for _ in 0..50 {
            p.step(0.01, 1.0);
        }
        assert!((p.y - 2.0 * (1.0 - (-1.0f64).exp())).abs() < 1e-12);
    }

    #[test]
    fn second_order_settles_at_its_gain() {
        let mut p = SecondOrder::new(3.0, 10.0, 0.7);
        for _ in 0..500 {
            p.step(0.01, 1.0);
        }
        assert!((p.y - 3.0).abs() < 1e-3);
    }

    #[test]
    fn dead_zone_and_backlash() {
        let dz = DeadZone { width: 0.2 };
        assert_eq!(
            [dz.apply(0.1), dz.apply(-0.2), dz.apply(0.5), dz.apply(-0.5)],
            [0.0, 0.0, 0.3, -0.3]
        );
        let mut b = Backlash { gap: 1.0, y: 0.0 };
        assert_eq!(b.apply(0.4), 0.0);
        assert_eq!(b.apply(2.0), 1.5);
        assert_eq!(b.apply(1.2), 1.5, "reversing inside the play moves nothing");
        assert_eq!(b.apply(0.0), 0.5);
    }
}
