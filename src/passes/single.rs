//! Single scattering along the view ray, for the models whose profile holds the higher orders
//! only (`Model::HalfspaceSingle`):
//! - the light-entry image, drawn by the `shadow` pass beside its maps: where each light's ray
//!   enters the object, and the slopes of the surface there (glsl/shadow.frag);
//! - `thickness`: the depth of the nearest face turned away from the camera, where each view
//!   ray leaves the object;
//! - `front`: the surface the camera sees, its position and normals, and its depth;
//! - `single` (compute): per sample that `front` covered, the light scattered once inside,
//!   from the visible surface to that exit, with each light's attenuation from the distance it
//!   travels inside (its shadow map's first surface to the point); `composite` adds it. See
//!   `glsl/single.comp`. Shading the mesh's triangles directly, lavapipe pays for whole blocks
//!   of pixels on triangles a few pixels wide; the compute pass keeps every lane busy.
//!
//! The three camera passes take one sample per [`crate::scene::single::downsample`] pixels
//! along each side; the composite brings them to every pixel, following the depth.

use super::data::{ATLAS_VERTEX_ATTRIBUTES, ATLAS_VERTEX_BINDINGS};
use super::PassName;
use super::{draw_mesh, DrawTarget, MeshDraw};
use crate::gpu::{shaders, GraphicsDesc, Pipeline, Sampler};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};
use crate::layout::Item;
use ash::vk;

/// Format of the front surface's images (position, normal, facet).
pub const FRONT_FORMAT: vk::Format = Item::FrontPosition.format();
/// Format of the back-face depth and of the front surface's depth.
pub const DEPTH_FORMAT: vk::Format = Item::BackDepth.format();

/// Intervals along each view ray, of equal attenuation in the least extinguishing channel;
/// where the most extinguishing one's extinction is more than a few times larger, one fewer
/// of equal attenuation in that one (the two share the last end), merged along the ray
/// (`glsl/single.comp`). Over
/// each the light's path inside is taken as linear and the exponential integrated exactly,
/// so what fewer intervals miss is the path's bend (`tests/suite/single.rs` holds the pass to the
/// truth of single scattering on the ketchup sphere).
pub const STEPS: u32 = 8;

/// Free paths of the least extinguishing channel beyond which `single` does not follow the
/// view ray: what lies beyond is attenuated below e^-DEPTH_CAP on the view ray alone, and the
/// chord factor of the higher orders is within as much of 1 there (a specialization constant of
/// `glsl/single.comp`).
pub const DEPTH_CAP: f32 = 12.0;

/// The mesh both passes draw and the frame uniforms.
#[derive(Clone, Copy)]
pub struct MeshInputs {
    /// Frame uniforms.
    pub frame: ResourceId,
    /// Atlas mesh vertices.
    pub vertices: ResourceId,
    /// Atlas mesh indices.
    pub indices: ResourceId,
    /// Index count.
    pub index_count: u32,
}

fn camera_desc<'a>(fragment: &'a [u8], color: &'a [vk::Format]) -> GraphicsDesc<'a> {
    GraphicsDesc {
        vertex: shaders::CAMERA_VERT,
        fragment: Some(fragment),
        vertex_bindings: &ATLAS_VERTEX_BINDINGS,
        // Position and normal.
        vertex_attributes: &ATLAS_VERTEX_ATTRIBUTES[..2],
        color_formats: color,
        depth_format: DEPTH_FORMAT,
        cull: vk::CullModeFlags::NONE,
        depth_bias: None,
        fragment_constants: &[],
        samples: 1,
    }
}

/// Declares `thickness`, writing the back-face depth `back`.
pub fn thickness(graph: &mut RenderGraph, i: MeshInputs, back: ResourceId) {
    camera_pass(
        graph,
        PassName::Thickness,
        shaders::THICKNESS_FRAG,
        i,
        &[],
        back,
    );
}

/// Declares a draw of the mesh seen from the camera, `fragment` writing `colors` (in
/// [`FRONT_FORMAT`]) and the depth into `depth`, kept for later passes.
fn camera_pass(
    graph: &mut RenderGraph,
    name: PassName,
    fragment: &'static [u8],
    m: MeshInputs,
    colors: &[ResourceId],
    depth: ResourceId,
) {
    let colors = colors.to_vec();
    let mut pass = graph
        .pass(name.as_str())
        .access(m.frame, Access::Uniform(Stage::Vertex))
        .mesh(m.vertices, m.indices);
    for &c in &colors {
        pass = pass.access(c, Access::ColorAttachment);
    }
    pass.access(depth, Access::DepthAttachment)
        .setup(move |gpu, res| {
            let set = res.bind().uniform(0, m.frame).finish()?;
            let formats = vec![FRONT_FORMAT; colors.len()];
            let pipeline = Pipeline::graphics::<()>(
                gpu,
                name.as_str(),
                &camera_desc(fragment, &formats),
                set,
            )?;
            let color: Vec<vk::ImageView> = colors.iter().map(|&id| res.image(id).view).collect();
            let depth = res.image(depth).clone();
            let mesh = MeshDraw::of(res, m.vertices, m.indices, m.index_count);
            Ok(Box::new(move |rec| {
                let target = DrawTarget {
                    color: &color,
                    color_access: Access::ColorAttachment,
                    clear: vk::ClearColorValue::default(),
                    resolve: &[],
                    depth: Some((depth.view, vk::AttachmentStoreOp::STORE)),
                    extent: depth.info.extent,
                };
                draw_mesh(rec, &target, &pipeline, mesh, || {});
            }))
        });
}

/// The surface the camera sees, per sample (from `front`).
#[derive(Clone, Copy)]
pub struct FrontImages {
    /// Its depth (kept for the composite's upsample).
    pub depth: ResourceId,
    /// Position, and 1 where a view ray meets the object (0 elsewhere).
    pub position: ResourceId,
    /// Interpolated normal, turned to the camera.
    pub normal: ResourceId,
    /// The triangle's normal on the same side.
    pub facet: ResourceId,
}

/// Declares `front`, writing the surface the camera sees into `f`.
pub fn front(graph: &mut RenderGraph, m: MeshInputs, f: FrontImages) {
    let colors = [f.position, f.normal, f.facet];
    camera_pass(
        graph,
        PassName::Front,
        shaders::FRONT_FRAG,
        m,
        &colors,
        f.depth,
    );
}

/// What `single` reads.
pub struct SingleInputs {
    /// Frame uniforms.
    pub frame: ResourceId,
    /// The light-entry image (drawn by `shadow`).
    pub entry: ResourceId,
    /// Back-face depth from `thickness`.
    pub back: ResourceId,
    /// The surface the camera sees (from `front`).
    pub front: FrontImages,
    /// Whether the medium refracts (eta != 1): the view ray and the lights' paths bend at the
    /// surface and are weighed by Fresnel's transmittance.
    pub refracts: bool,
    /// Whether the light's entry for a point inside comes from the neighbouring texels of the
    /// light-entry image where the one under it fails (`scene::shadow::entry_neighbours`).
    pub entry_neighbours: bool,
}

/// Declares `single`, writing the single-scattered radiance per sample into `out`: a compute
/// pass over the samples `front` drew.
pub fn single(graph: &mut RenderGraph, i: SingleInputs, out: ResourceId) {
    graph
        .pass(PassName::Single.as_str())
        .access(i.frame, Access::Uniform(Stage::Compute))
        .access(i.entry, Access::StorageRead(Stage::Compute))
        .access(i.back, Access::Sampled(Stage::Compute))
        .access(i.front.position, Access::Sampled(Stage::Compute))
        .access(i.front.normal, Access::Sampled(Stage::Compute))
        .access(i.front.facet, Access::Sampled(Stage::Compute))
        .access(out, Access::StorageWrite(Stage::Compute))
        .setup(move |gpu, res| {
            let set = res
                .bind()
                .uniform(0, i.frame)
                .storage_image(1, i.entry)
                .sampled(2, i.back, Sampler::nearest(gpu)?)
                .sampled(3, i.front.position, Sampler::nearest(gpu)?)
                .sampled(4, i.front.normal, Sampler::nearest(gpu)?)
                .sampled(5, i.front.facet, Sampler::nearest(gpu)?)
                .storage_image(6, out)
                .finish()?;
            let pipeline = Pipeline::compute_specialized::<u32>(
                gpu,
                PassName::Single.as_str(),
                shaders::SINGLE_COMP,
                set,
                &[
                    i.refracts as u32,
                    DEPTH_CAP.to_bits(),
                    i.entry_neighbours as u32,
                ],
            )?;
            let extent = res.image(out).info.extent;
            Ok(Box::new(move |rec| {
                super::compute::dispatch_2d(rec, &pipeline, &STEPS, extent, 8)
            }))
        });
}
