//! The safety mechanisms by name (ISO 26262-5 Annex D's and the seed's §12.4), as a
//! fault-injection campaign names the one it expects to detect a fault, and the set a
//! campaign switches off to show that its cells would notice a mechanism missing.
//!
//! Switching a mechanism off exists for that proof only: no profile or command line of a
//! vehicle can ask for it (`SupervisorConfig::disabled` is empty unless code sets it).

/// A safety mechanism.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Mechanism {
    /// CAN's own error detection and fault confinement, in the controllers (bit, stuff, CRC,
    /// form and acknowledgement errors; error counters to bus-off).
    Can,
    /// End-to-end protection of the command: its checksum and rolling counter.
    E2e,
    /// Message timeout: the watchdog cascade on missed commands, the E-stop chain's timeout.
    Timeout,
    /// Signal range check: setpoints outside the vehicle's limits (and non-finite ones).
    Range,
    /// Redundant communication: the command on two buses, voted.
    Redundancy,
    /// A 2-out-of-3 voter over redundant sensors.
    Voter,
    /// The safe state: full braking with the motors and steering off, the E-stop latch.
    SafeState,
    /// AUTOSAR SecOC: authenticated commands and freshness.
    Secoc,
    /// Driver takeover: the mode manager hands the vehicle to a driver's input at once.
    Takeover,
    /// Fail-operational control: a second control ECU or a backup actuator taking over.
    FailOperational,
}

impl Mechanism {
    /// Every mechanism, in the order a report's columns list them.
    pub const ALL: [Mechanism; 10] = [
        Mechanism::Can,
        Mechanism::E2e,
        Mechanism::Timeout,
        Mechanism::Range,
        Mechanism::Redundancy,
        Mechanism::Voter,
        Mechanism::SafeState,
        Mechanism::Secoc,
        Mechanism::Takeover,
        Mechanism::FailOperational,
    ];

    /// Those a campaign can switch off in the vehicle's software (`--disable`).
    pub const REMOVABLE: [Mechanism; 7] = [
        Mechanism::E2e,
        Mechanism::Timeout,
        Mechanism::Range,
        Mechanism::Redundancy,
        Mechanism::Voter,
        Mechanism::SafeState,
        Mechanism::Secoc,
    ];

    /// Its name in campaign files and reports.
    pub fn name(self) -> &'static str {
        match self {
            Mechanism::Can => "can",
            Mechanism::E2e => "e2e",
            Mechanism::Timeout => "timeout",
            Mechanism::Range => "range",
            Mechanism::Redundancy => "redundancy",
            Mechanism::Voter => "voter",
            Mechanism::SafeState => "safe-state",
            Mechanism::Secoc => "secoc",
            Mechanism::Takeover => "takeover",
            Mechanism::FailOperational => "fail-op",
        }
    }

    /// The mechanism of that name.
    pub fn from_name(name: &str) -> Option<Mechanism> {
        Mechanism::ALL.into_iter().find(|m| m.name() == name)
    }

    fn bit(self) -> u16 {
        1 << self as u16
    }
}

impl core::fmt::Display for Mechanism {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// A set of mechanisms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Mechanisms(u16);

impl Mechanisms {
    /// No mechanism.
    pub const NONE: Mechanisms = Mechanisms(0);

    /// The set with `m` added.
    pub fn with(self, m: Mechanism) -> Mechanisms {
        Mechanisms(self.0 | m.bit())
    }

    /// Whether `m` is in the set.
    pub fn contains(self, m: Mechanism) -> bool {
        self.0 & m.bit() != 0
    }

    /// Whether the set is empty.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// Its members, in [`Mechanism::ALL`]'s order.
    pub fn iter(self) -> impl Iterator<Item = Mechanism> {
        Mechanism::ALL
            .into_iter()
            .filter(move |m| self.contains(*m))
    }
}

impl FromIterator<Mechanism> for Mechanisms {
    fn from_iter<I: IntoIterator<Item = Mechanism>>(iter: I) -> Self {
        iter.into_iter().fold(Mechanisms::NONE, Mechanisms::with)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_go_both_ways_and_sets_hold_what_was_added() {
        for m in Mechanism::ALL {
            assert_eq!(Mechanism::from_name(m.name()), Some(m));
        }
        assert_eq!(Mechanism::from_name("crc"), None);
        let set: Mechanisms = [Mechanism::E2e, Mechanism::Secoc].into_iter().collect();
        assert!(set.contains(Mechanism::E2e) && set.contains(Mechanism::Secoc));
        assert!(!set.contains(Mechanism::Range));
        assert_eq!(
            set.iter().collect::<Vec<_>>(),
            [Mechanism::E2e, Mechanism::Secoc]
        );
        assert!(Mechanisms::NONE.is_empty());
    }
}
