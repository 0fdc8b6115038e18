//! The memory a scene takes and the memory the machine has: what a reader checks before it
//! reads a large scene, and what front ends report.

use crate::ErrorKind;

pub use splat_core::host::{available, peak_resident};

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
