//! The fault tour's attacker on bus 1, with SecOC off and on: what each attack achieves
//! against the plain tug, and that the secured variant refuses and counts it.
#![allow(clippy::unwrap_used)]

use bywire_core::Timestamp;
use bywire_sim::attacker::Attack;
use bywire_sim::event::{Happening, SimEvent};
use bywire_sim::fault::Fault;
use bywire_sim::report::SecurityCounts;
use bywire_sim::scenario::Scenario;
use bywire_sim::tug::Tug;
use bywire_vehicle::redundancy::Channel;
use bywire_vehicle::supervisor::{EstopState, Watchdog};

/// The fault tour to its end, the tug plain or secured.
fn tour(secoc: bool) -> Tug {
    let mut scenario = Scenario::builtin("fault-tour").unwrap();
    scenario.tug.secoc = secoc;
    let mut tug = Tug::new(scenario.params(1, scenario.tug.payload)).unwrap();
    while tug.now() < Timestamp::from_millis(90_000) && !tug.arrived() {
        scenario.step(&mut tug);
    }
    assert!(tug.arrived(), "the route is finished after every attack");
    tug
}

fn at(t: &SimEvent) -> f64 {
    t.t.as_nanos() as f64 / 1e9
}

/// The first event that is `what` in [from, to).
fn first(tug: &Tug, what: impl Fn(&Happening) -> bool, from: f64, to: f64) -> Option<&SimEvent> {
    tug.events
        .iter()
        .find(|e| (from..to).contains(&at(e)) && what(&e.what))
}

/// Any change of the watchdog's level.
fn watchdog(what: &Happening) -> bool {
    matches!(what, Happening::Watchdog(_))
}

fn attack_window(tug: &Tug, attack: Attack) -> (f64, f64) {
    let fault = Fault::Attack(attack);
    let start = first(tug, |w| *w == Happening::Fault(fault), 0.0, 1e9).unwrap();
    let cleared = |w: &Happening| *w == Happening::FaultCleared(fault);
    let end = first(tug, cleared, at(start), 1e9).unwrap();
    (at(start), at(end))
}

/// The flood of 0x000 is the same with SecOC or without: bus 1 carries nothing else, the
/// E-stop chain's frames stop, and the chain counts as open — the safe state — while the
/// commands go on over bus 1b alone.
fn assert_flood_ends_in_the_safe_state(tug: &Tug) {
    let (start, end) = attack_window(tug, Attack::Flood);
    let estop = |state| move |w: &Happening| *w == Happening::Estop(state);
    let braking = first(tug, estop(EstopState::BrakesApplied), start, end).unwrap();
    // Three 20 ms cycles after the chain's last frame, plus the frame then on its way.
    assert!(at(braking) - start <= 0.065, "{braking:?}");
    let b_alone = |w: &Happening| *w == Happening::Redundancy(Some(Channel::B));
    assert!(first(tug, b_alone, start, end).is_some());
    assert!(first(tug, estop(EstopState::Stopped), start, end + 2.0).is_some());
    assert!(tug.attacker().unwrap().sent() > 1_000);
}

#[test]
fn without_secoc_the_attacks_pass_every_check_but_the_redundant_bus() {
    let tug = tour(false);
    let security = SecurityCounts::of(&tug);
    let stats = tug.ecu().unwrap().stats();
    // (a) Forged commands pass CRC and counter: the ADS's own are then refused as repeats.
    // Only bus 1b's copy, which the attacker cannot reach, disagrees: the voter brakes fully
    // (a vehicle without the second bus obeys them; see the wire tests). A denial of service.
    for attack in [Attack::ForgeCommands, Attack::ReplayCommands] {
        let (start, end) = attack_window(&tug, attack);
        let full = |w: &Happening| *w == Happening::Watchdog(Watchdog::FullBraking);
        let braking = first(&tug, full, start, end).unwrap();
        assert!(at(braking) - start <= 0.025, "{attack:?}: {braking:?}");
    }
    assert!(stats.disagreements >= 80, "{stats:?}");
    assert!(stats.repeated >= 80, "{stats:?}");
    assert_eq!(stats.authentication, 0);
    assert_eq!(security.foreign_commands, 0, "the voter took none");
    // (c) A forged speed toward the ADS is taken for a second: nothing on the ADS side can
    // tell it from the vehicle's.
    assert!(security.false_speeds >= 45, "{security:?}");
    assert_eq!(security.ads_authentication, 0);
    let (start, end) = attack_window(&tug, Attack::ForgeState);
    assert!(first(&tug, watchdog, start, end).is_none());
    assert_flood_ends_in_the_safe_state(&tug);
}

#[test]
fn with_secoc_forgeries_and_replays_are_refused_and_counted_and_the_tug_drives_on() {
    let tug = tour(true);
    let security = SecurityCounts::of(&tug);
    let stats = tug.ecu().unwrap().stats();
    assert!(security.secoc);
    // (a), (b): every forged and replayed command refused by its MAC or its freshness; the
    // watchdog never notices, the vehicle drives on.
    for attack in [
        Attack::ForgeCommands,
        Attack::ReplayCommands,
        Attack::ForgeState,
    ] {
        let (start, end) = attack_window(&tug, attack);
        assert!(
            first(&tug, watchdog, start, end + 0.1).is_none(),
            "{attack:?}: {:?}",
            tug.events
        );
    }
    assert_eq!(security.foreign_commands, 0);
    // 50 forged and 50 replayed commands, one a cycle for a second each.
    assert!(stats.authentication >= 95, "{stats:?}");
    assert!(security.ecu_mac + security.ecu_stale >= 95, "{security:?}");
    assert!(security.ecu_stale >= 1, "{security:?}");
    // The forgeries never reach the voter; the few disagreements are the flood's, as bus 1
    // comes back (the plain tour has 50 a forging attack on top).
    assert!(stats.disagreements < 20, "{stats:?}");
    // (c): the forged speed refused at the ADS, none taken.
    assert!(security.ads_authentication >= 45, "{security:?}");
    assert_eq!(security.false_speeds, 0);
    assert_flood_ends_in_the_safe_state(&tug);
}

/// The apron loop with bus 1b lost from 5 s, and forged commands on bus 1 from 10 s for a
/// second: with one bus left there is no copy to disagree with.
fn forging_on_one_bus(secoc: bool) -> Tug {
    use std::time::Duration;
    let mut scenario = Scenario::builtin("apron-loop").unwrap();
    scenario.tug.secoc = secoc;
    scenario.events = vec![
        (
            Duration::from_secs(5),
            Fault::RedundantBusLoss,
            Some(Duration::from_secs(10)),
        ),
        (
            Duration::from_secs(10),
            Fault::Attack(Attack::ForgeCommands),
            Some(Duration::from_secs(1)),
        ),
    ];
    let mut tug = Tug::new(scenario.params(1, scenario.tug.payload)).unwrap();
    while tug.now() < Timestamp::from_millis(12_000) {
        scenario.step(&mut tug);
    }
    tug
}

#[test]
fn on_one_bus_the_plain_tug_obeys_forged_commands_and_the_secured_one_refuses_them() {
    let plain = forging_on_one_bus(false);
    let security = SecurityCounts::of(&plain);
    // One a cycle for a second, the forged one taken each time.
    assert!(security.foreign_commands >= 40, "{security:?}");
    assert_eq!(plain.ecu().unwrap().stats().authentication, 0);

    let secured = forging_on_one_bus(true);
    let security = SecurityCounts::of(&secured);
    assert_eq!(security.foreign_commands, 0, "{security:?}");
    assert!(secured.ecu().unwrap().stats().authentication >= 45);
    let (start, end) = attack_window(&secured, Attack::ForgeCommands);
    assert!(first(&secured, watchdog, start, end + 0.1).is_none());
}

/// The apron loop's first 20 s, the tug plain or secured: bus 1's load as the simulation
/// counts it, and as the frames logged on it add up.
fn bus1_load(secoc: bool) -> (f64, f64) {
    use bywire_core::busload::{frame_time_ns, Bitrates};
    let mut scenario = Scenario::builtin("apron-loop").unwrap();
    scenario.tug.secoc = secoc;
    let mut tug = Tug::new(scenario.params(1, scenario.tug.payload)).unwrap();
    while tug.now() < Timestamp::from_millis(20_000) {
        scenario.step(&mut tug);
    }
    let rates = Bitrates {
        nominal: 500_000,
        data: secoc.then_some(bywire_tug::secured::DATA_BITRATE),
    };
    let logged: f64 = tug
        .bus1_log
        .iter()
        .map(|(_, frame)| frame_time_ns(frame, rates))
        .sum();
    (tug.bus_loads()[0], logged / 20e9)
}

#[test]
fn the_secured_command_bus_is_less_loaded_than_the_plain_one() {
    let (plain, plain_logged) = bus1_load(false);
    let (secured, secured_logged) = bus1_load(true);
    // The simulation's count is its frames' time on the bus (a frame still on its way at the
    // end is counted whole by one and not yet logged by the other).
    for (counted, logged) in [(plain, plain_logged), (secured, secured_logged)] {
        assert!((counted - logged).abs() < 0.001, "{counted} vs {logged}");
    }
    // FD with a 2 Mbit/s data phase carries the MAC in less time than the classic payload's
    // 500 kbit/s: the secured bus is at least a third less loaded.
    assert!(secured < plain * 0.67, "secured {secured}, plain {plain}");
    assert!(plain > 0.05 && plain < 0.10, "{plain}");
}
