//! The async companion of [`SocketCan`] (feature `tokio`): the same socket, waited on by the
//! tokio reactor instead of a blocked thread.

use std::time::Duration;

use bywire_core::Frame;
use tokio::io::unix::AsyncFd;

use super::{queue_full, receive_ready, try_send, Attempt, SocketCan, SEND_PATIENCE};
use crate::{BusError, Received};

/// A SocketCAN socket for async code.
pub struct AsyncSocketCan {
    fd: AsyncFd<SocketCan>,
}

impl AsyncSocketCan {
    /// Register an open socket with the current tokio runtime (an error outside one).
    pub fn new(bus: SocketCan) -> Result<Self, BusError> {
        Ok(AsyncSocketCan {
            fd: super::sys::register_async(bus)?,
        })
    }

    /// The blocking socket, for its options and counts.
    pub fn get_ref(&self) -> &SocketCan {
        self.fd.get_ref()
    }

    /// The next frame.
    pub async fn recv(&self) -> Result<Received, BusError> {
        // Each pass waits for readiness; a wake-up without a frame clears it and waits again.
        loop {
            let mut ready = self.fd.readable().await?;
            match receive_ready(&ready.get_inner().shared)? {
                Some(received) => return Ok(received),
                None => ready.clear_ready(),
            }
        }
    }

    /// Send a frame, waiting (without blocking the runtime) while the interface's queue is full.
    pub async fn send(&self, frame: &Frame) -> Result<(), BusError> {
        let give_up = tokio::time::Instant::now() + SEND_PATIENCE;
        let mut pause = Duration::from_micros(50);
        // Bounded by SEND_PATIENCE, as the blocking send.
        loop {
            match try_send(&self.fd.get_ref().shared, frame, false)? {
                Attempt::Sent => return Ok(()),
                Attempt::Full if tokio::time::Instant::now() < give_up => {
                    tokio::time::sleep(pause).await;
                    pause = (pause * 2).min(Duration::from_millis(5));
                }
                Attempt::Full => return Err(queue_full(&self.fd.get_ref().shared)),
            }
        }
    }
}
