//! The command line's allocator: the system allocator, except that large freed blocks are
//! kept for a while and handed out again for the next request of about their size.
//!
//! Why: tract allocates every intermediate tensor of a tile afresh, and the same shapes
//! recur tile after tile. glibc serves blocks that large with fresh mappings, whose pages
//! the kernel must fault in and zero on first touch; that was about a quarter of the CPU
//! time of `temc bench` (docs/speed.md). Reusing a freed block skips both.
//! Keeping heap memory is a process-wide choice, so only the `temc` program makes it; the
//! library leaves it to its host.
//!
//! The cache holds at most [`SLOTS`] blocks and a byte cap set by [`BlockCache::enable`]
//! (0, the start, keeps nothing); past the cap the least recently freed blocks go back to
//! the system.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::Mutex;

/// Blocks from this size up are kept when freed; smaller ones stay with glibc's heap,
/// which already reuses them.
const MIN_BLOCK: usize = 1 << 20;

/// How many freed blocks the cache can hold (and how many it can lend for smaller requests).
const SLOTS: usize = 64;

/// A kept block serves a request down to 1/MAX_SLACK of its size: tract's tensors of one tile
/// differ in channel count, so exact sizes alone would rarely meet.
const MAX_SLACK: usize = 2;

/// One kept block: its address and the layout it was allocated with. The address is kept
/// as an integer so the table is `Send`.
#[derive(Clone, Copy)]
struct Slot {
    addr: usize,
    size: usize,
    align: usize,
    /// When it was freed (a counter), to let the oldest go first.
    freed: u64,
}

const EMPTY: Slot = Slot {
    addr: 0,
    size: 0,
    align: 0,
    freed: 0,
};

struct Table {
    slots: [Slot; SLOTS],
    /// Kept blocks handed out for a smaller request, by address: what they really are.
    lent: [Slot; SLOTS],
    held: usize,
    cap: usize,
    clock: u64,
}

/// The allocator; see the module documentation.
pub struct BlockCache {
    table: Mutex<Table>,
}

impl BlockCache {
    /// A cache that keeps nothing until [`BlockCache::enable`].
    pub const fn new() -> Self {
        BlockCache {
            table: Mutex::new(Table {
                slots: [EMPTY; SLOTS],
                lent: [EMPTY; SLOTS],
                held: 0,
                cap: 0,
                clock: 0,
            }),
        }
    }

    /// Lets the cache keep up to `cap_bytes` of freed blocks (0 turns it off and frees
    /// what it holds).
    pub fn enable(&self, cap_bytes: usize) {
        let mut t = self.lock();
        t.cap = cap_bytes;
        t.evict_to(0);
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Table> {
        // No code that can panic runs under the lock, but a poisoned table is still valid.
        self.table.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A kept block for `layout`, taken out of the cache: the smallest that holds it and
    /// is at most [`MAX_SLACK`] times its size. One larger than asked is recorded as lent,
    /// so that its free gives back the whole block.
    fn take(&self, layout: Layout) -> Option<*mut u8> {
        if layout.size() < MIN_BLOCK {
            return None;
        }
        let mut t = self.lock();
        let fits = |s: &Slot| {
            s.addr != 0
                && s.size >= layout.size()
                && s.size <= layout.size().saturating_mul(MAX_SLACK)
                && s.addr.is_multiple_of(layout.align())
        };
        let i = (0..SLOTS)
            .filter(|&i| fits(&t.slots[i]))
            .min_by_key(|&i| t.slots[i].size)?;
        let slot = t.slots[i];
        if slot.size != layout.size() || slot.align != layout.align() {
            let j = t.lent.iter().position(|s| s.addr == 0)?;
            t.lent[j] = slot;
        }
        t.slots[i] = EMPTY;
        t.held -= slot.size;
        Some(slot.addr as *mut u8)
    }

    /// Frees a block: keeps it, or gives it back to the system.
    fn release(&self, ptr: *mut u8, layout: Layout) {
        if layout.size() < MIN_BLOCK {
            // SAFETY: the caller's block with its own layout; small blocks are never lent.
            return unsafe { System.dealloc(ptr, layout) };
        }
        let mut t = self.lock();
        let layout = t.return_lent(ptr).unwrap_or(layout);
        if layout.size() <= t.cap {
            t.evict_to(layout.size());
            if let Some(i) = t.slots.iter().position(|s| s.addr == 0) {
                t.clock += 1;
                t.held += layout.size();
                t.slots[i] = Slot {
                    addr: ptr as usize,
                    size: layout.size(),
                    align: layout.align(),
                    freed: t.clock,
                };
                return;
            }
        }
        // SAFETY: the block with the layout it was allocated with.
        unsafe { System.dealloc(ptr, layout) }
    }
}

impl Default for BlockCache {
    fn default() -> Self {
        Self::new()
    }
}

impl Table {
    /// The layout a lent block was allocated with, where `ptr` is one (it is no longer lent).
    fn return_lent(&mut self, ptr: *mut u8) -> Option<Layout> {
        let j = self.lent.iter().position(|s| s.addr == ptr as usize)?;
        let s = std::mem::replace(&mut self.lent[j], EMPTY);
        // SAFETY: the layout the block was allocated with.
        Some(unsafe { Layout::from_size_align_unchecked(s.size, s.align) })
    }

    /// Frees the oldest blocks until `room` more bytes fit under the cap and a slot is free.
    fn evict_to(&mut self, room: usize) {
        loop {
            let full = self.slots.iter().all(|s| s.addr != 0);
            if !full && self.held + room <= self.cap {
                return;
            }
            let Some(i) = (0..SLOTS)
                .filter(|&i| self.slots[i].addr != 0)
                .min_by_key(|&i| self.slots[i].freed)
            else {
                return;
            };
            let s = std::mem::replace(&mut self.slots[i], EMPTY);
            self.held -= s.size;
            // SAFETY: the block came from System with exactly this layout and nobody else
            // holds it since it was kept.
            unsafe {
                System.dealloc(
                    s.addr as *mut u8,
                    Layout::from_size_align_unchecked(s.size, s.align),
                )
            };
        }
    }
}

// SAFETY: every block handed out is either fresh from System or a kept block, freed and owned
// by nobody else, at least the requested size (at most twice it) at an address of the
// requested alignment; one larger than asked, or of another alignment, is recorded as lent,
// and every block freed goes back to System with the layout it was allocated with, or into
// the table.
unsafe impl GlobalAlloc for BlockCache {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        match self.take(layout) {
            Some(p) => p,
            // SAFETY: the caller's contract (non-zero size) passes through.
            None => unsafe { System.alloc(layout) },
        }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        match self.take(layout) {
            Some(p) => {
                // SAFETY: the kept block is layout.size() bytes and ours now.
                unsafe { std::ptr::write_bytes(p, 0, layout.size()) };
                p
            }
            // SAFETY: as in alloc.
            None => unsafe { System.alloc_zeroed(layout) },
        }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        self.release(ptr, layout)
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // A block that is not lent is System's with exactly `layout`, so System may resize it
        // (glibc moves large blocks with mremap, without copying). A lent one is bigger than
        // `layout` says: it moves, and its free returns the whole block.
        let lent =
            layout.size() >= MIN_BLOCK && self.lock().lent.iter().any(|s| s.addr == ptr as usize);
        if !lent {
            // SAFETY: the caller's contract passes through for System's own block.
            return unsafe { System.realloc(ptr, layout, new_size) };
        }
        // SAFETY: the caller guarantees new_size and the alignment form a valid layout.
        let new_layout = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
        // SAFETY: as in alloc, then both blocks are valid for the bytes copied.
        unsafe {
            let new = self.alloc(new_layout);
            if !new.is_null() {
                std::ptr::copy_nonoverlapping(ptr, new, layout.size().min(new_size));
                self.dealloc(ptr, layout);
            }
            new
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn big(n: usize) -> Layout {
        Layout::from_size_align(n, 64).unwrap()
    }

    /// Whether the first `n` bytes at `p` are zero.
    unsafe fn zero(p: *const u8, n: usize) -> bool {
        unsafe { std::slice::from_raw_parts(p, n) }
            .iter()
            .all(|&b| b == 0)
    }

    #[test]
    fn a_freed_block_serves_the_next_request_of_its_size() {
        let c = BlockCache::new();
        c.enable(8 * MIN_BLOCK);
        unsafe {
            let a = c.alloc(big(2 * MIN_BLOCK));
            c.dealloc(a, big(2 * MIN_BLOCK));
            let other = c.alloc(big(3 * MIN_BLOCK));
            assert_ne!(other, a, "another size is not served from the cache");
            let b = c.alloc(big(2 * MIN_BLOCK));
            assert_eq!(b, a);
            c.dealloc(b, big(2 * MIN_BLOCK));
            c.dealloc(other, big(3 * MIN_BLOCK));
        }
        assert_eq!(c.lock().held, 5 * MIN_BLOCK);
        c.enable(0);
        assert_eq!(c.lock().held, 0);
    }

    #[test]
    fn a_larger_block_serves_down_to_half_its_size_and_returns_whole() {
        let c = BlockCache::new();
        c.enable(8 * MIN_BLOCK);
        unsafe {
            let a = c.alloc(big(4 * MIN_BLOCK));
            c.dealloc(a, big(4 * MIN_BLOCK));
            let small = c.alloc(big(MIN_BLOCK));
            assert_ne!(small, a, "a quarter of the block is too little to lend it");
            let b = c.alloc(big(3 * MIN_BLOCK));
            assert_eq!(b, a);
            assert_eq!(c.lock().held, 0);
            c.dealloc(b, big(3 * MIN_BLOCK));
            assert_eq!(c.lock().held, 4 * MIN_BLOCK, "the whole block came back");
            let again = c.alloc(big(4 * MIN_BLOCK));
            assert_eq!(again, a, "and serves its full size again");
            c.dealloc(again, big(4 * MIN_BLOCK));
            c.dealloc(small, big(MIN_BLOCK));
        }
        c.enable(0);
        assert_eq!(c.lock().held, 0);
    }

    #[test]
    fn a_lent_block_keeps_its_bytes_when_resized_and_returns_whole() {
        let c = BlockCache::new();
        c.enable(8 * MIN_BLOCK);
        unsafe {
            let a = c.alloc(big(4 * MIN_BLOCK));
            c.dealloc(a, big(4 * MIN_BLOCK));
            let b = c.alloc(big(3 * MIN_BLOCK));
            assert_eq!(b, a);
            b.write_bytes(5, 3 * MIN_BLOCK);
            let g = c.realloc(b, big(3 * MIN_BLOCK), 2 * MIN_BLOCK);
            assert!(std::slice::from_raw_parts(g, 2 * MIN_BLOCK)
                .iter()
                .all(|&x| x == 5));
            assert_eq!(
                c.lock().held,
                4 * MIN_BLOCK,
                "the lent block came back whole"
            );
            c.dealloc(g, big(2 * MIN_BLOCK));
        }
        c.enable(0);
    }

    #[test]
    fn the_cap_lets_the_oldest_blocks_go() {
        let c = BlockCache::new();
        c.enable(3 * MIN_BLOCK);
        unsafe {
            let blocks: Vec<_> = (0..4).map(|_| c.alloc(big(MIN_BLOCK))).collect();
            for &p in &blocks {
                c.dealloc(p, big(MIN_BLOCK));
            }
            let t = c.lock();
            assert_eq!(t.held, 3 * MIN_BLOCK);
            let kept: Vec<usize> = t
                .slots
                .iter()
                .filter(|s| s.addr != 0)
                .map(|s| s.addr)
                .collect();
            assert!(
                !kept.contains(&(blocks[0] as usize)),
                "the oldest left first"
            );
        }
        c.enable(0);
    }

    #[test]
    fn off_keeps_nothing_and_zeroed_blocks_are_zero() {
        let c = BlockCache::new();
        unsafe {
            let a = c.alloc(big(MIN_BLOCK));
            c.dealloc(a, big(MIN_BLOCK));
            assert_eq!(c.lock().held, 0);
            c.enable(4 * MIN_BLOCK);
            let a = c.alloc(big(MIN_BLOCK));
            a.write_bytes(7, MIN_BLOCK);
            c.dealloc(a, big(MIN_BLOCK));
            let z = c.alloc_zeroed(big(MIN_BLOCK));
            assert_eq!(z, a);
            assert!(zero(z, MIN_BLOCK));
            let g = c.realloc(z, big(MIN_BLOCK), 2 * MIN_BLOCK);
            assert!(zero(g, MIN_BLOCK));
            c.dealloc(g, big(2 * MIN_BLOCK));
        }
        c.enable(0);
    }
}
