//! Process plumbing every node of the stack shares: one monotonic clock,
//! absolute-deadline sleeps and termination signals. Kept here, beside the
//! transport, so the clock that stamps [`crate::Header::t_mono_ns`] is the
//! same in every process.

use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};

/// `CLOCK_MONOTONIC`, ns. Never allocates or blocks.
pub fn mono_now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: valid pointer to a timespec; CLOCK_MONOTONIC always exists.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleeps until `CLOCK_MONOTONIC` reaches `deadline_ns` (absolute, so
/// wake-up errors never accumulate). Returns at once if it has passed.
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: valid timespec; no remaining-time output with TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if rc != libc::EINTR {
            return;
        }
    }
}

/// Puts the calling thread under `SCHED_FIFO` at `priority` (1..=99):
/// real-time scheduling for the stack's 1 kHz loops. Refused without
/// `CAP_SYS_NICE` or an `RLIMIT_RTPRIO` of at least `priority`; the error is
/// the system's.
pub fn set_fifo_priority(priority: i32) -> std::io::Result<()> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: plain syscall on the calling thread.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

static TERMINATE: AtomicBool = AtomicBool::new(false);
static SIGNAL: AtomicI32 = AtomicI32::new(0);

extern "C" fn on_signal(sig: libc::c_int) {
    // Only async-signal-safe work: two atomic stores.
    SIGNAL.store(sig, Ordering::Relaxed);
    TERMINATE.store(true, Ordering::Release);
}

/// Makes SIGINT and SIGTERM set a flag that [`termination_requested`]
/// reads, instead of killing the process: the loops then stop cleanly and
/// release their shared memory. SIGPIPE is ignored.
pub fn install_termination_handler() {
    // SAFETY: a plain handler that only stores atomics.
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_signal as *const () as usize;
        libc::sigemptyset(&mut sa.sa_mask);
        sa.sa_flags = 0;
        libc::sigaction(libc::SIGINT, &sa, std::ptr::null_mut());
        libc::sigaction(libc::SIGTERM, &sa, std::ptr::null_mut());
        libc::signal(libc::SIGPIPE, libc::SIG_IGN);
    }
}

/// True once SIGINT or SIGTERM arrived.
pub fn termination_requested() -> bool {
    TERMINATE.load(Ordering::Acquire)
}

/// The signal that requested termination (0: none).
pub fn termination_signal() -> i32 {
    SIGNAL.load(Ordering::Relaxed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_is_monotonic_and_sleep_reaches_its_deadline() {
        let t0 = mono_now_ns();
        sleep_until_ns(t0 + 2_000_000);
        let t1 = mono_now_ns();
        assert!(t1 >= t0 + 2_000_000);
        sleep_until_ns(t0); // in the past: returns at once
        assert!(mono_now_ns() >= t1);
    }
}
