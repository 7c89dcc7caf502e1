//! # bywire-vehicle: the vehicle interface and its safety logic
//!
//! - [`command`]: the vocabulary both ends speak — the command, control and steering modes,
//!   gears, and the vehicle's reported watchdog level and E-stop state — with names, text and
//!   raw numbers converted in one place.
//! - [`reference_tug`]: the reference tug's CAN messages (`dbc/reference-tug.dbc`), as structs
//!   generated from the DBC at build time, plus the E2E protection (counter, CRC-8 with data ID)
//!   every message carries.
//! - [`supervisor`]: the logic a vehicle control ECU runs on the other end of the wire: command
//!   validation, the watchdog cascade, the E-stop latch, control modes with driver takeover,
//!   and the actuator outputs. A sans-IO node: frames and time in, frames and outputs out.
//! - [`ads`]: the ADS side: commands out at the command rate with counter and CRC (a stale
//!   command becomes a controlled stop), the emergency-brake burst, and feedback validated into
//!   a [`ads::VehicleState`] whose fields carry their age.
//! - [`redundancy`]: the two-bus voter and a 2-out-of-3 sensor voter.
//! - [`autoware`]: the `autoware-can` output (one `Control` as three frames, all or nothing)
//!   and its decoder.
//! - [`acceptance`]: vehicle acceptance checks (steering sweep, speed steps, watchdog and E-stop
//!   timing) as a node on the command bus, for any profile's vehicle.
//! - [`wire`]: the ADS side's messages on the wire: the reference tug through its generated
//!   structs, or any vehicle a profile describes, by role, through the runtime codec.
//! - [`profile`]: TOML vehicle profiles checked against their DBC; `reference-tug` and
//!   `autoware-can` ship.

//!
//! The supervisor fails closed: before it has seen a run of valid commands and an engage
//! request, its watchdog is at full braking and the ADS has no say over the actuators.
//! ```
//! use bywire_core::Timestamp;
//! use bywire_vehicle::command::Gear;
//! use bywire_vehicle::supervisor::{Supervisor, SupervisorConfig, Watchdog};
//!
//! let mut supervisor = Supervisor::new(SupervisorConfig::default());
//! supervisor.poll(Timestamp::ZERO, &mut |_state_frame| {});
//! assert_eq!(supervisor.watchdog(), Watchdog::FullBraking);
//! let actuators = supervisor.actuators(Timestamp::ZERO);
//! assert!(!actuators.ads_in_control && !actuators.steering_enabled && actuators.velocity == 0.0);
//! assert_eq!("D".parse::<Gear>(), Ok(Gear::Drive));
//! ```

pub mod acceptance;
pub mod ads;
pub mod autoware;
pub mod command;
pub mod profile;
pub mod redundancy;
pub mod reference_tug;
pub mod supervisor;
pub mod wire;
