//! A wheel's drive: the motor and its controller in velocity mode (torque and power limits,
//! regenerative braking limited by speed and state of charge), the friction brake, the
//! spring-applied parking brake, and the coordinator that blends regeneration and friction.

/// Drive and brake parameters of one wheel (defaults: a tug's wheel module).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveParams {
    /// Wheel radius, m.
    pub wheel_radius: f64,
    /// Motor torque limit at the wheel, N·m.
    pub max_torque: f64,
    /// Motor power limit, W.
    pub max_power: f64,
    /// Regenerative torque limit at the wheel, N·m.
    pub max_regen_torque: f64,
    /// Below this speed regeneration fades out, m/s.
    pub regen_fade_speed: f64,
    /// Above this state of charge the battery takes no regeneration.
    pub regen_soc_limit: f64,
    /// Drive efficiency (motor and inverter).
    pub efficiency: f64,
    /// Velocity controller gain: N·m per m/s of speed error.
    pub speed_gain: f64,
    /// Friction brake torque at full demand, N·m.
    pub max_brake_torque: f64,
    /// Friction brake response time constant, s.
    pub brake_time_constant: f64,
    /// Parking brake holding torque, N·m.
    pub parking_torque: f64,
}

impl Default for DriveParams {
    fn default() -> Self {
        DriveParams {
            wheel_radius: 0.25,
            max_torque: 1_200.0,
            max_power: 12_000.0,
            max_regen_torque: 600.0,
            regen_fade_speed: 0.5,
            regen_soc_limit: 0.95,
            efficiency: 0.9,
            speed_gain: 2_000.0,
            max_brake_torque: 2_500.0,
            brake_time_constant: 0.08,
            parking_torque: 3_000.0,
        }
    }
}

/// The motor's torque (positive: along the wheel's rolling direction) and the electrical
/// power it takes (negative: regenerated).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorOutput {
    /// Torque at the wheel, N·m.
    pub torque: f64,
    /// Electrical power, W.
    pub power: f64,
}

/// How a braking demand was shared.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BrakeShare {
    /// Regenerative part, N·m.
    pub regen: f64,
    /// Friction part, N·m.
    pub friction: f64,
}

/// The braking coordinator: regeneration first, up to what it can take now, friction for the
/// rest.
pub fn blend(demand: f64, regen_available: f64) -> BrakeShare {
    let demand = demand.max(0.0);
    let regen = demand.min(regen_available.max(0.0));
    BrakeShare {
        regen,
        friction: demand - regen,
    }
}

/// One wheel's drive and brakes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelDrive {
    /// Parameters.
    pub params: DriveParams,
    brake_torque: f64,
    parked: bool,
}

impl WheelDrive {
    /// A drive with the parking brake applied (as a powered-off tug stands).
    pub fn new(params: DriveParams) -> WheelDrive {
        WheelDrive {
            params,
            brake_torque: 0.0,
            parked: true,
        }
    }

    /// Regenerative torque available at `speed` (m/s) and state of charge `soc`.
    pub fn regen_available(&self, speed: f64, soc: f64) -> f64 {
        let p = &self.params;
        if soc >= p.regen_soc_limit {
            return 0.0;
        }
        let fade = if p.regen_fade_speed > 0.0 {
            (speed.abs() / p.regen_fade_speed).min(1.0)
        } else {
            1.0
        };
        p.max_regen_torque * fade
    }

    /// The velocity controller: torque toward `setpoint` (m/s) at wheel speed `speed`, within
    /// the torque limit, the power limit, and (when it brakes) the regeneration limit.
    pub fn motor(&self, setpoint: f64, speed: f64, soc: f64) -> MotorOutput {
        let p = &self.params;
        let demand = (p.speed_gain * (setpoint - speed)).clamp(-p.max_torque, p.max_torque);
        let omega = speed / p.wheel_radius;
        let power_limited = if omega.abs() > 1e-6 {
            demand.clamp(-p.max_power / omega.abs(), p.max_power / omega.abs())
        } else {
            demand
        };
        // Braking (torque against the motion) is regeneration: limited by what it can take.
        let braking = power_limited * speed < 0.0;
        let torque = if braking {
            let limit = self.regen_available(speed, soc);
            power_limited.clamp(-limit, limit)
        } else {
            power_limited
        };
        let mechanical = torque * omega;
        let power = if mechanical >= 0.0 {
            mechanical / p.efficiency
        } else {
            mechanical * p.efficiency
        };
        MotorOutput { torque, power }
    }

    /// Advance the friction brake toward `demand` (0–1 of its full torque).
    pub fn step_brake(&mut self, dt: f64, demand: f64) {
        let p = &self.params;
        let target = demand.clamp(0.0, 1.0) * p.max_brake_torque;
        let alpha = if p.brake_time_constant > 0.0 {
            (dt / p.brake_time_constant).min(1.0)
        } else {
            1.0
        };
        self.brake_torque += (target - self.brake_torque) * alpha;
    }

    /// Friction brake torque now, N·m.
    pub fn brake_torque(&self) -> f64 {
        self.brake_torque
    }

    /// Release (powered) or apply (springs) the parking brake.
    pub fn set_parked(&mut self, parked: bool) {
        self.parked = parked;
    }

    /// The parking brake is applied.
    pub fn is_parked(&self) -> bool {
        self.parked
    }

    /// Torque opposing the wheel's motion from the brakes, N·m (friction, plus the parking
    /// brake when applied).
    pub fn holding_torque(&self) -> f64 {
        self.brake_torque
            + if self.parked {
                self.params.parking_torque
            } else {
                0.0
            }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_motor_respects_torque_power_and_regeneration_limits() {
        let drive = WheelDrive::new(DriveParams::default());
        // From standstill: the torque limit.
        assert_eq!(drive.motor(5.0, 0.0, 0.5).torque, 1_200.0);
        // At 4 m/s (16 rad/s): 12 kW allows 750 N·m.
        let at_speed = drive.motor(8.0, 4.0, 0.5);
        assert!((at_speed.torque - 750.0).abs() < 1e-9);
        assert!((at_speed.power - 12_000.0 / 0.9).abs() < 1e-6);
        // Braking at speed: regeneration, limited, power flows back.
        let braking = drive.motor(0.0, 4.0, 0.5);
        assert_eq!(braking.torque, -600.0);
        assert!(braking.power < 0.0);
        // A full battery takes nothing; near standstill regeneration fades.
        assert_eq!(drive.motor(0.0, 4.0, 0.97).torque, 0.0);
        assert!((drive.regen_available(0.25, 0.5) - 300.0).abs() < 1e-9);
    }

    #[test]
    fn the_coordinator_uses_regeneration_first_and_friction_for_the_rest() {
        assert_eq!(
            blend(400.0, 600.0),
            BrakeShare {
                regen: 400.0,
                friction: 0.0
            }
        );
        assert_eq!(
            blend(1_000.0, 600.0),
            BrakeShare {
                regen: 600.0,
                friction: 400.0
            }
        );
        assert_eq!(
            blend(1_000.0, 0.0),
            BrakeShare {
                regen: 0.0,
                friction: 1_000.0
            }
        );
        assert_eq!(
            blend(-5.0, 600.0),
            BrakeShare {
                regen: 0.0,
                friction: 0.0
            }
        );
    }

    #[test]
    fn brakes_respond_with_their_time_constant_and_the_parking_brake_holds() {
        let mut drive = WheelDrive::new(DriveParams::default());
        assert!(drive.is_parked());
        drive.set_parked(false);
        for _ in 0..80 {
            drive.step_brake(0.001, 1.0);
        }
        // One time constant: 1 − 1/e of full torque (within the Euler step's error).
        let fraction = drive.brake_torque() / 2_500.0;
        assert!((fraction - 0.632).abs() < 0.01, "{fraction}");
        drive.set_parked(true);
        assert!((drive.holding_torque() - drive.brake_torque() - 3_000.0).abs() < 1e-9);
    }
}
