//! `bywire bridge`: the ADS side of a vehicle interface on a bus, driven by JSON lines.
//!
//! The sans-IO `Ads` node on the real-time runner (one port per bus): stdin lines become
//! commands (the latest wins), the node's frames go to every bus on its schedule, feedback from
//! either bus feeds its validation, and the vehicle state goes to stdout as JSON lines at
//! `--rate`, with the reason the vehicle is not following when it is not. A lost bus degrades
//! (the other goes on); any end — EOF, a read error, stdout closed, SIGINT, SIGTERM, SIGHUP —
//! ends in the safe stop with `--estop-on-eof`, during which no line is taken; a setpoint beyond
//! the vehicle's limits is refused, never clamped, and a brake beyond them is its hardest.

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::sync::Arc;
use std::time::Duration;

use crate::support::interrupt::interrupt_flag;
use crate::support::vehicles::{keep_freshness, SecOcArgs, Wire};
use anyhow::{anyhow, Context, Result};
use bywire_bus::runner::{Flow, Hooks, Runner};
use bywire_bus::BusError;
use bywire_core::node::Port;
use bywire_core::Timestamp;
use bywire_log::lines::{CappedLines, Line};
use bywire_vehicle::ads::{Ads, AdsCommand};
use bywire_vehicle::command::{ControlMode, Gear, SteeringMode, TurnIndicators};
use bywire_vehicle::profile::Limits;
use serde::Deserialize;
use serde_json::json;

#[derive(clap::Args)]
#[command(
    after_help = "Commands on stdin, one JSON object per line (fields optional; the latest \
command wins; \"at_s\": when to take the line, seconds from the start, so a file plays at\nits own pace):\n  {\"at_s\": 0.5, \"steering\": 5.0, \"velocity\": 1.5, \"brake\": 0, \"gear\": \"drive\", \"mode\": \"autonomous\",\n   \"steering_mode\": \"normal\", \"engage\": true, \"operator_reset\": false}\n  {\"turn_indicators\": \"left\", \"hazard_lights\": true}   (where the profile has lights)\n  {\"emergency_brake\": 4.0}   start the emergency-brake burst (deceleration m/s²;\n   beyond the vehicle's, its hardest)\n  {\"release_brake\": true}\nKeep sending: a command older than the profile's staleness (200 ms for reference-tug) is\nreplaced by a controlled stop. A setpoint beyond the profile's limits is refused (stderr and a\nbad_command event) and the last valid one goes on aging; a brake beyond the vehicle's is taken\nas its hardest (stderr and a saturated event).\n\nTo engage: send commands with \"mode\": \"autonomous\" for a moment (the vehicle wants a run of\nvalid ones), then one with \"engage\": true. While the vehicle is not following, each state\nline's \"reason\" says why and what to do (an E-stop latched since start wants the operator\nreset sequence: \"operator_reset\": true twice, then engage).\n\nExamples:\n  bywire bridge --profile reference-tug socketcan:can0 < commands.jsonl\n  bywire bridge --profile reference-tug sim:demo@500000 --with-vehicle --estop-on-eof\n  bywire bridge --profile ./my-tug.toml socketcan:can0 --rate 20\n\nAny profile with [command] and [state] drives its vehicle's own messages, by role (and
--with-vehicle simulates that vehicle)."
)]
pub struct Args {
    /// A shipped profile (reference-tug) or a profile file.
    #[arg(long)]
    profile: String,
    /// The bus (virtual:NAME, sim:NAME@BITRATE, socketcan:IFACE).
    bus: String,
    /// A redundant second bus: every command goes on both, feedback is taken from either.
    bus2: Option<String>,
    /// State lines per second on stdout.
    #[arg(long, default_value_t = 10.0, value_parser = crate::support::numbers::rate)]
    rate: f64,
    /// At any end (EOF, stdout closed, SIGINT, SIGTERM, SIGHUP), brake (emergency-brake burst
    /// and a stop command) for one second before exiting, instead of just stopping to send.
    #[arg(long)]
    estop_on_eof: bool,
    /// Run a simulated vehicle (`bywire vehicle`: the real supervisor and a plant) on the same
    /// buses, for trying the bridge without a vehicle; only for in-process buses.
    #[arg(long)]
    with_vehicle: bool,
    #[command(flatten)]
    secoc: SecOcArgs,
}

/// A command line from stdin.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct CommandLine {
    steering: Option<f64>,
    velocity: Option<f64>,
    brake: Option<f64>,
    gear: Option<String>,
    mode: Option<String>,
    steering_mode: Option<String>,
    engage: Option<bool>,
    operator_reset: Option<bool>,
    turn_indicators: Option<String>,
    hazard_lights: Option<bool>,
    emergency_brake: Option<f64>,
    release_brake: Option<bool>,
    /// When to take the line, seconds after the bridge started (the stdin thread holds it
    /// until then): a file of commands plays back at its own pace.
    at_s: Option<f64>,
}

/// The longest a line may ask to wait (`at_s`): a day (more is a typo).
const LONGEST_WAIT_S: f64 = 86_400.0;

/// Whether `at_s` is a time a line may ask for: 0 to a day after the start.
fn pace_in_range(at_s: f64) -> bool {
    (0.0..=LONGEST_WAIT_S).contains(&at_s)
}

/// Only a line's `at_s`, read before the line is handed over.
#[derive(Deserialize)]
struct Pace {
    at_s: Option<f64>,
}

/// When the line `text` asks to be taken, from `start`: `None` for now (no `at_s`, or one
/// not in 0..=a day, which the line's own check then refuses).
fn taken_at(text: &str, start: std::time::Instant) -> Option<std::time::Instant> {
    let at_s = serde_json::from_str::<Pace>(text).ok()?.at_s?;
    pace_in_range(at_s).then(|| start + Duration::from_secs_f64(at_s))
}

/// A command line's command, and what was taken as less than asked (a brake beyond the
/// vehicle's).
struct Applied {
    command: AdsCommand,
    warning: Option<String>,
}

/// Apply a command line to the previous command (fields left out keep their value), refusing
/// a setpoint the vehicle's limits do not allow; a brake beyond the vehicle's is its hardest.
fn apply(line: &CommandLine, previous: AdsCommand, limits: &Limits) -> Result<Applied> {
    fn parsed<T: std::str::FromStr<Err = bywire_vehicle::command::UnknownName>>(
        text: Option<&str>,
        previous: T,
    ) -> Result<T> {
        text.map_or(Ok(previous), |t| {
            t.parse().map_err(|e| anyhow!("'{t}': {e}"))
        })
    }
    let command = AdsCommand {
        steering: line.steering.unwrap_or(previous.steering),
        velocity: line.velocity.unwrap_or(previous.velocity),
        brake: line.brake.unwrap_or(previous.brake),
        gear: parsed::<Gear>(line.gear.as_deref(), previous.gear)?,
        mode: parsed::<ControlMode>(line.mode.as_deref(), previous.mode)?,
        steering_mode: parsed::<SteeringMode>(
            line.steering_mode.as_deref(),
            previous.steering_mode,
        )?,
        // Edges: a request lasts for the line that asks for it.
        engage: line.engage.unwrap_or(false),
        operator_reset: line.operator_reset.unwrap_or(false),
        turn_indicators: parsed::<TurnIndicators>(
            line.turn_indicators.as_deref(),
            previous.turn_indicators,
        )?,
        hazard_lights: line.hazard_lights.unwrap_or(previous.hazard_lights),
    };
    let (command, warning) = limits.admit(command).map_err(|e| anyhow!(e))?;
    Ok(Applied { command, warning })
}

fn state_json(ads: &Ads<Wire>, now: Timestamp) -> serde_json::Value {
    let s = ads.state();
    let age_ms = |at: Option<Duration>| at.map(|d| d.as_secs_f64() * 1e3);
    json!({
        "t_s": now.as_nanos() as f64 / 1e9,
        "feedback_alive": ads.feedback_alive(now),
        "mode": s.mode.value.map(|m| m.name().to_lowercase()),
        "velocity": s.velocity.value,
        "steering": s.steering.value,
        "watchdog_level": s.watchdog_level.value.map(|l| l.raw()),
        "estop_state": s.estop_state.value.map(|c| c.raw()),
        "warning": s.warning.value,
        "driver_override": s.driver_override.value,
        // A fail-operational vehicle's degradation level and the fault behind it.
        "degradation": s.degradation.value.map(|level| json!({
            "level": level.to_string(),
            "reason": s.degradation_reason.value.flatten().map(|f| f.to_string()),
        })),
        "wheel_speeds": s.wheel_speeds.value,
        "echo_latency_ms": s.echo_latency.value.map(|d| d.as_secs_f64() * 1e3),
        "steering_response_ms": s.steering_response.value.map(|d| d.as_secs_f64() * 1e3),
        "odometry": s.odometry.value.map(|p| json!({"x": p.x, "y": p.y, "yaw": p.yaw})),
        "state_age_ms": age_ms(s.mode.age(now)),
        "reason": ads.blocker(now).map(|b| b.to_string()),
        "rejected": {
            "checksum": ads.stats().checksum,
            "counter": ads.stats().counter,
            "echo": ads.stats().echo,
            "range": ads.stats().range,
        },
        "secoc": crate::support::vehicles::secoc_counts(ads.wire()),
    })
}

/// What the stdin thread hands over.
enum Input {
    Line(u64, Line),
    /// The input ended: EOF or the reason it could not be read further.
    End(String),
}

/// The bridge's side of the run: stdin in, state and events out, the safe stop at the end.
struct Bridge<'a> {
    out: &'a mut dyn Write,
    inputs: Receiver<Input>,
    limits: Limits,
    command: AdsCommand,
    report: Duration,
    next_report: Timestamp,
    estop_on_eof: bool,
    braking_until: Option<Timestamp>,
    buses: Vec<(Port, String)>,
    /// Stdout failed: nothing more is written (and the input counts as ended).
    output_lost: bool,
    /// Where the secured wire's freshness is kept.
    freshness: Option<bywire_secoc::store::FreshnessStore>,
    /// Set by SIGINT, SIGTERM or SIGHUP: an end of input like any other.
    interrupted: Arc<AtomicBool>,
}

impl Bridge<'_> {
    fn write(&mut self, line: serde_json::Value) {
        if self.output_lost {
            return;
        }
        if writeln!(self.out, "{line}")
            .and_then(|()| self.out.flush())
            .is_err()
        {
            self.output_lost = true;
        }
    }

    fn event(&mut self, now: Timestamp, kind: &str, detail: &str) {
        self.write(json!({"t_s": now.as_nanos() as f64 / 1e9, "event": kind, "detail": detail}));
    }

    fn refuse(&mut self, now: Timestamp, number: u64, why: &str) {
        let _ = writeln!(
            std::io::stderr(),
            "bywire bridge: line {number}: {why} (refused; the last valid command goes on aging)"
        );
        self.event(now, "bad_command", &format!("line {number}: {why}"));
    }

    fn take_line(&mut self, ads: &mut Ads<Wire>, now: Timestamp, number: u64, line: Line) {
        let text = match line {
            Line::Text(text) if text.trim().is_empty() => return,
            Line::Text(text) => text,
            other => return self.refuse(now, number, &other.problem().unwrap_or_default()),
        };
        if self.braking_until.is_some() {
            // The end has begun: nothing overrides the safe stop.
            return self.event(
                now,
                "ignored",
                &format!("line {number}: the bridge is braking to end"),
            );
        }
        let line = match serde_json::from_str::<CommandLine>(&text) {
            Ok(line) => line,
            Err(e) => return self.refuse(now, number, &e.to_string()),
        };
        if let Some(at_s) = line.at_s.filter(|t| !pace_in_range(*t)) {
            return self.refuse(
                now,
                number,
                &format!("at_s {at_s}: seconds from the start, 0 to {LONGEST_WAIT_S}"),
            );
        }
        // A stop is carried out whatever else the line asks for.
        if let Some(deceleration) = line.emergency_brake {
            match self.limits.emergency_deceleration(deceleration) {
                Ok(taken) => {
                    self.warn(now, number, taken.warning.as_deref());
                    ads.emergency_brake(now, taken.value);
                    self.event(now, "emergency_brake", &format!("{} m/s²", taken.value));
                }
                Err(why) => self.refuse(now, number, &why),
            }
        }
        let applied = match apply(&line, self.command, &self.limits) {
            Ok(applied) => applied,
            Err(e) => return self.refuse(now, number, &e.to_string()),
        };
        self.warn(now, number, applied.warning.as_deref());
        if line.release_brake == Some(true) {
            ads.release_brake();
            self.event(now, "brake_released", "");
        }
        self.command = applied.command;
        // Finite and within limits (checked above): the node takes it.
        ads.set_command(now, applied.command);
    }

    /// A request taken as less than asked (a brake beyond the vehicle's): said on stderr and
    /// as an event.
    fn warn(&mut self, now: Timestamp, number: u64, warning: Option<&str>) {
        if let Some(warning) = warning {
            let _ = writeln!(std::io::stderr(), "bywire bridge: line {number}: {warning}");
            self.event(now, "saturated", &format!("line {number}: {warning}"));
        }
    }

    /// The end of input: brake for a second (with `--estop-on-eof`) or end now.
    fn end_of_input(&mut self, ads: &mut Ads<Wire>, now: Timestamp, why: &str) -> Flow {
        if self.braking_until.is_some() {
            return Flow::Continue;
        }
        if !self.estop_on_eof {
            return Flow::Stop;
        }
        ads.safe_stop(now, self.limits.deceleration_m_s2);
        self.event(now, "end_of_input", &format!("{why}: braking for 1 s"));
        self.braking_until = Some(now.saturating_add(Duration::from_secs(1)));
        Flow::Continue
    }
}

impl Hooks<Ads<Wire>> for Bridge<'_> {
    fn after_poll(&mut self, ads: &mut Ads<Wire>, now: Timestamp) -> Flow {
        // Bounded per pass; the rest waits for the next (the runner is woken per line). A
        // signal or a closed stdout ends the input before any further line is taken.
        for _ in 0..256 {
            let ended = if self.interrupted.load(Ordering::Relaxed) {
                Some("a signal (SIGINT, SIGTERM or SIGHUP)")
            } else if self.output_lost {
                Some("stdout closed")
            } else {
                None
            };
            if let Some(why) = ended {
                if self.end_of_input(ads, now, why) == Flow::Stop {
                    return Flow::Stop;
                }
            }
            let why = match self.inputs.try_recv() {
                Ok(Input::Line(number, line)) => {
                    self.take_line(ads, now, number, line);
                    continue;
                }
                Err(TryRecvError::Empty) => break,
                Ok(Input::End(why)) => why,
                Err(TryRecvError::Disconnected) => "end of input".to_string(),
            };
            if self.end_of_input(ads, now, &why) == Flow::Stop {
                return Flow::Stop;
            }
            if self.braking_until.is_some() {
                break;
            }
        }
        if let Err(why) = keep_freshness(&mut self.freshness, ads.wire()) {
            // What is signed next could not be kept: a restart would reuse it. Brake and end.
            if self.braking_until.is_none() {
                ads.safe_stop(now, self.limits.deceleration_m_s2);
                self.event(now, "freshness", &format!("{why}: braking for 1 s"));
                self.braking_until = Some(now.saturating_add(Duration::from_secs(1)));
            }
        }
        if now >= self.next_report {
            self.write(state_json(ads, now));
            self.next_report = self.next_report.saturating_add(self.report).max(now);
        }
        if self.braking_until.is_some_and(|until| now >= until) {
            return Flow::Stop;
        }
        Flow::Continue
    }

    fn wake_at(&self) -> Option<Timestamp> {
        Some(
            self.braking_until
                .map_or(self.next_report, |b| b.min(self.next_report)),
        )
    }

    fn bus_lost(&mut self, _: &mut Ads<Wire>, now: Timestamp, port: Port, error: &BusError) {
        let lost = self
            .buses
            .iter()
            .find(|(p, _)| *p == port)
            .map_or("?", |(_, s)| s.as_str());
        let left: Vec<&str> = self
            .buses
            .iter()
            .filter(|(p, _)| *p != port)
            .map(|(_, s)| s.as_str())
            .collect();
        let detail = format!("{lost}: {error}; commanding on {} only", left.join(", "));
        let _ = writeln!(std::io::stderr(), "bywire bridge: bus {detail}");
        self.event(now, "bus_lost", &detail);
        self.buses.retain(|(p, _)| *p != port);
    }
}

/// Read stdin on a thread, a line at a time in bounded memory, waking the runner per line; a
/// line with `at_s` is held until then (and the lines after it with it).
fn stdin_thread(waker: bywire_bus::runner::Waker) -> Receiver<Input> {
    let (send, inputs) = mpsc::sync_channel(1024);
    let start = std::time::Instant::now();
    std::thread::spawn(move || {
        let mut lines = CappedLines::new(std::io::stdin().lock());
        let end = loop {
            match lines.next_line() {
                Some(Ok((number, line))) => {
                    if let Line::Text(text) = &line {
                        if let Some(at) = taken_at(text, start) {
                            std::thread::sleep(
                                at.saturating_duration_since(std::time::Instant::now()),
                            );
                        }
                    }
                    if send.send(Input::Line(number, line)).is_err() {
                        return;
                    }
                    waker.wake();
                }
                Some(Err(e)) => break format!("stdin: {e}"),
                None => break "end of input".to_string(),
            }
        };
        let _ = send.send(Input::End(end));
        waker.wake();
    });
    inputs
}

/// Run the bridge until stdin ends (and, with `--estop-on-eof`, one second of braking).
pub fn run(args: &Args, out: &mut dyn Write) -> Result<()> {
    let profile = crate::support::vehicles::load_profile(&args.profile)?;
    let specs = crate::support::vehicles::command_buses(&args.bus, args.bus2.as_ref());
    // Both sides speak the profile's messages by role, through the runtime codec (its
    // [secoc] messages authenticated with --key-file).
    let (wire, freshness) = args.secoc.wire(&profile)?;
    let vehicle_stop = Arc::new(AtomicBool::new(false));
    let vehicle = if args.with_vehicle {
        Some(crate::support::vehicles::spawn_in_process(
            &specs,
            &profile,
            wire.clone(),
            &vehicle_stop,
        )?)
    } else {
        None
    };
    let mut endpoints = Vec::new();
    for (port, spec) in &specs {
        endpoints.push((
            *port,
            bywire_bus::open(spec).with_context(|| format!("bus {spec}"))?,
        ));
    }
    let mut runner = Runner::new(endpoints);
    let mut config = profile.ads_config();
    config.redundant = specs.len() > 1;
    let mut ads = Ads::with_wire(config, wire);
    let mut bridge = Bridge {
        out,
        inputs: stdin_thread(runner.waker()),
        limits: profile.profile.limits,
        command: AdsCommand::default(),
        report: Duration::from_secs_f64(1.0 / args.rate),
        next_report: Timestamp::ZERO,
        estop_on_eof: args.estop_on_eof,
        braking_until: None,
        buses: specs.clone(),
        output_lost: false,
        freshness,
        interrupted: interrupt_flag(),
    };
    // The runner is never stopped from outside: a signal ends the input, and the bridge's
    // hooks end the run (after the safe stop, with --estop-on-eof).
    let result = runner.run(&mut ads, &AtomicBool::new(false), None, &mut bridge);
    vehicle_stop.store(true, Ordering::Relaxed);
    if let Some(vehicle) = vehicle {
        let _ = vehicle.join();
    }
    result.map_err(|e| anyhow!("every bus lost (last: {e})"))?;
    Ok(())
}
