//! Latency of a drive-by-wire chain from its logs: command → heartbeat echo, setpoint steps →
//! the actual value's response (dead time to 10 %, 50 %, rise 10–90 %, settling, overshoot),
//! each message's cycle time, jitter and gaps against the DBC, and a frame's transfer from one
//! channel to another (a gateway, a redundant bus, a delayed path).
//!
//! [`Analyzer`] takes records in time order, one at a time, and keeps bounded state: latency
//! figures in fixed histograms (10 µs bins up to 10 s), per-message counters, one step's
//! samples at a time ([`MAX_STEP_SAMPLES`]) and at most [`MAX_PENDING`] frames waiting for
//! their transfer.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use bywire_control::metrics::{step_metrics, StepMetrics};
use bywire_core::{Frame, Timestamp};
use bywire_dbc::codec::Decoded;
use bywire_dbc::decoder::Decoder;

use bywire_dbc::model::Database;
use bywire_vehicle::profile::LoadedProfile;

/// Histogram bins: 10 µs each, up to 10 s; longer figures land in the last bin.
const BIN_NS: u64 = 10_000;
const BINS: usize = 1_000_000;
/// Samples kept of one step's response.
pub const MAX_STEP_SAMPLES: usize = 100_000;
/// Frames waiting on their source channel for the same frame on the destination channel.
pub const MAX_PENDING: usize = 65_536;
/// Steps kept (each a handful of numbers).
pub const MAX_STEPS: usize = 100_000;

/// A signal by message and signal name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SignalRef {
    /// The message's name.
    pub message: String,
    /// The signal's name.
    pub signal: String,
}

impl SignalRef {
    /// `MESSAGE.SIGNAL`.
    pub fn parse(text: &str) -> Option<SignalRef> {
        let (message, signal) = text.split_once('.')?;
        (!message.is_empty() && !signal.is_empty()).then(|| SignalRef {
            message: message.to_string(),
            signal: signal.to_string(),
        })
    }
}

impl std::fmt::Display for SignalRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}.{}", self.message, self.signal)
    }
}

/// What to measure.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Config {
    /// The command's rolling counter and the feedback's echo of it.
    pub echo: Option<(SignalRef, SignalRef)>,
    /// Setpoint → actual pairs whose steps are measured.
    pub responses: Vec<(SignalRef, SignalRef)>,
    /// The smallest setpoint change that counts as a step.
    pub step_min: f64,
    /// Channel pairs (from, to) whose identical frames are matched.
    pub transfers: Vec<(String, String)>,
    /// Longest a transfer or an echo may take to be matched.
    pub window: Duration,
    /// Longest a step's response is followed (it ends sooner at the next step).
    pub step_window: Duration,
}

impl Config {
    /// The echo and the steering and speed responses a loaded vehicle profile binds: its
    /// roles as they were found in its DBC when it loaded, not looked up again by name.
    pub fn from_profile(loaded: &LoadedProfile) -> Config {
        let mut config = Config {
            step_min: 0.5,
            window: Duration::from_secs(1),
            step_window: Duration::from_secs(5),
            ..Config::default()
        };
        let (Some(command), Some(state)) = (&loaded.bindings.command, &loaded.bindings.state)
        else {
            return config;
        };
        let db = &loaded.database;
        let pair = |(m1, s1), (m2, s2)| Some((bound(db, m1, s1)?, bound(db, m2, s2)?));
        let (c, s) = (command.message, state.message);
        config.echo = pair((c, command.counter), (s, state.heartbeat_echo));
        config.responses = [
            pair((c, command.steering), (s, state.steering)),
            pair((c, command.velocity), (s, state.velocity)),
        ]
        .into_iter()
        .flatten()
        .collect();
        config
    }
}

/// The message and signal at these places of `db` (a binding's), by name.
pub(crate) fn bound(db: &Database, message: usize, signal: usize) -> Option<SignalRef> {
    let m = db.messages.get(message)?;
    Some(SignalRef {
        message: m.name.clone(),
        signal: m.signals.get(signal)?.name.clone(),
    })
}

/// Why a configuration does not fit a DBC.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ConfigError(pub(crate) String);

/// Latency figures of one kind.
#[derive(Debug, Clone, PartialEq)]
pub struct Distribution {
    /// Samples.
    pub count: u64,
    /// Smallest, mean and largest, ms.
    pub min_ms: f64,
    /// Mean, ms.
    pub mean_ms: f64,
    /// Largest, ms.
    pub max_ms: f64,
    /// Median, 90th, 99th percentile, ms (to 10 µs).
    pub p50_ms: f64,
    /// 90th percentile, ms.
    pub p90_ms: f64,
    /// 99th percentile, ms.
    pub p99_ms: f64,
    /// Non-empty histogram bins: (lower edge ms, count), 10 µs wide.
    pub histogram: Vec<(f64, u64)>,
}

/// A histogram of durations with exact count, sum, min and max.
struct Histogram {
    bins: Vec<u32>,
    count: u64,
    sum_ns: u128,
    min_ns: u64,
    max_ns: u64,
}

impl Histogram {
    fn new() -> Histogram {
        Histogram {
            bins: Vec::new(),
            count: 0,
            sum_ns: 0,
            min_ns: u64::MAX,
            max_ns: 0,
        }
    }

    fn add(&mut self, ns: u64) {
        if self.bins.is_empty() {
            self.bins = vec![0; BINS];
        }
        let bin = usize::try_from(ns / BIN_NS).unwrap_or(BINS).min(BINS - 1);
        if let Some(b) = self.bins.get_mut(bin) {
            *b = b.saturating_add(1);
        }
        self.count += 1;
        self.sum_ns += u128::from(ns);
        self.min_ns = self.min_ns.min(ns);
        self.max_ns = self.max_ns.max(ns);
    }

    /// The `per_mille`th per-mille: the smallest bin holding that share of the samples.
    fn percentile(&self, per_mille: u64) -> f64 {
        let rank = (self.count.saturating_mul(per_mille)).div_ceil(1000).max(1);
        let mut seen = 0u64;
        for (i, &n) in self.bins.iter().enumerate() {
            seen += u64::from(n);
            if seen >= rank {
                // The bin's upper edge, within the observed range.
                let edge = (i as u64 + 1) * BIN_NS;
                return edge.clamp(self.min_ns, self.max_ns) as f64 / 1e6;
            }
        }
        self.max_ns as f64 / 1e6
    }

    fn summary(&self) -> Option<Distribution> {
        (self.count > 0).then(|| Distribution {
            count: self.count,
            min_ms: self.min_ns as f64 / 1e6,
            mean_ms: self.sum_ns as f64 / self.count as f64 / 1e6,
            max_ms: self.max_ns as f64 / 1e6,
            p50_ms: self.percentile(500),
            p90_ms: self.percentile(900),
            p99_ms: self.percentile(990),
            histogram: self
                .bins
                .iter()
                .enumerate()
                .filter(|(_, &n)| n > 0)
                .map(|(i, &n)| ((i as u64 * BIN_NS) as f64 / 1e6, u64::from(n)))
                .collect(),
        })
    }
}

/// One message's timing on one channel.
#[derive(Debug, Clone, PartialEq)]
pub struct CycleStats {
    /// The channel.
    pub channel: String,
    /// The message's name (or its identifier in hex when the DBC has none).
    pub message: String,
    /// Its identifier (bit 31 set for extended, as in DBC files).
    pub raw_id: u32,
    /// The DBC's cycle time, ms.
    pub nominal_ms: Option<f64>,
    /// Frames.
    pub frames: u64,
    /// Mean, smallest and largest gap between frames, ms.
    pub mean_ms: f64,
    /// Smallest gap, ms.
    pub min_ms: f64,
    /// Largest gap, ms.
    pub max_ms: f64,
    /// Standard deviation of the gaps, ms.
    pub jitter_ms: f64,
    /// Gaps over 1.5 cycle times (missed frames), when the DBC gives a cycle time.
    pub late_gaps: u64,
}

#[derive(Default)]
struct Cycle {
    frames: u64,
    last: Option<u64>,
    sum: f64,
    sum_sq: f64,
    min: f64,
    max: f64,
    late: u64,
    nominal_ns: Option<u64>,
}

/// One setpoint step and how the actual value followed it.
#[derive(Debug, Clone, PartialEq)]
pub struct StepResponse {
    /// When the new setpoint was first on the bus, s since the log's first record.
    pub at_s: f64,
    /// The setpoint before and after.
    pub from: f64,
    /// The new setpoint.
    pub to: f64,
    /// Time to cross 10 %, 50 % and 90 % of the step, s (dead time is the 10 % crossing).
    pub t10_s: Option<f64>,
    /// Time to cross 50 %, s.
    pub t50_s: Option<f64>,
    /// Time to cross 90 %, s.
    pub t90_s: Option<f64>,
    /// The classic figures (rise, settling, overshoot) over the response until the next step.
    pub metrics: Option<StepMetrics>,
}

/// One setpoint → actual pair's steps.
#[derive(Debug, Clone, PartialEq)]
pub struct ResponseReport {
    /// The setpoint.
    pub setpoint: SignalRef,
    /// The actual value.
    pub actual: SignalRef,
    /// Its steps.
    pub steps: Vec<StepResponse>,
}

/// One channel pair's transfers.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferReport {
    /// Where frames were first seen.
    pub from: String,
    /// Where they arrived.
    pub to: String,
    /// How long they took.
    pub latency: Option<Distribution>,
    /// Frames seen on `from` that never arrived within the window.
    pub unmatched: u64,
}

/// What an analysis found.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Records read.
    pub records: u64,
    /// Command → echo latency.
    pub echo: Option<Distribution>,
    /// Commands whose counter was never echoed within the window.
    pub echo_missing: u64,
    /// Step responses.
    pub responses: Vec<ResponseReport>,
    /// Cycle times per channel and message, in channel then identifier order.
    pub cycles: Vec<CycleStats>,
    /// Transfers.
    pub transfers: Vec<TransferReport>,
}

/// A signal found in the DBC: its message's identifier and the signal's index.
#[derive(Clone, Copy)]
pub(crate) struct Located {
    pub(crate) raw: u32,
    pub(crate) extended: bool,
    pub(crate) index: usize,
}

/// Where `s` is in `decoder`'s DBC, with the signal's unit; an error names what is missing.
pub(crate) fn locate(decoder: &Decoder, s: &SignalRef) -> Result<(Located, String), ConfigError> {
    let message = decoder
        .database()
        .message_by_name(&s.message)
        .ok_or_else(|| ConfigError(format!("{s}: the DBC has no message '{}'", s.message)))?;
    let (index, signal) = message
        .signals
        .iter()
        .enumerate()
        .find(|(_, sig)| sig.name == s.signal)
        .ok_or_else(|| ConfigError(format!("{s}: {} has no signal '{}'", s.message, s.signal)))?;
    let located = Located {
        raw: message.id,
        extended: message.extended,
        index,
    };
    Ok((located, signal.unit.clone()))
}

struct Response {
    setpoint: Located,
    actual: Located,
    current: Option<f64>,
    step: Option<(u64, f64, f64)>,
    /// The actual value when the step began (the last one before it).
    initial: Option<f64>,
    last_actual: Option<f64>,
    times: Vec<f64>,
    values: Vec<f64>,
    steps: Vec<StepResponse>,
}

struct Transfer {
    from: String,
    to: String,
    pending: VecDeque<(u64, Frame)>,
    latency: Histogram,
    unmatched: u64,
}

/// A command waiting for its echo.
struct Pending {
    sent: u64,
    echoed: bool,
    data: u64,
}

/// A frame's first 8 bytes as a number (to recognise a copy).
fn head(frame: &Frame) -> u64 {
    let mut bytes = [0u8; 8];
    for (b, d) in bytes.iter_mut().zip(frame.data()) {
        *b = *d;
    }
    u64::from_le_bytes(bytes)
}

/// The streaming analysis.
pub struct Analyzer<'a> {
    decoder: &'a Decoder,
    config: Config,
    echo: Option<(Located, Located)>,
    /// Counter value → when it was first commanded, whether it was echoed yet, and the
    /// command's first 8 bytes (a copy on a redundant bus is the same command).
    commands: BTreeMap<u64, Pending>,
    echo_latency: Histogram,
    echo_missing: u64,
    responses: Vec<Response>,
    /// Channel → identifier (bit 31 for extended) → timing; a channel's name is kept once.
    cycles: BTreeMap<String, BTreeMap<u32, Cycle>>,
    transfers: Vec<Transfer>,
    first: Option<u64>,
    records: u64,
    values: Vec<Option<Decoded>>,
}

impl<'a> Analyzer<'a> {
    /// An analysis of `config` with the messages of `decoder`; an error names a message or
    /// signal the DBC does not have.
    pub fn new(decoder: &'a Decoder, config: Config) -> Result<Analyzer<'a>, ConfigError> {
        let locate = |s: &SignalRef| locate(decoder, s).map(|(l, _)| l);
        let echo = match &config.echo {
            Some((command, feedback)) => Some((locate(command)?, locate(feedback)?)),
            None => None,
        };
        let mut responses = Vec::new();
        for (setpoint, actual) in &config.responses {
            responses.push(Response {
                setpoint: locate(setpoint)?,
                actual: locate(actual)?,
                current: None,
                step: None,
                initial: None,
                last_actual: None,
                times: Vec::new(),
                values: Vec::new(),
                steps: Vec::new(),
            });
        }
        let transfers = config
            .transfers
            .iter()
            .map(|(from, to)| Transfer {
                from: from.clone(),
                to: to.clone(),
                pending: VecDeque::new(),
                latency: Histogram::new(),
                unmatched: 0,
            })
            .collect();
        let most_signals = decoder
            .database()
            .messages
            .iter()
            .map(|m| m.signals.len())
            .max()
            .unwrap_or(0);
        Ok(Analyzer {
            decoder,
            config,
            echo,
            commands: BTreeMap::new(),
            echo_latency: Histogram::new(),
            echo_missing: 0,
            responses,
            cycles: BTreeMap::new(),
            transfers,
            first: None,
            records: 0,
            values: vec![None; most_signals],
        })
    }

    /// The next record (in time order).
    pub fn push(&mut self, at: Timestamp, channel: &str, frame: &Frame) {
        let Some(id) = frame.id() else { return };
        let now = at.as_nanos();
        let first = *self.first.get_or_insert(now);
        self.records += 1;
        let (raw, extended) = (id.as_raw(), id.is_extended());
        self.note_cycle(channel, raw, extended, now);
        self.note_transfer(channel, now, frame);
        let decoded = self.decode(raw, extended, frame);
        if !decoded {
            return;
        }
        let value = |values: &[Option<Decoded>], l: Located| {
            (l.raw == raw && l.extended == extended)
                .then(|| values.get(l.index).copied().flatten())
                .flatten()
                .map(|d| d.physical.as_f64())
        };
        if let Some((command, feedback)) = self.echo {
            let window = u64::try_from(self.config.window.as_nanos()).unwrap_or(u64::MAX);
            if let Some(counter) = value(&self.values, command) {
                let data = head(frame);
                let copy = self.commands.get(&counter.to_bits()).is_some_and(|p| {
                    !p.echoed && p.data == data && now.saturating_sub(p.sent) <= window
                });
                if !copy {
                    let pending = Pending {
                        sent: now,
                        echoed: false,
                        data,
                    };
                    if let Some(Pending { echoed: false, .. }) =
                        self.commands.insert(counter.to_bits(), pending)
                    {
                        self.echo_missing += 1;
                    }
                }
            }
            if let Some(echoed) = value(&self.values, feedback) {
                if let Some(p) = self.commands.get_mut(&echoed.to_bits()) {
                    if !p.echoed && now.saturating_sub(p.sent) <= window {
                        p.echoed = true;
                        self.echo_latency.add(now.saturating_sub(p.sent));
                    }
                }
            }
        }
        let step_window = u64::try_from(self.config.step_window.as_nanos()).unwrap_or(u64::MAX);
        for response in &mut self.responses {
            if let Some(setpoint) = value(&self.values, response.setpoint) {
                let changed = response
                    .current
                    .is_some_and(|c| (setpoint - c).abs() >= self.config.step_min);
                if changed {
                    finish_step(response, first);
                    let from = response.current.unwrap_or(setpoint);
                    response.step = Some((now, from, setpoint));
                    response.initial = response.last_actual;
                }
                if response.current.is_none() || changed {
                    response.current = Some(setpoint);
                }
            }
            let actual = value(&self.values, response.actual);
            if actual.is_some() {
                response.last_actual = actual;
            }
            if let (Some(actual), Some((start, _, _))) = (actual, response.step) {
                let within = now.saturating_sub(start) <= step_window;
                if within && response.times.len() < MAX_STEP_SAMPLES {
                    response.initial.get_or_insert(actual);
                    response.times.push(now.saturating_sub(start) as f64 / 1e9);
                    response.values.push(actual);
                }
            }
        }
    }

    /// Decode the frame into `values` if a configured signal is in it.
    fn decode(&mut self, raw: u32, extended: bool, frame: &Frame) -> bool {
        let wanted = |l: &Located| l.raw == raw && l.extended == extended;
        let needed = self.echo.is_some_and(|(a, b)| wanted(&a) || wanted(&b))
            || self
                .responses
                .iter()
                .any(|r| wanted(&r.setpoint) || wanted(&r.actual));
        if !needed {
            return false;
        }
        let Some((_, _, codec)) = self.decoder.message_with_id(raw, extended) else {
            return false;
        };
        self.values.iter_mut().for_each(|v| *v = None);
        codec.decode(frame.data(), &mut self.values).is_ok()
    }

    fn note_cycle(&mut self, channel: &str, raw: u32, extended: bool, now: u64) {
        let key_id = raw | if extended { 0x8000_0000 } else { 0 };
        if !self.cycles.contains_key(channel) {
            self.cycles.insert(channel.to_string(), BTreeMap::new());
        }
        let Some(by_id) = self.cycles.get_mut(channel) else {
            return;
        };
        let decoder = self.decoder;
        let cycle = by_id.entry(key_id).or_insert_with(|| Cycle {
            min: f64::INFINITY,
            nominal_ns: decoder
                .message_with_id(raw, extended)
                .and_then(|(_, m, _)| decoder.database().cycle_time(m))
                .and_then(|d| u64::try_from(d.as_nanos()).ok()),
            ..Cycle::default()
        });
        cycle.frames += 1;
        if let Some(last) = cycle.last {
            let gap_ns = now.saturating_sub(last);
            let gap = gap_ns as f64 / 1e6;
            cycle.sum += gap;
            cycle.sum_sq += gap * gap;
            cycle.min = cycle.min.min(gap);
            cycle.max = cycle.max.max(gap);
            if cycle
                .nominal_ns
                .is_some_and(|n| gap_ns.saturating_mul(2) > n.saturating_mul(3))
            {
                cycle.late += 1;
            }
        }
        cycle.last = Some(now);
    }

    fn note_transfer(&mut self, channel: &str, now: u64, frame: &Frame) {
        let window = u64::try_from(self.config.window.as_nanos()).unwrap_or(u64::MAX);
        for transfer in &mut self.transfers {
            // Frames that waited longer than the window never arrived.
            while transfer
                .pending
                .front()
                .is_some_and(|(at, _)| now.saturating_sub(*at) > window)
            {
                transfer.pending.pop_front();
                transfer.unmatched += 1;
            }
            if channel == transfer.to {
                if let Some(i) = transfer.pending.iter().position(|(_, f)| f == frame) {
                    if let Some((at, _)) = transfer.pending.remove(i) {
                        transfer.latency.add(now.saturating_sub(at));
                    }
                    continue;
                }
            }
            if channel == transfer.from {
                if transfer.pending.len() >= MAX_PENDING {
                    transfer.pending.pop_front();
                    transfer.unmatched += 1;
                }
                transfer.pending.push_back((now, *frame));
            }
        }
    }

    /// The figures, after the last record.
    pub fn finish(mut self) -> Report {
        let first = self.first.unwrap_or(0);
        self.echo_missing += self.commands.values().filter(|p| !p.echoed).count() as u64;
        for response in &mut self.responses {
            finish_step(response, first);
        }
        let cycles = self
            .cycles
            .into_iter()
            .flat_map(|(channel, by_id)| {
                by_id
                    .into_iter()
                    .map(move |(id, c)| (channel.clone(), id, c))
            })
            .map(|(channel, raw_id, c)| {
                let gaps = c.frames.saturating_sub(1) as f64;
                let mean = if gaps > 0.0 { c.sum / gaps } else { 0.0 };
                let variance = if gaps > 0.0 {
                    (c.sum_sq / gaps - mean * mean).max(0.0)
                } else {
                    0.0
                };
                let message = self
                    .decoder
                    .message_with_id(raw_id & 0x1FFF_FFFF, raw_id & 0x8000_0000 != 0)
                    .map_or_else(
                        || format!("0x{:X}", raw_id & 0x1FFF_FFFF),
                        |(_, m, _)| m.name.clone(),
                    );
                CycleStats {
                    channel,
                    message,
                    raw_id,
                    nominal_ms: c.nominal_ns.map(|n| n as f64 / 1e6),
                    frames: c.frames,
                    mean_ms: mean,
                    min_ms: if c.min.is_finite() { c.min } else { 0.0 },
                    max_ms: c.max,
                    jitter_ms: variance.sqrt(),
                    late_gaps: c.late,
                }
            })
            .collect();
        Report {
            records: self.records,
            echo: self.echo_latency.summary(),
            echo_missing: if self.echo.is_some() {
                self.echo_missing
            } else {
                0
            },
            responses: self
                .config
                .responses
                .iter()
                .zip(self.responses)
                .map(|((setpoint, actual), r)| ResponseReport {
                    setpoint: setpoint.clone(),
                    actual: actual.clone(),
                    steps: r.steps,
                })
                .collect(),
            cycles,
            transfers: self
                .transfers
                .into_iter()
                .map(|t| TransferReport {
                    unmatched: t.unmatched + t.pending.len() as u64,
                    from: t.from,
                    to: t.to,
                    latency: t.latency.summary(),
                })
                .collect(),
        }
    }
}

/// Close the step in progress: its crossings and metrics from the samples since it began.
fn finish_step(response: &mut Response, first: u64) {
    let Some((start, from, to)) = response.step.take() else {
        return;
    };
    let times = std::mem::take(&mut response.times);
    let values = std::mem::take(&mut response.values);
    if response.steps.len() >= MAX_STEPS {
        return;
    }
    let initial = response.initial.take().unwrap_or(from);
    let crossing = |fraction: f64| {
        let level = initial + fraction * (to - initial);
        let rising = to > initial;
        let mut previous: Option<(f64, f64)> = None;
        for (&t, &v) in times.iter().zip(&values) {
            let reached = if rising { v >= level } else { v <= level };
            if reached {
                return Some(match previous {
                    Some((t0, v0)) if v != v0 => t0 + (t - t0) * (level - v0) / (v - v0),
                    _ => t,
                });
            }
            previous = Some((t, v));
        }
        None
    };
    response.steps.push(StepResponse {
        at_s: start.saturating_sub(first) as f64 / 1e9,
        from,
        to,
        t10_s: crossing(0.1),
        t50_s: crossing(0.5),
        t90_s: crossing(0.9),
        metrics: step_metrics(&times, &values, initial, to).ok(),
    });
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;
    use bywire_core::frame::{ClassicFrame, StandardId};
    use bywire_core::Id;

    const DBC: &str = "BA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 65535;
BO_ 256 Cmd: 8 ADS
 SG_ Counter : 0|4@1+ (1,0) [0|15] \"\" ECU
 SG_ Angle : 8|16@1- (0.1,0) [-90|90] \"deg\" ECU
BO_ 257 State: 8 ECU
 SG_ Echo : 0|4@1+ (1,0) [0|15] \"\" ADS
 SG_ Angle : 8|16@1- (0.1,0) [-90|90] \"deg\" ADS
BA_ \"GenMsgCycleTime\" BO_ 256 20;
";

    fn frame(id: u16, counter: u8, angle_deci: i16) -> Frame {
        let a = angle_deci.to_le_bytes();
        let data = [counter, a[0], a[1], 0, 0, 0, 0, 0];
        Frame::Classic(
            ClassicFrame::new(Id::Standard(StandardId::new(id).unwrap()), &data).unwrap(),
        )
    }

    fn signal(text: &str) -> SignalRef {
        SignalRef::parse(text).unwrap()
    }

    fn ms(t: u64) -> Timestamp {
        Timestamp::from_nanos(t * 1_000_000)
    }

    #[test]
    fn echoes_transfers_cycles_and_a_step_from_a_hand_made_log() {
        let (db, _) = bywire_dbc::parse(DBC.as_bytes(), bywire_dbc::Mode::Lenient).unwrap();
        let decoder = Decoder::new(db);
        let config = Config {
            echo: Some((signal("Cmd.Counter"), signal("State.Echo"))),
            responses: vec![(signal("Cmd.Angle"), signal("State.Angle"))],
            step_min: 1.0,
            transfers: vec![("b".into(), "a".into())],
            window: Duration::from_secs(1),
            step_window: Duration::from_secs(5),
        };
        let mut analyzer = Analyzer::new(&decoder, config).unwrap();
        // Commands every 20 ms from 20 ms on channel b and, 3 ms later, the same frame on
        // channel a; the state echoes each counter 7 ms after the command on b. One cycle is
        // late (80 → 140 ms). At 140 ms the angle steps from 0 to 10°; the state's angle ramps
        // at 0.1°/ms from 140 ms. Command 6 is lost on a; counter 9 is never echoed.
        let mut t = 0;
        for k in 0u8..12 {
            t += if k == 4 { 60 } else { 20 };
            let angle = if t >= 100 { 100 } else { 0 };
            analyzer.push(ms(t), "b", &frame(0x100, k, angle));
            if k != 6 {
                analyzer.push(ms(t + 3), "a", &frame(0x100, k, angle));
            }
            let actual = i16::try_from((t + 7).saturating_sub(140).min(100)).unwrap();
            let echo = if k == 9 { 15 } else { k };
            analyzer.push(ms(t + 7), "a", &frame(0x101, echo, actual));
        }
        let report = analyzer.finish();
        let echo = report.echo.unwrap();
        assert_eq!(echo.count, 11);
        assert_eq!((echo.min_ms, echo.max_ms), (7.0, 7.0));
        assert_eq!(report.echo_missing, 1);
        let transfer = report.transfers[0].latency.as_ref().unwrap();
        assert_eq!(
            (transfer.count, transfer.p50_ms, transfer.max_ms),
            (11, 3.0, 3.0)
        );
        assert_eq!(report.transfers[0].unmatched, 1);
        let cmd_on_b = report
            .cycles
            .iter()
            .find(|c| c.channel == "b" && c.message == "Cmd")
            .unwrap();
        assert_eq!(cmd_on_b.nominal_ms, Some(20.0));
        assert_eq!(cmd_on_b.frames, 12);
        assert_eq!((cmd_on_b.min_ms, cmd_on_b.max_ms), (20.0, 60.0));
        assert_eq!(cmd_on_b.late_gaps, 1);
        let steps = &report.responses[0].steps;
        assert_eq!(steps.len(), 1);
        let step = &steps[0];
        // The step is first on the bus at 140 ms, 120 ms after the first record.
        assert_eq!((step.from, step.to), (0.0, 10.0));
        assert!((step.at_s - 0.12).abs() < 1e-9, "{}", step.at_s);
        // Sampled every 20 ms from 7 ms on (0.7°, 2.7°, 4.7°, …): 1° is crossed at 10 ms and
        // 5° at 50 ms, between samples.
        assert!((step.t10_s.unwrap() - 0.01).abs() < 1e-9, "{step:?}");
        assert!((step.t50_s.unwrap() - 0.05).abs() < 1e-9, "{step:?}");
        assert!(step.metrics.is_some());
    }

    proptest::proptest! {
        /// Any records — unknown identifiers, short or garbage data, time going backwards —
        /// end in a report, never a panic.
        #[test]
        fn any_records_end_in_a_report(
            records in proptest::collection::vec(
                (0u64..5_000, 0x0FEu16..0x103, proptest::collection::vec(proptest::num::u8::ANY, 0..=8), 0u8..3),
                0..300,
            )
        ) {
            let (db, _) = bywire_dbc::parse(DBC.as_bytes(), bywire_dbc::Mode::Lenient).unwrap();
            let decoder = Decoder::new(db);
            let config = Config {
                echo: Some((signal("Cmd.Counter"), signal("State.Echo"))),
                responses: vec![(signal("Cmd.Angle"), signal("State.Angle"))],
                step_min: 0.5,
                transfers: vec![("c0".into(), "c1".into())],
                window: Duration::from_millis(100),
                step_window: Duration::from_secs(1),
            };
            let mut analyzer = Analyzer::new(&decoder, config).unwrap();
            for (t, id, data, channel) in &records {
                let frame = Frame::Classic(
                    ClassicFrame::new(Id::Standard(StandardId::new(*id).unwrap()), data).unwrap(),
                );
                analyzer.push(ms(*t), &format!("c{channel}"), &frame);
            }
            let report = analyzer.finish();
            proptest::prop_assert_eq!(report.records, records.len() as u64);
        }
    }

    #[test]
    fn unknown_signals_are_named() {
        let (db, _) = bywire_dbc::parse(DBC.as_bytes(), bywire_dbc::Mode::Lenient).unwrap();
        let decoder = Decoder::new(db);
        let config = Config {
            echo: Some((signal("Cmd.Nope"), signal("State.Echo"))),
            ..Config::default()
        };
        let error = Analyzer::new(&decoder, config).err().unwrap();
        assert_eq!(error.to_string(), "Cmd.Nope: Cmd has no signal 'Nope'");
        let config = Config {
            responses: vec![(signal("Gone.A"), signal("State.Angle"))],
            ..Config::default()
        };
        let error = Analyzer::new(&decoder, config).err().unwrap();
        assert_eq!(error.to_string(), "Gone.A: the DBC has no message 'Gone'");
    }
}
