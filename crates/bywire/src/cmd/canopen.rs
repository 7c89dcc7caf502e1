//! `bywire canopen`: scan a bus, read and write objects over SDO, send NMT commands, run a
//! CANopen device (an EDS-described one, the CiA 402 drive or the Roboteq controller) as a
//! stand-in for hardware, and check EDS files.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{anyhow, bail, Context, Result};
use bywire_bus::{runner, Bus};
use bywire_canopen::cia402::Drive;
use bywire_canopen::device::{Application, Device, DeviceEvent, Plain};
use bywire_canopen::eds::{self, Severity};
use bywire_canopen::master::{Master, MasterEvent};
use bywire_canopen::nmt::{HeartbeatEvent, NmtCommand, NmtState};
use bywire_canopen::od::{DataType, ObjectDictionary};
use bywire_canopen::roboteq::Mdc1460;
use bywire_canopen::scan::Scanner;
use bywire_canopen::sdo::{SdoOutcome, TransferMode};

use crate::support::busarg;
use crate::support::interrupt::interrupt_flag;
use crate::support::numbers::hex;

#[derive(clap::Subcommand)]
pub enum CanopenCommand {
    /// Find the nodes on a bus (SDO requests to every ID, heartbeats) and read their identity.
    #[command(
        after_help = "Example:\n  bywire canopen scan can0\n\nEvery node ID 1-127 is asked for 0x1000 over SDO; nodes that answer or send a heartbeat\nare listed with their NMT state, device type, identity (0x1018) and name (0x1008)."
    )]
    Scan {
        /// The bus.
        bus: String,
        /// How long to listen for answers and heartbeats, ms.
        #[arg(long, default_value_t = 500)]
        wait: u64,
    },
    /// Read or write an object over SDO.
    #[command(
        after_help = "Examples:\n  bywire canopen sdo can0 2 read 0x1008:0 --type str\n  bywire canopen sdo can0 2 read 0x6041 --eds drive.eds\n  bywire canopen sdo can0 2 write 0x6081:0 1500 --type u32\n  bywire canopen sdo can0 2 write 0x2F00 DEADBEEF --type hex --mode block\n\nTypes: bool u8 u16 u24 u32 u64 i8 i16 i24 i32 i64 f32 f64 str hex. Without --type or --eds a\nread prints the bytes in hex."
    )]
    Sdo {
        /// The bus.
        bus: String,
        /// The node ID.
        node: u8,
        #[command(subcommand)]
        action: SdoAction,
    },
    /// Send an NMT command and report the state the node's heartbeat shows afterwards.
    #[command(
        after_help = "Examples:\n  bywire canopen nmt can0 2 start\n  bywire canopen nmt can0 0 preop     (node 0: every node)"
    )]
    Nmt {
        /// The bus.
        bus: String,
        /// The node ID (0: all nodes).
        node: u8,
        /// start, stop, preop, reset or reset-comm.
        command: String,
        /// How long to wait for the node's heartbeat, ms.
        #[arg(long, default_value_t = 500)]
        wait: u64,
    },
    /// Run a CANopen device on a bus until Ctrl-C: SDO, NMT, heartbeat, EMCY and PDOs.
    #[command(
        after_help = "Examples:\n  bywire canopen node can0 --node 1 --profile roboteq\n  bywire canopen node virtual:bench --node 2 --profile cia402 --autostart\n  bywire canopen node can0 --node 5 --eds vendor.eds --export-eds seen.eds\n\nProfiles: roboteq (an MDC1460-like dual-channel controller with its motor model and\ncommand watchdog; RPDO1 0x200+ID is the motor command; like the real controller it also\nhas a CiA 402 face for channel 1: 0x6040/0x6041, modes 0x6060, targets 0x607A/0x60FF), cia402 (a CiA 402 drive with a motor\nmodel: profile position/velocity, cyclic synchronous position/velocity). With --eds any\ndevice the file describes answers SDO, NMT, heartbeat and its PDOs. NMT changes and\nheartbeat events are printed as they happen."
    )]
    Node {
        /// The bus.
        bus: String,
        /// The node ID.
        #[arg(long = "node")]
        id: u8,
        /// Describe the device with this EDS or DCF file.
        #[arg(long, conflicts_with = "profile", required_unless_present = "profile")]
        eds: Option<PathBuf>,
        /// A built-in device: roboteq or cia402.
        #[arg(long)]
        profile: Option<String>,
        /// Enter operational by itself after boot-up.
        #[arg(long)]
        autostart: bool,
        /// Write the device's dictionary as an EDS file (for a master such as python-canopen).
        #[arg(long, value_name = "FILE")]
        export_eds: Option<PathBuf>,
        /// Stop after this many seconds (default: until Ctrl-C).
        #[arg(long, value_parser = crate::support::numbers::positive_seconds)]
        duration: Option<f64>,
    },
    /// Check an EDS or DCF file: every diagnostic with its line, and what it describes.
    Eds {
        /// The file.
        file: PathBuf,
        /// Node ID for $NODEID values.
        #[arg(long)]
        node: Option<u8>,
    },
}

#[derive(clap::Subcommand)]
pub enum SdoAction {
    /// Read INDEX[:SUB].
    Read {
        /// The object, e.g. 0x1018:1.
        object: String,
        #[command(flatten)]
        how: SdoOptions,
    },
    /// Write VALUE to INDEX[:SUB].
    Write {
        /// The object.
        object: String,
        /// The value, as its type reads it.
        #[arg(allow_hyphen_values = true)]
        value: String,
        #[command(flatten)]
        how: SdoOptions,
    },
}

#[derive(clap::Args)]
pub struct SdoOptions {
    /// The value's type.
    #[arg(long = "type")]
    data_type: Option<String>,
    /// Take the type from this EDS/DCF file.
    #[arg(long)]
    eds: Option<PathBuf>,
    /// Transfer: auto (expedited up to 4 bytes), segmented, block.
    #[arg(long, default_value = "auto")]
    mode: String,
    /// SDO timeout, ms.
    #[arg(long, default_value_t = 1000)]
    timeout: u64,
}

pub fn run(command: &CanopenCommand, out: &mut impl Write) -> Result<()> {
    match command {
        CanopenCommand::Scan { bus, wait } => scan(bus, Duration::from_millis(*wait), out),
        CanopenCommand::Sdo { bus, node, action } => sdo(bus, *node, action, out),
        CanopenCommand::Nmt {
            bus,
            node,
            command,
            wait,
        } => nmt(bus, *node, command, Duration::from_millis(*wait), out),
        CanopenCommand::Node {
            bus,
            id,
            eds,
            profile,
            autostart,
            export_eds,
            duration,
        } => {
            let dictionary = |od: ObjectDictionary| -> Result<ObjectDictionary> {
                if let Some(path) = export_eds {
                    let info = eds::DeviceInfo {
                        vendor_name: "bywire".into(),
                        product_name: profile.clone().unwrap_or_else(|| "device".into()),
                        ..eds::DeviceInfo::default()
                    };
                    std::fs::write(path, eds::write(&od, &info, Some(*id)))
                        .with_context(|| format!("--export-eds {}", path.display()))?;
                }
                Ok(od)
            };
            let options = NodeOptions {
                bus,
                autostart: *autostart,
                duration: duration.map(Duration::from_secs_f64),
            };
            check_node_id(*id)?;
            match (eds, profile.as_deref()) {
                (Some(path), _) => {
                    let od = dictionary(load_eds(path, Some(*id), out)?)?;
                    run_device(Device::new(*id, od, Plain), &options, out)
                }
                (None, Some("roboteq")) => run_device(
                    Device::new(
                        *id,
                        dictionary(bywire_canopen::roboteq::dictionary(*id, 2))?,
                        Mdc1460::default(),
                    ),
                    &options,
                    out,
                ),
                (None, Some("cia402")) => run_device(
                    Device::new(
                        *id,
                        dictionary(bywire_canopen::cia402::drive_dictionary(*id))?,
                        Drive::new(),
                    ),
                    &options,
                    out,
                ),
                (None, Some(other)) => {
                    bail!("--profile {other}: not a built-in device (roboteq, cia402)")
                }
                (None, None) => bail!("give --eds FILE or --profile roboteq|cia402"),
            }
        }
        CanopenCommand::Eds { file, node } => check_eds(file, *node, out),
    }
}

fn check_node_id(id: u8) -> Result<()> {
    if (1..=127).contains(&id) {
        Ok(())
    } else {
        bail!("node ID {id}: CANopen node IDs are 1-127")
    }
}

/// Read an EDS (UTF-8 or Windows-1252) and print its diagnostics.
fn read_eds(path: &Path, node: Option<u8>, out: &mut impl Write) -> Result<eds::Eds> {
    let bytes = std::fs::read(path).with_context(|| format!("{}", path.display()))?;
    let loaded = eds::parse_bytes(&bytes, node).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    for diagnostic in &loaded.diagnostics {
        writeln!(out, "{}: {diagnostic}", path.display())?;
    }
    Ok(loaded)
}

/// Refuse an EDS whose objects had to be left out: a device, an SDO client and `canopen eds`
/// accept the same files.
fn refuse_errors(loaded: &eds::Eds, path: &Path) -> Result<()> {
    if loaded
        .diagnostics
        .iter()
        .any(|d| d.severity == Severity::Error)
    {
        bail!("{}: objects were left out (errors above)", path.display());
    }
    Ok(())
}

fn load_eds(path: &Path, node: Option<u8>, out: &mut impl Write) -> Result<ObjectDictionary> {
    let loaded = read_eds(path, node, out)?;
    refuse_errors(&loaded, path)?;
    Ok(loaded.dictionary)
}

fn check_eds(path: &Path, node: Option<u8>, out: &mut impl Write) -> Result<()> {
    let loaded = read_eds(path, node, out)?;
    let objects = loaded.dictionary.objects();
    let entries: usize = objects.iter().map(|o| o.entries().len()).sum();
    let rpdos = objects
        .iter()
        .filter(|o| (0x1400..=0x15FF).contains(&o.index))
        .count();
    let tpdos = objects
        .iter()
        .filter(|o| (0x1800..=0x19FF).contains(&o.index))
        .count();
    writeln!(
        out,
        "{}: {} {}: {} objects, {entries} entries, {rpdos} RPDOs, {tpdos} TPDOs",
        path.display(),
        loaded.info.vendor_name,
        loaded.info.product_name,
        objects.len()
    )?;
    refuse_errors(&loaded, path)
}

fn open_bus(text: &str) -> Result<Box<dyn Bus>> {
    busarg::open(text).with_context(|| format!("bus '{text}'"))
}

/// `INDEX[:SUB]` in hex (with or without 0x) — how CANopen tools write objects.
fn parse_object(text: &str) -> Result<(u16, u8)> {
    let (index, sub) = text.split_once(':').unwrap_or((text, "0"));
    let index = hex::<u16>(index.trim()).ok_or_else(|| {
        anyhow!("object '{text}': index '{index}' is not a hex number up to FFFF")
    })?;
    let sub = hex::<u8>(sub.trim()).ok_or_else(|| {
        anyhow!("object '{text}': sub-index '{sub}' is not a hex number up to FF")
    })?;
    Ok((index, sub))
}

fn parse_type(name: &str) -> Result<DataType> {
    Ok(match name {
        "bool" => DataType::Boolean,
        "u8" => DataType::Unsigned(1),
        "u16" => DataType::Unsigned(2),
        "u24" => DataType::Unsigned(3),
        "u32" => DataType::Unsigned(4),
        "u64" => DataType::Unsigned(8),
        "i8" => DataType::Integer(1),
        "i16" => DataType::Integer(2),
        "i24" => DataType::Integer(3),
        "i32" => DataType::Integer(4),
        "i64" => DataType::Integer(8),
        "f32" => DataType::Real32,
        "f64" => DataType::Real64,
        "str" => DataType::VisibleString,
        "hex" => DataType::Domain,
        other => bail!("--type {other}: not a type (bool u8 u16 u24 u32 u64 i8 i16 i24 i32 i64 f32 f64 str hex)"),
    })
}

fn parse_mode(name: &str) -> Result<TransferMode> {
    Ok(match name {
        "auto" => TransferMode::Auto,
        "segmented" => TransferMode::Segmented,
        "block" => TransferMode::Block,
        other => bail!("--mode {other}: not a transfer mode (auto, segmented, block)"),
    })
}

/// The type for `index:sub`: --type, else the EDS's, else none.
fn type_for(
    how: &SdoOptions,
    node: u8,
    index: u16,
    sub: u8,
    out: &mut impl Write,
) -> Result<Option<DataType>> {
    if let Some(name) = &how.data_type {
        return parse_type(name).map(Some);
    }
    let Some(path) = &how.eds else {
        return Ok(None);
    };
    let od = load_eds(path, Some(node), out)?;
    let entry = od.entry(index, sub).map_err(|abort| {
        anyhow!(
            "{}: 0x{index:04X}:{sub:02X}: {}",
            path.display(),
            abort.description()
        )
    })?;
    Ok(Some(entry.data_type))
}

/// Run a master until its one SDO transfer ends.
fn transfer(bus_text: &str, master: &mut Master, timeout: Duration) -> Result<SdoOutcome> {
    let bus = open_bus(bus_text)?;
    let stop = interrupt_flag();
    let mut outcome = None;
    runner::run_until(
        bus,
        master,
        &stop,
        Some(timeout + Duration::from_secs(1)),
        |m| {
            outcome = outcome.take().or_else(|| m.take_sdo_outcome());
            outcome.is_some()
        },
    )
    .with_context(|| format!("bus '{bus_text}'"))?;
    outcome.ok_or_else(|| anyhow!("interrupted"))
}

fn sdo(bus: &str, node: u8, action: &SdoAction, out: &mut impl Write) -> Result<()> {
    check_node_id(node)?;
    let (object, how) = match action {
        SdoAction::Read { object, how } | SdoAction::Write { object, how, .. } => (object, how),
    };
    let (index, sub) = parse_object(object)?;
    let mode = parse_mode(&how.mode)?;
    let data_type = type_for(how, node, index, sub, out)?;
    let timeout = Duration::from_millis(how.timeout);
    let mut master =
        Master::new(0, Duration::ZERO, Duration::from_millis(100)).with_sdo_timeout(timeout);
    let what = format!("node {node}, 0x{index:04X}:{sub:02X}");
    match action {
        SdoAction::Read { .. } => {
            master.sdo().upload(node, index, sub, mode)?;
            let bytes = transfer(bus, &mut master, timeout)?
                .result
                .map_err(|e| anyhow!("{what}: {e}"))?;
            let text = match data_type {
                Some(data_type) => data_type.format(&bytes),
                None => bytes
                    .iter()
                    .map(|b| format!("{b:02X}"))
                    .collect::<Vec<_>>()
                    .join(" "),
            };
            writeln!(out, "{text}")?;
        }
        SdoAction::Write { value, .. } => {
            let data_type = data_type.ok_or_else(|| {
                anyhow!("{what}: give --type or --eds to say how to write '{value}'")
            })?;
            let bytes = data_type.parse(value).map_err(|e| anyhow!("{what}: {e}"))?;
            master.sdo().download(node, index, sub, &bytes, mode)?;
            transfer(bus, &mut master, timeout)?
                .result
                .map_err(|e| anyhow!("{what}: {e}"))?;
        }
    }
    Ok(())
}

fn nmt(
    bus_text: &str,
    node: u8,
    command: &str,
    wait: Duration,
    out: &mut impl Write,
) -> Result<()> {
    let command = match command {
        "start" => NmtCommand::Start,
        "stop" => NmtCommand::Stop,
        "preop" | "pre-operational" => NmtCommand::EnterPreOperational,
        "reset" => NmtCommand::ResetNode,
        "reset-comm" => NmtCommand::ResetCommunication,
        other => bail!("'{other}': not an NMT command (start, stop, preop, reset, reset-comm)"),
    };
    if node > 127 {
        bail!("node {node}: CANopen node IDs are 1-127 (0: all)");
    }
    let mut master = Master::new(0, Duration::ZERO, Duration::from_millis(100));
    master.nmt(command, node);
    if node == 0 {
        let bus = open_bus(bus_text)?;
        runner::run_until(
            bus,
            &mut master,
            &interrupt_flag(),
            Some(Duration::from_millis(50)),
            |_| false,
        )?;
        writeln!(out, "all nodes: {} sent", command_name(command))?;
        return Ok(());
    }
    master.monitor(node, wait.max(Duration::from_millis(1)));
    // After a reset the node boots (boot-up message) and reports pre-operational: only the
    // states its heartbeats report after the boot-up count (one from before the reset, or the
    // boot-up's own "initialising", may come first, in a batch of its own on a loaded machine).
    let resets = command.target() == NmtState::BootUp;
    let mut booted = false;
    let mut seen = None;
    let bus = open_bus(bus_text)?;
    runner::run_until(bus, &mut master, &interrupt_flag(), Some(wait), |m| {
        while let Some(event) = m.next_event() {
            match event {
                MasterEvent::Heartbeat(HeartbeatEvent::BootUp { node: n }) if n == node => {
                    booted = true;
                    seen = None;
                }
                MasterEvent::Heartbeat(HeartbeatEvent::StateChanged { node: n, state })
                    if n == node && (booted || !resets) && state != NmtState::BootUp =>
                {
                    seen = Some(state)
                }
                _ => {}
            }
        }
        match (resets, seen) {
            (true, Some(_)) => booted,
            (false, Some(state)) => state == command.target(),
            (_, None) => false,
        }
    })?;
    let name = command_name(command);
    match (seen, booted) {
        (Some(state), true) => writeln!(out, "node {node}: boot-up, {}", state.name())?,
        (Some(state), false) => writeln!(out, "node {node}: {}", state.name())?,
        (None, true) => writeln!(out, "node {node}: boot-up")?,
        (None, false) => writeln!(
            out,
            "node {node}: {name} sent; no heartbeat within {} ms",
            wait.as_millis()
        )?,
    }
    Ok(())
}

fn command_name(command: NmtCommand) -> &'static str {
    match command {
        NmtCommand::Start => "start",
        NmtCommand::Stop => "stop",
        NmtCommand::EnterPreOperational => "preop",
        NmtCommand::ResetNode => "reset",
        NmtCommand::ResetCommunication => "reset-comm",
    }
}

fn scan(bus_text: &str, wait: Duration, out: &mut impl Write) -> Result<()> {
    let bus = open_bus(bus_text)?;
    let mut scanner = Scanner::default();
    runner::run_until(bus, &mut scanner, &interrupt_flag(), Some(wait), |_| false)?;
    if scanner.found().is_empty() {
        writeln!(out, "no nodes answered within {} ms", wait.as_millis())?;
        return Ok(());
    }
    writeln!(
        out,
        "node  state            device type  vendor      product     revision    serial      name"
    )?;
    for (node, state) in scanner.found() {
        let read = |index: u16, sub: u8| -> Result<Option<Vec<u8>>> {
            let mut master = Master::new(0, Duration::ZERO, Duration::from_millis(100))
                .with_sdo_timeout(Duration::from_millis(300));
            master.sdo().upload(*node, index, sub, TransferMode::Auto)?;
            Ok(transfer(bus_text, &mut master, Duration::from_millis(300))?
                .result
                .ok())
        };
        let hex32 = |bytes: Option<Vec<u8>>| match bytes.as_deref() {
            Some([a, b, c, d]) => format!("0x{:08X}", u32::from_le_bytes([*a, *b, *c, *d])),
            _ => "-".to_string(),
        };
        let device_type = hex32(read(0x1000, 0)?);
        let identity: Vec<String> = (1..=4)
            .map(|sub| read(0x1018, sub).map(hex32))
            .collect::<Result<_>>()?;
        let name = read(0x1008, 0)?.map_or_else(
            || "-".to_string(),
            |b| String::from_utf8_lossy(&b).into_owned(),
        );
        let state = state.map_or("-", NmtState::name);
        writeln!(
            out,
            "{node:>4}  {state:<15}  {device_type:<11}  {}  {name}",
            identity
                .iter()
                .map(|s| format!("{s:<10}"))
                .collect::<Vec<_>>()
                .join("  ")
        )?;
    }
    Ok(())
}

struct NodeOptions<'a> {
    bus: &'a str,
    autostart: bool,
    duration: Option<Duration>,
}

fn run_device<A: Application>(
    device: Device<A>,
    options: &NodeOptions<'_>,
    out: &mut impl Write,
) -> Result<()> {
    let mut device = if options.autostart {
        device.with_autostart()
    } else {
        device
    };
    let bus = open_bus(options.bus)?;
    let node = device.node();
    writeln!(out, "node {node} on {}", options.bus)?;
    out.flush()?;
    let mut failure = None;
    runner::run_until(
        bus,
        &mut device,
        &interrupt_flag(),
        options.duration,
        |device| {
            while let Some(event) = device.next_event() {
                let line = match event {
                    DeviceEvent::Nmt(state) => Some(format!("nmt {}", state.name())),
                    DeviceEvent::Heartbeat(HeartbeatEvent::Lost { node }) => {
                        Some(format!("heartbeat of node {node} lost"))
                    }
                    DeviceEvent::Heartbeat(HeartbeatEvent::Recovered { node, state }) => {
                        Some(format!("heartbeat of node {node} back: {}", state.name()))
                    }
                    DeviceEvent::LifeGuardLost => Some("life guarding lost".to_string()),
                    DeviceEvent::Pdo(event) => Some(format!("pdo {event:?}")),
                    DeviceEvent::Heartbeat(_) | DeviceEvent::Written { .. } => None,
                };
                if let Some(line) = line {
                    if let Err(e) = writeln!(out, "{line}").and_then(|()| out.flush()) {
                        failure = Some(e);
                        return true;
                    }
                }
            }
            false
        },
    )
    .with_context(|| format!("bus '{}'", options.bus))?;
    match failure {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}
