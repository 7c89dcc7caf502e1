//! Vehicle acceptance checks, as a sans-IO node on the vehicle's command bus: it engages the
//! vehicle, sweeps the steering across its range, steps the speed, falls silent to time the
//! watchdog, and presses the E-stop to time the latch — then reports each check with its
//! figures. The same node runs against a real vehicle (real-time runner) or the simulated tug.

use core::time::Duration;

use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Timestamp};

use crate::ads::{Ads, AdsCommand};
use crate::command::{ControlMode, EstopCode, Gear, WatchdogLevel};
use crate::profile::LoadedProfile;
use crate::wire::ProfileWire;

/// One check's outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckResult {
    /// Its name.
    pub name: &'static str,
    /// Passed.
    pub passed: bool,
    /// Figures, or why it failed.
    pub detail: String,
}

/// What the checks ask of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckConfig {
    /// Steering sweep range (±), degrees, and step.
    pub sweep_deg: f64,
    /// Sweep step, degrees.
    pub sweep_step_deg: f64,
    /// Time at each sweep step before judging it.
    pub dwell: Duration,
    /// Largest steering error accepted, degrees.
    pub steering_tolerance_deg: f64,
    /// Speeds to step to, m/s.
    pub speeds: [f64; 2],
}

impl Default for CheckConfig {
    fn default() -> Self {
        CheckConfig {
            sweep_deg: 40.0,
            sweep_step_deg: 1.0,
            dwell: Duration::from_millis(600),
            steering_tolerance_deg: 2.0,
            speeds: [1.0, 2.5],
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Engage {
        since: Timestamp,
    },
    Rates {
        since: Timestamp,
        frames: u32,
    },
    Sweep {
        step: i64,
        since: Timestamp,
    },
    Speed {
        index: usize,
        since: Timestamp,
    },
    Settle {
        since: Timestamp,
    },
    Silent {
        since: Timestamp,
        last_command: Timestamp,
        holding: Option<Timestamp>,
        braking: Option<Timestamp>,
    },
    Reengage {
        since: Timestamp,
    },
    Estop {
        since: Timestamp,
        latched: Option<Timestamp>,
    },
    Released {
        since: Timestamp,
    },
    Reset {
        since: Timestamp,
    },
    Done,
}

/// The acceptance checker.
pub struct Checker {
    ads: Ads<ProfileWire>,
    config: CheckConfig,
    state_id: u32,
    /// The wire the E-stop frames go out through (`None`: the vehicle has no E-stop message).
    estop: Option<ProfileWire>,
    phase: Phase,
    results: Vec<CheckResult>,
    command: AdsCommand,
    cycle: u32,
    estop_counter: u64,
    next_estop: Timestamp,
    worst_steering: (f64, f64),
    started: bool,
    cycle_ms: u64,
    last_poll: Timestamp,
}

impl Checker {
    /// Checks for the vehicle `profile` describes (the E-stop check needs the reference
    /// `EmergencyStop` message).
    pub fn new(
        profile: &LoadedProfile,
        config: CheckConfig,
    ) -> Result<Checker, crate::profile::ProfileError> {
        let wire = ProfileWire::new(profile)?;
        let state_id = profile
            .profile
            .state
            .as_ref()
            .and_then(|s| {
                profile
                    .database
                    .messages
                    .iter()
                    .find(|m| m.name == s.message)
            })
            .map_or(0, |m| m.raw_id());
        // The E-stop checks press the vehicle's own E-stop message, where it has one.
        let estop = wire.has_estop().then(|| wire.clone());
        Ok(Checker {
            ads: Ads::with_wire(profile.ads_config(), wire),
            config,
            state_id,
            estop,
            phase: Phase::Engage {
                since: Timestamp::ZERO,
            },
            results: Vec::new(),
            command: AdsCommand {
                gear: Gear::Drive,
                mode: ControlMode::Autonomous,
                ..AdsCommand::default()
            },
            cycle: 0,
            estop_counter: 0,
            next_estop: Timestamp::ZERO,
            worst_steering: (0.0, 0.0),
            started: false,
            cycle_ms: u64::try_from(profile.ads_config().cycle.as_millis())
                .unwrap_or(20)
                .max(1),
            last_poll: Timestamp::ZERO,
        })
    }

    /// The checks so far.
    pub fn results(&self) -> &[CheckResult] {
        &self.results
    }

    /// Every check has run (or the run stopped at a failure that leaves no point going on).
    pub fn is_done(&self) -> bool {
        self.phase == Phase::Done
    }

    fn record(&mut self, name: &'static str, passed: bool, detail: String) {
        self.results.push(CheckResult {
            name,
            passed,
            detail,
        });
    }

    fn autonomous(&self) -> bool {
        self.ads.state().mode.value == Some(ControlMode::Autonomous)
    }

    /// Take in a frame from the vehicle.
    fn receive(&mut self, now: Timestamp, frame: &Frame) {
        if let Phase::Rates { since, frames } = self.phase {
            if frame.id().is_some_and(|id| id.as_raw() == self.state_id) && now >= since {
                self.phase = Phase::Rates {
                    since,
                    frames: frames + 1,
                };
            }
        }
        self.ads.on_frame(now, Ads::<ProfileWire>::PORT_A, frame);
        if let Phase::Silent {
            since,
            last_command,
            holding,
            braking,
        } = self.phase
        {
            let level = self.ads.state().watchdog_level.value;
            let holding = holding.or_else(|| {
                level
                    .is_some_and(|l| l != WatchdogLevel::Normal)
                    .then_some(now)
            });
            let braking =
                braking.or_else(|| (level == Some(WatchdogLevel::FullBraking)).then_some(now));
            self.phase = Phase::Silent {
                since,
                last_command,
                holding,
                braking,
            };
        }
        if let Phase::Estop {
            since,
            latched: None,
        } = self.phase
        {
            if self
                .ads
                .state()
                .estop_state
                .value
                .is_some_and(|s| s != EstopCode::Normal)
            {
                self.phase = Phase::Estop {
                    since,
                    latched: Some(now),
                };
            }
        }
    }

    fn steering(&self) -> f64 {
        self.ads.state().steering.value.unwrap_or(f64::NAN)
    }

    fn speed(&self) -> f64 {
        self.ads.state().velocity.value.unwrap_or(f64::NAN)
    }

    /// Advance the checks and send what is due.
    fn step(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        self.last_poll = now;
        if !self.started {
            self.started = true;
            self.phase = Phase::Engage { since: now };
        }
        self.cycle = self.cycle.wrapping_add(1);
        let asks = self.advance(now);
        if let Some(pressed) = asks.press_estop {
            self.send_estop(now, pressed, out);
        }
        let _ = self.ads.set_command(
            now,
            AdsCommand {
                engage: asks.engage,
                operator_reset: asks.operator_reset,
                ..self.command
            },
        );
        // Silent: the ADS side is not polled at all, so it counts no command it did not send
        // (the vehicle's echo stays one it knows).
        if !asks.silent {
            // Bus A's copy (the checker drives one bus).
            self.ads.poll(now, &mut |port, frame| {
                if port == Ads::<ProfileWire>::PORT_A {
                    out(frame);
                }
            });
        }
        if let Phase::Silent {
            since,
            holding,
            braking,
            ..
        } = self.phase
        {
            // The silence starts with the first command not sent.
            if since == now {
                self.phase = Phase::Silent {
                    since,
                    last_command: now,
                    holding,
                    braking,
                };
            }
        }
    }

    /// The phase's checks at `now`, and what the ADS side is asked to do this cycle: the one
    /// transition function of the checker's phases, a method per phase.
    fn advance(&mut self, now: Timestamp) -> Asks {
        match self.phase {
            Phase::Engage { since } => self.engaging(now, since),
            Phase::Rates { since, frames } => self.counting_rates(now, since, frames),
            Phase::Sweep { step, since } => self.sweeping(now, step, since),
            Phase::Speed { index, since } => self.stepping_speed(now, index, since),
            Phase::Settle { since } => self.settling(now, since),
            Phase::Silent {
                since,
                last_command,
                holding,
                braking,
            } => self.falling_silent(now, since, last_command, (holding, braking)),
            Phase::Reengage { since } => self.reengaging(now, since),
            Phase::Estop { since, latched } => self.pressing_estop(now, since, latched),
            Phase::Released { since } => self.releasing_estop(now, since),
            Phase::Reset { since } => self.resetting(now, since),
            Phase::Done => Asks::default(),
        }
    }

    fn engaging(&mut self, now: Timestamp, since: Timestamp) -> Asks {
        let engage = self.ads.feedback_alive(now) && !self.autonomous() && self.cycle % 200 < 25;
        if self.autonomous() {
            let took = format!("autonomous after {} ms", since_ms(now, since));
            self.record("engage", true, took);
            self.phase = Phase::Rates {
                since: now.saturating_add(Duration::from_millis(100)),
                frames: 0,
            };
        } else if since_ms(now, since) > 5_000 {
            let why = "the vehicle did not report autonomous mode within 5 s".into();
            self.record("engage", false, why);
            self.phase = Phase::Done;
        }
        Asks {
            engage,
            ..Asks::default()
        }
    }

    fn counting_rates(&mut self, now: Timestamp, since: Timestamp, frames: u32) -> Asks {
        if now >= since.saturating_add(Duration::from_secs(1)) {
            let expected = 1_000 / self.ads_cycle_ms();
            let ok = u64::from(frames).abs_diff(expected) <= expected / 10 + 1;
            let counted = format!("{frames} state frames in 1 s (expected {expected})");
            self.record("feedback rate", ok, counted);
            self.phase = Phase::Sweep {
                step: -self.steps(),
                since: now,
            };
        }
        Asks::default()
    }

    fn sweeping(&mut self, now: Timestamp, step: i64, since: Timestamp) -> Asks {
        let setpoint = f64::from(i32::try_from(step).unwrap_or(0)) * self.config.sweep_step_deg;
        self.command.steering = setpoint;
        // The first step travels from straight ahead to the end of the range.
        let dwell = if step == -self.steps() {
            self.config.dwell.saturating_mul(8)
        } else {
            self.config.dwell
        };
        if now.saturating_since(since) < dwell {
            return Asks::default();
        }
        let error = (self.steering() - setpoint).abs();
        let next_step = Phase::Sweep {
            step: step + 1,
            since: now,
        };
        let speeds = Phase::Speed {
            index: 0,
            since: now,
        };
        // A missing reading (NaN) fails too.
        if error.is_nan() || error > self.config.steering_tolerance_deg {
            let off = format!(
                "at {setpoint:+.1}°: actual {:+.1}°, off by {error:.1}° (> {:.1}°)",
                self.steering(),
                self.config.steering_tolerance_deg
            );
            self.record("steering sweep", false, off);
            self.command.steering = 0.0;
            self.phase = speeds;
            return Asks::default();
        }
        if error > self.worst_steering.1 {
            self.worst_steering = (setpoint, error);
        }
        if step < self.steps() {
            self.phase = next_step;
            return Asks::default();
        }
        let (at, worst) = self.worst_steering;
        let swept = format!(
            "±{:.0}° in {:.0}° steps, worst error {worst:.2}° at {at:+.0}°",
            self.config.sweep_deg, self.config.sweep_step_deg
        );
        self.record("steering sweep", true, swept);
        self.command.steering = 0.0;
        self.phase = speeds;
        Asks::default()
    }

    fn stepping_speed(&mut self, now: Timestamp, index: usize, since: Timestamp) -> Asks {
        let target = self.config.speeds.get(index).copied().unwrap_or(0.0);
        self.command.velocity = target;
        if since_ms(now, since) >= 6_000 {
            let error = (self.speed() - target).abs();
            let ok = error <= 0.1 * target.max(1.0);
            let reached = format!("{target:.1} m/s: {:.2} m/s after 6 s", self.speed());
            self.record("speed step", ok, reached);
            self.phase = if index + 1 < self.config.speeds.len() {
                Phase::Speed {
                    index: index + 1,
                    since: now,
                }
            } else {
                Phase::Settle { since: now }
            };
        }
        Asks::default()
    }

    fn settling(&mut self, now: Timestamp, since: Timestamp) -> Asks {
        self.command.velocity = 0.0;
        if since_ms(now, since) >= 4_000 {
            self.phase = Phase::Silent {
                since: now,
                last_command: now,
                holding: None,
                braking: None,
            };
        }
        Asks::default()
    }

    fn falling_silent(
        &mut self,
        now: Timestamp,
        since: Timestamp,
        last_command: Timestamp,
        (holding, braking): (Option<Timestamp>, Option<Timestamp>),
    ) -> Asks {
        if since_ms(now, since) >= 400 {
            let cycle = Duration::from_millis(self.ads_cycle_ms()).as_secs_f64() * 1e3;
            let after = |t: Option<Timestamp>| {
                t.map(|t| t.saturating_since(last_command).as_secs_f64() * 1e3)
            };
            let (hold_ms, brake_ms) = (after(holding), after(braking));
            // Holding from 1.5 cycles, full braking from 5.5, each seen in the next state frame.
            let ok = hold_ms.is_some_and(|t| t <= 1.5 * cycle + cycle + 2.0)
                && brake_ms.is_some_and(|t| t <= 5.5 * cycle + cycle + 2.0);
            let seen = format!(
                "holding after {} ms, full braking after {} ms of silence",
                show(hold_ms),
                show(brake_ms)
            );
            self.record("watchdog", ok, seen);
            self.phase = Phase::Reengage { since: now };
        }
        Asks {
            silent: true,
            ..Asks::default()
        }
    }

    fn reengaging(&mut self, now: Timestamp, since: Timestamp) -> Asks {
        let level = self.ads.state().watchdog_level.value;
        let engage = self.ads.feedback_alive(now)
            && (self.cycle % 200 < 25)
            && (!self.autonomous() || level == Some(WatchdogLevel::AwaitingEngage));
        let ready = self.autonomous() && level == Some(WatchdogLevel::Normal);
        if ready || since_ms(now, since) > 5_000 {
            if !ready {
                self.record("re-engage", false, "not autonomous again within 5 s".into());
            }
            self.phase = if self.estop.is_some() && ready {
                Phase::Estop {
                    since: now,
                    latched: None,
                }
            } else {
                Phase::Done
            };
        }
        Asks {
            engage,
            ..Asks::default()
        }
    }

    fn pressing_estop(
        &mut self,
        now: Timestamp,
        since: Timestamp,
        latched: Option<Timestamp>,
    ) -> Asks {
        if since_ms(now, since) >= 500 {
            let ms = latched.map(|t| t.saturating_since(since).as_secs_f64() * 1e3);
            let reaction = format!("latched {} ms after the press", show(ms));
            self.record("E-stop reaction", ms.is_some_and(|t| t <= 60.0), reaction);
            self.phase = Phase::Released { since: now };
        }
        Asks {
            press_estop: Some(true),
            ..Asks::default()
        }
    }

    fn releasing_estop(&mut self, now: Timestamp, since: Timestamp) -> Asks {
        if since_ms(now, since) >= 1_000 {
            let state = self.ads.state().estop_state.value;
            let held = state.is_some_and(|s| s != EstopCode::Normal);
            let seen = if held {
                "still latched 1 s after release"
            } else {
                "released by itself"
            };
            self.record("E-stop latch", held, seen.into());
            self.phase = Phase::Reset { since: now };
        }
        Asks {
            press_estop: Some(false),
            ..Asks::default()
        }
    }

    fn resetting(&mut self, now: Timestamp, since: Timestamp) -> Asks {
        let state = self.ads.state().estop_state.value;
        let operator_reset =
            state.is_some_and(EstopCode::awaits_operator_reset) && self.cycle % 500 < 25;
        let engage = state == Some(EstopCode::ResetConfirmed) && self.cycle % 200 < 25;
        let clear = state == Some(EstopCode::Normal);
        if clear || since_ms(now, since) > 6_000 {
            let took = format!("latch clear after {} ms", since_ms(now, since));
            self.record("operator reset", clear, took);
            self.phase = Phase::Done;
        }
        Asks {
            engage,
            operator_reset,
            press_estop: Some(false),
            ..Asks::default()
        }
    }

    /// The E-stop chain's frame, every 20 ms while the checker holds the button (or has let
    /// it go).
    fn send_estop(&mut self, now: Timestamp, pressed: bool, out: &mut dyn FnMut(Frame)) {
        if now < self.next_estop {
            return;
        }
        self.next_estop = now.saturating_add(Duration::from_millis(20));
        let counter = self.estop_counter;
        self.estop_counter = self.estop_counter.wrapping_add(1);
        if let Some(frame) = self
            .estop
            .as_mut()
            .and_then(|w| w.estop_frame(pressed, counter))
        {
            out(frame);
        }
    }

    fn steps(&self) -> i64 {
        let steps = (self.config.sweep_deg / self.config.sweep_step_deg.max(0.1)).floor();
        // At most a thousand steps each way: the range is small.
        (0..1_000i32)
            .take_while(|k| f64::from(*k) < steps)
            .last()
            .map_or(0, |k| i64::from(k) + 1)
    }

    fn ads_cycle_ms(&self) -> u64 {
        self.cycle_ms
    }
}

/// What the checker asks of the ADS side in one cycle.
#[derive(Debug, Clone, Copy, Default)]
struct Asks {
    /// Request engagement.
    engage: bool,
    /// Send nothing (the watchdog check).
    silent: bool,
    /// Press the operator's reset.
    operator_reset: bool,
    /// Send the E-stop chain's frame, pressed or released.
    press_estop: Option<bool>,
}

/// Milliseconds from `since` to `now`.
fn since_ms(now: Timestamp, since: Timestamp) -> u128 {
    now.saturating_since(since).as_millis()
}

fn show(ms: Option<f64>) -> String {
    ms.map_or("—".to_string(), |t| format!("{t:.0}"))
}

impl Node for Checker {
    fn on_frame(&mut self, now: Timestamp, _port: Port, frame: &Frame) {
        self.receive(now, frame);
    }
    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        self.step(now, &mut |frame| out(Port::MAIN, frame));
    }
    fn next_deadline(&self) -> Option<Timestamp> {
        // The checks count cycles of a millisecond.
        Some(self.last_poll.saturating_add(Duration::from_millis(1)))
    }
}
