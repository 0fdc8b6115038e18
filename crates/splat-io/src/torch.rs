//! gsplat's checkpoints: the `ckpt_STEP_rankR.pt` files `simple_trainer` saves (`torch.save`
//! of `{"step": step, "splats": splats.state_dict()}`), read without PyTorch.
//!
//! `torch.save` writes a zip archive (PyTorch ≥ 1.6; always Zip64, read by the crate's `zip`) of
//! `ARCHIVE/data.pkl`, a pickle of the object (read by the crate's `pickle`), and one entry
//! `ARCHIVE/data/KEY` a storage, its raw little-endian elements (`ARCHIVE/byteorder` says
//! `little` where present). A tensor is pickled as a call of
//! `torch._utils._rebuild_tensor_v2(storage, offset, size, stride, requires_grad, hooks)`, its
//! storage as the persistent id `("storage", torch.FloatStorage, KEY, location, numel)`.
//!
//! The splats are gsplat's parameters before their activations, as its `.ply` export writes
//! them and 3DGS's reader reads them: `means` (N, 3), `scales` (N, 3, log), `quats` (N, 4,
//! w x y z, not normalised), `opacities` (N, logit), `sh0` (N, 1, 3, the DC coefficient) and
//! `shN` (N, K, 3, K = 0, 3, 8 or 15). A run with `--app_opt` keeps `features` and `colors`
//! for an appearance network instead of `sh0`: refused by name, as is anything else that is
//! not such a checkpoint.

use crate::pickle::{self, Value};
use crate::ply::{opacity_from_logit, scale_from_log, unit_quaternion};
use crate::{Error, ErrorKind, read_file};
use glam::Vec3;
use rayon::prelude::*;
use splat_core::particle::{SH_MAX_COEFFS, sh_coeff_count};
use splat_core::{Particle, ParticleError, Scene};
use std::collections::HashMap;
use std::path::Path;

/// What a checkpoint says besides its splats.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckpointInfo {
    /// The training step it was saved at, where it says.
    pub step: Option<i64>,
}

impl CheckpointInfo {
    /// What `splat info` adds to the format's name: the step, where the checkpoint says.
    pub fn describe(&self) -> String {
        self.step.map_or_else(String::new, |step| format!("step {step}"))
    }
}

/// Read the gsplat checkpoint at `path`.
pub fn read_gsplat_checkpoint(path: &Path) -> Result<(Scene, CheckpointInfo), Error> {
    let bytes = read_file(path)?;
    parse_gsplat_checkpoint(&bytes).map_err(|e| Error::new(path, e))
}

/// Parse a gsplat checkpoint's bytes.
pub fn parse_gsplat_checkpoint(bytes: &[u8]) -> Result<(Scene, CheckpointInfo), ErrorKind> {
    let fail = |m: String| ErrorKind::Checkpoint(m);
    let archive = Archive::open(bytes).map_err(fail)?;
    let root = pickle::load(&archive.data_pkl).map_err(fail)?;
    let splats = root.get("splats").ok_or_else(|| {
        fail(format!(
            "no \"splats\" in the checkpoint (its keys: {}): not one of gsplat's simple_trainer",
            root.keys().join(", ")
        ))
    })?;
    if splats.get("sh0").is_none() && splats.get("colors").is_some() {
        return Err(fail(
            "the splats hold \"features\" and \"colors\" for gsplat's appearance network (simple_trainer's app_opt), which \
             splat does not run: train without it, or export a .ply of the colours the network gives"
                .into(),
        ));
    }
    let tensor = |name: &str| -> Result<Tensor<'_>, ErrorKind> {
        let value = splats
            .get(name)
            .ok_or_else(|| fail(format!("the splats have no \"{name}\" (they have: {})", splats.keys().join(", "))))?;
        archive.tensor(value).map_err(|m| fail(format!("\"{name}\": {m}")))
    };
    let step = match root.get("step") {
        Some(Value::Int(step)) => Some(*step),
        _ => None,
    };
    let scene = gsplat_scene(&Splats {
        means: tensor("means")?,
        scales: tensor("scales")?,
        quats: tensor("quats")?,
        opacities: tensor("opacities")?,
        sh0: tensor("sh0")?,
        sh_n: tensor("shN")?,
    })?;
    Ok((scene, CheckpointInfo { step }))
}

/// A tensor's shape and its elements in row-major order: bytes of its storage, decoded to f32
/// as they are read.
struct Tensor<'b> {
    shape: Vec<usize>,
    bytes: &'b [u8],
    /// Bytes an element.
    size: usize,
    decode: fn(&[u8]) -> f32,
}

impl Tensor<'_> {
    /// Elements `first..first + N` (row `first / N` of a tensor of rows of N).
    fn row<const N: usize>(&self, first: usize) -> [f32; N] {
        std::array::from_fn(|k| (self.decode)(&self.bytes[(first + k) * self.size..][..self.size]))
    }
}

/// gsplat's parameter tensors.
struct Splats<'b> {
    means: Tensor<'b>,
    scales: Tensor<'b>,
    quats: Tensor<'b>,
    opacities: Tensor<'b>,
    sh0: Tensor<'b>,
    sh_n: Tensor<'b>,
}

/// The scene of gsplat's parameters, with 3DGS's activations (those of its `.ply` reader).
fn gsplat_scene(s: &Splats<'_>) -> Result<Scene, ErrorKind> {
    let n = s.means.shape.first().copied().unwrap_or(0);
    let shape = |t: &Tensor, name: &str, tail: &[&[usize]]| -> Result<(), ErrorKind> {
        if t.shape.first() == Some(&n) && tail.iter().any(|tail| t.shape[1..] == **tail) {
            return Ok(());
        }
        let expected: Vec<String> = tail.iter().map(|tail| format!("{:?}", [&[n][..], tail].concat())).collect();
        Err(ErrorKind::Checkpoint(format!("\"{name}\" has shape {:?}, expected {}", t.shape, expected.join(" or "))))
    };
    shape(&s.means, "means", &[&[3]])?;
    shape(&s.scales, "scales", &[&[3]])?;
    shape(&s.quats, "quats", &[&[4]])?;
    shape(&s.opacities, "opacities", &[&[], &[1]])?;
    shape(&s.sh0, "sh0", &[&[1, 3]])?;
    shape(&s.sh_n, "shN", &[&[0, 3], &[3, 3], &[8, 3], &[15, 3]])?;
    let rest = s.sh_n.shape[1];
    let sh_degree = [0, 3, 8, 15].iter().position(|&k| k == rest).expect("checked above") as u8;
    // On every core; where some splat fails, the first that does is named, whatever the threads.
    let particles: Result<Vec<_>, _> = (0..n).into_par_iter().map(|i| particle(s, i, sh_degree)).collect();
    let particles =
        particles.map_err(|_| (0..n).find_map(|i| particle(s, i, sh_degree).err()).expect("a splat failed"))?;
    Ok(Scene::new(particles, sh_degree))
}

/// Splat `i` of gsplat's parameters, SH degree `degree`.
fn particle(s: &Splats, i: usize, degree: u8) -> Result<Particle, ErrorKind> {
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
    let (mean, log_scale, quat) = (s.means.row::<3>(3 * i), s.scales.row::<3>(3 * i), s.quats.row::<4>(4 * i));
    let ([logit], dc) = (s.opacities.row::<1>(i), s.sh0.row::<3>(3 * i));
    let rest = sh_coeff_count(degree) - 1;
    let mut sh = [Vec3::ZERO; SH_MAX_COEFFS];
    sh[0] = Vec3::from(dc);
    for (k, c) in sh.iter_mut().enumerate().skip(1).take(rest) {
        let coefficient = s.sh_n.row::<3>(3 * (i * rest + k - 1));
        finite(&coefficient, "shN")?;
        *c = Vec3::from(coefficient);
    }
    for (values, name) in
        [(&mean[..], "means"), (&log_scale, "scales"), (&quat, "quats"), (&[logit], "opacities"), (&dc, "sh0")]
    {
        finite(values, name)?;
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

/// A checkpoint's archive: its pickle and its storages by key.
struct Archive<'b> {
    data_pkl: Vec<u8>,
    storages: HashMap<String, std::borrow::Cow<'b, [u8]>>,
}

impl<'b> Archive<'b> {
    fn open(bytes: &'b [u8]) -> Result<Self, String> {
        if !bytes.starts_with(b"PK") {
            return Err(
                "not a zip archive: a checkpoint of PyTorch before 1.6 (its legacy format), or not a PyTorch file"
                    .into(),
            );
        }
        let directory = crate::zip::directory(bytes)?;
        let pickles: Vec<&str> =
            directory.iter().map(|(name, _)| name.as_str()).filter(|n| n.ends_with("/data.pkl")).collect();
        let [pickle_name] = pickles[..] else {
            return Err(format!("{} data.pkl entries where a torch.save archive has one", pickles.len()));
        };
        let prefix = pickle_name.trim_end_matches("data.pkl").to_string();
        let mut data_pkl = None;
        let mut storages = HashMap::new();
        for (name, entry) in &directory {
            let Some(local) = name.strip_prefix(&prefix) else { continue };
            if local == "data.pkl" {
                data_pkl = Some(entry.contents(bytes, name)?.into_owned());
            } else if local == "byteorder" {
                let order = entry.contents(bytes, name)?;
                if &order[..] != b"little" {
                    let order = String::from_utf8_lossy(&order).into_owned();
                    return Err(format!("its storages are {order}-endian; only little-endian ones are read"));
                }
            } else if let Some(key) = local.strip_prefix("data/") {
                storages.insert(key.to_string(), entry.contents(bytes, name)?);
            }
        }
        Ok(Self { data_pkl: data_pkl.expect("found above"), storages })
    }

    /// The tensor a pickled value rebuilds.
    fn tensor(&self, value: &Value) -> Result<Tensor<'_>, String> {
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
    ) -> Result<Tensor<'_>, String> {
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
        let bytes = self.storages.get(key).ok_or_else(|| format!("its storage data/{key} is not in the archive"))?;
        let end = offset.checked_add(count).and_then(|e| e.checked_mul(size)).filter(|&e| e <= bytes.len());
        let end = end.ok_or_else(|| {
            format!("{count} elements from {offset} run past its storage data/{key} ({} bytes)", bytes.len())
        })?;
        Ok(Tensor { shape, bytes: &bytes[offset * size..end], size, decode })
    }
}
