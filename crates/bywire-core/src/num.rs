//! Numbers between the physical and the wire: rounding a float to the integer a signal or an
//! object carries.

/// 2^52: from here on every `f64` is a whole number.
const WHOLE_FROM: f64 = 4_503_599_627_370_496.0;

/// A number as a message shows it (an `f64` or an `f32`, printed as that type prints it):
/// as Rust prints it while that is short, in exponent form from 10^15 or below 10^-4 (a unit
/// mistake of 1e100 is not echoed as 101 digits).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Short<T>(pub T);

macro_rules! short_display {
    ($($float:ty),*) => {$(
        impl core::fmt::Display for Short<$float> {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                let magnitude = self.0.abs();
                if magnitude.is_finite() && magnitude != 0.0 && !(1e-4..1e15).contains(&magnitude)
                {
                    write!(f, "{:e}", self.0)
                } else {
                    write!(f, "{}", self.0)
                }
            }
        }
    )*};
}

short_display!(f32, f64);

/// `value` rounded to the nearest integer, halves away from zero, saturating at the ends of
/// `i64` (NaN is 0): exactly `libm::round(value) as i64`. Written out because a general
/// rounding function works on the float's bits for every magnitude (tens of instructions, a
/// call), where a value headed for an integer needs one conversion and one compare; drives
/// and controllers round their actual values and setpoints many times a millisecond.
#[allow(clippy::cast_possible_truncation, clippy::cast_precision_loss)]
pub fn round_to_i64(value: f64) -> i64 {
    // Toward zero, saturating (NaN to 0).
    let whole = value as i64;
    // Beyond 2^52 the value is whole already (or saturated); NaN fails both compares.
    if !(value < WHOLE_FROM && value > -WHOLE_FROM) {
        return whole;
    }
    // Exact: the fraction of a float below 2^52 is itself a float.
    let fraction = value - whole as f64;
    if fraction >= 0.5 {
        whole + 1
    } else if fraction <= -0.5 {
        whole - 1
    } else {
        whole
    }
}

/// [`round_to_i64`], saturating at the ends of `i32`.
#[allow(clippy::cast_possible_truncation)]
pub fn round_to_i32(value: f64) -> i32 {
    round_to_i64(value).clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}
