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

/// A stream of headers with slices (mesh frames, topology, rest shape):
/// every message on shared memory, the newest through zenoh (a viewer
/// wants the latest).
pub enum SliceSource<
    H: std::fmt::Debug + ZeroCopySend + 'static,
    T: std::fmt::Debug + ZeroCopySend + 'static,
> {
    /// An iceoryx2 slice subscriber (same host).
    Shm(Subscriber<Ipc, [T], H>),
    /// A zenoh newest-wins slot (stamps already in this host's clock).
    Remote(crate::remote::SliceInbox<H, T>),
}

impl<H, T> SliceSource<H, T>
where
    H: std::fmt::Debug + ZeroCopySend + Pod + Stamped + Send,
    T: std::fmt::Debug + ZeroCopySend + Pod + Send,
{
    /// Hands `f` each message that arrived since the last call.
    pub fn drain(&self, mut f: impl FnMut(&H, &[T])) {
        match self {
            SliceSource::Shm(s) => {
                while let Ok(Some(m)) = s.receive() {
                    f(m.user_header(), m.payload());
                }
            }
            SliceSource::Remote(r) => {
                if let Some((h, v)) = r.take() {
                    f(&h, &v);
                }
            }
        }
    }
}
