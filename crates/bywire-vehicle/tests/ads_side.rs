//! The ADS side against the real supervisor on the bit-timed bus, its own fail-safes, its
//! feedback validation, and the redundancy voters.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use bywire_core::node::Node;
use bywire_tug::wire::ReferenceWire;
use std::time::Duration;

use bywire_core::node::Port;
use bywire_core::{Frame, Id};
use bywire_net::network::{Network, NodeHandle};
use bywire_net::sim::NodeId;
use bywire_tug::messages::{self, ControlMode, Gear, VehicleToAdsState};
use bywire_vehicle::ads::{Ads, AdsCommand, AdsConfig, Blocker};
use bywire_vehicle::command::{EstopCode, WatchdogLevel};
use bywire_vehicle::redundancy::{Channel, DualVoter, Vote, VoteFailure};
use bywire_vehicle::supervisor::{Supervisor, SupervisorConfig, Watchdog};
use bywire_vehicle::wire::VehicleWire;
use common::{ms, sealed};

/// ADS and supervisor on one 500 kbit/s bus, on the network runner; between milliseconds the
/// vehicle's speed follows the actuators (braking stops it). A tap logs the ADS's frames.
struct Loop {
    net: Network,
    tap: NodeId,
    ads_node: NodeHandle<Ads<ReferenceWire>>,
    vcu_node: NodeHandle<Supervisor<ReferenceWire>>,
    now: u64,
    ads_frames: Vec<(u64, Frame)>,
}

impl Loop {
    fn new() -> Loop {
        let mut net = Network::new();
        let bus = net.add_bus("bus1", 500_000, None);
        let ads_node = net.add_node(Ads::with_wire(AdsConfig::default(), ReferenceWire));
        let vcu_node = net.add_node(Supervisor::with_wire(
            SupervisorConfig::default(),
            ReferenceWire,
        ));
        net.wire(ads_node, Port::MAIN, bus).unwrap();
        net.wire(vcu_node, Port::MAIN, bus).unwrap();
        let tap = net.tap(bus).unwrap();
        Loop {
            net,
            tap,
            ads_node,
            vcu_node,
            now: 0,
            ads_frames: Vec::new(),
        }
    }

    fn run_to(&mut self, until: u64) {
        while self.now < until {
            self.net.run_for(Duration::from_millis(1));
            self.now += 1;
            let tap = self.tap;
            while let Some(r) = self.net.bus_mut(0).unwrap().receive(tap) {
                // The ADS's own frames: commands (0x100) and the emergency brake.
                if r.frame.id().is_some_and(|id| id.as_raw() < 0x101) {
                    let at = r.timestamp.as_nanos() / 1_000_000;
                    self.ads_frames.push((at, r.frame));
                }
            }
            let a = self.vcu().actuators(ms(self.now));
            let speed = common::plant_speed(&a);
            let mut vcu = self.net.node_mut(self.vcu_node).unwrap();
            vcu.set_feedback(speed, a.steering);
        }
    }

    fn command(&mut self, c: AdsCommand) {
        let now = ms(self.now);
        assert!(self
            .net
            .node_mut(self.ads_node)
            .unwrap()
            .set_command(now, c));
    }

    /// At 400 ms (after the run of valid commands a recovery needs): an engage, then plain
    /// commands at 1.5 m/s until 600 ms.
    fn engage_at_400(&mut self) {
        self.run_to(400);
        self.command(AdsCommand {
            engage: true,
            ..drive(1.5)
        });
        self.run_to(440);
        self.command(drive(1.5));
        self.run_to(600);
    }

    fn ads(&self) -> &Ads<ReferenceWire> {
        self.net.node(self.ads_node).unwrap()
    }

    fn vcu(&self) -> &Supervisor<ReferenceWire> {
        self.net.node(self.vcu_node).unwrap()
    }
}

fn drive(velocity: f64) -> AdsCommand {
    AdsCommand {
        velocity,
        gear: Gear::Drive,
        mode: ControlMode::Autonomous,
        ..AdsCommand::default()
    }
}

#[test]
fn ads_engages_and_drives_the_supervisor_with_valid_feedback() {
    let mut l = Loop::new();
    l.command(drive(1.5));
    l.engage_at_400();
    assert_eq!(l.vcu().watchdog(), Watchdog::Normal);
    assert_eq!(l.vcu().mode(), ControlMode::Autonomous);
    assert_eq!(l.vcu().stats().rejected(), 0);
    let now = ms(l.now);
    assert!(l.ads().feedback_alive(now));
    let state = l.ads().state();
    assert_eq!(state.mode.value, Some(ControlMode::Autonomous));
    assert_eq!(state.velocity.value, Some(1.5));
    // The echo comes back within a cycle or two (state frames are sent every 20 ms).
    let latency = state.echo_latency.value.unwrap();
    assert!(latency <= Duration::from_millis(40), "{latency:?}");
    assert!(l.ads().stats().accepted > 20 && l.ads().stats().echo == 0);
    // Commands every 20 ms exactly, with counters rolling and CRCs good.
    let commands: Vec<&(u64, Frame)> = l
        .ads_frames
        .iter()
        .filter(|(_, f)| f.id() == Some(Id::standard(0x100).unwrap()))
        .collect();
    // (The first went at the first poll after the command, 1 ms late; the schedule holds.)
    assert!(commands[1..].windows(2).all(|w| w[1].0 - w[0].0 == 20));
    assert!(commands.len() >= 29);
    for (k, (_, f)) in commands.iter().enumerate() {
        let p: [u8; 8] = f.data().try_into().unwrap();
        assert!(messages::is_sealed(0x100, &p));
        assert_eq!(usize::from(p[6] & 0x0F), k % 16);
    }
}

/// A state frame that fails verification is counted as such and never read.
#[cfg(feature = "secoc")]
#[test]
fn an_unauthenticated_state_frame_is_counted_and_not_read() {
    use bywire_secoc::{Key, Layout};
    use bywire_vehicle::secured::{Secured, SecuredTable};
    let state_id = Id::standard(VehicleToAdsState::ID).unwrap();
    let table = |key| {
        let mut table = SecuredTable::new(&Key::new([key; 16]), 1 << 10);
        table
            .secure(state_id, Layout::new(0x42, 8, 32, 8, 24).unwrap(), 1)
            .unwrap();
        table
    };
    let mut ads = commanded(Secured::new(ReferenceWire, table(4)));
    // The plain frame, and one signed with another key.
    ads.on_frame(
        ms(41),
        Port::MAIN,
        &state_frame(0, 2, ControlMode::Autonomous),
    );
    let mut forger = table(5);
    let forged = forger
        .protect(state_frame(0, 2, ControlMode::Autonomous))
        .unwrap();
    ads.on_frame(ms(42), Port::MAIN, &forged);
    assert_eq!((ads.stats().authentication, ads.stats().accepted), (2, 0));
    assert_eq!(ads.state().mode.value, None, "nothing read");
    // Signed with the right key, it is read.
    let signed = table(4)
        .protect(state_frame(0, 2, ControlMode::Autonomous))
        .unwrap();
    ads.on_frame(ms(43), Port::MAIN, &signed);
    assert_eq!((ads.stats().authentication, ads.stats().accepted), (2, 1));
    assert_eq!(ads.state().mode.value, Some(ControlMode::Autonomous));
}

/// What keeps the vehicle from following, in the order a user clears it, and what to do.
#[test]
fn the_blocker_names_what_keeps_the_vehicle_from_following() {
    let mut l = Loop::new();
    assert_eq!(l.ads().blocker(ms(0)), Some(Blocker::NoFeedback));
    l.command(drive(1.5));
    l.run_to(100);
    // Answering, but still braking after start-up: it wants valid commands, then engage.
    let blocker = l.ads().blocker(ms(l.now));
    assert!(matches!(blocker, Some(Blocker::Watchdog(_))), "{blocker:?}");
    l.run_to(400);
    assert_eq!(
        l.ads().blocker(ms(l.now)),
        Some(Blocker::Watchdog(WatchdogLevel::AwaitingEngage))
    );
    l.engage_at_400();
    assert_eq!(l.ads().blocker(ms(l.now)), None);
    l.command(AdsCommand {
        mode: ControlMode::Manual,
        ..drive(0.0)
    });
    l.run_to(700);
    assert_eq!(
        l.ads().blocker(ms(l.now)),
        Some(Blocker::NotEngaged(ControlMode::Manual))
    );
    // Silence from the vehicle: back to no feedback.
    l.net.drop_output(l.vcu_node, true);
    l.run_to(800);
    assert_eq!(l.ads().blocker(ms(l.now)), Some(Blocker::NoFeedback));
    // Each says what to do next.
    for (blocker, says) in [
        (Blocker::NoFeedback, "does the profile match"),
        (
            Blocker::Estop(EstopCode::Stopped),
            "operator_reset again to confirm",
        ),
        (
            Blocker::Estop(EstopCode::EstopReset),
            "send operator_reset again",
        ),
        (Blocker::Estop(EstopCode::ResetConfirmed), "send engage"),
        (Blocker::Estop(EstopCode::Requested), "E-stop: requested"),
        (Blocker::DriverOverride, "hands and feet off"),
        (
            Blocker::Watchdog(WatchdogLevel::FullBraking),
            "keep sending valid commands, then engage",
        ),
        (
            Blocker::Watchdog(WatchdogLevel::AwaitingEngage),
            "keep sending valid commands and engage",
        ),
        (
            Blocker::Watchdog(WatchdogLevel::Decelerating),
            "commands late",
        ),
        (
            Blocker::NotEngaged(ControlMode::Manual),
            "mode autonomous with engage: true",
        ),
    ] {
        let text = blocker.to_string();
        assert!(text.contains(says), "{text:?} lacks {says:?}");
    }
}

/// Verifies: REQ-SS-1.
#[test]
fn a_stale_command_becomes_a_controlled_stop() {
    let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
    ads.set_command(ms(0), drive(3.0));
    assert_eq!(ads.effective_command(ms(200)).unwrap().velocity, 3.0);
    let stop = ads.effective_command(ms(201)).unwrap();
    assert_eq!((stop.velocity, stop.brake), (0.0, 30.0));
    // Non-finite commands are refused; the old one keeps ageing.
    assert!(!ads.set_command(ms(250), drive(f64::NAN)));
    assert_eq!(ads.effective_command(ms(250)).unwrap().velocity, 0.0);
    assert!(ads.set_command(ms(260), drive(1.0)));
    assert_eq!(ads.effective_command(ms(260)).unwrap().velocity, 1.0);
}

#[test]
fn emergency_brake_burst_is_three_frames_in_10_ms_then_20_hz() {
    let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
    ads.emergency_brake(ms(100), 4.0);
    let mut sent = Vec::new();
    for t in 100..=300 {
        ads.poll(ms(t), &mut |port, f| {
            if port == Port::MAIN {
                sent.push((t, f))
            }
        });
    }
    let times: Vec<u64> = sent.iter().map(|(t, _)| *t).collect();
    assert_eq!(&times[..3], &[100, 104, 108]);
    assert!(times[2] - times[0] <= 10);
    assert!(
        times[3..].windows(2).all(|w| w[1] - w[0] == 50),
        "{times:?}"
    );
    assert_eq!(sent[0].1.id(), Some(Id::standard(0).unwrap()));
    ads.release_brake();
    let mut after = 0;
    for t in 301..400 {
        ads.poll(ms(t), &mut |_, _| after += 1);
    }
    assert_eq!(after, 0);
}

/// An ADS over `wire` that has sent its first three commands (at 0, 20 and 40 ms).
fn commanded<W: bywire_vehicle::wire::AdsWire>(wire: W) -> Ads<W> {
    let mut ads = Ads::with_wire(AdsConfig::default(), wire);
    ads.set_command(ms(0), drive(1.0));
    for t in 0..=40 {
        ads.poll(ms(t), &mut |_, _| {});
    }
    ads
}

fn state_frame(counter: u8, echo: u8, mode: ControlMode) -> Frame {
    let mut m = VehicleToAdsState::default();
    m.set_velocity_actual(1.0).unwrap();
    m.set_control_mode_raw(mode as u64);
    m.set_heartbeat_echo_raw(u64::from(echo));
    m.set_counter_raw(u64::from(counter));
    let mut p = m.0;
    messages::seal(VehicleToAdsState::ID, &mut p);
    Frame::classic(Id::standard(VehicleToAdsState::ID).unwrap(), &p).unwrap()
}

#[test]
fn feedback_is_validated_and_times_out() {
    let mut ads = commanded(ReferenceWire);
    // Commands 0, 1, 2 were sent at 0, 20, 40 ms.
    ads.on_frame(
        ms(41),
        Port::MAIN,
        &state_frame(0, 2, ControlMode::Autonomous),
    );
    assert_eq!(ads.stats().accepted, 1);
    assert_eq!(
        ads.state().echo_latency.value,
        Some(Duration::from_millis(1))
    );
    // A bad CRC, a repeated counter, an echo of a command never sent recently.
    let mut bad = state_frame(1, 2, ControlMode::Autonomous);
    if let Frame::Classic(f) = &bad {
        let mut d: [u8; 8] = f.data().try_into().unwrap();
        d[2] ^= 1;
        bad = Frame::classic(f.id(), &d).unwrap();
    }
    ads.on_frame(ms(42), Port::MAIN, &bad);
    ads.on_frame(
        ms(43),
        Port::MAIN,
        &state_frame(0, 2, ControlMode::Autonomous),
    );
    ads.on_frame(
        ms(44),
        Port::MAIN,
        &state_frame(1, 9, ControlMode::Autonomous),
    );
    // The last is counted as no echo, but what the vehicle says of itself is taken.
    let s = ads.stats();
    assert_eq!((s.checksum, s.counter, s.echo, s.accepted), (1, 1, 1, 2));
    // Alive (answering these commands) for 3 cycles after the last echo, then not, though
    // its state is fresher.
    assert!(ads.feedback_alive(ms(41 + 60)));
    assert!(!ads.feedback_alive(ms(41 + 61)));
    assert_eq!(
        ads.state().mode.age(ms(141)),
        Some(Duration::from_millis(97))
    );
}

/// Verifies: REQ-RED-1.
#[test]
fn dual_voter_follows_the_reference_logic() {
    let timeout = Duration::from_millis(60);
    let mut v = DualVoter::new(timeout, Duration::from_millis(5));
    assert_eq!(v.vote(ms(0)), Vote::Failed(VoteFailure::BothLost));
    v.receive(Channel::A, ms(10), 7u8);
    v.receive(Channel::B, ms(12), 7u8);
    assert_eq!(v.vote(ms(12)), Vote::Agreed(7));
    // B goes silent: degraded on A once B's copy is older than the timeout.
    v.receive(Channel::A, ms(30), 8);
    assert_eq!(v.vote(ms(30)), Vote::Pending);
    // B's copy is fresh for the whole timeout, stale a nanosecond after.
    assert_eq!(v.arrived(Channel::B), Some(ms(12)));
    let stale = v.stale_at(Channel::B).unwrap();
    assert_eq!(stale, ms(72).saturating_add(Duration::from_nanos(1)));
    assert_eq!(v.vote(ms(72)), Vote::Pending);
    assert!(matches!(v.vote(stale), Vote::Degraded { .. }));
    assert_eq!(
        v.vote(ms(73)),
        Vote::Degraded {
            value: 8,
            healthy: Channel::A
        }
    );
    // Both silent.
    assert_eq!(v.vote(ms(91)), Vote::Failed(VoteFailure::BothLost));
    // Disagreeing fresh copies.
    v.receive(Channel::A, ms(100), 1);
    v.receive(Channel::B, ms(101), 2);
    assert_eq!(v.vote(ms(101)), Vote::Failed(VoteFailure::Disagree));
}

/// A copy whose partner came within the timeout is fresh from its own arrival; one whose
/// partner came longer ago goes stale with the partner (its bus was that late).
#[test]
fn dual_voter_a_copy_is_fresh_from_its_arrival_only_within_the_timeout_of_its_partner() {
    let timeout = Duration::from_millis(50);
    let one_ns = Duration::from_nanos(1);
    for (late, stale_at) in [
        (50, ms(100).saturating_add(one_ns)),
        (51, ms(50).saturating_add(one_ns)),
    ] {
        let mut v = DualVoter::new(timeout, Duration::from_millis(5))
            .paired_by(|a: &(u8, u8), b: &(u8, u8)| a.1 == b.1);
        v.receive(Channel::A, ms(0), (7, 1));
        v.receive(Channel::B, ms(late), (7, 1));
        assert_eq!(v.stale_at(Channel::B), Some(stale_at), "{late} ms late");
    }
}

/// Verifies: REQ-RED-1.
#[test]
fn dual_voter_pairs_the_copies_of_one_command() {
    let (timeout, skew) = (Duration::from_millis(30), Duration::from_millis(5));
    // By arrival time (no counter): equal copies 12 ms apart are one command late on one bus;
    // different ones so far apart may be two commands, so the vote waits; within the window
    // they disagree.
    let mut v = DualVoter::new(timeout, skew);
    v.receive(Channel::A, ms(0), 7u8);
    v.receive(Channel::B, ms(12), 7u8);
    assert_eq!(v.vote(ms(12)), Vote::Agreed(7));
    v.receive(Channel::A, ms(20), 8);
    assert_eq!(v.vote(ms(20)), Vote::Pending);
    v.receive(Channel::B, ms(24), 9);
    assert_eq!(v.vote(ms(24)), Vote::Failed(VoteFailure::Disagree));
    // By counter (value, counter): the same counter is one command however far apart, and two
    // counters are never compared, however close.
    let mut v = DualVoter::new(timeout, skew).paired_by(|a: &(u8, u8), b: &(u8, u8)| a.1 == b.1);
    v.receive(Channel::A, ms(0), (7, 1));
    v.receive(Channel::B, ms(15), (7, 1));
    assert_eq!(v.vote(ms(15)), Vote::Agreed((7, 1)));
    v.receive(Channel::A, ms(20), (8, 2));
    assert_eq!(
        v.vote(ms(20)),
        Vote::Pending,
        "B's copy 5 ms before is the last command's"
    );
    v.receive(Channel::B, ms(35), (9, 2));
    assert_eq!(v.vote(ms(35)), Vote::Failed(VoteFailure::Disagree));
}

/// Verifies: REQ-RED-1.
#[test]
fn dual_voter_compares_a_bus_behind_by_more_than_a_cycle() {
    let (timeout, skew) = (Duration::from_millis(30), Duration::from_millis(5));
    let by_counter = |a: &(u8, u8), b: &(u8, u8)| a.1 == b.1;
    // B 25 ms behind (20 ms cycle): its copy of command 1 comes after A's command 2, and is
    // compared with A's copy of 1 all the same.
    let mut v = DualVoter::new(timeout, skew).paired_by(by_counter);
    v.receive(Channel::A, ms(0), (7, 1));
    v.receive(Channel::A, ms(20), (8, 2));
    assert_eq!(
        v.vote(ms(20)),
        Vote::Degraded {
            value: (8, 2),
            healthy: Channel::A
        }
    );
    v.receive(Channel::B, ms(25), (7, 1));
    assert_eq!(v.vote(ms(25)), Vote::Agreed((7, 1)));
    v.receive(Channel::A, ms(40), (9, 3));
    assert_eq!(v.vote(ms(40)), Vote::Pending);
    v.receive(Channel::B, ms(45), (5, 2));
    assert_eq!(v.vote(ms(45)), Vote::Failed(VoteFailure::Disagree));
    // B 45 ms behind: its copy comes over a timeout after A's, stale; A's last is taken alone,
    // and a late copy that contradicts A's is a disagreement still.
    let mut v = DualVoter::new(timeout, skew).paired_by(by_counter);
    v.receive(Channel::A, ms(0), (7, 1));
    v.receive(Channel::A, ms(20), (8, 2));
    v.receive(Channel::A, ms(40), (9, 3));
    v.receive(Channel::B, ms(45), (7, 1));
    assert_eq!(
        v.vote(ms(45)),
        Vote::Degraded {
            value: (9, 3),
            healthy: Channel::A
        }
    );
    assert_eq!(
        v.stale_at(Channel::B),
        Some(ms(30).saturating_add(Duration::from_nanos(1)))
    );
    v.receive(Channel::B, ms(65), (6, 2));
    assert_eq!(v.vote(ms(65)), Vote::Failed(VoteFailure::Disagree));
    // A copy whose counter came round (an older command's, over two timeouts before) is not
    // its partner: it counts from its own arrival.
    let mut v = DualVoter::new(timeout, skew).paired_by(by_counter);
    v.receive(Channel::A, ms(0), (7, 1));
    v.receive(Channel::B, ms(61), (7, 1));
    assert_eq!(
        v.stale_at(Channel::B),
        Some(ms(91).saturating_add(Duration::from_nanos(1)))
    );
    assert_eq!(
        v.vote(ms(61)),
        Vote::Degraded {
            value: (7, 1),
            healthy: Channel::B
        }
    );
}

#[test]
fn dual_voter_leaves_out_a_bus_further_behind_than_it_pairs_by_time() {
    let (timeout, skew) = (Duration::from_millis(30), Duration::from_millis(5));
    let by_counter = |a: &(u8, u8), b: &(u8, u8)| a.1 == b.1;
    let voter = || DualVoter::new(timeout, skew).paired_by(by_counter);
    // B 65 ms behind (over two timeouts): A's commands 1–4 have come when B's copy of 1 does.
    let a_copies = |v: &mut DualVoter<(u8, u8)>| {
        for (k, value) in (0..4u8).zip([7, 8, 9, 10]) {
            v.receive(Channel::A, ms(20 * u64::from(k)), (value, k + 1));
        }
    };
    // Known to be behind (the caller took command 4): compared with A's copy of 1, however
    // long ago, and stale as it comes; A's copies are taken alone.
    let mut v = voter();
    a_copies(&mut v);
    v.receive_behind(Channel::B, ms(65), (7, 1));
    assert_eq!(
        v.vote(ms(65)),
        Vote::Degraded {
            value: (10, 4),
            healthy: Channel::A
        }
    );
    assert_eq!(
        v.stale_at(Channel::B),
        Some(ms(30).saturating_add(Duration::from_nanos(1)))
    );
    let mut v = voter();
    a_copies(&mut v);
    v.receive_behind(Channel::B, ms(65), (6, 1));
    assert_eq!(v.vote(ms(65)), Vote::Failed(VoteFailure::Disagree));
    // Its partner no longer kept (eight of A's copies came since): stale all the same.
    let mut v = voter();
    for k in 0..12u8 {
        v.receive(Channel::A, ms(20 * u64::from(k)), (k, k + 1));
    }
    v.receive_behind(Channel::B, ms(225), (99, 1));
    assert_eq!(v.stale_at(Channel::B), Some(ms(225)));
    assert_eq!(
        v.vote(ms(225)),
        Vote::Degraded {
            value: (11, 12),
            healthy: Channel::A
        }
    );
    // Received as new, the same copy would be a command of its own, waiting for a partner.
    let mut v = voter();
    a_copies(&mut v);
    v.receive(Channel::B, ms(65), (7, 1));
    assert_eq!(v.vote(ms(65)), Vote::Pending);
}

/// The reference tug's wheels.
const TUG_WHEELS: bywire_vehicle::ads::WheelGeometry = bywire_vehicle::ads::WheelGeometry {
    wheelbase: 3.2,
    track: 1.8,
};

/// Feed the ADS 2 s of wheel feedback at 50 Hz: every wheel at `angles` (degrees) and
/// `speeds` (m/s); the odometry pose at the end.
fn odometry_after(angles: [f64; 4], speeds: [f64; 4]) -> bywire_control::kinematics::Pose {
    odometry_with(Some(TUG_WHEELS), angles, speeds).unwrap()
}

/// As `odometry_after`, with `wheels` as the ADS knows them (or not).
fn odometry_with(
    wheels: Option<bywire_vehicle::ads::WheelGeometry>,
    angles: [f64; 4],
    speeds: [f64; 4],
) -> Option<bywire_control::kinematics::Pose> {
    let config = AdsConfig {
        wheels,
        ..AdsConfig::default()
    };
    let mut ads = Ads::with_wire(config, ReferenceWire);
    feed_wheels(&mut ads, 0, angles, speeds);
    ads.state().odometry.value
}

/// 2 s of wheel feedback at 50 Hz to `ads` from `from_ms`: every wheel at `angles` (degrees)
/// and `speeds`.
fn feed_wheels<O: bywire_vehicle::ads::Odometer>(
    ads: &mut Ads<ReferenceWire, O>,
    from_ms: u64,
    angles: [f64; 4],
    speeds: [f64; 4],
) {
    use bywire_tug::messages::{VehicleToAdsSensors, VehicleToAdsWheelAngles};
    for k in 0..=100u64 {
        let now = ms(from_ms + 20 * k);
        let mut a = VehicleToAdsWheelAngles::default();
        a.set_wheel_angle_fl(angles[0]).unwrap();
        a.set_wheel_angle_fr(angles[1]).unwrap();
        a.set_wheel_angle_rl(angles[2]).unwrap();
        a.set_wheel_angle_rr(angles[3]).unwrap();
        a.set_counter_raw(k % 16);
        ads.on_frame(now, Port::MAIN, &sealed(VehicleToAdsWheelAngles::ID, a.0));
        let mut s = VehicleToAdsSensors::default();
        s.set_wheel_speed_fl(speeds[0]).unwrap();
        s.set_wheel_speed_fr(speeds[1]).unwrap();
        s.set_wheel_speed_rl(speeds[2]).unwrap();
        s.set_wheel_speed_rr(speeds[3]).unwrap();
        s.set_counter_raw(k % 16);
        ads.on_frame(now, Port::MAIN, &sealed(VehicleToAdsSensors::ID, s.0));
    }
}

/// A vehicle brings its own dead reckoning: the ADS side hands it each interval and the
/// wheels, and reports what it says (here a model that ignores the steering angles).
#[test]
fn a_vehicle_brings_its_own_odometer() {
    use bywire_control::kinematics::{Pose, WheelState};
    use bywire_vehicle::ads::Odometer;
    #[derive(Debug, Clone, Default)]
    struct StraightAhead {
        pose: Pose,
        intervals: Vec<f64>,
    }
    impl Odometer for StraightAhead {
        fn update(&mut self, dt: f64, wheels: &[WheelState; 4]) -> Option<Pose> {
            self.intervals.push(dt);
            self.pose.x += dt * wheels.iter().map(|w| w.speed).sum::<f64>() / 4.0;
            Some(self.pose)
        }
        fn reset(&mut self, pose: Pose) {
            self.pose = pose;
        }
    }
    let mut ads = Ads::with_odometer(
        AdsConfig::default(),
        ReferenceWire,
        StraightAhead::default(),
    );
    feed_wheels(&mut ads, 0, [30.0; 4], [1.0; 4]);
    let pose = ads.state().odometry.value.unwrap();
    assert!((pose.x - 2.0).abs() < 1e-9 && pose.y == 0.0, "{pose:?}");
    // Each interval since the last sensors frame, the first frame having none before it.
    let intervals = &ads.odometer().intervals;
    assert_eq!(intervals.len(), 100);
    assert!(intervals.iter().all(|dt| (dt - 0.02).abs() < 1e-12));
    ads.reset_odometry(Pose {
        x: 5.0,
        ..Pose::default()
    });
    assert_eq!(ads.state().odometry.value, None);
    feed_wheels(&mut ads, 2_020, [0.0; 4], [0.5; 4]);
    let pose = ads.state().odometry.value.unwrap();
    assert!((pose.x - 6.01).abs() < 1e-9, "{pose:?}");
}

/// A vehicle whose geometry the ADS was not given has no odometry (no wheelbase is assumed).
#[test]
fn without_the_vehicles_geometry_there_is_no_odometry() {
    assert!(odometry_with(Some(TUG_WHEELS), [0.0; 4], [1.0; 4]).is_some());
    assert!(odometry_with(None, [0.0; 4], [1.0; 4]).is_none());
}

#[test]
fn odometry_follows_the_four_wheels() {
    // Crab at 30°, 1 m/s, for 2 s: (√3, 1) without turning.
    let p = odometry_after([30.0; 4], [1.0; 4]);
    assert!(
        (p.x - 3f64.sqrt()).abs() < 0.02 && (p.y - 1.0).abs() < 0.02,
        "{p:?}"
    );
    assert!(p.yaw.abs() < 1e-3, "{p:?}");
    // Tank turn at 0.5 rad/s: wheels tangent to the circle through them, speed ω·r.
    let (a, b) = (1.6f64, 0.9f64);
    let r = a.hypot(b);
    let tangent = (a / b).atan().to_degrees(); // angle of (-b, a) folded into ±90°
    let v = 0.5 * r;
    let p = odometry_after([-tangent, tangent, tangent, -tangent], [-v, v, -v, v]);
    assert!(p.x.abs() < 0.02 && p.y.abs() < 0.02, "{p:?}");
    assert!((p.yaw - 1.0).abs() < 0.01, "{p:?}");
}

#[test]
fn steering_response_is_measured_from_setpoint_to_actual() {
    let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
    ads.set_command(
        ms(0),
        AdsCommand {
            steering: 0.0,
            ..drive(1.0)
        },
    );
    for t in (0..=1000u32).step_by(20) {
        let now = ms(u64::from(t));
        if t >= 100 {
            let steer = AdsCommand {
                steering: 10.0,
                ..drive(1.0)
            };
            ads.set_command(now, steer);
        }
        ads.poll(now, &mut |_, _| {});
        // The vehicle steers at 30°/s from 120 ms on.
        let actual = (f64::from(t.saturating_sub(120)) * 0.03).min(10.0);
        let mut m = VehicleToAdsState::default();
        m.set_steering_angle_actual(actual).unwrap();
        m.set_counter_raw(u64::from(t / 20 % 16));
        // Echo the command just sent.
        m.set_heartbeat_echo_raw(u64::from((t / 20) % 16));
        ads.on_frame(
            ms(u64::from(t) + 1),
            Port::MAIN,
            &sealed(VehicleToAdsState::ID, m.0),
        );
    }
    // 9.5° (within 0.5° of 10°) is reached at 120 + 9.5/0.03 ≈ 437 → the 441 ms frame.
    let response = ads.state().steering_response.value.unwrap();
    assert_eq!(response, Duration::from_millis(441 - 100));
}

/// The vehicle's state and wheel-speed frames on two buses, bus B's behind A's by a cycle and
/// a quarter up to twelve and a half cycles (past half a 4-bit counter's range at the 20 ms
/// cycle, where B's frames look ahead of A's): each of B's is recognised as the copy of one
/// already taken from A, not counted as a frame out of sequence, and never taken (the feedback
/// comes from A all the same). From three cycles behind every frame but a few was refused
/// before, as B's late copies broke the one sequence both buses fed: a single late bus cost
/// the ADS all its feedback.
#[test]
fn feedback_copies_late_on_one_bus_are_copies_not_counter_errors() {
    for late in [25, 45, 70, 150, 200, 250] {
        let config = AdsConfig {
            redundant: true,
            ..AdsConfig::default()
        };
        let mut ads = Ads::with_wire(config, ReferenceWire);
        let mut vcu = Supervisor::with_wire(SupervisorConfig::default(), ReferenceWire);
        let mut wheels = ReferenceWire;
        let mut late_on_b: Vec<(u64, Frame)> = Vec::new();
        assert!(ads.set_command(ms(0), AdsCommand::default()));
        for t in 0..1_000u64 {
            let now = ms(t);
            let mut commands = Vec::new();
            bywire_core::node::Node::poll(&mut ads, now, &mut |port, frame| {
                if port == Ads::<ReferenceWire>::PORT_A {
                    commands.push(frame);
                }
            });
            for frame in &commands {
                vcu.on_frame(now, Port::MAIN, frame);
            }
            let mut feedback = Vec::new();
            vcu.poll(now, &mut |port, frame| {
                if port == Port::MAIN {
                    feedback.push(frame)
                }
            });
            if t % 20 == 10 {
                let speed = f64::from(u32::try_from(t).unwrap()) / 1_000.0;
                feedback.extend(wheels.wheel_speeds_frame([speed; 4], t / 20));
            }
            for frame in feedback {
                bywire_core::node::Node::on_frame(
                    &mut ads,
                    now,
                    Ads::<ReferenceWire>::PORT_A,
                    &frame,
                );
                late_on_b.push((t + late, frame));
            }
            for (_, frame) in late_on_b.iter().filter(|(at, _)| *at == t) {
                bywire_core::node::Node::on_frame(
                    &mut ads,
                    now,
                    Ads::<ReferenceWire>::PORT_B,
                    frame,
                );
            }
            late_on_b.retain(|(at, _)| *at > t);
        }
        let stats = ads.stats();
        // 50 state frames and 50 wheel-speed frames, each taken once, from A.
        assert!(stats.accepted >= 95, "{late} ms: {stats:?}");
        assert!(stats.accepted <= 100, "{late} ms: {stats:?}");
        assert_eq!(stats.counter, 0, "{late} ms: {stats:?}");
        assert_eq!(stats.echo, 0, "{late} ms: {stats:?}");
        let speeds = ads.state().wheel_speeds;
        assert_eq!(
            speeds.value,
            Some([0.99; 4]),
            "{late} ms: A's last, not B's"
        );
        assert_eq!(speeds.at, Some(ms(990)));
    }
}
