//! Roboteq motor controllers over CANopen: the controller's own objects (0x2000 motor
//! command, 0x2002 set velocity, the 0x21xx read-backs), RPDO1 mapped to the motor command as
//! Roboteq ships it, an [`Mdc1460`]-like device with a motor model and command watchdog for
//! the simulator, and the master-side [`RoboteqMotor`] the vehicle ECU uses.
//!
//! Like the real controller, the device has two faces: Roboteq's own objects, and the CiA 402
//! drive profile for channel 1 (device type 0x00020192; controlword 0x6040, statusword 0x6041,
//! modes 0x6060/0x6061, target position 0x607A, profile velocity 0x6081, target velocity
//! 0x60FF, position and velocity actual 0x6064/0x606C, in encoder counts and RPM). While the
//! CiA 402 state machine has the power stage on (Operation enabled, a quick stop or a fault
//! reaction), channel 1 follows it; otherwise Roboteq's commands drive it.
//!
//! Roboteq's manual: RPDO1 on `0x200 + node` carries a signed 32-bit motor command in
//! -1000..=1000 (‰ of full power), little-endian two's complement — `0x201: BC 02 00 00` is
//! 700 (70 %) for node 1. Remapped to 0x2002 the same four bytes are a speed in RPM
//! (`B0 04 00 00` = 1200 RPM).

use alloc::vec;
use core::time::Duration;

use bywire_core::frame::Frame;
use bywire_core::time::Timestamp;

use crate::abort::Abort;
use crate::cia402::{
    self, add_drive_objects, add_pdo, communication_objects, round, Drive, Motor, PdoDefault,
    StopLatch, StopReason,
};
use crate::device::{error_register, Application, EmcyProducer};
use crate::nmt::{classic, cob_id};
use crate::od::{Access, DataType, Entry, Number, ObjectDictionary, ObjectKind};
use crate::pdo::COB_ID_INVALID;
use crate::sdo::{QueueFull, SdoClient, TransferMode};

/// Roboteq object indices.
pub mod object {
    /// Set motor command (S32 per channel, -1000..=1000).
    pub const MOTOR_COMMAND: u16 = 0x2000;
    /// Set position (S32 per channel).
    pub const SET_POSITION: u16 = 0x2001;
    /// Set velocity (S32 per channel, RPM).
    pub const SET_VELOCITY: u16 = 0x2002;
    /// Emergency shutdown (U8).
    pub const EMERGENCY_SHUTDOWN: u16 = 0x200C;
    /// Release shutdown (U8).
    pub const RELEASE_SHUTDOWN: u16 = 0x200D;
    /// Stop in all modes (U8).
    pub const STOP_ALL: u16 = 0x200E;
    /// Motor amps (S16 per channel, 0.1 A).
    pub const MOTOR_AMPS: u16 = 0x2100;
    /// Actual motor command (S16 per channel).
    pub const ACTUAL_COMMAND: u16 = 0x2101;
    /// Applied power level (S16 per channel, ‰).
    pub const POWER_LEVEL: u16 = 0x2102;
    /// Encoder motor speed (S32 per channel, RPM).
    pub const ENCODER_SPEED: u16 = 0x2103;
    /// Absolute encoder count (S32 per channel).
    pub const ENCODER_COUNT: u16 = 0x2104;
    /// Internal voltages (U16: 1 internal, 2 battery in 0.1 V, 3 5 V output in mV).
    pub const VOLTAGES: u16 = 0x210D;
    /// Temperatures (S8: 1 MCU, 2-3 power stage, °C).
    pub const TEMPERATURES: u16 = 0x210F;
    /// Status flags (U16).
    pub const STATUS_FLAGS: u16 = 0x2111;
    /// Fault flags (U16).
    pub const FAULT_FLAGS: u16 = 0x2112;
}

/// Fault flag: emergency stop (Roboteq's FF bit 5).
pub const FAULT_EMERGENCY_STOP: u16 = 0x0010;
/// Status flag: power stage off.
pub const STATUS_POWER_OFF: u16 = 0x0008;
/// EMCY code the device sends on an emergency shutdown (manufacturer specific).
pub const EMCY_SHUTDOWN: u16 = 0xFF10;

/// The four bytes of a motor command (or a velocity) as RPDO1 carries them.
pub fn command_payload(value: i32) -> [u8; 4] {
    value.to_le_bytes()
}

/// Read a motor command payload back.
pub fn parse_command(payload: &[u8]) -> Option<i32> {
    Some(i32::from_le_bytes(payload.get(..4)?.try_into().ok()?))
}

/// A Roboteq controller's dictionary for `node` with `channels` motors (1 or 2).
pub fn dictionary(node: u8, channels: u8) -> ObjectDictionary {
    use object::*;
    let channels = channels.clamp(1, 2);
    let mut od = ObjectDictionary::new();
    communication_objects(
        &mut od,
        node,
        cia402::DEVICE_TYPE,
        "MDC1460",
        [0x0000_0358, 0x1460, 2, u32::from(node)],
    );
    add_drive_objects(&mut od, cia402::Mode::SUPPORTED);
    let per_channel = |od: &mut ObjectDictionary,
                       index: u16,
                       name: &str,
                       data_type: DataType,
                       access: Access,
                       limits: Option<(i64, i64)>| {
        let entries = (1..=channels)
            .map(|sub| {
                let entry = Entry::new(sub, &alloc::format!("{name}, ch{sub}"), data_type, access)
                    .mappable();
                match limits {
                    Some((low, high)) => {
                        entry.with_limits(Some(Number::Int(low)), Some(Number::Int(high)))
                    }
                    None => entry,
                }
            })
            .collect();
        od.add_object(index, name, ObjectKind::Array, entries);
    };
    per_channel(
        &mut od,
        MOTOR_COMMAND,
        "Set Motor Command",
        DataType::I32,
        Access::WriteOnly,
        Some((-1000, 1000)),
    );
    per_channel(
        &mut od,
        SET_POSITION,
        "Set Position",
        DataType::I32,
        Access::WriteOnly,
        None,
    );
    per_channel(
        &mut od,
        SET_VELOCITY,
        "Set Velocity",
        DataType::I32,
        Access::WriteOnly,
        Some((-65_535, 65_535)),
    );
    od.add_var(
        EMERGENCY_SHUTDOWN,
        Entry::new(0, "Emergency Shutdown", DataType::U8, Access::WriteOnly).mappable(),
    );
    od.add_var(
        RELEASE_SHUTDOWN,
        Entry::new(0, "Release Shutdown", DataType::U8, Access::WriteOnly).mappable(),
    );
    od.add_var(
        STOP_ALL,
        Entry::new(0, "Stop in all modes", DataType::U8, Access::WriteOnly).mappable(),
    );
    per_channel(
        &mut od,
        MOTOR_AMPS,
        "Read Motor Amps",
        DataType::I16,
        Access::ReadOnly,
        None,
    );
    per_channel(
        &mut od,
        ACTUAL_COMMAND,
        "Read Actual Motor Command",
        DataType::I16,
        Access::ReadOnly,
        None,
    );
    per_channel(
        &mut od,
        POWER_LEVEL,
        "Read Applied Power Level",
        DataType::I16,
        Access::ReadOnly,
        None,
    );
    per_channel(
        &mut od,
        ENCODER_SPEED,
        "Read Encoder Motor Speed",
        DataType::I32,
        Access::ReadOnly,
        None,
    );
    per_channel(
        &mut od,
        ENCODER_COUNT,
        "Read Absolute Encoder Count",
        DataType::I32,
        Access::ReadOnly,
        None,
    );
    od.add_object(
        VOLTAGES,
        "Read Internal Voltages",
        ObjectKind::Array,
        vec![
            Entry::new(1, "Internal volts", DataType::U16, Access::ReadOnly)
                .mappable()
                .with_int(120),
            Entry::new(2, "Battery volts", DataType::U16, Access::ReadOnly)
                .mappable()
                .with_int(480),
            Entry::new(3, "5V output", DataType::U16, Access::ReadOnly)
                .mappable()
                .with_int(5_000),
        ],
    );
    od.add_object(
        TEMPERATURES,
        "Read Temperature",
        ObjectKind::Array,
        (1..=3)
            .map(|sub| {
                Entry::new(sub, "Temperature", DataType::I8, Access::ReadOnly)
                    .mappable()
                    .with_int(30)
            })
            .collect(),
    );
    od.add_var(
        STATUS_FLAGS,
        Entry::new(0, "Read Status Flags", DataType::U16, Access::ReadOnly).mappable(),
    );
    od.add_var(
        FAULT_FLAGS,
        Entry::new(0, "Read Fault Flags", DataType::U16, Access::ReadOnly).mappable(),
    );
    let id = u32::from(node);
    add_pdo(
        &mut od,
        false,
        &PdoDefault {
            number: 1,
            cob_id: 0x200 + id,
            transmission: 255,
            inhibit: 0,
            event_timer: 0,
            mapping: &[(MOTOR_COMMAND, 1, 32)],
        },
    );
    let second = if channels > 1 {
        0x300 + id
    } else {
        COB_ID_INVALID | (0x300 + id)
    };
    add_pdo(
        &mut od,
        false,
        &PdoDefault {
            number: 2,
            cob_id: second,
            transmission: 255,
            inhibit: 0,
            event_timer: 0,
            mapping: &[(MOTOR_COMMAND, channels, 32)],
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
            mapping: &[
                (ACTUAL_COMMAND, 1, 16),
                (MOTOR_AMPS, 1, 16),
                (STATUS_FLAGS, 0, 16),
                (FAULT_FLAGS, 0, 16),
            ],
        },
    );
    add_pdo(
        &mut od,
        true,
        &PdoDefault {
            number: 2,
            cob_id: 0x280 + id,
            transmission: 255,
            inhibit: 0,
            event_timer: 100,
            mapping: &[(ENCODER_SPEED, 1, 32), (ENCODER_COUNT, 1, 32)],
        },
    );
    od
}

/// One motor channel of the simulated controller.
#[derive(Debug, Clone, Copy, Default)]
struct Channel {
    /// -1000..=1000 power command (open loop) — or, when `speed` is set, ignored.
    command: i32,
    /// Closed-loop speed target, RPM.
    speed: Option<i32>,
    /// Speed in RPM, position in encoder counts.
    motor: Motor,
}

/// A simulated Roboteq MDC1460 (dual channel, 60 V/ 2×60 A): motor commands from RPDO or
/// SDO, a first-order motor per channel, a command watchdog (Roboteq's RWD, 1 s by default),
/// emergency shutdown and release.
#[derive(Debug, Clone)]
pub struct Mdc1460 {
    channels: [Channel; 2],
    /// The CiA 402 face of channel 1 (its motor is the channel's).
    drive: Drive,
    last_command: Option<Timestamp>,
    last_step: Option<Timestamp>,
    shutdown: bool,
    /// No command for this long stops the motors (zero: never).
    pub watchdog: Duration,
    /// Speed at full power, RPM.
    pub max_rpm: f64,
    /// Motor time constant, s.
    pub time_constant: f64,
    /// Encoder counts per revolution.
    pub counts_per_revolution: f64,
}

impl Default for Mdc1460 {
    fn default() -> Self {
        Mdc1460 {
            channels: [Channel::default(); 2],
            drive: Drive::new().with_external_motor(),
            last_command: None,
            last_step: None,
            shutdown: false,
            watchdog: Duration::from_millis(1_000),
            max_rpm: 3_000.0,
            time_constant: 0.15,
            counts_per_revolution: 4_096.0,
        }
    }
}

impl Mdc1460 {
    /// The speed of channel 1 or 2, RPM.
    pub fn speed(&self, channel: u8) -> f64 {
        self.channels
            .get(usize::from(channel.saturating_sub(1)))
            .map_or(0.0, |c| c.motor.velocity)
    }

    /// The power command a channel follows now (-1000..=1000).
    pub fn command(&self, channel: u8) -> i32 {
        self.channels
            .get(usize::from(channel.saturating_sub(1)))
            .map_or(0, |c| c.command)
    }

    /// The CiA 402 face of channel 1.
    pub fn drive(&self) -> &Drive {
        &self.drive
    }

    /// The controller is in emergency shutdown.
    pub fn is_shut_down(&self) -> bool {
        self.shutdown
    }

    fn stop_all(&mut self) {
        for channel in &mut self.channels {
            channel.command = 0;
            channel.speed = channel.speed.map(|_| 0);
        }
    }
}

/// Whether an object belongs to the CiA 402 face.
fn is_drive_object(index: u16) -> bool {
    (0x6000..=0x6FFF).contains(&index)
}

impl Application for Mdc1460 {
    fn check_write(
        &self,
        od: &ObjectDictionary,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<(), Abort> {
        if is_drive_object(index) {
            return self.drive.check_write(od, index, sub, data);
        }
        if self.shutdown
            && matches!(
                index,
                object::MOTOR_COMMAND | object::SET_VELOCITY | object::SET_POSITION
            )
        {
            // Roboteq ignores motor commands until the shutdown is released.
            return Err(Abort::DeviceState);
        }
        Ok(())
    }

    fn on_written(&mut self, now: Timestamp, od: &mut ObjectDictionary, index: u16, sub: u8) {
        if is_drive_object(index) {
            self.drive.on_written(now, od, index, sub);
            return;
        }
        let channel = self.channels.get_mut(usize::from(sub.saturating_sub(1)));
        match (index, channel) {
            (object::MOTOR_COMMAND, Some(channel)) if !self.shutdown => {
                channel.command =
                    i32::try_from(od.get_signed(index, sub).unwrap_or(0)).unwrap_or(0);
                channel.speed = None;
                self.last_command = Some(now);
            }
            (object::SET_VELOCITY, Some(channel)) if !self.shutdown => {
                channel.speed =
                    Some(i32::try_from(od.get_signed(index, sub).unwrap_or(0)).unwrap_or(0));
                self.last_command = Some(now);
            }
            (object::EMERGENCY_SHUTDOWN, _) => {
                self.shutdown = true;
                self.stop_all();
            }
            (object::RELEASE_SHUTDOWN, _) => self.shutdown = false,
            (object::STOP_ALL, _) => self.stop_all(),
            _ => {}
        }
    }

    fn on_nmt(
        &mut self,
        now: Timestamp,
        state: crate::nmt::NmtState,
        od: &mut ObjectDictionary,
        emcy: &mut EmcyProducer,
    ) {
        self.drive.on_nmt(now, state, od, emcy);
    }

    fn on_communication_lost(
        &mut self,
        now: Timestamp,
        od: &mut ObjectDictionary,
        emcy: &mut EmcyProducer,
    ) {
        self.stop_all();
        self.drive.on_communication_lost(now, od, emcy);
    }

    fn step(&mut self, now: Timestamp, od: &mut ObjectDictionary, emcy: &mut EmcyProducer) {
        let dt = self
            .last_step
            .map_or(0.0, |last| now.saturating_since(last).as_secs_f64())
            .min(0.1);
        self.last_step = Some(now);
        if !self.watchdog.is_zero()
            && self
                .last_command
                .is_some_and(|last| now >= last.saturating_add(self.watchdog))
        {
            self.stop_all();
            self.last_command = None;
        }
        if self.shutdown {
            emcy.raise(od, EMCY_SHUTDOWN, error_register::MANUFACTURER, [0; 5]);
        } else {
            emcy.clear(od, EMCY_SHUTDOWN);
        }
        let (max_rpm, tau, cpr) = (
            self.max_rpm,
            self.time_constant.max(1e-3),
            self.counts_per_revolution,
        );
        // The CiA 402 face sees channel 1 in encoder counts and RPM, and asks a speed of it.
        self.drive.max_velocity = max_rpm;
        self.drive.set_velocity_units(cpr / 60.0);
        let first = self.channels.first().map(|c| c.motor).unwrap_or_default();
        // (Its deadline is asked after this poll anyway.)
        let _ = self
            .drive
            .set_actual(first.position / 60.0 * cpr, first.velocity);
        self.drive.step(now, od, emcy);
        let drive_demand = self.drive.state().is_powered().then(|| self.drive.demand());
        for (channel, sub) in self.channels.iter_mut().zip(1u8..) {
            let target = match (sub, drive_demand, channel.speed) {
                (1, Some(demand), _) => demand.clamp(-max_rpm, max_rpm),
                (_, _, Some(rpm)) => f64::from(rpm).clamp(-max_rpm, max_rpm),
                (_, _, None) => f64::from(channel.command.clamp(-1000, 1000)) / 1000.0 * max_rpm,
            };
            let target = if self.shutdown { 0.0 } else { target };
            let before = channel.motor.velocity;
            // First order: the speed closes 1/tau of the gap per second — except under the
            // CiA 402 face, whose profile is already a ramp the speed loop tracks.
            let lag = if sub == 1 && drive_demand.is_some() {
                dt.max(1e-6)
            } else {
                tau
            };
            let rate = (target - before).abs() / lag;
            channel.motor.step_velocity(target, rate, dt);
            let power = if max_rpm > 0.0 {
                round(target / max_rpm * 1000.0)
            } else {
                0
            };
            let amps = round(
                (channel.motor.velocity - before).abs() / dt.max(1e-3) / max_rpm * 50.0
                    + power.unsigned_abs() as f64 / 1000.0 * 100.0,
            );
            let revolutions = channel.motor.position / 60.0;
            let _ = od.set_int(object::ACTUAL_COMMAND, sub, power);
            let _ = od.set_int(object::POWER_LEVEL, sub, power);
            let _ = od.set_int(object::MOTOR_AMPS, sub, amps.min(i64::from(i16::MAX)));
            let _ = od.set_int(object::ENCODER_SPEED, sub, round(channel.motor.velocity));
            let _ = od.set_int(object::ENCODER_COUNT, sub, round(revolutions * cpr));
        }
        let faults = if self.shutdown {
            FAULT_EMERGENCY_STOP
        } else {
            0
        };
        let status = if self.shutdown { STATUS_POWER_OFF } else { 0 };
        let _ = od.set(object::FAULT_FLAGS, 0, &faults.to_le_bytes());
        let _ = od.set(object::STATUS_FLAGS, 0, &status.to_le_bytes());
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        Some(self.last_step.map_or(Timestamp::ZERO, |t| {
            t.saturating_add(Duration::from_millis(10))
        }))
    }

    fn reset(&mut self, od: &mut ObjectDictionary) {
        self.drive.reset(od);
        *self = Mdc1460 {
            drive: self.drive.clone(),
            watchdog: self.watchdog,
            max_rpm: self.max_rpm,
            time_constant: self.time_constant,
            counts_per_revolution: self.counts_per_revolution,
            ..Mdc1460::default()
        };
    }
}

/// Queue the SDO writes that remap RPDO1 of `node` from the motor command (0x2000) to set
/// velocity (0x2002) of `channel`, following CiA 301: invalidate, clear, map, count, validate.
pub fn remap_rpdo1_to_velocity(
    sdo: &mut SdoClient,
    node: u8,
    channel: u8,
) -> Result<(), QueueFull> {
    let cob = 0x200 + u32::from(node);
    let entry = (u32::from(object::SET_VELOCITY) << 16) | (u32::from(channel) << 8) | 32;
    sdo.download(
        node,
        0x1400,
        1,
        &(cob | COB_ID_INVALID).to_le_bytes(),
        TransferMode::Auto,
    )?;
    sdo.download(node, 0x1600, 0, &[0], TransferMode::Auto)?;
    sdo.download(node, 0x1600, 1, &entry.to_le_bytes(), TransferMode::Auto)?;
    sdo.download(node, 0x1600, 0, &[1], TransferMode::Auto)?;
    sdo.download(node, 0x1400, 1, &cob.to_le_bytes(), TransferMode::Auto)?;
    Ok(())
}

/// What a [`RoboteqMotor`] commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RoboteqCommand {
    /// Power, -1000..=1000 (RPDO1 mapped to 0x2000).
    Power(i32),
    /// Speed in RPM (RPDO1 remapped to 0x2002).
    Velocity(i32),
}

/// The master side of a Roboteq channel: RPDO1 every cycle, zero until commanded and after
/// any stop (heartbeat loss, EMCY, a fault flag) until acknowledged.
#[derive(Debug, Clone)]
pub struct RoboteqMotor {
    node: u8,
    command: RoboteqCommand,
    stopped: StopLatch,
    fault_flags: u16,
    actual_command: i16,
    speed: i32,
}

impl RoboteqMotor {
    /// Command channel 1 of the controller at `node` (RPDO1).
    pub fn new(node: u8, command: RoboteqCommand) -> RoboteqMotor {
        let command = match command {
            RoboteqCommand::Power(_) => RoboteqCommand::Power(0),
            RoboteqCommand::Velocity(_) => RoboteqCommand::Velocity(0),
        };
        RoboteqMotor {
            node,
            command,
            stopped: StopLatch::default(),
            fault_flags: 0,
            actual_command: 0,
            speed: 0,
        }
    }

    /// Its node.
    pub fn node(&self) -> u8 {
        self.node
    }

    /// Set the command (power clamped to ±1000).
    pub fn set(&mut self, command: RoboteqCommand) {
        self.command = match command {
            RoboteqCommand::Power(p) => RoboteqCommand::Power(p.clamp(-1000, 1000)),
            velocity @ RoboteqCommand::Velocity(_) => velocity,
        };
    }

    /// Stop and hold until acknowledged.
    pub fn stop(&mut self, reason: StopReason) {
        self.stopped.stop(reason);
    }

    /// Why it is held stopped.
    pub fn stopped(&self) -> Option<StopReason> {
        self.stopped.reason()
    }

    /// Release a stop.
    pub fn acknowledge(&mut self) {
        self.stopped.acknowledge();
    }

    /// Last reported fault flags, actual command and encoder speed.
    pub fn feedback(&self) -> (u16, i16, i32) {
        (self.fault_flags, self.actual_command, self.speed)
    }

    /// The RPDO1 payload to send now.
    pub fn payload(&self) -> [u8; 4] {
        let value = match (self.stopped.reason(), self.command) {
            (Some(_), _) => 0,
            (None, RoboteqCommand::Power(p) | RoboteqCommand::Velocity(p)) => p,
        };
        command_payload(value)
    }

    /// Take in a frame: TPDO1/TPDO2 feedback and emergencies.
    pub fn on_frame(&mut self, _now: Timestamp, frame: &Frame) {
        let node = u16::from(self.node);
        match (cob_id(frame), frame.data()) {
            (Some(id), [a, b, _, _, _, _, f0, f1]) if id == 0x180 + node => {
                self.actual_command = i16::from_le_bytes([*a, *b]);
                self.fault_flags = u16::from_le_bytes([*f0, *f1]);
                if self.fault_flags != 0 {
                    self.stop(StopReason::Fault);
                }
            }
            (Some(id), [a, b, c, d, ..]) if id == 0x280 + node => {
                self.speed = i32::from_le_bytes([*a, *b, *c, *d])
            }
            _ => self.stopped.on_emergency(self.node, frame),
        }
    }

    /// Send RPDO1.
    pub fn poll(&mut self, _now: Timestamp, out: &mut dyn FnMut(Frame)) {
        out(classic(0x200 + u16::from(self.node), &self.payload()));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::Device;
    use bywire_core::node::{Node, Port};

    #[test]
    fn the_manuals_byte_examples() {
        // 700 = 70 % of full power on node 1's RPDO1.
        assert_eq!(command_payload(700), [0xBC, 0x02, 0x00, 0x00]);
        assert_eq!(parse_command(&[0xBC, 0x02, 0x00, 0x00]), Some(700));
        // Remapped to set velocity: 1200 RPM.
        assert_eq!(command_payload(1200), [0xB0, 0x04, 0x00, 0x00]);
        // Negatives are two's complement.
        assert_eq!(command_payload(-700), [0x44, 0xFD, 0xFF, 0xFF]);
        assert_eq!(parse_command(&[0x18, 0xFC, 0xFF, 0xFF]), Some(-1000));
        assert_eq!(parse_command(&[0x01, 0x02]), None);
        let motor = {
            let mut motor = RoboteqMotor::new(1, RoboteqCommand::Power(0));
            motor.set(RoboteqCommand::Power(700));
            motor
        };
        let mut sent = alloc::vec::Vec::new();
        motor.clone().poll(Timestamp::ZERO, &mut |f| sent.push(f));
        assert_eq!(cob_id(&sent[0]), Some(0x201));
        assert_eq!(sent[0].data(), [0xBC, 0x02, 0x00, 0x00]);
    }

    fn run(
        device: &mut Device<Mdc1460>,
        from_ms: u64,
        to_ms: u64,
        frames: &[(u64, Frame)],
    ) -> alloc::vec::Vec<Frame> {
        let mut sent = alloc::vec::Vec::new();
        for ms in from_ms..to_ms {
            let now = Timestamp::from_millis(ms);
            for (_, frame) in frames.iter().filter(|(at, _)| *at == ms) {
                device.on_frame(now, Port::MAIN, frame);
            }
            device.poll(now, &mut |port, f| {
                if port == Port::MAIN {
                    sent.push(f)
                }
            });
        }
        sent
    }

    #[test]
    fn rpdo1_drives_the_motor_and_the_watchdog_stops_it() {
        let mut device = Device::new(1, dictionary(1, 2), Mdc1460::default()).with_autostart();
        let command = classic(0x201, &[0xBC, 0x02, 0x00, 0x00]);
        let frames: alloc::vec::Vec<(u64, Frame)> = (0..10).map(|i| (i * 100, command)).collect();
        run(&mut device, 0, 1_000, &frames);
        assert_eq!(device.app().command(1), 700);
        let speed = device.app().speed(1);
        // Six time constants in: within 1 % of 70 % of 3000 RPM.
        assert!((speed - 2_100.0).abs() < 21.0, "got {speed}");
        assert_eq!(
            device.od().get_signed(object::ENCODER_SPEED, 1),
            Some(round(speed))
        );
        // No command for a second: the watchdog stops the motor.
        run(&mut device, 1_000, 1_899, &[]);
        assert_eq!(
            device.app().command(1),
            700,
            "the last command was at 900 ms"
        );
        run(&mut device, 1_899, 4_000, &[]);
        assert_eq!(device.app().command(1), 0);
        assert!(device.app().speed(1).abs() < 1.0);
    }

    /// An expedited SDO download to node 1.
    fn sdo_write(index: u16, sub: u8, data: &[u8]) -> Frame {
        let command = match data.len() {
            1 => 0x2F,
            2 => 0x2B,
            _ => 0x23,
        };
        let [lo, hi] = index.to_le_bytes();
        let mut payload = [command, lo, hi, sub, 0, 0, 0, 0];
        for (slot, byte) in payload.iter_mut().skip(4).zip(data) {
            *slot = *byte;
        }
        classic(0x601, &payload)
    }

    #[test]
    fn the_cia402_face_drives_channel_1_and_hands_back_to_roboteqs_commands() {
        let mut device = Device::new(1, dictionary(1, 2), Mdc1460::default()).with_autostart();
        assert_eq!(
            device.od().get_unsigned(0x1000, 0),
            Some(u64::from(cia402::DEVICE_TYPE))
        );
        // Profile velocity, Shutdown, Switch on, Enable operation, 1200 RPM.
        let frames = [
            (10, sdo_write(cia402::object::MODES, 0, &[3])),
            (
                20,
                sdo_write(cia402::object::CONTROLWORD, 0, &6u16.to_le_bytes()),
            ),
            (
                30,
                sdo_write(cia402::object::CONTROLWORD, 0, &7u16.to_le_bytes()),
            ),
            (
                40,
                sdo_write(cia402::object::CONTROLWORD, 0, &15u16.to_le_bytes()),
            ),
            (
                50,
                sdo_write(cia402::object::TARGET_VELOCITY, 0, &1200i32.to_le_bytes()),
            ),
        ];
        run(&mut device, 0, 2_000, &frames);
        assert_eq!(
            device.app().drive().state(),
            cia402::State::OperationEnabled
        );
        let statusword = device
            .od()
            .get_unsigned(cia402::object::STATUSWORD, 0)
            .unwrap();
        assert_eq!(
            statusword & 0x6F,
            0x27,
            "operation enabled: {statusword:#06x}"
        );
        let rpm = device
            .od()
            .get_signed(cia402::object::VELOCITY_ACTUAL, 0)
            .unwrap();
        assert!((rpm - 1200).abs() <= 12, "{rpm} RPM");
        assert_eq!(device.od().get_signed(object::ENCODER_SPEED, 1), Some(rpm));
        // The power stage off (Disable voltage): Roboteq's own command drives channel 1 again.
        let frames = [
            (
                2_000,
                sdo_write(cia402::object::CONTROLWORD, 0, &0u16.to_le_bytes()),
            ),
            (
                2_010,
                sdo_write(object::MOTOR_COMMAND, 1, &(-500i32).to_le_bytes()),
            ),
        ];
        run(&mut device, 2_000, 2_950, &frames);
        assert_eq!(
            device.app().drive().state(),
            cia402::State::SwitchOnDisabled
        );
        let speed = device.app().speed(1);
        assert!((speed + 1_500.0).abs() < 20.0, "{speed} RPM");
    }

    #[test]
    fn the_cia402_face_moves_to_a_target_position_in_encoder_counts() {
        let mut device = Device::new(1, dictionary(1, 1), Mdc1460::default()).with_autostart();
        let target: i32 = 10 * 4096; // ten revolutions
        let frames = [
            (10, sdo_write(cia402::object::MODES, 0, &[1])),
            (
                15,
                sdo_write(cia402::object::PROFILE_VELOCITY, 0, &1000u32.to_le_bytes()),
            ),
            (
                20,
                sdo_write(cia402::object::CONTROLWORD, 0, &6u16.to_le_bytes()),
            ),
            (
                30,
                sdo_write(cia402::object::CONTROLWORD, 0, &7u16.to_le_bytes()),
            ),
            (
                40,
                sdo_write(cia402::object::CONTROLWORD, 0, &15u16.to_le_bytes()),
            ),
            (
                50,
                sdo_write(cia402::object::TARGET_POSITION, 0, &target.to_le_bytes()),
            ),
            // New set-point (bit 4) starts the move.
            (
                60,
                sdo_write(cia402::object::CONTROLWORD, 0, &0x1Fu16.to_le_bytes()),
            ),
        ];
        // Ten revolutions at 1000 RPM take 0.6 s.
        run(&mut device, 0, 400, &frames);
        let moving = device
            .od()
            .get_signed(cia402::object::VELOCITY_ACTUAL, 0)
            .unwrap();
        assert!(
            (700..=1_010).contains(&moving),
            "on its way, within the profile velocity: {moving} RPM"
        );
        run(&mut device, 400, 3_000, &[]);
        let position = device
            .od()
            .get_signed(cia402::object::POSITION_ACTUAL, 0)
            .unwrap();
        assert!(
            (position - i64::from(target)).abs() <= 40,
            "at {position}, target {target}"
        );
        let statusword = device
            .od()
            .get_unsigned(cia402::object::STATUSWORD, 0)
            .unwrap();
        assert!(
            statusword & 0x0400 != 0,
            "target reached: {statusword:#06x}"
        );
        assert_eq!(
            device.od().get_signed(object::ENCODER_COUNT, 1),
            Some(position)
        );
    }
}
