//! The drive state machine (CiA 402 figure 12): states, controlword commands, events and
//! the one transition function; the modes of operation.

/// The drive states (CiA 402 figure 12).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum State {
    /// Initialising; not yet able to switch on.
    NotReadyToSwitchOn,
    /// Power stage off, waiting for Shutdown.
    SwitchOnDisabled,
    /// Ready; waiting for Switch on.
    ReadyToSwitchOn,
    /// Power stage on, not yet enabled.
    SwitchedOn,
    /// Following commands.
    OperationEnabled,
    /// Stopping with the quick stop ramp (or stopped, holding).
    QuickStopActive,
    /// A fault was detected; the drive is stopping.
    FaultReactionActive,
    /// Stopped on a fault; waiting for Fault reset.
    Fault,
}

impl State {
    /// The state bits of the statusword (bits 0-3, 5, 6).
    pub fn statusword_bits(self) -> u16 {
        match self {
            State::NotReadyToSwitchOn => 0x0000,
            State::SwitchOnDisabled => 0x0040,
            State::ReadyToSwitchOn => 0x0021,
            State::SwitchedOn => 0x0023,
            State::OperationEnabled => 0x0027,
            State::QuickStopActive => 0x0007,
            State::FaultReactionActive => 0x000F,
            State::Fault => 0x0008,
        }
    }

    /// The state a statusword reports (CiA 402 table 30 masks).
    pub fn from_statusword(statusword: u16) -> Option<State> {
        let wide = statusword & 0x4F;
        let narrow = statusword & 0x6F;
        Some(match (wide, narrow) {
            (0x00, _) => State::NotReadyToSwitchOn,
            (0x40, _) => State::SwitchOnDisabled,
            (0x0F, _) => State::FaultReactionActive,
            (0x08, _) => State::Fault,
            (_, 0x21) => State::ReadyToSwitchOn,
            (_, 0x23) => State::SwitchedOn,
            (_, 0x27) => State::OperationEnabled,
            (_, 0x07) => State::QuickStopActive,
            _ => return None,
        })
    }

    /// The power stage drives the motor.
    pub fn is_powered(self) -> bool {
        matches!(
            self,
            State::OperationEnabled | State::QuickStopActive | State::FaultReactionActive
        )
    }
}

/// A device-control command decoded from the controlword (CiA 402 table 28).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Command {
    /// 0xxx x110.
    Shutdown,
    /// 0xxx 0111.
    SwitchOn,
    /// 0xxx 1111: switch on and enable operation.
    EnableOperation,
    /// 0xxx xx0x.
    DisableVoltage,
    /// 0xxx x01x.
    QuickStop,
    /// 0xxx 0111 from Operation enabled.
    DisableOperation,
    /// Bit 7 rising.
    FaultReset,
    /// Nothing (bit 7 high without an edge, or a pattern naming no command).
    None,
}

/// Controlword values the master sends.
pub mod controlword {
    /// Shutdown.
    pub const SHUTDOWN: u16 = 0x0006;
    /// Switch on.
    pub const SWITCH_ON: u16 = 0x0007;
    /// Switch on + enable operation.
    pub const ENABLE_OPERATION: u16 = 0x000F;
    /// Disable voltage.
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    /// Quick stop.
    pub const QUICK_STOP: u16 = 0x0002;
    /// Fault reset (the rising edge counts).
    pub const FAULT_RESET: u16 = 0x0080;
    /// Profile position: new set-point.
    pub const NEW_SET_POINT: u16 = 0x0010;
    /// Profile position: change set immediately.
    pub const CHANGE_IMMEDIATELY: u16 = 0x0020;
    /// Halt.
    pub const HALT: u16 = 0x0100;
}

impl Command {
    /// Decode `controlword` given the previous one (fault reset is an edge) and whether the
    /// drive is in Operation enabled (switch on means disable operation there).
    pub fn decode(controlword: u16, previous: u16) -> Command {
        if controlword & 0x80 != 0 {
            return if previous & 0x80 == 0 {
                Command::FaultReset
            } else {
                Command::None
            };
        }
        if controlword & 0x02 == 0 {
            return Command::DisableVoltage;
        }
        if controlword & 0x04 == 0 {
            return Command::QuickStop;
        }
        match controlword & 0x0F {
            0x06 | 0x0E => Command::Shutdown,
            0x07 => Command::SwitchOn,
            0x0F => Command::EnableOperation,
            _ => Command::None,
        }
    }
}

/// What moves the state machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Event {
    /// Initialisation finished (transition 1).
    Initialised,
    /// A controlword command.
    Command(Command),
    /// A fault was detected (transition 13).
    Fault,
    /// The fault reaction finished (transition 14).
    FaultReactionDone,
    /// The quick stop ramp finished; the option code says whether to leave (transition 12).
    QuickStopDone {
        /// Quick stop option code 1-4: go to Switch on disabled.
        leave: bool,
    },
}

/// Quick stop option codes 5-8 allow returning to Operation enabled from Quick stop active.
/// The one transition function of the drive: every state and event is named.
pub fn transition(state: State, event: Event) -> State {
    use Command as C;
    use State as S;
    match (state, event) {
        (_, Event::Fault) if state != S::Fault => S::FaultReactionActive,
        (S::Fault, Event::Fault) => S::Fault,
        (S::NotReadyToSwitchOn, Event::Initialised) => S::SwitchOnDisabled,
        (S::NotReadyToSwitchOn, _) => S::NotReadyToSwitchOn,
        (S::SwitchOnDisabled, Event::Command(C::Shutdown)) => S::ReadyToSwitchOn,
        (S::SwitchOnDisabled, _) => S::SwitchOnDisabled,
        (S::ReadyToSwitchOn, Event::Command(C::SwitchOn)) => S::SwitchedOn,
        (S::ReadyToSwitchOn, Event::Command(C::EnableOperation)) => S::SwitchedOn,
        (S::ReadyToSwitchOn, Event::Command(C::DisableVoltage | C::QuickStop)) => {
            S::SwitchOnDisabled
        }
        (S::ReadyToSwitchOn, _) => S::ReadyToSwitchOn,
        (S::SwitchedOn, Event::Command(C::EnableOperation)) => S::OperationEnabled,
        (S::SwitchedOn, Event::Command(C::Shutdown)) => S::ReadyToSwitchOn,
        (S::SwitchedOn, Event::Command(C::DisableVoltage | C::QuickStop)) => S::SwitchOnDisabled,
        (S::SwitchedOn, _) => S::SwitchedOn,
        (S::OperationEnabled, Event::Command(C::SwitchOn | C::DisableOperation)) => S::SwitchedOn,
        (S::OperationEnabled, Event::Command(C::Shutdown)) => S::ReadyToSwitchOn,
        (S::OperationEnabled, Event::Command(C::DisableVoltage)) => S::SwitchOnDisabled,
        (S::OperationEnabled, Event::Command(C::QuickStop)) => S::QuickStopActive,
        (S::OperationEnabled, _) => S::OperationEnabled,
        (S::QuickStopActive, Event::Command(C::DisableVoltage)) => S::SwitchOnDisabled,
        (S::QuickStopActive, Event::QuickStopDone { leave: true }) => S::SwitchOnDisabled,
        (S::QuickStopActive, Event::Command(C::EnableOperation)) => S::OperationEnabled,
        (S::QuickStopActive, _) => S::QuickStopActive,
        (S::FaultReactionActive, Event::FaultReactionDone) => S::Fault,
        (S::FaultReactionActive, _) => S::FaultReactionActive,
        (S::Fault, Event::Command(C::FaultReset)) => S::SwitchOnDisabled,
        (S::Fault, _) => S::Fault,
    }
}

/// Modes of operation (0x6060) this drive runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    /// 1.
    ProfilePosition,
    /// 3.
    ProfileVelocity,
    /// 8.
    CyclicSynchronousPosition,
    /// 9.
    CyclicSynchronousVelocity,
}

impl Mode {
    /// The 0x6060 code.
    pub fn code(self) -> i8 {
        match self {
            Mode::ProfilePosition => 1,
            Mode::ProfileVelocity => 3,
            Mode::CyclicSynchronousPosition => 8,
            Mode::CyclicSynchronousVelocity => 9,
        }
    }

    /// The mode a 0x6060 code names.
    pub fn from_code(code: i64) -> Option<Mode> {
        match code {
            1 => Some(Mode::ProfilePosition),
            3 => Some(Mode::ProfileVelocity),
            8 => Some(Mode::CyclicSynchronousPosition),
            9 => Some(Mode::CyclicSynchronousVelocity),
            _ => None,
        }
    }

    /// Supported drive modes (0x6502) bits for every mode here.
    pub const SUPPORTED: u32 = 0x0001 | 0x0004 | 0x0080 | 0x0100;
}
