//! [`ProfileWire`]: any vehicle a profile describes, spoken by role through the runtime DBC
//! codec (needs `std`: profiles and their DBC are loaded from files).

use alloc::vec::Vec;
use core::time::Duration;

use bywire_core::node::Port;
use bywire_core::{FileError, Frame, Id};
use bywire_dbc::codec::{Decoded, MessageCodec, Value};
use bywire_dbc::e2e::{ChecksumAlgorithm, Protection};
use bywire_dbc::Message;

use crate::arbitration::{DuplexWire, Role, Side};
use crate::bindings::{CommandBindings, ReportBindings, StateBindings, WheelBindings};
use crate::command::{ControlCommand, ControlMode, Gear, SteeringMode, TurnIndicators, Vocabulary};
use crate::command::{EstopCode, WatchdogLevel};
use crate::profile::{LoadedProfile, ProfileError};
use crate::wire::{
    AdsWire, Counters, DegradationReport, Feedback, Incoming, Rejected, StateFeedback, StateReport,
    VehicleWire,
};

/// One message spoken by role: its codec, protection, and the signal index of each role.
#[derive(Debug, Clone)]
struct RoleMessage {
    id: u32,
    extended: bool,
    codec: MessageCodec,
    protection: Protection,
    /// Declared physical range per signal (`None` where min = max, i.e. undeclared).
    ranges: Vec<Option<(f64, f64)>>,
    /// Encode/decode scratch, sized at start.
    values: Vec<Option<Value>>,
    decoded: Vec<Option<Decoded>>,
    counter_bits: u8,
    /// Whether a wrong checksum refuses the frame (only a campaign's proof turns it off).
    checksum_checked: bool,
}

impl RoleMessage {
    /// `message`, its counter and checksum at these places (found when the profile loaded).
    fn new(
        message: &Message,
        counter: Option<usize>,
        checksum: Option<usize>,
        algorithm: ChecksumAlgorithm,
        key: &str,
        invalid: &dyn Fn(&str, String) -> ProfileError,
    ) -> Result<RoleMessage, ProfileError> {
        let counter = match counter {
            None => None,
            Some(index) => {
                let (name, bits) = message
                    .signals
                    .get(index)
                    .map_or(("?", 0), |s| (s.name.as_str(), s.length));
                if !(1..=8).contains(&bits) {
                    return Err(invalid(
                        key,
                        format!("counter '{name}' is {bits} bits; 1 to 8 are supported"),
                    ));
                }
                Some((index, bits))
            }
        };
        let declared = Protection::of(message);
        let checksum = match checksum {
            Some(index) => {
                // An algorithm the DBC declares on the signal wins over the profile's.
                let algorithm = declared
                    .and_then(|p| p.checksum)
                    .filter(|(i, _)| *i == index)
                    .and_then(|(_, a)| a)
                    .unwrap_or(algorithm);
                Some((index, Some(algorithm)))
            }
            None => None,
        };
        let protection = Protection {
            counter,
            checksum,
            data_id: declared.and_then(|p| p.data_id),
        };
        let codec = MessageCodec::new(message);
        let ranges = message
            .signals
            .iter()
            .map(|s| {
                let (min, max) = (s.minimum.as_f64(), s.maximum.as_f64());
                (max > min).then_some((min, max))
            })
            .collect();
        Ok(RoleMessage {
            id: message.raw_id(),
            extended: message.raw_id() > 0x7FF,
            values: vec![None; codec.signal_count()],
            decoded: vec![None; codec.signal_count()],
            checksum_checked: true,
            codec,
            protection,
            ranges,
            counter_bits: counter.map_or(0, |(_, bits)| u8::try_from(bits).unwrap_or(8)),
        })
    }

    /// `message` with the counter and checksum its DBC declares (or opendbc's naming
    /// implies).
    fn declared(
        message: &Message,
        algorithm: ChecksumAlgorithm,
        key: &str,
        invalid: &dyn Fn(&str, String) -> ProfileError,
    ) -> Result<RoleMessage, ProfileError> {
        let protection = Protection::of(message);
        let counter = protection.and_then(|p| p.counter).map(|(i, _)| i);
        let checksum = protection.and_then(|p| p.checksum).map(|(i, _)| i);
        RoleMessage::new(message, counter, checksum, algorithm, key, invalid)
    }

    /// Check a frame of this message: its counter (0 without one), or why not (a remote frame
    /// has no data, so it is short: malformed).
    fn check(&mut self, frame: &Frame) -> Result<u64, Rejected> {
        let counter = match self.protection.verify(&self.codec, frame.data()) {
            Ok(counter) => counter.unwrap_or(0),
            Err(bywire_dbc::e2e::ProtectionError::Checksum { .. }) if !self.checksum_checked => {
                let index = self.protection.counter.map(|(index, _)| index);
                index
                    .and_then(|i| self.codec.read_raw(i, frame.data()))
                    .unwrap_or(0)
            }
            Err(bywire_dbc::e2e::ProtectionError::Checksum { .. }) => {
                return Err(Rejected::Checksum)
            }
            Err(_) => return Err(Rejected::Malformed),
        };
        self.codec
            .decode(frame.data(), &mut self.decoded)
            .map_err(|_| Rejected::Malformed)?;
        Ok(counter)
    }

    /// A frame on this message's identifier (a remote frame too: `check` refuses it).
    fn is(&self, frame: &Frame) -> bool {
        frame.id().is_some_and(|id| self.has_id(id))
    }

    fn has_id(&self, id: Id) -> bool {
        id.as_raw() == self.id && id.is_extended() == self.extended
    }

    /// Encode the values set in `self.values`, then counter and checksum.
    fn frame(&mut self, counter: u64) -> Option<Frame> {
        let mut payload = [0u8; 64];
        let size = self.codec.encode(&self.values, &mut payload).ok()?;
        self.protection
            .fill(&self.codec, counter, &mut payload)
            .ok()?;
        let id = if self.extended {
            Id::extended(self.id).ok()?
        } else {
            Id::standard(self.id).ok()?
        };
        let data = payload.get(..size)?;
        if size <= 8 {
            Frame::classic(id, data).ok()
        } else {
            Frame::fd(id, data, false, false).ok()
        }
    }

    /// Set a role's value exactly, or refuse it (`false`): a value beyond the signal's
    /// declared range (or not a number) would reach the vehicle as another.
    fn set_exact(&mut self, index: usize, value: f64) -> bool {
        let within = match self.ranges.get(index).copied().flatten() {
            Some((min, max)) => (min..=max).contains(&value),
            None => value.is_finite(),
        };
        if within {
            self.store(index, value);
        }
        within
    }

    /// Set a role's value, clamped to the signal's declared range (a report of the vehicle's
    /// own state; an emergency brake beyond the signal's range, which is a request for the
    /// hardest braking it carries).
    fn set_clamped(&mut self, index: usize, value: f64) {
        let value = match self.ranges.get(index).copied().flatten() {
            Some((min, max)) => value.clamp(min, max),
            None => value,
        };
        self.store(index, value);
    }

    fn store(&mut self, index: usize, value: f64) {
        if let Some(slot) = self.values.get_mut(index) {
            *slot = Some(Value::Float(value));
        }
    }

    fn set_raw(&mut self, index: usize, raw: u64) {
        if let Some(slot) = self.values.get_mut(index) {
            *slot = Some(Value::UInt(raw));
        }
    }

    /// Check and decode a frame of this message: its counter, or `None` if corrupt.
    fn read(&mut self, frame: &Frame) -> Option<u64> {
        self.check(frame).ok()
    }

    fn physical(&self, index: usize) -> Option<f64> {
        self.decoded
            .get(index)
            .copied()
            .flatten()
            .map(|d| d.physical.as_f64())
    }

    fn raw(&self, index: usize) -> Option<u64> {
        self.decoded.get(index).copied().flatten().map(|d| d.raw)
    }

    fn in_range(&self, index: usize) -> bool {
        match (
            self.physical(index),
            self.ranges.get(index).copied().flatten(),
        ) {
            (Some(value), Some((min, max))) => value >= min && value <= max,
            (Some(value), None) => value.is_finite(),
            (None, _) => false,
        }
    }
}

/// One vocabulary enum's raw numbers on this vehicle, resolved once from the profile's
/// `[enums.ROLE]` table (the reference numbering where the profile has none).
#[derive(Debug, Clone)]
struct EnumMap<T: 'static>(Vec<(T, u64)>);

impl<T: Vocabulary> EnumMap<T> {
    fn new(profile: &LoadedProfile, role: &str) -> Result<EnumMap<T>, ProfileError> {
        let invalid = |key: String, reason: &str| {
            ProfileError::from(FileError::invalid(&profile.profile.name, key, reason))
        };
        let Some(table) = profile.profile.enums.get(role) else {
            return Ok(EnumMap(T::ALL.iter().map(|v| (*v, v.raw())).collect()));
        };
        if let Some(name) = table.keys().find(|name| T::from_name(name).is_none()) {
            let names: Vec<&str> = T::ALL.iter().map(|v| v.name()).collect();
            return Err(invalid(
                format!("enums.{role}.{name}"),
                &format!("not a name of this table: {}", names.join(", ")),
            ));
        }
        let mut map = Vec::with_capacity(T::ALL.len());
        for value in T::ALL {
            let raw = table.get(value.name()).ok_or_else(|| {
                invalid(
                    format!("enums.{role}.{}", value.name()),
                    "missing: every value needs its raw number",
                )
            })?;
            map.push((*value, *raw));
        }
        Ok(EnumMap(map))
    }

    fn raw(&self, value: T) -> u64 {
        self.0
            .iter()
            .find(|(v, _)| *v == value)
            .map_or(0, |(_, raw)| *raw)
    }

    fn value(&self, raw: u64) -> Option<T> {
        self.0.iter().find(|(_, r)| *r == raw).map(|(v, _)| *v)
    }
}

/// Any vehicle a profile describes, by role, through the runtime codec. Buffers are sized
/// when it is made: no allocation per frame.
#[derive(Debug, Clone)]
pub struct ProfileWire {
    command: RoleMessage,
    command_signals: CommandBindings,
    state: RoleMessage,
    state_signals: StateBindings,
    wheel_speeds: Option<(RoleMessage, [usize; 4])>,
    wheel_angles: Option<(RoleMessage, [usize; 4])>,
    brake: Option<(RoleMessage, usize, usize)>,
    estop: Option<(RoleMessage, usize)>,
    degradation: Option<(RoleMessage, ReportBindings)>,
    gears: EnumMap<Gear>,
    modes: EnumMap<ControlMode>,
    steering_modes: EnumMap<SteeringMode>,
    turn_indicators: EnumMap<TurnIndicators>,
}

impl ProfileWire {
    /// The wire of a loaded profile; it needs `[command]` and `[state]`. A profile that
    /// declares `[secoc]` is refused: its wire needs its key
    /// (`LoadedProfile::secured_wire`, feature `secoc`), never the messages unauthenticated.
    pub fn new(loaded: &LoadedProfile) -> Result<ProfileWire, ProfileError> {
        if loaded.profile.secoc.is_some() {
            return Err(FileError::invalid(
                &loaded.profile.name,
                "secoc",
                "the profile secures its messages: give it its key file",
            )
            .into());
        }
        Self::unsecured(loaded)
    }

    /// The wire without the profile's SecOC, for [`crate::secured::Secured`] to wrap.
    pub(crate) fn unsecured(loaded: &LoadedProfile) -> Result<ProfileWire, ProfileError> {
        let (p, db, b) = (&loaded.profile, &loaded.database, &loaded.bindings);
        let invalid = |key: &str, reason: String| {
            ProfileError::from(FileError::invalid(&p.name, key, reason))
        };
        let (Some(c), Some(command_signals)) = (&p.command, b.command) else {
            return Err(invalid(
                "command",
                "a vehicle interface needs [command]".to_string(),
            ));
        };
        let (Some(_), Some(state_signals)) = (&p.state, b.state) else {
            return Err(invalid(
                "state",
                "a vehicle interface needs [state]".to_string(),
            ));
        };
        let algorithm = c.algorithm().ok_or_else(|| {
            invalid(
                "command.checksum_algorithm",
                format!("'{}' is not a checksum algorithm", c.checksum_algorithm),
            )
        })?;
        // The places were found in this database when the profile loaded.
        let message = |index: usize, key: &str| {
            db.messages
                .get(index)
                .ok_or_else(|| invalid(key, "not in the DBC".to_string()))
        };
        let command = RoleMessage::new(
            message(command_signals.message, "command.message")?,
            Some(command_signals.counter),
            Some(command_signals.checksum),
            algorithm,
            "command",
            &invalid,
        )?;
        let state = RoleMessage::new(
            message(state_signals.message, "state.message")?,
            Some(state_signals.counter),
            Some(state_signals.checksum),
            algorithm,
            "state",
            &invalid,
        )?;
        let declared = |index: usize, key: &str| {
            RoleMessage::declared(message(index, key)?, algorithm, key, &invalid)
        };
        let wheels = |role: &str, w: Option<WheelBindings>| {
            w.map(|w| {
                let role = declared(w.message, &format!("{role}.message"))?;
                Ok::<_, ProfileError>((role, w.signals))
            })
            .transpose()
        };
        let wheel_speeds = wheels("wheel_speeds", b.wheel_speeds)?;
        let wheel_angles = wheels("wheel_angles", b.wheel_angles)?;
        let brake = b
            .emergency_brake
            .map(|e| {
                let role = declared(e.message, "emergency_brake.message")?;
                Ok::<_, ProfileError>((role, e.request, e.deceleration))
            })
            .transpose()?;
        let estop = b
            .estop
            .map(|e| Ok::<_, ProfileError>((declared(e.message, "estop.message")?, e.request)))
            .transpose()?;
        let degradation = b
            .fail_operational
            .as_ref()
            .and_then(|f| f.report)
            .map(|r| {
                let role = declared(r.message, "fail_operational.report.message")?;
                Ok::<_, ProfileError>((role, r))
            })
            .transpose()?;
        Ok(ProfileWire {
            estop,
            degradation,
            command,
            command_signals,
            state,
            state_signals,
            wheel_speeds,
            wheel_angles,
            brake,
            gears: EnumMap::new(loaded, "gear")?,
            modes: EnumMap::new(loaded, "control_mode")?,
            steering_modes: EnumMap::new(loaded, "steering_mode")?,
            turn_indicators: EnumMap::new(loaded, "turn_indicators")?,
        })
    }
}

impl Counters for ProfileWire {
    fn command_counter_bits(&self) -> u8 {
        self.command.counter_bits
    }

    fn state_counter_bits(&self) -> u8 {
        self.state.counter_bits
    }
}

impl AdsWire for ProfileWire {
    fn wheel_counter_bits(&self) -> u8 {
        self.wheel_speeds
            .as_ref()
            .map_or(self.state.counter_bits, |(m, _)| m.counter_bits)
    }

    fn command_frame(&mut self, c: &ControlCommand, counter: u64) -> Option<Frame> {
        let s = self.command_signals;
        let raws = [
            (s.gear, self.gears.raw(c.gear)),
            (s.control_mode, self.modes.raw(c.mode)),
            (s.steering_mode, self.steering_modes.raw(c.steering_mode)),
            (s.engage, u64::from(c.engage)),
            (s.operator_reset, u64::from(c.operator_reset)),
        ];
        let m = &mut self.command;
        // A setpoint the signal cannot carry is not sent as another: no frame (the vehicle's
        // watchdog counts a missed cycle).
        let carried = m.set_exact(s.steering, c.steering)
            & m.set_exact(s.velocity, c.velocity)
            & m.set_exact(s.brake, c.brake);
        if !carried {
            return None;
        }
        for (index, raw) in raws {
            m.set_raw(index, raw);
        }
        let lights = [
            (
                s.turn_indicators,
                self.turn_indicators.raw(c.turn_indicators),
            ),
            (s.hazard_lights, u64::from(c.hazard_lights)),
        ];
        for (index, raw) in lights {
            if let Some(index) = index {
                m.set_raw(index, raw);
            }
        }
        m.frame(counter)
    }

    fn emergency_brake_frame(&mut self, deceleration: f64, counter: u64) -> Option<Frame> {
        let (m, request, decel) = self.brake.as_mut()?;
        m.set_raw(*request, 1);
        m.set_clamped(*decel, deceleration);
        m.frame(counter)
    }

    fn feedback(&mut self, frame: &Frame) -> Feedback {
        if self.state.is(frame) {
            let Some(counter) = self.state.read(frame) else {
                return Feedback::Corrupt;
            };
            let s = self.state_signals;
            let m = &self.state;
            // A level or latch state that names nothing is out of range, not unreported.
            let level = s.watchdog_level.and_then(|i| m.raw(i));
            let estop = s.estop_state.and_then(|i| m.raw(i));
            let known = level.is_none_or(|raw| WatchdogLevel::from_raw(raw).is_some())
                && estop.is_none_or(|raw| EstopCode::from_raw(raw).is_some());
            let level = level.and_then(WatchdogLevel::from_raw);
            let estop = estop.and_then(EstopCode::from_raw);
            // A value the profile does not name: the ADS is not in control.
            let mode = m
                .raw(s.control_mode)
                .and_then(|raw| self.modes.value(raw))
                .unwrap_or(ControlMode::Manual);
            return Feedback::State(StateFeedback {
                counter,
                steering: m.physical(s.steering).unwrap_or(f64::NAN),
                velocity: m.physical(s.velocity).unwrap_or(f64::NAN),
                mode,
                watchdog_level: level,
                estop_state: estop,
                warning: s.warning.and_then(|i| m.raw(i)).map(|raw| raw == 1),
                driver_override: s.driver_override.and_then(|i| m.raw(i)).map(|raw| raw == 1),
                gear: s
                    .gear
                    .and_then(|i| m.raw(i))
                    .and_then(|raw| self.gears.value(raw)),
                steering_mode: m
                    .raw(s.steering_mode)
                    .and_then(|raw| self.steering_modes.value(raw)),
                turn_indicators: s
                    .turn_indicators
                    .and_then(|i| m.raw(i))
                    .and_then(|raw| self.turn_indicators.value(raw)),
                hazard_lights: s.hazard_lights.and_then(|i| m.raw(i)).map(|raw| raw == 1),
                heartbeat_echo: m.raw(s.heartbeat_echo).unwrap_or(u64::MAX),
                in_range: [Some(s.steering), Some(s.velocity), s.watchdog_level]
                    .into_iter()
                    .flatten()
                    .all(|i| m.in_range(i))
                    && known,
            });
        }
        if let Some((m, indices)) = self.wheel_speeds.as_mut() {
            if m.is(frame) {
                let Some(counter) = m.read(frame) else {
                    return Feedback::Corrupt;
                };
                let speeds = indices.map(|i| m.physical(i).unwrap_or(f64::NAN));
                return Feedback::WheelSpeeds { counter, speeds };
            }
        }
        if let Some((m, indices)) = self.wheel_angles.as_mut() {
            if m.is(frame) {
                let Some(counter) = m.read(frame) else {
                    return Feedback::Corrupt;
                };
                let angles = indices.map(|i| m.physical(i).unwrap_or(f64::NAN));
                return Feedback::WheelAngles { counter, angles };
            }
        }
        if let Some((m, b)) = self.degradation.as_mut() {
            if m.is(frame) {
                // A level or reason that names nothing is a report not to be read.
                let report = m.read(frame).and_then(|_| {
                    let reason = match b.reason {
                        Some(i) => m.raw(i)?,
                        None => 0,
                    };
                    DegradationReport::from_raw(m.raw(b.level)?, reason)
                });
                return report.map_or(Feedback::Corrupt, Feedback::Degradation);
            }
        }
        Feedback::Other
    }
}

impl ProfileWire {
    /// The E-stop frame, as the vehicle's safety controller sends it (`pressed`: the chain is
    /// open), where the profile has an `[estop]` message.
    pub fn estop_frame(&mut self, pressed: bool, counter: u64) -> Option<Frame> {
        let (m, request) = self.estop.as_mut()?;
        m.set_raw(*request, u64::from(pressed));
        m.frame(counter)
    }

    /// Whether the profile has an `[estop]` message.
    pub fn has_estop(&self) -> bool {
        self.estop.is_some()
    }

    /// The command a checked command frame carries; `None` if a value names nothing.
    fn decoded_command(&self) -> Option<ControlCommand> {
        let s = self.command_signals;
        let m = &self.command;
        // Raw value → the variant (no allocation).
        fn named<T: Vocabulary>(m: &RoleMessage, index: usize, map: &EnumMap<T>) -> Option<T> {
            m.raw(index).and_then(|raw| map.value(raw))
        }
        // Lights a command message does not carry stay off.
        let turn_indicators = match s.turn_indicators {
            Some(index) => named(m, index, &self.turn_indicators)?,
            None => TurnIndicators::Off,
        };
        let hazard_lights = match s.hazard_lights {
            Some(index) => m.raw(index)? == 1,
            None => false,
        };
        Some(ControlCommand {
            steering: m.physical(s.steering)?,
            velocity: m.physical(s.velocity)?,
            brake: m.physical(s.brake)?,
            gear: named(m, s.gear, &self.gears)?,
            mode: named(m, s.control_mode, &self.modes)?,
            steering_mode: named(m, s.steering_mode, &self.steering_modes)?,
            engage: m.raw(s.engage)? == 1,
            operator_reset: m.raw(s.operator_reset)? == 1,
            turn_indicators,
            hazard_lights,
        })
    }
}

impl VehicleWire for ProfileWire {
    fn is_command(&self, id: Id) -> bool {
        self.command.has_id(id)
    }

    fn switch_off(&mut self, off: crate::mechanism::Mechanisms) {
        self.command.checksum_checked = !off.contains(crate::mechanism::Mechanism::E2e);
    }

    fn incoming(&mut self, frame: &Frame) -> Incoming {
        if self.command.is(frame) {
            return Incoming::Command(
                self.command
                    .check(frame)
                    .map(|counter| (self.decoded_command(), counter)),
            );
        }
        if let Some((m, request)) = self.estop.as_mut() {
            if m.is(frame) {
                return match m.check(frame) {
                    Ok(_) => Incoming::Estop(m.raw(*request) == Some(1)),
                    Err(_) => Incoming::Other,
                };
            }
        }
        if let Some((m, request, _)) = self.brake.as_mut() {
            if m.is(frame) {
                return match m.check(frame) {
                    Ok(_) => Incoming::EmergencyBrake(m.raw(*request) == Some(1)),
                    Err(_) => Incoming::Other,
                };
            }
        }
        Incoming::Other
    }

    fn state_frame(&mut self, r: &StateReport, counter: u64) -> Option<Frame> {
        let s = self.state_signals;
        let raws = [
            (Some(s.control_mode), self.modes.raw(r.mode)),
            (
                Some(s.steering_mode),
                self.steering_modes.raw(r.steering_mode),
            ),
            (s.gear, self.gears.raw(r.gear)),
            (Some(s.heartbeat_echo), r.heartbeat_echo),
            (s.watchdog_level, r.watchdog_level.raw()),
            (s.estop_state, r.estop_state.raw()),
            (s.warning, u64::from(r.warning)),
            (s.driver_override, u64::from(r.driver_override)),
            (s.steering_enabled, u64::from(r.steering_enabled)),
            (
                s.turn_indicators,
                self.turn_indicators.raw(r.turn_indicators),
            ),
            (s.hazard_lights, u64::from(r.hazard_lights)),
        ];
        let m = &mut self.state;
        m.set_clamped(s.steering, r.steering);
        m.set_clamped(s.velocity, r.velocity);
        for (index, raw) in raws {
            if let Some(index) = index {
                m.set_raw(index, raw);
            }
        }
        m.frame(counter)
    }

    fn wheel_speeds_frame(&mut self, speeds: [f64; 4], counter: u64) -> Option<Frame> {
        let (m, indices) = self.wheel_speeds.as_mut()?;
        for (index, speed) in indices.iter().zip(speeds) {
            m.set_clamped(*index, speed);
        }
        m.frame(counter)
    }

    fn wheel_angles_frame(&mut self, angles: [f64; 4], counter: u64) -> Option<Frame> {
        let (m, indices) = self.wheel_angles.as_mut()?;
        for (index, angle) in indices.iter().zip(angles) {
            m.set_clamped(*index, angle);
        }
        m.frame(counter)
    }

    fn degradation_frame(&mut self, report: &DegradationReport, counter: u64) -> Option<Frame> {
        let (m, b) = self.degradation.as_mut()?;
        m.set_raw(b.level, report.level.raw());
        if let Some(reason) = b.reason {
            m.set_raw(reason, report.reason_raw());
        }
        m.frame(counter)
    }
}

/// The two halves' status messages of a duplicated control ECU, as a profile's
/// `[fail_operational.control]` names them: the halves' [`DuplexWire`] for any vehicle.
/// The halves compute in step, so an output of the one in control agrees with the standby's
/// when its bytes are the same.
#[derive(Debug, Clone)]
pub struct ProfileDuplexWire {
    /// A's and B's status messages and their role signals.
    status: [(RoleMessage, usize); 2],
    period: Duration,
}

impl ProfileDuplexWire {
    /// The status messages of `loaded`'s control ECUs (`None`: it declares none).
    pub fn new(loaded: &LoadedProfile) -> Result<Option<ProfileDuplexWire>, ProfileError> {
        let (Some(roles), Some(bindings)) = (
            loaded
                .profile
                .fail_operational
                .as_ref()
                .and_then(|f| f.control.as_ref()),
            loaded
                .bindings
                .fail_operational
                .as_ref()
                .and_then(|f| f.control),
        ) else {
            return Ok(None);
        };
        let invalid = |key: &str, reason: String| {
            ProfileError::from(FileError::invalid(&loaded.profile.name, key, reason))
        };
        let [a, b] = bindings;
        // A checksum the DBC declares without its algorithm takes the command's (checked
        // when the profile loaded), or CRC-8 SAE J1850 on a profile without one.
        let algorithm = loaded
            .profile
            .command
            .as_ref()
            .and_then(crate::profile::CommandRoles::algorithm)
            .unwrap_or(ChecksumAlgorithm::Crc8SaeJ1850);
        let half = |binding: crate::bindings::StatusBinding, key: &str| {
            let message = loaded
                .database
                .messages
                .get(binding.message)
                .ok_or_else(|| invalid(key, "not in the DBC".to_string()))?;
            let role = RoleMessage::declared(message, algorithm, key, &invalid)?;
            Ok::<_, ProfileError>((role, binding.signal.unwrap_or(0)))
        };
        Ok(Some(ProfileDuplexWire {
            status: [
                half(a, "fail_operational.control.a")?,
                half(b, "fail_operational.control.b")?,
            ],
            period: Duration::from_millis(roles.status_period_ms.max(1)),
        }))
    }

    fn of(&mut self, side: Side) -> &mut (RoleMessage, usize) {
        let [a, b] = &mut self.status;
        match side {
            Side::A => a,
            Side::B => b,
        }
    }
}

impl DuplexWire for ProfileDuplexWire {
    fn status_port(&self) -> Port {
        crate::redundancy::Channel::A.port()
    }

    fn status_period(&self) -> Duration {
        self.period
    }

    fn status_frame(&mut self, side: Side, role: Role, counter: u8) -> Option<Frame> {
        let (message, signal) = self.of(side);
        message.set_raw(*signal, u64::from(role.raw()));
        message.frame(u64::from(counter))
    }

    fn partner_status(&mut self, side: Side, frame: &Frame) -> Option<Role> {
        let (message, signal) = self.of(side.other());
        if !message.is(frame) {
            return None;
        }
        message.read(frame)?;
        message.raw(*signal).map(Role::from_raw)
    }

    fn agree(&self, _port: Port, mine: &Frame, theirs: &Frame) -> Option<bool> {
        Some(mine.data() == theirs.data())
    }
}
