//! The ADS side's checks against the vehicle's, command by command: random commands (within
//! the limits, at them, just beyond, far beyond, not numbers, every gear and mode), each judged
//! by what the ADS side sends ([`Limits::admit`], then the wire's encoding) and by what a
//! [`Supervisor`] accepts of its frame; every command one side takes and the other refuses is
//! a disagreement. A command the ADS side sends and the vehicle refuses is one the vehicle
//! ignores while the ADS believes it drives; one the vehicle would take and the ADS side
//! refuses is a limit set apart. Either way the two ends of the wire were configured apart.

use core::time::Duration;

use bywire_core::node::Node;
use bywire_core::Timestamp;

use crate::command::{ControlCommand, ControlMode, Gear, SteeringMode, TurnIndicators};
use crate::profile::Limits;
use crate::supervisor::{Supervisor, SupervisorConfig};
use crate::wire::{AdsWire, VehicleWire};

/// Disagreements kept in a report (all are counted).
pub const KEPT: usize = 100;

/// One command the two sides judge differently.
#[derive(Debug, Clone, PartialEq)]
pub struct Disagreement {
    /// The command as generated.
    pub command: ControlCommand,
    /// The ADS side: `Ok` when it sends the command, else why not.
    pub ads: Result<(), String>,
    /// The vehicle: `Ok` when its supervisor accepts the frame, else why not.
    pub vehicle: Result<(), String>,
}

/// What a fuzzing run found.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FuzzReport {
    /// Commands generated.
    pub commands: u64,
    /// Of them, sent by the ADS side.
    pub sent: u64,
    /// Of them, not sent and not encodable either (a value beyond its signal's range, which
    /// the wire refuses to carry as another): no verdict of the vehicle's to compare.
    pub unencodable: u64,
    /// Disagreements counted.
    pub disagreements: u64,
    /// The first [`KEPT`] of them.
    pub kept: Vec<Disagreement>,
}

/// SplitMix64: a small, fixed generator, so a seed names one run everywhere.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A number in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    fn pick<T: Copy>(&mut self, from: &[T]) -> Option<T> {
        let len = u64::try_from(from.len()).ok()?;
        let index = usize::try_from(self.next() % len.max(1)).ok()?;
        from.get(index).copied()
    }

    /// A value for a setpoint whose limit is `limit` (its range `low..=limit` when `low` is
    /// given): well within, at the edge, just beyond, far beyond, or not a number.
    fn value(&mut self, limit: f64, low: Option<f64>) -> f64 {
        let low = low.unwrap_or(-limit);
        let span = limit - low;
        match self.next() % 10 {
            0..=3 => low + span * self.unit(),
            4 => limit,
            5 => low,
            6 => limit + span * 1e-3 * (1.0 + self.unit()),
            7 => low - span * 1e-3 * (1.0 + self.unit()),
            8 => (self.unit() - 0.5) * limit * 1e6,
            _ => self
                .pick(&[f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -0.0])
                .unwrap_or(f64::NAN),
        }
    }
}

/// `n` random commands from `seed` through the ADS side (`limits`, then `ads_wire`) and a
/// supervisor (`config`, reading `vehicle_wire`), one command cycle apart with the counter in
/// sequence, so only the values decide.
pub fn fuzz<A: AdsWire, V: VehicleWire>(
    limits: &Limits,
    (mut ads_wire, vehicle_wire): (A, V),
    config: SupervisorConfig,
    n: u64,
    seed: u64,
) -> FuzzReport {
    let mut rng = SplitMix(seed);
    let mut supervisor = Supervisor::with_wire(config, vehicle_wire);
    let mut report = FuzzReport::default();
    let mut now = Timestamp::ZERO;
    let mut counter = 0u64;
    for _ in 0..n {
        let command = ControlCommand {
            steering: rng.value(limits.steering_deg, None),
            velocity: rng.value(limits.speed_m_s, None),
            brake: rng.value(100.0, Some(0.0)),
            gear: rng.pick(Gear::ALL).unwrap_or(Gear::Neutral),
            mode: rng.pick(ControlMode::ALL).unwrap_or(ControlMode::Manual),
            steering_mode: rng.pick(SteeringMode::ALL).unwrap_or(SteeringMode::Normal),
            engage: rng.next().is_multiple_of(2),
            operator_reset: rng.next().is_multiple_of(8),
            turn_indicators: rng.pick(TurnIndicators::ALL).unwrap_or(TurnIndicators::Off),
            hazard_lights: rng.next().is_multiple_of(2),
        };
        report.commands += 1;
        // The ADS side's verdict, and the frame the vehicle is given: the one it sends, or the
        // command as generated where it sends none (would the vehicle have taken it?).
        let admitted = limits.admit(command);
        let frame = match &admitted {
            Ok((taken, _)) => ads_wire.command_frame(taken, counter),
            Err(_) => None,
        };
        let ads = match (&admitted, &frame) {
            (Ok(_), Some(_)) => Ok(()),
            (Ok(_), None) => Err("the wire cannot encode it".to_string()),
            (Err(why), _) => Err(why.clone()),
        };
        let Some(frame) = frame.or_else(|| ads_wire.command_frame(&command, counter)) else {
            report.unencodable += 1;
            continue;
        };
        report.sent += u64::from(ads.is_ok());
        let before = supervisor.stats();
        supervisor.on_frame(now, Supervisor::<V>::PORT_A, &frame);
        supervisor.poll(now, &mut |_, _| {});
        let after = supervisor.stats();
        let vehicle = match after.rejected_since(before).next() {
            Some(why) => Err(why.name().to_string()),
            None if after.accepted > before.accepted => Ok(()),
            None => Err("not taken as a command".to_string()),
        };
        counter = counter.wrapping_add(1);
        now = now.saturating_add(config.cycle.max(Duration::from_millis(1)));
        if ads.is_ok() != vehicle.is_ok() {
            report.disagreements += 1;
            if report.kept.len() < KEPT {
                report.kept.push(Disagreement {
                    command,
                    ads,
                    vehicle,
                });
            }
        }
    }
    report
}
