//! `bywire uds`: a UDS tester on any bus (`session`, `read-did`, `write-did`, `read-dtc`,
//! `clear-dtc`, `routine`, `reset`, `security`, `tester-present`, `dtc-setting`,
//! `comm-control`, `raw`), with udsoncan's habits, and `uds serve`, a server with the DIDs and
//! DTCs given on the command line — an ECU for testers to talk to. Both are `bywire-diag`'s
//! nodes on the real-time runner.

use std::io::Write;

use anyhow::{anyhow, bail, Context, Result};
use bywire_bus::runner::{Flow, Runner};
use bywire_core::node::Port;
use bywire_core::Timestamp;
use bywire_diag::client::{self, ClientError, ClientTiming, UdsClient};
use bywire_diag::describe::{self, Description};
use bywire_diag::isotp::{IsoTpConfig, DEFAULT_TIMEOUT};
use bywire_diag::tester::{Plan, RoutineControl, Script, ScriptError, Service};
use bywire_diag::uds::{Did, Routine, Session, UdsEvent, UdsServer, UdsTiming};
use serde_json::{json, Value};

use crate::support::busarg;
use crate::support::interrupt::interrupt_flag;
use crate::support::numbers::{can_id, extended_addressing, hex, hex_pairs};

/// How the tester reaches the ECU, and what it does first.
#[derive(clap::Args)]
pub struct Tester {
    /// The bus (a plain interface name means SocketCAN).
    bus: String,
    /// The identifier requests go out with (hex; 8 digits: extended).
    #[arg(long, default_value = "7E0")]
    tx: String,
    /// The identifier answers come on (hex).
    #[arg(long, default_value = "7E8")]
    rx: String,
    /// Extended addressing: the ECU's address byte [and the tester's].
    #[arg(short = 'x', value_name = "ADDR[:RXADDR]")]
    extended: Option<String>,
    /// Pad every frame with this byte (hex).
    #[arg(long, value_name = "BYTE")]
    padding: Option<String>,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    /// The ECU's DIDs and DTCs: a TOML description file, a CANdela CDD (its DIDs' records
    /// decoded field by field), or `tug` (the reference tug).
    #[arg(long, value_name = "FILE|tug")]
    describe: Option<String>,
    /// Change to this session first (1 default, 2 programming, 3 extended).
    #[arg(long, value_name = "N")]
    session: Option<u8>,
    /// Then unlock this security level (odd) with --key-fn.
    #[arg(long, value_name = "LEVEL")]
    security: Option<u8>,
    /// The key function: demo (the demonstration key), xor:HEX (the seed XOR these bytes,
    /// repeated), or exec:PROGRAM (run as PROGRAM LEVEL SEED_HEX, printing the key in hex).
    #[arg(long, value_name = "FN", default_value = "demo")]
    key_fn: String,
    /// P2: how long the first answer may take, ms (the server's, once a session is set).
    #[arg(long, default_value_t = 1000)]
    p2_ms: u64,
    /// P2*: how long an answer may take after response pending, ms.
    #[arg(long, default_value_t = 5000)]
    p2_star_ms: u64,
}

#[derive(clap::Subcommand)]
pub enum UdsCommand {
    /// DiagnosticSessionControl: change the session.
    #[command(after_help = "Examples:
  bywire uds session can0 3
  bywire uds session vcan0 --tx 18DA10F1 --rx 18DAF110 2")]
    Session {
        #[command(flatten)]
        tester: Tester,
        /// 1 default, 2 programming, 3 extended (or a name, or any sub-function as 0xNN).
        #[arg(value_name = "SESSION")]
        code: String,
    },
    /// ReadDataByIdentifier: one or more DIDs (hex) in one request.
    #[command(after_help = "Examples:
  bywire uds read-did can0 F190 F195
  bywire uds read-did can0 F190 0301 --describe tug --json

With several DIDs, each but the last needs its length from --describe.")]
    ReadDid {
        #[command(flatten)]
        tester: Tester,
        /// The DIDs (hex).
        #[arg(required = true)]
        dids: Vec<String>,
    },
    /// WriteDataByIdentifier: a DID and its value (text, or hex:BYTES).
    #[command(after_help = "Examples:
  bywire uds write-did can0 --session 3 --security 1 0200 hex:0000001400000000")]
    WriteDid {
        #[command(flatten)]
        tester: Tester,
        /// The DID (hex).
        did: String,
        /// The value: text, or hex:BYTES.
        value: String,
    },
    /// ReadDTCInformation: the DTCs matching a status mask, with their status bits (and
    /// snapshots and occurrence counts with --snapshots).
    #[command(after_help = "Examples:
  bywire uds read-dtc can0
  bywire uds read-dtc can0 --status 01 --describe tug      (failing now)
  bywire uds read-dtc can0 --snapshots --describe tug --json")]
    ReadDtc {
        #[command(flatten)]
        tester: Tester,
        /// The status mask (hex).
        #[arg(long, default_value = "FF")]
        status: String,
        /// Also read each DTC's snapshot records (0x04) and extended data (0x06).
        #[arg(long)]
        snapshots: bool,
        /// Only count them (0x01).
        #[arg(long, conflicts_with = "snapshots")]
        count: bool,
    },
    /// ClearDiagnosticInformation: a DTC group (hex; FFFFFF: all).
    ClearDtc {
        #[command(flatten)]
        tester: Tester,
        /// The group.
        #[arg(default_value = "FFFFFF")]
        group: String,
    },
    /// RoutineControl: start, stop or results of a routine (hex), with optional data.
    #[command(after_help = "Examples:
  bywire uds routine can0 --session 3 --security 1 start 0203
  bywire uds routine can0 --session 3 results 0203")]
    Routine {
        #[command(flatten)]
        tester: Tester,
        /// start, stop or results.
        #[arg(value_parser = ["start", "stop", "results"])]
        action: String,
        /// The routine (hex).
        routine: String,
        /// Its option record (hex bytes).
        data: Option<String>,
    },
    /// ECUReset: hard, keyoffon, soft, or a sub-function (hex).
    Reset {
        #[command(flatten)]
        tester: Tester,
        /// The kind.
        #[arg(default_value = "hard")]
        kind: String,
    },
    /// SecurityAccess: ask a seed at LEVEL (odd) and send the key --key-fn computes.
    #[command(after_help = "Examples:
  bywire uds security can0 --session 3 1
  bywire uds security can0 --session 3 3 --key-fn exec:./seed2key")]
    Security {
        #[command(flatten)]
        tester: Tester,
        /// The level (odd).
        level: u8,
    },
    /// TesterPresent.
    TesterPresent {
        #[command(flatten)]
        tester: Tester,
    },
    /// ControlDTCSetting: on or off (needs a non-default session).
    DtcSetting {
        #[command(flatten)]
        tester: Tester,
        /// on or off.
        #[arg(value_parser = ["on", "off"])]
        setting: String,
    },
    /// CommunicationControl: the control type (0 enable rx/tx … 3 disable both) and the
    /// communication type (1 normal, 2 network management, 3 both).
    CommControl {
        #[command(flatten)]
        tester: Tester,
        /// The control type.
        control: u8,
        /// The communication type.
        #[arg(default_value_t = 1)]
        communication: u8,
    },
    /// Any request, as hex bytes; prints the positive answer in hex.
    Raw {
        #[command(flatten)]
        tester: Tester,
        /// The request (hex bytes, e.g. 22F190 or "22 F1 90").
        #[arg(required = true)]
        request: Vec<String>,
    },
    /// Answer UDS requests on a bus until Ctrl-C, printing what the tester did.
    #[command(after_help = "Examples:
  bywire uds serve can0 --did F190=WBYWIRE0TUG000042 --did F195=1.4.0
  bywire uds serve vcan0 --tx 7E8 --rx 7E0 --did 0101=hex:0000:rw --dtc C10100 --dtc 512300:passed

A DID's value is text, or hex:BYTES; :rw makes it writable in the extended session, :rws
writable there after SecurityAccess. A DTC (hex, 24 bits) is reported failed (testFailed,
pending, confirmed, ...) or, with :passed, failed once and passed since. SecurityAccess uses
the demonstration key (each seed byte XOR 0x5A, plus the level): not a secret.")]
    Serve {
        /// The bus (a plain interface name means SocketCAN).
        bus: String,
        /// The identifier answers go out with (hex).
        #[arg(long, default_value = "7E8")]
        tx: String,
        /// The identifier requests come on (hex).
        #[arg(long, default_value = "7E0")]
        rx: String,
        /// Also take functional requests on this identifier (hex, e.g. 7DF).
        #[arg(long)]
        functional: Option<String>,
        /// A data identifier: ID=VALUE (text or hex:BYTES), :rw for writable.
        #[arg(long = "did", value_name = "ID=VALUE[:rw]")]
        dids: Vec<String>,
        /// A DTC: CODE[:passed].
        #[arg(long = "dtc", value_name = "CODE[:passed]")]
        dtcs: Vec<String>,
        /// A routine: ID=MILLISECONDS it runs[:hex:RESULT] (answered with response pending
        /// when it takes time).
        #[arg(long = "routine", value_name = "ID=MS[:hex:RESULT]")]
        routines: Vec<String>,
    },
}

fn parse_did(text: &str) -> Result<(u16, Did)> {
    let (id, rest) = text
        .split_once('=')
        .ok_or_else(|| anyhow!("--did {text}: expected ID=VALUE"))?;
    let id = hex::<u16>(id).ok_or_else(|| anyhow!("--did {text}: '{id}' is not a hex DID"))?;
    let (value, writable, secured) = match (rest.strip_suffix(":rws"), rest.strip_suffix(":rw")) {
        (Some(v), _) => (v, true, true),
        (None, Some(v)) => (v, true, false),
        (None, None) => (rest, false, false),
    };
    let value = match value.strip_prefix("hex:") {
        Some(digits) => hex_pairs(digits).map_err(|e| anyhow!("--did {text}: {e}"))?,
        None => value.as_bytes().to_vec(),
    };
    let writable_in = if writable {
        vec![Session::Extended]
    } else {
        Vec::new()
    };
    Ok((
        id,
        Did {
            value,
            writable_in,
            secured,
        },
    ))
}

fn parse_routine(text: &str) -> Result<(u16, Routine)> {
    let (id, rest) = text
        .split_once('=')
        .ok_or_else(|| anyhow!("--routine {text}: expected ID=MS"))?;
    let id =
        hex::<u16>(id).ok_or_else(|| anyhow!("--routine {text}: '{id}' is not a hex routine"))?;
    let (ms, result) = match rest.split_once(":hex:") {
        Some((ms, digits)) => (
            ms,
            hex_pairs(digits).map_err(|e| anyhow!("--routine {text}: {e}"))?,
        ),
        None => (rest, Vec::new()),
    };
    let ms: u64 = ms
        .parse()
        .map_err(|_| anyhow!("--routine {text}: '{ms}' is not milliseconds"))?;
    Ok((
        id,
        Routine {
            runs_for: std::time::Duration::from_millis(ms),
            result,
            secured: false,
        },
    ))
}

fn parse_dtc(text: &str) -> Result<(u32, bool)> {
    let (code, passed) = match text.strip_suffix(":passed") {
        Some(c) => (c, true),
        None => (text, false),
    };
    let dtc = hex::<u32>(code)
        .filter(|d| *d <= 0xFF_FFFF)
        .ok_or_else(|| anyhow!("--dtc {text}: not a 24-bit hex DTC"))?;
    Ok((dtc, passed))
}

pub fn run(command: &UdsCommand, out: &mut dyn Write) -> Result<()> {
    let UdsCommand::Serve {
        bus,
        tx,
        rx,
        functional,
        dids,
        dtcs,
        routines,
    } = command
    else {
        return run_tester(command, out);
    };
    let mut server = UdsServer::new(
        // The runner confirms every frame sent.
        IsoTpConfig::new(can_id(tx, "--tx")?, can_id(rx, "--rx")?).confirmed(DEFAULT_TIMEOUT),
        UdsTiming::default(),
    );
    if let Some(f) = functional {
        server = server.with_functional(can_id(f, "--functional")?);
    }
    for text in dids {
        let (id, did) = parse_did(text)?;
        server.set_did(id, did);
    }
    for text in routines {
        let (id, routine) = parse_routine(text)?;
        server.set_routine(id, routine);
    }
    for text in dtcs {
        let (dtc, passed) = parse_dtc(text)?;
        server.report(dtc, true);
        if passed {
            server.report(dtc, false);
        }
    }
    let endpoint = busarg::open(bus).with_context(|| format!("bus {bus}"))?;
    let mut runner = Runner::new(vec![(Port::MAIN, endpoint)]);
    let mut write_error = None;
    let mut hooks = |server: &mut UdsServer, now: Timestamp| {
        for event in server.take_events() {
            let line = match event {
                UdsEvent::Session(s) => format!("session {s:?}"),
                UdsEvent::Reset(kind) => format!("reset {kind}"),
                UdsEvent::Written(id) => format!("written {id:04X}"),
                UdsEvent::Cleared(group) => format!("cleared {group:06X}"),
                UdsEvent::Transport(e) => format!("transport: {e}"),
                UdsEvent::Unlocked(level) => format!("unlocked {level}"),
                UdsEvent::RoutineStarted(id) => format!("routine {id:04X} started"),
                UdsEvent::RoutineStopped(id) => format!("routine {id:04X} stopped"),
            };
            let t = now.as_nanos() as f64 / 1e9;
            if let Err(e) = writeln!(out, "{t:.3} {line}").and_then(|()| out.flush()) {
                write_error = Some(e);
                return Flow::Stop;
            }
        }
        Flow::Continue
    };
    runner
        .run(&mut server, &interrupt_flag(), None, &mut hooks)
        .map_err(|e| anyhow!("bus {bus}: {e}"))?;
    match write_error {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

impl UdsCommand {
    /// The tester's options of a tester command.
    fn tester(&self) -> Option<&Tester> {
        match self {
            UdsCommand::Serve { .. } => None,
            UdsCommand::Session { tester, .. }
            | UdsCommand::ReadDid { tester, .. }
            | UdsCommand::WriteDid { tester, .. }
            | UdsCommand::ReadDtc { tester, .. }
            | UdsCommand::ClearDtc { tester, .. }
            | UdsCommand::Routine { tester, .. }
            | UdsCommand::Reset { tester, .. }
            | UdsCommand::Security { tester, .. }
            | UdsCommand::TesterPresent { tester }
            | UdsCommand::DtcSetting { tester, .. }
            | UdsCommand::CommControl { tester, .. }
            | UdsCommand::Raw { tester, .. } => Some(tester),
        }
    }
}

impl Tester {
    fn channel(&self) -> Result<IsoTpConfig> {
        let mut config = IsoTpConfig::new(can_id(&self.tx, "--tx")?, can_id(&self.rx, "--rx")?)
            .confirmed(DEFAULT_TIMEOUT);
        if let Some(x) = &self.extended {
            config.addressing = extended_addressing(x)?;
        }
        if let Some(p) = &self.padding {
            config.padding = Some(hex_byte(p, "--padding")?);
        }
        Ok(config)
    }

    fn timing(&self) -> ClientTiming {
        ClientTiming {
            p2: std::time::Duration::from_millis(self.p2_ms),
            p2_extended: std::time::Duration::from_millis(self.p2_star_ms),
            ..ClientTiming::default()
        }
    }

    /// The key for `seed` at `level`.
    fn key(&self, level: u8, seed: &[u8]) -> Result<Vec<u8>> {
        let spec = &self.key_fn;
        if spec == "demo" {
            return Ok(bywire_diag::uds::demo_key(level, seed));
        }
        if let Some(hex) = spec.strip_prefix("xor:") {
            let mask = hex_pairs(hex).map_err(|e| anyhow!("--key-fn {spec}: {e}"))?;
            if mask.is_empty() {
                bail!("--key-fn {spec}: no bytes to XOR with");
            }
            return Ok(seed
                .iter()
                .zip(mask.iter().cycle())
                .map(|(s, m)| s ^ m)
                .collect());
        }
        if let Some(program) = spec.strip_prefix("exec:") {
            let output = std::process::Command::new(program)
                .arg(level.to_string())
                .arg(describe::hex(seed))
                .output()
                .with_context(|| format!("--key-fn {spec}"))?;
            if !output.status.success() {
                bail!("--key-fn {spec}: the program failed ({})", output.status);
            }
            let text = String::from_utf8_lossy(&output.stdout);
            let digits: String = text.split_whitespace().collect();
            return hex_pairs(&digits).map_err(|e| anyhow!("--key-fn {spec}: its key: {e}"));
        }
        bail!("--key-fn {spec}: demo, xor:HEX or exec:PROGRAM")
    }
}

/// A 16-bit hex number named by `what`.
fn hex_u16(text: &str, what: &str) -> Result<u16> {
    hex(text).ok_or_else(|| anyhow!("{what} {text}: not a 16-bit hex number"))
}

/// A hex byte (0x allowed) named by `what`.
fn hex_byte(text: &str, what: &str) -> Result<u8> {
    hex(text).ok_or_else(|| anyhow!("{what} {text}: not a hex byte"))
}

impl UdsCommand {
    /// What the tester does: the tester's session and unlock, then the command's service.
    fn plan(&self, tester: &Tester) -> Result<Plan> {
        let service = match self {
            UdsCommand::Serve { .. } => bail!("not a tester command"),
            UdsCommand::Session { code, .. } => Service::Session(match code.as_str() {
                "default" => 1,
                "programming" => 2,
                "extended" => 3,
                other => other
                    .strip_prefix("0x")
                    .map_or_else(|| other.parse().ok(), |_| hex::<u8>(other))
                    .ok_or_else(|| anyhow!("session {other}: 1, 2, 3, a name or 0xNN"))?,
            }),
            UdsCommand::ReadDid { dids, .. } => Service::ReadDids(
                dids.iter()
                    .map(|did| hex_u16(did, "DID"))
                    .collect::<Result<_>>()?,
            ),
            UdsCommand::WriteDid { did, value, .. } => Service::WriteDid {
                did: hex_u16(did, "DID")?,
                value: match value.strip_prefix("hex:") {
                    Some(digits) => hex_pairs(digits).map_err(|e| anyhow!("{value}: {e}"))?,
                    None => value.as_bytes().to_vec(),
                },
            },
            UdsCommand::ReadDtc {
                status,
                count,
                snapshots,
                ..
            } => Service::ReadDtcs {
                status: hex_byte(status, "--status")?,
                count_only: *count,
                details: *snapshots,
            },
            UdsCommand::ClearDtc { group, .. } => Service::ClearDtcs(
                hex::<u32>(group)
                    .filter(|g| *g <= 0xFF_FFFF)
                    .ok_or_else(|| anyhow!("group {group}: not a 24-bit hex DTC group"))?,
            ),
            UdsCommand::Routine {
                action,
                routine,
                data,
                ..
            } => Service::Routine {
                control: match action.as_str() {
                    "start" => RoutineControl::Start,
                    "stop" => RoutineControl::Stop,
                    _ => RoutineControl::Results,
                },
                id: hex_u16(routine, "routine")?,
                record: match data {
                    Some(data) => hex_pairs(data).map_err(|e| anyhow!("{data}: {e}"))?,
                    None => Vec::new(),
                },
            },
            UdsCommand::Reset { kind, .. } => Service::Reset(match kind.as_str() {
                "hard" => 1,
                "keyoffon" => 2,
                "soft" => 3,
                other => hex_byte(other, "reset")?,
            }),
            UdsCommand::Security { level, .. } => Service::Unlock(*level),
            UdsCommand::TesterPresent { .. } => Service::TesterPresent,
            UdsCommand::DtcSetting { setting, .. } => Service::DtcSetting(setting == "on"),
            UdsCommand::CommControl {
                control,
                communication,
                ..
            } => Service::CommControl(*control, *communication),
            UdsCommand::Raw { request, .. } => {
                let digits: String = request.concat().split_whitespace().collect();
                Service::Raw(hex_pairs(&digits).map_err(|e| anyhow!("raw: {e}"))?)
            }
        };
        Ok(Plan {
            session: tester.session,
            unlock: tester.security,
            service,
        })
    }
}

/// The ECU description `spec` names: `tug` (the reference tug's), a TOML file, or a database
/// of DIDs (a CDD): its records, to decode field by field, beside the description their names
/// and lengths make.
fn description(spec: &str) -> Result<(Description, Option<bywire_dbc::Database>)> {
    if spec == "tug" {
        return Ok((bywire_tug::diagnostics::description(), None));
    }
    let bytes = std::fs::read(spec).with_context(|| format!("--describe {spec}"))?;
    let path = std::path::Path::new(spec);
    if crate::support::dbc::format_of(path, &bytes) == bywire_dbc::Format::Cdd {
        let records = crate::support::dbc::load(path, false)?;
        let mut d = Description::iso14229();
        for m in &records.messages {
            let Ok(id) = u16::try_from(m.id) else {
                continue;
            };
            d.dids.insert(
                id,
                describe::DidInfo {
                    name: m.name.clone(),
                    length: usize::try_from(m.size).ok(),
                    kind: describe::ValueKind::Bytes,
                },
            );
        }
        return Ok((d, Some(records)));
    }
    let text = String::from_utf8_lossy(&bytes);
    let d = Description::from_toml(&text, spec).map_err(|e| anyhow!("--describe {e}"))?;
    Ok((d, None))
}

/// A DID's record decoded by its fields (a CDD's): `Name(field: value unit, ...)` and the
/// fields as JSON.
fn record_fields(
    records: Option<&bywire_dbc::Database>,
    id: u16,
    value: &[u8],
) -> Option<(String, Value)> {
    use crate::support::signals::FrameText;
    let m = records?.messages.iter().find(|m| m.id == u32::from(id))?;
    let codec = bywire_dbc::codec::MessageCodec::new(m);
    let mut values = vec![None; codec.signal_count()];
    let error = codec.decode(value, &mut values).err();
    let decoded = bywire_dbc::decoder::DecodedFrame {
        message: m,
        signals: bywire_dbc::decoder::signal_values(m, &values).collect(),
        error: error.map(|e| e.to_string()),
    };
    Some((
        decoded.single_line(true),
        Value::Object(decoded.json_signals()),
    ))
}

fn run_tester(command: &UdsCommand, out: &mut dyn Write) -> Result<()> {
    let tester = command
        .tester()
        .ok_or_else(|| anyhow!("not a tester command"))?;
    let (description, records) = match &tester.describe {
        Some(spec) => description(spec)?,
        None => (Description::iso14229(), None),
    };
    let mut script = Script::new(command.plan(tester)?, |level: u8, seed: &[u8]| {
        tester.key(level, seed)
    });
    let mut client = UdsClient::new(tester.channel()?, tester.timing());
    let endpoint = busarg::open(&tester.bus).with_context(|| format!("bus {}", tester.bus))?;
    let mut runner = Runner::new(vec![(Port::MAIN, endpoint)]);
    let mut failure: Option<anyhow::Error> = None;
    let mut queued: Option<Vec<u8>> = None;
    let mut started = false;
    let mut last_request = Vec::new();
    let mut hooks = |client: &mut UdsClient, now: Timestamp| {
        if !started {
            started = true;
            match script.next(None) {
                Ok(next) => queued = next,
                Err(e) => {
                    failure = Some(script_error(e));
                    return Flow::Stop;
                }
            }
        } else if let Some(outcome) = client.take_outcome() {
            let answer = match outcome {
                Ok(answer) => answer,
                Err(e) => {
                    failure = Some(request_error(&last_request, &e));
                    return Flow::Stop;
                }
            };
            match script.next(Some(answer)) {
                Ok(next) => queued = next,
                Err(e) => {
                    failure = Some(script_error(e));
                    return Flow::Stop;
                }
            }
        } else if queued.is_none() {
            // Waiting for an answer.
            return Flow::Continue;
        }
        let Some(request) = queued.take() else {
            return Flow::Stop;
        };
        // A TesterPresent of the client's own may be on its way: try again next time.
        match client.request(now, &request) {
            Ok(()) => last_request = request,
            Err(ClientError::Busy) => queued = Some(request),
            Err(e) => {
                failure = Some(request_error(&request, &e));
                return Flow::Stop;
            }
        }
        Flow::Continue
    };
    let ended = runner
        .run(&mut client, &interrupt_flag(), None, &mut hooks)
        .map_err(|e| anyhow!("bus {}: {e}", tester.bus))?;
    if let Some(e) = failure {
        return Err(e);
    }
    if ended != bywire_bus::runner::Ended::ByHooks {
        bail!("interrupted");
    }
    report(
        command,
        tester,
        (&description, records.as_ref()),
        script.answers(),
        out,
    )
}

/// A script's error as the command line says it: a key function's own error as it is.
fn script_error(error: ScriptError<anyhow::Error>) -> anyhow::Error {
    match error {
        ScriptError::Key(e) => e,
        other => anyhow!("{other}"),
    }
}

fn request_error(request: &[u8], error: &ClientError) -> anyhow::Error {
    anyhow!("request {}: {error}", describe::hex(request))
}

/// The command's answers (the service's, then its details), as text or JSON.
fn report(
    command: &UdsCommand,
    tester: &Tester,
    (d, records): (&Description, Option<&bywire_dbc::Database>),
    answers: &[Vec<u8>],
    out: &mut dyn Write,
) -> Result<()> {
    let answer = answers.first().cloned().unwrap_or_default();
    let (text, value): (String, Value) = match command {
        UdsCommand::Session { .. } => match answer.as_slice() {
            [0x50, session, a, b, c, e] => {
                let p2 = u16::from_be_bytes([*a, *b]);
                let p2x = u32::from(u16::from_be_bytes([*c, *e])) * 10;
                (
                    format!("session {session}: P2 {p2} ms, P2* {p2x} ms"),
                    json!({"session": session, "p2_ms": p2, "p2_star_ms": p2x}),
                )
            }
            other => (
                format!("session: {}", describe::hex(other)),
                json!({"answer": describe::hex(other)}),
            ),
        },
        UdsCommand::ReadDid { dids, .. } => {
            let ids: Vec<u16> = dids
                .iter()
                .map(|did| hex_u16(did, "DID"))
                .collect::<Result<_>>()?;
            let values = client::did_values(&answer, &ids, &|id| d.did_length(id))
                .map_err(|e| anyhow!("{e} (give the DIDs' lengths with --describe)"))?;
            let mut lines = Vec::new();
            let mut object = serde_json::Map::new();
            for (id, value) in values {
                let name = d.dids.get(&id).map(|i| i.name.clone());
                if let Some((shown, fields)) = record_fields(records, id, &value) {
                    lines.push(format!("{id:04X} {shown}"));
                    object.insert(
                        format!("{id:04X}"),
                        json!({"name": name, "value": fields, "hex": describe::hex(&value)}),
                    );
                    continue;
                }
                let shown = d.show(id, &value);
                lines.push(match &name {
                    Some(name) => format!("{id:04X} {name}: {shown}"),
                    None => format!("{id:04X}: {shown}"),
                });
                object.insert(
                    format!("{id:04X}"),
                    json!({"name": name, "value": shown, "hex": describe::hex(&value)}),
                );
            }
            (lines.join("\n"), Value::Object(object))
        }
        UdsCommand::ReadDtc { count: true, .. } => {
            let count = client::dtc_count(&answer).map_err(|e| anyhow!("{e}"))?;
            (format!("{count} DTCs"), json!({"count": count}))
        }
        UdsCommand::ReadDtc { .. } => dtc_report(d, answers, &answer)?,
        UdsCommand::Routine {
            action, routine, ..
        } => {
            let record = answer.get(4..).unwrap_or(&[]);
            (
                format!("routine {routine} {action}: {}", describe::hex(record)),
                json!({"routine": routine, "action": action, "record": describe::hex(record)}),
            )
        }
        UdsCommand::Reset { .. } => {
            let kind = answer.get(1).copied().unwrap_or(0);
            (format!("reset {kind}: done"), json!({"reset": kind}))
        }
        UdsCommand::Security { level, .. } => (
            format!("security level {level}: unlocked"),
            json!({"unlocked": level}),
        ),
        UdsCommand::ClearDtc { group, .. } => {
            (format!("cleared {group}"), json!({"cleared": group}))
        }
        UdsCommand::WriteDid { did, .. } => (format!("{did} written"), json!({"written": did})),
        UdsCommand::TesterPresent { .. } => {
            ("tester present: answered".into(), json!({"present": true}))
        }
        UdsCommand::DtcSetting { setting, .. } => (
            format!("DTC setting {setting}"),
            json!({"dtc_setting": setting}),
        ),
        UdsCommand::CommControl { control, .. } => (
            format!("communication control {control}: done"),
            json!({"comm_control": control}),
        ),
        UdsCommand::Raw { .. } | UdsCommand::Serve { .. } => (
            describe::hex(&answer),
            json!({"answer": describe::hex(&answer)}),
        ),
    };
    if tester.json {
        writeln!(out, "{value}")?;
    } else if !text.is_empty() {
        writeln!(out, "{text}")?;
    }
    Ok(())
}

/// DTCs with their names and status bits; with --snapshots their records.
fn dtc_report(d: &Description, answers: &[Vec<u8>], answer: &[u8]) -> Result<(String, Value)> {
    let (_, dtcs) = client::dtc_list(answer).map_err(|e| anyhow!("{e}"))?;
    let mut lines = Vec::new();
    let mut list = Vec::new();
    for (i, (dtc, status)) in dtcs.iter().enumerate() {
        let name = d.dtcs.get(dtc).cloned();
        let bits = describe::status_bits(*status);
        lines.push(format!(
            "{} {dtc:06X} {}status {status:02X}: {}",
            describe::dtc_code(*dtc),
            name.as_ref().map(|n| format!("{n}, ")).unwrap_or_default(),
            bits.join(" ")
        ));
        let mut entry = json!({
            "dtc": format!("{dtc:06X}"),
            "code": describe::dtc_code(*dtc),
            "name": name,
            "status": status,
            "status_bits": bits,
        });
        // The details follow the list: snapshot then extended data for each DTC.
        if let (Some(snapshot), Some(extended)) = (answers.get(1 + 2 * i), answers.get(2 + 2 * i)) {
            let (_, _, records) =
                client::snapshots(snapshot, &|id| d.did_length(id)).map_err(|e| {
                    anyhow!("{dtc:06X}: {e} (give the snapshot DIDs' lengths with --describe)")
                })?;
            let mut shown = Vec::new();
            for record in &records {
                let values: Vec<String> = record
                    .values
                    .iter()
                    .map(|(id, v)| {
                        let name = d
                            .dids
                            .get(id)
                            .map_or_else(|| format!("{id:04X}"), |i| i.name.clone());
                        format!("{name} {}", d.show(*id, v))
                    })
                    .collect();
                lines.push(format!(
                    "  snapshot {}: {}",
                    record.number,
                    values.join(", ")
                ));
                shown.push(json!({
                    "record": record.number,
                    "values": record.values.iter().map(|(id, v)| json!({
                        "did": format!("{id:04X}"), "value": d.show(*id, v), "hex": describe::hex(v)
                    })).collect::<Vec<_>>(),
                }));
            }
            // Extended data record 0x01: the occurrence count.
            let occurrences = match extended.as_slice() {
                [.., 0x01, count] => Some(*count),
                _ => None,
            };
            if let Some(count) = occurrences {
                lines.push(format!("  occurrences: {count}"));
            }
            entry["snapshots"] = json!(shown);
            entry["occurrences"] = json!(occurrences);
        }
        list.push(entry);
    }
    if lines.is_empty() {
        lines.push("no DTCs".into());
    }
    Ok((lines.join("\n"), Value::Array(list)))
}
