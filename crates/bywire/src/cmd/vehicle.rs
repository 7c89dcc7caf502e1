//! `bywire vehicle`: a simulated vehicle for any profile on any bus — the real supervisor with
//! the profile's wire in front of a plant (`bywire_sim::vehicle`), on the real-time runner.
//! Status lines (JSON) go to stdout at `--rate`.

use std::io::Write;
use std::time::Duration;

use crate::support::interrupt::interrupt_flag;
use crate::support::vehicles::{keep_freshness, SecOcArgs, Wire};
use anyhow::{anyhow, Result};
use bywire_bus::runner::{Flow, Hooks, Runner};
use bywire_bus::BusError;
use bywire_core::node::Port;
use bywire_core::Timestamp;
use bywire_sim::vehicle::SimulatedVehicle;
use bywire_vehicle::supervisor::Supervisor;
use serde_json::json;

#[derive(clap::Args)]
#[command(
    after_help = "The vehicle fails closed: it brakes until it has seen a run of valid commands and an\n\
engage request. An E-stop frame (the profile's [estop] message) latches it until the operator\n\
reset sequence. With BUS2 the commands are voted on across both buses; one lost degrades.\n\n\
Examples:\n  bywire vehicle --profile reference-tug vcan0\n  \
bywire vehicle --profile reference-tug socketcand:127.0.0.1:29536/vcan0\n  \
bywire vehicle --profile ./my-vehicle.toml sim:demo@500000 sim:demo-b@500000 --rate 5"
)]
pub struct Args {
    /// A shipped profile (reference-tug) or a profile file.
    #[arg(long)]
    profile: String,
    /// The command bus.
    bus: String,
    /// A redundant second command bus.
    bus2: Option<String>,
    /// Status lines per second on stdout (0: none).
    #[arg(long, default_value_t = 1.0, value_parser = crate::support::numbers::rate_or_off)]
    rate: f64,
    /// Stop after this many seconds (default: until interrupted).
    #[arg(long, value_parser = crate::support::numbers::positive_seconds)]
    duration: Option<f64>,
    #[command(flatten)]
    secoc: SecOcArgs,
}

type Vehicle = SimulatedVehicle<Wire>;

/// Status lines and lost buses, for the vehicle's run.
struct Status<'a> {
    out: Option<&'a mut dyn Write>,
    period: Option<Duration>,
    next: Timestamp,
    /// Where the secured wire's freshness is kept.
    freshness: Option<bywire_secoc::store::FreshnessStore>,
}

impl Hooks<Vehicle> for Status<'_> {
    fn after_poll(&mut self, vehicle: &mut Vehicle, now: Timestamp) -> Flow {
        if let Err(why) = keep_freshness(&mut self.freshness, vehicle.supervisor().wire()) {
            // Its next frames could not be kept: stop sending (the ADS sees the vehicle go).
            let _ = writeln!(std::io::stderr(), "bywire vehicle: {why}; stopping");
            return Flow::Stop;
        }
        let (Some(out), Some(period)) = (self.out.as_mut(), self.period) else {
            return Flow::Continue;
        };
        if now < self.next {
            return Flow::Continue;
        }
        self.next = self.next.saturating_add(period).max(now);
        let s = vehicle.supervisor();
        let plant = vehicle.plant();
        let stats = s.stats();
        let line = json!({
            "t_s": now.as_nanos() as f64 / 1e9,
            "mode": s.mode().name().to_lowercase(),
            "watchdog": s.watchdog().level().to_string(),
            "estop": s.estop().code().to_string(),
            "degraded": s.degraded().map(|c| format!("{c:?}")),
            "speed": plant.speed,
            "steering": plant.steering,
            "distance": plant.distance,
            "accepted": stats.accepted,
            "rejected": stats.rejected(),
            "secoc": crate::support::vehicles::secoc_counts(s.wire()),
        });
        // A closed stdout ends the status lines, not the vehicle.
        if writeln!(out, "{line}").and_then(|()| out.flush()).is_err() {
            self.out = None;
        }
        Flow::Continue
    }

    fn wake_at(&self) -> Option<Timestamp> {
        self.out.as_ref().and(self.period).map(|_| self.next)
    }

    fn bus_lost(&mut self, _: &mut Vehicle, _: Timestamp, port: Port, error: &BusError) {
        let which = if port == Supervisor::<Wire>::PORT_A {
            "A"
        } else {
            "B"
        };
        let _ = writeln!(
            std::io::stderr(),
            "bywire vehicle: bus {which} lost: {error}; going on with the other"
        );
    }
}

/// Run the vehicle until interrupted or `--duration` has passed.
pub fn run(args: &Args, out: &mut dyn Write) -> Result<()> {
    let limit = args.duration.map(Duration::from_secs_f64);
    let profile = crate::support::vehicles::load_profile(&args.profile)?;
    let (wire, freshness) = args.secoc.wire(&profile)?;
    let specs = crate::support::vehicles::command_buses(&args.bus, args.bus2.as_ref());
    let mut vehicle = Vehicle::from_profile(&profile, wire, specs.len() > 1);
    let mut runner = Runner::new(crate::support::vehicles::endpoints(&specs)?);
    let mut status = Status {
        out: Some(out),
        period: (args.rate > 0.0).then(|| Duration::from_secs_f64(1.0 / args.rate)),
        next: Timestamp::ZERO,
        freshness,
    };
    let stop = interrupt_flag();
    let result = runner.run(&mut vehicle, &stop, limit, &mut status);
    result.map_err(|e| anyhow!("every bus lost (last: {e})"))?;
    Ok(())
}
