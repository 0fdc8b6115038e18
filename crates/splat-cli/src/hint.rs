//! The command line's words for what the libraries say in theirs: a refused GPU render's
//! remedies ([`splat_gpu::Remedy`]), a lens the oracle cannot see through and the strict PLY
//! reader's refusal, as the flags that apply them.

use splat_core::camera::CameraError;
use splat_gpu::{GpuError, Remedy};
use splat_io::ErrorKind;

/// The flag that applies `remedy`.
fn flag(remedy: Remedy) -> &'static str {
    match remedy {
        Remedy::Cpu => "--backend cpu",
        Remedy::CenterDepth => "--fragment-depth center",
        Remedy::StandardPattern => "--sample-pattern standard",
        Remedy::NoEarlyStop => "no --early-stop",
        Remedy::ExactMethod => "--method exact",
        Remedy::RasterOperations => "--method enderton",
    }
}

/// ` (FLAG or FLAG)` after an error whose cause a flag can lift, empty otherwise.
pub fn flags(error: &anyhow::Error) -> String {
    let said = error.chain().find_map(|cause| {
        if let Some(gpu) = cause.downcast_ref::<GpuError>() {
            let flags: Vec<&str> = gpu.remedies().iter().map(|&r| flag(r)).collect();
            return (!flags.is_empty()).then(|| flags.join(" or "));
        }
        if let Some(splat_core::RenderError::Camera(CameraError::NotPinhole { .. })) = cause.downcast_ref() {
            return Some("--method exact".to_string());
        }
        let io = cause.downcast_ref::<splat_io::Error>()?;
        matches!(io.kind, ErrorKind::UnknownProperty { .. }).then(|| "drop --strict".to_string())
    });
    said.map_or_else(String::new, |s| format!(" ({s})"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_refusal_gets_the_flags_of_its_remedies() {
        let refused = GpuError::refused("no", &[Remedy::CenterDepth, Remedy::Cpu]);
        assert_eq!(
            flags(&anyhow::Error::new(refused).context("rendering")),
            " (--fragment-depth center or --backend cpu)"
        );
        let other = GpuError::Unsupported("no".into());
        assert_eq!(flags(&anyhow::Error::new(other)), "");
        let strict = splat_io::Error::new("a.ply", ErrorKind::UnknownProperty { line: 3, name: "filter_3D".into() });
        assert_eq!(flags(&anyhow::Error::new(strict)), " (drop --strict)");
    }

    /// Every `--flag` in the code of the libraries, outside comments (`--features`, cargo's,
    /// allowed): their messages say what to change in their own terms and leave the flag to
    /// the CLI ([`flags`]).
    #[test]
    fn no_library_message_names_a_flag() {
        let crates = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("crates/");
        let mut found = Vec::new();
        for library in ["splat-core", "splat-gpu", "splat-io"] {
            let mut folders = vec![crates.join(library).join("src")];
            while let Some(folder) = folders.pop() {
                for entry in std::fs::read_dir(&folder).expect("a source folder").flatten() {
                    let path = entry.path();
                    if path.is_dir() {
                        folders.push(path);
                    } else if path.extension().is_some_and(|e| e == "rs") {
                        let text = std::fs::read_to_string(&path).expect("a source file");
                        for (n, line) in text.lines().enumerate() {
                            let code = line.trim_start();
                            let flag = code.match_indices("--").any(|(i, _)| {
                                code[i + 2..].starts_with(|c: char| c.is_ascii_lowercase())
                                    && !code[i + 2..].starts_with("features")
                            });
                            if flag && !code.starts_with("//") {
                                found.push(format!("{}:{}: {code}", path.display(), n + 1));
                            }
                        }
                    }
                }
            }
        }
        assert!(found.is_empty(), "library code names CLI flags:\n{}", found.join("\n"));
    }
}
