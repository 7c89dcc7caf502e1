//! The redundancy rows of the fault matrix: the ADS sends every command on two bit-timed
//! buses; the supervisor votes. One bus silent → degraded, still driving; both silent → the
//! watchdog cascade; copies that disagree → full braking at once.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::time::Duration;

use bywire_bus::sim::SimBus;
use bywire_core::{Frame, Id, Timestamp};
use bywire_vehicle::redundancy::Channel;
use bywire_vehicle::reference_tug::{self, AdsToVehicleControl, ControlMode};
use bywire_vehicle::supervisor::{Redundancy, Supervisor, SupervisorConfig, Watchdog};

fn ms(t: u64) -> Timestamp {
    Timestamp::from_millis(t)
}

fn command(counter: u8, velocity: f64, engage: bool) -> Frame {
    let mut m = AdsToVehicleControl::default();
    m.set_velocity_cmd(velocity).unwrap();
    m.set_gear_cmd_raw(3);
    m.set_control_mode_cmd_raw(ControlMode::Autonomous as u64);
    m.set_engage_request_raw(u64::from(engage));
    m.set_heartbeat_counter_raw(u64::from(counter & 0x0F));
    let mut p = m.0;
    reference_tug::seal(AdsToVehicleControl::ID, &mut p);
    Frame::classic(Id::standard(AdsToVehicleControl::ID).unwrap(), &p).unwrap()
}

/// What each bus carries in one cycle.
#[derive(Clone, Copy, PartialEq)]
enum Copy {
    Same,
    Silent,
    /// A different velocity on this bus.
    Different,
}

struct Rig {
    buses: [SimBus; 2],
    ads: [usize; 2],
    vcu: [usize; 2],
    supervisor: Supervisor,
    now: u64,
    counter: u8,
    log: Vec<(u64, Watchdog)>,
}

impl Rig {
    fn new() -> Rig {
        let mut buses = [SimBus::new(500_000, None), SimBus::new(500_000, None)];
        let ads = [buses[0].add_node(), buses[1].add_node()];
        let vcu = [buses[0].add_node(), buses[1].add_node()];
        let config = SupervisorConfig {
            redundancy: Some(Redundancy {
                timeout: Duration::from_millis(50),
                skew: Duration::from_millis(5),
            }),
            ..SupervisorConfig::default()
        };
        Rig {
            buses,
            ads,
            vcu,
            supervisor: Supervisor::new(config),
            now: 0,
            counter: 0,
            log: Vec::new(),
        }
    }

    /// One 20 ms cycle: the ADS sends on each bus as told, then time runs.
    fn cycle(&mut self, a: Copy, b: Copy, engage: bool) {
        for (bus, copy) in [a, b].into_iter().enumerate() {
            let velocity = if copy == Copy::Different { 3.0 } else { 2.0 };
            if copy != Copy::Silent {
                let f = command(self.counter, velocity, engage);
                self.buses[bus].submit(self.ads[bus], f, ms(self.now));
            }
        }
        self.counter = self.counter.wrapping_add(1);
        let end = self.now + 20;
        while self.now < end {
            self.now += 1;
            let now = ms(self.now);
            let before = self.supervisor.watchdog();
            for (bus, channel) in [(0, Channel::A), (1, Channel::B)] {
                self.buses[bus].advance(now);
                while let Some(r) = self.buses[bus].receive(self.vcu[bus]) {
                    self.supervisor
                        .on_frame_from(r.timestamp, channel, &r.frame);
                }
            }
            self.supervisor.poll(now, &mut |_| {});
            if self.supervisor.watchdog() != before {
                self.log.push((self.now, self.supervisor.watchdog()));
            }
            let a = self.supervisor.actuators(now);
            self.supervisor
                .set_feedback(if a.brake > 0.0 { 0.0 } else { a.velocity }, 0.0);
        }
    }

    fn engaged() -> Rig {
        let mut rig = Rig::new();
        for _ in 0..12 {
            rig.cycle(Copy::Same, Copy::Same, false);
        }
        rig.cycle(Copy::Same, Copy::Same, true);
        rig.cycle(Copy::Same, Copy::Same, false);
        assert_eq!(rig.supervisor.mode(), ControlMode::Autonomous);
        assert_eq!(rig.supervisor.watchdog(), Watchdog::Normal);
        rig.log.clear();
        rig
    }
}

#[test]
fn both_buses_agreeing_accept_each_command_once() {
    let rig = Rig::engaged();
    // 14 cycles, each command taken once although it came twice.
    assert_eq!(rig.supervisor.stats().accepted, 14);
    assert_eq!(rig.supervisor.degraded(), None);
}

#[test]
fn one_redundant_bus_silent_drives_on_degraded() {
    let mut rig = Rig::engaged();
    let accepted = rig.supervisor.stats().accepted;
    for _ in 0..10 {
        rig.cycle(Copy::Same, Copy::Silent, false);
    }
    // B's last copy times out after 50 ms: until then A's copies wait for a partner (two
    // cycles held), then A alone is accepted in degraded mode.
    assert_eq!(rig.supervisor.degraded(), Some(Channel::A));
    assert_eq!(rig.supervisor.watchdog(), Watchdog::Normal);
    let levels: Vec<Watchdog> = rig.log.iter().map(|(_, w)| *w).collect();
    assert!(
        levels
            .iter()
            .all(|w| matches!(w, Watchdog::Holding { .. } | Watchdog::Normal)),
        "{levels:?}"
    );
    assert!(rig.supervisor.stats().accepted >= accepted + 7);
    let a = rig.supervisor.actuators(ms(rig.now));
    assert!(a.ads_in_control && a.velocity == 2.0 && a.warning);
    // B comes back: agreement again, degraded cleared.
    for _ in 0..3 {
        rig.cycle(Copy::Same, Copy::Same, false);
    }
    assert_eq!(rig.supervisor.degraded(), None);
}

#[test]
fn both_redundant_buses_silent_run_the_watchdog_cascade() {
    let mut rig = Rig::engaged();
    for _ in 0..6 {
        rig.cycle(Copy::Silent, Copy::Silent, false);
    }
    assert_eq!(rig.supervisor.watchdog(), Watchdog::FullBraking);
    let first_brake = rig
        .log
        .iter()
        .find(|(_, w)| *w == Watchdog::FullBraking)
        .unwrap()
        .0;
    let holding = rig.log.first().unwrap().0;
    // Five and a half cycles after the last command, as with one bus.
    assert_eq!(first_brake - holding, 4 * 20);
}

#[test]
fn redundant_buses_disagreeing_brake_at_once() {
    let mut rig = Rig::engaged();
    let start = rig.now;
    rig.cycle(Copy::Same, Copy::Different, false);
    assert_eq!(rig.supervisor.watchdog(), Watchdog::FullBraking);
    assert_eq!(rig.supervisor.stats().disagreements, 1);
    // Within the cycle it arrived in (both copies on the wire within 1 ms).
    let (at, _) = rig
        .log
        .iter()
        .find(|(_, w)| *w == Watchdog::FullBraking)
        .unwrap();
    assert!(*at <= start + 2, "{at} vs {start}");
    let a = rig.supervisor.actuators(ms(rig.now));
    assert!(a.brake == 100.0 && !a.steering_enabled);
    // Latched: agreeing copies afterwards need the recovery run and a re-engage.
    for _ in 0..3 {
        rig.cycle(Copy::Same, Copy::Same, false);
    }
    assert!(matches!(
        rig.supervisor.watchdog(),
        Watchdog::Recovering { .. }
    ));
}
