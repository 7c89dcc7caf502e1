//! The supervisor's details, call by call without a bus: each state machine's table, every
//! limit at its boundary, the state frame's bits, the deadlines. (Mutation testing showed
//! where the fault matrix alone left behaviour unpinned.)
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Id};
use bywire_tug::messages::{
    AdsToVehicleControl, ControlMode, EmergencyBrake, EmergencyStop, VehicleToAdsState,
};
use bywire_tug::wire::ReferenceWire;
use bywire_vehicle::supervisor::{
    motor_rpm, next_mode, Cascade, CommandStats, EstopInputs, EstopState, ModeInputs, Supervisor,
    SupervisorConfig, Watchdog, WatchdogEvent,
};
use common::{command, ms, sealed};

/// A supervisor driven to autonomous at 2 m/s; returns it, the next counter and the time.
fn engaged() -> (Supervisor<ReferenceWire>, u8, u64) {
    engaged_with(SupervisorConfig::default())
}

fn engaged_with(config: SupervisorConfig) -> (Supervisor<ReferenceWire>, u8, u64) {
    let mut s = Supervisor::with_wire(config, ReferenceWire);
    let mut t = 0;
    for k in 0..12u8 {
        s.on_frame(ms(t), Port::MAIN, &command(k, |_| {}));
        s.poll(ms(t), &mut |_, _| {});
        t += 20;
    }
    s.on_frame(
        ms(t),
        Port::MAIN,
        &command(12, |m| m.set_engage_request_raw(1)),
    );
    s.poll(ms(t), &mut |_, _| {});
    assert_eq!(s.mode(), ControlMode::Autonomous);
    (s, 13, t + 20)
}

fn state_frame(s: &mut Supervisor<ReferenceWire>, now: u64) -> VehicleToAdsState {
    let mut frames = Vec::new();
    // Force the next state frame due: poll well after the last one.
    s.poll(ms(now), &mut |port, f| {
        if port == Port::MAIN {
            frames.push(f)
        }
    });
    let f = frames.last().expect("a state frame is due");
    VehicleToAdsState(f.data().try_into().unwrap())
}

/// Verifies: REQ-TO-1.
#[test]
fn watchdog_table() {
    let c = Cascade::default();
    use Watchdog::*;
    use WatchdogEvent::*;
    assert_eq!(Holding { missed: 2 }.next(Missed(0), c), Normal);
    assert_eq!(Normal.next(Missed(2), c), Holding { missed: 2 });
    assert_eq!(Normal.next(Missed(3), c), Decelerating { missed: 3 });
    assert_eq!(Normal.next(Missed(5), c), FullBraking);
    for state in [
        Normal,
        Holding { missed: 1 },
        Decelerating { missed: 4 },
        Recovering { valid_run: 3 },
    ] {
        assert_eq!(state.next(Disagreement, c), FullBraking);
    }
    assert_eq!(
        Recovering { valid_run: 10 }.next(Valid { engage: true }, c),
        Normal
    );
    assert_eq!(
        Recovering { valid_run: 9 }.next(Valid { engage: true }, c),
        Recovering { valid_run: 10 }
    );
    assert_eq!(
        Recovering { valid_run: 10 }.next(Valid { engage: false }, c),
        Recovering { valid_run: 11 }
    );
    let levels: Vec<u64> = [
        Normal,
        Holding { missed: 1 },
        Decelerating { missed: 3 },
        FullBraking,
        Recovering { valid_run: 1 },
    ]
    .iter()
    .map(|w| w.level().raw())
    .collect();
    assert_eq!(levels, [0, 1, 2, 3, 4]);
}

/// Verifies: REQ-ES-1.
#[test]
fn estop_and_mode_tables() {
    let held = EstopInputs {
        standstill: false,
        ..EstopInputs::default()
    };
    assert_eq!(
        EstopState::BrakesApplied.next(held),
        EstopState::BrakesApplied
    );
    assert_eq!(
        EstopState::BrakesApplied.next(EstopInputs {
            standstill: true,
            ..held
        }),
        EstopState::Stopped
    );
    let inputs = ModeInputs {
        requested: ControlMode::Calibration,
        engage: false,
        driver_input: false,
        estop: false,
        watchdog_normal: true,
        standstill: true,
    };
    assert_eq!(
        next_mode(ControlMode::Calibration, inputs),
        ControlMode::Calibration
    );
    assert_eq!(
        next_mode(
            ControlMode::Calibration,
            ModeInputs {
                requested: ControlMode::Manual,
                ..inputs
            }
        ),
        ControlMode::Manual
    );
    assert_eq!(
        next_mode(
            ControlMode::Manual,
            ModeInputs {
                standstill: false,
                ..inputs
            }
        ),
        ControlMode::Manual,
        "calibration only at standstill"
    );
}

#[test]
fn stats_add_up_and_rpm_needs_a_wheel() {
    let stats = CommandStats {
        accepted: 100,
        malformed: 1,
        checksum: 2,
        repeated: 4,
        skipped: 8,
        out_of_range: 16,
        disagreements: 32,
        authentication: 64,
        // Not a command rejection.
        unauthenticated: 128,
    };
    assert_eq!(stats.rejected(), 127);
    assert_eq!(motor_rpm(1.0, 20.0, 0.0), 0.0);
    assert!((motor_rpm(1.0, 20.0, 0.5) - 2400.0 / std::f64::consts::PI).abs() < 1e-9);
}

/// Verifies: REQ-RNG-1.
#[test]
fn limits_hold_at_their_boundaries() {
    let (mut s, mut k, mut t) = engaged();
    let mut send = |s: &mut Supervisor<ReferenceWire>, edit: &dyn Fn(&mut AdsToVehicleControl)| {
        s.on_frame(ms(t), Port::MAIN, &command(k, edit));
        k = k.wrapping_add(1);
        t += 20;
    };
    // Exactly at the limits: accepted.
    send(&mut s, &|m| m.set_steering_angle_cmd(40.0).unwrap());
    send(&mut s, &|m| m.set_velocity_cmd(5.0).unwrap());
    send(&mut s, &|m| m.set_brake_cmd(100.0).unwrap());
    assert_eq!(s.stats().out_of_range, 0);
    assert_eq!(s.command().unwrap().brake, 100.0);
    // Just past them: refused.
    send(&mut s, &|m| m.set_steering_angle_cmd(-40.1).unwrap());
    send(&mut s, &|m| m.set_velocity_cmd(5.01).unwrap());
    send(&mut s, &|m| m.set_brake_cmd_raw(201)); // 100.5 %
    assert_eq!(s.stats().out_of_range, 3);
}

#[test]
fn extended_frames_with_the_same_numbers_are_ignored() {
    let (mut s, k, t) = engaged();
    let before = s.stats();
    for id in [
        AdsToVehicleControl::ID,
        EmergencyStop::ID,
        EmergencyBrake::ID,
    ] {
        let standard = match id {
            AdsToVehicleControl::ID => command(k, |_| {}),
            EmergencyStop::ID => sealed(EmergencyStop::ID, [1, 0, 0, 0, 0, 0, 0, 0]),
            _ => sealed(EmergencyBrake::ID, [1, 40, 0, 0, 0, 0, 0, 0]),
        };
        let extended = Frame::classic(Id::extended(id).unwrap(), standard.data()).unwrap();
        s.on_frame(ms(t), Port::MAIN, &extended);
    }
    assert_eq!(s.stats(), before);
    assert_eq!(s.estop(), EstopState::Normal);
    assert_eq!(s.actuators(ms(t)).brake, 0.0);
}

/// Verifies: REQ-E2E-2.
#[test]
fn a_restart_after_silence_is_accepted_but_not_the_frozen_value() {
    let (mut s, k, t) = engaged();
    // 200 ms of silence, then the stream restarts at another value: accepted.
    let accepted = s.stats().accepted;
    s.on_frame(ms(t + 200), Port::MAIN, &command(k + 5, |_| {}));
    assert_eq!(s.stats().accepted, accepted + 1);
    // Silence again, then the same value as the last accepted: the sender is frozen.
    s.on_frame(ms(t + 400), Port::MAIN, &command(k + 5, |_| {}));
    assert_eq!(s.stats().repeated, 1);
}

/// Verifies: REQ-TK-1.
#[test]
fn takeover_and_standstill_thresholds_are_inclusive_of_the_driver() {
    let (mut s, _, _) = engaged();
    assert!(!s.driver_input());
    s.set_driver_input(3.0, 0.0);
    assert!(s.driver_input());
    assert_eq!(
        s.mode(),
        ControlMode::Manual,
        "torque at the threshold takes over"
    );
    let (mut s, _, _) = engaged();
    s.set_driver_input(0.0, 0.1);
    assert_eq!(
        s.mode(),
        ControlMode::Manual,
        "pedal at the threshold takes over"
    );
    // Standstill is strictly below 0.05 m/s: at 0.05 the E-stop waits with brakes applied.
    let (mut s, _, t) = engaged();
    s.set_feedback(0.05, 0.0);
    s.on_frame(
        ms(t),
        Port::MAIN,
        &sealed(EmergencyStop::ID, [1, 0, 0, 0, 0, 0, 0, 0]),
    );
    assert_eq!(s.estop(), EstopState::BrakesApplied);
    s.set_feedback(0.0, 0.0);
    s.poll(ms(t + 1), &mut |_, _| {});
    assert_eq!(s.estop(), EstopState::Stopped);
}

#[test]
fn deadlines_follow_the_last_command_and_the_state_frame() {
    let mut s = Supervisor::with_wire(SupervisorConfig::default(), ReferenceWire);
    assert_eq!(s.next_deadline(), Some(ms(0)), "the first state frame");
    s.poll(ms(0), &mut |_, _| {});
    assert_eq!(s.next_deadline(), Some(ms(20)));
    s.on_frame(ms(5), Port::MAIN, &command(0, |_| {}));
    // Missed-cycle tick at 5 + 20 + 10 = 35 ms; the state frame at 20 ms comes first.
    assert_eq!(s.next_deadline(), Some(ms(20)));
    s.poll(ms(20), &mut |_, _| {});
    assert_eq!(s.next_deadline(), Some(ms(35)));
    s.poll(ms(35), &mut |_, _| {});
    assert_eq!(s.next_deadline(), Some(ms(40)));
    s.poll(ms(40), &mut |_, _| {});
    assert_eq!(s.next_deadline(), Some(ms(55)), "the second tick");
}

/// On two buses, a command whose copy came on one bus only waits for its partner until the
/// other bus's last copy is stale: the supervisor asks to be polled then, not later.
#[test]
fn a_copy_waiting_for_its_partner_is_due_when_the_other_bus_goes_stale() {
    use bywire_vehicle::redundancy::Channel;
    use bywire_vehicle::supervisor::Redundancy;
    let cycle = std::time::Duration::from_millis(20);
    let config = SupervisorConfig {
        redundancy: Some(Redundancy::for_cycle(cycle)),
        ..SupervisorConfig::default()
    };
    let mut s = Supervisor::with_wire(config, ReferenceWire);
    let mut t = 0;
    for k in 0..12u8 {
        let frame = command(k, |_| {});
        s.on_frame(ms(t), Channel::A.port(), &frame);
        s.on_frame(ms(t), Channel::B.port(), &frame);
        s.poll(ms(t), &mut |_, _| {});
        t += 20;
    }
    s.on_frame(ms(t), Channel::A.port(), &command(12, |_| {}));
    s.poll(ms(t), &mut |_, _| {});
    // B's last copy came 20 ms ago and counts for the redundancy's 30 ms.
    let b_stale = ms(t + 10).saturating_add(std::time::Duration::from_nanos(1));
    assert_eq!(s.next_deadline(), Some(b_stale));
}

/// A degradation level steers in the modes its limits allow: crab goes on when degraded,
/// and becomes normal steering at the minimal-risk level.
#[test]
fn the_degradation_levels_limits_choose_the_steering_mode() {
    use bywire_vehicle::command::{FaultClass, SteeringMode};
    use bywire_vehicle::degradation::{DegradationPolicy, Fault};
    for (class, expected) in [
        (FaultClass::SensorChannelOut, SteeringMode::Crab),
        (FaultClass::ControlTakeover, SteeringMode::Normal),
    ] {
        let config = SupervisorConfig {
            degradation: Some(DegradationPolicy::default()),
            ..SupervisorConfig::default()
        };
        let (mut s, k, t) = engaged_with(config);
        s.on_frame(
            ms(t),
            Port::MAIN,
            &command(k, |m| m.set_steering_mode_cmd_raw(SteeringMode::Crab.raw())),
        );
        assert_eq!(s.actuators(ms(t)).steering_mode, SteeringMode::Crab);
        s.report_fault(Fault {
            class,
            source: 1,
            at: ms(t),
        });
        assert_eq!(s.actuators(ms(t)).steering_mode, expected, "{class:?}");
    }
}

/// A campaign's proof that a cell would notice the safe state missing: switched off, the
/// commands lost leave the last one in force; switched on, the same loss brakes.
#[test]
fn with_the_safe_state_switched_off_the_last_command_goes_on() {
    use bywire_vehicle::mechanism::Mechanism;
    let off = SupervisorConfig {
        disabled: [Mechanism::SafeState].into_iter().collect(),
        ..SupervisorConfig::default()
    };
    for (config, keeps_driving) in [(SupervisorConfig::default(), false), (off, true)] {
        let (mut s, _, t) = engaged_with(config);
        let driving = s.actuators(ms(t));
        assert!(
            driving.motors_enabled && driving.velocity > 0.0,
            "{driving:?}"
        );
        let later = t + 500;
        s.poll(ms(later), &mut |_, _| {});
        assert_eq!(s.watchdog(), Watchdog::FullBraking);
        let a = s.actuators(ms(later));
        assert_eq!(
            (
                a.motors_enabled,
                a.velocity == driving.velocity,
                a.motor_rpm == driving.motor_rpm && a.motor_rpm > 0.0,
                a.brake == 0.0
            ),
            (keeps_driving, keeps_driving, keeps_driving, keeps_driving),
            "{a:?}"
        );
    }
}

#[test]
fn controlled_deceleration_keeps_falling_across_cycles() {
    let (mut s, _, t) = engaged();
    // Last command at t - 20; poll through missed cycles 3 and 4.
    let last = t - 20;
    let mut samples = Vec::new();
    for now in (last..last + 100).step_by(5) {
        s.poll(ms(now), &mut |_, _| {});
        if matches!(s.watchdog(), Watchdog::Decelerating { .. }) {
            samples.push(s.actuators(ms(now)).velocity);
        }
    }
    assert!(samples.len() > 4);
    assert!(samples.windows(2).all(|w| w[1] < w[0]), "{samples:?}");
}

#[test]
fn steering_moves_at_its_rate_towards_the_command() {
    let (mut s, mut k, mut t) = engaged();
    for _ in 0..5 {
        s.on_frame(
            ms(t),
            Port::MAIN,
            &command(k, |m| m.set_steering_angle_cmd(10.0).unwrap()),
        );
        s.poll(ms(t), &mut |_, _| {});
        k += 1;
        t += 20;
    }
    // 30°/s: 0.6° for each of the five 20 ms polls that saw 10°.
    let a = s.actuators(ms(t - 20));
    assert!((a.steering - 3.0).abs() < 1e-9, "{}", a.steering);
    assert!(a.steering_enabled && a.ads_in_control);
}

#[test]
fn actuators_in_each_situation() {
    // Full braking while autonomous: the ADS is still the one in control.
    let (mut s, _, t) = engaged();
    s.poll(ms(t + 200), &mut |_, _| {});
    let a = s.actuators(ms(t + 200));
    assert_eq!(s.watchdog(), Watchdog::FullBraking);
    assert!(a.ads_in_control && a.brake == 100.0);
    // E-stop: not the ADS.
    let (mut s, _, t) = engaged();
    s.on_frame(
        ms(t),
        Port::MAIN,
        &sealed(EmergencyStop::ID, [1, 0, 0, 0, 0, 0, 0, 0]),
    );
    assert!(!s.actuators(ms(t)).ads_in_control);
    // Manual with a normal watchdog: no warning; at start (full braking): warning.
    let (mut s, k, t) = engaged();
    s.on_frame(
        ms(t),
        Port::MAIN,
        &command(k, |m| m.set_control_mode_cmd_raw(0)),
    );
    assert_eq!(s.mode(), ControlMode::Manual);
    assert!(!s.actuators(ms(t)).warning);
    let fresh = Supervisor::with_wire(SupervisorConfig::default(), ReferenceWire);
    assert!(fresh.actuators(ms(0)).warning);
    // The emergency brake holds until exactly three cycles after the frame.
    let (mut s, _, t) = engaged();
    s.on_frame(
        ms(t),
        Port::MAIN,
        &sealed(EmergencyBrake::ID, [1, 40, 0, 0, 0, 0, 0, 0]),
    );
    assert_eq!(s.actuators(ms(t + 59)).brake, 100.0);
    assert_eq!(s.actuators(ms(t + 60)).brake, 0.0);
}

#[test]
fn state_frame_bits() {
    let (mut s, k, t) = engaged();
    let f = state_frame(&mut s, t);
    assert_eq!((f.warning_flag_raw(), f.steering_enabled_raw()), (0, 1));
    assert_eq!(f.control_mode_raw(), 1);
    // Holding: warning on, steering still enabled.
    let f = state_frame(&mut s, t + 30);
    assert_eq!(f.watchdog_level_raw(), 1);
    assert_eq!((f.warning_flag_raw(), f.steering_enabled_raw()), (1, 1));
    // Full braking: steering disabled.
    let f = state_frame(&mut s, t + 200);
    assert_eq!((f.warning_flag_raw(), f.steering_enabled_raw()), (1, 0));
    // Manual: steering not the ADS's.
    let (mut s, _, t) = engaged();
    s.on_frame(
        ms(t),
        Port::MAIN,
        &command(k, |m| m.set_control_mode_cmd_raw(0)),
    );
    let f = state_frame(&mut s, t);
    assert_eq!(f.steering_enabled_raw(), 0);
    // E-stop latched while autonomous-requested: disabled.
    let (mut s, _, t) = engaged();
    s.on_frame(
        ms(t),
        Port::MAIN,
        &sealed(EmergencyStop::ID, [1, 0, 0, 0, 0, 0, 0, 0]),
    );
    let f = state_frame(&mut s, t);
    assert_eq!((f.steering_enabled_raw(), f.estop_state_raw()), (0, 4));
}

/// The supervisor over a secured wire: signed commands taken, forged ones refused (read
/// anyway once SecOC is switched off, as a campaign's proof needs), its state frames signed.
#[cfg(feature = "secoc")]
#[test]
fn a_supervisor_over_a_secured_wire_takes_signed_commands_and_signs_its_state() {
    use bywire_secoc::{Key, Layout};
    use bywire_vehicle::mechanism::Mechanism;
    use bywire_vehicle::secured::{Checked, Secured, SecuredTable};
    use bywire_vehicle::supervisor::Rejection;
    use bywire_vehicle::wire::{Counters, VehicleWire};
    let (command_id, state_id) = (
        Id::standard(AdsToVehicleControl::ID).unwrap(),
        Id::standard(VehicleToAdsState::ID).unwrap(),
    );
    let table = |key: u8| {
        let mut table = SecuredTable::new(&Key::new([key; 16]), 1 << 10);
        let layout = |data_id| Layout::new(data_id, 8, 32, 8, 24).unwrap();
        table.secure(command_id, layout(1), 1).unwrap();
        table.secure(state_id, layout(2), 1).unwrap();
        table
    };
    let wire = Secured::new(ReferenceWire, table(7));
    assert_eq!(
        wire.state_counter_bits(),
        ReferenceWire.state_counter_bits()
    );
    assert!(wire.table().is_some());
    let mut s = Supervisor::with_wire(SupervisorConfig::default(), wire);
    let (mut ads, mut forger) = (table(7), table(8));
    s.on_frame(ms(0), Port::MAIN, &ads.protect(command(0, |_| {})).unwrap());
    s.on_frame(
        ms(20),
        Port::MAIN,
        &forger.protect(command(1, |_| {})).unwrap(),
    );
    s.on_frame(ms(40), Port::MAIN, &command(1, |_| {}));
    let stats = s.stats();
    assert_eq!(stats.accepted, 1);
    assert_eq!(stats.rejected_for(Rejection::Authentication), 2);
    // Its state goes out signed, its payload the plain wire's 8 bytes.
    let mut sent = Vec::new();
    s.poll(ms(100), &mut |_, f| sent.push(f));
    let state = sent
        .iter()
        .find(|f| f.id() == Some(state_id))
        .expect("a state frame");
    assert!(state.data().len() > 8);
    match ads.check(bywire_vehicle::redundancy::Channel::A, state) {
        Checked::Authentic(payload) => {
            assert!(matches!(payload, Frame::Classic(_)));
            assert_eq!(payload.data(), &state.data()[..8]);
        }
        other => panic!("{other:?}"),
    }
    // SecOC switched off: a forged command is read as if it were authentic.
    s.wire_mut()
        .switch_off([Mechanism::Secoc].into_iter().collect());
    s.on_frame(
        ms(60),
        Port::MAIN,
        &forger.protect(command(1, |_| {})).unwrap(),
    );
    assert_eq!(s.stats().accepted, 2);
}
