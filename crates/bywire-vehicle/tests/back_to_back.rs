//! Back-to-back testing: an executable specification of the supervisor's decisions, written
//! from the requirements as a plain table-driven model that shares no code with the
//! implementation, run against the supervisor on random sequences of command cycles (valid
//! commands, missing ones, corrupted checksums, out-of-range setpoints, a driver's input), with
//! proptest shrinking any disagreement to the shortest sequence.
//!
//! Each cycle is 20 ms: the driver's input is set, the cycle's frame (if any) arrives, and
//! 15 ms later the decisions are compared: the watchdog level, the control mode, whether the
//! ADS's command drives the actuators, and what the actuators are told. The CI run takes
//! 2,000 sequences; `BACK_TO_BACK_CASES=1000000` runs the million.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use bywire_core::node::{Node, Port};
use bywire_tug::messages::{AdsToVehicleControl, ControlMode as TugMode};
use bywire_tug::wire::ReferenceWire;
use bywire_vehicle::command::ControlMode;
use bywire_vehicle::supervisor::{Supervisor, SupervisorConfig, Watchdog};
use common::{command, ms, sealed};
use proptest::prelude::*;

/// What one cycle brings.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Sent {
    /// A command: speed (m/s), the engage bit, autonomous (or manual) requested.
    Command {
        velocity: u8,
        engage: bool,
        autonomous: bool,
    },
    /// Nothing this cycle.
    Missing,
    /// A command whose checksum does not match.
    BadChecksum,
    /// A command steering beyond the limit (44° of 40°).
    OutOfRange,
}

#[derive(Debug, Clone, Copy)]
struct Cycle {
    driver: bool,
    sent: Sent,
}

/// The watchdog's levels as the requirements name them.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Level {
    Normal,
    Holding,
    Decelerating,
    FullBraking,
    /// Full braking, valid commands coming: `run` of them so far.
    Recovering(u32),
}

/// The decisions compared after each cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Decisions {
    level: Level,
    autonomous: bool,
    /// The actuators: motors enabled, full brake, the speed setpoint (when following the ADS).
    motors: bool,
    full_brake: bool,
    velocity: Option<f64>,
}

/// The specification, from REQ-E2E-1/2 (checksum, counter), REQ-RNG-1 (range), REQ-TO-1/2
/// (the cascade: 1–2 missed hold, 3–4 decelerate, 5 brake fully; after full braking a run of
/// 10 valid commands and an engage) and REQ-TK-1 (a driver takes over at once).
#[derive(Debug, Default)]
struct Spec {
    /// The counter the sender puts on its next frame.
    next_counter: u8,
    /// The value the receiver's sequence check compares with, and cycles since it was set.
    checked: Option<u8>,
    since_checked: u32,
    /// The counter of the command in force.
    taken_counter: Option<u8>,
    /// A command was ever taken; cycles since the last.
    ever: bool,
    missed: u32,
    level: Option<Level>,
    autonomous: bool,
    engage_bit: bool,
    command: Option<(u8, bool)>,
    driver: bool,
    /// A planted defect: holding for a third missed cycle (the cascade says decelerate).
    planted: bool,
}

impl Spec {
    fn level(&self) -> Level {
        self.level.unwrap_or(Level::FullBraking)
    }

    fn cycle(&mut self, c: Cycle) -> Decisions {
        // A driver's input takes over at once.
        self.driver = c.driver;
        if self.driver {
            self.autonomous = false;
        }
        let mut taken = None;
        if c.sent != Sent::Missing {
            let counter = self.next_counter;
            self.next_counter = (counter + 1) % 16;
            if c.sent != Sent::BadChecksum {
                // The sequence: the next value of a live stream; after 5 silent cycles any
                // value but the one it froze on; a repeat is no news; a jump restarts from it.
                let stale = self.since_checked > 5;
                let in_sequence = match self.checked {
                    None => true,
                    Some(_) if stale => self.taken_counter != Some(counter),
                    Some(last) => (counter + 16 - last) % 16 == 1,
                };
                let repeat = !stale && self.checked == Some(counter);
                if !repeat {
                    self.checked = Some(counter);
                    self.since_checked = 0;
                }
                if in_sequence {
                    if let Sent::Command {
                        velocity,
                        engage,
                        autonomous,
                    } = c.sent
                    {
                        taken = Some((counter, velocity, engage, autonomous));
                    }
                }
            }
        }
        self.since_checked += 1;
        match taken {
            Some((counter, velocity, engage, autonomous)) => {
                let edge = engage && !self.engage_bit;
                self.engage_bit = engage;
                self.taken_counter = Some(counter);
                self.command = Some((velocity, autonomous));
                self.ever = true;
                self.missed = 0;
                self.level = Some(match self.level() {
                    Level::FullBraking => Level::Recovering(1),
                    Level::Recovering(run) if edge && run >= 10 => Level::Normal,
                    Level::Recovering(run) => Level::Recovering(run + 1),
                    _ => Level::Normal,
                });
                if self.autonomous && !autonomous {
                    self.autonomous = false;
                } else if !self.autonomous
                    && autonomous
                    && edge
                    && !self.driver
                    && self.level() == Level::Normal
                {
                    self.autonomous = true;
                }
            }
            None if self.ever => {
                self.missed += 1;
                let hold = if self.planted { 3 } else { 2 };
                self.level = Some(match (self.level(), self.missed) {
                    (Level::FullBraking | Level::Recovering(_), _) => Level::FullBraking,
                    (_, m) if m <= hold => Level::Holding,
                    (_, 3..=4) => Level::Decelerating,
                    _ => Level::FullBraking,
                });
            }
            None => {}
        }
        let level = self.level();
        let (motors, full_brake, velocity) = match (self.autonomous, level) {
            (false, _) => (true, false, None),
            (true, Level::Normal | Level::Holding) => {
                (true, false, self.command.map(|(v, _)| f64::from(v)))
            }
            (true, Level::Decelerating) => (true, false, None),
            (true, _) => (false, true, None),
        };
        Decisions {
            level,
            autonomous: self.autonomous,
            motors,
            full_brake,
            velocity,
        }
    }
}

/// The supervisor, fed the same cycles over the reference tug's wire.
struct Implementation {
    supervisor: Supervisor<ReferenceWire>,
    counter: u8,
    t: u64,
}

impl Implementation {
    fn new() -> Self {
        Implementation {
            supervisor: Supervisor::with_wire(SupervisorConfig::default(), ReferenceWire),
            counter: 0,
            t: 0,
        }
    }

    fn cycle(&mut self, c: Cycle) -> Decisions {
        let s = &mut self.supervisor;
        s.set_driver_input(if c.driver { 10.0 } else { 0.0 }, 0.0);
        let counter = self.counter;
        let frame = match c.sent {
            Sent::Missing => None,
            Sent::Command {
                velocity,
                engage,
                autonomous,
            } => Some(command(counter, |m| {
                m.set_velocity_cmd(f64::from(velocity)).unwrap();
                m.set_engage_request_raw(u64::from(engage));
                let mode = if autonomous {
                    TugMode::Autonomous
                } else {
                    TugMode::Manual
                };
                m.set_control_mode_cmd_raw(mode as u64);
            })),
            Sent::BadChecksum => {
                let mut payload = [0u8; 8];
                payload.copy_from_slice(command(counter, |_| {}).data());
                payload[7] ^= 0x5A;
                let id = bywire_core::Id::standard(AdsToVehicleControl::ID).unwrap();
                Some(bywire_core::Frame::classic(id, &payload).unwrap())
            }
            Sent::OutOfRange => {
                let mut m = AdsToVehicleControl::default();
                m.set_velocity_cmd(1.0).unwrap();
                m.set_gear_cmd_raw(3);
                m.set_control_mode_cmd_raw(TugMode::Autonomous as u64);
                m.set_steering_angle_cmd(44.0).unwrap();
                m.set_heartbeat_counter_raw(u64::from(counter));
                Some(sealed(AdsToVehicleControl::ID, m.0))
            }
        };
        if let Some(frame) = frame {
            self.counter = (counter + 1) % 16;
            s.on_frame(ms(self.t), Port::MAIN, &frame);
        }
        s.poll(ms(self.t), &mut |_, _| {});
        let at = ms(self.t + 15);
        s.poll(at, &mut |_, _| {});
        self.t += 20;
        let a = s.actuators(at);
        Decisions {
            level: match s.watchdog() {
                Watchdog::Normal => Level::Normal,
                Watchdog::Holding { .. } => Level::Holding,
                Watchdog::Decelerating { .. } => Level::Decelerating,
                Watchdog::FullBraking => Level::FullBraking,
                Watchdog::Recovering { valid_run } => Level::Recovering(valid_run),
            },
            autonomous: s.mode() == ControlMode::Autonomous,
            motors: a.motors_enabled,
            full_brake: a.brake >= 100.0 && !a.motors_enabled,
            velocity: (a.ads_in_control && a.motors_enabled && a.brake == 0.0)
                .then_some(a.velocity)
                .filter(|_| matches!(s.watchdog(), Watchdog::Normal | Watchdog::Holding { .. })),
        }
    }
}

fn sent() -> impl Strategy<Value = Sent> {
    prop_oneof![
        6 => (0u8..3, any::<bool>(), prop::bool::weighted(0.9)).prop_map(|(velocity, engage, autonomous)| {
            Sent::Command { velocity, engage, autonomous }
        }),
        2 => Just(Sent::Missing),
        1 => Just(Sent::BadChecksum),
        1 => Just(Sent::OutOfRange),
    ]
}

fn cycles() -> impl Strategy<Value = Vec<Cycle>> {
    prop::collection::vec(
        (prop::bool::weighted(0.05), sent()).prop_map(|(driver, sent)| Cycle { driver, sent }),
        1..80,
    )
}

/// Runs of cycles that reach autonomous driving often: a prefix of valid commands, then an
/// engage, then anything.
fn engaged_cycles() -> impl Strategy<Value = Vec<Cycle>> {
    cycles().prop_map(|rest| {
        let mut all: Vec<Cycle> = (0..12)
            .map(|k| Cycle {
                driver: false,
                sent: Sent::Command {
                    velocity: 2,
                    engage: k == 11,
                    autonomous: true,
                },
            })
            .collect();
        all.extend(rest);
        all
    })
}

fn cases() -> u32 {
    std::env::var("BACK_TO_BACK_CASES")
        .ok()
        .and_then(|n| n.parse().ok())
        .unwrap_or(2_000)
}

fn agree(cycles: &[Cycle]) -> Result<(), TestCaseError> {
    agree_with(Spec::default(), cycles)
}

fn agree_with(mut spec: Spec, cycles: &[Cycle]) -> Result<(), TestCaseError> {
    let mut implementation = Implementation::new();
    for (k, c) in cycles.iter().enumerate() {
        let expected = spec.cycle(*c);
        let got = implementation.cycle(*c);
        prop_assert_eq!(got, expected, "cycle {} ({:?})", k, c);
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    /// Verifies: REQ-E2E-1, REQ-E2E-2, REQ-RNG-1, REQ-TO-1, REQ-TO-2, REQ-TK-1.
    #[test]
    fn the_supervisor_decides_as_its_specification_on_random_cycles(cycles in engaged_cycles()) {
        agree(&cycles)?;
    }

    #[test]
    fn the_supervisor_decides_as_its_specification_from_power_on(cycles in cycles()) {
        agree(&cycles)?;
    }
}

/// A planted disagreement (the specification holding one cycle longer) is found, and shrunk
/// to the engaging prefix and three cycles without a command taken (missing, or refused).
#[test]
fn a_planted_disagreement_is_found_and_shrunk_to_the_shortest() {
    let mut runner = proptest::test_runner::TestRunner::new(ProptestConfig::with_cases(2_000));
    let planted = || Spec {
        planted: true,
        ..Spec::default()
    };
    let result = runner.run(&engaged_cycles(), |cycles| agree_with(planted(), &cycles));
    let Err(proptest::test_runner::TestError::Fail(why, minimal)) = result else {
        panic!("the planted defect was not found: {result:?}");
    };
    assert!(why.message().contains("Holding"), "{why}");
    assert_eq!(minimal.len(), 12 + 3, "not the shortest: {minimal:?}");
}
