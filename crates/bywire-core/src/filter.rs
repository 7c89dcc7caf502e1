//! Receive filters with SocketCAN semantics.
//!
//! A filter is a pair `can_id`/`can_mask` in the SocketCAN numeric form (identifier plus
//! EFF/RTR flag bits). A frame matches when `frame_id & mask == filter_id & mask`; the
//! [`INV_FILTER`] bit in `can_id` inverts that. Error frames are not matched by ordinary filters:
//! a socket receives them through its *error mask* (error classes it wants), or through a filter
//! whose mask has the ERR flag set. Matching here reproduces the Linux `can_raw` rules, including
//! the kernel's normalisation of filters at registration (a mask with the EFF flag on a standard
//! filter only compares 11 bits) and `CAN_RAW_JOIN_FILTERS`.
//!
//! The text forms are candump's: `123:7FF` (match), `123~7FF` (inverted), `#FFFFFFFF` (error
//! mask), `j` (join). An identifier written with 8 digits is taken as extended.

use core::str::FromStr;

use crate::frame::{Frame, EFF_FLAG, EFF_MASK, ERR_FLAG, RTR_FLAG, SFF_MASK};

/// Set in a filter's `can_id` to invert it (shares its value with the ERR flag).
pub const INV_FILTER: u32 = 0x2000_0000;

/// A SocketCAN `struct can_filter`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Filter {
    /// Identifier with flags; [`INV_FILTER`] inverts.
    pub can_id: u32,
    /// Bits of the frame's `can_id` that must match.
    pub can_mask: u32,
}

impl Filter {
    /// Accept every non-error frame (the default filter of a SocketCAN raw socket).
    pub const ALL: Filter = Filter {
        can_id: 0,
        can_mask: 0,
    };

    /// A filter from raw SocketCAN values.
    pub const fn new(can_id: u32, can_mask: u32) -> Filter {
        Filter { can_id, can_mask }
    }

    /// Exactly this standard or extended identifier, data frames only.
    pub fn exact(id: crate::Id) -> Filter {
        match id {
            crate::Id::Standard(s) => {
                Filter::new(u32::from(s.as_raw()), SFF_MASK | EFF_FLAG | RTR_FLAG)
            }
            crate::Id::Extended(e) => {
                Filter::new(e.as_raw() | EFF_FLAG, EFF_MASK | EFF_FLAG | RTR_FLAG)
            }
        }
    }

    /// The same filter, inverted (matches what it did not).
    pub const fn inverted(self) -> Filter {
        Filter::new(self.can_id ^ INV_FILTER, self.can_mask)
    }

    /// Whether `frame` passes this one filter, by the kernel's rules.
    pub fn matches(&self, frame: &Frame) -> bool {
        self.matches_can_id(frame.socketcan_id())
    }

    /// As [`Filter::matches`], on a SocketCAN `can_id` with flags.
    pub fn matches_can_id(&self, can_id: u32) -> bool {
        let mut id = self.can_id;
        let mut mask = self.can_mask;
        if mask & ERR_FLAG != 0 {
            // Registered on the error list: error frames with any of the mask's class bits.
            mask &= EFF_MASK;
            return can_id & ERR_FLAG != 0 && can_id & mask != 0;
        }
        if can_id & ERR_FLAG != 0 {
            return false;
        }
        let inverted = id & INV_FILTER != 0;
        if mask & EFF_FLAG != 0 && id & EFF_FLAG == 0 {
            mask &= SFF_MASK | EFF_FLAG | RTR_FLAG;
        }
        id &= mask;
        if inverted {
            can_id & mask != id
        } else {
            can_id & mask == id
        }
    }
}

/// Error classes a socket wants as error frames (`CAN_RAW_ERR_FILTER`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct ErrorMask(pub u32);

impl ErrorMask {
    /// No error frames (the kernel's default).
    pub const NONE: ErrorMask = ErrorMask(0);
    /// Every error class.
    pub const ALL: ErrorMask = ErrorMask(EFF_MASK);

    fn matches_can_id(self, can_id: u32) -> bool {
        can_id & ERR_FLAG != 0 && can_id & self.0 & EFF_MASK != 0
    }
}

/// The receive filtering of one socket: its filters, its error mask and the join option.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FilterSet<'a> {
    /// The filters; an empty list receives no data frames.
    pub filters: &'a [Filter],
    /// Error classes delivered as error frames.
    pub error_mask: ErrorMask,
    /// `CAN_RAW_JOIN_FILTERS`: a frame must match every filter instead of any.
    pub join: bool,
}

impl FilterSet<'static> {
    /// A fresh raw socket: every data frame, no error frames.
    pub const DEFAULT: FilterSet<'static> = FilterSet {
        filters: &[Filter::ALL],
        error_mask: ErrorMask::NONE,
        join: false,
    };
}

impl FilterSet<'_> {
    /// Whether a socket with these settings receives `frame`.
    pub fn accepts(&self, frame: &Frame) -> bool {
        let can_id = frame.socketcan_id();
        let error = self.error_mask.matches_can_id(can_id);
        // Without join, any one match delivers it: no need to count the rest.
        if !self.join || self.filters.len() <= 1 {
            return error || self.filters.iter().any(|f| f.matches_can_id(can_id));
        }
        let matches = self
            .filters
            .iter()
            .filter(|f| f.matches_can_id(can_id))
            .count()
            + usize::from(error);
        // With join the kernel counts the matches of one frame and delivers it once the count
        // reaches the number of filters.
        matches >= self.filters.len()
    }
}

/// One item of candump's filter list.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FilterItem {
    /// `id:mask` or `id~mask`.
    Filter(Filter),
    /// `#mask`: error classes.
    ErrorMask(ErrorMask),
    /// `j` or `J`: join the filters.
    Join,
}

/// A filter item that is not candump's syntax, with the 1-based column of the problem.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("column {column}: {reason} (expected id:mask, id~mask, #errmask or j)")]
pub struct ParseFilterError {
    /// 1-based column.
    pub column: usize,
    /// What is wrong.
    pub reason: &'static str,
}

fn hex32(text: &str, column: usize) -> Result<u32, ParseFilterError> {
    if text.is_empty() || text.len() > 8 {
        return Err(ParseFilterError {
            column,
            reason: "need 1 to 8 hex digits",
        });
    }
    u32::from_str_radix(text, 16).map_err(|_| ParseFilterError {
        column,
        reason: "not a hex number",
    })
}

impl FromStr for FilterItem {
    type Err = ParseFilterError;

    fn from_str(text: &str) -> Result<FilterItem, ParseFilterError> {
        if text == "j" || text == "J" {
            return Ok(FilterItem::Join);
        }
        if let Some(mask) = text.strip_prefix('#') {
            return hex32(mask, 2).map(|m| FilterItem::ErrorMask(ErrorMask(m)));
        }
        let Some(split) = text.find([':', '~']) else {
            return Err(ParseFilterError {
                column: 1,
                reason: "no ':' or '~'",
            });
        };
        let (id_text, rest) = text.split_at(split);
        let inverted = rest.starts_with('~');
        let mut can_id = hex32(id_text, 1)?;
        // candump never lets a data filter ask for error frames.
        let can_mask = hex32(rest.get(1..).unwrap_or(""), split + 2)? & !ERR_FLAG;
        if id_text.len() == 8 {
            can_id |= EFF_FLAG;
        }
        if inverted {
            can_id |= INV_FILTER;
        }
        Ok(FilterItem::Filter(Filter::new(can_id, can_mask)))
    }
}
