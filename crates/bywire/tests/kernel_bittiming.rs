//! Bit timing against the Linux kernel's own calculation: `../shared/tools/canvm.sh` boots a VM
//! with emulated SJA1000 controllers (8 MHz clock); for each case `ip link set can0 type can
//! bitrate B sample-point P` makes the kernel's driver compute the registers, and
//! `ip -details link show can0` reports them. Requests the kernel refuses must be refused here.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use bywire_core::bittiming::{calculate, SJA1000};

const CLOCK: u32 = 8_000_000;

fn cases() -> Vec<(u32, Option<u32>)> {
    let mut cases = Vec::new();
    let bitrates = [
        10_000, 20_000, 33_333, 47_619, 50_000, 83_333, 95_238, 100_000, 125_000, 250_000, 400_000,
        500_000, 615_384, 666_666, 800_000, 1_000_000,
    ];
    for (i, &bitrate) in bitrates.iter().enumerate() {
        cases.push((bitrate, None));
        cases.push((bitrate, Some([700, 750, 800, 875, 900][i % 5])));
    }
    // Refused by the kernel: too far from any reachable bitrate, or faster than the clock allows.
    cases.extend([(950_000, None), (3_000_000, None), (700_000, Some(875))]);
    cases
}

#[derive(Debug, PartialEq)]
struct Registers {
    bitrate: u32,
    sample_point_permille: u32,
    tq: u32,
    prop_seg: u32,
    phase_seg1: u32,
    phase_seg2: u32,
    sjw: u32,
    brp: u32,
}

fn field(words: &[&str], name: &str) -> u32 {
    let i = words
        .iter()
        .position(|w| *w == name)
        .unwrap_or_else(|| panic!("no {name} in {words:?}"));
    words[i + 1].parse().unwrap()
}

fn parse_kernel(block: &str) -> Option<Registers> {
    if block.contains("FAIL") {
        return None;
    }
    let words: Vec<&str> = block.split_whitespace().collect();
    let sp: f64 = words[words.iter().position(|w| *w == "sample-point").unwrap() + 1]
        .parse()
        .unwrap();
    Some(Registers {
        bitrate: field(&words, "bitrate"),
        sample_point_permille: (sp * 1000.0).round() as u32,
        tq: field(&words, "tq"),
        prop_seg: field(&words, "prop-seg"),
        phase_seg1: field(&words, "phase-seg1"),
        phase_seg2: field(&words, "phase-seg2"),
        sjw: field(&words, "sjw"),
        brp: field(&words, "brp"),
    })
}

#[test]
fn sja1000_timing_agrees_with_the_linux_kernel() {
    let cases = cases();
    let mut script = String::new();
    for (i, (bitrate, sp)) in cases.iter().enumerate() {
        let sp_arg = sp.map_or(String::new(), |p| format!("sample-point 0.{p:03}"));
        script.push_str(&format!(
            "echo CASE {i}; if ip link set can0 type can bitrate {bitrate} {sp_arg} sjw 1 2>/dev/null; \
             then ip -details link show can0 | grep -E 'bitrate|prop-seg'; else echo FAIL; fi\n"
        ));
    }
    let text = common::in_canvm(&["--sja1000", "1"], &script);
    let blocks: Vec<&str> = text.split("CASE ").skip(1).collect();
    assert_eq!(blocks.len(), cases.len(), "{text}");
    let mut agreed = 0;
    let mut refused = 0;
    for (block, (bitrate, sp)) in blocks.iter().zip(&cases) {
        let kernel = parse_kernel(block.split_once('\n').map_or("", |(_, rest)| rest));
        let ours = calculate(CLOCK, *bitrate, *sp, Some(1), &SJA1000)
            .ok()
            .map(|t| Registers {
                bitrate: t.bitrate,
                sample_point_permille: t.sample_point_permille,
                tq: t.tq_ns,
                prop_seg: t.prop_seg,
                phase_seg1: t.phase_seg1,
                phase_seg2: t.phase_seg2,
                sjw: t.sjw,
                brp: t.brp,
            });
        assert_eq!(ours, kernel, "bitrate {bitrate}, sample point {sp:?}");
        if kernel.is_some() {
            agreed += 1;
        } else {
            refused += 1;
        }
    }
    assert!(agreed >= 20, "only {agreed} cases computed");
    assert!(refused >= 2, "only {refused} refusals compared");
}
