//! A bus's schedule from its DBC: each message's worst-case response time
//! ([`bywire_core::schedule`]), whether it meets its deadline, and the bus's utilisation —
//! a design check that needs no bus.
//!
//! What the analysis takes from the file, per message:
//! - the frame: identifier, size, classic or FD with bit rate switching (`VFrameFormat`), at
//!   its longest stuffed length;
//! - the period: `GenMsgCycleTime`; a message whose `GenMsgSendType` is spontaneous or
//!   event-driven is sporadic with `GenMsgDelayTime` as its minimum interval (the shorter of the
//!   two when it is both cyclic and spontaneous); a message with neither cannot be analysed, and
//!   the result says so (it is left out, so the others' bounds do not hold while it is sent);
//! - the deadline: `GenMsgDeadline` when given, else the cycle time, else the minimum interval;
//! - the queuing jitter: `GenMsgJitter` when given, else the caller's figure for every message.
//!
//! All four attributes are milliseconds.

use core::time::Duration;

use bywire_core::busload::Bitrates;
use bywire_core::frame::{Dlc, ExtendedId, Id, StandardId};
use bywire_core::schedule::{bit_ns, response_time, worst_frame_ns, Outcome, Stream};
use bywire_core::wire::FrameShape;

use crate::{Database, Message};

/// What the file does not say.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// The bus's bitrates.
    pub rates: Bitrates,
    /// Queuing jitter of messages without a `GenMsgJitter`.
    pub jitter: Duration,
}

/// One analysed message.
#[derive(Debug, Clone, PartialEq)]
pub struct MessageSchedule {
    /// Its name.
    pub name: String,
    /// Its identifier.
    pub id: Id,
    /// Its longest time on the bus, interframe space included.
    pub frame_ns: u64,
    /// Its period or minimum interval.
    pub period_ns: u64,
    /// Whether it is sporadic (the period is a minimum interval).
    pub sporadic: bool,
    /// Its queuing jitter.
    pub jitter_ns: u64,
    /// Its deadline.
    pub deadline_ns: u64,
    /// The analysis's result.
    pub outcome: Outcome,
}

impl MessageSchedule {
    /// Whether its worst-case response time is within its deadline (never, without a bound).
    pub fn meets_deadline(&self) -> bool {
        self.outcome
            .is_ok_and(|response| response.worst_ns <= self.deadline_ns)
    }
}

/// A message the analysis had to leave out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skipped {
    /// Its name.
    pub name: String,
    /// Its identifier as written in the file.
    pub raw_id: u32,
    /// Why.
    pub reason: String,
}

/// The bus's schedule.
#[derive(Debug, Clone, PartialEq)]
pub struct Schedule {
    /// The analysed messages, highest priority first.
    pub messages: Vec<MessageSchedule>,
    /// The messages left out, in file order.
    pub skipped: Vec<Skipped>,
    /// The share of the bus the analysed messages need at their worst (each frame at its
    /// longest, each message at its period), in percent.
    pub utilisation: f64,
}

impl Schedule {
    /// The messages that can miss their deadline.
    pub fn misses(&self) -> impl Iterator<Item = &MessageSchedule> {
        self.messages.iter().filter(|m| !m.meets_deadline())
    }
}

/// The schedule of the messages of `db` that `selected` picks, on one bus.
pub fn analyse(db: &Database, selected: impl Fn(&Message) -> bool, options: Options) -> Schedule {
    let mut messages = Vec::new();
    let mut skipped = Vec::new();
    for message in db.messages.iter().filter(|m| selected(m)) {
        match timing(db, message, options) {
            Ok(m) => messages.push(m),
            Err(reason) => skipped.push(Skipped {
                name: message.name.clone(),
                raw_id: message.raw_id(),
                reason,
            }),
        }
    }
    messages.sort_by_key(|m| m.id);
    let streams: Vec<Stream> = messages
        .iter()
        .map(|m| Stream {
            id: m.id,
            frame_ns: m.frame_ns,
            period_ns: m.period_ns,
            jitter_ns: m.jitter_ns,
        })
        .collect();
    let bit = bit_ns(options.rates.nominal);
    for (index, message) in messages.iter_mut().enumerate() {
        message.outcome = response_time(&streams, index, bit);
    }
    let utilisation = 100.0
        * streams
            .iter()
            .map(|s| s.frame_ns as f64 / s.period_ns as f64)
            .sum::<f64>();
    Schedule {
        messages,
        skipped,
        utilisation,
    }
}

/// A message's frame, period, jitter and deadline, or why it has none.
fn timing(db: &Database, message: &Message, options: Options) -> Result<MessageSchedule, String> {
    let id = if message.extended {
        ExtendedId::new(message.id).map(Id::Extended)
    } else {
        u16::try_from(message.id)
            .ok()
            .and_then(StandardId::new)
            .map(Id::Standard)
    }
    .ok_or_else(|| format!("identifier 0x{:X} is out of range", message.id))?;
    let (fd, brs) = db.fd_format(message);
    let size = usize::try_from(message.size).unwrap_or(usize::MAX);
    let dlc = if fd {
        Dlc::fd_covering(size)
    } else {
        Dlc::from_classic_len(size)
    }
    .ok_or_else(|| format!("size {} bytes fits no frame", message.size))?;
    let shape = FrameShape {
        extended: message.extended,
        remote: false,
        fd,
    };
    let cycle = db.cycle_time(message);
    let spontaneous = db
        .message_attribute_text(message, "GenMsgSendType")
        .is_some_and(|t| {
            let t = t.to_ascii_lowercase();
            t.contains("spontan") || t.contains("event")
        });
    let min_interval = db.message_attribute_ms(message, "GenMsgDelayTime");
    let period = match (spontaneous, cycle, min_interval) {
        (true, _, None) => {
            return Err("spontaneous, with no GenMsgDelayTime (minimum interval)".into())
        }
        (true, Some(cycle), Some(interval)) => cycle.min(interval),
        (true, None, Some(interval)) => interval,
        (false, Some(cycle), _) => cycle,
        (false, None, _) => return Err("no GenMsgCycleTime".into()),
    };
    let deadline = db
        .message_attribute_ms(message, "GenMsgDeadline")
        .or(cycle)
        .unwrap_or(period);
    let jitter = db
        .message_attribute_ms(message, "GenMsgJitter")
        .unwrap_or(options.jitter);
    let ns = |d: Duration| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
    Ok(MessageSchedule {
        name: message.name.clone(),
        id,
        frame_ns: worst_frame_ns(shape, dlc, brs, options.rates),
        period_ns: ns(period),
        sporadic: spontaneous,
        jitter_ns: ns(jitter),
        deadline_ns: ns(deadline),
        outcome: Err(bywire_core::schedule::Unbounded::NoPeriod),
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;
    use crate::{parse, Mode};

    const HEADER: &str = "BA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 65535;
BA_DEF_ BO_ \"GenMsgSendType\" ENUM \"Cyclic\",\"Spontaneous\",\"CyclicAndSpontaneous\";
BA_DEF_ BO_ \"GenMsgDelayTime\" INT 0 65535;
BA_DEF_ BO_ \"GenMsgDeadline\" INT 0 65535;
BA_DEF_ BO_ \"VFrameFormat\" ENUM \"StandardCAN\",\"ExtendedCAN\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"StandardCAN_FD\",\"ExtendedCAN_FD\";
BA_DEF_DEF_ \"GenMsgSendType\" \"Cyclic\";
";

    fn schedule(body: &str, rates: Bitrates) -> Schedule {
        schedule_with_jitter(body, rates, Duration::ZERO)
    }

    fn schedule_with_jitter(body: &str, rates: Bitrates, jitter: Duration) -> Schedule {
        let (db, _) = parse(format!("{HEADER}{body}").as_bytes(), Mode::Lenient).unwrap();
        analyse(&db, |_| true, Options { rates, jitter })
    }

    const CLASSIC_500K: Bitrates = Bitrates {
        nominal: 500_000,
        data: None,
    };

    #[test]
    fn periods_deadlines_and_what_is_left_out_come_from_the_attributes() {
        let s = schedule(
            "BO_ 256 Fast: 8 A
BO_ 512 Event: 2 A
BO_ 768 Mixed: 4 A
BO_ 1024 Unknown: 8 A
BO_ 1280 NoInterval: 8 A
BO_ 2147484160 Ext: 8 A
BA_ \"GenMsgCycleTime\" BO_ 256 10;
BA_ \"GenMsgDeadline\" BO_ 256 5;
BA_ \"GenMsgSendType\" BO_ 512 1;
BA_ \"GenMsgDelayTime\" BO_ 512 2;
BA_ \"GenMsgSendType\" BO_ 768 2;
BA_ \"GenMsgCycleTime\" BO_ 768 100;
BA_ \"GenMsgDelayTime\" BO_ 768 20;
BA_ \"GenMsgSendType\" BO_ 1280 1;
BA_ \"GenMsgCycleTime\" BO_ 2147484160 50;
",
            CLASSIC_500K,
        );
        let by_name = |n: &str| s.messages.iter().find(|m| m.name == n).unwrap();
        assert_eq!(by_name("Fast").period_ns, 10_000_000);
        assert_eq!(by_name("Fast").deadline_ns, 5_000_000);
        assert!(!by_name("Fast").sporadic);
        assert_eq!(by_name("Event").period_ns, 2_000_000);
        assert!(by_name("Event").sporadic);
        assert_eq!(by_name("Event").deadline_ns, 2_000_000);
        assert_eq!(by_name("Mixed").period_ns, 20_000_000);
        assert_eq!(by_name("Mixed").deadline_ns, 100_000_000);
        // Priority order: the extended 0x200's first 11 bits are zero, so it wins over all.
        let order: Vec<&str> = s.messages.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(order, ["Ext", "Fast", "Event", "Mixed"]);
        let skipped: Vec<(&str, &str)> = s
            .skipped
            .iter()
            .map(|k| (k.name.as_str(), k.reason.as_str()))
            .collect();
        assert_eq!(
            skipped,
            [
                ("Unknown", "no GenMsgCycleTime"),
                (
                    "NoInterval",
                    "spontaneous, with no GenMsgDelayTime (minimum interval)"
                )
            ]
        );
        assert!(s.misses().next().is_none());
        // 268 µs / 10 ms + (2 bytes) 146 µs / 2 ms + (4 bytes) 186 µs / 20 ms + (extended,
        // 8 bytes) 318 µs / 50 ms.
        let expected: f64 = s
            .messages
            .iter()
            .map(|m| 100.0 * m.frame_ns as f64 / m.period_ns as f64)
            .sum();
        assert!((s.utilisation - expected).abs() < 1e-9);
        assert!(
            s.utilisation > 11.0 && s.utilisation < 12.0,
            "{}",
            s.utilisation
        );
    }

    #[test]
    fn an_overloaded_bus_shows_its_misses() {
        // Eleven 8-byte messages every 3 ms at 500 kbit/s: 268 µs each, 98 % of the bus.
        let mut body = String::new();
        for i in 0..11 {
            let id = 0x100 + i;
            body.push_str(&format!(
                "BO_ {id} M{i}: 8 A\nBA_ \"GenMsgCycleTime\" BO_ {id} 3;\n"
            ));
        }
        let s = schedule(&body, CLASSIC_500K);
        let worst: Vec<u64> = s
            .messages
            .iter()
            .map(|m| m.outcome.unwrap().worst_ns)
            .collect();
        // The first waits for one lower frame, then each waits for those above it too.
        for (i, w) in worst.iter().enumerate().take(10) {
            assert_eq!(*w, (i as u64 + 2) * 268_000, "{worst:?}");
        }
        assert_eq!(worst[10], 11 * 268_000);
        assert!(s.misses().next().is_none(), "{worst:?}");
        assert!((s.utilisation - 100.0 * 11.0 * 0.268 / 3.0).abs() < 1e-9);
        // Queued up to 0.1 ms late: the two lowest end after their next release is due.
        let late = schedule_with_jitter(&body, CLASSIC_500K, Duration::from_micros(100));
        let missed: Vec<&str> = late.misses().map(|m| m.name.as_str()).collect();
        assert_eq!(missed, ["M9", "M10"]);
        assert_eq!(late.messages[9].outcome.unwrap().worst_ns, 3_048_000);
    }

    #[test]
    fn fd_messages_use_the_data_bitrate() {
        let body = "BO_ 256 Big: 64 A
BA_ \"GenMsgCycleTime\" BO_ 256 10;
BA_ \"VFrameFormat\" BO_ 256 14;
";
        let slow = schedule(body, CLASSIC_500K);
        let fast = schedule(
            body,
            Bitrates {
                nominal: 500_000,
                data: Some(2_000_000),
            },
        );
        assert!(fast.messages[0].frame_ns * 2 < slow.messages[0].frame_ns);
        assert!(fast.messages[0].meets_deadline());
    }
}
