//! Handles: the values C holds are generation-tagged slot ids, never addresses.
//!
//! A handle encodes (generation, kind tag, slot index + 1). Looking it up takes the
//! registry lock once and returns an `Arc` to the object, so an entry point keeps the
//! object alive for its whole call even if another thread releases the handle meanwhile
//! (no check-then-use race). Releasing the last reference bumps the slot's generation, so a
//! stale handle, or one whose slot was reused, never matches again; a handle of another
//! kind (a filter passed as a device) fails the tag check.

use std::sync::{Arc, Mutex, MutexGuard};

/// Bits for the slot index (+1, so no handle is 0): about a million live objects per kind.
const INDEX_BITS: u32 = 20;
/// Bits for the kind tag (device, filter, buffer).
const TAG_BITS: u32 = 2;
const SHIFT: u32 = INDEX_BITS + TAG_BITS;
/// Generations wrap after 2^42 releases of one slot on 64-bit targets.
const GEN_MASK: usize = usize::MAX >> SHIFT;

struct Slot<T> {
    generation: usize,
    object: Option<Arc<T>>,
    /// References held by C (New* gives one, Retain* adds one, Release* drops one).
    refs: usize,
}

struct Slots<T> {
    slots: Vec<Slot<T>>,
    free: Vec<usize>,
}

/// The live objects of one kind.
pub(crate) struct Registry<T> {
    tag: usize,
    inner: Mutex<Slots<T>>,
}

impl<T> Registry<T> {
    /// An empty registry whose handles carry `tag` (1..=3).
    pub(crate) const fn new(tag: usize) -> Self {
        Self {
            tag,
            inner: Mutex::new(Slots {
                slots: Vec::new(),
                free: Vec::new(),
            }),
        }
    }

    fn lock(&self) -> MutexGuard<'_, Slots<T>> {
        // A panic elsewhere cannot leave the slots inconsistent (every update is one
        // assignment), so a poisoned lock is still usable.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn encode(&self, index: usize, generation: usize) -> usize {
        (generation << SHIFT) | (self.tag << INDEX_BITS) | (index + 1)
    }

    fn decode(&self, handle: usize) -> Option<(usize, usize)> {
        let index = handle & ((1 << INDEX_BITS) - 1);
        if index == 0 || (handle >> INDEX_BITS) & ((1 << TAG_BITS) - 1) != self.tag {
            return None;
        }
        Some((index - 1, handle >> SHIFT))
    }

    /// Registers `object` with one reference; None when every slot is taken.
    pub(crate) fn insert(&self, object: T) -> Option<usize> {
        let mut s = self.lock();
        let index = match s.free.pop() {
            Some(i) => i,
            None if s.slots.len() < (1 << INDEX_BITS) - 1 => {
                s.slots.push(Slot {
                    generation: 0,
                    object: None,
                    refs: 0,
                });
                s.slots.len() - 1
            }
            None => return None,
        };
        let slot = &mut s.slots[index];
        slot.object = Some(Arc::new(object));
        slot.refs = 1;
        Some(self.encode(index, slot.generation))
    }

    /// The live object behind `handle`.
    pub(crate) fn get(&self, handle: usize) -> Option<Arc<T>> {
        let (index, generation) = self.decode(handle)?;
        let s = self.lock();
        let slot = s.slots.get(index)?;
        (slot.generation == generation)
            .then(|| slot.object.clone())
            .flatten()
    }

    /// Adds a reference; false for a dead handle.
    pub(crate) fn retain(&self, handle: usize) -> bool {
        let Some((index, generation)) = self.decode(handle) else {
            return false;
        };
        let mut s = self.lock();
        match s.slots.get_mut(index) {
            Some(slot) if slot.generation == generation && slot.object.is_some() => {
                slot.refs += 1;
                true
            }
            _ => false,
        }
    }

    /// Drops a reference. None for a dead handle; Some(Some(object)) when this was the last
    /// one: the handle is dead from now on and the caller drops the object outside the
    /// registry lock (its destructor may release other objects).
    pub(crate) fn release(&self, handle: usize) -> Option<Option<Arc<T>>> {
        let (index, generation) = self.decode(handle)?;
        let mut s = self.lock();
        let slot = s.slots.get_mut(index)?;
        if slot.generation != generation || slot.object.is_none() {
            return None;
        }
        slot.refs -= 1;
        if slot.refs > 0 {
            return Some(None);
        }
        let object = slot.object.take();
        slot.generation = (slot.generation + 1) & GEN_MASK;
        s.free.push(index);
        Some(object)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn released_handles_stay_dead_after_their_slot_is_reused() {
        let r = Registry::new(1);
        let a = r.insert(10).unwrap();
        assert_eq!(r.get(a).as_deref(), Some(&10));
        assert!(r.retain(a));
        assert!(matches!(r.release(a), Some(None)));
        assert!(matches!(r.release(a), Some(Some(_))));
        assert!(r.get(a).is_none());
        let b = r.insert(20).unwrap();
        assert_ne!(a, b, "the reused slot has a new generation");
        assert!(r.get(a).is_none() && r.release(a).is_none() && !r.retain(a));
        assert_eq!(r.get(b).as_deref(), Some(&20));
        let other = Registry::<i32>::new(2);
        assert!(
            other.get(b).is_none(),
            "a handle of another kind is refused"
        );
        assert!(r.get(0).is_none() && r.get(usize::MAX).is_none());
    }
}
