//! Any sequence of frames and times into an ISO-TP channel (classic and CAN FD, each
//! addressing, received padding checked or not, transmit confirmations or not, a frame gap),
//! while it also sends: nothing panics, and nothing received is empty or longer than its
//! buffer.
#![no_main]

use bywire_core::frame::{Frame, Id};
use bywire_core::time::Timestamp;
use bywire_diag::isotp::{Addressing, IsoTp, IsoTpConfig, IsoTpEvent};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&setup, data)) = data.split_first() else { return };
    let Some((&options, data)) = data.split_first() else { return };
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
    if options & 1 != 0 {
        config.rx_padding = Some(0xCC);
        config.rx_padding_check.length = options & 2 != 0;
        config.rx_padding_check.content = options & 4 != 0;
    }
    if options & 8 != 0 {
        config = config.confirmed(std::time::Duration::from_millis(u64::from(options >> 4) * 10));
    }
    config.frame_gap = std::time::Duration::from_micros(u64::from(options & 0x30));
    let confirm = options & 0x40 != 0;
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
        let mut sent = Vec::new();
        channel.poll(time, &mut |_, frame| sent.push(frame));
        // Confirm what went out (or not: the channel must time out on its own).
        if confirm {
            for frame in &sent {
                channel.on_sent(time, frame);
            }
        }
        while let Some(event) = channel.next_event() {
            if let IsoTpEvent::Received(message) = event {
                assert!(!message.is_empty() && message.len() <= 500);
            }
        }
    }
});
