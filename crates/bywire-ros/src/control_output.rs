//! The controller-side output: Autoware's final `Control` from a topic, out as the three
//! `autoware-can` frames (0x100, 0x101, 0x102), republished on DDS, or both — the output modes
//! `can`, `dds` and `dds-and-can`. A command with a non-finite or out-of-range value goes
//! nowhere (neither a frame nor a sample), and is reported.

use std::sync::atomic::{AtomicBool, Ordering};

use bywire_bus::{Bus, BusError};
use bywire_vehicle::autoware::{self, Output, OutputMode, Refused};

use crate::dds::{mio1, reliable, RosError, RosNode, POLL_SLICE};
use crate::msg::{self, Control};

/// Autoware's controller output, the default input.
pub const INPUT_TOPIC: &str = "/control/trajectory_follower/control_cmd";
/// Where the vehicle command gate publishes, the default DDS output.
pub const OUTPUT_TOPIC: &str = "/control/command/control_cmd";
/// Commands taken from the subscription before the stop flag is looked at again.
const TAKE_BATCH: usize = 256;

/// How the output runs.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlOutputConfig {
    /// Where the commands go.
    pub mode: OutputMode,
    /// The `Control` topic read.
    pub input: String,
    /// The `Control` topic written in the DDS modes.
    pub output: String,
    /// The mode byte of 0x102 (`autoware-can.dbc`: 1 autonomous, 2 manual, 3 remote).
    pub mode_byte: u8,
    /// Limits a command must keep to be sent.
    pub limits: autoware::Limits,
}

impl Default for ControlOutputConfig {
    fn default() -> Self {
        ControlOutputConfig {
            mode: OutputMode::CanOnly,
            input: INPUT_TOPIC.to_string(),
            output: OUTPUT_TOPIC.to_string(),
            mode_byte: 1,
            limits: autoware::Limits::default(),
        }
    }
}

/// What happened to one command.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Sent with this sequence number.
    Sent(u16),
    /// Refused whole.
    Refused(Refused),
    /// The bus failed.
    BusLost(String),
}

/// Validity flags of a command that is sent: its steering (bit 0) and its longitudinal part
/// (bit 1) are both valid — a command with either not finite or out of range is not sent.
pub const VALID: u8 = 0b11;

/// The three frames' command from a `Control` message, with its validity flags and its stamp
/// in ms (modulo 2³²).
pub fn from_ros(message: &Control) -> (autoware::Control, u8, u32) {
    let control = autoware::Control {
        steering_tire_angle: f64::from(message.lateral.steering_tire_angle),
        steering_tire_rotation_rate: f64::from(message.lateral.steering_tire_rotation_rate),
        velocity: f64::from(message.longitudinal.velocity),
        acceleration: f64::from(message.longitudinal.acceleration),
    };
    let validity = VALID;
    // The wire field is 32 bits of milliseconds: it wraps, as the layout intends.
    let millis = message.stamp.as_nanos() / 1_000_000;
    let stamp_ms = u32::try_from(millis % (1 << 32)).unwrap_or(0);
    (control, validity, stamp_ms)
}

/// Run until `stop`: every `Control` from `config.input` goes out as `config.mode` says;
/// `report` hears each command's outcome. Ends with an error when the bus fails.
pub fn run(
    node: &mut RosNode,
    bus: Box<dyn Bus>,
    config: &ControlOutputConfig,
    stop: &AtomicBool,
    report: &mut dyn FnMut(&Control, Outcome),
) -> Result<(), RosError> {
    let qos = reliable(1);
    let mut input = node.subscription::<Control>(&config.input, &qos)?;
    let publisher = match config.mode {
        OutputMode::CanOnly => None,
        OutputMode::DdsOnly | OutputMode::DdsAndCan => {
            Some(node.publisher::<Control>(&config.output, &qos)?)
        }
    };
    let (mut tx, _rx) = bus.split();
    let mut output = Output::new(config.mode, config.limits);
    let io = |e: std::io::Error| RosError::Create(format!("polling the subscription: {e}"));
    let mut poll = mio1::Poll::new().map_err(io)?;
    poll.registry()
        .register(&mut input, mio1::Token(0), mio1::Interest::READABLE)
        .map_err(io)?;
    let mut events = mio1::Events::with_capacity(4);
    while !stop.load(Ordering::Relaxed) {
        if let Err(e) = poll.poll(&mut events, Some(POLL_SLICE)) {
            if e.kind() != std::io::ErrorKind::Interrupted {
                return Err(io(e));
            }
        }
        for _ in 0..TAKE_BATCH {
            let Ok(Some((message, _))) = input.take() else {
                break;
            };
            let (control, validity, stamp_ms) = from_ros(&message);
            let mut frames = Vec::with_capacity(3);
            let mut republish = false;
            let sent = output.send(
                &control,
                config.mode_byte,
                validity,
                stamp_ms,
                &mut |frame| frames.push(frame),
                &mut |_, _| republish = true,
            );
            let sequence = match sent {
                Ok(sequence) => sequence,
                Err(refused) => {
                    report(&message, Outcome::Refused(refused));
                    continue;
                }
            };
            for frame in &frames {
                match tx.send(frame) {
                    Ok(()) => {}
                    Err(BusError::Unsupported(why)) => {
                        return Err(RosError::Create(format!("the bus cannot send {why}")))
                    }
                    Err(e) => {
                        report(&message, Outcome::BusLost(e.to_string()));
                        return Err(RosError::Create(format!("the bus failed: {e}")));
                    }
                }
            }
            if republish {
                if let Some(publisher) = &publisher {
                    if let Err(e) = publisher.publish(message) {
                        return Err(RosError::Create(format!("publishing: {e:?}")));
                    }
                }
            }
            report(&message, Outcome::Sent(sequence));
        }
    }
    Ok(())
}

/// A `Control` for tests and examples: these setpoints, stamped `stamp_nanos`.
pub fn control(
    angle: f32,
    rate: f32,
    velocity: f32,
    acceleration: f32,
    stamp_nanos: u64,
) -> Control {
    let stamp = msg::Time::from_nanos(stamp_nanos);
    Control {
        stamp,
        control_time: stamp,
        lateral: msg::Lateral {
            stamp,
            control_time: stamp,
            steering_tire_angle: angle,
            steering_tire_rotation_rate: rate,
            is_defined_steering_tire_rotation_rate: true,
        },
        longitudinal: msg::Longitudinal {
            stamp,
            control_time: stamp,
            velocity,
            acceleration,
            jerk: 0.0,
            is_defined_acceleration: true,
            is_defined_jerk: false,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_control_message_becomes_the_three_frames_command() {
        let m = control(0.1, -0.5, 2.5, -1.25, 1_700_000_000_123_456_789);
        let (c, validity, stamp_ms) = from_ros(&m);
        assert_eq!(c.steering_tire_angle, f64::from(0.1f32));
        assert_eq!(c.acceleration, -1.25);
        assert_eq!(validity, 3);
        assert_eq!(u64::from(stamp_ms), 1_700_000_000_123u64 % (1u64 << 32));
    }
}
