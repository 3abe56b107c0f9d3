//! What stops a script call: this thread's deadline and stop flag, and the memory the
//! thread holds, counted by [`CountingAllocator`].

use std::cell::Cell;
use std::time::Instant;

use rhai::Dynamic;

thread_local! {
    /// Deadline of the script call running on this thread.
    pub(super) static DEADLINE: Cell<Option<Instant>> = const { Cell::new(None) };
    /// Whether the call running on this thread was stopped at least once. Some of
    /// Rhai's functions swallow their callbacks' errors (a sort comparator that is
    /// stopped only makes the sort go on): once stopped, the whole call fails.
    pub(super) static STOPPED: Cell<bool> = const { Cell::new(false) };
    /// Why the call running on this thread was stopped.
    pub(super) static STOP_REASON: Cell<&'static str> = const { Cell::new("time limit exceeded") };
    /// Bytes this thread holds, as [`CountingAllocator`] counts them.
    pub(super) static HELD: Cell<isize> = const { Cell::new(0) };
    /// Operations this thread's script calls have made, for the clock checks.
    pub(super) static TICKS: Cell<u32> = const { Cell::new(0) };
    /// What this thread held when its script call started.
    pub(super) static HELD_AT_START: Cell<isize> = const { Cell::new(0) };
}

/// A global allocator that counts the bytes each thread holds, so that a script call
/// is stopped when it holds more than [`ScriptLimits::max_memory`]. A program opts in
/// with `#[global_allocator] static A: CountingAllocator = CountingAllocator::SYSTEM;`
/// (or [`CountingAllocator::new`] around another allocator); without it no memory
/// limit applies. The count is a thread-local addition per allocation.
#[derive(Debug, Default, Clone, Copy)]
pub struct CountingAllocator<A = std::alloc::System> {
    inner: A,
}

impl CountingAllocator {
    /// Counting around the system allocator.
    pub const SYSTEM: Self = Self {
        inner: std::alloc::System,
    };
}

impl<A> CountingAllocator<A> {
    /// Counting around `inner`, which serves every allocation.
    pub const fn new(inner: A) -> Self {
        Self { inner }
    }
}

fn count_held(bytes: isize) {
    // The counter is a const-initialised `Cell` without destructor: using it allocates
    // nothing, and after the thread's end `try_with` just skips.
    let _ = HELD.try_with(|h| h.set(h.get().wrapping_add(bytes)));
}

// SAFETY: every call is passed unchanged to the inner allocator, which upholds the
// `GlobalAlloc` contract; the counting touches no allocation.
unsafe impl<A: std::alloc::GlobalAlloc> std::alloc::GlobalAlloc for CountingAllocator<A> {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        count_held(layout.size() as isize);
        // SAFETY: the caller keeps `alloc`'s contract, which the inner allocator shares.
        unsafe { self.inner.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: std::alloc::Layout) -> *mut u8 {
        count_held(layout.size() as isize);
        // SAFETY: as for `alloc`.
        unsafe { self.inner.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        count_held(-(layout.size() as isize));
        // SAFETY: `ptr` came from the inner allocator through this one with `layout`.
        unsafe { self.inner.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new_size: usize) -> *mut u8 {
        count_held(new_size as isize - layout.size() as isize);
        // SAFETY: as for `dealloc`, with the caller's valid `new_size`.
        unsafe { self.inner.realloc(ptr, layout, new_size) }
    }
}

/// Stops the call running on this thread for `reason`.
pub(super) fn stop(reason: &'static str) -> Option<Dynamic> {
    STOPPED.with(|s| s.set(true));
    STOP_REASON.with(|r| r.set(reason));
    Some(Dynamic::from(reason.to_string()))
}
