//! `bywire check`: the vehicle acceptance checks against a vehicle on a bus (in real time), or
//! against the simulated tug (`tug`, in simulated time, optionally with a fault).

use std::io::Write;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use bywire_bus::runner;
use bywire_sim::fault::Fault;
use bywire_sim::steering::SensorFault;
use bywire_sim::tug::{OnBothCommandBuses, Tug, TugParams};
use bywire_vehicle::acceptance::{CheckConfig, Checker};
use bywire_vehicle::profile::Profile;

use crate::support::interrupt::interrupt_flag;

#[derive(clap::Args)]
#[command(
    after_help = "Examples:\n  bywire check --profile reference-tug --with-vehicle           (the simulated tug)\n  bywire check --profile reference-tug --with-vehicle --tug-fault stuck-sensor\n  bywire check --profile ./my-tug.toml socketcan:can0              (a real vehicle, in real time)\n\nChecks, in order: engage, feedback rate, steering sweep (±40° in 1° steps, each within\n2.0° after 0.6 s), speed steps (1.0 and 2.5 m/s within 10 % after 6 s), watchdog (commands\nstop: holding and full braking at their cycle counts), re-engage, and with an EmergencyStop\nmessage: E-stop reaction, latch, and the operator's reset. Exit 1 when any check fails.\nOn a real vehicle the tug moves: run it where it may."
)]
pub struct Args {
    /// A shipped profile or a profile file.
    #[arg(long)]
    profile: String,
    /// The vehicle's bus (`tug`: the same as --with-vehicle).
    #[arg(
        required_unless_present = "with_vehicle",
        conflicts_with = "with_vehicle"
    )]
    bus: Option<String>,
    /// Check the simulated vehicle instead of one on a bus: the reference tug, its plant and
    /// buses in simulated time (as `bridge` and `ros2 vehicle` take --with-vehicle).
    #[arg(long)]
    with_vehicle: bool,
    /// With --with-vehicle: a fault to give it (stuck-sensor: the front-left steering sensor
    /// reads 0°).
    #[arg(long)]
    tug_fault: Option<String>,
    /// Sweep range, degrees (±).
    #[arg(long, default_value_t = 40.0)]
    sweep: f64,
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    let loaded = if std::path::Path::new(&args.profile).exists() {
        Profile::load(std::path::Path::new(&args.profile))?
    } else {
        bywire_tug::builtin(&args.profile)?
    };
    if !(args.sweep > 0.0 && args.sweep <= 90.0) {
        bail!("--sweep {}: more than 0, at most 90 degrees", args.sweep);
    }
    let config = CheckConfig {
        sweep_deg: args.sweep,
        ..CheckConfig::default()
    };
    let mut checker =
        Checker::new(&loaded, config).with_context(|| format!("--profile {}", args.profile))?;
    let bus = args.bus.as_deref().filter(|bus| *bus != "tug");
    if args.with_vehicle || bus.is_none() {
        let mut tug = Tug::new(TugParams::default())?;
        match args.tug_fault.as_deref() {
            None => {}
            Some("stuck-sensor") => {
                tug.inject(Fault::SensorFault(0, SensorFault::Stuck(0.0)), None)
            }
            Some(other) => bail!("--tug-fault {other}: not a fault (stuck-sensor)"),
        }
        // The checker in the built-in ADS's place, on the simulated runner.
        let mut ads = OnBothCommandBuses(&mut checker);
        for _ in 0..600_000 {
            tug.step_with_ads(&mut ads);
            if ads.0.is_done() {
                break;
            }
        }
    } else {
        if args.tug_fault.is_some() {
            bail!("--tug-fault is for the simulated vehicle (--with-vehicle)");
        }
        let name = bus.unwrap_or_default();
        let bus = crate::support::busarg::open(name).with_context(|| format!("bus '{name}'"))?;
        runner::run_until(
            bus,
            &mut checker,
            &interrupt_flag(),
            Some(Duration::from_secs(600)),
            |c| c.is_done(),
        )
        .with_context(|| format!("bus '{name}'"))?;
    }
    let mut failed = Vec::new();
    for result in checker.results() {
        writeln!(
            out,
            "{}  {:<16} {}",
            if result.passed { "PASS" } else { "FAIL" },
            result.name,
            result.detail
        )?;
        if !result.passed {
            failed.push(result.name);
        }
    }
    if !checker.is_done() {
        bail!("the checks did not finish");
    }
    if !failed.is_empty() {
        bail!("failed: {}", failed.join(", "));
    }
    Ok(())
}
