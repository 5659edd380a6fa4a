//! What a client receives: zenoh delivers on its own threads, so each
//! stream lands in a bounded wait-free ring ([`Inbox`]: rtrb's single
//! producer, single consumer queue; zenoh's threads take turns at the
//! producer end behind a mutex the consumer never touches) that a
//! real-time thread drains without allocating, locking or waiting for a
//! producer mid-write, or in a newest-wins slot for the viewer's slices
//! ([`SliceInbox`]). A full ring refuses the newest message (counted as
//! lost): only the consumer may take from it, and one drained every tick
//! fills only while its thread stalls. Stamps are moved into this host's
//! clock on arrival; messages of another protocol version or layout are
//! refused and counted.

use super::clock::{ClockMap, Stamped};
use super::{Link, RemoteError, codec};
use bytemuck::Pod;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use zenoh::Wait;

/// A stream's counters.
#[derive(Debug, Default)]
pub struct InboxCounts {
    /// Messages accepted.
    pub received: AtomicU64,
    /// Messages dropped because the reader had not taken the ones before
    /// (an [`Inbox`]: the newest refused; a [`SliceInbox`]: the older
    /// replaced).
    pub lost: AtomicU64,
    /// Messages refused (another version or layout, or before the clock
    /// was known).
    pub refused: AtomicU64,
    /// The first refusal, for the user.
    pub first_refusal: Mutex<Option<String>>,
}

impl InboxCounts {
    fn refuse(&self, why: impl FnOnce() -> String) {
        self.refused.fetch_add(1, Ordering::Relaxed);
        if let Ok(mut first) = self.first_refusal.lock()
            && first.is_none()
        {
            *first = Some(why());
        }
    }

    /// The first refusal's reason, if any.
    pub fn first_refusal(&self) -> Option<String> {
        self.first_refusal.lock().ok().and_then(|f| f.clone())
    }
}

/// A stream's messages, oldest first, at most `capacity` kept.
pub struct Inbox<T> {
    queue: rtrb::Consumer<T>,
    counts: Arc<InboxCounts>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
}

impl<T: Pod + Stamped + Send + Sync> Inbox<T> {
    /// Subscribes to `stream` of `link`'s session.
    pub fn subscribe(link: &Link, stream: &str, capacity: usize) -> Result<Self, RemoteError> {
        Self::open(link, stream, capacity, false)
    }

    /// [`Inbox::subscribe`], then asks the bridge for the newest message
    /// (a once-published stream, `scene`, sent before this client joined).
    pub fn subscribe_with_query(
        link: &Link,
        stream: &str,
        capacity: usize,
    ) -> Result<Self, RemoteError> {
        Self::open(link, stream, capacity, true)
    }

    fn open(link: &Link, stream: &str, capacity: usize, query: bool) -> Result<Self, RemoteError> {
        let key = link.name().service(stream);
        let (producer, queue) = rtrb::RingBuffer::new(capacity.max(1));
        let producer = Arc::new(Mutex::new(producer));
        let counts = Arc::new(InboxCounts::default());
        let accept = {
            let (q, c, clock, synced, k) = (
                producer,
                counts.clone(),
                link.clock().clone(),
                link.synced(),
                key.clone(),
            );
            move |bytes: &[u8]| match codec::decode::<T>(&k, bytes) {
                Ok(_) if !synced.load(Ordering::Acquire) => {
                    c.refuse(|| format!("{k}: a message before the clock was known"))
                }
                Ok(mut msg) => {
                    msg.map_stamps(|t| clock.to_local(t));
                    c.received.fetch_add(1, Ordering::Relaxed);
                    let pushed = q.lock().is_ok_and(|mut p| p.push(msg).is_ok());
                    if !pushed {
                        c.lost.fetch_add(1, Ordering::Relaxed);
                    }
                }
                Err(e) => c.refuse(|| e.to_string()),
            }
        };
        let on_sample = accept.clone();
        let subscriber = link
            .zenoh()
            .declare_subscriber(key.clone())
            .callback(move |sample| on_sample(&sample.payload().to_bytes()))
            .wait()
            .map_err(|e| RemoteError::declare(&key, e))?;
        if query {
            ask_bridge(link, &key, accept);
        }
        Ok(Self {
            queue,
            counts,
            _subscriber: subscriber,
        })
    }

    /// The oldest message not yet taken (wait-free: no allocation, no
    /// lock, no waiting for a producer).
    pub fn pop(&mut self) -> Option<T> {
        self.queue.pop().ok()
    }

    /// The counters.
    pub fn counts(&self) -> &InboxCounts {
        &self.counts
    }
}

/// A header and its slice.
type Slot<H, T> = Arc<Mutex<Option<(H, Vec<T>)>>>;

/// The newest header and slice of a stream (mesh frames, topology, rest,
/// the original surface): a viewer wants the latest, not every one.
pub struct SliceInbox<H, T> {
    slot: Slot<H, T>,
    counts: Arc<InboxCounts>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
}

impl<H: Pod + Stamped + Send, T: Pod + Send> SliceInbox<H, T> {
    /// Subscribes to `stream`, then asks the bridge for the newest message
    /// (a once-published stream sent before this client joined).
    pub fn subscribe(link: &Link, stream: &str) -> Result<Self, RemoteError> {
        let key = link.name().service(stream);
        let slot: Slot<H, T> = Arc::new(Mutex::new(None));
        let counts = Arc::new(InboxCounts::default());
        // A live message wins over the bridge's answer to the join query,
        // whichever comes first (the answer may be older).
        let live = Arc::new(AtomicBool::new(false));
        let accept = {
            let (slot, counts, clock, k) = (
                slot.clone(),
                counts.clone(),
                link.clock().clone(),
                key.clone(),
            );
            move |bytes: &[u8], unless: Option<&AtomicBool>| {
                accept_slice(&k, bytes, &slot, &counts, &clock, unless)
            }
        };
        let (on_sample, seen) = (accept.clone(), live.clone());
        let subscriber = link
            .zenoh()
            .declare_subscriber(key.clone())
            .callback(move |s| {
                seen.store(true, Ordering::Release);
                on_sample(&s.payload().to_bytes(), None)
            })
            .wait()
            .map_err(|e| RemoteError::declare(&key, e))?;
        ask_bridge(link, &key, move |bytes| accept(bytes, Some(&live)));
        Ok(Self {
            slot,
            counts,
            _subscriber: subscriber,
        })
    }

    /// The newest message, if one came since the last call.
    pub fn take(&self) -> Option<(H, Vec<T>)> {
        self.slot.lock().ok()?.take()
    }

    /// The counters.
    pub fn counts(&self) -> &InboxCounts {
        &self.counts
    }
}

/// Asks the bridge for its copy of what `key` carried before this client
/// joined; `accept` takes the answer on zenoh's threads.
fn ask_bridge(link: &Link, key: &str, accept: impl Fn(&[u8]) + Send + Sync + 'static) {
    let _ = link
        .zenoh()
        .get(key.to_string())
        .callback(move |reply| {
            if let Ok(s) = reply.result() {
                accept(&s.payload().to_bytes());
            }
        })
        .wait();
}

/// Decodes a slice message into `slot`; `unless`: skip it when that flag
/// is set, checked under the slot's lock (a live message, which sets it
/// before taking the lock, always wins over the join query's answer).
fn accept_slice<H: Pod + Stamped, T: Pod>(
    key: &str,
    bytes: &[u8],
    slot: &Mutex<Option<(H, Vec<T>)>>,
    counts: &InboxCounts,
    clock: &ClockMap,
    unless: Option<&AtomicBool>,
) {
    let mut items = Vec::new();
    match codec::decode_slice::<H, T>(key, bytes, &mut items) {
        Ok(mut h) => {
            h.map_stamps(|t| clock.to_local(t));
            let Ok(mut s) = slot.lock() else { return };
            if unless.is_some_and(|u| u.load(Ordering::Acquire)) {
                return;
            }
            counts.received.fetch_add(1, Ordering::Relaxed);
            if s.replace((h, items)).is_some() {
                counts.lost.fetch_add(1, Ordering::Relaxed);
            }
        }
        Err(e) => counts.refuse(|| e.to_string()),
    }
}
