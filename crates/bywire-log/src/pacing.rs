//! When to replay each record of a log: at its recorded offset from the first record, faster
//! or slower by a factor, with long gaps optionally skipped. Pure arithmetic on the log's
//! timestamps; the caller adds the offsets to its own clock and sleeps.

use core::time::Duration;

use bywire_core::Timestamp;

/// The replay schedule of one pass through a log.
#[derive(Debug, Clone, PartialEq)]
pub struct Pacer {
    speed: f64,
    skip_gaps_over: Option<Duration>,
    first: Option<u64>,
    previous: Option<u64>,
    skipped: Duration,
}

impl Pacer {
    /// Replay `speed` times faster than recorded (a speed that is not a positive number
    /// counts as 1).
    pub fn new(speed: f64) -> Pacer {
        Pacer {
            speed: if speed.is_finite() && speed > 0.0 {
                speed
            } else {
                1.0
            },
            skip_gaps_over: None,
            first: None,
            previous: None,
            skipped: Duration::ZERO,
        }
    }

    /// Gaps between records longer than `limit` take no time (canplayer's `-g`).
    pub fn skipping_gaps_over(mut self, limit: Duration) -> Pacer {
        self.skip_gaps_over = Some(limit);
        self
    }

    /// How long after the replay's start the record logged at `logged` is due, records taken
    /// in the order read (one logged before the first is due at the start).
    pub fn due(&mut self, logged: Timestamp) -> Duration {
        let logged = logged.as_nanos();
        if let (Some(limit), Some(previous)) = (self.skip_gaps_over, self.previous) {
            let gap = Duration::from_nanos(logged.saturating_sub(previous));
            if gap > limit {
                self.skipped += gap;
            }
        }
        self.previous = Some(logged);
        let first = *self.first.get_or_insert(logged);
        Duration::from_nanos(logged.saturating_sub(first))
            .saturating_sub(self.skipped)
            .div_f64(self.speed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(ms: u64) -> Timestamp {
        Timestamp::from_millis(ms)
    }

    #[test]
    fn records_are_due_at_their_offset_scaled_by_the_speed() {
        let mut pacer = Pacer::new(2.0);
        assert_eq!(pacer.due(at(1_000)), Duration::ZERO);
        assert_eq!(pacer.due(at(1_100)), Duration::from_millis(50));
        // Out of order: due before the one before it, so already due when it is read.
        assert_eq!(pacer.due(at(1_050)), Duration::from_millis(25));
        assert_eq!(pacer.due(at(900)), Duration::ZERO, "before the first");
        assert_eq!(pacer.due(at(2_000)), Duration::from_millis(500));
        assert_eq!(Pacer::new(f64::NAN).due(at(5)), Duration::ZERO);
        let mut half = Pacer::new(0.5);
        half.due(at(0));
        assert_eq!(half.due(at(10)), Duration::from_millis(20));
    }

    #[test]
    fn long_gaps_are_skipped() {
        let mut pacer = Pacer::new(1.0).skipping_gaps_over(Duration::from_secs(1));
        pacer.due(at(0));
        assert_eq!(pacer.due(at(500)), Duration::from_millis(500));
        // A 10 s gap takes no time; the records after it keep their spacing.
        assert_eq!(pacer.due(at(10_500)), Duration::from_millis(500));
        assert_eq!(pacer.due(at(10_700)), Duration::from_millis(700));
    }
}
