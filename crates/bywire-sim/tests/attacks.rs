//! The fault tour's attacker on bus 1, with SecOC off and on: what each attack achieves
//! against the plain tug, and that the secured variant refuses and counts it.
#![allow(clippy::unwrap_used)]

use bywire_core::Timestamp;
use bywire_sim::report::SecurityCounts;
use bywire_sim::scenario::Scenario;
use bywire_sim::tug::{SimEvent, Tug};

/// The fault tour to its end, the tug plain or secured.
fn tour(secoc: bool) -> Tug {
    let mut scenario = Scenario::builtin("fault-tour").unwrap();
    scenario.tug.secoc = secoc;
    let mut tug = Tug::new(scenario.params(1, scenario.tug.payload));
    while tug.now() < Timestamp::from_millis(90_000) && !tug.arrived() {
        scenario.step(&mut tug);
    }
    assert!(tug.arrived(), "the route is finished after every attack");
    tug
}

fn at(t: &SimEvent) -> f64 {
    t.t.as_nanos() as f64 / 1e9
}

/// The first event of `kind` starting with `detail` in [from, to).
fn first<'a>(tug: &'a Tug, kind: &str, detail: &str, from: f64, to: f64) -> Option<&'a SimEvent> {
    tug.events
        .iter()
        .find(|e| (from..to).contains(&at(e)) && e.kind == kind && e.detail.starts_with(detail))
}

fn attack_window(tug: &Tug, attack: &str) -> (f64, f64) {
    let start = first(tug, "fault", &format!("Attack({attack})"), 0.0, 1e9).unwrap();
    let end = first(
        tug,
        "fault_cleared",
        &format!("Attack({attack})"),
        at(start),
        1e9,
    )
    .unwrap();
    (at(start), at(end))
}

/// The flood of 0x000 is the same with SecOC or without: bus 1 carries nothing else, the
/// E-stop chain's frames stop, and the chain counts as open — the safe state — while the
/// commands go on over bus 1b alone.
fn assert_flood_ends_in_the_safe_state(tug: &Tug) {
    let (start, end) = attack_window(tug, "Flood");
    let braking = first(tug, "estop", "BrakesApplied", start, end).unwrap();
    // Three 20 ms cycles after the chain's last frame, plus the frame then on its way.
    assert!(at(braking) - start <= 0.065, "{braking:?}");
    assert!(first(tug, "redundancy", "bus 1b alone", start, end).is_some());
    assert!(first(tug, "estop", "Stopped", start, end + 2.0).is_some());
    assert!(tug.attacker().sent() > 1_000);
}

#[test]
fn without_secoc_the_attacks_pass_every_check_but_the_redundant_bus() {
    let tug = tour(false);
    let security = SecurityCounts::of(&tug);
    let stats = tug.ecu().stats();
    // (a) Forged commands pass CRC and counter: the ADS's own are then refused as repeats.
    // Only bus 1b's copy, which the attacker cannot reach, disagrees: the voter brakes fully
    // (a vehicle without the second bus obeys them; see the wire tests). A denial of service.
    for attack in ["ForgeCommands", "ReplayCommands"] {
        let (start, end) = attack_window(&tug, attack);
        let braking = first(&tug, "watchdog", "full_braking", start, end).unwrap();
        assert!(at(braking) - start <= 0.025, "{attack}: {braking:?}");
    }
    assert!(stats.disagreements >= 80, "{stats:?}");
    assert!(stats.repeated >= 80, "{stats:?}");
    assert_eq!(stats.authentication, 0);
    assert_eq!(security.foreign_commands, 0, "the voter took none");
    // (c) A forged speed toward the ADS is taken for a second: nothing on the ADS side can
    // tell it from the vehicle's.
    assert!(security.false_speeds >= 45, "{security:?}");
    assert_eq!(security.ads_authentication, 0);
    let (start, end) = attack_window(&tug, "ForgeState");
    assert!(first(&tug, "watchdog", "", start, end).is_none());
    assert_flood_ends_in_the_safe_state(&tug);
}

#[test]
fn with_secoc_forgeries_and_replays_are_refused_and_counted_and_the_tug_drives_on() {
    let tug = tour(true);
    let security = SecurityCounts::of(&tug);
    let stats = tug.ecu().stats();
    assert!(security.secoc);
    // (a), (b): every forged and replayed command refused by its MAC or its freshness; the
    // watchdog never notices, the vehicle drives on.
    for attack in ["ForgeCommands", "ReplayCommands", "ForgeState"] {
        let (start, end) = attack_window(&tug, attack);
        assert!(
            first(&tug, "watchdog", "", start, end + 0.1).is_none(),
            "{attack}: {:?}",
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
