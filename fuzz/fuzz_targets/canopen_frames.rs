//! Any sequence of frames and times into a CANopen drive, a Roboteq controller and a master:
//! nothing panics, and every SDO answer of the drive is a CiA 301 response or abort.
#![no_main]

use bywire_canopen::cia402::{drive_dictionary, Drive, DriveController, Mode};
use bywire_canopen::device::Device;
use bywire_canopen::master::{Controlled, Master};
use bywire_canopen::roboteq::{dictionary, Mdc1460};
use bywire_core::node::{Node, Port};
use bywire_core::frame::{Frame, Id};
use bywire_core::time::Timestamp;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut drive = Device::new(2, drive_dictionary(2), Drive::new());
    let mut roboteq = Device::new(1, dictionary(1, 2), Mdc1460::default()).with_autostart();
    let mut master = Master::new(127, core::time::Duration::from_millis(100), core::time::Duration::from_millis(10));
    master.add(Controlled::Drive(DriveController::new(2, Mode::ProfileVelocity, core::time::Duration::from_millis(100))));
    let mut now = 0u64;
    for chunk in data.chunks(11) {
        let [a, b, c, rest @ ..] = chunk else { break };
        now += u64::from(*c);
        let id = Id::standard(u32::from(u16::from_le_bytes([*a, *b]) & 0x7FF)).unwrap();
        let frame = if a & 0x80 != 0 && rest.is_empty() {
            Frame::remote(id, bywire_core::frame::Dlc::from_nibble(b & 0x0F))
        } else {
            Frame::classic(id, rest).unwrap()
        };
        let time = Timestamp::from_millis(now);
        for node in [&mut drive as &mut dyn Node, &mut roboteq, &mut master] {
            node.on_frame(time, Port::MAIN, &frame);
            node.poll(time, &mut |_, out| {
                if out.id() == Id::standard(0x582).ok() {
                    let command = out.data()[0];
                    assert!(out.data().len() == 8 && matches!(command >> 5, 0..=6), "{out:?}");
                }
            });
        }
    }
});
