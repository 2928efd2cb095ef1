//! Real-time set-up of the calling thread, systemd notifications, and the
//! real-time loop's short pause in a busy wait.

use crate::config::RealtimeConfig;
use std::os::unix::net::UnixDatagram;

/// What the real-time set-up achieved.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RtReport {
    /// mlockall succeeded.
    pub memory_locked: bool,
    /// SCHED_FIFO at the requested priority is in force.
    pub fifo: bool,
    /// The thread is pinned to the requested CPU.
    pub pinned: bool,
    /// What was refused, in words (one line each).
    pub warnings: Vec<String>,
}

impl RtReport {
    /// Memory locked and SCHED_FIFO: the loop can meet its deadlines.
    pub fn realtime(&self) -> bool {
        self.memory_locked && self.fifo
    }
}

fn errno_text() -> String {
    std::io::Error::last_os_error().to_string()
}

/// Touches `kib` KiB of stack so that later cycles never page-fault on it.
#[inline(never)]
fn prefault_stack(kib: usize) {
    const CHUNK: usize = 16 * 1024;
    fn touch(levels: usize) {
        let mut buf = [0u8; CHUNK];
        // Volatile so the buffer is really written.
        for i in (0..CHUNK).step_by(4096) {
            // SAFETY: in bounds.
            unsafe { std::ptr::write_volatile(buf.as_mut_ptr().add(i), 1) };
        }
        if levels > 1 {
            touch(levels - 1);
        }
        std::hint::black_box(&buf);
    }
    touch(kib.div_ceil(16).max(1));
}

/// Applies `cfg` to the calling thread: memory lock, stack pre-fault, CPU
/// pinning, SCHED_FIFO. Each refusal becomes a warning in the report.
pub fn setup(cfg: &RealtimeConfig) -> RtReport {
    let mut r = RtReport::default();
    if !cfg.enabled {
        r.warnings
            .push("real-time set-up disabled by configuration (realtime.enabled = false)".into());
        return r;
    }
    if cfg.lock_memory {
        // SAFETY: plain syscall.
        if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } == 0 {
            r.memory_locked = true;
        } else {
            r.warnings.push(format!(
                "mlockall failed ({}): page faults may delay cycles; raise RLIMIT_MEMLOCK \
                 (LimitMEMLOCK=infinity in the unit) or run with CAP_IPC_LOCK",
                errno_text()
            ));
        }
    }
    prefault_stack(cfg.prefault_stack_kib);
    if let Some(cpu) = cfg.cpu {
        // SAFETY: cpu_set_t is plain data; CPU_SET bounds-checks via its size.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            if cpu < 8 * std::mem::size_of::<libc::cpu_set_t>() {
                libc::CPU_SET(cpu, &mut set);
                if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0 {
                    r.pinned = true;
                }
            }
        }
        if !r.pinned {
            r.warnings.push(format!(
                "cannot pin the control thread to CPU {cpu} ({})",
                errno_text()
            ));
        }
    }
    match shared_mem_schema::process::set_fifo_priority(cfg.priority) {
        Ok(()) => r.fifo = true,
        Err(e) => r.warnings.push(format!(
            "SCHED_FIFO priority {} refused ({e}): the loop runs with normal priority and its \
             jitter will show it; grant LimitRTPRIO=99 / CAP_SYS_NICE",
            cfg.priority
        )),
    }
    r
}

/// systemd's notification socket (`$NOTIFY_SOCKET`), when started by
/// systemd with `Type=notify`.
pub struct Notifier {
    socket: Option<(UnixDatagram, std::os::unix::net::SocketAddr)>,
    /// `$WATCHDOG_USEC` as a period, if the unit has a watchdog.
    pub watchdog_usec: Option<u64>,
}

impl Notifier {
    /// Connects to `$NOTIFY_SOCKET` if set (paths and abstract names).
    pub fn from_env() -> Self {
        use std::os::linux::net::SocketAddrExt;
        let socket = std::env::var_os("NOTIFY_SOCKET").and_then(|p| {
            let p = p.to_string_lossy().into_owned();
            let addr = match p.strip_prefix('@') {
                Some(name) => std::os::unix::net::SocketAddr::from_abstract_name(name).ok()?,
                None => std::os::unix::net::SocketAddr::from_pathname(&p).ok()?,
            };
            let s = UnixDatagram::unbound().ok()?;
            s.set_nonblocking(true).ok()?;
            Some((s, addr))
        });
        let watchdog_usec = std::env::var("WATCHDOG_USEC")
            .ok()
            .and_then(|v| v.parse().ok());
        Self {
            socket,
            watchdog_usec,
        }
    }

    /// Whether systemd listens.
    pub fn active(&self) -> bool {
        self.socket.is_some()
    }

    /// Sends a notification such as `READY=1` (non-blocking; errors are
    /// ignored: systemd may be gone at shutdown).
    pub fn notify(&self, msg: &str) {
        if let Some((s, addr)) = &self.socket {
            let _ = s.send_to_addr(msg.as_bytes(), addr);
        }
    }
}

/// A short sleep in a hardware-clocked wait (lockstep). Not a yield: under
/// `SCHED_FIFO` a yield lets only other real-time threads run, so the peers
/// this loop waits for (the simulator, the policy node) would starve on a
/// loaded machine and the wait would end in a hardware timeout.
pub(crate) fn pause_briefly() {
    std::thread::sleep(std::time::Duration::from_micros(20));
}
