//! What happens in a run, typed: the faults, the buses' controllers, the supervisor's
//! states, the ECU's and the built-in ADS's events. Reports and plots show each as a kind and
//! a detail ([`SimEvent::kind`], [`Happening`]'s `Display`); code matches on the variants.

use bywire_core::confinement::NodeState;
use bywire_core::Timestamp;
use bywire_tug::ecu::EcuEvent;
use bywire_tug::messages::ControlMode;
use bywire_vehicle::arbitration::Side;
use bywire_vehicle::backup::InCharge;
use bywire_vehicle::command::{DegradationLevel, FaultClass};
use bywire_vehicle::redundancy::Channel;
use bywire_vehicle::supervisor::{EstopState, Watchdog};

use crate::bus::TugBus;
use crate::fault::Fault;
use crate::mission::MissionEvent;

/// What happened.
#[derive(Debug, Clone, PartialEq)]
pub enum Happening {
    /// A fault was injected.
    Fault(Fault),
    /// A fault's time ran out.
    FaultCleared(Fault),
    /// A controller's fault-confinement state changed.
    BusState {
        /// The bus.
        bus: TugBus,
        /// Who is at that endpoint (`ECU`, `drive 0x23`, ...).
        who: String,
        /// Its new state.
        state: NodeState,
    },
    /// The supervisor's watchdog moved to another level.
    Watchdog(Watchdog),
    /// The supervisor's E-stop latch moved.
    Estop(EstopState),
    /// The supervisor's control mode changed.
    Mode(ControlMode),
    /// The command buses: one alone (the other lost), or both agreeing again (`None`).
    Redundancy(Option<Channel>),
    /// The vehicle control ECU said so.
    Ecu(EcuEvent),
    /// The built-in ADS said so.
    Mission(MissionEvent),
    /// Which of the redundant tug's ECUs is in control changed (`None`: neither is).
    Control(Option<Side>),
    /// The degradation level changed, with the fault it is reported with.
    Degradation(DegradationLevel, Option<FaultClass>),
    /// Another of the redundant tug's actuators steers a corner.
    Steering {
        /// The corner (0 FL … 3 RR).
        corner: usize,
        /// The actuator now steering it.
        in_charge: InCharge,
    },
}

impl Happening {
    /// Its kind, as reports name it (`fault`, `watchdog`, `heartbeat_lost`, ...).
    pub fn kind(&self) -> &'static str {
        match self {
            Happening::Fault(_) => "fault",
            Happening::FaultCleared(_) => "fault_cleared",
            Happening::BusState { .. } => "bus_state",
            Happening::Watchdog(_) => "watchdog",
            Happening::Estop(_) => "estop",
            Happening::Mode(_) => "mode",
            Happening::Redundancy(_) => "redundancy",
            Happening::Ecu(event) => event.kind(),
            Happening::Mission(event) => event.kind(),
            Happening::Control(_) => "control",
            Happening::Degradation(..) => "degradation",
            Happening::Steering { .. } => "steering",
        }
    }
}

/// Its detail, as reports show it (the fault, the new state).
impl core::fmt::Display for Happening {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Happening::Fault(fault) | Happening::FaultCleared(fault) => write!(f, "{fault}"),
            Happening::BusState { bus, who, state } => {
                write!(f, "{} {who}: {state:?}", bus.name())
            }
            Happening::Watchdog(watchdog) => f.write_str(watchdog_name(*watchdog)),
            Happening::Estop(estop) => write!(f, "{estop:?}"),
            Happening::Mode(mode) => write!(f, "{mode:?}"),
            Happening::Redundancy(Some(Channel::A)) => f.write_str("bus 1 alone (bus 1b lost)"),
            Happening::Redundancy(Some(Channel::B)) => f.write_str("bus 1b alone (bus 1 lost)"),
            Happening::Redundancy(None) => f.write_str("both buses agree"),
            Happening::Ecu(event) => write!(f, "{event}"),
            Happening::Mission(event) => write!(f, "{event}"),
            Happening::Control(Some(side)) => write!(f, "ECU {side:?} in control"),
            Happening::Control(None) => f.write_str("neither ECU in control"),
            Happening::Degradation(level, Some(reason)) => write!(f, "{level} ({reason})"),
            Happening::Degradation(level, None) => write!(f, "{level}"),
            Happening::Steering { corner, in_charge } => {
                let corner = ["FL", "FR", "RL", "RR"]
                    .get(*corner)
                    .copied()
                    .unwrap_or("?");
                let by = match in_charge {
                    InCharge::Primary => "its primary",
                    InCharge::Backup => "its backup valve",
                    InCharge::Neither => "nothing",
                };
                write!(f, "{corner} steered by {by}")
            }
        }
    }
}

/// A watchdog level's name in reports.
fn watchdog_name(watchdog: Watchdog) -> &'static str {
    match watchdog {
        Watchdog::Normal => "normal",
        Watchdog::Holding { .. } => "holding",
        Watchdog::Decelerating { .. } => "decelerating",
        Watchdog::FullBraking => "full_braking",
        Watchdog::Recovering { .. } => "recovering",
    }
}

/// Something that happened in a run, and when.
#[derive(Debug, Clone, PartialEq)]
pub struct SimEvent {
    /// When.
    pub t: Timestamp,
    /// What.
    pub what: Happening,
}

impl SimEvent {
    /// Its kind (see [`Happening::kind`]).
    pub fn kind(&self) -> &'static str {
        self.what.kind()
    }
}

/// As reports write it: the time in seconds, the kind and the detail.
impl serde::Serialize for SimEvent {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut record = serializer.serialize_struct("SimEvent", 3)?;
        #[allow(clippy::cast_precision_loss)]
        record.serialize_field("t_s", &(self.t.as_nanos() as f64 / 1e9))?;
        record.serialize_field("kind", self.kind())?;
        record.serialize_field("detail", &self.what.to_string())?;
        record.end()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn an_event_reads_as_reports_have_always_written_it() {
        let at = Timestamp::from_millis(1_500);
        let event = |what| SimEvent { t: at, what };
        let off = event(Happening::BusState {
            bus: TugBus::Bus2,
            who: "drive 0x23".into(),
            state: NodeState::BusOff,
        });
        assert_eq!(
            serde_json::to_string(&off).unwrap(),
            r#"{"t_s":1.5,"kind":"bus_state","detail":"bus2 drive 0x23: BusOff"}"#
        );
        let lost = event(Happening::Ecu(EcuEvent::HeartbeatLost(0x21)));
        assert_eq!(
            (lost.kind(), lost.what.to_string().as_str()),
            ("heartbeat_lost", "node 0x21")
        );
        let braking = event(Happening::Watchdog(Watchdog::FullBraking));
        assert_eq!(braking.what.to_string(), "full_braking");
        let alone = event(Happening::Redundancy(Some(Channel::B)));
        assert_eq!(alone.what.to_string(), "bus 1b alone (bus 1 lost)");
        let fault = event(Happening::FaultCleared(Fault::Estop));
        assert_eq!(
            (fault.kind(), fault.what.to_string().as_str()),
            ("fault_cleared", "Estop")
        );
    }
}
