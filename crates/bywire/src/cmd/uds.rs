//! `bywire uds serve`: a UDS server (`bywire-diag`) on any bus, with the DIDs and DTCs given on
//! the command line — an ECU for testers (udsoncan, vendor tools) to talk to.

use std::io::Write;

use anyhow::{anyhow, Context, Result};
use bywire_bus::runner::{Flow, Runner};
use bywire_core::node::Port;
use bywire_core::Timestamp;
use bywire_diag::isotp::IsoTpConfig;
use bywire_diag::uds::{Did, Routine, Session, UdsEvent, UdsServer, UdsTiming};

use crate::support::busarg;
use crate::support::numbers::can_id;

#[derive(clap::Subcommand)]
pub enum UdsCommand {
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
    let id = u16::from_str_radix(id, 16)
        .map_err(|_| anyhow!("--did {text}: '{id}' is not a hex DID"))?;
    let (value, writable, secured) = match (rest.strip_suffix(":rws"), rest.strip_suffix(":rw")) {
        (Some(v), _) => (v, true, true),
        (None, Some(v)) => (v, true, false),
        (None, None) => (rest, false, false),
    };
    let value = match value.strip_prefix("hex:") {
        Some(hex) => hex_bytes(hex).map_err(|e| anyhow!("--did {text}: {e}"))?,
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

fn hex_bytes(hex: &str) -> Result<Vec<u8>> {
    if !hex.len().is_multiple_of(2) {
        return Err(anyhow!("an odd number of hex digits"));
    }
    (0..hex.len())
        .step_by(2)
        .map(|i| {
            hex.get(i..i + 2)
                .and_then(|b| u8::from_str_radix(b, 16).ok())
                .ok_or_else(|| anyhow!("'{hex}' is not hex"))
        })
        .collect()
}

fn parse_routine(text: &str) -> Result<(u16, Routine)> {
    let (id, rest) = text
        .split_once('=')
        .ok_or_else(|| anyhow!("--routine {text}: expected ID=MS"))?;
    let id = u16::from_str_radix(id, 16)
        .map_err(|_| anyhow!("--routine {text}: '{id}' is not a hex routine"))?;
    let (ms, result) = match rest.split_once(":hex:") {
        Some((ms, hex)) => (
            ms,
            hex_bytes(hex).map_err(|e| anyhow!("--routine {text}: {e}"))?,
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
    let dtc = u32::from_str_radix(code, 16)
        .ok()
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
    } = command;
    let mut server = UdsServer::new(
        IsoTpConfig::new(can_id(tx, "--tx")?, can_id(rx, "--rx")?),
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
        .run(&mut server, &crate::interrupt_flag(), None, &mut hooks)
        .map_err(|e| anyhow!("bus {bus}: {e}"))?;
    match write_error {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}
