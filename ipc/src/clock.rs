//! `CLOCK_MONOTONIC` in nanoseconds: the one time base of every Concord process on a machine
//! (Python's `time.monotonic_ns()` reads the same clock).

/// Now, ns since an arbitrary point fixed at boot.
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC is always available on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Nanoseconds to seconds.
pub fn secs(ns: u64) -> f64 {
    ns as f64 * 1e-9
}
