//! Vehicles as the commands find and run them: profiles by name or file, and the simulated
//! vehicle on in-process buses beside a bridge.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::thread::JoinHandle;

use anyhow::{bail, Context, Result};
use bywire_bus::runner::{Flow, Runner};
use bywire_core::node::Port;
use bywire_secoc::keys::KeyFile;
use bywire_secoc::store::FreshnessStore;
use bywire_sim::vehicle::SimulatedVehicle;
use bywire_vehicle::profile::LoadedProfile;
use bywire_vehicle::redundancy::Channel;
use bywire_vehicle::secured::Secured;
use bywire_vehicle::wire::ProfileWire;

/// A profile's wire, secured when it declares `[secoc]`.
pub type Wire = Secured<ProfileWire>;

/// What a secured wire's receivers made of the frames they verified (accepted, and each
/// reason a frame was rejected: a wrong MAC, a stale or too-far freshness, a malformed frame)
/// and its freshness syncs, for status lines; `null` for an unsecured profile.
pub fn secoc_counts(wire: &Wire) -> serde_json::Value {
    let Some(table) = wire.table() else {
        return serde_json::Value::Null;
    };
    let s = table.stats();
    serde_json::json!({
        "accepted": s.frames.accepted,
        "rejected": s.frames.rejected(),
        "mac": s.frames.mac,
        "stale": s.frames.stale,
        "window": s.frames.window,
        "malformed": s.frames.malformed,
        "syncs_taken": s.syncs_taken,
        "syncs_refused": s.syncs_refused,
        "syncs_sent": s.syncs_sent,
    })
}
type Vehicle = SimulatedVehicle<Wire>;

/// Freshness values a store reserves at a time (one write per this many frames); within the
/// window a profile's receivers accept by default.
const FRESHNESS_STEP: u64 = 256;

/// SecOC for a profile that declares `[secoc]`.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct SecOcArgs {
    /// The key file of a profile that declares [secoc]: 32 hex digits per key id, readable by
    /// its owner only. Without it such a profile is refused (never run unauthenticated).
    #[arg(long, value_name = "KEYFILE")]
    pub key_file: Option<std::path::PathBuf>,
    /// Where this side keeps its freshness across restarts, so that a restart is no rewind
    /// (without it the other side refuses the first frames as stale, then resynchronises it).
    #[arg(long, value_name = "FILE", requires = "key_file")]
    pub freshness_file: Option<std::path::PathBuf>,
}

impl SecOcArgs {
    /// The profile's wire with these keys, and the freshness store if one was given.
    pub fn wire(&self, profile: &LoadedProfile) -> Result<(Wire, Option<FreshnessStore>)> {
        let keys = match &self.key_file {
            Some(path) => Some(KeyFile::load(path).context("--key-file")?),
            None => None,
        };
        let (store, next) = match &self.freshness_file {
            Some(path) => {
                let (store, next) =
                    FreshnessStore::open(path, FRESHNESS_STEP).context("--freshness-file")?;
                (Some(store), next)
            }
            None => (None, 1),
        };
        let wire = profile
            .wire_with_keys(keys.as_ref(), next)
            .with_context(|| format!("--profile {}", profile.profile.name))?;
        Ok((wire, store))
    }
}

/// Reserve in `store` what `wire` signs next; `Err` with why the store cannot keep it.
pub fn keep_freshness(store: &mut Option<FreshnessStore>, wire: &Wire) -> Result<(), String> {
    match (store.as_mut(), wire.table()) {
        (Some(store), Some(table)) => table.reserve_in(store).map_err(|e| e.to_string()),
        _ => Ok(()),
    }
}

/// The command buses given on the command line, each on its port (bus A on port A, the
/// redundant bus B, if given, on port B), plain names as SocketCAN.
pub fn command_buses(bus: &str, bus2: Option<&String>) -> Vec<(Port, String)> {
    // Both ends give their command buses the same ports (the ADS side and the supervisor).
    [
        (Channel::A.port(), Some(bus)),
        (Channel::B.port(), bus2.map(String::as_str)),
    ]
    .into_iter()
    .filter_map(|(port, spec)| spec.map(|s| (port, crate::support::busarg::full_spec(s))))
    .collect()
}

/// A shipped profile by name, or a profile file; it must describe a vehicle to command.
pub fn load_profile(name: &str) -> Result<LoadedProfile> {
    let loaded = bywire_tug::named_or_file(name, std::path::Path::new(""))?;
    if loaded.profile.command.is_none() || loaded.profile.state.is_none() {
        bail!("--profile {name}: no [command] section (the autoware-can profile is an output format, not a vehicle to bridge)");
    }
    Ok(loaded)
}

pub fn endpoints(specs: &[(Port, String)]) -> Result<Vec<(Port, Box<dyn bywire_bus::Bus>)>> {
    specs
        .iter()
        .map(|(port, spec)| {
            Ok((
                *port,
                bywire_bus::open(spec).with_context(|| format!("bus {spec}"))?,
            ))
        })
        .collect()
}

/// The vehicle on its own thread over in-process buses (`bridge --with-vehicle`), until `stop`.
pub fn spawn_in_process(
    specs: &[(Port, String)],
    profile: &LoadedProfile,
    wire: Wire,
    stop: &Arc<AtomicBool>,
) -> Result<JoinHandle<()>> {
    for (_, spec) in specs {
        let parsed: bywire_bus::BusSpec = spec.parse()?;
        if !matches!(
            parsed,
            bywire_bus::BusSpec::Virtual { .. } | bywire_bus::BusSpec::Sim { .. }
        ) {
            bail!("--with-vehicle needs in-process buses (virtual: or sim:), not {spec}; run `bywire vehicle` beside the bridge instead");
        }
    }
    let mut vehicle = Vehicle::from_profile(profile, wire, specs.len() > 1);
    let mut runner = Runner::new(endpoints(specs)?);
    let stop = Arc::clone(stop);
    Ok(std::thread::spawn(move || {
        let _ = runner.run(&mut vehicle, &stop, None, &mut |_: &mut Vehicle, _| {
            Flow::Continue
        });
    }))
}
