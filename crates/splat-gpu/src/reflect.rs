//! Pipeline layouts derived from a module's bindings, as wgpu derives its automatic layouts, but
//! with the count of a binding array, which wgpu's automatic layouts do not take (they declare
//! every binding a single item): the splatting kernels' split arrays in binding arrays
//! (`crate::split::PartBindings::Array`) need them.

use naga::{AddressSpace, ImageClass, StorageAccess, TypeInner};

/// The layout entries an entry point uses: its groups in order, each its bindings.
pub(crate) type Groups = Vec<Vec<wgpu::BindGroupLayoutEntry>>;

/// The bindings each compute entry point of the WGSL `source` uses, by entry point, group by
/// group: each visible to the compute stage, a binding array with its count. A module the
/// kernels could not have written (an unparsable source, a binding of a kind this crate does not
/// bind) is an error naming it.
pub(crate) fn compute_layouts(source: &str) -> Result<Vec<(String, Groups)>, String> {
    let module = naga::front::wgsl::parse_str(source).map_err(|e| e.emit_to_string(source))?;
    let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
        .validate(&module)
        .map_err(|e| format!("{e:?}"))?;
    let mut out = Vec::new();
    for (i, entry_point) in module.entry_points.iter().enumerate() {
        if entry_point.stage != naga::ShaderStage::Compute {
            continue;
        }
        let used = info.get_entry_point(i);
        let mut groups: Groups = Vec::new();
        for (handle, var) in module.global_variables.iter() {
            let Some(binding) = &var.binding else { continue };
            if used[handle].is_empty() {
                continue;
            }
            let (ty, count) = match module.types[var.ty].inner {
                TypeInner::BindingArray { base, size: naga::ArraySize::Constant(n) } => (base, Some(n)),
                _ => (var.ty, None),
            };
            let name = var.name.as_deref().unwrap_or("?");
            let ty = binding_type(var.space, &module.types[ty].inner).ok_or_else(|| {
                format!("{}: binding {} ({name}) is of a kind not derived here", entry_point.name, binding.binding)
            })?;
            let group = binding.group as usize;
            if groups.len() <= group {
                groups.resize_with(group + 1, Vec::new);
            }
            let visibility = wgpu::ShaderStages::COMPUTE;
            groups[group].push(wgpu::BindGroupLayoutEntry { binding: binding.binding, visibility, ty, count });
        }
        out.push((entry_point.name.clone(), groups));
    }
    Ok(out)
}

/// The binding type of a global in `space` of type `inner`: a storage buffer, a sampled or a
/// storage texture; `None` for any other kind.
fn binding_type(space: AddressSpace, inner: &TypeInner) -> Option<wgpu::BindingType> {
    let buffer = |ty| wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None };
    match (space, inner) {
        (AddressSpace::Storage { access }, _) => {
            Some(buffer(wgpu::BufferBindingType::Storage { read_only: !access.contains(StorageAccess::STORE) }))
        }
        (AddressSpace::Handle, TypeInner::Image { dim: naga::ImageDimension::D2, arrayed: false, class }) => {
            match *class {
                ImageClass::Storage { format: naga::StorageFormat::Rgba32Float, access } => {
                    let access = match (access.contains(StorageAccess::LOAD), access.contains(StorageAccess::STORE)) {
                        (true, true) => wgpu::StorageTextureAccess::ReadWrite,
                        (true, false) => wgpu::StorageTextureAccess::ReadOnly,
                        (false, _) => wgpu::StorageTextureAccess::WriteOnly,
                    };
                    let (format, view_dimension) = (wgpu::TextureFormat::Rgba32Float, wgpu::TextureViewDimension::D2);
                    Some(wgpu::BindingType::StorageTexture { access, format, view_dimension })
                }
                ImageClass::Sampled { kind: naga::ScalarKind::Float, multi } => Some(wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: multi,
                }),
                _ => None,
            }
        }
        _ => None,
    }
}

/// The pipeline layout of `groups` (and their bind group layouts, which it holds).
pub(crate) fn pipeline_layout(device: &wgpu::Device, label: &str, groups: &Groups) -> wgpu::PipelineLayout {
    let layouts: Vec<_> = groups
        .iter()
        .map(|entries| {
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries })
        })
        .collect();
    crate::context::pipeline_layout(device, label, &layouts.iter().collect::<Vec<_>>())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each entry point gets the bindings it uses alone, of their kinds, a binding array with its
    /// count and in its group.
    #[test]
    fn layouts_are_the_bindings_each_entry_point_uses() {
        let source = "
            enable wgpu_binding_array;
            struct Part { e: array<u32> }
            @group(0) @binding(0) var<storage, read> a: array<u32>;
            @group(0) @binding(3) var<storage, read_write> b: array<u32>;
            @group(1) @binding(7) var<storage, read> parts: binding_array<Part, 3>;
            @group(0) @binding(5) var out: texture_storage_2d<rgba32float, write>;
            @compute @workgroup_size(1) fn first() { b[0] = a[0]; }
            @compute @workgroup_size(1) fn second(@builtin(global_invocation_id) id: vec3<u32>) {
                b[1] = parts[id.x].e[0];
                textureStore(out, vec2<u32>(0u), vec4<f32>(1.0));
            }";
        let layouts = compute_layouts(source).unwrap();
        let bindings = |groups: &Groups| -> Vec<Vec<(u32, Option<u32>)>> {
            groups.iter().map(|g| g.iter().map(|e| (e.binding, e.count.map(|c| c.get()))).collect()).collect()
        };
        assert_eq!(layouts[0].0, "first");
        assert_eq!(bindings(&layouts[0].1), [vec![(0, None), (3, None)]]);
        assert_eq!(bindings(&layouts[1].1), [vec![(3, None), (5, None)], vec![(7, Some(3))]]);
        let read_only = |e: &wgpu::BindGroupLayoutEntry| match e.ty {
            wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Storage { read_only }, .. } => Some(read_only),
            _ => None,
        };
        assert_eq!(layouts[0].1[0].iter().map(read_only).collect::<Vec<_>>(), [Some(true), Some(false)]);
        assert!(matches!(
            layouts[1].1[0][1].ty,
            wgpu::BindingType::StorageTexture { access: wgpu::StorageTextureAccess::WriteOnly, .. }
        ));
        let sampler = "@group(0) @binding(0) var s: sampler; @compute @workgroup_size(1) fn main() { _ = s; }";
        assert!(compute_layouts(sampler).unwrap_err().contains("binding 0 (s)"));
    }
}
