//! Fault confinement (ISO 11898-1): the transmit and receive error counters and the node states
//! they lead to, as a pure state machine fed with events.
//!
//! A node starts *error active*. Errors raise its counters (a transmit error by 8, a receive
//! error by 1, some by 8), successes lower them by 1. With either counter above 127 it is *error
//! passive* (it may only signal errors recessively); with the transmit counter above 255 it is
//! *bus-off* and takes no part in the bus until it has seen 128 sequences of 11 recessive bits,
//! after which it is error active with both counters at zero.

/// The node's fault-confinement state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum NodeState {
    /// Takes part fully; signals errors with an active (dominant) error flag.
    ErrorActive,
    /// Signals errors only with a passive (recessive) flag, and waits longer between frames.
    ErrorPassive,
    /// Off the bus.
    BusOff,
}

/// How a transmit error came about, for the two exceptions to "TEC + 8".
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TransmitErrorCause {
    /// Any error that the rules do not exempt.
    Other,
    /// An ACK error seen by an error-passive transmitter; `dominant_in_passive_flag` when it
    /// then saw a dominant bit while sending its passive error flag.
    AckWhilePassive {
        /// A dominant bit was seen during the passive error flag.
        dominant_in_passive_flag: bool,
    },
    /// A stuff error in arbitration: a stuff bit sent recessive was read back dominant.
    StuffInArbitration,
}

/// Something that happened on the bus, as the node's controller sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Event {
    /// A frame was sent and acknowledged, with no error up to the end of EOF.
    TransmitSuccess,
    /// A frame was received correctly up to the ACK slot and acknowledged.
    ReceiveSuccess,
    /// The node, transmitting, detected an error and sent an error flag.
    TransmitError(TransmitErrorCause),
    /// The node, receiving, detected an error (not a bit error in its own error flag).
    ReceiveError,
    /// A receiver saw a dominant bit as the first bit after sending its error flag.
    DominantAfterErrorFlag,
    /// A bit error while sending an active error flag or overload flag.
    BitErrorInFlag {
        /// The node was the transmitter of the frame.
        transmitter: bool,
    },
    /// 14 consecutive dominant bits after an active error flag (or 8 after a passive one),
    /// or a further 8 after that.
    DominantSequenceAfterFlag {
        /// The node was the transmitter of the frame.
        transmitter: bool,
    },
    /// 11 consecutive recessive bits seen (counts towards bus-off recovery).
    RecessiveSequence,
    /// The host asks to leave bus-off (controllers that need a request before they recover).
    RecoveryRequested,
}

/// A state change caused by an event.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct StateChange {
    /// State before.
    pub from: NodeState,
    /// State after.
    pub to: NodeState,
}

/// ISO allows REC to be set anywhere in 119..=127 after a good reception while error passive.
pub const REC_AFTER_PASSIVE_RECEPTION: u16 = 127;
/// Occurrences of 11 recessive bits that end bus-off.
pub const RECOVERY_SEQUENCES: u16 = 128;
/// Counter level from which controllers report an error warning.
pub const WARNING_LEVEL: u16 = 96;

/// The error counters and state of one node.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Confinement {
    tec: u16,
    rec: u16,
    state: NodeState,
    recovery_sequences: u16,
    /// Whether bus-off recovery waits for [`Event::RecoveryRequested`].
    manual_recovery: bool,
    recovery_requested: bool,
}

impl Default for Confinement {
    fn default() -> Self {
        Self::new(false)
    }
}

impl Confinement {
    /// A node just started: error active, counters at zero. With `manual_recovery` the
    /// recessive sequences only count once the host has asked to recover.
    pub const fn new(manual_recovery: bool) -> Self {
        Confinement {
            tec: 0,
            rec: 0,
            state: NodeState::ErrorActive,
            recovery_sequences: 0,
            manual_recovery,
            recovery_requested: false,
        }
    }

    /// Transmit error counter (above 255 only in bus-off).
    pub fn tec(&self) -> u16 {
        self.tec
    }

    /// Receive error counter.
    pub fn rec(&self) -> u16 {
        self.rec
    }

    /// The state.
    pub fn state(&self) -> NodeState {
        self.state
    }

    /// Whether either counter is at the warning level (SocketCAN's ERROR_WARNING).
    pub fn is_warning(&self) -> bool {
        self.state == NodeState::ErrorActive
            && (self.tec >= WARNING_LEVEL || self.rec >= WARNING_LEVEL)
    }

    /// Recessive sequences counted towards recovery so far.
    pub fn recovery_progress(&self) -> u16 {
        self.recovery_sequences
    }

    /// Apply one event; returns the state change it caused, if any. This is the only place the
    /// counters and state change.
    pub fn on_event(&mut self, event: Event) -> Option<StateChange> {
        let from = self.state;
        match (self.state, event) {
            (NodeState::BusOff, Event::RecoveryRequested) => self.recovery_requested = true,
            (NodeState::BusOff, Event::RecessiveSequence) => {
                if !self.manual_recovery || self.recovery_requested {
                    self.recovery_sequences = self.recovery_sequences.saturating_add(1);
                    if self.recovery_sequences >= RECOVERY_SEQUENCES {
                        *self = Confinement::new(self.manual_recovery);
                    }
                }
            }
            // Off the bus, a node neither sends nor receives.
            (
                NodeState::BusOff,
                Event::TransmitSuccess
                | Event::ReceiveSuccess
                | Event::TransmitError(_)
                | Event::ReceiveError
                | Event::DominantAfterErrorFlag
                | Event::BitErrorInFlag { .. }
                | Event::DominantSequenceAfterFlag { .. },
            ) => {}
            (
                NodeState::ErrorActive | NodeState::ErrorPassive,
                Event::RecessiveSequence | Event::RecoveryRequested,
            ) => {}
            (NodeState::ErrorActive | NodeState::ErrorPassive, Event::TransmitSuccess) => {
                self.tec = self.tec.saturating_sub(1);
            }
            (NodeState::ErrorActive | NodeState::ErrorPassive, Event::ReceiveSuccess) => {
                self.rec = if self.rec > 127 {
                    REC_AFTER_PASSIVE_RECEPTION
                } else {
                    self.rec.saturating_sub(1)
                };
            }
            (state, Event::TransmitError(cause)) => {
                let exempt = match cause {
                    TransmitErrorCause::Other => false,
                    TransmitErrorCause::AckWhilePassive {
                        dominant_in_passive_flag,
                    } => state == NodeState::ErrorPassive && !dominant_in_passive_flag,
                    TransmitErrorCause::StuffInArbitration => true,
                };
                if !exempt {
                    self.tec = self.tec.saturating_add(8);
                }
            }
            (NodeState::ErrorActive | NodeState::ErrorPassive, Event::ReceiveError) => {
                self.rec = self.rec.saturating_add(1);
            }
            (NodeState::ErrorActive | NodeState::ErrorPassive, Event::DominantAfterErrorFlag) => {
                self.rec = self.rec.saturating_add(8);
            }
            (
                NodeState::ErrorActive | NodeState::ErrorPassive,
                Event::BitErrorInFlag { transmitter }
                | Event::DominantSequenceAfterFlag { transmitter },
            ) => {
                if transmitter {
                    self.tec = self.tec.saturating_add(8);
                } else {
                    self.rec = self.rec.saturating_add(8);
                }
            }
        }
        self.state = if self.state == NodeState::BusOff {
            NodeState::BusOff
        } else if self.tec > 255 {
            self.recovery_sequences = 0;
            self.recovery_requested = false;
            NodeState::BusOff
        } else if self.tec > 127 || self.rec > 127 {
            NodeState::ErrorPassive
        } else {
            NodeState::ErrorActive
        };
        (self.state != from).then_some(StateChange {
            from,
            to: self.state,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sixteen_transmit_errors_make_passive_and_thirty_two_bus_off() {
        let mut c = Confinement::default();
        for i in 1..=15 {
            assert_eq!(
                c.on_event(Event::TransmitError(TransmitErrorCause::Other)),
                None,
                "{i}"
            );
        }
        assert!(c.is_warning());
        assert_eq!(
            c.on_event(Event::TransmitError(TransmitErrorCause::Other)),
            Some(StateChange {
                from: NodeState::ErrorActive,
                to: NodeState::ErrorPassive
            })
        );
        assert_eq!(c.tec(), 128);
        for _ in 0..15 {
            c.on_event(Event::TransmitError(TransmitErrorCause::Other));
        }
        assert_eq!((c.tec(), c.state()), (248, NodeState::ErrorPassive));
        assert_eq!(
            c.on_event(Event::TransmitError(TransmitErrorCause::Other))
                .map(|s| s.to),
            Some(NodeState::BusOff)
        );
    }

    #[test]
    fn bus_off_above_255_and_recovery_after_128_sequences() {
        let mut c = Confinement::default();
        for _ in 0..32 {
            c.on_event(Event::TransmitError(TransmitErrorCause::Other));
        }
        assert_eq!((c.tec(), c.state()), (256, NodeState::BusOff));
        // Frames are ignored while off the bus.
        c.on_event(Event::TransmitSuccess);
        assert_eq!(c.tec(), 256);
        for _ in 0..127 {
            assert_eq!(c.on_event(Event::RecessiveSequence), None);
        }
        assert_eq!(
            c.on_event(Event::RecessiveSequence),
            Some(StateChange {
                from: NodeState::BusOff,
                to: NodeState::ErrorActive
            })
        );
        assert_eq!((c.tec(), c.rec()), (0, 0));
    }

    #[test]
    fn manual_recovery_waits_for_the_request() {
        let mut c = Confinement::new(true);
        for _ in 0..32 {
            c.on_event(Event::TransmitError(TransmitErrorCause::Other));
        }
        for _ in 0..200 {
            c.on_event(Event::RecessiveSequence);
        }
        assert_eq!(c.state(), NodeState::BusOff);
        c.on_event(Event::RecoveryRequested);
        for _ in 0..128 {
            c.on_event(Event::RecessiveSequence);
        }
        assert_eq!(c.state(), NodeState::ErrorActive);
    }

    #[test]
    fn exceptions_and_receive_rules() {
        let mut c = Confinement::default();
        c.on_event(Event::TransmitError(TransmitErrorCause::StuffInArbitration));
        assert_eq!(c.tec(), 0);
        // The ACK exception only holds while error passive.
        let ack = TransmitErrorCause::AckWhilePassive {
            dominant_in_passive_flag: false,
        };
        c.on_event(Event::TransmitError(ack));
        assert_eq!(c.tec(), 8);
        for _ in 0..15 {
            c.on_event(Event::TransmitError(TransmitErrorCause::Other));
        }
        assert_eq!((c.tec(), c.state()), (128, NodeState::ErrorPassive));
        c.on_event(Event::TransmitError(ack));
        assert_eq!(c.tec(), 128);
        c.on_event(Event::TransmitSuccess);
        assert_eq!((c.tec(), c.state()), (127, NodeState::ErrorActive));

        let mut r = Confinement::default();
        r.on_event(Event::ReceiveError);
        r.on_event(Event::DominantAfterErrorFlag);
        assert_eq!(r.rec(), 9);
        for _ in 0..15 {
            r.on_event(Event::BitErrorInFlag { transmitter: false });
        }
        assert_eq!((r.rec(), r.state()), (129, NodeState::ErrorPassive));
        r.on_event(Event::ReceiveSuccess);
        assert_eq!(
            (r.rec(), r.state()),
            (REC_AFTER_PASSIVE_RECEPTION, NodeState::ErrorActive)
        );
        r.on_event(Event::ReceiveSuccess);
        assert_eq!(r.rec(), REC_AFTER_PASSIVE_RECEPTION - 1);
        // A receive error never leads to bus-off.
        for _ in 0..1000 {
            r.on_event(Event::ReceiveError);
        }
        assert_eq!(r.state(), NodeState::ErrorPassive);
    }
}
