//! The redundancy rows of the fault matrix, over several wires: the commands travel on two
//! bit-timed buses (one ADS computer per bus, on the simulated runner) and the supervisor votes
//! on the decoded commands. Agreeing copies → each command taken once; one bus silent →
//! degraded, still driving; both silent → the watchdog cascade; copies that disagree → full
//! braking at once.
//!
//! The same suite runs for the reference tug through the generated structs and through its
//! profile, and for two layouts the reference tug does not have: a 6-byte command and a CAN FD
//! command (16 bytes). Voting used to compare 8-byte classic payloads only, so a profile with
//! any other command frame was never voted on.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use bywire_core::node::Node;
use std::time::Duration;

use common::vehicles::{self, by_profile, reference_wire, Vehicle};

use bywire_core::node::Port;
use bywire_core::Timestamp;
use bywire_net::network::{Network, NodeHandle};
use bywire_tug::messages::{ControlMode, Gear};
use bywire_vehicle::ads::{Ads, AdsCommand};
use bywire_vehicle::profile::LoadedProfile;
use bywire_vehicle::redundancy::Channel;
use bywire_vehicle::supervisor::{Redundancy, Supervisor, SupervisorConfig, Watchdog};
use bywire_vehicle::wire::{AdsWire, Counters, ProfileWire, VehicleWire};

/// The shuttle test vehicle with its command message replaced by `command_block`.
fn shuttle_with(command_block: &str) -> LoadedProfile {
    vehicles::shuttle_with(|dbc| {
        let start = dbc.find("BO_ 1280 Shuttle_Cmd").unwrap();
        let end = start + dbc[start..].find("\n\n").unwrap();
        format!("{}{}{}", &dbc[..start], command_block.trim(), &dbc[end..])
    })
}

/// Six bytes: 10-bit setpoints, a 4-bit counter and an XOR checksum in the last byte.
const SIX_BYTES: &str = r#"
BO_ 1280 Shuttle_Cmd: 6 ADS
 SG_ Cmd_Steer : 0|10@1- (0.1,0) [-30|30] "deg" VCU
 SG_ Cmd_Speed : 10|10@1+ (0.02,0) [0|12] "m/s" VCU
 SG_ Cmd_Brake : 20|7@1+ (1,0) [0|100] "%" VCU
 SG_ Cmd_Engage : 27|1@1+ (1,0) [0|1] "" VCU
 SG_ Cmd_Gear : 28|3@1+ (1,0) [0|7] "" VCU
 SG_ Cmd_Reset : 31|1@1+ (1,0) [0|1] "" VCU
 SG_ Cmd_Mode : 32|2@1+ (1,0) [0|3] "" VCU
 SG_ Cmd_SteerMode : 34|2@1+ (1,0) [0|3] "" VCU
 SG_ Cmd_Alive : 36|4@1+ (1,0) [0|15] "" VCU
 SG_ Cmd_Xor : 40|8@1+ (1,0) [0|255] "" VCU
"#;

/// Sixteen bytes (a CAN FD frame): the shuttle's layout with a reserved tail.
const FD_SIXTEEN_BYTES: &str = r#"
BO_ 1280 Shuttle_Cmd: 16 ADS
 SG_ Cmd_Steer : 7|16@0- (0.01,0) [-30|30] "deg" VCU
 SG_ Cmd_Speed : 23|16@0+ (0.001,0) [0|12] "m/s" VCU
 SG_ Cmd_Brake : 32|7@1+ (1,0) [0|100] "%" VCU
 SG_ Cmd_Engage : 39|1@1+ (1,0) [0|1] "" VCU
 SG_ Cmd_Gear : 40|3@1+ (1,0) [0|7] "" VCU
 SG_ Cmd_Mode : 43|2@1+ (1,0) [0|3] "" VCU
 SG_ Cmd_Reset : 45|1@1+ (1,0) [0|1] "" VCU
 SG_ Cmd_SteerMode : 46|2@1+ (1,0) [0|3] "" VCU
 SG_ Cmd_Reserved : 64|56@1+ (1,0) [0|0] "" VCU
 SG_ Cmd_Alive : 120|4@1+ (1,0) [0|15] "" VCU
 SG_ Cmd_Xor : 48|8@1+ (1,0) [0|255] "" VCU
"#;

/// The command frame's length on the wire (to show a layout really differs).
fn command_len<W: AdsWire>(vehicle: &mut Vehicle<W>) -> usize {
    vehicle
        .wire
        .command_frame(&AdsCommand::default(), 0)
        .unwrap()
        .data()
        .len()
}

/// A network with bus A and bus B, an ADS computer on each, and the supervisor on both.
struct Rig<W: AdsWire + VehicleWire> {
    net: Network,
    ads: [NodeHandle<Ads<W>>; 2],
    supervisor: NodeHandle<Supervisor<W>>,
    cycle: Duration,
    /// Watchdog changes, at the end of the cycle they happened in (ms).
    log: Vec<(u64, Watchdog)>,
}

/// What each ADS computer sends in one cycle.
#[derive(Clone, Copy, PartialEq)]
enum Copy {
    Same,
    Silent,
    /// A different speed on this bus.
    Different,
}

impl<W: AdsWire + VehicleWire + Clone + 'static> Rig<W> {
    fn new(mut vehicle: Vehicle<W>) -> Rig<W> {
        let mut net = Network::new();
        let fd = command_len(&mut vehicle) > 8;
        let a = net.add_bus("bus A", 500_000, fd.then_some(2_000_000));
        let b = net.add_bus("bus B", 500_000, fd.then_some(2_000_000));
        let cycle = vehicle.supervisor.cycle;
        let config = SupervisorConfig {
            redundancy: Some(Redundancy::for_cycle(cycle)),
            ..vehicle.supervisor
        };
        let ads = [(); 2].map(|()| net.add_node(Ads::with_wire(vehicle.ads, vehicle.wire.clone())));
        let supervisor = net.add_node(Supervisor::with_wire(config, vehicle.wire.clone()));
        net.wire(ads[0], Port::MAIN, a).unwrap();
        net.wire(ads[1], Port::MAIN, b).unwrap();
        net.wire(supervisor, Supervisor::<W>::PORT_A, a).unwrap();
        net.wire(supervisor, Supervisor::<W>::PORT_B, b).unwrap();
        Rig {
            net,
            ads,
            supervisor,
            cycle,
            log: Vec::new(),
        }
    }

    fn now(&self) -> Timestamp {
        self.net.now()
    }

    fn supervisor(&self) -> &Supervisor<W> {
        self.net.node(self.supervisor).unwrap()
    }

    /// One command cycle: each ADS computer is given its command (or is cut off), then the
    /// network runs for a cycle in steps of a millisecond, the vehicle's speed following the
    /// actuators.
    fn cycle(&mut self, a: Copy, b: Copy, engage: bool) {
        let now = self.now();
        for (i, copy) in [a, b].into_iter().enumerate() {
            let velocity = if copy == Copy::Different { 3.0 } else { 2.0 };
            let command = AdsCommand {
                velocity,
                gear: Gear::Drive,
                mode: ControlMode::Autonomous,
                engage,
                ..AdsCommand::default()
            };
            let ads = self.ads[i];
            assert!(self.net.node_mut(ads).unwrap().set_command(now, command));
            self.net.drop_output(ads, copy == Copy::Silent);
        }
        let steps = u32::try_from(self.cycle.as_millis()).unwrap();
        for _ in 0..steps {
            let before = self.supervisor().watchdog();
            self.net.run_for(Duration::from_millis(1));
            let now = self.now();
            let after = self.supervisor().watchdog();
            if after != before {
                self.log.push((now.as_nanos() / 1_000_000, after));
            }
            let act = self.supervisor().actuators(now);
            let speed = common::plant_speed(&act);
            let mut supervisor = self.net.node_mut(self.supervisor).unwrap();
            supervisor.set_feedback(speed, 0.0);
        }
    }

    /// Through the recovery run and an engage: autonomous, watchdog normal.
    fn engaged(vehicle: Vehicle<W>) -> Rig<W> {
        let mut rig = Rig::new(vehicle);
        for _ in 0..12 {
            rig.cycle(Copy::Same, Copy::Same, false);
        }
        rig.cycle(Copy::Same, Copy::Same, true);
        rig.cycle(Copy::Same, Copy::Same, false);
        assert_eq!(rig.supervisor().mode(), ControlMode::Autonomous);
        assert_eq!(rig.supervisor().watchdog(), Watchdog::Normal);
        rig.log.clear();
        rig
    }
}

fn cycle_ms<W: AdsWire + VehicleWire>(rig: &Rig<W>) -> u64 {
    u64::try_from(rig.cycle.as_millis()).unwrap()
}

fn agreeing_copies_are_taken_once<W: AdsWire + VehicleWire + Clone + 'static>(vehicle: Vehicle<W>) {
    let rig = Rig::engaged(vehicle);
    let stats = rig.supervisor().stats();
    // 14 cycles, each command taken once although it came twice; none refused.
    assert_eq!(stats.accepted, 14, "{stats:?}");
    assert_eq!(stats.rejected(), 0, "{stats:?}");
    assert_eq!(rig.supervisor().degraded(), None);
}

fn one_bus_silent_degrades<W: AdsWire + VehicleWire + Clone + 'static>(vehicle: Vehicle<W>) {
    let mut rig = Rig::engaged(vehicle);
    for _ in 0..10 {
        rig.cycle(Copy::Same, Copy::Silent, false);
    }
    // B's last copy times out after a cycle and a half: until then A's copy waits for its
    // partner (the watchdog holds at most), then A alone is accepted in degraded mode.
    assert_eq!(rig.supervisor().degraded(), Some(Channel::A));
    assert_eq!(rig.supervisor().watchdog(), Watchdog::Normal);
    assert!(
        rig.log
            .iter()
            .all(|(_, w)| matches!(w, Watchdog::Holding { .. } | Watchdog::Normal)),
        "{:?}",
        rig.log
    );
    let act = rig.supervisor().actuators(rig.now());
    assert!(
        act.ads_in_control && act.velocity == 2.0 && act.warning,
        "{act:?}"
    );
    // B comes back: agreement again, degraded cleared.
    for _ in 0..3 {
        rig.cycle(Copy::Same, Copy::Same, false);
    }
    assert_eq!(rig.supervisor().degraded(), None);
    // The other way round: A lost, B carries on.
    for _ in 0..10 {
        rig.cycle(Copy::Silent, Copy::Same, false);
    }
    assert_eq!(rig.supervisor().degraded(), Some(Channel::B));
    assert_eq!(rig.supervisor().watchdog(), Watchdog::Normal);
}

fn both_buses_silent_brake<W: AdsWire + VehicleWire + Clone + 'static>(vehicle: Vehicle<W>) {
    let mut rig = Rig::engaged(vehicle);
    for _ in 0..7 {
        rig.cycle(Copy::Silent, Copy::Silent, false);
    }
    assert_eq!(rig.supervisor().watchdog(), Watchdog::FullBraking);
    let first_brake = rig
        .log
        .iter()
        .find(|(_, w)| *w == Watchdog::FullBraking)
        .unwrap()
        .0;
    let holding = rig.log.first().unwrap().0;
    // The cascade runs as with one bus: one missed cycle holds, the fifth brakes.
    assert_eq!(first_brake - holding, 4 * cycle_ms(&rig));
    let act = rig.supervisor().actuators(rig.now());
    assert!(act.brake == 100.0 && !act.steering_enabled, "{act:?}");
}

fn disagreeing_copies_brake_at_once<W: AdsWire + VehicleWire + Clone + 'static>(
    vehicle: Vehicle<W>,
) {
    let mut rig = Rig::engaged(vehicle);
    let start = rig.now().as_nanos() / 1_000_000;
    rig.cycle(Copy::Same, Copy::Different, false);
    assert_eq!(rig.supervisor().watchdog(), Watchdog::FullBraking);
    assert_eq!(rig.supervisor().stats().disagreements, 1);
    // Within a couple of milliseconds of the copies' arrival.
    let (at, _) = rig
        .log
        .iter()
        .find(|(_, w)| *w == Watchdog::FullBraking)
        .unwrap();
    assert!(*at <= start + 2, "{at} vs {start}");
    let act = rig.supervisor().actuators(rig.now());
    assert!(act.brake == 100.0 && !act.steering_enabled, "{act:?}");
    // Latched: agreeing copies afterwards need the recovery run and a re-engage.
    for _ in 0..3 {
        rig.cycle(Copy::Same, Copy::Same, false);
    }
    assert!(matches!(
        rig.supervisor().watchdog(),
        Watchdog::Recovering { .. }
    ));
}

/// How the hand-fed copies come: 40 cycles, engaged in cycle 12; from cycle 14 on, each bus's
/// copy late by the next of its milliseconds (in turn, within the cycle: a later copy would be
/// a missed one), bus B silent from cycle `b_cycles`, and its speed `b_speed`.
struct Plan<'a> {
    a_late_ms: &'a [u64],
    b_late_ms: &'a [u64],
    b_cycles: u64,
    b_speed: f64,
    /// The command's speed changes every cycle (by bus B's `b_speed - 2.0` more on B).
    ramp: bool,
}

impl Plan<'_> {
    const CYCLES: u64 = 40;

    /// Both buses on time, carrying the same command throughout.
    const STEADY: Plan<'static> = Plan {
        a_late_ms: &[0],
        b_late_ms: &[0],
        b_cycles: u64::MAX,
        b_speed: 2.0,
        ramp: false,
    };

    /// The speed commanded in cycle `k` on bus A.
    fn speed(&self, k: u64) -> f64 {
        if self.ramp && k >= 14 {
            1.0 + 0.25 * f64::from(u32::try_from(k % 8).unwrap())
        } else {
            2.0
        }
    }
}

/// The supervisor alone, its command frames put in by hand at the instants `plan` says (as
/// loaded ADS computers send them). Returns the supervisor at the end, the watchdog's changes
/// with the cycle they happened in, and the end's time.
fn hand_fed<W: AdsWire + VehicleWire + Clone + 'static>(
    mut vehicle: Vehicle<W>,
    plan: &Plan,
) -> (Supervisor<W>, Vec<(u64, Watchdog)>, Timestamp) {
    let cycle = vehicle.supervisor.cycle;
    let cycle_ms = u64::try_from(cycle.as_millis()).unwrap();
    let config = SupervisorConfig {
        redundancy: Some(Redundancy::for_cycle(cycle)),
        ..vehicle.supervisor
    };
    let mut supervisor = Supervisor::with_wire(config, vehicle.wire.clone());
    let mut log = Vec::new();
    let late = |k: u64, table: &[u64]| {
        if k >= 14 {
            table[usize::try_from(k).unwrap() % table.len()]
        } else {
            0
        }
    };
    let mut frame = |k: u64, velocity: f64| {
        let command = AdsCommand {
            velocity,
            gear: Gear::Drive,
            mode: ControlMode::Autonomous,
            engage: k == 12,
            ..AdsCommand::default()
        };
        vehicle.wire.command_frame(&command, k).unwrap()
    };
    let frames: Vec<_> = (0..Plan::CYCLES)
        .map(|k| {
            let b_more = if k >= 14 { plan.b_speed - 2.0 } else { 0.0 };
            (frame(k, plan.speed(k)), frame(k, plan.speed(k) + b_more))
        })
        .collect();
    // Each copy at its cycle's start plus its lateness (more than a cycle, too).
    let arrival = |k: u64, table: &[u64]| k * cycle_ms + late(k, table);
    for t in 0..Plan::CYCLES * cycle_ms {
        let k = t / cycle_ms;
        let now = Timestamp::from_millis(t);
        let before = supervisor.watchdog();
        for (j, (frame_a, frame_b)) in (0..).zip(&frames) {
            if arrival(j, plan.b_late_ms) == t && j < plan.b_cycles {
                supervisor.on_frame(now, Channel::B.port(), frame_b);
            }
            if arrival(j, plan.a_late_ms) == t {
                supervisor.on_frame(now, Channel::A.port(), frame_a);
            }
        }
        supervisor.poll(now, &mut |_, _| {});
        if supervisor.watchdog() != before {
            log.push((k, supervisor.watchdog()));
        }
        let act = supervisor.actuators(now);
        let speed = common::plant_speed(&act);
        supervisor.set_feedback(speed, 0.0);
    }
    (
        supervisor,
        log,
        Timestamp::from_millis(Plan::CYCLES * cycle_ms),
    )
}

/// Losing bus B costs no more than a cycle or two of holding, also while A's copies come up to
/// 12 ms late: the vehicle never decelerates for it, let alone brakes. (A's copies used to wait
/// for B's partner copy until B's last copy was three cycles old, so a bus loss alone held the
/// vehicle for three cycles, and a late copy on A on top of it braked the vehicle in full.)
fn losing_one_bus_holds_at_most_while_the_other_is_late<
    W: AdsWire + VehicleWire + Clone + 'static,
>(
    vehicle: Vehicle<W>,
) {
    for lost_at in 16..21 {
        let (supervisor, log, end) = hand_fed(
            vehicle.clone(),
            &Plan {
                b_cycles: lost_at,
                a_late_ms: &[0, 3, 12, 8, 1],
                ..Plan::STEADY
            },
        );
        let after_engage: Vec<_> = log.iter().filter(|(k, _)| *k > 13).collect();
        assert!(
            after_engage
                .iter()
                .all(|(_, w)| matches!(w, Watchdog::Holding { .. } | Watchdog::Normal)),
            "B lost after cycle {lost_at}: {after_engage:?}"
        );
        assert_eq!(supervisor.mode(), ControlMode::Autonomous);
        assert_eq!(supervisor.degraded(), Some(Channel::A));
        let act = supervisor.actuators(end);
        assert!(
            act.ads_in_control && act.velocity == 2.0 && act.warning,
            "{act:?}"
        );
    }
    // A's copies late by 18 ms every other cycle (39 ms apart, then 1 ms), with B lost: at most
    // slowing, never braking.
    let b_lost = Plan {
        b_cycles: 16,
        a_late_ms: &[0, 18],
        ..Plan::STEADY
    };
    let (supervisor, log, _) = hand_fed(vehicle, &b_lost);
    assert!(
        log.iter()
            .filter(|(k, _)| *k > 13)
            .all(|(_, w)| !matches!(w, Watchdog::FullBraking | Watchdog::Recovering { .. })),
        "{log:?}"
    );
    assert_eq!(supervisor.mode(), ControlMode::Autonomous, "{log:?}");
}

/// The copies of one command (one rolling counter) are compared however far apart they come:
/// bus B's computer 8–15 ms behind A's (each command taken when its second copy comes), the copies equal → each command taken once, not
/// degraded. (Copies were paired by arrival within 5 ms, so two computers a few milliseconds
/// out of step braked a vehicle that either alone would have driven, and a copy 15 ms late
/// met the other bus's next command within the window and counted as a disagreement.) The
/// same copies at two speeds are a disagreement however far apart: full braking.
fn copies_of_one_command_are_compared_however_far_apart<
    W: AdsWire + VehicleWire + Clone + 'static,
>(
    vehicle: Vehicle<W>,
) {
    let in_step = Plan {
        // 8 ms late first (cycle 14), so that no command comes more than a cycle and a half
        // after the one before (the watchdog would hold, rightly).
        b_late_ms: &[15, 11, 8],
        ..Plan::STEADY
    };
    let (supervisor, log, end) = hand_fed(vehicle.clone(), &in_step);
    assert!(log.iter().all(|(k, _)| *k <= 13), "{log:?}");
    assert_eq!(supervisor.watchdog(), Watchdog::Normal);
    assert_eq!(supervisor.mode(), ControlMode::Autonomous);
    assert_eq!(supervisor.degraded(), None);
    let stats = supervisor.stats();
    assert_eq!(stats.accepted, Plan::CYCLES, "{stats:?}");
    assert_eq!(stats.rejected(), 0, "{stats:?}");
    let act = supervisor.actuators(end);
    assert!(
        act.ads_in_control && act.velocity == 2.0 && !act.warning,
        "{act:?}"
    );
    // B's copies as late, at another speed: the first one brakes.
    let differing = Plan {
        b_speed: 3.0,
        ..in_step
    };
    let (supervisor, log, _) = hand_fed(vehicle, &differing);
    assert_eq!(supervisor.watchdog(), Watchdog::FullBraking, "{log:?}");
    assert_eq!(
        log.iter().find(|(k, _)| *k >= 14),
        Some(&(14, Watchdog::FullBraking))
    );
    assert!(supervisor.stats().disagreements > 0);
    assert_ne!(supervisor.command().map(|c| c.velocity), Some(3.0));
}

/// A bus more than a cycle behind the other (its ADS computer a cycle or two late, or a
/// gateway holding its frames): each of its copies comes after the other bus's next command.
/// Within the timeout, each command is still compared, and taken when its second copy comes;
/// over it, the late bus's copies come stale and the vehicle drives on the other bus's in
/// degraded mode, the late copies still checked against them — copies at another speed brake.
/// So up to seven cycles behind (the copies the voter keeps) and less than half the counter's
/// range (past which a copy behind cannot be told from one ahead). (The vehicle braked in full:
/// first for a bus more than a cycle behind, a copy waiting for a partner the other bus had
/// already replaced; then for a bus three cycles behind, whose copies' partners were no longer
/// looked for.)
fn a_bus_more_than_a_cycle_behind_is_compared_late_or_left_out<
    W: AdsWire + VehicleWire + Clone + 'static,
>(
    vehicle: Vehicle<W>,
) {
    let cycle_ms = u64::try_from(vehicle.supervisor.cycle.as_millis()).unwrap();
    let timeout_ms = cycle_ms + cycle_ms / 2;
    let half_range = 1u64 << (vehicle.wire.command_counter_bits() - 1);
    let within = [cycle_ms + cycle_ms / 4];
    let over = [timeout_ms + cycle_ms / 4];
    let beyond_pairing_by_time = [3 * cycle_ms + cycle_ms / 4];
    let furthest_kept = [(half_range - 1).min(7) * cycle_ms + cycle_ms / 4];
    for (late, degraded) in [
        (&within, None),
        (&over, Some(Channel::A)),
        (&beyond_pairing_by_time, Some(Channel::A)),
        (&furthest_kept, Some(Channel::A)),
    ] {
        assert!(late[0] > cycle_ms);
        let plan = Plan {
            b_late_ms: late,
            ..Plan::STEADY
        };
        let (supervisor, log, end) = hand_fed(vehicle.clone(), &plan);
        // At most a hold while the lateness begins (the gap it makes), then normal.
        assert!(log.iter().all(|(k, _)| *k <= 17), "{late:?}: {log:?}");
        assert_eq!(supervisor.watchdog(), Watchdog::Normal, "{late:?}");
        assert_eq!(supervisor.mode(), ControlMode::Autonomous, "{late:?}");
        assert_eq!(supervisor.degraded(), degraded, "{late:?}");
        let stats = supervisor.stats();
        assert_eq!(stats.rejected(), 0, "{late:?}: {stats:?}");
        // Compared: the last command's second copy comes after the end. Left out: each is
        // taken as it comes.
        let taken = if degraded.is_some() {
            Plan::CYCLES
        } else {
            Plan::CYCLES - 1
        };
        assert_eq!(stats.accepted, taken, "{late:?}: {stats:?}");
        let act = supervisor.actuators(end);
        assert!(
            act.ads_in_control && act.velocity == 2.0 && act.warning == degraded.is_some(),
            "{late:?}: {act:?}"
        );
        // The late bus at another speed: a disagreement, however late its copies.
        let (supervisor, log, _) = hand_fed(
            vehicle.clone(),
            &Plan {
                b_speed: 3.0,
                ..plan
            },
        );
        assert_eq!(
            supervisor.watchdog(),
            Watchdog::FullBraking,
            "{late:?}: {log:?}"
        );
        assert!(supervisor.stats().disagreements > 0, "{late:?}");
        assert_ne!(supervisor.command().map(|c| c.velocity), Some(3.0));
    }
}

/// `plan` hand-fed: after the engage the watchdog never changes, no command is refused, and
/// the ADS is in control at the end. The supervisor, and the plan's label for messages.
fn drives_on_undisturbed<W: AdsWire + VehicleWire + Clone + 'static>(
    vehicle: Vehicle<W>,
    plan: &Plan,
) -> (Supervisor<W>, String) {
    let (supervisor, log, end) = hand_fed(vehicle, plan);
    let label = format!("A {:?}, B {:?}", plan.a_late_ms, plan.b_late_ms);
    assert!(log.iter().all(|(k, _)| *k < 14), "{label}: {log:?}");
    assert_eq!(supervisor.watchdog(), Watchdog::Normal, "{label}");
    let stats = supervisor.stats();
    assert_eq!(stats.rejected(), 0, "{label}: {stats:?}");
    assert!(supervisor.actuators(end).ads_in_control, "{label}");
    (supervisor, label)
}

/// Jitter between the buses, up to more than a cycle: each command waits for its second copy
/// (or for the other bus's last copy to go stale), and a vote pending is no missed command —
/// the watchdog stays normal throughout. (It reported a missed cycle every cycle or two, for
/// a millisecond, when a copy waited past a cycle and a half after the last command taken.)
fn jitter_between_the_buses_is_no_missed_command<W: AdsWire + VehicleWire + Clone + 'static>(
    vehicle: Vehicle<W>,
) {
    let cycle_ms = u64::try_from(vehicle.supervisor.cycle.as_millis()).unwrap();
    let (quarter, five_eighths) = (cycle_ms / 4, cycle_ms * 5 / 8);
    let patterns: [(&[u64], &[u64]); 4] = [
        (&[0], &[quarter, cycle_ms + quarter]),
        (&[quarter, cycle_ms + quarter], &[0]),
        (&[0, five_eighths], &[five_eighths, 0]),
        (&[0], &[3 * quarter, quarter, 3 * cycle_ms / 2 - 2]),
    ];
    for (a_late_ms, b_late_ms) in patterns {
        let plan = Plan {
            a_late_ms,
            b_late_ms,
            ..Plan::STEADY
        };
        let (supervisor, label) = drives_on_undisturbed(vehicle.clone(), &plan);
        let stats = supervisor.stats();
        assert!(stats.accepted >= Plan::CYCLES - 1, "{label}: {stats:?}");
    }
    // Copies that keep waiting are counted from the first: a bus half the counter's range
    // behind or more (its copies cannot be told from copies ahead) brings copies that never
    // pair, and the cascade runs to full braking.
    let half_range = 1u64 << (vehicle.wire.command_counter_bits() - 1);
    if half_range + 2 < Plan::CYCLES / 3 {
        let far = [(half_range + 2) * cycle_ms];
        let plan = Plan {
            b_late_ms: &far,
            b_speed: 3.0,
            ..Plan::STEADY
        };
        let (supervisor, log, _) = hand_fed(vehicle, &plan);
        assert_eq!(supervisor.watchdog(), Watchdog::FullBraking, "{log:?}");
        assert_ne!(supervisor.command().map(|c| c.velocity), Some(3.0));
    }
}

/// A command that changes every cycle is compared with its own copy whichever bus brings it
/// first: never with the other bus's copy of an earlier command that had the same counter. (With
/// a 1-bit counter the counter comes round every second cycle, within the two timeouts over
/// which copies were paired: each new command met the other bus's copy of the command two
/// cycles before, and the vehicle braked in full at the first change of speed.)
fn a_changing_command_is_compared_with_its_own_copy<W: AdsWire + VehicleWire + Clone + 'static>(
    vehicle: Vehicle<W>,
) {
    let cycle_ms = u64::try_from(vehicle.supervisor.cycle.as_millis()).unwrap();
    let (early, late) = ([0], [cycle_ms / 4]);
    for (a_late_ms, b_late_ms) in [(&early, &late), (&late, &early)] {
        let plan = Plan {
            a_late_ms,
            b_late_ms,
            ramp: true,
            ..Plan::STEADY
        };
        let (supervisor, label) = drives_on_undisturbed(vehicle.clone(), &plan);
        let stats = supervisor.stats();
        assert_eq!(stats.accepted, Plan::CYCLES, "{label}: {stats:?}");
        // The last command's speed, as its signal's resolution gives it back.
        let taken = supervisor.command().unwrap().velocity;
        assert!(
            (taken - plan.speed(Plan::CYCLES - 1)).abs() < 0.03,
            "{label}: {taken}"
        );
        // The same, bus B's copies faster by 0.5 m/s: the first changed command brakes.
        let (supervisor, log, _) = hand_fed(
            vehicle.clone(),
            &Plan {
                b_speed: 2.5,
                ..plan
            },
        );
        assert_eq!(
            supervisor.watchdog(),
            Watchdog::FullBraking,
            "{label}: {log:?}"
        );
        assert_eq!(
            log.iter().find(|(k, _)| *k >= 14),
            Some(&(14, Watchdog::FullBraking)),
            "{label}"
        );
    }
}

/// The shuttle's six-byte command with a `bits`-bit counter.
fn six_bytes_with_counter(bits: u32) -> Vehicle<ProfileWire> {
    let block = SIX_BYTES.replace(
        "Cmd_Alive : 36|4@1+ (1,0) [0|15]",
        &format!("Cmd_Alive : 36|{bits}@1+ (1,0) [0|{}]", (1 << bits) - 1),
    );
    let mut vehicle = by_profile(&shuttle_with(&block));
    assert_eq!(
        vehicle.wire.command_counter_bits(),
        u8::try_from(bits).unwrap()
    );
    assert_eq!(command_len(&mut vehicle), 6);
    vehicle
}

/// Counters that come round within a few cycles (opendbc's 2-bit counters; a 1-bit toggle):
/// the scenarios that do not need a counter's range of several cycles.
mod short_counters {
    use super::*;

    /// The scenarios for a `bits`-bit counter.
    fn suite(bits: u32) {
        let vehicle = six_bytes_with_counter(bits);
        agreeing_copies_are_taken_once(vehicle.clone());
        one_bus_silent_degrades(vehicle.clone());
        both_buses_silent_brake(vehicle.clone());
        disagreeing_copies_brake_at_once(vehicle.clone());
        a_changing_command_is_compared_with_its_own_copy(vehicle);
    }

    #[test]
    fn two_bit_counter() {
        suite(2);
    }

    #[test]
    fn one_bit_counter() {
        suite(1);
    }
}

/// Each scenario for each wire.
macro_rules! for_every_wire {
    ($($scenario:ident),* $(,)?) => {
        mod reference_wire {
            use super::*;
            $(#[test] fn $scenario() { super::$scenario(reference_wire()) })*
        }
        mod reference_tug_profile {
            use super::*;
            fn vehicle() -> Vehicle<ProfileWire> {
                by_profile(&bywire_tug::profile().unwrap())
            }
            $(#[test] fn $scenario() { super::$scenario(vehicle()) })*
        }
        mod six_byte_command {
            use super::*;
            fn vehicle() -> Vehicle<ProfileWire> {
                let mut v = by_profile(&shuttle_with(SIX_BYTES));
                assert_eq!(command_len(&mut v), 6);
                v
            }
            $(#[test] fn $scenario() { super::$scenario(vehicle()) })*
        }
        mod fd_command {
            use super::*;
            fn vehicle() -> Vehicle<ProfileWire> {
                let mut v = by_profile(&shuttle_with(FD_SIXTEEN_BYTES));
                assert_eq!(command_len(&mut v), 16);
                v
            }
            $(#[test] fn $scenario() { super::$scenario(vehicle()) })*
        }
    };
}

for_every_wire!(
    agreeing_copies_are_taken_once,
    one_bus_silent_degrades,
    both_buses_silent_brake,
    disagreeing_copies_brake_at_once,
    losing_one_bus_holds_at_most_while_the_other_is_late,
    copies_of_one_command_are_compared_however_far_apart,
    a_bus_more_than_a_cycle_behind_is_compared_late_or_left_out,
    jitter_between_the_buses_is_no_missed_command,
    a_changing_command_is_compared_with_its_own_copy,
);
