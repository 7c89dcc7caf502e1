//! Rounding against libm's `round`, bit for bit: every class of float (any bit pattern),
//! values near halves, and the edges where floats become whole and integers saturate.
#![allow(clippy::cast_possible_truncation)]

use bywire_core::num::{round_to_i32, round_to_i64};
use proptest::prelude::*;

fn reference(value: f64) -> i64 {
    libm::round(value) as i64
}

fn reference_i32(value: f64) -> i32 {
    libm::round(value).clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
}

#[test]
fn edges_round_as_libm_does() {
    let two_52 = 4_503_599_627_370_496.0_f64;
    let mut edges = vec![
        0.0,
        -0.0,
        0.5,
        -0.5,
        1.5,
        -1.5,
        2.5,
        -2.5,
        0.499_999_999_999_999_94,
        -0.499_999_999_999_999_94,
        two_52,
        two_52 - 0.5,
        two_52 + 1.0,
        2.0 * two_52 - 1.0,
        9.223_372_036_854_775e18,
        -9.223_372_036_854_775e18,
        1e300,
        -1e300,
        f64::MAX,
        f64::MIN,
        f64::MIN_POSITIVE,
        f64::EPSILON,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
    ];
    // Each edge's neighbours one step either way.
    let neighbours: Vec<f64> = edges
        .iter()
        .flat_map(|v| {
            [
                f64::from_bits(v.to_bits() + 1),
                f64::from_bits(v.to_bits().wrapping_sub(1)),
            ]
        })
        .collect();
    edges.extend(neighbours);
    for value in edges {
        assert_eq!(round_to_i64(value), reference(value), "{value:e}");
        assert_eq!(round_to_i32(value), reference_i32(value), "{value:e}");
    }
}

proptest! {
    #[test]
    fn any_float_rounds_as_libm_does(bits in any::<u64>()) {
        let value = f64::from_bits(bits);
        prop_assert_eq!(round_to_i64(value), reference(value));
        prop_assert_eq!(round_to_i32(value), reference_i32(value));
    }

    #[test]
    fn values_near_halves_round_as_libm_does(whole in -3_000_000i64..3_000_000, step in -4i64..=4) {
        // A half, and the floats just beside it.
        let half = whole as f64 + 0.5;
        let value = f64::from_bits(half.to_bits().wrapping_add_signed(step));
        prop_assert_eq!(round_to_i64(value), reference(value));
        prop_assert_eq!(round_to_i32(value), reference_i32(value));
    }
}

#[test]
fn messages_show_unit_mistakes_in_exponent_form() {
    use bywire_core::num::Short;
    assert_eq!(Short(1e100).to_string(), "1e100");
    assert_eq!(Short(-3e30).to_string(), "-3e30");
    assert_eq!(Short(1.5e-7).to_string(), "1.5e-7");
    for (value, shown) in [
        (0.0, "0"),
        (-4.1, "-4.1"),
        (172.0, "172"),
        (f64::NAN, "NaN"),
    ] {
        assert_eq!(Short(value).to_string(), shown);
    }
    assert_eq!(Short(f64::NEG_INFINITY).to_string(), "-inf");
    // An f32 as it was sent, not as widened (1e30f32 is 1.0000000150474662e30 as an f64).
    assert_eq!(Short(1e30f32).to_string(), "1e30");
    assert_eq!(Short(-2.5f32).to_string(), "-2.5");
}
