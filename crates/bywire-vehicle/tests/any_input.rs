//! Anything from the bus, in any order and at any time, never panics either node, and the
//! supervisor's outputs stay safe: nothing drives the vehicle unless a valid command engaged
//! it, and outputs are always finite.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Id, Timestamp};
use bywire_tug::wire::ReferenceWire;
use bywire_vehicle::ads::{Ads, AdsConfig};
use bywire_vehicle::supervisor::{Supervisor, SupervisorConfig};
use proptest::prelude::*;

fn any_frame() -> impl Strategy<Value = Frame> {
    let ids = prop_oneof![
        Just(0u32),
        Just(1),
        Just(0x100),
        Just(0x101),
        Just(0x102),
        Just(0x103),
        0u32..0x800
    ];
    (
        ids,
        proptest::collection::vec(any::<u8>(), 0..=8),
        any::<bool>(),
        0u8..4,
    )
        .prop_map(|(id, data, extended, kind)| {
            let id = if extended {
                Id::extended(id).unwrap()
            } else {
                Id::standard(id).unwrap()
            };
            match kind {
                0 => Frame::remote(
                    id,
                    bywire_core::Dlc::from_nibble(u8::try_from(data.len()).unwrap()),
                ),
                1 => Frame::fd(id, &data, true, false).unwrap(),
                _ => Frame::classic(id, &data).unwrap(),
            }
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]
    /// Verifies: REQ-IN-1.
    #[test]
    fn random_traffic_is_harmless(
        frames in proptest::collection::vec((any_frame(), 0u64..50, any::<f64>(), any::<f64>()), 1..200)
    ) {
        let mut supervisor = Supervisor::with_wire(SupervisorConfig::default(), ReferenceWire);
        let mut ads = Ads::with_wire(AdsConfig::default(), ReferenceWire);
        let mut t = 0u64;
        for (frame, gap, torque, speed) in frames {
            t += gap;
            let now = Timestamp::from_millis(t);
            supervisor.on_frame(now, Port::MAIN, &frame);
            supervisor.set_driver_input(torque, 0.0);
            supervisor.set_feedback(speed, speed);
            supervisor.poll(now, &mut |_, _| {});
            ads.on_frame(now, Port::MAIN, &frame);
            ads.poll(now, &mut |_, _| {});
            let a = supervisor.actuators(now);
            // Random bytes never pass the CRC: the vehicle is never engaged.
            prop_assert!(!a.ads_in_control && !a.steering_enabled);
            prop_assert!(a.velocity.is_finite() && a.motor_rpm.is_finite() && a.steering.is_finite());
            prop_assert!((0.0..=100.0).contains(&a.brake));
        }
    }
}
