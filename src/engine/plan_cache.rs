//! The plans a model keeps, one per tile size, the least recently used dropped first.
//!
//! A plan holds size-dependent state (about 8 MB at 160x160, 29 MB at 736x736 for the
//! balanced model), so a host that resizes its viewport would otherwise keep one more plan
//! with every size it ever had (docs/memory.md, "A host that resizes").

use std::collections::HashMap;
use std::sync::Arc;

/// Tile sizes whose plans a [`super::Model`] keeps. Every tile of one image has one size,
/// so this covers a host alternating between a few image sizes (viewport, preview, final).
pub const PLAN_CACHE_SIZES: usize = 4;

/// Values by tile size, at most [`PLAN_CACHE_SIZES`] of them.
pub(super) struct PlanCache<P> {
    entries: HashMap<(usize, usize), (Arc<P>, u64)>,
    /// Stamps uses, so the oldest entry is the one with the smallest stamp.
    clock: u64,
}

impl<P> PlanCache<P> {
    pub(super) fn new() -> Self {
        Self {
            entries: HashMap::new(),
            clock: 0,
        }
    }

    /// The value for `size`, marked as just used.
    pub(super) fn get(&mut self, size: (usize, usize)) -> Option<Arc<P>> {
        self.clock += 1;
        let clock = self.clock;
        self.entries.get_mut(&size).map(|(p, used)| {
            *used = clock;
            p.clone()
        })
    }

    /// Keeps `value` for `size`; when full, drops the least recently used other size
    /// first (runs holding its `Arc` finish with it).
    pub(super) fn insert(&mut self, size: (usize, usize), value: Arc<P>) {
        self.clock += 1;
        if !self.entries.contains_key(&size) && self.entries.len() >= PLAN_CACHE_SIZES {
            let oldest = self.entries.iter().min_by_key(|(_, (_, used))| *used);
            if let Some((&old, _)) = oldest {
                self.entries.remove(&old);
            }
        }
        self.entries.insert(size, (value, self.clock));
    }

    /// Whether `size` is kept, without marking it used.
    #[cfg(test)]
    pub(super) fn contains(&self, size: (usize, usize)) -> bool {
        self.entries.contains_key(&size)
    }

    /// The sizes kept, in order.
    pub(super) fn sizes(&self) -> Vec<(usize, usize)> {
        let mut v: Vec<_> = self.entries.keys().copied().collect();
        v.sort_unstable();
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sizes(n: usize) -> Vec<(usize, usize)> {
        (0..n).map(|k| (32 * (k + 1), 64)).collect()
    }

    #[test]
    fn keeps_at_most_the_capacity() {
        let mut c = PlanCache::new();
        for (k, s) in sizes(PLAN_CACHE_SIZES + 3).into_iter().enumerate() {
            c.insert(s, Arc::new(k));
            assert!(c.sizes().len() <= PLAN_CACHE_SIZES);
            assert_eq!(c.get(s).as_deref(), Some(&k), "the newest is kept");
        }
        assert_eq!(c.sizes(), sizes(PLAN_CACHE_SIZES + 3)[3..].to_vec());
    }

    #[test]
    fn drops_the_least_recently_used_not_the_oldest_inserted() {
        let mut c = PlanCache::new();
        let s = sizes(PLAN_CACHE_SIZES + 1);
        for (k, &size) in s[..PLAN_CACHE_SIZES].iter().enumerate() {
            c.insert(size, Arc::new(k));
        }
        // The first size is used again, so the second is now the least recently used.
        assert!(c.get(s[0]).is_some());
        c.insert(s[PLAN_CACHE_SIZES], Arc::new(99));
        assert!(c.contains(s[0]));
        assert!(!c.contains(s[1]));
        assert_eq!(c.sizes().len(), PLAN_CACHE_SIZES);
    }

    #[test]
    fn reinserting_a_kept_size_drops_nothing() {
        let mut c = PlanCache::new();
        let s = sizes(PLAN_CACHE_SIZES);
        for (k, &size) in s.iter().enumerate() {
            c.insert(size, Arc::new(k));
        }
        c.insert(s[2], Arc::new(7));
        assert_eq!(c.sizes(), s);
        assert_eq!(c.get(s[2]).as_deref(), Some(&7));
    }
}
