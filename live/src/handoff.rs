//! How messages pass between the threads of a live run: newest-wins
//! slots for what may be skipped, bounded queues for what may not.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use crossbeam_channel::{Receiver, Sender, TrySendError};

/// A message with the wall-clock time it arrived, µs.
#[derive(Debug, Clone)]
pub struct Arrived<T> {
    pub item: T,
    pub wall: i64,
}

/// The sending side of a one-place queue that keeps only the newest item:
/// a consumer that falls behind skips to the latest instead of queueing.
pub struct NewestWins<T> {
    sender: Sender<T>,
    stale: Receiver<T>,
    dropped: Arc<AtomicU64>,
}

/// A one-place newest-wins queue and the counter of items it dropped.
pub fn newest_wins<T>() -> (NewestWins<T>, Receiver<T>, Arc<AtomicU64>) {
    let (sender, receiver) = crossbeam_channel::bounded(1);
    let dropped = Arc::new(AtomicU64::new(0));
    (
        NewestWins {
            sender,
            stale: receiver.clone(),
            dropped: Arc::clone(&dropped),
        },
        receiver,
        dropped,
    )
}

impl<T> NewestWins<T> {
    /// Puts `item`, replacing an item still waiting (counted as dropped).
    pub fn put(&self, item: T) {
        let item = match self.sender.try_send(item) {
            Ok(()) | Err(TrySendError::Disconnected(_)) => return,
            Err(TrySendError::Full(item)) => item,
        };
        if self.stale.try_recv().is_ok() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
        // Only this sender fills the slot, which was just emptied; should a
        // second producer have raced in, this item is the one dropped.
        if self.sender.try_send(item).is_err() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Items replaced before the consumer took them.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// Where range images and their slices go: images to a newest-wins slot
/// (a perception that falls behind skips to the latest), slices to a queue
/// (a skipped slice would be lines of an image lost).
pub struct SensorFeed {
    pub images: NewestWins<Arrived<arcnav_perception::RangeImage>>,
    pub slices: Sender<Arrived<arcnav_perception::RangeSlice>>,
}

/// Perception's side of a [`SensorFeed`].
pub struct SensorInputs {
    pub images: Receiver<Arrived<arcnav_perception::RangeImage>>,
    pub slices: Receiver<Arrived<arcnav_perception::RangeSlice>>,
    /// Images replaced by newer ones before perception took them.
    pub replaced: Arc<AtomicU64>,
}

/// A feed whose slice queue holds `slices` slices.
pub fn sensor_feed(slices: usize) -> (SensorFeed, SensorInputs) {
    let (images, image_receiver, replaced) = newest_wins();
    let (slice_sender, slice_receiver) = crossbeam_channel::bounded(slices.max(1));
    (
        SensorFeed {
            images,
            slices: slice_sender,
        },
        SensorInputs {
            images: image_receiver,
            slices: slice_receiver,
            replaced,
        },
    )
}

/// Sends without blocking; a full queue drops the item and counts it.
pub fn offer<T>(sender: &Sender<T>, item: T, dropped: &mut u64) -> bool {
    match sender.try_send(item) {
        Ok(()) => true,
        Err(TrySendError::Full(_)) => {
            *dropped += 1;
            true
        }
        Err(TrySendError::Disconnected(_)) => false,
    }
}

/// Where a stage hands its output to the next thread.
pub enum Handoff<T> {
    /// Only the newest waits: a consumer that falls behind skips (counted).
    NewestWins(NewestWins<T>),
    /// Everything waits its turn; a full queue holds the producer back
    /// (what reproducing lock-step needs: no cycle is skipped).
    Every(Sender<T>),
}

impl<T> Handoff<T> {
    /// A hand-off of `every` item (a queue of `capacity`) or of the newest only.
    pub fn new(every: bool, capacity: usize) -> (Self, Receiver<T>, Arc<AtomicU64>) {
        if every {
            let (sender, receiver) = crossbeam_channel::bounded(capacity);
            (
                Handoff::Every(sender),
                receiver,
                Arc::new(AtomicU64::new(0)),
            )
        } else {
            let (slot, receiver, dropped) = newest_wins();
            (Handoff::NewestWins(slot), receiver, dropped)
        }
    }

    /// Hands `item` on; `false` when the consumer is gone.
    pub fn put(&self, item: T) -> bool {
        match self {
            Handoff::NewestWins(slot) => {
                slot.put(item);
                true
            }
            Handoff::Every(sender) => sender.send(item).is_ok(),
        }
    }

    /// Items skipped before the consumer took them.
    pub fn dropped(&self) -> u64 {
        match self {
            Handoff::NewestWins(slot) => slot.dropped(),
            Handoff::Every(_) => 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn newest_wins_keeps_the_newest_and_counts_what_it_replaced() {
        let (slot, receiver, dropped) = newest_wins();
        slot.put(1);
        slot.put(2);
        slot.put(3);
        assert_eq!(receiver.try_recv(), Ok(3));
        assert_eq!(dropped.load(Ordering::Relaxed), 2);
        assert_eq!(slot.dropped(), 2);
        slot.put(4);
        assert_eq!(receiver.try_recv(), Ok(4));
        assert!(receiver.try_recv().is_err());
        // Dropping the producer ends the consumer's loop.
        drop(slot);
        assert!(receiver.recv().is_err());
    }

    #[test]
    fn a_slow_consumer_never_holds_more_than_one_item() {
        let (slot, receiver, dropped) = newest_wins::<Vec<u8>>();
        let consumer = std::thread::spawn(move || {
            let mut seen = Vec::new();
            while let Ok(item) = receiver.recv() {
                seen.push(item[0]);
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
            seen
        });
        for i in 0..=200u8 {
            slot.put(vec![i; 1 << 16]);
            std::thread::sleep(std::time::Duration::from_micros(100));
        }
        let dropped_count = dropped.load(Ordering::Relaxed);
        drop(slot);
        let seen = consumer.join().unwrap();
        // Everything is either seen or counted, the newest is never lost,
        // and what was seen is in order.
        assert_eq!(seen.len() as u64 + dropped_count, 201);
        assert_eq!(seen.last(), Some(&200));
        assert!(seen.windows(2).all(|w| w[0] < w[1]));
        assert!(dropped_count > 0, "a 2 ms consumer fed every 0.1 ms drops");
    }

    #[test]
    fn a_handoff_of_every_item_skips_none() {
        let (handoff, receiver, dropped) = Handoff::new(true, 2);
        let consumer = std::thread::spawn(move || receiver.iter().collect::<Vec<u32>>());
        for i in 0..100 {
            assert!(handoff.put(i));
        }
        drop(handoff);
        assert_eq!(consumer.join().unwrap(), (0..100).collect::<Vec<_>>());
        assert_eq!(dropped.load(Ordering::Relaxed), 0);
    }
}
