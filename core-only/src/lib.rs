//! The safety core with neither the standard library nor an allocator: the supervisor's
//! state machines (watchdog cascade, E-stop latch, modes), the two-bus and 2-out-of-3
//! voters, the A/B arbitration, the backup actuator switch, the degradation latch, the E2E
//! counter check, the SecOC receive path, and the CANopen safety objects (heartbeat
//! consumer, node guarding, EMCY, the CiA 402 drive controller's safe stop).
//!
//! Linking this static library is the check: rustc refuses to link a crate graph that uses
//! `alloc` and has no global allocator, so if anything these crates build without their
//! `std` feature reached for `alloc`, this would not build. The table below keeps the entry
//! points in the library, as an ECU's image would keep them.
#![no_std]

use bywire_canopen::cia402::DriveController;
use bywire_canopen::nmt::{HeartbeatConsumer, NodeGuard};
use bywire_core::e2e::CounterChecker;
use bywire_secoc::Receiver;
use bywire_vehicle::arbitration::Arbiter;
use bywire_vehicle::backup::ActuatorPair;
use bywire_vehicle::degradation::Degradation;
use bywire_vehicle::redundancy::{DualVoter, TripleVoter};
use bywire_vehicle::supervisor::{next_mode, EstopState, Watchdog};

/// Entry points kept in the image (function addresses; never called from here).
pub struct EntryPoints(pub [*const (); 13]);

// SAFETY: addresses of functions, read-only for the life of the program.
unsafe impl Sync for EntryPoints {}

#[used]
#[no_mangle]
pub static BYWIRE_SAFETY_CORE: EntryPoints = EntryPoints([
    Watchdog::next as *const (),
    EstopState::next as *const (),
    next_mode as *const (),
    DualVoter::<f64>::vote as *const (),
    TripleVoter::vote as *const (),
    Arbiter::step as *const (),
    ActuatorPair::step as *const (),
    Degradation::report as *const (),
    CounterChecker::check as *const (),
    Receiver::accept as *const (),
    HeartbeatConsumer::on_frame as *const (),
    NodeGuard::poll as *const (),
    DriveController::poll as *const (),
]);

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    // An ECU resets here (its watchdog fires); this check only needs the handler to exist.
    loop {}
}
