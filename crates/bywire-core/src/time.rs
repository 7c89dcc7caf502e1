//! Time as the caller gives it: nothing in bywire below the runners reads a clock.

use core::time::Duration;

/// A point in time, in nanoseconds since an epoch the caller chooses (boot, Unix, simulation
/// start). Arithmetic is checked or saturating, never wrapping: the difference of two readings
/// taken out of order is `None`, not a huge positive number.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Timestamp(u64);

impl Timestamp {
    /// The epoch itself.
    pub const ZERO: Timestamp = Timestamp(0);

    /// A timestamp `nanos` nanoseconds after the epoch.
    pub const fn from_nanos(nanos: u64) -> Self {
        Timestamp(nanos)
    }

    /// A timestamp `micros` microseconds after the epoch (saturating).
    pub const fn from_micros(micros: u64) -> Self {
        Timestamp(micros.saturating_mul(1_000))
    }

    /// A timestamp `millis` milliseconds after the epoch (saturating).
    pub const fn from_millis(millis: u64) -> Self {
        Timestamp(millis.saturating_mul(1_000_000))
    }

    /// Nanoseconds since the epoch.
    pub const fn as_nanos(self) -> u64 {
        self.0
    }

    /// Time from `earlier` to `self`, or `None` when `earlier` is in fact later.
    pub fn checked_since(self, earlier: Timestamp) -> Option<Duration> {
        self.0.checked_sub(earlier.0).map(Duration::from_nanos)
    }

    /// Time from `earlier` to `self`, zero when `earlier` is later.
    pub fn saturating_since(self, earlier: Timestamp) -> Duration {
        Duration::from_nanos(self.0.saturating_sub(earlier.0))
    }

    /// `self + d`, or `None` past the end of representable time.
    pub fn checked_add(self, d: Duration) -> Option<Timestamp> {
        // In 64 bits throughout (`Duration::as_nanos` is 128-bit): every deadline is one of
        // these.
        let nanos = d
            .as_secs()
            .checked_mul(1_000_000_000)?
            .checked_add(u64::from(d.subsec_nanos()))?;
        self.0.checked_add(nanos).map(Timestamp)
    }

    /// `self + d`, clamped to the end of representable time.
    pub fn saturating_add(self, d: Duration) -> Timestamp {
        self.checked_add(d).unwrap_or(Timestamp(u64::MAX))
    }
}

/// The earliest of several optional deadlines (`None`: that timer is not running), as a node
/// with several timers answers `next_deadline`. A plain loop: runners ask this at every event,
/// and `into_iter().flatten().min()` over an array compiles to far more work than the compares.
pub fn earliest<const N: usize>(deadlines: [Option<Timestamp>; N]) -> Option<Timestamp> {
    let mut first: Option<Timestamp> = None;
    for deadline in deadlines {
        first = match (first, deadline) {
            (Some(f), Some(d)) => Some(f.min(d)),
            (f, d) => f.or(d),
        };
    }
    first
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn earliest_skips_stopped_timers() {
        let t = Timestamp::from_millis;
        assert_eq!(earliest([None, Some(t(5)), None, Some(t(3))]), Some(t(3)));
        assert_eq!(earliest([Some(t(3)), Some(t(3))]), Some(t(3)));
        assert_eq!(earliest::<2>([None, None]), None);
        assert_eq!(earliest::<0>([]), None);
    }

    #[test]
    fn out_of_order_difference_is_none_not_wrapped() {
        let a = Timestamp::from_millis(10);
        let b = Timestamp::from_millis(4);
        assert_eq!(b.checked_since(a), None);
        assert_eq!(b.saturating_since(a), Duration::ZERO);
        assert_eq!(a.checked_since(b), Some(Duration::from_millis(6)));
        assert_eq!(
            Timestamp::from_nanos(u64::MAX).checked_add(Duration::from_nanos(1)),
            None
        );
        assert_eq!(
            Timestamp::from_nanos(u64::MAX - 1)
                .saturating_add(Duration::from_secs(1))
                .as_nanos(),
            u64::MAX
        );
    }
}
