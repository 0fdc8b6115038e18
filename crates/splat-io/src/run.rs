//! What a trainer's run folder says of the splats it saved, beyond their file: the settings of
//! the run that change how they render and where its cameras line up with them. Read beside a
//! checkpoint, and beside a 3DGS `.ply` in its model folder:
//!
//! | trainer | the splats | the run's config | what is read |
//! |---|---|---|---|
//! | 3DGS | `MODEL/point_cloud/iteration_N/point_cloud.ply`, `MODEL/chkpntN.pth` | `MODEL/cfg_args`, `str()` of its model parameters' `Namespace` | `white_background` |
//! | gsplat | `RESULT/ckpts/ckpt_STEP_rankR.pt` | `RESULT/cfg.yml`, `yaml.dump` of its dataclass | `antialiased`, `near_plane`, `normalize_world_space`, `data_dir`, `data_factor` |
//! | splatfacto | `RUN/nerfstudio_models/step-STEP.ckpt` | `RUN/config.yml`, `yaml.dump` of its `TrainerConfig`; `RUN/dataparser_transforms.json` | `rasterize_mode`, `background_color` |
//!
//! 3DGRUT keeps its config in its checkpoint ([`crate::torch`]). A run's screen filter goes to
//! [`Scene::screen_filter`], its renderer, near plane and background to [`Scene::trained`];
//! what it says of its world becomes a note. The configs are read by their lines, not by a
//! YAML parser.

use crate::torch::Trainer;
use glam::Vec3;
use splat_core::trainer::{Preset, Trained};
use splat_core::{Scene, ScreenFilter};
use std::path::{Path, PathBuf};

/// The background splatfacto's evaluation composites over where its `background_color` is
/// `random` (its default): Viser's background colour (`Splatfacto.__init__`); `white` and
/// `black` are those colours.
pub const SPLATFACTO_RANDOM_BACKGROUND: Vec3 = Vec3::new(0.1490, 0.1647, 0.2157);

/// Read what the run folder of `file` (saved by `trainer`) says of its splats into `scene` and
/// `notes`: nothing where `file` lies in no such folder.
pub(crate) fn read_beside(file: &Path, trainer: Trainer, scene: &mut Scene, notes: &mut Vec<String>) {
    match trainer {
        Trainer::Inria => inria(file, scene, notes),
        Trainer::Gsplat => gsplat(file, scene, notes),
        Trainer::Splatfacto => splatfacto(file, scene, notes),
        Trainer::Grut => {}
    }
}

/// 3DGS's model folder: the `.ply` of an iteration (`MODEL/point_cloud/iteration_N/`) or a
/// checkpoint (`MODEL/`), whose `cfg_args` says whether the run trained and evaluates over a
/// white background (`train.py -w`: `bg_color = [1, 1, 1] if dataset.white_background`).
fn inria(file: &Path, scene: &mut Scene, notes: &mut Vec<String>) {
    let folder = crate::folder_of(file);
    let iteration = folder.file_name().is_some_and(|n| n.to_string_lossy().starts_with("iteration_"));
    let model = match folder.parent() {
        Some(point_cloud) if iteration && point_cloud.file_name().is_some_and(|n| n == "point_cloud") => {
            point_cloud.parent().unwrap_or(Path::new("."))
        }
        _ => folder,
    };
    let cfg_args = model.join("cfg_args");
    let Ok(text) = std::fs::read_to_string(&cfg_args) else { return };
    if text.contains("white_background=True") {
        scene.trained.get_or_insert(Trained::of(Preset::ThreeDgs)).background = Some(Vec3::ONE);
        notes.push(format!(
            "3DGS trained these splats over a white background ({} says white_background=True), as its renders \
             composite them: they render so",
            cfg_args.display()
        ));
    }
}

/// gsplat's `RESULT/cfg.yml` beside `RESULT/ckpts/`: its normalised world noted, its
/// antialiased mode and near plane applied.
fn gsplat(checkpoint: &Path, scene: &mut Scene, notes: &mut Vec<String>) {
    let Some(config) = RunConfig::beside(checkpoint, "cfg.yml") else { return };
    notes.extend(config.world_note());
    if config.setting("antialiased") == Some("true") {
        antialiased(scene, notes, "gsplat", &config, "antialiased: true");
    }
    let Some(near) = config.setting("near_plane") else { return };
    let trained = scene.trained.get_or_insert(Trained::of(Preset::Gsplat));
    match near.parse::<f32>() {
        Ok(plane) if plane == trained.near => {}
        Ok(plane) if plane.is_finite() && plane > 0.0 => {
            trained.near = plane;
            notes.push(format!(
                "gsplat culled these splats at the near plane {plane} ({} says near_plane: {near}): the splatting \
                 methods do too",
                config.path.display()
            ));
        }
        _ => notes.push(format!(
            "{} says near_plane: {near}, not a positive distance: the splatting methods cull at gsplat's default {}",
            config.path.display(),
            trained.near
        )),
    }
}

/// splatfacto's `RUN/config.yml` and `RUN/dataparser_transforms.json` beside
/// `RUN/nerfstudio_models/`: the transforms noted, the rasterize mode and background applied.
fn splatfacto(checkpoint: &Path, scene: &mut Scene, notes: &mut Vec<String>) {
    let Some(run) = checkpoint.parent().and_then(Path::parent) else { return };
    let transforms = run.join("dataparser_transforms.json");
    if transforms.is_file() {
        notes.push(format!(
            "splatfacto trained these splats in its normalised world: {} moves the cameras of its transforms.json \
             there (splat's dataparser-transforms option)",
            transforms.display()
        ));
    }
    let Some(config) = RunConfig::beside(checkpoint, "config.yml") else { return };
    if config.nested("rasterize_mode") == Some("antialiased") {
        antialiased(scene, notes, "splatfacto", &config, "rasterize_mode: antialiased");
    }
    let color = config.nested("background_color");
    let background = match color {
        Some("random") => SPLATFACTO_RANDOM_BACKGROUND,
        Some("white") => Vec3::ONE,
        _ => return,
    };
    scene.trained.get_or_insert(Trained::of(Preset::Gsplat)).background = Some(background);
    let [r, g, b] = background.to_array();
    notes.push(format!(
        "splatfacto evaluates these splats over the background {r},{g},{b} ({} says background_color: {}): they \
         render so",
        config.path.display(),
        color.unwrap_or_default()
    ));
}

/// gsplat's antialiased mode, which `trainer`'s run `config` names (`says`): its screen filter,
/// and its preset in place of the classic mode's.
fn antialiased(scene: &mut Scene, notes: &mut Vec<String>, trainer: &str, config: &RunConfig, says: &str) {
    scene.screen_filter = ScreenFilter::Antialiased;
    scene.trained = Some(Trained::instead(scene.trained, Preset::GsplatAntialiased));
    notes.push(format!(
        "{trainer} rasterized these splats in gsplat's antialiased mode ({} says {says}): the splatting methods \
         apply its screen filter",
        config.path.display()
    ));
}

/// A trainer's run config, the `yaml.dump` of its config object: gsplat's `cfg.yml` (a
/// dataclass), Nerfstudio's `config.yml` (its `TrainerConfig`, the model's config nested in the
/// pipeline's).
struct RunConfig {
    path: PathBuf,
    text: String,
}

impl RunConfig {
    /// The config `name` of the run whose checkpoint is `checkpoint` (`RUN/name` for
    /// `RUN/FOLDER/checkpoint`), where there is one.
    fn beside(checkpoint: &Path, name: &str) -> Option<Self> {
        let path = checkpoint.parent()?.parent()?.join(name);
        let text = std::fs::read_to_string(&path).ok()?;
        Some(Self { path, text })
    }

    /// A top-level scalar: its `key: value` line at the left margin (nested values are
    /// indented, lists and objects have no value on their key's line).
    fn setting(&self, key: &str) -> Option<&str> {
        self.scalar(key, |line| line)
    }

    /// A scalar at any depth: the first `key: value` line, however indented (for a key that
    /// one object of the config alone has).
    fn nested(&self, key: &str) -> Option<&str> {
        self.scalar(key, str::trim_start)
    }

    /// The value of the first line that is `key: value` once `line` cuts it.
    fn scalar<'t>(&'t self, key: &str, line: impl Fn(&'t str) -> &'t str) -> Option<&'t str> {
        self.text
            .lines()
            .find_map(|l| line(l).strip_prefix(key)?.strip_prefix(": ").map(str::trim))
            .filter(|v| !v.is_empty())
    }

    /// Where it says the run trained in its normalised world (gsplat's), a note saying so, with
    /// the run's data folder and factor.
    fn world_note(&self) -> Option<String> {
        if self.setting("normalize_world_space")? != "true" {
            return None;
        }
        let data = self.setting("data_dir").map_or(String::new(), |dir| format!(" from {dir}"));
        let factor = self
            .setting("data_factor")
            .filter(|&f| f != "1")
            .map_or(String::new(), |f| format!(", its images downscaled by {f} (splat's data-factor option)"));
        Some(format!(
            "gsplat trained these splats in its normalised world ({} says normalize_world_space: true){data}: the \
             cameras of its COLMAP model line up with them through splat's gsplat-world option{factor}",
            self.path.display()
        ))
    }
}
