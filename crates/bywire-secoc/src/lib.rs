//! # bywire-secoc: authenticated CAN messages, as AUTOSAR SecOC defines them
//!
//! A rolling counter and a CRC catch stale and corrupted frames, not forged ones: their
//! polynomial and data ID are public. SecOC adds a message authentication code over the
//! message's data ID, its payload and a *freshness value* that only grows, so a frame cannot be
//! forged without the key nor replayed once its freshness has been passed.
//!
//! - **Framing** ([`Layout`]), as AUTOSAR and cantools define it: the MAC is computed over
//!   data ID (16 bits, big-endian) ‖ the authentic payload ‖ the full freshness value (its
//!   `fv_length` bits, most significant first, zero-padded to a byte); on the wire the payload is
//!   followed by the freshness value's low `fv_tx_length` bits and the MAC's leading
//!   `mac_tx_length` bits, packed most significant bit first.
//! - **The MAC** ([`Authenticator`]): CMAC with AES-128 (RFC 4493), RustCrypto's `aes` and
//!   `cmac`; the comparison takes the same time whatever the bits.
//! - **Profiles** ([`PROFILES`]): AUTOSAR's "24Bit-CMAC-8Bit-FV" (profile 1) and
//!   "24Bit-CMAC-No-FV" (profile 2), or any lengths.
//! - **Freshness** ([`Sender`], [`Receiver`]): the sender counts up and refuses to go past the
//!   largest value (it never wraps into a value already used); the receiver rebuilds the full
//!   value from the bits on the wire (the low bits of the last accepted value replaced, carried
//!   into the high bits when they wrapped), accepts it only ahead of the last accepted value and
//!   within its window, and names each rejection ([`Rejection`]) and counts it ([`Counts`]).
//!
//! Everything on the control path is `no_std`, allocates nothing and runs in bounded time (at
//! most [`MAX_ATTEMPTS`] MACs per frame). With the `std` feature, [`keys`] reads key files
//! (refusing ones others can read, never printing a key) and [`store`] persists a sender's
//! freshness so that a restart is not a rewind.
//!
//! # A missing key
//! A message declared secured whose key is missing is a configuration error: the caller must
//! refuse to start. There is no fallback to sending or accepting it unauthenticated.
//!
//! ```
//! use bywire_secoc::{Authenticator, Key, Layout, Receiver, Sender, profile};
//! let key = Key::new([0x2b; 16]);
//! let auth = Authenticator::new(&key);
//! let layout = Layout::of_profile(profile("24Bit-CMAC-8Bit-FV").unwrap(), 0x0100, 4).unwrap();
//! let mut frame = [0x11, 0x22, 0x33, 0x44, 0, 0, 0, 0];
//! let mut sender = Sender::new(1);
//! sender.sign(&auth, &layout, &mut frame).unwrap();
//! let mut receiver = Receiver::new(0, 16);
//! assert_eq!(receiver.accept(&auth, &layout, &frame), Ok(1));
//! // The same frame again is a replay.
//! assert!(receiver.accept(&auth, &layout, &frame).is_err());
//! ```
// The control path is `no_std`: built without the `std` feature, it has no standard library.
#![cfg_attr(not(feature = "std"), no_std)]
#![cfg_attr(docsrs, feature(doc_auto_cfg))]

#[cfg(feature = "std")]
pub mod keys;
#[cfg(feature = "std")]
pub mod store;

use core::fmt;

use aes::Aes128;
use cmac::{Cmac, KeyInit, Mac};

/// The longest authentic payload (a CAN FD frame).
pub const MAX_PAYLOAD: usize = 64;
/// The longest freshness value, in bits.
pub const MAX_FRESHNESS_BITS: u32 = 64;
/// The longest MAC, in bits (the whole CMAC).
pub const MAC_BITS: u32 = 128;
/// The most MACs a receiver computes for one frame: the fresh candidates, and on failure the
/// older ones that tell a replay from a forgery.
pub const MAX_ATTEMPTS: u64 = 8;

/// A named set of lengths (AUTOSAR's SecOC profiles).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Profile {
    /// The profile's name, as AUTOSAR writes it.
    pub name: &'static str,
    /// SecOCFreshnessValueLength, in bits.
    pub fv_length: u32,
    /// SecOCFreshnessValueTxLength: the low bits of the freshness value sent.
    pub fv_tx_length: u32,
    /// SecOCAuthInfoTxLength: the leading bits of the MAC sent.
    pub mac_tx_length: u32,
}

/// AUTOSAR's SecOC profiles 1 and 2 (both CMAC/AES-128).
pub const PROFILES: &[Profile] = &[
    Profile {
        name: "24Bit-CMAC-8Bit-FV",
        fv_length: 8,
        fv_tx_length: 8,
        mac_tx_length: 24,
    },
    Profile {
        name: "24Bit-CMAC-No-FV",
        fv_length: 0,
        fv_tx_length: 0,
        mac_tx_length: 24,
    },
];

/// A profile by name (case-insensitive).
pub fn profile(name: &str) -> Option<&'static Profile> {
    PROFILES.iter().find(|p| p.name.eq_ignore_ascii_case(name))
}

/// Why lengths do not make a layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum LayoutError {
    /// The authentic payload is longer than [`MAX_PAYLOAD`].
    Payload(usize),
    /// The freshness value is longer than 64 bits.
    Freshness(u32),
    /// More freshness bits sent than the freshness value has.
    FreshnessTx {
        /// Sent.
        tx: u32,
        /// The whole value.
        length: u32,
    },
    /// A MAC of no bits, or of more than 128.
    Mac(u32),
    /// The secured message is longer than [`MAX_PAYLOAD`].
    Secured(usize),
}

impl fmt::Display for LayoutError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LayoutError::Payload(n) => write!(f, "an authentic payload of {n} bytes (at most 64)"),
            LayoutError::Freshness(n) => write!(f, "a freshness value of {n} bits (at most 64)"),
            LayoutError::FreshnessTx { tx, length } => write!(
                f,
                "{tx} freshness bits sent of a freshness value of {length} bits"
            ),
            LayoutError::Mac(n) => write!(f, "a MAC of {n} bits sent (1 to 128)"),
            LayoutError::Secured(n) => {
                write!(f, "a secured message of {n} bytes (at most 64)")
            }
        }
    }
}

/// Where a secured message's parts are, and what its MAC covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// The data ID the MAC covers (SecOCDataId).
    pub data_id: u16,
    /// The authentic payload's length in bytes; the freshness and MAC bits follow it.
    pub payload_length: usize,
    /// The freshness value's length in bits.
    pub fv_length: u32,
    /// Its low bits sent.
    pub fv_tx_length: u32,
    /// The MAC's leading bits sent.
    pub mac_tx_length: u32,
}

impl Layout {
    /// A layout from its lengths (bits for freshness and MAC, bytes for the payload).
    pub fn new(
        data_id: u16,
        payload_length: usize,
        fv_length: u32,
        fv_tx_length: u32,
        mac_tx_length: u32,
    ) -> Result<Layout, LayoutError> {
        if payload_length > MAX_PAYLOAD {
            return Err(LayoutError::Payload(payload_length));
        }
        if fv_length > MAX_FRESHNESS_BITS {
            return Err(LayoutError::Freshness(fv_length));
        }
        if fv_tx_length > fv_length {
            return Err(LayoutError::FreshnessTx {
                tx: fv_tx_length,
                length: fv_length,
            });
        }
        if mac_tx_length == 0 || mac_tx_length > MAC_BITS {
            return Err(LayoutError::Mac(mac_tx_length));
        }
        let layout = Layout {
            data_id,
            payload_length,
            fv_length,
            fv_tx_length,
            mac_tx_length,
        };
        if layout.secured_length() > MAX_PAYLOAD {
            return Err(LayoutError::Secured(layout.secured_length()));
        }
        Ok(layout)
    }

    /// A profile's lengths for a message.
    pub fn of_profile(
        profile: &Profile,
        data_id: u16,
        payload_length: usize,
    ) -> Result<Layout, LayoutError> {
        Layout::new(
            data_id,
            payload_length,
            profile.fv_length,
            profile.fv_tx_length,
            profile.mac_tx_length,
        )
    }

    /// The bytes the secured message needs: the payload, then the freshness and MAC bits.
    pub fn secured_length(&self) -> usize {
        // Saturating: the fields are public, and a hand-made layout must not overflow here.
        let bits = self.fv_tx_length.saturating_add(self.mac_tx_length);
        self.payload_length
            .saturating_add(usize::try_from(bits.div_ceil(8)).unwrap_or(usize::MAX))
    }

    /// The largest freshness value.
    pub fn freshness_max(&self) -> u64 {
        low_mask(self.fv_length)
    }

    /// The freshness bits a secured message carries.
    pub fn sent_freshness(&self, data: &[u8]) -> Option<u64> {
        let data = data.get(..self.secured_length())?;
        Some(read_bits(data, self.payload_length * 8, self.fv_tx_length))
    }
}

/// The low `bits` bits set.
fn low_mask(bits: u32) -> u64 {
    if bits >= 64 {
        u64::MAX
    } else {
        (1u64 << bits) - 1
    }
}

/// Bit `index` of `data`, most significant bit of the first byte first.
fn bit(data: &[u8], index: usize) -> bool {
    data.get(index / 8)
        .is_some_and(|b| b & (0x80 >> (index % 8)) != 0)
}

fn set_bit(data: &mut [u8], index: usize, on: bool) {
    if let Some(b) = data.get_mut(index / 8) {
        let mask = 0x80 >> (index % 8);
        if on {
            *b |= mask;
        } else {
            *b &= !mask;
        }
    }
}

/// `count` bits (≤ 64) from `offset`, as a number.
fn read_bits(data: &[u8], offset: usize, count: u32) -> u64 {
    (0..usize::try_from(count).unwrap_or(0))
        .fold(0u64, |v, i| (v << 1) | u64::from(bit(data, offset + i)))
}

/// Write the low `count` bits (≤ 64) of `value` at `offset`.
fn write_bits(data: &mut [u8], offset: usize, count: u32, value: u64) {
    for i in 0..count {
        set_bit(
            data,
            offset + usize::try_from(i).unwrap_or(0),
            (value >> (count - 1 - i)) & 1 == 1,
        );
    }
}

/// A 128-bit AES key. Its `Debug` never shows it.
#[derive(Clone, PartialEq, Eq)]
pub struct Key([u8; 16]);

impl Key {
    /// A key from its bytes.
    pub fn new(bytes: [u8; 16]) -> Key {
        Key(bytes)
    }
}

impl fmt::Debug for Key {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Key(<redacted>)")
    }
}

/// Why a message cannot be signed or checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum SecOcError {
    /// The buffer is shorter than the secured message.
    Short {
        /// Bytes the layout needs.
        needed: usize,
        /// Bytes given.
        given: usize,
    },
    /// The freshness value does not fit its length, or the sender has used the last one (a
    /// new key is needed: it never wraps into values already used).
    FreshnessExhausted,
}

impl fmt::Display for SecOcError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SecOcError::Short { needed, given } => {
                write!(f, "{given} bytes where the secured message needs {needed}")
            }
            SecOcError::FreshnessExhausted => {
                f.write_str("the freshness value is past its largest value (a new key is needed)")
            }
        }
    }
}

/// CMAC-AES-128 with one key, its key schedule computed once.
#[derive(Clone)]
pub struct Authenticator {
    cmac: Cmac<Aes128>,
}

impl fmt::Debug for Authenticator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Authenticator(<key redacted>)")
    }
}

impl Authenticator {
    /// An authenticator with `key`.
    pub fn new(key: &Key) -> Authenticator {
        Authenticator {
            cmac: <Cmac<Aes128> as KeyInit>::new(&key.0.into()),
        }
    }

    /// The whole CMAC of `message`.
    pub fn cmac(&self, message: &[u8]) -> [u8; 16] {
        let mut mac = self.cmac.clone();
        mac.update(message);
        let mut out = [0u8; 16];
        out.copy_from_slice(mac.finalize().into_bytes().as_slice());
        out
    }

    /// The whole MAC of a secured message's payload with `freshness`: over data ID ‖ payload ‖
    /// freshness value.
    pub fn mac(
        &self,
        layout: &Layout,
        data: &[u8],
        freshness: u64,
    ) -> Result<[u8; 16], SecOcError> {
        if freshness > layout.freshness_max() {
            return Err(SecOcError::FreshnessExhausted);
        }
        let payload = data.get(..layout.payload_length).ok_or(SecOcError::Short {
            needed: layout.payload_length,
            given: data.len(),
        })?;
        // data ID (2) + payload (≤ 64) + freshness (≤ 8), on the stack.
        let mut input = [0u8; 2 + MAX_PAYLOAD + 8];
        let [hi, lo] = layout.data_id.to_be_bytes();
        let freshness_bytes = usize::try_from(layout.fv_length.div_ceil(8)).unwrap_or(8);
        let length = 2 + payload.len() + freshness_bytes;
        let Some(input) = input.get_mut(..length) else {
            return Err(SecOcError::Short {
                needed: length,
                given: 2 + MAX_PAYLOAD + 8,
            });
        };
        let (id, rest) = input.split_at_mut(2);
        id.copy_from_slice(&[hi, lo]);
        let (body, fresh) = rest.split_at_mut(payload.len());
        body.copy_from_slice(payload);
        write_bits(fresh, 0, layout.fv_length, freshness);
        Ok(self.cmac(input))
    }

    /// Sign `data` in place with `freshness`: its low bits and the MAC's leading bits written
    /// after the payload (bits of `data` beyond them are left as they are).
    pub fn sign(&self, layout: &Layout, freshness: u64, data: &mut [u8]) -> Result<(), SecOcError> {
        let needed = layout.secured_length();
        if data.len() < needed {
            return Err(SecOcError::Short {
                needed,
                given: data.len(),
            });
        }
        let mac = self.mac(layout, data, freshness)?;
        let at = layout.payload_length * 8;
        write_bits(
            data,
            at,
            layout.fv_tx_length,
            freshness & low_mask(layout.fv_tx_length),
        );
        let at = at + usize::try_from(layout.fv_tx_length).unwrap_or(0);
        for i in 0..usize::try_from(layout.mac_tx_length).unwrap_or(0) {
            set_bit(data, at + i, bit(&mac, i));
        }
        Ok(())
    }

    /// Whether `data`'s MAC bits are those of `freshness` (its freshness bits are not looked
    /// at: the receiver has rebuilt the value from them). Compares every bit, whatever differs.
    pub fn mac_matches(&self, layout: &Layout, freshness: u64, data: &[u8]) -> bool {
        if data.len() < layout.secured_length() {
            return false;
        }
        let Ok(mac) = self.mac(layout, data, freshness) else {
            return false;
        };
        let at = layout.payload_length * 8 + usize::try_from(layout.fv_tx_length).unwrap_or(0);
        let differ = (0..usize::try_from(layout.mac_tx_length).unwrap_or(0))
            .fold(false, |d, i| d | (bit(&mac, i) != bit(data, at + i)));
        !differ
    }

    /// Whether `data` is exactly what signing its payload with `freshness` gives (freshness
    /// bits and MAC), as cantools' `verify_authenticator` checks.
    pub fn verify(&self, layout: &Layout, freshness: u64, data: &[u8]) -> bool {
        layout.sent_freshness(data) == Some(freshness & low_mask(layout.fv_tx_length))
            && self.mac_matches(layout, freshness, data)
    }
}

/// The sending side's freshness: the next value, never reused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sender {
    next: u64,
    /// The largest value possible has been used.
    exhausted: bool,
}

impl Sender {
    /// Counting from `next` (1 for a new key; a persisted value after a restart).
    pub fn new(next: u64) -> Sender {
        Sender {
            next,
            exhausted: false,
        }
    }

    /// The value the next message is signed with.
    pub fn next(&self) -> u64 {
        self.next
    }

    /// Sign `data` with the next freshness value, which is then used up; the value used.
    pub fn sign(
        &mut self,
        auth: &Authenticator,
        layout: &Layout,
        data: &mut [u8],
    ) -> Result<u64, SecOcError> {
        if self.exhausted {
            return Err(SecOcError::FreshnessExhausted);
        }
        let freshness = self.next;
        // Past the layout's largest value nothing more is signed (a new key is needed).
        auth.sign(layout, freshness, data)?;
        match freshness.checked_add(1) {
            Some(next) => self.next = next,
            None => self.exhausted = true,
        }
        Ok(freshness)
    }

    /// A freshness-sync value from the receiver's side: go on after it (never back).
    pub fn resync(&mut self, accepted: u64) {
        match accepted.checked_add(1) {
            Some(after) => self.next = self.next.max(after),
            None => self.exhausted = true,
        }
    }
}

/// Why a receiver refused a secured message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Rejection {
    /// Shorter than the secured message.
    Malformed,
    /// The MAC is that of no freshness value tried: forged, corrupted, or another key.
    Mac,
    /// Authentic, but with a freshness value not newer than the last accepted: a replayed
    /// message, or a sender whose freshness went back (a restart without its persisted value).
    Stale,
    /// Authentic and newer, but further ahead than the window allows (the sender needs a
    /// resynchronisation).
    Window,
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Rejection::Malformed => "shorter than the secured message",
            Rejection::Mac => "the MAC does not match (forged or corrupted)",
            Rejection::Stale => "authentic but not fresh (a replay, or the sender went back)",
            Rejection::Window => "authentic but beyond the freshness window",
        })
    }
}

/// A receiver's counts, one per outcome.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counts {
    /// Messages accepted.
    pub accepted: u64,
    /// [`Rejection::Malformed`].
    pub malformed: u64,
    /// [`Rejection::Mac`].
    pub mac: u64,
    /// [`Rejection::Stale`].
    pub stale: u64,
    /// [`Rejection::Window`].
    pub window: u64,
}

impl Counts {
    /// Every rejection.
    pub fn rejected(&self) -> u64 {
        self.malformed
            .saturating_add(self.mac)
            .saturating_add(self.stale)
            .saturating_add(self.window)
    }

    /// Count one outcome (a receiver's, or a sum over several).
    pub fn record(&mut self, outcome: Result<u64, Rejection>) {
        let slot = match outcome {
            Ok(_) => &mut self.accepted,
            Err(Rejection::Malformed) => &mut self.malformed,
            Err(Rejection::Mac) => &mut self.mac,
            Err(Rejection::Stale) => &mut self.stale,
            Err(Rejection::Window) => &mut self.window,
        };
        *slot = slot.saturating_add(1);
    }
}

/// The receiving side's freshness for one message: the last accepted value and how far ahead
/// of it a new one may be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Receiver {
    last: u64,
    window: u64,
    counts: Counts,
}

impl Receiver {
    /// Having accepted `last` (0 for a new key; a persisted or synchronised value otherwise),
    /// accepting values up to `window` ahead of the last accepted one (at least 1).
    pub fn new(last: u64, window: u64) -> Receiver {
        Receiver {
            last,
            window: window.max(1),
            counts: Counts::default(),
        }
    }

    /// The last accepted freshness value.
    pub fn last(&self) -> u64 {
        self.last
    }

    /// The counts so far.
    pub fn counts(&self) -> Counts {
        self.counts
    }

    /// Check a secured message: its freshness rebuilt, its MAC checked; the freshness value
    /// accepted (it becomes the last), or why not. Counted either way.
    pub fn accept(
        &mut self,
        auth: &Authenticator,
        layout: &Layout,
        data: &[u8],
    ) -> Result<u64, Rejection> {
        let outcome = self.judge(auth, layout, data);
        if let Ok(freshness) = outcome {
            self.last = freshness;
        }
        self.counts.record(outcome);
        outcome
    }

    fn judge(&self, auth: &Authenticator, layout: &Layout, data: &[u8]) -> Result<u64, Rejection> {
        let sent = layout.sent_freshness(data).ok_or(Rejection::Malformed)?;
        let max = layout.freshness_max();
        if layout.fv_length == 0 {
            // No freshness at all (profile 2): authenticity only, no replay protection.
            return if auth.mac_matches(layout, 0, data) {
                Ok(0)
            } else {
                Err(Rejection::Mac)
            };
        }
        let authentic = |fv: u64| auth.mac_matches(layout, fv, data);
        let step = (layout.fv_tx_length < 64).then(|| 1u64 << layout.fv_tx_length);
        let (fresh, older) = candidates(self.last, sent, step, max, self.window);
        for fv in fresh.into_iter().flatten() {
            if authentic(fv) {
                return if fv.saturating_sub(self.last) <= self.window {
                    Ok(fv)
                } else {
                    Err(Rejection::Window)
                };
            }
        }
        // Only to name the failure: an older value that makes the MAC right is a replay.
        if older.into_iter().flatten().any(authentic) {
            return Err(Rejection::Stale);
        }
        Err(Rejection::Mac)
    }
}

/// The freshness values a message with `sent` low bits may carry after `last`: the newer ones
/// within the window, in order (the first is the value the bits name, carried into the high
/// bits when they wrapped; just that one when even it is beyond the window, to name the
/// rejection), and the two latest older ones (to tell a replay from a forgery). A step of
/// `None` means every bit is sent.
fn candidates(
    last: u64,
    sent: u64,
    step: Option<u64>,
    max: u64,
    window: u64,
) -> ([Option<u64>; 6], [Option<u64>; 2]) {
    let mut fresh = [None; 6];
    let Some(step) = step else {
        // Every bit sent: the value itself.
        return if sent > last {
            ([Some(sent), None, None, None, None, None], [None; 2])
        } else {
            ([None; 6], [Some(sent), None])
        };
    };
    let same = (last & !(step - 1)) | sent;
    let (first, newest_old) = if same > last {
        (Some(same), same.checked_sub(step))
    } else {
        (same.checked_add(step), Some(same))
    };
    let older = [newest_old, newest_old.and_then(|v| v.checked_sub(step))];
    let limit = last.saturating_add(window).min(max);
    let mut next = first.filter(|v| *v <= max);
    for slot in fresh.iter_mut() {
        match next {
            Some(v) if v <= limit => {
                *slot = Some(v);
                next = v.checked_add(step);
            }
            _ => break,
        }
    }
    if fresh[0].is_none() {
        fresh[0] = first.filter(|v| *v <= max);
    }
    (fresh, older)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;

    fn hex(text: &str) -> [u8; 16] {
        let mut out = [0u8; 16];
        for (i, b) in out.iter_mut().enumerate() {
            *b = u8::from_str_radix(&text[i * 2..i * 2 + 2], 16).unwrap();
        }
        out
    }

    fn bytes(text: &str) -> ([u8; 64], usize) {
        let mut out = [0u8; 64];
        let n = text.len() / 2;
        for (i, b) in out.iter_mut().take(n).enumerate() {
            *b = u8::from_str_radix(&text[i * 2..i * 2 + 2], 16).unwrap();
        }
        (out, n)
    }

    /// RFC 4493 section 4's four examples.
    #[test]
    fn cmac_aes_128_gives_rfc_4493s_vectors() {
        let auth = Authenticator::new(&Key::new(hex("2b7e151628aed2a6abf7158809cf4f3c")));
        let message = "6bc1bee22e409f96e93d7e117393172aae2d8a571e03ac9c9eb76fac45af8e5130c81c46a35ce411e5fbc1191a0a52eff69f2445df4f9b17ad2b417be66c3710";
        for (length, tag) in [
            (0, "bb1d6929e95937287fa37d129b756746"),
            (16, "070a16b46b4d4144f79bdd9dd04a287c"),
            (40, "dfa66747de9ae63030ca32611497c827"),
            (64, "51f0bebf7e3b9d92fc49741779363cfe"),
        ] {
            let (m, _) = bytes(message);
            assert_eq!(auth.cmac(&m[..length]), hex(tag), "{length} bytes");
        }
    }

    #[test]
    fn layouts_refuse_lengths_that_do_not_fit() {
        assert_eq!(Layout::new(1, 65, 8, 8, 24), Err(LayoutError::Payload(65)));
        assert_eq!(
            Layout::new(1, 4, 65, 8, 24),
            Err(LayoutError::Freshness(65))
        );
        assert_eq!(
            Layout::new(1, 4, 8, 9, 24),
            Err(LayoutError::FreshnessTx { tx: 9, length: 8 })
        );
        assert_eq!(Layout::new(1, 4, 8, 8, 0), Err(LayoutError::Mac(0)));
        assert_eq!(Layout::new(1, 4, 8, 8, 129), Err(LayoutError::Mac(129)));
        assert_eq!(Layout::new(1, 60, 8, 8, 128), Err(LayoutError::Secured(77)));
        let l = Layout::new(1, 4, 32, 4, 28).unwrap();
        assert_eq!(l.secured_length(), 8);
        assert_eq!(l.freshness_max(), u64::from(u32::MAX));
    }

    #[test]
    fn bits_are_packed_most_significant_first_after_the_payload() {
        let auth = Authenticator::new(&Key::new([7; 16]));
        // 4 freshness bits then a 12-bit MAC: the freshness in the high nibble of byte 2.
        let layout = Layout::new(0x0102, 2, 16, 4, 12).unwrap();
        let mut data = [0xAB, 0xCD, 0, 0, 0x55];
        auth.sign(&layout, 0x1235, &mut data).unwrap();
        let mac = auth.mac(&layout, &data, 0x1235).unwrap();
        assert_eq!(data[..2], [0xAB, 0xCD]);
        assert_eq!(data[2] >> 4, 0x5);
        assert_eq!(
            (u16::from(data[2] & 0x0F) << 8) | u16::from(data[3]),
            (u16::from(mac[0]) << 4) | u16::from(mac[1] >> 4)
        );
        assert_eq!(
            data[4], 0x55,
            "bytes after the authenticator are left alone"
        );
        assert!(auth.verify(&layout, 0x1235, &data));
        assert!(!auth.verify(&layout, 0x1236, &data));
    }

    fn profile1() -> (Authenticator, Layout) {
        let auth = Authenticator::new(&Key::new([0x42; 16]));
        let layout = Layout::of_profile(profile("24bit-cmac-8bit-fv").unwrap(), 0x0100, 4).unwrap();
        (auth, layout)
    }

    fn signed(auth: &Authenticator, layout: &Layout, freshness: u64, payload: u8) -> [u8; 8] {
        let mut data = [payload, 2, 3, 4, 0, 0, 0, 0];
        auth.sign(layout, freshness, &mut data).unwrap();
        data
    }

    #[test]
    fn the_receiver_carries_the_high_bits_when_the_low_ones_wrap() {
        let auth = Authenticator::new(&Key::new([0x42; 16]));
        // 16-bit freshness, 8 bits sent.
        let layout = Layout::new(7, 4, 16, 8, 24).unwrap();
        let mut receiver = Receiver::new(0x01FE, 16);
        assert_eq!(
            receiver.accept(&auth, &layout, &signed(&auth, &layout, 0x01FF, 1)),
            Ok(0x01FF)
        );
        // Low bits 0x03 after 0xFF: the next block.
        assert_eq!(
            receiver.accept(&auth, &layout, &signed(&auth, &layout, 0x0203, 1)),
            Ok(0x0203)
        );
        assert_eq!(receiver.last(), 0x0203);
        // A value skipped ahead within the window is accepted; beyond it, refused as such.
        assert_eq!(
            receiver.accept(&auth, &layout, &signed(&auth, &layout, 0x0213, 1)),
            Ok(0x0213)
        );
        assert_eq!(
            receiver.accept(&auth, &layout, &signed(&auth, &layout, 0x0240, 1)),
            Err(Rejection::Window)
        );
        // The old ones again: replays.
        assert_eq!(
            receiver.accept(&auth, &layout, &signed(&auth, &layout, 0x0213, 1)),
            Err(Rejection::Stale)
        );
        assert_eq!(
            receiver.accept(&auth, &layout, &signed(&auth, &layout, 0x0203, 1)),
            Err(Rejection::Stale)
        );
        // A forged MAC.
        let mut forged = signed(&auth, &layout, 0x0214, 1);
        forged[7] ^= 1;
        assert_eq!(
            receiver.accept(&auth, &layout, &forged),
            Err(Rejection::Mac)
        );
        // Another key's message.
        let other = Authenticator::new(&Key::new([0x43; 16]));
        assert_eq!(
            receiver.accept(&auth, &layout, &signed(&other, &layout, 0x0214, 1)),
            Err(Rejection::Mac)
        );
        assert_eq!(
            receiver.accept(&auth, &layout, &[1, 2, 3]),
            Err(Rejection::Malformed)
        );
        assert_eq!(
            receiver.counts(),
            Counts {
                accepted: 3,
                malformed: 1,
                mac: 2,
                stale: 2,
                window: 1
            }
        );
        assert_eq!(receiver.counts().rejected(), 6);
        assert_eq!(receiver.last(), 0x0213);
    }

    #[test]
    fn profile_1_rejects_a_replay_and_a_changed_payload() {
        let (auth, layout) = profile1();
        let mut sender = Sender::new(1);
        let mut receiver = Receiver::new(0, 4);
        let mut frames = [[0u8; 8]; 3];
        for (i, frame) in frames.iter_mut().enumerate() {
            *frame = [u8::try_from(i).unwrap(), 0, 0, 0, 0, 0, 0, 0];
            sender.sign(&auth, &layout, frame).unwrap();
            assert_eq!(receiver.accept(&auth, &layout, frame), Ok(i as u64 + 1));
        }
        assert_eq!(
            receiver.accept(&auth, &layout, &frames[1]),
            Err(Rejection::Stale)
        );
        let mut changed = frames[2];
        changed[0] ^= 0x80;
        assert_eq!(
            receiver.accept(&auth, &layout, &changed),
            Err(Rejection::Mac)
        );
        // An 8-bit freshness is used up at 255: the sender refuses to wrap.
        let mut sender = Sender::new(255);
        let mut frame = [0u8; 8];
        assert_eq!(sender.sign(&auth, &layout, &mut frame), Ok(255));
        assert_eq!(
            sender.sign(&auth, &layout, &mut frame),
            Err(SecOcError::FreshnessExhausted)
        );
    }

    #[test]
    fn a_sender_resynchronised_goes_on_after_the_receivers_value_never_back() {
        let mut sender = Sender::new(5);
        sender.resync(100);
        assert_eq!(sender.next(), 101);
        sender.resync(3);
        assert_eq!(sender.next(), 101);
    }

    #[test]
    fn profile_2_checks_authenticity_only() {
        let auth = Authenticator::new(&Key::new([1; 16]));
        let layout = Layout::of_profile(profile("24Bit-CMAC-No-FV").unwrap(), 9, 5).unwrap();
        assert_eq!(layout.secured_length(), 8);
        let mut data = [1, 2, 3, 4, 5, 0, 0, 0];
        auth.sign(&layout, 0, &mut data).unwrap();
        let mut receiver = Receiver::new(0, 1);
        assert_eq!(receiver.accept(&auth, &layout, &data), Ok(0));
        assert_eq!(receiver.accept(&auth, &layout, &data), Ok(0));
        data[1] = 9;
        assert_eq!(receiver.accept(&auth, &layout, &data), Err(Rejection::Mac));
    }

    #[test]
    fn no_freshness_bits_sent_tries_the_next_values_within_the_window() {
        let auth = Authenticator::new(&Key::new([1; 16]));
        let layout = Layout::new(9, 4, 32, 0, 32).unwrap();
        let mut receiver = Receiver::new(10, 3);
        assert_eq!(
            receiver.accept(&auth, &layout, &signed(&auth, &layout, 12, 0)),
            Ok(12)
        );
        assert_eq!(
            receiver.accept(&auth, &layout, &signed(&auth, &layout, 12, 0)),
            Err(Rejection::Stale)
        );
        assert_eq!(
            receiver.accept(&auth, &layout, &signed(&auth, &layout, 16, 0)),
            Err(Rejection::Mac),
            "beyond the window is not tried"
        );
    }

    #[test]
    fn the_full_value_sent_is_taken_as_it_is() {
        let auth = Authenticator::new(&Key::new([1; 16]));
        let layout = Layout::new(9, 0, 64, 64, 64).unwrap();
        let mut receiver = Receiver::new(1 << 40, 1 << 20);
        let sign = |fv| {
            let mut d = [0u8; 16];
            auth.sign(&layout, fv, &mut d).unwrap();
            d
        };
        assert_eq!(
            receiver.accept(&auth, &layout, &sign((1 << 40) + 5)),
            Ok((1 << 40) + 5)
        );
        assert_eq!(
            receiver.accept(&auth, &layout, &sign(1 << 40)),
            Err(Rejection::Stale)
        );
        assert_eq!(
            receiver.accept(&auth, &layout, &sign(u64::MAX)),
            Err(Rejection::Window)
        );
    }

    #[test]
    fn errors_say_what_is_wrong_and_keys_never_print() {
        let said = [
            (LayoutError::Payload(65).to_string(), "65 bytes"),
            (LayoutError::Freshness(70).to_string(), "70 bits"),
            (
                LayoutError::FreshnessTx { tx: 9, length: 8 }.to_string(),
                "9 freshness bits sent of a freshness value of 8",
            ),
            (LayoutError::Mac(0).to_string(), "MAC of 0 bits"),
            (LayoutError::Secured(77).to_string(), "77 bytes"),
            (
                SecOcError::Short {
                    needed: 8,
                    given: 3,
                }
                .to_string(),
                "3 bytes where the secured message needs 8",
            ),
            (SecOcError::FreshnessExhausted.to_string(), "new key"),
            (Rejection::Malformed.to_string(), "shorter"),
            (Rejection::Mac.to_string(), "MAC does not match"),
            (Rejection::Stale.to_string(), "not fresh"),
            (Rejection::Window.to_string(), "window"),
        ];
        for (text, expected) in said {
            assert!(text.contains(expected), "{text:?} lacks {expected:?}");
        }
        let key = Key::new([0xA5; 16]);
        for shown in [
            format!("{key:?}"),
            format!("{:?}", Authenticator::new(&key)),
        ] {
            assert!(shown.contains("redacted"), "{shown}");
            assert!(
                !shown.contains("165") && !shown.to_lowercase().contains("a5"),
                "{shown}"
            );
        }
    }

    #[test]
    fn short_buffers_are_refused_never_read_or_written_past() {
        let (auth, layout) = profile1();
        let mut short = [1u8, 2, 3];
        assert_eq!(
            auth.sign(&layout, 1, &mut short),
            Err(SecOcError::Short {
                needed: 8,
                given: 3
            })
        );
        assert_eq!(short, [1, 2, 3], "nothing written");
        assert_eq!(
            auth.mac(&layout, &short, 1),
            Err(SecOcError::Short {
                needed: 4,
                given: 3
            })
        );
        let good = signed(&auth, &layout, 1, 9);
        assert!(!auth.mac_matches(&layout, 1, &good[..7]));
        assert!(auth.mac_matches(&layout, 1, &good));
        assert!(!auth.mac_matches(&layout, layout.freshness_max() + 1, &good));
    }

    #[test]
    fn a_sender_past_the_largest_freshness_signs_nothing_more() {
        let auth = Authenticator::new(&Key::new([3; 16]));
        // An 8-bit freshness value: 255 is the last one a key may sign.
        let layout = Layout::new(5, 2, 8, 8, 24).unwrap();
        let mut sender = Sender::new(255);
        let mut data = [1u8, 2, 0, 0, 0, 0];
        assert_eq!(sender.sign(&auth, &layout, &mut data), Ok(255));
        let mut again = [1u8, 2, 0, 0, 0, 0];
        assert_eq!(
            sender.sign(&auth, &layout, &mut again),
            Err(SecOcError::FreshnessExhausted)
        );
        assert_eq!(again, [1, 2, 0, 0, 0, 0], "nothing signed");
        // A 64-bit value: the last one is signed once, and the sender never wraps to zero.
        let layout = Layout::new(5, 0, 64, 64, 32).unwrap();
        let mut sender = Sender::new(u64::MAX);
        let mut data = [0u8; 12];
        assert_eq!(sender.sign(&auth, &layout, &mut data), Ok(u64::MAX));
        assert_eq!(
            sender.sign(&auth, &layout, &mut data),
            Err(SecOcError::FreshnessExhausted)
        );
        let mut resynced = Sender::new(1);
        resynced.resync(u64::MAX);
        assert_eq!(
            resynced.sign(&auth, &layout, &mut data),
            Err(SecOcError::FreshnessExhausted)
        );
    }

    proptest::proptest! {
        /// Whatever the lengths and the sender's steps (within the window), every message is
        /// accepted with the value it was signed with, and none twice.
        #[test]
        fn signed_in_order_is_accepted_in_order(
            fv_length in 1u32..=64,
            tx in 0u32..=64,
            mac in 1u32..=64,
            steps in proptest::collection::vec(1u64..=4, 1..40),
            start in 0u64..1_000_000,
        ) {
            let tx = tx.min(fv_length);
            let layout = Layout::new(3, 8, fv_length, tx, mac).unwrap();
            let auth = Authenticator::new(&Key::new([9; 16]));
            let start = start & layout.freshness_max();
            let mut receiver = Receiver::new(start, 4);
            let mut fv = start;
            for step in steps {
                let Some(next) = fv.checked_add(step).filter(|v| *v <= layout.freshness_max()) else { break };
                fv = next;
                let mut data = [0x5Au8; 24];
                auth.sign(&layout, fv, &mut data).unwrap();
                // A short MAC may collide with an older value's; only a whole one cannot.
                let outcome = receiver.accept(&auth, &layout, &data);
                if mac >= 32 {
                    proptest::prop_assert_eq!(outcome, Ok(fv));
                    proptest::prop_assert_eq!(receiver.accept(&auth, &layout, &data), Err(Rejection::Stale));
                }
            }
        }

        /// Any bytes: no panic, and a rejection is counted.
        #[test]
        fn any_bytes_are_judged_without_a_panic(
            data in proptest::collection::vec(proptest::num::u8::ANY, 0..70),
            last in proptest::num::u64::ANY,
            fv_length in 0u32..=64,
            tx in 0u32..=64,
        ) {
            let tx = tx.min(fv_length);
            let layout = Layout::new(3, 4, fv_length, tx, 24).unwrap();
            let auth = Authenticator::new(&Key::new([9; 16]));
            let mut receiver = Receiver::new(last, 8);
            let _ = receiver.accept(&auth, &layout, &data);
            proptest::prop_assert_eq!(receiver.counts().accepted + receiver.counts().rejected(), 1);
        }
    }
}
