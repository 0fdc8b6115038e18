//! Storage arrays larger than one binding, split over several (docs/architecture.md, "Scenes
//! larger than a binding").
//!
//! A device binds at most `max_storage_buffer_binding_size` bytes of one storage buffer (128 MiB
//! on lavapipe, 2–4 GiB on desktop drivers), far less than its memory. So the scene arrays the
//! ray tracer reads (particles, BVH nodes, SH coefficients), and the splatting path's projected
//! splats and canonical transforms, are held in parts of 2^s elements, one buffer and one
//! binding each, and the kernels read (and write) them through an accessor (and setter)
//! generated into their modules ([`SplitLayout::wgsl`]): element i is element i & (2^s − 1) of
//! part i >> s.
//!
//! ```wgsl
//! @group(0) @binding(1) var<storage, read> particles: array<Particle>;
//! @group(0) @binding(18) var<storage, read> particles_1: array<Particle>;
//! fn particle_at(i: u32) -> Particle {
//!     var v: Particle;
//!     let j = i & 1048575u;
//!     switch i >> 20u {
//!         case 1u: { v = particles_1[j]; }
//!         default: { v = particles[j]; }
//!     }
//!     return v;
//! }
//! ```
//!
//! An array that fits one binding gets the one-line accessor `return particles[i];`, so every
//! scene that fits has the same module text (compiled once) and reads as it did unsplit.

use crate::context::storage_entry;
use crate::{GpuContext, GpuError};
use std::fmt::Write;

/// A storage array of a kernel that may be split: its WGSL names and element, read-only unless
/// it has a setter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) struct SplitArray {
    /// What it holds, for messages ("particle").
    pub what: &'static str,
    /// Part 0's variable (`particles`); part p's is `particles_p`.
    pub var: &'static str,
    /// The accessor (`particle_at`).
    pub accessor: &'static str,
    /// The element type in WGSL.
    pub ty: &'static str,
    /// Bytes of one element (its array stride in WGSL).
    pub stride: u64,
    /// Part 0's binding.
    pub binding: u32,
    /// The setter (`splat_set(i, v)`) of a read-write array; `None`: read-only.
    pub setter: Option<&'static str>,
}

impl SplitArray {
    /// An array of `T` (its WGSL twin `ty`), read through `accessor`, part 0 at `binding`.
    pub const fn of<T>(
        what: &'static str,
        var: &'static str,
        accessor: &'static str,
        ty: &'static str,
        binding: u32,
    ) -> Self {
        Self { what, var, accessor, ty, stride: std::mem::size_of::<T>() as u64, binding, setter: None }
    }

    /// The same array read and written, element i written by `setter(i, v)`.
    pub const fn writable(self, setter: &'static str) -> Self {
        Self { setter: Some(setter), ..self }
    }

    /// `data` (elements of this array) uploaded as `split`'s parts ([`upload`]).
    pub fn upload(&self, ctx: &GpuContext, split: Split, data: &[u8]) -> Result<Vec<wgpu::Buffer>, GpuError> {
        upload(ctx, self.what, self.stride, split, data)
    }

    /// Its WGSL access mode.
    fn access(&self) -> &'static str {
        if self.setter.is_some() { "read_write" } else { "read" }
    }
}

/// How an array is cut: `parts` bindings of 2^`shift` elements each, the last one shorter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Split {
    /// Bindings.
    pub parts: u32,
    /// log₂ of the elements of a part (0 when the array is whole).
    pub shift: u32,
}

impl Split {
    /// The whole array in one binding.
    pub const WHOLE: Split = Split { parts: 1, shift: 0 };

    /// The parts of `len` elements of `stride` bytes in bindings of at most `max_binding` bytes:
    /// one if they fit, else as many as needed of the largest power of two of elements that fits
    /// (a power of two, so the kernel finds the part by a shift).
    pub fn of(len: u64, stride: u64, max_binding: u64) -> Split {
        if len.saturating_mul(stride) <= max_binding {
            return Split::WHOLE;
        }
        let shift = (max_binding / stride).max(1).ilog2();
        Split { parts: u32::try_from(len.div_ceil(1 << shift)).unwrap_or(u32::MAX), shift }
    }

    /// The elements of each part of an array of `len` elements so cut, in part order (one empty
    /// part for an empty array, which binds one zeroed element).
    pub fn ranges(self, len: u64) -> impl Iterator<Item = std::ops::Range<u64>> {
        let per_part = if self.parts == 1 { len } else { 1 << self.shift };
        (0..u64::from(self.parts)).map(move |p| {
            let first = (p * per_part).min(len);
            first..(first + per_part).min(len)
        })
    }
}

/// The largest m in 0..=n for which `fits(m)` holds, `fits` holding up to some m and not after
/// (bisection): how many particles of a scene's kind fit where all of them do not.
pub(crate) fn most_that_fit(n: u64, fits: impl Fn(u64) -> bool) -> u64 {
    let (mut lo, mut hi) = (0, n);
    while lo < hi {
        let mid = (lo + hi).div_ceil(2);
        if fits(mid) { lo = mid } else { hi = mid - 1 }
    }
    lo
}

/// Kernels compiled for each split of their arrays on first use, and kept: a split is a compile
/// of its own (the ray tracer's megakernel, the splatting kernels, the radix sort).
pub(crate) struct PerSplit<K, V>(std::sync::Mutex<Vec<(K, std::sync::Arc<V>)>>);

impl<K: PartialEq + Copy, V> PerSplit<K, V> {
    /// None compiled yet.
    pub fn new() -> Self {
        Self(std::sync::Mutex::new(Vec::new()))
    }

    /// The kernels of `split`: kept ones, or `compile`'s, kept from now on.
    pub fn get(&self, split: K, compile: impl FnOnce() -> Result<V, GpuError>) -> Result<std::sync::Arc<V>, GpuError> {
        let mut kept = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, k)) = kept.iter().find(|(s, _)| *s == split) {
            return Ok(k.clone());
        }
        let k = std::sync::Arc::new(compile()?);
        kept.push((split, k.clone()));
        Ok(k)
    }
}

/// A kernel's split arrays: each with its cut, part 0 at the array's own binding and the other
/// parts at bindings from `first_extra` on, array by array.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub(crate) struct SplitLayout {
    pub arrays: Vec<(SplitArray, Split)>,
    pub first_extra: u32,
}

impl SplitLayout {
    /// The bindings of `array`'s parts, each with its buffer in `parts` (the array's buffers in
    /// part order), as a bind group of a kernel of this layout takes them; none when the layout
    /// has no such array.
    pub fn bind<'b>(&self, array: &SplitArray, parts: &'b [wgpu::Buffer]) -> Vec<(u32, &'b wgpu::Buffer)> {
        let Some(a) = self.arrays.iter().position(|(x, _)| x == array) else { return Vec::new() };
        self.bindings().into_iter().filter(|b| b.0 == a).map(|(_, p, binding)| (binding, &parts[p as usize])).collect()
    }

    /// Every part: (array index, part, binding).
    pub fn bindings(&self) -> Vec<(usize, u32, u32)> {
        let mut extra = self.first_extra;
        let mut out = Vec::new();
        for (a, (array, split)) in self.arrays.iter().enumerate() {
            out.push((a, 0, array.binding));
            for p in 1..split.parts {
                out.push((a, p, extra));
                extra += 1;
            }
        }
        out
    }

    /// Bindings beyond one per array.
    pub fn extra_bindings(&self) -> u32 {
        self.arrays.iter().map(|(_, s)| s.parts - 1).sum()
    }

    /// Storage entries of the parts after the first (part 0 is the kernel's own entry).
    pub fn extra_entries(&self, visibility: wgpu::ShaderStages) -> Vec<wgpu::BindGroupLayoutEntry> {
        self.bindings()
            .into_iter()
            .filter(|&(_, p, _)| p > 0)
            .map(|(a, _, b)| storage_entry(b, visibility, self.arrays[a].0.setter.is_none()))
            .collect()
    }

    /// The WGSL declarations of every part and each array's accessor (and setter).
    pub fn wgsl(&self) -> String {
        let mut out = String::from("\n// Generated by splat_gpu::split: the scene arrays and their accessors.\n");
        let bindings = self.bindings();
        for (a, (array, split)) in self.arrays.iter().enumerate() {
            let SplitArray { var, accessor, ty, .. } = array;
            for &(_, p, binding) in bindings.iter().filter(|b| b.0 == a) {
                let name = part_name(var, p);
                let access = array.access();
                let _ = writeln!(out, "@group(0) @binding({binding}) var<storage, {access}> {name}: array<{ty}>;");
            }
            let _ = writeln!(out, "fn {accessor}(i: u32) -> {ty} {{");
            if split.parts == 1 {
                let _ = writeln!(out, "    return {var}[i];");
            } else {
                let _ = writeln!(out, "    var v: {ty};");
                write_switch(&mut out, var, *split, "v = {}[j];");
                out.push_str("    return v;\n");
            }
            out.push_str("}\n");
            if let Some(setter) = array.setter {
                let _ = writeln!(out, "fn {setter}(i: u32, v: {ty}) {{");
                if split.parts == 1 {
                    let _ = writeln!(out, "    {var}[i] = v;");
                } else {
                    write_switch(&mut out, var, *split, "{}[j] = v;");
                }
                out.push_str("}\n");
            }
        }
        out
    }
}

/// `switch` on element i's part, running `statement` with `{}` the part's variable and `j`
/// the element's index in it.
fn write_switch(out: &mut String, var: &str, split: Split, statement: &str) {
    let _ = writeln!(out, "    let j = i & {}u;", (1u64 << split.shift) - 1);
    let _ = writeln!(out, "    switch i >> {}u {{", split.shift);
    for p in 1..split.parts {
        let _ = writeln!(out, "        case {p}u: {{ {} }}", statement.replace("{}", &part_name(var, p)));
    }
    let _ = writeln!(out, "        default: {{ {} }}", statement.replace("{}", var));
    out.push_str("    }\n");
}

/// Part p's variable: `var`, `var_1`, `var_2`, …
fn part_name(var: &str, p: u32) -> String {
    if p == 0 { var.to_string() } else { format!("{var}_{p}") }
}

/// Read-write buffers of `len` elements of `stride` bytes (the scene's `what`) in the parts of
/// `split` (one element for an empty array, as a binding needs one); a device that cannot
/// allocate them is refused with [`GpuError::DeviceMemory`].
pub(crate) fn alloc(
    ctx: &GpuContext,
    what: &'static str,
    stride: u64,
    split: Split,
    len: u64,
) -> Result<Vec<wgpu::Buffer>, GpuError> {
    let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let buffers = split
        .ranges(len.max(1))
        .map(|range| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(what),
                size: (range.end - range.start) * stride,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })
        .collect();
    if let Some(e) = pollster::block_on(scope.pop()) {
        return Err(GpuError::DeviceMemory { buffer: what, bytes: len * stride, message: e.to_string() });
    }
    Ok(buffers)
}

/// Elements `range` of a u32 array held in `parts`, cut as `split`.
pub(crate) fn read_u32(
    ctx: &GpuContext,
    parts: &[wgpu::Buffer],
    split: Split,
    range: std::ops::Range<u64>,
) -> Result<Vec<u32>, GpuError> {
    let mut out = Vec::with_capacity((range.end - range.start) as usize);
    for (part, held) in parts.iter().zip(split.ranges(range.end)) {
        let (first, last) = (range.start.max(held.start), range.end.min(held.end));
        if first < last {
            out.extend(ctx.read_u32_at(part, (first - held.start) as usize, (last - first) as usize)?);
        }
    }
    Ok(out)
}

/// Write `data` (u32 elements from element 0) into `parts`, cut as `split`.
pub(crate) fn write_u32(ctx: &GpuContext, parts: &[wgpu::Buffer], split: Split, data: &[u32]) {
    for (part, held) in parts.iter().zip(split.ranges(data.len() as u64)).filter(|(_, held)| !held.is_empty()) {
        ctx.queue.write_buffer(part, 0, bytemuck::cast_slice(&data[held.start as usize..held.end as usize]));
    }
}

/// `data` (elements of `stride` bytes, the scene's `what`) as `split`'s parts, one read-only
/// storage buffer each, in part order; a device that cannot allocate them is refused with
/// [`GpuError::DeviceMemory`].
pub(crate) fn upload(
    ctx: &GpuContext,
    what: &'static str,
    stride: u64,
    split: Split,
    data: &[u8],
) -> Result<Vec<wgpu::Buffer>, GpuError> {
    let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    // A binding cannot be empty: an empty array is one zeroed element.
    let zero = vec![0u8; stride as usize];
    let data = if data.is_empty() { &zero[..] } else { data };
    let part_bytes = if split.parts == 1 { data.len() } else { (stride << split.shift) as usize };
    let buffers = data.chunks(part_bytes).map(|part| ctx.upload(what, part)).collect();
    if let Some(e) = pollster::block_on(scope.pop()) {
        return Err(GpuError::DeviceMemory { buffer: what, bytes: data.len() as u64, message: e.to_string() });
    }
    Ok(buffers)
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: SplitArray = SplitArray::of::<[f32; 4]>("particle", "xs", "x_at", "vec4<f32>", 1);
    const B: SplitArray = SplitArray::of::<u32>("node", "ys", "y_at", "u32", 2).writable("y_set");

    #[test]
    fn parts_are_powers_of_two_within_the_binding() {
        assert_eq!(Split::of(100, 16, 1600), Split::WHOLE);
        // 100 elements of 16 bytes in bindings of 1000 bytes: 62 fit, so parts of 32.
        assert_eq!(Split::of(100, 16, 1000), Split { parts: 4, shift: 5 });
        assert_eq!(Split::of(128, 16, 1024), Split { parts: 2, shift: 6 });
        assert_eq!(Split::of(129, 16, 1024), Split { parts: 3, shift: 6 });
        // An element above the limit still gets one per part (the binding check refuses it).
        assert_eq!(Split::of(3, 64, 16), Split { parts: 3, shift: 0 });
        let ranges = |split: Split, len| split.ranges(len).collect::<Vec<_>>();
        assert_eq!(ranges(Split { parts: 4, shift: 5 }, 100), [0..32, 32..64, 64..96, 96..100]);
        assert_eq!(Split::WHOLE.ranges(7).collect::<Vec<_>>(), vec![std::ops::Range { start: 0, end: 7 }]);
        assert_eq!(Split::WHOLE.ranges(0).collect::<Vec<_>>(), vec![std::ops::Range { start: 0, end: 0 }]);
        assert_eq!(most_that_fit(1000, |m| m <= 617), 617);
        assert_eq!(most_that_fit(1000, |_| false), 0);
    }

    #[test]
    fn the_generated_accessors_validate_and_number_their_bindings_in_order() {
        let layout = SplitLayout { arrays: vec![(A, Split { parts: 3, shift: 5 }), (B, Split::WHOLE)], first_extra: 7 };
        assert_eq!(layout.bindings(), vec![(0, 0, 1), (0, 1, 7), (0, 2, 8), (1, 0, 2)]);
        assert_eq!(layout.extra_bindings(), 2);
        let source = format!(
            "{}\n@compute @workgroup_size(1) fn main() {{ let v = x_at(70u) + vec4<f32>(f32(y_at(3u))); y_set(2u, 5u); }}",
            layout.wgsl()
        );
        let module =
            naga::front::wgsl::parse_str(&source).unwrap_or_else(|e| panic!("{}\n{source}", e.emit_to_string(&source)));
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
            .validate(&module)
            .expect("valid");
        assert!(source.contains("case 2u: { v = xs_2[j]; }"), "{source}");
        assert!(source.contains("fn y_at(i: u32) -> u32 {\n    return ys[i];\n}"), "{source}");
        assert!(source.contains("var<storage, read_write> ys: array<u32>;"), "{source}");
        assert!(source.contains("fn y_set(i: u32, v: u32) {\n    ys[i] = v;\n}"), "{source}");
        let split = SplitLayout { arrays: vec![(B, Split { parts: 2, shift: 4 })], first_extra: 3 };
        assert!(split.wgsl().contains("case 1u: { ys_1[j] = v; }"), "{}", split.wgsl());
        assert!(
            !split.extra_entries(wgpu::ShaderStages::COMPUTE)[0].ty.eq(&storage_entry(
                3,
                wgpu::ShaderStages::COMPUTE,
                true
            )
            .ty)
        );
    }
}
