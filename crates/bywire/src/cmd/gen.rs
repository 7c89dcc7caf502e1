//! `bywire gen`: cangen's traffic generator, and a DBC-driven one that sends every cyclic
//! message at its cycle time with plausible values.

use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use bywire_core::{ClassicFrame, Dlc, FdFrame, Frame, Id};

use crate::support::busarg;
use crate::support::interrupt::interrupt_flag;
use crate::support::numbers::{hex, hex_pairs};
use crate::support::signals::Dbc;
use bywire_dbc::codec::EncodeMode;

#[derive(clap::Args)]
#[command(after_help = "Examples:
  bywire gen can0                          (random frames every 200 ms)
  bywire gen vcan0 -g 4 -I 42A -L 1 -D i -v (fixed ID and length, incrementing data)
  bywire gen vcan0 -e -L i -n 100          (extended IDs, incrementing length)
  bywire gen vcan0 -f -b -g 0 -n 10000     (CAN FD with BRS, as fast as the bus takes)
  bywire gen vcan0 --dbc vehicle.dbc       (every message at its GenMsgCycleTime)

Modes for -I, -L and -D: r (random, the default), i (increment) or a fixed hex value.
With --dbc each message with a GenMsgCycleTime is sent at that period with values moving
smoothly through each signal's range, counters and checksums filled in.")]
pub struct Args {
    /// The bus (a plain interface name means SocketCAN).
    bus: String,
    /// Gap between bursts in milliseconds.
    #[arg(short = 'g', default_value_t = 200.0, value_parser = crate::support::numbers::milliseconds)]
    gap_ms: f64,
    /// Extended (29-bit) identifiers.
    #[arg(short = 'e')]
    extended: bool,
    /// CAN FD frames.
    #[arg(short = 'f')]
    fd: bool,
    /// CAN FD frames with bit rate switch.
    #[arg(short = 'b')]
    brs: bool,
    /// CAN FD frames with the error state indicator.
    #[arg(short = 'E')]
    esi: bool,
    /// Remote frames.
    #[arg(short = 'R')]
    remote: bool,
    /// Mix extended, FD, BRS, ESI and remote frames at random.
    #[arg(short = 'm')]
    mix: bool,
    /// Identifier mode: r, i or a hex ID.
    #[arg(short = 'I', default_value = "r")]
    id_mode: String,
    /// Length mode: r, i or a fixed length (hex DLC for classic, byte count for FD).
    #[arg(short = 'L', default_value = "r")]
    len_mode: String,
    /// Data mode: r, i or fixed hex data.
    #[arg(short = 'D', default_value = "r")]
    data_mode: String,
    /// Stop after this many frames.
    #[arg(short = 'n')]
    count: Option<u64>,
    /// Frames per burst.
    #[arg(short = 'c', default_value_t = 1)]
    burst: u32,
    /// Print each frame sent.
    #[arg(short = 'v')]
    verbose: bool,
    /// Seed for the random values (a fixed seed repeats the same traffic).
    #[arg(long)]
    seed: Option<u64>,
    /// Generate each message of this DBC at its cycle time.
    #[arg(long, value_name = "FILE")]
    dbc: Option<PathBuf>,
}

/// r, i or a fixed value.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode<T> {
    Random,
    Increment,
    Fixed(T),
}

fn mode<T>(flag: char, text: &str, fixed: impl Fn(&str) -> Option<T>) -> Result<Mode<T>> {
    match text {
        "r" => Ok(Mode::Random),
        "i" => Ok(Mode::Increment),
        other => fixed(other)
            .map(Mode::Fixed)
            .ok_or_else(|| anyhow!("-{flag} '{other}': expected r, i or a hex value")),
    }
}

/// The frame generator of cangen's modes.
struct Generator {
    rng: fastrand::Rng,
    ids: Mode<u32>,
    lens: Mode<usize>,
    data: Mode<Vec<u8>>,
    extended: bool,
    fd: bool,
    brs: bool,
    esi: bool,
    remote: bool,
    mix: bool,
    counter: u64,
}

impl Generator {
    fn new(args: &Args) -> Result<Generator> {
        let ids = mode('I', &args.id_mode, hex::<u32>)?;
        let lens = mode('L', &args.len_mode, |s| {
            hex::<u8>(s).filter(|l| *l <= 64).map(usize::from)
        })?;
        let data = mode('D', &args.data_mode, |s| {
            hex_pairs(s).ok().filter(|bytes| bytes.len() <= 64)
        })?;
        if let Mode::Fixed(id) = ids {
            let limit = if args.extended { 0x1FFF_FFFF } else { 0x7FF };
            if id > limit {
                return Err(anyhow!(
                    "-I {:X}: above the {limit:X} limit of the ID format",
                    id
                ));
            }
        }
        let rng = args
            .seed
            .map_or_else(fastrand::Rng::new, fastrand::Rng::with_seed);
        Ok(Generator {
            rng,
            ids,
            lens,
            data,
            extended: args.extended,
            fd: args.fd || args.brs || args.esi,
            brs: args.brs,
            esi: args.esi,
            remote: args.remote,
            mix: args.mix,
            counter: 0,
        })
    }

    fn next(&mut self) -> Result<Frame> {
        let (mut extended, mut fd, mut brs, mut esi, mut remote) =
            (self.extended, self.fd, self.brs, self.esi, self.remote);
        if self.mix {
            extended = self.rng.bool();
            fd = self.rng.bool();
            brs = fd && self.rng.bool();
            esi = fd && self.rng.bool();
            remote = !fd && self.rng.u8(..8) == 0;
        }
        let n = self.counter;
        self.counter += 1;
        let id_limit = if extended { 0x1FFF_FFFF } else { 0x7FF };
        let raw_id = match self.ids {
            Mode::Random => self.rng.u32(..=id_limit),
            Mode::Increment => u32::try_from(n % (u64::from(id_limit) + 1)).unwrap_or(0),
            Mode::Fixed(id) => id & id_limit,
        };
        let id = if extended {
            Id::extended(raw_id)?
        } else {
            Id::standard(raw_id)?
        };
        let max_len = if fd { 64 } else { 8 };
        // Incrementing data needs at least one byte, as in cangen.
        let min_len = usize::from(self.data == Mode::Increment);
        let len = match &self.lens {
            Mode::Random => self.rng.usize(min_len..=max_len),
            Mode::Increment => {
                let span = u64::try_from(max_len - min_len + 1).unwrap_or(1);
                min_len + usize::try_from(n % span).unwrap_or(0)
            }
            Mode::Fixed(l) => (*l).min(max_len),
        };
        if remote && !fd {
            let dlc = Dlc::from_classic_len(len.min(8)).ok_or_else(|| anyhow!("bad length"))?;
            return Ok(Frame::remote(id, dlc));
        }
        let mut data = [0u8; 64];
        let data = data.get_mut(..len).unwrap_or_default();
        match &self.data {
            Mode::Random => self.rng.fill(data),
            Mode::Increment => {
                for (byte, value) in data.iter_mut().zip(n.to_le_bytes()) {
                    *byte = value;
                }
            }
            Mode::Fixed(bytes) => {
                for (byte, value) in data.iter_mut().zip(bytes) {
                    *byte = *value;
                }
            }
        }
        Ok(if fd {
            Frame::Fd(FdFrame::padded(id, data, brs, esi)?)
        } else {
            Frame::Classic(ClassicFrame::new(id, data)?)
        })
    }
}

pub fn run(args: &Args, out: &mut impl Write) -> Result<()> {
    let dbc = match &args.dbc {
        Some(path) => Some(Dbc::new(crate::support::dbc::load(path, false)?)),
        None => None,
    };
    let mut generator = Generator::new(args)?;
    let mut bus =
        busarg::open_to_send(&args.bus, "gen").with_context(|| format!("bus '{}'", args.bus))?;
    let stop = interrupt_flag();
    let mut sent = 0u64;
    let mut emit = |frame: &Frame, out: &mut dyn Write| -> Result<bool> {
        bus.send(frame)
            .with_context(|| format!("bus '{}': cannot send {frame}", args.bus))?;
        sent += 1;
        if args.verbose {
            writeln!(out, "  {}  {frame}", args.bus)?;
        }
        Ok(args.count.is_some_and(|n| sent >= n) || stop.load(Ordering::Relaxed))
    };
    if let Some(dbc) = dbc {
        return run_dbc(&dbc, &mut emit, out);
    }
    let gap = Duration::from_secs_f64(args.gap_ms / 1000.0);
    let mut next = Instant::now();
    loop {
        for _ in 0..args.burst.max(1) {
            if emit(&generator.next()?, out)? {
                return Ok(());
            }
        }
        next += gap;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
}

/// Every message with a cycle time, sent on its schedule; signal values follow a slow sine
/// through each signal's range (different phase per signal), so plots and monitors move.
fn run_dbc(
    dbc: &Dbc,
    emit: &mut dyn FnMut(&Frame, &mut dyn Write) -> Result<bool>,
    out: &mut dyn Write,
) -> Result<()> {
    let messages: Vec<_> = dbc
        .decoder()
        .database()
        .messages
        .iter()
        .filter_map(|m| dbc.decoder().cycle_time(m).map(|c| (m, c)))
        .collect();
    if messages.is_empty() {
        return Err(anyhow!("the DBC has no message with a GenMsgCycleTime"));
    }
    let start = Instant::now();
    let mut due: Vec<Duration> = vec![Duration::ZERO; messages.len()];
    let mut counters = vec![0u64; messages.len()];
    loop {
        let (index, at) = due
            .iter()
            .copied()
            .enumerate()
            .min_by_key(|(_, at)| *at)
            .ok_or_else(|| anyhow!("no messages"))?;
        std::thread::sleep(at.saturating_sub(start.elapsed()));
        let (message, cycle) = messages
            .get(index)
            .copied()
            .ok_or_else(|| anyhow!("no message"))?;
        let t = at.as_secs_f64();
        let assignments: Vec<String> = message
            .signals
            .iter()
            .enumerate()
            .filter_map(|(i, s)| {
                let (lo, hi) = s.reachable_range()?;
                let (lo, hi) = (lo.max(s.minimum.as_f64()), hi.min(s.maximum.as_f64()));
                let (lo, hi) = if lo < hi {
                    (lo, hi)
                } else {
                    s.reachable_range()?
                };
                let phase = f64::from(u32::try_from(i).unwrap_or(0));
                let x = 0.5 + 0.5 * (t * 0.2 + phase).sin();
                let value = lo + (hi - lo) * x;
                let step = s.factor.as_f64().abs();
                let value = if step > 0.0 {
                    (value / step).floor() * step
                } else {
                    value
                };
                Some(format!("{}={value}", s.name))
            })
            .collect();
        let counter = counters.get(index).copied().unwrap_or(0);
        let frame = dbc.encode(message, &assignments, counter, EncodeMode::Clamp)?;
        if let Some(c) = counters.get_mut(index) {
            *c += 1;
        }
        if let Some(d) = due.get_mut(index) {
            *d += cycle;
        }
        if emit(&frame, out)? {
            return Ok(());
        }
    }
}
