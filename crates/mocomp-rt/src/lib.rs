//! Real-time threads on a general-purpose Linux PC, the way ros2_control and UR's drivers do it
//! (`../shared/reference/realtime.md`): `SCHED_FIFO` at a priority, memory locked so no page
//! fault stalls a cycle, optional pinning to one core, and sleeping to absolute deadlines on the
//! monotonic clock.
//!
//! The operating system may refuse each of these (no root, no `rtprio` or `memlock` limit in
//! `/etc/security/limits.conf`). A refusal is not fatal: [`apply`] returns an [`RtReport`] that
//! says what took effect and what was refused, so the caller warns once and says in its summary
//! that it ran without. Threads a real-time thread spawns inherit its policy, priority and
//! affinity (Linux's default `PTHREAD_INHERIT_SCHED`), which is how the client's receive threads
//! and a simulator's threads get theirs: set the thread first, then start them.
//!
//! No `unsafe` here: `thread-priority` wraps `pthread_setschedparam`, `nix` wraps `mlockall`,
//! `sched_setaffinity` and `clock_nanosleep`.
//!
//! **Limits.** Only scheduling, memory locking, pinning and deadline sleeps: it owns no thread's
//! work and decides no policy.

use serde::{Deserialize, Serialize};
use std::time::{Duration, Instant};
use thread_priority::unix::{
    NormalThreadSchedulePolicy, RealtimeThreadSchedulePolicy, ThreadSchedulePolicy,
    set_thread_priority_and_policy, thread_native_id, thread_schedule_policy_param,
};
use thread_priority::{ThreadPriority, ThreadPriorityValue};

/// ros2_control's controller manager runs its update loop at `SCHED_FIFO` 50.
pub const DEFAULT_PRIORITY: u8 = 50;

/// `[realtime]`: how the live loop (and the simulators that stand for other machines) run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RtConfig {
    /// Ask for real-time scheduling at all. [true]
    pub enabled: bool,
    /// `SCHED_FIFO` priority of the loop and the robot client's receive thread, 1–99. [50, as
    /// ros2_control's controller manager]
    pub priority: u8,
    /// `SCHED_FIFO` priority of the in-process simulated controller and tracker, 1–99. They
    /// stand for other machines, so no normal process may delay them; one below the loop, so
    /// the simulated controller waking on the loop's command does not preempt the loop in the
    /// middle of its cycle (on a 2-core PC that put the simulator's work into the loop's compute
    /// time: median 49 → 64 µs, p99 105 → 232 µs). [49]
    pub simulator_priority: u8,
    /// Lock all memory (`mlockall`), so no page fault stalls a cycle. [true]
    pub lock_memory: bool,
    /// Hold `/dev/cpu_dma_latency` at 0 µs while running, as `cyclictest` does: idle CPUs then
    /// poll instead of entering sleep states that take long to wake from, so the loop wakes on
    /// time for the next state; the price is idle CPUs that do not sleep while the loop runs.
    /// `true`, `false`, or `"auto"`: held on bare metal, not under a hypervisor. A virtual
    /// machine's idle vCPU that polls is a busy thread to its host, which then spends the VM's
    /// CPU share on it and freezes the vCPUs when it runs out: on the 2-vCPU VM this was measured
    /// on (`bench/cpu_sleep_on_vm.py`), holding it beside one busy process froze each vCPU for
    /// 100 ms about ten times a minute (223 jiffies of steal a minute), against a 10 ms worst
    /// wake-up and 2 jiffies without, and a 100 ms freeze stops the robot's program on its
    /// 50 ms watchdog. ["auto"]
    pub prevent_cpu_sleep: CpuSleep,
    /// Pin the loop and the robot and tracker clients' receive threads to this CPU (and the
    /// in-process simulators too, unless `simulator_cpu` says otherwise), leaving the other
    /// CPUs to the rest of the PC. One core for the loop and the thread that wakes it spares a
    /// cross-core wake-up each cycle, which on a virtual machine costs far more than on bare
    /// metal (measured on a 2-vCPU VM: state-to-loop wake-up p99 472 µs unpinned, 36 µs
    /// pinned). [none: the scheduler chooses]
    pub cpu: Option<usize>,
    /// Pin the in-process simulated controller and tracker to this CPU. [none: as `cpu`]
    pub simulator_cpu: Option<usize>,
}

impl Default for RtConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            priority: DEFAULT_PRIORITY,
            simulator_priority: DEFAULT_PRIORITY - 1,
            lock_memory: true,
            prevent_cpu_sleep: CpuSleep::Auto,
            cpu: None,
            simulator_cpu: None,
        }
    }
}

/// `[realtime] prevent_cpu_sleep`: whether to hold the CPUs' idle latency at zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CpuSleep {
    /// Held on bare metal, not under a hypervisor (`"auto"`).
    Auto,
    /// Always held (`true`).
    Prevent,
    /// Never held (`false`).
    Allow,
}

impl Serialize for CpuSleep {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Self::Auto => s.serialize_str("auto"),
            Self::Prevent => s.serialize_bool(true),
            Self::Allow => s.serialize_bool(false),
        }
    }
}

impl<'de> Deserialize<'de> for CpuSleep {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Bool(bool),
            Word(String),
        }
        match Raw::deserialize(d)? {
            Raw::Bool(true) => Ok(Self::Prevent),
            Raw::Bool(false) => Ok(Self::Allow),
            Raw::Word(w) if w == "auto" => Ok(Self::Auto),
            Raw::Word(w) => Err(serde::de::Error::custom(format!(
                "prevent_cpu_sleep = {w:?}: true, false or \"auto\""
            ))),
        }
    }
}

impl CpuSleep {
    /// Whether to hold the latency on this machine (`virtual_machine`: under a hypervisor).
    pub fn hold(self, virtual_machine: bool) -> bool {
        match self {
            Self::Auto => !virtual_machine,
            Self::Prevent => true,
            Self::Allow => false,
        }
    }
}

/// Whether this machine runs under a hypervisor: the CPU says so (x86's `hypervisor` flag in
/// `/proc/cpuinfo`), or the kernel names one (`/sys/hypervisor/type`).
pub fn under_hypervisor() -> bool {
    let flagged =
        std::fs::read_to_string("/proc/cpuinfo").is_ok_and(|t| cpuinfo_flags_hypervisor(&t));
    flagged || std::fs::read_to_string("/sys/hypervisor/type").is_ok_and(|t| !t.trim().is_empty())
}

/// Whether a `/proc/cpuinfo` text has the `hypervisor` CPU flag.
pub fn cpuinfo_flags_hypervisor(cpuinfo: &str) -> bool {
    cpuinfo.lines().any(|l| {
        l.split_once(':').is_some_and(|(k, v)| {
            k.trim() == "flags" && v.split_whitespace().any(|f| f == "hypervisor")
        })
    })
}

/// A setting out of range, or a request the operating system refused.
#[derive(Debug, thiserror::Error)]
pub enum RtError {
    /// A setting is out of its range.
    #[error("realtime.{key} = {value}: {why}")]
    Setting {
        /// The key.
        key: &'static str,
        /// Its value.
        value: String,
        /// What it must be.
        why: String,
    },
    /// `SCHED_FIFO` was refused.
    #[error("SCHED_FIFO priority {priority} refused ({source}; needs root, or an rtprio limit)")]
    Fifo {
        /// The priority asked for.
        priority: u8,
        /// The cause.
        source: thread_priority::Error,
    },
    /// Going back to normal scheduling was refused.
    #[error("SCHED_OTHER refused ({0})")]
    Normal(thread_priority::Error),
    /// The policy could not be read.
    #[error("reading the scheduling policy failed ({0})")]
    Query(thread_priority::Error),
    /// `mlockall` was refused.
    #[error("locking memory refused ({0}; needs root, or a memlock limit)")]
    LockMemory(#[source] nix::Error),
    /// Memory was not locked because the limit is finite.
    #[error(
        "locking memory not attempted: the memlock limit is {0} KiB, and with every future \
         allocation locked the process would fail once it grew past it (needs root, or \
         `memlock unlimited`)"
    )]
    MemlockLimit(u64),
    /// `/dev/cpu_dma_latency` could not be held.
    #[error("holding /dev/cpu_dma_latency at 0 µs refused ({0}; needs root)")]
    CpuLatency(#[source] std::io::Error),
    /// `sched_setaffinity` was refused.
    #[error("pinning to CPU {cpu} refused ({source})")]
    Pin {
        /// The CPU.
        cpu: usize,
        /// The cause.
        source: nix::Error,
    },
}

impl RtConfig {
    /// Checks the ranges, naming the key.
    pub fn validate(&self) -> Result<(), RtError> {
        for (key, p) in [
            ("priority", self.priority),
            ("simulator_priority", self.simulator_priority),
        ] {
            if !(1..=99).contains(&p) {
                return Err(RtError::Setting {
                    key,
                    value: p.to_string(),
                    why: "must be in 1–99".into(),
                });
            }
        }
        let n = std::thread::available_parallelism().map_or(1, usize::from);
        for (key, cpu) in [("cpu", self.cpu), ("simulator_cpu", self.simulator_cpu)] {
            if let Some(cpu) = cpu.filter(|c| *c >= n) {
                return Err(RtError::Setting {
                    key,
                    value: cpu.to_string(),
                    why: format!("this machine has CPUs 0–{}", n - 1),
                });
            }
        }
        Ok(())
    }
}

/// The calling thread's scheduling policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Policy {
    /// `SCHED_FIFO` at this priority.
    Fifo(u8),
    /// `SCHED_RR` at this priority.
    RoundRobin(u8),
    /// A normal (time-sharing) policy.
    Normal,
}

/// The calling thread's scheduling policy.
pub fn current_policy() -> Result<Policy, RtError> {
    let (policy, params) =
        thread_schedule_policy_param(thread_native_id()).map_err(RtError::Query)?;
    let prio = u8::try_from(params.sched_priority).unwrap_or(0);
    Ok(match policy {
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo) => Policy::Fifo(prio),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::RoundRobin) => {
            Policy::RoundRobin(prio)
        }
        _ => Policy::Normal,
    })
}

/// Puts the calling thread under `SCHED_FIFO` at `priority` (1–99).
pub fn set_fifo(priority: u8) -> Result<(), RtError> {
    let value = ThreadPriorityValue::try_from(priority).map_err(|why| RtError::Setting {
        key: "priority",
        value: priority.to_string(),
        why: why.to_string(),
    })?;
    set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .map_err(|source| RtError::Fifo { priority, source })
}

/// Puts the calling thread back under normal time-sharing (for threads a real-time thread spawns
/// that must not compete with it: a logger, a status printer).
pub fn set_normal() -> Result<(), RtError> {
    if current_policy()? == Policy::Normal {
        return Ok(());
    }
    set_thread_priority_and_policy(
        thread_native_id(),
        // Nice 0: the library maps 0..=99 onto nice 19..=-20 as `(39 · (1 − p/99)) as i8 − 20`,
        // which is 0 for p = 47.
        ThreadPriority::Crossplatform(ThreadPriorityValue::try_from(47u8).map_err(|why| {
            RtError::Setting {
                key: "priority",
                value: "47".into(),
                why: why.to_string(),
            }
        })?),
        ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Other),
    )
    .map_err(RtError::Normal)
}

/// Locks every current and future page of the process in memory. Only as root or with an
/// unlimited memlock limit: under a finite one, a later allocation past the limit would fail
/// (and abort the process) instead of merely going unlocked.
pub fn lock_memory() -> Result<(), RtError> {
    use nix::sys::mman::{MlockAllFlags, mlockall};
    use nix::sys::resource::{Resource, getrlimit};
    let (soft, _) = getrlimit(Resource::RLIMIT_MEMLOCK).map_err(RtError::LockMemory)?;
    may_lock_all(nix::unistd::geteuid().is_root(), soft)?;
    mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE).map_err(RtError::LockMemory)
}

/// Whether locking all future memory is safe: as root (the limit does not apply), or with no
/// limit.
fn may_lock_all(root: bool, memlock_soft_limit: u64) -> Result<(), RtError> {
    if root || memlock_soft_limit == nix::sys::resource::RLIM_INFINITY {
        Ok(())
    } else {
        Err(RtError::MemlockLimit(memlock_soft_limit / 1024))
    }
}

/// Pins the calling thread to `cpu`.
pub fn pin_to_cpu(cpu: usize) -> Result<(), RtError> {
    use nix::sched::{CpuSet, sched_setaffinity};
    use nix::unistd::Pid;
    let mut set = CpuSet::new();
    set.set(cpu)
        .map_err(|source| RtError::Pin { cpu, source })?;
    // Pid 0: the calling thread.
    sched_setaffinity(Pid::from_raw(0), &set).map_err(|source| RtError::Pin { cpu, source })
}

/// Lets the calling thread run on every CPU again (for a normal thread spawned by a pinned
/// real-time one).
pub fn unpin() -> Result<(), RtError> {
    use nix::sched::{CpuSet, sched_setaffinity};
    use nix::unistd::Pid;
    let n = std::thread::available_parallelism().map_or(1, usize::from);
    let mut set = CpuSet::new();
    for cpu in 0..n.min(CpuSet::count()) {
        set.set(cpu)
            .map_err(|source| RtError::Pin { cpu, source })?;
    }
    sched_setaffinity(Pid::from_raw(0), &set).map_err(|source| RtError::Pin { cpu: 0, source })
}

/// Back to normal time-sharing on every CPU: [`set_normal`] and [`unpin`], both tried (for a
/// thread that leaves real time: a logger a pinned loop spawned, a command done feeding the
/// robot). The first error, if any.
pub fn leave_realtime() -> Result<(), RtError> {
    let normal = set_normal();
    let unpinned = unpin();
    normal.and(unpinned)
}

/// Keeps every CPU out of deep idle states while it lives (the kernel's PM QoS request through
/// `/dev/cpu_dma_latency`, withdrawn when the file is closed).
#[derive(Debug)]
pub struct CpuLatencyGuard {
    _file: std::fs::File,
}

/// Asks the kernel to keep wake-up latency from idle at 0 µs until the guard is dropped.
pub fn hold_cpu_latency_zero() -> Result<CpuLatencyGuard, RtError> {
    use std::io::Write;
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/cpu_dma_latency")
        .map_err(RtError::CpuLatency)?;
    // The request is a binary 32-bit integer in microseconds.
    file.write_all(&0i32.to_ne_bytes())
        .map_err(RtError::CpuLatency)?;
    Ok(CpuLatencyGuard { _file: file })
}

/// What [`apply`] achieved.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RtReport {
    /// `SCHED_FIFO` priority in effect, if any.
    pub fifo: Option<u8>,
    /// Memory locked.
    pub memory_locked: bool,
    /// CPU pinned to, if any.
    pub cpu: Option<usize>,
    /// CPUs kept out of deep idle states.
    pub cpu_sleep_prevented: bool,
    /// `prevent_cpu_sleep = "auto"` left the CPUs to sleep: a virtual machine.
    pub cpu_sleep_allowed_on_vm: bool,
    /// What was asked for and refused, each with its reason.
    pub refused: Vec<String>,
    /// Real-time scheduling was switched off in the configuration.
    pub disabled: bool,
}

impl RtReport {
    /// Everything asked for took effect.
    pub fn complete(&self) -> bool {
        self.refused.is_empty() && !self.disabled
    }

    /// One line for a summary: what the thread ran with.
    pub fn describe(&self) -> String {
        if self.disabled {
            return "normal scheduling (realtime.enabled = false)".into();
        }
        let mut parts = Vec::new();
        match self.fifo {
            Some(p) => parts.push(format!("SCHED_FIFO {p}")),
            None => parts.push("normal scheduling (SCHED_FIFO refused)".into()),
        }
        parts.push(if self.memory_locked {
            "memory locked".into()
        } else {
            "memory not locked".into()
        });
        if let Some(c) = self.cpu {
            parts.push(format!("pinned to CPU {c}"));
        }
        if self.cpu_sleep_prevented {
            parts.push("CPU idle latency 0 µs".into());
        }
        if self.cpu_sleep_allowed_on_vm {
            parts.push("CPUs may sleep (a virtual machine)".into());
        }
        parts.join(", ")
    }

    /// The warning to print once when something was refused (`None` when all took effect).
    pub fn warning(&self) -> Option<String> {
        if self.refused.is_empty() {
            return None;
        }
        Some(format!(
            "running without full real-time scheduling: {}. Run as root, or grant it in \
             /etc/security/limits.conf (`@realtime - rtprio 99`, `@realtime - memlock unlimited`), \
             or set realtime.enabled = false to silence this",
            self.refused.join("; ")
        ))
    }
}

/// Applies `cfg` to the calling thread at `priority` (the loop's, or the simulators'): locks
/// memory (process-wide) when asked, pins when asked, holds the CPUs' idle latency at zero when
/// asked (the guard keeps it: drop it when the loop ends), and sets `SCHED_FIFO`. Never fails:
/// what the operating system refused is in the report.
pub fn apply(cfg: &RtConfig, priority: u8) -> (RtReport, Option<CpuLatencyGuard>) {
    let mut r = RtReport::default();
    if !cfg.enabled {
        r.disabled = true;
        return (r, None);
    }
    if cfg.lock_memory {
        match lock_memory() {
            Ok(()) => r.memory_locked = true,
            Err(e) => r.refused.push(e.to_string()),
        }
    }
    if let Some(cpu) = cfg.cpu {
        match pin_to_cpu(cpu) {
            Ok(()) => r.cpu = Some(cpu),
            Err(e) => r.refused.push(e.to_string()),
        }
    }
    let mut guard = None;
    let vm = cfg.prevent_cpu_sleep == CpuSleep::Auto && under_hypervisor();
    r.cpu_sleep_allowed_on_vm = vm;
    if cfg.prevent_cpu_sleep.hold(vm) {
        match hold_cpu_latency_zero() {
            Ok(g) => {
                guard = Some(g);
                r.cpu_sleep_prevented = true;
            }
            Err(e) => r.refused.push(e.to_string()),
        }
    }
    match set_fifo(priority) {
        Ok(()) => r.fifo = Some(priority),
        Err(e) => r.refused.push(e.to_string()),
    }
    (r, guard)
}

/// Sleeps until `deadline` on the monotonic clock (`clock_nanosleep` with an absolute time, so a
/// preemption between reading the clock and sleeping does not push the wake-up later). Returns
/// at once when the deadline has passed.
pub fn sleep_until(deadline: Instant) {
    use nix::sys::time::TimeSpec;
    use nix::time::{ClockId, ClockNanosleepFlags, clock_gettime, clock_nanosleep};
    let now = Instant::now();
    let Some(left) = deadline.checked_duration_since(now) else {
        return;
    };
    // `Instant` is CLOCK_MONOTONIC on Linux; map the deadline onto it once.
    let Ok(mono) = clock_gettime(ClockId::CLOCK_MONOTONIC) else {
        std::thread::sleep(left);
        return;
    };
    let target = mono + TimeSpec::from_duration(left);
    loop {
        match clock_nanosleep(
            ClockId::CLOCK_MONOTONIC,
            ClockNanosleepFlags::TIMER_ABSTIME,
            &target,
        ) {
            Err(nix::Error::EINTR) => continue,
            Ok(_) => return,
            Err(_) => {
                // Not expected on Linux; fall back to a relative sleep.
                if let Some(left) = deadline.checked_duration_since(Instant::now()) {
                    std::thread::sleep(left);
                }
                return;
            }
        }
    }
}

/// A periodic schedule on absolute deadlines: each [`Ticker::wait`] sleeps to the next deadline.
/// A late wake-up does not shift the schedule; a wake-up more than `max_late` periods behind
/// restarts it from now (the missed deadlines are counted, not made up in a burst).
#[derive(Debug, Clone)]
pub struct Ticker {
    next: Instant,
    period: Duration,
    max_late: u32,
    missed: u64,
}

impl Ticker {
    /// The first deadline is one `period` from now.
    pub fn new(period: Duration, max_late: u32) -> Self {
        Self {
            next: Instant::now() + period,
            period,
            max_late,
            missed: 0,
        }
    }

    /// Sleeps to the next deadline. Returns how many deadlines have passed since the previous
    /// call (1 on time, more when late): the caller runs that many steps, up to `max_late`.
    pub fn wait(&mut self) -> u32 {
        sleep_until(self.next);
        self.advance(Instant::now())
    }

    /// The deadlines due at `now` (at least 1; see [`Ticker::wait`]), the schedule moved on: the
    /// clock-free half of `wait`.
    pub fn advance(&mut self, now: Instant) -> u32 {
        let behind = now.saturating_duration_since(self.next);
        let mut due = 1 + (behind.as_nanos() / self.period.as_nanos().max(1)) as u64;
        if due > u64::from(self.max_late) {
            self.missed += due - u64::from(self.max_late);
            due = u64::from(self.max_late);
            self.next = now;
        } else {
            self.next += self.period * (due as u32 - 1);
        }
        self.next += self.period;
        due as u32
    }

    /// Deadlines given up (beyond `max_late` behind) so far.
    pub fn missed(&self) -> u64 {
        self.missed
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    #[test]
    fn defaults_follow_ros2_control_and_parse_key_by_key() {
        let c = RtConfig::default();
        assert_eq!(c.priority, 50);
        assert!(c.simulator_priority < c.priority);
        let c: RtConfig = toml::from_str("priority = 70\ncpu = 0").unwrap();
        assert_eq!((c.priority, c.cpu, c.lock_memory), (70, Some(0), true));
        let e = toml::from_str::<RtConfig>("priorty = 70").unwrap_err();
        assert!(e.to_string().contains("priorty"), "{e}");
    }

    #[test]
    fn cpu_sleep_is_a_switch_or_auto_and_auto_lets_a_virtual_machine_sleep() {
        let parse = |v: &str| {
            toml::from_str::<RtConfig>(&format!("prevent_cpu_sleep = {v}"))
                .map(|c| c.prevent_cpu_sleep)
        };
        assert_eq!(parse("true").unwrap(), CpuSleep::Prevent);
        assert_eq!(parse("false").unwrap(), CpuSleep::Allow);
        assert_eq!(parse("\"auto\"").unwrap(), CpuSleep::Auto);
        assert_eq!(RtConfig::default().prevent_cpu_sleep, CpuSleep::Auto);
        let e = parse("\"always\"").unwrap_err().to_string();
        assert!(e.contains("\"always\"") && e.contains("auto"), "{e}");
        // Written back as read.
        for v in [CpuSleep::Auto, CpuSleep::Prevent, CpuSleep::Allow] {
            let c = RtConfig {
                prevent_cpu_sleep: v,
                ..RtConfig::default()
            };
            let back: RtConfig = toml::from_str(&toml::to_string(&c).unwrap()).unwrap();
            assert_eq!(back.prevent_cpu_sleep, v);
        }
        assert!(CpuSleep::Auto.hold(false) && !CpuSleep::Auto.hold(true));
        assert!(CpuSleep::Prevent.hold(true) && !CpuSleep::Allow.hold(false));
    }

    #[test]
    fn the_hypervisor_flag_is_read_from_the_flags_line_only() {
        let vm =
            "processor\t: 0\nflags\t\t: fpu vme sse2 hypervisor lahf_lm\nbugs\t\t: spectre_v1\n";
        let metal =
            "processor\t: 0\nflags\t\t: fpu vme sse2 lahf_lm\nmodel name\t: not a hypervisor\n";
        assert!(cpuinfo_flags_hypervisor(vm));
        assert!(!cpuinfo_flags_hypervisor(metal));
        assert!(!cpuinfo_flags_hypervisor(""));
        // A flag that only contains the word is not it.
        assert!(!cpuinfo_flags_hypervisor("flags : hypervisor_x\n"));
    }

    #[test]
    fn out_of_range_settings_are_named() {
        let mut c = RtConfig {
            priority: 0,
            ..RtConfig::default()
        };
        assert!(
            c.validate()
                .unwrap_err()
                .to_string()
                .contains("realtime.priority")
        );
        c.priority = 100;
        assert!(c.validate().is_err());
        c.priority = 50;
        c.cpu = Some(4096);
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("realtime.cpu") && e.contains("4096"), "{e}");
        c.cpu = Some(0);
        c.validate().unwrap();
        c.simulator_cpu = Some(4096);
        assert!(
            c.validate()
                .unwrap_err()
                .to_string()
                .contains("realtime.simulator_cpu")
        );
    }

    #[test]
    fn memory_is_locked_only_where_future_allocations_cannot_fail_for_it() {
        use nix::sys::resource::RLIM_INFINITY;
        assert!(may_lock_all(true, 8 << 20).is_ok());
        assert!(may_lock_all(false, RLIM_INFINITY).is_ok());
        let e = may_lock_all(false, 8 << 20).unwrap_err().to_string();
        assert!(
            e.contains("8192 KiB") && e.contains("memlock unlimited"),
            "{e}"
        );
    }

    #[test]
    fn a_disabled_config_changes_nothing_and_says_so() {
        let cfg = RtConfig {
            enabled: false,
            ..RtConfig::default()
        };
        let before = current_policy().unwrap();
        let (r, guard) = apply(&cfg, 50);
        assert!(guard.is_none());
        assert!(r.disabled && !r.complete() && r.warning().is_none());
        assert!(r.describe().contains("enabled = false"));
        assert_eq!(current_policy().unwrap(), before);
    }

    /// On a thread of its own: what the OS grants takes effect and shows in the report, and
    /// threads spawned afterwards inherit it; what it refuses is named. Either way the thread
    /// goes back to normal scheduling.
    #[test]
    fn fifo_is_applied_or_its_refusal_reported_and_children_inherit_it() {
        std::thread::spawn(|| {
            let cfg = RtConfig {
                lock_memory: false,
                prevent_cpu_sleep: CpuSleep::Allow,
                ..RtConfig::default()
            };
            let (r, _) = apply(&cfg, 42);
            match r.fifo {
                Some(p) => {
                    assert_eq!(p, 42);
                    assert_eq!(current_policy().unwrap(), Policy::Fifo(42));
                    assert!(r.describe().contains("SCHED_FIFO 42"), "{}", r.describe());
                    let child = std::thread::spawn(|| current_policy().unwrap())
                        .join()
                        .unwrap();
                    assert_eq!(child, Policy::Fifo(42));
                    set_normal().unwrap();
                    assert_eq!(current_policy().unwrap(), Policy::Normal);
                }
                None => {
                    let w = r.warning().unwrap();
                    assert!(w.contains("SCHED_FIFO priority 42 refused"), "{w}");
                    assert!(r.describe().contains("refused"));
                    assert_eq!(current_policy().unwrap(), Policy::Normal);
                }
            }
        })
        .join()
        .unwrap();
    }

    /// A thread leaving real time is back under normal scheduling on every CPU, whether its
    /// FIFO priority was granted or not.
    #[test]
    fn leaving_real_time_unpins_and_returns_to_normal_scheduling() {
        use nix::sched::sched_getaffinity;
        use nix::unistd::Pid;
        std::thread::spawn(|| {
            pin_to_cpu(0).unwrap();
            set_fifo(42).ok();
            let cpus = |set: nix::sched::CpuSet| {
                (0..nix::sched::CpuSet::count())
                    .filter(|&c| set.is_set(c).unwrap_or(false))
                    .count()
            };
            assert_eq!(cpus(sched_getaffinity(Pid::from_raw(0)).unwrap()), 1);
            leave_realtime().unwrap();
            assert_eq!(current_policy().unwrap(), Policy::Normal);
            let n = std::thread::available_parallelism().map_or(1, usize::from);
            assert_eq!(cpus(sched_getaffinity(Pid::from_raw(0)).unwrap()), n);
        })
        .join()
        .unwrap();
    }

    /// The PM QoS request is held while the guard lives (the kernel shows the file open by this
    /// process) and withdrawn when it is dropped; without root it is refused by name.
    #[test]
    fn the_cpu_latency_request_lives_as_long_as_its_guard() {
        let held = || {
            std::fs::read_dir("/proc/self/fd").unwrap().any(|e| {
                std::fs::read_link(e.unwrap().path())
                    .is_ok_and(|l| l.to_string_lossy() == "/dev/cpu_dma_latency")
            })
        };
        match hold_cpu_latency_zero() {
            Ok(g) => {
                assert!(held());
                drop(g);
                assert!(!held());
            }
            Err(e) => assert!(e.to_string().contains("cpu_dma_latency"), "{e}"),
        }
    }

    #[test]
    fn sleep_until_never_wakes_early_and_returns_at_once_for_the_past() {
        for ms in [0u64, 1, 3] {
            let deadline = Instant::now() + Duration::from_millis(ms);
            sleep_until(deadline);
            assert!(Instant::now() >= deadline);
        }
        // A deadline in the past: no sleep at all (no lower bound on time is asserted, only
        // that it returns).
        sleep_until(Instant::now() - Duration::from_millis(5));
    }

    #[test]
    fn the_ticker_counts_late_deadlines_instead_of_bursting() {
        // Stepped time: the schedule is judged at instants the test chooses, not the machine's.
        let ms = Duration::from_millis(1);
        let mut t = Ticker::new(ms, 5);
        let start = t.next - ms;
        // On time, and half a period late: one step each.
        assert_eq!(t.advance(start + ms), 1);
        assert_eq!(t.advance(start + ms * 2 + ms / 2), 1);
        // Two periods late: three steps due, none missed.
        assert_eq!(t.advance(start + ms * 5 + ms / 2), 3);
        assert_eq!(t.missed(), 0);
        // 30 periods late: at most max_late steps are due, the rest counted as missed.
        let late = start + ms * 36;
        assert_eq!(t.advance(late), 5);
        assert_eq!(t.missed(), 26);
        // Back on schedule from the restart: the next deadline is one period after it.
        assert_eq!(t.next, late + ms);
        assert_eq!(t.advance(late + ms), 1);
        assert_eq!(t.missed(), 26);
    }

    #[test]
    fn the_ticker_sleeps_to_its_deadline() {
        let mut t = Ticker::new(Duration::from_millis(2), 5);
        let deadline = t.next;
        assert!(t.wait() >= 1);
        assert!(Instant::now() >= deadline, "woke before the deadline");
    }
}
