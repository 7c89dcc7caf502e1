//! Any bytes as a server's answers to the UDS client and its decoders: the client never
//! panics and ends every request with an outcome or keeps waiting within its deadline; the
//! decoders name a malformed answer instead of misreading it.
#![no_main]

use bywire_core::frame::{Frame, Id};
use bywire_core::time::Timestamp;
use bywire_diag::client::{self, ClientTiming, UdsClient};
use bywire_diag::isotp::IsoTpConfig;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let lengths = |id: u16| (id % 3 != 0).then_some(usize::from(id % 7));
    let _ = client::dtc_list(data);
    let _ = client::dtc_count(data);
    let _ = client::snapshots(data, &lengths);
    let _ = client::did_values(data, &[0xF190, 0x0101], &lengths);

    let config = IsoTpConfig::new(Id::standard(0x7E0).unwrap(), Id::standard(0x7E8).unwrap());
    let mut tester = UdsClient::new(config, ClientTiming::default());
    let mut now = Timestamp::ZERO;
    let _ = tester.request(now, &[0x22, 0xF1, 0x90]);
    // Frames of up to 8 bytes on the answer identifier, each after a step of time.
    let mut rest = data;
    while let [step, len, tail @ ..] = rest {
        let take = usize::from(*len % 9).min(tail.len());
        let (bytes, next) = tail.split_at(take);
        rest = next;
        now = now.saturating_add(core::time::Duration::from_micros(u64::from(*step) * 500));
        if let Ok(frame) = Frame::classic(Id::standard(0x7E8).unwrap(), bytes) {
            tester.on_frame(now, &frame);
        }
        tester.poll(now, &mut |_, _| {});
        if tester.take_outcome().is_some() && !tester.busy() {
            let _ = tester.request(now, &[0x19, 0x02, 0xFF]);
        }
    }
});
