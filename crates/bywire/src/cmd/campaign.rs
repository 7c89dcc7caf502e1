//! `bywire campaign`: a fault-injection campaign file run cell by cell in the simulator
//! (`bywire_sim::campaign`), its results as JUnit XML, JSON and a coverage matrix.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use bywire_sim::campaign::{self, report, Campaign, Verdict};
use bywire_vehicle::mechanism::{Mechanism, Mechanisms};

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire campaign campaigns/default.toml --out campaign-out
  bywire campaign campaigns/default.toml --disable e2e --out without-e2e
  bywire campaign campaigns/smoke.toml --jobs 2

Every fault of the file runs in every operating state on every profile: one cell each, on the
simulated runner (deterministic: the same results on any machine and with any --jobs). A cell
passes when the mechanism it expects detects the fault within its bound, the vehicle's most
severe reaction is the one expected (within its bound), and the actuators never leave the
vehicle's limits. Writes DIR/junit.xml (a test case per cell, profile/state/fault/mechanism),
DIR/cells.json (every cell's detections, reaction and times), DIR/report.md and
DIR/report.html (fault classes against mechanisms per profile). Exit 1 on any failed cell.

--disable MECHANISM switches one off in the vehicle's software (e2e, timeout, range,
redundancy, voter, safe-state, secoc; repeatable): the cells that then fail are the evidence
that the campaign would notice it missing.")]
pub struct Args {
    /// The campaign file (TOML).
    file: PathBuf,
    /// Cells run at once (default: the number of CPUs).
    #[arg(long, value_name = "N")]
    jobs: Option<usize>,
    /// Where the reports go.
    #[arg(long, value_name = "DIR", default_value = "campaign-out")]
    out: PathBuf,
    /// Switch a mechanism off in the vehicle's software (repeatable).
    #[arg(long, value_name = "MECHANISM", value_parser = removable)]
    disable: Vec<Mechanism>,
    /// Print every cell as it ends, not only the failed ones.
    #[arg(long, short)]
    verbose: bool,
}

fn removable(name: &str) -> Result<Mechanism, String> {
    let names: Vec<&str> = Mechanism::REMOVABLE.iter().map(|m| m.name()).collect();
    Mechanism::from_name(name)
        .filter(|m| Mechanism::REMOVABLE.contains(m))
        .ok_or_else(|| format!("one of {}", names.join(", ")))
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    let campaign = Campaign::load(&args.file)?;
    let disabled: Mechanisms = args.disable.iter().copied().collect();
    let jobs = args.jobs.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    let started = std::time::Instant::now();
    let verbose = args.verbose;
    let results = campaign::run(&campaign, jobs, disabled, &|c| {
        if verbose || c.verdict == Verdict::Fail {
            let verdict = match c.verdict {
                Verdict::Pass => "pass",
                Verdict::Fail => "FAIL",
                Verdict::NotApplicable => "n/a",
            };
            eprintln!("{verdict:4} {} {}", c.name, c.why);
        }
    })?;
    let wall = started.elapsed().as_secs_f64();
    report::write(&args.out, &campaign, &results, disabled, wall)
        .with_context(|| format!("--out {}", args.out.display()))?;
    let t = report::Tally::of(&results);
    writeln!(
        out,
        "{}: {} cells, {} executed, {} passed, {} failed, {} not applicable in {wall:.1} s ({jobs} job{}); reports in {}",
        campaign.name,
        results.len(),
        t.executed,
        t.passed,
        t.failed,
        t.not_applicable,
        if jobs == 1 { "" } else { "s" },
        args.out.display()
    )?;
    // A mechanism whose removal fails no cell is one this campaign does not test.
    let unnoticed = report::unnoticed(&results, disabled);
    if !unnoticed.is_empty() {
        let names: Vec<&str> = unnoticed.iter().map(|m| m.name()).collect();
        bail!(
            "with {} switched off no cell failed: this campaign does not test {}",
            names.join(", "),
            if names.len() == 1 { "it" } else { "them" }
        );
    }
    if t.failed > 0 {
        bail!(
            "{} of {} cells failed (see {})",
            t.failed,
            t.executed,
            args.out.join("report.md").display()
        );
    }
    Ok(())
}
