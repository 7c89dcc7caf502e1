use core::time::Duration;

use crate::time::Timestamp;

/// A counter that counts 0, 1, …, 2^width − 1, 0, … (width 1–8 bits).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct RollingCounter {
    width: u8,
    value: u8,
}

impl RollingCounter {
    /// A counter of `width` bits (clamped to 1–8) starting at 0.
    pub fn new(width: u8) -> Self {
        RollingCounter {
            width: width.clamp(1, 8),
            value: 0,
        }
    }

    /// The current value.
    pub fn value(&self) -> u8 {
        self.value
    }

    /// How many values the counter takes.
    pub fn modulus(&self) -> u16 {
        1u16 << self.width
    }

    /// How many steps forward `to` is from `from` (0 to modulus − 1): a value fewer than
    /// half the modulus ahead came after `from`, any other came at or before it.
    pub fn steps_from(&self, from: u8, to: u8) -> u16 {
        let modulus = self.modulus();
        (u16::from(to) % modulus + modulus - u16::from(from) % modulus) % modulus
    }

    /// Return the current value and advance.
    pub fn next_value(&mut self) -> u8 {
        let v = self.value;
        self.value = u8::try_from((u16::from(v) + 1) % self.modulus()).unwrap_or(0);
        v
    }
}

/// What a received counter value says about the stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CounterStatus {
    /// The first value (or the first after a resynchronisation).
    Initial,
    /// One more than the previous value.
    InSequence,
    /// The same value again: no new data.
    Repeated,
    /// Ahead by more than one, within the allowed gap: `lost` values were missed.
    Skipped {
        /// Values missed.
        lost: u8,
    },
    /// A jump larger than allowed (or backwards): the checker resynchronises on this value.
    OutOfSequence,
    /// Nothing new arrived within the timeout before this value: the stream went stale; the
    /// checker resynchronises on this value.
    Stale,
}

/// Checks a stream of counter values against the previous one and the time since it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CounterChecker {
    counter: RollingCounter,
    max_lost: u8,
    timeout: Duration,
    last: Option<(u8, Timestamp)>,
}

impl CounterChecker {
    /// A checker for `width`-bit counters accepting up to `max_lost` missed values between two
    /// receptions, with data older than `timeout` stale.
    pub fn new(width: u8, max_lost: u8, timeout: Duration) -> Self {
        CounterChecker {
            counter: RollingCounter::new(width),
            max_lost,
            timeout,
            last: None,
        }
    }

    /// Judge `value` received at `now`.
    pub fn check(&mut self, now: Timestamp, value: u8) -> CounterStatus {
        let value = u8::try_from(u16::from(value) % self.counter.modulus()).unwrap_or(0);
        let Some((last, seen)) = self.last else {
            self.last = Some((value, now));
            return CounterStatus::Initial;
        };
        let stale = now.checked_since(seen).is_none_or(|age| age > self.timeout);
        if stale {
            self.last = Some((value, now));
            return CounterStatus::Stale;
        }
        let status = match self.counter.steps_from(last, value) {
            0 => CounterStatus::Repeated,
            1 => CounterStatus::InSequence,
            d if d - 1 <= u16::from(self.max_lost) => CounterStatus::Skipped {
                lost: u8::try_from(d - 1).unwrap_or(u8::MAX),
            },
            _ => CounterStatus::OutOfSequence,
        };
        // A repeated value is not fresh: the staleness clock keeps running from the last new one.
        if status != CounterStatus::Repeated {
            self.last = Some((value, now));
        }
        status
    }

    /// Forget the stream: the next value is `Initial`.
    pub fn reset(&mut self) {
        self.last = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counter_wraps_at_its_width() {
        let mut c = RollingCounter::new(2);
        let seq: [u8; 6] = core::array::from_fn(|_| c.next_value());
        assert_eq!(seq, [0, 1, 2, 3, 0, 1]);
        assert_eq!(c.value(), 2, "the value the next call gives");
        assert_eq!(RollingCounter::new(8).modulus(), 256);
        assert_eq!(RollingCounter::new(0).modulus(), 2);
        let four = RollingCounter::new(4);
        assert_eq!(four.steps_from(14, 1), 3);
        assert_eq!(four.steps_from(1, 14), 13);
        assert_eq!(four.steps_from(5, 5), 0);
        // Values wider than the counter are taken modulo it.
        assert_eq!(four.steps_from(0, 17), 1);
    }

    #[test]
    fn checker_tells_the_cases_apart() {
        let ms = Timestamp::from_millis;
        let mut c = CounterChecker::new(4, 2, Duration::from_millis(50));
        assert_eq!(c.check(ms(0), 14), CounterStatus::Initial);
        assert_eq!(c.check(ms(10), 15), CounterStatus::InSequence);
        assert_eq!(c.check(ms(20), 0), CounterStatus::InSequence);
        assert_eq!(c.check(ms(30), 0), CounterStatus::Repeated);
        assert_eq!(c.check(ms(40), 3), CounterStatus::Skipped { lost: 2 });
        assert_eq!(c.check(ms(50), 7), CounterStatus::OutOfSequence);
        assert_eq!(c.check(ms(60), 6), CounterStatus::OutOfSequence);
        // Repeats do not refresh: 50 ms after the last new value it is stale.
        assert_eq!(c.check(ms(100), 6), CounterStatus::Repeated);
        assert_eq!(c.check(ms(111), 7), CounterStatus::Stale);
        assert_eq!(c.check(ms(112), 8), CounterStatus::InSequence);
        // Time going backwards is treated as stale, never as fresh.
        assert_eq!(c.check(ms(1), 9), CounterStatus::Stale);
        c.reset();
        assert_eq!(c.check(ms(2), 3), CounterStatus::Initial);
        // A full byte: values high in the range are themselves, a wider one taken modulo.
        let mut byte = CounterChecker::new(8, 2, Duration::from_millis(50));
        assert_eq!(byte.check(ms(0), 254), CounterStatus::Initial);
        assert_eq!(byte.check(ms(10), 255), CounterStatus::InSequence);
        assert_eq!(byte.check(ms(20), 0), CounterStatus::InSequence);
        let mut nibble = CounterChecker::new(4, 2, Duration::from_millis(50));
        assert_eq!(nibble.check(ms(0), 0x13), CounterStatus::Initial);
        assert_eq!(nibble.check(ms(10), 4), CounterStatus::InSequence);
    }
}
