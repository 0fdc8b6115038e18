//! What the machine tells of its memory: the one place the library asks the operating system
//! (Linux's `/proc`; `None` elsewhere). Readers check a scene against it before they read it,
//! the GPU path checks a CPU adapter's arrays (whose device memory is the host's) before it
//! builds them, and front ends report it.

/// A figure of a Linux `/proc` file (`key: N kB`), in bytes; `None` elsewhere.
fn proc_kib(file: &str, key: &str) -> Option<u64> {
    let text = std::fs::read_to_string(file).ok()?;
    let line = text.lines().find(|l| l.strip_prefix(key).is_some_and(|rest| rest.starts_with(':')))?;
    Some(line.split_whitespace().nth(1)?.parse::<u64>().ok()? * 1024)
}

/// The memory the system can still give (Linux's `MemAvailable`), in bytes; `None` elsewhere.
pub fn available() -> Option<u64> {
    proc_kib("/proc/meminfo", "MemAvailable")
}

/// This process's peak resident set (Linux's `VmHWM`), in bytes; `None` elsewhere.
pub fn peak_resident() -> Option<u64> {
    proc_kib("/proc/self/status", "VmHWM")
}
