//! Trainers' checkpoints, read without PyTorch:
//!
//! - 3DGS's `train.py` saves `chkpnt{iteration}.pth` at `--checkpoint_iterations`, `torch.save`
//!   of `(gaussians.capture(), iteration)`;
//! - gsplat's `simple_trainer` saves `ckpt_STEP_rankR.pt`, `torch.save` of `{"step": step,
//!   "splats": splats.state_dict()}`, one a rank where its training is distributed;
//! - Nerfstudio's trainer saves `nerfstudio_models/step-STEP.ckpt`, `torch.save` of `{"step",
//!   "pipeline": pipeline.state_dict(), "optimizers", "schedulers", "scalers"}`; a splatfacto
//!   model keeps its splats in the pipeline's `_model.gauss_params.*` (`_model.*` in checkpoints
//!   before the parameter dict; `module.` before either where the run was distributed);
//! - 3DGRUT's trainer saves `ckpt_last.pt`, `torch.save` of its model's parameters at the top
//!   level beside the run's OmegaConf config.
//!
//! `torch.save` writes a zip archive (PyTorch ≥ 1.6; always Zip64, read by the crate's `zip`) of
//! `ARCHIVE/data.pkl`, a pickle of the object (read by the crate's `pickle`), and one entry
//! `ARCHIVE/data/KEY` a storage, its raw little-endian elements (`ARCHIVE/byteorder` says
//! `little` where present). A tensor is pickled as a call of
//! `torch._utils._rebuild_tensor_v2(storage, offset, size, stride, requires_grad, hooks)`, its
//! storage as the persistent id `("storage", torch.FloatStorage, KEY, location, numel)`. Only
//! the pickle and the six storages of the splats are read from the file, a block of splats at
//! a time: a Nerfstudio checkpoint is about three times its splats (Adam's two moments of every
//! parameter).
//!
//! The splats are the parameters before their activations, as the trainers' `.ply` exports
//! write them and 3DGS's reader reads them: positions (N, 3), log scales (N, 3), quaternions
//! (N, 4, w x y z, not normalised), opacity logits (N or N × 1), the DC coefficient (N × 1 × 3
//! or N × 3) and the rest of the SH (N × K × 3, or 3DGRUT's N × 3K, K = 0, 3, 8 or 15). A
//! splatfacto model of SH degree 0 trains its colour as a logit (its `features_dc` through a
//! sigmoid) and exports RGB2SH of it: so it is read. How the trainer rendered its splats is kept
//! with them ([`Scene::trained`]): gsplat's rasterizer for gsplat's and splatfacto's (in its
//! antialiased mode, with that [`Scene::screen_filter`], where the run's config beside its
//! checkpoints says so), 3DGRUT's renderer and kernel as its config names them.
//! What splat cannot render as the trainer does (gsplat's `--app_opt` appearance network,
//! 3DGRUT's neural features, other activations or kernels) is refused by name, as is anything
//! else that is not such a checkpoint.

use crate::pickle::{self, Value};
use crate::ply::{opacity_from_logit, scale_from_log, unit_quaternion};
use crate::zip::{EntryReader, FileSource, Source};
use crate::{Error, ErrorKind, file_name};
use glam::Vec3;
use rayon::prelude::*;
use splat_core::particle::{SH_MAX_COEFFS, sh_coeff_count};
use splat_core::sh::rgb_to_dc;
use splat_core::trainer::{GRUT_MIN_RESPONSE, Preset, Trained, min_response_cutoff};
use splat_core::{Particle, ParticleError, Scene};
use std::borrow::Cow;
use std::collections::HashMap;
use std::path::Path;

/// The trainer a checkpoint is of.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trainer {
    /// gsplat's `simple_trainer`.
    Gsplat,
    /// Nerfstudio's splatfacto.
    Splatfacto,
    /// NVIDIA's 3DGRUT (3DGRT and 3DGUT).
    Grut,
    /// 3DGS, the INRIA trainer (`train.py --checkpoint_iterations`).
    Inria,
}

impl Trainer {
    /// Its checkpoint's format, as `splat info` names it.
    pub const fn checkpoint_name(self) -> &'static str {
        match self {
            Self::Gsplat => "gsplat checkpoint",
            Self::Splatfacto => "Nerfstudio splatfacto checkpoint",
            Self::Grut => "3DGRUT checkpoint",
            Self::Inria => "3DGS checkpoint",
        }
    }
}

/// What a checkpoint says besides its splats.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckpointInfo {
    /// Whose checkpoint it is.
    pub trainer: Trainer,
    /// The training step it was saved at, where it says.
    pub step: Option<i64>,
    /// What the reader found that the user should hear of (how the trainer renders them).
    pub notes: Vec<String>,
}

impl CheckpointInfo {
    /// What `splat info` adds to the format's name: the step, where the checkpoint says.
    pub fn describe(&self) -> String {
        self.step.map_or_else(String::new, |step| format!("step {step}"))
    }
}

/// Read the checkpoint at `path` (gsplat's, Nerfstudio's splatfacto's, 3DGRUT's or 3DGS's,
/// whatever its extension): its pickle and the storages of its splats, nothing more. gsplat's
/// distributed training splits the splats between its ranks, each saving `ckpt_STEP_rankR.pt`:
/// one rank's file is read with every other rank's of its step beside it, in rank order, as
/// `simple_trainer`'s evaluation concatenates them.
pub fn read_checkpoint(path: &Path) -> Result<(Scene, CheckpointInfo), Error> {
    let read = |path: &Path| {
        let source = FileSource::open(path).map_err(|e| Error::new(path, ErrorKind::Io(e)))?;
        checkpoint(&source).map_err(|e| Error::new(path, e))
    };
    let (mut scene, mut info) = read(path)?;
    crate::run::read_beside(path, info.trainer, &mut scene, &mut info.notes);
    if info.trainer != Trainer::Gsplat {
        return Ok((scene, info));
    }
    let ranks = gsplat_ranks(path)?;
    if ranks.len() == 1 {
        return Ok((scene, info));
    }
    let mut parts = Vec::with_capacity(ranks.len());
    for rank in &ranks {
        if rank == path {
            parts.push(std::mem::take(&mut scene.particles));
            continue;
        }
        let (part, part_info) = read(rank)?;
        if part_info.trainer != Trainer::Gsplat || part.sh_degree != scene.sh_degree {
            let why = format!(
                "not another rank of {}: a {:?} checkpoint of SH degree {} beside one of gsplat's of degree {}",
                file_name(path),
                part_info.trainer,
                part.sh_degree,
                scene.sh_degree
            );
            return Err(Error::new(rank, ErrorKind::Checkpoint(why)));
        }
        parts.push(part.particles);
    }
    scene.particles = Vec::with_capacity(parts.iter().map(Vec::len).sum());
    for part in parts {
        scene.particles.extend(part);
    }
    let names: Vec<String> = ranks.iter().map(|p| file_name(p)).collect();
    info.notes.push(format!(
        "gsplat's distributed training split these splats between {} ranks: read {} together, in rank order, as its \
         simple_trainer's evaluation concatenates them",
        ranks.len(),
        names.join(", ")
    ));
    Ok((scene, info))
}

/// The step and rank of a gsplat checkpoint's file name, `ckpt_STEP_rankR.pt`.
fn gsplat_rank(name: &str) -> Option<(&str, u32)> {
    let (step, rank) = name.strip_prefix("ckpt_")?.strip_suffix(".pt")?.rsplit_once("_rank")?;
    Some((step, rank.parse().ok()?))
}

/// The checkpoints of every rank of a gsplat run beside `path` when its name is one rank's
/// (`ckpt_STEP_rankR.pt`), in rank order; else `path` alone. A rank missing between them is
/// refused by name: the run's splats would be read in part.
fn gsplat_ranks(path: &Path) -> Result<Vec<std::path::PathBuf>, Error> {
    let name = file_name(path);
    let Some((step, _)) = gsplat_rank(&name) else { return Ok(vec![path.to_path_buf()]) };
    let of = |rank: u32| path.with_file_name(format!("ckpt_{step}_rank{rank}.pt"));
    let folder = crate::folder_of(path);
    let mut highest = 0;
    if let Ok(entries) = std::fs::read_dir(folder) {
        for entry in entries.flatten() {
            let other = entry.file_name().to_string_lossy().into_owned();
            if let Some((s, rank)) = gsplat_rank(&other)
                && s == step
            {
                highest = highest.max(rank);
            }
        }
    }
    let ranks: Vec<_> = (0..=highest).map(of).collect();
    if let Some(missing) = ranks.iter().find(|p| !p.is_file()) {
        let why = format!(
            "{} is one rank's share of a distributed gsplat run with {} ranks, and {} is missing: the run's splats are \
             split between its ranks' checkpoints",
            name,
            highest + 1,
            file_name(missing)
        );
        return Err(Error::new(path, ErrorKind::Checkpoint(why)));
    }
    Ok(ranks)
}

/// Parse a checkpoint's bytes.
pub fn parse_checkpoint(bytes: &[u8]) -> Result<(Scene, CheckpointInfo), ErrorKind> {
    checkpoint(bytes)
}

fn fail(message: String) -> ErrorKind {
    ErrorKind::Checkpoint(message)
}

fn checkpoint<S: Source + ?Sized>(source: &S) -> Result<(Scene, CheckpointInfo), ErrorKind> {
    let archive = Archive::open(source).map_err(fail)?;
    let root = pickle::load(&archive.data_pkl).map_err(fail)?;
    let inria = inria_parameters(&root);
    let step = match root.get("step").or(root.get("global_step")) {
        Some(Value::Int(step)) => Some(*step),
        _ => inria.as_ref().map(|(_, iteration)| *iteration),
    };
    let mut notes = Vec::new();
    let mut trained = None;
    let (trainer, parameters) = if let Some((parameters, _)) = inria {
        (Trainer::Inria, parameters)
    } else if let Some(splats) = root.get("splats") {
        trained = Some(Trained::of(Preset::Gsplat));
        (Trainer::Gsplat, gsplat_parameters(splats)?)
    } else if let Some(pipeline) = root.get("pipeline") {
        trained = Some(Trained::of(Preset::Gsplat));
        (Trainer::Splatfacto, splatfacto_parameters(pipeline)?)
    } else if root.get("positions").is_some() && root.get("density").is_some() {
        let (parameters, grut) = grut_parameters(&root, &mut notes)?;
        trained = grut;
        (Trainer::Grut, parameters)
    } else {
        return Err(fail(format!(
            "neither \"splats\" (gsplat's simple_trainer), \"pipeline\" (Nerfstudio's), \"positions\" and \
             \"density\" (3DGRUT's) nor 3DGS's (capture, iteration) in the checkpoint (its keys: {})",
            root.keys().join(", ")
        )));
    };
    let tensor = |(name, key, value): &(&'static str, String, &Value)| {
        archive.tensor(value).map(|t| t.named(name)).map_err(|m| fail(format!("\"{key}\": {m}")))
    };
    let [means, scales, quats, opacities, dc, rest] = &parameters;
    let splats = Splats {
        means: tensor(means)?,
        scales: tensor(scales)?,
        quats: tensor(quats)?,
        opacities: tensor(opacities)?,
        dc: tensor(dc)?,
        rest: tensor(rest)?,
    };
    let scene = Scene { trained, ..splats.scene(trainer)? };
    Ok((scene, CheckpointInfo { trainer, step, notes }))
}

/// The six parameters (positions, log scales, quaternions, opacity logits, DC, the rest of the
/// SH), each by its name as a splat property, its key in the checkpoint and its value.
type Parameters<'v> = [(&'static str, String, &'v Value); 6];

/// 3DGS's checkpoint, `chkpnt{iteration}.pth`: `torch.save((gaussians.capture(), iteration))`,
/// the capture a tuple of the active SH degree, `_xyz`, `_features_dc` (N × 1 × 3),
/// `_features_rest` (N × K × 3), `_scaling`, `_rotation` and `_opacity`, then the densification
/// statistics, the optimizer's state and the spatial learning rate's scale. `None` where the
/// pickled object is not such a pair.
fn inria_parameters(root: &Value) -> Option<(Parameters<'_>, i64)> {
    let Value::Tuple(pair) = root else { return None };
    let [Value::Tuple(capture), Value::Int(iteration)] = &pair[..] else { return None };
    let [Value::Int(_), xyz, dc, rest, scaling, rotation, opacity, ..] = &capture[..] else { return None };
    let tensor = |v: &Value| matches!(v, Value::Call(..));
    if ![xyz, dc, rest, scaling, rotation, opacity].into_iter().all(tensor) {
        return None;
    }
    let named = |name: &'static str, value| (name, name.to_string(), value);
    let parameters = [
        named("_xyz", xyz),
        named("_scaling", scaling),
        named("_rotation", rotation),
        named("_opacity", opacity),
        named("_features_dc", dc),
        named("_features_rest", rest),
    ];
    Some((parameters, *iteration))
}

/// gsplat's splats: `splats.state_dict()`.
fn gsplat_parameters(splats: &Value) -> Result<Parameters<'_>, ErrorKind> {
    if splats.get("sh0").is_none() && splats.get("colors").is_some() {
        return Err(fail(
            "the splats hold \"features\" and \"colors\" for gsplat's appearance network (simple_trainer's app_opt), which \
             splat does not run: train without it, or export a .ply of the colours the network gives"
                .into(),
        ));
    }
    let get = |name: &'static str| -> Result<_, ErrorKind> {
        let value = splats
            .get(name)
            .ok_or_else(|| fail(format!("the splats have no \"{name}\" (they have: {})", splats.keys().join(", "))))?;
        Ok((name, name.to_string(), value))
    };
    Ok([get("means")?, get("scales")?, get("quats")?, get("opacities")?, get("sh0")?, get("shN")?])
}

/// The prefixes of splatfacto's parameters in a pipeline's state dict: its `gauss_params`, the
/// model's own attributes in older checkpoints, and either under DDP's `module.`.
const SPLATFACTO_PREFIXES: [&str; 4] =
    ["_model.gauss_params.", "_model.", "module._model.gauss_params.", "module._model."];

/// splatfacto's splats in Nerfstudio's `pipeline.state_dict()`.
fn splatfacto_parameters(pipeline: &Value) -> Result<Parameters<'_>, ErrorKind> {
    let prefix =
        SPLATFACTO_PREFIXES.iter().find(|p| pipeline.get(&format!("{p}means")).is_some()).ok_or_else(|| {
            let keys = pipeline.keys();
            let shown: Vec<&str> = keys.iter().take(6).copied().collect();
            let more = if keys.len() > shown.len() {
                format!(" and {} more", keys.len() - shown.len())
            } else {
                String::new()
            };
            fail(format!(
                "the pipeline holds no splatfacto model (no \"_model.gauss_params.means\"): a checkpoint of another \
             Nerfstudio method (its keys: {}{more})",
                shown.join(", ")
            ))
        })?;
    let get = |name: &'static str| -> Result<_, ErrorKind> {
        let key = format!("{prefix}{name}");
        let value =
            pipeline.get(&key).ok_or_else(|| fail(format!("the pipeline has \"{prefix}means\" but no \"{key}\"")))?;
        Ok((name, key, value))
    };
    Ok([get("means")?, get("scales")?, get("quats")?, get("opacities")?, get("features_dc")?, get("features_rest")?])
}

/// Splats built together: each tensor's rows of a block are read, then the block's splats are
/// built from them on every core. A block's rows take at most 15 MB (59 f32 a splat at SH
/// degree 3), so reading costs about the memory of the scene itself.
const BLOCK: usize = 1 << 16;

/// 3DGRUT's splats: the model's parameters at the checkpoint's top level (`positions`,
/// `rotation`, `scale`, `density`, `features_albedo`, `features_specular`), beside the run's
/// config (an OmegaConf `DictConfig`), whose activations must be 3DGS's (sigmoid and exp, as
/// its `.ply` export assumes); with the renderer and kernel the config names
/// ([`grut_rendering`]).
fn grut_parameters<'v>(
    root: &'v Value,
    notes: &mut Vec<String>,
) -> Result<(Parameters<'v>, Option<Trained>), ErrorKind> {
    match root.get("feature_type") {
        None => {}
        Some(Value::Str(t)) if t == "sh" => {}
        Some(Value::Str(t)) => {
            return Err(fail(format!(
                "3DGRUT's particles hold {t} features (its feature_type) for a network to decode, which splat does not \
                 run: only its spherical harmonics (feature_type sh) are read"
            )));
        }
        Some(other) => return Err(fail(format!("3DGRUT's feature_type is {other:?}, not a name"))),
    }
    let config = root.get("config");
    let setting = |path: &[&str]| config.and_then(|c| omegaconf(c, path));
    for (path, expected) in [(["model", "density_activation"], "sigmoid"), (["model", "scale_activation"], "exp")] {
        match setting(&path) {
            None => {}
            Some(Value::Str(name)) if name == expected => {}
            Some(value) => {
                return Err(fail(format!(
                    "3DGRUT trained these particles with {} {}, where a splat's is {expected} (3DGS's, which its \
                     .ply export assumes too)",
                    path.join("."),
                    shown(value)
                )));
            }
        }
    }
    let trained = grut_rendering(&setting, notes)?;
    let get = |name: &'static str| -> Result<_, ErrorKind> {
        let value = root.get(name).ok_or_else(|| fail(format!("3DGRUT's checkpoint has no \"{name}\"")))?;
        Ok((name, name.to_string(), value))
    };
    let parameters = [
        get("positions")?,
        get("scale")?,
        get("rotation")?,
        get("density")?,
        get("features_albedo")?,
        get("features_specular")?,
    ];
    Ok((parameters, trained))
}

/// The kernel degrees of 3DGRT's tracer (`particleResponse`: its switch has cases 0, the linear
/// kernel, 1, 3, 4, 5 and 8, and the Gaussian for any other): the generalised Gaussians splat
/// renders as 3DGRT does.
const GRUT_DEGREES: [i64; 6] = [1, 2, 3, 4, 5, 8];

/// How a 3DGRUT run's config (`setting`, by path) says its particles render: the renderer and
/// kernel it trained them through (`render.method`, `render.particle_kernel_degree`,
/// `render.particle_kernel_min_response`), where it names its renderer; `notes` say so, and of
/// its normalised world and surfels. A kernel splat does not have is refused.
fn grut_rendering<'v>(
    setting: &dyn Fn(&[&str]) -> Option<&'v Value>,
    notes: &mut Vec<String>,
) -> Result<Option<Trained>, ErrorKind> {
    let preset = match setting(&["render", "method"]) {
        Some(Value::Str(method)) => [Preset::ThreeDgrt, Preset::ThreeDgut].into_iter().find(|p| p.name() == method),
        _ => None,
    };
    let mut trained = preset.map(|preset| grut_kernel(preset, setting)).transpose()?;
    let named = |path: &[&str], value: &str| matches!(setting(path), Some(Value::Str(s)) if s == value);
    if let Some(trained) = &mut trained
        && named(&["model", "background", "name"], "background-color")
        && named(&["model", "background", "color"], "white")
    {
        trained.background = Some(glam::Vec3::ONE);
        notes.push("3DGRUT composites these particles over white (its model.background.color): they render so".into());
    }
    match trained {
        Some(trained) => {
            let (name, method) =
                (if trained.preset == Preset::ThreeDgrt { "3DGRT" } else { "3DGUT" }, trained.preset.name());
            let kernel = if trained.has_presets_kernel() {
                String::new()
            } else {
                format!(
                    " and the kernel the run set (degree {}, cut off at {:.4}σ by its minimum response)",
                    trained.kernel_degree, trained.cutoff
                )
            };
            notes.push(format!(
                "{name} trained these particles (its render.method {method}): they render as it renders them, with \
                 the {method} preset{kernel}, where no other preset or kernel is chosen"
            ));
        }
        None => notes.push(
            "the checkpoint's config does not say how 3DGRUT rendered these particles (its render.method): they \
             render with the default kernel, where the 3dgrt and 3dgut presets render them as its two renderers do"
                .into(),
        ),
    }
    if named(&["render", "primitive_type"], "trisurfel") {
        notes.push(
            "3DGRUT trained these particles as flat surfels (its render.primitive_type trisurfel); they are read as \
             Gaussians of their three scales"
                .into(),
        );
    }
    if let Some(Value::Bool(true)) = setting(&["dataset", "normalize_world_space"]) {
        notes.push(
            "3DGRUT trained these particles in its normalised world (its dataset.normalize_world_space, a port of \
             gsplat's): their COLMAP cameras line up with them there, where splat's gsplat-world option moves them"
                .into(),
        );
    }
    Ok(trained)
}

/// The kernel a 3DGRUT run of `preset`'s renderer trained with: its config's degree and minimum
/// response where it sets them (`setting`, by path), else the preset's; the cutoff is that
/// response's radius ([`min_response_cutoff`]).
fn grut_kernel<'v>(preset: Preset, setting: &dyn Fn(&[&str]) -> Option<&'v Value>) -> Result<Trained, ErrorKind> {
    let degree = match setting(&["render", "particle_kernel_degree"]) {
        None => preset.kernel_degree(),
        Some(Value::Int(degree)) if GRUT_DEGREES.contains(degree) => *degree as u32,
        Some(other) => {
            return Err(fail(format!(
                "3DGRUT trained these particles with render.particle_kernel_degree {}, a kernel splat does not \
                 render as 3DGRT does: the generalised Gaussians of degree 1, 2, 3, 4, 5 and 8",
                shown(other)
            )));
        }
    };
    let min_response = match setting(&["render", "particle_kernel_min_response"]) {
        None => GRUT_MIN_RESPONSE,
        Some(&Value::Float(r)) if r > 0.0 && r < 1.0 => r as f32,
        Some(other) => {
            return Err(fail(format!(
                "3DGRUT's render.particle_kernel_min_response is {}, not a response between 0 and 1",
                shown(other)
            )));
        }
    };
    Ok(Trained { kernel_degree: degree, cutoff: min_response_cutoff(min_response, degree), ..Trained::of(preset) })
}

/// A config's value as a message shows it: a name quoted, a number as it is.
fn shown(value: &Value) -> String {
    match value {
        Value::Str(name) => format!("\"{name}\""),
        Value::Int(i) => i.to_string(),
        Value::Float(x) => x.to_string(),
        other => format!("{other:?}"),
    }
}

/// A setting of a pickled OmegaConf config, by its path of keys: a `DictConfig` keeps its
/// nodes in `_content`, and a value node its value in `_val` (their pickled states).
fn omegaconf<'v>(config: &'v Value, path: &[&str]) -> Option<&'v Value> {
    let mut node = config;
    for key in path {
        node = node.state()?.get("_content")?.get(key)?;
    }
    node.state()?.get("_val")
}

/// A tensor's shape and where its elements lie: rows read a block at a time from its storage.
struct Tensor<'s, S: Source + ?Sized> {
    /// Its parameter's name, as splat properties are named in errors.
    name: &'static str,
    shape: Vec<usize>,
    /// Its storage's entry, read a block of rows at a time.
    storage: EntryReader<'s, S>,
    /// The byte of the storage its first element starts at.
    first: u64,
    /// Bytes an element.
    size: usize,
    decode: fn(&[u8]) -> f32,
}

impl<S: Source + ?Sized> Tensor<'_, S> {
    fn named(self, name: &'static str) -> Self {
        Self { name, ..self }
    }

    /// Elements a row (the product of the shape after its first dimension).
    fn width(&self) -> usize {
        self.shape[1..].iter().product()
    }

    /// Rows `rows`; each call's rows follow the last's.
    fn rows(&mut self, rows: std::ops::Range<usize>) -> Result<Rows<'_>, ErrorKind> {
        let (name, size, decode, width) = (self.name, self.size, self.decode, self.width());
        let at = self.first + (rows.start * width * size) as u64;
        let bytes = self.storage.piece(at, (rows.len() * width * size) as u64).map_err(fail)?;
        Ok(Rows { name, bytes, width, size, decode })
    }

    /// An error unless the shape is (`n`, one of `tails`).
    fn expect_shape(&self, n: usize, tails: &[&[usize]]) -> Result<(), ErrorKind> {
        if self.shape.first() == Some(&n) && tails.iter().any(|tail| self.shape[1..] == **tail) {
            return Ok(());
        }
        let expected: Vec<String> = tails.iter().map(|tail| format!("{:?}", [&[n][..], tail].concat())).collect();
        Err(fail(format!("\"{}\" has shape {:?}, expected {}", self.name, self.shape, expected.join(" or "))))
    }
}

/// A trainer's parameter tensors.
struct Splats<'s, S: Source + ?Sized> {
    means: Tensor<'s, S>,
    scales: Tensor<'s, S>,
    quats: Tensor<'s, S>,
    opacities: Tensor<'s, S>,
    dc: Tensor<'s, S>,
    rest: Tensor<'s, S>,
}

impl<S: Source + ?Sized> Splats<'_, S> {
    /// The scene of the parameters, with 3DGS's activations (those of its `.ply` reader).
    fn scene(mut self, trainer: Trainer) -> Result<Scene, ErrorKind> {
        let n = self.means.shape.first().copied().unwrap_or(0);
        self.means.expect_shape(n, &[&[3]])?;
        self.scales.expect_shape(n, &[&[3]])?;
        self.quats.expect_shape(n, &[&[4]])?;
        self.opacities.expect_shape(n, &[&[], &[1]])?;
        let rest: &[&[usize]] = &[&[0, 3], &[3, 3], &[8, 3], &[15, 3]];
        match trainer {
            Trainer::Gsplat | Trainer::Inria => self.dc.expect_shape(n, &[&[1, 3]])?,
            Trainer::Splatfacto | Trainer::Grut => self.dc.expect_shape(n, &[&[3]])?,
        }
        match trainer {
            Trainer::Gsplat | Trainer::Splatfacto | Trainer::Inria => self.rest.expect_shape(n, rest)?,
            // 3DGRUT's features_specular: N × 3K, coefficient by coefficient.
            Trainer::Grut => self.rest.expect_shape(n, &[&[0], &[9], &[24], &[45]])?,
        }
        let degree = [0, 9, 24, 45].iter().position(|&w| w == self.rest.width()).expect("checked above") as u8;
        // splatfacto at degree 0 trains a colour logit, exported as RGB2SH(sigmoid(·)).
        let dc = if trainer == Trainer::Splatfacto && degree == 0 { Dc::ColourLogit } else { Dc::Coefficient };
        let mut particles = Vec::with_capacity(n);
        for first in (0..n).step_by(BLOCK) {
            let rows = first..(first + BLOCK).min(n);
            let block = Block {
                first,
                means: self.means.rows(rows.clone())?,
                scales: self.scales.rows(rows.clone())?,
                quats: self.quats.rows(rows.clone())?,
                opacities: self.opacities.rows(rows.clone())?,
                dc: self.dc.rows(rows.clone())?,
                rest: self.rest.rows(rows.clone())?,
                degree,
                dc_meaning: dc,
            };
            // On every core; where some splat fails, the first that does is named, whatever the
            // threads, unless the file is damaged, which is said first.
            let built: Result<Vec<_>, _> = rows.clone().into_par_iter().map(|i| block.particle(i)).collect();
            match built {
                Ok(built) => particles.par_extend(built),
                Err(_) => {
                    let error = rows.into_iter().find_map(|i| block.particle(i).err()).expect("a splat failed");
                    drop(block);
                    self.finish()?;
                    return Err(error);
                }
            }
        }
        self.finish()?;
        Ok(Scene::new(particles, degree))
    }

    /// Check every storage read.
    fn finish(&mut self) -> Result<(), ErrorKind> {
        for t in [&mut self.means, &mut self.scales, &mut self.quats, &mut self.opacities, &mut self.dc, &mut self.rest]
        {
            t.storage.finish().map_err(fail)?;
        }
        Ok(())
    }
}

/// A block's rows of one tensor: their bytes, decoded as they are read.
struct Rows<'a> {
    /// The parameter's name, as splat properties are named in errors.
    name: &'static str,
    bytes: Cow<'a, [u8]>,
    /// Elements a row, and bytes an element.
    width: usize,
    size: usize,
    decode: fn(&[u8]) -> f32,
}

impl Rows<'_> {
    /// Element `k` of the block's rows.
    fn element(&self, k: usize) -> f32 {
        (self.decode)(&self.bytes[k * self.size..][..self.size])
    }

    /// Row `j` of the block, of `N` elements (the width).
    fn row<const N: usize>(&self, j: usize) -> [f32; N] {
        debug_assert_eq!(N, self.width);
        std::array::from_fn(|k| self.element(j * N + k))
    }

    /// Row `j` of the block, into the front of `out`.
    fn row_into<'o>(&self, j: usize, out: &'o mut [f32]) -> &'o [f32] {
        let out = &mut out[..self.width];
        for (k, value) in out.iter_mut().enumerate() {
            *value = self.element(j * self.width + k);
        }
        out
    }

    /// An error naming the first of `values` (row `j`'s) that is not finite, as splat `index`'s.
    fn finite(&self, values: &[f32], index: u64) -> Result<(), ErrorKind> {
        match values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            Some((k, &v)) => {
                let property = if self.width == 1 { self.name.to_string() } else { format!("{}[{k}]", self.name) };
                Err(ErrorKind::NonFinite { index, property, value: f64::from(v) })
            }
            None => Ok(()),
        }
    }
}

/// A block of splats' parameters.
struct Block<'a> {
    /// The index of its first splat.
    first: usize,
    means: Rows<'a>,
    scales: Rows<'a>,
    quats: Rows<'a>,
    opacities: Rows<'a>,
    dc: Rows<'a>,
    rest: Rows<'a>,
    degree: u8,
    dc_meaning: Dc,
}

impl Block<'_> {
    /// Splat `i` (of the checkpoint; one of the block's).
    fn particle(&self, i: usize) -> Result<Particle, ErrorKind> {
        let (index, j) = (i as u64, i - self.first);
        let (mean, log_scale, quat) = (self.means.row::<3>(j), self.scales.row::<3>(j), self.quats.row::<4>(j));
        let ([logit], dc) = (self.opacities.row::<1>(j), self.dc.row::<3>(j));
        self.means.finite(&mean, index)?;
        self.scales.finite(&log_scale, index)?;
        self.quats.finite(&quat, index)?;
        self.opacities.finite(&[logit], index)?;
        self.dc.finite(&dc, index)?;
        let mut rest = [0.0; 3 * (SH_MAX_COEFFS - 1)];
        let rest = self.rest.row_into(j, &mut rest);
        self.rest.finite(rest, index)?;
        let mut sh = [Vec3::ZERO; SH_MAX_COEFFS];
        sh[0] = match self.dc_meaning {
            Dc::Coefficient => Vec3::from(dc),
            Dc::ColourLogit => rgb_to_dc(Vec3::from(dc.map(|x| opacity_from_logit(f64::from(x)) as f32))),
        };
        for (c, value) in sh[1..].iter_mut().zip(rest.chunks_exact(3)) {
            *c = Vec3::from_slice(value);
        }
        debug_assert_eq!(rest.len(), 3 * (sh_coeff_count(self.degree) - 1));
        let mut scale = [0.0f32; 3];
        for (axis, (&raw, out)) in log_scale.iter().zip(&mut scale).enumerate() {
            let raw = f64::from(raw);
            *out = scale_from_log(raw).ok_or_else(|| ErrorKind::BadScale {
                index,
                detail: format!(
                    "scales[{axis}] = {raw} gives exp = {}, which is not a usable positive scale",
                    raw.exp() as f32
                ),
            })?;
        }
        let q = unit_quaternion(quat.map(f64::from)).ok_or(ErrorKind::ZeroQuaternion { index })?;
        let opacity = opacity_from_logit(f64::from(logit)) as f32;
        Particle::new(Vec3::from(mean), Vec3::from(scale), q, opacity, sh).map_err(|error| match error {
            ParticleError::ZeroQuaternion => ErrorKind::ZeroQuaternion { index },
            error => ErrorKind::Particle { index, error },
        })
    }
}

/// What a checkpoint's DC parameter holds.
#[derive(Clone, Copy)]
enum Dc {
    /// The SH DC coefficient itself.
    Coefficient,
    /// A colour's logit (splatfacto at SH degree 0): the coefficient is RGB2SH(sigmoid(x)).
    ColourLogit,
}

/// A checkpoint's archive: its pickle, and where each storage lies.
struct Archive<'s, S: Source + ?Sized> {
    source: &'s S,
    data_pkl: Vec<u8>,
    storages: HashMap<String, crate::zip::CentralEntry>,
    /// Each storage's entry name, for its errors.
    prefix: String,
}

impl<'s, S: Source + ?Sized> Archive<'s, S> {
    fn open(source: &'s S) -> Result<Self, String> {
        if source.size() < 2 || source.piece(0, 2, "the signature")?[..] != *b"PK" {
            return Err(
                "not a zip archive: a checkpoint of PyTorch before 1.6 (its legacy format), or not a PyTorch file"
                    .into(),
            );
        }
        let directory = crate::zip::directory(source)?;
        let pickles: Vec<&str> =
            directory.iter().map(|(name, _)| name.as_str()).filter(|n| n.ends_with("/data.pkl")).collect();
        let [pickle_name] = pickles[..] else {
            return Err(format!("{} data.pkl entries where a torch.save archive has one", pickles.len()));
        };
        let prefix = pickle_name.trim_end_matches("data.pkl").to_string();
        let mut data_pkl = None;
        let mut storages = HashMap::new();
        for (name, entry) in directory {
            let Some(local) = name.strip_prefix(&prefix) else { continue };
            if local == "data.pkl" {
                data_pkl = Some(entry.contents(source, &name)?.into_owned());
            } else if local == "byteorder" {
                let order = entry.contents(source, &name)?;
                if &order[..] != b"little" {
                    let order = String::from_utf8_lossy(&order).into_owned();
                    return Err(format!("its storages are {order}-endian; only little-endian ones are read"));
                }
            } else if let Some(key) = local.strip_prefix("data/") {
                storages.insert(key.to_string(), entry);
            }
        }
        Ok(Self { source, data_pkl: data_pkl.expect("found above"), storages, prefix })
    }

    /// The tensor a pickled value rebuilds.
    fn tensor(&self, value: &Value) -> Result<Tensor<'s, S>, String> {
        let Value::Call(callable, args) = value else { return Err("not a tensor".into()) };
        let (Value::Global(module, function), Value::Tuple(args)) = (&**callable, &**args) else {
            return Err("not a tensor".into());
        };
        match (module.as_str(), function.as_str(), &args[..]) {
            ("torch._utils", "_rebuild_parameter" | "_rebuild_parameter_with_state", [data, ..]) => self.tensor(data),
            (
                "torch._utils",
                "_rebuild_tensor_v2",
                [storage, Value::Int(offset), Value::Tuple(size), Value::Tuple(stride), ..],
            ) => {
                let ints = |v: &[Value], what: &str| -> Result<Vec<usize>, String> {
                    v.iter()
                        .map(|x| match x {
                            Value::Int(i) => usize::try_from(*i).map_err(|_| format!("a negative {what}")),
                            _ => Err(format!("a {what} that is not an integer")),
                        })
                        .collect()
                };
                let (shape, stride) = (ints(size, "size")?, ints(stride, "stride")?);
                let offset = usize::try_from(*offset).map_err(|_| "a negative storage offset".to_string())?;
                self.elements(storage, offset, shape, &stride)
            }
            (module, function, _) => Err(format!("a call of {module}.{function}, which is not a tensor")),
        }
    }

    /// The elements of a tensor of `shape` at `offset` in the storage a persistent id names,
    /// laid out row-major (`stride`).
    fn elements(
        &self,
        storage: &Value,
        offset: usize,
        shape: Vec<usize>,
        stride: &[usize],
    ) -> Result<Tensor<'s, S>, String> {
        let Value::Persistent(id) = storage else { return Err("a tensor without a storage".into()) };
        let Value::Tuple(id) = &**id else { return Err("a storage id that is not a tuple".into()) };
        let [Value::Str(kind), Value::Global(_, ty), Value::Str(key), _location, ..] = &id[..] else {
            return Err("a storage id other than torch.save's (\"storage\", type, key, location, numel)".into());
        };
        if kind != "storage" {
            return Err(format!("a persistent id of kind {kind}"));
        }
        let (size, decode): (usize, fn(&[u8]) -> f32) = match ty.as_str() {
            "FloatStorage" => (4, |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            "DoubleStorage" => (8, |b| f64::from_le_bytes(std::array::from_fn(|k| b[k])) as f32),
            "HalfStorage" => (2, |b| half::f16::from_le_bytes([b[0], b[1]]).to_f32()),
            "BFloat16Storage" => (2, |b| half::bf16::from_le_bytes([b[0], b[1]]).to_f32()),
            other => return Err(format!("elements of type {other}, where a splat parameter is a float")),
        };
        // Row-major strides as PyTorch computes them (an empty dimension counts as one); a
        // dimension of one element, or a tensor of none, is row-major with any stride.
        let contiguous: Vec<usize> =
            (0..shape.len()).map(|d| shape[d + 1..].iter().map(|&n| n.max(1)).product::<usize>()).collect();
        let count: usize = shape.iter().product();
        let same = shape.iter().zip(stride.iter().zip(&contiguous)).all(|(&n, (&s, &c))| n <= 1 || s == c);
        if stride.len() != shape.len() || (count > 0 && !same) {
            return Err(format!("a tensor of shape {shape:?} laid out with strides {stride:?}, not row-major"));
        }
        let entry = self.storages.get(key).ok_or_else(|| format!("its storage data/{key} is not in the archive"))?;
        let name = format!("{}data/{key}", self.prefix);
        let storage = entry.reader(self.source, &name)?;
        let end = offset.checked_add(count).and_then(|e| e.checked_mul(size)).filter(|&e| e as u64 <= storage.len());
        end.ok_or_else(|| {
            format!("{count} elements from {offset} run past its storage data/{key} ({} bytes)", storage.len())
        })?;
        Ok(Tensor { name: "", shape, storage, first: (offset * size) as u64, size, decode })
    }
}
