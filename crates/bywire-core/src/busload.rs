//! Bus load: how much of the bus's time frames occupy.
//!
//! A frame occupies its exact stuffed length plus the 3-bit interframe space (what
//! `canbusload -e` counts); FD frames with BRS spend their data phase at the data bitrate.
//! [`LoadMeter`] measures consecutive windows from timestamped frames; [`predicted_load`] gives
//! the load a set of periodic messages will cause.

use core::time::Duration;

use crate::frame::Frame;
use crate::time::Timestamp;
use crate::wire::{self, FrameShape};

/// Bits of intermission between frames.
pub const INTERFRAME_BITS: u32 = 3;

/// How stuff bits are counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Stuffing {
    /// The frame's real stuff bits (`canbusload -e`).
    #[default]
    Exact,
    /// No stuff bits (`canbusload` without `-e`).
    None,
    /// The most any frame of this format and DLC can have.
    WorstCase,
}

/// Bus bitrates: nominal, and the FD data-phase rate if the bus uses one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Bitrates {
    /// Nominal (arbitration) bitrate in bit/s.
    pub nominal: u32,
    /// Data-phase bitrate for FD frames with BRS.
    pub data: Option<u32>,
}

/// Bits a frame occupies including the interframe space (0 for error frames, which are reports).
pub fn frame_bits(frame: &Frame, stuffing: Stuffing) -> u32 {
    let Some(id) = frame.id() else { return 0 };
    let shape = FrameShape {
        extended: id.is_extended(),
        remote: frame.is_remote(),
        fd: frame.is_fd(),
    };
    let bits = match stuffing {
        Stuffing::Exact => return exact(frame, None).0,
        Stuffing::None => wire::unstuffed_length(shape, frame.dlc()),
        Stuffing::WorstCase => wire::length_bounds(shape, frame.dlc()).1,
    };
    u32::try_from(bits).unwrap_or(u32::MAX) + INTERFRAME_BITS
}

/// Time a frame occupies the bus, interframe space included, in nanoseconds.
pub fn frame_time_ns(frame: &Frame, rates: Bitrates) -> f64 {
    exact(frame, Some(rates)).1
}

/// Exact bits and (with bitrates) time of a frame, interframe space included, from one encoding.
fn exact(frame: &Frame, rates: Option<Bitrates>) -> (u32, f64) {
    let Ok(w) = wire::encode(frame) else {
        return (0, 0.0);
    };
    let bits = u32::try_from(w.len()).unwrap_or(u32::MAX) + INTERFRAME_BITS;
    let ns = rates.map_or(0.0, |rates| {
        let brs = matches!(frame, Frame::Fd(f) if f.brs());
        let data = if brs { rates.data } else { None };
        w.time_ns(rates.nominal, data)
            + f64::from(INTERFRAME_BITS) * 1e9 / f64::from(rates.nominal.max(1))
    });
    (bits, ns)
}

/// One measured window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoadReport {
    /// Window start.
    pub start: Timestamp,
    /// Frames that started in the window.
    pub frames: u32,
    /// Bits those frames occupied, interframe space included.
    pub bits: u64,
    /// Data bits they carried (8 per data byte; none for remote frames).
    pub payload_bits: u64,
    /// Time the bus was busy with them, ns.
    pub busy_ns: f64,
    /// Share of the window the bus was busy, in percent.
    pub load_percent: f64,
}

/// Bus load over consecutive windows of fixed length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoadMeter {
    rates: Bitrates,
    stuffing: Stuffing,
    window: Duration,
    start: Option<Timestamp>,
    frames: u32,
    bits: u64,
    payload_bits: u64,
    busy_ns: f64,
}

impl LoadMeter {
    /// A meter for a bus at `rates`, reporting every `window`.
    pub fn new(rates: Bitrates, window: Duration, stuffing: Stuffing) -> Self {
        LoadMeter {
            rates,
            stuffing,
            window: window.max(Duration::from_nanos(1)),
            start: None,
            frames: 0,
            bits: 0,
            payload_bits: 0,
            busy_ns: 0.0,
        }
    }

    /// The first window starts at `start` (instead of at the first frame): windows on a clock
    /// of the caller's, such as whole seconds of a live measurement.
    pub fn starting_at(mut self, start: Timestamp) -> Self {
        self.start = Some(start);
        self
    }

    /// Close the current window if `now` is past its end, returning its report. Call again
    /// until `None` to step over idle windows.
    pub fn advance(&mut self, now: Timestamp) -> Option<LoadReport> {
        let start = self.start?;
        let end = start.saturating_add(self.window);
        if now < end {
            return None;
        }
        // Window lengths are far below 2^53 ns: exact in f64.
        #[allow(clippy::cast_precision_loss)]
        let window_ns = self.window.as_nanos() as f64;
        let report = LoadReport {
            start,
            frames: self.frames,
            bits: self.bits,
            payload_bits: self.payload_bits,
            busy_ns: self.busy_ns,
            load_percent: 100.0 * self.busy_ns / window_ns,
        };
        self.start = Some(end);
        self.frames = 0;
        self.bits = 0;
        self.payload_bits = 0;
        self.busy_ns = 0.0;
        Some(report)
    }

    /// Count a frame seen at `now`; returns the report of a window it closed, if any (call
    /// [`LoadMeter::advance`] for any further idle windows).
    pub fn record(&mut self, now: Timestamp, frame: &Frame) -> Option<LoadReport> {
        let report = self.advance(now);
        // After a long gap the window moves up to `now` in one step.
        while self
            .start
            .is_some_and(|s| now >= s.saturating_add(self.window))
        {
            let Some(s) = self.start else { break };
            let skipped = now.saturating_since(s).as_nanos() / self.window.as_nanos().max(1);
            let step = u32::try_from(skipped).unwrap_or(u32::MAX);
            self.start = Some(s.saturating_add(self.window.saturating_mul(step)));
        }
        if self.start.is_none() {
            self.start = Some(now);
        }
        // Exact counting encodes the frame once for both its bits and its time; with a data
        // bitrate the time is always the exact one (an FD data phase is not nominal bits).
        let (bits, ns) = match (self.stuffing, self.rates.data) {
            (Stuffing::Exact, _) => exact(frame, Some(self.rates)),
            (_, Some(_)) => (
                frame_bits(frame, self.stuffing),
                frame_time_ns(frame, self.rates),
            ),
            (Stuffing::None | Stuffing::WorstCase, None) => {
                let bits = frame_bits(frame, self.stuffing);
                (
                    bits,
                    f64::from(bits) * 1e9 / f64::from(self.rates.nominal.max(1)),
                )
            }
        };
        if bits == 0 {
            return report; // error frames are reports, not traffic
        }
        let payload = if frame.is_remote() {
            0
        } else {
            frame.data().len()
        };
        self.frames = self.frames.saturating_add(1);
        self.bits = self.bits.saturating_add(u64::from(bits));
        self.payload_bits = self
            .payload_bits
            .saturating_add(8 * u64::try_from(payload).unwrap_or(0));
        self.busy_ns += ns;
        report
    }
}

/// A message sent every `period`, occupying `bits` each time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PeriodicMessage {
    /// Cycle time.
    pub period: Duration,
    /// Bits per frame, interframe space included (see [`frame_bits`]).
    pub bits: u32,
}

/// The load in percent that `messages` cause on a bus of `bitrate` bit/s.
pub fn predicted_load(messages: &[PeriodicMessage], bitrate: u32) -> f64 {
    let bits_per_second: f64 = messages
        .iter()
        .filter(|m| !m.period.is_zero())
        .map(|m| f64::from(m.bits) / m.period.as_secs_f64())
        .sum();
    100.0 * bits_per_second / f64::from(bitrate.max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(t: &str) -> Frame {
        t.parse().unwrap()
    }

    #[test]
    fn frame_bits_by_stuffing_mode() {
        // canbusload without -e: 47 + 8n (standard), 67 + 8n (extended), interframe included.
        assert_eq!(frame_bits(&frame("123#DEADBEEF"), Stuffing::None), 47 + 32);
        assert_eq!(
            frame_bits(&frame("12345678#DEADBEEF"), Stuffing::None),
            67 + 32
        );
        assert_eq!(frame_bits(&frame("000#"), Stuffing::Exact), 50 + 3);
        let exact = frame_bits(&frame("123#DEADBEEF"), Stuffing::Exact);
        let worst = frame_bits(&frame("123#DEADBEEF"), Stuffing::WorstCase);
        assert!(79 <= exact && exact <= worst);
        assert_eq!(frame_bits(&frame("20000004#"), Stuffing::Exact), 0);
    }

    #[test]
    fn meter_reports_windows_and_idle_ones() {
        let rates = Bitrates {
            nominal: 500_000,
            data: None,
        };
        let mut m = LoadMeter::new(rates, Duration::from_millis(10), Stuffing::Exact);
        let f = frame("000#");
        // 100 frames of 53 bits at 2 µs/bit in 10 ms: 10.6 ms busy would exceed; use 50.
        for i in 0..50u64 {
            assert_eq!(m.record(Timestamp::from_micros(i * 100), &f), None);
        }
        let r = m.record(Timestamp::from_millis(25), &f).unwrap();
        assert_eq!((r.frames, r.bits, r.payload_bits), (50, 50 * 53, 0));
        assert!((r.load_percent - 100.0 * 50.0 * 53.0 * 2000.0 / 1e7).abs() < 1e-9);
        // The window after the gap starts at 20 ms and holds the frame at 25 ms.
        let r = m.advance(Timestamp::from_millis(30)).unwrap();
        assert_eq!((r.start, r.frames), (Timestamp::from_millis(20), 1));
        assert_eq!(m.advance(Timestamp::from_millis(39)), None);
        assert_eq!(m.advance(Timestamp::from_millis(40)).unwrap().frames, 0);
    }

    #[test]
    fn a_meter_on_the_callers_clock_reports_each_window_even_when_idle() {
        let rates = Bitrates {
            nominal: 500_000,
            data: None,
        };
        let second = Duration::from_secs(1);
        let mut m = LoadMeter::new(rates, second, Stuffing::None).starting_at(Timestamp::ZERO);
        assert_eq!(m.advance(Timestamp::from_millis(999)), None);
        let idle = m.advance(Timestamp::from_millis(1000)).unwrap();
        assert_eq!(
            (idle.start, idle.frames, idle.bits),
            (Timestamp::ZERO, 0, 0)
        );
        m.record(Timestamp::from_millis(1500), &frame("123#DEADBEEF"));
        m.record(Timestamp::from_millis(1600), &frame("123#R"));
        m.record(Timestamp::from_millis(1700), &frame("20000004#")); // an error frame
        let r = m.advance(Timestamp::from_millis(2000)).unwrap();
        assert_eq!((r.frames, r.bits, r.payload_bits), (2, 79 + 47, 32));
        assert!((r.busy_ns - 126.0 * 2000.0).abs() < 1e-6);
    }

    #[test]
    fn predicted_load_of_periodic_messages() {
        let m = [
            PeriodicMessage {
                period: Duration::from_millis(10),
                bits: 125,
            },
            PeriodicMessage {
                period: Duration::from_millis(20),
                bits: 250,
            },
        ];
        // 12.5 kbit/s + 12.5 kbit/s on 500 kbit/s = 5 %.
        assert!((predicted_load(&m, 500_000) - 5.0).abs() < 1e-9);
    }
}
