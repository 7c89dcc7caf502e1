//! The one place numeric options are checked, as clap value parsers: a value that is not a
//! number, not finite, out of its range or too large to be a duration is a usage error
//! (exit 2) naming the option — never a panic deep in a command, never silently changed.

/// The longest duration an option may give: a week (a longer one is a typo).
const MAX_SECONDS: f64 = 7.0 * 24.0 * 3600.0;

fn number(text: &str) -> Result<f64, String> {
    let value: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("'{text}' is not a number"))?;
    if value.is_finite() {
        Ok(value)
    } else {
        Err(format!("'{text}' is not a finite number"))
    }
}

/// Seconds, more than 0 and at most a week.
pub fn positive_seconds(text: &str) -> Result<f64, String> {
    let value = number(text)?;
    if value > 0.0 && value <= MAX_SECONDS {
        Ok(value)
    } else {
        Err(format!(
            "{value}: more than 0 and at most {MAX_SECONDS} seconds"
        ))
    }
}

/// Seconds, 0 or more and at most a week.
pub fn seconds(text: &str) -> Result<f64, String> {
    let value = number(text)?;
    if (0.0..=MAX_SECONDS).contains(&value) {
        Ok(value)
    } else {
        Err(format!(
            "{value}: 0 or more and at most {MAX_SECONDS} seconds"
        ))
    }
}

/// A moment for a log's clock: an RFC 3339 time (`2026-12-07T08:00:00Z`, any offset), a UTC
/// date (`2026-12-07`, its midnight) or Unix seconds (`1796630400.5`), from 1970 to 2262
/// (what nanoseconds since the epoch hold).
pub fn moment(text: &str) -> Result<bywire_core::Timestamp, String> {
    let trimmed = text.trim();
    let nanos = if let Ok(time) = chrono::DateTime::parse_from_rfc3339(trimmed) {
        time.timestamp_nanos_opt()
    } else if let Ok(date) = chrono::NaiveDate::parse_from_str(trimmed, "%Y-%m-%d") {
        date.and_hms_opt(0, 0, 0)
            .and_then(|t| t.and_utc().timestamp_nanos_opt())
    } else {
        let seconds = number(trimmed).map_err(|_| {
            format!("'{text}' is not a time: 2026-12-07T08:00:00Z, 2026-12-07 or Unix seconds")
        })?;
        // Whole nanoseconds below 2^63: the range checked before the conversion.
        (0.0..9.2e9)
            .contains(&seconds)
            .then(|| (seconds * 1e9).round() as i64)
    };
    nanos
        .and_then(|n| u64::try_from(n).ok())
        .map(bywire_core::Timestamp::from_nanos)
        .ok_or_else(|| format!("'{text}': not between 1970 and 2262"))
}

/// `10m` as (`10`, `m`): the number, then the letters from the first one.
fn number_and_unit(text: &str) -> (&str, &str) {
    let trimmed = text.trim();
    let split = trimmed
        .find(|c: char| c.is_ascii_alphabetic())
        .unwrap_or(trimmed.len());
    trimmed.split_at(split)
}

/// A duration with a unit (`500ms`, `30s`, `10m`, `2h`; a plain number is seconds), more than
/// 0 and at most a week: its seconds.
pub fn duration(text: &str) -> Result<f64, String> {
    let (value, unit) = number_and_unit(text);
    let scale = match unit {
        "" | "s" => 1.0,
        "ms" => 1e-3,
        "m" | "min" => 60.0,
        "h" => 3600.0,
        _ => return Err(format!("'{text}': the unit is one of ms, s, m, h")),
    };
    positive_seconds(&(number(value)? * scale).to_string())
}

/// A size with a unit (`512k`, `100M`, `2G`: powers of 1024; a plain number is bytes), at least
/// 4 KiB and at most 1 TiB: its bytes.
pub fn size(text: &str) -> Result<u64, String> {
    let (value, unit) = number_and_unit(text);
    let scale = match unit.to_ascii_uppercase().trim_end_matches(['B', 'I']) {
        "" => 1.0,
        "K" => 1024.0,
        "M" => 1024.0 * 1024.0,
        "G" => 1024.0 * 1024.0 * 1024.0,
        _ => return Err(format!("'{text}': the unit is one of k, M, G")),
    };
    let bytes = number(value)? * scale;
    if (4096.0..=1024f64.powi(4)).contains(&bytes) {
        // In range, so the conversion is exact enough and cannot wrap.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        Ok(bytes as u64)
    } else {
        Err(format!("'{text}': at least 4 KiB and at most 1 TiB"))
    }
}

/// Milliseconds, 0 or more and at most a week.
pub fn milliseconds(text: &str) -> Result<f64, String> {
    let value = number(text)?;
    if (0.0..=MAX_SECONDS * 1e3).contains(&value) {
        Ok(value)
    } else {
        Err(format!(
            "{value}: 0 or more and at most {} ms",
            MAX_SECONDS * 1e3
        ))
    }
}

/// A rate, from one in 1000 seconds to 1000 per second (its period must be a duration).
pub fn rate(text: &str) -> Result<f64, String> {
    let value = number(text)?;
    if (0.001..=1000.0).contains(&value) {
        Ok(value)
    } else {
        Err(format!("{value}: from 0.001 to 1000 per second"))
    }
}

/// A rate that may be 0 (off), else as [`rate`].
pub fn rate_or_off(text: &str) -> Result<f64, String> {
    if number(text)? == 0.0 {
        return Ok(0.0);
    }
    rate(text)
}

/// A speed factor, from 0.001 to 1000.
pub fn factor(text: &str) -> Result<f64, String> {
    let value = number(text)?;
    if (0.001..=1000.0).contains(&value) {
        Ok(value)
    } else {
        Err(format!("{value}: from 0.001 to 1000"))
    }
}

/// An unsigned integer type an option can hold, with its largest value (for the error).
pub trait Whole: TryFrom<u64> {
    /// The largest value.
    const MAX: u64;
}

impl Whole for u8 {
    const MAX: u64 = u8::MAX as u64;
}

impl Whole for u16 {
    const MAX: u64 = u16::MAX as u64;
}

impl Whole for u32 {
    const MAX: u64 = u32::MAX as u64;
}

impl Whole for u64 {
    const MAX: u64 = u64::MAX;
}

/// A whole number, decimal or `0x` hex, within `T`'s range (a clap value parser: the same
/// spelling for every whole-number option, as `--data-id 0x100` and `--freshness 0x10`).
pub fn whole<T: Whole>(text: &str) -> Result<T, String> {
    let parsed = match text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")) {
        Some(hex) => u64::from_str_radix(hex, 16),
        None => text.parse(),
    };
    parsed
        .ok()
        .and_then(|n| T::try_from(n).ok())
        .ok_or_else(|| {
            format!(
                "{text}: not a whole number from 0 to {} (0x for hex)",
                T::MAX
            )
        })
}

/// A hex number within `T`'s range, `0x` optional: the one spelling of identifiers, DIDs,
/// DTCs and object indices. Hex digits only (no sign, no spaces: `from_str_radix` alone
/// takes `+1F`).
pub fn hex<T: Whole>(text: &str) -> Option<T> {
    let digits = text
        .strip_prefix("0x")
        .or_else(|| text.strip_prefix("0X"))
        .unwrap_or(text);
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    u64::from_str_radix(digits, 16)
        .ok()
        .and_then(|n| T::try_from(n).ok())
}

/// Bytes written as pairs of hex digits (`0A1B2C`), as can-utils and UDS tools write data.
pub fn hex_pairs(text: &str) -> Result<Vec<u8>, String> {
    if !text.len().is_multiple_of(2) {
        return Err(format!("'{text}': an odd number of hex digits"));
    }
    (0..text.len())
        .step_by(2)
        .map(|i| {
            text.get(i..i + 2)
                .and_then(hex::<u8>)
                .ok_or_else(|| format!("'{text}' is not hex"))
        })
        .collect()
}

/// A CAN identifier as can-utils' ISO-TP tools read one: hex, extended when written with 8
/// digits or above 0x7FF; `option` names it in the error.
pub fn can_id(text: &str, option: &str) -> anyhow::Result<bywire_core::Id> {
    let raw =
        hex::<u32>(text).ok_or_else(|| anyhow::anyhow!("{option} {text}: not a hex identifier"))?;
    let id = if text.len() == 8 || raw > 0x7FF {
        bywire_core::Id::extended(raw)
    } else {
        bywire_core::Id::standard(raw)
    };
    id.map_err(|e| anyhow::anyhow!("{option} {text}: {e}"))
}

/// A hex byte, as can-utils reads one (a clap value parser too).
pub fn hex_u8(text: &str) -> Result<u8, String> {
    hex(text).ok_or_else(|| format!("'{text}' is not a hex byte"))
}

/// can-utils' `-x ADDR[:RXADDR]`: extended addressing with the address byte sent and, if
/// given, the one received (else the same).
pub fn extended_addressing(text: &str) -> anyhow::Result<bywire_diag::isotp::Addressing> {
    let (tx, rx) = text.split_once(':').unwrap_or((text, text));
    let byte = |t: &str| hex_u8(t).map_err(|e| anyhow::anyhow!("-x {text}: {e}"));
    Ok(bywire_diag::isotp::Addressing::Extended {
        target: byte(tx)?,
        source: byte(if rx.is_empty() { tx } else { rx })?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moments_are_rfc_3339_times_dates_or_unix_seconds() {
        let nanos = |text| moment(text).map(bywire_core::Timestamp::as_nanos);
        assert_eq!(nanos("2026-12-07T08:00:00Z"), Ok(1_796_630_400_000_000_000));
        assert_eq!(
            nanos("2026-12-07T09:00:00.25+01:00"),
            Ok(1_796_630_400_250_000_000)
        );
        assert_eq!(nanos("2026-12-07"), Ok(1_796_601_600_000_000_000));
        assert_eq!(nanos("1796630400.5"), Ok(1_796_630_400_500_000_000));
        assert_eq!(nanos("0"), Ok(0));
        assert!(moment("-1")
            .unwrap_err()
            .contains("not between 1970 and 2262"));
        assert!(moment("1969-12-31T23:59:59Z").is_err());
        assert!(moment("3000-01-01").is_err());
        assert!(moment("tomorrow").unwrap_err().contains("is not a time"));
        assert!(moment("nan").is_err());
    }

    #[test]
    fn out_of_range_numbers_are_refused_with_their_value() {
        assert_eq!(positive_seconds("2.5"), Ok(2.5));
        for bad in ["-1", "0", "NaN", "inf", "1e300", "x"] {
            assert!(positive_seconds(bad).is_err(), "{bad}");
        }
        assert_eq!(milliseconds("0"), Ok(0.0));
        assert_eq!(seconds("0"), Ok(0.0));
        assert!(seconds("-1").is_err() && seconds("1e300").is_err());
        assert!(milliseconds("1e300").is_err());
        assert!(rate("1e-300").is_err() && rate("1001").is_err() && rate("20").is_ok());
        assert_eq!(rate_or_off("0"), Ok(0.0));
        assert!(factor("1e-300").is_err() && factor("2").is_ok());
    }

    #[test]
    fn hex_takes_digits_with_an_optional_0x_and_nothing_else() {
        assert_eq!(hex::<u16>("7E0"), Some(0x7E0));
        assert_eq!(hex::<u16>("0xF190"), Some(0xF190));
        assert_eq!(hex::<u8>("0XfF"), Some(0xFF));
        for bad in ["", "0x", "+1F", "-1", " 1F", "1F ", "G1", "10000"] {
            assert_eq!(hex::<u16>(bad), None, "{bad}");
        }
        assert_eq!(hex_pairs("0A1b"), Ok(vec![0x0A, 0x1B]));
        assert_eq!(hex_pairs(""), Ok(vec![]));
        for bad in ["0A1", "+1", "zz", "0x12"] {
            assert!(hex_pairs(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn durations_and_sizes_take_units_and_refuse_the_rest() {
        assert_eq!(duration("10m"), Ok(600.0));
        assert_eq!(duration("500ms"), Ok(0.5));
        assert_eq!(duration("2h"), Ok(7200.0));
        assert_eq!(duration("45"), Ok(45.0));
        for bad in ["0s", "-1m", "10 days", "1e9h", "m", "NaNs"] {
            assert!(duration(bad).is_err(), "{bad}");
        }
        assert_eq!(size("100M"), Ok(100 << 20));
        assert_eq!(size("512k"), Ok(512 << 10));
        assert_eq!(size("2GiB"), Ok(2 << 30));
        assert_eq!(size("8192"), Ok(8192));
        for bad in ["10", "2T", "-5M", "5X", "NaNM", "1e30"] {
            assert!(size(bad).is_err(), "{bad}");
        }
    }
}
