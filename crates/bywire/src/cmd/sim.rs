//! `bywire sim`: the simulated tug on its buses, driven along a route by the ADS side, in
//! real time or as fast as possible; candump logs of every bus, a metrics JSON and a plot.

use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use bywire_core::Timestamp;
use bywire_sim::report::RunReport;
use bywire_sim::scenario::Scenario;
use bywire_sim::tug::{Tug, TugBus};

use crate::support::interrupt::interrupt_flag;
use crate::support::sim_serve::Shared;

#[derive(clap::Args)]
#[command(
    after_help = "Examples:\n  bywire sim                          (real time, the apron-loop route)\n  bywire sim --fast --seed 7 --out run1\n  bywire sim --scenario fault-tour --serve   (then: bywire dump socketcand:127.0.0.1:29536/bus2)\n\nWrites into --out: bus1.log (vehicle control, 500 kbit/s), bus2.log (CANopen drives,\n1 Mbit/s), bus3.log (sensors, 500 kbit/s) and bus1b.log (the redundant command bus) in\ncandump -L form, metrics.json (sim_seconds, completed, events, route tracking error,\nsteering steps, the tank turn, command-echo latency, bus loads, battery, the supervisor's\ncounts, security: what an attack achieved and what SecOC refused, response times per identifier,
fail_operational: the redundant tug's ECU faults, one record each),
truth.csv (the plant's true pose, motion, wheel angles and speeds and steering mode every
10 ms, on the logs' clock) and run.png (route and path,\nbus loads, speed, steering command and actual, heading, faults marked). The same seed and --start-time give the same logs, byte for byte."
)]
pub struct Args {
    /// Run as fast as possible instead of in real time.
    #[arg(long)]
    fast: bool,
    /// Seed of every noise source.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Scenario: built in (apron-loop, fault-tour, fail-operational) or a TOML file.
    #[arg(long, default_value = "apron-loop")]
    scenario: String,
    /// Folder for the logs and metrics.
    #[arg(long, default_value = "sim-out")]
    out: PathBuf,
    /// Payload, kg (instead of the scenario's).
    #[arg(long)]
    payload: Option<f64>,
    /// The secured variant, whatever the scenario says (its `secoc = true`): commands, E-stop,
    /// emergency brake and the vehicle's reports authenticated (SecOC), CAN FD on bus 1 and 1b.
    #[arg(long)]
    secoc: bool,
    /// The logs' time at the run's start (default: now): 2026-12-07T08:00:00Z, 2026-12-07
    /// or Unix seconds. The same seed and start time give the same files.
    #[arg(long, value_name = "TIME", value_parser = crate::support::numbers::moment)]
    start_time: Option<Timestamp>,
    /// Stop after this many simulated seconds at most.
    #[arg(long, default_value_t = 600.0, value_parser = crate::support::numbers::positive_seconds)]
    max_seconds: f64,
    /// No live view, even in a terminal.
    #[arg(long)]
    no_view: bool,
    /// Serve the buses (bus1, bus2, bus3, bus1b) over socketcand while it runs, so other
    /// programs watch and inject traffic (loopback only).
    #[arg(long, value_name = "ADDR:PORT", num_args = 0..=1, default_missing_value = "127.0.0.1:29536")]
    serve: Option<std::net::SocketAddr>,
    /// Serve the live page and the Foxglove WebSocket protocol while it runs (loopback only):
    /// the four buses decoded, the tug on a map of its route with its mode, degradation level
    /// and the live view's fault buttons; in Foxglove, the tug's pose (foxglove.PoseInFrame
    /// on /tug/pose) and route (/tug/route) for the 3D panel.
    #[arg(long, alias = "foxglove", value_name = "ADDR:PORT", num_args = 0..=1, default_missing_value = "127.0.0.1:8080")]
    web: Option<std::net::SocketAddr>,
    /// With --serve: send socketcand's discovery beacon (naming the four buses) every 3 s, to
    /// 127.0.0.1:42000 or to ADDR:PORT, as socketcand does (python-can's detect_beacon reads it).
    #[arg(long, value_name = "ADDR:PORT", num_args = 0..=1, default_missing_value = "127.0.0.1:42000", requires = "serve")]
    beacon: Option<std::net::SocketAddr>,
    /// After the run (the route done, or --max-seconds), keep the tug running in real time
    /// for this many seconds, parked with its buses served or attached, so testers can
    /// diagnose it (e.g. read the fault tour's DTCs with udsoncan); Ctrl-C ends it sooner.
    #[arg(long, value_name = "SECONDS", value_parser = crate::support::numbers::positive_seconds)]
    linger: Option<f64>,
    /// Carry a simulated bus to and from another bus while it runs, e.g. bus2=vcan0 (a
    /// SocketCAN interface, for candump and the other can-utils) or
    /// bus3=socketcand:HOST:PORT/NAME; any bus argument. Repeatable.
    #[arg(long, value_name = "BUS=BUSARG")]
    attach: Vec<String>,
    /// Sweep: run these scenarios (comma-separated; built in or files) × --seeds × --payloads
    /// × --grades as fast as possible on --jobs threads, each into its own folder under --out,
    /// with sweep.csv summarising the runs.
    #[arg(long, value_name = "SCENARIOS", value_delimiter = ',', conflicts_with_all = ["serve", "attach", "linger", "web"])]
    sweep: Vec<String>,
    /// The sweep's seeds: A..B (inclusive) or one seed.
    #[arg(long, value_name = "A..B", requires = "sweep")]
    seeds: Option<String>,
    /// The sweep's payloads, kg (comma-separated; default: each scenario's).
    #[arg(long, value_delimiter = ',', requires = "sweep")]
    payloads: Vec<f64>,
    /// The sweep's grades, rise over run (comma-separated; default: each scenario's).
    #[arg(
        long,
        value_delimiter = ',',
        requires = "sweep",
        allow_hyphen_values = true
    )]
    grades: Vec<f64>,
    /// Runs at once (default: the machine's cores).
    #[arg(long, requires = "sweep")]
    jobs: Option<usize>,
    /// Drive the tug over ROS 2 instead of the built-in mission: the Autoware vehicle
    /// interface takes the ADS's place on bus 1 and 1b (as `bywire ros2 vehicle`; see its
    /// --help for the topics), and the true pose goes to /localization/kinematic_state
    /// (nav_msgs/Odometry). Real time.
    #[cfg(feature = "ros2")]
    #[arg(long, conflicts_with_all = ["fast", "linger", "secoc"])]
    ros2: bool,
    #[cfg(feature = "ros2")]
    #[command(flatten)]
    node: crate::support::ros2::NodeArgs,
}

/// `--start-time`, or now.
fn start_time(args: &Args) -> Timestamp {
    args.start_time.unwrap_or_else(|| {
        let since_epoch = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        Timestamp::from_nanos(u64::try_from(since_epoch.as_nanos()).unwrap_or(u64::MAX))
    })
}

/// A built-in scenario or one from a file.
fn load_scenario(name: &str, option: &str) -> Result<Scenario> {
    match Scenario::builtin(name) {
        Some(scenario) => Ok(scenario),
        None if std::path::Path::new(name).is_file() => {
            let text = std::fs::read_to_string(name).with_context(|| format!("{option} {name}"))?;
            Ok(Scenario::parse(&text, name)?)
        }
        None => {
            bail!("{option} {name}: not a built-in scenario (apron-loop, fault-tour, fail-operational) nor a file")
        }
    }
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    if !args.sweep.is_empty() {
        return sweep(args, out);
    }
    let scenario = load_scenario(&args.scenario, "--scenario")?;
    let payload = args.payload.unwrap_or(scenario.tug.payload);
    if !(0.0..=4_500.0).contains(&payload) {
        bail!("--payload {payload}: 0 to 4500 kg");
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("--out {}", args.out.display()))?;
    let mut params = scenario.params(args.seed, payload);
    params.secoc |= args.secoc;
    let mut tug = Tug::new(params)?;
    let mut shared = Shared::default();
    for attach in &args.attach {
        let (name, spec) = attach
            .split_once('=')
            .ok_or_else(|| anyhow!("--attach {attach}: BUS=BUSARG, e.g. bus2=vcan0"))?;
        let bus = TugBus::named(name).ok_or_else(|| {
            anyhow!("--attach {attach}: {name} is not a bus of the tug (bus1, bus2, bus3, bus1b)")
        })?;
        let endpoint =
            crate::support::busarg::open(spec).with_context(|| format!("--attach {attach}"))?;
        shared.attach(&mut tug, bus, endpoint);
    }
    let logs_start = start_time(args);
    if let Some(listen) = args.web {
        let faults = scenario.events.iter().map(|(_, f, d)| (*f, *d)).collect();
        let address = shared.web(&mut tug, listen, logs_start, faults)?;
        crate::support::live::announce(out, address)?;
    }
    if let Some(listen) = args.serve {
        let address = shared.serve(&mut tug, listen, args.beacon)?;
        writeln!(
            out,
            "serving bus1, bus2, bus3 and bus1b on {address} (socketcand)"
        )?;
        out.flush()?;
    }
    let limit = Timestamp::from_nanos((args.max_seconds * 1e9) as u64);
    let start = Instant::now();
    // In a terminal, in real time: the live view.
    let live = !args.fast
        && !args.no_view
        && args.linger.is_none()
        && std::io::IsTerminal::is_terminal(&std::io::stdout());
    #[cfg(feature = "ros2")]
    let over_ros2 = args.ros2;
    #[cfg(not(feature = "ros2"))]
    let over_ros2 = false;
    let completed = if over_ros2 {
        #[cfg(feature = "ros2")]
        run_over_ros2(&mut tug, &scenario, args, &mut shared, out)?;
        false
    } else if live {
        matches!(
            crate::tui::sim_view::run(
                &mut tug,
                &scenario,
                Duration::from_secs_f64(args.max_seconds),
                &mut shared
            )?,
            crate::tui::sim_view::Ending::Arrived
        )
    } else {
        run_plain(&mut tug, &scenario, args, limit, start, &mut shared, out)?
    };
    let report = RunReport::of(
        &tug,
        &scenario.name,
        args.seed,
        logs_start,
        completed,
        start.elapsed(),
    );
    crate::plot::sim::write(&tug, &args.out.join("run.png"))?;
    bywire_sim::output::write_run(&tug, &report, &args.out)?;
    if let Some(summary) = shared.summary() {
        writeln!(out, "socketcand: {summary}")?;
    }
    if let Some(lost) = shared.stop_web().filter(|lost| *lost > 0) {
        writeln!(
            out,
            "web: clients lost {lost} messages by reading too slowly"
        )?;
    }
    writeln!(out, "{}", summary(&report, &args.out))?;
    Ok(())
}

/// The run in a line: how it ended, what the step test, the crab approach and the tank turn
/// gave, tracking and loads, and where the files are.
fn summary(report: &RunReport, folder: &std::path::Path) -> String {
    use bywire_sim::report::StepRecord;
    let (tracking, load) = (report.tracking_error_m, report.bus_load);
    let mut parts = Vec::new();
    let settled: Vec<(f64, f64)> = report
        .steering_steps
        .iter()
        .filter_map(|step| match step {
            StepRecord::Measured {
                settling_s,
                overshoot_percent,
                ..
            } => Some((*settling_s, *overshoot_percent)),
            StepRecord::Failed { .. } => None,
        })
        .collect();
    if !report.steering_steps.is_empty() {
        let worst = |pick: fn(&(f64, f64)) -> f64| settled.iter().map(pick).fold(0.0, f64::max);
        parts.push(format!(
            "step test {} of {} settled (at most {:.2} s, overshoot {:.1} %)",
            settled.len(),
            report.steering_steps.len(),
            worst(|s| s.0),
            worst(|s| s.1)
        ));
    }
    if let Some(crab) = report.crab_approach {
        parts.push(format!(
            "crab approach {:.1} m sideways over {:.1} m",
            crab.lateral_m.abs(),
            crab.forward_m.abs()
        ));
    }
    if let Some(tank) = &report.tank_turn {
        let settling = match &tank.step {
            StepRecord::Measured { settling_s, .. } => format!("wheels set in {settling_s:.2} s"),
            StepRecord::Failed { error, .. } => format!("wheels not measured: {error}"),
        };
        parts.push(format!(
            "tank turn in {:.1} s ({settling}, holding within {:.2}°)",
            tank.duration_s, tank.hold_peak_to_peak_deg
        ));
    }
    parts.push(format!(
        "tracking error max {:.2} m, mean {:.2} m",
        tracking.max, tracking.mean
    ));
    parts.push(format!(
        "bus loads {:.1} %, {:.1} %, {:.1} %",
        load.bus1 * 100.0,
        load.bus2 * 100.0,
        load.bus3 * 100.0
    ));
    format!(
        "{} after {:.1} s: {}; logs and metrics in {}",
        if report.completed {
            "route completed"
        } else {
            "stopped"
        },
        report.sim_seconds,
        parts.join("; "),
        folder.display()
    )
}

/// `--sweep`: every combination on `--jobs` threads, a line per finished run, sweep.csv.
fn sweep(args: &Args, out: &mut impl Write) -> Result<()> {
    let scenarios: Vec<Scenario> = args
        .sweep
        .iter()
        .map(|name| load_scenario(name, "--sweep"))
        .collect::<Result<_>>()?;
    let seeds = match args.seeds.as_deref() {
        None => args.seed..=args.seed,
        Some(text) => {
            let (a, b) = text.split_once("..").unwrap_or((text, text));
            let parse = |s: &str| {
                s.trim()
                    .parse::<u64>()
                    .map_err(|_| anyhow!("--seeds {text}: expected A..B or one seed"))
            };
            let (a, b) = (parse(a)?, parse(b)?);
            if b < a {
                bail!("--seeds {text}: {b} is below {a}");
            }
            a..=b
        }
    };
    for &payload in &args.payloads {
        if !(0.0..=4_500.0).contains(&payload) {
            bail!("--payloads {payload}: 0 to 4500 kg");
        }
    }
    for &grade in &args.grades {
        if !(-0.2..=0.2).contains(&grade) {
            bail!("--grades {grade}: −0.2 to 0.2 (rise over run)");
        }
    }
    let jobs = bywire_sim::sweep::jobs(&scenarios, seeds, &args.payloads, &args.grades);
    if jobs.len() > 100_000 {
        bail!("the sweep has {} runs; at most 100000", jobs.len());
    }
    let threads = args.jobs.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    if threads == 0 || threads > 256 {
        bail!("--jobs {threads}: 1 to 256");
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("--out {}", args.out.display()))?;
    let limit = Timestamp::from_nanos((args.max_seconds * 1e9) as u64);
    let start = Instant::now();
    let total = jobs.len();
    let finished = std::sync::atomic::AtomicUsize::new(0);
    let report_line = |index: usize, outcome: &bywire_sim::sweep::Outcome| {
        let n = finished.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        let name = jobs.get(index).map(|j| j.folder()).unwrap_or_default();
        let what = match outcome {
            Ok((_, r)) => format!(
                "{} after {:.1} s",
                if r.completed { "completed" } else { "stopped" },
                r.sim_seconds
            ),
            Err(e) => format!("failed: {e}"),
        };
        // Progress goes to standard error; the summary is the file.
        let _ = writeln!(std::io::stderr(), "[{n}/{total}] {name}: {what}");
    };
    let outcomes = bywire_sim::sweep::run(
        &jobs,
        threads,
        limit,
        start_time(args),
        &args.out,
        &report_line,
    );
    let wall = start.elapsed().as_secs_f64();
    let mut csv = String::from(bywire_sim::sweep::SUMMARY_COLUMNS);
    csv.push('\n');
    for (job, outcome) in jobs.iter().zip(&outcomes) {
        csv.push_str(&bywire_sim::sweep::summary_row(job, outcome));
        csv.push('\n');
    }
    let path = args.out.join("sweep.csv");
    crate::support::files::write_atomically(&path, |tmp| {
        std::fs::write(tmp, &csv).with_context(|| format!("{}", path.display()))
    })?;
    let failed = outcomes.iter().filter(|o| o.is_err()).count();
    writeln!(
        out,
        "{} on {} in {wall:.1} s ({:.1} runs per minute); {failed} failed; summary in {}",
        crate::support::words::counted(total, "run"),
        crate::support::words::counted(threads, "thread"),
        total as f64 / wall.max(1e-9) * 60.0,
        path.display()
    )?;
    if failed > 0 {
        bail!("{failed} of {total} runs failed (see {})", path.display());
    }
    Ok(())
}

/// Run driven over ROS 2 until Ctrl-C (then a second of braking) or --max-seconds, with
/// progress lines every 5 simulated seconds.
#[cfg(feature = "ros2")]
fn run_over_ros2(
    tug: &mut Tug,
    scenario: &Scenario,
    args: &Args,
    shared: &mut Shared,
    out: &mut impl Write,
) -> Result<()> {
    use bywire_ros::simulation::{self, SimulationConfig};
    let mut node = args.node.open("simulated_tug")?;
    writeln!(
        out,
        "node {} driving the simulated tug (publish /control/command/control_cmd)",
        node.fully_qualified_name()
    )?;
    out.flush()?;
    let config = SimulationConfig {
        limit: Duration::from_secs_f64(args.max_seconds),
        ..SimulationConfig::default()
    };
    let mut next_line = Timestamp::ZERO;
    simulation::run(
        &mut node,
        tug,
        scenario,
        &config,
        &interrupt_flag(),
        &mut |event| {
            let text = event.to_string();
            let _ = writeln!(std::io::stderr(), "bywire sim: {text}");
        },
        &mut |tug| {
            shared.exchange(tug).map_err(|e| e.to_string())?;
            let now = tug.now();
            if now >= next_line {
                next_line = now.saturating_add(Duration::from_secs(5));
                let speed = format!("{:4.2} m/s", tug.pose_speed());
                writeln!(out, "{}", progress_line(tug, &speed))
                    .and_then(|()| out.flush())
                    .map_err(|e| e.to_string())?;
            }
            Ok(())
        },
    )
    .map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

/// A progress line: the time, where the tug is, then `what`.
fn progress_line(tug: &Tug, what: &str) -> String {
    let pose = tug.pose();
    format!(
        "t={:6.1}s  x={:7.2} y={:7.2}  {what}",
        tug.now().as_nanos() as f64 / 1e9,
        pose.x,
        pose.y
    )
}

/// Run without the view: progress lines every 5 simulated seconds, paced to real time unless
/// `--fast`.
fn run_plain(
    tug: &mut Tug,
    scenario: &Scenario,
    args: &Args,
    limit: Timestamp,
    start: Instant,
    shared: &mut Shared,
    out: &mut impl Write,
) -> Result<bool> {
    let stop = interrupt_flag();
    let mut next_report = Timestamp::ZERO;
    let completed = loop {
        scenario.step(tug);
        let now = tug.now();
        shared.exchange(tug)?;
        if tug.arrived() {
            break true;
        }
        if now >= limit || stop.load(std::sync::atomic::Ordering::Relaxed) {
            break false;
        }
        if now >= next_report {
            next_report = now.saturating_add(Duration::from_secs(5));
            let to_go = format!("{:5.1} m to go", tug.remaining().unwrap_or(f64::NAN));
            writeln!(out, "{}", progress_line(tug, &to_go))?;
            out.flush()?;
        }
        if !args.fast {
            keep_pace(Duration::from_nanos(now.as_nanos()), start);
        }
    };
    if let Some(seconds) = args.linger {
        writeln!(
            out,
            "lingering for {seconds} s in real time, the buses still served (Ctrl-C ends it)"
        )?;
        out.flush()?;
        let (sim_from, wall_from) = (tug.now(), Instant::now());
        let linger = Duration::from_secs_f64(seconds);
        while wall_from.elapsed() < linger && !stop.load(std::sync::atomic::Ordering::Relaxed) {
            scenario.step(tug);
            shared.exchange(tug)?;
            keep_pace(tug.now().saturating_since(sim_from), wall_from);
        }
    }
    Ok(completed)
}

/// Real time: wait while `simulated` (since `wall_start`) is ahead of the wall clock.
fn keep_pace(simulated: Duration, wall_start: Instant) {
    let ahead = simulated.saturating_sub(wall_start.elapsed());
    if !ahead.is_zero() {
        std::thread::sleep(ahead);
    }
}
