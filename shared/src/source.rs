//! Where a client's messages come from: shared memory on the simulation's
//! host, or zenoh through a bridge (`--connect`). A closed set matched on
//! the real-time thread's every tick, hence an enum; both arms hand out
//! copies without allocating, locking or waiting for a writer.

use crate::remote::{Inbox, Stamped};
use crate::services::{Ipc, ZeroCopySend};
use bytemuck::Pod;
use iceoryx2::port::subscriber::Subscriber;

/// A stream of fixed-size messages.
pub enum Source<T: std::fmt::Debug + ZeroCopySend + 'static> {
    /// An iceoryx2 subscriber (same host).
    Shm(Subscriber<Ipc, T, ()>),
    /// A zenoh inbox (stamps already in this host's clock).
    Remote(Inbox<T>),
}

impl<T: std::fmt::Debug + ZeroCopySend + Pod + Stamped + Send + Sync> Source<T> {
    /// The oldest message not yet taken.
    pub fn pop(&mut self) -> Option<T> {
        match self {
            Source::Shm(s) => s.receive().ok().flatten().map(|m| *m),
            Source::Remote(i) => i.pop(),
        }
    }
}
