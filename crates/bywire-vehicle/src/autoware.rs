//! The `autoware-can` output: one Autoware `Control` command as three classic frames.
//!
//! - 0x100: steering tire angle (rad) and rotation rate (rad/s), each × 1,000,000 as a signed
//!   little-endian int32;
//! - 0x101: velocity (m/s) and acceleration (m/s²), each × 1,000 as int32;
//! - 0x102: mode byte, validity-flags byte, uint16 sequence, uint32 timestamp in ms.
//!
//! A command with a non-finite value, or one outside the limits or the int32 range, produces
//! no frame at all: the three go together or not at all. `dbc/autoware-can.dbc` describes the
//! same layout for tools. Output goes to the sinks [`OutputMode`] chooses (`bywire-ros` gives the
//! DDS one: `bywire ros2 control-output`).

use crate::command::UnknownName;
use bywire_core::{Frame, Id, StandardId};

/// Identifiers of the three frames.
pub const STEERING_ID: u16 = 0x100;
/// Velocity and acceleration.
pub const VELOCITY_ID: u16 = 0x101;
/// Mode, flags, sequence, timestamp.
pub const STATUS_ID: u16 = 0x102;

/// The DBC for the layout.
pub const DBC: &str = include_str!("../dbc/autoware-can.dbc");

/// An Autoware `Control` command (the fields this output carries).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Control {
    /// Steering tire angle, rad.
    pub steering_tire_angle: f64,
    /// Steering tire rotation rate, rad/s.
    pub steering_tire_rotation_rate: f64,
    /// Velocity, m/s.
    pub velocity: f64,
    /// Acceleration, m/s².
    pub acceleration: f64,
}

/// What the receiver is told besides the setpoints.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Status {
    /// Control mode byte.
    pub mode: u8,
    /// Validity flags (bit 0: steering valid, bit 1: longitudinal valid).
    pub validity: u8,
    /// Rolling sequence number.
    pub sequence: u16,
    /// Timestamp, ms.
    pub timestamp_ms: u32,
}

/// Limits a command must respect to be sent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Largest |steering tire angle|, rad.
    pub angle: f64,
    /// Largest |rotation rate|, rad/s.
    pub rate: f64,
    /// Largest |velocity|, m/s.
    pub velocity: f64,
    /// Largest |acceleration|, m/s².
    pub acceleration: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            angle: 1.0,
            rate: 2.0,
            velocity: 30.0,
            acceleration: 10.0,
        }
    }
}

impl Limits {
    /// A command that asks to decelerate harder than the limit allows (down to −∞) asks to
    /// brake as hard as the vehicle can: it comes back as a stop (velocity 0) at the largest
    /// deceleration, and `true`. Any other command comes back as it is (NaN included: the
    /// encoder refuses it).
    pub fn braking_at_most(&self, control: Control) -> (Control, bool) {
        if control.acceleration < -self.acceleration {
            let stop = Control {
                velocity: 0.0,
                acceleration: -self.acceleration,
                ..control
            };
            (stop, true)
        } else {
            (control, false)
        }
    }
}

/// Why a command was not sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Refused {
    /// A value is NaN or infinite; which field.
    NotFinite(&'static str),
    /// A value is beyond its limit; which field.
    OutOfRange(&'static str),
}

impl core::fmt::Display for Refused {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Refused::NotFinite(field) => write!(f, "{field} is not finite: nothing sent"),
            Refused::OutOfRange(field) => write!(f, "{field} is out of range: nothing sent"),
        }
    }
}

impl core::error::Error for Refused {}

/// `value × scale` as an int32, if the value is finite, within `limit` and representable.
fn scaled(field: &'static str, value: f64, limit: f64, scale: f64) -> Result<i32, Refused> {
    if !value.is_finite() {
        return Err(Refused::NotFinite(field));
    }
    let raw = libm::round(value * scale);
    if value.abs() > limit || raw < f64::from(i32::MIN) || raw > f64::from(i32::MAX) {
        return Err(Refused::OutOfRange(field));
    }
    // In range (checked above): the cast is exact.
    #[allow(clippy::cast_possible_truncation)]
    Ok(raw as i32)
}

fn frame(id: u16, payload: [u8; 8]) -> Frame {
    let id = Id::Standard(StandardId::new(id).unwrap_or(StandardId::ZERO));
    Frame::classic(id, &payload).unwrap_or(Frame::remote(id, bywire_core::Dlc::from_nibble(0)))
}

fn pair(a: [u8; 4], b: [u8; 4]) -> [u8; 8] {
    let [a0, a1, a2, a3] = a;
    let [b0, b1, b2, b3] = b;
    [a0, a1, a2, a3, b0, b1, b2, b3]
}

/// Encode a command into its three frames, or refuse it whole.
pub fn encode(control: &Control, status: &Status, limits: &Limits) -> Result<[Frame; 3], Refused> {
    let angle = scaled(
        "steering_tire_angle",
        control.steering_tire_angle,
        limits.angle,
        1e6,
    )?;
    let rate = scaled(
        "steering_tire_rotation_rate",
        control.steering_tire_rotation_rate,
        limits.rate,
        1e6,
    )?;
    let velocity = scaled("velocity", control.velocity, limits.velocity, 1e3)?;
    let acceleration = scaled(
        "acceleration",
        control.acceleration,
        limits.acceleration,
        1e3,
    )?;
    let [s0, s1] = status.sequence.to_le_bytes();
    Ok([
        frame(STEERING_ID, pair(angle.to_le_bytes(), rate.to_le_bytes())),
        frame(
            VELOCITY_ID,
            pair(velocity.to_le_bytes(), acceleration.to_le_bytes()),
        ),
        frame(
            STATUS_ID,
            pair(
                [status.mode, status.validity, s0, s1],
                status.timestamp_ms.to_le_bytes(),
            ),
        ),
    ])
}

/// The vehicle side: collects the three frames and yields the command when the status frame
/// completes a set.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Decoder {
    steering: Option<(f64, f64)>,
    velocity: Option<(f64, f64)>,
}

fn halves(frame: &Frame) -> Option<([u8; 4], [u8; 4])> {
    let data: [u8; 8] = match frame {
        Frame::Classic(f) if !f.is_remote() => f.data().try_into().ok()?,
        _ => return None,
    };
    let [a0, a1, a2, a3, b0, b1, b2, b3] = data;
    Some(([a0, a1, a2, a3], [b0, b1, b2, b3]))
}

impl Decoder {
    /// Take one frame; a complete command when this was the status frame of a full set.
    pub fn on_frame(&mut self, frame: &Frame) -> Option<(Control, Status)> {
        let Some(Id::Standard(id)) = frame.id() else {
            return None;
        };
        let (a, b) = halves(frame)?;
        match id.as_raw() {
            STEERING_ID => {
                self.steering = Some((
                    f64::from(i32::from_le_bytes(a)) / 1e6,
                    f64::from(i32::from_le_bytes(b)) / 1e6,
                ));
                None
            }
            VELOCITY_ID => {
                self.velocity = Some((
                    f64::from(i32::from_le_bytes(a)) / 1e3,
                    f64::from(i32::from_le_bytes(b)) / 1e3,
                ));
                None
            }
            STATUS_ID => {
                let ((angle, rate), (velocity, acceleration)) =
                    (self.steering.take()?, self.velocity.take()?);
                let [mode, validity, s0, s1] = a;
                Some((
                    Control {
                        steering_tire_angle: angle,
                        steering_tire_rotation_rate: rate,
                        velocity,
                        acceleration,
                    },
                    Status {
                        mode,
                        validity,
                        sequence: u16::from_le_bytes([s0, s1]),
                        timestamp_ms: u32::from_le_bytes(b),
                    },
                ))
            }
            _ => None,
        }
    }
}

/// Where commands go.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OutputMode {
    /// Only to DDS.
    DdsOnly,
    /// Only to CAN.
    CanOnly,
    /// To both.
    DdsAndCan,
}

impl core::str::FromStr for OutputMode {
    type Err = UnknownName;
    fn from_str(s: &str) -> Result<Self, UnknownName> {
        match s {
            "dds-only" | "dds" => Ok(OutputMode::DdsOnly),
            "can-only" | "can" => Ok(OutputMode::CanOnly),
            "dds-and-can" => Ok(OutputMode::DdsAndCan),
            _ => Err(UnknownName {
                kind: "control-output mode",
                expected: &["dds", "can", "dds-and-can"],
            }),
        }
    }
}

/// Sends commands to the sinks an [`OutputMode`] selects, all or nothing: a refused command
/// reaches no sink.
#[derive(Debug, Clone)]
pub struct Output {
    /// The mode.
    pub mode: OutputMode,
    /// Limits checked before anything is sent.
    pub limits: Limits,
    sequence: u16,
}

impl Output {
    /// An output in `mode`.
    pub fn new(mode: OutputMode, limits: Limits) -> Self {
        Output {
            mode,
            limits,
            sequence: 0,
        }
    }

    /// Send one command: frames to `can` (in order 0x100, 0x101, 0x102) and/or the command to
    /// `dds` (the ROS 2 side republishes it). Returns the sequence number used.
    pub fn send(
        &mut self,
        control: &Control,
        mode: u8,
        validity: u8,
        timestamp_ms: u32,
        can: &mut dyn FnMut(Frame),
        dds: &mut dyn FnMut(&Control, &Status),
    ) -> Result<u16, Refused> {
        let status = Status {
            mode,
            validity,
            sequence: self.sequence,
            timestamp_ms,
        };
        // Encode first: a refusal leaves every sink untouched.
        let frames = encode(control, &status, &self.limits)?;
        if matches!(self.mode, OutputMode::CanOnly | OutputMode::DdsAndCan) {
            for f in frames {
                can(f);
            }
        }
        if matches!(self.mode, OutputMode::DdsOnly | OutputMode::DdsAndCan) {
            dds(control, &status);
        }
        self.sequence = self.sequence.wrapping_add(1);
        Ok(status.sequence)
    }
}
