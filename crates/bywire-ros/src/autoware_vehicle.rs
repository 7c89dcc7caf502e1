//! Autoware's vehicle interface in terms of a profile's vehicle: `Control` (and `Twist`) into
//! the vehicle's command, the vehicle's feedback into Autoware's reports. No I/O: the DDS side
//! is `vehicle_interface`.
//!
//! Autoware steers a bicycle: one tire angle δ on a wheelbase L, a path of curvature tan δ / L.
//! A four-wheel-steered vehicle in normal mode turns front and rear in counter-phase, on
//! curvature 2 tan δf / L; the same path wants δf = atan(tan δ / 2), and the angle reported back
//! is the bicycle's equivalent. In crab mode the angle is the direction of travel; in a tank
//! turn there is no steering angle (the speed is the wheels' speed about the centre). Commands
//! beyond the profile's limits are refused, never clamped; a brake beyond the vehicle's is its
//! hardest.

use bywire_control::kinematics::{four_wheel, WheelState};
use bywire_core::num::Short;
use bywire_core::Timestamp;
use bywire_vehicle::ads::{AdsCommand, VehicleState};
use bywire_vehicle::command::{
    ControlMode, DegradationLevel, FaultClass, Gear, SteeringMode, TurnIndicators, WatchdogLevel,
};
use bywire_vehicle::profile::Limits;
use core::time::Duration;

use crate::msg::{
    self, control_mode, gear, hazard_lights, turn_indicators, Header, JointState, Time, Twist,
};

/// The vehicle's geometry as the mapping needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Wheelbase, m.
    pub wheelbase: f64,
    /// Track, m.
    pub track: f64,
    /// Wheel diameter, m (for the drive joints' rad/s).
    pub wheel_diameter: f64,
    /// Front and rear steer in counter-phase in normal mode (a 4WS vehicle).
    pub four_wheel_steer: bool,
}

/// The vehicle's steering command (degrees) for Autoware's tire angle (rad) in `mode`.
pub fn steering_command(tire_angle: f64, mode: SteeringMode, g: &Geometry) -> f64 {
    match mode {
        SteeringMode::Normal if g.four_wheel_steer => {
            libm::atan(libm::tan(tire_angle) / 2.0).to_degrees()
        }
        SteeringMode::Normal | SteeringMode::Crab => tire_angle.to_degrees(),
        SteeringMode::Tank => 0.0,
    }
}

/// Autoware's tire angle (rad) for the vehicle's steering (degrees) in `mode`.
pub fn tire_angle(steering_deg: f64, mode: SteeringMode, g: &Geometry) -> f64 {
    let angle = steering_deg.to_radians();
    match mode {
        SteeringMode::Normal if g.four_wheel_steer => libm::atan(2.0 * libm::tan(angle)),
        SteeringMode::Normal | SteeringMode::Crab => angle,
        SteeringMode::Tank => 0.0,
    }
}

/// Brake (%) for a commanded acceleration: a deceleration as a share of the vehicle's
/// largest; none when accelerating.
pub fn brake_percent(acceleration: f64, max_deceleration: f64) -> f64 {
    if acceleration >= 0.0 || max_deceleration <= 0.0 {
        0.0
    } else {
        (-acceleration / max_deceleration * 100.0).min(100.0)
    }
}

/// A command mapped from an Autoware input, and what was taken as less than asked.
#[derive(Debug, Clone, PartialEq)]
pub struct Mapped {
    /// The command to send.
    pub command: AdsCommand,
    /// Set when a brake beyond the vehicle's was taken as its hardest.
    pub warning: Option<String>,
}

/// The largest tire angle (rad) Autoware may ask for in `mode`: the profile's steering limit
/// as a bicycle's tire angle. A tank turn takes no angle; its commands are checked as normal
/// steering's.
pub fn largest_tire_angle(mode: SteeringMode, g: &Geometry, limits: &Limits) -> f64 {
    let mode = match mode {
        SteeringMode::Tank => SteeringMode::Normal,
        other => other,
    };
    tire_angle(limits.steering_deg, mode, g)
}

/// The command for an Autoware `Control`, from the previous one (gear, modes and requests
/// kept), or why it is refused. Every field is checked before any conversion, in Autoware's
/// own terms: the tire angle within the profile's limit as a tire angle (and within ±90°,
/// beyond which the 4WS mapping's tangent would wrap to another, often reversed, angle), the
/// rotation rate within the profile's steering rate, the velocity within its speed, the
/// acceleration within its deceleration either way. A deceleration beyond the vehicle's is
/// a request to brake as hard as it can: a stop at full brake, with a warning.
pub fn from_control(
    control: &msg::Control,
    previous: AdsCommand,
    g: &Geometry,
    limits: &Limits,
) -> Result<Mapped, String> {
    let lateral = &control.lateral;
    let longitudinal = &control.longitudinal;
    let angle = f64::from(lateral.steering_tire_angle);
    let rate = f64::from(lateral.steering_tire_rotation_rate);
    let velocity = f64::from(longitudinal.velocity);
    let acceleration = f64::from(longitudinal.acceleration);
    let jerk = f64::from(longitudinal.jerk);
    for (name, value, defined) in [
        ("steering_tire_angle", angle, true),
        (
            "steering_tire_rotation_rate",
            rate,
            lateral.is_defined_steering_tire_rotation_rate,
        ),
        ("velocity", velocity, true),
        (
            "acceleration",
            acceleration,
            longitudinal.is_defined_acceleration,
        ),
        ("jerk", jerk, longitudinal.is_defined_jerk),
    ] {
        // −∞ m/s² is the one infinity with a meaning: brake as hard as the vehicle can.
        let braking = name == "acceleration" && value == f64::NEG_INFINITY;
        if defined && !value.is_finite() && !braking {
            return Err(format!("{name} is not finite"));
        }
    }
    let mode = previous.steering_mode;
    let largest_angle = largest_tire_angle(mode, g, limits);
    if !(angle.abs() < core::f64::consts::FRAC_PI_2 && angle.abs() <= largest_angle) {
        return Err(format!(
            "steering_tire_angle {} rad: beyond ±{:.4} rad (this vehicle's ±{}° in {mode} \
             steering)",
            Short(lateral.steering_tire_angle),
            largest_angle,
            limits.steering_deg
        ));
    }
    // The mapping's slope is at most 2 (4WS counter-phase, near straight ahead).
    let per_axle = if g.four_wheel_steer && mode != SteeringMode::Crab {
        2.0
    } else {
        1.0
    };
    let largest_rate = limits.steering_rate_deg_s.to_radians() * per_axle;
    if lateral.is_defined_steering_tire_rotation_rate && rate.abs() > largest_rate {
        return Err(format!(
            "steering_tire_rotation_rate {} rad/s: beyond ±{largest_rate:.4} rad/s",
            Short(lateral.steering_tire_rotation_rate)
        ));
    }
    if velocity.abs() > limits.speed_m_s {
        return Err(format!(
            "velocity {} m/s: beyond ±{} m/s",
            Short(longitudinal.velocity),
            limits.speed_m_s
        ));
    }
    let acceleration = if longitudinal.is_defined_acceleration {
        acceleration
    } else {
        0.0
    };
    if acceleration > limits.deceleration_m_s2 {
        return Err(format!(
            "acceleration {} m/s²: beyond this vehicle's {} m/s²",
            Short(longitudinal.acceleration),
            limits.deceleration_m_s2
        ));
    }
    let steering = steering_command(angle, mode, g);
    if acceleration < -limits.deceleration_m_s2 {
        let warning = format!(
            "acceleration {} m/s²: a deceleration beyond this vehicle's {} m/s², braking as \
             hard as it can (a stop at full brake)",
            Short(longitudinal.acceleration),
            limits.deceleration_m_s2
        );
        let command = AdsCommand {
            steering,
            velocity: 0.0,
            brake: 100.0,
            ..previous
        };
        limits.check(&command)?;
        return Ok(Mapped {
            command,
            warning: Some(warning),
        });
    }
    let command = AdsCommand {
        steering,
        velocity,
        brake: brake_percent(acceleration, limits.deceleration_m_s2),
        ..previous
    };
    limits.check(&command)?;
    Ok(Mapped {
        command,
        warning: None,
    })
}

/// Below this a twist component counts as zero.
const STILL: f64 = 1e-6;

/// The command for a `cmd_vel` twist, through the 4WS kinematics: sideways motion without
/// turning is crab, turning on the spot a tank turn, anything else normal steering on the
/// twist's curvature. A vehicle without four-wheel steer takes only the normal case.
pub fn from_twist(
    twist: &Twist,
    previous: AdsCommand,
    g: &Geometry,
    limits: &Limits,
) -> Result<AdsCommand, String> {
    let (vx, vy, omega) = (twist.linear.x, twist.linear.y, twist.angular.z);
    if ![vx, vy, omega].iter().all(|v| v.is_finite()) {
        return Err("a twist component is not finite".into());
    }
    let moving = vx.abs() > STILL || vy.abs() > STILL;
    let (steering_mode, steering, velocity) = if g.four_wheel_steer && vy.abs() > STILL {
        if omega.abs() > STILL {
            return Err("turning while moving sideways: a 4WS vehicle crabs or turns".into());
        }
        // Crab: the wheels point where the body goes; backwards is reverse at the mirrored angle.
        let (speed, angle) = if vx < 0.0 {
            (-libm::hypot(vx, vy), libm::atan2(-vy, -vx))
        } else {
            (libm::hypot(vx, vy), libm::atan2(vy, vx))
        };
        (SteeringMode::Crab, angle.to_degrees(), speed)
    } else if g.four_wheel_steer && !moving && omega.abs() > STILL {
        let radius = libm::hypot(g.wheelbase / 2.0, g.track / 2.0);
        (SteeringMode::Tank, 0.0, omega * radius)
    } else if !moving {
        (previous.steering_mode, previous.steering, 0.0)
    } else {
        if vy.abs() > STILL {
            return Err("sideways motion needs four-wheel steer".into());
        }
        let curvature = omega / vx;
        let per_axle = if g.four_wheel_steer { 2.0 } else { 1.0 };
        let angle = libm::atan(curvature * g.wheelbase / per_axle);
        (SteeringMode::Normal, angle.to_degrees(), vx)
    };
    let command = AdsCommand {
        steering,
        velocity,
        brake: 0.0,
        steering_mode,
        ..previous
    };
    limits.check(&command)?;
    Ok(command)
}

/// The gear of an Autoware gear code; `None` for `NONE` (no change).
pub fn gear_from_code(code: u8) -> Result<Option<Gear>, String> {
    match code {
        gear::NONE => Ok(None),
        gear::NEUTRAL => Ok(Some(Gear::Neutral)),
        // Autoware's numbered drive gears are all forward.
        gear::DRIVE..=19 => Ok(Some(Gear::Drive)),
        gear::REVERSE | 21 => Ok(Some(Gear::Reverse)),
        gear::PARK => Ok(Some(Gear::Park)),
        other => Err(format!(
            "gear code {other}: this vehicle has park, reverse, neutral and drive"
        )),
    }
}

/// Autoware's code for a gear.
pub fn gear_code(g: Gear) -> u8 {
    match g {
        Gear::Park => gear::PARK,
        Gear::Reverse => gear::REVERSE,
        Gear::Neutral => gear::NEUTRAL,
        Gear::Drive => gear::DRIVE,
    }
}

/// The turn indicators an Autoware `TurnIndicatorsCommand` code asks for (`None`: no command).
pub fn turn_indicators_from_code(code: u8) -> Result<Option<TurnIndicators>, String> {
    match code {
        turn_indicators::NO_COMMAND => Ok(None),
        turn_indicators::DISABLE => Ok(Some(TurnIndicators::Off)),
        turn_indicators::ENABLE_LEFT => Ok(Some(TurnIndicators::Left)),
        turn_indicators::ENABLE_RIGHT => Ok(Some(TurnIndicators::Right)),
        other => Err(format!(
            "turn indicators code {other}: expected 0 (no command), 1 (off), 2 (left), 3 (right)"
        )),
    }
}

/// Autoware's `TurnIndicatorsReport` code for the turn indicators.
pub fn turn_indicators_code(lights: TurnIndicators) -> u8 {
    match lights {
        TurnIndicators::Off => turn_indicators::DISABLE,
        TurnIndicators::Left => turn_indicators::ENABLE_LEFT,
        TurnIndicators::Right => turn_indicators::ENABLE_RIGHT,
    }
}

/// Whether an Autoware `HazardLightsCommand` code asks for the hazard lights on (`None`: no
/// command).
pub fn hazard_lights_from_code(code: u8) -> Result<Option<bool>, String> {
    match code {
        hazard_lights::NO_COMMAND => Ok(None),
        hazard_lights::DISABLE => Ok(Some(false)),
        hazard_lights::ENABLE => Ok(Some(true)),
        other => Err(format!(
            "hazard lights code {other}: expected 0 (no command), 1 (off), 2 (on)"
        )),
    }
}

/// Autoware's `HazardLightsReport` code for the hazard lights.
pub fn hazard_lights_code(on: bool) -> u8 {
    if on {
        hazard_lights::ENABLE
    } else {
        hazard_lights::DISABLE
    }
}

/// A degradation level as the vehicle interface shows it: its name, with the fault it is
/// reported with (`minimal-risk (actuator-backup)`).
pub fn degradation_text(level: DegradationLevel, reason: Option<FaultClass>) -> String {
    match reason {
        Some(reason) => format!("{level} ({reason})"),
        None => level.to_string(),
    }
}

/// Autoware's control mode for the vehicle's reported mode and watchdog level (`None`: no
/// valid feedback; a profile without a watchdog level reports none). Autonomous with the
/// watchdog braking (full braking, or awaiting a re-engage) is disengaged: the vehicle no
/// longer follows the ADS and drives again only once engaged, so Autoware must not take it
/// for autonomous. Holding or decelerating is still autonomous: the next command resumes.
pub fn control_mode_code(mode: Option<ControlMode>, watchdog: Option<WatchdogLevel>) -> u8 {
    let braked = matches!(
        watchdog,
        Some(WatchdogLevel::FullBraking | WatchdogLevel::AwaitingEngage)
    );
    match mode {
        None | Some(ControlMode::Calibration) => control_mode::NOT_READY,
        Some(ControlMode::Autonomous) if braked => control_mode::DISENGAGED,
        Some(ControlMode::Autonomous) => control_mode::AUTONOMOUS,
        Some(ControlMode::Manual) => control_mode::MANUAL,
        Some(ControlMode::Estop) => control_mode::DISENGAGED,
    }
}

/// Longitudinal and lateral velocity (m/s) and heading rate (rad/s): from the four wheels'
/// speeds and angles when they are fresh (the body's motion that fits them best), else from
/// the speed and steering reported, through the steering mode's kinematics.
pub fn body_velocity(
    state: &VehicleState,
    now: Timestamp,
    fresh: Duration,
    g: &Geometry,
) -> Option<(f64, f64, f64)> {
    let speeds = state.wheel_speeds.fresh(now, fresh);
    let angles = state.wheel_angles.fresh(now, fresh);
    if let (Some(speeds), Some(angles)) = (speeds, angles) {
        let mut wheels = [WheelState::default(); 4];
        for ((w, s), a) in wheels.iter_mut().zip(speeds).zip(angles) {
            *w = WheelState {
                speed: s,
                angle: a.to_radians(),
            };
        }
        if let Some(t) = four_wheel(g.wheelbase, g.track).forward(&wheels) {
            return Some((t.vx, t.vy, t.omega));
        }
    }
    let v = state.velocity.fresh(now, fresh)?;
    let steering = state.steering.fresh(now, fresh).unwrap_or(0.0).to_radians();
    let mode = state.steering_mode.fresh(now, fresh).unwrap_or_default();
    Some(match mode {
        SteeringMode::Normal => {
            let per_axle = if g.four_wheel_steer { 2.0 } else { 1.0 };
            (v, 0.0, v * per_axle * libm::tan(steering) / g.wheelbase)
        }
        SteeringMode::Crab => (v * libm::cos(steering), v * libm::sin(steering), 0.0),
        SteeringMode::Tank => (0.0, 0.0, v / libm::hypot(g.wheelbase / 2.0, g.track / 2.0)),
    })
}

/// The joints of the four wheels, in this order.
pub const JOINTS: [&str; 8] = [
    "fl_steer", "fr_steer", "rl_steer", "rr_steer", "fl_drive", "fr_drive", "rl_drive", "rr_drive",
];

/// The wheels as joints: steering joints at their angle (rad), drive joints at their rotation
/// (rad, integrated by the caller) and rate (rad/s); `None` without fresh wheel feedback.
pub fn joint_state(
    state: &VehicleState,
    now: Timestamp,
    fresh: Duration,
    g: &Geometry,
    drive_rotation: &[f64; 4],
    stamp: Time,
) -> Option<JointState> {
    let speeds = state.wheel_speeds.fresh(now, fresh)?;
    let angles = state.wheel_angles.fresh(now, fresh)?;
    let radius = g.wheel_diameter / 2.0;
    let mut position: Vec<f64> = angles.iter().map(|a| a.to_radians()).collect();
    position.extend_from_slice(drive_rotation);
    let mut velocity = vec![0.0; 4];
    velocity.extend(
        speeds
            .iter()
            .map(|s| if radius > 0.0 { s / radius } else { 0.0 }),
    );
    Some(JointState {
        header: Header {
            stamp,
            frame_id: "base_link".into(),
        },
        name: JOINTS.iter().map(|j| j.to_string()).collect(),
        position,
        velocity,
        effort: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_degradation_level_shows_with_its_reason() {
        assert_eq!(degradation_text(DegradationLevel::Nominal, None), "nominal");
        assert_eq!(
            degradation_text(
                DegradationLevel::MinimalRisk,
                Some(FaultClass::ActuatorBackup)
            ),
            "minimal-risk (actuator-backup)"
        );
    }

    const TUG: Geometry = Geometry {
        wheelbase: 3.2,
        track: 1.8,
        wheel_diameter: 0.5,
        four_wheel_steer: true,
    };

    fn limits() -> Limits {
        Limits {
            steering_deg: 40.0,
            steering_rate_deg_s: 30.0,
            speed_m_s: 5.0,
            deceleration_m_s2: 4.0,
        }
    }

    #[test]
    fn a_bicycle_angle_becomes_the_same_path_in_counter_phase() {
        let delta = 0.3f64;
        let front = steering_command(delta, SteeringMode::Normal, &TUG).to_radians();
        // The bicycle's curvature equals the 4WS curvature.
        let bicycle = libm::tan(delta) / TUG.wheelbase;
        let four_ws = 2.0 * libm::tan(front) / TUG.wheelbase;
        assert!((bicycle - four_ws).abs() < 1e-12);
        // And back.
        let back = tire_angle(front.to_degrees(), SteeringMode::Normal, &TUG);
        assert!((back - delta).abs() < 1e-12);
        let front_steered = Geometry {
            four_wheel_steer: false,
            ..TUG
        };
        assert!(
            (steering_command(delta, SteeringMode::Normal, &front_steered) - delta.to_degrees())
                .abs()
                < 1e-12
        );
        assert_eq!(steering_command(delta, SteeringMode::Tank, &TUG), 0.0);
    }

    #[test]
    fn control_messages_are_checked_and_refused_not_clamped() {
        let c = crate::control_output::control(0.2, 0.0, 2.0, -2.0, 0);
        let command = from_control(&c, AdsCommand::default(), &TUG, &limits())
            .unwrap()
            .command;
        assert_eq!(command.velocity, 2.0);
        assert_eq!(command.brake, 50.0);
        let too_fast = crate::control_output::control(0.0, 0.0, 6.0, 0.0, 0);
        assert!(from_control(&too_fast, command, &TUG, &limits())
            .unwrap_err()
            .contains("velocity 6"));
        let nan = crate::control_output::control(f32::NAN, 0.0, 1.0, 0.0, 0);
        assert_eq!(
            from_control(&nan, command, &TUG, &limits()).unwrap_err(),
            "steering_tire_angle is not finite"
        );
        // 1.0 rad at the tire is 37.9° at the front in counter-phase: within 40°; 1.1 rad is
        // 44.5°, beyond.
        let wide = crate::control_output::control(1.0, 0.0, 1.0, 0.0, 0);
        assert!(from_control(&wide, command, &TUG, &limits()).is_ok());
        let wider = crate::control_output::control(1.1, 0.0, 1.0, 0.0, 0);
        assert!(from_control(&wider, command, &TUG, &limits()).is_err());
    }

    /// Every field of a `Control`, out of range, not finite, or in the wrong unit: refused
    /// before any conversion, or (a deceleration beyond the vehicle's) a stop at full brake.
    #[test]
    fn every_control_field_is_range_checked_before_conversion() {
        use crate::control_output::control;
        let previous = AdsCommand::default();
        let map = |c: &msg::Control| from_control(c, previous, &TUG, &limits());
        let refused = |c: &msg::Control, says: &str| {
            let why = map(c).unwrap_err();
            assert!(why.contains(says), "{why} (wanted {says})");
        };
        // Degrees sent as radians, or a wrapped angle: the 4WS tangent would have turned
        // 3.0 rad into -4.1°, 2.5 rad into -20.5° and 100 rad into -16.4°.
        for angle in [
            3.0,
            2.5,
            100.0,
            -3.0,
            1.6,
            core::f32::consts::FRAC_PI_2,
            1.04,
        ] {
            refused(&control(angle, 0.0, 1.0, 0.0, 0), "steering_tire_angle");
        }
        assert!(map(&control(1.03, 0.0, 1.0, 0.0, 0)).is_ok());
        // Front-steered, in crab and in tank mode the limit is the profile's own angle.
        let front_steered = Geometry {
            four_wheel_steer: false,
            ..TUG
        };
        let crab = AdsCommand {
            steering_mode: SteeringMode::Crab,
            ..previous
        };
        for (g, p) in [(&front_steered, previous), (&TUG, crab)] {
            assert!(from_control(&control(0.69, 0.0, 1.0, 0.0, 0), p, g, &limits()).is_ok());
            assert!(from_control(&control(0.71, 0.0, 1.0, 0.0, 0), p, g, &limits()).is_err());
        }
        let tank = AdsCommand {
            steering_mode: SteeringMode::Tank,
            ..previous
        };
        assert!(from_control(&control(3.0, 0.0, 1.0, 0.0, 0), tank, &TUG, &limits()).is_err());
        // 30°/s sent as 30 rad/s; the tire's rate may be twice the wheel's in counter-phase.
        refused(
            &control(0.0, 30.0, 1.0, 0.0, 0),
            "steering_tire_rotation_rate 30",
        );
        assert!(map(&control(0.0, 1.04, 1.0, 0.0, 0)).is_ok());
        refused(
            &control(0.0, f32::INFINITY, 1.0, 0.0, 0),
            "rotation_rate is not finite",
        );
        // 18 km/h sent for 5 m/s.
        refused(&control(0.0, 0.0, 18.0, 0.0, 0), "velocity 18");
        refused(
            &control(0.0, 0.0, f32::NAN, 0.0, 0),
            "velocity is not finite",
        );
        refused(
            &control(0.0, 0.0, 1.0, 1e30, 0),
            "acceleration 1e30 m/s²: beyond",
        );
        refused(&control(0.0, 0.0, 1.0, 4.5, 0), "acceleration 4.5");
        refused(
            &control(0.0, 0.0, 1.0, f32::NAN, 0),
            "acceleration is not finite",
        );
        refused(
            &control(0.0, 0.0, 1.0, f32::INFINITY, 0),
            "acceleration is not finite",
        );
        let mut jerky = control(0.0, 0.0, 1.0, 0.0, 0);
        jerky.longitudinal.jerk = f32::NAN;
        assert!(map(&jerky).is_ok(), "an undefined jerk is not looked at");
        jerky.longitudinal.is_defined_jerk = true;
        refused(&jerky, "jerk is not finite");
        // Braking harder than the vehicle can is braking as hard as it can: a stop, never
        // full brake beside a speed to keep.
        for acceleration in [f32::NEG_INFINITY, -1e30, -9.81, -4.5] {
            let stop = map(&control(0.1, 0.0, 1.5, acceleration, 0)).unwrap();
            assert_eq!((stop.command.velocity, stop.command.brake), (0.0, 100.0));
            assert!(stop.warning.unwrap().contains("braking as hard as it can"));
        }
        let firm = map(&control(0.1, 0.0, 1.5, -4.0, 0)).unwrap();
        assert_eq!((firm.command.velocity, firm.command.brake), (1.5, 100.0));
        assert_eq!(firm.warning, None);
    }

    fn twist(vx: f64, vy: f64, wz: f64) -> Twist {
        Twist {
            linear: msg::Vector3 {
                x: vx,
                y: vy,
                z: 0.0,
            },
            angular: msg::Vector3 {
                x: 0.0,
                y: 0.0,
                z: wz,
            },
        }
    }

    #[test]
    fn twists_choose_the_steering_mode() {
        let p = AdsCommand::default();
        let crab = from_twist(&twist(1.0, 0.5, 0.0), p, &TUG, &limits()).unwrap();
        assert_eq!(crab.steering_mode, SteeringMode::Crab);
        assert!((crab.steering - libm::atan(0.5).to_degrees()).abs() < 1e-9);
        assert!((crab.velocity - 1.25f64.sqrt()).abs() < 1e-9);
        assert!(from_twist(&twist(1.0, 1.0, 0.0), p, &TUG, &limits())
            .unwrap_err()
            .contains("steering 45"));
        let back = from_twist(&twist(-1.0, 0.5, 0.0), p, &TUG, &limits()).unwrap();
        assert!(back.velocity < 0.0 && back.steering < 0.0);
        let tank = from_twist(&twist(0.0, 0.0, 0.5), p, &TUG, &limits()).unwrap();
        assert_eq!(tank.steering_mode, SteeringMode::Tank);
        assert!((tank.velocity - 0.5 * libm::hypot(1.6, 0.9)).abs() < 1e-9);
        let turn = from_twist(&twist(2.0, 0.0, 0.25), p, &TUG, &limits()).unwrap();
        assert_eq!(turn.steering_mode, SteeringMode::Normal);
        // curvature 0.125 1/m: 2 tan(front) / L.
        assert!((2.0 * libm::tan(turn.steering.to_radians()) / 3.2 - 0.125).abs() < 1e-12);
        assert!(from_twist(&twist(1.0, 1.0, 0.1), p, &TUG, &limits()).is_err());
        assert!(from_twist(&twist(f64::NAN, 0.0, 0.0), p, &TUG, &limits()).is_err());
    }

    #[test]
    fn gear_and_mode_codes_follow_autoware() {
        assert_eq!(gear_from_code(0), Ok(None));
        assert_eq!(gear_from_code(2), Ok(Some(Gear::Drive)));
        assert_eq!(gear_from_code(20), Ok(Some(Gear::Reverse)));
        assert_eq!(gear_from_code(22), Ok(Some(Gear::Park)));
        assert!(gear_from_code(23).unwrap_err().contains("23"));
        for g in [Gear::Park, Gear::Reverse, Gear::Neutral, Gear::Drive] {
            assert_eq!(gear_from_code(gear_code(g)), Ok(Some(g)));
        }
        assert_eq!(control_mode_code(None, None), control_mode::NOT_READY);
        assert_eq!(control_mode_code(Some(ControlMode::Autonomous), None), 1);
        assert_eq!(control_mode_code(Some(ControlMode::Manual), None), 4);
        assert_eq!(control_mode_code(Some(ControlMode::Estop), None), 5);
        // Autonomous only while the vehicle follows the ADS.
        for (level, code) in [
            (WatchdogLevel::Normal, 1),
            (WatchdogLevel::Holding, 1),
            (WatchdogLevel::Decelerating, 1),
            (WatchdogLevel::FullBraking, 5),
            (WatchdogLevel::AwaitingEngage, 5),
        ] {
            let mode = Some(ControlMode::Autonomous);
            assert_eq!(control_mode_code(mode, Some(level)), code, "{level:?}");
            assert_eq!(control_mode_code(Some(ControlMode::Manual), Some(level)), 4);
        }
    }

    #[test]
    fn light_codes_follow_autoware() {
        assert_eq!(turn_indicators_from_code(0), Ok(None));
        assert_eq!(turn_indicators_from_code(2), Ok(Some(TurnIndicators::Left)));
        assert!(turn_indicators_from_code(4).unwrap_err().contains("code 4"));
        for lights in TurnIndicators::ALL {
            let code = turn_indicators_code(*lights);
            assert_eq!(turn_indicators_from_code(code), Ok(Some(*lights)));
        }
        assert_eq!(hazard_lights_from_code(0), Ok(None));
        assert!(hazard_lights_from_code(3).unwrap_err().contains("code 3"));
        for on in [false, true] {
            assert_eq!(
                hazard_lights_from_code(hazard_lights_code(on)),
                Ok(Some(on))
            );
        }
    }

    #[test]
    fn brake_is_a_share_of_the_largest_deceleration() {
        assert_eq!(brake_percent(1.0, 4.0), 0.0);
        assert_eq!(brake_percent(-1.0, 4.0), 25.0);
        assert_eq!(brake_percent(-9.0, 4.0), 100.0);
    }
}
