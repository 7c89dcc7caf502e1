//! Dictionary builders: the CiA 301 communication objects, PDO defaults, and the CiA 402
//! objects of a drive.

use super::{Mode, DEFAULT_ABORT_CONNECTION, DEFAULT_QUICK_STOP_OPTION};
use alloc::vec;

use crate::od::{Access, DataType, Entry, ObjectDictionary, ObjectKind};

/// The CiA 301 communication objects every device here has: device type, error register and
/// history, SYNC, name, EMCY, heartbeat consumer (four entries) and producer, identity.
pub fn communication_objects(
    od: &mut ObjectDictionary,
    node: u8,
    device_type: u32,
    name: &str,
    identity: [u32; 4],
) {
    let node32 = u32::from(node);
    od.add_var(
        0x1000,
        Entry::new(0, "Device type", DataType::U32, Access::ReadOnly)
            .with_int(i64::from(device_type)),
    );
    od.add_var(
        0x1001,
        Entry::new(0, "Error register", DataType::U8, Access::ReadOnly).mappable(),
    );
    od.add_object(
        0x1003,
        "Pre-defined error field",
        ObjectKind::Array,
        vec![
            Entry::new(0, "Number of errors", DataType::U8, Access::ReadWrite),
            Entry::new(1, "Standard error field", DataType::U32, Access::ReadOnly),
            Entry::new(2, "Standard error field", DataType::U32, Access::ReadOnly),
            Entry::new(3, "Standard error field", DataType::U32, Access::ReadOnly),
            Entry::new(4, "Standard error field", DataType::U32, Access::ReadOnly),
        ],
    );
    od.add_var(
        0x1005,
        Entry::new(0, "COB-ID SYNC", DataType::U32, Access::ReadWrite).with_int(0x80),
    );
    od.add_var(
        0x1006,
        Entry::new(
            0,
            "Communication cycle period",
            DataType::U32,
            Access::ReadWrite,
        ),
    );
    od.add_var(
        0x1008,
        Entry::new(
            0,
            "Manufacturer device name",
            DataType::VisibleString,
            Access::Const,
        )
        .with_default(name.as_bytes()),
    );
    od.add_var(
        0x1014,
        Entry::new(0, "COB-ID EMCY", DataType::U32, Access::ReadWrite)
            .with_int(i64::from(0x80 + node32)),
    );
    od.add_var(
        0x1015,
        Entry::new(0, "Inhibit time EMCY", DataType::U16, Access::ReadWrite),
    );
    od.add_object(
        0x1016,
        "Consumer heartbeat time",
        ObjectKind::Array,
        (1..=4)
            .map(|sub| {
                Entry::new(
                    sub,
                    "Consumer heartbeat time",
                    DataType::U32,
                    Access::ReadWrite,
                )
            })
            .collect(),
    );
    od.add_var(
        0x1017,
        Entry::new(
            0,
            "Producer heartbeat time",
            DataType::U16,
            Access::ReadWrite,
        )
        .with_int(100),
    );
    od.add_var(
        0x100C,
        Entry::new(0, "Guard time", DataType::U16, Access::ReadWrite),
    );
    od.add_var(
        0x100D,
        Entry::new(0, "Life time factor", DataType::U8, Access::ReadWrite),
    );
    od.add_object(
        0x1018,
        "Identity object",
        ObjectKind::Record,
        [
            "Vendor-ID",
            "Product code",
            "Revision number",
            "Serial number",
        ]
        .iter()
        .zip(identity)
        .zip(1u8..)
        .map(|((name, value), sub)| {
            Entry::new(sub, name, DataType::U32, Access::ReadOnly).with_int(i64::from(value))
        })
        .collect(),
    );
}

/// A PDO's communication and mapping parameters, as a dictionary describes them by default.
pub struct PdoDefault<'a> {
    /// PDO number from 1.
    pub number: u16,
    /// COB-ID (with bit 31 set for a disabled PDO).
    pub cob_id: u32,
    /// Transmission type.
    pub transmission: u8,
    /// Inhibit time, 100 µs.
    pub inhibit: u16,
    /// Event timer, ms.
    pub event_timer: u16,
    /// Mapped objects: `(index, sub, bits)`.
    pub mapping: &'a [(u16, u8, u8)],
}

/// Add a PDO's parameter objects (eight mapping entries).
pub fn add_pdo(od: &mut ObjectDictionary, transmit: bool, pdo: &PdoDefault<'_>) {
    let base = if transmit { 0x1800 } else { 0x1400 } + pdo.number - 1;
    let name = if transmit { "TPDO" } else { "RPDO" };
    od.add_object(
        base,
        &alloc::format!("{name}{} communication parameter", pdo.number),
        ObjectKind::Record,
        vec![
            Entry::new(1, "COB-ID", DataType::U32, Access::ReadWrite)
                .with_int(i64::from(pdo.cob_id)),
            Entry::new(2, "Transmission type", DataType::U8, Access::ReadWrite)
                .with_int(i64::from(pdo.transmission)),
            Entry::new(3, "Inhibit time", DataType::U16, Access::ReadWrite)
                .with_int(i64::from(pdo.inhibit)),
            Entry::new(5, "Event timer", DataType::U16, Access::ReadWrite)
                .with_int(i64::from(pdo.event_timer)),
            Entry::new(6, "SYNC start value", DataType::U8, Access::ReadWrite),
        ],
    );
    let mut entries: alloc::vec::Vec<Entry> = (1..=8u8)
        .map(|sub| {
            let raw =
                pdo.mapping
                    .get(usize::from(sub - 1))
                    .map_or(0, |(index, object_sub, bits)| {
                        (u32::from(*index) << 16) | (u32::from(*object_sub) << 8) | u32::from(*bits)
                    });
            Entry::new(
                sub,
                &alloc::format!("Mapped object {sub}"),
                DataType::U32,
                Access::ReadWrite,
            )
            .with_int(i64::from(raw))
        })
        .collect();
    let count = u8::try_from(pdo.mapping.len()).unwrap_or(0);
    entries.insert(
        0,
        Entry::new(
            0,
            "Number of mapped objects",
            DataType::U8,
            Access::ReadWrite,
        )
        .with_int(i64::from(count)),
    );
    od.add_object(
        base + 0x200,
        &alloc::format!("{name}{} mapping parameter", pdo.number),
        ObjectKind::Record,
        entries,
    );
}

/// The default PDO layout of [`drive_dictionary`], which [`DriveController`](super::DriveController) speaks:
/// RPDO1 `0x200+id` controlword + modes of operation; RPDO2 `0x300+id` target position +
/// target velocity; TPDO1 `0x180+id` statusword + modes display (on change and every 100 ms);
/// TPDO2 `0x280+id` position + velocity actual (on change, at most every 10 ms, and every
/// 100 ms).
pub fn drive_dictionary(node: u8) -> ObjectDictionary {
    use super::object::*;
    let mut od = ObjectDictionary::new();
    let id = u32::from(node);
    communication_objects(
        &mut od,
        node,
        DEVICE_TYPE,
        "bywire drive",
        [0x0000_0B1E, 0x0402, 1, id],
    );
    add_drive_objects(&mut od, Mode::SUPPORTED);
    add_pdo(
        &mut od,
        false,
        &PdoDefault {
            number: 1,
            cob_id: 0x200 + id,
            transmission: 255,
            inhibit: 0,
            event_timer: 0,
            mapping: &[(CONTROLWORD, 0, 16), (MODES, 0, 8)],
        },
    );
    add_pdo(
        &mut od,
        false,
        &PdoDefault {
            number: 2,
            cob_id: 0x300 + id,
            transmission: 255,
            inhibit: 0,
            event_timer: 0,
            mapping: &[(TARGET_POSITION, 0, 32), (TARGET_VELOCITY, 0, 32)],
        },
    );
    add_pdo(
        &mut od,
        true,
        &PdoDefault {
            number: 1,
            cob_id: 0x180 + id,
            transmission: 255,
            inhibit: 0,
            event_timer: 100,
            mapping: &[(STATUSWORD, 0, 16), (MODES_DISPLAY, 0, 8)],
        },
    );
    add_pdo(
        &mut od,
        true,
        &PdoDefault {
            number: 2,
            cob_id: 0x280 + id,
            transmission: 255,
            // Actual values change with every encoder tick: at most one TPDO2 per 10 ms.
            inhibit: 100,
            event_timer: 100,
            mapping: &[(POSITION_ACTUAL, 0, 32), (VELOCITY_ACTUAL, 0, 32)],
        },
    );
    od
}

/// The device type (0x1000) of a CiA 402 drive: profile 402, servo drive.
pub const DEVICE_TYPE: u32 = 0x0002_0192;

/// The CiA 402 objects a [`Drive`](super::Drive) works on (0x6007 to 0x6502), for a drive of its own or a
/// controller with a CiA 402 face beside its own objects; `supported_modes` for 0x6502.
pub fn add_drive_objects(od: &mut ObjectDictionary, supported_modes: u32) {
    use super::object::*;
    let rw = |name: &str, data_type| Entry::new(0, name, data_type, Access::ReadWrite).mappable();
    let ro = |name: &str, data_type| Entry::new(0, name, data_type, Access::ReadOnly).mappable();
    od.add_var(
        ABORT_CONNECTION,
        rw("Abort connection option code", DataType::I16).with_int(DEFAULT_ABORT_CONNECTION),
    );
    od.add_var(ERROR_CODE, ro("Error code", DataType::U16));
    od.add_var(CONTROLWORD, rw("Controlword", DataType::U16));
    od.add_var(STATUSWORD, ro("Statusword", DataType::U16));
    od.add_var(
        QUICK_STOP_OPTION,
        rw("Quick stop option code", DataType::I16).with_int(DEFAULT_QUICK_STOP_OPTION),
    );
    od.add_var(MODES, rw("Modes of operation", DataType::I8).with_int(3));
    od.add_var(
        MODES_DISPLAY,
        ro("Modes of operation display", DataType::I8),
    );
    od.add_var(POSITION_ACTUAL, ro("Position actual value", DataType::I32));
    od.add_var(VELOCITY_ACTUAL, ro("Velocity actual value", DataType::I32));
    od.add_var(TARGET_POSITION, rw("Target position", DataType::I32));
    od.add_var(
        PROFILE_VELOCITY,
        rw("Profile velocity", DataType::U32).with_int(2_000),
    );
    od.add_var(
        PROFILE_ACCELERATION,
        rw("Profile acceleration", DataType::U32).with_int(10_000),
    );
    od.add_var(
        PROFILE_DECELERATION,
        rw("Profile deceleration", DataType::U32).with_int(10_000),
    );
    od.add_var(
        QUICK_STOP_DECELERATION,
        rw("Quick stop deceleration", DataType::U32).with_int(50_000),
    );
    od.add_var(TARGET_VELOCITY, rw("Target velocity", DataType::I32));
    od.add_var(
        SUPPORTED_MODES,
        Entry::new(0, "Supported drive modes", DataType::U32, Access::ReadOnly)
            .with_int(i64::from(supported_modes)),
    );
}
