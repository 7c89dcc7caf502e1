//! The tug's secured variant: every message of the command path authenticated (CMAC-AES-128
//! with AUTOSAR profile 1's wire layout — 8 freshness bits and a 24-bit MAC after the payload
//! — over a 64-bit freshness value: profile 1's own 8-bit value would wrap after 255 frames,
//! five seconds of commands), as CAN FD frames on bus 1 and 1b.
//!
//! Secured: the ADS's command and emergency brake, the safety controller's E-stop, and the
//! vehicle's state, wheel-speed and wheel-angle reports. Each keeps its 8-byte payload (counter
//! and CRC unchanged) and gains the freshness value's low 8 bits and a 24-bit MAC: 12 bytes, one
//! FD frame (DLC 9) with the data phase at 2 Mbit/s. The data ID of each is its identifier.
//! Freshness syncs go on [`SYNC_ID`].
//!
//! Why FD and not a companion frame (the command's 8 bytes have no room for 32 more bits):
//! one frame is atomic — a command and its MAC cannot be separated by a lost, delayed or
//! interleaved frame, so the receiver needs no pairing state and acts on the command as soon as
//! it ends — and it is shorter on the bus. [`variant_costs`] gives both from the exact wire
//! model: at 500 kbit/s with a 2 Mbit/s data phase the secured command occupies the bus for
//! less time than the classic command alone (about 131 µs against 242 µs); a companion frame
//! adds a second frame after it (about 408 µs in all, and the command cannot be acted on
//! before its companion ends); even without the faster data phase the FD frame (about 338 µs)
//! is shorter than the pair. Over the apron loop the simulated bus 1 carries 4.5 % load
//! secured against 7.3 % plain.

use bywire_core::busload::{frame_time_ns, Bitrates};
use bywire_core::{Frame, Id, StandardId};
use bywire_secoc::{Key, Layout, LayoutError};
use bywire_vehicle::command::ControlCommand;
use bywire_vehicle::secured::{Secured, SecuredTable, SyncMessage, TableError};
use bywire_vehicle::wire::AdsWire;

use crate::messages::{
    AdsToVehicleControl, EmergencyBrake, EmergencyStop, VehicleToAdsSensors, VehicleToAdsState,
    VehicleToAdsWheelAngles,
};
use crate::wire::ReferenceWire;

/// The tug's wire: the reference wire, secured or as it is.
pub type TugWire = Secured<ReferenceWire>;

/// The freshness value's length (SecOCFreshnessValueLength), bits.
pub const FRESHNESS_BITS: u32 = 64;
/// Its low bits sent (SecOCFreshnessValueTxLength), as profile 1.
pub const FRESHNESS_TX_BITS: u32 = 8;
/// The MAC's bits sent (SecOCAuthInfoTxLength), as profile 1.
pub const MAC_TX_BITS: u32 = 24;
/// The messages secured, by identifier (each also its data ID).
pub const SECURED: [u32; 6] = [
    EmergencyBrake::ID,
    EmergencyStop::ID,
    AdsToVehicleControl::ID,
    VehicleToAdsState::ID,
    VehicleToAdsSensors::ID,
    VehicleToAdsWheelAngles::ID,
];
/// The freshness-sync message's identifier (and data ID).
pub const SYNC_ID: u32 = 0x0F0;
/// How far ahead of the last accepted freshness a value may be: a sender restarting from its
/// store may skip at most this many (its reservation step must not exceed it).
pub const WINDOW: u64 = 1024;
/// The data-phase bitrate of bus 1 and 1b in the secured variant.
pub const DATA_BITRATE: u32 = 2_000_000;

fn standard(id: u32) -> Id {
    Id::Standard(StandardId::new(u16::try_from(id).unwrap_or(0)).unwrap_or(StandardId::ZERO))
}

/// Why the secured table could not be built (the lengths above are wrong: a build that
/// asked for the secured variant must not fall back to the plain one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum SecuredError {
    /// A message's lengths do not fit a frame.
    Layout(LayoutError),
    /// The table refused a message.
    Table(TableError),
}

impl core::fmt::Display for SecuredError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SecuredError::Layout(e) => write!(f, "the secured layout: {e}"),
            SecuredError::Table(e) => write!(f, "the secured table: {e}"),
        }
    }
}

impl std::error::Error for SecuredError {}

/// The secured messages' table for one node with `key`, its frames signed from freshness
/// `next` on (1 for a new key, a persisted value after a restart).
pub fn table(key: &Key, next: u64) -> Result<SecuredTable, SecuredError> {
    let mut table = SecuredTable::new(key, WINDOW);
    for id in SECURED {
        let data_id = u16::try_from(id).unwrap_or(u16::MAX);
        // 8 bytes of command, 1 of freshness sent, 3 of MAC: a 12-byte FD frame.
        let layout = Layout::new(data_id, 8, FRESHNESS_BITS, FRESHNESS_TX_BITS, MAC_TX_BITS)
            .map_err(SecuredError::Layout)?;
        table
            .secure(standard(id), layout, next)
            .map_err(SecuredError::Table)?;
    }
    table
        .with_sync(SyncMessage {
            id: standard(SYNC_ID),
            data_id: u16::try_from(SYNC_ID).unwrap_or(u16::MAX),
        })
        .map_err(SecuredError::Table)
}

/// The tug's wire secured with `key`, from freshness `next` on.
pub fn secured(key: &Key, next: u64) -> Result<TugWire, SecuredError> {
    Ok(Secured::new(ReferenceWire, table(key, next)?))
}

/// The tug's wire as it is.
pub fn plain() -> TugWire {
    Secured::plain(ReferenceWire)
}

/// One way of carrying the command's authenticator: its frames' time on the bus.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VariantCost {
    /// Time on the bus per command, interframe spaces included, µs.
    pub bus_us: f64,
    /// From the start of the command's first frame to the end of its last, µs (at the
    /// earliest: the companion frame right behind the command).
    pub latency_us: f64,
    /// Bus load of the command at 50 Hz, percent of the bus.
    pub load_percent_at_50hz: f64,
}

/// What each way of carrying the command costs on bus 1 (500 kbit/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VariantCosts {
    /// The 8-byte command as it is (no MAC).
    pub plain: VariantCost,
    /// Secured in one 12-byte FD frame, its data phase at [`DATA_BITRATE`] (the variant).
    pub fd: VariantCost,
    /// The same FD frame without bit-rate switching (a bus that cannot go faster).
    pub fd_without_brs: VariantCost,
    /// The classic command followed by a 4-byte classic companion frame with the freshness
    /// byte and the MAC.
    pub companion: VariantCost,
}

/// The costs of a typical command in each variant, from the exact wire model.
pub fn variant_costs() -> VariantCosts {
    let rates = Bitrates {
        nominal: 500_000,
        data: Some(DATA_BITRATE),
    };
    let command = ControlCommand {
        steering: 12.5,
        velocity: 3.0,
        ..ControlCommand::default()
    };
    let plain_frame = ReferenceWire.command_frame(&command, 5);
    let key = Key::new([0x5A; 16]);
    let fd_frame = secured(&key, 1)
        .ok()
        .and_then(|mut w| w.command_frame(&command, 5));
    // A companion frame: the freshness byte and the 24-bit MAC, 4 bytes, the next identifier.
    let companion = fd_frame.as_ref().and_then(|f| {
        let tail = f.data().get(8..12)?;
        Frame::classic(standard(AdsToVehicleControl::ID + 0x80), tail).ok()
    });
    let time = |f: &Option<Frame>| f.as_ref().map_or(0.0, |f| frame_time_ns(f, rates)) / 1e3;
    let cost = |bus_us: f64, latency_us: f64| VariantCost {
        bus_us,
        latency_us,
        load_percent_at_50hz: bus_us * 50.0 / 1e6 * 100.0,
    };
    let slow = fd_frame.map(|f| match f {
        Frame::Fd(fd) => {
            bywire_core::frame::FdFrame::new(fd.id(), fd.data(), false, false).map_or(f, Frame::Fd)
        }
        other => other,
    });
    let plain = time(&plain_frame);
    let fd = time(&fd_frame);
    let fd_slow = time(&slow);
    let pair = plain + time(&companion);
    VariantCosts {
        plain: cost(plain, plain),
        fd: cost(fd, fd),
        fd_without_brs: cost(fd_slow, fd_slow),
        companion: cost(pair, pair),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fd_variant_is_shorter_on_the_bus_than_the_plain_command_and_the_companion_longer() {
        let costs = variant_costs();
        let VariantCosts {
            plain,
            fd,
            fd_without_brs,
            companion,
        } = costs;
        // Exact stuffed lengths vary a few bits with the content; the order does not.
        assert!(plain.bus_us > 200.0 && plain.bus_us < 280.0, "{plain:?}");
        assert!(fd.bus_us < plain.bus_us, "{fd:?} vs {plain:?}");
        // Without the faster data phase the four bytes more cost, but less than a frame more.
        assert!(fd_without_brs.bus_us > plain.bus_us, "{fd_without_brs:?}");
        assert!(
            fd_without_brs.bus_us < companion.bus_us,
            "{fd_without_brs:?}"
        );
        assert!(companion.bus_us > plain.bus_us + 100.0, "{companion:?}");
        assert!(companion.latency_us > fd.latency_us);
    }

    #[test]
    fn every_secured_message_is_in_the_table_and_the_sync_apart() {
        let key = Key::new([1; 16]);
        let t = table(&key, 7).unwrap();
        for id in SECURED {
            assert_eq!(t.next_freshness(standard(id)), Some(7));
            assert_eq!(t.layout(standard(id)).map(|l| l.secured_length()), Some(12));
        }
        assert_eq!(t.next_freshness(standard(SYNC_ID)), None);
    }
}
