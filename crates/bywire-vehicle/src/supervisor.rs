//! The vehicle-side supervisor: what a vehicle control ECU runs between the ADS and the
//! actuators. A sans-IO node: [`Supervisor::on_frame`] takes the ADS's commands and the
//! E-stop chain's frames, [`Supervisor::poll`] advances time and emits the state frame,
//! [`Supervisor::actuators`] says what the actuators must do.
//!
//! Three state machines, each with one exhaustive transition function:
//!
//! - **Watchdog** ([`Watchdog::next`]): 1–2 missed command cycles hold the last command and
//!   raise the warning flag; 3–4 decelerate under control; 5 or more brake fully and disable
//!   steering, latched until a run of valid commands *and* an explicit re-engage request.
//! - **E-stop latch** ([`EstopState::next`]): NORMAL → E_STOP_REQUESTED → MOTORS_DISABLED →
//!   BRAKES_APPLIED → STOPPED, and back only through OPERATOR_RESET → E_STOP_RESET →
//!   RESET_CONFIRMED and a re-engage; never automatically.
//! - **Control mode** ([`next_mode`]): driver input above a threshold drops autonomous to
//!   manual at once; autonomous needs a request with an engage edge, no driver input, a
//!   normal watchdog and no E-stop.
//!
//! It starts failed closed: watchdog at full braking (no command seen yet), manual mode.
//! Time is passed in; nothing allocates after construction; every loop is bounded.

use core::time::Duration;

use bywire_control::stages::RateLimiter;
use bywire_core::e2e::{CounterChecker, CounterStatus, RollingCounter};
use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Timestamp};

use crate::command::{
    ControlMode, DegradationLevel, EstopCode, Gear, SteeringMode, TurnIndicators, WatchdogLevel,
};
use crate::degradation::{Degradation, DegradationPolicy, Fault};
use crate::mechanism::{Mechanism, Mechanisms};
use crate::redundancy::{Channel, DualVoter, Vote, VoteFailure};
use crate::wire::{DegradationReport, Incoming, Rejected, StateReport, VehicleWire};

/// Command cycles without an E-stop frame, once one has come, after which the chain is open.
pub const ESTOP_TIMEOUT_CYCLES: u32 = 3;

/// Tuning of the supervisor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupervisorConfig {
    /// The command period the ADS promises.
    pub cycle: Duration,
    /// The watchdog cascade.
    pub cascade: Cascade,
    /// Deceleration at watchdog levels 3–4, m/s².
    pub controlled_deceleration: f64,
    /// Largest steering angle accepted, degrees.
    pub steering_range: f64,
    /// Largest steering rate sent to the actuator, degrees per second.
    pub steering_rate: f64,
    /// Largest speed accepted, m/s.
    pub speed_limit: f64,
    /// Steering-wheel torque that means a driver takes over, N·m.
    pub takeover_torque: f64,
    /// Pedal travel (0–1) that means a driver takes over.
    pub takeover_pedal: f64,
    /// Motor revolutions per wheel revolution.
    pub gear_ratio: f64,
    /// Wheel diameter, m.
    pub wheel_diameter: f64,
    /// Speed below which the vehicle counts as stopped, m/s.
    pub standstill: f64,
    /// Commands arrive on two buses and are voted on (`None`: one bus).
    pub redundancy: Option<Redundancy>,
    /// Degradation levels of a fail-operational vehicle (`None`: fail-safe only, every
    /// fault a mechanism reports is the safe state).
    pub degradation: Option<DegradationPolicy>,
    /// Mechanisms switched off, for a fault-injection campaign's proof that it would notice
    /// (see [`crate::mechanism`]); empty on every vehicle.
    pub disabled: Mechanisms,
}

/// Voting on commands received on two buses (see [`crate::redundancy::DualVoter`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Redundancy {
    /// A bus whose last copy is older than this is lost.
    pub timeout: Duration,
    /// Without a rolling counter (which pairs the copies of one command), copies further
    /// apart than this are not compared, unless equal.
    pub skew: Duration,
}

impl Redundancy {
    /// For commands every `cycle`: a bus is lost once its copy is half a cycle overdue (the
    /// watchdog's tolerance), and (without a counter) the two copies of one command arrive
    /// within 5 ms of each other. The other bus's copies wait for their partners until then,
    /// so a longer timeout would hold the vehicle for as long on the loss of one bus.
    pub fn for_cycle(cycle: Duration) -> Redundancy {
        Redundancy {
            timeout: cycle.saturating_add(cycle / 2),
            skew: Duration::from_millis(5),
        }
    }
}

impl Default for SupervisorConfig {
    /// The reference tug's values.
    fn default() -> Self {
        SupervisorConfig {
            cycle: Duration::from_millis(20),
            cascade: Cascade::default(),
            controlled_deceleration: 1.5,
            steering_range: 40.0,
            steering_rate: 30.0,
            speed_limit: 5.0,
            takeover_torque: 3.0,
            takeover_pedal: 0.1,
            gear_ratio: 20.0,
            wheel_diameter: 0.5,
            standstill: 0.05,
            redundancy: None,
            degradation: None,
            disabled: Mechanisms::NONE,
        }
    }
}

/// The watchdog cascade: up to `hold` missed cycles hold the last command, up to
/// `decelerate` decelerate under control, more brake fully.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cascade {
    /// Last missed-cycle count that still holds (2 on the reference tug).
    pub hold: u32,
    /// Last missed-cycle count that still decelerates under control (4).
    pub decelerate: u32,
    /// Valid commands in a row needed before a re-engage is accepted after full braking (10).
    pub recovery_run: u32,
}

impl Default for Cascade {
    fn default() -> Self {
        Cascade {
            hold: 2,
            decelerate: 4,
            recovery_run: 10,
        }
    }
}

/// The watchdog's level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Watchdog {
    /// Commands arrive.
    Normal,
    /// 1–2 cycles missed: hold the last command, warn.
    Holding {
        /// Cycles missed.
        missed: u32,
    },
    /// 3–4 cycles missed: decelerate under control, steering held.
    Decelerating {
        /// Cycles missed.
        missed: u32,
    },
    /// 5 or more missed (or never a command): full braking, steering disabled. Latched.
    FullBraking,
    /// Valid commands again after full braking: still braking until `recovery_run` of them
    /// and a re-engage request.
    Recovering {
        /// Valid commands in a row so far.
        valid_run: u32,
    },
}

/// What the watchdog sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WatchdogEvent {
    /// A valid command; `engage` when it carries a re-engage request edge.
    Valid {
        /// A re-engage request (rising edge).
        engage: bool,
    },
    /// Whole command cycles missed since the last valid command (≥ 1).
    Missed(u32),
    /// Redundant copies of a command disagree: fail closed at once.
    Disagreement,
}

impl Watchdog {
    /// The one transition function.
    pub fn next(self, event: WatchdogEvent, cascade: Cascade) -> Watchdog {
        use Watchdog::*;
        use WatchdogEvent::*;
        let by_missed = |missed: u32| match missed {
            0 => Normal,
            m if m <= cascade.hold => Holding { missed },
            m if m <= cascade.decelerate => Decelerating { missed },
            _ => FullBraking,
        };
        let recovery_run = cascade.recovery_run;
        match (self, event) {
            (_, Disagreement) => FullBraking,
            (Normal | Holding { .. } | Decelerating { .. }, Valid { .. }) => Normal,
            (Normal | Holding { .. } | Decelerating { .. }, Missed(n)) => by_missed(n),
            (FullBraking, Valid { .. }) => Recovering { valid_run: 1 },
            (FullBraking, Missed(_)) => FullBraking,
            (Recovering { valid_run }, Valid { engage }) => {
                if engage && valid_run >= recovery_run {
                    Normal
                } else {
                    Recovering {
                        valid_run: valid_run.saturating_add(1),
                    }
                }
            }
            (Recovering { .. }, Missed(_)) => FullBraking,
        }
    }

    /// The level the vehicle reports.
    pub fn level(self) -> WatchdogLevel {
        match self {
            Watchdog::Normal => WatchdogLevel::Normal,
            Watchdog::Holding { .. } => WatchdogLevel::Holding,
            Watchdog::Decelerating { .. } => WatchdogLevel::Decelerating,
            Watchdog::FullBraking => WatchdogLevel::FullBraking,
            Watchdog::Recovering { .. } => WatchdogLevel::AwaitingEngage,
        }
    }
}

/// The E-stop latch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EstopState {
    /// No E-stop.
    Normal,
    /// The chain opened.
    EstopRequested,
    /// Drive motors disabled.
    MotorsDisabled,
    /// Brakes applied.
    BrakesApplied,
    /// At standstill, latched.
    Stopped,
    /// An operator pressed reset with the chain closed.
    OperatorReset,
    /// The chain was verified closed.
    EstopReset,
    /// The operator confirmed; a re-engage returns to normal.
    ResetConfirmed,
}

/// What the E-stop latch sees at one evaluation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EstopInputs {
    /// The chain is open (an E-stop frame with the request set, or a timed-out chain).
    pub active: bool,
    /// The operator-reset input rose.
    pub operator_reset: bool,
    /// A re-engage request rose.
    pub engage: bool,
    /// The vehicle is at standstill.
    pub standstill: bool,
}

impl EstopState {
    /// The one transition function; evaluated until nothing changes (at most 8 steps).
    pub fn next(self, i: EstopInputs) -> EstopState {
        use EstopState::*;
        match self {
            Normal if i.active => EstopRequested,
            Normal => Normal,
            EstopRequested => MotorsDisabled,
            MotorsDisabled => BrakesApplied,
            BrakesApplied if i.standstill => Stopped,
            BrakesApplied => BrakesApplied,
            Stopped if i.operator_reset && !i.active => OperatorReset,
            Stopped => Stopped,
            // A new press during the reset sequence starts over.
            OperatorReset | EstopReset | ResetConfirmed if i.active => EstopRequested,
            OperatorReset => EstopReset,
            EstopReset if i.operator_reset => ResetConfirmed,
            EstopReset => EstopReset,
            ResetConfirmed if i.engage => Normal,
            ResetConfirmed => ResetConfirmed,
        }
    }

    /// The state the vehicle reports.
    pub fn code(self) -> EstopCode {
        match self {
            EstopState::Normal => EstopCode::Normal,
            EstopState::EstopRequested => EstopCode::Requested,
            EstopState::MotorsDisabled => EstopCode::MotorsDisabled,
            EstopState::BrakesApplied => EstopCode::BrakesApplied,
            EstopState::Stopped => EstopCode::Stopped,
            EstopState::OperatorReset => EstopCode::OperatorReset,
            EstopState::EstopReset => EstopCode::EstopReset,
            EstopState::ResetConfirmed => EstopCode::ResetConfirmed,
        }
    }

    /// Whether the latch holds the vehicle.
    pub fn is_latched(self) -> bool {
        self != EstopState::Normal
    }
}

/// What the control-mode machine sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ModeInputs {
    /// The mode the ADS asks for.
    pub requested: ControlMode,
    /// An engage request rose with this command.
    pub engage: bool,
    /// A driver's steering torque or pedal is above its threshold.
    pub driver_input: bool,
    /// The E-stop latch holds.
    pub estop: bool,
    /// The watchdog is normal.
    pub watchdog_normal: bool,
    /// The vehicle is at standstill.
    pub standstill: bool,
}

/// The control-mode transition function.
pub fn next_mode(current: ControlMode, i: ModeInputs) -> ControlMode {
    use ControlMode::*;
    if i.estop {
        return Estop;
    }
    match current {
        // Leaving E-stop goes to manual, never straight back to autonomous.
        Estop => Manual,
        Autonomous if i.driver_input => Manual,
        Autonomous if i.requested != Autonomous => Manual,
        Autonomous => Autonomous,
        Manual if i.requested == Autonomous && i.engage && !i.driver_input && i.watchdog_normal => {
            Autonomous
        }
        Manual if i.requested == Calibration && i.standstill => Calibration,
        Manual => Manual,
        Calibration if i.requested != Calibration => Manual,
        Calibration => Calibration,
    }
}

/// Why a command was rejected (each counted).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Rejection {
    /// Not 8 bytes, not a classic data frame.
    Malformed,
    /// CRC wrong.
    Checksum,
    /// Same counter as the last one: no new data.
    RepeatedCounter,
    /// Counter jumped: frames were lost or replayed.
    SkippedCounter,
    /// A setpoint outside its limits, or an undefined steering mode.
    OutOfRange,
    /// The copies from the two buses differ.
    Disagreement,
    /// A secured command that failed verification: forged, replayed, or another key's.
    Authentication,
}

/// Counts of accepted and rejected commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CommandStats {
    /// Valid commands.
    pub accepted: u64,
    /// Malformed frames.
    pub malformed: u64,
    /// Checksum failures.
    pub checksum: u64,
    /// Repeated counters.
    pub repeated: u64,
    /// Skipped counters.
    pub skipped: u64,
    /// Out-of-range setpoints.
    pub out_of_range: u64,
    /// Redundant copies that disagreed.
    pub disagreements: u64,
    /// Secured commands that failed verification.
    pub authentication: u64,
    /// Other secured frames (E-stop, emergency brake) that failed verification and were not
    /// read; not command rejections.
    pub unauthenticated: u64,
}

impl Rejection {
    /// Every reason, in the order a report lists them.
    pub const ALL: [Rejection; 7] = [
        Rejection::Malformed,
        Rejection::Checksum,
        Rejection::RepeatedCounter,
        Rejection::SkippedCounter,
        Rejection::OutOfRange,
        Rejection::Disagreement,
        Rejection::Authentication,
    ];

    /// Its name in a report.
    pub fn name(self) -> &'static str {
        match self {
            Rejection::Malformed => "malformed",
            Rejection::Checksum => "checksum",
            Rejection::RepeatedCounter => "repeated counter",
            Rejection::SkippedCounter => "skipped counter",
            Rejection::OutOfRange => "out of range",
            Rejection::Disagreement => "the two buses disagree",
            Rejection::Authentication => "not authenticated",
        }
    }
}

impl CommandStats {
    /// The commands rejected for `r`.
    pub fn rejected_for(&self, r: Rejection) -> u64 {
        match r {
            Rejection::Malformed => self.malformed,
            Rejection::Checksum => self.checksum,
            Rejection::RepeatedCounter => self.repeated,
            Rejection::SkippedCounter => self.skipped,
            Rejection::OutOfRange => self.out_of_range,
            Rejection::Disagreement => self.disagreements,
            Rejection::Authentication => self.authentication,
        }
    }

    /// The reasons counted in `self` and not yet in `before`.
    pub fn rejected_since(self, before: CommandStats) -> impl Iterator<Item = Rejection> {
        Rejection::ALL
            .into_iter()
            .filter(move |r| self.rejected_for(*r) > before.rejected_for(*r))
    }

    fn count(&mut self, r: Rejection) {
        let slot = match r {
            Rejection::Malformed => &mut self.malformed,
            Rejection::Checksum => &mut self.checksum,
            Rejection::RepeatedCounter => &mut self.repeated,
            Rejection::SkippedCounter => &mut self.skipped,
            Rejection::OutOfRange => &mut self.out_of_range,
            Rejection::Disagreement => &mut self.disagreements,
            Rejection::Authentication => &mut self.authentication,
        };
        *slot = slot.saturating_add(1);
    }

    /// All rejections.
    pub fn rejected(&self) -> u64 {
        self.malformed
            + self.checksum
            + self.repeated
            + self.skipped
            + self.out_of_range
            + self.disagreements
            + self.authentication
    }
}

/// A validated command.
pub use crate::command::ControlCommand as Command;

/// What the actuators must do now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Actuators {
    /// The ADS's commands drive the vehicle (autonomous mode).
    pub ads_in_control: bool,
    /// The steering actuator is enabled.
    pub steering_enabled: bool,
    /// Steering angle setpoint, degrees (rate limited).
    pub steering: f64,
    /// Steering mode.
    pub steering_mode: SteeringMode,
    /// Drive motors enabled.
    pub motors_enabled: bool,
    /// Speed setpoint, m/s.
    pub velocity: f64,
    /// Motor speed setpoint, rpm.
    pub motor_rpm: f64,
    /// Friction brake, %.
    pub brake: f64,
    /// Gear.
    pub gear: Gear,
    /// The warning flag (reported to the ADS).
    pub warning: bool,
}

/// Motor rpm for a vehicle speed: `v · ratio · 60 / (π · d)`.
pub fn motor_rpm(velocity: f64, gear_ratio: f64, wheel_diameter: f64) -> f64 {
    if wheel_diameter > 0.0 {
        velocity * gear_ratio * 60.0 / (core::f64::consts::PI * wheel_diameter)
    } else {
        0.0
    }
}

/// The supervisor node, reading a vehicle's messages through its wire
/// ([`crate::wire::ProfileWire`] for any vehicle a profile describes).
#[derive(Debug, Clone)]
pub struct Supervisor<W: VehicleWire> {
    wire: W,
    config: SupervisorConfig,
    counter: CounterChecker,
    counter_b: CounterChecker,
    /// Votes on the decoded command and its counter, whatever the frame's format.
    voter: Option<DualVoter<(Command, u8)>>,
    /// The bus whose last copy waits for its partner from the other bus: taken in degraded
    /// mode if the other bus's last copy goes stale first.
    waiting: Option<Channel>,
    /// When the first copy still waiting since the last command was taken came: the watchdog
    /// counts missed cycles from it (a vote pending is no missed command; copies that keep
    /// waiting count from the first all the same).
    pending_since: Option<Timestamp>,
    /// How long after a command is taken a copy with its counter is the other bus's copy of
    /// it: the bus timeout (without a counter, any copy within the skew window).
    copy_window: Duration,
    degraded: Option<Channel>,
    /// The degradation latch (a fail-safe vehicle's stays nominal until its first fault,
    /// which is a safe stop).
    degradation: Degradation,
    stats: CommandStats,
    command: Option<Command>,
    last_valid: Option<Timestamp>,
    last_engage_bit: bool,
    last_reset_bit: bool,
    watchdog: Watchdog,
    /// Whole missed cycles already reported to the watchdog.
    missed_reported: u32,
    decelerating_since: Option<(Timestamp, f64)>,
    estop: EstopState,
    estop_active: bool,
    /// When the last E-stop frame came (`None`: the vehicle has sent none yet).
    estop_heard: Option<Timestamp>,
    /// The chain counts as open for want of its frames (until the next one comes).
    estop_chain_lost: bool,
    emergency_brake_until: Option<Timestamp>,
    mode: ControlMode,
    driver_input: bool,
    speed: f64,
    steering_actual: f64,
    steering: RateLimiter,
    last_poll: Option<Timestamp>,
    next_state_frame: Timestamp,
    state_counter: u64,
    echo: u8,
}

impl<W: VehicleWire> Supervisor<W> {
    /// A supervisor reading `wire`, failed closed: full braking until commands arrive and it
    /// is engaged.
    pub fn with_wire(config: SupervisorConfig, mut wire: W) -> Self {
        let mut steering = RateLimiter::new(config.steering_rate, config.steering_rate);
        steering.reset(0.0);
        let bits = wire.command_counter_bits();
        wire.switch_off(config.disabled);
        // Without its vote, each bus's copy is taken as it comes.
        let redundancy = config
            .redundancy
            .filter(|_| !config.disabled.contains(Mechanism::Redundancy));
        Supervisor {
            wire,
            config,
            counter: CounterChecker::new(bits, 0, config.cycle.saturating_mul(5)),
            counter_b: CounterChecker::new(bits, 0, config.cycle.saturating_mul(5)),
            voter: redundancy.map(|r| {
                let voter = DualVoter::new(r.timeout, r.skew);
                if bits > 0 {
                    // The counter comes round after its range of cycles: copies further
                    // apart than that less half a cycle are never of one command.
                    let range = RollingCounter::new(bits).modulus();
                    let period = config.cycle.saturating_mul(u32::from(range));
                    voter
                        .paired_by(|a: &(Command, u8), b: &(Command, u8)| a.1 == b.1)
                        .pairing_within(period.saturating_sub(config.cycle / 2))
                } else {
                    voter
                }
            }),
            waiting: None,
            pending_since: None,
            copy_window: config.redundancy.map_or(Duration::ZERO, |r| {
                if bits > 0 {
                    r.timeout
                } else {
                    r.skew
                }
            }),
            degraded: None,
            degradation: Degradation::new(
                config
                    .degradation
                    .unwrap_or_else(DegradationPolicy::fail_safe),
            ),
            stats: CommandStats::default(),
            command: None,
            last_valid: None,
            last_engage_bit: false,
            last_reset_bit: false,
            watchdog: Watchdog::FullBraking,
            missed_reported: 0,
            decelerating_since: None,
            estop: EstopState::Normal,
            estop_active: false,
            estop_heard: None,
            estop_chain_lost: false,
            emergency_brake_until: None,
            mode: ControlMode::Manual,
            driver_input: false,
            speed: 0.0,
            steering_actual: 0.0,
            steering,
            last_poll: None,
            next_state_frame: Timestamp::ZERO,
            state_counter: 0,
            echo: 0,
        }
    }

    /// The wire it reads.
    pub fn wire(&self) -> &W {
        &self.wire
    }

    /// The wire, to send the vehicle's other messages with it.
    pub fn wire_mut(&mut self) -> &mut W {
        &mut self.wire
    }

    /// The watchdog's level.
    pub fn watchdog(&self) -> Watchdog {
        self.watchdog
    }

    /// The E-stop latch's state.
    pub fn estop(&self) -> EstopState {
        self.estop
    }

    /// Whether the E-stop chain counts as open because its frames stopped coming (not
    /// because one asked for the E-stop), until the next one comes.
    pub fn estop_chain_lost(&self) -> bool {
        self.estop_chain_lost
    }

    /// The control mode.
    pub fn mode(&self) -> ControlMode {
        self.mode
    }

    /// Command counts.
    pub fn stats(&self) -> CommandStats {
        self.stats
    }

    /// The last valid command.
    pub fn command(&self) -> Option<Command> {
        self.command
    }

    /// What the vehicle measures: speed (m/s) and steering angle (degrees).
    pub fn set_feedback(&mut self, speed: f64, steering: f64) {
        if speed.is_finite() {
            self.speed = speed;
        }
        if steering.is_finite() {
            self.steering_actual = steering;
        }
        // Standstill moves the E-stop latch on at once, not at the next poll.
        self.evaluate(false, false);
    }

    /// The driver's steering torque (N·m) and pedal travel (0–1); above the thresholds this
    /// takes over at once.
    pub fn set_driver_input(&mut self, torque: f64, pedal: f64) {
        // Non-finite readings count as input present: fail towards the driver.
        self.driver_input = !(torque.abs() < self.config.takeover_torque
            && pedal.abs() < self.config.takeover_pedal);
        self.evaluate(false, false);
    }

    /// Whether a driver's input is above the takeover thresholds.
    pub fn driver_input(&self) -> bool {
        self.driver_input
    }

    fn standstill(&self) -> bool {
        self.speed.abs() < self.config.standstill
    }

    /// Which bus delivers alone, when redundancy is degraded.
    pub fn degraded(&self) -> Option<Channel> {
        self.degraded
    }

    /// The degradation latch: the level and the faults behind it.
    pub fn degradation(&self) -> &Degradation {
        &self.degradation
    }

    /// A fault a fail-operational mechanism found (reported once, at its edge): the level
    /// from now on, whose limits [`Supervisor::actuators`] applies. At
    /// [`DegradationLevel::SafeStop`] the vehicle brakes fully, as for a lost command stream.
    pub fn report_fault(&mut self, fault: Fault) -> DegradationLevel {
        self.degradation.report(fault)
    }

    /// Back to nominal after the faults are repaired: only at a standstill (whether it was
    /// reset).
    pub fn reset_degradation(&mut self) -> bool {
        let standstill = self.standstill();
        self.degradation.reset(standstill)
    }

    /// Validate a command frame from `channel`.
    fn validate(
        &mut self,
        now: Timestamp,
        channel: Channel,
        read: Result<(Option<Command>, u64), Rejected>,
    ) -> Result<(Command, u8), Rejection> {
        let (command, counter) = read.map_err(|rejected| match rejected {
            Rejected::Malformed => Rejection::Malformed,
            Rejected::Checksum => Rejection::Checksum,
            Rejected::Authentication => Rejection::Authentication,
        })?;
        let counter = u8::try_from(counter).unwrap_or(0);
        let last = self.command.map(|_| self.echo);
        let checker = match channel {
            Channel::A => &mut self.counter,
            Channel::B => &mut self.counter_b,
        };
        let status = match self.config.disabled.contains(Mechanism::E2e) {
            true => CounterStatus::InSequence,
            false => checker.check(now, counter),
        };
        match status {
            CounterStatus::Initial | CounterStatus::InSequence => {}
            // After a silence the stream may restart anywhere, but not with the value it
            // froze on: a frozen sender must not get a frame through every timeout.
            CounterStatus::Stale if last == Some(counter) => {
                return Err(Rejection::RepeatedCounter)
            }
            CounterStatus::Stale => {}
            CounterStatus::Repeated => return Err(Rejection::RepeatedCounter),
            CounterStatus::Skipped { .. } | CounterStatus::OutOfSequence => {
                return Err(Rejection::SkippedCounter)
            }
        }
        let c = self.config;
        let command = command.ok_or(Rejection::OutOfRange)?;
        // Written so that a NaN (a float signal can carry one) fails every comparison. The
        // E-stop mode is the vehicle's to report: a command cannot request it (a stop is asked
        // for on the E-stop and emergency-brake messages), so one that does is refused, as the
        // ADS side refuses to send it (`profile::Limits::admit`).
        let within = command.steering.abs() <= c.steering_range
            && command.velocity.abs() <= c.speed_limit
            && (0.0..=100.0).contains(&command.brake)
            && command.mode != ControlMode::Estop;
        if !within && !c.disabled.contains(Mechanism::Range) {
            return Err(Rejection::OutOfRange);
        }
        Ok((command, counter))
    }

    /// A frame from one of the two buses.
    fn receive(&mut self, now: Timestamp, channel: Channel, frame: &Frame) {
        match self.wire.incoming_from(channel, frame) {
            Incoming::Command(read) => self.on_command(now, channel, read),
            Incoming::Estop(requested) => {
                self.estop_heard = Some(now);
                self.estop_chain_lost = false;
                self.estop_active = requested;
                self.evaluate(false, false);
            }
            Incoming::EmergencyBrake(requested) => {
                // Each brake frame holds full braking for 3 cycles (the burst, then 20 Hz).
                self.emergency_brake_until =
                    requested.then(|| now.saturating_add(self.config.cycle.saturating_mul(3)));
            }
            Incoming::Unauthenticated => {
                self.stats.unauthenticated = self.stats.unauthenticated.saturating_add(1);
            }
            Incoming::Other => {}
        }
    }

    fn on_command(
        &mut self,
        now: Timestamp,
        channel: Channel,
        read: Result<(Option<Command>, u64), Rejected>,
    ) {
        let (command, counter) = match self.validate(now, channel, read) {
            Err(r) => return self.stats.count(r),
            Ok(valid) => valid,
        };
        // With two buses: a copy of the command in force or of one before it (the other
        // bus's copy came first, or this bus is behind).
        let recent = self
            .last_valid
            .is_some_and(|t| now.saturating_since(t) <= self.copy_window);
        let taken = self.voter.is_some() && recent && self.taken_already(counter);
        if let Some(voter) = self.voter.as_mut() {
            if taken {
                voter.receive_behind(channel, now, (command, counter));
            } else {
                voter.receive(channel, now, (command, counter));
            }
            match voter.vote(now) {
                Vote::Agreed(_) => self.degraded = None,
                Vote::Degraded { healthy, .. } => {
                    self.degraded = Some(healthy);
                    // The other bus is the healthy one: this copy came over a timeout after
                    // its partner, its bus is late, and the other bus's copies are taken alone.
                    if healthy != channel {
                        return;
                    }
                }
                Vote::Pending => {
                    self.waiting = Some(channel);
                    self.pending_since.get_or_insert(now);
                    return;
                }
                Vote::Failed(VoteFailure::BothLost) => return,
                Vote::Failed(VoteFailure::Disagree) => {
                    self.waiting = None;
                    self.stats.count(Rejection::Disagreement);
                    self.watchdog = self
                        .watchdog
                        .next(WatchdogEvent::Disagreement, self.config.cascade);
                    return self.evaluate(false, false);
                }
            }
            // Compared, but nothing new to take.
            if taken {
                return;
            }
        }
        self.accept(now, command, counter);
    }

    /// Whether the command with `counter` is the one in force or came before it: fewer
    /// than half the counter's values behind the one taken last (with no counter, every
    /// command has the same one, 0).
    fn taken_already(&self, counter: u8) -> bool {
        let rolling = RollingCounter::new(self.wire.command_counter_bits());
        rolling.steps_from(counter, self.echo) < rolling.modulus() / 2
    }

    fn accept(&mut self, now: Timestamp, command: Command, counter: u8) {
        self.stats.accepted = self.stats.accepted.saturating_add(1);
        let engage = command.engage && !self.last_engage_bit;
        let reset = command.operator_reset && !self.last_reset_bit;
        self.last_engage_bit = command.engage;
        self.last_reset_bit = command.operator_reset;
        self.echo = counter;
        self.command = Some(command);
        self.last_valid = Some(now);
        self.waiting = None;
        self.pending_since = None;
        self.missed_reported = 0;
        self.decelerating_since = None;
        self.watchdog = self
            .watchdog
            .next(WatchdogEvent::Valid { engage }, self.config.cascade);
        self.evaluate(engage, reset);
    }

    /// Run the E-stop latch and the mode machine on the current inputs.
    fn evaluate(&mut self, engage: bool, operator_reset: bool) {
        let mut inputs = EstopInputs {
            active: self.estop_active,
            operator_reset,
            engage,
            standstill: self.standstill(),
        };
        // The latch moves through its stages in order within one evaluation: bounded by its
        // eight states. An edge (reset, engage) is used by one transition only.
        for _ in 0..8 {
            let next = self.estop.next(inputs);
            if next == self.estop {
                break;
            }
            self.estop = next;
            inputs.operator_reset = false;
            inputs.engage = false;
        }
        let requested = self.command.map_or(ControlMode::Manual, |c| c.mode);
        self.mode = next_mode(
            self.mode,
            ModeInputs {
                requested,
                engage,
                driver_input: self.driver_input,
                estop: self.estop.is_latched(),
                watchdog_normal: self.watchdog == Watchdog::Normal,
                standstill: self.standstill(),
            },
        );
    }

    /// When [`Supervisor::step`] next has something to do.
    fn deadline(&self) -> Option<Timestamp> {
        let tick = self.last_heard().map(|t| {
            // Half a cycle of tolerance for jitter: cycle k is missed at (k + ½) cycles.
            let k = u32::try_from(u64::from(self.missed_reported) + 1).unwrap_or(u32::MAX);
            t.saturating_add(self.config.cycle.saturating_mul(k))
                .saturating_add(self.config.cycle / 2)
        });
        let due = tick.map_or(self.next_state_frame, |t| t.min(self.next_state_frame));
        let due = self.estop_deadline().map_or(due, |t| t.min(due));
        Some(self.partner_deadline().map_or(due, |t| t.min(due)))
    }

    /// What the watchdog counts missed cycles from: the last command taken, or the first copy
    /// since then still waiting for its partner.
    fn last_heard(&self) -> Option<Timestamp> {
        let taken = self.last_valid?;
        Some(self.pending_since.map_or(taken, |first| first.max(taken)))
    }

    /// When a copy waiting for its partner is taken alone: the other bus's last copy stale.
    fn partner_deadline(&self) -> Option<Timestamp> {
        let voter = self.voter.as_ref()?;
        voter.stale_at(self.waiting?.other())
    }

    /// Take a copy that waited for its partner in vain, in degraded mode, once the other
    /// bus's last copy is stale; as arrived then, so the watchdog counts from its arrival.
    fn take_waiting_copy(&mut self, now: Timestamp) {
        let (Some(channel), Some(voter)) = (self.waiting, self.voter) else {
            return;
        };
        match voter.vote(now) {
            Vote::Pending => {}
            Vote::Degraded {
                value: (command, counter),
                healthy,
            } if healthy == channel => {
                self.degraded = Some(healthy);
                let arrived = voter.arrived(channel).unwrap_or(now);
                self.accept(arrived, command, counter);
            }
            // Stale itself: nothing left to take.
            _ => self.waiting = None,
        }
    }

    /// When a chain heard before counts as open for want of its frames: three command cycles
    /// after the last (a bus that cannot carry the E-stop chain is an E-stop).
    fn estop_deadline(&self) -> Option<Timestamp> {
        let heard = self.estop_heard.filter(|_| !self.estop_active)?;
        Some(heard.saturating_add(self.config.cycle.saturating_mul(ESTOP_TIMEOUT_CYCLES)))
    }

    /// Advance to `now`: watchdog ticks, the latch at standstill, the state frame when due
    /// (given once; [`Node::poll`] sends it on each command bus).
    fn step(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        self.take_waiting_copy(now);
        let timeouts = !self.config.disabled.contains(Mechanism::Timeout);
        if let Some(last) = self.last_heard().filter(|_| timeouts) {
            let cycle = self.config.cycle.as_nanos().max(1);
            let elapsed = now.saturating_since(last).as_nanos();
            let tolerance = cycle / 2;
            let missed =
                u32::try_from(elapsed.saturating_sub(tolerance) / cycle).unwrap_or(u32::MAX);
            if missed > self.missed_reported {
                self.missed_reported = missed;
                let before = self.watchdog;
                self.watchdog = self
                    .watchdog
                    .next(WatchdogEvent::Missed(missed), self.config.cascade);
                if matches!(self.watchdog, Watchdog::Decelerating { .. })
                    && !matches!(before, Watchdog::Decelerating { .. })
                {
                    let held = self.command.map_or(0.0, |c| c.velocity);
                    self.decelerating_since = Some((now, held));
                }
            }
        }
        if timeouts && self.estop_deadline().is_some_and(|t| now >= t) {
            self.estop_active = true;
            self.estop_chain_lost = true;
        }
        if self.emergency_brake_until.is_some_and(|until| now >= until) {
            self.emergency_brake_until = None;
        }
        self.evaluate(false, false);
        let dt = self
            .last_poll
            .map_or(0.0, |last| now.saturating_since(last).as_secs_f64());
        self.last_poll = Some(now);
        let target = self.steering_target();
        self.steering.step(dt, target);
        if now >= self.next_state_frame {
            self.next_state_frame = now.saturating_add(self.config.cycle);
            if let Some(frame) = self.state_frame() {
                out(frame);
            }
            // Beside it, on a fail-operational vehicle whose wire has one, the degradation
            // report (a fail-safe vehicle's frames stay as they are).
            let report = DegradationReport {
                level: self.degradation.level(),
                reason: self.degradation.reason().map(|f| f.class),
            };
            let frame = self
                .config
                .degradation
                .and_then(|_| self.wire.degradation_frame(&report, self.state_counter));
            if let Some(frame) = frame {
                out(frame);
            }
        }
        if let Some(frame) = self.wire.pending_frame(now) {
            out(frame);
        }
    }

    fn steering_target(&self) -> f64 {
        match (self.mode, self.watchdog) {
            (ControlMode::Autonomous, Watchdog::Normal | Watchdog::Holding { .. }) => {
                self.command.map_or(self.steering_actual, |c| c.steering)
            }
            // Held where it is (decelerating), or where the driver puts it.
            _ => self.steering_actual,
        }
    }

    /// The steering mode in force: the command's, unless the degradation level forbids it
    /// (then normal steering).
    fn steering_mode(&self) -> SteeringMode {
        let commanded = self
            .command
            .map_or(SteeringMode::Normal, |c| c.steering_mode);
        match self.degradation.limits() {
            Some(limits) if !limits.steering_modes.allows(commanded) => SteeringMode::Normal,
            _ => commanded,
        }
    }

    /// What the actuators must do now.
    pub fn actuators(&self, now: Timestamp) -> Actuators {
        let actuators = self.outputs(now);
        // Switched off, nothing ever brakes on its own (not even a latched E-stop): the last
        // command goes on as it was.
        if !actuators.motors_enabled && self.config.disabled.contains(Mechanism::SafeState) {
            if let Some(command) = self.command {
                let c = self.config;
                return Actuators {
                    steering_enabled: true,
                    steering: command.steering,
                    motors_enabled: true,
                    velocity: command.velocity,
                    motor_rpm: motor_rpm(command.velocity, c.gear_ratio, c.wheel_diameter),
                    brake: command.brake,
                    ..actuators
                };
            }
        }
        actuators
    }

    fn outputs(&self, now: Timestamp) -> Actuators {
        let c = self.config;
        let command = self.command;
        let steering_mode = self.steering_mode();
        let gear = command.map_or(Gear::Park, |c| c.gear);
        let full_brake = Actuators {
            ads_in_control: self.mode == ControlMode::Autonomous,
            steering_enabled: false,
            steering: self.steering_actual,
            steering_mode,
            motors_enabled: false,
            velocity: 0.0,
            motor_rpm: 0.0,
            brake: 100.0,
            gear,
            warning: true,
        };
        // The latch passes MOTORS_DISABLED to BRAKES_APPLIED within one evaluation, so a
        // latched E-stop always reads as motors off and brakes on.
        if self.estop.is_latched() {
            return full_brake;
        }
        if self.mode != ControlMode::Autonomous {
            // The driver (or a service tool) drives; the ADS's setpoints are ignored.
            return Actuators {
                ads_in_control: false,
                steering_enabled: false,
                steering: self.steering_actual,
                steering_mode,
                motors_enabled: true,
                velocity: 0.0,
                motor_rpm: 0.0,
                brake: 0.0,
                gear,
                warning: self.watchdog != Watchdog::Normal,
            };
        }
        if self.emergency_brake_until.is_some_and(|until| now < until)
            || self.degradation.level() == DegradationLevel::SafeStop
        {
            return full_brake;
        }
        let steering = self.steering.value().unwrap_or(self.steering_actual);
        let (velocity, brake, warning) = match (self.watchdog, command) {
            (Watchdog::Normal, Some(cmd)) => (cmd.velocity, cmd.brake, self.degraded.is_some()),
            (Watchdog::Holding { .. }, Some(cmd)) => (cmd.velocity, cmd.brake, true),
            (Watchdog::Decelerating { .. }, _) => {
                let (since, held) = self.decelerating_since.unwrap_or((now, 0.0));
                let drop = c.controlled_deceleration * now.saturating_since(since).as_secs_f64();
                let v = (held.abs() - drop).max(0.0).copysign(held);
                (v, 0.0, true)
            }
            _ => return full_brake,
        };
        // Degraded: no faster than the level allows.
        let (velocity, warning) = match self.degradation.limits() {
            Some(limits) => (
                velocity.clamp(-limits.speed_limit, limits.speed_limit),
                true,
            ),
            None => (velocity, warning),
        };
        Actuators {
            ads_in_control: true,
            steering_enabled: true,
            steering,
            steering_mode,
            motors_enabled: true,
            velocity,
            motor_rpm: motor_rpm(velocity, c.gear_ratio, c.wheel_diameter),
            brake,
            gear,
            warning,
        }
    }

    /// The `VehicleToAds_State` frame.
    fn state_frame(&mut self) -> Option<Frame> {
        let steering_enabled = self.mode == ControlMode::Autonomous
            && matches!(
                self.watchdog,
                Watchdog::Normal | Watchdog::Holding { .. } | Watchdog::Decelerating { .. }
            )
            && !self.estop.is_latched();
        let report = StateReport {
            steering: self.steering_actual,
            velocity: self.speed,
            mode: self.mode,
            steering_mode: self.steering_mode(),
            gear: self.command.map_or(Gear::Park, |c| c.gear),
            watchdog_level: self.watchdog.level(),
            estop_state: self.estop.code(),
            warning: self.watchdog != Watchdog::Normal
                || self.degraded.is_some()
                || self.degradation.level() != DegradationLevel::Nominal,
            driver_override: self.driver_input,
            steering_enabled,
            turn_indicators: self
                .command
                .map_or(TurnIndicators::Off, |c| c.turn_indicators),
            // The hazard lights also warn while the vehicle stops on its own.
            hazard_lights: self.command.is_some_and(|c| c.hazard_lights)
                || self.watchdog == Watchdog::FullBraking
                || self.estop.is_latched(),
            heartbeat_echo: u64::from(self.echo),
        };
        let frame = self.wire.state_frame(&report, self.state_counter);
        let mask = (1u64 << self.wire.state_counter_bits().clamp(1, 8)) - 1;
        self.state_counter = (self.state_counter + 1) & mask;
        frame
    }
}

impl<W: VehicleWire> crate::arbitration::Degrades for Supervisor<W> {
    fn report_fault(&mut self, fault: Fault) {
        Supervisor::report_fault(self, fault);
    }
}

impl<W: VehicleWire> Supervisor<W> {
    /// The port of the command bus (bus A; the only one without redundancy).
    pub const PORT_A: Port = crate::redundancy::Channel::A.port();
    /// The port of the redundant command bus B.
    pub const PORT_B: Port = crate::redundancy::Channel::B.port();
}

/// The supervisor as a node: commands and the E-stop chain on [`Supervisor::PORT_A`] and, with
/// redundancy, [`Supervisor::PORT_B`]; the state frame goes out on each command bus, so the ADS
/// keeps its feedback when one bus is lost. Frames on other ports are not its buses'.
impl<W: VehicleWire> Node for Supervisor<W> {
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        match port {
            Self::PORT_A => self.receive(now, Channel::A, frame),
            Self::PORT_B if self.voter.is_some() => self.receive(now, Channel::B, frame),
            _ => {}
        }
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        let redundant = self.voter.is_some();
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
