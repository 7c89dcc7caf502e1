//! Container frames split into the PDUs they carry (AUTOSAR's dynamic container layout): each
//! PDU behind a header of its identifier and length, one after another; a header of
//! identifier 0, or too few bytes left for a header, ends the frame (what follows is padding).

use crate::model::{ByteOrder, ContainerHeader};

/// Why a container frame does not split.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ContainerError {
    /// A header gives a length past the frame's end.
    #[error(
        "the contained PDU at byte {offset} (header ID {header_id:#x}) claims {length} bytes, \
         {available} are left"
    )]
    Overrun {
        /// Where its header starts.
        offset: usize,
        /// Its header identifier.
        header_id: u32,
        /// The length its header gives.
        length: usize,
        /// The bytes left after its header.
        available: usize,
    },
}

/// One PDU of a container frame: its header identifier and its bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ContainedPdu<'d> {
    /// The identifier its header gives.
    pub header_id: u32,
    /// Its bytes.
    pub data: &'d [u8],
}

/// The PDUs of a container frame, in order; an error ends them.
#[derive(Debug, Clone)]
pub struct Split<'d> {
    header: ContainerHeader,
    byte_order: ByteOrder,
    data: &'d [u8],
    offset: usize,
    done: bool,
}

/// Split `data` into the PDUs behind headers of `header`'s kind, their fields in `byte_order`.
pub fn split(header: ContainerHeader, byte_order: ByteOrder, data: &[u8]) -> Split<'_> {
    Split {
        header,
        byte_order,
        data,
        offset: 0,
        done: false,
    }
}

fn field(bytes: &[u8], byte_order: ByteOrder) -> usize {
    let fold = |acc: usize, b: &u8| (acc << 8) | usize::from(*b);
    match byte_order {
        ByteOrder::BigEndian => bytes.iter().fold(0, fold),
        ByteOrder::LittleEndian => bytes.iter().rev().fold(0, fold),
    }
}

impl<'d> Iterator for Split<'d> {
    type Item = Result<ContainedPdu<'d>, ContainerError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let (id_size, length_size) = self.header.sizes();
        let header = self
            .data
            .get(self.offset..self.offset + id_size + length_size)?;
        let (id_bytes, length_bytes) = header.split_at(id_size);
        let header_id = u32::try_from(field(id_bytes, self.byte_order)).unwrap_or(u32::MAX);
        if header_id == 0 {
            self.done = true;
            return None;
        }
        let length = field(length_bytes, self.byte_order);
        let start = self.offset + id_size + length_size;
        let available = self.data.len() - start;
        match self.data.get(start..start.saturating_add(length)) {
            Some(data) => {
                self.offset = start + length;
                Some(Ok(ContainedPdu { header_id, data }))
            }
            None => {
                self.done = true;
                Some(Err(ContainerError::Overrun {
                    offset: self.offset,
                    header_id,
                    length,
                    available,
                }))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn short_headers_split_until_padding() {
        let frame = [
            0, 0, 1, 2, 0xAA, 0xBB, // PDU 1, two bytes
            0x12, 0x34, 0x56, 0, // PDU 0x123456, empty
            0, 0, 0, 0, 0xFF, 0xFF, // padding
        ];
        let pdus: Vec<_> = split(ContainerHeader::Short, ByteOrder::BigEndian, &frame)
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(
            pdus,
            [
                ContainedPdu {
                    header_id: 1,
                    data: &[0xAA, 0xBB]
                },
                ContainedPdu {
                    header_id: 0x12_3456,
                    data: &[]
                }
            ]
        );
    }

    #[test]
    fn long_little_endian_headers_and_a_length_past_the_end() {
        let frame = [7, 0, 0, 0, 1, 0, 0, 0, 9, 8, 0, 0, 0, 5, 0, 0, 0, 1];
        let mut pdus = split(ContainerHeader::Long, ByteOrder::LittleEndian, &frame);
        assert_eq!(
            pdus.next(),
            Some(Ok(ContainedPdu {
                header_id: 7,
                data: &[9]
            }))
        );
        assert_eq!(
            pdus.next(),
            Some(Err(ContainerError::Overrun {
                offset: 9,
                header_id: 8,
                length: 5,
                available: 1
            }))
        );
        assert_eq!(pdus.next(), None);
    }
}
