//! # bywire-vehicle: the vehicle interface and its safety logic
//!
//! - [`command`]: the vocabulary both ends speak — the command, control and steering modes,
//!   gears, and the vehicle's reported watchdog level and E-stop state — with names, text and
//!   raw numbers converted in one place.
//! - [`supervisor`]: the logic a vehicle control ECU runs on the other end of the wire: command
//!   validation, the watchdog cascade, the E-stop latch, control modes with driver takeover,
//!   and the actuator outputs. A sans-IO node: frames and time in, frames and outputs out.
//! - [`ads`]: the ADS side: commands out at the command rate with counter and CRC (a stale
//!   command becomes a controlled stop), the emergency-brake burst, and feedback validated into
//!   a [`ads::VehicleState`] whose fields carry their age.
//! - [`redundancy`]: the two-bus voter and a 2-out-of-3 sensor voter.
//! - Fail-operational layers: [`arbitration`] (an A/B pair of control ECUs, one active, one
//!   in hot standby, takeover without split brain), [`backup`] (a primary actuator and its
//!   backup, switched on a failed feedback check) and [`degradation`] (levels from nominal to
//!   safe stop, the rule per fault class, the latch); a profile's [`fail_operational`]
//!   section (with `std`) declares which of them a vehicle carries.
//! - [`mechanism`]: the safety mechanisms by name, and the set a fault-injection campaign
//!   switches off to show its cells would notice one missing.
//! - [`autoware`]: the `autoware-can` output (one `Control` as three frames, all or nothing)
//!   and its decoder.
//! - [`replay`]: a recorded session fed to a supervisor, its decisions as a trace to compare;
//!   [`fuzz`]: random commands judged by the ADS side's checks and the vehicle's, compared.
//! - [`acceptance`]: vehicle acceptance checks (steering sweep, speed steps, watchdog and E-stop
//!   timing) as a node on the command bus, for any profile's vehicle.
//! - `secured` (feature `secoc`): any wire with its messages authenticated (AUTOSAR SecOC:
//!   CMAC, freshness, replay and forgery rejected and counted, freshness sync).
//! - [`wire`]: a vehicle's messages on the wire, behind the traits the nodes speak through;
//!   [`wire::ProfileWire`] speaks any vehicle a profile describes, by role, through the runtime
//!   codec (a vehicle crate may add a wire over generated structs: `bywire-tug` does).
//! - [`profile`]: TOML vehicle profiles checked against their DBC; `autoware-can` and `shuttle` ship here,
//!   each vehicle's own with its crate.
//!
//! Nothing here names a particular vehicle.
//!
//! The control path (the vocabulary, supervisor, ADS side, voters, the wire traits and the
//! Autoware frames) is `no_std` with `alloc`; the `std` feature (on by default) adds profiles,
//! [`wire::ProfileWire`] and the acceptance checks, which load files and a DBC.
//!
//! The supervisor fails closed: it starts at full braking, and valid commands alone do not
//! release it — only a run of them and then an engage request.
//! ```
//! use bywire_vehicle::supervisor::{Cascade, Watchdog, WatchdogEvent};
//!
//! let cascade = Cascade::default(); // hold 2 cycles, decelerate to 4, recover after 10
//! let mut watchdog = Watchdog::FullBraking;
//! for _ in 0..20 {
//!     watchdog = watchdog.next(WatchdogEvent::Valid { engage: false }, cascade);
//! }
//! assert!(matches!(watchdog, Watchdog::Recovering { .. }));
//! watchdog = watchdog.next(WatchdogEvent::Valid { engage: true }, cascade);
//! assert_eq!(watchdog, Watchdog::Normal);
//! assert_eq!(watchdog.next(WatchdogEvent::Missed(5), cascade), Watchdog::FullBraking);
//! ```

#![cfg_attr(not(feature = "std"), no_std)]

#[cfg(feature = "std")]
extern crate alloc;

#[cfg(feature = "std")]
pub mod acceptance;
pub mod ads;
pub mod arbitration;
pub mod autoware;
pub mod backup;
#[cfg(feature = "std")]
pub mod bindings;
pub mod command;
pub mod degradation;
#[cfg(feature = "std")]
pub mod fail_operational;
#[cfg(feature = "std")]
pub mod fuzz;
pub mod mechanism;
#[cfg(feature = "std")]
pub mod profile;
#[cfg(feature = "std")]
mod profile_wire;
pub mod redundancy;
#[cfg(feature = "std")]
pub mod replay;
#[cfg(feature = "secoc")]
pub mod secured;
pub mod supervisor;
pub mod wire;
