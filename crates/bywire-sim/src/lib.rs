//! # bywire-sim: the simulated airside tug
//!
//! Plant models, each a small state advanced by `step(dt, ...)`, deterministic for a seed:
//! - [`steering`]: the electrohydraulic steering chain of one corner — motor controller output
//!   → DC motor → orbital valve (flow from the input shaft's speed, a dead zone, follow-up that
//!   holds when the shaft stops, limited by supply pressure) → double-acting cylinder →
//!   linkage → wheel angle → potentiometer (noise, quantisation, faults);
//! - [`drive`]: a wheel's drive motor (torque and power limits, regenerative braking limited
//!   by speed and state of charge), friction and parking brakes, the braking coordinator;
//! - [`battery`]: the 88 V traction battery (capacity, state of charge, internal resistance);
//! - [`chassis`]: the tug's body (mass with payload, grade, rolling resistance) moved by the
//!   four wheels' angles and speeds;
//! - [`rng`]: the seeded random numbers every noise source draws from;
//! - [`tug`]: the tug's network — the ADS side and the vehicle control ECU on bus 1, the ECU
//!   commanding eight CiA 402 drives on bus 2 — around the plants, in simulated time;
//! - [`fault`]: the faults a scenario injects; [`record`]: what a run records (events, trace,
//!   truth, step responses, response times, what attacks achieved);
//! - [`scenario`]: routes, load, grade and faults, built in or from TOML files;
//! - [`attacker`]: a node on bus 1 without the key: forged and replayed commands, a forged
//!   speed toward the ADS, a flood of identifier 0x000;
//! - [`report`]: a run's report (what `metrics.json` holds), with serde;
//! - [`truth`]: the plant's true state every 10 ms as CSV (`truth.csv`);
//! - [`output`]: a run's files (bus logs, truth, metrics); [`sweep`]: many runs on all cores;
//! - [`campaign`]: fault-injection campaigns over any profile's vehicle, judged cell by cell
//!   against the mechanism and reaction expected, reported as a coverage matrix;
//! - [`vehicle`]: a simulated vehicle for any profile — the real supervisor in front of a
//!   simple plant, as one node (`bywire vehicle`).

//!
//! The tug's first simulated second: the ECU fails closed, then the ADS engages it.
//! ```
//! use bywire_sim::tug::{Tug, TugParams};
//!
//! let mut tug = Tug::new(TugParams::default())?;
//! for _ in 0..1_000 {
//!     tug.step(); // one simulated millisecond
//! }
//! assert_eq!(tug.now().as_nanos(), 1_000_000_000);
//! assert!(tug.engaged_at().is_some());
//! # Ok::<(), bywire_sim::tug::TugError>(())
//! ```

pub mod attacker;
pub mod battery;
pub mod bus;
pub mod campaign;
pub mod chassis;
pub mod drive;
pub mod event;
pub mod fail_operational;
pub mod fault;
pub mod mission;
pub mod nodes;
pub mod output;
pub mod record;
pub mod report;
pub mod rng;
pub mod scenario;
pub mod steering;
pub mod sweep;
pub mod truth;
pub mod tug;
pub mod vehicle;
