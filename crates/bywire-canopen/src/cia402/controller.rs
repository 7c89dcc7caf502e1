//! The master side: a [`DriveController`] that walks a drive to Operation enabled, commands
//! it, and stops it safely (heartbeat loss, EMCY, fault) until acknowledged.

use super::{controlword, Mode, State};
use core::time::Duration;

use bywire_core::frame::Frame;
use bywire_core::time::Timestamp;

use crate::nmt::{classic, cob_id};

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

    /// Stop on an emergency from `node`, other than an error reset and the CAN
    /// communication warnings (0x81xx: overrun, error passive, recovered from bus-off): the
    /// communication they report is watched by the heartbeat consumer, which stops the drive
    /// if it is really lost, and a drive that lost its master faults on its own.
    pub fn on_emergency(&mut self, node: u8, frame: &Frame) {
        if let Some((from, emergency)) = crate::emcy::Emergency::parse(frame) {
            let communication_warning = emergency.code & 0xFF00 == 0x8100;
            if from == node && emergency.code != 0 && !communication_warning {
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

/// A target of zero of the kind `mode` follows.
fn zero_setpoint(mode: Mode) -> Setpoint {
    match mode {
        Mode::ProfileVelocity | Mode::CyclicSynchronousVelocity => Setpoint::Velocity(0),
        Mode::ProfilePosition | Mode::CyclicSynchronousPosition => Setpoint::Position(0),
    }
}

/// The master side of one CiA 402 drive, speaking the PDO layout of [`drive_dictionary`](super::drive_dictionary):
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
    /// When its process data (either TPDO) last came.
    last_heard: Option<Timestamp>,
    status_timeout: Duration,
    position_actual: i32,
    velocity_actual: i32,
    fault_reset_phase: bool,
    /// Acknowledged while the drive reports Fault: since when (its first poll after) its
    /// fault is being reset. A Fault statusword stops the drive again only once the reset has
    /// had the status timeout to take.
    resetting: Option<Option<Timestamp>>,
    set_point_toggle: bool,
}

impl DriveController {
    /// A controller for the drive at `node` in `mode`; a statusword older than `status_timeout`
    /// stops the drive.
    pub fn new(node: u8, mode: Mode, status_timeout: Duration) -> DriveController {
        DriveController {
            node,
            mode,
            setpoint: zero_setpoint(mode),
            enable: false,
            stopped: StopLatch::default(),
            statusword: None,
            last_status: None,
            last_heard: None,
            status_timeout,
            position_actual: 0,
            velocity_actual: 0,
            fault_reset_phase: false,
            resetting: None,
            set_point_toggle: false,
        }
    }

    /// The drive's node.
    pub fn node(&self) -> u8 {
        self.node
    }

    /// Switch the mode of operation (sent with the controlword from the next cycle); the
    /// target becomes zero of the new mode's kind until the next set-point.
    pub fn set_mode(&mut self, mode: Mode) {
        if mode != self.mode {
            self.mode = mode;
            self.setpoint = zero_setpoint(mode);
        }
    }

    /// The mode of operation commanded.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Ask for Operation enabled (or, `false`, for the power stage off).
    pub fn set_enabled(&mut self, enable: bool) {
        self.enable = enable;
    }

    /// The target to follow once enabled.
    pub fn set_setpoint(&mut self, setpoint: Setpoint) {
        self.setpoint = setpoint;
    }

    /// The target it follows once enabled.
    pub fn setpoint(&self) -> Setpoint {
        self.setpoint
    }

    /// Stop the drive now (quick stop) and hold it until acknowledged.
    pub fn stop(&mut self, reason: StopReason) {
        self.stopped.stop(reason);
    }

    /// Why the drive is held stopped, if it is.
    pub fn stopped(&self) -> Option<StopReason> {
        self.stopped.reason()
    }

    /// Release a stop: the drive may be walked back to Operation enabled (faults are reset;
    /// the statuswords that still report the fault meanwhile do not stop it again, for up to
    /// the status timeout).
    pub fn acknowledge(&mut self) {
        self.stopped.acknowledge();
        let faulted = matches!(
            self.drive_state(),
            Some(State::Fault | State::FaultReactionActive)
        );
        self.resetting = faulted.then_some(None);
    }

    /// The drive state its last statusword reported.
    pub fn drive_state(&self) -> Option<State> {
        self.statusword.and_then(State::from_statusword)
    }

    /// Last reported actual position and velocity.
    pub fn actual(&self) -> (i32, i32) {
        (self.position_actual, self.velocity_actual)
    }

    /// When the drive's process data last came (`None`: never): a liveness finer than its
    /// heartbeat when its actual values come at every SYNC.
    pub fn last_heard(&self) -> Option<Timestamp> {
        self.last_heard
    }

    /// Take in a frame: the drive's TPDOs and emergencies.
    pub fn on_frame(&mut self, now: Timestamp, frame: &Frame) {
        let node = u16::from(self.node);
        match (cob_id(frame), frame.data()) {
            (Some(id), [lo, hi, ..]) if id == 0x180 + node && !frame.is_remote() => {
                let statusword = u16::from_le_bytes([*lo, *hi]);
                self.statusword = Some(statusword);
                self.last_status = Some(now);
                self.last_heard = Some(now);
                if matches!(
                    State::from_statusword(statusword),
                    Some(State::Fault | State::FaultReactionActive)
                ) {
                    let reset_takes = match self.resetting {
                        Some(Some(since)) => now < since.saturating_add(self.status_timeout),
                        Some(None) => true,
                        None => false,
                    };
                    if !reset_takes {
                        self.resetting = None;
                        self.stop(StopReason::Fault);
                    }
                } else if self.resetting.is_some() {
                    self.resetting = None;
                }
            }
            (Some(id), [a, b, c, d, e, f, g, h]) if id == 0x280 + node => {
                self.position_actual = i32::from_le_bytes([*a, *b, *c, *d]);
                self.velocity_actual = i32::from_le_bytes([*e, *f, *g, *h]);
                self.last_heard = Some(now);
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
        if self.resetting == Some(None) {
            self.resetting = Some(Some(now));
        }
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
        out(classic(RPDO2 + node, &[p0, p1, p2, p3, v0, v1, v2, v3]));
    }
}

/// RPDO2's base identifier: a controller's targets go on `RPDO2 + node`.
const RPDO2: u16 = 0x300;

/// The targets a [`DriveController`] sent in `frame`: its node, target position and target
/// velocity (`None`: not a controller's RPDO2).
pub fn rpdo2_targets(frame: &Frame) -> Option<(u8, i32, i32)> {
    let node = cob_id(frame)?
        .checked_sub(RPDO2)
        .filter(|n| (1..=127).contains(n))?;
    let data: [u8; 8] = frame.data().try_into().ok()?;
    let [p0, p1, p2, p3, v0, v1, v2, v3] = data;
    Some((
        u8::try_from(node).ok()?,
        i32::from_le_bytes([p0, p1, p2, p3]),
        i32::from_le_bytes([v0, v1, v2, v3]),
    ))
}
