//! `bywire isotp send|recv`: ISO-TP on any bus with can-utils' isotpsend/isotprecv options,
//! the sans-IO channel of `bywire-diag` on the real-time runner.

use std::io::{Read, Write};
use std::time::Duration;

use anyhow::{anyhow, bail, Context, Result};
use bywire_core::{Id, Timestamp};
use bywire_diag::isotp::{IsoTp, IsoTpConfig, IsoTpEvent, StMin};

use crate::support::busarg;
use crate::support::interrupt::interrupt_flag;
use crate::support::numbers::{can_id, extended_addressing, hex, hex_u8};

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
        /// Frame transmit time in nanoseconds, added to the separation between consecutive
        /// frames (ZERO or 0: none, the default).
        #[arg(short = 't', value_name = "NS", value_parser = frame_time)]
        frame_time: Option<u64>,
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
    /// Show the ISO-TP frames of a conversation, like isotpdump, live or from a log.
    #[command(after_help = "Examples:
  bywire isotp dump can0 -s 7E0 -d 7E8
  bywire isotp dump vcan0 -s 7E0 -d 7E8 -a -t z
  bywire isotp dump --log drive.blf -s 7E0 -d 7E8      (any log format)

Each frame of either identifier as isotpdump prints it: [SF]/[FF] with the length,
[CF] with its sequence number, [FC] with flow status, block size and STmin.")]
    Dump {
        /// The bus (a plain interface name means SocketCAN); none with --log.
        #[arg(required_unless_present = "log")]
        bus: Option<String>,
        /// Read the frames from this log (any format) instead of a bus.
        #[arg(long, value_name = "FILE", conflicts_with = "bus")]
        log: Option<std::path::PathBuf>,
        /// One identifier of the conversation (hex).
        #[arg(short = 's', value_name = "CAN_ID")]
        source: String,
        /// The other (hex).
        #[arg(short = 'd', value_name = "CAN_ID")]
        destination: String,
        /// Extended addressing: the source's address byte, or `any`.
        #[arg(short = 'x', value_name = "ADDR")]
        extended: Option<String>,
        /// Extended addressing: the destination's address byte, or `any`.
        #[arg(short = 'X', value_name = "ADDR")]
        rx_extended: Option<String>,
        /// Print the data as ASCII too.
        #[arg(short = 'a')]
        ascii: bool,
        /// Timestamps: a (absolute), d (delta), z (from the first frame).
        #[arg(short = 't', value_parser = ["a", "d", "z"])]
        timestamp: Option<String>,
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
    /// Padding: the byte frames sent are padded with [:the byte received frames carry, checked
    /// with -P].
    #[arg(short = 'p', value_name = "[TX]:[RX]")]
    padding: Option<String>,
    /// Check received frames' padding: l (length), c (content: needs -p :RX), a (both); a
    /// frame that fails is dropped and its transfer fails.
    #[arg(short = 'P', value_name = "MODE", value_parser = ["l", "c", "a"])]
    padding_check: Option<String>,
    /// CAN FD link layer: MTU (72 for FD), TX_DL, flags (1: bit-rate switch).
    #[arg(short = 'L', value_name = "MTU:TX_DL:FLAGS")]
    link: Option<String>,
    /// Give up waiting for the peer, or for a frame to be confirmed sent, after this many
    /// milliseconds (N_As, N_Ar, N_Bs, N_Cr).
    #[arg(long, default_value_t = 1000)]
    timeout_ms: u64,
    /// The largest message received.
    #[arg(long, default_value_t = 1 << 20)]
    max_message: usize,
}

impl ChannelArgs {
    fn config(&self) -> Result<IsoTpConfig> {
        let mut c = IsoTpConfig::new(
            can_id(&self.source, "-s")?,
            can_id(&self.destination, "-d")?,
        );
        if let Some(x) = &self.extended {
            c.addressing = extended_addressing(x)?;
        }
        if let Some(p) = &self.padding {
            let mut parts = p.split(':');
            let byte = |text: &str| -> Result<Option<u8>> {
                if text.is_empty() {
                    return Ok(None);
                }
                Ok(Some(hex_u8(text).map_err(|e| anyhow!("-p {p}: {e}"))?))
            };
            c.padding = byte(parts.next().unwrap_or_default())?;
            c.rx_padding = byte(parts.next().unwrap_or_default())?;
        }
        if let Some(mode) = &self.padding_check {
            c.rx_padding_check.length = mode != "c";
            c.rx_padding_check.content = mode != "l";
            if c.rx_padding_check.content && c.rx_padding.is_none() {
                bail!("-P {mode}: checking the padding's content needs the byte: -p [TX]:RX");
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
        let timeout = Duration::from_millis(self.timeout_ms);
        // The runner confirms every frame sent.
        c = c.confirmed(timeout);
        c.n_bs = timeout;
        c.n_cr = timeout;
        c.max_message = self.max_message;
        Ok(c)
    }
}

/// isotpsend's `-t`: nanoseconds, or ZERO.
fn frame_time(text: &str) -> std::result::Result<u64, String> {
    if text == "ZERO" {
        return Ok(0);
    }
    text.parse()
        .map_err(|_| format!("{text}: nanoseconds (a whole number) or ZERO"))
}

/// Hex bytes separated by white space.
fn parse_hex(text: &str) -> Result<Vec<u8>> {
    text.split_whitespace()
        .enumerate()
        .map(|(i, t)| {
            hex::<u8>(t).ok_or_else(|| anyhow!("stdin: item {} '{t}' is not a hex byte", i + 1))
        })
        .collect()
}

pub fn run(command: &IsotpCommand, input: &mut dyn Read, out: &mut dyn Write) -> Result<()> {
    match command {
        IsotpCommand::Send {
            channel,
            force_st_min,
            frame_time,
            fixed,
        } => {
            let mut config = channel.config()?;
            config.st_min_override = force_st_min.map(Duration::from_nanos);
            config.frame_gap = Duration::from_nanos(frame_time.unwrap_or(0));
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
            let outcome = drive(&channel.bus, &mut node, |node| match node.next_event() {
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
            let outcome = drive(&channel.bus, &mut node, |node| {
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
        IsotpCommand::Dump {
            bus,
            log,
            source,
            destination,
            extended,
            rx_extended,
            ascii,
            timestamp,
        } => dump(
            bus.as_ref(),
            log.as_deref(),
            (can_id(source, "-s")?, can_id(destination, "-d")?),
            (
                address_filter(extended.as_ref(), "-x")?,
                address_filter(rx_extended.as_ref(), "-X")?,
            ),
            *ascii,
            timestamp.as_deref(),
            out,
        ),
    }
}

/// Which address byte a side's frames must carry: none (normal addressing), any, or one.
#[derive(Clone, Copy, PartialEq, Eq)]
enum AddressFilter {
    None,
    Any,
    Byte(u8),
}

fn address_filter(text: Option<&String>, option: &str) -> Result<AddressFilter> {
    match text.map(String::as_str) {
        None => Ok(AddressFilter::None),
        Some("any") => Ok(AddressFilter::Any),
        Some(t) => Ok(AddressFilter::Byte(
            hex_u8(t).map_err(|e| anyhow!("{option} {t}: {e}"))?,
        )),
    }
}

/// One frame as isotpdump prints it (after its timestamp), or `None` when it is not part of
/// the conversation.
fn dump_line(
    interface: &str,
    frame: &bywire_core::Frame,
    ids: (Id, Id),
    filters: (AddressFilter, AddressFilter),
    ascii: bool,
) -> Option<String> {
    use bywire_diag::isotp::Pdu;
    let id = frame.id()?;
    let filter = if id == ids.0 {
        filters.0
    } else if id == ids.1 {
        filters.1
    } else {
        return None;
    };
    let data = frame.data();
    let ext = match filter {
        AddressFilter::None => 0,
        AddressFilter::Any => 1,
        AddressFilter::Byte(b) => {
            if data.first() != Some(&b) {
                return None;
            }
            1
        }
    };
    let mut line = if id.is_extended() {
        format!(" {interface}  {:8X}", id.as_raw())
    } else {
        format!(" {interface}  {:3X}", id.as_raw())
    };
    if ext == 1 {
        line += &format!("{{{:02X}}}", data.first().copied().unwrap_or(0));
    }
    line += &if frame.is_fd() {
        format!(" [{:02}]  ", data.len())
    } else {
        format!("  [{}]  ", data.len())
    };
    let after = data.get(ext..).unwrap_or(&[]);
    let payload: &[u8] = match Pdu::parse(after) {
        Pdu::Single { length, data } => {
            line += &format!("[SF] ln: {length:<4} data:");
            data
        }
        Pdu::First { length, data } => {
            line += &format!("[FF] ln: {length:<4} data:");
            data
        }
        Pdu::Consecutive { sequence, data } => {
            line += &format!("[CF] sn: {sequence:X}    data:");
            data
        }
        Pdu::Flow {
            status,
            block_size,
            st_min,
        } => {
            let name = ["CTS", "WT", "OVFLW"]
                .get(usize::from(status))
                .copied()
                .unwrap_or("reserved");
            let off = if block_size == 0 { "= off " } else { "" };
            let time = match st_min {
                0x00..=0x7F => format!("{st_min} ms"),
                0xF1..=0xF9 => format!("{} us", u16::from(st_min & 0x0F) * 100),
                _ => "reserved".to_string(),
            };
            line += &format!(
                "[FC] FC: {status} = {name} # BS: {block_size} {off}# STmin: 0x{st_min:02X} = {time}"
            );
            &[]
        }
        Pdu::Unknown => {
            line += "[??]";
            &[]
        }
    };
    if !payload.is_empty() {
        line.push(' ');
        for b in payload {
            line += &format!("{b:02X} ");
        }
        if ascii {
            // Aligned as isotpdump aligns it: to the column after a full classic frame's data;
            // a longer (FD) payload pushes the marker left-aligned into a field as wide as
            // the overshoot.
            let pad = (7 - ext as i64 - payload.len() as i64) * 3 + 5;
            let width = pad.unsigned_abs() as usize;
            line += &if pad >= 0 {
                format!("{:>width$}", "-  '")
            } else {
                format!("{:<width$}", "-  '")
            };
            line.extend(payload.iter().map(|&b| {
                if (0x20..0x7F).contains(&b) {
                    b as char
                } else {
                    '.'
                }
            }));
            line.push('\'');
        }
    }
    Some(line)
}

/// `isotp dump`: frames of the conversation from a bus or a log, with timestamps as asked.
#[allow(clippy::too_many_arguments)]
fn dump(
    bus: Option<&String>,
    log: Option<&std::path::Path>,
    ids: (Id, Id),
    filters: (AddressFilter, AddressFilter),
    ascii: bool,
    timestamp: Option<&str>,
    out: &mut dyn Write,
) -> Result<()> {
    let mut first: Option<Timestamp> = None;
    let mut last: Option<Timestamp> = None;
    let mut print = |out: &mut dyn Write,
                     at: Timestamp,
                     interface: &str,
                     frame: &bywire_core::Frame|
     -> Result<()> {
        let Some(line) = dump_line(interface, frame, ids, filters, ascii) else {
            return Ok(());
        };
        let stamp = match timestamp {
            Some("a") => Some(at),
            Some("z") => Some(Timestamp::from_nanos(
                at.as_nanos()
                    .saturating_sub(first.get_or_insert(at).as_nanos()),
            )),
            Some("d") => {
                let since = last.map_or(0, |l| at.as_nanos().saturating_sub(l.as_nanos()));
                last = Some(at);
                Some(Timestamp::from_nanos(since))
            }
            _ => None,
        };
        if let Some(t) = stamp {
            let ns = t.as_nanos();
            write!(
                out,
                "({}.{:06}) ",
                ns / 1_000_000_000,
                ns % 1_000_000_000 / 1000
            )?;
        }
        writeln!(out, "{line}")?;
        Ok(())
    };
    if let Some(path) = log {
        let (name, input) = crate::support::logs::input(Some(path))?;
        for record in
            crate::support::logs::records(&name, input, crate::support::logs::Skip::Unreadable)
        {
            let record = record?;
            print(out, record.timestamp, &record.interface, &record.frame)?;
        }
        return Ok(());
    }
    let arg = busarg::parse(bus.map(String::as_str).unwrap_or_default())?;
    let opened = busarg::open_all(std::slice::from_ref(&arg))?;
    let readers = busarg::Readers::start(opened);
    let stop = interrupt_flag();
    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
        match readers.events.recv_timeout(Duration::from_millis(100)) {
            Ok((_, Ok(received))) => {
                print(out, received.timestamp, &arg.name, &received.frame)?;
                out.flush()?;
            }
            Ok((_, Err(e))) => bail!("bus {}: {e}", arg.spec),
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
        }
    }
    Ok(())
}

/// Run `node` on `bus` until `done` has an outcome (or Ctrl-C: `None`).
fn drive(
    bus: &str,
    node: &mut IsoTp,
    mut done: impl FnMut(&mut IsoTp) -> Option<Result<()>>,
) -> Result<Option<Result<()>>> {
    let bus_handle = busarg::open(bus).with_context(|| format!("bus {bus}"))?;
    let mut outcome = None;
    bywire_bus::runner::run_until(bus_handle, node, &interrupt_flag(), None, |node| {
        outcome = done(node);
        outcome.is_some()
    })
    .map_err(|e| anyhow!("bus {bus}: {e}"))?;
    Ok(outcome)
}
