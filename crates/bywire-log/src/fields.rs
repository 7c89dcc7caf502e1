//! The words of a text log line as values, with errors naming the line and the column of the
//! word at fault (ASC and TRC lines are words separated by spaces).

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

#[cfg(test)]
mod tests {
    use super::*;

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
