//! Realtime hygiene for a stepping thread: `SCHED_FIFO`, memory locked (`mlockall`),
//! the stack prefaulted, the CPUs' wake-up latency held at 0 (PM QoS), the thread
//! pinned to one core; and what was actually obtained, read back from the kernel, for
//! the run report.
//!
//! Both processes of a run use it: the emulator (`oils run`) and the onboard stub
//! (`oils stub`). A refused priority is an error (the caller asked for it by name); a
//! refused memory lock, latency hold or pin is a warning in
//! [`RealtimeStatus::warnings`]: the run goes on and says so. The syscalls are `libc`'s,
//! each `unsafe` block with its SAFETY note.

use serde::{Deserialize, Serialize};

/// Bytes of stack touched before tick 0 ([`Hygiene::lock_memory`]): far more than a
/// step uses (a step's deepest frames are the plant's and the flight software's, tens of
/// KiB), far less than a thread's stack (8 MiB main, 2 MiB spawned).
pub const PREFAULT_STACK_BYTES: usize = 512 * 1024;

/// Why a list of CPUs cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CpusError {
    /// Nothing given.
    #[error("an empty list: give one or two CPU numbers, EMULATOR[,STUB] (e.g. 0,1)")]
    Empty,
    /// An entry is not a CPU number.
    #[error("`{entry}` is not a CPU number: give one or two, EMULATOR[,STUB] (e.g. 0,1)")]
    NotANumber {
        /// The entry as written.
        entry: String,
    },
    /// More than the two stepping threads a run has.
    #[error("{count} CPUs given: a run pins two stepping threads, EMULATOR[,STUB] (e.g. 0,1)")]
    TooMany {
        /// How many were given.
        count: usize,
    },
    /// A CPU the kernel does not have online.
    #[error("CPU {cpu} is not online (online: {online})")]
    NotOnline {
        /// The CPU.
        cpu: usize,
        /// The online CPUs, as the kernel lists them (`0-1`).
        online: String,
    },
    /// A CPU online but outside this process's affinity (a cpuset, `taskset`).
    #[error("CPU {cpu} is online but not allowed to this process (allowed: {allowed})")]
    NotAllowed {
        /// The CPU.
        cpu: usize,
        /// The CPUs this process may run on.
        allowed: String,
    },
}

/// Parses `EMULATOR[,STUB]`: one or two CPU numbers, the first for the emulator's
/// stepping thread, the second for the onboard stub's. Syntax only; [`check_cpus`] asks
/// the kernel.
pub fn parse_cpus(s: &str) -> Result<Vec<usize>, CpusError> {
    if s.trim().is_empty() {
        return Err(CpusError::Empty);
    }
    let cpus = s
        .split(',')
        .map(|e| {
            let e = e.trim();
            e.parse::<usize>()
                .map_err(|_| CpusError::NotANumber { entry: e.into() })
        })
        .collect::<Result<Vec<_>, _>>()?;
    check_count(&cpus)?;
    Ok(cpus)
}

fn check_count(cpus: &[usize]) -> Result<(), CpusError> {
    match cpus.len() {
        0 => Err(CpusError::Empty),
        1 | 2 => Ok(()),
        count => Err(CpusError::TooMany { count }),
    }
}

/// Checks that every CPU of `cpus` (one or two) is online and allowed to this process.
pub fn check_cpus(cpus: &[usize]) -> Result<(), CpusError> {
    check_count(cpus)?;
    let online = std::fs::read_to_string("/sys/devices/system/cpu/online").ok();
    let allowed = allowed_cpus();
    check_cpus_against(cpus, online.as_deref(), allowed.as_deref())
}

/// [`check_cpus`] against a kernel list of online CPUs (`0-3,6`; `None`: not known) and
/// the process's affinity (`None`: not known).
pub fn check_cpus_against(
    cpus: &[usize],
    online: Option<&str>,
    allowed: Option<&[usize]>,
) -> Result<(), CpusError> {
    check_count(cpus)?;
    for &cpu in cpus {
        if cpu >= libc::CPU_SETSIZE as usize {
            return Err(CpusError::NotOnline {
                cpu,
                online: online.map_or("unknown".into(), |l| l.trim().into()),
            });
        }
        if let Some(list) = online {
            let list = list.trim();
            if !list_contains(list, cpu) {
                return Err(CpusError::NotOnline {
                    cpu,
                    online: list.into(),
                });
            }
        }
        if let Some(allowed) = allowed {
            if !allowed.contains(&cpu) {
                return Err(CpusError::NotAllowed {
                    cpu,
                    allowed: format_list(allowed),
                });
            }
        }
    }
    Ok(())
}

/// Whether the kernel's list format (`0-3,6,8-9`) holds `cpu`. An unreadable entry holds
/// nothing.
fn list_contains(list: &str, cpu: usize) -> bool {
    list.split(',').any(|part| {
        let part = part.trim();
        match part.split_once('-') {
            Some((a, b)) => match (a.parse::<usize>(), b.parse::<usize>()) {
                (Ok(a), Ok(b)) => (a..=b).contains(&cpu),
                _ => false,
            },
            None => part.parse::<usize>() == Ok(cpu),
        }
    })
}

/// CPUs as a comma-separated list.
fn format_list(cpus: &[usize]) -> String {
    cpus.iter()
        .map(|c| c.to_string())
        .collect::<Vec<_>>()
        .join(",")
}

/// The CPUs the calling thread may run on (`None` if the kernel will not say).
pub fn allowed_cpus() -> Option<Vec<usize>> {
    // SAFETY: cpu_set_t is a plain bit array; all zeros is a valid (empty) set.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    // SAFETY: pid 0 is the calling thread; the size and pointer are those of `set`.
    if unsafe { libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) } != 0
    {
        return None;
    }
    Some(
        (0..libc::CPU_SETSIZE as usize)
            // SAFETY: `cpu` < CPU_SETSIZE, inside the set.
            .filter(|&cpu| unsafe { libc::CPU_ISSET(cpu, &set) })
            .collect(),
    )
}

/// Pins the calling thread to `cpu` alone.
fn set_affinity(cpus: &[usize]) -> std::io::Result<()> {
    // SAFETY: as in `allowed_cpus`.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    for &cpu in cpus.iter().filter(|&&c| c < libc::CPU_SETSIZE as usize) {
        // SAFETY: `cpu` < CPU_SETSIZE, inside the set.
        unsafe { libc::CPU_SET(cpu, &mut set) };
    }
    // SAFETY: pid 0 is the calling thread; the size and pointer are those of `set`.
    if unsafe { libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// Puts the calling process under `SCHED_FIFO` at `priority` (1-99): the kernel then
/// wakes the stepping loop ahead of ordinary work. Children spawned afterwards inherit
/// the policy. Needs root or `CAP_SYS_NICE` (an `Err` otherwise). Memory is locked
/// separately ([`Hygiene::lock_memory`]).
pub fn set_realtime_priority(priority: i32) -> std::io::Result<()> {
    if !(1..=99).contains(&priority) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "priority must be 1-99",
        ));
    }
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: valid pointer to a sched_param; pid 0 is this process.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// The calling thread's scheduling class and priority, as the kernel has them.
pub fn scheduling() -> (String, i32) {
    // SAFETY: plain syscall on the calling thread.
    let policy = unsafe { libc::sched_getscheduler(0) };
    let mut param = libc::sched_param { sched_priority: 0 };
    // SAFETY: valid pointer to a sched_param; pid 0 is the calling thread.
    let priority = if unsafe { libc::sched_getparam(0, &mut param) } == 0 {
        param.sched_priority
    } else {
        0
    };
    let name = match policy {
        libc::SCHED_OTHER => "SCHED_OTHER",
        libc::SCHED_FIFO => "SCHED_FIFO",
        libc::SCHED_RR => "SCHED_RR",
        libc::SCHED_BATCH => "SCHED_BATCH",
        libc::SCHED_IDLE => "SCHED_IDLE",
        -1 => "unknown",
        _ => "other",
    };
    (name.into(), priority)
}

/// What a process's stepping thread obtained before tick 0, as read back from the
/// kernel (the run report's `realtime.emulator` and `realtime.onboard`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RealtimeStatus {
    /// Scheduling class of the stepping thread: `SCHED_OTHER`, `SCHED_FIFO`, ...
    pub sched_policy: String,
    /// Its priority (0 under `SCHED_OTHER`).
    pub sched_priority: i32,
    /// Whether memory locking was asked for (realtime runs and `--rt-priority`).
    pub memory_lock_requested: bool,
    /// Whether `mlockall(MCL_CURRENT | MCL_FUTURE)` succeeded.
    pub memory_locked: bool,
    /// Stack bytes touched before tick 0 (0: not asked).
    pub stack_prefaulted_bytes: u64,
    /// Whether holding the CPUs' wake-up latency at 0 was asked for (with the memory
    /// lock: realtime runs and `--rt-priority`; see [`Hygiene::hold_wake_latency`]).
    #[serde(default)]
    pub wake_latency_requested: bool,
    /// Whether the kernel holds it: 0 written to `/dev/cpu_dma_latency`, and read back.
    #[serde(default)]
    pub wake_latency_held: bool,
    /// The CPU the stepping thread was asked to run on.
    pub cpu_requested: Option<usize>,
    /// The CPUs it may run on, read back after pinning (`[0]`: pinned to CPU 0).
    pub cpus_allowed: Vec<usize>,
    /// Whether it is pinned to the CPU asked for (read back, not assumed).
    pub pinned: bool,
    /// What was asked and refused, and why.
    pub warnings: Vec<String>,
}

impl RealtimeStatus {
    /// One line: `SCHED_FIFO 10, memory locked, pinned to CPU 1`.
    pub fn summary(&self) -> String {
        let mut s = if self.sched_priority > 0 {
            format!("{} {}", self.sched_policy, self.sched_priority)
        } else {
            self.sched_policy.clone()
        };
        s.push_str(match (self.memory_lock_requested, self.memory_locked) {
            (_, true) => ", memory locked",
            (true, false) => ", memory NOT locked",
            (false, false) => ", memory not locked",
        });
        s.push_str(
            match (self.wake_latency_requested, self.wake_latency_held) {
                (_, true) => ", wake-up latency held at 0",
                (true, false) => ", wake-up latency NOT held",
                (false, false) => "",
            },
        );
        match (self.cpu_requested, self.pinned) {
            (Some(cpu), true) => s.push_str(&format!(", pinned to CPU {cpu}")),
            (Some(cpu), false) => s.push_str(&format!(", NOT pinned to CPU {cpu}")),
            (None, _) => s.push_str(", not pinned"),
        }
        s
    }
}

/// Realtime set-up of the calling (stepping) thread, undone on drop: memory unlocked,
/// the thread's former affinity restored (a library caller's process goes on as it was).
#[derive(Debug, Default)]
pub struct Hygiene {
    locked: bool,
    lock_requested: bool,
    prefaulted: u64,
    wake_latency_requested: bool,
    /// Open while the request holds: closing it withdraws the request.
    wake_latency: Option<std::fs::File>,
    cpu: Option<usize>,
    former_affinity: Option<Vec<usize>>,
    warnings: Vec<String>,
}

impl Hygiene {
    /// Nothing done yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Locks the process's memory (`mlockall(MCL_CURRENT | MCL_FUTURE)`: no page fault
    /// in a step, pages mapped later locked as they come) and prefaults
    /// [`PREFAULT_STACK_BYTES`] of the calling thread's stack. Refused (no
    /// `CAP_IPC_LOCK`, a `RLIMIT_MEMLOCK` too small): a warning, memory left unlocked.
    pub fn lock_memory(&mut self) {
        self.lock_requested = true;
        if let Some(why) = memlock_limit_too_small() {
            self.warnings.push(format!("memory not locked: {why}"));
        } else {
            // SAFETY: plain syscall; failure only leaves pages unlocked, which is reported.
            if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } == 0 {
                self.locked = true;
            } else {
                self.warnings.push(format!(
                    "memory not locked: mlockall: {} (needs root or CAP_IPC_LOCK)",
                    std::io::Error::last_os_error()
                ));
            }
        }
        prefault_stack();
        self.prefaulted = PREFAULT_STACK_BYTES as u64;
    }

    /// Asks the kernel to keep every CPU's wake-up latency at 0 for as long as this value
    /// lives (PM QoS: 0 written to `/dev/cpu_dma_latency`, the file held open, as
    /// `cyclictest` does): idle CPUs then stay in their shallowest idle state (on a
    /// `haltpoll` guest, polling rather than halting), so a timer wakes the stepping
    /// thread without a deep idle exit. Measured on the 2-core VM, `cyclictest` at 1 ms:
    /// mean wake-up 19 us with it, 35 us without (`--laptop`). Costs power on an idle
    /// machine, so only realtime runs ask. Refused (not root): a warning.
    pub fn hold_wake_latency(&mut self) {
        use std::io::{Read, Write};
        self.wake_latency_requested = true;
        let held = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(CPU_DMA_LATENCY)
            .and_then(|mut f| {
                f.write_all(&0i32.to_ne_bytes())?;
                // Read back: the latency the kernel now holds for all (the smallest
                // request of any holder).
                let mut now = [0u8; 4];
                f.read_exact(&mut now)?;
                Ok((f, i32::from_ne_bytes(now)))
            });
        match held {
            Ok((f, 0)) => self.wake_latency = Some(f),
            Ok((_, us)) => self.warnings.push(format!(
                "wake-up latency not held at 0: {CPU_DMA_LATENCY} reads {us} us after 0 was written"
            )),
            Err(e) => self.warnings.push(format!(
                "wake-up latency not held at 0: {CPU_DMA_LATENCY}: {e} (needs root)"
            )),
        }
    }

    /// Pins the calling thread to `cpu`. Refused: a warning, the thread left as it was.
    pub fn pin_to(&mut self, cpu: usize) {
        self.cpu = Some(cpu);
        let former = allowed_cpus();
        match set_affinity(&[cpu]) {
            Ok(()) => self.former_affinity = former,
            Err(e) => self
                .warnings
                .push(format!("not pinned to CPU {cpu}: sched_setaffinity: {e}")),
        }
    }

    /// What the calling thread has now, read back from the kernel.
    pub fn status(&self) -> RealtimeStatus {
        let (sched_policy, sched_priority) = scheduling();
        let cpus_allowed = allowed_cpus().unwrap_or_default();
        let pinned = self.cpu.is_some_and(|c| cpus_allowed == [c]);
        let mut warnings = self.warnings.clone();
        if let (Some(cpu), false, true) = (self.cpu, pinned, self.former_affinity.is_some()) {
            warnings.push(format!(
                "pinned to CPU {cpu} but the kernel reports CPUs {}",
                format_list(&cpus_allowed)
            ));
        }
        RealtimeStatus {
            sched_policy,
            sched_priority,
            memory_lock_requested: self.lock_requested,
            memory_locked: self.locked,
            stack_prefaulted_bytes: self.prefaulted,
            wake_latency_requested: self.wake_latency_requested,
            wake_latency_held: self.wake_latency.is_some(),
            cpu_requested: self.cpu,
            cpus_allowed,
            pinned,
            warnings,
        }
    }
}

impl Drop for Hygiene {
    fn drop(&mut self) {
        if self.locked {
            // SAFETY: plain syscall; undoes this value's mlockall.
            unsafe { libc::munlockall() };
        }
        if let Some(former) = self.former_affinity.take() {
            let _ = set_affinity(&former);
        }
    }
}

/// The kernel's PM QoS interface for the CPUs' wake-up latency.
const CPU_DMA_LATENCY: &str = "/dev/cpu_dma_latency";

/// Why `mlockall(MCL_FUTURE)` would be unsafe to ask for here: not root and a finite
/// `RLIMIT_MEMLOCK` (every later allocation past the limit would then fail, and Rust
/// aborts on a failed allocation). `None`: go ahead.
fn memlock_limit_too_small() -> Option<String> {
    // SAFETY: plain syscall.
    if unsafe { libc::geteuid() } == 0 {
        return None;
    }
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: valid pointer to an rlimit.
    if unsafe { libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut lim) } != 0 {
        return Some(format!("getrlimit: {}", std::io::Error::last_os_error()));
    }
    (lim.rlim_cur != libc::RLIM_INFINITY).then(|| {
        format!(
            "RLIMIT_MEMLOCK is {} bytes and this process is not root (raise it: `ulimit -l unlimited`, or LimitMEMLOCK=infinity)",
            lim.rlim_cur
        )
    })
}

/// Touches [`PREFAULT_STACK_BYTES`] of stack below the caller, so the step loop's frames
/// land on pages already mapped (and, with memory locked, locked).
#[inline(never)]
fn prefault_stack() {
    let buf = [1u8; PREFAULT_STACK_BYTES];
    std::hint::black_box(&buf);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_lists_parse_or_say_why_not() {
        assert_eq!(parse_cpus("0,1"), Ok(vec![0, 1]));
        assert_eq!(parse_cpus(" 3 "), Ok(vec![3]));
        assert_eq!(parse_cpus("1, 1"), Ok(vec![1, 1]));
        assert_eq!(parse_cpus(""), Err(CpusError::Empty));
        assert_eq!(
            parse_cpus("0,x"),
            Err(CpusError::NotANumber { entry: "x".into() })
        );
        assert_eq!(
            parse_cpus("-1"),
            Err(CpusError::NotANumber { entry: "-1".into() })
        );
        assert_eq!(
            parse_cpus("0,,1"),
            Err(CpusError::NotANumber { entry: "".into() })
        );
        assert_eq!(
            parse_cpus("0-3"),
            Err(CpusError::NotANumber {
                entry: "0-3".into()
            })
        );
        assert_eq!(parse_cpus("0,1,2"), Err(CpusError::TooMany { count: 3 }));
        assert_eq!(parse_cpus("99999"), Ok(vec![99999]));
        let e = parse_cpus("0,x").unwrap_err().to_string();
        assert!(
            e.contains("`x` is not a CPU number") && e.contains("EMULATOR[,STUB]"),
            "{e}"
        );
    }

    #[test]
    fn cpus_are_checked_against_online_and_allowed() {
        assert_eq!(
            check_cpus_against(&[0, 1], Some("0-1\n"), Some(&[0, 1])),
            Ok(())
        );
        assert_eq!(check_cpus_against(&[6], Some("0-3,6"), None), Ok(()));
        assert_eq!(
            check_cpus_against(&[0, 2], Some("0-1\n"), None),
            Err(CpusError::NotOnline {
                cpu: 2,
                online: "0-1".into()
            })
        );
        assert_eq!(
            check_cpus_against(&[5], Some("0-3,6"), None)
                .unwrap_err()
                .to_string(),
            "CPU 5 is not online (online: 0-3,6)"
        );
        assert_eq!(
            check_cpus_against(&[1], Some("0-3"), Some(&[0, 2])),
            Err(CpusError::NotAllowed {
                cpu: 1,
                allowed: "0,2".into()
            })
        );
        assert_eq!(check_cpus_against(&[], None, None), Err(CpusError::Empty));
        assert!(matches!(
            check_cpus_against(&[99999], None, None),
            Err(CpusError::NotOnline { cpu: 99999, .. })
        ));
    }

    #[test]
    fn this_machine_has_cpu_0_and_not_cpu_4095() {
        assert_eq!(check_cpus(&[0]), Ok(()));
        assert!(check_cpus(&[4095]).is_err());
    }

    #[test]
    fn hygiene_reports_what_it_obtained_and_undoes_it() {
        // On a thread of its own: pinning changes the calling thread.
        std::thread::spawn(|| {
            let before = allowed_cpus().unwrap();
            {
                let mut h = Hygiene::new();
                h.pin_to(0);
                let s = h.status();
                assert_eq!(s.cpu_requested, Some(0));
                // Pinned, or a warning saying why not: never silence.
                assert!(s.pinned || !s.warnings.is_empty(), "{s:?}");
                assert_eq!(s.pinned, s.cpus_allowed == [0]);
                assert!(!s.memory_lock_requested && !s.memory_locked);
                assert!(s.summary().contains("CPU 0"), "{}", s.summary());
            }
            assert_eq!(allowed_cpus().unwrap(), before, "affinity restored on drop");
        })
        .join()
        .unwrap();
    }

    #[test]
    fn memory_lock_is_obtained_or_said_refused() {
        let mut h = Hygiene::new();
        h.lock_memory();
        let s = h.status();
        assert!(s.memory_lock_requested);
        assert_eq!(s.stack_prefaulted_bytes, PREFAULT_STACK_BYTES as u64);
        assert!(
            s.memory_locked || s.warnings.iter().any(|w| w.contains("memory not locked")),
            "{s:?}"
        );
        assert_eq!(s.cpu_requested, None);
        assert!(!s.pinned);
        assert!(!s.wake_latency_requested && !s.wake_latency_held);
    }

    #[test]
    fn wake_latency_is_held_or_said_refused_and_released() {
        let before = std::fs::read(CPU_DMA_LATENCY).ok();
        let mut h = Hygiene::new();
        h.hold_wake_latency();
        let s = h.status();
        assert!(s.wake_latency_requested);
        if s.wake_latency_held {
            assert!(
                s.summary().contains("wake-up latency held at 0"),
                "{}",
                s.summary()
            );
        } else {
            assert!(
                s.warnings
                    .iter()
                    .any(|w| w.contains("wake-up latency not held")),
                "{s:?}"
            );
            assert!(s.summary().contains("wake-up latency NOT held"));
        }
        drop(h);
        // Released with the value: the latency is what it was before.
        if s.wake_latency_held {
            assert_eq!(
                std::fs::read(CPU_DMA_LATENCY).ok(),
                before,
                "request not withdrawn"
            );
        }
    }
}
