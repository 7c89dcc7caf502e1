//! An attacker on bus 1: a node that has no key but hears everything and sends what it likes
//! — a compromised telematics box, a laptop on the diagnostic port. It knows the DBC: the
//! counters, the CRC's polynomial and data ID are public.
//!
//! - [`Attack::ForgeCommands`]: after each of the ADS's commands it sends one of its own with
//!   the next counter and a valid CRC, steering [`FORGED_STEERING`]: the ADS's next command then
//!   repeats the forged counter and is refused, so the forged one is what the vehicle obeys.
//! - [`Attack::ReplayCommands`]: the same, with the commands it captured early in the run
//!   (choosing the captured one whose counter comes next).
//! - [`Attack::ForgeState`]: after each state frame of the vehicle, one with the next counter,
//!   the same echo and a speed of [`FORGED_SPEED`], toward the ADS.
//! - [`Attack::Flood`]: identifier 0x000 back to back, winning every arbitration.
//!
//! Against the secured variant it does what it can without the key: the secured frame's shape
//! (FD, the payload then the freshness and MAC bits) with its payload, the freshness bits
//! advanced and the MAC bits it last saw — or, replaying, a whole captured frame, MAC and all.

use bywire_core::frame::FdFrame;
use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Id, StandardId, Timestamp};
use bywire_tug::messages::{self, AdsToVehicleControl, VehicleToAdsState};

/// The steering a forged command asks for, degrees.
pub const FORGED_STEERING: f64 = 30.0;
/// The speed a forged state frame reports, m/s.
pub const FORGED_SPEED: f64 = 7.5;
/// How many of the first commands of the run are kept for the replay.
const CAPTURE: usize = 256;

/// What the attacker does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Attack {
    /// Forged commands with a valid CRC and counter.
    ForgeCommands,
    /// Commands captured earlier in the run, replayed.
    ReplayCommands,
    /// Forged state frames (a fake speed) toward the ADS.
    ForgeState,
    /// Identifier 0x000 back to back.
    Flood,
}

/// The attacker node.
#[derive(Debug, Default)]
pub struct Attacker {
    attack: Option<Attack>,
    captured: Vec<Frame>,
    /// The next frame to send, and from when.
    due: Option<(Timestamp, Frame)>,
    /// A flood frame is on its way (one at a time, the next as soon as it went out).
    in_flight: bool,
    last_seen: Timestamp,
    sent: u64,
}

impl Attacker {
    /// An attacker that only listens.
    pub fn new() -> Attacker {
        Attacker {
            captured: Vec::with_capacity(CAPTURE),
            ..Attacker::default()
        }
    }

    /// Attack (or, `None`, stop).
    pub fn set_attack(&mut self, attack: Option<Attack>) {
        if attack != self.attack {
            self.attack = attack;
            self.due = None;
            self.in_flight = false;
        }
    }

    /// The attack under way.
    pub fn attack(&self) -> Option<Attack> {
        self.attack
    }

    /// Frames it has sent.
    pub fn sent(&self) -> u64 {
        self.sent
    }

    fn forged_command(&self, genuine: &Frame) -> Option<Frame> {
        let payload: [u8; 8] = genuine.data().get(..8)?.try_into().ok()?;
        let m = AdsToVehicleControl(payload);
        let mut command = messages::command_of(&m)?;
        command.steering = FORGED_STEERING;
        let counter = u8::try_from((m.heartbeat_counter_raw() + 1) & 0x0F).ok()?;
        let forged = messages::command_message(&command, counter)?;
        let frame = messages::sealed_frame(AdsToVehicleControl::ID, forged.0);
        Some(in_shape_of(genuine, &frame))
    }

    fn replayed_command(&self, genuine: &Frame) -> Option<Frame> {
        let counter = |f: &Frame| {
            let payload: [u8; 8] = f.data().get(..8)?.try_into().ok()?;
            Some(AdsToVehicleControl(payload).heartbeat_counter_raw())
        };
        let next = (counter(genuine)? + 1) & 0x0F;
        self.captured
            .iter()
            .find(|f| counter(f) == Some(next))
            .copied()
    }

    fn forged_state(&self, genuine: &Frame) -> Option<Frame> {
        let payload: [u8; 8] = genuine.data().get(..8)?.try_into().ok()?;
        let mut m = VehicleToAdsState(payload);
        m.set_counter_raw((m.counter_raw() + 1) & 0x0F);
        m.set_velocity_actual(FORGED_SPEED).ok()?;
        let frame = messages::sealed_frame(VehicleToAdsState::ID, m.0);
        Some(in_shape_of(genuine, &frame))
    }
}

/// `forged` (8 bytes) in the shape `genuine` has: as it is for a classic frame; for a secured
/// one, followed by the genuine frame's freshness byte advanced and its MAC bits, unchanged.
fn in_shape_of(genuine: &Frame, forged: &Frame) -> Frame {
    if !genuine.is_fd() {
        return *forged;
    }
    let mut data = [0u8; 64];
    let len = genuine.data().len().min(64);
    if let (Some(out), Some(tail)) = (data.get_mut(..len), genuine.data().get(..len)) {
        out.copy_from_slice(tail);
    }
    if let (Some(head), Some(payload)) = (data.get_mut(..8), forged.data().get(..8)) {
        head.copy_from_slice(payload);
    }
    if let Some(fv) = data.get_mut(8) {
        *fv = fv.wrapping_add(1);
    }
    let id = forged.id().unwrap_or(Id::Standard(StandardId::ZERO));
    data.get(..len)
        .and_then(|d| FdFrame::new(id, d, true, false).ok())
        .map_or(*forged, Frame::Fd)
}

impl Node for Attacker {
    fn on_frame(&mut self, now: Timestamp, _port: Port, frame: &Frame) {
        self.last_seen = now;
        let raw = frame.id().map(Id::as_raw);
        if raw == Some(AdsToVehicleControl::ID) && self.captured.len() < CAPTURE {
            self.captured.push(*frame);
        }
        let answer = match (self.attack, raw) {
            (Some(Attack::ForgeCommands), Some(AdsToVehicleControl::ID)) => {
                self.forged_command(frame)
            }
            (Some(Attack::ReplayCommands), Some(AdsToVehicleControl::ID)) => {
                self.replayed_command(frame)
            }
            (Some(Attack::ForgeState), Some(VehicleToAdsState::ID)) => self.forged_state(frame),
            _ => None,
        };
        if let Some(frame) = answer {
            self.due = Some((now, frame));
        }
    }

    fn on_sent(&mut self, now: Timestamp, _port: Port, _frame: &Frame) -> bool {
        self.last_seen = now;
        self.sent = self.sent.saturating_add(1);
        self.in_flight = false;
        true
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        self.last_seen = now;
        if self.attack == Some(Attack::Flood) {
            if !self.in_flight {
                self.in_flight = true;
                let zero = Id::Standard(StandardId::ZERO);
                if let Ok(frame) = Frame::classic(zero, &[0; 8]) {
                    out(Port::MAIN, frame);
                }
            }
            return;
        }
        if let Some((_, frame)) = self.due.take() {
            out(Port::MAIN, frame);
        }
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        match (self.attack, self.due) {
            (Some(Attack::Flood), _) if !self.in_flight => Some(self.last_seen),
            (_, Some((at, _))) => Some(at),
            _ => None,
        }
    }
}
