//! `bywire ros2`: ROS 2 over DDS without a ROS installation (the `bywire-ros` crate): the CAN
//! bridge ros2_socketcan offers, and the controller-side Autoware output.

use std::io::Write;

use anyhow::{anyhow, bail, Context, Result};
use bywire_ros::can_bridge::{self, BridgeEvent, BridgedBus, CanBridgeConfig, CanTopics};
use bywire_ros::control_output::{self, ControlOutputConfig, Outcome};
use bywire_ros::vehicle_interface::{self, VehicleEvent, VehicleInterfaceConfig};
use bywire_vehicle::autoware::OutputMode;

use crate::support::busarg;
use crate::support::interrupt::interrupt_flag;
use crate::support::ros2::NodeArgs;

/// Refusals printed before the rest are only counted.
const REFUSALS_SHOWN: u64 = 20;

#[derive(clap::Subcommand)]
pub enum Ros2Command {
    /// CAN buses as ROS 2 topics, a drop-in for Autoware's ros2_socketcan: received frames on
    /// from_can_bus (CAN FD on from_can_bus_fd), what arrives on to_can_bus (to_can_bus_fd)
    /// is sent.
    #[command(after_help = "Examples:
  bywire ros2 can can0
  bywire ros2 can can0,123:7FF --use-bus-time --namespace /sensing/can
  bywire ros2 can vcan0 vcan1            (topics under /vcan0/... and /vcan1/..., frame_id the bus)
  bywire ros2 can can0 --remap to_can_bus:=/vehicle/can_tx --dds-interface lo

Filters follow the bus as in candump (ID:MASK, ID~MASK, #ERRMASK, j) and select what is
published. Classic, remote and error frames go on from_can_bus as can_msgs/msg/Frame; CAN FD
frames on from_can_bus_fd as ros2_socketcan_msgs/msg/FdFrame (with --enable-can-fd every frame
goes there, as ros2_socketcan's enable_can_fd). A message that makes no valid frame (an id
beyond its width, DLC above 15, an FD length CAN FD has no code for, is_error) is refused on
stderr and nothing is sent. QoS as ros2_socketcan: reliable, volatile, depth 500.")]
    Can(CanArgs),
    /// Autoware's controller output on a Linux box: Control from a topic, out as the three
    /// autoware-can frames (0x100, 0x101, 0x102), republished on DDS, or both.
    #[command(after_help = "Examples:
  bywire ros2 control-output can0 --mode can
  bywire ros2 control-output can0 --mode dds-and-can --input /control/trajectory_follower/control_cmd

A command with a non-finite or out-of-range value is refused whole: no frame and no sample; one
that decelerates harder than 10 m/s² goes out as a stop at 10 m/s² (said on stderr). Any end
(SIGINT, SIGTERM, SIGHUP, a DDS failure) sends that stop, holding the last steering, for a
second before exiting (nothing new is taken meanwhile). The frames follow `autoware-can.dbc` (bywire-vehicle/dbc): angle and rate x 1e6, velocity and
acceleration x 1e3 as int32, then mode, validity flags, sequence and the stamp in ms.")]
    ControlOutput(ControlOutputArgs),
    /// The Autoware vehicle interface for any profile: control_cmd, gear_cmd, cmd_vel and the
    /// control-mode service in; steering, velocity, gear and control-mode status out, and the
    /// 4WS truth Autoware lacks (the wheels as JointState, the steering mode).
    #[command(after_help = "Examples:
  bywire ros2 vehicle --profile reference-tug can0
  bywire ros2 vehicle --profile reference-tug can0 can1          (a redundant pair)
  bywire ros2 vehicle --profile reference-tug virtual:v --with-vehicle

In:  /control/command/control_cmd (autoware_control_msgs/Control: the tire angle through the
     vehicle's geometry, velocity, a deceleration as brake), /control/command/gear_cmd,
     /vehicle/command/steering_mode (std_msgs/String: normal, crab, tank), /cmd_vel
     (geometry_msgs/Twist through the 4WS kinematics), /control/command/
     {turn_indicators_cmd, hazard_lights_cmd} where the profile's [command] has
     turn_indicators and hazard_lights, /control/command/emergency_cmd
     (tier4_vehicle_msgs/VehicleEmergencyStamped: the emergency brake and a stop, disengaged,
     while it holds; driving again takes an engage), and the service /control/control_mode_request
     (autoware_vehicle_msgs/ControlModeCommand: 1 engages, answered when the vehicle reports
     autonomous; 4 disengages).
Out: /vehicle/status/{steering_status, velocity_status, gear_status, control_mode,
     joint_states, steering_mode} at --rate, from fresh feedback only, and
     {turn_indicators_status, hazard_lights_status} where the profile's [state] has them,
     and degradation (std_msgs/String: the level and its reason, e.g. \"minimal-risk
     (actuator-backup)\") where the profile declares [fail_operational.report];
     /diagnostics (diagnostic_msgs/DiagnosticArray, as diagnostic_aggregator reads it) once a
     second and on every change: the vehicle (OK, WARN for a watchdog holding or decelerating,
     a degraded level or a driver's override, ERROR for an E-stop, a safe stop or full braking
     while engaged, STALE without its state) with its watchdog, E-stop and mode, and each bus
     (up, or lost with its error).
     control_mode is DISENGAGED (5) after an E-stop, and while the vehicle's watchdog brakes
     (full braking, or awaiting a re-engage): engage again to drive.
Keep publishing control_cmd: one older than the profile's staleness (200 ms for reference-tug)
is replaced by a controlled stop. A command beyond the profile's limits is refused, never
clamped, each field checked before any conversion (a tire angle within the profile's steering
limit as a tire angle, never beyond ±90°); a deceleration beyond the vehicle's is a stop at full
brake (said on stderr). The E-stop's operator reset is not offered over ROS 2. Any end (SIGINT,
SIGTERM, SIGHUP) brakes for a second, taking no input meanwhile.")]
    Vehicle(VehicleArgs),
    /// CANopen drives on ROS 2, as ros2_canopen's CiA 402 driver offers them: the master of a
    /// bus description (bywire's bus.toml or ros2_canopen's bus.yml) with services, targets
    /// and states per drive.
    #[command(after_help = "Examples:
  bywire ros2 canopen can0 --config bus.toml
  bywire ros2 canopen can0 --config bus.yml --namespace /drives

Per CiA 402 drive NAME: services NAME/{init, enable, disable, halt, recover, position_mode,
velocity_mode, cyclic_position_mode, cyclic_velocity_mode} (std_srvs/Trigger; init and
recover answer once the drive reports Operation enabled), NAME/target (the set-point in drive
units: canopen_interfaces/COTargetDouble service and std_msgs/Float64 topic), and
NAME/joint_states (sensor_msgs/JointState), NAME/nmt_state and NAME/drive_state
(std_msgs/String) at --rate. Heartbeat loss, an emergency or a fault stop the drive until
recover. Ctrl-C quick-stops every drive before exiting.")]
    Canopen(CanopenArgs),
}

#[derive(clap::Args)]
pub struct CanArgs {
    /// Buses, each with optional candump filters and a label: [LABEL=]BUS[,ID:MASK|ID~MASK|#ERRMASK|j]*
    #[arg(required = true, num_args = 1..=16)]
    buses: Vec<String>,
    #[command(flatten)]
    node: NodeArgs,
    /// header.frame_id of published frames (default: `can` for one bus, the bus's name for
    /// several).
    #[arg(long)]
    frame_id: Option<String>,
    /// Stamp frames with their reception time on the bus, not the time they are published.
    #[arg(long)]
    use_bus_time: bool,
    /// Publish the frames this bridge sends as well (on) or not (off).
    #[arg(long, default_value = "on", value_parser = ["on", "off"])]
    loopback: String,
    /// Publish every frame, classic ones too, on from_can_bus_fd.
    #[arg(long)]
    enable_can_fd: bool,
    /// Send FD frames without the bit-rate switch.
    #[arg(long)]
    no_brs: bool,
    /// Rename a topic: from_can_bus:=NAME (also to_can_bus, from_can_bus_fd, to_can_bus_fd).
    #[arg(long = "remap", value_name = "FROM:=TO")]
    remaps: Vec<String>,
}

/// Apply `FROM:=TO` remappings to the topic names.
fn remap(remaps: &[String]) -> Result<CanTopics> {
    let mut topics = CanTopics::default();
    for text in remaps {
        let (from, to) = text
            .split_once(":=")
            .ok_or_else(|| anyhow!("--remap {text}: expected FROM:=TO"))?;
        let slot = match from.trim_start_matches('/') {
            "from_can_bus" => &mut topics.from_can_bus,
            "to_can_bus" => &mut topics.to_can_bus,
            "from_can_bus_fd" => &mut topics.from_can_bus_fd,
            "to_can_bus_fd" => &mut topics.to_can_bus_fd,
            other => bail!(
                "--remap {text}: '{other}' is not a topic of this bridge (from_can_bus, \
                 to_can_bus, from_can_bus_fd, to_can_bus_fd)"
            ),
        };
        bywire_ros::dds::name(to).with_context(|| format!("--remap {text}"))?;
        *slot = to.to_string();
    }
    Ok(topics)
}

/// Stderr lines for what the bridges report (refusals capped).
struct Reporter {
    command: &'static str,
    refused: u64,
}

impl Reporter {
    fn line(&self, text: &str) {
        let _ = writeln!(std::io::stderr(), "bywire ros2 {}: {text}", self.command);
    }

    fn refusal(&mut self, text: &str) {
        self.refused += 1;
        if self.refused <= REFUSALS_SHOWN {
            self.line(&format!("refused: {text}"));
        }
        if self.refused == REFUSALS_SHOWN {
            self.line("further refusals are only counted");
        }
    }
}

pub fn run(command: &Ros2Command, out: &mut dyn Write) -> Result<()> {
    match command {
        Ros2Command::Can(args) => can(args, out),
        Ros2Command::ControlOutput(args) => control(args, out),
        Ros2Command::Vehicle(args) => vehicle(args, out),
        Ros2Command::Canopen(args) => canopen(args, out),
    }
}

fn can(args: &CanArgs, out: &mut dyn Write) -> Result<()> {
    let config = CanBridgeConfig {
        topics: remap(&args.remaps)?,
        frame_id: args.frame_id.clone(),
        use_bus_time: args.use_bus_time,
        loopback: args.loopback == "on",
        fd_for_all: args.enable_can_fd,
        brs: !args.no_brs,
    };
    let parsed: Vec<busarg::BusArg> = args
        .buses
        .iter()
        .map(|b| busarg::parse(b))
        .collect::<Result<_>>()?;
    let opened = busarg::open_all(&parsed)?;
    let buses = parsed
        .into_iter()
        .zip(opened)
        .map(|(arg, bus)| BridgedBus {
            name: arg.name,
            bus,
        })
        .collect();
    let mut node = args.node.open("socket_can_bridge")?;
    let mut reporter = Reporter {
        command: "can",
        refused: 0,
    };
    reporter.line(&format!("node {} bridging", node.fully_qualified_name()));
    let stats =
        can_bridge::run(
            &mut node,
            buses,
            &config,
            &interrupt_flag(),
            &mut |event| match event {
                BridgeEvent::Refused { bus, why } => reporter.refusal(&format!("{bus}: {why}")),
                BridgeEvent::BusLost { bus, error } => {
                    reporter.line(&format!("bus {bus} lost: {error}; the others go on"))
                }
                BridgeEvent::PublishFailed { bus, error } => {
                    reporter.line(&format!("{bus}: {error}"))
                }
                BridgeEvent::NoEcho { bus, why } => reporter.line(&format!(
                    "bus {bus}: frames sent are not published back as received ({why})"
                )),
            },
        )?;
    writeln!(
        out,
        "{} frames published, {} sent, {} refused",
        stats.published, stats.sent, stats.refused
    )?;
    Ok(())
}

#[derive(clap::Args)]
pub struct ControlOutputArgs {
    /// The bus the frames go on.
    bus: String,
    #[command(flatten)]
    node: NodeArgs,
    /// Where commands go: can, dds or dds-and-can.
    #[arg(long, default_value = "can")]
    mode: OutputMode,
    /// The Control topic read.
    #[arg(long, default_value = control_output::INPUT_TOPIC)]
    input: String,
    /// The Control topic written in the dds modes.
    #[arg(long, default_value = control_output::OUTPUT_TOPIC)]
    output: String,
    /// The mode byte of 0x102 (1 autonomous, 2 manual, 3 remote).
    #[arg(long, default_value_t = 1)]
    mode_byte: u8,
}

fn control(args: &ControlOutputArgs, out: &mut dyn Write) -> Result<()> {
    let config = ControlOutputConfig {
        mode: args.mode,
        input: args.input.clone(),
        output: args.output.clone(),
        mode_byte: args.mode_byte,
        ..ControlOutputConfig::default()
    };
    let bus = busarg::open(&args.bus).with_context(|| format!("bus {}", args.bus))?;
    let mut node = args.node.open("control_output")?;
    let mut reporter = Reporter {
        command: "control-output",
        refused: 0,
    };
    let mut sent = 0u64;
    reporter.line(&format!(
        "node {} reading {}",
        node.fully_qualified_name(),
        config.input
    ));
    control_output::run(
        &mut node,
        bus,
        &config,
        &interrupt_flag(),
        &mut |_, outcome| match outcome {
            Outcome::Sent(_) => sent += 1,
            Outcome::Refused(why) => reporter.refusal(&why.to_string()),
            Outcome::BusLost(e) => reporter.line(&format!("bus lost: {e}")),
            Outcome::Saturated(why) => reporter.line(&why),
            Outcome::Unreadable(why) => {
                reporter.refusal(&format!("a sample that cannot be read: {why}"))
            }
        },
    )?;
    writeln!(out, "{sent} commands sent, {} refused", reporter.refused)?;
    Ok(())
}

#[derive(clap::Args)]
pub struct VehicleArgs {
    /// A shipped profile (reference-tug) or a profile file.
    #[arg(long)]
    profile: String,
    /// The bus (a plain interface name means SocketCAN).
    bus: String,
    /// A redundant second bus: every command goes on both, feedback is taken from either.
    bus2: Option<String>,
    #[command(flatten)]
    node: NodeArgs,
    /// Reports per second.
    #[arg(long, default_value_t = 30.0, value_parser = crate::support::numbers::rate)]
    rate: f64,
    /// Run a simulated vehicle (`bywire vehicle`) on the same in-process buses.
    #[arg(long)]
    with_vehicle: bool,
    #[command(flatten)]
    secoc: crate::support::vehicles::SecOcArgs,
}

fn vehicle(args: &VehicleArgs, out: &mut dyn Write) -> Result<()> {
    use crate::support::vehicles;
    let profile = vehicles::load_profile(&args.profile)?;
    let specs = vehicles::command_buses(&args.bus, args.bus2.as_ref());
    let stop_vehicle = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let (wire, freshness) = args.secoc.wire(&profile)?;
    let simulated = if args.with_vehicle {
        Some(vehicles::spawn_in_process(
            &specs,
            &profile,
            wire.clone(),
            &stop_vehicle,
        )?)
    } else {
        None
    };
    let buses = vehicles::endpoints(&specs)?
        .into_iter()
        .zip(&specs)
        .map(|((port, bus), (_, name))| (port, name.clone(), bus))
        .collect();
    let config = VehicleInterfaceConfig {
        report_period: std::time::Duration::from_secs_f64(1.0 / args.rate),
        ..VehicleInterfaceConfig::default()
    };
    let mut node = args.node.open("vehicle_interface")?;
    let mut reporter = Reporter {
        command: "vehicle",
        refused: 0,
    };
    reporter.line(&format!(
        "node {} for {}",
        node.fully_qualified_name(),
        profile.profile.name
    ));
    let result = vehicle_interface::run(
        &mut node,
        &profile,
        (wire, freshness),
        buses,
        &config,
        &interrupt_flag(),
        &mut |event| match event {
            VehicleEvent::Refused(why) => reporter.refusal(&why),
            other => reporter.line(&other.to_string()),
        },
    );
    stop_vehicle.store(true, std::sync::atomic::Ordering::Relaxed);
    if let Some(simulated) = simulated {
        let _ = simulated.join();
    }
    result?;
    writeln!(out, "{} inputs refused", reporter.refused)?;
    Ok(())
}

#[derive(clap::Args)]
pub struct CanopenArgs {
    /// The bus.
    bus: String,
    /// The bus description: bus.toml (bywire's) or bus.yml (ros2_canopen's).
    #[arg(long)]
    config: std::path::PathBuf,
    #[command(flatten)]
    node: NodeArgs,
    /// Joint and state reports per second.
    #[arg(long, default_value_t = 50.0, value_parser = crate::support::numbers::rate)]
    rate: f64,
}

fn canopen(args: &CanopenArgs, out: &mut dyn Write) -> Result<()> {
    use bywire_canopen::config::BusConfig;
    use bywire_ros::canopen_bridge::{self, CanopenEvent};
    let path = &args.config;
    let yaml = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("yml") || e.eq_ignore_ascii_case("yaml"));
    let config = if yaml {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("--config {}", path.display()))?;
        let base = path.parent().unwrap_or(std::path::Path::new("."));
        BusConfig::parse_ros2_canopen(&text, &path.display().to_string(), base)?
    } else {
        BusConfig::load(path)?
    };
    let reporter = Reporter {
        command: "canopen",
        refused: 0,
    };
    for node in &config.nodes {
        for warning in &node.warnings {
            reporter.line(&format!("{} (node {}): {warning}", node.name, node.id));
        }
    }
    let bus = busarg::open(&args.bus).with_context(|| format!("bus {}", args.bus))?;
    let mut node = args.node.open("canopen_master")?;
    reporter.line(&format!(
        "node {} for {}",
        node.fully_qualified_name(),
        path.display()
    ));
    let mut calls = 0u64;
    canopen_bridge::run(
        &mut node,
        &config,
        bus,
        std::time::Duration::from_secs_f64(1.0 / args.rate),
        &interrupt_flag(),
        &mut |event| match event {
            CanopenEvent::Called {
                drive,
                service,
                success,
                message,
            } => {
                calls += 1;
                reporter.line(&format!(
                    "{drive}/{service}: {} ({message})",
                    if success { "done" } else { "refused" }
                ));
            }
            CanopenEvent::Stopped { drive, why } => {
                reporter.line(&format!("{drive} stopped: {why}"))
            }
            CanopenEvent::NotExposed(what) => reporter.line(&format!("not exposed: {what}")),
            CanopenEvent::BusLost(e) => reporter.line(&format!("bus lost: {e}")),
        },
    )?;
    writeln!(out, "{calls} service calls")?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn remaps_name_the_topic_and_check_the_name() {
        let t = remap(&["to_can_bus:=/vehicle/can_tx".into()]).unwrap();
        assert_eq!(t.to_can_bus, "/vehicle/can_tx");
        assert_eq!(t.from_can_bus, "from_can_bus");
        assert!(remap(&["x:=y".into()])
            .unwrap_err()
            .to_string()
            .contains("'x' is not a topic"));
        assert!(remap(&["from_can_bus".into()]).is_err());
        assert!(
            format!("{:#}", remap(&["from_can_bus:=a b".into()]).unwrap_err()).contains("'a b'")
        );
    }
}
