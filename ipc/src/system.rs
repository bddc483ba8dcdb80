//! Operating-system set-up of an onboard process: real-time scheduling, memory locking, CPU
//! pinning, and systemd's readiness and watchdog notifications.

use std::io;
use std::os::unix::net::UnixDatagram;

/// Real-time requests; each is optional, and each refusal is reported, never fatal.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct RealtimeConfig {
    /// Lock all current and future pages in RAM (mlockall).
    pub lock_memory: bool,
    /// SCHED_FIFO priority (1–99) for the loop thread only; `None` keeps the default scheduler.
    pub fifo_priority: Option<u8>,
    /// CPU to pin the loop thread to.
    pub cpu: Option<usize>,
}

/// Applies `rt` to the calling thread (the loop thread); returns one message per refusal.
pub fn apply_realtime(rt: &RealtimeConfig) -> Vec<String> {
    let mut refused = Vec::new();
    if rt.lock_memory {
        // SAFETY: mlockall takes flags only.
        if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } != 0 {
            refused.push(format!(
                "mlockall refused ({}); raise LimitMEMLOCK or grant CAP_IPC_LOCK",
                io::Error::last_os_error()
            ));
        }
    }
    if let Some(priority) = rt.fifo_priority {
        let param = libc::sched_param {
            sched_priority: i32::from(priority.clamp(1, 99)),
        };
        // SAFETY: pthread_self is always valid; param outlives the call.
        let rc =
            unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
        if rc != 0 {
            refused.push(format!(
                "SCHED_FIFO priority {priority} refused ({}); grant CAP_SYS_NICE or set LimitRTPRIO",
                io::Error::from_raw_os_error(rc)
            ));
        }
    }
    if let Some(cpu) = rt.cpu {
        // SAFETY: the set is zeroed, then one bit is set within its size.
        let rc = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(cpu, &mut set);
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
        };
        if rc != 0 {
            refused.push(format!(
                "pinning to CPU {cpu} refused ({})",
                io::Error::last_os_error()
            ));
        }
    }
    refused
}

/// systemd notifications over `$NOTIFY_SOCKET`; does nothing when not started by systemd.
pub struct Notifier {
    socket: Option<UnixDatagram>,
    /// Watchdog ping interval (half of `$WATCHDOG_USEC`), ns.
    pub watchdog_interval_ns: Option<u64>,
}

impl Notifier {
    pub fn from_env() -> Self {
        let socket = std::env::var_os("NOTIFY_SOCKET").and_then(|path| {
            let sock = UnixDatagram::unbound().ok()?;
            let path = path.to_string_lossy().into_owned();
            let connected = match path.strip_prefix('@') {
                Some(abstract_name) => {
                    use std::os::linux::net::SocketAddrExt;
                    let addr =
                        std::os::unix::net::SocketAddr::from_abstract_name(abstract_name).ok()?;
                    sock.connect_addr(&addr)
                }
                None => sock.connect(&path),
            };
            connected.ok().map(|_| sock)
        });
        let watchdog_interval_ns = std::env::var("WATCHDOG_USEC")
            .ok()
            .and_then(|v| v.parse::<u64>().ok())
            .map(|usec| usec * 1000 / 2);
        Notifier {
            socket,
            watchdog_interval_ns,
        }
    }

    fn send(&self, state: &[u8]) {
        if let Some(s) = &self.socket {
            let _ = s.send(state);
        }
    }

    /// READY=1: the loop is running.
    pub fn ready(&self) {
        self.send(b"READY=1");
    }

    /// WATCHDOG=1: the loop advanced.
    pub fn watchdog(&self) {
        self.send(b"WATCHDOG=1");
    }

    /// STOPPING=1.
    pub fn stopping(&self) {
        self.send(b"STOPPING=1");
    }
}
