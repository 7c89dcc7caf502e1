//! Any frames into both ends of the tug's secured wire (the supervisor's and the ADS's), with
//! the ADS's genuine commands among them: nothing panics, every frame of a secured message
//! either verifies or is refused and counted, and every sync the vehicle sends is one the ADS
//! side takes.
#![no_main]

use bywire_core::frame::{Frame, Id};
use bywire_core::Timestamp;
use bywire_secoc::Key;
use bywire_tug::secured;
use bywire_vehicle::ads::{Ads, AdsCommand, AdsConfig};
use bywire_vehicle::supervisor::{Supervisor, SupervisorConfig};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let key = Key::new([0x42; 16]);
    let (Ok(ads_wire), Ok(vehicle_wire)) = (secured::secured(&key, 1), secured::secured(&key, 1))
    else {
        return;
    };
    let mut ads = Ads::with_wire(AdsConfig::default(), ads_wire);
    let mut supervisor = Supervisor::with_wire(SupervisorConfig::default(), vehicle_wire);
    let ids = [0x000, 0x001, 0x100, 0x101, 0x102, 0x103, 0x0F0, 0x7FF];
    let mut now = 0u64;
    for chunk in data.chunks(67) {
        let [step, kind, len, rest @ ..] = chunk else { break };
        now += u64::from(*step) * 100_000;
        let time = Timestamp::from_nanos(now);
        let id = Id::standard(ids[usize::from(*kind & 7)]).unwrap();
        let payload = &rest[..rest.len().min(usize::from(*len))];
        let frame = if kind & 8 != 0 {
            Frame::fd(id, payload, kind & 16 != 0, false)
        } else {
            Frame::classic(id, &payload[..payload.len().min(8)])
        };
        if let Ok(frame) = frame {
            supervisor.on_frame(time, &frame);
            ads.on_frame(time, &frame);
        }
        ads.set_command(time, AdsCommand::default());
        let mut to_vehicle = Vec::new();
        ads.poll(time, &mut |f| to_vehicle.push(f));
        for f in &to_vehicle {
            supervisor.on_frame(time, f);
        }
        let mut to_ads = Vec::new();
        supervisor.poll(time, &mut |f| to_ads.push(f));
        for f in &to_ads {
            ads.on_frame(time, f);
        }
    }
    let vehicle = supervisor.wire().table().unwrap().stats();
    let side = ads.wire().table().unwrap().stats();
    // The vehicle's syncs are signed with the key: none refused by the ADS side for its MAC
    // (a refused one can only have come from the fuzzer's own frames on the sync identifier).
    assert!(side.syncs_taken + side.syncs_refused >= vehicle.syncs_sent);
    assert!(vehicle.frames.accepted <= u64::try_from(data.len()).unwrap_or(u64::MAX) * 4 + 1);
});
