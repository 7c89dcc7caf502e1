//! The words of a text log line as values, with errors naming the line and the column of the
//! word at fault (ASC and TRC lines are words separated by spaces).

use std::collections::BTreeMap;

use bywire_core::frame::Dlc;

use crate::candump::{LogError, LogErrorKind};

/// A malformed line of a text format, at a column.
pub(crate) fn syntax(line: u64, column: usize, what: String) -> LogError {
    LogError::Syntax {
        line,
        column,
        kind: LogErrorKind::Format(what),
    }
}

/// The column (1-based) of `word` within `text` (a slice of it).
pub(crate) fn column_of(text: &str, word: &str) -> usize {
    (word.as_ptr() as usize).saturating_sub(text.as_ptr() as usize) + 1
}

/// A number with up to `digits` fraction digits (`0.100000`) in units of 10^-`digits`:
/// seconds with 9 digits are nanoseconds, milliseconds with 6 are nanoseconds too.
pub(crate) fn fixed_point(text: &str, digits: u32) -> Option<u64> {
    let (whole, fraction) = text.split_once('.').unwrap_or((text, ""));
    let fraction_digits = u32::try_from(fraction.len()).ok()?;
    if whole.is_empty() || fraction_digits > digits || !fraction.bytes().all(|b| b.is_ascii_digit())
    {
        return None;
    }
    let whole: u64 = whole.parse().ok()?;
    let fraction = if fraction.is_empty() {
        0
    } else {
        fraction.parse::<u64>().ok()? * 10u64.pow(digits - fraction_digits)
    };
    whole.checked_mul(10u64.pow(digits))?.checked_add(fraction)
}

/// `count` data bytes from `words` in base `radix`.
pub(crate) fn data_bytes(
    line: u64,
    text: &str,
    words: &[&str],
    count: usize,
    radix: u32,
) -> Result<Vec<u8>, LogError> {
    if words.len() < count {
        let at = words
            .last()
            .map_or(text.len() + 1, |w| column_of(text, w) + w.len());
        return Err(syntax(
            line,
            at,
            format!("{count} data bytes expected, {} found", words.len()),
        ));
    }
    words
        .iter()
        .take(count)
        .map(|w| {
            u8::from_str_radix(w, radix).map_err(|_| {
                syntax(
                    line,
                    column_of(text, w),
                    format!("'{w}' is not a data byte"),
                )
            })
        })
        .collect()
}

/// A DLC (0-15) in base `radix`.
pub(crate) fn dlc(line: u64, text: &str, word: &str, radix: u32) -> Result<Dlc, LogError> {
    u8::from_str_radix(word, radix)
        .ok()
        .and_then(Dlc::new)
        .ok_or_else(|| {
            syntax(
                line,
                column_of(text, word),
                format!("'{word}' is not a DLC (0-15)"),
            )
        })
}

/// The channel (bus) number of an interface for ASC, TRC and BLF: its trailing number plus one
/// (`can0` is 1), else the next number not taken; remembered in `taken`.
/// Channel names a file may give (each a comment or property).
pub(crate) const MAX_CHANNEL_NAMES: usize = 256;

/// Whether a name a file gives a channel can be an interface's: letters, digits and `_-.:/`,
/// at most 64 characters.
pub(crate) fn is_interface_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_-.:/".contains(c))
}

/// A comment naming a channel's interface (`PREFIX2 = bus1`, which text logs carry before a
/// channel's first frame): its number and name.
pub(crate) fn channel_comment<'t>(text: &'t str, prefix: &str) -> Option<(u32, &'t str)> {
    let (number, name) = text.strip_prefix(prefix)?.split_once(" = ")?;
    let name = name.trim();
    Some((number.trim().parse().ok()?, name)).filter(|_| is_interface_name(name))
}

/// The comment [`channel_comment`] reads, when `interface` is one its channel number does not
/// name (`can1` is channel 2).
pub(crate) fn channel_comment_text(prefix: &str, channel: u32, interface: &str) -> Option<String> {
    (interface != format!("can{}", channel.saturating_sub(1)))
        .then(|| format!("{prefix}{channel} = {interface}"))
}

pub(crate) fn channel_number(taken: &mut BTreeMap<String, u32>, interface: &str) -> u32 {
    if let Some(n) = taken.get(interface) {
        return *n;
    }
    let digits = interface.len()
        - interface
            .bytes()
            .rev()
            .take_while(u8::is_ascii_digit)
            .count();
    let number = interface
        .get(digits..)
        .and_then(|d| d.parse::<u32>().ok())
        .map(|n| n.saturating_add(1))
        .filter(|n| !taken.values().any(|t| t == n))
        .unwrap_or_else(|| taken.values().max().map_or(1, |m| m + 1));
    taken.insert(interface.to_string(), number);
    number
}

/// The time base of a log written as offsets from a start (ASC, TRC): the first frame sets the
/// start (rounded down by the format's rule), and times never go backwards in the file (a
/// frame from before the last is written at the last's time, as python-can does).
#[derive(Debug, Default)]
pub(crate) struct WriteClock {
    start: Option<u64>,
    last: u64,
}

impl WriteClock {
    /// The offset of a frame at `at` from the start, in nanoseconds, and the start when this
    /// frame set it (`start_of` rounds the first frame's time down to it).
    pub(crate) fn offset(
        &mut self,
        at: u64,
        start_of: impl FnOnce(u64) -> u64,
    ) -> (u64, Option<u64>) {
        let (start, new) = match self.start {
            Some(start) => (start, None),
            None => {
                let start = start_of(at).min(at);
                self.start = Some(start);
                self.last = start;
                (start, Some(start))
            }
        };
        self.last = at.max(self.last);
        (self.last - start, new)
    }

    /// Whether no frame was written yet.
    pub(crate) fn unstarted(&self) -> bool {
        self.start.is_none()
    }
}

/// A little-endian `u16` at `at`.
pub(crate) fn u16_at(bytes: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(bytes.get(at..at + 2)?.try_into().ok()?))
}

/// A little-endian `u32` at `at`.
pub(crate) fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?))
}

/// A little-endian `u64` at `at`.
pub(crate) fn u64_at(bytes: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(bytes.get(at..at + 8)?.try_into().ok()?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_write_clock_starts_at_the_first_frame_and_never_goes_back() {
        let mut clock = WriteClock::default();
        assert!(clock.unstarted());
        assert_eq!(
            clock.offset(1_500, |at| at - at % 1_000),
            (500, Some(1_000))
        );
        assert_eq!(clock.offset(2_200, |_| 0), (1_200, None));
        assert_eq!(
            clock.offset(1_700, |_| 0),
            (1_200, None),
            "earlier: at the last time"
        );
        assert!(!clock.unstarted());
    }

    #[test]
    fn fixed_point_numbers() {
        assert_eq!(fixed_point("0.100000", 9), Some(100_000_000));
        assert_eq!(fixed_point("12", 9), Some(12_000_000_000));
        assert_eq!(fixed_point("1059.9", 6), Some(1_059_900_000));
        for bad in [
            "",
            ".5",
            "1.2.3",
            "1.x",
            "1.1234567890",
            "99999999999999999999",
        ] {
            assert_eq!(fixed_point(bad, 9), None, "{bad}");
        }
    }
}
