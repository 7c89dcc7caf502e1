//! The real-time runner: one sans-IO node on one bus endpoint, against the monotonic clock.
//! It polls the node when its deadline comes or a frame arrives, and sends what it emits.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use bywire_core::node::Node;
use bywire_core::time::Timestamp;

use crate::{Bus, BusError};

/// The longest the runner waits without looking at `stop`.
const MAX_WAIT: Duration = Duration::from_millis(20);

/// Run `node` on `bus` until `stop` is set or the bus fails; gives the node back. Time starts
/// at zero when the runner starts.
pub fn run<N: Node>(bus: &mut dyn Bus, mut node: N, stop: &AtomicBool) -> Result<N, BusError> {
    run_until(bus, &mut node, stop, None, |_| false)?;
    Ok(node)
}

/// Run `node` on `bus` until `done` says so (checked after each poll has been sent, so what
/// the node answered last goes out), `stop` is
/// set, or `limit` has passed; `true` when `done` ended it.
pub fn run_until<N: Node>(
    bus: &mut dyn Bus,
    node: &mut N,
    stop: &AtomicBool,
    limit: Option<Duration>,
    mut done: impl FnMut(&mut N) -> bool,
) -> Result<bool, BusError> {
    let start = Instant::now();
    let clock =
        || Timestamp::from_nanos(u64::try_from(start.elapsed().as_nanos()).unwrap_or(u64::MAX));
    let mut outgoing = Vec::new();
    while !stop.load(Ordering::Relaxed) && limit.is_none_or(|limit| start.elapsed() < limit) {
        let now = clock();
        node.poll(now, &mut |frame| outgoing.push(frame));
        for frame in outgoing.drain(..) {
            bus.send(&frame)?;
        }
        if done(node) {
            return Ok(true);
        }
        let wait = node
            .next_deadline()
            .map_or(MAX_WAIT, |deadline| deadline.saturating_since(clock()))
            .min(MAX_WAIT);
        if let Some(received) = bus.recv(Some(wait))? {
            if !received.own {
                node.on_frame(clock(), &received.frame);
            }
        }
    }
    Ok(false)
}
