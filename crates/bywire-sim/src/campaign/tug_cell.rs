//! One campaign cell on the whole simulated tug (`model = "tug"`): the redundant tug (or the
//! plain one) drives the fail-operational scenario's service road with its own ADS, the fault
//! goes in through [`Tug::inject`] as a scenario's would, and the ECU in control is watched a
//! millisecond at a time — its supervisor as on the plant model, and the layers only the
//! whole tug has: the 2-out-of-3 angle voters (their faults reported to the degradation
//! latch), the A/B takeover and the backup steering valves.

use bywire_vehicle::arbitration::Side;
use bywire_vehicle::backup::InCharge;
use bywire_vehicle::command::FaultClass as LayerFault;
use bywire_vehicle::mechanism::{Mechanism, Mechanisms};

use super::rig::{detectors, reaction_of, Observer, Snapshot, Vehicle};
use super::{Campaign, Cell, CellResult, FaultClass, FaultEntry, State};
use crate::fault::{ActuatorFailure, Fault};
use crate::scenario::Scenario;
use crate::steering::SensorFault;
use crate::tug::{Tug, TugParams};

/// When the fault goes in: the tug engaged and cruising on the service road's straight.
const INJECT_MS: u64 = 8_000;

/// The tug's fault for `entry` (`Err`: why it does not apply to this tug).
fn tug_fault(entry: &FaultEntry, redundant: bool) -> Result<Fault, String> {
    let corner = || {
        entry
            .corner
            .filter(|c| *c < 4)
            .ok_or_else(|| format!("{} needs corner 0 (FL) … 3 (RR)", entry.class.name()))
    };
    let side = || match entry.side.as_deref() {
        Some("B" | "b") => Side::B,
        _ => Side::A,
    };
    let value = entry.value.unwrap_or(0.0);
    let fault = match entry.class {
        FaultClass::AngleSensor => Fault::AngleSensor {
            corner: corner()?,
            module: usize::from(matches!(entry.module.as_deref(), Some("C" | "c"))),
            fault: match entry.sensor.as_deref() {
                Some("stuck") => SensorFault::Stuck(value),
                Some("drift") => SensorFault::Drift(value),
                Some("open") => SensorFault::OpenCircuit,
                _ => SensorFault::Silent,
            },
        },
        FaultClass::EcuSilent => Fault::EcuSilent(side()),
        FaultClass::EcuWrongOutput => Fault::EcuWrongOutput(side()),
        FaultClass::EcuBabble => Fault::EcuBabble(side()),
        FaultClass::SteeringActuator => Fault::SteeringActuator {
            corner: corner()?,
            backup: entry.backup,
            failure: match entry.failure.as_deref() {
                Some("runaway") => ActuatorFailure::Runaway,
                Some("drive-lost") => ActuatorFailure::DriveLost,
                _ => ActuatorFailure::Stuck,
            },
        },
        FaultClass::NodeSilent => Fault::AdsSilence,
        FaultClass::Estop => Fault::Estop,
        FaultClass::DriverTakeover => Fault::DriverTakeover,
        FaultClass::RedundantBusLost => Fault::RedundantBusLoss,
        FaultClass::ChecksumCorrupted => Fault::CorruptCommands,
        FaultClass::Duplicated => Fault::DuplicateCommands,
        FaultClass::Delayed => Fault::DelayCommands(entry.delay_ms.unwrap_or(50)),
        _ => {
            return Err(
                "injected on the plant model's cells (the whole tug model takes the faults of its layers)"
                    .into(),
            )
        }
    };
    if fault.needs_redundancy() && !redundant {
        return Err(
            "the plain tug has one ECU and no further angle sensors or backup valves".into(),
        );
    }
    Ok(fault)
}

/// The whole tug's layers as the detectors read them.
#[derive(Debug, Clone, PartialEq)]
struct Layers {
    /// The degradation faults the ECU in control has taken.
    faults: Vec<LayerFault>,
    in_control: Option<Side>,
    steering: [InCharge; 4],
}

impl Layers {
    fn of(tug: &Tug) -> Layers {
        let ecu = tug.vehicle_control_ecu();
        let degradation = ecu.map(|e| *e.supervisor().degradation());
        let faults = degradation
            .iter()
            .flat_map(|d| [d.first(), d.second()])
            .flatten()
            .map(|f| f.class)
            .collect();
        Layers {
            faults,
            // The arbitration's own view (a faulted ECU is not hidden from it).
            in_control: tug.ecu_pair().and_then(crate::tug::EcuPair::in_control),
            steering: ecu.map_or([InCharge::Primary; 4], |e| e.steering_in_charge()),
        }
    }

    /// The layers' mechanisms that noticed something since `before`.
    fn detectors(&self, before: &Layers) -> Mechanisms {
        let mut found = Mechanisms::NONE;
        for class in self.faults.iter().filter(|c| !before.faults.contains(c)) {
            found = found.with(match class {
                LayerFault::SensorChannelOut | LayerFault::SensorLost => Mechanism::Voter,
                _ => Mechanism::FailOperational,
            });
        }
        if self.in_control != before.in_control || self.steering != before.steering {
            found = found.with(Mechanism::FailOperational);
        }
        found
    }
}

/// The cell's run on the whole tug: `Err` when it does not apply, else its failures.
pub(super) fn drive(
    campaign: &Campaign,
    vehicle: &Vehicle,
    cell: &Cell,
    entry: &FaultEntry,
    result: &mut CellResult,
) -> Result<Vec<String>, String> {
    if cell.state != State::Cruising {
        return Err(
            "the whole tug's cells run while it cruises the service road; the other states are the plant model's"
                .into(),
        );
    }
    let fault = tug_fault(entry, vehicle.redundant)?;
    let scenario = Scenario::builtin("fail-operational").ok_or("no fail-operational scenario")?;
    let params = TugParams {
        redundant: vehicle.redundant,
        ..scenario.params(campaign.seed, 2_000.0)
    };
    let mut tug = Tug::new(params).map_err(|e| e.to_string())?;
    tug.switch_off(vehicle.disabled);
    let inject = campaign.inject_at_ms.max(INJECT_MS);
    let observe = entry.observe_ms.unwrap_or(campaign.observe_ms);
    for _ in 0..inject {
        tug.step();
    }
    let snapshot = |tug: &Tug| {
        let ecu = tug.ecu()?;
        Some((Snapshot::of(ecu, 0), ecu.actuators(tug.now())))
    };
    let Some((before, actuators)) = snapshot(&tug) else {
        return Err("the tug has no ECU".into());
    };
    let layers_before = Layers::of(&tug);
    let mut observer = Observer::new(vehicle.limits());
    observer.baseline = reaction_of(&before, &actuators);
    tug.inject(fault, entry.duration(vehicle.cycle()));
    for t in 1..=observe {
        tug.step();
        let Some((now, a)) = snapshot(&tug) else {
            return Err("the tug lost its ECU".into());
        };
        observer.limits(&a, || format!("{t} ms after the fault"));
        let noticed: Mechanisms = detectors(&before, &now)
            .iter()
            .chain(Layers::of(&tug).detectors(&layers_before).iter())
            .collect();
        observer.observe(t as f64, noticed, reaction_of(&now, &a), result);
    }
    Ok(observer.judge(cell, vehicle.cycle(), result))
}
