//! `bywire isotp send|recv`: ISO-TP on any bus with can-utils' isotpsend/isotprecv options,
//! the sans-IO channel of `bywire-diag` on the real-time runner.

use std::io::{Read, Write};
use std::time::Duration;

use anyhow::{anyhow, bail, Context, Result};
use bywire_bus::runner::{Flow, Runner};
use bywire_core::node::Port;
use bywire_core::{Id, Timestamp};
use bywire_diag::isotp::{Addressing, IsoTp, IsoTpConfig, IsoTpEvent, StMin};

use crate::support::busarg;

/// The most hex input `send` reads (an ISO-TP message of up to 4 GiB is not typed by hand).
const MAX_INPUT: u64 = 64 << 20;

#[derive(clap::Subcommand)]
pub enum IsotpCommand {
    /// Send one message (hex bytes on stdin), like isotpsend.
    #[command(after_help = "Examples:
  echo 22 F1 90 | bywire isotp send can0 -s 7E0 -d 7E8
  bywire isotp send vcan0 -s 18DA10F1 -d 18DAF110 -D 4095
  echo 01 02 03 | bywire isotp send can0 -s 123 -d 321 -x 10:F1 -p CC: -L 72:64:1

CAN IDs and addresses are hexadecimal (8 digits: extended). -L MTU:TX_DL:FLAGS as can-utils:
MTU 72 is CAN FD, TX_DL its frame length, FLAGS 1 the bit-rate switch.")]
    Send {
        #[command(flatten)]
        channel: ChannelArgs,
        /// Ignore the receiver's STmin and wait this many nanoseconds between frames.
        #[arg(short = 'f', value_name = "NS")]
        force_st_min: Option<u64>,
        /// Send a fixed message of this many bytes (0x00, 0x01, ...) instead of stdin's.
        #[arg(short = 'D', value_name = "LEN")]
        fixed: Option<usize>,
    },
    /// Receive messages and print them as hex bytes, like isotprecv.
    #[command(after_help = "Examples:
  bywire isotp recv can0 -s 7E8 -d 7E0 -l
  bywire isotp recv vcan0 -s 321 -d 123 -b 4 -m F5      (block size 4, STmin 500 µs)")]
    Recv {
        #[command(flatten)]
        channel: ChannelArgs,
        /// Block size offered (0: off).
        #[arg(short = 'b', default_value_t = 0)]
        block_size: u8,
        /// STmin asked for, as the flow-control byte in hex (00-7F ms, F1-F9 100-900 µs).
        #[arg(short = 'm', value_parser = hex_u8, default_value = "0")]
        st_min: u8,
        /// WAIT frames accepted in a row.
        #[arg(short = 'w', default_value_t = 10)]
        max_wait: u8,
        /// Keep receiving after the first message.
        #[arg(short = 'l')]
        keep: bool,
    },
}

/// What both take: the channel's identifiers and frame format.
#[derive(clap::Args)]
pub struct ChannelArgs {
    /// The bus (a plain interface name means SocketCAN).
    bus: String,
    /// The identifier sent with (hex; 8 digits: extended).
    #[arg(short = 's', value_name = "CAN_ID")]
    source: String,
    /// The identifier received on (hex).
    #[arg(short = 'd', value_name = "CAN_ID")]
    destination: String,
    /// Extended addressing: the address byte sent [and the one received].
    #[arg(short = 'x', value_name = "ADDR[:RXADDR]")]
    extended: Option<String>,
    /// Padding: the byte frames sent are padded with [:the byte expected, not checked].
    #[arg(short = 'p', value_name = "[TX]:[RX]")]
    padding: Option<String>,
    /// CAN FD link layer: MTU (72 for FD), TX_DL, flags (1: bit-rate switch).
    #[arg(short = 'L', value_name = "MTU:TX_DL:FLAGS")]
    link: Option<String>,
    /// Give up waiting for the peer after this many milliseconds (N_Bs, N_Cr).
    #[arg(long, default_value_t = 1000)]
    timeout_ms: u64,
    /// The largest message received.
    #[arg(long, default_value_t = 1 << 20)]
    max_message: usize,
}

fn hex_u8(text: &str) -> Result<u8, String> {
    u8::from_str_radix(text, 16).map_err(|_| format!("'{text}' is not a hex byte"))
}

/// A CAN identifier as can-utils reads one: hex, 8 digits or above 0x7FF for extended.
fn can_id(text: &str, what: &str) -> Result<Id> {
    let raw = u32::from_str_radix(text, 16).map_err(|_| anyhow!("{what} {text}: not hex"))?;
    let id = if text.len() == 8 || raw > 0x7FF {
        Id::extended(raw)
    } else {
        Id::standard(raw)
    };
    id.map_err(|e| anyhow!("{what} {text}: {e}"))
}

impl ChannelArgs {
    fn config(&self) -> Result<IsoTpConfig> {
        let mut c = IsoTpConfig::new(
            can_id(&self.source, "-s")?,
            can_id(&self.destination, "-d")?,
        );
        if let Some(x) = &self.extended {
            let (tx, rx) = x.split_once(':').unwrap_or((x, x));
            let byte = |t: &str| hex_u8(t).map_err(|e| anyhow!("-x {x}: {e}"));
            c.addressing = Addressing::Extended {
                target: byte(tx)?,
                source: byte(if rx.is_empty() { tx } else { rx })?,
            };
        }
        if let Some(p) = &self.padding {
            let tx = p.split(':').next().unwrap_or_default();
            if !tx.is_empty() {
                c.padding = Some(hex_u8(tx).map_err(|e| anyhow!("-p {p}: {e}"))?);
            }
        }
        if let Some(link) = &self.link {
            let parts: Vec<&str> = link.split(':').collect();
            let number = |i: usize| -> Result<u64> {
                parts
                    .get(i)
                    .ok_or_else(|| anyhow!("-L {link}: expected MTU:TX_DL:FLAGS"))?
                    .parse()
                    .map_err(|_| anyhow!("-L {link}: not a number"))
            };
            let (mtu, tx_dl, flags) = (number(0)?, number(1)?, number(2)?);
            if mtu == 72 {
                if bywire_core::frame::Dlc::from_fd_len(usize::try_from(tx_dl).unwrap_or(0))
                    .is_none_or(|_| tx_dl < 8)
                {
                    bail!("-L {link}: TX_DL {tx_dl} is not 8, 12, 16, 20, 24, 32, 48 or 64");
                }
                c.fd = true;
                c.tx_dl = usize::try_from(tx_dl).unwrap_or(64);
                c.brs = flags & 1 == 1;
            } else if mtu != 16 {
                bail!("-L {link}: MTU {mtu} is 16 (classic CAN) or 72 (CAN FD)");
            }
        }
        c.n_bs = Duration::from_millis(self.timeout_ms);
        c.n_cr = Duration::from_millis(self.timeout_ms);
        c.max_message = self.max_message;
        Ok(c)
    }
}

/// Hex bytes separated by white space.
fn parse_hex(text: &str) -> Result<Vec<u8>> {
    text.split_whitespace()
        .enumerate()
        .map(|(i, t)| {
            u8::from_str_radix(t, 16)
                .map_err(|_| anyhow!("stdin: item {} '{t}' is not a hex byte", i + 1))
        })
        .collect()
}

pub fn run(command: &IsotpCommand, input: &mut dyn Read, out: &mut dyn Write) -> Result<()> {
    match command {
        IsotpCommand::Send {
            channel,
            force_st_min,
            fixed,
        } => {
            let mut config = channel.config()?;
            config.st_min_override = force_st_min.map(Duration::from_nanos);
            let data = match fixed {
                Some(len) => (0..*len).map(|i| (i % 256) as u8).collect(),
                None => {
                    let mut text = String::new();
                    input
                        .take(MAX_INPUT)
                        .read_to_string(&mut text)
                        .context("stdin")?;
                    parse_hex(&text)?
                }
            };
            let mut node = IsoTp::new(config);
            node.send(&data).map_err(|e| anyhow!("{e}"))?;
            let outcome = drive(&channel.bus, &mut node, |node, _| match node.next_event() {
                Some(IsoTpEvent::Sent) => Some(Ok(())),
                Some(IsoTpEvent::Failed {
                    sending: true,
                    error,
                }) => Some(Err(anyhow!("{error}"))),
                _ => None,
            })?;
            outcome.unwrap_or(Ok(()))
        }
        IsotpCommand::Recv {
            channel,
            block_size,
            st_min,
            max_wait,
            keep,
        } => {
            let mut config = channel.config()?;
            config.block_size = *block_size;
            config.st_min = StMin::from_byte(*st_min);
            config.max_wait_frames = *max_wait;
            let mut node = IsoTp::new(config);
            let mut write_error = None;
            let outcome = drive(&channel.bus, &mut node, |node, _| {
                while let Some(event) = node.next_event() {
                    match event {
                        IsoTpEvent::Received(message) => {
                            let line: String =
                                message.iter().map(|b| format!("{b:02X} ")).collect();
                            if let Err(e) = writeln!(out, "{line}").and_then(|()| out.flush()) {
                                write_error = Some(e);
                                return Some(Ok(()));
                            }
                            if !keep {
                                return Some(Ok(()));
                            }
                        }
                        IsoTpEvent::Failed { error, .. } => {
                            let _ = writeln!(std::io::stderr(), "bywire isotp recv: {error}");
                        }
                        IsoTpEvent::Sent => {}
                    }
                }
                None
            })?;
            if let Some(e) = write_error {
                return Err(e.into());
            }
            outcome.unwrap_or(Ok(()))
        }
    }
}

/// Run `node` on `bus` until `done` has an outcome (or Ctrl-C: `None`).
fn drive(
    bus: &str,
    node: &mut IsoTp,
    mut done: impl FnMut(&mut IsoTp, Timestamp) -> Option<Result<()>>,
) -> Result<Option<Result<()>>> {
    let bus_handle = busarg::open(bus).with_context(|| format!("bus {bus}"))?;
    let mut runner = Runner::new(vec![(Port::MAIN, bus_handle)]);
    let mut outcome = None;
    let mut hooks = |node: &mut IsoTp, now: Timestamp| match done(node, now) {
        Some(result) => {
            outcome = Some(result);
            Flow::Stop
        }
        None => Flow::Continue,
    };
    runner
        .run(node, &crate::interrupt_flag(), None, &mut hooks)
        .map_err(|e| anyhow!("bus {bus}: {e}"))?;
    Ok(outcome)
}
