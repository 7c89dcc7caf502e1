//! One corner's electrohydraulic steering: the motor controller's output turns a DC motor on
//! the input shaft of an orbital valve (a hydraulic steering unit); the valve meters oil to a
//! double-acting cylinder in proportion to the shaft's speed, outside a dead zone, and closes
//! when the shaft stops (follow-up), so the wheel holds; the cylinder moves the wheel through
//! the steering arm; a potentiometer on the kingpin reports the angle.

use crate::rng::Rng;

/// The chain's parameters (defaults: a baggage tug's corner).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteeringParams {
    /// Valve input-shaft speed at full motor command, rpm.
    pub shaft_max_rpm: f64,
    /// Motor (and gearbox) time constant, s.
    pub motor_time_constant: f64,
    /// Valve displacement, m³ per revolution of the input shaft.
    pub displacement: f64,
    /// Shaft speed below which the valve stays closed (centering springs), rpm.
    pub dead_zone_rpm: f64,
    /// Pump flow limit, m³/s.
    pub pump_flow: f64,
    /// Supply (relief) pressure, bar (70–150 on the tug).
    pub supply_bar: f64,
    /// Pressure needed to turn the wheel at standstill, bar.
    pub load_standstill_bar: f64,
    /// ... and while rolling, bar.
    pub load_rolling_bar: f64,
    /// Cylinder piston area on the cap side, m².
    pub cap_area: f64,
    /// ... and on the rod side, m².
    pub rod_area: f64,
    /// Half the cylinder's stroke, m.
    pub half_stroke: f64,
    /// Steering arm radius, m.
    pub arm: f64,
    /// Sensor range (±), degrees.
    pub sensor_range_deg: f64,
    /// Sensor resolution, bits.
    pub sensor_bits: u32,
    /// Sensor noise, degrees (one sigma).
    pub sensor_noise_deg: f64,
}

impl Default for SteeringParams {
    fn default() -> Self {
        let bore: f64 = 0.050;
        let rod: f64 = 0.025;
        let cap = core::f64::consts::PI * bore * bore / 4.0;
        SteeringParams {
            shaft_max_rpm: 60.0,
            motor_time_constant: 0.05,
            displacement: 100e-6,
            dead_zone_rpm: 2.0,
            pump_flow: 16.0 / 60_000.0,
            supply_bar: 120.0,
            load_standstill_bar: 40.0,
            load_rolling_bar: 25.0,
            cap_area: cap,
            rod_area: cap - core::f64::consts::PI * rod * rod / 4.0,
            // A stroke long enough for the tank turn's ~61° (end stop at asin(0.14/0.15) = 69°).
            half_stroke: 0.140,
            arm: 0.150,
            sensor_range_deg: 75.0,
            sensor_bits: 12,
            sensor_noise_deg: 0.05,
        }
    }
}

/// A fault of the angle sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SensorFault {
    /// Working.
    None,
    /// Reads this angle whatever the wheel does, degrees.
    Stuck(f64),
    /// Reads the angle plus an error growing at this rate, degrees per second.
    Drift(f64),
    /// The wiper lost contact: reads the upper rail.
    OpenCircuit,
    /// No reading at all: a sensor module reports the channel missing (the potentiometer's
    /// track, which has no such report, reads the upper rail).
    Silent,
}

/// The state of one corner's steering chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteeringChain {
    /// Parameters.
    pub params: SteeringParams,
    shaft_rpm: f64,
    piston: f64,
    /// The wheel's angle from the piston, worked out once a step (it is read several times a
    /// step: the sensors, the plant, the truth).
    angle_deg: f64,
    /// The piston's position and the arm's length `angle_deg` was worked out from (bits).
    angle_from: [u64; 2],
    drift: f64,
    fault: SensorFault,
}

impl SteeringChain {
    /// A chain with the wheel straight ahead.
    pub fn new(params: SteeringParams) -> SteeringChain {
        SteeringChain {
            params,
            shaft_rpm: 0.0,
            piston: 0.0,
            angle_deg: 0.0,
            angle_from: [0.0f64.to_bits(), params.arm.to_bits()],
            drift: 0.0,
            fault: SensorFault::None,
        }
    }

    /// Advance by `dt` seconds with the motor command (−1 … 1, the controller's output) while
    /// the tug rolls or not.
    pub fn step(&mut self, dt: f64, command: f64, rolling: bool) {
        let p = &self.params;
        let command = if command.is_finite() {
            command.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        // The motor: first order toward its commanded speed.
        let target = command * p.shaft_max_rpm;
        let alpha = if p.motor_time_constant > 0.0 {
            (dt / p.motor_time_constant).min(1.0)
        } else {
            1.0
        };
        self.shaft_rpm += (target - self.shaft_rpm) * alpha;
        // The valve meters in proportion to the shaft's speed beyond its dead zone, within the
        // pump's flow, and only if the supply pressure can overcome the load.
        let load = if rolling {
            p.load_rolling_bar
        } else {
            p.load_standstill_bar
        };
        let effective_rpm = (self.shaft_rpm.abs() - p.dead_zone_rpm).max(0.0);
        let flow = if p.supply_bar > load {
            (p.displacement * effective_rpm / 60.0).min(p.pump_flow)
        } else {
            0.0
        };
        let area = if self.shaft_rpm >= 0.0 {
            p.cap_area
        } else {
            p.rod_area
        };
        let speed = flow / area * self.shaft_rpm.signum();
        self.piston = (self.piston + speed * dt).clamp(-p.half_stroke, p.half_stroke);
        self.update_angle();
        if let SensorFault::Drift(rate) = self.fault {
            self.drift += rate * dt;
        }
    }

    /// The redundant tug's backup valve, in parallel with the orbital valve, over the same
    /// `dt` after [`Self::step`]: it meters oil for `rate` degrees per second of the wheel
    /// (its driver's demand), if the supply can overcome the load.
    pub fn backup_flow(&mut self, dt: f64, rate: f64, rolling: bool) {
        let p = &self.params;
        let load = if rolling {
            p.load_rolling_bar
        } else {
            p.load_standstill_bar
        };
        if !rate.is_finite() || p.supply_bar <= load {
            return;
        }
        // The wheel's rate through the linkage: stroke = arm × sin(angle).
        let speed = p.arm * libm::cos(self.angle_deg.to_radians()) * rate.to_radians();
        self.piston = (self.piston + speed * dt).clamp(-p.half_stroke, p.half_stroke);
        self.update_angle();
    }

    /// The wheel's angle from the piston, worked out again if the piston moved.
    fn update_angle(&mut self) {
        let p = &self.params;
        // A piston at rest (the valve closed, as it mostly is) leaves the angle as it was.
        let angle_from = [self.piston.to_bits(), p.arm.to_bits()];
        if angle_from != self.angle_from {
            self.angle_from = angle_from;
            self.angle_deg = libm::asin((self.piston / p.arm).clamp(-1.0, 1.0)).to_degrees();
        }
    }

    /// The valve's input shaft seizes (its motor or the valve jammed): it stands, and the
    /// orbital valve stays closed. Held while called before every step, with the motor's
    /// command zero (a stalled motor turns nothing).
    pub fn seize(&mut self) {
        self.shaft_rpm = 0.0;
    }

    /// The wheel's angle, degrees (the linkage: the piston turns the arm).
    pub fn wheel_angle_deg(&self) -> f64 {
        self.angle_deg
    }

    /// The valve input shaft's speed, rpm.
    pub fn shaft_rpm(&self) -> f64 {
        self.shaft_rpm
    }

    /// Set (or clear) a sensor fault.
    pub fn set_fault(&mut self, fault: SensorFault) {
        self.fault = fault;
        self.drift = 0.0;
    }

    /// What one of the redundant tug's further angle sensors reads with `fault` (a drift's
    /// error so far: `drift` degrees; `None`: no reading). Their faults are the caller's:
    /// the plain tug has none to step.
    pub fn further_sensor_deg(&self, fault: SensorFault, drift: f64, rng: &mut Rng) -> Option<f64> {
        let truth = match fault {
            SensorFault::None => self.wheel_angle_deg(),
            SensorFault::Stuck(angle) => angle,
            SensorFault::Drift(_) => self.wheel_angle_deg() + drift,
            SensorFault::OpenCircuit => return Some(self.params.sensor_range_deg),
            SensorFault::Silent => return None,
        };
        Some(self.quantised(truth, rng))
    }

    /// What the potentiometer reads: the angle with noise, quantised to its resolution,
    /// clipped to its range — or what a fault makes of it.
    pub fn sensor_deg(&self, rng: &mut Rng) -> f64 {
        let p = &self.params;
        let truth = match self.fault {
            SensorFault::None => self.wheel_angle_deg(),
            SensorFault::Stuck(angle) => angle,
            SensorFault::Drift(_) => self.wheel_angle_deg() + self.drift,
            SensorFault::OpenCircuit | SensorFault::Silent => return p.sensor_range_deg,
        };
        self.quantised(truth, rng)
    }

    /// What the potentiometer's second track reads (a dual-track sensor; the faults above are
    /// of the first track, the one the drive's position loop uses).
    pub fn second_track_deg(&self, rng: &mut Rng) -> f64 {
        self.quantised(self.wheel_angle_deg(), rng)
    }

    /// `truth` with the track's noise, quantised to its resolution, clipped to its range.
    fn quantised(&self, truth: f64, rng: &mut Rng) -> f64 {
        let p = &self.params;
        let noisy = truth + rng.normal(p.sensor_noise_deg);
        let steps = f64::from(1u32 << p.sensor_bits.min(24)) - 1.0;
        let quantum = 2.0 * p.sensor_range_deg / steps;
        let code = libm::round(
            (noisy.clamp(-p.sensor_range_deg, p.sensor_range_deg) + p.sensor_range_deg) / quantum,
        );
        code * quantum - p.sensor_range_deg
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Run for `millis` milliseconds in 1 ms steps.
    fn run(chain: &mut SteeringChain, millis: u32, command: f64, rolling: bool) {
        for _ in 0..millis {
            chain.step(0.001, command, rolling);
        }
    }

    #[test]
    fn the_wheel_turns_at_the_rate_the_valve_meters_and_holds_when_the_shaft_stops() {
        let p = SteeringParams::default();
        let mut chain = SteeringChain::new(p);
        // Half command: 30 rpm at the shaft, 28 beyond the dead zone, within the pump's flow.
        run(&mut chain, 500, 0.5, true);
        let before = chain.wheel_angle_deg();
        run(&mut chain, 500, 0.5, true);
        let piston_speed = p.displacement * 28.0 / 60.0 / p.cap_area;
        let expected =
            (libm::asin(((before.to_radians().sin() * p.arm) + piston_speed * 0.5) / p.arm))
                .to_degrees()
                - before;
        let turned = chain.wheel_angle_deg() - before;
        assert!((turned - expected).abs() < 0.01, "{turned} vs {expected}");
        // The shaft stops: the valve closes and the wheel holds (follow-up).
        run(&mut chain, 300, 0.0, true);
        let held = chain.wheel_angle_deg();
        run(&mut chain, 2000, 0.0, true);
        assert_eq!(chain.wheel_angle_deg(), held);
        // The other way, on the rod side: faster for the same flow.
        let mut left = SteeringChain::new(p);
        run(&mut left, 1000, -0.5, true);
        assert!(left.wheel_angle_deg() < 0.0 && left.wheel_angle_deg().abs() > before.abs());
    }

    #[test]
    fn the_backup_valve_turns_the_wheel_at_its_rate_past_a_seized_shaft() {
        let mut chain = SteeringChain::new(SteeringParams::default());
        for _ in 0..1000 {
            chain.seize();
            chain.step(0.001, 0.0, true);
            chain.backup_flow(0.001, 5.0, true);
        }
        assert_eq!(chain.shaft_rpm(), 0.0);
        // 5°/s for a second, near 0° where the linkage is nearly linear.
        assert!(
            (chain.wheel_angle_deg() - 5.0).abs() < 0.05,
            "{}",
            chain.wheel_angle_deg()
        );
        // Without it, the seized shaft holds the wheel.
        let held = chain.wheel_angle_deg();
        for _ in 0..500 {
            chain.seize();
            chain.step(0.001, 0.0, true);
        }
        assert_eq!(chain.wheel_angle_deg(), held);
    }

    #[test]
    fn dead_zone_pressure_and_stroke_limit_the_motion() {
        let mut chain = SteeringChain::new(SteeringParams::default());
        // 1 rpm is inside the 2 rpm dead zone.
        run(&mut chain, 2000, 1.0 / 60.0, true);
        assert_eq!(chain.wheel_angle_deg(), 0.0);
        // A supply below the standstill load cannot turn a standing wheel, but can a rolling one.
        let weak = SteeringParams {
            supply_bar: 30.0,
            ..SteeringParams::default()
        };
        let mut standing = SteeringChain::new(weak);
        run(&mut standing, 1000, 1.0, false);
        assert_eq!(standing.wheel_angle_deg(), 0.0);
        let mut rolling = SteeringChain::new(weak);
        run(&mut rolling, 1000, 1.0, true);
        assert!(rolling.wheel_angle_deg() > 5.0);
        // Full command for long: the cylinder's end stop (asin(0.14/0.15) = 68.96°).
        run(&mut rolling, 10000, 1.0, true);
        assert!(
            (rolling.wheel_angle_deg() - 68.96).abs() < 0.01,
            "{}",
            rolling.wheel_angle_deg()
        );
    }

    #[test]
    fn the_sensor_quantises_adds_noise_and_shows_its_faults() {
        let mut chain = SteeringChain::new(SteeringParams {
            sensor_noise_deg: 0.0,
            ..SteeringParams::default()
        });
        run(&mut chain, 1000, 0.5, true);
        let mut rng = Rng::new(1);
        let reading = chain.sensor_deg(&mut rng);
        let quantum = 150.0 / 4095.0;
        assert!((reading - chain.wheel_angle_deg()).abs() <= quantum / 2.0 + 1e-9);
        assert!(
            ((reading + 75.0) / quantum - libm::round((reading + 75.0) / quantum)).abs() < 1e-6,
            "on the grid"
        );
        chain.set_fault(SensorFault::Stuck(3.0));
        assert!((chain.sensor_deg(&mut rng) - 3.0).abs() <= quantum);
        chain.set_fault(SensorFault::Drift(2.0));
        run(&mut chain, 1500, 0.0, true);
        let error = chain.sensor_deg(&mut rng) - chain.wheel_angle_deg();
        assert!((error - 3.0).abs() <= quantum, "{error}");
        chain.set_fault(SensorFault::OpenCircuit);
        assert_eq!(chain.sensor_deg(&mut rng), 75.0);
        // The second track still reads the wheel.
        assert!((chain.second_track_deg(&mut rng) - chain.wheel_angle_deg()).abs() <= quantum);
        // Noise: a thousand readings of a still wheel spread by about sigma.
        let noisy = SteeringChain::new(SteeringParams::default());
        let readings: Vec<f64> = (0..1000).map(|_| noisy.sensor_deg(&mut rng)).collect();
        let sigma = (readings.iter().map(|r| r * r).sum::<f64>() / 1000.0).sqrt();
        assert!((sigma - 0.05).abs() < 0.01, "{sigma}");
    }
}
