//! CANopen drives on ROS 2, as ros2_canopen's CiA 402 driver offers them: the NMT master of a
//! bus description on the real-time runner, and per CiA 402 drive (under its name)
//!
//! - services (`std_srvs/Trigger`): `init` (NMT start, then switch on; answered once the drive
//!   reports Operation enabled), `enable`, `disable`, `halt` (quick stop, held), `recover`
//!   (acknowledge the stop, switch on; answered like `init`), `position_mode`,
//!   `velocity_mode`, `cyclic_position_mode`, `cyclic_velocity_mode`;
//! - `target`: the set-point in drive units, as a service (`canopen_interfaces/COTargetDouble`,
//!   as ros2_canopen) and as a topic (`std_msgs/Float64`);
//! - `joint_states` (`sensor_msgs/JointState`: position and velocity actual, drive units),
//!   `nmt_state` and `drive_state` (`std_msgs/String`).
//!
//! Heartbeat loss, an emergency, a fault or a silent statusword stop the drive as its
//! [`DriveController`] does, and the stop holds until `recover`.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use bywire_bus::runner::{Flow, Hooks, Runner};
use bywire_bus::{Bus, BusError};
use bywire_canopen::cia402::{DriveController, Mode, Setpoint, State, StopReason};
use bywire_canopen::config::{BusConfig, Driver};
use bywire_canopen::master::{Controlled, Master};
use bywire_canopen::nmt::{Liveness, NmtCommand, NmtState};
use bywire_core::node::Port;
use bywire_core::Timestamp;
use ros2_client::{Message, RmwRequestId};
use serde::{Deserialize, Serialize};

use crate::dds::{
    mio1, reliable, wake_on_readiness, Publisher, RosError, RosNode, Server, Subscription,
};
use crate::msg::{Float64, Header, JointState, StringMsg, Time};

/// How long `init` and `recover` wait for Operation enabled.
const SWITCH_ON_TIMEOUT: Duration = Duration::from_secs(3);
/// How long the drives are held in quick stop at the end of a run before it returns.
const FINAL_STOP: Duration = Duration::from_millis(200);
/// Requests taken from one service in one pass.
const TAKE_BATCH: usize = 16;

/// `std_srvs/srv/Trigger`'s request (ROS 2 gives an empty message one placeholder byte).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct TriggerRequest {
    /// Unused.
    pub structure_needs_at_least_one_member: u8,
}

/// `std_srvs/srv/Trigger`'s response.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct TriggerResponse {
    /// Done.
    pub success: bool,
    /// What happened.
    pub message: String,
}

/// `canopen_interfaces/srv/COTargetDouble`'s request.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct TargetRequest {
    /// The set-point, drive units.
    pub target: f64,
}

/// `canopen_interfaces/srv/COTargetDouble`'s response.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct TargetResponse {
    /// Taken.
    pub success: bool,
}

impl Message for TriggerRequest {}
impl Message for TriggerResponse {}
impl Message for TargetRequest {}
impl Message for TargetResponse {}

/// The Trigger services of a drive, in this order.
const TRIGGERS: [&str; 9] = [
    "init",
    "enable",
    "disable",
    "halt",
    "recover",
    "position_mode",
    "velocity_mode",
    "cyclic_position_mode",
    "cyclic_velocity_mode",
];

/// What the caller hears of.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CanopenEvent {
    /// A service was called and answered.
    Called {
        /// The drive.
        drive: String,
        /// The service.
        service: String,
        /// The answer.
        success: bool,
        /// Its message.
        message: String,
    },
    /// A drive stopped (heartbeat lost, emergency, fault, halt).
    Stopped {
        /// The drive.
        drive: String,
        /// Why.
        why: String,
    },
    /// A node of the bus description is not exposed (only CiA 402 drives are).
    NotExposed(String),
    /// The bus failed.
    BusLost(String),
}

struct DriveTopics {
    name: String,
    node: u8,
    triggers: Vec<Server<TriggerRequest, TriggerResponse>>,
    target_service: Server<TargetRequest, TargetResponse>,
    target_topic: Subscription<Float64>,
    joints: Publisher<JointState>,
    nmt_state: Publisher<StringMsg>,
    drive_state: Publisher<StringMsg>,
    /// A call waiting for Operation enabled: which service, its request, until when.
    waiting: Option<(usize, RmwRequestId, Timestamp)>,
    stopped: Option<StopReason>,
}

/// A drive's NMT state as ROS 2 tools name them.
fn nmt_name(liveness: Option<Liveness>) -> &'static str {
    match liveness {
        None | Some(Liveness::Unknown) => "unknown",
        Some(Liveness::Lost { .. }) => "lost",
        Some(Liveness::Alive { state, .. }) => match state {
            NmtState::BootUp => "boot-up",
            NmtState::Stopped => "stopped",
            NmtState::Operational => "operational",
            NmtState::PreOperational => "pre-operational",
        },
    }
}

fn drive_state_name(state: Option<State>) -> &'static str {
    match state {
        None => "unknown",
        Some(State::NotReadyToSwitchOn) => "not ready to switch on",
        Some(State::SwitchOnDisabled) => "switch on disabled",
        Some(State::ReadyToSwitchOn) => "ready to switch on",
        Some(State::SwitchedOn) => "switched on",
        Some(State::OperationEnabled) => "operation enabled",
        Some(State::QuickStopActive) => "quick stop active",
        Some(State::FaultReactionActive) => "fault reaction active",
        Some(State::Fault) => "fault",
    }
}

fn stop_text(reason: StopReason) -> String {
    match reason {
        StopReason::HeartbeatLost => "heartbeat lost".into(),
        StopReason::Emergency(code) => format!("emergency {code:#06X}"),
        StopReason::Fault => "the drive reported a fault".into(),
        StopReason::StatusTimeout => "the statusword stopped arriving".into(),
        StopReason::Commanded => "halted".into(),
    }
}

fn drive(master: &mut Master, node: u8) -> Option<&mut DriveController> {
    match master.controlled(node) {
        Some(Controlled::Drive(d)) => Some(d),
        _ => None,
    }
}

/// The bridge's side of the run.
struct Bridge<'a> {
    drives: Vec<DriveTopics>,
    report_period: Duration,
    next_report: Timestamp,
    stop: &'a AtomicBool,
    /// Set when `stop` was seen: the drives are halted and the run ends at this time.
    stopping_until: Option<Timestamp>,
    report: &'a mut dyn FnMut(CanopenEvent),
}

impl Bridge<'_> {
    fn answer(
        &mut self,
        i: usize,
        service: usize,
        id: RmwRequestId,
        success: bool,
        message: String,
    ) {
        let Some(d) = self.drives.get(i) else { return };
        if let Some(server) = d.triggers.get(service) {
            let _ = server.send_response(
                id,
                TriggerResponse {
                    success,
                    message: message.clone(),
                },
            );
        }
        (self.report)(CanopenEvent::Called {
            drive: d.name.clone(),
            service: TRIGGERS.get(service).copied().unwrap_or("?").to_string(),
            success,
            message,
        });
    }

    /// Carry out a Trigger call; `None` when it is answered later (init, recover).
    fn trigger(&mut self, master: &mut Master, i: usize, service: usize) -> Option<(bool, String)> {
        let node = self.drives.get(i)?.node;
        let mode =
            |m: Mode| -> Option<(bool, String)> { Some((true, format!("mode {}", m.code()))) };
        let d = drive(master, node)?;
        match TRIGGERS.get(service).copied()? {
            "init" | "recover" => {
                d.acknowledge();
                d.set_enabled(true);
                master.nmt(NmtCommand::Start, node);
                None
            }
            "enable" => {
                d.set_enabled(true);
                Some((true, "enabling".into()))
            }
            "disable" => {
                d.set_enabled(false);
                Some((true, "disabled".into()))
            }
            "halt" => {
                d.stop(StopReason::Commanded);
                Some((true, "quick stop; `recover` releases it".into()))
            }
            "position_mode" => {
                d.set_mode(Mode::ProfilePosition);
                mode(Mode::ProfilePosition)
            }
            "velocity_mode" => {
                d.set_mode(Mode::ProfileVelocity);
                mode(Mode::ProfileVelocity)
            }
            "cyclic_position_mode" => {
                d.set_mode(Mode::CyclicSynchronousPosition);
                mode(Mode::CyclicSynchronousPosition)
            }
            "cyclic_velocity_mode" => {
                d.set_mode(Mode::CyclicSynchronousVelocity);
                mode(Mode::CyclicSynchronousVelocity)
            }
            _ => Some((false, "unknown service".into())),
        }
    }

    /// The set-point for `target` in the drive's mode (whole drive units, refused beyond i32).
    fn set_target(master: &mut Master, node: u8, target: f64) -> bool {
        let Some(d) = drive(master, node) else {
            return false;
        };
        if !target.is_finite() || target.abs() > f64::from(i32::MAX) {
            return false;
        }
        // Within i32 (checked above): the cast is exact after rounding.
        #[allow(clippy::cast_possible_truncation)]
        let units = libm::round(target) as i32;
        d.set_setpoint(match d.mode() {
            Mode::ProfileVelocity | Mode::CyclicSynchronousVelocity => Setpoint::Velocity(units),
            Mode::ProfilePosition | Mode::CyclicSynchronousPosition => Setpoint::Position(units),
        });
        true
    }

    fn take_calls(&mut self, master: &mut Master, now: Timestamp) {
        for i in 0..self.drives.len() {
            for service in 0..TRIGGERS.len() {
                for _ in 0..TAKE_BATCH {
                    let request = self
                        .drives
                        .get(i)
                        .and_then(|d| d.triggers.get(service))
                        .and_then(|s| s.receive_request().ok().flatten());
                    let Some((id, _)) = request else { break };
                    match self.trigger(master, i, service) {
                        Some((success, message)) => self.answer(i, service, id, success, message),
                        None => {
                            if let Some(d) = self.drives.get_mut(i) {
                                if let Some((old_service, old, _)) = d.waiting.take() {
                                    self.answer(
                                        i,
                                        old_service,
                                        old,
                                        false,
                                        "replaced by a newer call".into(),
                                    );
                                }
                            }
                            if let Some(d) = self.drives.get_mut(i) {
                                d.waiting =
                                    Some((service, id, now.saturating_add(SWITCH_ON_TIMEOUT)));
                            }
                        }
                    }
                }
            }
            let Some(d) = self.drives.get(i) else {
                continue;
            };
            let node = d.node;
            for _ in 0..TAKE_BATCH {
                let Ok(Some((id, request))) = d.target_service.receive_request() else {
                    break;
                };
                let success = Self::set_target(master, node, request.target);
                let _ = d
                    .target_service
                    .send_response(id, TargetResponse { success });
            }
            for _ in 0..TAKE_BATCH {
                let Ok(Some((m, _))) = d.target_topic.take() else {
                    break;
                };
                Self::set_target(master, node, m.data);
            }
        }
    }

    fn watch(&mut self, master: &mut Master, now: Timestamp) {
        for i in 0..self.drives.len() {
            let Some(d) = self.drives.get(i) else {
                continue;
            };
            let (node, waiting, was_stopped) = (d.node, d.waiting, d.stopped);
            let Some(controller) = drive(master, node) else {
                continue;
            };
            let (state, stopped) = (controller.drive_state(), controller.stopped());
            if stopped != was_stopped {
                if let Some(reason) = stopped {
                    let name = d.name.clone();
                    (self.report)(CanopenEvent::Stopped {
                        drive: name,
                        why: stop_text(reason),
                    });
                }
                if let Some(d) = self.drives.get_mut(i) {
                    d.stopped = stopped;
                }
            }
            let Some((service, id, deadline)) = waiting else {
                continue;
            };
            let outcome = if state == Some(State::OperationEnabled) && stopped.is_none() {
                Some((true, "operation enabled".to_string()))
            } else if now >= deadline {
                Some((
                    false,
                    format!(
                        "not enabled within {} s: {}{}",
                        SWITCH_ON_TIMEOUT.as_secs(),
                        drive_state_name(state),
                        stopped
                            .map(|r| format!(", stopped: {}", stop_text(r)))
                            .unwrap_or_default()
                    ),
                ))
            } else {
                None
            };
            if let Some((success, message)) = outcome {
                if let Some(d) = self.drives.get_mut(i) {
                    d.waiting = None;
                }
                self.answer(i, service, id, success, message);
            }
        }
    }

    fn publish(&mut self, master: &mut Master) {
        let stamp = Time::now();
        for d in &self.drives {
            let nmt = nmt_name(master.liveness(d.node));
            let _ = d.nmt_state.publish(StringMsg { data: nmt.into() });
            let Some(controller) = drive(master, d.node) else {
                continue;
            };
            let (position, velocity) = controller.actual();
            let state = drive_state_name(controller.drive_state()).to_string();
            let state = match controller.stopped() {
                Some(reason) => format!("{state} (stopped: {})", stop_text(reason)),
                None => state,
            };
            let _ = d.drive_state.publish(StringMsg { data: state });
            let _ = d.joints.publish(JointState {
                header: Header {
                    stamp,
                    frame_id: String::new(),
                },
                name: vec![d.name.clone()],
                position: vec![f64::from(position)],
                velocity: vec![f64::from(velocity)],
                effort: Vec::new(),
            });
        }
    }
}

impl Hooks<Master> for Bridge<'_> {
    fn after_poll(&mut self, master: &mut Master, now: Timestamp) -> Flow {
        if let Some(until) = self.stopping_until {
            return if now >= until {
                Flow::Stop
            } else {
                Flow::Continue
            };
        }
        if self.stop.load(Ordering::Relaxed) {
            // The end of the run is a safe stop: every drive quick-stopped, for a few cycles.
            for d in &self.drives {
                if let Some(controller) = drive(master, d.node) {
                    controller.stop(StopReason::Commanded);
                }
            }
            self.stopping_until = Some(now.saturating_add(FINAL_STOP));
            return Flow::Continue;
        }
        self.take_calls(master, now);
        self.watch(master, now);
        if now >= self.next_report {
            self.publish(master);
            self.next_report = self.next_report.saturating_add(self.report_period).max(now);
        }
        Flow::Continue
    }

    fn wake_at(&self) -> Option<Timestamp> {
        let waiting = self
            .drives
            .iter()
            .filter_map(|d| d.waiting.map(|(_, _, at)| at));
        waiting
            .chain([self.next_report])
            .chain(self.stopping_until)
            .min()
    }

    fn bus_lost(&mut self, _: &mut Master, _: Timestamp, _: Port, error: &BusError) {
        (self.report)(CanopenEvent::BusLost(error.to_string()));
    }
}

/// Run the master of `config` on `bus` with its CiA 402 drives on ROS 2 until `stop` (then
/// every drive is quick-stopped before it returns).
pub fn run(
    node: &mut RosNode,
    config: &BusConfig,
    bus: Box<dyn Bus>,
    report_period: Duration,
    stop: &AtomicBool,
    report: &mut dyn FnMut(CanopenEvent),
) -> Result<(), RosError> {
    let io = |e: std::io::Error| RosError::Create(format!("polling the services: {e}"));
    let poll = mio1::Poll::new().map_err(io)?;
    let mut token = 0usize;
    let mut drives = Vec::new();
    let qos = reliable(10);
    for n in &config.nodes {
        if !matches!(n.driver, Driver::Cia402(_)) {
            report(CanopenEvent::NotExposed(format!(
                "{} (node {}): only CiA 402 drives are offered on ROS 2",
                n.name, n.id
            )));
            continue;
        }
        let name = |s: &str| format!("{}/{s}", n.name);
        let mut triggers = Vec::new();
        for service in TRIGGERS {
            let mut server = node.server::<TriggerRequest, TriggerResponse>(
                &name(service),
                "std_srvs",
                "Trigger",
            )?;
            poll.registry()
                .register(&mut server, mio1::Token(token), mio1::Interest::READABLE)
                .map_err(io)?;
            token += 1;
            triggers.push(server);
        }
        let mut target_service = node.server::<TargetRequest, TargetResponse>(
            &name("target"),
            "canopen_interfaces",
            "COTargetDouble",
        )?;
        poll.registry()
            .register(
                &mut target_service,
                mio1::Token(token),
                mio1::Interest::READABLE,
            )
            .map_err(io)?;
        let mut target_topic = node.subscription::<Float64>(&name("target"), &qos)?;
        poll.registry()
            .register(
                &mut target_topic,
                mio1::Token(token + 1),
                mio1::Interest::READABLE,
            )
            .map_err(io)?;
        token += 2;
        drives.push(DriveTopics {
            name: n.name.clone(),
            node: n.id,
            triggers,
            target_service,
            target_topic,
            joints: node.publisher(&name("joint_states"), &qos)?,
            nmt_state: node.publisher(&name("nmt_state"), &qos)?,
            drive_state: node.publisher(&name("drive_state"), &qos)?,
            waiting: None,
            stopped: None,
        });
    }
    let mut master = config.master();
    let mut runner = Runner::new(vec![(Port::MAIN, bus)]);
    let done = Arc::new(AtomicBool::new(false));
    let waiter = wake_on_readiness(poll, runner.waker(), Arc::clone(&done));
    let mut bridge = Bridge {
        drives,
        report_period,
        next_report: Timestamp::ZERO,
        stop,
        stopping_until: None,
        report,
    };
    let never = AtomicBool::new(false);
    let result = runner.run(&mut master, &never, None, &mut bridge);
    done.store(true, Ordering::Relaxed);
    let _ = waiter.join();
    result
        .map(|_| ())
        .map_err(|e| RosError::Create(format!("the bus is lost: {e}")))
}
