//! The Autoware CAN output: hand-computed bytes, all-or-nothing refusal, the decoder, the
//! output modes, and cantools decoding our frames with the shipped DBC.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::io::Write;
use std::process::{Command, Stdio};

use bywire_core::Frame;
use bywire_vehicle::autoware::{
    encode, Control, Decoder, Limits, Output, OutputMode, Refused, Status, DBC,
};

fn control() -> Control {
    Control {
        steering_tire_angle: 0.1,
        steering_tire_rotation_rate: -0.5,
        velocity: 2.5,
        acceleration: -1.25,
    }
}

fn status() -> Status {
    Status {
        mode: 1,
        validity: 0x03,
        sequence: 0x1234,
        timestamp_ms: 0x0102_0304,
    }
}

#[test]
fn frames_match_hand_computed_bytes() {
    let frames = encode(&control(), &status(), &Limits::default()).unwrap();
    let text: Vec<String> = frames.iter().map(Frame::to_string).collect();
    assert_eq!(
        text,
        [
            "100#A0860100E05EF8FF",
            "101#C40900001EFBFFFF",
            "102#0103341204030201"
        ]
    );
}

#[test]
fn non_finite_or_out_of_range_sends_nothing() {
    let mut output = Output::new(OutputMode::DdsAndCan, Limits::default());
    let mut frames = Vec::new();
    let mut published = Vec::new();
    for (bad, why) in [
        (
            Control {
                velocity: f64::NAN,
                ..control()
            },
            Refused::NotFinite("velocity"),
        ),
        (
            Control {
                acceleration: f64::INFINITY,
                ..control()
            },
            Refused::NotFinite("acceleration"),
        ),
        (
            Control {
                steering_tire_angle: 1.5,
                ..control()
            },
            Refused::OutOfRange("steering_tire_angle"),
        ),
    ] {
        assert_eq!(
            output.send(&bad, 1, 3, 0, &mut |f| frames.push(f), &mut |c, s| {
                published.push((*c, *s))
            }),
            Err(why)
        );
    }
    assert!(frames.is_empty() && published.is_empty());
    // And the sequence did not advance for refused commands.
    assert_eq!(
        output.send(&control(), 1, 3, 0, &mut |f| frames.push(f), &mut |c, s| {
            published.push((*c, *s))
        }),
        Ok(0)
    );
    assert_eq!((frames.len(), published.len()), (3, 1));
}

#[test]
fn output_modes_select_the_sinks() {
    for (mode, frames_expected, dds_expected) in [
        ("can-only", 6, 0),
        ("dds-only", 0, 2),
        ("dds-and-can", 6, 2),
    ] {
        let mut output = Output::new(mode.parse().unwrap(), Limits::default());
        let mut frames = Vec::new();
        let mut published = Vec::new();
        for _ in 0..2 {
            output
                .send(&control(), 1, 3, 7, &mut |f| frames.push(f), &mut |c, s| {
                    published.push((*c, *s))
                })
                .unwrap();
        }
        assert_eq!(
            (frames.len(), published.len()),
            (frames_expected, dds_expected),
            "{mode}"
        );
        // What DDS gets is the command and the status the frames carry.
        for (i, (c, s)) in published.iter().enumerate() {
            assert_eq!(
                (*c, s.sequence, s.timestamp_ms),
                (control(), u16::try_from(i).unwrap(), 7)
            );
        }
    }
    assert_eq!("dds".parse::<OutputMode>(), Ok(OutputMode::DdsOnly));
    assert_eq!("can".parse::<OutputMode>(), Ok(OutputMode::CanOnly));
    assert!("both"
        .parse::<OutputMode>()
        .unwrap_err()
        .to_string()
        .contains("dds-and-can"));
}

#[test]
fn the_decoder_returns_what_was_encoded() {
    let mut decoder = Decoder::default();
    let frames = encode(&control(), &status(), &Limits::default()).unwrap();
    assert_eq!(decoder.on_frame(&frames[0]), None);
    assert_eq!(decoder.on_frame(&frames[1]), None);
    assert_eq!(decoder.on_frame(&frames[2]), Some((control(), status())));
    // A status frame without the other two completes nothing.
    assert_eq!(decoder.on_frame(&frames[2]), None);
}

#[test]
fn cantools_decodes_our_frames_with_the_shipped_dbc() {
    let dir = std::env::temp_dir().join(format!("bywire-autoware-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("autoware-can.dbc");
    std::fs::write(&path, DBC).unwrap();
    let frames = encode(&control(), &status(), &Limits::default()).unwrap();
    let input: String = frames
        .iter()
        .map(|f| {
            let hex: String = f.data().iter().map(|b| format!("{b:02X}")).collect();
            format!("{} {hex}\n", f.id().unwrap().as_raw())
        })
        .collect();
    let script = r#"
import sys, cantools
db = cantools.database.load_file(sys.argv[1])
for line in sys.stdin:
    i, d = line.split()
    for k, v in sorted(db.decode_message(int(i), bytes.fromhex(d), decode_choices=False).items()):
        print(k, repr(float(v)))
"#;
    let mut child = Command::new("python3")
        .args(["-c", script])
        .arg(&path)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let value = |name: &str| -> f64 {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{name} ")))
            .unwrap()
            .parse()
            .unwrap()
    };
    assert!((value("SteeringTireAngle") - 0.1).abs() < 1e-12);
    assert!((value("SteeringTireRotationRate") + 0.5).abs() < 1e-12);
    assert!((value("Velocity") - 2.5).abs() < 1e-12);
    assert!((value("Acceleration") + 1.25).abs() < 1e-12);
    assert_eq!(value("Mode"), 1.0);
    assert_eq!(value("ValidityFlags"), 3.0);
    assert_eq!(value("Sequence"), f64::from(0x1234));
    assert_eq!(value("TimestampMs"), f64::from(0x0102_0304));
    std::fs::remove_dir_all(&dir).ok();
}

/// Verifies: REQ-SS-2.
#[test]
fn braking_harder_than_the_limit_is_a_stop_at_the_largest_deceleration() {
    let limits = Limits::default();
    for asked in [-10.5, -1e30, f64::NEG_INFINITY] {
        let (stop, saturated) = limits.braking_at_most(Control {
            acceleration: asked,
            ..control()
        });
        assert!(saturated, "{asked}");
        assert_eq!((stop.velocity, stop.acceleration), (0.0, -10.0));
        assert_eq!(stop.steering_tire_angle, control().steering_tire_angle);
    }
    for kept in [-10.0, -1.0, 3.0, f64::NAN] {
        let asked = Control {
            acceleration: kept,
            ..control()
        };
        let (same, saturated) = limits.braking_at_most(asked);
        assert!(!saturated);
        assert_eq!(same.acceleration.to_bits(), kept.to_bits());
    }
}
