//! `bywire sim --web`: the simulated tug's buses on the live page and Foxglove server, with its
//! pose (`/tug/pose`, Foxglove's `PoseInFrame`, so the 3D panel shows it), its route
//! (`/tug/route`, `PosesInFrame`), its state (`/tug/state`: phase, mode, degradation level,
//! faults and the buttons the page shows) and a command topic (`/tug/command`) for the live
//! view's fault buttons, E-stop and reset.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Result;
use bywire_bus::virtual_bus::VirtualBus;
use bywire_bus::{Bus, BusRx, Received};
use bywire_core::Timestamp;
use bywire_dbc::decoder::Decoder;
use bywire_net::sim::NodeId;
use bywire_sim::fault::Fault;
use bywire_sim::tug::{Tug, TugBus};
use bywire_web::hub::time_json;
use bywire_web::{Access, Database};
use serde_json::{json, Value as Json};

use crate::support::busarg;
use crate::support::live::{Live, LiveBus, LiveConfig};

/// How often the pose and state are published, in simulated time.
const STATE_PERIOD: Duration = Duration::from_millis(100);
/// How often the route is published again (for clients that join late).
const ROUTE_PERIOD: Duration = Duration::from_secs(2);
/// The frame of reference of the pose and route.
const FRAME_ID: &str = "apron";

/// One of the tug's buses on the page: the port the hub sees it through, and the endpoint
/// what clients send arrives on.
struct Port {
    bus: TugBus,
    port: NodeId,
    from_clients: Box<dyn BusRx>,
}

/// The live server of a run.
pub struct SimWeb {
    live: Live,
    ports: Vec<Port>,
    faults: Vec<(Fault, Option<Duration>)>,
    /// The run's start (what the logs count from): frames and poses carry it plus the
    /// simulated time.
    start: Timestamp,
    next_state: Timestamp,
    next_route: Timestamp,
    scratch: Vec<Option<bywire_dbc::codec::Decoded>>,
}

impl SimWeb {
    /// Serve `tug`'s buses on `listen`, their frames timed from `start` as the logs are;
    /// `faults` are the scenario's, which the page's buttons inject.
    pub fn start(
        tug: &mut Tug,
        listen: SocketAddr,
        start: Timestamp,
        faults: Vec<(Fault, Option<Duration>)>,
    ) -> Result<Self> {
        // In-process buses of this run only, which carry what clients send to the tug.
        let prefix = format!("bywire-sim-{}-web", std::process::id());
        let bus_name = |bus: TugBus| format!("{prefix}-{}", bus.name());
        let database = |text: &str| -> Result<Arc<Database>> {
            let (db, _) = bywire_dbc::parse_str(text, bywire_dbc::Mode::Strict)?;
            Ok(Arc::new(Database::new(Decoder::new(db))))
        };
        let (vehicle, drives) = (
            database(bywire_tug::messages::DBC)?,
            database(bywire_tug::DRIVES_DBC)?,
        );
        let buses = TugBus::ALL
            .iter()
            .map(|bus| {
                let (bitrate, database) = match bus {
                    TugBus::Bus2 => (1_000_000, &drives),
                    _ => (500_000, &vehicle),
                };
                Ok(LiveBus {
                    arg: busarg::parse(&format!("{}=virtual:{}", bus.name(), bus_name(*bus)))?,
                    bitrate: Some(bitrate),
                    database: Some(Arc::clone(database)),
                    fed: true,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let live = Live::start(
            &buses,
            LiveConfig::new(
                "bywire sim",
                listen,
                // A simulation: the page's buttons and transmit panel act on it alone.
                Access {
                    token: None,
                    origins: Vec::new(),
                    allow_send: true,
                },
            ),
            |hub| {
                hub.channel("/tug/pose", "foxglove.PoseInFrame", pose_schema())
                    .channel("/tug/route", "foxglove.PosesInFrame", route_schema())
                    .channel("/tug/state", "bywire.TugState", state_schema())
                    .command_topic("/tug/command")
                    .metadata("vehicle", "reference tug (simulated)")
            },
        )?;
        let ports = TugBus::ALL
            .iter()
            .map(|bus| {
                let (_, from_clients) =
                    (Box::new(VirtualBus::join(&bus_name(*bus))) as Box<dyn Bus>).split();
                Port {
                    bus: *bus,
                    port: tug.attach(*bus),
                    from_clients,
                }
            })
            .collect();
        Ok(SimWeb {
            live,
            ports,
            faults,
            start,
            next_state: Timestamp::ZERO,
            next_route: Timestamp::ZERO,
            scratch: Vec::new(),
        })
    }

    /// Where it listens.
    pub fn address(&self) -> SocketAddr {
        self.live.address()
    }

    /// After a step: the buses' frames to the hub and what clients sent onto the buses (both
    /// bounded by what came since the last step), the commands clients sent applied, the
    /// pose, state and route published when their time has come.
    pub fn step(&mut self, tug: &mut Tug) {
        let hub = self.live.hub();
        let start = self.start;
        let at = |t: Timestamp| start.saturating_add(Duration::from_nanos(t.as_nanos()));
        for (index, port) in self.ports.iter_mut().enumerate() {
            while let Some((time, frame)) = tug.receive(port.bus, port.port) {
                let received = received(frame, at(time));
                hub.on_frame(index, &received, &mut self.scratch);
            }
            while let Ok(Some(sent)) = port.from_clients.recv(Some(Duration::ZERO)) {
                // On the simulated bus, and in the trace as the bus's other frames.
                hub.on_frame(
                    index,
                    &received(sent.frame, at(tug.now())),
                    &mut self.scratch,
                );
                tug.send(port.bus, port.port, sent.frame);
            }
        }
        for (_, command) in hub.take_commands() {
            if command.get("estop").and_then(Json::as_bool) == Some(true) {
                tug.inject(Fault::Estop, Some(Duration::from_secs(1)));
            }
            if command.get("reset").and_then(Json::as_bool) == Some(true) {
                tug.inject(Fault::OperatorReset, None);
            }
            let chosen = command
                .get("fault")
                .and_then(Json::as_u64)
                .and_then(|n| usize::try_from(n).ok())
                .and_then(|n| n.checked_sub(1))
                .and_then(|n| self.faults.get(n));
            if let Some((fault, duration)) = chosen {
                tug.inject(*fault, *duration);
            }
        }
        let now = tug.now();
        if now >= self.next_state {
            self.next_state = now.saturating_add(STATE_PERIOD);
            hub.publish_json(hub.extra_channel(0), at(now), &pose_json(tug, at(now)));
            hub.publish_json(
                hub.extra_channel(2),
                at(now),
                &self.state_json(tug, at(now)),
            );
        }
        if now >= self.next_route {
            self.next_route = now.saturating_add(ROUTE_PERIOD);
            hub.publish_json(hub.extra_channel(1), at(now), &route_json(tug, at(now)));
        }
    }

    fn state_json(&self, tug: &Tug, at: Timestamp) -> Json {
        let pose = tug.pose();
        let ecu = tug.ecu();
        let buttons: Vec<Json> = self
            .faults
            .iter()
            .take(9)
            .enumerate()
            .map(|(i, (fault, _))| json!({"number": i + 1, "fault": fault.to_string()}))
            .collect();
        json!({
            "timestamp": time_json(at),
            "phase": tug.phase().map(|p| p.to_string()),
            "speed_mps": tug.pose_speed(),
            "x": pose.x,
            "y": pose.y,
            "yaw_deg": pose.yaw.to_degrees(),
            "wheels_deg": tug.wheel_angles(),
            "to_go_m": tug.remaining().filter(|m| m.is_finite()),
            "mode": ecu.map(|e| format!("{:?}", e.mode())),
            "watchdog": ecu.map(|e| format!("{:?}", e.watchdog())),
            "estop": ecu.map(|e| format!("{:?}", e.estop())),
            "level": ecu.map(|e| e.degradation().level().to_string()),
            "redundancy": ecu.map(|e| if e.degraded().is_some() { "degraded" } else { "both buses" }),
            "faults": tug.active_faults().map(|f| f.to_string()).collect::<Vec<_>>(),
            "buttons": buttons,
            "soc_percent": tug.soc() * 100.0,
        })
    }

    /// Stop serving; what clients lost, in all.
    pub fn stop(self) -> u64 {
        self.live.stop()
    }
}

/// A heading about the vertical axis as a quaternion.
fn orientation(yaw: f64) -> Json {
    json!({"x": 0.0, "y": 0.0, "z": (yaw / 2.0).sin(), "w": (yaw / 2.0).cos()})
}

fn received(frame: bywire_core::Frame, timestamp: Timestamp) -> Received {
    Received {
        frame,
        timestamp,
        own: false,
        local: false,
        hardware: None,
    }
}

fn pose_json(tug: &Tug, at: Timestamp) -> Json {
    let pose = tug.pose();
    json!({
        "timestamp": time_json(at),
        "frame_id": FRAME_ID,
        "pose": {"position": {"x": pose.x, "y": pose.y, "z": 0.0}, "orientation": orientation(pose.yaw)},
    })
}

fn route_json(tug: &Tug, at: Timestamp) -> Json {
    let route = tug.route();
    let poses: Vec<Json> = route
        .iter()
        .zip(route.iter().skip(1).chain(route.last()))
        .map(|(p, next)| {
            let yaw = (next.y - p.y).atan2(next.x - p.x);
            json!({"position": {"x": p.x, "y": p.y, "z": 0.0}, "orientation": orientation(yaw)})
        })
        .collect();
    json!({"timestamp": time_json(at), "frame_id": FRAME_ID, "poses": poses})
}

fn time_schema() -> Json {
    json!({"type": "object", "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}})
}

fn pose_schema_of(title: &str) -> Json {
    let number = json!({"type": "number"});
    json!({
        "title": title,
        "type": "object",
        "properties": {
            "position": {"type": "object", "properties": {"x": number, "y": number, "z": number}, "required": ["x", "y", "z"]},
            "orientation": {"type": "object", "properties": {"x": number, "y": number, "z": number, "w": number}, "required": ["x", "y", "z", "w"]},
        },
        "required": ["position", "orientation"],
    })
}

/// Foxglove's `PoseInFrame`: a time, a frame of reference, a pose.
fn pose_schema() -> Json {
    json!({
        "title": "foxglove.PoseInFrame",
        "type": "object",
        "properties": {
            "timestamp": time_schema(),
            "frame_id": {"type": "string"},
            "pose": pose_schema_of("foxglove.Pose"),
        },
        "required": ["timestamp", "frame_id", "pose"],
    })
}

/// Foxglove's `PosesInFrame`: a time, a frame of reference, poses.
fn route_schema() -> Json {
    json!({
        "title": "foxglove.PosesInFrame",
        "type": "object",
        "properties": {
            "timestamp": time_schema(),
            "frame_id": {"type": "string"},
            "poses": {"type": "array", "items": pose_schema_of("foxglove.Pose")},
        },
        "required": ["timestamp", "frame_id", "poses"],
    })
}

fn state_schema() -> Json {
    json!({
        "title": "bywire.TugState",
        "type": "object",
        "properties": {
            "timestamp": time_schema(),
            "phase": {"type": ["string", "null"]},
            "speed_mps": {"type": "number"},
            "x": {"type": "number"},
            "y": {"type": "number"},
            "yaw_deg": {"type": "number"},
            "wheels_deg": {"type": "array", "items": {"type": "number"}, "description": "FL, FR, RL, RR"},
            "to_go_m": {"type": ["number", "null"]},
            "mode": {"type": ["string", "null"]},
            "watchdog": {"type": ["string", "null"]},
            "estop": {"type": ["string", "null"]},
            "level": {"type": ["string", "null"], "description": "the degradation level"},
            "redundancy": {"type": ["string", "null"]},
            "faults": {"type": "array", "items": {"type": "string"}},
            "buttons": {"type": "array", "items": {"type": "object"}},
            "soc_percent": {"type": "number"},
        },
    })
}
