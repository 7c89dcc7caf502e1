//! Any sequence of frames and times into an ISO-TP channel (classic and CAN FD, each
//! addressing), while it also sends: nothing panics, and nothing received is empty or longer
//! than its buffer.
#![no_main]

use bywire_core::frame::{Frame, Id};
use bywire_core::time::Timestamp;
use bywire_diag::isotp::{Addressing, IsoTp, IsoTpConfig, IsoTpEvent};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&setup, data)) = data.split_first() else { return };
    let mut config = IsoTpConfig::new(Id::standard(0x7E8).unwrap(), Id::standard(0x7E0).unwrap());
    config.fd = setup & 1 != 0;
    config.tx_dl = 64;
    config.max_message = 500;
    config.block_size = (setup >> 4) & 3;
    config.addressing = match (setup >> 1) & 3 {
        0 => Addressing::Normal,
        1 => Addressing::Extended { target: 0xF1, source: 0x10 },
        _ => Addressing::Mixed { extension: 0x42 },
    };
    let mut channel = IsoTp::new(config);
    let _ = channel.send(&[0x62; 300]);
    let mut now = 0u64;
    for chunk in data.chunks(66) {
        let [step, len, rest @ ..] = chunk else { break };
        now += u64::from(*step) * 100_000;
        let payload = &rest[..rest.len().min(usize::from(*len))];
        let frame = if config.fd {
            Frame::fd(Id::standard(0x7E0).unwrap(), payload, true, false)
        } else {
            Frame::classic(Id::standard(0x7E0).unwrap(), &payload[..payload.len().min(8)])
        };
        let time = Timestamp::from_nanos(now);
        if let Ok(frame) = frame {
            channel.on_frame(time, &frame);
        }
        channel.poll(time, &mut |_, _| {});
        while let Some(event) = channel.next_event() {
            if let IsoTpEvent::Received(message) = event {
                assert!(!message.is_empty() && message.len() <= 500);
            }
        }
    }
});
