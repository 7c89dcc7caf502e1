//! The faults and operator actions a scenario injects into the simulated tug, applied at the
//! edges of its network: outputs dropped, frames tampered with on a bus, a plant or an input
//! changed (see [`crate::tug::Tug::inject`]).

use core::time::Duration;

use bywire_net::sim::Tamper;
use bywire_tug::messages::AdsToVehicleControl;

use bywire_vehicle::arbitration::Side;

use crate::attacker::Attack;
use crate::bus::TugBus;
use crate::steering::SensorFault;

/// A fault (or operator action) a scenario injects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// The ADS stops sending.
    AdsSilence,
    /// The E-stop chain opens (the safety controller requests an E-stop).
    Estop,
    /// The operator's reset: reset pressed until the latch clears, then engage.
    OperatorReset,
    /// A drive node (by node ID) stops sending (cut off, powered down).
    DriveSilence(u8),
    /// The angle sensor of a corner (0 FL … 3 RR) fails.
    SensorFault(usize, SensorFault),
    /// The ADS's commands arrive with a flipped bit (their checksum fails), on bus 1 and 1b.
    CorruptCommands,
    /// Every ADS command arrives twice, on bus 1 and 1b.
    DuplicateCommands,
    /// The ADS's commands arrive this many milliseconds late, on bus 1 and 1b.
    DelayCommands(u64),
    /// A driver turns the steering wheel (torque above the takeover threshold).
    DriverTakeover,
    /// The ECU's controller on bus 1 meets a burst of bus errors until it is bus-off; it
    /// recovers after 128 × 11 recessive bits.
    EcuBusOff,
    /// The node that sends this identifier on this bus meets the same burst, from its next
    /// frame of that identifier on, and recovers the same way.
    BusOff {
        /// The bus.
        bus: TugBus,
        /// An 11-bit identifier the node sends.
        id: u16,
    },
    /// Bus 1b, the redundant command bus, is cut: the ECU votes with bus 1 alone.
    RedundantBusLoss,
    /// A node on bus 1 without the key attacks ([`crate::attacker`]).
    Attack(Attack),
    /// One of the redundant tug's vehicle control ECUs falls silent (its communication
    /// stack hangs, its transceiver fails): nothing it sends reaches any bus.
    EcuSilent(Side),
    /// One of the redundant tug's ECUs computes wrongly: a steering trim corrupted in its
    /// memory puts its front-left setpoint 5 degrees off.
    EcuWrongOutput(Side),
    /// One of the redundant tug's ECUs babbles: silent for its own messages, it floods bus 1
    /// with identifier 0x000 until its partner's fence cuts its transceiver.
    EcuBabble(Side),
    /// One of the redundant tug's further angle sensors fails: `corner`'s (0 FL … 3 RR) in
    /// module `module` (0: B, 1: C), as `fault` says (`Silent`: the module reports no
    /// reading).
    AngleSensor {
        /// The corner.
        corner: usize,
        /// The module.
        module: usize,
        /// How it fails.
        fault: SensorFault,
    },
    /// A corner's steering actuator fails: the primary (the drive turning the orbital
    /// valve's input) or, `backup`, the redundant tug's backup valve.
    SteeringActuator {
        /// The corner (0 FL … 3 RR).
        corner: usize,
        /// The backup valve, not the primary.
        backup: bool,
        /// How it fails.
        failure: ActuatorFailure,
    },
    /// At a standstill, the redundant tug's faults are repaired: both ECUs back to their
    /// power-on roles (A in control), the degradation level back to nominal.
    Repair,
    /// Whichever node sends frames with this identifier on this bus sends them corrupted
    /// (a bit flipped), twice, or late (one such fault an identifier: the latest holds).
    TamperFrames {
        /// The bus.
        bus: TugBus,
        /// The 11-bit identifier.
        id: u16,
        /// What happens to them.
        tamper: Tamper,
    },
}

/// The corners' names, 0 … 3.
const CORNERS: [&str; 4] = ["FL", "FR", "RL", "RR"];

/// How a steering actuator fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ActuatorFailure {
    /// It sticks: the primary's valve input seizes, the backup's spool stays closed.
    Stuck,
    /// It runs away: the primary's output stage drives full one way while powered (a failed
    /// bridge or feedback), the backup's spool sticks open.
    Runaway,
    /// Its drive loses its supply: silent on the bus, its motor or valve unpowered.
    DriveLost,
}

/// As in events and the live view: the variant's name, identifiers and node IDs in hex.
impl core::fmt::Display for Fault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Fault::DriveSilence(node) => write!(f, "DriveSilence(0x{node:02X})"),
            Fault::TamperFrames { bus, id, tamper } => {
                write!(f, "TamperFrames {{ {} 0x{id:03X} {tamper:?} }}", bus.name())
            }
            Fault::BusOff { bus, id } => write!(f, "BusOff {{ {} 0x{id:03X} }}", bus.name()),
            Fault::AngleSensor {
                corner,
                module,
                fault,
            } => {
                let corner = CORNERS.get(*corner).copied().unwrap_or("?");
                let module = if *module == 0 { "B" } else { "C" };
                write!(f, "AngleSensor({corner} {module} {fault:?})")
            }
            Fault::SteeringActuator {
                corner,
                backup,
                failure,
            } => {
                let corner = CORNERS.get(*corner).copied().unwrap_or("?");
                let which = if *backup { "backup" } else { "primary" };
                write!(f, "SteeringActuator({corner} {which} {failure:?})")
            }
            other => write!(f, "{other:?}"),
        }
    }
}

/// A fault that tampers with frames on their way: on these buses, frames of this 11-bit
/// identifier, this way.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tampering<'a> {
    /// The buses.
    pub buses: &'a [TugBus],
    /// The identifier.
    pub id: u16,
    /// What happens to the frames.
    pub tamper: Tamper,
}

impl Fault {
    /// Whether it is a fault of a layer only the redundant tug has (its second ECU, its
    /// further angle sensors, its backup steering valves) or of their repair.
    pub fn needs_redundancy(&self) -> bool {
        matches!(
            self,
            Fault::EcuSilent(_)
                | Fault::EcuWrongOutput(_)
                | Fault::EcuBabble(_)
                | Fault::AngleSensor { .. }
                | Fault::SteeringActuator { backup: true, .. }
                | Fault::Repair
        )
    }

    /// The frames this fault tampers with (`None`: it does not tamper with frames).
    pub fn tampering(&self) -> Option<Tampering<'_>> {
        // The ADS's commands on both buses that carry them, as a faulty ADS would send them.
        const COMMAND_BUSES: [TugBus; 2] = [TugBus::Bus1, TugBus::Bus1b];
        let command = u16::try_from(AdsToVehicleControl::ID).unwrap_or(0x100);
        let (buses, id, tamper): (&[TugBus], u16, Tamper) = match self {
            Fault::CorruptCommands => (&COMMAND_BUSES, command, Tamper::FlipBit),
            Fault::DuplicateCommands => (&COMMAND_BUSES, command, Tamper::Duplicate),
            Fault::DelayCommands(ms) => (
                &COMMAND_BUSES,
                command,
                Tamper::Delay(Duration::from_millis(*ms)),
            ),
            Fault::TamperFrames { bus, id, tamper } => (core::slice::from_ref(bus), *id, *tamper),
            _ => return None,
        };
        Some(Tampering { buses, id, tamper })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fault_tampers_with_the_frames_it_names_and_no_others() {
        let command = u16::try_from(AdsToVehicleControl::ID).unwrap_or(0);
        let delay = Fault::DelayCommands(30).tampering();
        assert_eq!(
            delay,
            Some(Tampering {
                buses: &[TugBus::Bus1, TugBus::Bus1b],
                id: command,
                tamper: Tamper::Delay(Duration::from_millis(30)),
            })
        );
        let on_bus2 = Fault::TamperFrames {
            bus: TugBus::Bus2,
            id: 0x211,
            tamper: Tamper::Duplicate,
        };
        let tampering = on_bus2.tampering();
        assert_eq!(
            tampering.map(|t| (t.buses, t.id)),
            Some((&[TugBus::Bus2][..], 0x211))
        );
        assert_eq!(Fault::AdsSilence.tampering(), None);
        assert_eq!(Fault::Estop.tampering(), None);
    }
}
