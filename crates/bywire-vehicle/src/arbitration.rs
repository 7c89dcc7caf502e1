//! A/B arbitration for a duplicated control ECU: one side in control, the other in hot
//! standby computing the same outputs, and the standby taking over when the side in control
//! goes silent, reports a fault, or commands what the standby would not.
//!
//! **Why a fence and not a message.** A takeover agreed over the bus cannot rule out both
//! sides in control: a standby whose receiver fails hears a healthy active side as silence.
//! So the standby takes over through a line of its own: it asserts the *fence* (in hardware,
//! the partner's transceiver standby pin or output-enable), which cuts the other side's
//! outputs at once whatever that side believes, and only the side that took over asserts it.
//! A side's outputs reach the actuators when it is [`Role::Active`] and not fenced
//! ([`Arbiter::transmits`]), so at most one side ever does. A side that hears nothing at all
//! (no partner, and no other traffic) blames its own receiver and steps out: in control, so
//! that the standby takes over; in standby, rather than taking over.
//!
//! One transition, [`Arbiter::step`], per side. The crate's `fail_operational` suite checks
//! over every interleaving of the two sides' steps, every pattern of lost heartbeats and every
//! single fault (either side crashed, deaf, failing its self-test; A computing wrong outputs),
//! for 28 heartbeat periods (140 ms at 5 ms, a 20 ms silence timeout): never both sides'
//! outputs on the bus; never neither side in control for longer than the silence timeout and
//! three heartbeat periods (35 ms there, and reached); no takeover without a fault and up to
//! three heartbeats lost in a row.

use core::time::Duration;

use bywire_core::Timestamp;

/// Which of the two ECUs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    /// The side in control at start.
    A,
    /// The hot standby at start.
    B,
}

/// A side's role.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Role {
    /// In control: its outputs drive the actuators (unless fenced).
    Active,
    /// Computing the same outputs, ready to take over.
    Standby,
    /// Out until reset, for the reason given.
    Out(OutReason),
}

impl Role {
    /// The role as a status message carries it: 0 active, 1 standby, 2 out for its
    /// self-test, 3 fenced, 4 deaf.
    pub fn raw(self) -> u8 {
        match self {
            Role::Active => 0,
            Role::Standby => 1,
            Role::Out(OutReason::SelfTest) => 2,
            Role::Out(OutReason::Fenced) => 3,
            Role::Out(OutReason::Deaf) => 4,
        }
    }

    /// The role a status message carries; a number no role has reads as out for its
    /// self-test (a sender that says nothing sensible is not fit to be in control).
    pub fn from_raw(raw: u64) -> Role {
        match raw {
            0 => Role::Active,
            1 => Role::Standby,
            3 => Role::Out(OutReason::Fenced),
            4 => Role::Out(OutReason::Deaf),
            _ => Role::Out(OutReason::SelfTest),
        }
    }
}

/// Why a side stepped out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OutReason {
    /// Its own self-test failed.
    SelfTest,
    /// The partner took over and fenced it.
    Fenced,
    /// It heard nothing at all on the bus for the silence timeout: its receiver has failed
    /// (in control it would act on stale commands; as standby it would take the silence for
    /// the partner's).
    Deaf,
}

/// Why the standby took over.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TakeoverReason {
    /// No heartbeat from the partner within the silence timeout, and other frames heard
    /// after it (the takeover comes with the first frame after the timeout).
    PartnerSilent,
    /// The partner's heartbeat said it was out.
    PartnerReportedOut,
    /// The partner's outputs differed from this side's own beyond the bound, for the
    /// disagreement time.
    OutputsDisagree,
}

/// What a side's heartbeat says, as the partner decoded it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Heartbeat {
    /// The sender's role.
    pub role: Role,
    /// When it arrived.
    pub at: Timestamp,
}

/// Timing of the arbitration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ArbiterConfig {
    /// The partner is silent after this long without a heartbeat (several heartbeat periods,
    /// so that single lost frames never cause a takeover).
    pub silence: Duration,
    /// The active side's outputs may differ from the standby's own computation for this long
    /// before the standby takes over.
    pub disagreement: Duration,
}

/// What one side sees at a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ArbiterInputs {
    /// This side's own self-test passes.
    pub self_test_ok: bool,
    /// The partner's last heartbeat (`None`: none yet).
    pub partner: Option<Heartbeat>,
    /// When this side last received any frame but its own (the partner's heartbeat, the
    /// ADS's commands, the drives' feedback): all silent, the fault is this side's receiver.
    pub traffic_at: Option<Timestamp>,
    /// The standby's comparison of the active side's last outputs with its own (`None`:
    /// nothing to compare this step).
    pub outputs_agree: Option<bool>,
    /// The partner's fence is asserted on this side: its outputs are cut.
    pub fenced: bool,
}

/// One side's arbitration state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Arbiter {
    side: Side,
    role: Role,
    config: ArbiterConfig,
    started: Timestamp,
    /// Since when the active side's outputs have disagreed with this side's own.
    disagree_since: Option<Timestamp>,
    /// Why this side took over, once it has (its fence stays asserted from then on).
    took_over: Option<TakeoverReason>,
}

impl Arbiter {
    /// A side at power-on at `now`: A active, B standby.
    pub fn new(side: Side, config: ArbiterConfig, now: Timestamp) -> Self {
        Arbiter {
            side,
            role: match side {
                Side::A => Role::Active,
                Side::B => Role::Standby,
            },
            config,
            started: now,
            disagree_since: None,
            took_over: None,
        }
    }

    /// Which side this is.
    pub fn side(&self) -> Side {
        self.side
    }

    /// This side's role.
    pub fn role(&self) -> Role {
        self.role
    }

    /// Why this side took over (`None`: it has not).
    pub fn took_over(&self) -> Option<TakeoverReason> {
        self.took_over
    }

    /// Whether this side asserts the fence on its partner: from its takeover on, latched (a
    /// side that took over and then fails leaves the partner it replaced cut off; two faults
    /// end in the actuators' own safe stop).
    pub fn fences_partner(&self) -> bool {
        self.took_over.is_some()
    }

    /// Whether this side's outputs reach the actuators, given whether the partner's fence is
    /// asserted on it.
    pub fn transmits(&self, fenced: bool) -> bool {
        self.role == Role::Active && !fenced
    }

    /// Back to the power-on roles (for a reset at standstill).
    pub fn reset(&mut self, now: Timestamp) {
        *self = Arbiter::new(self.side, self.config, now);
    }

    /// The one transition: this side's role after seeing `inputs` at `now`.
    pub fn step(&mut self, now: Timestamp, inputs: ArbiterInputs) -> Role {
        let silent_since = |heard: Option<Timestamp>| {
            now.saturating_since(heard.unwrap_or(self.started)) > self.config.silence
        };
        // The partner is silent only if this side heard other frames after the partner had
        // been quiet for the whole timeout: a receiver that fails silences everything at once,
        // and must not pass for a silent partner on the way to being found deaf.
        let partner_heard = inputs.partner.map_or(self.started, |h| h.at);
        let partner_silent = inputs
            .traffic_at
            .is_some_and(|heard| heard.saturating_since(partner_heard) > self.config.silence);
        let disagree_since = match (self.role, inputs.outputs_agree) {
            (Role::Standby, Some(false)) => Some(self.disagree_since.unwrap_or(now)),
            (Role::Standby, None) => self.disagree_since,
            _ => None,
        };
        let takeover = if inputs
            .partner
            .is_some_and(|h| matches!(h.role, Role::Out(_)))
        {
            Some(TakeoverReason::PartnerReportedOut)
        } else if partner_silent {
            Some(TakeoverReason::PartnerSilent)
        } else if disagree_since
            .is_some_and(|since| now.saturating_since(since) >= self.config.disagreement)
        {
            Some(TakeoverReason::OutputsDisagree)
        } else {
            None
        };
        let role = match (self.role, inputs.self_test_ok, inputs.fenced) {
            (Role::Out(reason), _, _) => Role::Out(reason),
            (_, false, _) => Role::Out(OutReason::SelfTest),
            (_, true, true) => Role::Out(OutReason::Fenced),
            (_, true, false) if silent_since(inputs.traffic_at) => Role::Out(OutReason::Deaf),
            (Role::Active, true, false) => Role::Active,
            (Role::Standby, true, false) => match takeover {
                Some(reason) => {
                    self.took_over = Some(reason);
                    Role::Active
                }
                None => Role::Standby,
            },
        };
        self.disagree_since = if role == Role::Standby {
            disagree_since
        } else {
            None
        };
        self.role = role;
        role
    }
}
