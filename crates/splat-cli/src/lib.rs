//! The commands of `splat` as a library: each module is one command's arguments (clap) and
//! its `run`, over `splat-core`, `splat-io` and `splat-gpu`. The binary (`main.rs`) parses the
//! command line and dispatches; the Python package (`splat-py`) stages scenes and renders
//! through the same arguments, so that an option is declared once for both.

pub mod args;
pub mod bench;
pub mod compare;
pub mod converge;
pub mod convert;
pub mod hint;
pub mod hits;
pub mod info;
pub mod merge;
pub mod render;
pub mod reproduce;
pub mod stratify;
pub mod undistort;
pub mod ztest;

/// `n` and `noun`, plural unless `n` is 1: "1 view", "3 views".
pub fn counted(n: usize, noun: &str) -> String {
    if n == 1 { format!("1 {noun}") } else { format!("{n} {noun}s") }
}

/// Whether `a` and `b` name one file or folder, however they are spelled (relative or
/// absolute, `./` and symbolic links resolved), whether or not it exists yet. The commands check
/// their outputs with it, so that none writes over what it reads or another of its outputs.
pub fn same_path(a: &std::path::Path, b: &std::path::Path) -> bool {
    matches!((resolved(a), resolved(b)), (Some(a), Some(b)) if a == b)
}

/// `path` absolute, through its deepest existing folder canonicalised, the names below it
/// (not created yet) appended as they are; `None` where it cannot be resolved.
fn resolved(path: &std::path::Path) -> Option<std::path::PathBuf> {
    let absolute = std::path::absolute(path).ok()?;
    let mut existing = absolute.as_path();
    let mut below = Vec::new();
    let mut canonical = loop {
        match std::fs::canonicalize(existing) {
            Ok(c) => break c,
            Err(_) => {
                below.push(existing.file_name()?);
                existing = existing.parent()?;
            }
        }
    };
    canonical.extend(below.iter().rev());
    Some(canonical)
}

#[cfg(test)]
mod tests {
    use clap::{Args, Command};
    use splat_core::catalogue::Param;

    /// The flag the catalogue gives each parameter (in the viewer's hover text and the warning
    /// about options a method does not read) is an option of every command that takes methods.
    #[test]
    fn every_parameter_flag_of_the_catalogue_is_an_option() {
        let commands = [
            ("render", crate::render::RenderArgs::augment_args(Command::new("render"))),
            ("converge", crate::converge::ConvergeArgs::augment_args(Command::new("converge"))),
            ("bench", crate::bench::BenchArgs::augment_args(Command::new("bench"))),
        ];
        for (name, command) in commands {
            for param in Param::ALL {
                let flag = param.info().flag;
                assert!(command.get_arguments().any(|a| a.get_long() == Some(flag)), "splat {name} has no --{flag}");
            }
        }
    }
}
