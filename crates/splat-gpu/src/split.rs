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
//!
//! Where the adapter has arrays of storage buffers in one binding ([`PartBindings::Array`]), the
//! parts after the first are one binding array instead, in bind group [`ARRAY_GROUP`], and the
//! accessor indexes it by the part: no `switch`, and the parts count against the stage's
//! binding-array elements (lavapipe 25: a million) rather than its storage bindings (48), so what
//! bounds a scene is the device's memory.
//!
//! ```wgsl
//! @group(0) @binding(1) var<storage, read> particles: array<Particle>;
//! struct particles_part { e: array<Particle> }
//! @group(1) @binding(18) var<storage, read> particles_parts: binding_array<particles_part, 2>;
//! fn particle_at(i: u32) -> Particle {
//!     let j = i & 1048575u;
//!     let p = (i >> 20u) - 1u;
//!     if p >= 2u { return particles[j]; } else {
//!         return particles_parts[p].e[j];
//!     }
//! }
//! ```

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

    /// `len` elements of this array uploaded as `split`'s parts, each part's bytes made by
    /// `part` ([`upload_parts`]).
    pub fn upload_parts<P: AsRef<[u8]>>(
        &self,
        ctx: &GpuContext,
        split: Split,
        len: u64,
        part: impl Fn(std::ops::Range<u64>) -> P,
    ) -> Result<Vec<wgpu::Buffer>, GpuError> {
        upload_parts(ctx, self.what, self.stride, split, len, part)
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

/// The most elements an array the kernels index holds: their element indices are u32.
pub(crate) const MAX_ELEMENTS: u64 = u32::MAX as u64;

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

/// The bind group of binding arrays ([`PartBindings::Array`]), apart from group 0: Vulkan's
/// update-after-bind descriptor sets, which hold them, cannot hold group 0's dynamically offset
/// parameters (wgpu refuses "both a binding array and a dynamically offset buffer" in a group).
pub(crate) const ARRAY_GROUP: u32 = 1;

/// How a kernel binds the parts after the first of a split array.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PartBindings {
    /// A binding each, the accessor choosing by a `switch`: on any adapter, each part counts
    /// against the storage bindings a stage.
    Each,
    /// One binding array (`binding_array<…, parts − 1>`) indexed by the part, where the adapter
    /// has arrays of storage buffers in one binding with non-uniform indexing: the parts count
    /// against the binding-array elements a stage instead.
    Array,
}

/// One binding of a [`SplitLayout`]: parts `parts` of its array `array`, alone or as a binding
/// array.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct PartsBinding {
    /// The array's index in the layout.
    pub array: usize,
    /// Its bind group: 0, or [`ARRAY_GROUP`] for a binding array.
    pub group: u32,
    /// The binding.
    pub binding: u32,
    /// The parts it holds.
    pub parts: std::ops::Range<u32>,
    /// Whether it is a binding array (of `parts.len()` buffers, which may be one).
    pub arrayed: bool,
}

/// The buffers of one binding of a split array, as a bind group takes them ([`Bound::entry`]).
#[derive(Clone, Debug)]
pub(crate) struct Bound<'b> {
    group: u32,
    binding: u32,
    buffers: Vec<wgpu::BufferBinding<'b>>,
    arrayed: bool,
}

impl<'b> Bound<'b> {
    /// Its bind group entry.
    pub fn entry(&self) -> wgpu::BindGroupEntry<'_> {
        let resource = if self.arrayed {
            wgpu::BindingResource::BufferArray(&self.buffers)
        } else {
            wgpu::BindingResource::Buffer(self.buffers[0].clone())
        };
        wgpu::BindGroupEntry { binding: self.binding, resource }
    }
}

/// A kernel's bind groups: group 0, and [`ARRAY_GROUP`] where its split arrays have binding
/// arrays.
pub(crate) struct BindGroups {
    zero: wgpu::BindGroup,
    arrays: Option<wgpu::BindGroup>,
}

impl BindGroups {
    /// Group 0 of `entries` and the parts of group 0 among `parts` on `layout`, and the others
    /// (binding arrays) on `arrays_layout`, which a kernel with binding arrays has.
    pub fn new(
        device: &wgpu::Device,
        label: Option<&str>,
        layout: &wgpu::BindGroupLayout,
        arrays_layout: Option<&wgpu::BindGroupLayout>,
        entries: &[wgpu::BindGroupEntry],
        parts: &[Bound],
    ) -> Self {
        let of = |group| parts.iter().filter(move |b| b.group == group).map(Bound::entry);
        let zero: Vec<_> = entries.iter().cloned().chain(of(0)).collect();
        let zero = device.create_bind_group(&wgpu::BindGroupDescriptor { label, layout, entries: &zero });
        let arrays: Vec<_> = of(ARRAY_GROUP).collect();
        let arrays = (!arrays.is_empty()).then(|| {
            let layout = arrays_layout.expect("a kernel with binding arrays has their group's layout");
            device.create_bind_group(&wgpu::BindGroupDescriptor { label, layout, entries: &arrays })
        });
        Self { zero, arrays }
    }

    /// The groups of `entries` and the split arrays' `parts` on the layouts `pipeline` holds
    /// (derived from its module: wgpu's automatic ones, or `crate::reflect`'s).
    pub fn auto(
        device: &wgpu::Device,
        label: Option<&str>,
        pipeline: &wgpu::ComputePipeline,
        entries: &[wgpu::BindGroupEntry],
        parts: &[Bound],
    ) -> Self {
        let arrays = parts.iter().any(|b| b.group == ARRAY_GROUP).then(|| pipeline.get_bind_group_layout(ARRAY_GROUP));
        Self::new(device, label, &pipeline.get_bind_group_layout(0), arrays.as_ref(), entries, parts)
    }

    /// Set them in a compute pass, group 0 at dynamic `offsets`.
    pub fn set_compute(&self, pass: &mut wgpu::ComputePass<'_>, offsets: &[u32]) {
        pass.set_bind_group(0, &self.zero, offsets);
        if let Some(arrays) = &self.arrays {
            pass.set_bind_group(ARRAY_GROUP, arrays, &[]);
        }
    }

    /// Set them in a render pass, group 0 at dynamic `offsets`.
    pub fn set_render(&self, pass: &mut wgpu::RenderPass<'_>, offsets: &[u32]) {
        pass.set_bind_group(0, &self.zero, offsets);
        if let Some(arrays) = &self.arrays {
            pass.set_bind_group(ARRAY_GROUP, arrays, &[]);
        }
    }
}

/// The bind group layouts of a kernel's own `entries` and its split arrays' binding arrays
/// (`arrays`, [`SplitLayout::extra_entries`] of [`ARRAY_GROUP`]; none, no such group), and the
/// pipeline layout of both.
pub(crate) fn layouts(
    device: &wgpu::Device,
    label: &str,
    entries: &[wgpu::BindGroupLayoutEntry],
    arrays: &[wgpu::BindGroupLayoutEntry],
) -> (wgpu::BindGroupLayout, Option<wgpu::BindGroupLayout>, wgpu::PipelineLayout) {
    let layout =
        |entries| device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries });
    let (zero, arrays) = (layout(entries), (!arrays.is_empty()).then(|| layout(arrays)));
    let groups: Vec<_> = std::iter::once(&zero).chain(arrays.as_ref()).collect();
    let pipeline = crate::context::pipeline_layout(device, label, &groups);
    (zero, arrays, pipeline)
}

/// A kernel's split arrays: each with its cut, part 0 at the array's own binding and the other
/// parts at bindings from `first_extra` on, array by array (one binding array an array with
/// [`PartBindings::Array`]).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub(crate) struct SplitLayout {
    pub arrays: Vec<(SplitArray, Split)>,
    pub first_extra: u32,
    pub parts: PartBindings,
}

impl SplitLayout {
    /// The bindings of `array`'s parts, each with its buffers from `parts` (the array's buffers
    /// in part order), as a bind group of a kernel of this layout takes them; none when the
    /// layout has no such array.
    pub fn bind<'b>(&self, array: &SplitArray, parts: &'b [wgpu::Buffer]) -> Vec<Bound<'b>> {
        let Some(a) = self.arrays.iter().position(|(x, _)| x == array) else { return Vec::new() };
        self.bindings()
            .into_iter()
            .filter(|b| b.array == a)
            .map(|b| Bound {
                group: b.group,
                binding: b.binding,
                buffers: parts[b.parts.start as usize..b.parts.end as usize]
                    .iter()
                    .map(wgpu::Buffer::as_entire_buffer_binding)
                    .collect(),
                arrayed: b.arrayed,
            })
            .collect()
    }

    /// Every binding, array by array: part 0 at the array's own binding, then its other parts.
    pub fn bindings(&self) -> Vec<PartsBinding> {
        let mut extra = self.first_extra;
        let mut out = Vec::new();
        for (a, (array, split)) in self.arrays.iter().enumerate() {
            let one = |binding, p| PartsBinding { array: a, group: 0, binding, parts: p..p + 1, arrayed: false };
            out.push(one(array.binding, 0));
            let rest = 1..split.parts;
            match self.parts {
                PartBindings::Each => {
                    for p in rest {
                        out.push(one(extra, p));
                        extra += 1;
                    }
                }
                PartBindings::Array if !rest.is_empty() => {
                    let (group, binding) = (ARRAY_GROUP, extra);
                    out.push(PartsBinding { array: a, group, binding, parts: rest, arrayed: true });
                    extra += 1;
                }
                PartBindings::Array => {}
            }
        }
        out
    }

    /// Bindings beyond one per array.
    pub fn extra_bindings(&self) -> u32 {
        self.bindings().len() as u32 - self.arrays.len() as u32
    }

    /// Buffers in binding arrays.
    pub fn array_elements(&self) -> u32 {
        self.bindings().iter().filter(|b| b.arrayed).map(|b| b.parts.len() as u32).sum()
    }

    /// Where a kernel with `own` storage bindings of its own and this layout's needs more of a
    /// shader stage than `ctx` gives: (needed, available), of storage bindings or, past them,
    /// of binding-array elements; `None` when it fits.
    pub fn over(&self, ctx: &GpuContext, own: u32) -> Option<(u32, u32)> {
        let bindings = own + self.extra_bindings();
        if bindings > ctx.storage_buffers {
            return Some((bindings, ctx.storage_buffers));
        }
        let elements = self.array_elements();
        (elements > ctx.binding_array_elements).then_some((elements, ctx.binding_array_elements))
    }

    /// Storage entries of bind group `group` for the parts after the first (part 0 is the
    /// kernel's own entry), each visible to `visibility` of its array's index in the layout.
    pub fn extra_entries(
        &self,
        group: u32,
        visibility: impl Fn(usize) -> wgpu::ShaderStages,
    ) -> Vec<wgpu::BindGroupLayoutEntry> {
        self.bindings()
            .into_iter()
            .filter(|b| b.parts.start > 0 && b.group == group)
            .map(|b| wgpu::BindGroupLayoutEntry {
                count: if b.arrayed { std::num::NonZeroU32::new(b.parts.len() as u32) } else { None },
                ..storage_entry(b.binding, visibility(b.array), self.arrays[b.array].0.setter.is_none())
            })
            .collect()
    }

    /// What must open a module with this layout's declarations, before any other item: the
    /// enable directive of binding arrays where it has any.
    pub fn directives(&self) -> &'static str {
        if self.array_elements() > 0 { "enable wgpu_binding_array;\n" } else { "" }
    }

    /// The WGSL declarations of every part and each array's accessor (and setter), to follow
    /// [`SplitLayout::directives`] and the kernel's source.
    pub fn wgsl(&self) -> String {
        let mut out = String::from("\n// Generated by splat_gpu::split: the scene arrays and their accessors.\n");
        let bindings = self.bindings();
        for (a, (array, split)) in self.arrays.iter().enumerate() {
            let SplitArray { var, accessor, ty, .. } = array;
            let access = array.access();
            for b in bindings.iter().filter(|b| b.array == a) {
                let (group, binding) = (b.group, b.binding);
                if b.arrayed {
                    let n = b.parts.len();
                    let _ = writeln!(out, "struct {var}_part {{ e: array<{ty}> }}");
                    let _ = writeln!(
                        out,
                        "@group({group}) @binding({binding}) var<storage, {access}> {var}_parts: binding_array<{var}_part, {n}>;"
                    );
                } else {
                    let name = part_name(var, b.parts.start);
                    let _ = writeln!(
                        out,
                        "@group({group}) @binding({binding}) var<storage, {access}> {name}: array<{ty}>;"
                    );
                }
            }
            let _ = writeln!(out, "fn {accessor}(i: u32) -> {ty} {{");
            match (split.parts, self.parts) {
                (1, _) => {
                    let _ = writeln!(out, "    return {var}[i];");
                }
                (_, PartBindings::Each) => {
                    let _ = writeln!(out, "    var v: {ty};");
                    write_switch(&mut out, var, *split, "v = {}[j];");
                    out.push_str("    return v;\n");
                }
                (_, PartBindings::Array) => {
                    write_part_branch(&mut out, var, *split, "return {};");
                }
            }
            out.push_str("}\n");
            if let Some(setter) = array.setter {
                let _ = writeln!(out, "fn {setter}(i: u32, v: {ty}) {{");
                match (split.parts, self.parts) {
                    (1, _) => {
                        let _ = writeln!(out, "    {var}[i] = v;");
                    }
                    (_, PartBindings::Each) => write_switch(&mut out, var, *split, "{}[j] = v;"),
                    (_, PartBindings::Array) => write_part_branch(&mut out, var, *split, "{} = v;"),
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

/// Element i in part 0 or in the binding array of the others: `statement` with `{}` the
/// element, run in the branch of its part. An index past the array takes part 0, as the
/// `switch`'s default does: a binding array has no robust access past its count.
fn write_part_branch(out: &mut String, var: &str, split: Split, statement: &str) {
    let _ = writeln!(out, "    let j = i & {}u;", (1u64 << split.shift) - 1);
    // The part's place in the binding array: part 0 wraps to the largest u32.
    let _ = writeln!(out, "    let p = (i >> {}u) - 1u;", split.shift);
    let first = statement.replace("{}", &format!("{var}[j]"));
    let _ = writeln!(out, "    if p >= {}u {{ {first} }} else {{", split.parts - 1);
    let rest = format!("{var}_parts[p].e[j]");
    let _ = writeln!(out, "        {}", statement.replace("{}", &rest));
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

/// A part's elements as the bytes [`upload_parts`] takes, without a copy.
pub(crate) struct PartBytes<T>(pub Vec<T>);

impl<T: bytemuck::Pod> AsRef<[u8]> for PartBytes<T> {
    fn as_ref(&self) -> &[u8] {
        bytemuck::cast_slice(&self.0)
    }
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
    let bytes = |range: std::ops::Range<u64>| &data[(range.start * stride) as usize..(range.end * stride) as usize];
    upload_parts(ctx, what, stride, split, data.len() as u64 / stride, bytes)
}

/// `len` elements of `stride` bytes (the scene's `what`) as `split`'s parts, one read-only
/// storage buffer each, in part order, part p's bytes made by `part` of its elements' range as
/// it is uploaded: a scene's arrays made part by part hold one part on the host at a time, not
/// the whole array beside the device's copy. A device that cannot allocate them is refused with
/// [`GpuError::DeviceMemory`].
pub(crate) fn upload_parts<P: AsRef<[u8]>>(
    ctx: &GpuContext,
    what: &'static str,
    stride: u64,
    split: Split,
    len: u64,
    part: impl Fn(std::ops::Range<u64>) -> P,
) -> Result<Vec<wgpu::Buffer>, GpuError> {
    let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    // A binding cannot be empty: an empty array is one zeroed element.
    let zero = vec![0u8; stride as usize];
    let buffers = if len == 0 {
        vec![ctx.upload(what, &zero)]
    } else {
        split.ranges(len).map(|range| ctx.upload(what, part(range).as_ref())).collect()
    };
    if let Some(e) = pollster::block_on(scope.pop()) {
        return Err(GpuError::DeviceMemory { buffer: what, bytes: len * stride, message: e.to_string() });
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

    /// Parse and validate `source`, with binding arrays where `arrays`.
    fn validate(source: &str, arrays: bool) {
        let module =
            naga::front::wgsl::parse_str(source).unwrap_or_else(|e| panic!("{}\n{source}", e.emit_to_string(source)));
        let capabilities = if arrays {
            naga::valid::Capabilities::STORAGE_BUFFER_BINDING_ARRAY
                | naga::valid::Capabilities::STORAGE_BUFFER_BINDING_ARRAY_NON_UNIFORM_INDEXING
        } else {
            naga::valid::Capabilities::empty()
        };
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), capabilities)
            .validate(&module)
            .unwrap_or_else(|e| panic!("{e:?}\n{source}"));
    }

    #[test]
    fn the_generated_accessors_validate_and_number_their_bindings_in_order() {
        let arrays = vec![(A, Split { parts: 3, shift: 5 }), (B, Split::WHOLE)];
        let layout = SplitLayout { arrays: arrays.clone(), first_extra: 7, parts: PartBindings::Each };
        let at = |b: &PartsBinding| (b.array, b.group, b.binding, b.parts.clone(), b.arrayed);
        let bindings: Vec<_> = layout.bindings().iter().map(at).collect();
        let one = |a, binding, p: u32| (a, 0, binding, p..p + 1, false);
        assert_eq!(bindings, vec![one(0, 1, 0), one(0, 7, 1), one(0, 8, 2), one(1, 2, 0)]);
        assert_eq!((layout.extra_bindings(), layout.array_elements()), (2, 0));
        let main =
            "@compute @workgroup_size(1) fn main() { let v = x_at(70u) + vec4<f32>(f32(y_at(3u))); y_set(2u, 5u); }";
        let source = format!("{}{}\n{main}", layout.directives(), layout.wgsl());
        validate(&source, false);
        assert!(source.contains("case 2u: { v = xs_2[j]; }"), "{source}");
        assert!(source.contains("fn y_at(i: u32) -> u32 {\n    return ys[i];\n}"), "{source}");
        assert!(source.contains("var<storage, read_write> ys: array<u32>;"), "{source}");
        assert!(source.contains("fn y_set(i: u32, v: u32) {\n    ys[i] = v;\n}"), "{source}");
        let split =
            SplitLayout { arrays: vec![(B, Split { parts: 2, shift: 4 })], first_extra: 3, parts: PartBindings::Each };
        assert!(split.wgsl().contains("case 1u: { ys_1[j] = v; }"), "{}", split.wgsl());
        assert!(
            !split.extra_entries(0, |_| wgpu::ShaderStages::COMPUTE)[0].ty.eq(&storage_entry(
                3,
                wgpu::ShaderStages::COMPUTE,
                true
            )
            .ty)
        );
        // As binding arrays: one binding for the parts after the first, of their count.
        let layout = SplitLayout { arrays, first_extra: 7, parts: PartBindings::Array };
        let bindings: Vec<_> = layout.bindings().iter().map(at).collect();
        assert_eq!(bindings, vec![one(0, 1, 0), (0, ARRAY_GROUP, 7, 1..3, true), one(1, 2, 0)]);
        assert_eq!((layout.extra_bindings(), layout.array_elements()), (1, 2));
        assert!(layout.extra_entries(0, |_| wgpu::ShaderStages::COMPUTE).is_empty());
        let stages = [wgpu::ShaderStages::VERTEX, wgpu::ShaderStages::FRAGMENT];
        let arrays = layout.extra_entries(ARRAY_GROUP, |a| stages[a]);
        let counts: Vec<_> = arrays.iter().map(|e| (e.visibility, e.binding, e.count)).collect();
        assert_eq!(counts, [(wgpu::ShaderStages::VERTEX, 7, std::num::NonZeroU32::new(2))]);
        let source = format!("{}{}\n{main}", layout.directives(), layout.wgsl());
        validate(&source, true);
        assert!(
            source.contains("@group(1) @binding(7) var<storage, read> xs_parts: binding_array<xs_part, 2>;"),
            "{source}"
        );
        assert!(source.contains("if p >= 2u { return xs[j]; } else {\n        return xs_parts[p].e[j];"), "{source}");
        let split =
            SplitLayout { arrays: vec![(B, Split { parts: 2, shift: 4 })], first_extra: 3, parts: PartBindings::Array };
        let main = "@compute @workgroup_size(1) fn main() { y_set(20u, y_at(3u)); }";
        let source = format!("{}{}\n{main}", split.directives(), split.wgsl());
        validate(&source, true);
        assert!(source.contains("let j = i & 15u;") && source.contains("ys_parts[p].e[j] = v;"), "{source}");
    }
}
