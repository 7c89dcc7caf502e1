//! Worst-case response times of CAN messages, by the revised schedulability analysis of Davis,
//! Burns, Bril and Lukkien ("Controller Area Network (CAN) schedulability analysis: refuted,
//! revisited and revised", Real-Time Systems 35, 2007).
//!
//! Each message is a stream of frames queued at least `period` apart (periodic or sporadic),
//! each up to `jitter` after its nominal release, by controllers that always offer their
//! highest-priority pending frame; the identifier is the priority. A frame on the bus cannot be
//! pre-empted, so a message waits for at most one lower-priority frame already started
//! (blocking), for every higher-priority frame queued meanwhile (interference), and for its own
//! earlier instances in the same priority level-m busy period — the revision: a message's
//! first instance can meet its deadline while a later one misses it. Bus errors are not
//! counted: a destroyed frame's retransmission is on top of these figures.
//!
//! Times are integer nanoseconds, frame times rounded up, so every figure is an upper bound.
//! Every fixed-point iteration is bounded ([`STEP_BUDGET`]); a message whose busy period does
//! not close within it is reported [`Unbounded`], never as a bound.

use crate::busload::{Bitrates, INTERFRAME_BITS};
use crate::frame::{Dlc, Id};
use crate::wire::{length_bounds, unstuffed_length, FrameShape};

/// Fixed-point steps one message's analysis may take (busy period and every instance).
pub const STEP_BUDGET: u32 = 1_000_000;

/// A message as the analysis sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stream {
    /// Its identifier: the priority.
    pub id: Id,
    /// Longest time one frame occupies the bus, interframe space included ([`worst_frame_ns`]).
    pub frame_ns: u64,
    /// Shortest time between two queuings (the cycle time, or a sporadic message's minimum
    /// interval). Must be positive.
    pub period_ns: u64,
    /// Latest a frame is queued after its nominal release.
    pub jitter_ns: u64,
}

/// Why a message has no bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unbounded {
    /// The message and those above it need the bus 100 % of the time or more: its busy period
    /// never ends.
    Overloaded,
    /// The busy period did not close within [`STEP_BUDGET`] steps.
    TooLong,
    /// Another stream has the same identifier: priorities must be unique.
    SharedIdentifier,
    /// A period of zero.
    NoPeriod,
}

/// One message's worst case.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Response {
    /// Worst-case response time: from nominal release to the end of the frame (its jitter
    /// included).
    pub worst_ns: u64,
    /// The longest a lower-priority frame can hold the bus when this one is queued.
    pub blocking_ns: u64,
    /// The worst-case queuing delay of the worst instance (from queuing to the start of its
    /// transmission).
    pub queuing_ns: u64,
    /// The longest priority level-m busy period.
    pub busy_period_ns: u64,
    /// Instances of the message in that busy period.
    pub instances: u64,
    /// Which of them (0: the first) has the worst response.
    pub worst_instance: u64,
}

/// One message's result.
pub type Outcome = Result<Response, Unbounded>;

/// The worst-case response time of `streams[index]` among `streams` on a bus whose bit lasts
/// `bit_ns` (rounded up).
pub fn response_time(streams: &[Stream], index: usize, bit_ns: u64) -> Outcome {
    let Some(&m) = streams.get(index) else {
        return Err(Unbounded::NoPeriod);
    };
    if streams.iter().any(|s| s.period_ns == 0) {
        return Err(Unbounded::NoPeriod);
    }
    let others = || {
        streams
            .iter()
            .enumerate()
            .filter(move |&(i, _)| i != index)
            .map(|(_, s)| s)
    };
    if others().any(|s| s.id == m.id) {
        return Err(Unbounded::SharedIdentifier);
    }
    let higher = || others().filter(|s| s.id < m.id);
    let blocking = others()
        .filter(|s| s.id > m.id)
        .map(|s| s.frame_ns)
        .max()
        .unwrap_or(0);
    // Utilisation of this level and above: at 1 or more the busy period never closes.
    let utilisation: f64 = higher()
        .chain(core::iter::once(&m))
        .map(|s| s.frame_ns as f64 / s.period_ns as f64)
        .sum();
    if utilisation >= 1.0 {
        return Err(Unbounded::Overloaded);
    }
    let mut budget = STEP_BUDGET;
    let mut step = || {
        budget = budget.checked_sub(1)?;
        Some(())
    };
    // The busy period: t = B + Σ_{k ∈ hp(m) ∪ {m}} ⌈(t + J_k) / T_k⌉ C_k.
    let mut busy = m.frame_ns;
    loop {
        step().ok_or(Unbounded::TooLong)?;
        let next = higher()
            .chain(core::iter::once(&m))
            .fold(blocking, |sum, k| {
                sum.saturating_add(
                    releases(busy, k.jitter_ns, k.period_ns).saturating_mul(k.frame_ns),
                )
            });
        if next == busy {
            break;
        }
        busy = next;
    }
    let instances = releases(busy, m.jitter_ns, m.period_ns);
    let mut worst: Option<Response> = None;
    let mut queuing = blocking;
    for q in 0..instances {
        // w(q) = B + q C_m + Σ_{k ∈ hp(m)} ⌈(w + J_k + τ_bit) / T_k⌉ C_k, from the previous
        // instance's fixed point (below the new one).
        let own = q.saturating_mul(m.frame_ns);
        queuing = queuing.max(blocking.saturating_add(own));
        loop {
            step().ok_or(Unbounded::TooLong)?;
            let next = higher().fold(blocking.saturating_add(own), |sum, k| {
                let window = queuing.saturating_add(bit_ns);
                sum.saturating_add(
                    releases(window, k.jitter_ns, k.period_ns).saturating_mul(k.frame_ns),
                )
            });
            if next == queuing {
                break;
            }
            queuing = next;
        }
        // R(q) = J_m + w(q) − q T_m + C_m
        let response = m
            .jitter_ns
            .saturating_add(queuing)
            .saturating_add(m.frame_ns)
            .saturating_sub(q.saturating_mul(m.period_ns));
        if worst.is_none_or(|w| response > w.worst_ns) {
            worst = Some(Response {
                worst_ns: response,
                blocking_ns: blocking,
                queuing_ns: queuing.saturating_sub(q.saturating_mul(m.period_ns)),
                busy_period_ns: busy,
                instances,
                worst_instance: q,
            });
        }
    }
    worst.ok_or(Unbounded::TooLong)
}

/// ⌈(window + jitter) / period⌉: releases of a stream within a window.
fn releases(window: u64, jitter: u64, period: u64) -> u64 {
    window.saturating_add(jitter).div_ceil(period.max(1))
}

/// A bit's duration at `bitrate`, in nanoseconds rounded up.
pub fn bit_ns(bitrate: u32) -> u64 {
    1_000_000_000u64.div_ceil(u64::from(bitrate.max(1)))
}

/// The longest time a frame of this shape and DLC occupies the bus, interframe space included:
/// the most stuff bits any identifier and data can cause ([`length_bounds`]). With `brs` and a
/// data bitrate, the FD data phase runs at the data bitrate; the stuff bits that can fall in the
/// arbitration phase are counted at the nominal rate, the rest at the data rate.
pub fn worst_frame_ns(shape: FrameShape, dlc: Dlc, brs: bool, rates: Bitrates) -> u64 {
    let stuffed_max = length_bounds(shape, dlc).1;
    let unstuffed = unstuffed_length(shape, dlc);
    let nominal_ns = |bits: usize| {
        (bits as u64)
            .saturating_mul(1_000_000_000)
            .div_ceil(u64::from(rates.nominal.max(1)))
    };
    let data_rate = rates.data.filter(|_| brs && shape.fd);
    let Some(data_rate) = data_rate else {
        return nominal_ns(stuffed_max + INTERFRAME_BITS as usize);
    };
    // SOF through BRS, then ACK slot, ACK delimiter, EOF and the interframe space.
    let arbitration = if shape.extended { 36 } else { 17 };
    let nominal_bits = arbitration + 9 + INTERFRAME_BITS as usize;
    let data_bits = unstuffed.saturating_sub(arbitration + 9);
    let stuff = stuffed_max.saturating_sub(unstuffed);
    // After SOF a stuff bit can come at bit 5 and every 4 bits after it.
    let stuff_in_arbitration = stuff.min((arbitration - 1) / 4);
    let data_ns = ((data_bits + stuff - stuff_in_arbitration) as u64)
        .saturating_mul(1_000_000_000)
        .div_ceil(u64::from(data_rate.max(1)));
    nominal_ns(nominal_bits + stuff_in_arbitration).saturating_add(data_ns)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;
    use crate::frame::StandardId;

    fn id(raw: u16) -> Id {
        Id::Standard(StandardId::new(raw).unwrap())
    }

    fn stream(raw: u16, frame_ns: u64, period_ns: u64, jitter_ns: u64) -> Stream {
        Stream {
            id: id(raw),
            frame_ns,
            period_ns,
            jitter_ns,
        }
    }

    #[test]
    fn worst_classic_frame_at_500k_is_the_longest_stuffed_frame() {
        let shape = FrameShape::default();
        let rates = Bitrates {
            nominal: 500_000,
            data: None,
        };
        // 8 data bytes: 111 bits unstuffed (with the interframe space). Davis et al.'s formula
        // allows ⌊(98 − 1) / 4⌋ = 24 stuff bits in the 98 stuffed bits (135 bits); the exact
        // search finds at most 23, because the fixed DLC bits break the runs.
        let ns = worst_frame_ns(shape, Dlc::new(8).unwrap(), false, rates);
        assert_eq!(ns, 134 * 2_000);
        // No data: 47 bits and at most 7 stuff bits (the formula: 8).
        assert_eq!(
            worst_frame_ns(shape, Dlc::new(0).unwrap(), false, rates),
            54 * 2_000
        );
    }

    #[test]
    fn fd_data_phase_at_the_data_rate_bounds_every_frame() {
        let shape = FrameShape {
            fd: true,
            ..FrameShape::default()
        };
        let rates = Bitrates {
            nominal: 500_000,
            data: Some(2_000_000),
        };
        let dlc = Dlc::new(15).unwrap();
        let bound = worst_frame_ns(shape, dlc, true, rates);
        let slow = worst_frame_ns(shape, dlc, false, rates);
        assert!(bound < slow, "{bound} vs {slow}");
        // Every frame of this shape takes at most the bound: try a few extreme payloads.
        for (raw, byte) in [
            (0x000u16, 0x00u8),
            (0x7FF, 0xFF),
            (0x555, 0x55),
            (0x0F0, 0x0F),
        ] {
            let fd = crate::frame::FdFrame::new(id(raw), &[byte; 64], true, false).unwrap();
            let exact = crate::busload::frame_time_ns(&crate::Frame::Fd(fd), rates);
            assert!(
                exact <= bound as f64,
                "{raw:03X}/{byte:02X}: {exact} > {bound}"
            );
        }
    }

    /// Davis et al.'s illustration of the flaw the revision fixes: three messages, each taking
    /// 1 ms, periods 2.5, 3.5 and 3.5 ms. The old analysis gives the lowest one 3 ms; its
    /// second instance really ends 3.5 ms after its release.
    #[test]
    fn a_later_instance_can_be_the_worst() {
        let ms = 1_000_000;
        let streams = [
            stream(1, ms, 2_500_000, 0),
            stream(2, ms, 3_500_000, 0),
            stream(3, ms, 3_500_000, 0),
        ];
        // A bit of 1 ns: a frame queued at the critical instant loses to those queued with it.
        let bit = 1;
        let first = response_time(&streams, 0, bit).unwrap();
        assert_eq!(first.worst_ns, 2 * ms, "blocked by one frame, then sent");
        assert_eq!(first.blocking_ns, ms);
        let low = response_time(&streams, 2, bit).unwrap();
        assert_eq!(low.instances, 2);
        assert_eq!(low.worst_instance, 1);
        assert_eq!(low.worst_ns, 3_500_000);
        assert_eq!(low.blocking_ns, 0);
    }

    #[test]
    fn interference_counts_every_release_in_the_window() {
        // A: 100 µs every 1 ms; B: 200 µs every 2 ms with 50 µs jitter; C: 300 µs every 5 ms.
        let streams = [
            stream(0x10, 100_000, 1_000_000, 0),
            stream(0x20, 200_000, 2_000_000, 50_000),
            stream(0x30, 300_000, 5_000_000, 0),
        ];
        let c = response_time(&streams, 2, 2_000).unwrap();
        // w = 0 + ⌈(w+τ)/1ms⌉·100 + ⌈(w+50+τ)/2ms⌉·200 → 300 µs; R = 300 + 300.
        assert_eq!(c.queuing_ns, 300_000);
        assert_eq!(c.worst_ns, 600_000);
        let b = response_time(&streams, 1, 2_000).unwrap();
        // w = 300 (blocked by C) + 100 (A) = 400; R = 50 + 400 + 200.
        assert_eq!(b.worst_ns, 650_000);
    }

    #[test]
    fn overload_and_bad_streams_have_no_bound() {
        let streams = [stream(1, 600, 1_000, 0), stream(2, 500, 1_000, 0)];
        assert!(response_time(&streams, 0, 1).is_ok());
        assert_eq!(response_time(&streams, 1, 1), Err(Unbounded::Overloaded));
        let shared = [stream(1, 10, 1_000, 0), stream(1, 10, 1_000, 0)];
        assert_eq!(
            response_time(&shared, 0, 1),
            Err(Unbounded::SharedIdentifier)
        );
        let zero = [stream(1, 10, 0, 0)];
        assert_eq!(response_time(&zero, 0, 1), Err(Unbounded::NoPeriod));
        assert_eq!(response_time(&zero, 5, 1), Err(Unbounded::NoPeriod));
    }

    #[test]
    fn near_full_utilisation_stays_within_the_step_budget() {
        // 99.99 % utilisation with coprime periods: long busy periods, but bounded work.
        let streams = [
            stream(1, 4_999, 10_000, 0),
            stream(2, 4_999, 10_001, 0),
            stream(3, 1, 1_000_003, 0),
        ];
        for index in 0..streams.len() {
            let outcome = response_time(&streams, index, 1);
            if let Ok(r) = outcome {
                assert!(r.worst_ns >= streams[index].frame_ns);
            }
        }
    }
}
