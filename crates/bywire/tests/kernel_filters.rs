//! Filter matching against the Linux kernel itself: in `../shared/tools/canvm.sh`, one candump
//! per filter list listens on vcan0 (candump hands its filters to `can_raw`), cansend sends a
//! set of frames, and the frames each candump received must be exactly those our `FilterSet`
//! accepts for the same filter list.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use bywire_core::filter::{ErrorMask, FilterItem};
use bywire_core::{FilterSet, Frame};

/// candump filter lists (what follows `vcan0,`).
const FILTERS: &[&str] = &[
    "123:7FF",
    "123:C00007FF",
    "123:DFFFFFFF",
    "00000123:1FFFFFFF",
    "00000123:9FFFFFFF",
    "12345678:1FFFFFFF",
    "120:7F0",
    "123~7FF",
    "123~C00007FF",
    "0:0",
    "0~0",
    "100:700,010:0F0",
    "100:700,010:0F0,j",
    "100:700,200:700,300:700",
    "7FF:7FF,00000000:80000000",
];

/// Frames cansend sends.
const FRAMES: &[&str] = &[
    "123#01",
    "124#02",
    "00000123#03",
    "123#R",
    "12F#04",
    "130#05",
    "12345678#06",
    "12345679#07",
    "115#08",
    "125#09",
    "215#0A",
    "325#0B",
    "7FF#0C",
    "1FFFFFFF#0D",
    "000#0E",
    "00000000#0F",
    "223#R2",
];

fn ours(filters: &str, frame: &Frame) -> bool {
    let mut list = Vec::new();
    let mut error_mask = ErrorMask::NONE;
    let mut join = false;
    for item in filters.split(',') {
        match item.parse::<FilterItem>().unwrap() {
            FilterItem::Filter(f) => list.push(f),
            FilterItem::ErrorMask(m) => error_mask = m,
            FilterItem::Join => join = true,
        }
    }
    FilterSet {
        filters: &list,
        error_mask,
        join,
    }
    .accepts(frame)
}

#[test]
fn filters_agree_with_the_kernel() {
    let mut script = String::from("set -e\n");
    for (i, f) in FILTERS.iter().enumerate() {
        script += &format!("candump -L vcan0,{f} > /tmp/f{i} & \n");
    }
    // Every candump listening before the first frame: each of its filters is an entry on
    // vcan0 in the kernel's receive lists (a fixed wait misses frames on a loaded machine).
    let entries: usize = FILTERS
        .iter()
        .map(|f| f.split(',').filter(|item| *item != "j").count())
        .sum();
    script += &format!(
        "for i in $(seq 300); do [ $(cat /proc/net/can/rcvlist_* | awk '$1 == \"vcan0\"' | wc -l) -ge {entries} ] && break; sleep 0.05; done\n"
    );
    for frame in FRAMES {
        script += &format!("cansend vcan0 {frame}\n");
    }
    script += "sleep 0.5\nkill $(jobs -p) 2>/dev/null || true\nsleep 0.2\n";
    for i in 0..FILTERS.len() {
        script += &format!("echo FILTER {i}; cat /tmp/f{i}\n");
    }
    let text = common::in_canvm(&["--can-utils"], &script);
    let blocks: Vec<&str> = text.split("FILTER ").skip(1).collect();
    assert_eq!(blocks.len(), FILTERS.len(), "{text}");
    let mut compared = 0;
    for (filters, block) in FILTERS.iter().zip(&blocks) {
        // candump -L lines: "(timestamp) vcan0 123#01"
        let kernel: Vec<String> = block
            .lines()
            .skip(1)
            .filter_map(|l| l.split_whitespace().nth(2))
            .map(str::to_string)
            .collect();
        let expected: Vec<String> = FRAMES
            .iter()
            .map(|t| t.parse::<Frame>().unwrap())
            .filter(|f| ours(filters, f))
            .map(|f| f.to_string())
            .collect();
        assert_eq!(kernel, expected, "filter list {filters}");
        compared += FRAMES.len();
    }
    assert_eq!(compared, FILTERS.len() * FRAMES.len());
}
