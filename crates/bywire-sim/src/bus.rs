//! The tug's four buses, by the names their logs and servers take.

/// The tug's buses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TugBus {
    /// Vehicle control, 500 kbit/s.
    Bus1,
    /// CANopen drives, 1 Mbit/s.
    Bus2,
    /// Sensors, 500 kbit/s.
    Bus3,
    /// The redundant command bus, 500 kbit/s.
    Bus1b,
}

impl TugBus {
    /// Every bus.
    pub const ALL: [TugBus; 4] = [TugBus::Bus1, TugBus::Bus2, TugBus::Bus3, TugBus::Bus1b];

    /// Its name, as its log file and servers call it.
    pub fn name(self) -> &'static str {
        match self {
            TugBus::Bus1 => "bus1",
            TugBus::Bus2 => "bus2",
            TugBus::Bus3 => "bus3",
            TugBus::Bus1b => "bus1b",
        }
    }

    /// The bus of this name (`bus1`, `bus2`, `bus3`, `bus1b`).
    pub fn named(name: &str) -> Option<TugBus> {
        TugBus::ALL.into_iter().find(|b| b.name() == name)
    }
}
