//! `bywire isotp` against the Linux kernel's ISO-TP (`can-isotp`) and can-utils' isotpsend and
//! isotprecv, on vcan inside `../shared/tools/canvm.sh`: 4095-byte messages both ways with
//! block sizes and STmin (one side's flow control obeyed by the other, read off candump's
//! timestamps), classic and CAN FD, an escape-length message beyond 4095 bytes, and extended
//! addressing on 29-bit identifiers both ways.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use common::{section, Scratch};

fn pattern(len: usize) -> Vec<u8> {
    (0..len).map(|i| (i * 31 % 251) as u8).collect()
}

fn hex(data: &[u8]) -> String {
    data.iter().map(|b| format!("{b:02X} ")).collect()
}

/// candump -ta lines: (time s, id, data bytes).
fn frames(dump: &str) -> Vec<(f64, String, Vec<u8>)> {
    dump.lines()
        .filter_map(|l| {
            let mut parts = l.split_whitespace();
            let time = parts
                .next()?
                .trim_matches(|c| c == '(' || c == ')')
                .parse()
                .ok()?;
            let _iface = parts.next()?;
            let id = parts.next()?.to_string();
            let _len = parts.next()?;
            let data = parts
                .filter_map(|b| u8::from_str_radix(b, 16).ok())
                .collect();
            Some((time, id, data))
        })
        .collect()
}

/// Check one transfer in a dump: consecutive frames from `sender` in blocks of `bs`, each
/// block after a flow control from the other side, and `gap_s` between frames of a block.
/// This is real time in a VM: a frame can leave late after the time its predecessor was timed
/// from, so 95 % of the gaps must hold STmin (to the microsecond is the simulated-time tests').
fn check_flow(dump: &str, sender: &str, bs: usize, gap_s: f64) {
    let frames = frames(dump);
    assert!(!frames.is_empty(), "no frames in:\n{dump}");
    let mut in_block = 0;
    let mut last: Option<f64> = None;
    let mut cfs = 0;
    let mut gaps: Vec<f64> = Vec::new();
    for (t, id, data) in &frames {
        let kind = data.first().map_or(0xF, |b| b >> 4);
        if id == sender && kind == 2 {
            cfs += 1;
            in_block += 1;
            assert!(
                in_block <= bs,
                "more than {bs} consecutive frames without flow control"
            );
            if let Some(previous) = last {
                gaps.push(t - previous);
            }
            last = Some(*t);
        } else if id != sender && kind == 3 {
            in_block = 0;
            last = None;
        }
    }
    assert!(cfs > 100, "{cfs} consecutive frames");
    let held = gaps.iter().filter(|g| **g >= gap_s * 0.95).count();
    assert!(
        held * 100 >= gaps.len() * 95,
        "{held} of {} gaps hold STmin {gap_s} s: {gaps:?}",
        gaps.len()
    );
}

#[test]
fn bywire_and_the_kernel_exchange_iso_tp_both_ways() {
    let bin = env!("CARGO_BIN_EXE_bywire");
    let dir = Scratch::new("isotp");
    let message = pattern(4095);
    // Beyond 4095 bytes (isotpsend reads at most 5000).
    let long = pattern(4800);
    std::fs::write(dir.join("m4095.txt"), hex(&message)).unwrap();
    std::fs::write(dir.join("m4800.txt"), hex(&long)).unwrap();
    let d = dir.display();
    // Each transfer: a listener first, candump beside it, then the sender.
    let script = format!(
        r#"B={bin}
cd /tmp
# Entries for vcan0 in the kernel's receive lists: a listener adds its own once it is ready.
entries() {{ cat /proc/net/can/rcvlist_* | awk '$1 == "vcan0"' | wc -l; }}
# Start a listener in the background (its pid in L), back once it listens (15 s at most): a
# fixed wait misses frames on a loaded machine.
listen() {{ n=$(entries); "$@" & L=$!; for i in $(seq 300); do [ $(entries) -gt $n ] && return; sleep 0.05; done; }}
# Send; give candump ($D) time to write the last frames, stop it, wait for the listeners.
run() {{ "$@"; sleep 0.3; kill $D 2>/dev/null; wait; }}
echo "== to the kernel"
listen candump -ta vcan0 > dump1.txt; D=$L
listen isotprecv -s 7E8 -d 7E0 -b 4 -m 01 vcan0 > recv1.txt
run sh -c "$B isotp send vcan0 -s 7E0 -d 7E8 < {d}/m4095.txt"
cat recv1.txt
echo "== dump 1"
cat dump1.txt
echo "== from the kernel"
listen candump -ta vcan0 > dump2.txt; D=$L
listen $B isotp recv vcan0 -s 321 -d 123 -b 3 -m F5 > recv2.txt
run sh -c "isotpsend -s 123 -d 321 vcan0 < {d}/m4095.txt"
cat recv2.txt
echo "== dump 2"
cat dump2.txt
echo "== fd to the kernel"
listen isotprecv -s 7E8 -d 7E0 -L 72:64:1 vcan0 > recv3.txt
run sh -c "$B isotp send vcan0 -s 7E0 -d 7E8 -L 72:64:1 < {d}/m4095.txt"
cat recv3.txt
echo "== fd from the kernel"
listen $B isotp recv vcan0 -s 321 -d 123 -L 72:64:1 > recv4.txt
run sh -c "isotpsend -s 123 -d 321 -L 72:64:1 vcan0 < {d}/m4095.txt"
cat recv4.txt
echo "== long to the kernel"
listen isotprecv -s 7E8 -d 7E0 -L 72:64:1 vcan0 > recv5.txt
run sh -c "$B isotp send vcan0 -s 7E0 -d 7E8 -L 72:64:1 < {d}/m4800.txt"
cat recv5.txt
echo "== long from the kernel"
listen $B isotp recv vcan0 -s 321 -d 123 -L 72:64:1 > recv6.txt
run sh -c "isotpsend -s 123 -d 321 -L 72:64:1 vcan0 < {d}/m4800.txt"
cat recv6.txt
echo "== extended to the kernel"
listen isotprecv -s 18DAF110 -d 18DA10F1 -x F1:10 -b 2 -m 01 vcan0 > recv7.txt
run sh -c "head -c 900 {d}/m4095.txt | $B isotp send vcan0 -s 18DA10F1 -d 18DAF110 -x 10:F1"
cat recv7.txt
echo "== extended from the kernel"
listen $B isotp recv vcan0 -s 18DAF110 -d 18DA10F1 -x F1:10 -b 3 > recv8.txt
run sh -c "head -c 900 {d}/m4095.txt | isotpsend -s 18DA10F1 -d 18DAF110 -x 10:F1 vcan0"
cat recv8.txt
echo "== extended dump"
listen candump -ta vcan0 > dump9.txt; D=$L
listen isotprecv -s 18DAF110 -d 18DA10F1 -x F1:10 vcan0 > /dev/null
run sh -c "head -c 60 {d}/m4095.txt | $B isotp send vcan0 -s 18DA10F1 -d 18DAF110 -x 10:F1"
cat dump9.txt
echo "== padding checked"
listen $B isotp recv vcan0 -s 321 -d 123 -p AA:AA -P a > recv10.txt
run sh -c "head -c 57 {d}/m4095.txt | isotpsend -s 123 -d 321 -p AA:AA vcan0"
cat recv10.txt
echo "== padding refused"
listen timeout 4 $B isotp recv vcan0 -s 321 -d 123 -p AA:AA -P a > recv11.txt 2>&1
run sh -c "head -c 57 {d}/m4095.txt | isotpsend -s 123 -d 321 -p CC:AA vcan0"
cat recv11.txt
echo "== kernel checks ours"
listen isotprecv -s 7E8 -d 7E0 -p AA:AA -P a vcan0 > recv12.txt
run sh -c "head -c 57 {d}/m4095.txt | $B isotp send vcan0 -s 7E0 -d 7E8 -p AA:AA -P a"
cat recv12.txt
echo "== dumps"
listen isotpdump -s 7E0 -d 7E8 -a vcan0 > theirs.txt; P1=$L
listen $B isotp dump vcan0 -s 7E0 -d 7E8 -a > ours.txt; P2=$L
listen isotprecv -s 7E8 -d 7E0 -b 2 -m F3 vcan0 > /dev/null; R=$L
head -c 300 {d}/m4095.txt | $B isotp send vcan0 -s 7E0 -d 7E8
wait $R
listen isotprecv -s 7E8 -d 7E0 -m 7F -L 72:64:1 vcan0 > /dev/null; R=$L
head -c 600 {d}/m4095.txt | isotpsend -s 7E0 -d 7E8 -L 72:64:1 vcan0
wait $R
echo 3E 00 | isotpsend -s 7E0 -d 7E8 vcan0
sleep 0.5; kill $P1 $P2; wait $P1 $P2
echo "== theirs"
cat theirs.txt
echo "== ours"
cat ours.txt
echo "== end"
"#
    );
    let dir_text = dir.to_string_lossy().into_owned();
    let out = common::in_canvm(
        &[
            "--can-utils",
            "--fd",
            "--include",
            bin,
            "--include",
            &dir_text,
        ],
        &script,
    );
    let received = |name: &str| section(&out, name).trim().to_string();
    let want = hex(&message).trim().to_string();
    assert_eq!(received("to the kernel"), want, "bywire → kernel:\n{out}");
    assert_eq!(received("from the kernel"), want, "kernel → bywire");
    assert_eq!(
        received("fd to the kernel"),
        want,
        "bywire → kernel, CAN FD"
    );
    assert_eq!(
        received("fd from the kernel"),
        want,
        "kernel → bywire, CAN FD"
    );
    // The kernel obeyed our flow control (BS 3, STmin 500 µs), and we the kernel's (BS 4,
    // STmin 1 ms).
    check_flow(section(&out, "dump 1"), "7E0", 4, 0.001);
    check_flow(section(&out, "dump 2"), "123", 3, 0.0005);
    // Beyond 4095 bytes: the escape first frame, where the kernel has it.
    let long_want = hex(&long).trim().to_string();
    let to = received("long to the kernel");
    let from = received("long from the kernel");
    // Extended addressing on 29-bit identifiers (the address byte first in every frame),
    // both ways; the first 300 bytes of the message (900 hex characters with spaces).
    let short = hex(&message[..300]).trim().to_string();
    assert_eq!(
        received("extended to the kernel"),
        short,
        "bywire → kernel, -x"
    );
    assert_eq!(
        received("extended from the kernel"),
        short,
        "kernel → bywire, -x"
    );
    // Padding checked both ways (-P a): the kernel's padded frames taken, its frames padded
    // with another byte refused; the kernel checking ours takes them.
    // 19 bytes: the last consecutive frame is padded.
    let nineteen = hex(&message[..19]).trim().to_string();
    assert_eq!(
        received("padding checked"),
        nineteen,
        "kernel → bywire, -P a"
    );
    let refused = received("padding refused");
    assert!(refused.contains("not padded as required"), "{refused}");
    assert!(!refused.contains(&nineteen), "{refused}");
    assert_eq!(
        received("kernel checks ours"),
        nineteen,
        "bywire → kernel, -P a"
    );
    let extended = frames(section(&out, "extended dump"));
    // 20 bytes: a first frame (5 of them behind the address byte), its flow control, three
    // consecutive frames.
    assert_eq!(extended.len(), 5, "{extended:?}");
    for (_, id, data) in &extended {
        let (address, expected_id) = if id == "18DA10F1" {
            (0x10, true)
        } else {
            (0xF1, id == "18DAF110")
        };
        assert!(expected_id, "{id}");
        assert_eq!(data[0], address, "{id} {data:02X?}");
    }
    // The dump reads every frame as isotpdump does, line for line (SF, FF, CF, FC in both
    // directions, classic and FD, with the ASCII column).
    let theirs = section(&out, "theirs");
    let ours = section(&out, "ours");
    assert!(theirs.lines().count() > 20, "{theirs}");
    assert_eq!(ours, theirs);
    let bytes = |t: &str| t.split_whitespace().count();
    assert!(
        from == long_want,
        "kernel → bywire: {} bytes of 4800",
        bytes(&from)
    );
    assert!(
        to == long_want,
        "bywire → kernel: {} bytes of 4800",
        bytes(&to)
    );
}
