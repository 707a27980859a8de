//! Peak heap use of a piece of code, for tests that bound memory (the memory budget's
//! "check before allocating" contract).
//!
//! A test binary installs [`CountingAllocator`] as its global allocator:
//!
//! ```ignore
//! #[global_allocator]
//! static ALLOCATOR: volmorph_testkit::alloc_peak::CountingAllocator =
//!     volmorph_testkit::alloc_peak::CountingAllocator::new();
//! ```
//!
//! and measures with [`CountingAllocator::peak_during`]. The counts are process-wide, so a
//! measuring test runs alone in a child process of its binary ([`in_child`]): other tests
//! running on other threads would add their own allocations.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The system allocator, counting the bytes live and their peak (bytes requested, not the
/// allocator's overhead).
pub struct CountingAllocator {
    live: AtomicUsize,
    peak: AtomicUsize,
}

impl CountingAllocator {
    /// A counter with nothing counted yet.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            live: AtomicUsize::new(0),
            peak: AtomicUsize::new(0),
        }
    }

    /// Run `f` and return its result with the peak of live bytes above those live when it
    /// started (bytes).
    pub fn peak_during<R>(&self, f: impl FnOnce() -> R) -> (R, usize) {
        let base = self.live.load(Ordering::Relaxed);
        self.peak.store(base, Ordering::Relaxed);
        let r = f();
        let peak = self.peak.load(Ordering::Relaxed);
        (r, peak.saturating_sub(base))
    }
}

impl Default for CountingAllocator {
    fn default() -> Self {
        Self::new()
    }
}

// A global allocator is an unsafe trait; this one only forwards to `System`.
// SAFETY: every call is forwarded to `System` unchanged; the counters are only statistics.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded with the caller's layout.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let now = self.live.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            self.peak.fetch_max(now, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded with the caller's pointer and layout.
        unsafe { System.dealloc(ptr, layout) };
        self.live.fetch_sub(layout.size(), Ordering::Relaxed);
    }
}

/// Environment variable naming the one test a child process of a test binary runs.
const CHILD: &str = "VOLMORPH_TEST_CHILD";

/// Run the test `name` (its path in the test binary, e.g. `module::test`) alone in a child
/// process of the current test binary and fail if it fails or runs no test.
///
/// Returns `true` in that child, where the caller then runs the test's body, and `false` in
/// the parent once the child has passed:
///
/// ```ignore
/// #[test]
/// fn bounded() {
///     if !in_child("module::bounded") {
///         return;
///     }
///     // measured body
/// }
/// ```
///
/// # Panics
/// In the parent, when the child cannot be started, fails, or runs no test (a wrong `name`).
#[must_use]
pub fn in_child(name: &str) -> bool {
    if std::env::var(CHILD).as_deref() == Ok(name) {
        return true;
    }
    let exe = std::env::current_exe().expect("the test binary's path");
    let out = std::process::Command::new(exe)
        .args([name, "--exact", "--nocapture", "--test-threads=1"])
        .env(CHILD, name)
        .output()
        .expect("the test binary runs as a child");
    assert!(
        out.status.success(),
        "child test {name} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("1 passed"),
        "the child ran no test:\n{stdout}"
    );
    false
}
