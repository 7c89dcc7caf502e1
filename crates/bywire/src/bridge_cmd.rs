//! `bywire bridge`: the ADS side of a vehicle interface on a bus, driven by JSON lines.
//!
//! This is the real-time runner of the sans-IO `Ads` node: stdin lines become commands (the
//! latest wins), the node's frames go to the bus on its schedule, frames from the bus feed its
//! validation, and the vehicle state goes to stdout as JSON lines at `--rate`.

use std::io::{BufRead, Write};
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use bywire_bus::{Bus, BusRx};
use bywire_core::{Frame, Timestamp};
use bywire_vehicle::ads::{Ads, AdsCommand};
use bywire_vehicle::profile::{LoadedProfile, Profile};
use bywire_vehicle::redundancy::Channel;
use bywire_vehicle::reference_tug::{ControlMode, Gear, SteeringMode};
use bywire_vehicle::supervisor::{Redundancy, Supervisor};
use bywire_vehicle::wire::ProfileWire;
use serde::Deserialize;
use serde_json::json;

#[derive(clap::Args)]
#[command(
    after_help = "Commands on stdin, one JSON object per line (fields optional; the latest \
command wins):\n  {\"steering\": 5.0, \"velocity\": 1.5, \"brake\": 0, \"gear\": \"drive\", \"mode\": \"autonomous\",\n   \"steering_mode\": \"normal\", \"engage\": true, \"operator_reset\": false}\n  {\"emergency_brake\": 4.0}   start the emergency-brake burst (deceleration m/s²)\n  {\"release_brake\": true}\nKeep sending: a command older than the profile's staleness (200 ms for reference-tug) is\nreplaced by a controlled stop.\n\nExamples:\n  bywire bridge --profile reference-tug socketcan:can0 < commands.jsonl\n  bywire bridge --profile reference-tug sim:demo@500000 --with-vehicle --estop-on-eof\n  bywire bridge --profile ./my-tug.toml socketcan:can0 --rate 20\n\nAny profile with [command] and [state] drives its vehicle's own messages, by role (and
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
    #[arg(long, default_value_t = 10.0)]
    rate: f64,
    /// At the end of stdin, brake (emergency-brake burst and a stop command) for one second
    /// before exiting, instead of just stopping to send.
    #[arg(long)]
    estop_on_eof: bool,
    /// Run a simulated vehicle (the vehicle-side supervisor with a simple plant) on the same
    /// bus, for trying the bridge without a vehicle; only for in-process buses.
    #[arg(long)]
    with_vehicle: bool,
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
    emergency_brake: Option<f64>,
    release_brake: Option<bool>,
}

fn gear(name: &str) -> Result<Gear> {
    Ok(match name.to_ascii_lowercase().as_str() {
        "park" | "p" => Gear::Park,
        "reverse" | "r" => Gear::Reverse,
        "neutral" | "n" => Gear::Neutral,
        "drive" | "d" => Gear::Drive,
        other => bail!("gear '{other}' is not park, reverse, neutral or drive"),
    })
}

fn mode(name: &str) -> Result<ControlMode> {
    Ok(match name.to_ascii_lowercase().as_str() {
        "manual" => ControlMode::Manual,
        "autonomous" => ControlMode::Autonomous,
        "calibration" => ControlMode::Calibration,
        other => bail!("mode '{other}' is not manual, autonomous or calibration"),
    })
}

fn steering_mode(name: &str) -> Result<SteeringMode> {
    Ok(match name.to_ascii_lowercase().as_str() {
        "normal" => SteeringMode::Normal,
        "crab" => SteeringMode::Crab,
        "tank" => SteeringMode::Tank,
        other => bail!("steering mode '{other}' is not normal, crab or tank"),
    })
}

/// Apply a command line to the previous command (fields left out keep their value).
fn apply(line: &CommandLine, previous: AdsCommand) -> Result<AdsCommand> {
    Ok(AdsCommand {
        steering: line.steering.unwrap_or(previous.steering),
        velocity: line.velocity.unwrap_or(previous.velocity),
        brake: line.brake.unwrap_or(previous.brake),
        gear: line
            .gear
            .as_deref()
            .map(gear)
            .transpose()?
            .unwrap_or(previous.gear),
        mode: line
            .mode
            .as_deref()
            .map(mode)
            .transpose()?
            .unwrap_or(previous.mode),
        steering_mode: line
            .steering_mode
            .as_deref()
            .map(steering_mode)
            .transpose()?
            .unwrap_or(previous.steering_mode),
        // Edges: a request lasts for the line that asks for it.
        engage: line.engage.unwrap_or(false),
        operator_reset: line.operator_reset.unwrap_or(false),
    })
}

fn load_profile(name: &str) -> Result<LoadedProfile> {
    let loaded = if std::path::Path::new(name).exists() {
        Profile::load(std::path::Path::new(name))?
    } else {
        Profile::builtin(name)?
    };
    if loaded.profile.command.is_none() {
        bail!("--profile {name}: no [command] section (the autoware-can profile is an output format, not a vehicle to bridge)");
    }
    Ok(loaded)
}

/// A simulated vehicle: the supervisor on its own endpoint, with speed and steering following
/// the actuators, on a thread until `stop` closes.
fn spawn_vehicle(
    buses: Vec<(Channel, Box<dyn Bus>)>,
    profile: &LoadedProfile,
    wire: ProfileWire,
    start: Instant,
    stop: Receiver<()>,
) -> std::thread::JoinHandle<()> {
    let mut config = profile.supervisor_config();
    if buses.len() > 1 {
        config.redundancy = Some(Redundancy {
            timeout: config.cycle.saturating_mul(3),
            skew: Duration::from_millis(5),
        });
    }
    let mut supervisor = Supervisor::with_wire(config, wire);
    std::thread::spawn(move || {
        let (mut txs, mut rxs): (Vec<_>, Vec<_>) = buses
            .into_iter()
            .map(|(channel, bus)| {
                let (tx, rx) = bus.split();
                (tx, (channel, rx))
            })
            .unzip();
        // Bounded by the bridge: it closes `stop` when it ends.
        while matches!(stop.try_recv(), Err(TryRecvError::Empty)) {
            let now = since(start);
            for (channel, rx) in &mut rxs {
                while let Ok(Some(r)) = rx.recv(Some(Duration::from_micros(500))) {
                    supervisor.on_frame_from(since(start), *channel, &r.frame);
                }
            }
            let mut out = Vec::new();
            supervisor.poll(now, &mut |f| out.push(f));
            for f in out {
                for tx in &mut txs {
                    let _ = tx.send(&f);
                }
            }
            let a = supervisor.actuators(now);
            let speed = if a.brake > 0.0 || !a.motors_enabled {
                0.0
            } else {
                a.velocity
            };
            supervisor.set_feedback(speed, a.steering);
            std::thread::sleep(Duration::from_millis(2));
        }
    })
}

fn since(start: Instant) -> Timestamp {
    Timestamp::from_nanos(u64::try_from(start.elapsed().as_nanos()).unwrap_or(u64::MAX))
}

fn state_json(ads: &Ads<ProfileWire>, now: Timestamp) -> serde_json::Value {
    let s = ads.state();
    let age_ms = |at: Option<Duration>| at.map(|d| d.as_secs_f64() * 1e3);
    json!({
        "t_s": now.as_nanos() as f64 / 1e9,
        "feedback_alive": ads.feedback_alive(now),
        "mode": s.mode.value.map(|m| format!("{m:?}").to_lowercase()),
        "velocity": s.velocity.value,
        "steering": s.steering.value,
        "watchdog_level": s.watchdog_level.value,
        "estop_state": s.estop_state.value,
        "warning": s.warning.value,
        "driver_override": s.driver_override.value,
        "wheel_speeds": s.wheel_speeds.value,
        "echo_latency_ms": s.echo_latency.value.map(|d| d.as_secs_f64() * 1e3),
        "steering_response_ms": s.steering_response.value.map(|d| d.as_secs_f64() * 1e3),
        "odometry": s.odometry.value.map(|p| json!({"x": p.x, "y": p.y, "yaw": p.yaw})),
        "state_age_ms": age_ms(s.mode.age(now)),
        "rejected": {
            "checksum": ads.stats().checksum,
            "counter": ads.stats().counter,
            "echo": ads.stats().echo,
            "range": ads.stats().range,
        },
    })
}

fn event(out: &mut dyn Write, now: Timestamp, kind: &str, detail: &str) -> Result<()> {
    let line = json!({"t_s": now.as_nanos() as f64 / 1e9, "event": kind, "detail": detail});
    writeln!(out, "{line}")?;
    out.flush()?;
    Ok(())
}

/// Run the bridge until stdin ends (and, with `--estop-on-eof`, one second of braking).
pub fn run(args: &Args, out: &mut dyn Write) -> Result<()> {
    if !(args.rate > 0.0 && args.rate <= 1000.0) {
        bail!("--rate {}: between 0 and 1000 lines per second", args.rate);
    }
    let profile = load_profile(&args.profile)?;
    let specs: Vec<(Channel, &String)> = [
        (Channel::A, Some(&args.bus)),
        (Channel::B, args.bus2.as_ref()),
    ]
    .into_iter()
    .filter_map(|(channel, spec)| spec.map(|s| (channel, s)))
    .collect();
    let mut buses = Vec::new();
    for (_, spec) in &specs {
        buses.push(bywire_bus::open(spec).with_context(|| format!("bus {spec}"))?);
    }
    // Both sides speak the profile's messages by role, through the runtime codec.
    let wire = ProfileWire::new(&profile).with_context(|| format!("--profile {}", args.profile))?;
    let start = Instant::now();
    let (stop_vehicle, vehicle_stop) = mpsc::channel();
    let vehicle = if args.with_vehicle {
        let mut vehicle_buses = Vec::new();
        for (channel, spec) in &specs {
            let parsed: bywire_bus::BusSpec = spec.parse()?;
            if matches!(parsed, bywire_bus::BusSpec::SocketCan { .. }) {
                bail!("--with-vehicle needs in-process buses (virtual: or sim:), not {spec}");
            }
            vehicle_buses.push((*channel, bywire_bus::open(spec)?));
        }
        Some(spawn_vehicle(
            vehicle_buses,
            &profile,
            wire.clone(),
            start,
            vehicle_stop,
        ))
    } else {
        None
    };
    let (frames_in, frames) = mpsc::channel();
    let mut txs = Vec::new();
    for bus in buses {
        let (tx, rx) = bus.split();
        txs.push(tx);
        receive_thread(rx, frames_in.clone());
    }
    drop(frames_in);
    // The same feedback frame arrives once per bus: take the first copy.
    let mut recent: std::collections::VecDeque<(Timestamp, Frame)> =
        std::collections::VecDeque::new();
    let lines = stdin_thread();
    let mut ads = Ads::with_wire(profile.ads_config(), wire);
    let mut command = AdsCommand::default();
    let report = Duration::from_secs_f64(1.0 / args.rate);
    let mut next_report = since(start);
    let mut braking_until: Option<Timestamp> = None;
    let mut line_number = 0u64;
    // Each pass handles what arrived and what is due, then sleeps a millisecond; it ends when
    // stdin has ended (and the braking second has passed).
    loop {
        let now = since(start);
        loop {
            match lines.try_recv() {
                Ok(Ok(text)) => {
                    line_number += 1;
                    if text.trim().is_empty() {
                        continue;
                    }
                    let parsed = serde_json::from_str::<CommandLine>(&text)
                        .map_err(anyhow::Error::from)
                        .and_then(|line| Ok((apply(&line, command)?, line)));
                    match parsed {
                        Ok((next, line)) => {
                            if let Some(decel) = line.emergency_brake {
                                ads.emergency_brake(now, decel);
                                event(out, now, "emergency_brake", &format!("{decel} m/s²"))?;
                            }
                            if line.release_brake == Some(true) {
                                ads.release_brake();
                                event(out, now, "brake_released", "")?;
                            }
                            command = next;
                            if !ads.set_command(now, command) {
                                event(
                                    out,
                                    now,
                                    "bad_command",
                                    &format!("line {line_number}: not finite"),
                                )?;
                            }
                        }
                        Err(e) => {
                            event(out, now, "bad_command", &format!("line {line_number}: {e}"))?
                        }
                    }
                }
                Ok(Err(e)) => bail!("stdin: {e}"),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => {
                    if braking_until.is_none() {
                        if !args.estop_on_eof {
                            drop(stop_vehicle);
                            if let Some(v) = vehicle {
                                let _ = v.join();
                            }
                            return Ok(());
                        }
                        ads.emergency_brake(now, 4.0);
                        ads.set_command(
                            now,
                            AdsCommand {
                                velocity: 0.0,
                                brake: 100.0,
                                engage: false,
                                operator_reset: false,
                                ..command
                            },
                        );
                        event(out, now, "end_of_input", "braking for 1 s")?;
                        braking_until = Some(now.saturating_add(Duration::from_secs(1)));
                    }
                    break;
                }
            }
        }
        while let Ok(frame) = frames.try_recv() {
            recent.retain(|(at, _)| now.saturating_since(*at) < Duration::from_millis(10));
            if recent.iter().any(|(_, seen)| *seen == frame) {
                continue;
            }
            if recent.len() < 64 {
                recent.push_back((now, frame));
            }
            ads.on_frame(now, &frame);
        }
        let mut outgoing = Vec::new();
        ads.poll(now, &mut |f| outgoing.push(f));
        for f in outgoing {
            for tx in &mut txs {
                tx.send(&f).context("sending")?;
            }
        }
        if now >= next_report {
            writeln!(out, "{}", state_json(&ads, now))?;
            out.flush()?;
            next_report = next_report.saturating_add(report).max(now);
        }
        if braking_until.is_some_and(|until| now >= until) {
            drop(stop_vehicle);
            if let Some(v) = vehicle {
                let _ = v.join();
            }
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

fn receive_thread(mut rx: Box<dyn BusRx>, send: mpsc::Sender<Frame>) {
    std::thread::spawn(move || {
        // Ends when the bridge drops its end or the bus fails.
        while let Ok(received) = rx.recv(Some(Duration::from_millis(50))) {
            if let Some(r) = received {
                if send.send(r.frame).is_err() {
                    return;
                }
            }
        }
    });
}

fn stdin_thread() -> Receiver<std::io::Result<String>> {
    let (send, lines) = mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::stdin().lock().lines() {
            if send.send(line).is_err() {
                return;
            }
        }
    });
    lines
}
