//! CiA 402 drives, on both ends of the wire: the device state machine driven by the
//! controlword and reported in the statusword (one exhaustive transition function), a drive
//! application with a motor model (profile position, profile velocity, cyclic synchronous
//! position and velocity), and the master-side [`DriveController`] that walks a drive to
//! Operation enabled, commands it, and brings it to a safe stop on heartbeat loss, EMCY or a
//! fault, staying stopped until the application acknowledges.

use alloc::vec;
use core::time::Duration;

use bywire_core::frame::Frame;
use bywire_core::time::Timestamp;

use crate::abort::Abort;
use crate::device::{error_register, Application, EmcyProducer};
use crate::nmt::{classic, cob_id, NmtState};
use crate::od::{Access, DataType, Entry, ObjectDictionary, ObjectKind};

/// Controlword (0x6040), statusword (0x6041) and the other CiA 402 objects used here.
pub mod object {
    /// Abort connection option code.
    pub const ABORT_CONNECTION: u16 = 0x6007;
    /// Error code.
    pub const ERROR_CODE: u16 = 0x603F;
    /// Controlword.
    pub const CONTROLWORD: u16 = 0x6040;
    /// Statusword.
    pub const STATUSWORD: u16 = 0x6041;
    /// Quick stop option code.
    pub const QUICK_STOP_OPTION: u16 = 0x605A;
    /// Modes of operation.
    pub const MODES: u16 = 0x6060;
    /// Modes of operation display.
    pub const MODES_DISPLAY: u16 = 0x6061;
    /// Position actual value.
    pub const POSITION_ACTUAL: u16 = 0x6064;
    /// Velocity actual value.
    pub const VELOCITY_ACTUAL: u16 = 0x606C;
    /// Target position.
    pub const TARGET_POSITION: u16 = 0x607A;
    /// Profile velocity.
    pub const PROFILE_VELOCITY: u16 = 0x6081;
    /// Profile acceleration.
    pub const PROFILE_ACCELERATION: u16 = 0x6083;
    /// Profile deceleration.
    pub const PROFILE_DECELERATION: u16 = 0x6084;
    /// Quick stop deceleration.
    pub const QUICK_STOP_DECELERATION: u16 = 0x6085;
    /// Target velocity.
    pub const TARGET_VELOCITY: u16 = 0x60FF;
    /// Supported drive modes.
    pub const SUPPORTED_MODES: u16 = 0x6502;
}

/// The drive states (CiA 402 figure 12).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum State {
    /// Initialising; not yet able to switch on.
    NotReadyToSwitchOn,
    /// Power stage off, waiting for Shutdown.
    SwitchOnDisabled,
    /// Ready; waiting for Switch on.
    ReadyToSwitchOn,
    /// Power stage on, not yet enabled.
    SwitchedOn,
    /// Following commands.
    OperationEnabled,
    /// Stopping with the quick stop ramp (or stopped, holding).
    QuickStopActive,
    /// A fault was detected; the drive is stopping.
    FaultReactionActive,
    /// Stopped on a fault; waiting for Fault reset.
    Fault,
}

impl State {
    /// The state bits of the statusword (bits 0-3, 5, 6).
    pub fn statusword_bits(self) -> u16 {
        match self {
            State::NotReadyToSwitchOn => 0x0000,
            State::SwitchOnDisabled => 0x0040,
            State::ReadyToSwitchOn => 0x0021,
            State::SwitchedOn => 0x0023,
            State::OperationEnabled => 0x0027,
            State::QuickStopActive => 0x0007,
            State::FaultReactionActive => 0x000F,
            State::Fault => 0x0008,
        }
    }

    /// The state a statusword reports (CiA 402 table 30 masks).
    pub fn from_statusword(statusword: u16) -> Option<State> {
        let wide = statusword & 0x4F;
        let narrow = statusword & 0x6F;
        Some(match (wide, narrow) {
            (0x00, _) => State::NotReadyToSwitchOn,
            (0x40, _) => State::SwitchOnDisabled,
            (0x0F, _) => State::FaultReactionActive,
            (0x08, _) => State::Fault,
            (_, 0x21) => State::ReadyToSwitchOn,
            (_, 0x23) => State::SwitchedOn,
            (_, 0x27) => State::OperationEnabled,
            (_, 0x07) => State::QuickStopActive,
            _ => return None,
        })
    }

    /// The power stage drives the motor.
    pub fn is_powered(self) -> bool {
        matches!(
            self,
            State::OperationEnabled | State::QuickStopActive | State::FaultReactionActive
        )
    }
}

/// A device-control command decoded from the controlword (CiA 402 table 28).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Command {
    /// 0xxx x110.
    Shutdown,
    /// 0xxx 0111.
    SwitchOn,
    /// 0xxx 1111: switch on and enable operation.
    EnableOperation,
    /// 0xxx xx0x.
    DisableVoltage,
    /// 0xxx x01x.
    QuickStop,
    /// 0xxx 0111 from Operation enabled.
    DisableOperation,
    /// Bit 7 rising.
    FaultReset,
    /// Nothing (bit 7 high without an edge, or a pattern naming no command).
    None,
}

/// Controlword values the master sends.
pub mod controlword {
    /// Shutdown.
    pub const SHUTDOWN: u16 = 0x0006;
    /// Switch on.
    pub const SWITCH_ON: u16 = 0x0007;
    /// Switch on + enable operation.
    pub const ENABLE_OPERATION: u16 = 0x000F;
    /// Disable voltage.
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    /// Quick stop.
    pub const QUICK_STOP: u16 = 0x0002;
    /// Fault reset (the rising edge counts).
    pub const FAULT_RESET: u16 = 0x0080;
    /// Profile position: new set-point.
    pub const NEW_SET_POINT: u16 = 0x0010;
    /// Profile position: change set immediately.
    pub const CHANGE_IMMEDIATELY: u16 = 0x0020;
    /// Halt.
    pub const HALT: u16 = 0x0100;
}

impl Command {
    /// Decode `controlword` given the previous one (fault reset is an edge) and whether the
    /// drive is in Operation enabled (switch on means disable operation there).
    pub fn decode(controlword: u16, previous: u16) -> Command {
        if controlword & 0x80 != 0 {
            return if previous & 0x80 == 0 {
                Command::FaultReset
            } else {
                Command::None
            };
        }
        if controlword & 0x02 == 0 {
            return Command::DisableVoltage;
        }
        if controlword & 0x04 == 0 {
            return Command::QuickStop;
        }
        match controlword & 0x0F {
            0x06 | 0x0E => Command::Shutdown,
            0x07 => Command::SwitchOn,
            0x0F => Command::EnableOperation,
            _ => Command::None,
        }
    }
}

/// What moves the state machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Event {
    /// Initialisation finished (transition 1).
    Initialised,
    /// A controlword command.
    Command(Command),
    /// A fault was detected (transition 13).
    Fault,
    /// The fault reaction finished (transition 14).
    FaultReactionDone,
    /// The quick stop ramp finished; the option code says whether to leave (transition 12).
    QuickStopDone {
        /// Quick stop option code 1-4: go to Switch on disabled.
        leave: bool,
    },
}

/// Quick stop option codes 5-8 allow returning to Operation enabled from Quick stop active.
/// The one transition function of the drive: every state and event is named.
pub fn transition(state: State, event: Event) -> State {
    use Command as C;
    use State as S;
    match (state, event) {
        (_, Event::Fault) if state != S::Fault => S::FaultReactionActive,
        (S::Fault, Event::Fault) => S::Fault,
        (S::NotReadyToSwitchOn, Event::Initialised) => S::SwitchOnDisabled,
        (S::NotReadyToSwitchOn, _) => S::NotReadyToSwitchOn,
        (S::SwitchOnDisabled, Event::Command(C::Shutdown)) => S::ReadyToSwitchOn,
        (S::SwitchOnDisabled, _) => S::SwitchOnDisabled,
        (S::ReadyToSwitchOn, Event::Command(C::SwitchOn)) => S::SwitchedOn,
        (S::ReadyToSwitchOn, Event::Command(C::EnableOperation)) => S::SwitchedOn,
        (S::ReadyToSwitchOn, Event::Command(C::DisableVoltage | C::QuickStop)) => {
            S::SwitchOnDisabled
        }
        (S::ReadyToSwitchOn, _) => S::ReadyToSwitchOn,
        (S::SwitchedOn, Event::Command(C::EnableOperation)) => S::OperationEnabled,
        (S::SwitchedOn, Event::Command(C::Shutdown)) => S::ReadyToSwitchOn,
        (S::SwitchedOn, Event::Command(C::DisableVoltage | C::QuickStop)) => S::SwitchOnDisabled,
        (S::SwitchedOn, _) => S::SwitchedOn,
        (S::OperationEnabled, Event::Command(C::SwitchOn | C::DisableOperation)) => S::SwitchedOn,
        (S::OperationEnabled, Event::Command(C::Shutdown)) => S::ReadyToSwitchOn,
        (S::OperationEnabled, Event::Command(C::DisableVoltage)) => S::SwitchOnDisabled,
        (S::OperationEnabled, Event::Command(C::QuickStop)) => S::QuickStopActive,
        (S::OperationEnabled, _) => S::OperationEnabled,
        (S::QuickStopActive, Event::Command(C::DisableVoltage)) => S::SwitchOnDisabled,
        (S::QuickStopActive, Event::QuickStopDone { leave: true }) => S::SwitchOnDisabled,
        (S::QuickStopActive, Event::Command(C::EnableOperation)) => S::OperationEnabled,
        (S::QuickStopActive, _) => S::QuickStopActive,
        (S::FaultReactionActive, Event::FaultReactionDone) => S::Fault,
        (S::FaultReactionActive, _) => S::FaultReactionActive,
        (S::Fault, Event::Command(C::FaultReset)) => S::SwitchOnDisabled,
        (S::Fault, _) => S::Fault,
    }
}

/// Modes of operation (0x6060) this drive runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    /// 1.
    ProfilePosition,
    /// 3.
    ProfileVelocity,
    /// 8.
    CyclicSynchronousPosition,
    /// 9.
    CyclicSynchronousVelocity,
}

impl Mode {
    /// The 0x6060 code.
    pub fn code(self) -> i8 {
        match self {
            Mode::ProfilePosition => 1,
            Mode::ProfileVelocity => 3,
            Mode::CyclicSynchronousPosition => 8,
            Mode::CyclicSynchronousVelocity => 9,
        }
    }

    /// The mode a 0x6060 code names.
    pub fn from_code(code: i64) -> Option<Mode> {
        match code {
            1 => Some(Mode::ProfilePosition),
            3 => Some(Mode::ProfileVelocity),
            8 => Some(Mode::CyclicSynchronousPosition),
            9 => Some(Mode::CyclicSynchronousVelocity),
            _ => None,
        }
    }

    /// Supported drive modes (0x6502) bits for every mode here.
    pub const SUPPORTED: u32 = 0x0001 | 0x0004 | 0x0080 | 0x0100;
}

/// A motor with limited acceleration: velocity in units/s, position in units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Motor {
    /// Position, units.
    pub position: f64,
    /// Velocity, units/s.
    pub velocity: f64,
}

impl Motor {
    /// Move the velocity toward `target` by at most `rate * dt`, then integrate.
    pub fn step_velocity(&mut self, target: f64, rate: f64, dt: f64) {
        let change = (target - self.velocity).clamp(-rate * dt, rate * dt);
        self.velocity += change;
        self.position += self.velocity * dt;
    }
}

/// The drive parameters a step uses, read from the dictionary once per change.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Params {
    mode: Option<Mode>,
    acceleration: f64,
    deceleration: f64,
    quick: f64,
    profile_velocity: f64,
    target_velocity: f64,
}

impl Params {
    /// The objects the parameters come from.
    const INDICES: [u16; 6] = [
        object::MODES,
        object::PROFILE_ACCELERATION,
        object::PROFILE_DECELERATION,
        object::QUICK_STOP_DECELERATION,
        object::PROFILE_VELOCITY,
        object::TARGET_VELOCITY,
    ];

    fn read(od: &ObjectDictionary) -> Params {
        let read = |index: u16| real(od.get_signed(index, 0).unwrap_or(0));
        Params {
            mode: Mode::from_code(od.get_signed(object::MODES, 0).unwrap_or(0)),
            acceleration: read(object::PROFILE_ACCELERATION).max(1.0),
            deceleration: read(object::PROFILE_DECELERATION).max(1.0),
            quick: read(object::QUICK_STOP_DECELERATION).max(1.0),
            profile_velocity: read(object::PROFILE_VELOCITY),
            target_velocity: read(object::TARGET_VELOCITY),
        }
    }
}

/// A CiA 402 drive: the application of a [`crate::device::Device`].
#[derive(Debug, Clone)]
pub struct Drive {
    state: State,
    previous_controlword: u16,
    motor: Motor,
    last_step: Option<Timestamp>,
    position_target: f64,
    fault_pending: Option<u16>,
    raised: Option<u16>,
    /// The dictionary's drive parameters, read again after a write to one (`None`: not yet).
    params: Option<Params>,
    /// What was last written to the dictionary (statusword, mode display, position and
    /// velocity actual): unchanged values are not written again.
    published: Option<(u16, i8, i64, i64)>,
    /// The motor is outside (a plant the runner steps): the drive computes a velocity demand
    /// and is told the actual position and velocity.
    external: bool,
    demand: f64,
    /// Position units a velocity unit moves in a second (1 when velocity is position units
    /// per second; a Roboteq's counts per RPM-second is its counts per revolution / 60).
    position_per_velocity: f64,
    /// Maximum velocity the motor reaches (velocity units).
    pub max_velocity: f64,
}

impl Default for Drive {
    fn default() -> Self {
        Drive::new()
    }
}

/// Quick stop option code 2 (CiA 402 default): stop on the quick stop ramp, then Switch on
/// disabled.
const DEFAULT_QUICK_STOP_OPTION: i64 = 2;
/// Abort connection option 1 (CiA 402 default): fault.
const DEFAULT_ABORT_CONNECTION: i64 = 1;
/// EMCY code of a fault on a lost connection (heartbeat or life guarding, CiA 301).
const LOST_CONNECTION: u16 = 0x8130;
/// Position window within which the target counts as reached.
const POSITION_WINDOW: f64 = 10.0;
/// Velocity below which the motor counts as stopped.
const STANDSTILL: f64 = 1.0;

impl Drive {
    /// A drive that has not yet initialised.
    pub fn new() -> Drive {
        Drive {
            state: State::NotReadyToSwitchOn,
            previous_controlword: 0,
            motor: Motor::default(),
            last_step: None,
            position_target: 0.0,
            fault_pending: None,
            raised: None,
            params: None,
            published: None,
            external: false,
            demand: 0.0,
            position_per_velocity: 1.0,
            max_velocity: 10_000.0,
        }
    }

    /// A drive whose motor is a plant outside it: read [`Drive::demand`] after each poll and
    /// report what the plant did with [`Drive::set_actual`].
    pub fn with_external_motor(mut self) -> Drive {
        self.external = true;
        self
    }

    /// With an external motor whose velocity is in other units than position per second (RPM
    /// beside encoder counts): `position_per_velocity` position units a velocity unit moves in
    /// a second. Position modes brake in time with it.
    pub fn with_velocity_units(mut self, position_per_velocity: f64) -> Drive {
        self.set_velocity_units(position_per_velocity);
        self
    }

    /// As [`Drive::with_velocity_units`], on a drive already built (a value that is not a
    /// positive number is ignored).
    pub fn set_velocity_units(&mut self, position_per_velocity: f64) {
        if position_per_velocity.is_finite() && position_per_velocity > 0.0 {
            self.position_per_velocity = position_per_velocity;
        }
    }

    /// The velocity the drive asks of its motor now, units/s (zero with the power stage off).
    pub fn demand(&self) -> f64 {
        self.demand
    }

    /// The plant's actual position (units) and velocity (units/s).
    pub fn set_actual(&mut self, position: f64, velocity: f64) {
        if self.external {
            self.motor = Motor { position, velocity };
        }
    }

    /// Drive the motor toward `target` within `rate`: the internal model moves, or the external
    /// plant gets the ramped demand.
    fn drive_motor(&mut self, target: f64, rate: f64, dt: f64) {
        if self.external {
            self.demand += (target - self.demand).clamp(-rate * dt, rate * dt);
        } else {
            self.motor.step_velocity(target, rate, dt);
            self.demand = self.motor.velocity;
        }
    }

    /// The drive state.
    pub fn state(&self) -> State {
        self.state
    }

    /// The motor.
    pub fn motor(&self) -> Motor {
        self.motor
    }

    /// Report a fault (EMCY `code`, e.g. 0x2310 overcurrent): the drive reacts on its next
    /// step and stays in Fault while the cause remains.
    pub fn inject_fault(&mut self, code: u16) {
        self.fault_pending = Some(code);
    }

    /// The cause of an injected fault is gone: a fault reset now succeeds.
    pub fn clear_fault(&mut self) {
        self.fault_pending = None;
    }

    fn apply(&mut self, event: Event, od: &mut ObjectDictionary) {
        self.state = transition(self.state, event);
        self.publish(od);
    }

    /// The mode of operation: from the cache, or the dictionary when a write made it stale.
    fn mode(&self, od: &ObjectDictionary) -> Option<Mode> {
        match self.params {
            Some(params) => params.mode,
            None => Params::read(od).mode,
        }
    }

    fn publish(&mut self, od: &mut ObjectDictionary) {
        let mut statusword = self.state.statusword_bits();
        if self.state.is_powered()
            || matches!(self.state, State::SwitchedOn | State::ReadyToSwitchOn)
        {
            statusword |= 0x0010; // voltage enabled
        }
        statusword |= 0x0200; // remote: controlled over the network
        if self.target_reached(od) {
            statusword |= 0x0400;
        }
        let display = self.mode(od).map_or(0, Mode::code);
        let values = (
            statusword,
            display,
            round(self.motor.position),
            round(self.motor.velocity),
        );
        // Each value only when it changed: a moving drive's position changes every step, its
        // statusword seldom.
        let before = self.published.replace(values);
        let changed = |field: fn(&(u16, i8, i64, i64)) -> i64| {
            before.as_ref().map(field) != Some(field(&values))
        };
        if changed(|v| i64::from(v.0)) {
            let _ = od.set(object::STATUSWORD, 0, &statusword.to_le_bytes());
        }
        if changed(|v| i64::from(v.1)) {
            let _ = od.set(object::MODES_DISPLAY, 0, &display.to_le_bytes());
        }
        if changed(|v| v.2) {
            let _ = od.set_int(object::POSITION_ACTUAL, 0, values.2);
        }
        if changed(|v| v.3) {
            let _ = od.set_int(object::VELOCITY_ACTUAL, 0, values.3);
        }
    }

    fn target_reached(&self, od: &ObjectDictionary) -> bool {
        match (self.state, self.mode(od)) {
            (
                State::OperationEnabled,
                Some(Mode::ProfilePosition | Mode::CyclicSynchronousPosition),
            ) => {
                (self.motor.position - self.position_target).abs() <= POSITION_WINDOW
                    && self.motor.velocity.abs() < STANDSTILL
            }
            (State::OperationEnabled, Some(_)) => {
                let target = self
                    .params
                    .map_or_else(|| Params::read(od).target_velocity, |p| p.target_velocity);
                (self.motor.velocity - target).abs() < STANDSTILL
            }
            (State::QuickStopActive | State::FaultReactionActive, _) => {
                self.motor.velocity.abs() < STANDSTILL
            }
            _ => false,
        }
    }

    fn react_to_lost_connection(&mut self, od: &mut ObjectDictionary, emcy: &mut EmcyProducer) {
        match od
            .get_signed(object::ABORT_CONNECTION, 0)
            .unwrap_or(DEFAULT_ABORT_CONNECTION)
        {
            0 => {}
            2 => self.apply(Event::Command(Command::DisableVoltage), od),
            3 => self.apply(Event::Command(Command::QuickStop), od),
            _ => {
                let _ = od.set(object::ERROR_CODE, 0, &LOST_CONNECTION.to_le_bytes());
                emcy.raise(od, LOST_CONNECTION, error_register::COMMUNICATION, [0; 5]);
                self.raised = Some(LOST_CONNECTION);
                self.apply(Event::Fault, od);
            }
        }
    }
}

/// Round to the nearest integer (saturating at the ends of `i64`, as `as` does for floats).
#[allow(clippy::cast_possible_truncation)]
pub(crate) fn round(value: f64) -> i64 {
    libm::round(value) as i64
}

#[allow(clippy::cast_precision_loss)]
fn real(value: i64) -> f64 {
    value as f64
}

impl Application for Drive {
    fn check_write(
        &self,
        _od: &ObjectDictionary,
        index: u16,
        _sub: u8,
        data: &[u8],
    ) -> Result<(), Abort> {
        if index == object::MODES {
            let code = data.first().map(|b| i64::from(i8::from_le_bytes([*b])));
            if code.and_then(Mode::from_code).is_none() {
                return Err(Abort::InvalidValue);
            }
        }
        Ok(())
    }

    fn on_written(&mut self, _now: Timestamp, od: &mut ObjectDictionary, index: u16, _sub: u8) {
        // The cached parameters are read again when one of them changed (targets of position
        // arrive every cycle and are not among them).
        if Params::INDICES.contains(&index) {
            self.params = Some(Params::read(od));
        }
        match index {
            object::CONTROLWORD => {
                let controlword =
                    u16::try_from(od.get_unsigned(object::CONTROLWORD, 0).unwrap_or(0))
                        .unwrap_or(0);
                let command = Command::decode(controlword, self.previous_controlword);
                let new_set_point = controlword & controlword::NEW_SET_POINT != 0
                    && self.previous_controlword & controlword::NEW_SET_POINT == 0;
                self.previous_controlword = controlword;
                if command == Command::FaultReset && self.fault_pending.is_some() {
                    // The cause is still there: the reset does nothing.
                    self.publish(od);
                    return;
                }
                self.apply(Event::Command(command), od);
                if new_set_point && self.mode(od) == Some(Mode::ProfilePosition) {
                    self.position_target =
                        real(od.get_signed(object::TARGET_POSITION, 0).unwrap_or(0));
                }
            }
            object::TARGET_POSITION if self.mode(od) == Some(Mode::CyclicSynchronousPosition) => {
                self.position_target = real(od.get_signed(object::TARGET_POSITION, 0).unwrap_or(0));
            }
            _ => self.publish(od),
        }
    }

    fn on_nmt(
        &mut self,
        _now: Timestamp,
        state: NmtState,
        od: &mut ObjectDictionary,
        emcy: &mut EmcyProducer,
    ) {
        // Leaving operational while powered is a lost connection to the controlling master.
        if state == NmtState::Stopped && self.state.is_powered() {
            self.react_to_lost_connection(od, emcy);
        }
    }

    fn on_communication_lost(
        &mut self,
        _now: Timestamp,
        od: &mut ObjectDictionary,
        emcy: &mut EmcyProducer,
    ) {
        if self.state.is_powered() {
            self.react_to_lost_connection(od, emcy);
        }
    }

    fn step(&mut self, now: Timestamp, od: &mut ObjectDictionary, emcy: &mut EmcyProducer) {
        if self.state == State::NotReadyToSwitchOn {
            self.apply(Event::Initialised, od);
        }
        if let Some(code) = self.fault_pending {
            if !matches!(self.state, State::Fault | State::FaultReactionActive) {
                let _ = od.set(object::ERROR_CODE, 0, &code.to_le_bytes());
                emcy.raise(od, code, error_register::PROFILE, [0; 5]);
                self.raised = Some(code);
                self.apply(Event::Fault, od);
            }
        }
        let dt = self
            .last_step
            .map_or(0.0, |last| now.saturating_since(last).as_secs_f64())
            .min(0.1);
        self.last_step = Some(now);
        let params = *self.params.get_or_insert_with(|| Params::read(od));
        let (acceleration, deceleration, quick) =
            (params.acceleration, params.deceleration, params.quick);
        let halted = self.previous_controlword & controlword::HALT != 0;
        match self.state {
            State::OperationEnabled if !halted => match self.mode(od) {
                Some(Mode::ProfileVelocity) => {
                    let target = params
                        .target_velocity
                        .clamp(-self.max_velocity, self.max_velocity);
                    let rate = if target.abs() < self.motor.velocity.abs() {
                        deceleration
                    } else {
                        acceleration
                    };
                    self.drive_motor(target, rate, dt);
                }
                Some(Mode::CyclicSynchronousVelocity) => {
                    let target = params
                        .target_velocity
                        .clamp(-self.max_velocity, self.max_velocity);
                    self.drive_motor(target, acceleration.max(quick), dt);
                }
                Some(Mode::ProfilePosition | Mode::CyclicSynchronousPosition) => {
                    let limit = params.profile_velocity.clamp(1.0, self.max_velocity);
                    let remaining = self.position_target - self.motor.position;
                    // Brake in time: the speed from which `deceleration` stops within `remaining`.
                    let braking = libm::sqrt(
                        2.0 * deceleration * remaining.abs() / self.position_per_velocity,
                    );
                    let speed = limit.min(braking);
                    let target = if remaining.abs() <= POSITION_WINDOW / 2.0 {
                        0.0
                    } else {
                        speed.copysign(remaining)
                    };
                    self.drive_motor(target, acceleration.max(deceleration), dt);
                }
                None => self.drive_motor(0.0, quick, dt),
            },
            State::OperationEnabled => self.drive_motor(0.0, deceleration, dt),
            State::QuickStopActive | State::FaultReactionActive => {
                self.drive_motor(0.0, quick, dt);
                if self.motor.velocity.abs() < STANDSTILL {
                    if !self.external {
                        self.motor.velocity = 0.0;
                    }
                    self.demand = 0.0;
                    let event = if self.state == State::FaultReactionActive {
                        Event::FaultReactionDone
                    } else {
                        let option = od
                            .get_signed(object::QUICK_STOP_OPTION, 0)
                            .unwrap_or(DEFAULT_QUICK_STOP_OPTION);
                        Event::QuickStopDone {
                            leave: (1..=4).contains(&option) || option == 0,
                        }
                    };
                    self.state = transition(self.state, event);
                }
            }
            // Power stage off: the motor coasts to a stop on friction.
            State::NotReadyToSwitchOn
            | State::SwitchOnDisabled
            | State::ReadyToSwitchOn
            | State::SwitchedOn
            | State::Fault => {
                self.drive_motor(0.0, quick, dt);
            }
        }
        if !self.state.is_powered() {
            // Power stage off: the motor gets nothing.
            self.demand = 0.0;
        }
        // Out of Fault by a reset: the errors that caused it are history.
        if self.state == State::SwitchOnDisabled {
            if let Some(code) = self.raised.take() {
                emcy.clear(od, code);
                let _ = od.set(object::ERROR_CODE, 0, &[0, 0]);
            }
        }
        if self.state == State::OperationEnabled && self.mode(od) == Some(Mode::ProfileVelocity) {
            self.position_target = self.motor.position;
        }
        self.publish(od);
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        // The motor model wants a step every few milliseconds while anything moves.
        let moving = self.motor.velocity.abs() >= f64::EPSILON || self.state.is_powered();
        moving.then(|| {
            self.last_step.map_or(Timestamp::ZERO, |t| {
                t.saturating_add(Duration::from_millis(5))
            })
        })
    }

    fn reset(&mut self, od: &mut ObjectDictionary) {
        *self = Drive {
            max_velocity: self.max_velocity,
            external: self.external,
            position_per_velocity: self.position_per_velocity,
            ..Drive::new()
        };
        self.publish(od);
    }
}

/// The CiA 301 communication objects every device here has: device type, error register and
/// history, SYNC, name, EMCY, heartbeat consumer (four entries) and producer, identity.
pub fn communication_objects(
    od: &mut ObjectDictionary,
    node: u8,
    device_type: u32,
    name: &str,
    identity: [u32; 4],
) {
    let node32 = u32::from(node);
    od.add_var(
        0x1000,
        Entry::new(0, "Device type", DataType::U32, Access::ReadOnly)
            .with_int(i64::from(device_type)),
    );
    od.add_var(
        0x1001,
        Entry::new(0, "Error register", DataType::U8, Access::ReadOnly).mappable(),
    );
    od.add_object(
        0x1003,
        "Pre-defined error field",
        ObjectKind::Array,
        vec![
            Entry::new(0, "Number of errors", DataType::U8, Access::ReadWrite),
            Entry::new(1, "Standard error field", DataType::U32, Access::ReadOnly),
            Entry::new(2, "Standard error field", DataType::U32, Access::ReadOnly),
            Entry::new(3, "Standard error field", DataType::U32, Access::ReadOnly),
            Entry::new(4, "Standard error field", DataType::U32, Access::ReadOnly),
        ],
    );
    od.add_var(
        0x1005,
        Entry::new(0, "COB-ID SYNC", DataType::U32, Access::ReadWrite).with_int(0x80),
    );
    od.add_var(
        0x1006,
        Entry::new(
            0,
            "Communication cycle period",
            DataType::U32,
            Access::ReadWrite,
        ),
    );
    od.add_var(
        0x1008,
        Entry::new(
            0,
            "Manufacturer device name",
            DataType::VisibleString,
            Access::Const,
        )
        .with_default(name.as_bytes()),
    );
    od.add_var(
        0x1014,
        Entry::new(0, "COB-ID EMCY", DataType::U32, Access::ReadWrite)
            .with_int(i64::from(0x80 + node32)),
    );
    od.add_var(
        0x1015,
        Entry::new(0, "Inhibit time EMCY", DataType::U16, Access::ReadWrite),
    );
    od.add_object(
        0x1016,
        "Consumer heartbeat time",
        ObjectKind::Array,
        (1..=4)
            .map(|sub| {
                Entry::new(
                    sub,
                    "Consumer heartbeat time",
                    DataType::U32,
                    Access::ReadWrite,
                )
            })
            .collect(),
    );
    od.add_var(
        0x1017,
        Entry::new(
            0,
            "Producer heartbeat time",
            DataType::U16,
            Access::ReadWrite,
        )
        .with_int(100),
    );
    od.add_var(
        0x100C,
        Entry::new(0, "Guard time", DataType::U16, Access::ReadWrite),
    );
    od.add_var(
        0x100D,
        Entry::new(0, "Life time factor", DataType::U8, Access::ReadWrite),
    );
    od.add_object(
        0x1018,
        "Identity object",
        ObjectKind::Record,
        [
            "Vendor-ID",
            "Product code",
            "Revision number",
            "Serial number",
        ]
        .iter()
        .zip(identity)
        .zip(1u8..)
        .map(|((name, value), sub)| {
            Entry::new(sub, name, DataType::U32, Access::ReadOnly).with_int(i64::from(value))
        })
        .collect(),
    );
}

/// A PDO's communication and mapping parameters, as a dictionary describes them by default.
pub struct PdoDefault<'a> {
    /// PDO number from 1.
    pub number: u16,
    /// COB-ID (with bit 31 set for a disabled PDO).
    pub cob_id: u32,
    /// Transmission type.
    pub transmission: u8,
    /// Inhibit time, 100 µs.
    pub inhibit: u16,
    /// Event timer, ms.
    pub event_timer: u16,
    /// Mapped objects: `(index, sub, bits)`.
    pub mapping: &'a [(u16, u8, u8)],
}

/// Add a PDO's parameter objects (eight mapping entries).
pub fn add_pdo(od: &mut ObjectDictionary, transmit: bool, pdo: &PdoDefault<'_>) {
    let base = if transmit { 0x1800 } else { 0x1400 } + pdo.number - 1;
    let name = if transmit { "TPDO" } else { "RPDO" };
    od.add_object(
        base,
        &alloc::format!("{name}{} communication parameter", pdo.number),
        ObjectKind::Record,
        vec![
            Entry::new(1, "COB-ID", DataType::U32, Access::ReadWrite)
                .with_int(i64::from(pdo.cob_id)),
            Entry::new(2, "Transmission type", DataType::U8, Access::ReadWrite)
                .with_int(i64::from(pdo.transmission)),
            Entry::new(3, "Inhibit time", DataType::U16, Access::ReadWrite)
                .with_int(i64::from(pdo.inhibit)),
            Entry::new(5, "Event timer", DataType::U16, Access::ReadWrite)
                .with_int(i64::from(pdo.event_timer)),
            Entry::new(6, "SYNC start value", DataType::U8, Access::ReadWrite),
        ],
    );
    let mut entries: alloc::vec::Vec<Entry> = (1..=8u8)
        .map(|sub| {
            let raw =
                pdo.mapping
                    .get(usize::from(sub - 1))
                    .map_or(0, |(index, object_sub, bits)| {
                        (u32::from(*index) << 16) | (u32::from(*object_sub) << 8) | u32::from(*bits)
                    });
            Entry::new(
                sub,
                &alloc::format!("Mapped object {sub}"),
                DataType::U32,
                Access::ReadWrite,
            )
            .with_int(i64::from(raw))
        })
        .collect();
    let count = u8::try_from(pdo.mapping.len()).unwrap_or(0);
    entries.insert(
        0,
        Entry::new(
            0,
            "Number of mapped objects",
            DataType::U8,
            Access::ReadWrite,
        )
        .with_int(i64::from(count)),
    );
    od.add_object(
        base + 0x200,
        &alloc::format!("{name}{} mapping parameter", pdo.number),
        ObjectKind::Record,
        entries,
    );
}

/// The default PDO layout of [`drive_dictionary`], which [`DriveController`] speaks:
/// RPDO1 `0x200+id` controlword + modes of operation; RPDO2 `0x300+id` target position +
/// target velocity; TPDO1 `0x180+id` statusword + modes display (on change and every 100 ms);
/// TPDO2 `0x280+id` position + velocity actual (on change, at most every 10 ms, and every
/// 100 ms).
pub fn drive_dictionary(node: u8) -> ObjectDictionary {
    use object::*;
    let mut od = ObjectDictionary::new();
    let id = u32::from(node);
    communication_objects(
        &mut od,
        node,
        DEVICE_TYPE,
        "bywire drive",
        [0x0000_0B1E, 0x0402, 1, id],
    );
    add_drive_objects(&mut od, Mode::SUPPORTED);
    add_pdo(
        &mut od,
        false,
        &PdoDefault {
            number: 1,
            cob_id: 0x200 + id,
            transmission: 255,
            inhibit: 0,
            event_timer: 0,
            mapping: &[(CONTROLWORD, 0, 16), (MODES, 0, 8)],
        },
    );
    add_pdo(
        &mut od,
        false,
        &PdoDefault {
            number: 2,
            cob_id: 0x300 + id,
            transmission: 255,
            inhibit: 0,
            event_timer: 0,
            mapping: &[(TARGET_POSITION, 0, 32), (TARGET_VELOCITY, 0, 32)],
        },
    );
    add_pdo(
        &mut od,
        true,
        &PdoDefault {
            number: 1,
            cob_id: 0x180 + id,
            transmission: 255,
            inhibit: 0,
            event_timer: 100,
            mapping: &[(STATUSWORD, 0, 16), (MODES_DISPLAY, 0, 8)],
        },
    );
    add_pdo(
        &mut od,
        true,
        &PdoDefault {
            number: 2,
            cob_id: 0x280 + id,
            transmission: 255,
            // Actual values change with every encoder tick: at most one TPDO2 per 10 ms.
            inhibit: 100,
            event_timer: 100,
            mapping: &[(POSITION_ACTUAL, 0, 32), (VELOCITY_ACTUAL, 0, 32)],
        },
    );
    od
}

/// The device type (0x1000) of a CiA 402 drive: profile 402, servo drive.
pub const DEVICE_TYPE: u32 = 0x0002_0192;

/// The CiA 402 objects a [`Drive`] works on (0x6007 to 0x6502), for a drive of its own or a
/// controller with a CiA 402 face beside its own objects; `supported_modes` for 0x6502.
pub fn add_drive_objects(od: &mut ObjectDictionary, supported_modes: u32) {
    use object::*;
    let rw = |name: &str, data_type| Entry::new(0, name, data_type, Access::ReadWrite).mappable();
    let ro = |name: &str, data_type| Entry::new(0, name, data_type, Access::ReadOnly).mappable();
    od.add_var(
        ABORT_CONNECTION,
        rw("Abort connection option code", DataType::I16).with_int(DEFAULT_ABORT_CONNECTION),
    );
    od.add_var(ERROR_CODE, ro("Error code", DataType::U16));
    od.add_var(CONTROLWORD, rw("Controlword", DataType::U16));
    od.add_var(STATUSWORD, ro("Statusword", DataType::U16));
    od.add_var(
        QUICK_STOP_OPTION,
        rw("Quick stop option code", DataType::I16).with_int(DEFAULT_QUICK_STOP_OPTION),
    );
    od.add_var(MODES, rw("Modes of operation", DataType::I8).with_int(3));
    od.add_var(
        MODES_DISPLAY,
        ro("Modes of operation display", DataType::I8),
    );
    od.add_var(POSITION_ACTUAL, ro("Position actual value", DataType::I32));
    od.add_var(VELOCITY_ACTUAL, ro("Velocity actual value", DataType::I32));
    od.add_var(TARGET_POSITION, rw("Target position", DataType::I32));
    od.add_var(
        PROFILE_VELOCITY,
        rw("Profile velocity", DataType::U32).with_int(2_000),
    );
    od.add_var(
        PROFILE_ACCELERATION,
        rw("Profile acceleration", DataType::U32).with_int(10_000),
    );
    od.add_var(
        PROFILE_DECELERATION,
        rw("Profile deceleration", DataType::U32).with_int(10_000),
    );
    od.add_var(
        QUICK_STOP_DECELERATION,
        rw("Quick stop deceleration", DataType::U32).with_int(50_000),
    );
    od.add_var(TARGET_VELOCITY, rw("Target velocity", DataType::I32));
    od.add_var(
        SUPPORTED_MODES,
        Entry::new(0, "Supported drive modes", DataType::U32, Access::ReadOnly)
            .with_int(i64::from(supported_modes)),
    );
}

/// Why a [`DriveController`] stopped its drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StopReason {
    /// The drive's heartbeat stopped.
    HeartbeatLost,
    /// The drive sent an emergency with this code.
    Emergency(u16),
    /// The drive reported Fault (or Fault reaction active).
    Fault,
    /// The drive's statusword stopped arriving.
    StatusTimeout,
    /// The application asked for it.
    Commanded,
}

/// A safe stop that holds until acknowledged: the master-side controllers' latch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StopLatch(Option<StopReason>);

impl StopLatch {
    /// Stop (the first reason stays until acknowledged).
    pub fn stop(&mut self, reason: StopReason) {
        if self.0.is_none() {
            self.0 = Some(reason);
        }
    }

    /// Why it holds, if it does.
    pub fn reason(&self) -> Option<StopReason> {
        self.0
    }

    /// Release.
    pub fn acknowledge(&mut self) {
        self.0 = None;
    }

    /// Stop on an emergency (other than an error reset) from `node`.
    pub fn on_emergency(&mut self, node: u8, frame: &Frame) {
        if let Some((from, emergency)) = crate::device::Emergency::parse(frame) {
            if from == node && emergency.code != 0 {
                self.stop(StopReason::Emergency(emergency.code));
            }
        }
    }
}

/// What the controller wants of the drive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Setpoint {
    /// Profile or cyclic velocity, units/s.
    Velocity(i32),
    /// Profile or cyclic position, units.
    Position(i32),
}

/// The master side of one CiA 402 drive, speaking the PDO layout of [`drive_dictionary`]:
/// it reads the statusword from TPDO1, sends the controlword and mode on RPDO1 and the
/// targets on RPDO2 every cycle. Fail closed: until the drive reports Operation enabled and
/// nothing has stopped it, targets are zero; after a stop, the drive is held in Quick stop
/// (or disabled) with zero targets until [`DriveController::acknowledge`].
#[derive(Debug, Clone)]
pub struct DriveController {
    node: u8,
    mode: Mode,
    setpoint: Setpoint,
    enable: bool,
    stopped: StopLatch,
    statusword: Option<u16>,
    last_status: Option<Timestamp>,
    status_timeout: Duration,
    position_actual: i32,
    velocity_actual: i32,
    fault_reset_phase: bool,
    set_point_toggle: bool,
}

impl DriveController {
    /// A controller for the drive at `node` in `mode`; a statusword older than `status_timeout`
    /// stops the drive.
    pub fn new(node: u8, mode: Mode, status_timeout: Duration) -> DriveController {
        DriveController {
            node,
            mode,
            setpoint: match mode {
                Mode::ProfileVelocity | Mode::CyclicSynchronousVelocity => Setpoint::Velocity(0),
                Mode::ProfilePosition | Mode::CyclicSynchronousPosition => Setpoint::Position(0),
            },
            enable: false,
            stopped: StopLatch::default(),
            statusword: None,
            last_status: None,
            status_timeout,
            position_actual: 0,
            velocity_actual: 0,
            fault_reset_phase: false,
            set_point_toggle: false,
        }
    }

    /// The drive's node.
    pub fn node(&self) -> u8 {
        self.node
    }

    /// Ask for Operation enabled (or, `false`, for the power stage off).
    pub fn set_enabled(&mut self, enable: bool) {
        self.enable = enable;
    }

    /// The target to follow once enabled.
    pub fn set_setpoint(&mut self, setpoint: Setpoint) {
        self.setpoint = setpoint;
    }

    /// Stop the drive now (quick stop) and hold it until acknowledged.
    pub fn stop(&mut self, reason: StopReason) {
        self.stopped.stop(reason);
    }

    /// Why the drive is held stopped, if it is.
    pub fn stopped(&self) -> Option<StopReason> {
        self.stopped.reason()
    }

    /// Release a stop: the drive may be walked back to Operation enabled (faults are reset).
    pub fn acknowledge(&mut self) {
        self.stopped.acknowledge();
    }

    /// The drive state its last statusword reported.
    pub fn drive_state(&self) -> Option<State> {
        self.statusword.and_then(State::from_statusword)
    }

    /// Last reported actual position and velocity.
    pub fn actual(&self) -> (i32, i32) {
        (self.position_actual, self.velocity_actual)
    }

    /// Take in a frame: the drive's TPDOs and emergencies.
    pub fn on_frame(&mut self, now: Timestamp, frame: &Frame) {
        let node = u16::from(self.node);
        match (cob_id(frame), frame.data()) {
            (Some(id), [lo, hi, ..]) if id == 0x180 + node && !frame.is_remote() => {
                let statusword = u16::from_le_bytes([*lo, *hi]);
                self.statusword = Some(statusword);
                self.last_status = Some(now);
                if matches!(
                    State::from_statusword(statusword),
                    Some(State::Fault | State::FaultReactionActive)
                ) {
                    self.stop(StopReason::Fault);
                }
            }
            (Some(id), [a, b, c, d, e, f, g, h]) if id == 0x280 + node => {
                self.position_actual = i32::from_le_bytes([*a, *b, *c, *d]);
                self.velocity_actual = i32::from_le_bytes([*e, *f, *g, *h]);
            }
            _ => self.stopped.on_emergency(self.node, frame),
        }
    }

    /// The drive's heartbeat was lost.
    pub fn on_heartbeat_lost(&mut self) {
        self.stop(StopReason::HeartbeatLost);
    }

    /// The controlword to send now.
    fn controlword(&mut self) -> u16 {
        let state = self.drive_state();
        if self.stopped.reason().is_some() {
            return match state {
                Some(State::OperationEnabled | State::QuickStopActive) | None => {
                    controlword::QUICK_STOP
                }
                _ => controlword::DISABLE_VOLTAGE,
            };
        }
        if !self.enable {
            return match state {
                Some(State::OperationEnabled | State::SwitchedOn) => controlword::SHUTDOWN,
                _ => controlword::DISABLE_VOLTAGE,
            };
        }
        match state {
            None | Some(State::NotReadyToSwitchOn | State::FaultReactionActive) => {
                controlword::DISABLE_VOLTAGE
            }
            Some(State::SwitchOnDisabled) => controlword::SHUTDOWN,
            Some(State::ReadyToSwitchOn) => controlword::SWITCH_ON,
            Some(State::SwitchedOn) => controlword::ENABLE_OPERATION,
            Some(State::OperationEnabled) => {
                let mut word = controlword::ENABLE_OPERATION;
                if self.mode == Mode::ProfilePosition {
                    // A new set-point on every other cycle, applied at once.
                    self.set_point_toggle = !self.set_point_toggle;
                    if self.set_point_toggle {
                        word |= controlword::NEW_SET_POINT | controlword::CHANGE_IMMEDIATELY;
                    }
                }
                word
            }
            Some(State::QuickStopActive) => controlword::DISABLE_VOLTAGE,
            Some(State::Fault) => {
                // Fault reset is an edge: alternate 0x0000 and 0x0080.
                self.fault_reset_phase = !self.fault_reset_phase;
                if self.fault_reset_phase {
                    controlword::FAULT_RESET
                } else {
                    controlword::DISABLE_VOLTAGE
                }
            }
        }
    }

    /// One control cycle: check the statusword's age, then send RPDO1 and RPDO2.
    pub fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        if self.enable
            && self
                .last_status
                .is_some_and(|last| now >= last.saturating_add(self.status_timeout))
        {
            self.stop(StopReason::StatusTimeout);
        }
        let word = self.controlword();
        let running =
            self.stopped.reason().is_none() && self.drive_state() == Some(State::OperationEnabled);
        let (position, velocity) = match (running, self.setpoint) {
            (true, Setpoint::Velocity(v)) => (self.position_actual, v),
            (true, Setpoint::Position(p)) => (p, 0),
            // Fail closed: hold where it is, zero speed.
            (false, _) => (self.position_actual, 0),
        };
        let node = u16::from(self.node);
        let [c0, c1] = word.to_le_bytes();
        out(classic(
            0x200 + node,
            &[c0, c1, self.mode.code().to_le_bytes()[0]],
        ));
        let [p0, p1, p2, p3] = position.to_le_bytes();
        let [v0, v1, v2, v3] = velocity.to_le_bytes();
        out(classic(0x300 + node, &[p0, p1, p2, p3, v0, v1, v2, v3]));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL_STATES: [State; 8] = [
        State::NotReadyToSwitchOn,
        State::SwitchOnDisabled,
        State::ReadyToSwitchOn,
        State::SwitchedOn,
        State::OperationEnabled,
        State::QuickStopActive,
        State::FaultReactionActive,
        State::Fault,
    ];

    #[test]
    fn statuswords_name_their_states() {
        for state in ALL_STATES {
            assert_eq!(State::from_statusword(state.statusword_bits()), Some(state));
            // Other bits (voltage enabled, remote, target reached) do not change the state.
            assert_eq!(
                State::from_statusword(state.statusword_bits() | 0x0610),
                Some(state)
            );
        }
    }

    #[test]
    fn controlword_commands_follow_table_28() {
        assert_eq!(Command::decode(0x0006, 0), Command::Shutdown);
        assert_eq!(Command::decode(0x0007, 0), Command::SwitchOn);
        assert_eq!(Command::decode(0x000F, 0), Command::EnableOperation);
        assert_eq!(Command::decode(0x0000, 0), Command::DisableVoltage);
        assert_eq!(Command::decode(0x0002, 0), Command::QuickStop);
        assert_eq!(Command::decode(0x0080, 0), Command::FaultReset);
        assert_eq!(Command::decode(0x0080, 0x0080), Command::None);
    }

    #[test]
    fn the_transitions_of_figure_12() {
        use Command as C;
        let walk = [
            (
                State::NotReadyToSwitchOn,
                Event::Initialised,
                State::SwitchOnDisabled,
            ),
            (
                State::SwitchOnDisabled,
                Event::Command(C::Shutdown),
                State::ReadyToSwitchOn,
            ),
            (
                State::ReadyToSwitchOn,
                Event::Command(C::SwitchOn),
                State::SwitchedOn,
            ),
            (
                State::SwitchedOn,
                Event::Command(C::EnableOperation),
                State::OperationEnabled,
            ),
            (
                State::OperationEnabled,
                Event::Command(C::SwitchOn),
                State::SwitchedOn,
            ),
            (
                State::SwitchedOn,
                Event::Command(C::Shutdown),
                State::ReadyToSwitchOn,
            ),
            (
                State::ReadyToSwitchOn,
                Event::Command(C::DisableVoltage),
                State::SwitchOnDisabled,
            ),
            (
                State::OperationEnabled,
                Event::Command(C::Shutdown),
                State::ReadyToSwitchOn,
            ),
            (
                State::OperationEnabled,
                Event::Command(C::DisableVoltage),
                State::SwitchOnDisabled,
            ),
            (
                State::SwitchedOn,
                Event::Command(C::QuickStop),
                State::SwitchOnDisabled,
            ),
            (
                State::OperationEnabled,
                Event::Command(C::QuickStop),
                State::QuickStopActive,
            ),
            (
                State::QuickStopActive,
                Event::QuickStopDone { leave: true },
                State::SwitchOnDisabled,
            ),
            (
                State::QuickStopActive,
                Event::QuickStopDone { leave: false },
                State::QuickStopActive,
            ),
            (
                State::OperationEnabled,
                Event::Fault,
                State::FaultReactionActive,
            ),
            (
                State::FaultReactionActive,
                Event::FaultReactionDone,
                State::Fault,
            ),
            (
                State::Fault,
                Event::Command(C::FaultReset),
                State::SwitchOnDisabled,
            ),
            (
                State::QuickStopActive,
                Event::Command(C::EnableOperation),
                State::OperationEnabled,
            ),
            (
                State::Fault,
                Event::Command(C::EnableOperation),
                State::Fault,
            ),
            (
                State::SwitchOnDisabled,
                Event::Command(C::EnableOperation),
                State::SwitchOnDisabled,
            ),
        ];
        for (from, event, to) in walk {
            assert_eq!(transition(from, event), to, "{from:?} + {event:?}");
        }
        // A fault is reached from every state.
        for state in ALL_STATES {
            let after = transition(state, Event::Fault);
            assert!(
                matches!(after, State::FaultReactionActive | State::Fault),
                "{state:?}"
            );
        }
    }
}
