//! A fixed-capacity sequence of bus levels.

use core::fmt;

/// The most bits one frame occupies on the bus, with room to spare: the longest ISO CAN FD frame
/// (extended identifier, 64 bytes, worst-case stuffing) is under 740 bits from SOF through EOF.
pub const MAX_FRAME_BITS: usize = 768;

const WORDS: usize = MAX_FRAME_BITS / 64;

/// Bus levels in time order: `false` is dominant (0), `true` recessive (1).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct BitSeq {
    words: [u64; WORDS],
    len: u16,
}

/// A bit sequence longer than [`MAX_FRAME_BITS`], or text that is not 0s and 1s.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum BitSeqError {
    /// More bits than a frame can have.
    #[error("more than {MAX_FRAME_BITS} bits")]
    TooLong,
    /// A character other than 0, 1, or a separator.
    #[error("character {index} ('{found}') is not 0 or 1")]
    NotABit {
        /// 0-based character index.
        index: usize,
        /// The character.
        found: char,
    },
}

impl Default for BitSeq {
    fn default() -> Self {
        Self::new()
    }
}

impl BitSeq {
    /// An empty sequence.
    pub const fn new() -> Self {
        BitSeq {
            words: [0; WORDS],
            len: 0,
        }
    }

    /// Number of bits.
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// Whether there are no bits.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Append a bit; fails only past [`MAX_FRAME_BITS`].
    pub fn push(&mut self, bit: bool) -> Result<(), BitSeqError> {
        let i = self.len();
        let word = self.words.get_mut(i / 64).ok_or(BitSeqError::TooLong)?;
        if bit {
            *word |= 1 << (i % 64);
        } else {
            *word &= !(1 << (i % 64));
        }
        self.len += 1;
        Ok(())
    }

    /// The bit at `index`, if there is one.
    pub fn get(&self, index: usize) -> Option<bool> {
        if index >= self.len() {
            return None;
        }
        self.words
            .get(index / 64)
            .map(|w| (w >> (index % 64)) & 1 == 1)
    }

    /// Invert the bit at `index` (a disturbance on the bus); false if out of range.
    pub fn flip(&mut self, index: usize) -> bool {
        if index >= self.len() {
            return false;
        }
        match self.words.get_mut(index / 64) {
            Some(w) => {
                *w ^= 1 << (index % 64);
                true
            }
            None => false,
        }
    }

    /// Drop bits from `len` on.
    pub fn truncate(&mut self, len: usize) {
        if len < self.len() {
            // len < self.len <= u16::MAX
            self.len = u16::try_from(len).unwrap_or(self.len);
        }
    }

    /// The bits in order.
    pub fn iter(&self) -> impl Iterator<Item = bool> + '_ {
        (0..self.len()).map(|i| self.get(i).unwrap_or(true))
    }

    /// Parse a string of `0` and `1`; spaces, `_`, `|` and `.` are ignored as separators.
    pub fn parse_levels(text: &str) -> Result<BitSeq, BitSeqError> {
        let mut seq = BitSeq::new();
        for (index, c) in text.chars().enumerate() {
            match c {
                '0' => seq.push(false)?,
                '1' => seq.push(true)?,
                ' ' | '_' | '|' | '.' | '\t' | '\n' | '\r' => {}
                found => return Err(BitSeqError::NotABit { index, found }),
            }
        }
        Ok(seq)
    }
}

impl fmt::Display for BitSeq {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for bit in self.iter() {
            f.write_str(if bit { "1" } else { "0" })?;
        }
        Ok(())
    }
}

impl fmt::Debug for BitSeq {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "BitSeq({self})")
    }
}
