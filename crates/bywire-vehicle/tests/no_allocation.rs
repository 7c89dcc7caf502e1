//! The supervisor allocates nothing after construction: frames in, polls, actuator reads and
//! the state frames out run under `allocation-counter`'s counting allocator.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Timestamp};
use bywire_tug::messages::{AdsToVehicleControl, EmergencyStop};
use bywire_tug::wire::ReferenceWire;
use bywire_vehicle::supervisor::{Supervisor, SupervisorConfig};
use common::sealed;

/// Verifies: REQ-MEM-1.
#[test]
fn the_supervisor_never_allocates() {
    supervisor_never_allocates(Supervisor::with_wire(
        SupervisorConfig::default(),
        ReferenceWire,
    ));
}

#[test]
fn the_supervisor_reading_by_profile_never_allocates() {
    let loaded = bywire_tug::profile().unwrap();
    let wire = bywire_vehicle::wire::ProfileWire::new(&loaded).unwrap();
    supervisor_never_allocates(Supervisor::with_wire(SupervisorConfig::default(), wire));
}

fn supervisor_never_allocates<W: bywire_vehicle::wire::VehicleWire>(mut supervisor: Supervisor<W>) {
    // Frames prepared before counting: 200 commands with rolling counters, some bad ones, and
    // the E-stop chain opening and closing.
    let commands: Vec<Frame> = (0..200u64)
        .map(|k| {
            let mut m = AdsToVehicleControl::default();
            m.set_velocity_cmd(1.0).unwrap();
            m.set_control_mode_cmd_raw(1);
            m.set_engage_request_raw(u64::from(k == 20));
            m.set_heartbeat_counter_raw(k % 16);
            let mut f = sealed(AdsToVehicleControl::ID, m.0);
            if k % 37 == 0 {
                f = Frame::classic(f.id().unwrap(), &[0; 8]).unwrap();
            }
            f
        })
        .collect();
    let estop = |on: bool| {
        let mut m = EmergencyStop::default();
        m.set_estop_request_raw(u64::from(on));
        sealed(EmergencyStop::ID, m.0)
    };
    let (open, closed) = (estop(true), estop(false));
    let mut frames_out = 0;
    let mut checksum = 0.0;
    let counted = allocation_counter::measure(|| {
        for (k, frame) in commands.iter().enumerate() {
            let now = Timestamp::from_millis(20 * k as u64);
            supervisor.on_frame(now, Port::MAIN, frame);
            if k == 150 {
                supervisor.on_frame(now, Port::MAIN, &open);
            }
            if k == 160 {
                supervisor.on_frame(now, Port::MAIN, &closed);
            }
            supervisor.set_driver_input(0.0, 0.0);
            supervisor.poll(now, &mut |_, _| frames_out += 1);
            let a = supervisor.actuators(now);
            supervisor.set_feedback(a.velocity, a.steering);
            checksum += a.motor_rpm + a.brake;
        }
    });
    assert!(checksum.is_finite());
    assert!(frames_out >= 199, "{frames_out} state frames");
    assert!(supervisor.stats().checksum > 0 && supervisor.stats().accepted > 100);
    assert_eq!(counted.count_total, 0, "allocations in the supervisor");
}

/// Verifies: REQ-MEM-1.
#[test]
fn the_ads_side_never_allocates() {
    ads_never_allocates(bywire_vehicle::ads::Ads::with_wire(
        bywire_vehicle::ads::AdsConfig::default(),
        ReferenceWire,
    ));
}

#[test]
fn the_ads_side_driven_by_profile_never_allocates() {
    use bywire_vehicle::ads::{Ads, AdsConfig};
    let loaded = bywire_tug::profile().unwrap();
    let wire = bywire_vehicle::wire::ProfileWire::new(&loaded).unwrap();
    ads_never_allocates(Ads::with_wire(AdsConfig::default(), wire));
}

fn ads_never_allocates<W: bywire_vehicle::wire::AdsWire>(mut ads: bywire_vehicle::ads::Ads<W>) {
    use bywire_tug::messages::{ControlMode, VehicleToAdsState};
    use bywire_vehicle::ads::AdsCommand;
    let states: Vec<Frame> = (0..100u64)
        .map(|k| {
            let mut m = VehicleToAdsState::default();
            m.set_control_mode_raw(1);
            m.set_counter_raw(k % 16);
            m.set_heartbeat_echo_raw(k % 16);
            sealed(VehicleToAdsState::ID, m.0)
        })
        .collect();
    let command = AdsCommand {
        velocity: 1.0,
        mode: ControlMode::Autonomous,
        ..AdsCommand::default()
    };
    let mut sent = 0;
    let counted = allocation_counter::measure(|| {
        for (k, state) in states.iter().enumerate() {
            let now = Timestamp::from_millis(20 * k as u64);
            ads.set_command(now, command);
            if k == 50 {
                ads.emergency_brake(now, 3.0);
            }
            ads.poll(now, &mut |_, _| sent += 1);
            ads.on_frame(
                now.saturating_add(std::time::Duration::from_millis(1)),
                Port::MAIN,
                state,
            );
        }
    });
    assert!(
        sent >= 100 && ads.stats().accepted > 90,
        "{:?}",
        ads.stats()
    );
    assert_eq!(counted.count_total, 0, "allocations on the ADS side");
}

/// Verifies: REQ-MEM-1.
#[test]
fn the_fail_operational_mechanisms_never_allocate() {
    use bywire_vehicle::arbitration::{Arbiter, ArbiterConfig, ArbiterInputs, Heartbeat, Side};
    use bywire_vehicle::backup::{ActuatorPair, Feedback, FeedbackCheck};
    use bywire_vehicle::command::FaultClass;
    use bywire_vehicle::degradation::{Degradation, DegradationPolicy, Fault};
    use bywire_vehicle::redundancy::{TripleConfig, TripleVoter};
    use std::time::Duration;

    let ms = Duration::from_millis;
    let mut voter = TripleVoter::new(
        TripleConfig {
            tolerance: 0.5,
            persistence: ms(20),
            timeout: ms(50),
        },
        Timestamp::ZERO,
    );
    let config = ArbiterConfig {
        silence: ms(30),
        disagreement: ms(30),
        deaf: ms(100),
    };
    let mut b = Arbiter::new(Side::B, config, Timestamp::ZERO);
    let mut pair = ActuatorPair::new(
        FeedbackCheck {
            still: 0.5,
            overrun: 5.0,
            persistence: ms(40),
            heartbeat_timeout: ms(50),
        },
        Timestamp::ZERO,
    );
    let mut latch = Degradation::new(DegradationPolicy::default());
    let mut voted = 0.0;
    let counted = allocation_counter::measure(|| {
        for k in 0..500u64 {
            let now = Timestamp::from_millis(k);
            for channel in 0..3 {
                let drift = if channel == 2 { k as f64 / 100.0 } else { 0.0 };
                voter.receive(channel, now, 10.0 + drift);
            }
            voted += voter.vote(now).value().unwrap_or(0.0);
            b.step(
                now,
                ArbiterInputs {
                    self_test_ok: true,
                    partner: (k < 200).then_some(Heartbeat {
                        role: bywire_vehicle::arbitration::Role::Active,
                        at: now,
                    }),
                    traffic_at: Some(now),
                    outputs_agree: Some(true),
                    fenced: false,
                },
            );
            pair.step(
                now,
                Feedback {
                    demanded: 10.0,
                    measured: if k < 300 { 10.0 } else { 0.0 },
                    drive_fault: false,
                    heartbeat_at: Some(now),
                },
            );
            latch.report(Fault {
                class: FaultClass::ALL[(k % 6) as usize],
                source: 0,
                at: now,
            });
        }
    });
    assert!(voted > 0.0);
    assert!(b.took_over().is_some());
    assert_eq!(counted.count_total, 0, "allocations in the mechanisms");
}

#[test]
fn a_duplicated_supervisor_never_allocates() {
    use bywire_vehicle::arbitration::Side;
    let (mut pair, _) = common::vehicles::duplicated_shuttle();
    // Each half's status, prepared before counting: the pair hears its own halves.
    let mut statuses = Vec::new();
    pair.poll(Timestamp::ZERO, &mut |port, frame| {
        statuses.push((port, frame))
    });
    let mut sent = 0;
    // Other traffic both halves hear (a silent partner is told from a deaf receiver by it).
    let other = Frame::classic(bywire_core::Id::standard(0x7FF).unwrap(), &[0]).unwrap();
    let counted = allocation_counter::measure(|| {
        for k in 1..300u64 {
            let now = Timestamp::from_millis(10 * k);
            pair.on_frame(now, bywire_core::node::Port(0), &other);
            pair.on_frame(now, bywire_core::node::Port(8), &other);
            // B's port hears A's status and A's hears B's; after 2 s A falls silent.
            for (port, frame) in &statuses {
                let to = if port.0 < 8 {
                    bywire_core::node::Port(port.0 + 8)
                } else {
                    bywire_core::node::Port(port.0 - 8)
                };
                if k < 200 || port.0 >= 8 {
                    pair.on_frame(now, to, frame);
                }
            }
            pair.poll(now, &mut |_, _| sent += 1);
        }
    });
    assert!(sent > 300);
    assert_eq!(pair.in_control(), Some(Side::B));
    assert_eq!(
        counted.count_total, 0,
        "allocations in the duplicated supervisor"
    );
}
