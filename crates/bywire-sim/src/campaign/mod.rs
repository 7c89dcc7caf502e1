//! Fault-injection campaigns: a TOML file declares fault classes (with their parameters and
//! the mechanism expected to detect each, the reaction and their time bounds), the vehicle
//! profiles and the operating states; [`Campaign::cells`] expands every combination, [`run`]
//! runs each cell on the simulated runner (deterministic, on several threads) and judges it,
//! and [`report`] writes the results as JUnit XML, JSON and a coverage matrix (Markdown and
//! HTML) of fault classes against mechanisms.
//!
//! A cell is one profile's vehicle — its real supervisor reading its wire, in front of the
//! simple plant of [`crate::vehicle`] — with a fault-injecting ADS, the vehicle's safety
//! controller and an intruder on one or two bit-timed buses ([`rig`]); or (`model = "tug"`)
//! the whole simulated tug, for the faults of its fail-operational layers. It is brought to its
//! operating state, the fault is injected, and for the observation window every millisecond
//! says which mechanisms have noticed something and what the vehicle does. A cell passes when
//! the expected mechanism detects the fault in time, the vehicle's most severe reaction is the
//! one expected (reached in time), and the actuators never leave the vehicle's limits.
//!
//! ```toml
//! name = "smoke"
//! states = ["cruising", "manual"]
//!
//! [[profile]]
//! name = "reference-tug"      # a built-in profile, or a file relative to the campaign's
//! buses = 2                   # the command on two buses, voted
//!
//! [[fault]]
//! class = "checksum-corrupted"
//! mechanism = "e2e"
//! reaction = "none"
//! detect_ms = 30
//! requirements = ["REQ-E2E-CHECKSUM"]
//!
//! [[fault]]
//! class = "node-silent"
//! mechanism = "timeout"
//! reaction = "safe-stop"
//! detect_ms = 60
//! react_ms = 140
//! states.manual = { reaction = "none" }   # per-state overrides (or `skip = "why"`)
//! ```

pub mod report;
pub mod rig;
mod tug_cell;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use serde::{Deserialize, Serialize};

use bywire_vehicle::mechanism::{Mechanism, Mechanisms};

use bywire_core::FileError;

/// A campaign as its file declares it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Campaign {
    /// Its name (the JUnit suite's).
    pub name: String,
    /// The seed of every cell's random numbers (jitter).
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// When the fault is injected, ms after start (the state reached well before).
    #[serde(default = "default_inject")]
    pub inject_at_ms: u64,
    /// How long after the injection a cell is watched, ms (a fault may say otherwise).
    #[serde(default = "default_observe")]
    pub observe_ms: u64,
    /// The operating states to run every fault in.
    pub states: Vec<State>,
    /// The vehicles.
    #[serde(rename = "profile")]
    pub profiles: Vec<ProfileEntry>,
    /// The faults.
    #[serde(rename = "fault")]
    pub faults: Vec<FaultEntry>,
    /// Where the file is (profiles named by path are found relative to it).
    #[serde(skip)]
    pub dir: PathBuf,
}

fn default_seed() -> u64 {
    1
}
fn default_inject() -> u64 {
    2_000
}
fn default_observe() -> u64 {
    1_500
}

/// A vehicle a campaign runs on.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProfileEntry {
    /// A built-in profile, or a profile file (relative to the campaign file).
    pub name: String,
    /// Its name in reports (the profile's by default).
    #[serde(default)]
    pub label: Option<String>,
    /// Command buses: 1, or 2 with the copies voted.
    #[serde(default = "one")]
    pub buses: u8,
    /// Secure the profile's messages as this `[secoc]` section says, with a simulation-only
    /// test key (`test_key`, 32 hex digits) in place of a key file.
    #[serde(default)]
    pub secoc: Option<toml::Table>,
    /// What runs behind the supervisor.
    #[serde(default)]
    pub model: Model,
}

/// What a profile's cells run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Model {
    /// The profile's supervisor in front of the simple plant, with a fault-injecting ADS:
    /// any profile, every operating state.
    #[default]
    Plant,
    /// The whole simulated tug (`reference-tug` or `reference-tug-redundant`): its ECU or
    /// ECU pair, CANopen drives, electrohydraulic steering and its own ADS driving the
    /// service road; for the faults of its layers (sensors, ECUs, steering actuators), while
    /// cruising.
    Tug,
}

fn one() -> u8 {
    1
}

impl ProfileEntry {
    /// Its name in reports.
    pub fn label(&self) -> &str {
        self.label.as_deref().unwrap_or(&self.name)
    }
}

/// An operating state a fault is injected in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum State {
    /// The ADS connected and sending, a driver driving (after a takeover).
    Manual,
    /// Autonomous, straight ahead at 2 m/s.
    Cruising,
    /// Autonomous at 2 m/s, turning.
    Turning,
    /// Stopped with the E-stop latched (pressed and released; no operator reset).
    EstopLatched,
    /// Autonomous at 2 m/s with redundancy already lost: one command bus cut, or (one bus)
    /// a fault the profile's degradation rules make a degraded level.
    Degraded,
}

impl State {
    /// Where the vehicle already is in this state, on the reactions' scale.
    pub fn reaction(self) -> Reaction {
        match self {
            State::Manual => Reaction::Manual,
            State::Cruising | State::Turning => Reaction::None,
            State::EstopLatched => Reaction::Estop,
            State::Degraded => Reaction::Degraded,
        }
    }

    /// Its name in files and reports.
    pub fn name(self) -> &'static str {
        match self {
            State::Manual => "manual",
            State::Cruising => "cruising",
            State::Turning => "turning",
            State::EstopLatched => "estop-latched",
            State::Degraded => "degraded",
        }
    }
}

/// The fault classes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FaultClass {
    /// The ADS's command frames meet bit errors on the wire (`count` transmissions).
    BitError,
    /// The same, stuff errors.
    StuffError,
    /// The same, CRC errors.
    CrcError,
    /// The ADS's command frames are lost before the wire (`duration_ms`).
    FrameDropped,
    /// They leave `delay_ms` late.
    Delayed,
    /// Each is sent twice.
    Duplicated,
    /// An intruder re-sends command frames recorded a second earlier.
    Replayed,
    /// The ADS's counter skips values once.
    CounterSkipped,
    /// The ADS's counter stops (`duration_ms`).
    CounterFrozen,
    /// The ADS's checksum is wrong (`duration_ms`).
    ChecksumCorrupted,
    /// A node floods the bus with identifier `id` (0x000 by default).
    BabblingIdiot,
    /// The ADS's controller goes bus-off (a broken transceiver) and recovers.
    BusOff,
    /// The second command bus is cut.
    RedundantBusLost,
    /// The ADS falls silent.
    NodeSilent,
    /// The ADS's clock runs `percent` slow.
    ClockDrift,
    /// The ADS's cycle varies by up to `jitter_ms` either way.
    Jitter,
    /// A setpoint (`signal`: steering or velocity) beyond the vehicle's limit, as far as its
    /// signal carries.
    OutOfRange,
    /// A setpoint that is not a number (where the signal is a float).
    NonFinite,
    /// An intruder sends commands of its own (secured profiles: without the key).
    Forged,
    /// The safety controller's E-stop is pressed.
    Estop,
    /// A driver turns the steering wheel.
    DriverTakeover,
    /// One of the redundant tug's further angle sensors fails (`corner`, `module` B or C,
    /// `sensor`: stuck, drift or silent, with `value`).
    AngleSensor,
    /// One of the redundant tug's control ECUs (`side` A or B) falls silent.
    EcuSilent,
    /// One computes wrongly (a steering setpoint 5° off).
    EcuWrongOutput,
    /// One floods bus 1 until its partner fences it.
    EcuBabble,
    /// A corner's steering actuator (`corner`; `backup` for the backup valve) fails as
    /// `failure` says: stuck, runaway or drive-lost.
    SteeringActuator,
}

impl FaultClass {
    /// Every class, in report order.
    pub const ALL: [FaultClass; 26] = [
        FaultClass::BitError,
        FaultClass::StuffError,
        FaultClass::CrcError,
        FaultClass::FrameDropped,
        FaultClass::Delayed,
        FaultClass::Duplicated,
        FaultClass::Replayed,
        FaultClass::CounterSkipped,
        FaultClass::CounterFrozen,
        FaultClass::ChecksumCorrupted,
        FaultClass::BabblingIdiot,
        FaultClass::BusOff,
        FaultClass::RedundantBusLost,
        FaultClass::NodeSilent,
        FaultClass::ClockDrift,
        FaultClass::Jitter,
        FaultClass::OutOfRange,
        FaultClass::NonFinite,
        FaultClass::Forged,
        FaultClass::Estop,
        FaultClass::DriverTakeover,
        FaultClass::AngleSensor,
        FaultClass::EcuSilent,
        FaultClass::EcuWrongOutput,
        FaultClass::EcuBabble,
        FaultClass::SteeringActuator,
    ];

    /// Its name in files and reports.
    pub fn name(self) -> &'static str {
        match self {
            FaultClass::BitError => "bit-error",
            FaultClass::StuffError => "stuff-error",
            FaultClass::CrcError => "crc-error",
            FaultClass::FrameDropped => "frame-dropped",
            FaultClass::Delayed => "delayed",
            FaultClass::Duplicated => "duplicated",
            FaultClass::Replayed => "replayed",
            FaultClass::CounterSkipped => "counter-skipped",
            FaultClass::CounterFrozen => "counter-frozen",
            FaultClass::ChecksumCorrupted => "checksum-corrupted",
            FaultClass::BabblingIdiot => "babbling-idiot",
            FaultClass::BusOff => "bus-off",
            FaultClass::RedundantBusLost => "redundant-bus-lost",
            FaultClass::NodeSilent => "node-silent",
            FaultClass::ClockDrift => "clock-drift",
            FaultClass::Jitter => "jitter",
            FaultClass::OutOfRange => "out-of-range",
            FaultClass::NonFinite => "non-finite",
            FaultClass::Forged => "forged",
            FaultClass::Estop => "estop",
            FaultClass::DriverTakeover => "driver-takeover",
            FaultClass::AngleSensor => "angle-sensor",
            FaultClass::EcuSilent => "ecu-silent",
            FaultClass::EcuWrongOutput => "ecu-wrong-output",
            FaultClass::EcuBabble => "ecu-babble",
            FaultClass::SteeringActuator => "steering-actuator",
        }
    }
}

/// What the vehicle does, from least to most severe; a cell's reaction is the most severe
/// reached after the injection, if it is beyond where the operating state already was.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Reaction {
    /// Nothing changes: the fault was refused or masked.
    None,
    /// The ADS drives on with less redundancy or tighter limits.
    Degraded,
    /// The minimal-risk manoeuvre: on at the tightest limits to the next safe stop point.
    MinimalRisk,
    /// The watchdog holds the last command.
    Hold,
    /// The watchdog decelerates under control.
    Decelerate,
    /// A driver has the vehicle; the ADS's setpoints are ignored.
    Manual,
    /// Full braking, motors and steering off.
    SafeStop,
    /// The E-stop latched: full braking until an operator resets it.
    Estop,
}

impl Reaction {
    /// Its name in files and reports.
    pub fn name(self) -> &'static str {
        match self {
            Reaction::None => "none",
            Reaction::Degraded => "degraded",
            Reaction::MinimalRisk => "minimal-risk",
            Reaction::Hold => "hold",
            Reaction::Decelerate => "decelerate",
            Reaction::Manual => "manual",
            Reaction::SafeStop => "safe-stop",
            Reaction::Estop => "estop",
        }
    }

    /// Its rank: a driver in control and full braking are alike to the ADS (it no longer
    /// drives), so a fault of the ADS in the manual state asks no further reaction.
    pub fn severity(self) -> u8 {
        match self {
            Reaction::None => 0,
            Reaction::Degraded => 1,
            Reaction::MinimalRisk => 2,
            Reaction::Hold => 3,
            Reaction::Decelerate => 4,
            Reaction::Manual | Reaction::SafeStop => 5,
            Reaction::Estop => 6,
        }
    }
}

/// A fault class with its parameters and expectations.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultEntry {
    /// The class.
    pub class: FaultClass,
    /// A name for it when a campaign has the class more than once.
    #[serde(default)]
    pub label: Option<String>,
    /// Transmissions destroyed (wire errors), default 1.
    #[serde(default)]
    pub count: Option<u32>,
    /// How long the fault lasts, ms (default: the whole observation).
    #[serde(default)]
    pub duration_ms: Option<u64>,
    /// How long the fault lasts in the profile's command cycles (in place of `duration_ms`).
    #[serde(default)]
    pub cycles: Option<u32>,
    /// Lateness of delayed frames, ms.
    #[serde(default)]
    pub delay_ms: Option<u64>,
    /// How much slower the ADS's clock runs, %.
    #[serde(default)]
    pub percent: Option<f64>,
    /// Largest jitter either way, ms.
    #[serde(default)]
    pub jitter_ms: Option<u64>,
    /// The setpoint an out-of-range or non-finite fault puts in: `steering` or `velocity`.
    #[serde(default)]
    pub signal: Option<String>,
    /// A babbling node's identifier.
    #[serde(default)]
    pub id: Option<u16>,
    /// The corner a sensor or actuator fault hits: 0 FL … 3 RR.
    #[serde(default)]
    pub corner: Option<usize>,
    /// The sensor module: "B" or "C".
    #[serde(default)]
    pub module: Option<String>,
    /// How a sensor fails: "stuck", "drift" or "silent".
    #[serde(default)]
    pub sensor: Option<String>,
    /// The stuck angle (degrees) or drift rate (degrees per second).
    #[serde(default)]
    pub value: Option<f64>,
    /// The control ECU: "A" or "B".
    #[serde(default)]
    pub side: Option<String>,
    /// The backup actuator, not the primary.
    #[serde(default)]
    pub backup: bool,
    /// How an actuator fails: "stuck", "runaway" or "drive-lost".
    #[serde(default)]
    pub failure: Option<String>,
    /// How long this fault's cells are watched after the injection, ms.
    #[serde(default)]
    pub observe_ms: Option<u64>,
    /// What its cells expect.
    #[serde(flatten)]
    pub expect: Expectation,
    /// Overrides per profile (by its label), or per profile in one state (`label/state`,
    /// applied last).
    #[serde(default)]
    pub profiles: BTreeMap<String, Override>,
    /// Overrides per operating state (applied after the profile's).
    #[serde(default)]
    pub states: BTreeMap<State, Override>,
    /// The requirement ids its cells verify.
    #[serde(default)]
    pub requirements: Vec<String>,
}

impl FaultEntry {
    /// Its name in reports: its label, or its class's name.
    pub fn name(&self) -> &str {
        self.label.as_deref().unwrap_or(self.class.name())
    }

    /// How long it lasts on a vehicle commanding every `cycle` (`None`: the whole
    /// observation).
    pub fn duration(&self, cycle: core::time::Duration) -> Option<core::time::Duration> {
        match (self.duration_ms, self.cycles) {
            (Some(ms), _) => Some(core::time::Duration::from_millis(ms)),
            (None, Some(cycles)) => Some(cycle.saturating_mul(cycles)),
            (None, None) => None,
        }
    }
}

/// What a fault's cells expect. A bound is given in ms or in the profile's command cycles
/// (five cycles when neither is).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Expectation {
    /// The mechanism that must detect it (`none`: no mechanism needs to).
    #[serde(with = "mechanism_name")]
    pub mechanism: Option<Mechanism>,
    /// The reaction.
    pub reaction: Reaction,
    /// Bound on the detection, ms after the injection.
    #[serde(default)]
    pub detect_ms: Option<u64>,
    /// Bound on the detection, command cycles after the injection.
    #[serde(default)]
    pub detect_cycles: Option<f64>,
    /// Bound on the reaction, ms after the injection.
    #[serde(default)]
    pub react_ms: Option<u64>,
    /// Bound on the reaction, command cycles after the injection.
    #[serde(default)]
    pub react_cycles: Option<f64>,
}

/// Cycles a bound is when the campaign gives none.
const DEFAULT_BOUND_CYCLES: f64 = 5.0;

impl Expectation {
    /// The detection bound, ms, for a profile commanding every `cycle`.
    pub fn detect_bound(&self, cycle: core::time::Duration) -> f64 {
        bound(self.detect_ms, self.detect_cycles, cycle)
    }

    /// The reaction bound, ms.
    pub fn react_bound(&self, cycle: core::time::Duration) -> f64 {
        bound(self.react_ms, self.react_cycles, cycle)
    }
}

fn bound(ms: Option<u64>, cycles: Option<f64>, cycle: core::time::Duration) -> f64 {
    let cycle_ms = cycle.as_secs_f64() * 1e3;
    match (ms, cycles) {
        (Some(ms), _) => ms as f64,
        (None, Some(c)) => c * cycle_ms,
        (None, None) => DEFAULT_BOUND_CYCLES * cycle_ms,
    }
}

/// A fault's expectations changed in one operating state, or the state skipped.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Override {
    /// The mechanism (`none`: none needs to detect it).
    #[serde(default, with = "optional_mechanism_name")]
    pub mechanism: Option<Option<Mechanism>>,
    /// The reaction.
    #[serde(default)]
    pub reaction: Option<Reaction>,
    /// The detection bound, ms.
    #[serde(default)]
    pub detect_ms: Option<u64>,
    /// The detection bound, cycles.
    #[serde(default)]
    pub detect_cycles: Option<f64>,
    /// The reaction bound, ms.
    #[serde(default)]
    pub react_ms: Option<u64>,
    /// The reaction bound, cycles.
    #[serde(default)]
    pub react_cycles: Option<f64>,
    /// Not applicable in this state, for this reason.
    #[serde(default)]
    pub skip: Option<String>,
}

mod mechanism_name {
    use super::Mechanism;
    use serde::{de::Error, Deserialize, Deserializer, Serializer};

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Mechanism>, D::Error> {
        let name = String::deserialize(d)?;
        parse(&name).map_err(D::Error::custom)
    }

    pub fn serialize<S: Serializer>(m: &Option<Mechanism>, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(m.map_or("none", Mechanism::name))
    }

    pub fn parse(name: &str) -> Result<Option<Mechanism>, String> {
        if name == "none" {
            return Ok(None);
        }
        Mechanism::from_name(name).map(Some).ok_or_else(|| {
            let known: Vec<&str> = Mechanism::ALL.iter().map(|m| m.name()).collect();
            format!("'{name}' is no mechanism (none, {})", known.join(", "))
        })
    }
}

mod optional_mechanism_name {
    use super::Mechanism;
    use serde::{de::Error, Deserialize, Deserializer};

    pub fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Option<Option<Mechanism>>, D::Error> {
        let name = String::deserialize(d)?;
        super::mechanism_name::parse(&name)
            .map(Some)
            .map_err(D::Error::custom)
    }
}

/// Why a campaign cannot run.
#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    /// The file, or what it names.
    #[error(transparent)]
    File(#[from] FileError),
    /// A profile it names.
    #[error("profile '{name}': {reason}")]
    Profile {
        /// The profile.
        name: String,
        /// Why.
        reason: String,
    },
}

impl Campaign {
    /// A campaign file.
    pub fn load(path: &Path) -> Result<Campaign, CampaignError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| FileError::syntax(&file, e))?;
        let mut campaign = Campaign::parse(&file, &text)?;
        campaign.dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Ok(campaign)
    }

    /// A campaign from its text (`file` names it in errors).
    pub fn parse(file: &str, text: &str) -> Result<Campaign, CampaignError> {
        let campaign: Campaign = toml::from_str(text).map_err(|e| FileError::syntax(file, e))?;
        let invalid = |key: String, reason: &str| FileError::invalid(file, &key, reason);
        if campaign.states.is_empty() {
            return Err(invalid("states".into(), "name at least one operating state").into());
        }
        if campaign.profiles.is_empty() {
            return Err(invalid("profile".into(), "name at least one [[profile]]").into());
        }
        for (i, p) in campaign.profiles.iter().enumerate() {
            if !(1..=2).contains(&p.buses) {
                return Err(invalid(format!("profile[{i}].buses"), "1 or 2").into());
            }
        }
        let mut names = std::collections::BTreeSet::new();
        for (i, f) in campaign.faults.iter().enumerate() {
            if !names.insert(f.name().to_string()) {
                return Err(invalid(
                    format!("fault[{i}]"),
                    "a class given twice needs a distinct label",
                )
                .into());
            }
        }
        Ok(campaign)
    }

    /// Every cell: profiles × states × faults, in that order. A cell expects its fault's
    /// expectations with the profile's overrides, then the state's, then the profile's in
    /// that state; and no reaction where
    /// the state is already at least as severe as the one expected (a latched E-stop
    /// cannot be made to stop harder; an ADS that no longer drives cannot lose control).
    pub fn cells(&self) -> Vec<Cell> {
        let mut cells = Vec::new();
        for (profile, p) in self.profiles.iter().enumerate() {
            for &state in &self.states {
                for (fault, entry) in self.faults.iter().enumerate() {
                    let mut expect = entry.expect;
                    let mut skip = None;
                    let both = format!("{}/{}", p.label(), state.name());
                    let overrides = [
                        entry.profiles.get(p.label()),
                        entry.states.get(&state),
                        entry.profiles.get(&both),
                    ];
                    for o in overrides.into_iter().flatten() {
                        expect.mechanism = o.mechanism.unwrap_or(expect.mechanism);
                        expect.reaction = o.reaction.unwrap_or(expect.reaction);
                        if o.detect_ms.is_some() || o.detect_cycles.is_some() {
                            (expect.detect_ms, expect.detect_cycles) =
                                (o.detect_ms, o.detect_cycles);
                        }
                        if o.react_ms.is_some() || o.react_cycles.is_some() {
                            (expect.react_ms, expect.react_cycles) = (o.react_ms, o.react_cycles);
                        }
                        skip = o.skip.clone().or(skip);
                    }
                    if expect.reaction.severity() <= state.reaction().severity() {
                        expect.reaction = Reaction::None;
                    }
                    cells.push(Cell {
                        profile,
                        state,
                        fault,
                        expect,
                        skip,
                    });
                }
            }
        }
        cells
    }
}

/// One combination to run.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    /// Index of its profile in the campaign.
    pub profile: usize,
    /// Its operating state.
    pub state: State,
    /// Index of its fault in the campaign.
    pub fault: usize,
    /// What it expects, overrides applied.
    pub expect: Expectation,
    /// Not applicable in this state, as the campaign says.
    pub skip: Option<String>,
}

/// How a cell ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// Everything expected happened, in time.
    Pass,
    /// Something expected did not, or something forbidden did.
    Fail,
    /// The fault does not apply to this profile or state (the reason says why).
    NotApplicable,
}

/// A detection: which mechanism, how long after the injection.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Detection {
    /// The mechanism.
    #[serde(with = "mechanism_name")]
    pub mechanism: Option<Mechanism>,
    /// When, ms after the injection.
    pub ms: f64,
}

/// What a cell gave.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CellResult {
    /// `profile/state/fault/mechanism`.
    pub name: String,
    /// The profile's label.
    pub profile: String,
    /// The operating state.
    pub state: State,
    /// The fault's name.
    pub fault: String,
    /// Its class.
    pub class: FaultClass,
    /// What was expected.
    pub expected: Expectation,
    /// Every mechanism that noticed something, first time each.
    pub detected_by: Vec<Detection>,
    /// The reaction observed.
    pub reaction: Reaction,
    /// When it was reached, ms after the injection.
    pub reaction_ms: Option<f64>,
    /// The verdict.
    pub verdict: Verdict,
    /// Why it failed, or why it does not apply; empty on a pass.
    pub why: String,
    /// Requirements it verifies.
    pub requirements: Vec<String>,
    /// Wall time the cell took, seconds.
    pub wall_seconds: f64,
}

/// The cell's name: `profile/state/fault/mechanism`.
pub fn cell_name(profile: &str, state: State, fault: &str, m: Option<Mechanism>) -> String {
    format!(
        "{profile}/{}/{fault}/{}",
        state.name(),
        m.map_or("none", Mechanism::name)
    )
}

/// Run every cell of `campaign` on `jobs` threads with the mechanisms `disabled` switched
/// off; `done` is told of each result as it comes (one at a time). The results in the
/// cells' order.
pub fn run(
    campaign: &Campaign,
    jobs: usize,
    disabled: Mechanisms,
    done: &(dyn Fn(&CellResult) + Sync),
) -> Result<Vec<CellResult>, CampaignError> {
    let vehicles = campaign
        .profiles
        .iter()
        .map(|p| rig::Vehicle::load(p, &campaign.dir, disabled))
        .collect::<Result<Vec<_>, _>>()?;
    let cells = campaign.cells();
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<CellResult>>> = Mutex::new(vec![None; cells.len()]);
    std::thread::scope(|scope| {
        for _ in 0..jobs.clamp(1, cells.len().max(1)) {
            scope.spawn(|| loop {
                let index = next.fetch_add(1, Ordering::Relaxed);
                let Some(cell) = cells.get(index) else { break };
                let Some(vehicle) = vehicles.get(cell.profile) else {
                    break;
                };
                let result = rig::run_cell(campaign, vehicle, cell);
                if let Ok(mut results) = results.lock() {
                    done(&result);
                    if let Some(slot) = results.get_mut(index) {
                        *slot = Some(result);
                    }
                }
            });
        }
    });
    Ok(results
        .into_inner()
        .unwrap_or_default()
        .into_iter()
        .flatten()
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = r#"
name = "t"
states = ["cruising", "manual"]
[[profile]]
name = "reference-tug"
[[fault]]
class = "checksum-corrupted"
mechanism = "e2e"
reaction = "none"
requirements = ["REQ-X"]
states.manual = { skip = "not here" }
[[fault]]
class = "node-silent"
mechanism = "timeout"
reaction = "safe-stop"
react_ms = 140
states.manual = { reaction = "none", mechanism = "none" }
"#;

    #[test]
    fn a_campaign_expands_profiles_states_and_faults_with_their_overrides() {
        let c = Campaign::parse("t.toml", SMALL).unwrap();
        let cells = c.cells();
        assert_eq!(cells.len(), 4);
        let silent_manual = &cells[3];
        assert_eq!(silent_manual.state, State::Manual);
        assert_eq!(silent_manual.expect.reaction, Reaction::None);
        assert_eq!(silent_manual.expect.mechanism, None);
        assert_eq!(silent_manual.expect.react_ms, Some(140));
        // The cruising cell expects the safe stop; in manual it would be none anyway.
        assert_eq!(cells[1].expect.reaction, Reaction::SafeStop);
        assert_eq!(cells[2].skip.as_deref(), Some("not here"));
        assert_eq!(cells[1].expect.mechanism, Some(Mechanism::Timeout));
    }

    #[test]
    fn a_bad_campaign_names_where() {
        let bad = SMALL.replace("mechanism = \"e2e\"", "mechanism = \"crc\"");
        let err = Campaign::parse("t.toml", &bad).unwrap_err().to_string();
        assert!(
            err.contains("t.toml") && err.contains("'crc' is no mechanism"),
            "{err}"
        );
        let twice = format!("{SMALL}\n[[fault]]\nclass = \"node-silent\"\nmechanism = \"timeout\"\nreaction = \"hold\"\n");
        let err = Campaign::parse("t.toml", &twice).unwrap_err().to_string();
        assert!(
            err.contains("fault[2]") && err.contains("distinct label"),
            "{err}"
        );
        let buses = SMALL.replace(
            "name = \"reference-tug\"",
            "name = \"reference-tug\"\nbuses = 3",
        );
        let err = Campaign::parse("t.toml", &buses).unwrap_err().to_string();
        assert!(err.contains("profile[0].buses"), "{err}");
    }
}
