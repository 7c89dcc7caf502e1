//! The drive: a [`crate::device::Application`] with a motor model (or an external plant)
//! that follows the state machine and the mode of operation.

use super::{controlword, object, transition, Command, Event, Mode, State};
use core::time::Duration;

use bywire_core::time::Timestamp;

use crate::abort::Abort;
use crate::device::{error_register, Application, EmcyProducer};
use crate::nmt::NmtState;
use crate::od::{ObjectDictionary, Slot};

/// A motor with limited acceleration: velocity in units/s, position in units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Motor {
    /// Position, units.
    pub position: f64,
    /// Velocity, units/s.
    pub velocity: f64,
}

impl Motor {
    /// Whether it turns (a velocity above rounding).
    fn turning(&self) -> bool {
        self.velocity.abs() >= f64::EPSILON
    }

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

    // Seldom (until the first read, and after a reset): out of line, so that the methods that
    // fall back on it, asked many times a step, stay small enough to inline.
    #[cold]
    #[inline(never)]
    fn read(od: &ObjectDictionary) -> Params {
        let mut params = Params {
            mode: None,
            acceleration: 1.0,
            deceleration: 1.0,
            quick: 1.0,
            profile_velocity: 0.0,
            target_velocity: 0.0,
        };
        for index in Params::INDICES {
            params.update(od, index);
        }
        params
    }

    /// Read the one parameter `index` holds again (nothing for other objects).
    fn update(&mut self, od: &ObjectDictionary, index: u16) {
        self.update_to(index, || od.get_signed(index, 0).unwrap_or(0));
    }

    /// The parameter `index` holds is now `value` (nothing for other objects).
    fn update_to(&mut self, index: u16, value: impl FnOnce() -> i64) {
        match index {
            object::MODES => self.mode = Mode::from_code(value()),
            object::PROFILE_ACCELERATION => self.acceleration = real(value()).max(1.0),
            object::PROFILE_DECELERATION => self.deceleration = real(value()).max(1.0),
            object::QUICK_STOP_DECELERATION => self.quick = real(value()).max(1.0),
            object::PROFILE_VELOCITY => self.profile_velocity = real(value()),
            object::TARGET_VELOCITY => self.target_velocity = real(value()),
            _ => {}
        }
    }
}

/// What a drive's published values are worked out from, floats as their bits.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PublishedFrom {
    state: State,
    mode: Option<Mode>,
    target_velocity: u64,
    position_target: u64,
    position: u64,
    velocity: u64,
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
    /// Where those four objects were last found in the dictionary (they are written every
    /// step a motor moves).
    published_at: [Option<Slot>; 4],
    /// What the published values were last worked out from: the same again gives the same
    /// values, and a drive publishes after every write of a setpoint, several times between
    /// two steps of its motor.
    published_from: Option<PublishedFrom>,
    /// Where the objects a master writes every cycle (controlword, mode, targets) were last
    /// found in the dictionary: each write is read back without a search.
    written_at: [Option<Slot>; 4],
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
pub(crate) const DEFAULT_QUICK_STOP_OPTION: i64 = 2;
/// Abort connection option 1 (CiA 402 default): fault.
pub(crate) const DEFAULT_ABORT_CONNECTION: i64 = 1;
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
            published_at: [None; 4],
            published_from: None,
            written_at: [None; 4],
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

    /// The plant's actual position (units) and velocity (units/s). Returns whether the drive's
    /// deadline may have moved: it asks for motor steps only while something moves, so a
    /// motor that starts or stops moving changes it (what a simulated runner's `feed` asks).
    pub fn set_actual(&mut self, position: f64, velocity: f64) -> bool {
        if !self.external {
            return false;
        }
        // The power stage is as it was: only the motor's turning can change `moving`.
        let was_turning = self.motor.turning();
        self.motor = Motor { position, velocity };
        self.motor.turning() != was_turning && !self.state.is_powered()
    }

    /// Whether it asks for motor steps: the motor turns or the power stage is on.
    fn moving(&self) -> bool {
        self.motor.turning() || self.state.is_powered()
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
        // Everything the values depend on (with the parameters cached: without them, the
        // dictionary too).
        let from = self.params.map(|params| PublishedFrom {
            state: self.state,
            mode: params.mode,
            target_velocity: params.target_velocity.to_bits(),
            position_target: self.position_target.to_bits(),
            position: self.motor.position.to_bits(),
            velocity: self.motor.velocity.to_bits(),
        });
        if from.is_some() && from == self.published_from {
            return;
        }
        self.published_from = from;
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
        let [at_status, at_display, at_position, at_velocity] = &mut self.published_at;
        if changed(|v| i64::from(v.0)) {
            if let Some(slot) = find(od, at_status, object::STATUSWORD) {
                let _ = od.set_at(slot, &statusword.to_le_bytes());
            }
        }
        if changed(|v| i64::from(v.1)) {
            if let Some(slot) = find(od, at_display, object::MODES_DISPLAY) {
                let _ = od.set_at(slot, &display.to_le_bytes());
            }
        }
        if changed(|v| v.2) {
            if let Some(slot) = find(od, at_position, object::POSITION_ACTUAL) {
                let _ = od.set_int_at(slot, values.2);
            }
        }
        if changed(|v| v.3) {
            if let Some(slot) = find(od, at_velocity, object::VELOCITY_ACTUAL) {
                let _ = od.set_int_at(slot, values.3);
            }
        }
    }

    /// The value of `index` (sub-index 0) as a signed integer, 0 if absent: the objects a
    /// master writes every cycle through their remembered slots, others by a search.
    fn written(&mut self, od: &ObjectDictionary, index: u16) -> i64 {
        const EVERY_CYCLE: [u16; 4] = [
            object::CONTROLWORD,
            object::MODES,
            object::TARGET_VELOCITY,
            object::TARGET_POSITION,
        ];
        let at = EVERY_CYCLE
            .iter()
            .position(|i| *i == index)
            .and_then(|k| self.written_at.get_mut(k));
        let value = match at {
            Some(at) => find(od, at, index).and_then(|slot| od.get_signed_at(slot)),
            None => od.get_signed(index, 0),
        };
        value.unwrap_or(0)
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

/// Where `index:0` is in `od`, from where it was last found (`at`, kept up to date).
fn find(od: &ObjectDictionary, at: &mut Option<Slot>, index: u16) -> Option<Slot> {
    let found = match *at {
        Some(hint) => od.relocate(hint, index, 0),
        None => od.locate(index, 0),
    };
    *at = found.ok();
    *at
}

/// Round to the nearest integer (saturating at the ends of `i64`, as `as` does for floats).
pub(crate) fn round(value: f64) -> i64 {
    bywire_core::num::round_to_i64(value)
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
        // A cached parameter is read again when its object is written (targets of velocity
        // and the mode arrive every cycle: one read each, not all six).
        match self.params {
            Some(_) if Params::INDICES.contains(&index) => {
                let value = self.written(od, index);
                if let Some(params) = self.params.as_mut() {
                    params.update_to(index, || value);
                }
            }
            None if Params::INDICES.contains(&index) => self.params = Some(Params::read(od)),
            _ => {}
        }
        match index {
            object::CONTROLWORD => {
                let controlword = u16::try_from(self.written(od, index)).unwrap_or(0);
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
                    self.position_target = real(self.written(od, object::TARGET_POSITION));
                }
            }
            object::TARGET_POSITION if self.mode(od) == Some(Mode::CyclicSynchronousPosition) => {
                self.position_target = real(self.written(od, object::TARGET_POSITION));
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
        self.moving().then(|| {
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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::cia402::drive_dictionary;
    use crate::device::Device;
    use crate::nmt::classic;
    use bywire_core::frame::Frame;
    use bywire_core::node::{Node, Port};

    fn statusword(device: &Device<Drive>) -> u16 {
        u16::try_from(device.od().get_unsigned(object::STATUSWORD, 0).unwrap()).unwrap()
    }

    fn targets(position: i32, velocity: i32) -> Frame {
        let mut data = [0u8; 8];
        data[..4].copy_from_slice(&position.to_le_bytes());
        data[4..].copy_from_slice(&velocity.to_le_bytes());
        classic(0x301, &data)
    }

    /// The plant's values move an unpowered drive's deadline only when its motor starts or
    /// stops turning (it asks for motor steps while anything moves), and say so.
    #[test]
    fn actual_values_say_when_they_move_the_deadline() {
        let mut drive = Drive::new().with_external_motor();
        assert_eq!(drive.next_deadline(), None);
        assert!(!drive.set_actual(10.0, 0.0), "still");
        assert!(drive.set_actual(10.0, 50.0), "starts turning");
        assert!(drive.next_deadline().is_some());
        assert!(!drive.set_actual(11.0, 60.0), "turning on");
        assert!(drive.set_actual(11.0, 0.0), "stops");
        assert_eq!(drive.next_deadline(), None);
        // Its own model's values are not the plant's: nothing to say.
        assert!(!Drive::new().set_actual(0.0, 100.0));
    }

    /// A new target written between two steps of the motor (nothing else changed) changes
    /// the published statusword at once: what the values are worked out from includes it.
    #[test]
    fn target_reached_follows_a_new_target_with_the_motor_unchanged() {
        let at = Timestamp::from_millis;
        let mut device = Device::new(1, drive_dictionary(1), Drive::new().with_external_motor());
        let mut sent = |_: Port, _: Frame| {};
        device.poll(at(0), &mut sent);
        device.on_frame(at(1), Port::MAIN, &classic(0x000, &[0x01, 1]));
        // Profile velocity, walked to Operation enabled.
        for controlword in [0x06u16, 0x07, 0x0F] {
            let [lo, hi] = controlword.to_le_bytes();
            device.on_frame(at(2), Port::MAIN, &classic(0x201, &[lo, hi, 3]));
            device.poll(at(2), &mut sent);
        }
        device.on_frame(at(3), Port::MAIN, &targets(0, 500));
        let _ = device.app_mut().0.set_actual(0.0, 500.0);
        device.poll(at(4), &mut sent);
        assert_eq!(device.app().state(), State::OperationEnabled);
        assert_ne!(statusword(&device) & 0x0400, 0, "at its target velocity");
        device.on_frame(at(4), Port::MAIN, &targets(0, 800));
        assert_eq!(statusword(&device) & 0x0400, 0, "a new target velocity");
        device.on_frame(at(4), Port::MAIN, &targets(0, 500));
        assert_ne!(
            statusword(&device) & 0x0400,
            0,
            "back to the one it runs at"
        );
        // Profile position, the motor still: a new set point is a target not yet reached.
        device.on_frame(at(5), Port::MAIN, &classic(0x201, &[0x0F, 0, 1]));
        device.on_frame(at(5), Port::MAIN, &targets(0, 0));
        let _ = device.app_mut().0.set_actual(0.0, 0.0);
        device.on_frame(at(5), Port::MAIN, &classic(0x201, &[0x1F, 0, 1]));
        device.poll(at(5), &mut sent);
        assert_ne!(statusword(&device) & 0x0400, 0, "at its set point");
        device.on_frame(at(6), Port::MAIN, &classic(0x201, &[0x0F, 0, 1]));
        device.on_frame(at(6), Port::MAIN, &targets(1_000, 0));
        device.on_frame(at(6), Port::MAIN, &classic(0x201, &[0x1F, 0, 1]));
        assert_eq!(statusword(&device) & 0x0400, 0, "a new set point");
    }
}
