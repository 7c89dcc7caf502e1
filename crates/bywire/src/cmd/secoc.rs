//! `bywire secoc`: sign a frame, verify one, or verify every secured frame of a capture with a
//! DBC's SecOC declarations.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use bywire_core::Frame;
use bywire_dbc::secoc::Secured;
use bywire_secoc::keys::KeyFile;
use bywire_secoc::{Authenticator, Counts, Layout, Receiver};

use crate::support::logs;
use crate::support::numbers::whole;

#[derive(clap::Subcommand)]
pub enum SecocCommand {
    /// Sign a frame: its data is the authentic payload; the truncated freshness value and MAC
    /// are appended and the secured frame printed (can-utils text).
    #[command(after_help = "Examples:
  bywire secoc sign --key ads.key --data-id 0x100 --freshness 7 --profile 24Bit-CMAC-8Bit-FV 100#11223344
  bywire secoc sign --key ads.key --data-id 256 --freshness 1000 --fv-length 32 --fv-tx-length 8 \\
      --mac-tx-length 32 100##0112233445566778899

KEYFILE holds the 16-byte key as 32 hex digits (or KEY_ID HEX lines, chosen with --key-id) and
must be readable by its owner alone (chmod 600).")]
    Sign {
        #[command(flatten)]
        one: OneFrame,
        /// The authentic payload's length in bytes (bytes after the authenticator are kept);
        /// the frame's whole data when not given.
        #[arg(long, value_name = "BYTES")]
        payload_length: Option<usize>,
    },
    /// Verify a secured frame with its full freshness value (exit 1 when it does not check
    /// out); or, with --dbc, every secured frame of logs, their freshness rebuilt as a
    /// receiver does.
    #[command(after_help = "Examples:
  bywire secoc verify --key ads.key --data-id 0x100 --freshness 7 --profile 24Bit-CMAC-8Bit-FV 100#1122334407A1B2C3
  bywire secoc verify --key ads.key --dbc tug-secured.dbc drive.blf

With --dbc, each message with a SecOCDataId attribute is checked (see bywire-dbc's secoc module
for the attributes); each rejection is printed with its record and reason (a forged or
corrupted MAC, a replay, a jump past the window), then the counts per message. Exit 1 when any
frame was rejected.")]
    Verify {
        #[command(flatten)]
        one: OneFrameOrLog,
    },
}

/// What signing or verifying one frame needs.
#[derive(clap::Args)]
pub struct OneFrame {
    /// The key file.
    #[arg(long, value_name = "KEYFILE")]
    key: PathBuf,
    /// The key's id in the key file.
    #[arg(long, default_value_t = 0)]
    key_id: u32,
    /// The data ID (SecOCDataId; 0x for hex).
    #[arg(long, value_name = "N", value_parser = whole::<u16>)]
    data_id: u16,
    /// The full freshness value (0x for hex).
    #[arg(long, value_name = "FV", value_parser = whole::<u64>)]
    freshness: u64,
    #[command(flatten)]
    lengths: Lengths,
    /// The frame (can-utils text: 123#11223344, 123##1... for CAN FD).
    frame: String,
}

/// A profile, or the three lengths of AUTOSAR's SecOC configuration.
#[derive(clap::Args)]
pub struct Lengths {
    /// An AUTOSAR profile: 24Bit-CMAC-8Bit-FV or 24Bit-CMAC-No-FV.
    #[arg(long, conflicts_with_all = ["fv_length", "fv_tx_length", "mac_tx_length"])]
    profile: Option<String>,
    /// SecOCFreshnessValueLength, in bits.
    #[arg(long, value_name = "BITS", requires_all = ["fv_tx_length", "mac_tx_length"])]
    fv_length: Option<u32>,
    /// SecOCFreshnessValueTxLength: the freshness bits sent.
    #[arg(long, value_name = "BITS", requires = "fv_length")]
    fv_tx_length: Option<u32>,
    /// SecOCAuthInfoTxLength: the MAC bits sent.
    #[arg(long, value_name = "BITS", requires = "fv_length")]
    mac_tx_length: Option<u32>,
}

/// Verify: one frame, or logs with a DBC.
#[derive(clap::Args)]
pub struct OneFrameOrLog {
    /// The key file.
    #[arg(long, value_name = "KEYFILE")]
    key: PathBuf,
    /// The key's id in the key file (one frame; with --dbc each message's SecOCKeyId).
    #[arg(long, default_value_t = 0, conflicts_with = "dbc")]
    key_id: u32,
    /// The data ID (SecOCDataId; 0x for hex).
    #[arg(long, value_name = "N", required_unless_present = "dbc", value_parser = whole::<u16>)]
    data_id: Option<u16>,
    /// The full freshness value (one frame; 0x for hex).
    #[arg(long, value_name = "FV", required_unless_present = "dbc", value_parser = whole::<u64>)]
    freshness: Option<u64>,
    #[command(flatten)]
    lengths: Lengths,
    /// The authentic payload's length in bytes (one frame; the frame's length less the
    /// authenticator's when not given).
    #[arg(long, value_name = "BYTES", conflicts_with = "dbc")]
    payload_length: Option<usize>,
    /// Check logs with this DBC's SecOC declarations instead of one frame.
    #[arg(long, value_name = "FILE")]
    dbc: Option<PathBuf>,
    /// With --dbc: the last freshness value accepted before the logs begin, per message.
    #[arg(long, value_name = "FV", default_value_t = 0, requires = "dbc", value_parser = whole::<u64>)]
    freshness_start: u64,
    /// With --dbc: how far ahead of the last accepted value a freshness value may be.
    #[arg(long, value_name = "N", default_value_t = 16, requires = "dbc")]
    window: u64,
    /// The frame (one frame), or the logs (with --dbc; any format; standard input when none).
    items: Vec<String>,
}

pub fn run(command: &SecocCommand, out: &mut dyn Write) -> Result<()> {
    match command {
        SecocCommand::Sign {
            one,
            payload_length,
        } => sign(one, *payload_length, out),
        SecocCommand::Verify { one } if one.dbc.is_some() => verify_logs(one, out),
        SecocCommand::Verify { one } => verify_one(one, out),
    }
}

fn key(path: &std::path::Path, id: u32) -> Result<Authenticator> {
    let keys = KeyFile::load(path)?;
    let key = keys.key(id).ok_or_else(|| {
        anyhow!(
            "{}: no key with id {id} (ids in the file: {:?})",
            path.display(),
            keys.ids().collect::<Vec<_>>()
        )
    })?;
    Ok(Authenticator::new(key))
}

/// The layout of one frame from the options: `payload` bytes of authentic payload.
fn layout(
    lengths: &Lengths,
    data_id: u16,
    payload: impl Fn(u32) -> Result<usize>,
) -> Result<Layout> {
    let (fv, tx, mac) = match (&lengths.profile, lengths.fv_length) {
        (Some(name), _) => {
            let p = bywire_secoc::profile(name).ok_or_else(|| {
                anyhow!(
                    "--profile {name}: not a known profile ({})",
                    bywire_secoc::PROFILES
                        .iter()
                        .map(|p| p.name)
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })?;
            (p.fv_length, p.fv_tx_length, p.mac_tx_length)
        }
        (None, Some(fv)) => (
            fv,
            lengths.fv_tx_length.unwrap_or(fv),
            lengths.mac_tx_length.unwrap_or(0),
        ),
        (None, None) => bail!("give --profile, or --fv-length, --fv-tx-length and --mac-tx-length"),
    };
    let payload = payload(tx + mac)?;
    Layout::new(data_id, payload, fv, tx, mac).map_err(|e| anyhow!("{e}"))
}

fn parse_frame(text: &str) -> Result<Frame> {
    text.parse::<Frame>()
        .map_err(|e| anyhow!("frame {text}: {e}"))
        .and_then(|f| {
            if f.is_remote() || f.is_error() {
                bail!("frame {text}: a remote or error frame has no payload to secure")
            }
            Ok(f)
        })
}

/// The frame with `data`, in the kind of the original (classic, or FD with its flags).
fn with_data(original: &Frame, data: &[u8]) -> Result<Frame> {
    let id = original
        .id()
        .ok_or_else(|| anyhow!("a frame without an identifier"))?;
    match original {
        Frame::Fd(fd) => {
            // Up to the next length a CAN FD frame has, zero-padded.
            let length = bywire_core::frame::Dlc::fd_covering(data.len())
                .map(bywire_core::frame::Dlc::fd_len)
                .ok_or_else(|| anyhow!("{} bytes do not fit a CAN FD frame", data.len()))?;
            let mut padded = data.to_vec();
            padded.resize(length, 0);
            Frame::fd(id, &padded, fd.brs(), fd.esi()).map_err(|e| anyhow!("{e}"))
        }
        _ => Frame::classic(id, data).map_err(|_| {
            anyhow!(
                "the secured frame needs {} bytes: more than a classic frame carries (write the \
                 frame as CAN FD, with ##)",
                data.len()
            )
        }),
    }
}

fn sign(one: &OneFrame, payload_length: Option<usize>, out: &mut dyn Write) -> Result<()> {
    let auth = key(&one.key, one.key_id)?;
    let frame = parse_frame(&one.frame)?;
    let data_id = one.data_id;
    let layout = layout(&one.lengths, data_id, |_| {
        Ok(payload_length.unwrap_or(frame.data().len()))
    })?;
    if layout.payload_length > frame.data().len() {
        bail!(
            "--payload-length {}: the frame has {} bytes",
            layout.payload_length,
            frame.data().len()
        );
    }
    let mut data = frame.data().to_vec();
    data.resize(data.len().max(layout.secured_length()), 0);
    auth.sign(&layout, one.freshness, &mut data)
        .map_err(|e| anyhow!("--freshness {}: {e}", one.freshness))?;
    writeln!(out, "{}", with_data(&frame, &data)?)?;
    Ok(())
}

fn verify_one(one: &OneFrameOrLog, out: &mut dyn Write) -> Result<()> {
    let [text] = one.items.as_slice() else {
        bail!("give one frame to verify (or --dbc and logs)");
    };
    let auth = key(&one.key, one.key_id)?;
    let frame = parse_frame(text)?;
    let data_id = one.data_id.unwrap_or_default();
    let freshness = one.freshness.unwrap_or_default();
    let length = frame.data().len();
    let layout = layout(&one.lengths, data_id, |bits| match one.payload_length {
        Some(n) => Ok(n),
        None => length
            .checked_sub(usize::try_from(bits.div_ceil(8)).unwrap_or(usize::MAX))
            .ok_or_else(|| {
                anyhow!("frame {text}: {length} bytes are too few for the authenticator")
            }),
    })?;
    if layout.secured_length() > length {
        bail!(
            "frame {text}: {length} bytes where the secured message needs {}",
            layout.secured_length()
        );
    }
    if !auth.verify(&layout, freshness, frame.data()) {
        bail!("frame {text}: does not verify with freshness {freshness} (a wrong MAC, key, data ID or freshness)");
    }
    writeln!(out, "ok")?;
    Ok(())
}

/// One secured message of the DBC, as a receiver checks it.
struct Checked {
    name: String,
    id: bywire_core::Id,
    /// For a PDU of a container frame, its header identifier.
    header_id: Option<u32>,
    layout: Layout,
    auth: Authenticator,
    receiver: Receiver,
}

/// A message's identifier as a frame's.
fn frame_id(message: &bywire_dbc::Message) -> Result<bywire_core::Id> {
    if message.extended {
        bywire_core::Id::extended(message.id)
    } else {
        bywire_core::Id::standard(message.id)
    }
    .map_err(|_| {
        anyhow!(
            "message {}: identifier {:#x} out of range",
            message.name,
            message.id
        )
    })
}

fn verify_logs(options: &OneFrameOrLog, out: &mut dyn Write) -> Result<()> {
    let path = options.dbc.as_ref().ok_or_else(|| anyhow!("--dbc"))?;
    let db = crate::support::dbc::load(path, false)?;
    let keys = KeyFile::load(&options.key)?;
    let mut checked = Vec::new();
    // Secured messages, and secured PDUs of container frames (with the frame and header).
    let mut containers = Vec::new();
    let mut secured_messages: Vec<(&bywire_dbc::Message, Option<(bywire_core::Id, u32)>)> =
        db.messages.iter().map(|m| (m, None)).collect();
    for container in &db.containers {
        let Some(frame) = db.message_by_name(&container.message) else {
            continue;
        };
        let id = frame_id(frame)?;
        containers.push((id, container.header, container.header_byte_order));
        secured_messages.extend(container.pdus.iter().map(|p| (p, Some((id, p.id)))));
    }
    for (message, contained) in secured_messages {
        let Some(secured) = Secured::of(message).with_context(|| path.display().to_string())?
        else {
            continue;
        };
        // A secured message without its key is refused, never checked without one.
        let key = keys.key(secured.key_id).ok_or_else(|| {
            anyhow!(
                "{}: message {} needs key id {}, which {} does not hold",
                path.display(),
                message.name,
                secured.key_id,
                options.key.display()
            )
        })?;
        let (id, header_id) = match contained {
            Some((id, header_id)) => (id, Some(header_id)),
            None => (frame_id(message)?, None),
        };
        checked.push(Checked {
            name: message.name.clone(),
            id,
            header_id,
            layout: secured.layout,
            auth: Authenticator::new(key),
            receiver: Receiver::new(options.freshness_start, options.window),
        });
    }
    if checked.is_empty() {
        bail!(
            "{}: no message declares SecOC (SecOCDataId)",
            path.display()
        );
    }
    let files: Vec<PathBuf> = options.items.iter().map(PathBuf::from).collect();
    for (name, input) in logs::inputs(&files)? {
        for (index, record) in logs::records(&name, input, logs::Skip::Unreadable).enumerate() {
            let record = record?;
            let frame_id = record.frame.id();
            // A container frame: each secured PDU it carries checked on its own.
            let pdus: Vec<(Option<u32>, &[u8])> = match containers
                .iter()
                .find(|(id, ..)| frame_id == Some(*id))
            {
                Some((_, header, order)) => {
                    let mut pdus = Vec::new();
                    for pdu in bywire_dbc::container::split(*header, *order, record.frame.data()) {
                        match pdu {
                            Ok(pdu) => pdus.push((Some(pdu.header_id), pdu.data)),
                            Err(error) => writeln!(
                                out,
                                "{name}: record {}: {} {}: {error}",
                                index + 1,
                                record.interface,
                                record.frame
                            )?,
                        }
                    }
                    pdus
                }
                None => vec![(None, record.frame.data())],
            };
            for (header_id, data) in pdus {
                let Some(message) = checked
                    .iter_mut()
                    .find(|c| frame_id == Some(c.id) && c.header_id == header_id)
                else {
                    continue;
                };
                if let Err(reason) = message
                    .receiver
                    .accept(&message.auth, &message.layout, data)
                {
                    writeln!(
                        out,
                        "{name}: record {}: {} {} {}: {reason}",
                        index + 1,
                        record.interface,
                        record.frame,
                        message.name
                    )?;
                }
            }
        }
    }
    let mut rejected = 0;
    for message in &checked {
        let Counts {
            accepted,
            malformed,
            mac,
            stale,
            window,
        } = message.receiver.counts();
        rejected += message.receiver.counts().rejected();
        writeln!(
            out,
            "{}: {accepted} accepted, {mac} bad MAC, {stale} replayed or stale, {window} beyond the window, {malformed} malformed",
            message.name
        )?;
    }
    if rejected > 0 {
        bail!("{rejected} secured frames rejected");
    }
    Ok(())
}
