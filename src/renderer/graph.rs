//! The steps that add the method's passes to the frame graph, in the order of the parent
//! module's diagram, over the resources the renderer imports and the transient ones it declares.

use super::{host_buffer, CaptureBuffers, HostBuffers, WindowOutput};
use crate::gpu::{Buffer, Gpu, Image};
use crate::graph::{Access, ImageDesc, RenderGraph, ResourceId, Stage};
use crate::layout::Item;
use crate::passes::{self, compute, data::SubsurfaceData, PassName};
use crate::scene::Scene;
use anyhow::Result;
use ash::vk;
use std::sync::Arc;

/// The graph's handles to the resources made outside it: the uploaded data, the renderer's
/// host buffers and the local response image.
#[derive(Clone, Copy)]
struct Imported {
    frame: ResourceId,
    environment: ResourceId,
    vertices: ResourceId,
    indices: ResourceId,
    texels: ResourceId,
    kernels: ResourceId,
    seam_rows: ResourceId,
    seam_entries: ResourceId,
    gather_rows: ResourceId,
    gather_entries: ResourceId,
    global_rows: ResourceId,
    global_entries: ResourceId,
    transfer: ResourceId,
    charts: ResourceId,
    texture: ResourceId,
    texture_entry: ResourceId,
    local: ResourceId,
    hdr_rb: ResourceId,
    display_rb: ResourceId,
}

impl Imported {
    /// Imports the uploaded data, `host`'s buffers and `local_image` into `g`.
    fn new(
        g: &mut RenderGraph,
        host: &HostBuffers,
        data: &SubsurfaceData,
        local_image: Arc<Image>,
    ) -> Imported {
        let frame = g.import_buffer(host.uniforms.clone(), None);
        let environment = g.import_buffer(host.environment_map.clone(), None);
        let vertices = g.import_buffer(data.vertices.clone(), None);
        let indices = g.import_buffer(data.indices.clone(), None);
        let texels = g.import_buffer(data.texels.clone(), None);
        let kernels = g.import_buffer(data.kernels.clone(), None);
        let seam_rows = g.import_buffer(data.seam_rows.clone(), None);
        let seam_entries = g.import_buffer(data.seam_entries.clone(), None);
        let gather_rows = g.import_buffer(data.gather_rows.clone(), None);
        let gather_entries = g.import_buffer(data.gather_entries.clone(), None);
        let global_rows = g.import_buffer(data.global_rows.clone(), None);
        let global_entries = g.import_buffer(data.global_entries.clone(), None);
        let transfer = g.import_buffer(data.transfer.clone(), None);
        let charts = g.import_image(data.charts.clone(), Access::Sampled(Stage::Compute));
        let texture = g.import_image(data.texture.clone(), Access::Sampled(Stage::Fragment));
        let texture_entry = g.import_buffer(data.texture_entry.clone(), None);
        let local = g.import_image(local_image, Access::StorageRead(Stage::Fragment));
        let hdr_rb = g.import_buffer(host.hdr_readback.clone(), Some(Access::HostRead));
        let display_rb = g.import_buffer(host.display_readback.clone(), Some(Access::HostRead));
        Imported {
            frame,
            environment,
            vertices,
            indices,
            texels,
            kernels,
            seam_rows,
            seam_entries,
            gather_rows,
            gather_entries,
            global_rows,
            global_entries,
            transfer,
            charts,
            texture,
            texture_entry,
            local,
            hdr_rb,
            display_rb,
        }
    }
}

/// The graph's transient resources that several passes share, with the shadow maps' size.
#[derive(Clone, Copy)]
struct Transients {
    /// Shadow map layers over all lights.
    layers: u32,
    /// Edge of the shadow maps, texels.
    shadow_size: u32,
    shadow_maps: ResourceId,
    map: ResourceId,
    node_irradiance: ResourceId,
    node_radiosity: ResourceId,
    hdr: ResourceId,
    depth: ResourceId,
    display: ResourceId,
    /// The radiance and display samples averaged into `hdr` and `display`, where the scene
    /// multisamples its camera view.
    samples: Option<(ResourceId, ResourceId)>,
}

impl Transients {
    /// Declares the shadow maps, the illumination map, the node buffers and the output images.
    fn new(g: &mut RenderGraph, scene: &Scene, data: &SubsurfaceData) -> Transients {
        let (w, h) = (scene.width, scene.height);
        let (aw, ah) = data.atlas_size;
        let layers: u32 = scene
            .lights
            .iter()
            .map(crate::scene::shadow::layers_of)
            .sum();
        let (s, _) = crate::scene::shadow::shadow_map_size(scene, data.texel_mm);
        let shadow_maps = g.image(
            Item::ShadowMaps.name(),
            ImageDesc::layered(passes::shadow::FORMAT, s, s, layers),
        );
        let map = g.image(
            Item::IlluminationMap.name(),
            ImageDesc::new(passes::illum::FORMAT, aw, ah),
        );
        let node_buffer = |g: &mut RenderGraph, item: Item| {
            g.buffer(item.name(), data.node_count.max(1) as u64 * item.bytes())
        };
        let node_irradiance = node_buffer(g, Item::NodeIrradiance);
        let node_radiosity = node_buffer(g, Item::NodeRadiosity);
        let hdr = g.image(
            Item::Radiance.name(),
            ImageDesc::new(passes::composite::HDR_FORMAT, w, h),
        );
        let n = scene.samples;
        let depth = g.image(
            Item::Depth.name(),
            ImageDesc::multisampled(passes::composite::DEPTH_FORMAT, w, h, n),
        );
        let display = g.image(
            Item::Display.name(),
            ImageDesc::new(passes::composite::DISPLAY_FORMAT, w, h),
        );
        let samples = (n > 1).then(|| {
            let image = |g: &mut RenderGraph, item: Item| {
                g.image(item.name(), ImageDesc::multisampled(item.format(), w, h, n))
            };
            (
                image(g, Item::RadianceSamples),
                image(g, Item::DisplaySamples),
            )
        });
        Transients {
            layers,
            shadow_size: s,
            shadow_maps,
            map,
            node_irradiance,
            node_radiosity,
            hdr,
            depth,
            display,
            samples,
        }
    }
}

/// What the pass-adding steps read: the device, the scene, its uploaded data and the graph's
/// handles to the shared resources.
pub(super) struct Assembly<'a> {
    gpu: &'a Arc<Gpu>,
    scene: &'a Scene,
    data: &'a SubsurfaceData,
    imported: Imported,
    transient: Transients,
}

impl<'a> Assembly<'a> {
    /// Makes the local response image, imports it into `g` with the uploaded data and `host`'s
    /// buffers, and declares the shared transient resources.
    pub(super) fn new(
        g: &mut RenderGraph,
        gpu: &'a Arc<Gpu>,
        scene: &'a Scene,
        data: &'a SubsurfaceData,
        host: &HostBuffers,
    ) -> Result<Assembly<'a>> {
        let (aw, ah) = data.atlas_size;
        let local_image = Arc::new(Image::zeroed_storage(
            gpu,
            Item::LocalResponse.name(),
            Item::LocalResponse.format(),
            aw,
            ah,
        )?);
        let imported = Imported::new(g, host, data, local_image);
        let transient = Transients::new(g, scene, data);
        Ok(Assembly {
            gpu,
            scene,
            data,
            imported,
            transient,
        })
    }

    /// Edge of the shadow maps, texels.
    pub(super) fn shadow_map_size(&self) -> u32 {
        self.transient.shadow_size
    }

    /// Makes the light-entry image for a model with a single-scattering pass (`single_pass`)
    /// and imports it into `g`: layered like the shadow maps, drawn by `shadow` and read by
    /// `single`. Kept across frames and imported in the layout both use, so that a frame under
    /// the same lights can skip `shadow`.
    pub(super) fn add_entry_image(
        &self,
        g: &mut RenderGraph,
        single_pass: bool,
    ) -> Result<Option<ResourceId>> {
        if !single_pass {
            return Ok(None);
        }
        let Transients {
            layers,
            shadow_size: s,
            ..
        } = self.transient;
        let entry = Image::cleared_attachment_layers(
            self.gpu,
            Item::EntryDepth.name(),
            passes::shadow::ENTRY_FORMAT,
            (s, s),
            layers,
            passes::shadow::ENTRY_CLEAR,
        )?;
        Ok(Some(g.import_image(
            Arc::new(entry),
            Access::StorageRead(Stage::Compute),
        )))
    }

    /// Adds the `shadow` pass (writing the light-entry image `entry` where there is one) and
    /// the `illum` pass that lights the atlas through its maps.
    pub(super) fn add_shadow_and_illumination(
        &self,
        g: &mut RenderGraph,
        entry: Option<ResourceId>,
    ) {
        let (scene, data) = (self.scene, self.data);
        let Imported {
            frame,
            vertices,
            indices,
            transfer,
            texture_entry,
            ..
        } = self.imported;
        let Transients {
            layers,
            shadow_maps,
            map,
            ..
        } = self.transient;
        passes::shadow::add(
            g,
            passes::shadow::ShadowInputs {
                frame,
                vertices,
                indices,
                index_count: data.index_count,
                layers,
                entry,
            },
            shadow_maps,
        );
        passes::illum::add(
            g,
            passes::illum::IllumInputs {
                frame,
                vertices,
                indices,
                index_count: data.index_count,
                shadow_maps,
                transfer,
                texture_entry,
                textured: scene.texture.is_some(),
                environment: scene.environment.is_some(),
                incidence: scene.material.takes_incidence_factor(),
            },
            map,
        );
    }

    /// Adds the compute passes from the illumination map to the responses: `dilate`, `local`,
    /// `gather` and `global` (run as `global_variant`).
    pub(super) fn add_responses(
        &self,
        g: &mut RenderGraph,
        global_variant: compute::GlobalVariant,
    ) {
        let data = self.data;
        let Imported {
            texels,
            kernels,
            seam_rows,
            seam_entries,
            gather_rows,
            gather_entries,
            global_rows,
            global_entries,
            charts,
            local,
            ..
        } = self.imported;
        let Transients {
            map,
            node_irradiance,
            node_radiosity,
            ..
        } = self.transient;
        let dilate_texels = g.import_buffer(data.dilate_texels.clone(), None);
        compute::dilate(g, dilate_texels, data.dilate_count, charts, map);
        compute::local(
            g,
            compute::LocalInputs {
                texels,
                texel_count: data.texel_count,
                kernels,
                kernel_size: data.kernel_size,
                seam_rows,
                seam_entries,
                map,
            },
            local,
        );
        let rows = |r, e| compute::SparseInputs {
            rows: r,
            entries: e,
            row_count: data.node_count,
        };
        compute::gather(g, rows(gather_rows, gather_entries), map, node_irradiance);
        compute::global(
            g,
            rows(global_rows, global_entries),
            node_irradiance,
            node_radiosity,
            global_variant,
        );
    }

    /// Adds the single-scattering passes (`thickness`, `front`, `single`, which reads the
    /// light-entry image `entry` that `shadow` draws) for a model that has them (`entry`
    /// given), at one sample per `scene::single::downsample` pixels along each side, and
    /// returns what the composite reads of them (a black pixel without the passes).
    pub(super) fn add_single_scattering(
        &self,
        g: &mut RenderGraph,
        entry: Option<ResourceId>,
    ) -> Result<passes::composite::SingleImages> {
        let (w, h) = crate::scene::single::size(self.scene);
        let Imported {
            frame,
            vertices,
            indices,
            ..
        } = self.imported;
        let single = if let Some(entry) = entry {
            let mesh = passes::single::MeshInputs {
                frame,
                vertices,
                indices,
                index_count: self.data.index_count,
            };
            let image = |g: &mut RenderGraph, item: Item| {
                g.image(item.name(), ImageDesc::new(item.format(), w, h))
            };
            let back = image(g, Item::BackDepth);
            let single = image(g, Item::SingleScattering);
            let front = passes::single::FrontImages {
                depth: image(g, Item::SingleDepth),
                position: image(g, Item::FrontPosition),
                normal: image(g, Item::FrontNormal),
                facet: image(g, Item::FrontFacet),
            };
            passes::single::thickness(g, mesh, back);
            passes::single::front(g, mesh, front);
            passes::single::single(
                g,
                passes::single::SingleInputs {
                    frame,
                    entry,
                    back,
                    front,
                    refracts: self.scene.material.eta != 1.0,
                    entry_neighbours: crate::scene::shadow::entry_neighbours(
                        self.scene,
                        self.shadow_map_size(),
                    )
                    .0,
                },
                single,
            );
            passes::composite::SingleImages {
                radiance: single,
                depth: front.depth,
                pass: true,
                ratio: [
                    self.scene.width as f32 / w as f32,
                    self.scene.height as f32 / h as f32,
                ],
            }
        } else {
            let black = Image::from_pixels(
                self.gpu,
                "no single scattering",
                Item::SingleScattering.format(),
                1,
                1,
                &[0; 16],
            )?;
            let black = g.import_image(Arc::new(black), Access::Sampled(Stage::Fragment));
            passes::composite::SingleImages {
                radiance: black,
                depth: black,
                pass: false,
                ratio: [1.0; 2],
            }
        };
        Ok(single)
    }

    /// Adds the `composite` pass that shades the object into the output images, with the
    /// single scattering in `single` (where the model has the pass).
    pub(super) fn add_composite(
        &self,
        g: &mut RenderGraph,
        single: passes::composite::SingleImages,
    ) {
        let (scene, data) = (self.scene, self.data);
        let Imported {
            frame,
            environment,
            vertices,
            indices,
            texture,
            local,
            ..
        } = self.imported;
        let Transients {
            shadow_maps,
            node_radiosity,
            hdr,
            depth,
            display,
            samples,
            ..
        } = self.transient;
        passes::composite::add(
            g,
            passes::composite::CompositeInputs {
                frame,
                vertices,
                indices,
                index_count: data.index_count,
                node_radiosity,
                local,
                texture,
                textured: scene.texture.is_some(),
                single,
                chord: scene.material.model.gathers_over_chord(),
                shadow_maps,
                oblique: scene.material.takes_oblique_exit() && scene.environment.is_none(),
                environment,
                surface: scene.surface.reflects(&scene.material),
                glint: scene.surface.reflects(&scene.material) && scene.environment.is_some(),
            },
            passes::composite::CompositeTargets {
                hdr,
                display,
                depth,
                samples: samples.map(|(hdr, display)| (hdr, display, scene.samples)),
            },
            (scene.exposure, scene.tonemap),
        );
    }

    /// For a window renderer: makes the window image and adds the `window` pass that writes
    /// it (and the `ui` pass over it); returns the image.
    pub(super) fn add_window(
        &self,
        g: &mut RenderGraph,
        window: Option<&WindowOutput>,
    ) -> Result<Option<Arc<Image>>> {
        let gpu = self.gpu;
        let (w, h) = (self.scene.width, self.scene.height);
        let display = self.transient.display;
        // The window pass reads the display before the readback does: the readback, skipped in
        // most window frames, is then the display's last user and changes no layout that a
        // pass after it relies on (see `crate::graph::compile::check_skip`).
        let window = match window {
            None => None,
            Some(out) => {
                let image = Arc::new(Image::new(
                    gpu,
                    "window image",
                    crate::gpu::ImageInfo {
                        format: passes::window::format(out.linear),
                        extent: vk::Extent2D {
                            width: w + out.left,
                            height: h,
                        },
                        layers: 1,
                        usage: vk::ImageUsageFlags::STORAGE
                            | vk::ImageUsageFlags::COLOR_ATTACHMENT
                            | vk::ImageUsageFlags::TRANSFER_SRC,
                        samples: 1,
                    },
                    false,
                )?);
                // Undefined -> the layout the graph expects at the start of each frame.
                gpu.one_shot(|cmd| {
                    image.transition(
                        gpu,
                        cmd,
                        (vk::PipelineStageFlags2::NONE, vk::AccessFlags2::NONE),
                        (
                            vk::PipelineStageFlags2::ALL_COMMANDS,
                            vk::AccessFlags2::TRANSFER_READ,
                        ),
                        (
                            vk::ImageLayout::UNDEFINED,
                            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                        ),
                    )
                })?;
                let window_id = g.import_image(image.clone(), Access::TransferRead);
                passes::window::add(
                    g,
                    display,
                    window_id,
                    out.linear,
                    passes::window::WindowInputs {
                        frame: self.imported.frame,
                        environment: self.imported.environment,
                        left: out.left,
                        backdrop: out.backdrop && self.scene.environment.is_some(),
                        look: (self.scene.exposure, self.scene.tonemap),
                    },
                );
                if let Some(ui) = &out.ui {
                    passes::ui::add(g, window_id, ui.clone());
                }
                Some(image)
            }
        };
        Ok(window)
    }

    /// Adds the `readback` pass that copies the radiance and display images to the host.
    pub(super) fn add_readback(&self, g: &mut RenderGraph) {
        let Imported {
            hdr_rb, display_rb, ..
        } = self.imported;
        let Transients { hdr, display, .. } = self.transient;
        passes::readback::add(
            g,
            PassName::Readback.as_str(),
            vec![(hdr, hdr_rb), (display, display_rb)],
        );
    }

    /// Makes the host buffers of [`super::Options::capture`] and adds the `capture` pass that
    /// copies the intermediate results into them (the single scattering in `single` when
    /// `single_pass`, and every layer of the light-entry image `entry`).
    pub(super) fn add_capture(
        &self,
        g: &mut RenderGraph,
        single: passes::composite::SingleImages,
        entry: Option<ResourceId>,
    ) -> Result<CaptureBuffers> {
        let (gpu, data) = (self.gpu, self.data);
        let (aw, ah) = data.atlas_size;
        let (sw, sh) = crate::scene::single::size(self.scene);
        let samples = sw as u64 * sh as u64;
        let Imported { local, .. } = self.imported;
        let Transients {
            map,
            node_irradiance,
            node_radiosity,
            ..
        } = self.transient;
        let atlas_bytes = aw as u64 * ah as u64 * 16;
        let node_bytes = data.node_count.max(1) as u64 * 16;
        let b = CaptureBuffers {
            irradiance: host_buffer(gpu, "capture irradiance", atlas_bytes)?,
            local: host_buffer(gpu, "capture local", atlas_bytes)?,
            node_irradiance: host_buffer(gpu, "capture node irradiance", node_bytes)?,
            node_radiosity: host_buffer(gpu, "capture node radiosity", node_bytes)?,
            single: single
                .pass
                .then(|| {
                    host_buffer(
                        gpu,
                        "capture single scattering",
                        samples * Item::SingleScattering.bytes(),
                    )
                })
                .transpose()?,
            entry: entry
                .map(|_| {
                    let s = self.transient.shadow_size as u64;
                    let texels = s * s * self.transient.layers as u64;
                    host_buffer(
                        gpu,
                        "capture light entry",
                        texels * Item::EntryDepth.bytes(),
                    )
                })
                .transpose()?,
        };
        let mut to_host =
            |buffer: &Arc<Buffer>| g.import_buffer(buffer.clone(), Some(Access::HostRead));
        let mut pairs = vec![
            (map, to_host(&b.irradiance)),
            (local, to_host(&b.local)),
            (node_irradiance, to_host(&b.node_irradiance)),
            (node_radiosity, to_host(&b.node_radiosity)),
        ];
        if let Some(buffer) = &b.single {
            pairs.push((single.radiance, to_host(buffer)));
        }
        if let (Some(image), Some(buffer)) = (entry, &b.entry) {
            pairs.push((image, to_host(buffer)));
        }
        passes::readback::add(g, PassName::Capture.as_str(), pairs);
        Ok(b)
    }
}
