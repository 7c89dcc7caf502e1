//! Filter matching against a table of cases worked out from the kernel's `can_raw` rules
//! (net/can/af_can.c: filters are normalised at registration, then matched per receive list).
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_core::filter::{ErrorMask, Filter, FilterItem, FilterSet};
use bywire_core::Frame;

fn frame(t: &str) -> Frame {
    t.parse().unwrap()
}

fn item(t: &str) -> FilterItem {
    t.parse().unwrap()
}

fn filter(t: &str) -> Filter {
    match item(t) {
        FilterItem::Filter(f) => f,
        other => panic!("{other:?}"),
    }
}

/// (filter text, frame text, receives)
const CASES: &[(&str, &str, bool)] = &[
    // id:mask on standard IDs; an 11-bit mask does not look at the EFF flag, so an extended
    // frame with the same low bits matches too (the classic candump surprise).
    ("123:7FF", "123#", true),
    ("123:7FF", "124#", false),
    ("123:7FF", "00000123#", true),
    ("123:7FF", "123#R", true),
    ("120:7F0", "12F#11", true),
    ("120:7F0", "130#11", false),
    // With the EFF flag in the mask only standard frames match (candump: 123:C00007FF).
    ("123:C00007FF", "123#", true),
    ("123:C00007FF", "00000123#", false),
    ("123:C00007FF", "123#R", false),
    // The kernel clears the upper ID bits of the mask for a standard filter with the EFF flag.
    ("123:DFFFFFFF", "123#", true),
    // 8-digit IDs are extended filters.
    ("12345678:1FFFFFFF", "12345678#", true),
    ("12345678:1FFFFFFF", "12345679#", false),
    // Without the EFF flag in the mask the format is not compared: a standard frame matches.
    ("00000123:1FFFFFFF", "123#", true),
    ("00000123:9FFFFFFF", "123#", false),
    // Inverted filters.
    ("123~7FF", "123#", false),
    ("123~7FF", "124#", true),
    ("123~7FF", "00000124#", true),
    ("123~C00007FF", "00000123#", true),
    // A zero mask matches every data frame but never an error frame.
    ("0:0", "7FF#", true),
    ("0:0", "1FFFFFFF#R", true),
    ("0:0", "20000004#0000000000000000", false),
    ("0~0", "123#", false),
    // Error frames never pass ordinary filters.
    ("4:7FF", "20000004#0000000000000000", false),
];

#[test]
fn single_filters_follow_the_kernel_rules() {
    for &(f, fr, expected) in CASES {
        let filters = [filter(f)];
        let set = FilterSet {
            filters: &filters,
            error_mask: ErrorMask::NONE,
            join: false,
        };
        assert_eq!(set.accepts(&frame(fr)), expected, "filter {f}, frame {fr}");
    }
}

#[test]
fn candump_filter_text() {
    assert_eq!(filter("123:7FF"), Filter::new(0x123, 0x7FF));
    assert_eq!(
        filter("12345678:1FFFFFFF"),
        Filter::new(0x9234_5678, 0x1FFF_FFFF)
    );
    assert_eq!(filter("123~7FF"), Filter::new(0x2000_0123, 0x7FF));
    // candump strips the ERR flag from data filter masks.
    assert_eq!(filter("0:FFFFFFFF"), Filter::new(0, 0xDFFF_FFFF));
    assert_eq!(
        item("#FFFFFFFF"),
        FilterItem::ErrorMask(ErrorMask(0xFFFF_FFFF))
    );
    assert_eq!(item("j"), FilterItem::Join);
    for bad in ["123", "12G:7FF", "123:", "123456789:1", "#", "#XYZ"] {
        assert!(bad.parse::<FilterItem>().is_err(), "{bad}");
    }
    let e = "123:7FG".parse::<FilterItem>().unwrap_err();
    assert_eq!(e.column, 5);
}

#[test]
fn error_mask_selects_error_classes() {
    let bus_off = frame("20000040#0000000000000000");
    let controller = frame("20000004#0004000000000000");
    let set = FilterSet {
        filters: &[],
        error_mask: ErrorMask(0x40),
        join: false,
    };
    assert!(set.accepts(&bus_off));
    assert!(!set.accepts(&controller));
    assert!(!set.accepts(&frame("123#")), "no filters: no data frames");
    // A data filter whose mask has the ERR flag is an error filter on the mask's class bits.
    let via_filter = [Filter::new(0, 0x2000_0004)];
    let set = FilterSet {
        filters: &via_filter,
        error_mask: ErrorMask::NONE,
        join: false,
    };
    assert!(set.accepts(&controller) && !set.accepts(&bus_off) && !set.accepts(&frame("123#")));
    assert!(!FilterSet::DEFAULT.accepts(&bus_off) && FilterSet::DEFAULT.accepts(&frame("123#")));
}

#[test]
fn several_filters_any_or_all_with_join() {
    let filters = [filter("100:700"), filter("010:0F0")];
    let any = FilterSet {
        filters: &filters,
        error_mask: ErrorMask::NONE,
        join: false,
    };
    let all = FilterSet { join: true, ..any };
    // 0x115 matches both, 0x125 only the first, 0x215 only the second.
    assert!(any.accepts(&frame("115#")) && all.accepts(&frame("115#")));
    assert!(any.accepts(&frame("125#")) && !all.accepts(&frame("125#")));
    assert!(any.accepts(&frame("215#")) && !all.accepts(&frame("215#")));
    assert!(!any.accepts(&frame("325#")));
    // With join, error frames are dropped unless they reach the filter count.
    let with_errors = FilterSet {
        error_mask: ErrorMask::ALL,
        ..all
    };
    assert!(!with_errors.accepts(&frame("20000040#0000000000000000")));
}
