//! Vehicles driven by role through the runtime codec ([`ProfileWire`]):
//! - for the reference tug it makes the same bytes as the generated structs, and reads
//!   feedback the same way (a differential test of two implementations);
//! - for a vehicle with another layout (profiles/shuttle: big-endian setpoints, 8-bit
//!   counters, XOR checksums, its own enum numbering) cantools decodes what the ADS side sends
//!   as the profile says, and the ADS side validates what cantools encodes.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use bywire_tug::wire::ReferenceWire;
use common::vehicles;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Id, Timestamp};
use bywire_tug::messages::{
    self, AdsToVehicleControl, ControlMode, EmergencyBrake, EmergencyStop, Gear, SteeringMode,
    VehicleToAdsSensors, VehicleToAdsState,
};
use bywire_vehicle::ads::{Ads, AdsCommand, AdsConfig};
use bywire_vehicle::command::{EstopCode, TurnIndicators, WatchdogLevel};
use bywire_vehicle::profile::Profile;
use bywire_vehicle::wire::{
    AdsWire, Counters, Feedback, Incoming, ProfileWire, StateReport, VehicleWire,
};
use proptest::prelude::*;

fn shuttle() -> bywire_vehicle::profile::LoadedProfile {
    Profile::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("profiles/shuttle.toml")).unwrap()
}

fn command_strategy() -> impl Strategy<Value = AdsCommand> {
    (
        -50.0f64..50.0,
        -6.0f64..9.0,
        0.0f64..110.0,
        0usize..4,
        0usize..4,
        0usize..3,
        any::<bool>(),
        any::<bool>(),
    )
        .prop_map(
            |(steering, velocity, brake, gear, mode, steering_mode, engage, operator_reset)| {
                AdsCommand {
                    steering,
                    velocity,
                    brake,
                    gear: [Gear::Park, Gear::Reverse, Gear::Neutral, Gear::Drive][gear],
                    mode: [
                        ControlMode::Manual,
                        ControlMode::Autonomous,
                        ControlMode::Estop,
                        ControlMode::Calibration,
                    ][mode],
                    steering_mode: [SteeringMode::Normal, SteeringMode::Crab, SteeringMode::Tank]
                        [steering_mode],
                    engage,
                    operator_reset,
                    ..AdsCommand::default()
                }
            },
        )
}

/// A profile with an `[estop]` message has an E-stop frame to send; one without has none.
#[test]
fn an_estop_frame_only_where_the_profile_has_the_message() {
    let mut tug = ProfileWire::new(&bywire_tug::profile().unwrap()).unwrap();
    assert!(tug.has_estop());
    assert!(tug.estop_frame(true, 0).is_some());
    let mut shuttle = ProfileWire::new(&shuttle()).unwrap();
    assert!(!shuttle.has_estop());
    assert_eq!(shuttle.estop_frame(true, 0), None);
}

/// The command's identifier is the command's; the wheel angles go out where a profile has them.
#[test]
fn the_command_is_known_by_its_identifier_and_the_wheel_angles_are_sent() {
    let loaded = bywire_tug::profile().unwrap();
    let mut tug = ProfileWire::new(&loaded).unwrap();
    assert!(tug.is_command(Id::standard(0x100).unwrap()));
    assert!(!tug.is_command(Id::standard(0x101).unwrap()));
    let frame = tug.wheel_angles_frame([1.0, -2.0, 3.0, -4.0], 3).unwrap();
    assert_eq!(
        frame,
        ReferenceWire
            .wheel_angles_frame([1.0, -2.0, 3.0, -4.0], 3)
            .unwrap()
    );
}

proptest! {

#[test]
    fn for_the_reference_tug_both_wires_make_the_same_bytes(command in command_strategy(), counter in 0u64..16, decel in 0.0f64..30.0) {
        let loaded = bywire_tug::profile().unwrap();
        let mut by_role = ProfileWire::new(&loaded).unwrap();
        let mut generated = ReferenceWire;
        prop_assert_eq!(by_role.command_frame(&command, counter), generated.command_frame(&command, counter));
        prop_assert_eq!(by_role.emergency_brake_frame(decel, counter), generated.emergency_brake_frame(decel, counter));
        prop_assert_eq!(by_role.command_counter_bits(), generated.command_counter_bits());
    }

    #[test]
    fn for_the_reference_tug_both_wires_send_the_same_wheel_speeds(speeds in any::<[i16; 4]>(), counter in 0u64..16) {
        let loaded = bywire_tug::profile().unwrap();
        let mut by_role = ProfileWire::new(&loaded).unwrap();
        // Both well inside and beyond the signals' ±20.48 m/s.
        let speeds = speeds.map(|s| f64::from(s) / 1000.0);
        prop_assert_eq!(by_role.wheel_speeds_frame(speeds, counter), ReferenceWire.wheel_speeds_frame(speeds, counter));
    }

    #[test]
    fn for_the_reference_tug_both_wires_read_feedback_alike(payload in any::<[u8; 8]>(), which in 0usize..3, seal in any::<bool>()) {
        let loaded = bywire_tug::profile().unwrap();
        let mut by_role = ProfileWire::new(&loaded).unwrap();
        let mut generated = ReferenceWire;
        let id = [VehicleToAdsState::ID, VehicleToAdsSensors::ID, 0x123][which];
        let frame = if seal { messages::sealed_frame(id, payload) } else { Frame::classic(Id::standard(id).unwrap(), &payload).unwrap() };
        prop_assert_eq!(by_role.feedback(&frame), generated.feedback(&frame));
    }
}

proptest! {
    #[test]
    fn for_the_reference_tug_both_wires_read_commands_alike(payload in any::<[u8; 8]>(), which in 0usize..4, seal in any::<bool>()) {
        let loaded = bywire_tug::profile().unwrap();
        let mut by_role = ProfileWire::new(&loaded).unwrap();
        let mut generated = ReferenceWire;
        let id = [AdsToVehicleControl::ID, EmergencyStop::ID, EmergencyBrake::ID, 0x123][which];
        let frame = if seal { messages::sealed_frame(id, payload) } else { Frame::classic(Id::standard(id).unwrap(), &payload).unwrap() };
        prop_assert_eq!(by_role.incoming(&frame), generated.incoming(&frame));
    }

    #[test]
    fn for_the_reference_tug_both_wires_write_the_same_state(
        steering in -60.0f64..60.0, velocity in -8.0f64..8.0, mode in 0u64..4, steering_mode in 0usize..3, gear in 0u64..4,
        watchdog_level in 0u64..5, estop_state in 0u64..8, flags in 0u8..8, echo in 0u64..16, counter in 0u64..16,
    ) {
        let loaded = bywire_tug::profile().unwrap();
        let mut by_role = ProfileWire::new(&loaded).unwrap();
        let report = StateReport {
            steering,
            velocity,
            mode: ControlMode::from_raw(mode).unwrap(),
            steering_mode: [SteeringMode::Normal, SteeringMode::Crab, SteeringMode::Tank][steering_mode],
            gear: Gear::from_raw(gear).unwrap(),
            watchdog_level: WatchdogLevel::from_raw(watchdog_level).unwrap(),
            estop_state: EstopCode::from_raw(estop_state).unwrap(),
            warning: flags & 1 != 0,
            driver_override: flags & 2 != 0,
            steering_enabled: flags & 4 != 0,
            // The tug's state message has no lights: both wires leave them out.
            turn_indicators: TurnIndicators::Left,
            hazard_lights: true,
            heartbeat_echo: echo,
        };
        prop_assert_eq!(VehicleWire::state_frame(&mut by_role, &report, counter), VehicleWire::state_frame(&mut ReferenceWire, &report, counter));
    }
}

/// cantools, given `dbc` (relative to the crate), decodes `lines` ("ID HEX") into JSON objects, or
/// encodes `{"id": .., "signals": {..}}` lines into "ID HEX".
fn cantools(dbc: &str, script: &str, input: &str) -> Vec<String> {
    let dbc = Path::new(env!("CARGO_MANIFEST_DIR")).join(dbc);
    let mut child = Command::new("python3")
        .args(["-c", script])
        .arg(&dbc)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    use std::io::Write;
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "cantools failed (installed by scripts/install-test-deps.sh)"
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

const DECODE: &str = r#"
import sys, json, cantools
from functools import reduce
db = cantools.database.load_file(sys.argv[1])
for line in sys.stdin:
    frame_id, data = line.split()
    data = bytes.fromhex(data)
    decoded = db.decode_message(int(frame_id), data, decode_choices=False)
    decoded["xor_ok"] = reduce(lambda a, b: a ^ b, data[:7], 0) == data[7]
    print(json.dumps({k: (float(v) if not isinstance(v, bool) else v) for k, v in decoded.items()}))
"#;

fn field(line: &str, name: &str) -> f64 {
    let key = format!("\"{name}\": ");
    let rest = &line[line
        .find(&key)
        .unwrap_or_else(|| panic!("{name} in {line}"))
        + key.len()..];
    let value = rest.split([',', '}']).next().unwrap().trim();
    match value {
        "true" => 1.0,
        "false" => 0.0,
        v => v.parse().unwrap(),
    }
}

#[test]
fn the_shuttles_commands_are_what_cantools_reads_by_role() {
    let loaded = shuttle();
    let wire = ProfileWire::new(&loaded).unwrap();
    let mut ads = Ads::with_wire(
        AdsConfig {
            cycle: Duration::from_millis(50),
            ..AdsConfig::default()
        },
        wire,
    );
    let commands = [
        AdsCommand {
            steering: 12.34,
            velocity: 3.5,
            brake: 0.0,
            gear: Gear::Drive,
            mode: ControlMode::Autonomous,
            steering_mode: SteeringMode::Crab,
            engage: true,
            operator_reset: false,
            ..AdsCommand::default()
        },
        AdsCommand {
            steering: -29.5,
            velocity: 0.25,
            brake: 40.0,
            gear: Gear::Park,
            mode: ControlMode::Calibration,
            steering_mode: SteeringMode::Tank,
            engage: false,
            operator_reset: true,
            ..AdsCommand::default()
        },
        // Beyond the DBC's ranges: not sent at all (never sent as another value; the vehicle's
        // watchdog counts the missed cycle).
        AdsCommand {
            steering: 45.0,
            velocity: 20.0,
            brake: 150.0,
            gear: Gear::Reverse,
            mode: ControlMode::Estop,
            steering_mode: SteeringMode::Normal,
            engage: false,
            operator_reset: false,
            ..AdsCommand::default()
        },
    ];
    let mut lines = String::new();
    let mut sent = Vec::new();
    // 300 cycles: the 8-bit counter wraps.
    for k in 0..300u64 {
        let now = Timestamp::from_millis(50 * k);
        let command = commands[usize::try_from(k % 3).unwrap()];
        ads.set_command(now, command);
        ads.poll(now, &mut |port, f| {
            if port == Port::MAIN {
                lines.push_str(&format!(
                    "{} {}\n",
                    f.id().unwrap().as_raw(),
                    f.data()
                        .iter()
                        .map(|b| format!("{b:02x}"))
                        .collect::<String>()
                ));
                sent.push((k, command));
            }
        });
    }
    // Each third command cannot be carried: 200 frames.
    assert_eq!(sent.len(), 200);
    assert!(sent.iter().all(|(k, _)| k % 3 != 2));
    let decoded = cantools("profiles/shuttle.dbc", DECODE, &lines);
    let gear = |g: Gear| match g {
        Gear::Park => 4.0,
        Gear::Reverse => 2.0,
        Gear::Neutral => 0.0,
        Gear::Drive => 1.0,
    };
    let mode = |m: ControlMode| match m {
        ControlMode::Manual => 0.0,
        ControlMode::Autonomous => 2.0,
        ControlMode::Estop => 3.0,
        ControlMode::Calibration => 1.0,
    };
    let steering_mode = |m: SteeringMode| match m {
        SteeringMode::Normal => 0.0,
        SteeringMode::Crab => 2.0,
        SteeringMode::Tank => 1.0,
    };
    for (line, (k, c)) in decoded.iter().zip(&sent) {
        assert!(
            (field(line, "Cmd_Steer") - c.steering).abs() < 0.006,
            "{line}"
        );
        assert!(
            (field(line, "Cmd_Speed") - c.velocity).abs() < 0.0006,
            "{line}"
        );
        assert_eq!(field(line, "Cmd_Brake"), c.brake.round(), "{line}");
        assert_eq!(field(line, "Cmd_Gear"), gear(c.gear), "{line}");
        assert_eq!(field(line, "Cmd_Mode"), mode(c.mode), "{line}");
        assert_eq!(
            field(line, "Cmd_SteerMode"),
            steering_mode(c.steering_mode),
            "{line}"
        );
        assert_eq!(field(line, "Cmd_Engage"), f64::from(u8::from(c.engage)));
        assert_eq!(
            field(line, "Cmd_Reset"),
            f64::from(u8::from(c.operator_reset))
        );
        assert_eq!(
            field(line, "Cmd_Alive"),
            (k % 256) as f64,
            "the 8-bit counter"
        );
        assert_eq!(field(line, "xor_ok"), 1.0, "{line}");
    }
    // The emergency brake on the shuttle's own message.
    ads.emergency_brake(Timestamp::from_millis(20_000), 2.5);
    let mut brake = String::new();
    ads.poll(Timestamp::from_millis(20_000), &mut |port, f| {
        if port == Port::MAIN && f.id().unwrap().as_raw() == 1279 {
            brake = format!(
                "1279 {}\n",
                f.data()
                    .iter()
                    .map(|b| format!("{b:02x}"))
                    .collect::<String>()
            );
        }
    });
    let line = &cantools("profiles/shuttle.dbc", DECODE, &brake)[0];
    assert_eq!(
        (
            field(line, "EB_Request"),
            field(line, "EB_Decel"),
            field(line, "xor_ok")
        ),
        (1.0, 2.5, 1.0)
    );
}

const ENCODE: &str = r#"
import sys, json, cantools
from functools import reduce
db = cantools.database.load_file(sys.argv[1])
for line in sys.stdin:
    request = json.loads(line)
    message = db.get_message_by_frame_id(request["id"])
    data = bytearray(message.encode(request["signals"], scaling=True, strict=False))
    if request.get("seal", True):
        data[7] = reduce(lambda a, b: a ^ b, data[:7], 0)
    print(request["id"], data.hex())
"#;

#[test]
fn the_shuttles_feedback_from_cantools_is_validated_by_role() {
    let loaded = shuttle();
    let mut ads = Ads::with_wire(
        AdsConfig {
            cycle: Duration::from_millis(50),
            ..AdsConfig::default()
        },
        ProfileWire::new(&loaded).unwrap(),
    );
    // Three commands sent (counters 0, 1, 2) so the echo has something to match.
    for k in 0..3u64 {
        let now = Timestamp::from_millis(50 * k);
        ads.set_command(
            now,
            AdsCommand {
                velocity: 2.0,
                gear: Gear::Drive,
                mode: ControlMode::Autonomous,
                ..AdsCommand::default()
            },
        );
        ads.poll(now, &mut |_, _| {});
    }
    let requests = [
        r#"{"id": 1281, "signals": {"St_Steer": -7.5, "St_Speed": 1.95, "St_Mode": 2, "St_SteerMode": 2, "St_Echo": 2, "St_Alive": 200, "St_Xor": 0}}"#,
        r#"{"id": 1282, "signals": {"W_FL": 1.9, "W_FR": 2.0, "W_RL": 1.95, "W_RR": 2.05, "Wheels_Counter": 7, "Checksum": 0}}"#,
        r#"{"id": 1281, "signals": {"St_Steer": 1.0, "St_Speed": 1.0, "St_Mode": 2, "St_SteerMode": 0, "St_Echo": 2, "St_Alive": 201, "St_Xor": 0}, "seal": false}"#,
        r#"{"id": 1281, "signals": {"St_Steer": 1.0, "St_Speed": 1.0, "St_Mode": 2, "St_SteerMode": 0, "St_Echo": 2, "St_Alive": 201, "St_Xor": 0}}"#,
        r#"{"id": 1281, "signals": {"St_Steer": 1.0, "St_Speed": 1.0, "St_Mode": 2, "St_SteerMode": 0, "St_Echo": 200, "St_Alive": 202, "St_Xor": 0}}"#,
    ];
    let frames: Vec<Frame> = cantools(
        "profiles/shuttle.dbc",
        ENCODE,
        &(requests.join("\n") + "\n"),
    )
    .iter()
    .map(|line| {
        let (id, hex) = line.split_once(' ').unwrap();
        let bytes: Vec<u8> = (0..hex.len() / 2)
            .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap())
            .collect();
        Frame::classic(Id::standard(id.parse().unwrap()).unwrap(), &bytes).unwrap()
    })
    .collect();
    let now = Timestamp::from_millis(120);
    ads.on_frame(now, Port::MAIN, &frames[0]);
    let state = *ads.state();
    assert_eq!(state.steering.value, Some(-7.5));
    assert_eq!(state.velocity.value, Some(1.95));
    assert_eq!(
        state.mode.value,
        Some(ControlMode::Autonomous),
        "raw 2 is Autonomous on the shuttle"
    );
    assert_eq!(
        state.watchdog_level.value, None,
        "the shuttle does not report it"
    );
    ads.on_frame(now, Port::MAIN, &frames[1]);
    let speeds = ads.state().wheel_speeds.value.unwrap();
    for (got, want) in speeds.iter().zip([1.9, 2.0, 1.95, 2.05]) {
        assert!((got - want).abs() < 1e-9, "{speeds:?}");
    }
    ads.on_frame(now, Port::MAIN, &frames[2]);
    assert_eq!(ads.stats().checksum, 1, "a wrong XOR is refused");
    ads.on_frame(now, Port::MAIN, &frames[3]);
    assert_eq!(
        ads.state().steering.value,
        Some(1.0),
        "201 follows 200 on the 8-bit counter"
    );
    ads.on_frame(now, Port::MAIN, &frames[4]);
    assert_eq!(ads.stats().echo, 1, "echo 200 matches no recent command");
    // Its values used all the same: the vehicle's own report.
    assert_eq!(ads.stats().accepted, 4);
}

#[test]
fn profile_wires_refuse_profiles_they_cannot_speak() {
    let loaded = shuttle();
    let mut broken = loaded.clone();
    broken
        .profile
        .enums
        .get_mut("gear")
        .unwrap()
        .remove("Drive");
    let error = ProfileWire::new(&broken).unwrap_err().to_string();
    assert_eq!(
        error,
        "shuttle: enums.gear.Drive: missing: every value needs its raw number"
    );
    let mut no_state = loaded;
    no_state.profile.state = None;
    assert!(ProfileWire::new(&no_state)
        .unwrap_err()
        .to_string()
        .contains("state: a vehicle interface needs [state]"));
}

/// The shuttle's ADS side and vehicle side, both by profile, on a bit-timed 500 kbit/s bus:
/// engaged, driven past an 8-bit counter wrap, then the ADS falls silent and the watchdog
/// cascade brakes.
#[test]
fn the_shuttle_runs_closed_loop_by_profile_on_the_bit_timed_bus() {
    use bywire_net::network::Network;
    use bywire_vehicle::supervisor::{Supervisor, Watchdog};
    let loaded = shuttle();
    let mut net = Network::new();
    let bus = net.add_bus("bus", 500_000, None);
    let ads = net.add_node(Ads::with_wire(
        loaded.ads_config(),
        ProfileWire::new(&loaded).unwrap(),
    ));
    let vcu = net.add_node(Supervisor::with_wire(
        loaded.supervisor_config(),
        ProfileWire::new(&loaded).unwrap(),
    ));
    net.wire(ads, Port::MAIN, bus).unwrap();
    net.wire(vcu, Port::MAIN, bus).unwrap();
    let drive = AdsCommand {
        velocity: 2.0,
        steering: 5.0,
        gear: Gear::Drive,
        mode: ControlMode::Autonomous,
        steering_mode: SteeringMode::Crab,
        ..AdsCommand::default()
    };
    // A millisecond at a time on the network runner: the ADS's command set before, the
    // vehicle's speed following the actuators after (braking stops it).
    for t in 1..=20_000u64 {
        let before = Timestamp::from_millis(t - 1);
        if t == 19_000 {
            net.drop_output(ads, true); // the ADS falls silent
        }
        let engage = (500..600).contains(&t);
        let command = AdsCommand { engage, ..drive };
        net.node_mut(ads).unwrap().set_command(before, command);
        net.run_for(Duration::from_millis(1));
        let now = Timestamp::from_millis(t);
        let a = net.node(vcu).unwrap().actuators(now);
        let speed = common::plant_speed(&a);
        net.node_mut(vcu).unwrap().set_feedback(speed, a.steering);
        let (ads, vcu) = (net.node(ads).unwrap(), net.node(vcu).unwrap());
        if t == 18_000 {
            // 360 command cycles of 50 ms: the 8-bit counters have wrapped.
            assert_eq!(vcu.mode(), ControlMode::Autonomous);
            assert_eq!(vcu.watchdog(), Watchdog::Normal);
            assert_eq!(vcu.stats().rejected(), 0, "{:?}", vcu.stats());
            assert_eq!(a.velocity, 2.0);
            assert_eq!(a.steering_mode, SteeringMode::Crab);
            let state = ads.state();
            assert_eq!(state.mode.value, Some(ControlMode::Autonomous));
            assert_eq!(state.velocity.value, Some(2.0));
            assert_eq!(
                state.watchdog_level.value, None,
                "the shuttle's status has no watchdog signal"
            );
            assert!(
                ads.stats().accepted > 300 && ads.stats().echo == 0 && ads.stats().counter == 0,
                "{:?}",
                ads.stats()
            );
        }
    }
    // A second of silence: well past the cascade's cycles, full braking.
    let vcu = net.node(vcu).unwrap();
    assert_eq!(vcu.watchdog(), Watchdog::FullBraking);
    assert_eq!(vcu.actuators(Timestamp::from_millis(20_000)).brake, 100.0);
}

#[test]
fn short_and_remote_command_frames_are_malformed_on_both_wires() {
    use bywire_core::frame::Dlc;
    use bywire_vehicle::wire::{Incoming, Rejected};
    let loaded = bywire_tug::profile().unwrap();
    let mut by_role = ProfileWire::new(&loaded).unwrap();
    let id = Id::standard(AdsToVehicleControl::ID).unwrap();
    for frame in [
        Frame::classic(id, &[0; 4]).unwrap(),
        Frame::remote(id, Dlc::from_nibble(8)),
        Frame::classic(id, &[]).unwrap(),
    ] {
        let expected = Incoming::Command(Err(Rejected::Malformed));
        assert_eq!(by_role.incoming(&frame), expected, "{frame:?}");
        assert_eq!(ReferenceWire.incoming(&frame), expected, "{frame:?}");
    }
}

#[test]
fn state_frames_count_through_the_whole_counter() {
    use bywire_vehicle::supervisor::{Supervisor, SupervisorConfig};
    for by_role in [false, true] {
        let mut counters = Vec::new();
        // The state frame as bus A carries it (the supervisor is not redundant here).
        let mut take = |port: Port, f: Frame| {
            if port == Port::MAIN && f.id().unwrap().as_raw() == VehicleToAdsState::ID {
                counters.push(f.data()[6] >> 4);
            }
        };
        if by_role {
            let loaded = bywire_tug::profile().unwrap();
            let mut vcu = Supervisor::with_wire(
                SupervisorConfig::default(),
                ProfileWire::new(&loaded).unwrap(),
            );
            for t in 0..400 {
                vcu.poll(Timestamp::from_millis(t), &mut take);
            }
        } else {
            let mut vcu = Supervisor::with_wire(SupervisorConfig::default(), ReferenceWire);
            for t in 0..400 {
                vcu.poll(Timestamp::from_millis(t), &mut take);
            }
        }
        assert_eq!(counters.len(), 20);
        assert!(
            counters
                .iter()
                .zip(counters.iter().skip(1))
                .all(|(a, b)| (a + 1) % 16 == *b),
            "{counters:?}"
        );
        assert_eq!(
            counters.iter().max(),
            Some(&15),
            "the 4-bit counter wraps at 16: {counters:?}"
        );
    }
}

#[test]
fn wheel_speed_counters_are_checked_at_their_width() {
    let loaded = bywire_tug::profile().unwrap();
    for by_role in [false, true] {
        let frames: Vec<Frame> = [0u64, 1, 4, 5]
            .iter()
            .map(|counter| {
                let mut m = VehicleToAdsSensors::default();
                m.set_counter_raw(*counter);
                messages::sealed_frame(VehicleToAdsSensors::ID, m.0)
            })
            .collect();
        let stats = if by_role {
            let mut ads = Ads::with_wire(AdsConfig::default(), ProfileWire::new(&loaded).unwrap());
            frames
                .iter()
                .for_each(|f| ads.on_frame(Timestamp::from_millis(1), Port::MAIN, f));
            ads.stats()
        } else {
            let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
            frames
                .iter()
                .for_each(|f| ads.on_frame(Timestamp::from_millis(1), Port::MAIN, f));
            ads.stats()
        };
        // 0, 1 in sequence; 1 → 4 skips two (a 4-bit counter sees it, a 1-bit one would not);
        // 5 follows 4 again.
        assert_eq!(
            (stats.accepted, stats.counter),
            (3, 1),
            "by role: {by_role}: {stats:?}"
        );
    }
}

/// A wheel-speed message without a counter (profiles may leave it out): every frame is taken
/// on one bus, and on two buses each frame once, the other bus's copy skipped. Every frame
/// but one a feedback timeout was refused as a repeated counter before.
#[test]
fn wheel_speeds_without_a_counter_are_taken_every_frame() {
    let loaded = vehicles::shuttle_with(|dbc| {
        dbc.lines()
            .filter(|line| !line.contains("SG_ Wheels_Counter"))
            .map(|line| format!("{line}\n"))
            .collect()
    });
    let mut vehicle = ProfileWire::new(&loaded).unwrap();
    assert_eq!(vehicle.wheel_counter_bits(), 0);
    for redundant in [false, true] {
        let config = AdsConfig {
            redundant,
            ..loaded.ads_config()
        };
        let mut ads = Ads::with_wire(config, ProfileWire::new(&loaded).unwrap());
        let ports = if redundant {
            vec![Ads::<ProfileWire>::PORT_A, Ads::<ProfileWire>::PORT_B]
        } else {
            vec![Ads::<ProfileWire>::PORT_A]
        };
        for k in 0..40u32 {
            let speed = f64::from(k) / 10.0;
            let frame = vehicle.wheel_speeds_frame([speed; 4], 0).unwrap();
            for port in &ports {
                let at = Timestamp::from_millis(u64::from(k) * 50 + 3 * u64::from(port.0));
                bywire_core::node::Node::on_frame(&mut ads, at, *port, &frame);
            }
        }
        let stats = ads.stats();
        assert_eq!((stats.accepted, stats.counter), (40, 0), "{stats:?}");
        assert_eq!(ads.state().wheel_speeds.value, Some([3.9; 4]));
    }
}

/// "ID HEX", as the cantools scripts read a frame.
fn id_and_hex(frame: &Frame) -> String {
    let hex: String = frame.data().iter().map(|b| format!("{b:02x}")).collect();
    format!("{} {hex}\n", frame.id().unwrap().as_raw())
}

/// A vehicle driving on in autonomous mode with `turn` and `hazard` lights.
fn lit_report(turn: TurnIndicators, hazard: bool, echo: u64) -> StateReport {
    StateReport {
        steering: 0.0,
        velocity: 1.0,
        mode: ControlMode::Autonomous,
        steering_mode: SteeringMode::Normal,
        gear: Gear::Drive,
        watchdog_level: WatchdogLevel::Normal,
        estop_state: EstopCode::Normal,
        warning: false,
        driver_override: false,
        steering_enabled: true,
        turn_indicators: turn,
        hazard_lights: hazard,
        heartbeat_echo: echo,
    }
}

/// A profile with lights (tests/data/tug-with-lights): its command carries the turn
/// indicators in the profile's own numbering (right 1, left 2) and the hazard lights as
/// cantools reads them, its state reports them, and both read back by role.
#[test]
fn lights_go_out_in_the_profiles_numbering_and_read_back() {
    let loaded = Profile::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/tug-with-lights.toml"),
    )
    .unwrap();
    let mut wire = ProfileWire::new(&loaded).unwrap();
    let numbered = |t: TurnIndicators| match t {
        TurnIndicators::Off => 0.0,
        TurnIndicators::Right => 1.0,
        TurnIndicators::Left => 2.0,
    };
    let cases = [
        (TurnIndicators::Off, false),
        (TurnIndicators::Left, false),
        (TurnIndicators::Right, true),
        (TurnIndicators::Off, true),
    ];
    let mut lines = String::new();
    for (counter, (turn, hazard)) in (0u64..).zip(cases) {
        let command = AdsCommand {
            velocity: 1.0,
            gear: Gear::Drive,
            mode: ControlMode::Autonomous,
            turn_indicators: turn,
            hazard_lights: hazard,
            ..AdsCommand::default()
        };
        let frame = AdsWire::command_frame(&mut wire, &command, counter).unwrap();
        let Incoming::Command(Ok((Some(read), _))) = VehicleWire::incoming(&mut wire, &frame)
        else {
            panic!("{frame:?}");
        };
        assert_eq!((read.turn_indicators, read.hazard_lights), (turn, hazard));
        let report = lit_report(turn, hazard, counter);
        let state = VehicleWire::state_frame(&mut wire, &report, counter).unwrap();
        let Feedback::State(feedback) = AdsWire::feedback(&mut wire, &state) else {
            panic!("{state:?}");
        };
        assert_eq!(
            (feedback.turn_indicators, feedback.hazard_lights),
            (Some(turn), Some(hazard))
        );
        lines.push_str(&id_and_hex(&frame));
        lines.push_str(&id_and_hex(&state));
    }
    let decoded = cantools("tests/data/tug-with-lights.dbc", DECODE, &lines);
    assert_eq!(decoded.len(), 2 * cases.len());
    for (pair, (turn, hazard)) in decoded.chunks(2).zip(cases) {
        let on = f64::from(u8::from(hazard));
        assert_eq!(
            field(&pair[0], "TurnIndicatorsCmd"),
            numbered(turn),
            "{pair:?}"
        );
        assert_eq!(field(&pair[0], "HazardLightsCmd"), on, "{pair:?}");
        assert_eq!(
            field(&pair[1], "TurnIndicators"),
            numbered(turn),
            "{pair:?}"
        );
        assert_eq!(field(&pair[1], "HazardLights"), on, "{pair:?}");
    }
    // The reference tug has no lights: its feedback reports none.
    let mut tug = ProfileWire::new(&bywire_tug::profile().unwrap()).unwrap();
    let report = lit_report(TurnIndicators::Left, true, 0);
    let state = VehicleWire::state_frame(&mut tug, &report, 0).unwrap();
    let Feedback::State(feedback) = AdsWire::feedback(&mut tug, &state) else {
        panic!("{state:?}");
    };
    assert_eq!(
        (feedback.turn_indicators, feedback.hazard_lights),
        (None, None)
    );
}

/// The vehicle side of a profile with lights: never commanded (full braking), its hazard
/// lights are on; commanded, its lights are as commanded.
#[test]
fn the_vehicle_shows_its_hazard_lights_while_it_stops_on_its_own() {
    use bywire_vehicle::supervisor::Supervisor;
    let loaded = Profile::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/tug-with-lights.toml"),
    )
    .unwrap();
    let mut vehicle = Supervisor::with_wire(
        loaded.supervisor_config(),
        ProfileWire::new(&loaded).unwrap(),
    );
    let mut ads = ProfileWire::new(&loaded).unwrap();
    let command = AdsCommand {
        velocity: 1.0,
        gear: Gear::Drive,
        mode: ControlMode::Autonomous,
        turn_indicators: TurnIndicators::Left,
        ..AdsCommand::default()
    };
    let mut shown = Vec::new();
    for k in 0..40u64 {
        let now = Timestamp::from_millis(20 * k);
        // Commands from 200 ms on.
        if k >= 10 {
            let frame = ads.command_frame(&command, k % 16).unwrap();
            Node::on_frame(&mut vehicle, now, Supervisor::<ProfileWire>::PORT_A, &frame);
        }
        let mut sent = Vec::new();
        Node::poll(&mut vehicle, now, &mut |_, frame| sent.push(frame));
        for frame in sent {
            if let Feedback::State(s) = ads.feedback(&frame) {
                shown.push((k, s.hazard_lights, s.turn_indicators));
            }
        }
    }
    let before: Vec<_> = shown.iter().filter(|(k, ..)| *k < 10).collect();
    assert!(!before.is_empty(), "{shown:?}");
    assert!(
        before
            .iter()
            .all(|(_, hazard, turn)| *hazard == Some(true) && *turn == Some(TurnIndicators::Off)),
        "{shown:?}"
    );
    let last = shown.last().unwrap();
    assert_eq!(
        (last.1, last.2),
        (Some(false), Some(TurnIndicators::Left)),
        "{shown:?}"
    );
}
