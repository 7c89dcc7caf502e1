//! The ADS side's details, call by call: schedules and deadlines, the burst's counters and
//! gaps, each feedback check and its counter, and the response-time trigger.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use bywire_core::node::{Node, Port};
use bywire_tug::messages::{
    ControlMode, EmergencyBrake, Gear, SteeringMode, VehicleToAdsSensors, VehicleToAdsState,
    VehicleToAdsWheelAngles,
};
use bywire_tug::wire::ReferenceWire;
use bywire_vehicle::ads::{Ads, AdsCommand, AdsConfig};
use common::{ms, sealed};

fn drive(steering: f64) -> AdsCommand {
    AdsCommand {
        steering,
        velocity: 1.0,
        gear: Gear::Drive,
        mode: ControlMode::Autonomous,
        engage: true,
        operator_reset: true,
        ..AdsCommand::default()
    }
}

/// A state frame with `counter`, echoing `echo`, edited by `edit`.
fn state(counter: u64, echo: u64, edit: impl FnOnce(&mut VehicleToAdsState)) -> bywire_core::Frame {
    let mut m = VehicleToAdsState::default();
    m.set_control_mode_raw(1);
    m.set_counter_raw(counter);
    m.set_heartbeat_echo_raw(echo);
    edit(&mut m);
    sealed(VehicleToAdsState::ID, m.0)
}

/// An ADS that has sent commands 0..n (one per 20 ms from 0).
fn sent(n: u64) -> Ads<ReferenceWire> {
    let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
    ads.set_command(ms(0), drive(0.0));
    for t in 0..n {
        ads.poll(ms(20 * t), &mut |_, _| {});
    }
    ads
}

#[test]
fn a_stale_command_drops_its_requests() {
    let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
    ads.set_command(ms(0), drive(0.0));
    let fresh = ads.effective_command(ms(0)).unwrap();
    assert!(fresh.engage && fresh.operator_reset);
    let stale = ads.effective_command(ms(500)).unwrap();
    assert!(!stale.engage && !stale.operator_reset);
}

#[test]
fn deadlines_and_a_late_poll() {
    let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
    assert_eq!(ads.next_deadline(), None);
    ads.set_command(ms(5), drive(0.0));
    assert_eq!(ads.next_deadline(), Some(ms(5)));
    ads.poll(ms(5), &mut |_, _| {});
    assert_eq!(ads.next_deadline(), Some(ms(25)));
    // Polled 100 ms late: one frame, and the schedule restarts from now.
    let mut n = 0;
    ads.poll(ms(125), &mut |_, _| n += 1);
    assert_eq!(n, 1);
    assert_eq!(ads.next_deadline(), Some(ms(145)));
    ads.emergency_brake(ms(130), 3.0);
    assert_eq!(ads.next_deadline(), Some(ms(130)));
}

#[test]
fn the_burst_counts_and_spaces_its_frames() {
    let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
    ads.emergency_brake(ms(0), 3.0);
    let mut frames = Vec::new();
    for t in 0..1000 {
        ads.poll(ms(t), &mut |port, f| {
            if port == Port::MAIN {
                frames.push((t, f))
            }
        });
    }
    let counters: Vec<u64> = frames
        .iter()
        .map(|(_, f)| EmergencyBrake(f.data().try_into().unwrap()).counter_raw())
        .collect();
    assert_eq!(
        &counters[..18],
        &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 0, 1]
    );
    let times: Vec<u64> = frames.iter().map(|(t, _)| *t).collect();
    assert_eq!(&times[..5], &[0, 4, 8, 58, 108]);
}

#[test]
fn each_feedback_check_counts() {
    let mut ads = sent(6); // commands 0..=5 sent; the echo window holds 5, 4, 3
    ads.on_frame(ms(101), Port::MAIN, &state(0, 5, |_| {}));
    assert_eq!(ads.stats().accepted, 1);
    // Out of range: steering, velocity, watchdog level.
    ads.on_frame(
        ms(102),
        Port::MAIN,
        &state(1, 5, |m| m.set_steering_angle_actual_raw(460)),
    );
    ads.on_frame(
        ms(103),
        Port::MAIN,
        &state(2, 5, |m| m.set_velocity_actual_raw(900)),
    );
    ads.on_frame(
        ms(104),
        Port::MAIN,
        &state(3, 5, |m| m.set_watchdog_level_raw(5)),
    );
    assert_eq!(ads.stats().range, 3);
    // Exactly 45° is still in range.
    ads.on_frame(
        ms(104),
        Port::MAIN,
        &state(4, 5, |m| m.set_steering_angle_actual_raw(450)),
    );
    assert_eq!((ads.stats().range, ads.stats().accepted), (3, 2));
    // An echo of a command sent, but too long ago: counted; what the vehicle reports of
    // itself is used all the same, its echo is not.
    let echoed = ads.state().echo_latency;
    ads.on_frame(
        ms(105),
        Port::MAIN,
        &state(5, 1, |m| m.set_steering_angle_actual_raw(123)),
    );
    assert_eq!((ads.stats().echo, ads.stats().accepted), (1, 3));
    assert_eq!(ads.state().steering.value, Some(12.3));
    assert_eq!(ads.state().echo_latency, echoed);
    // The oldest in the window is still fine.
    ads.on_frame(ms(106), Port::MAIN, &state(6, 3, |_| {}));
    assert_eq!(ads.stats().accepted, 4);
    // Flags come through.
    ads.on_frame(
        ms(107),
        Port::MAIN,
        &state(7, 5, |m| {
            m.set_warning_flag_raw(1);
            m.set_driver_override_raw(1);
            m.set_gear_raw(1);
            m.set_steering_mode_raw(2);
        }),
    );
    let s = ads.state();
    assert_eq!(
        (s.warning.value, s.driver_override.value),
        (Some(true), Some(true))
    );
    assert_eq!(
        (s.gear.value, s.steering_mode.value),
        (Some(Gear::Reverse), Some(SteeringMode::Tank))
    );
    ads.on_frame(ms(108), Port::MAIN, &state(8, 5, |_| {}));
    let s = ads.state();
    assert_eq!(
        (s.warning.value, s.driver_override.value),
        (Some(false), Some(false))
    );
}

#[test]
fn wheel_frames_count_and_check_their_counters() {
    let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
    let angles = |c| {
        sealed(VehicleToAdsWheelAngles::ID, {
            let mut m = VehicleToAdsWheelAngles::default();
            m.set_counter_raw(c);
            m.0
        })
    };
    let speeds = |c| {
        sealed(VehicleToAdsSensors::ID, {
            let mut m = VehicleToAdsSensors::default();
            m.set_counter_raw(c);
            m.0
        })
    };
    ads.on_frame(ms(0), Port::MAIN, &angles(0));
    ads.on_frame(ms(0), Port::MAIN, &speeds(0));
    assert_eq!(ads.stats().accepted, 2);
    ads.on_frame(ms(20), Port::MAIN, &angles(0));
    ads.on_frame(ms(20), Port::MAIN, &speeds(5));
    assert_eq!((ads.stats().counter, ads.stats().accepted), (2, 2));
    ads.on_frame(ms(40), Port::MAIN, &angles(1));
    ads.on_frame(ms(40), Port::MAIN, &speeds(6));
    assert_eq!((ads.stats().counter, ads.stats().accepted), (2, 4));
}

#[test]
fn a_change_within_the_tolerance_is_not_a_new_setpoint() {
    let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
    ads.set_command(ms(0), drive(0.0));
    ads.poll(ms(0), &mut |_, _| {});
    ads.on_frame(ms(10), Port::MAIN, &state(0, 0, |_| {}));
    let first = ads.state().steering_response;
    assert_eq!(first.value, Some(std::time::Duration::from_millis(10)));
    // 0.5° is the tolerance: not a new setpoint, so no new measurement.
    ads.set_command(ms(20), drive(0.5));
    ads.poll(ms(20), &mut |_, _| {});
    ads.on_frame(ms(30), Port::MAIN, &state(1, 1, |_| {}));
    assert_eq!(ads.state().steering_response, first);
    // 0.6° is.
    ads.set_command(ms(40), drive(0.6));
    ads.poll(ms(40), &mut |_, _| {});
    ads.on_frame(
        ms(45),
        Port::MAIN,
        &state(2, 2, |m| m.set_steering_angle_actual_raw(6)),
    );
    assert_eq!(
        ads.state().steering_response.value,
        Some(std::time::Duration::from_millis(5))
    );
}

/// Verifies: REQ-SS-1.
#[test]
fn the_safe_stop_brakes_at_once_and_holds_the_steering() {
    let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
    ads.set_command(
        ms(0),
        AdsCommand {
            engage: true,
            ..drive(5.0)
        },
    );
    ads.safe_stop(ms(10), 3.0);
    let c = ads.effective_command(ms(10)).unwrap();
    assert_eq!(
        (c.velocity, c.brake, c.steering, c.engage),
        (0.0, 100.0, 5.0, false)
    );
    let mut frames = Vec::new();
    ads.poll(ms(10), &mut |port, f| {
        if port == Port::MAIN {
            frames.push(f)
        }
    });
    // The emergency-brake frame goes first, then the stop command.
    let ids: Vec<u32> = frames
        .iter()
        .filter_map(|f| f.id())
        .map(|i| i.as_raw())
        .collect();
    assert_eq!(ids.first(), Some(&EmergencyBrake::ID), "{ids:x?}");
}
