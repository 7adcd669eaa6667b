//! Binding a graph resource to a shader slot, checked against the pass's declared accesses.
//!
//! A pass declares what it touches (`.access(id, Access::TexelRead(..))`) and, in its setup,
//! binds what its shader reads by naming the same resource and the slot:
//!
//! ```text
//! let set = res.bind().texel(0, texels, vk::Format::R32_UINT).storage_image(2, map).finish()?;
//! ```
//!
//! Binding a resource the pass did not declare, or declared with an access that does not fit
//! the descriptor (a storage image declared `Sampled`), is a [`GraphError::Binding`] naming the
//! pass, the resource and the slot. Texel views and samplers made here are owned by the
//! [`BindingSet`], hence by the pipeline made from it.

use super::{Access, GraphError, PassDecl, Physical, ResourceId, Resources};
use crate::gpu::{Binding, BindingSet, Buffer, Gpu, Image, Sampler, TexelView};
use ash::vk;
use std::sync::Arc;

/// A pass's view of the graph's resources during setup: lookups and checked binding.
pub struct PassResources<'a> {
    pub(super) gpu: &'a Arc<Gpu>,
    pub(super) decl: &'a PassDecl,
    pub(super) resources: &'a Resources,
}

impl<'a> PassResources<'a> {
    /// The image behind `id` (for its extent or format; bind it with [`PassResources::bind`]).
    pub fn image(&self, id: ResourceId) -> &'a Arc<Image> {
        self.resources.image(id)
    }

    /// The buffer behind `id`.
    pub fn buffer(&self, id: ResourceId) -> &'a Arc<Buffer> {
        self.resources.buffer(id)
    }

    /// The image or buffer behind `id`.
    pub fn physical(&self, id: ResourceId) -> &'a Physical {
        self.resources.physical(id)
    }

    /// Starts the pass's descriptor set.
    pub fn bind(&self) -> Bindings<'a> {
        Bindings {
            gpu: self.gpu,
            decl: self.decl,
            resources: self.resources,
            set: BindingSet::new(),
            error: None,
        }
    }
}

/// The descriptor kinds a pass can bind, with the accesses each needs declared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BindKind {
    /// A uniform buffer: `Access::Uniform`.
    Uniform,
    /// A storage buffer: `Access::Storage*`.
    StorageBuffer,
    /// A storage image: `Access::Storage*`.
    StorageImage,
    /// A sampled image: `Access::Sampled`.
    Sampled,
    /// A uniform texel buffer: `Access::TexelRead`.
    Texel,
    /// A storage texel buffer: `Access::TexelWrite`.
    StorageTexel,
}

impl BindKind {
    /// Whether a resource declared with `access` may be bound as this kind.
    pub fn admits(self, access: Access) -> bool {
        use Access as A;
        match self {
            BindKind::Uniform => matches!(access, A::Uniform(_)),
            BindKind::StorageBuffer | BindKind::StorageImage => matches!(
                access,
                A::StorageRead(_) | A::StorageWrite(_) | A::StorageReadWrite(_)
            ),
            BindKind::Sampled => matches!(access, A::Sampled(_)),
            BindKind::Texel => matches!(access, A::TexelRead(_)),
            BindKind::StorageTexel => matches!(access, A::TexelWrite(_)),
        }
    }

    fn wants_image(self) -> bool {
        matches!(self, BindKind::StorageImage | BindKind::Sampled)
    }
}

/// Checks that `pass` declared `resource` with an access that admits binding it as `kind` at
/// `slot`; `names` are the graph's resource names. Pure: the setup's check, testable alone.
pub fn check_binding(
    pass: &PassDecl,
    names: &[String],
    resource: ResourceId,
    slot: u32,
    kind: BindKind,
) -> Result<(), GraphError> {
    let declared = pass
        .accesses
        .iter()
        .find(|(r, _)| *r == resource)
        .map(|(_, a)| *a);
    match declared {
        Some(a) if kind.admits(a) => Ok(()),
        declared => Err(GraphError::Binding {
            pass: pass.name.clone(),
            resource: names
                .get(resource.0)
                .cloned()
                .unwrap_or_else(|| format!("#{}", resource.0)),
            slot,
            kind,
            declared,
        }),
    }
}

/// A descriptor set being bound; finish with [`Bindings::finish`].
pub struct Bindings<'a> {
    gpu: &'a Arc<Gpu>,
    decl: &'a PassDecl,
    resources: &'a Resources,
    set: BindingSet,
    error: Option<anyhow::Error>,
}

impl Bindings<'_> {
    /// Checks the access and kind; on success hands the physical resource to `bind`.
    fn with(
        mut self,
        slot: u32,
        id: ResourceId,
        kind: BindKind,
        bind: impl FnOnce(&mut BindingSet, &Arc<Gpu>, &Physical) -> anyhow::Result<()>,
    ) -> Self {
        if self.error.is_some() {
            return self;
        }
        let checked = check_binding(self.decl, &self.resources.names, id, slot, kind);
        let physical = self.resources.physical(id);
        let result = checked.map_err(anyhow::Error::from).and_then(|()| {
            match (kind.wants_image(), physical) {
                (true, Physical::Buffer(_)) | (false, Physical::Image(_)) => {
                    anyhow::bail!(
                        "pass '{}' binds '{}' at slot {slot} as {kind:?}, which it is not",
                        self.decl.name,
                        self.resources.names[id.0]
                    )
                }
                _ => bind(&mut self.set, self.gpu, physical),
            }
        });
        if let Err(e) = result {
            self.error = Some(e);
        }
        self
    }

    /// A uniform buffer (whole range) at `slot`.
    pub fn uniform(self, slot: u32, id: ResourceId) -> Self {
        self.with(slot, id, BindKind::Uniform, |set, _, p| {
            set.add(slot, Binding::Uniform(buffer(p).raw));
            Ok(())
        })
    }

    /// A storage buffer (whole range) at `slot`.
    pub fn storage_buffer(self, slot: u32, id: ResourceId) -> Self {
        self.with(slot, id, BindKind::StorageBuffer, |set, _, p| {
            set.add(slot, Binding::Storage(buffer(p).raw));
            Ok(())
        })
    }

    /// A storage image (full view, `GENERAL`) at `slot`.
    pub fn storage_image(self, slot: u32, id: ResourceId) -> Self {
        self.with(slot, id, BindKind::StorageImage, |set, _, p| {
            set.add(slot, Binding::StorageImage(image(p).view));
            Ok(())
        })
    }

    /// A sampled image (full view) with `sampler` at `slot`; the set keeps the sampler.
    pub fn sampled(self, slot: u32, id: ResourceId, sampler: Sampler) -> Self {
        self.with(slot, id, BindKind::Sampled, |set, _, p| {
            set.add(slot, Binding::Sampled(image(p).view, sampler.raw));
            set.keep(sampler);
            Ok(())
        })
    }

    /// The whole buffer as a uniform texel buffer of `format` at `slot`.
    pub fn texel(self, slot: u32, id: ResourceId, format: vk::Format) -> Self {
        self.texel_view(slot, id, format, BindKind::Texel)
    }

    /// The whole buffer as a storage texel buffer of `format` at `slot`.
    pub fn storage_texel(self, slot: u32, id: ResourceId, format: vk::Format) -> Self {
        self.texel_view(slot, id, format, BindKind::StorageTexel)
    }

    /// A texel view of the whole buffer, owned by the set.
    fn texel_view(self, slot: u32, id: ResourceId, format: vk::Format, kind: BindKind) -> Self {
        self.with(slot, id, kind, |set, gpu, p| {
            let view = TexelView::of_format(gpu, buffer(p), format)?;
            set.add(
                slot,
                match kind {
                    BindKind::StorageTexel => Binding::StorageTexelBuffer(view.raw),
                    _ => Binding::TexelBuffer(view.raw),
                },
            );
            set.keep(view);
            Ok(())
        })
    }

    /// The set, or the first binding error (naming pass, resource and slot).
    pub fn finish(self) -> anyhow::Result<BindingSet> {
        match self.error {
            Some(e) => Err(e),
            None => Ok(self.set),
        }
    }
}

fn buffer(p: &Physical) -> &Arc<Buffer> {
    match p {
        Physical::Buffer(b) => b,
        Physical::Image(_) => unreachable!("kind checked against the resource"),
    }
}

fn image(p: &Physical) -> &Arc<Image> {
    match p {
        Physical::Image(i) => i,
        Physical::Buffer(_) => unreachable!("kind checked against the resource"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::Stage;

    fn pass() -> PassDecl {
        PassDecl {
            name: "local".into(),
            accesses: vec![
                (ResourceId(0), Access::TexelRead(Stage::Compute)),
                (ResourceId(1), Access::Sampled(Stage::Compute)),
            ],
        }
    }

    fn names() -> Vec<String> {
        ["kernels", "charts", "radiance"].map(String::from).to_vec()
    }

    #[test]
    fn a_declared_resource_binds_with_a_fitting_kind() {
        assert!(check_binding(&pass(), &names(), ResourceId(0), 1, BindKind::Texel).is_ok());
        assert!(check_binding(&pass(), &names(), ResourceId(1), 2, BindKind::Sampled).is_ok());
    }

    #[test]
    fn an_undeclared_resource_is_named_with_pass_and_slot() {
        let e = check_binding(&pass(), &names(), ResourceId(2), 3, BindKind::StorageImage)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("'local'") && e.contains("'radiance'") && e.contains("slot 3"),
            "{e}"
        );
        assert!(e.contains("does not declare"), "{e}");
    }

    #[test]
    fn a_declared_access_of_another_kind_is_refused() {
        let e = check_binding(&pass(), &names(), ResourceId(1), 0, BindKind::StorageImage)
            .unwrap_err()
            .to_string();
        assert!(e.contains("'charts'") && e.contains("Sampled"), "{e}");
    }
}
