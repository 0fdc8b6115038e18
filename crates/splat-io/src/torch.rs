//! Trainers' checkpoints, read without PyTorch:
//!
//! - gsplat's `simple_trainer` saves `ckpt_STEP_rankR.pt`, `torch.save` of `{"step": step,
//!   "splats": splats.state_dict()}`;
//! - Nerfstudio's trainer saves `nerfstudio_models/step-STEP.ckpt`, `torch.save` of `{"step",
//!   "pipeline": pipeline.state_dict(), "optimizers", "schedulers", "scalers"}`; a splatfacto
//!   model keeps its splats in the pipeline's `_model.gauss_params.*` (`_model.*` in checkpoints
//!   before the parameter dict; `module.` before either where the run was distributed).
//!
//! `torch.save` writes a zip archive (PyTorch ≥ 1.6; always Zip64, read by the crate's `zip`) of
//! `ARCHIVE/data.pkl`, a pickle of the object (read by the crate's `pickle`), and one entry
//! `ARCHIVE/data/KEY` a storage, its raw little-endian elements (`ARCHIVE/byteorder` says
//! `little` where present). A tensor is pickled as a call of
//! `torch._utils._rebuild_tensor_v2(storage, offset, size, stride, requires_grad, hooks)`, its
//! storage as the persistent id `("storage", torch.FloatStorage, KEY, location, numel)`. Only
//! the pickle and the six storages of the splats are read from the file: a Nerfstudio
//! checkpoint is about three times its splats (Adam's two moments of every parameter).
//!
//! The splats are the parameters before their activations, as both trainers' `.ply` exports
//! write them and 3DGS's reader reads them: `means` (N, 3), `scales` (N, 3, log), `quats` (N,
//! 4, w x y z, not normalised), `opacities` (N or N × 1, logit), the DC coefficient (gsplat's
//! `sh0`, N × 1 × 3; splatfacto's `features_dc`, N × 3) and the rest (`shN`, `features_rest`: N
//! × K × 3, K = 0, 3, 8 or 15). A splatfacto model of SH degree 0 trains its colour as a logit
//! (its `features_dc` through a sigmoid) and exports RGB2SH of it: so it is read. A gsplat run
//! with `--app_opt` keeps `features` and `colors` for an appearance network instead of `sh0`:
//! refused by name, as is anything else that is not such a checkpoint.

use crate::pickle::{self, Value};
use crate::ply::{opacity_from_logit, scale_from_log, unit_quaternion};
use crate::zip::{FileSource, Source};
use crate::{Error, ErrorKind};
use glam::Vec3;
use rayon::prelude::*;
use splat_core::particle::{SH_MAX_COEFFS, sh_coeff_count};
use splat_core::sh::rgb_to_dc;
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
}

/// What a checkpoint says besides its splats.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckpointInfo {
    /// Whose checkpoint it is.
    pub trainer: Trainer,
    /// The training step it was saved at, where it says.
    pub step: Option<i64>,
}

impl CheckpointInfo {
    /// What `splat info` adds to the format's name: the step, where the checkpoint says.
    pub fn describe(&self) -> String {
        self.step.map_or_else(String::new, |step| format!("step {step}"))
    }
}

/// Read the checkpoint at `path` (gsplat's or Nerfstudio's splatfacto's, whatever its
/// extension): its pickle and the storages of its splats, nothing more.
pub fn read_checkpoint(path: &Path) -> Result<(Scene, CheckpointInfo), Error> {
    let source = FileSource::open(path).map_err(|e| Error::new(path, ErrorKind::Io(e)))?;
    checkpoint(&source).map_err(|e| Error::new(path, e))
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
    let step = match root.get("step") {
        Some(Value::Int(step)) => Some(*step),
        _ => None,
    };
    let (trainer, parameters) = if let Some(splats) = root.get("splats") {
        (Trainer::Gsplat, gsplat_parameters(splats)?)
    } else if let Some(pipeline) = root.get("pipeline") {
        (Trainer::Splatfacto, splatfacto_parameters(pipeline)?)
    } else {
        return Err(fail(format!(
            "neither \"splats\" (gsplat's simple_trainer) nor \"pipeline\" (Nerfstudio's) in the checkpoint (its \
             keys: {})",
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
    Ok((splats.scene(trainer)?, CheckpointInfo { trainer, step }))
}

/// The six parameters (positions, log scales, quaternions, opacity logits, DC, the rest of the
/// SH), each by its name as a splat property, its key in the checkpoint and its value.
type Parameters<'v> = [(&'static str, String, &'v Value); 6];

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

/// A tensor's shape and its elements in row-major order: bytes of its storage, decoded to f32
/// as they are read.
struct Tensor<'b> {
    /// Its parameter's name, as splat properties are named in errors.
    name: &'static str,
    shape: Vec<usize>,
    bytes: Cow<'b, [u8]>,
    /// Bytes an element.
    size: usize,
    decode: fn(&[u8]) -> f32,
}

impl Tensor<'_> {
    fn named(self, name: &'static str) -> Self {
        Self { name, ..self }
    }

    /// Elements `first..first + N` (row `first / N` of a tensor of rows of N).
    fn row<const N: usize>(&self, first: usize) -> [f32; N] {
        std::array::from_fn(|k| (self.decode)(&self.bytes[(first + k) * self.size..][..self.size]))
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
struct Splats<'b> {
    means: Tensor<'b>,
    scales: Tensor<'b>,
    quats: Tensor<'b>,
    opacities: Tensor<'b>,
    dc: Tensor<'b>,
    rest: Tensor<'b>,
}

impl Splats<'_> {
    /// The scene of the parameters, with 3DGS's activations (those of its `.ply` reader).
    fn scene(&self, trainer: Trainer) -> Result<Scene, ErrorKind> {
        let n = self.means.shape.first().copied().unwrap_or(0);
        self.means.expect_shape(n, &[&[3]])?;
        self.scales.expect_shape(n, &[&[3]])?;
        self.quats.expect_shape(n, &[&[4]])?;
        self.opacities.expect_shape(n, &[&[], &[1]])?;
        match trainer {
            Trainer::Gsplat => self.dc.expect_shape(n, &[&[1, 3]])?,
            Trainer::Splatfacto => self.dc.expect_shape(n, &[&[3]])?,
        }
        self.rest.expect_shape(n, &[&[0, 3], &[3, 3], &[8, 3], &[15, 3]])?;
        let degree = [0, 3, 8, 15].iter().position(|&k| k == self.rest.shape[1]).expect("checked above") as u8;
        // splatfacto at degree 0 trains a colour logit, exported as RGB2SH(sigmoid(·)).
        let dc = if trainer == Trainer::Splatfacto && degree == 0 { Dc::ColourLogit } else { Dc::Coefficient };
        // On every core; where some splat fails, the first that does is named, whatever the threads.
        let particles: Result<Vec<_>, _> = (0..n).into_par_iter().map(|i| self.particle(i, degree, dc)).collect();
        let particles =
            particles.map_err(|_| (0..n).find_map(|i| self.particle(i, degree, dc).err()).expect("a splat failed"))?;
        Ok(Scene::new(particles, degree))
    }

    /// Splat `i`, of SH degree `degree`.
    fn particle(&self, i: usize, degree: u8, dc_meaning: Dc) -> Result<Particle, ErrorKind> {
        let index = i as u64;
        let finite = |values: &[f32], name: &str| -> Result<(), ErrorKind> {
            match values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                Some((k, &v)) => {
                    let property = if values.len() == 1 { name.to_string() } else { format!("{name}[{k}]") };
                    Err(ErrorKind::NonFinite { index, property, value: f64::from(v) })
                }
                None => Ok(()),
            }
        };
        let (mean, log_scale, quat) =
            (self.means.row::<3>(3 * i), self.scales.row::<3>(3 * i), self.quats.row::<4>(4 * i));
        let ([logit], dc) = (self.opacities.row::<1>(i), self.dc.row::<3>(3 * i));
        for (values, t) in [
            (&mean[..], &self.means),
            (&log_scale, &self.scales),
            (&quat, &self.quats),
            (&[logit], &self.opacities),
            (&dc, &self.dc),
        ] {
            finite(values, t.name)?;
        }
        let rest = sh_coeff_count(degree) - 1;
        let mut sh = [Vec3::ZERO; SH_MAX_COEFFS];
        sh[0] = match dc_meaning {
            Dc::Coefficient => Vec3::from(dc),
            Dc::ColourLogit => rgb_to_dc(Vec3::from(dc.map(|x| opacity_from_logit(f64::from(x)) as f32))),
        };
        for (k, c) in sh.iter_mut().enumerate().skip(1).take(rest) {
            let coefficient = self.rest.row::<3>(3 * (i * rest + k - 1));
            finite(&coefficient, self.rest.name)?;
            *c = Vec3::from(coefficient);
        }
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
    fn tensor(&self, value: &Value) -> Result<Tensor<'s>, String> {
        let Value::Call(callable, args) = value else { return Err("not a tensor".into()) };
        let (Value::Global(module, function), Value::Tuple(args)) = (&**callable, &**args) else {
            return Err("not a tensor".into());
        };
        match (module.as_str(), function.as_str(), &args[..]) {
            ("torch._utils", "_rebuild_parameter", [data, ..]) => self.tensor(data),
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
    ) -> Result<Tensor<'s>, String> {
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
        let bytes = entry.contents(self.source, &format!("{}data/{key}", self.prefix))?;
        let end = offset.checked_add(count).and_then(|e| e.checked_mul(size)).filter(|&e| e <= bytes.len());
        let end = end.ok_or_else(|| {
            format!("{count} elements from {offset} run past its storage data/{key} ({} bytes)", bytes.len())
        })?;
        let bytes = match bytes {
            Cow::Borrowed(b) => Cow::Borrowed(&b[offset * size..end]),
            Cow::Owned(mut b) => {
                b.truncate(end);
                b.drain(..offset * size);
                Cow::Owned(b)
            }
        };
        Ok(Tensor { name: "", shape, bytes, size, decode })
    }
}
