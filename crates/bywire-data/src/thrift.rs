//! Thrift's compact protocol, writing only: what a Parquet footer and page headers are made of
//! (Parquet's `parquet.thrift`), for [`crate::encode`]'s files.
//!
//! Each `write_*` writes one field of the struct being written, by its field id; fields go in
//! increasing id order, as the protocol's deltas expect.

/// The compact protocol's type codes.
#[derive(Clone, Copy)]
#[repr(u8)]
pub(crate) enum Kind {
    I8 = 3,
    I32 = 5,
    I64 = 6,
    Binary = 8,
    List = 9,
    Struct = 12,
}

/// A value being written in the compact protocol.
#[derive(Default)]
pub(crate) struct Thrift {
    pub(crate) bytes: Vec<u8>,
    /// The last field id written in the struct being written.
    last: i16,
    /// The enclosing structs' last field ids.
    outer: Vec<i16>,
}

/// `value` as an unsigned LEB128 varint (Thrift's and Parquet's run headers).
pub(crate) fn varint(out: &mut Vec<u8>, mut value: u64) {
    while value >= 0x80 {
        out.push((value & 0x7f) as u8 | 0x80);
        value >>= 7;
    }
    out.push((value & 0x7f) as u8);
}

impl Thrift {
    fn varint(&mut self, value: u64) {
        varint(&mut self.bytes, value);
    }

    fn zigzag(&mut self, value: i64) {
        #[allow(clippy::cast_sign_loss)] // zigzag: the sign moves to the lowest bit
        self.varint(((value << 1) ^ (value >> 63)) as u64);
    }

    fn field(&mut self, id: i16, kind: u8) {
        let delta = u8::try_from(id - self.last)
            .ok()
            .filter(|d| (1..=15).contains(d));
        if let Some(delta) = delta {
            self.bytes.push((delta << 4) | kind);
        } else {
            self.bytes.push(kind);
            self.zigzag(i64::from(id));
        }
        self.last = id;
    }

    pub(crate) fn i8(&mut self, id: i16, value: i8) {
        // A byte is itself, not a varint.
        self.field(id, Kind::I8 as u8);
        self.bytes.push(value.to_le_bytes()[0]);
    }

    pub(crate) fn i32(&mut self, id: i16, value: i32) {
        self.field(id, Kind::I32 as u8);
        self.zigzag(i64::from(value));
    }

    pub(crate) fn i64(&mut self, id: i16, value: i64) {
        self.field(id, Kind::I64 as u8);
        self.zigzag(value);
    }

    pub(crate) fn binary(&mut self, id: i16, value: &[u8]) {
        self.field(id, Kind::Binary as u8);
        self.list_item_binary(value);
    }

    pub(crate) fn bool(&mut self, id: i16, value: bool) {
        // Booleans are in the field's type: 1 true, 2 false.
        self.field(id, if value { 1 } else { 2 });
    }

    /// A struct field: its fields follow, then [`Thrift::end`].
    pub(crate) fn begin(&mut self, id: i16) {
        self.field(id, Kind::Struct as u8);
        self.outer.push(self.last);
        self.last = 0;
    }

    /// A struct as a list's element: its fields follow, then [`Thrift::end`].
    pub(crate) fn begin_item(&mut self) {
        self.outer.push(self.last);
        self.last = 0;
    }

    /// The end of a struct (the top one's too).
    pub(crate) fn end(&mut self) {
        self.bytes.push(0);
        self.last = self.outer.pop().unwrap_or(0);
    }

    /// A list field of `len` elements of `kind`: the elements follow.
    pub(crate) fn list(&mut self, id: i16, kind: Kind, len: usize) {
        self.field(id, Kind::List as u8);
        if len < 15 {
            #[allow(clippy::cast_possible_truncation)] // below 15
            self.bytes.push(((len as u8) << 4) | kind as u8);
        } else {
            self.bytes.push(0xf0 | kind as u8);
            self.varint(len as u64);
        }
    }

    pub(crate) fn list_item_i32(&mut self, value: i32) {
        self.zigzag(i64::from(value));
    }

    pub(crate) fn list_item_binary(&mut self, value: &[u8]) {
        self.varint(value.len() as u64);
        self.bytes.extend_from_slice(value);
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn fields_are_deltas_or_ids_and_numbers_zigzag_varints() {
        let mut t = Thrift::default();
        t.i32(1, -1); // delta 1, I32: 0x15, zigzag(-1) = 1
        t.i64(17, 300); // delta 16: type byte then the id as a zigzag varint (34)
        t.bool(18, true);
        t.begin(19);
        t.binary(1, b"ab");
        t.end();
        t.list(20, Kind::I32, 2);
        t.list_item_i32(3);
        t.list_item_i32(-2);
        t.end();
        assert_eq!(
            t.bytes,
            [
                0x15, 0x01, // i32 1 = -1
                0x06, 0x22, 0xd8, 0x04, // i64 17 = 300 (zigzag 600)
                0x11, // bool 18 = true
                0x1c, 0x18, 0x02, b'a', b'b', 0x00, // struct 19 { binary 1 = "ab" }
                0x19, 0x25, 0x06, 0x03, // list 20 of two i32: 3, -2
                0x00
            ]
        );
    }
}
