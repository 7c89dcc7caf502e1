//! The controller-side output: Autoware's final `Control` from a topic, out as the three
//! `autoware-can` frames (0x100, 0x101, 0x102), republished on DDS, or both — the output modes
//! `can`, `dds` and `dds-and-can`. A command with a non-finite or out-of-range value goes
//! nowhere (neither a frame nor a sample), and is reported.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

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
    /// Sent as a stop at the largest deceleration: it asked to brake harder (why).
    Saturated(String),
    /// A sample that could not be read (why); nothing of it was sent.
    Unreadable(String),
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

/// How long the end of a run commands a stop.
pub const FINAL_BRAKING: Duration = Duration::from_secs(1);
/// The stop's period while it lasts: Autoware's control rate.
const FINAL_BRAKING_PERIOD: Duration = Duration::from_millis(33);

/// Run until `stop`: every `Control` from `config.input` goes out as `config.mode` says;
/// `report` hears each command's outcome. However the run ends — `stop` (a signal), the DDS
/// side failing — a vehicle that was commanded gets a stop at the largest deceleration for
/// [`FINAL_BRAKING`], during which no input is taken. Ends with an error when the bus fails.
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
    let (tx, _rx) = bus.split();
    let mut sink = Sink {
        tx,
        publisher,
        output: Output::new(config.mode, config.limits),
        mode_byte: config.mode_byte,
        last: None,
    };
    let io = |e: std::io::Error| RosError::Create(format!("polling the subscription: {e}"));
    let mut poll = mio1::Poll::new().map_err(io)?;
    poll.registry()
        .register(&mut input, mio1::Token(0), mio1::Interest::READABLE)
        .map_err(io)?;
    let mut events = mio1::Events::with_capacity(4);
    let ended = loop {
        if stop.load(Ordering::Relaxed) {
            break Ok(());
        }
        if let Err(e) = poll.poll(&mut events, Some(POLL_SLICE)) {
            if e.kind() != std::io::ErrorKind::Interrupted {
                break Err(SinkError::Other(io(e)));
            }
        }
        if let Err(e) = take_batch(&input, &mut sink, report) {
            break Err(e);
        }
    };
    match ended {
        // A failed bus takes no stop; anything else ends in one.
        Err(SinkError::Bus(why)) => Err(RosError::Create(why)),
        Ok(()) => sink.final_braking(),
        Err(SinkError::Other(e)) => Err(sink.final_braking().err().unwrap_or(e)),
    }
}

/// Where commands go, and the last one sent.
struct Sink {
    tx: Box<dyn bywire_bus::BusTx>,
    publisher: Option<ros2_client::Publisher<Control>>,
    output: Output,
    mode_byte: u8,
    last: Option<Control>,
}

enum SinkError {
    /// The bus failed (why): nothing more can be sent on it.
    Bus(String),
    /// Anything else.
    Other(RosError),
}

/// Take the commands waiting, at most a batch.
fn take_batch(
    input: &ros2_client::Subscription<Control>,
    sink: &mut Sink,
    report: &mut dyn FnMut(&Control, Outcome),
) -> Result<(), SinkError> {
    for _ in 0..TAKE_BATCH {
        let message = match input.take() {
            Ok(Some((message, _))) => message,
            Ok(None) => break,
            // The reader has moved past it; nothing of it is sent.
            Err(e) => {
                report(&Control::default(), Outcome::Unreadable(e.to_string()));
                continue;
            }
        };
        let limits = sink.output.limits;
        let (_, saturated) = limits.braking_at_most(from_ros(&message).0);
        if saturated {
            report(
                &message,
                Outcome::Saturated(format!(
                    "acceleration {} m/s²: beyond the largest deceleration, braking as hard as \
                     the vehicle can (a stop at {} m/s²)",
                    bywire_core::num::Short(message.longitudinal.acceleration),
                    -limits.acceleration
                )),
            );
        }
        // What is sent and republished is what the vehicle is asked: the stop, if it was one.
        let message = if saturated {
            stop_of(&message, limits.acceleration)
        } else {
            message
        };
        let (control, validity, stamp_ms) = from_ros(&message);
        match sink.send(&control, &message, validity, stamp_ms) {
            Ok(Ok(sequence)) => report(&message, Outcome::Sent(sequence)),
            Ok(Err(refused)) => report(&message, Outcome::Refused(refused)),
            Err(e) => {
                if let SinkError::Bus(why) = &e {
                    report(&message, Outcome::BusLost(why.clone()));
                }
                return Err(e);
            }
        }
    }
    Ok(())
}

impl Sink {
    /// Send one command (and republish `message` in the DDS modes): its sequence, why it was
    /// refused, or what failed.
    fn send(
        &mut self,
        control: &autoware::Control,
        message: &Control,
        validity: u8,
        stamp_ms: u32,
    ) -> Result<Result<u16, Refused>, SinkError> {
        let mut frames = Vec::with_capacity(3);
        let mut republish = false;
        let sent = self.output.send(
            control,
            self.mode_byte,
            validity,
            stamp_ms,
            &mut |frame| frames.push(frame),
            &mut |_, _| republish = true,
        );
        let sequence = match sent {
            Ok(sequence) => sequence,
            Err(refused) => return Ok(Err(refused)),
        };
        for frame in &frames {
            match self.tx.send(frame) {
                Ok(()) => {}
                Err(BusError::Unsupported(why)) => {
                    return Err(SinkError::Bus(format!("the bus cannot send {why}")))
                }
                Err(e) => return Err(SinkError::Bus(format!("the bus failed: {e}"))),
            }
        }
        if republish {
            if let Some(publisher) = &self.publisher {
                publisher.publish(*message).map_err(|e| {
                    SinkError::Other(RosError::Create(format!("publishing: {e:?}")))
                })?;
            }
        }
        self.last = Some(*message);
        Ok(Ok(sequence))
    }

    /// The end of a run: the last command's steering at zero speed and the largest
    /// deceleration, for [`FINAL_BRAKING`] (none where nothing was ever sent).
    fn final_braking(&mut self) -> Result<(), RosError> {
        let Some(last) = self.last else {
            return Ok(());
        };
        let start = std::time::Instant::now();
        let stop = stop_of(&last, self.output.limits.acceleration);
        let (control, validity, stamp_ms) = from_ros(&stop);
        let mut failed = None;
        // Bounded: one command a period for the braking's length.
        let periods = FINAL_BRAKING.as_millis() / FINAL_BRAKING_PERIOD.as_millis() + 1;
        for period in 0..periods {
            let elapsed = u32::try_from(start.elapsed().as_millis()).unwrap_or(u32::MAX);
            match self.send(&control, &stop, validity, stamp_ms.wrapping_add(elapsed)) {
                Ok(_) => {}
                Err(SinkError::Bus(why)) => return Err(RosError::Create(why)),
                // DDS failing does not stop the stops on the bus.
                Err(SinkError::Other(e)) => failed = failed.or(Some(e)),
            }
            let next =
                FINAL_BRAKING_PERIOD.saturating_mul(u32::try_from(period + 1).unwrap_or(u32::MAX));
            std::thread::sleep(next.saturating_sub(start.elapsed()));
        }
        failed.map_or(Ok(()), Err)
    }
}

/// `message` as a stop: its steering held (at rest), velocity 0 and the largest `deceleration`.
fn stop_of(message: &Control, deceleration: f64) -> Control {
    let mut stop = *message;
    stop.lateral.steering_tire_rotation_rate = 0.0;
    stop.longitudinal.velocity = 0.0;
    // A limit in m/s² is far inside f32's range.
    #[allow(clippy::cast_possible_truncation)]
    let deceleration = -deceleration as f32;
    stop.longitudinal.acceleration = deceleration;
    stop.longitudinal.is_defined_acceleration = true;
    stop
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
