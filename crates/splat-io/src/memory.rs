//! The memory a scene takes and the memory the machine has: what a reader checks before it
//! reads a large scene, and what front ends report.

use crate::ErrorKind;

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

/// Refuse, before reading them, `count` particles at SH degree `sh_degree` whose scene
/// ([`splat_core::Scene::bytes_for`]) would not fit in `available` bytes (`None`: not known,
/// nothing refused).
pub fn check_scene(count: u64, sh_degree: u8, available: Option<u64>) -> Result<(), ErrorKind> {
    let needed = splat_core::Scene::bytes_for(count, sh_degree);
    match available {
        Some(available) if needed > available => Err(ErrorKind::TooLarge { count, needed, available }),
        _ => Ok(()),
    }
}
