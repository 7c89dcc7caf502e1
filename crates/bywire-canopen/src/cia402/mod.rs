//! CiA 402 drives, on both ends of the wire: the device state machine driven by the
//! controlword and reported in the statusword (one exhaustive transition function), a drive
//! application with a motor model (profile position, profile velocity, cyclic synchronous
//! position and velocity), and the master-side [`DriveController`] that walks a drive to
//! Operation enabled, commands it, and brings it to a safe stop on heartbeat loss, EMCY or a
//! fault, staying stopped until the application acknowledges.

/// Controlword (0x6040), statusword (0x6041) and the other CiA 402 objects used here.
pub mod object {
    /// Abort connection option code.
    pub const ABORT_CONNECTION: u16 = 0x6007;
    /// Error code.
    pub const ERROR_CODE: u16 = 0x603F;
    /// Controlword.
    pub const CONTROLWORD: u16 = 0x6040;
    /// Statusword.
    pub const STATUSWORD: u16 = 0x6041;
    /// Quick stop option code.
    pub const QUICK_STOP_OPTION: u16 = 0x605A;
    /// Modes of operation.
    pub const MODES: u16 = 0x6060;
    /// Modes of operation display.
    pub const MODES_DISPLAY: u16 = 0x6061;
    /// Position actual value.
    pub const POSITION_ACTUAL: u16 = 0x6064;
    /// Velocity actual value.
    pub const VELOCITY_ACTUAL: u16 = 0x606C;
    /// Target position.
    pub const TARGET_POSITION: u16 = 0x607A;
    /// Profile velocity.
    pub const PROFILE_VELOCITY: u16 = 0x6081;
    /// Profile acceleration.
    pub const PROFILE_ACCELERATION: u16 = 0x6083;
    /// Profile deceleration.
    pub const PROFILE_DECELERATION: u16 = 0x6084;
    /// Quick stop deceleration.
    pub const QUICK_STOP_DECELERATION: u16 = 0x6085;
    /// Target velocity.
    pub const TARGET_VELOCITY: u16 = 0x60FF;
    /// Supported drive modes.
    pub const SUPPORTED_MODES: u16 = 0x6502;
}

mod controller;
#[cfg(feature = "alloc")]
mod dictionary;
#[cfg(feature = "alloc")]
mod drive;
mod state;

pub use controller::*;
#[cfg(feature = "alloc")]
pub use dictionary::*;
#[cfg(feature = "alloc")]
pub use drive::*;
pub use state::*;

#[cfg(test)]
mod tests {
    use super::*;

    const ALL_STATES: [State; 8] = [
        State::NotReadyToSwitchOn,
        State::SwitchOnDisabled,
        State::ReadyToSwitchOn,
        State::SwitchedOn,
        State::OperationEnabled,
        State::QuickStopActive,
        State::FaultReactionActive,
        State::Fault,
    ];

    #[test]
    fn statuswords_name_their_states() {
        for state in ALL_STATES {
            assert_eq!(State::from_statusword(state.statusword_bits()), Some(state));
            // Other bits (voltage enabled, remote, target reached) do not change the state.
            assert_eq!(
                State::from_statusword(state.statusword_bits() | 0x0610),
                Some(state)
            );
        }
    }

    #[test]
    fn controlword_commands_follow_table_28() {
        assert_eq!(Command::decode(0x0006, 0), Command::Shutdown);
        assert_eq!(Command::decode(0x0007, 0), Command::SwitchOn);
        assert_eq!(Command::decode(0x000F, 0), Command::EnableOperation);
        assert_eq!(Command::decode(0x0000, 0), Command::DisableVoltage);
        assert_eq!(Command::decode(0x0002, 0), Command::QuickStop);
        assert_eq!(Command::decode(0x0080, 0), Command::FaultReset);
        assert_eq!(Command::decode(0x0080, 0x0080), Command::None);
    }

    #[test]
    fn the_transitions_of_figure_12() {
        use Command as C;
        let walk = [
            (
                State::NotReadyToSwitchOn,
                Event::Initialised,
                State::SwitchOnDisabled,
            ),
            (
                State::SwitchOnDisabled,
                Event::Command(C::Shutdown),
                State::ReadyToSwitchOn,
            ),
            (
                State::ReadyToSwitchOn,
                Event::Command(C::SwitchOn),
                State::SwitchedOn,
            ),
            (
                State::SwitchedOn,
                Event::Command(C::EnableOperation),
                State::OperationEnabled,
            ),
            (
                State::OperationEnabled,
                Event::Command(C::SwitchOn),
                State::SwitchedOn,
            ),
            (
                State::SwitchedOn,
                Event::Command(C::Shutdown),
                State::ReadyToSwitchOn,
            ),
            (
                State::ReadyToSwitchOn,
                Event::Command(C::DisableVoltage),
                State::SwitchOnDisabled,
            ),
            (
                State::OperationEnabled,
                Event::Command(C::Shutdown),
                State::ReadyToSwitchOn,
            ),
            (
                State::OperationEnabled,
                Event::Command(C::DisableVoltage),
                State::SwitchOnDisabled,
            ),
            (
                State::SwitchedOn,
                Event::Command(C::QuickStop),
                State::SwitchOnDisabled,
            ),
            (
                State::OperationEnabled,
                Event::Command(C::QuickStop),
                State::QuickStopActive,
            ),
            (
                State::QuickStopActive,
                Event::QuickStopDone { leave: true },
                State::SwitchOnDisabled,
            ),
            (
                State::QuickStopActive,
                Event::QuickStopDone { leave: false },
                State::QuickStopActive,
            ),
            (
                State::OperationEnabled,
                Event::Fault,
                State::FaultReactionActive,
            ),
            (
                State::FaultReactionActive,
                Event::FaultReactionDone,
                State::Fault,
            ),
            (
                State::Fault,
                Event::Command(C::FaultReset),
                State::SwitchOnDisabled,
            ),
            (
                State::QuickStopActive,
                Event::Command(C::EnableOperation),
                State::OperationEnabled,
            ),
            (
                State::Fault,
                Event::Command(C::EnableOperation),
                State::Fault,
            ),
            (
                State::SwitchOnDisabled,
                Event::Command(C::EnableOperation),
                State::SwitchOnDisabled,
            ),
        ];
        for (from, event, to) in walk {
            assert_eq!(transition(from, event), to, "{from:?} + {event:?}");
        }
        // A fault is reached from every state.
        for state in ALL_STATES {
            let after = transition(state, Event::Fault);
            assert!(
                matches!(after, State::FaultReactionActive | State::Fault),
                "{state:?}"
            );
        }
    }
}
