//! SDO: the server a device runs and the client a master uses, each speaking expedited,
//! segmented and block transfers (with CRC), with abort codes and timeouts.
//!
//! Both are state machines driven by frames and time; they never block and never read a
//! clock. The server's buffers are sized when it is made, so serving never allocates.

use core::time::Duration;

/// Frames one SDO exchange may queue at once: a whole block (127 segments) and its end.
pub const OUTBOX: usize = 136;

/// The largest block a server or client offers (CiA 301 allows 1..=127 segments).
pub const MAX_BLOCK: u8 = 127;

/// How long a server waits for the client's next request in a transfer.
pub const SERVER_TIMEOUT: Duration = Duration::from_millis(1_000);

mod client;
mod frames;
mod server;

pub use client::*;
pub use frames::{abort_payload, crc16};
pub use server::*;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::abort::Abort;
    use crate::nmt::{classic, cob_id};
    use crate::od::{Access, DataType, Entry, ObjectDictionary};
    use alloc::vec::Vec;
    use bywire_core::frame::Frame;
    use bywire_core::time::Timestamp;

    struct Dictionary(ObjectDictionary);

    impl Objects for Dictionary {
        fn upload(&mut self, index: u16, sub: u8, into: &mut Vec<u8>) -> Result<(), Abort> {
            let value = self.0.read(index, sub)?;
            if value.len() > into.capacity() {
                return Err(Abort::OutOfMemory);
            }
            into.clear();
            into.extend_from_slice(value);
            Ok(())
        }
        fn check_download(&self, index: u16, sub: u8, _size: Option<usize>) -> Result<(), Abort> {
            let entry = self.0.entry(index, sub)?;
            if entry.access.writable() {
                Ok(())
            } else {
                Err(Abort::WriteReadOnly)
            }
        }
        fn download(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), Abort> {
            self.0.check_write(index, sub, data)?;
            self.0.set(index, sub, data)
        }
    }

    fn dictionary() -> Dictionary {
        let mut od = ObjectDictionary::new();
        od.add_var(
            0x1008,
            Entry::new(0, "Name", DataType::VisibleString, Access::ReadWrite)
                .with_default(b"bywire drive"),
        );
        od.add_var(
            0x2000,
            Entry::new(0, "Command", DataType::I32, Access::ReadWrite),
        );
        od.add_var(
            0x2001,
            Entry::new(0, "Blob", DataType::Domain, Access::ReadWrite).with_default(&[0; 1000]),
        );
        od.add_var(
            0x1000,
            Entry::new(0, "Device type", DataType::U32, Access::ReadOnly),
        );
        Dictionary(od)
    }

    /// Client and server wired back to back, frames passed until both are quiet.
    fn exchange(
        client: &mut SdoClient,
        server: &mut SdoServer,
        objects: &mut Dictionary,
        drop_frame: &mut dyn FnMut(&Frame) -> bool,
    ) {
        let now = Timestamp::from_millis(1);
        for _ in 0..10_000 {
            let mut to_server = Vec::new();
            client.poll(now, &mut |f| to_server.push(f));
            let mut to_client = Vec::new();
            for frame in &to_server {
                if !drop_frame(frame) {
                    server.on_frame(now, frame, objects);
                }
            }
            server.poll(now, &mut |f| to_client.push(f));
            for frame in &to_client {
                if !drop_frame(frame) {
                    client.on_frame(now, frame);
                }
            }
            if to_server.is_empty() && to_client.is_empty() && client.is_idle() {
                return;
            }
        }
        panic!("the exchange did not settle");
    }

    #[test]
    fn every_transfer_mode_moves_data_both_ways() {
        let data: Vec<u8> = (0..1000u32).map(|i| (i * 7 % 251) as u8).collect();
        for mode in [
            TransferMode::Auto,
            TransferMode::Segmented,
            TransferMode::Block,
        ] {
            let mut objects = dictionary();
            let mut server = SdoServer::new(5, 1024);
            let mut client = SdoClient::new(4, Duration::from_millis(500));
            client.download(5, 0x2001, 0, &data, mode).unwrap();
            client
                .download(5, 0x2000, 0, &(-700i32).to_le_bytes(), mode)
                .unwrap();
            client.upload(5, 0x2001, 0, mode).unwrap();
            client.upload(5, 0x1008, 0, mode).unwrap();
            exchange(&mut client, &mut server, &mut objects, &mut |_| false);
            let outcomes: Vec<_> = core::iter::from_fn(|| client.take_outcome()).collect();
            assert_eq!(outcomes.len(), 4, "{mode:?}");
            assert_eq!(outcomes[0].result, Ok(Vec::new()), "{mode:?}");
            assert_eq!(outcomes[1].result, Ok(Vec::new()), "{mode:?}");
            assert_eq!(objects.0.get_signed(0x2000, 0), Some(-700));
            assert_eq!(outcomes[2].result.as_deref(), Ok(&data[..]), "{mode:?}");
            assert_eq!(
                outcomes[3].result.as_deref(),
                Ok(&b"bywire drive"[..]),
                "{mode:?}"
            );
            assert!(server.is_idle());
        }
    }

    #[test]
    fn lost_block_segments_are_repeated() {
        let data: Vec<u8> = (0..900u32).map(|i| (i % 253) as u8).collect();
        let mut objects = dictionary();
        let mut server = SdoServer::new(5, 1024);
        let mut client = SdoClient::new(4, Duration::from_millis(500));
        client
            .download(5, 0x2001, 0, &data, TransferMode::Block)
            .unwrap();
        client.upload(5, 0x2001, 0, TransferMode::Block).unwrap();
        // Lose segment 40 once in each direction: the receiver acknowledges 39 and the
        // sender repeats from 40.
        let mut lost = Vec::new();
        exchange(&mut client, &mut server, &mut objects, &mut |frame| {
            let id = cob_id(frame).unwrap();
            let lose = frame.data()[0] == 40 && !lost.contains(&id);
            if lose {
                lost.push(id);
            }
            lose
        });
        assert_eq!(lost.len(), 2, "a segment was lost each way");
        let download = client.take_outcome().unwrap();
        assert_eq!(download.result, Ok(Vec::new()));
        assert_eq!(
            client.take_outcome().unwrap().result.as_deref(),
            Ok(&data[..])
        );
    }

    #[test]
    fn refusals_come_back_as_abort_codes() {
        let mut objects = dictionary();
        let mut server = SdoServer::new(5, 1024);
        let mut client = SdoClient::new(8, Duration::from_millis(500));
        client
            .download(5, 0x1000, 0, &[1, 2, 3, 4], TransferMode::Auto)
            .unwrap();
        client
            .download(5, 0x2000, 0, &[1, 2], TransferMode::Auto)
            .unwrap();
        client.upload(5, 0x3000, 0, TransferMode::Auto).unwrap();
        client.upload(5, 0x2000, 7, TransferMode::Block).unwrap();
        client
            .download(5, 0x1000, 0, &[0; 20], TransferMode::Block)
            .unwrap();
        client
            .download(5, 0x2001, 0, &[0; 2000], TransferMode::Segmented)
            .unwrap();
        exchange(&mut client, &mut server, &mut objects, &mut |_| false);
        let results: Vec<_> = core::iter::from_fn(|| client.take_outcome())
            .map(|o| o.result)
            .collect();
        assert_eq!(
            results,
            [
                Err(SdoError::Aborted(Abort::WriteReadOnly)),
                Err(SdoError::Aborted(Abort::LengthTooLow)),
                Err(SdoError::Aborted(Abort::NoObject)),
                Err(SdoError::Aborted(Abort::NoSubindex)),
                Err(SdoError::Aborted(Abort::WriteReadOnly)),
                Err(SdoError::Aborted(Abort::OutOfMemory)),
            ]
        );
    }

    #[test]
    fn a_silent_server_times_out_and_the_queue_is_bounded() {
        let mut client = SdoClient::new(1, Duration::from_millis(300));
        client.upload(5, 0x1000, 0, TransferMode::Auto).unwrap();
        assert_eq!(
            client.upload(5, 0x1000, 0, TransferMode::Auto),
            Err(QueueFull)
        );
        let mut sent = Vec::new();
        client.poll(Timestamp::from_millis(0), &mut |f| sent.push(f));
        assert_eq!(sent.len(), 1);
        assert_eq!(client.next_deadline(), Some(Timestamp::from_millis(300)));
        client.poll(Timestamp::from_millis(300), &mut |f| sent.push(f));
        assert_eq!(
            client.take_outcome().unwrap().result,
            Err(SdoError::Timeout)
        );
        assert_eq!(sent[1].data(), abort_payload(0x1000, 0, Abort::Timeout));
    }

    #[test]
    fn a_server_left_waiting_aborts_with_timeout() {
        let mut objects = dictionary();
        let mut server = SdoServer::new(5, 1024);
        let initiate = classic(0x605, &[0x40, 0x08, 0x10, 0, 0, 0, 0, 0]);
        server.on_frame(Timestamp::ZERO, &initiate, &mut objects);
        let mut sent = Vec::new();
        server.poll(Timestamp::ZERO, &mut |f| sent.push(f));
        assert_eq!(
            sent[0].data()[0],
            0x41,
            "segmented upload of a 12-byte string"
        );
        server.poll(
            SERVER_TIMEOUT
                .as_nanos()
                .try_into()
                .map(Timestamp::from_nanos)
                .unwrap(),
            &mut |f| sent.push(f),
        );
        assert_eq!(sent[1].data(), abort_payload(0x1008, 0, Abort::Timeout));
        assert!(server.is_idle());
    }

    #[test]
    fn crc16_matches_the_xmodem_check_value() {
        assert_eq!(crc16(0, b"123456789"), 0x31C3);
    }
}
