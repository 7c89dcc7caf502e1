//! The redundant tug's messages: its profile's degradation report the same bytes through the
//! generated structs as through the profile, read back by both; the two ECUs' status and the
//! comparison of their setpoints.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use bywire_core::node::Port;
use bywire_core::{Frame, Id};
use bywire_tug::duplex::TugDuplexWire;
use bywire_tug::ecu::{BUS1, BUS2};
use bywire_tug::wire::ReferenceWire;
use bywire_vehicle::arbitration::{DuplexWire, OutReason, Role, Side};
use bywire_vehicle::command::{DegradationLevel, FaultClass};
use bywire_vehicle::wire::{AdsWire, DegradationReport, Feedback, ProfileWire, VehicleWire};

#[test]
fn both_wires_make_and_read_the_same_degradation_report() {
    let loaded = bywire_tug::redundant_profile().unwrap();
    assert!(loaded.supervisor_config().degradation.is_some());
    let mut by_role = ProfileWire::new(&loaded).unwrap();
    for &level in DegradationLevel::ALL {
        for reason in std::iter::once(None).chain(FaultClass::ALL.iter().copied().map(Some)) {
            let report = DegradationReport { level, reason };
            for counter in [0, 7, 15] {
                let generated = ReferenceWire.degradation_frame(&report, counter).unwrap();
                let profiled = by_role.degradation_frame(&report, counter).unwrap();
                assert_eq!(generated, profiled, "{report:?} {counter}");
                assert_eq!(
                    ReferenceWire.feedback(&generated),
                    Feedback::Degradation(report)
                );
                assert_eq!(by_role.feedback(&generated), Feedback::Degradation(report));
            }
        }
    }
    // The plain tug's profile has no report: its vehicle sends none.
    let plain = bywire_tug::profile().unwrap();
    assert!(plain.supervisor_config().degradation.is_none());
    assert_eq!(
        bywire_tug::builtin("reference-tug-redundant")
            .unwrap()
            .profile
            .name,
        "reference-tug-redundant"
    );
}

#[test]
fn a_report_with_a_corrupt_crc_or_an_unknown_reason_is_not_read() {
    let report = DegradationReport {
        level: DegradationLevel::MinimalRisk,
        reason: Some(FaultClass::ControlTakeover),
    };
    let frame = ReferenceWire.degradation_frame(&report, 3).unwrap();
    let mut bytes: [u8; 8] = frame.data().try_into().unwrap();
    bytes[7] ^= 1;
    let corrupt = Frame::classic(frame.id().unwrap(), &bytes).unwrap();
    assert_eq!(ReferenceWire.feedback(&corrupt), Feedback::Corrupt);
    let mut m = bywire_tug::messages::VehicleToAdsDegradation::default();
    m.set_degradation_reason_raw(7);
    let unknown =
        bywire_tug::messages::sealed_frame(bywire_tug::messages::VehicleToAdsDegradation::ID, m.0);
    assert_eq!(ReferenceWire.feedback(&unknown), Feedback::Corrupt);
}

#[test]
fn each_ecu_reads_the_others_status_and_not_its_own() {
    let mut wire = TugDuplexWire::default();
    for role in [
        Role::Active,
        Role::Standby,
        Role::Out(OutReason::SelfTest),
        Role::Out(OutReason::Fenced),
        Role::Out(OutReason::Deaf),
    ] {
        let from_a = wire.status_frame(Side::A, role, 5).unwrap();
        assert_eq!(wire.partner_status(Side::B, &from_a), Some(role));
        assert_eq!(wire.partner_status(Side::A, &from_a), None);
        let from_b = wire.status_frame(Side::B, role, 5).unwrap();
        assert_eq!(wire.partner_status(Side::A, &from_b), Some(role));
    }
    assert_eq!(wire.status_port(), BUS1);
}

#[test]
fn setpoints_agree_within_the_tolerance_and_other_frames_are_not_compared() {
    let wire = TugDuplexWire::default();
    let rpdo2 = |node: u32, position: i32, velocity: i32| {
        let mut data = [0u8; 8];
        data[..4].copy_from_slice(&position.to_le_bytes());
        data[4..].copy_from_slice(&velocity.to_le_bytes());
        Frame::classic(Id::standard(0x300 + node).unwrap(), &data).unwrap()
    };
    let units = bywire_tug::ecu::STEERING_UNITS_PER_DEG;
    let steer = |deg: f64| rpdo2(0x11, bywire_core::num::round_to_i32(deg * units), 0);
    assert_eq!(wire.agree(BUS2, &steer(10.0), &steer(10.5)), Some(true));
    assert_eq!(wire.agree(BUS2, &steer(10.0), &steer(12.0)), Some(false));
    let speed = |v: f64| {
        rpdo2(
            0x21,
            0,
            bywire_core::num::round_to_i32(v * bywire_tug::ecu::DRIVE_UNITS_PER_M),
        )
    };
    assert_eq!(wire.agree(BUS2, &speed(2.0), &speed(2.05)), Some(true));
    assert_eq!(wire.agree(BUS2, &speed(2.0), &speed(2.5)), Some(false));
    // SYNC, a heartbeat, or anything on bus 1: not compared.
    let sync = Frame::classic(Id::standard(0x080).unwrap(), &[]).unwrap();
    assert_eq!(wire.agree(BUS2, &sync, &sync), None);
    assert_eq!(wire.agree(Port(0), &steer(10.0), &steer(30.0)), None);
}

#[test]
fn the_profile_declares_a_backup_valve_at_each_corner_and_a_wrong_pairing_is_refused() {
    let loaded = bywire_tug::redundant_profile().unwrap();
    let pairs = bywire_tug::backup_steering::pairs_of(&loaded)
        .unwrap()
        .unwrap();
    assert_eq!(
        pairs.map(|p| (p.primary, p.backup)),
        [(0x11, 0x31), (0x12, 0x32), (0x13, 0x33), (0x14, 0x34)]
    );
    assert_eq!(
        pairs[0].check.heartbeat_timeout,
        std::time::Duration::from_millis(60)
    );
    // The plain tug declares none.
    let plain = bywire_tug::profile().unwrap();
    assert_eq!(bywire_tug::backup_steering::pairs_of(&plain).unwrap(), None);
    // A corner judged by another corner's angle is not the tug's pairing.
    let text = format!(
        "{}\n{}",
        bywire_tug::PROFILE,
        bywire_tug::REDUNDANCY.replacen(
            "measured = { voted = \"angle-fr\" }",
            "measured = { voted = \"angle-rr\" }",
            1
        )
    );
    let crossed = bywire_vehicle::profile::Profile::parse("crossed", &text, |_| {
        Ok(bywire_tug::messages::DBC.to_string())
    })
    .unwrap();
    let err = bywire_tug::backup_steering::pairs_of(&crossed).unwrap_err();
    assert!(err.starts_with("fail_operational.actuators[1]:"), "{err}");
}

/// Two ECUs given the same sensor frames at the same instants latch the same channel out at
/// the same instant, however often each is polled besides (an A/B pair's halves are polled
/// for different frames of their own): a latch that followed the polls would set the halves'
/// setpoints apart and make the standby take over from a healthy ECU.
/// Verifies: REQ-VOT-2.
#[test]
fn the_voted_angles_latch_on_the_readings_not_on_the_polls() {
    use bywire_core::node::Node;
    use bywire_core::Timestamp;
    use bywire_tug::ecu::{Geometry, VehicleControlEcu, BUS3};
    use bywire_tug::messages::{self, SteeringAngleSensors, SteeringAnglesB, SteeringAnglesC};
    use bywire_vehicle::fail_operational::VotedRoles;

    let loaded = bywire_tug::redundant_profile().unwrap();
    let voted: [_; 4] = loaded
        .profile
        .fail_operational
        .as_ref()
        .unwrap()
        .voted
        .iter()
        .map(VotedRoles::config)
        .collect::<Vec<_>>()
        .try_into()
        .unwrap();
    let tolerance = voted[1].tolerance;
    let ecu = || {
        let geometry = Geometry {
            wheelbase: 2.0,
            track: 1.2,
        };
        VehicleControlEcu::new(loaded.supervisor_config(), geometry).with_voted_angles(voted)
    };
    // A cheap, fixed noise in thousandths: each run sees the same readings.
    let mut state = 0x2545_F491_u32;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state % 1000
    };
    let mut checked = 0;
    for extra_poll_us in [3, 7, 11, 29] {
        let (mut quiet, mut busy) = (ecu(), ecu());
        let mut frames = Vec::new();
        // Every 10 ms the three modules' frames; module B's front-right reading creeps
        // across the tolerance, noisily.
        for cycle in 0..150u64 {
            let base = cycle * 10_000 + 3_000;
            let drift = tolerance * (0.5 + f64::from(u32::try_from(cycle).unwrap()) / 100.0);
            let mut a = SteeringAngleSensors::default();
            let mut b = SteeringAnglesB::default();
            let mut c = SteeringAnglesC::default();
            // Every other reading at zero: the two healthy channels agree exactly.
            let _ = (a.set_second_angle_fr(0.0), c.set_angle_fr(0.0));
            let _ = b.set_angle_fr(drift + (f64::from(noise()) / 1000.0 - 0.5) * tolerance);
            let mut at = base;
            for frame in [
                messages::sealed_frame(SteeringAngleSensors::ID, a.0),
                messages::sealed_frame(SteeringAnglesB::ID, b.0),
                messages::sealed_frame(SteeringAnglesC::ID, c.0),
            ] {
                // Up to 80 µs later as stuffing and arbitration fall.
                at += 120 + u64::from(noise()) * 80 / 1000;
                frames.push((Timestamp::from_micros(at), frame));
            }
        }
        let end = Timestamp::from_millis(1_510);
        let drive = |ecu: &mut VehicleControlEcu, extra: Option<u64>| {
            let mut next_extra = extra.map(Timestamp::from_micros);
            let mut pending = frames.iter().peekable();
            let mut now = Timestamp::ZERO;
            // Bounded: every step moves time forward to the next frame, deadline or extra poll.
            for _ in 0..2_000_000 {
                let next_frame = pending.peek().map(|(t, _)| *t);
                let Some(next) = [next_frame, ecu.next_deadline(), next_extra]
                    .into_iter()
                    .flatten()
                    .min()
                else {
                    break;
                };
                if next > end {
                    break;
                }
                now = next.max(now);
                while let Some((_, frame)) = pending.next_if(|(t, _)| *t <= now) {
                    ecu.on_frame(now, BUS3, frame);
                }
                if next_extra.is_some_and(|t| t <= now) {
                    next_extra =
                        extra.map(|us| now.saturating_add(core::time::Duration::from_micros(us)));
                }
                ecu.poll(now, &mut |_, _| {});
            }
            ecu.supervisor().degradation().first()
        };
        let latched_quiet = drive(&mut quiet, None);
        let latched_busy = drive(&mut busy, Some(extra_poll_us));
        let latched = latched_quiet.expect("the drifting channel is never voted out");
        // Front right (corner 1), module B (channel 1): source 1 × 3 + 1.
        assert_eq!(
            (latched.class, latched.source),
            (FaultClass::SensorChannelOut, 4),
            "{latched:?}"
        );
        assert_eq!(
            latched_busy,
            Some(latched),
            "polled every {extra_poll_us} µs besides"
        );
        checked += 1;
    }
    assert_eq!(checked, 4);
}
