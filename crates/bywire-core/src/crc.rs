//! The CRCs of CAN and of AUTOSAR end-to-end protection.
//!
//! CAN computes its CRCs bit by bit over sequences that are not whole bytes (SOF through data),
//! so the core is a bit-serial register ([`CrcRegister`]); the byte functions feed it MSB first
//! and serve for check values. The E2E CRCs are byte-oriented and table-driven, since they run
//! once per protected message on the control path.

/// A non-reflected CRC register of up to 32 bits, fed one bit at a time (MSB-first order).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CrcRegister {
    value: u32,
    poly: u32,
    top: u32,
    mask: u32,
}

impl CrcRegister {
    /// CRC-15/CAN: classic CAN frames, polynomial 0x4599, initial value 0.
    pub const fn crc15() -> Self {
        Self::new(15, 0x4599, 0)
    }

    /// CRC-17 of ISO CAN FD frames with up to 16 data bytes: polynomial 0x1685B, initial value
    /// with the most significant bit set (ISO 11898-1:2015; the Bosch "non-ISO" FD used 0).
    pub const fn crc17_iso() -> Self {
        Self::new(17, 0x1_685B, 1 << 16)
    }

    /// CRC-21 of ISO CAN FD frames with more than 16 data bytes: polynomial 0x102899, initial
    /// value with the most significant bit set.
    pub const fn crc21_iso() -> Self {
        Self::new(21, 0x10_2899, 1 << 20)
    }

    /// A register of `width` bits (1..=32) with polynomial `poly` (without the x^width term).
    pub const fn new(width: u8, poly: u32, init: u32) -> Self {
        let mask = if width >= 32 {
            u32::MAX
        } else {
            (1u32 << width) - 1
        };
        CrcRegister {
            value: init & mask,
            poly: poly & mask,
            top: 1u32 << (width - 1),
            mask,
        }
    }

    /// Shift one message bit in.
    #[inline]
    pub fn push_bit(&mut self, bit: bool) {
        let feedback = ((self.value & self.top) != 0) ^ bit;
        self.value = (self.value << 1) & self.mask;
        if feedback {
            self.value ^= self.poly;
        }
    }

    /// Shift the `count` low bits of `bits` in, most significant first.
    pub fn push_bits(&mut self, bits: u64, count: u8) {
        for i in (0..count.min(64)).rev() {
            self.push_bit((bits >> i) & 1 == 1);
        }
    }

    /// Shift whole bytes in, most significant bit first.
    pub fn push_bytes(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.push_bits(u64::from(b), 8);
        }
    }

    /// The register's value: the CRC of everything pushed so far.
    pub const fn value(&self) -> u32 {
        self.value
    }
}

/// CRC-15/CAN of whole bytes (check value for "123456789": 0x059E).
pub fn crc15_can(bytes: &[u8]) -> u16 {
    let mut r = CrcRegister::crc15();
    r.push_bytes(bytes);
    // 15 bits always fit.
    u16::try_from(r.value()).unwrap_or(0)
}

/// CRC-17/CAN-FD of whole bytes with initial value 0, as catalogued (check 0x04F03).
pub fn crc17_can_fd(bytes: &[u8]) -> u32 {
    let mut r = CrcRegister::new(17, 0x1_685B, 0);
    r.push_bytes(bytes);
    r.value()
}

/// CRC-21/CAN-FD of whole bytes with initial value 0, as catalogued (check 0x0ED841).
pub fn crc21_can_fd(bytes: &[u8]) -> u32 {
    let mut r = CrcRegister::new(21, 0x10_2899, 0);
    r.push_bytes(bytes);
    r.value()
}

// i runs below 256, the table's length.
#[allow(clippy::indexing_slicing)]
const fn crc8_table(poly: u8) -> [u8; 256] {
    let mut table = [0u8; 256];
    let mut i = 0;
    while i < 256 {
        // i < 256 always fits a byte.
        #[allow(clippy::cast_possible_truncation)]
        let mut c = i as u8;
        let mut bit = 0;
        while bit < 8 {
            c = if c & 0x80 != 0 {
                (c << 1) ^ poly
            } else {
                c << 1
            };
            bit += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
}

static SAE_J1850_TABLE: [u8; 256] = crc8_table(0x1D);
static H2F_TABLE: [u8; 256] = crc8_table(0x2F);

// A u8 index into a 256-entry table cannot be out of bounds.
#[allow(clippy::indexing_slicing)]
fn crc8_update(table: &[u8; 256], mut crc: u8, bytes: &[u8]) -> u8 {
    for &b in bytes {
        crc = table[usize::from(crc ^ b)];
    }
    crc
}

/// CRC-8 SAE J1850: polynomial 0x1D, initial value 0xFF, final XOR 0xFF (check 0x4B).
pub fn crc8_sae_j1850(bytes: &[u8]) -> u8 {
    crc8_update(&SAE_J1850_TABLE, 0xFF, bytes) ^ 0xFF
}

/// CRC-8H2F (AUTOSAR): polynomial 0x2F, initial value 0xFF, final XOR 0xFF (check 0xDF).
pub fn crc8_h2f(bytes: &[u8]) -> u8 {
    crc8_update(&H2F_TABLE, 0xFF, bytes) ^ 0xFF
}

/// AUTOSAR `Crc_CalculateCRC8`-style chaining: continue an SAE J1850 CRC from a previous result
/// (`start` is a previous return value; the first call of a chain passes 0xFF ^ 0xFF = 0x00
/// through [`crc8_sae_j1850`] instead).
pub fn crc8_sae_j1850_continue(start: u8, bytes: &[u8]) -> u8 {
    crc8_update(&SAE_J1850_TABLE, start ^ 0xFF, bytes) ^ 0xFF
}

/// `Crc_CalculateCRC8H2F`-style chaining, as [`crc8_sae_j1850_continue`].
pub fn crc8_h2f_continue(start: u8, bytes: &[u8]) -> u8 {
    crc8_update(&H2F_TABLE, start ^ 0xFF, bytes) ^ 0xFF
}

/// XOR of all bytes: the simplest checksum, common in legacy vehicle messages.
pub fn xor8(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0, |acc, b| acc ^ b)
}

#[cfg(test)]
mod tests {
    use super::*;

    const CHECK: &[u8] = b"123456789";

    #[test]
    fn published_check_values() {
        assert_eq!(crc15_can(CHECK), 0x059E);
        assert_eq!(crc17_can_fd(CHECK), 0x0_4F03);
        assert_eq!(crc21_can_fd(CHECK), 0x0E_D841);
        assert_eq!(crc8_sae_j1850(CHECK), 0x4B);
        assert_eq!(crc8_h2f(CHECK), 0xDF);
        assert_eq!(xor8(&[0x0F, 0xF0, 0x01]), 0xFE);
    }

    #[test]
    fn chaining_equals_one_pass() {
        let (a, b) = CHECK.split_at(4);
        assert_eq!(
            crc8_sae_j1850_continue(crc8_sae_j1850(a), b),
            crc8_sae_j1850(CHECK)
        );
        assert_eq!(crc8_h2f_continue(crc8_h2f(a), b), crc8_h2f(CHECK));
    }
}
