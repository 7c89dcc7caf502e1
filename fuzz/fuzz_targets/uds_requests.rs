//! Any requests at any times into the UDS server (with DIDs, DTCs, a routine): nothing panics,
//! and every answer is the request's positive response (service + 0x40) or a negative one
//! (0x7F, the service, a code).
#![no_main]

use core::time::Duration;

use bywire_core::frame::Id;
use bywire_core::time::Timestamp;
use bywire_diag::isotp::IsoTpConfig;
use bywire_diag::uds::{Did, Routine, Session, UdsServer, UdsTiming};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let config = IsoTpConfig::new(Id::standard(0x7E8).unwrap(), Id::standard(0x7E0).unwrap());
    let mut server = UdsServer::new(config, UdsTiming::default());
    server.set_did(0xF190, Did { value: b"WBYWIRE0TUG000042".to_vec(), writable_in: vec![], secured: false });
    server.set_did(0x0101, Did { value: vec![0, 0], writable_in: vec![Session::Extended], secured: true });
    server.set_routine(0x0203, Routine { runs_for: Duration::from_millis(5), result: vec![1], secured: false });
    server.report(0xC10100, true);
    let mut now = 0u64;
    // Requests separated by a length byte, each after a step of time.
    let mut rest = data;
    while let [step, len, tail @ ..] = rest {
        let take = usize::from(*len).min(tail.len());
        let (request, next) = tail.split_at(take);
        rest = next;
        now += u64::from(*step) * 1_000_000;
        let at = Timestamp::from_nanos(now);
        server.poll(at, &mut |_, _| {});
        if let Some(answer) = server.handle(at, request) {
            let service = request[0];
            match answer.as_slice() {
                [0x7F, s, _] => assert_eq!(*s, service),
                [first, ..] => assert_eq!(*first, service.wrapping_add(0x40)),
                [] => panic!("an empty answer"),
            }
        }
        let _ = server.take_events();
    }
});
