//! The tug's body: each wheel's rolling speed follows the forces on it (drive torque, brakes,
//! rolling resistance and grade, a quarter of the mass each), and the body moves by swerve
//! kinematics from the four wheels' angles and speeds (least squares: wheels that disagree
//! scrub). Also the sensors the body carries: IMU and wheel encoders.

use bywire_control::kinematics::{four_wheel, Odometry, Pose, Swerve, Twist, WheelState};

use crate::rng::Rng;

/// Gravity, m/s².
const G: f64 = 9.81;

/// Body parameters (defaults: an electric baggage tug).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChassisParams {
    /// Empty mass, kg.
    pub mass: f64,
    /// Payload, kg (up to 4,500).
    pub payload: f64,
    /// Rolling resistance coefficient.
    pub rolling: f64,
    /// Wheelbase, m.
    pub wheelbase: f64,
    /// Track, m.
    pub track: f64,
    /// Wheel radius, m.
    pub wheel_radius: f64,
}

impl Default for ChassisParams {
    fn default() -> Self {
        ChassisParams {
            mass: 6_000.0,
            payload: 0.0,
            rolling: 0.015,
            wheelbase: 3.2,
            track: 1.8,
            wheel_radius: 0.25,
        }
    }
}

/// What acts on one wheel.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WheelInput {
    /// Angle, degrees.
    pub angle_deg: f64,
    /// Drive torque along the rolling direction, N·m.
    pub drive_torque: f64,
    /// Brake torque against the motion (or holding at standstill), N·m.
    pub brake_torque: f64,
}

/// The body's state.
#[derive(Debug, Clone)]
pub struct Chassis {
    /// Parameters.
    pub params: ChassisParams,
    swerve: Swerve<4>,
    speeds: [f64; 4],
    angles: [f64; 4],
    /// Each wheel's angle (degrees, bits) and its cosine: a wheel held still keeps its angle
    /// step after step.
    headings: [(u64, f64); 4],
    /// The road's grade (bits) and the sine and cosine of its slope: one road for a run.
    slope: (u64, f64, f64),
    odometry: Odometry,
    twist: Twist,
    last_twist: Twist,
}

impl Chassis {
    /// A tug at rest at `pose`.
    pub fn new(params: ChassisParams, pose: Pose) -> Chassis {
        Chassis {
            params,
            swerve: four_wheel(params.wheelbase, params.track),
            speeds: [0.0; 4],
            angles: [0.0; 4],
            headings: [(0.0f64.to_bits(), 1.0); 4],
            slope: (0.0f64.to_bits(), 0.0, 1.0),
            odometry: Odometry::new(pose),
            twist: Twist::default(),
            last_twist: Twist::default(),
        }
    }

    /// Advance `dt` seconds on a road of `grade` (rise over run, uphill positive along the
    /// body's heading).
    pub fn step(&mut self, dt: f64, wheels: &[WheelInput; 4], grade: f64) {
        let p = self.params;
        let quarter = (p.mass + p.payload.max(0.0)) / 4.0;
        // The same for every wheel, and for every step on one road.
        if self.slope.0 != grade.to_bits() {
            let slope = libm::atan(grade);
            self.slope = (grade.to_bits(), libm::sin(slope), libm::cos(slope));
        }
        let (_, along_slope, across_slope) = self.slope;
        for (((speed, angle), heading), wheel) in self
            .speeds
            .iter_mut()
            .zip(self.angles.iter_mut())
            .zip(self.headings.iter_mut())
            .zip(wheels)
        {
            *angle = wheel.angle_deg;
            if heading.0 != wheel.angle_deg.to_bits() {
                *heading = (
                    wheel.angle_deg.to_bits(),
                    libm::cos(wheel.angle_deg.to_radians()),
                );
            }
            let heading = heading.1;
            // Grade acts along the body; each wheel feels it along its own heading.
            let gravity = -quarter * G * along_slope * heading;
            let drive = wheel.drive_torque / p.wheel_radius;
            let resist = quarter * G * across_slope * p.rolling
                + wheel.brake_torque.max(0.0) / p.wheel_radius;
            let pushing = drive + gravity;
            let next = if speed.abs() < 1e-6 && pushing.abs() <= resist {
                // Static: brakes and rolling resistance hold the wheel.
                0.0
            } else {
                let direction = if speed.abs() > 1e-6 {
                    speed.signum()
                } else {
                    pushing.signum()
                };
                let accel = (pushing - resist * direction) / quarter;
                let candidate = *speed + accel * dt;
                // Resistance stops a wheel; it does not reverse it.
                if *speed != 0.0
                    && candidate.signum() != speed.signum()
                    && (pushing * direction) < resist
                {
                    0.0
                } else {
                    candidate
                }
            };
            *speed = next;
        }
        let states: [WheelState; 4] = core::array::from_fn(|i| WheelState {
            angle: self.angles.get(i).copied().unwrap_or(0.0).to_radians(),
            speed: self.speeds.get(i).copied().unwrap_or(0.0),
        });
        self.last_twist = self.twist;
        self.twist = self.swerve.forward(&states).unwrap_or_default();
        let _ = self.odometry.update(dt, self.twist);
    }

    /// Where the tug is.
    pub fn pose(&self) -> Pose {
        self.odometry.pose
    }

    /// Its motion (body frame).
    pub fn twist(&self) -> Twist {
        self.twist
    }

    /// Each wheel's rolling speed, m/s.
    pub fn wheel_speeds(&self) -> [f64; 4] {
        self.speeds
    }

    /// What the IMU reads: yaw rate (rad/s) and longitudinal acceleration (m/s²) over the
    /// last step, with noise.
    pub fn imu(&self, dt: f64, rng: &mut Rng) -> (f64, f64) {
        let accel = if dt > 0.0 {
            (self.twist.vx - self.last_twist.vx) / dt
        } else {
            0.0
        };
        (
            self.twist.omega + rng.normal(0.002),
            accel + rng.normal(0.02),
        )
    }

    /// What the wheel encoders read: speeds quantised to `resolution` m/s.
    pub fn encoders(&self, resolution: f64) -> [f64; 4] {
        self.speeds.map(|s| {
            if resolution > 0.0 {
                libm::round(s / resolution) * resolution
            } else {
                s
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Run for `millis` milliseconds in 1 ms steps.
    fn run(chassis: &mut Chassis, millis: u32, wheels: [WheelInput; 4], grade: f64) {
        for _ in 0..millis {
            chassis.step(0.001, &wheels, grade);
        }
    }

    fn straight(torque: f64) -> [WheelInput; 4] {
        [WheelInput {
            angle_deg: 0.0,
            drive_torque: torque,
            brake_torque: 0.0,
        }; 4]
    }

    #[test]
    fn newtons_law_on_the_flat_and_on_a_grade() {
        let mut chassis = Chassis::new(ChassisParams::default(), Pose::default());
        // 4 × 500 N·m / 0.25 m = 8 kN on 6 t, less 1.5 % rolling resistance: 1.186 m/s².
        run(&mut chassis, 2000, straight(500.0), 0.0);
        let expected = (8_000.0 - 6_000.0 * G * 0.015) / 6_000.0 * 2.0;
        assert!(
            (chassis.twist().vx - expected).abs() < 1e-6,
            "{} vs {expected}",
            chassis.twist().vx
        );
        assert!(
            (chassis.pose().x - expected).abs() < 0.01,
            "x = v·t/2 = {}",
            chassis.pose().x
        );
        assert!(chassis.pose().y.abs() < 1e-9);
        // Payload slows it; a 5 % grade without drive rolls it back.
        let mut loaded = Chassis::new(
            ChassisParams {
                payload: 4_500.0,
                ..ChassisParams::default()
            },
            Pose::default(),
        );
        run(&mut loaded, 2000, straight(500.0), 0.0);
        assert!(loaded.twist().vx < chassis.twist().vx * 0.6);
        let mut hill = Chassis::new(ChassisParams::default(), Pose::default());
        run(&mut hill, 1000, straight(0.0), 0.05);
        assert!(hill.twist().vx < -0.2);
        // Brakes hold it on that grade.
        let mut held = Chassis::new(ChassisParams::default(), Pose::default());
        let braked = [WheelInput {
            angle_deg: 0.0,
            drive_torque: 0.0,
            brake_torque: 1_000.0,
        }; 4];
        run(&mut held, 1000, braked, 0.05);
        assert_eq!(held.twist().vx, 0.0);
    }

    #[test]
    fn crab_moves_sideways_and_rolling_resistance_stops_it() {
        let mut chassis = Chassis::new(ChassisParams::default(), Pose::default());
        let crab = [WheelInput {
            angle_deg: 30.0,
            drive_torque: 300.0,
            brake_torque: 0.0,
        }; 4];
        run(&mut chassis, 2000, crab, 0.0);
        let t = chassis.twist();
        assert!(
            (libm::atan2(t.vy, t.vx).to_degrees() - 30.0).abs() < 1e-6,
            "crab: parallel wheels, no yaw"
        );
        assert!(t.omega.abs() < 1e-9);
        run(
            &mut chassis,
            30_000,
            [WheelInput {
                angle_deg: 30.0,
                ..WheelInput::default()
            }; 4],
            0.0,
        );
        assert_eq!(
            chassis.wheel_speeds(),
            [0.0; 4],
            "rolled to a stop, not backwards"
        );
        let mut rng = Rng::new(3);
        let (yaw_rate, _) = chassis.imu(0.001, &mut rng);
        assert!(yaw_rate.abs() < 0.01);
        assert_eq!(
            Chassis::new(ChassisParams::default(), Pose::default()).encoders(0.01),
            [0.0; 4]
        );
    }
}
