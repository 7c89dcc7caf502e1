//! The can-utils commands against can-utils itself, on the kernel's vcan interfaces inside
//! `../shared/tools/canvm.sh`: the same traffic through candump and `bywire dump`, cansend and
//! `bywire send`, canplayer and `bywire play` (each replaying the other's logs), canbusload and
//! `bywire busload`.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use common::section;

/// Run `script` in the VM with two vcan interfaces, can-utils and our binary as `$B`.
fn in_vm(script: &str) -> String {
    in_vm_with(script, &[])
}

/// The same with more host files copied into the VM.
fn in_vm_with(script: &str, files: &[&str]) -> String {
    let bin = env!("CARGO_BIN_EXE_bywire");
    // ready FILE IFACE: send warm-up frames (7FE#00) on IFACE until the listener writing FILE
    // has printed one, so a slow VM never loses the start of the traffic to a late listener.
    let ready = "ready() { for i in $(seq 50); do cansend $2 7FE#00; sleep 0.2; [ -s $1 ] && return; done; }";
    let script = format!("B={bin}\ncd /tmp\n{ready}\n{script}");
    let mut options = vec!["--can-utils", "--vcan", "2", "--include", bin];
    for f in files {
        options.extend(["--include", f]);
    }
    common::in_canvm(&options, &script)
}

/// The lines after the one with the 7FD marker frame.
fn after_marker(text: &str) -> &str {
    let marker = text
        .find("7FD")
        .unwrap_or_else(|| panic!("no marker in:\n{text}"));
    let end = text[marker..]
        .find('\n')
        .map_or(text.len(), |e| marker + e + 1);
    &text[end..]
}

/// Frames of the same traffic: classic, extended, remote (with DLC), FD with and without BRS,
/// an empty FD frame, a raw DLC, error frames, ASCII data, FD over 8 bytes.
const TRAFFIC: &str = "\
cansend vcan0 123#DEADBEEF; cansend vcan1 12345678#; cansend vcan0 123#R3
cansend vcan0 123##1112233; cansend vcan0 7FF##0; cansend vcan0 123#1122334455667788_E
cansend vcan0 2000000C#0108000000000F10; cansend vcan0 20000080#0000000000000000
cansend vcan0 20000008#00000A1900000000; cansend vcan0 123#414243
cansend vcan1 1F334455##3112233445566778899; cansend vcan0 000#00
";

/// Every form of output the VM's candump has (it predates `-N` and `-8`), byte for byte.
#[test]
fn dump_prints_what_candump_prints() {
    let forms = [
        "",
        "-L",
        "-ta",
        "-tA",
        "-a",
        "-e",
        "-td",
        "-tz",
        "-i",
        "-S",
        "-a -S",
        "-i -S -a",
        "-c",
        "-c -c",
        "-c -c -c -ta",
        "-x",
        "-L -x",
        "-ta -H",
        "-s 1",
        "-d",
        "-r 65536",
        "-D",
    ];
    let mut script = String::new();
    for (i, form) in forms.iter().enumerate() {
        script += &format!(
            "candump {form} vcan0,0:0,#FFFFFFFF vcan1 > c{i}.txt & P=\"$P $!\"\n$B dump {form} vcan0,0:0,#FFFFFFFF vcan1 > b{i}.txt & P=\"$P $!\"\n"
        );
    }
    let dbc = common::corpus("cantools/tests__files__dbc__motohawk.dbc");
    script += &format!("$B dump --dbc {dbc} vcan0 > decoded.txt & P=\"$P $!\"\n");
    // Every reader is listening once it has printed a warm-up frame; the marker after that is
    // the first frame all of them see, and the comparison starts behind it.
    script += "for i in $(seq 50); do cansend vcan0 7FE#00; cansend vcan1 7FE#00; sleep 0.2; \
               ready=1; for f in c*.txt b*.txt decoded.txt; do [ -s $f ] || ready=0; done; \
               [ $ready = 1 ] && break; done\ncansend vcan0 7FD#00\n";
    script += TRAFFIC;
    script += "cansend vcan0 1F0#A5B6D90000000000\n";
    script += "sleep 0.5\nkill -INT $P; sleep 0.5\n";
    for (i, form) in forms.iter().enumerate() {
        script += &format!(
            "echo '== candump {form}'; cat c{i}.txt; echo; echo '== bywire {form}'; cat b{i}.txt; echo\n"
        );
    }
    script += "echo '== decoded'; cat decoded.txt; echo '== end'\n";
    let out = in_vm_with(&script, &[&dbc]);
    for form in forms {
        if form == "-s 1" {
            // A spinning character a frame, each followed by a backspace: the same cycle
            // (how many turns depends on when each started listening).
            for who in ["candump", "bywire"] {
                let spun = section(&out, &format!("{who} {form}")).trim_end_matches('\n');
                let turns: Vec<char> = spun.chars().collect();
                assert!(turns.len() >= 24, "{who} -s 1: {spun:?}");
                for (k, pair) in turns.chunks(2).enumerate() {
                    assert_eq!(
                        pair,
                        [['|', '/', '-', '\\'][k % 4], '\x08'],
                        "{who}: {spun:?}"
                    );
                }
            }
            continue;
        }
        let theirs = after_marker(section(&out, &format!("candump {form}")));
        let ours = after_marker(section(&out, &format!("bywire {form}")));
        assert!(
            theirs.lines().count() >= 12,
            "candump {form} printed:\n{theirs}"
        );
        if form == "-td" || form == "-tz" {
            // Delta and zero-based times depend on when each program read the frame.
            let strip = |t: &str| -> Vec<String> {
                t.lines()
                    .map(|l| l.split_once(") ").map_or(l, |(_, r)| r).to_string())
                    .collect()
            };
            assert_eq!(strip(ours), strip(theirs), "dump {form}");
            // (SSS.UUUUUU): at least three digits of seconds, six of microseconds.
            assert!(
                ours.lines()
                    .filter(|l| !l.is_empty())
                    .all(|l| l.starts_with(" (")
                        && l.find('.')
                            .is_some_and(|d| d >= 5 && l[d + 7..].starts_with(") "))),
                "{ours}"
            );
        } else {
            assert_eq!(ours, theirs, "dump {form}");
        }
    }
    // With --dbc the signals follow their frame, as cantools shows them (in its order: by
    // start bit in network order).
    let decoded = after_marker(section(&out, "decoded"));
    assert!(
        decoded.contains("  vcan0  1F0   [8]  A5 B6 D9 00 00 00 00 00\n      ExampleMessage(\n          Enable: Enabled,\n          AverageRadius: 1.8 m,\n          Temperature: 244.14 degK\n      )\n"),
        "{decoded}"
    );
    // The words for error frames are there (-e).
    assert!(after_marker(section(&out, "bywire -e")).contains(
        "\tprotocol-violation{{frame-format-error,tx-dominant-bit-error}{acknowledge-slot}}"
    ));
}

/// `-D`: an interface that goes down and comes back is read on (said on stderr); without it
/// the dump ends with an error, as candump's.
#[test]
fn dump_goes_on_over_an_interface_that_went_down_with_minus_d() {
    let script = "\
$B dump -D vcan0 > on.txt 2> on.err & P1=$!
$B dump vcan0 > off.txt 2> off.err & P2=$!
ready on.txt vcan0; ready off.txt vcan0
ip link set vcan0 down
for i in $(seq 50); do grep -q 'going on' on.err && break; sleep 0.1; done
ip link set vcan0 up
cansend vcan0 321#01
for i in $(seq 50); do grep -q ' 321 ' on.txt && break; sleep 0.1; done
wait $P2; echo \"without exit $?\"
kill -INT $P1; wait $P1; echo \"with exit $?\"
echo '== on'; cat on.txt; cat on.err; echo '== off'; cat off.err; echo '== end'
";
    let out = in_vm(script);
    assert!(out.contains("with exit 0"), "{out}");
    assert!(out.contains("without exit 1"), "{out}");
    let on = section(&out, "on");
    assert!(
        on.contains("vcan0  321   [1]  01") && on.contains("going on: -D"),
        "{out}"
    );
    assert!(section(&out, "off").contains("bus 'vcan0'"), "{out}");
}

#[test]
fn send_sends_what_cansend_sends() {
    let frames = [
        "123#DEADBEEF",
        "1ABCDEF0#1122",
        "123#R4",
        "123#r",
        "123##1112233",
        "123##2",
        "7FF#DE.AD.BE.EF",
        "000#",
        "1FFFFFFF##3000102030405060708090A0B0C0D0E0F101112131415161718191A1B1C1D1E1F",
        "123#1122334455667788",
    ];
    let mut script = "candump -L vcan0 > sent.log & P=$!\nready sent.log vcan0\n".to_string();
    for f in frames {
        script += &format!("cansend vcan0 '{f}'; $B send vcan0 '{f}'\n");
    }
    script += "sleep 0.3\nkill -INT $P\nsleep 0.2\necho '== sent'\ncat sent.log\n";
    let out = in_vm(&script);
    let lines: Vec<&str> = section(&out, "sent")
        .lines()
        .map(|l| l.split_whitespace().nth(2).unwrap())
        .filter(|f| *f != "7FE#00")
        .collect();
    assert_eq!(lines.len(), 2 * frames.len(), "{out}");
    for pair in lines.chunks(2) {
        assert_eq!(pair[0], pair[1], "cansend vs bywire send");
    }
}

#[test]
fn logs_replay_both_ways() {
    let script = "\
candump -L vcan0 > theirs.log & P1=$!
ready theirs.log vcan0
cangen vcan0 -n 30 -g 1 -m; cangen vcan0 -n 10 -g 1 -e -R; cangen vcan0 -n 10 -g 2 -f -b
sleep 0.3; kill -INT $P1; sleep 0.2
candump -L vcan1 > ours_played.log & P2=$!
ready ours_played.log vcan1
$B play -I theirs.log vcan1=vcan0
sleep 0.3; kill -INT $P2; sleep 0.2
$B dump -f ours.log vcan0 & P3=$!
ready ours.log vcan0
cangen vcan0 -n 30 -g 1 -m; cangen vcan0 -n 10 -g 1 -f
sleep 0.5; kill -INT $P3; sleep 0.5
candump -L vcan1 > canplayer_played.log & P4=$!
ready canplayer_played.log vcan1
canplayer -I ours.log vcan1=vcan0
sleep 0.3; kill -INT $P4; sleep 0.2
echo '== theirs'; cat theirs.log; echo '== ours_played'; cat ours_played.log
echo '== ours'; cat ours.log; echo '== canplayer_played'; cat canplayer_played.log; echo '== end'
";
    let out = in_vm(script);
    let frames = |name: &str| -> Vec<String> {
        section(&out, name)
            .lines()
            .filter(|l| l.starts_with('('))
            .map(|l| l.split_whitespace().nth(2).unwrap().to_string())
            .filter(|f| f != "7FE#00")
            .collect()
    };
    let theirs = frames("theirs");
    assert!(theirs.len() >= 40, "{out}");
    assert_eq!(
        frames("ours_played"),
        theirs,
        "bywire play of a candump log"
    );
    let ours = frames("ours");
    assert!(ours.len() >= 30, "{out}");
    assert_eq!(
        frames("canplayer_played"),
        ours,
        "canplayer of a bywire dump log"
    );
    // Our log lines are candump's: (secs.usecs) vcan0 frame.
    for line in section(&out, "ours").lines() {
        let r = bywire_log::candump::parse_line(line).unwrap();
        assert_eq!(r.interface, "vcan0");
    }
}

#[test]
fn busload_agrees_with_canbusload() {
    // Classic data frames only: canbusload reads classic frames, and counts a remote frame's
    // DLC as data bits it does not have on the wire (checked separately below).
    let script = "\
candump -L vcan0 > traffic.log & P0=$!
ready traffic.log vcan0
cangen vcan0 -n 40 -g 1; cangen vcan0 -n 30 -g 1 -e
cangen vcan0 -n 20 -g 1 -L 8 -D 0000000000000000; cangen vcan0 -n 20 -g 1 -L 8 -D FFFFFFFFFFFFFFFF -e
sleep 0.3; kill -INT $P0; sleep 0.2
printf '(0.000000) vcan0 123#R8\\n(0.001000) vcan0 00000456#R2\\n' > remote.log
# Each meter listens once it has printed a report; it has counted a replay once its frames
# add up to the log's (then one report more shows nothing after it). 10 s at most each.
reports() { awk 'NF==5' $1 | wc -l; }
counted() { awk 'NF==5 {f+=$2} END {print f+0}' $1; }
listening() { for i in $(seq 100); do [ $(reports c.txt) -ge 1 ] && [ $(reports b.txt) -ge 1 ] && return; sleep 0.1; done; }
replayed() { for i in $(seq 100); do [ $(counted c.txt) -ge $1 ] && [ $(counted b.txt) -ge $1 ] && return; sleep 0.1; done; }
for log in traffic remote; do for m in -e -i x; do
  flag=$m; [ $m = x ] && flag=
  canbusload $flag vcan0@500000 > c.txt & P1=$!
  $B busload $flag vcan0@500000 > b.txt 2> b.err & P2=$!
  listening; canplayer -I $log.log
  replayed $(grep -c '^(' $log.log); sleep 1.2
  kill $P1; kill -INT $P2; sleep 0.3
  echo \"== $log $m\"; awk 'NF==5 {f+=$2; b+=$3; p+=$4} END {print f, b, p}' c.txt b.txt
  awk 'NF==5 {f+=$2; b+=$3; p+=$4} END {print f, b, p}' b.txt
  cat b.err
done; done
echo '== end'
";
    let out = in_vm(script);
    let totals = |name: &str| -> (Vec<u64>, Vec<u64>) {
        let s = section(&out, name);
        let mut lines = s.lines().map(|l| {
            l.split_whitespace()
                .map(|n| n.parse::<u64>().unwrap())
                .collect::<Vec<u64>>()
        });
        let both = lines.next().unwrap();
        let ours = lines.next().unwrap();
        // The first awk summed both files: theirs = both - ours.
        (both.iter().zip(&ours).map(|(b, o)| b - o).collect(), ours)
    };
    for mode in ["-e", "-i"] {
        let (theirs, ours) = totals(&format!("traffic {mode}"));
        assert!(theirs[0] >= 100, "{out}");
        assert_eq!(
            ours, theirs,
            "frames, bits, payload bits with {mode}: {out}"
        );
    }
    // Worst case: canbusload uses a closed-form bound on the stuff bits; ours is the true
    // maximum over every identifier and payload of each format and DLC, never above it.
    let (theirs, ours) = totals("traffic x");
    assert_eq!((ours[0], ours[2]), (theirs[0], theirs[2]));
    assert!(
        ours[1] <= theirs[1] && theirs[1] - ours[1] < theirs[1] / 50,
        "{ours:?} vs {theirs:?}"
    );
    // Remote frames: canbusload adds 8 data bits per DLC unit (10 here) that are not sent.
    let (theirs, ours) = totals("remote -i");
    assert_eq!(ours[0], theirs[0]);
    assert_eq!(theirs[1] - ours[1], 8 * 10, "{out}");
    assert_eq!(ours[2], 0);
}

/// Frames the receive queue dropped while the meter could not read (stopped, as a starved
/// process is) are said on stderr at the end, beside the figures that leave them out. (The
/// kernel tells a socket its drops with the next frame it queues: one is sent after the flood.)
#[test]
fn busload_says_what_the_receive_queue_dropped() {
    let script = "\
$B busload -i vcan0@500000 > b.txt 2> b.err & P=$!
for i in $(seq 100); do [ -s b.txt ] && break; sleep 0.1; done
kill -STOP $P
cangen vcan0 -n 3000 -g 0 -i -L 8
kill -CONT $P
sleep 0.5; cansend vcan0 7FF#00
sleep 1.5; kill -INT $P; wait $P
echo \"== counted $(awk 'NF==5 {f+=$2} END {print f+0}' b.txt)\"
echo '== err'; cat b.err; echo '== end'
";
    let out = in_vm(script);
    let counted: u64 = out
        .split("== counted ")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{out}"));
    let said = section(&out, "err");
    let dropped: u64 = said
        .strip_prefix("vcan0: ")
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{out}"));
    assert!(
        said.contains("frames dropped before they reached the meter"),
        "{out}"
    );
    assert!(counted > 0 && dropped > 0, "{out}");
    assert!(counted + dropped <= 3001, "{out}");
}

/// `bywire sim --attach`: the simulated drives' bus on vcan0, as candump sees it (every drive's
/// heartbeat, SYNC), and a frame cansend puts on vcan1 lands on the simulated sensor bus — sent
/// once the SYNC shows the simulation running (a loaded machine's VM can take seconds to start
/// it).
#[test]
fn sim_attaches_its_buses_to_vcan_for_can_utils() {
    let script = "\
candump -L vcan0 > drives.log & P1=$!
ready drives.log vcan0
$B sim --no-view --max-seconds 4 --out /tmp/run --attach bus2=vcan0 --attach bus3=vcan1 > sim.out 2>&1 & S=$!
for i in $(seq 100); do grep -q ' vcan0 080#' drives.log && break; sleep 0.1; done
cansend vcan1 7AB#01020304
wait $S; echo \"sim exit $?\"
kill -INT $P1; sleep 0.2
echo '== drives'; cat drives.log; echo '== bus3'; grep 7AB /tmp/run/bus3.log
echo '== sim'; cat sim.out; echo '== end'
";
    let out = in_vm(script);
    assert!(out.contains("sim exit 0"), "{out}");
    let drives = section(&out, "drives");
    for node in ["711", "712", "713", "714", "721", "722", "723", "724"] {
        assert!(
            drives.contains(&format!(" vcan0 {node}#05")),
            "heartbeat of 0x{node} (operational): {drives}"
        );
    }
    assert!(drives.contains(" vcan0 080#"), "SYNC: {drives}");
    assert!(
        section(&out, "bus3").contains(" bus3 7AB#01020304"),
        "the frame from cansend on the simulated bus 3: {out}"
    );
}
