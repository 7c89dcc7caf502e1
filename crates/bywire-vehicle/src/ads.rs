//! The ADS side of the wire: a sans-IO node that turns the ADS's latest command into
//! `AdsToVehicle_Control` frames at the command rate (rolling counter, CRC), sends the
//! emergency-brake burst, and validates every feedback frame into a [`VehicleState`] whose
//! fields carry validity and age.
//!
//! The ADS side fails safe too: a command older than its staleness limit is replaced by a
//! controlled stop (speed 0, brake applied, steering held) until a fresh one arrives.

use core::time::Duration;

use bywire_core::e2e::{CounterChecker, CounterStatus, RollingCounter};
use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Timestamp};

use bywire_control::kinematics::{four_wheel, Odometry, Pose, Swerve, WheelState};

use crate::command::{
    ControlMode, DegradationLevel, EstopCode, FaultClass, Gear, SteeringMode, TurnIndicators,
    WatchdogLevel,
};
use crate::wire::{AdsWire, Feedback, StateFeedback};

/// Tuning of the ADS side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdsConfig {
    /// Command period.
    pub cycle: Duration,
    /// A command older than this is replaced by a controlled stop.
    pub staleness: Duration,
    /// Brake applied by the controlled stop, %.
    pub stop_brake: f64,
    /// Feedback older than this many of its cycles is invalid.
    pub feedback_timeout_cycles: u32,
    /// The heartbeat echo must match one of the last this many commands sent.
    pub echo_window: u8,
    /// Emergency-brake frames: the burst's spacing and the repeat period after it.
    pub brake_burst_spacing: Duration,
    /// Repeat period after the burst (20 Hz).
    pub brake_repeat: Duration,
    /// The vehicle's four wheels, for odometry from their speeds and angles: a vehicle's own
    /// (a profile's `[vehicle]`); without them, no odometry.
    pub wheels: Option<WheelGeometry>,
    /// Steering within this of its setpoint counts as reached, degrees.
    pub steering_tolerance: f64,
    /// As a node, send every frame on both command buses ([`Ads::PORT_A`], [`Ads::PORT_B`]).
    pub redundant: bool,
}

/// Where a four-wheel-steered vehicle's wheels are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelGeometry {
    /// Wheelbase, m.
    pub wheelbase: f64,
    /// Track, m.
    pub track: f64,
}

/// What turns the four wheels' speeds and angles into a pose: the ADS side's dead reckoning.
/// [`WheelOdometer`], the default, fits the body's twist to the four wheels by least squares
/// from where they are, which holds for four-wheel steering, front steering and skid steering
/// alike; a vehicle with other means (a fused estimate, another chassis) brings its own.
pub trait Odometer {
    /// The pose after `dt` seconds with the wheels at `wheels` (angles in radians, speeds in
    /// m/s); `None` when the wheels give no motion to integrate.
    fn update(&mut self, dt: f64, wheels: &[WheelState; 4]) -> Option<Pose>;
    /// Start over at `pose`.
    fn reset(&mut self, pose: Pose);
}

/// Odometry from the four wheels' speeds and angles where their positions are known (a
/// profile's `[vehicle]`); without them, none.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelOdometer {
    wheels: Option<Swerve<4>>,
    odometry: Odometry,
}

impl WheelOdometer {
    /// An odometer for wheels at `geometry`, from the origin.
    pub fn new(geometry: Option<WheelGeometry>) -> Self {
        WheelOdometer {
            wheels: geometry.map(|w| four_wheel(w.wheelbase, w.track)),
            odometry: Odometry::default(),
        }
    }
}

impl Odometer for WheelOdometer {
    fn update(&mut self, dt: f64, wheels: &[WheelState; 4]) -> Option<Pose> {
        let twist = self.wheels.as_ref()?.forward(wheels)?;
        Some(self.odometry.update(dt, twist))
    }

    fn reset(&mut self, pose: Pose) {
        self.odometry = Odometry::new(pose);
    }
}

impl AdsConfig {
    /// Feedback older than this is invalid: `feedback_timeout_cycles` cycles.
    pub fn feedback_timeout(&self) -> Duration {
        self.cycle.saturating_mul(self.feedback_timeout_cycles)
    }
}

impl Default for AdsConfig {
    fn default() -> Self {
        AdsConfig {
            cycle: Duration::from_millis(20),
            staleness: Duration::from_millis(200),
            stop_brake: 30.0,
            feedback_timeout_cycles: 3,
            echo_window: 3,
            brake_burst_spacing: Duration::from_millis(4),
            brake_repeat: Duration::from_millis(50),
            wheels: None,
            steering_tolerance: 0.5,
            redundant: false,
        }
    }
}

/// What the ADS wants the vehicle to do.
pub use crate::command::ControlCommand as AdsCommand;

/// A feedback value with its time and validity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Field<T> {
    /// The last valid value.
    pub value: Option<T>,
    /// When it arrived.
    pub at: Option<Timestamp>,
}

impl<T> Default for Field<T> {
    fn default() -> Self {
        Field {
            value: None,
            at: None,
        }
    }
}

impl<T: Copy> Field<T> {
    fn set(&mut self, now: Timestamp, value: T) {
        self.value = Some(value);
        self.at = Some(now);
    }

    /// Its age at `now`.
    pub fn age(&self, now: Timestamp) -> Option<Duration> {
        self.at.map(|at| now.saturating_since(at))
    }

    /// The value if it is younger than `timeout` at `now`.
    pub fn fresh(&self, now: Timestamp, timeout: Duration) -> Option<T> {
        self.value
            .filter(|_| self.age(now).is_some_and(|a| a <= timeout))
    }
}

/// Why a feedback frame was not used (each counted).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FeedbackStats {
    /// Frames used.
    pub accepted: u64,
    /// Wrong CRC or malformed.
    pub checksum: u64,
    /// Counter repeated or jumped.
    pub counter: u64,
    /// Physical values outside their ranges.
    pub range: u64,
    /// State frames whose heartbeat echo matched none of the recent commands (their values
    /// are used all the same: the vehicle does not answer these commands, but it is what it
    /// reports).
    pub echo: u64,
    /// Secured frames that failed verification (forged, replayed, another key's).
    pub authentication: u64,
}

/// The vehicle as the ADS sees it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VehicleState {
    /// Steering angle, degrees.
    pub steering: Field<f64>,
    /// Speed, m/s.
    pub velocity: Field<f64>,
    /// Control mode.
    pub mode: Field<ControlMode>,
    /// The vehicle's command watchdog.
    pub watchdog_level: Field<WatchdogLevel>,
    /// The vehicle's E-stop latch.
    pub estop_state: Field<EstopCode>,
    /// The vehicle's warning flag.
    pub warning: Field<bool>,
    /// A driver has taken over.
    pub driver_override: Field<bool>,
    /// The gear engaged.
    pub gear: Field<Gear>,
    /// The steering mode the wheels are in.
    pub steering_mode: Field<SteeringMode>,
    /// The turn indicators.
    pub turn_indicators: Field<TurnIndicators>,
    /// The hazard lights are on.
    pub hazard_lights: Field<bool>,
    /// The degradation level of a fail-operational vehicle.
    pub degradation: Field<DegradationLevel>,
    /// The fault class it is degraded for (`None`: nominal).
    pub degradation_reason: Field<Option<FaultClass>>,
    /// Wheel speeds FL, FR, RL, RR, m/s.
    pub wheel_speeds: Field<[f64; 4]>,
    /// Time from sending a command to seeing its heartbeat echoed.
    pub echo_latency: Field<Duration>,
    /// Wheel angles FL, FR, RL, RR, degrees.
    pub wheel_angles: Field<[f64; 4]>,
    /// The pose integrated from wheel speeds and angles (4WS kinematics, least squares).
    pub odometry: Field<Pose>,
    /// Time from a steering setpoint change to the actual angle reaching it.
    pub steering_response: Field<Duration>,
}

/// The ADS-side node, speaking a vehicle's messages through its wire
/// ([`crate::wire::ProfileWire`] for any vehicle a profile describes).
#[derive(Debug, Clone)]
pub struct Ads<W: AdsWire, O: Odometer = WheelOdometer> {
    wire: W,
    config: AdsConfig,
    command: Option<(Timestamp, AdsCommand)>,
    counter: u64,
    /// When each counter value was last sent (counters are at most 8 bits wide).
    sent_at: [Option<Timestamp>; 256],
    next_command: Option<Timestamp>,
    brake: Option<BrakeBurst>,
    state: VehicleState,
    state_sequence: FeedbackSequence,
    sensors_sequence: FeedbackSequence,
    angles_sequence: FeedbackSequence,
    stats: FeedbackStats,
    /// The dead reckoning from the wheels.
    odometer: O,
    last_sensors: Option<Timestamp>,
    /// A steering setpoint not yet reached: (setpoint, since).
    steering_pending: Option<(f64, Timestamp)>,
    /// The last setpoint whose response was (or is being) measured.
    steering_reference: Option<f64>,
    /// Feedback frames without a counter lately taken as a node, to skip the redundant bus's
    /// copies.
    recent: [Option<(Port, Timestamp, Frame)>; RECENT],
    recent_next: usize,
}

/// Feedback frames remembered to recognise the copy from the other bus: a feedback timeout's
/// worth (three cycles of a state frame and two sensor frames) and more.
const RECENT: usize = 32;

/// What a feedback frame's counter says of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Sequenced {
    /// Newer than the last taken: take it.
    New,
    /// Not newer, as far as its counter tells: the other bus's copy, or a late bus's.
    Copy,
    /// Out of its own bus's sequence: refuse it.
    Broken,
    /// The message has no counter: the frame itself tells copies apart.
    Uncounted,
}

/// One feedback message's counter on the two buses it may come on: each bus's frames checked
/// in their own sequence (a bus that loses or delays frames breaks no sequence but its own),
/// and a frame taken only when its counter is ahead of the last taken from either bus — by one,
/// or by more from the bus that frame came from (its own sequence resumed after a gap). A bus
/// further behind than half the counter's range brings frames that look ahead by more than one:
/// they are passed over as the copies they are (only one a whole range minus one behind looks
/// like the next frame, and the state frame's echo check refuses that one).
#[derive(Debug, Clone, Copy)]
struct FeedbackSequence {
    counted: bool,
    counter: RollingCounter,
    buses: [CounterChecker; 2],
    timeout: Duration,
    /// The last counter taken, when, and from which bus.
    taken: Option<(u8, Timestamp, usize)>,
}

impl FeedbackSequence {
    fn new(bits: u8, timeout: Duration) -> Self {
        let checker = CounterChecker::new(bits, 0, timeout);
        FeedbackSequence {
            counted: bits > 0,
            counter: RollingCounter::new(bits),
            buses: [checker; 2],
            timeout,
            taken: None,
        }
    }

    /// A frame with `value` from `bus` (0 or 1) at `now`.
    fn judge(&mut self, now: Timestamp, bus: usize, value: u64) -> Sequenced {
        if !self.counted {
            return Sequenced::Uncounted;
        }
        let value = u8::try_from(value % u64::from(self.counter.modulus())).unwrap_or(0);
        let Some(checker) = self.buses.get_mut(bus) else {
            return Sequenced::Broken;
        };
        match checker.check(now, value) {
            CounterStatus::Initial | CounterStatus::InSequence | CounterStatus::Stale => {}
            CounterStatus::Repeated
            | CounterStatus::Skipped { .. }
            | CounterStatus::OutOfSequence => return Sequenced::Broken,
        }
        let fresh = self.taken.filter(|(_, at, _)| {
            now.checked_since(*at)
                .is_some_and(|age| age <= self.timeout)
        });
        let ahead = fresh.is_none_or(|(last, _, from)| {
            let steps = self.counter.steps_from(last, value);
            steps == 1 || (from == bus && steps > 0 && steps < self.counter.modulus() / 2)
        });
        if !ahead {
            return Sequenced::Copy;
        }
        self.taken = Some((value, now, bus));
        Sequenced::New
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct BrakeBurst {
    deceleration: f64,
    sent: u32,
    next: Timestamp,
}

impl<W: AdsWire> Ads<W> {
    /// A node speaking `wire` that sends nothing until it has a command, with odometry from
    /// the wheels at `config.wheels`.
    pub fn with_wire(config: AdsConfig, wire: W) -> Self {
        Ads::with_odometer(config, wire, WheelOdometer::new(config.wheels))
    }
}

impl<W: AdsWire, O: Odometer> Ads<W, O> {
    /// A node speaking `wire` that sends nothing until it has a command, reckoning its pose
    /// with `odometer`.
    pub fn with_odometer(config: AdsConfig, wire: W, odometer: O) -> Self {
        let timeout = config.feedback_timeout();
        let (state_bits, wheel_bits) = (wire.state_counter_bits(), wire.wheel_counter_bits());
        Ads {
            wire,
            config,
            command: None,
            counter: 0,
            sent_at: [None; 256],
            next_command: None,
            brake: None,
            state: VehicleState::default(),
            state_sequence: FeedbackSequence::new(state_bits, timeout),
            sensors_sequence: FeedbackSequence::new(wheel_bits, timeout),
            angles_sequence: FeedbackSequence::new(wheel_bits, timeout),
            stats: FeedbackStats::default(),
            odometer,
            last_sensors: None,
            steering_pending: None,
            steering_reference: None,
            recent: [None; RECENT],
            recent_next: 0,
        }
    }

    /// The wire it speaks through.
    pub fn wire(&self) -> &W {
        &self.wire
    }

    /// Its dead reckoning.
    pub fn odometer(&self) -> &O {
        &self.odometer
    }

    /// The latest command (latest wins); non-finite values are refused and the previous
    /// command stays (and ages).
    pub fn set_command(&mut self, now: Timestamp, command: AdsCommand) -> bool {
        let finite = command.steering.is_finite()
            && command.velocity.is_finite()
            && command.brake.is_finite();
        if finite {
            // A new setpoint when it moved beyond the tolerance from the last one measured
            // (so that a slow creep is measured too).
            let changed = self
                .steering_reference
                .is_none_or(|r| (r - command.steering).abs() > self.config.steering_tolerance);
            if changed {
                self.steering_reference = Some(command.steering);
                self.steering_pending = Some((command.steering, now));
            }
            self.command = Some((now, command));
            self.next_command.get_or_insert(now);
        }
        finite
    }

    /// Start the emergency-brake burst: 3 frames `brake_burst_spacing` apart, then one every
    /// `brake_repeat` until [`release_brake`](Self::release_brake).
    pub fn emergency_brake(&mut self, now: Timestamp, deceleration: f64) {
        self.brake = Some(BrakeBurst {
            deceleration,
            sent: 0,
            next: now,
        });
    }

    /// The safe stop at an end of input: the emergency-brake burst at `deceleration` and a
    /// command of zero speed at full brake (steering, gear and modes held, no requests).
    pub fn safe_stop(&mut self, now: Timestamp, deceleration: f64) {
        self.emergency_brake(now, deceleration);
        let held = self.command.map(|(_, c)| c).unwrap_or_default();
        self.set_command(
            now,
            AdsCommand {
                velocity: 0.0,
                brake: 100.0,
                engage: false,
                operator_reset: false,
                ..held
            },
        );
    }

    /// Stop sending emergency-brake frames.
    pub fn release_brake(&mut self) {
        self.brake = None;
    }

    /// Start the odometry over at `pose` (where the vehicle is known to be).
    pub fn reset_odometry(&mut self, pose: Pose) {
        self.odometer.reset(pose);
        self.state.odometry = Field::default();
    }

    /// The vehicle's state as validated so far.
    pub fn state(&self) -> &VehicleState {
        &self.state
    }

    /// Feedback counts.
    pub fn stats(&self) -> FeedbackStats {
        self.stats
    }

    /// Whether the vehicle answers this side's commands at `now`: a state frame echoing one
    /// of them is fresh.
    pub fn feedback_alive(&self, now: Timestamp) -> bool {
        self.state
            .echo_latency
            .fresh(now, self.config.feedback_timeout())
            .is_some()
    }

    /// The command to send at `now`: the latest, or a controlled stop if it is stale.
    pub fn effective_command(&self, now: Timestamp) -> Option<AdsCommand> {
        let (at, command) = self.command?;
        if now.saturating_since(at) <= self.config.staleness {
            return Some(command);
        }
        Some(AdsCommand {
            velocity: 0.0,
            brake: command.brake.max(self.config.stop_brake),
            engage: false,
            operator_reset: false,
            ..command
        })
    }

    /// The command counter's values: `0..modulus`.
    fn counter_mask(&self) -> u64 {
        (1u64 << self.wire.command_counter_bits().clamp(1, 8)) - 1
    }

    /// The command frame (`None` if the wire cannot encode it: nothing is sent, and the
    /// vehicle's watchdog sees a missed cycle — fail-safe).
    fn command_frame(&mut self, now: Timestamp, c: AdsCommand) -> Option<Frame> {
        let frame = self.wire.command_frame(&c, self.counter);
        if let Some(slot) = usize::try_from(self.counter)
            .ok()
            .and_then(|i| self.sent_at.get_mut(i))
        {
            *slot = Some(now);
        }
        self.counter = (self.counter + 1) & self.counter_mask();
        frame
    }

    /// When [`Ads::step`] next has something to send.
    fn deadline(&self) -> Option<Timestamp> {
        match (self.next_command, self.brake.map(|b| b.next)) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Send what is due at `now`: the emergency-brake frame first (it has the highest
    /// priority on the bus too), then the command (given once; [`Node::poll`] sends it on
    /// each command bus).
    fn step(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        if let Some(mut burst) = self.brake {
            if now >= burst.next {
                if let Some(frame) = self
                    .wire
                    .emergency_brake_frame(burst.deceleration, u64::from(burst.sent))
                {
                    out(frame);
                }
                burst.sent = burst.sent.saturating_add(1);
                let gap = if burst.sent < 3 {
                    self.config.brake_burst_spacing
                } else {
                    self.config.brake_repeat
                };
                burst.next = burst.next.saturating_add(gap).max(now);
                self.brake = Some(burst);
            }
        }
        if let (Some(due), Some(command)) = (self.next_command, self.effective_command(now)) {
            if now >= due {
                if let Some(frame) = self.command_frame(now, command) {
                    out(frame);
                }
                // Keep the schedule (no drift); skip cycles missed while not polled.
                let mut next = due.saturating_add(self.config.cycle);
                if next <= now {
                    next = now.saturating_add(self.config.cycle);
                }
                self.next_command = Some(next);
            }
        }
        if let Some(frame) = self.wire.pending_frame(now) {
            out(frame);
        }
    }

    /// A frame from the vehicle on `port` (as a node with two buses).
    fn receive(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        let bus = usize::from(port == Self::PORT_B);
        match self.wire.feedback(frame) {
            Feedback::Other => {}
            Feedback::Corrupt => self.stats.checksum += 1,
            Feedback::Unauthenticated => self.stats.authentication += 1,
            Feedback::State(state) => {
                let sequenced = self.state_sequence.judge(now, bus, state.counter);
                if self.take(sequenced, now, port, frame) {
                    self.on_state(now, state);
                }
            }
            Feedback::WheelAngles { counter, angles } => {
                let sequenced = self.angles_sequence.judge(now, bus, counter);
                if self.take(sequenced, now, port, frame) {
                    self.on_angles(now, angles);
                }
            }
            // Taken as it comes: a report that shows a level the vehicle has left is
            // corrected by the next, every state period.
            Feedback::Degradation(report) => {
                self.state.degradation.set(now, report.level);
                self.state.degradation_reason.set(now, report.reason);
            }
            Feedback::WheelSpeeds { counter, speeds } => {
                let sequenced = self.sensors_sequence.judge(now, bus, counter);
                if self.take(sequenced, now, port, frame) {
                    self.on_sensors(now, speeds);
                }
            }
        }
    }

    /// Whether a feedback frame is new, as its counter (or, without one, the frame) says;
    /// frames out of their bus's sequence are counted.
    fn take(&mut self, sequenced: Sequenced, now: Timestamp, port: Port, frame: &Frame) -> bool {
        match sequenced {
            Sequenced::New => true,
            Sequenced::Copy => false,
            Sequenced::Broken => {
                self.stats.counter += 1;
                false
            }
            Sequenced::Uncounted => !(self.config.redundant && self.is_copy(now, port, frame)),
        }
    }

    fn on_state(&mut self, now: Timestamp, m: StateFeedback) {
        let (steering, velocity) = (m.steering, m.velocity);
        if !m.in_range {
            self.stats.range += 1;
            return;
        }
        // The echo must be one of the last few commands sent.
        let echo = m.heartbeat_echo;
        let mask = self.counter_mask();
        let recent = (1..=u64::from(self.config.echo_window))
            .any(|back| self.counter.wrapping_sub(back) & mask == echo);
        let sent = usize::try_from(echo)
            .ok()
            .and_then(|i| self.sent_at.get(i))
            .copied()
            .flatten();
        // An echo of none of them: the vehicle does not answer these commands (none sent yet,
        // or it hears none), counted; what it reports of itself is taken all the same (its
        // CRC and counter are checked), so a vehicle is seen before it is commanded.
        let echoed = recent && sent.is_some();
        if !echoed {
            self.stats.echo += 1;
        }
        self.stats.accepted += 1;
        let s = &mut self.state;
        s.steering.set(now, steering);
        s.velocity.set(now, velocity);
        s.mode.set(now, m.mode);
        // Reported only by vehicles whose state message has them.
        if let Some(level) = m.watchdog_level {
            s.watchdog_level.set(now, level);
        }
        if let Some(estop) = m.estop_state {
            s.estop_state.set(now, estop);
        }
        if let Some(warning) = m.warning {
            s.warning.set(now, warning);
        }
        if let Some(driver) = m.driver_override {
            s.driver_override.set(now, driver);
        }
        if let Some(gear) = m.gear {
            s.gear.set(now, gear);
        }
        if let Some(mode) = m.steering_mode {
            s.steering_mode.set(now, mode);
        }
        if let Some(lights) = m.turn_indicators {
            s.turn_indicators.set(now, lights);
        }
        if let Some(on) = m.hazard_lights {
            s.hazard_lights.set(now, on);
        }

        match sent {
            Some(sent) if echoed => s.echo_latency.set(now, now.saturating_since(sent)),
            _ => return,
        }
        if let Some((setpoint, since)) = self.steering_pending {
            if (steering - setpoint).abs() <= self.config.steering_tolerance {
                s.steering_response.set(now, now.saturating_since(since));
                self.steering_pending = None;
            }
        }
    }

    fn on_angles(&mut self, now: Timestamp, angles: [f64; 4]) {
        self.stats.accepted += 1;
        self.state.wheel_angles.set(now, angles);
    }

    fn on_sensors(&mut self, now: Timestamp, speeds: [f64; 4]) {
        self.stats.accepted += 1;
        self.state.wheel_speeds.set(now, speeds);
        // Odometry needs fresh wheel angles; integrate over the time since the last sensors
        // frame (the wheels' twist is taken as constant in between).
        let angles = self
            .state
            .wheel_angles
            .fresh(now, self.config.feedback_timeout());
        if let (Some(angles), Some(last)) = (angles, self.last_sensors) {
            let mut states = [WheelState::default(); 4];
            for ((state, speed), angle) in states.iter_mut().zip(speeds).zip(angles) {
                *state = WheelState {
                    angle: angle.to_radians(),
                    speed,
                };
            }
            let dt = now.saturating_since(last).as_secs_f64();
            if let Some(pose) = self.odometer.update(dt, &states) {
                self.state.odometry.set(now, pose);
            }
        }
        self.last_sensors = Some(now);
    }
}

impl<W: AdsWire, O: Odometer> Ads<W, O> {
    /// The port of the command bus A.
    pub const PORT_A: Port = crate::redundancy::Channel::A.port();
    /// The port of the redundant command bus B.
    pub const PORT_B: Port = crate::redundancy::Channel::B.port();

    /// Whether `frame`, of a message without a counter, is the other bus's copy of one taken
    /// within the feedback timeout.
    fn is_copy(&mut self, now: Timestamp, port: Port, frame: &Frame) -> bool {
        let window = self.config.feedback_timeout();
        let copy = self.recent.iter().flatten().any(|(from, at, seen)| {
            *from != port && seen == frame && now.saturating_since(*at) <= window
        });
        if !copy {
            if let Some(slot) = self.recent.get_mut(self.recent_next) {
                *slot = Some((port, now, *frame));
            }
            self.recent_next = (self.recent_next + 1) % RECENT;
        }
        copy
    }
}

/// The ADS side as a node: its frames go out on [`Ads::PORT_A`] (and [`Ads::PORT_B`] when
/// [`AdsConfig::redundant`]); feedback is taken from either port, the second copy of a frame
/// that came on both skipped (a bus behind the other, however far, brings only copies).
impl<W: AdsWire, O: Odometer> Node for Ads<W, O> {
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        self.receive(now, port, frame);
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        let redundant = self.config.redundant;
        self.step(now, &mut |frame| {
            out(Self::PORT_A, frame);
            if redundant {
                out(Self::PORT_B, frame);
            }
        });
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        self.deadline()
    }
}

/// Why the vehicle is not following the ADS's commands, as its feedback tells it; the text
/// says what to do about it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Blocker {
    /// No valid state frame lately: the vehicle is silent, or its frames fail their checks.
    NoFeedback,
    /// The E-stop latch holds.
    Estop(EstopCode),
    /// A driver is overriding.
    DriverOverride,
    /// The command watchdog is not normal.
    Watchdog(WatchdogLevel),
    /// The vehicle is not in autonomous mode.
    NotEngaged(ControlMode),
}

impl core::fmt::Display for Blocker {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Blocker::NoFeedback => f.write_str(
                "no valid feedback from the vehicle: is it on this bus, and does the profile match it?",
            ),
            Blocker::Estop(EstopCode::Stopped) => f.write_str(
                "E-stop latched: release the E-stop, send operator_reset, then operator_reset again to confirm, then engage",
            ),
            Blocker::Estop(EstopCode::EstopReset) => {
                f.write_str("E-stop reset pending: send operator_reset again to confirm, then engage")
            }
            Blocker::Estop(EstopCode::ResetConfirmed) => {
                f.write_str("E-stop reset confirmed: send engage")
            }
            Blocker::Estop(code) => write!(f, "E-stop: {code}"),
            Blocker::DriverOverride => {
                f.write_str("a driver is overriding: hands and feet off, then engage")
            }
            Blocker::Watchdog(WatchdogLevel::FullBraking) => f.write_str(
                "watchdog: full braking (commands missed, invalid, or the two buses disagreed): keep sending valid commands, then engage",
            ),
            Blocker::Watchdog(WatchdogLevel::AwaitingEngage) => f.write_str(
                "watchdog: recovering after full braking: keep sending valid commands and engage",
            ),
            Blocker::Watchdog(level) => write!(f, "watchdog: {level} (commands late)"),
            Blocker::NotEngaged(mode) => write!(
                f,
                "mode {mode}: send mode autonomous with engage: true"
            ),
        }
    }
}

impl<W: AdsWire, O: Odometer> Ads<W, O> {
    /// Why the vehicle is not following the commands now (`None`: it is, by its feedback).
    /// The first reason that holds, in the order a user has to clear them.
    pub fn blocker(&self, now: Timestamp) -> Option<Blocker> {
        if !self.feedback_alive(now) {
            return Some(Blocker::NoFeedback);
        }
        let s = &self.state;
        if let Some(code) = s.estop_state.value.filter(|c| *c != EstopCode::Normal) {
            return Some(Blocker::Estop(code));
        }
        if s.driver_override.value == Some(true) {
            return Some(Blocker::DriverOverride);
        }
        let mode = s.mode.value.unwrap_or(ControlMode::Manual);
        if mode == ControlMode::Estop {
            return Some(Blocker::Estop(EstopCode::Requested));
        }
        if let Some(level) = s
            .watchdog_level
            .value
            .filter(|l| *l != WatchdogLevel::Normal)
        {
            return Some(Blocker::Watchdog(level));
        }
        (mode != ControlMode::Autonomous).then_some(Blocker::NotEngaged(mode))
    }
}
