//! The vocabulary both ends of a vehicle interface speak, whatever the vehicle: the command
//! ([`ControlCommand`]) with its modes, gears, steering modes and lights, and what the vehicle
//! reports back about its safety logic ([`WatchdogLevel`], [`EstopCode`]).
//!
//! Names, text and raw numbers are converted here and only here. The raw numbers are the
//! reference numbering (the reference tug's DBC uses them as they are); a profile maps each
//! name to its own vehicle's number.

use core::fmt;
use core::str::FromStr;

/// A name that is not one of an enum's.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownName {
    /// What was looked for (`gear`, `control mode`, `steering mode`).
    pub kind: &'static str,
    /// The names there are.
    pub expected: &'static [&'static str],
}

impl fmt::Display for UnknownName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "not a {}: expected ", self.kind)?;
        for (i, name) in self.expected.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            f.write_str(name)?;
        }
        Ok(())
    }
}

impl core::error::Error for UnknownName {}

/// What every vocabulary enum offers, for code generic over them (a profile's number maps).
pub trait Vocabulary: Copy + PartialEq + 'static {
    /// Every variant, in reference order.
    const ALL: &'static [Self];
    /// The name used in profiles and JSON.
    fn name(self) -> &'static str;
    /// The variant a profile names, exactly.
    fn from_name(name: &str) -> Option<Self>;
    /// The reference number.
    fn raw(self) -> u64;
}

/// One vocabulary enum: its variants with names and reference numbers.
macro_rules! vocabulary {
    (
        $(#[$doc:meta])* $name:ident, $kind:literal, default $default:ident,
        [$($(#[$vdoc:meta])* $variant:ident = $raw:literal, $text:literal $(| $alias:literal)*;)+]
    ) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum $name {
            $($(#[$vdoc])* $variant = $raw,)+
        }

        impl $name {
            /// Every variant, in reference order.
            pub const ALL: &'static [$name] = &[$($name::$variant,)+];

            /// The name used in profiles (`[enums]`) and JSON (`Drive`, `Autonomous`, …).
            pub fn name(self) -> &'static str {
                match self {
                    $($name::$variant => stringify!($variant),)+
                }
            }

            /// The variant a profile or DBC value description names, exactly.
            pub fn from_name(name: &str) -> Option<$name> {
                match name {
                    $(stringify!($variant) => Some($name::$variant),)+
                    _ => None,
                }
            }

            /// The reference number.
            pub fn raw(self) -> u64 {
                self as u64
            }

            /// From a reference number.
            pub fn from_raw(raw: u64) -> Option<$name> {
                match raw {
                    $($raw => Some($name::$variant),)+
                    _ => None,
                }
            }
        }

        impl Vocabulary for $name {
            const ALL: &'static [Self] = $name::ALL;
            fn name(self) -> &'static str {
                $name::name(self)
            }
            fn from_name(name: &str) -> Option<Self> {
                $name::from_name(name)
            }
            fn raw(self) -> u64 {
                $name::raw(self)
            }
        }

        impl Default for $name {
            fn default() -> Self {
                $name::$default
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(match self {
                    $($name::$variant => $text,)+
                })
            }
        }

        /// Text as a user types it: any case, with the usual short forms.
        impl FromStr for $name {
            type Err = UnknownName;
            fn from_str(text: &str) -> Result<Self, UnknownName> {
                let text = text.trim();
                $(if text.eq_ignore_ascii_case($text) $(|| text.eq_ignore_ascii_case($alias))* {
                    return Ok($name::$variant);
                })+
                Err(UnknownName {
                    kind: $kind,
                    expected: &[$($text),+],
                })
            }
        }
    };
}

vocabulary!(
    /// Control modes: requested by the ADS, reported by the vehicle.
    ControlMode, "control mode", default Manual, [
        /// A driver drives.
        Manual = 0, "manual";
        /// The ADS drives.
        Autonomous = 1, "autonomous" | "auto";
        /// Stopped by the E-stop chain.
        Estop = 2, "estop" | "e-stop";
        /// Service: actuators calibrated, no driving.
        Calibration = 3, "calibration";
    ]
);

vocabulary!(
    /// Steering modes of a four-wheel-steered vehicle.
    SteeringMode, "steering mode", default Normal, [
        /// Front and rear in counter-phase.
        Normal = 0, "normal";
        /// All wheels parallel.
        Crab = 1, "crab";
        /// Rotation on the spot.
        Tank = 2, "tank";
    ]
);

impl SteeringMode {
    /// The four wheels' angles (rad; FL, FR, RL, RR of `wheels`) this mode gives a commanded
    /// angle at a standstill: front + and rear − in normal mode, all alike in crab, tangent to a
    /// turn about the centre in a tank turn (the commanded angle unused).
    pub fn wheel_angles(
        self,
        steering_rad: f64,
        wheels: &bywire_control::kinematics::Swerve<4>,
    ) -> [f64; 4] {
        use bywire_control::kinematics::{Motion, WheelState};
        match self {
            SteeringMode::Normal => [steering_rad, steering_rad, -steering_rad, -steering_rad],
            SteeringMode::Crab => [steering_rad; 4],
            SteeringMode::Tank => wheels
                .inverse(
                    Motion::Tank { yaw_rate: 1.0 }.twist(),
                    &[WheelState::default(); 4],
                )
                .map(|w| w.angle),
        }
    }

    /// The four wheels' states (angle, speed) this mode gives `speed` (m/s) and a commanded
    /// angle on a rectangular 4WS vehicle (`wheels` FL, FR, RL, RR about its centre): normal
    /// steering on the path of curvature 2 tan δ / wheelbase (front and rear in counter-phase),
    /// crab at δ, a tank turn whose wheels roll at `speed`; at a standstill the angles
    /// [`SteeringMode::wheel_angles`] gives. `current` keeps each wheel from flipping round.
    pub fn wheel_states(
        self,
        speed: f64,
        steering_rad: f64,
        wheels: &bywire_control::kinematics::Swerve<4>,
        current: &[bywire_control::kinematics::WheelState; 4],
    ) -> [bywire_control::kinematics::WheelState; 4] {
        use bywire_control::kinematics::Motion;
        let front_left = wheels.wheels[0];
        let (wheelbase, radius) = (2.0 * front_left.x, libm::hypot(front_left.x, front_left.y));
        let motion = match self {
            SteeringMode::Normal => Motion::Normal {
                speed,
                curvature: 2.0 * libm::tan(steering_rad) / wheelbase,
            },
            SteeringMode::Crab => Motion::Crab {
                speed,
                angle: steering_rad,
            },
            SteeringMode::Tank => Motion::Tank {
                yaw_rate: speed / radius,
            },
        };
        let mut states = wheels.inverse(motion.twist(), current);
        if speed == 0.0 {
            for (state, angle) in states
                .iter_mut()
                .zip(self.wheel_angles(steering_rad, wheels))
            {
                state.angle = angle;
            }
        }
        states
    }
}

vocabulary!(
    /// Gears.
    Gear, "gear", default Park, [
        /// Park.
        Park = 0, "park" | "p";
        /// Reverse.
        Reverse = 1, "reverse" | "r";
        /// Neutral.
        Neutral = 2, "neutral" | "n";
        /// Drive.
        Drive = 3, "drive" | "d";
    ]
);

vocabulary!(
    /// The vehicle's command watchdog, as it reports it.
    WatchdogLevel, "watchdog level", default FullBraking, [
        /// Commands arrive.
        Normal = 0, "normal";
        /// A cycle or two missed: the last command is held.
        Holding = 1, "holding";
        /// More missed: decelerating under control, steering held.
        Decelerating = 2, "decelerating";
        /// Too many missed, invalid or disagreeing commands: full braking, latched.
        FullBraking = 3, "full braking";
        /// Valid commands again: still braking until a run of them and a re-engage.
        AwaitingEngage = 4, "awaiting re-engage";
    ]
);

vocabulary!(
    /// The vehicle's E-stop latch, as it reports it.
    EstopCode, "E-stop state", default Normal, [
        /// No E-stop.
        Normal = 0, "normal";
        /// The chain opened.
        Requested = 1, "requested";
        /// Drive motors disabled.
        MotorsDisabled = 2, "motors disabled";
        /// Brakes applied.
        BrakesApplied = 3, "brakes applied";
        /// At standstill, latched: an operator reset is needed.
        Stopped = 4, "stopped";
        /// An operator pressed reset with the chain closed.
        OperatorReset = 5, "operator reset";
        /// The chain was verified closed: the operator confirms with a second reset.
        EstopReset = 6, "reset, confirm";
        /// Confirmed: a re-engage returns to normal.
        ResetConfirmed = 7, "reset confirmed";
    ]
);

vocabulary!(
    /// The turn indicators.
    TurnIndicators, "turn indicator state", default Off, [
        /// Off.
        Off = 0, "off";
        /// Flashing left.
        Left = 1, "left" | "l";
        /// Flashing right.
        Right = 2, "right" | "r";
    ]
);

impl EstopCode {
    /// Whether the latch waits for the operator's reset (pressed once when stopped, once more
    /// to confirm).
    pub fn awaits_operator_reset(self) -> bool {
        matches!(self, EstopCode::Stopped | EstopCode::EstopReset)
    }
}

vocabulary!(
    /// How far a fail-operational vehicle has degraded, as it reports it (ordered: a later
    /// level is a worse one).
    DegradationLevel, "degradation level", default Nominal, [
        /// Every layer of redundancy in place.
        Nominal = 0, "nominal";
        /// One layer lost: reduced limits, the mission carries on.
        Degraded = 1, "degraded";
        /// Drive on at reduced limits to the next safe stop point and stop there.
        MinimalRisk = 2, "minimal-risk" | "minimal risk";
        /// Brake where it stands.
        SafeStop = 3, "safe-stop" | "safe stop";
    ]
);

vocabulary!(
    /// What a fail-operational mechanism found, as the vehicle reports the reason for its
    /// degradation level.
    FaultClass, "fault class", default SensorChannelOut, [
        /// One channel of a 2-out-of-3 sensor latched out: two left.
        SensorChannelOut = 1, "sensor-channel-out";
        /// A voted sensor has no value to trust.
        SensorLost = 2, "sensor-lost";
        /// The standby control ECU took over.
        ControlTakeover = 3, "control-takeover";
        /// The standby control ECU is out: no one left to take over.
        StandbyLost = 4, "standby-lost";
        /// The backup actuator took over from the primary.
        ActuatorBackup = 5, "actuator-backup";
        /// The backup actuator failed too.
        ActuatorLost = 6, "actuator-lost";
    ]
);

/// The setpoints and requests of one command (without the wire's counter and checksum): what
/// the ADS side sends and what the supervisor takes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ControlCommand {
    /// Steering angle, degrees.
    pub steering: f64,
    /// Speed, m/s.
    pub velocity: f64,
    /// Brake, %.
    pub brake: f64,
    /// Gear.
    pub gear: Gear,
    /// Control mode requested.
    pub mode: ControlMode,
    /// Steering mode.
    pub steering_mode: SteeringMode,
    /// Re-engage request.
    pub engage: bool,
    /// Operator reset (E-stop sequence).
    pub operator_reset: bool,
    /// Turn indicators (sent where the vehicle's command message has them).
    pub turn_indicators: TurnIndicators,
    /// Hazard lights on (sent where the vehicle's command message has them).
    pub hazard_lights: bool,
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    /// At a standstill: normal mode turns front and rear in counter-phase, crab all alike, a
    /// tank turn each wheel across its radius from the centre.
    #[test]
    fn each_mode_sets_the_four_wheels_as_it_says_at_a_standstill() {
        use bywire_control::kinematics::{four_wheel, WheelState};
        let wheels = four_wheel(2.5, 1.5);
        let current = [WheelState::default(); 4];
        let delta = 0.2;
        for (mode, expected) in [
            (SteeringMode::Normal, [delta, delta, -delta, -delta]),
            (SteeringMode::Crab, [delta; 4]),
        ] {
            assert_eq!(mode.wheel_angles(delta, &wheels), expected, "{mode:?}");
            let states = mode.wheel_states(0.0, delta, &wheels, &current);
            assert_eq!(states.map(|w| w.angle), expected, "{mode:?}");
            assert_eq!(states.map(|w| w.speed), [0.0; 4], "{mode:?}");
        }
        let tank = SteeringMode::Tank.wheel_angles(delta, &wheels);
        for (angle, wheel) in tank.iter().zip(wheels.wheels) {
            // Rolling across the radius: the wheel's direction is perpendicular to it.
            let along_radius = libm::cos(*angle) * wheel.x + libm::sin(*angle) * wheel.y;
            assert!(along_radius.abs() < 1e-9, "{angle} at {wheel:?}");
        }
    }

    /// Moving in normal mode, the path's curvature is 2 tan δ / wheelbase: the axles' middles
    /// steer by δ, front and rear in counter-phase.
    #[test]
    fn normal_mode_moving_steers_the_axles_by_the_commanded_angle() {
        use bywire_control::kinematics::{four_wheel, WheelState};
        let wheels = four_wheel(2.5, 1.5);
        let delta: f64 = 0.15;
        let states =
            SteeringMode::Normal.wheel_states(2.0, delta, &wheels, &[WheelState::default(); 4]);
        let axle = |a: f64, b: f64| libm::atan((libm::tan(a) + libm::tan(b)) / 2.0);
        let (front, rear) = (
            axle(states[0].angle, states[1].angle),
            axle(states[2].angle, states[3].angle),
        );
        // The inner and outer wheels differ (Ackermann); their mean tangent is the axle's,
        // within the track's small second-order effect.
        assert!((front - delta).abs() < 0.01, "front {front}");
        assert!((rear + delta).abs() < 0.01, "rear {rear}");
        assert!(
            states.iter().all(|w| (1.5..2.5).contains(&w.speed)),
            "{states:?}"
        );
    }

    #[test]
    fn names_text_and_numbers_go_both_ways() {
        for &gear in Gear::ALL {
            assert_eq!(Gear::from_name(gear.name()), Some(gear));
            assert_eq!(Gear::from_raw(gear.raw()), Some(gear));
            assert_eq!(gear.to_string().parse::<Gear>(), Ok(gear));
        }
        for &code in EstopCode::ALL {
            assert_eq!(EstopCode::from_raw(code.raw()), Some(code));
            assert_eq!(code.to_string().parse::<EstopCode>(), Ok(code));
        }
        assert_eq!("D".parse::<Gear>(), Ok(Gear::Drive));
        assert_eq!(
            " Autonomous ".parse::<ControlMode>(),
            Ok(ControlMode::Autonomous)
        );
        assert_eq!(SteeringMode::from_raw(3), None);
        assert_eq!(
            WatchdogLevel::from_raw(4),
            Some(WatchdogLevel::AwaitingEngage)
        );
        let err = "sideways".parse::<SteeringMode>().unwrap_err();
        assert_eq!(
            err.to_string(),
            "not a steering mode: expected normal, crab, tank"
        );
    }
}
