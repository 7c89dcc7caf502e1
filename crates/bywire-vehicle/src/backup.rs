//! A primary actuator and its backup for one function (steering, say): the demand routed to
//! the backup when the primary fails its feedback check, and to neither when the backup fails
//! too (the caller's safe state).
//!
//! The check compares the rate demanded of the actuator in charge with the rate measured by
//! an independent sensor (not the actuator's own report): no motion when motion is demanded,
//! motion the wrong way, or motion faster than demanded (a runaway, or any motion when none
//! is) count once they persist; a drive fault the actuator reports and a lost heartbeat count
//! at once. The switch happens at the step that finds the fault: within
//! [`FeedbackCheck::bound`] of its start, plus the caller's step period.

use core::time::Duration;

use bywire_core::Timestamp;

/// How an actuator's feedback is judged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedbackCheck {
    /// Rates below this (the function's unit per second) are no motion.
    pub still: f64,
    /// Motion faster than demanded by more than this is a runaway.
    pub overrun: f64,
    /// A tracking fault counts once it has lasted this long without a break (longer than
    /// the actuator's response lag to a step in demand).
    pub persistence: Duration,
    /// The actuator's heartbeat is lost after this long.
    pub heartbeat_timeout: Duration,
}

impl FeedbackCheck {
    /// The longest time from a fault's start to the switch, before the caller's step period.
    pub fn bound(&self, fault: ActuatorFault) -> Duration {
        match fault {
            ActuatorFault::HeartbeatLost => self.heartbeat_timeout,
            other => self.persistence_of(other),
        }
    }

    /// How long `fault` must last, once seen, to count: the persistence for a tracking
    /// fault, nothing for one the actuator reports or a heartbeat already overdue.
    fn persistence_of(&self, fault: ActuatorFault) -> Duration {
        match fault {
            ActuatorFault::NoMotion | ActuatorFault::WrongDirection | ActuatorFault::Runaway => {
                self.persistence
            }
            ActuatorFault::DriveFault | ActuatorFault::HeartbeatLost => Duration::ZERO,
        }
    }

    /// The fault `feedback` shows at `now`, before persistence; `heard_since` is when the
    /// actuator's heartbeat counts from if none has come.
    fn classify(
        &self,
        now: Timestamp,
        feedback: Feedback,
        heard_since: Timestamp,
    ) -> Option<ActuatorFault> {
        let Feedback {
            demanded,
            measured,
            drive_fault,
            heartbeat_at,
        } = feedback;
        let heard = heartbeat_at.unwrap_or(heard_since).max(heard_since);
        if drive_fault {
            Some(ActuatorFault::DriveFault)
        } else if now.saturating_since(heard) > self.heartbeat_timeout {
            Some(ActuatorFault::HeartbeatLost)
        } else if !(demanded.is_finite() && measured.is_finite()) {
            // A measurement that is not a number shows nothing moving as it should.
            Some(ActuatorFault::NoMotion)
        } else if demanded.abs() >= self.still && measured.abs() < self.still {
            Some(ActuatorFault::NoMotion)
        } else if demanded.abs() >= self.still && measured.signum() != demanded.signum() {
            Some(ActuatorFault::WrongDirection)
        } else if measured.abs() > demanded.abs() + self.overrun {
            Some(ActuatorFault::Runaway)
        } else {
            None
        }
    }
}

/// What failed an actuator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ActuatorFault {
    /// Motion demanded, none measured (stuck, or its drive lost).
    NoMotion,
    /// Measured moving against the demand.
    WrongDirection,
    /// Measured moving faster than demanded, or moving when nothing is.
    Runaway,
    /// The actuator reported a fault of its own.
    DriveFault,
    /// No heartbeat within the timeout.
    HeartbeatLost,
}

/// The feedback of the actuator in charge at one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Feedback {
    /// The rate demanded of it.
    pub demanded: f64,
    /// The rate an independent sensor measures.
    pub measured: f64,
    /// It reports a fault.
    pub drive_fault: bool,
    /// When its last heartbeat came (`None`: none yet).
    pub heartbeat_at: Option<Timestamp>,
}

/// Which actuator the demand goes to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum InCharge {
    /// The primary.
    Primary,
    /// The backup: the primary failed.
    Backup,
    /// Neither: both failed; the caller's safe state.
    Neither,
}

/// A primary actuator and its backup.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActuatorPair {
    check: FeedbackCheck,
    in_charge: InCharge,
    /// When the actuator in charge took charge: its heartbeat counts from then.
    since: Timestamp,
    /// The fault seen now and when it began (not yet persisted).
    suspect: Option<(ActuatorFault, Timestamp)>,
    /// What failed the primary and when it was found.
    primary_failed: Option<(ActuatorFault, Timestamp)>,
    /// What failed the backup and when it was found.
    backup_failed: Option<(ActuatorFault, Timestamp)>,
}

impl ActuatorPair {
    /// The primary in charge from `now`.
    pub fn new(check: FeedbackCheck, now: Timestamp) -> Self {
        ActuatorPair {
            check,
            in_charge: InCharge::Primary,
            since: now,
            suspect: None,
            primary_failed: None,
            backup_failed: None,
        }
    }

    /// The check.
    pub fn check(&self) -> FeedbackCheck {
        self.check
    }

    /// Which actuator the demand goes to.
    pub fn in_charge(&self) -> InCharge {
        self.in_charge
    }

    /// What failed the primary, and when it was found (`None`: it has not failed).
    pub fn primary_failed(&self) -> Option<(ActuatorFault, Timestamp)> {
        self.primary_failed
    }

    /// What failed the backup, and when it was found.
    pub fn backup_failed(&self) -> Option<(ActuatorFault, Timestamp)> {
        self.backup_failed
    }

    /// The primary in charge again (for the caller's reset at standstill).
    pub fn reset(&mut self, now: Timestamp) {
        *self = ActuatorPair::new(self.check, now);
    }

    /// The one transition: judge the feedback of the actuator in charge at `now`, and say
    /// which is in charge from now on.
    pub fn step(&mut self, now: Timestamp, feedback: Feedback) -> InCharge {
        let seen = match self.in_charge {
            InCharge::Neither => None,
            InCharge::Primary | InCharge::Backup => self.check.classify(now, feedback, self.since),
        };
        // A tracking fault must persist (any kind, without a break); the others count at once.
        let suspect = seen.map(|fault| match self.suspect {
            Some((_, began)) => (fault, began),
            None => (fault, now),
        });
        let failed = suspect.filter(|&(fault, began)| {
            now.saturating_since(began) >= self.check.persistence_of(fault)
        });
        let (in_charge, suspect) = match (self.in_charge, failed) {
            (InCharge::Primary, Some((fault, _))) => {
                self.primary_failed = Some((fault, now));
                self.since = now;
                (InCharge::Backup, None)
            }
            (InCharge::Backup, Some((fault, _))) => {
                self.backup_failed = Some((fault, now));
                (InCharge::Neither, None)
            }
            (InCharge::Neither, _) => (InCharge::Neither, None),
            (in_charge, None) => (in_charge, suspect),
        };
        self.in_charge = in_charge;
        self.suspect = suspect;
        in_charge
    }
}
