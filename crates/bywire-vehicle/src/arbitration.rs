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

use bywire_core::node::{Node, Port};
use bywire_core::time::earliest;
use bywire_core::{Frame, Timestamp};

use crate::command::FaultClass;

/// Which of the two ECUs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    /// The side in control at start.
    A,
    /// The hot standby at start.
    B,
}

impl Side {
    /// The partner.
    pub const fn other(self) -> Side {
        match self {
            Side::A => Side::B,
            Side::B => Side::A,
        }
    }
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
    /// It heard nothing at all on the bus for the deafness timeout: its receiver has failed
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
    /// No frame at all for this long is this side's receiver failed (longer than the longest
    /// gap between the frames it hears, the partner's status included).
    pub deaf: Duration,
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

    /// Whether the partner, last heard as `partner`, is silent: this side heard other frames
    /// (`traffic_at`, the latest) after the partner had been quiet for the whole timeout. A
    /// receiver that fails silences everything at once, and must not pass for a silent
    /// partner on the way to being found deaf.
    pub fn partner_silent(
        &self,
        partner: Option<Heartbeat>,
        traffic_at: Option<Timestamp>,
    ) -> bool {
        let partner_heard = partner.map_or(self.started, |h| h.at);
        traffic_at.is_some_and(|heard| heard.saturating_since(partner_heard) > self.config.silence)
    }

    /// The one transition: this side's role after seeing `inputs` at `now`.
    pub fn step(&mut self, now: Timestamp, inputs: ArbiterInputs) -> Role {
        let deaf =
            now.saturating_since(inputs.traffic_at.unwrap_or(self.started)) > self.config.deaf;
        let partner_silent = self.partner_silent(inputs.partner, inputs.traffic_at);
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
            (_, true, false) if deaf => Role::Out(OutReason::Deaf),
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

/// What one half of a duplicated ECU needs of its vehicle's messages.
pub trait DuplexWire {
    /// The port the halves' status frames go out and come in on.
    fn status_port(&self) -> Port;
    /// How often a half sends its status (its heartbeat).
    fn status_period(&self) -> Duration;
    /// `side`'s status frame with its `role` and rolling `counter`.
    fn status_frame(&mut self, side: Side, role: Role, counter: u8) -> Option<Frame>;
    /// The role in `frame`, if it is the status of `side`'s partner and reads as sound.
    fn partner_status(&mut self, side: Side, frame: &Frame) -> Option<Role>;
    /// Whether `theirs`, a frame the partner sent on `port`, agrees with `mine`, the frame
    /// this half made with its identifier; `None` for a frame that is no output to compare.
    fn agree(&self, port: Port, mine: &Frame, theirs: &Frame) -> Option<bool>;
}

/// A node that keeps a degradation latch (a vehicle control ECU's supervisor): a half tells
/// it of its takeover, or of its standby lost.
pub trait Degrades {
    /// A fault found (reported once).
    fn report_fault(&mut self, fault: crate::degradation::Fault);
}

/// One output this half's node made, kept for the comparison.
#[derive(Debug, Clone, Copy)]
struct Kept {
    port: Port,
    frame: Frame,
    /// The partner's last frame under its identifier disagreed with it.
    disagrees: bool,
}

/// Own outputs kept for the comparison: one per identifier and port.
const OWN_KEPT: usize = 16;

/// A half's node's frames handed over in one poll, at most (more are sent, not compared).
const POLL_KEPT: usize = 32;

/// One half of a duplicated ECU: its node, computing in either role, and its [`Arbiter`].
///
/// Both halves receive the same buses and run the same node in step ("hot standby"). What a
/// half's node sends reaches the bus only while the half is in control and not fenced. The
/// outputs the wire compares ([`DuplexWire::agree`]) are kept, one frame per identifier, and
/// compared with what the partner sends under that identifier; the partner's frames with such
/// an identifier are not given to the node (two senders of one identifier never share a bus,
/// and a node never sees its own frames either). The node is polled when its own deadline or a frame
/// calls for it, as it would be alone, so both halves' nodes see the same calls. Each half
/// sends its status every [`DuplexWire::status_period`] unless fenced.
///
/// The fence is an input ([`Duplex::set_fenced`]): the partner's output line, which a
/// vehicle wires in hardware and a simulation sets from the partner's
/// [`Arbiter::fences_partner`].
#[derive(Debug, Clone)]
pub struct Duplex<N, W> {
    node: N,
    wire: W,
    arbiter: Arbiter,
    fenced: bool,
    self_test_ok: bool,
    partner: Option<Heartbeat>,
    traffic_at: Option<Timestamp>,
    /// Whether the partner's outputs have been compared since the last reset.
    compared: bool,
    own: [Option<Kept>; OWN_KEPT],
    /// The node has frames it has not been polled after.
    node_due: bool,
    /// Its node was told its standby is lost.
    standby_lost_reported: bool,
    next_status: Timestamp,
    status_counter: u8,
}

impl<N: Node + Degrades, W: DuplexWire> Duplex<N, W> {
    /// `side`'s half running `node` from `now`.
    pub fn new(side: Side, config: ArbiterConfig, node: N, wire: W, now: Timestamp) -> Self {
        Duplex {
            node,
            wire,
            arbiter: Arbiter::new(side, config, now),
            fenced: false,
            self_test_ok: true,
            partner: None,
            traffic_at: None,
            compared: false,
            own: [None; OWN_KEPT],
            node_due: true,
            standby_lost_reported: false,
            next_status: now,
            status_counter: 0,
        }
    }

    /// The node.
    pub fn node(&self) -> &N {
        &self.node
    }

    /// The node, to change (its deadline is asked again by the runner's guard).
    pub fn node_mut(&mut self) -> &mut N {
        self.node_due = true;
        &mut self.node
    }

    /// The arbitration.
    pub fn arbiter(&self) -> &Arbiter {
        &self.arbiter
    }

    /// Whether this half's outputs reach the bus now.
    pub fn transmits(&self) -> bool {
        self.arbiter.transmits(self.fenced)
    }

    /// The partner's fence on this half (the hardware line).
    pub fn set_fenced(&mut self, fenced: bool) {
        self.fenced = fenced;
    }

    /// This half's self-test result.
    pub fn set_self_test(&mut self, ok: bool) {
        self.self_test_ok = ok;
    }

    /// Back to the power-on roles, partner and comparison forgotten (a reset at standstill).
    pub fn reset(&mut self, now: Timestamp) {
        self.arbiter.reset(now);
        self.partner = None;
        self.compared = false;
        for kept in self.own.iter_mut().flatten() {
            kept.disagrees = false;
        }
        self.standby_lost_reported = false;
        self.next_status = now;
    }

    /// Keep an output to compare, with whether the partner's last under its identifier
    /// disagreed.
    fn keep(&mut self, port: Port, frame: Frame) {
        let id = frame.id();
        let slot = self
            .own
            .iter()
            .position(|o| o.is_some_and(|o| o.port == port && o.frame.id() == id))
            .or_else(|| self.own.iter().position(Option::is_none));
        if let Some(slot) = slot.and_then(|i| self.own.get_mut(i)) {
            let disagrees = slot.is_some_and(|o| o.disagrees);
            *slot = Some(Kept {
                port,
                frame,
                disagrees,
            });
        }
    }

    /// The kept output with `frame`'s identifier on `port`.
    fn mine<'a>(own: &'a mut [Option<Kept>], port: Port, frame: &Frame) -> Option<&'a mut Kept> {
        let id = frame.id()?;
        own.iter_mut()
            .flatten()
            .find(|o| o.port == port && o.frame.id() == Some(id))
    }
}

impl<N: Node + Degrades, W: DuplexWire> Node for Duplex<N, W> {
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        self.traffic_at = Some(now);
        if port == self.wire.status_port() {
            if let Some(role) = self.wire.partner_status(self.arbiter.side(), frame) {
                self.partner = Some(Heartbeat { role, at: now });
                return;
            }
        }
        let wire = &self.wire;
        if let Some(kept) = Self::mine(&mut self.own, port, frame) {
            if let Some(agree) = wire.agree(port, &kept.frame, frame) {
                // Each output disagrees until the partner's next under its identifier
                // agrees: agreement on one does not clear another's disagreement.
                kept.disagrees = !agree;
                self.compared = true;
            }
            return;
        }
        self.node_due = true;
        self.node.on_frame(now, port, frame);
    }

    fn on_sent(&mut self, now: Timestamp, port: Port, frame: &Frame) -> bool {
        self.node.on_sent(now, port, frame)
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        let inputs = ArbiterInputs {
            self_test_ok: self.self_test_ok,
            partner: self.partner,
            traffic_at: self.traffic_at,
            outputs_agree: self
                .compared
                .then(|| !self.own.iter().flatten().any(|o| o.disagrees)),
            fenced: self.fenced,
        };
        let before = self.arbiter.role();
        let role = self.arbiter.step(now, inputs);
        // Its own node learns of a takeover, or (in control from the start) of its standby
        // lost; the standby that took over does not report its partner lost too.
        let partner_out = self.partner.is_some_and(|h| matches!(h.role, Role::Out(_)));
        let fault = match (before, role) {
            (Role::Standby, Role::Active) => Some(FaultClass::ControlTakeover),
            (Role::Active, Role::Active)
                if self.arbiter.took_over().is_none()
                    && !self.standby_lost_reported
                    && (partner_out
                        || self.arbiter.partner_silent(self.partner, self.traffic_at)) =>
            {
                self.standby_lost_reported = true;
                Some(FaultClass::StandbyLost)
            }
            _ => None,
        };
        if let Some(class) = fault {
            self.node_due = true;
            self.node.report_fault(crate::degradation::Fault {
                class,
                source: 0,
                at: now,
            });
        }
        let transmits = self.transmits();
        if self.node_due || self.node.next_deadline().is_some_and(|d| d <= now) {
            self.node_due = false;
            let mut kept = [None; POLL_KEPT];
            let mut count = 0;
            self.node.poll(now, &mut |port, frame| {
                if transmits {
                    out(port, frame);
                }
                if let Some(slot) = kept.get_mut(count) {
                    *slot = Some((port, frame));
                    count += 1;
                }
            });
            // Only the outputs the wire compares are kept.
            for (port, frame) in kept.into_iter().flatten() {
                if self.wire.agree(port, &frame, &frame).is_some() {
                    self.keep(port, frame);
                }
            }
        }
        if now >= self.next_status && !self.fenced {
            self.next_status = now.saturating_add(self.wire.status_period());
            let side = self.arbiter.side();
            if let Some(frame) = self.wire.status_frame(side, role, self.status_counter) {
                out(self.wire.status_port(), frame);
            }
            self.status_counter = self.status_counter.wrapping_add(1);
        }
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        // A standby looks again when the partner would count as silent.
        let silence = match (self.arbiter.role(), self.partner) {
            (Role::Standby, Some(h)) => Some(
                h.at.saturating_add(self.arbiter.config.silence)
                    .saturating_add(Duration::from_nanos(1)),
            ),
            _ => None,
        };
        let status = (!self.fenced).then_some(self.next_status);
        earliest([self.node.next_deadline(), status, silence])
    }
}

/// Both halves of a duplicated ECU and the fence line between them, as one node for a
/// simulated runner (on a vehicle the halves are two boxes and the line is a wire). A's
/// ports are its node's; B's are its node's plus [`FencedPair::B_PORTS`]. Each half's fence
/// follows the other's [`Arbiter::fences_partner`] the moment the other steps: a half fenced
/// hands nothing more to the bus (a frame it handed over before, still queued behind
/// arbitration, may yet go out, as from a transceiver cut a frame late).
#[derive(Debug, Clone)]
pub struct FencedPair<N, W> {
    a: Duplex<N, W>,
    b: Duplex<N, W>,
    /// A half powered off: nothing in or out.
    off: [bool; 2],
}

impl<N: Node + Degrades, W: DuplexWire> FencedPair<N, W> {
    /// Added to a node's port number for B's.
    pub const B_PORTS: u8 = 8;

    /// The pair: A in control, B in hot standby.
    pub fn new(a: Duplex<N, W>, b: Duplex<N, W>) -> Self {
        FencedPair {
            a,
            b,
            off: [false; 2],
        }
    }

    /// B's port for its node's `port`.
    pub fn b_port(port: Port) -> Port {
        Port(port.0.saturating_add(Self::B_PORTS))
    }

    /// One half.
    pub fn half(&self, side: Side) -> &Duplex<N, W> {
        match side {
            Side::A => &self.a,
            Side::B => &self.b,
        }
    }

    /// One half, to change.
    pub fn half_mut(&mut self, side: Side) -> &mut Duplex<N, W> {
        match side {
            Side::A => &mut self.a,
            Side::B => &mut self.b,
        }
    }

    /// The half whose outputs reach the bus (`None`: neither, the actuators' safe stop).
    pub fn in_control(&self) -> Option<Side> {
        [Side::A, Side::B]
            .into_iter()
            .find(|&side| !self.is_off(side) && self.half(side).transmits())
    }

    /// Power a half off (a crash: silent, deaf) or on again.
    pub fn power(&mut self, side: Side, on: bool) {
        if let Some(off) = self.off.get_mut(usize::from(side == Side::B)) {
            *off = !on;
        }
    }

    /// Whether a half is powered off.
    pub fn is_off(&self, side: Side) -> bool {
        self.off
            .get(usize::from(side == Side::B))
            .copied()
            .unwrap_or(true)
    }

    /// The half a pair port belongs to, and the port on that half's node.
    fn route(port: Port) -> (Side, Port) {
        match port.0.checked_sub(Self::B_PORTS) {
            Some(p) => (Side::B, Port(p)),
            None => (Side::A, port),
        }
    }

    fn fence(&mut self) {
        // A half powered off drives no line: its partner is free.
        let a_fences = !self.is_off(Side::A) && self.a.arbiter().fences_partner();
        let b_fences = !self.is_off(Side::B) && self.b.arbiter().fences_partner();
        self.a.set_fenced(b_fences);
        self.b.set_fenced(a_fences);
    }
}

impl<N: Node + Degrades, W: DuplexWire> Node for FencedPair<N, W> {
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        let (side, port) = Self::route(port);
        if !self.is_off(side) {
            self.half_mut(side).on_frame(now, port, frame);
        }
    }

    fn on_sent(&mut self, now: Timestamp, port: Port, frame: &Frame) -> bool {
        let (side, port) = Self::route(port);
        !self.is_off(side) && self.half_mut(side).on_sent(now, port, frame)
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        self.fence();
        if !self.is_off(Side::A) {
            self.a.poll(now, out);
        }
        self.fence();
        if !self.is_off(Side::B) {
            self.b
                .poll(now, &mut |port, frame| out(Self::b_port(port), frame));
        }
        self.fence();
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        let deadline = |side: Side| {
            if self.is_off(side) {
                None
            } else {
                self.half(side).next_deadline()
            }
        };
        earliest([deadline(Side::A), deadline(Side::B)])
    }
}
