//! Every buffer and image the renderer keeps on the device, with its element format and size,
//! stated once. The upload (`passes::data`), the passes' texel views, the memory report
//! (`Requirements`), the estimate made before preprocessing and the bench's traffic model all
//! read this table; the element counts come from [`Counts`], filled from a preprocessed scene
//! or, before preprocessing, from the estimate's guesses.

use ash::vk;

/// One item of device data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Item {
    /// Atlas mesh vertices (`passes::data::AtlasVertex`).
    AtlasVertices,
    /// Atlas mesh indices.
    AtlasIndices,
    /// Covered texels, `x | y << 16`.
    CoveredTexels,
    /// Covered texels whose centre a triangle may miss, packed like the covered texels.
    DilateTexels,
    /// Chart id + 1 per atlas texel.
    ChartIds,
    /// Kernels: two f16 rgb taps per element (halves 0-2 and 3-5), beta in the centre tap.
    Kernels,
    /// Seam-tap CSR row starts, one more than covered texels.
    SeamRows,
    /// Seam-tap entries: source texel bits as a float, rgb weight.
    SeamEntries,
    /// Gather CSR row starts, one more than nodes.
    GatherRows,
    /// Gather entries: texel bits as a float, weight.
    GatherEntries,
    /// Global CSR row starts (in entry pairs), one more than nodes.
    GlobalRows,
    /// Global entry pairs: `p0 | p1 << 16`, then two rgb weights as six f16.
    GlobalEntries,
    /// The albedo texture (sRGB; 1x1 white without one).
    Texture,
    /// The illumination map over the atlas.
    IlluminationMap,
    /// The local response over the atlas.
    LocalResponse,
    /// Irradiance per node.
    NodeIrradiance,
    /// Radiosity per node.
    NodeRadiosity,
    /// Shadow maps, one layer per directional or spot light, six per point light.
    ShadowMaps,
    /// Linear radiance per output pixel.
    Radiance,
    /// Depth per output sample.
    Depth,
    /// Linear radiance per output sample, averaged into [`Item::Radiance`] (multisampled
    /// output only).
    RadianceSamples,
    /// Tone-mapped value per output sample, averaged into [`Item::Display`] (multisampled
    /// output only).
    DisplaySamples,
    /// Tone-mapped display image.
    Display,
    /// Host-visible copy of the radiance.
    RadianceReadback,
    /// Host-visible copy of the display image.
    DisplayReadback,
    /// Single-scattered radiance per sample of the single-scattering passes (models with the
    /// pass; 1 element else).
    SingleScattering,
    /// Depth of the nearest back face per sample (the same models).
    BackDepth,
    /// Depth of the surface the camera sees per sample (the same models).
    SingleDepth,
    /// Position of the surface the camera sees per sample, and whether it sees one (the same
    /// models).
    FrontPosition,
    /// Interpolated normal there, turned to the camera (the same models).
    FrontNormal,
    /// Normal of the triangle there (the same models).
    FrontFacet,
    /// Light-entry depth per shadow-map texel, without the shadow bias, with its slopes (the
    /// same models).
    EntryDepth,
    /// The environment's transfer per atlas texel: its spherical-harmonic coefficients as f16,
    /// eight to an element (scenes with an environment light; 1 element else).
    EnvironmentTransfer,
    /// The texture's part of the light entering each atlas texel (textured scenes; 1 element
    /// else).
    TextureEntry,
    /// The environment map's radiance per pixel, host-visible, for the surface's mirror
    /// reflection and the viewer's backdrop (scenes with an environment light, room for the
    /// largest map the viewer can switch to; 1 element else).
    EnvironmentMap,
}

impl Item {
    /// Every item, in the memory report's order.
    pub const ALL: [Item; 35] = [
        Item::AtlasVertices,
        Item::AtlasIndices,
        Item::CoveredTexels,
        Item::DilateTexels,
        Item::ChartIds,
        Item::Kernels,
        Item::SeamRows,
        Item::SeamEntries,
        Item::GatherRows,
        Item::GatherEntries,
        Item::GlobalRows,
        Item::GlobalEntries,
        Item::Texture,
        Item::TextureEntry,
        Item::IlluminationMap,
        Item::LocalResponse,
        Item::NodeIrradiance,
        Item::NodeRadiosity,
        Item::ShadowMaps,
        Item::Radiance,
        Item::Depth,
        Item::RadianceSamples,
        Item::DisplaySamples,
        Item::Display,
        Item::RadianceReadback,
        Item::DisplayReadback,
        Item::SingleScattering,
        Item::BackDepth,
        Item::SingleDepth,
        Item::FrontPosition,
        Item::FrontNormal,
        Item::FrontFacet,
        Item::EntryDepth,
        Item::EnvironmentTransfer,
        Item::EnvironmentMap,
    ];

    /// Its name: the Vulkan object's debug name and the memory report's label.
    pub const fn name(self) -> &'static str {
        match self {
            Item::AtlasVertices => "atlas vertices",
            Item::AtlasIndices => "atlas indices",
            Item::CoveredTexels => "covered texels",
            Item::DilateTexels => "texels to dilate",
            Item::ChartIds => "chart ids",
            Item::Kernels => "kernels",
            Item::SeamRows => "seam rows",
            Item::SeamEntries => "seam entries",
            Item::GatherRows => "gather rows",
            Item::GatherEntries => "gather entries",
            Item::GlobalRows => "global rows",
            Item::GlobalEntries => "global entries",
            Item::Texture => "albedo texture",
            Item::TextureEntry => "texture entry",
            Item::IlluminationMap => "illumination map",
            Item::LocalResponse => "local response",
            Item::NodeIrradiance => "node irradiance",
            Item::NodeRadiosity => "node radiosity",
            Item::ShadowMaps => "shadow maps",
            Item::Radiance => "radiance",
            Item::Depth => "camera depth",
            Item::RadianceSamples => "radiance samples",
            Item::DisplaySamples => "display samples",
            Item::Display => "display",
            Item::RadianceReadback => "radiance readback",
            Item::DisplayReadback => "display readback",
            Item::SingleScattering => "single scattering",
            Item::BackDepth => "back-face depth",
            Item::SingleDepth => "single-scattering depth",
            Item::FrontPosition => "front position",
            Item::FrontNormal => "front normal",
            Item::FrontFacet => "front facet",
            Item::EntryDepth => "light-entry depth",
            Item::EnvironmentTransfer => "environment transfer",
            Item::EnvironmentMap => "environment map",
        }
    }

    /// The element's format as the passes see it (`UNDEFINED` for the vertex structure, whose
    /// attributes are listed with `AtlasVertex`).
    pub const fn format(self) -> vk::Format {
        use vk::Format as F;
        match self {
            Item::AtlasVertices => F::UNDEFINED,
            Item::AtlasIndices
            | Item::CoveredTexels
            | Item::DilateTexels
            | Item::ChartIds
            | Item::SeamRows
            | Item::GatherRows
            | Item::GlobalRows => F::R32_UINT,
            Item::Kernels | Item::GlobalEntries | Item::EnvironmentTransfer => F::R32G32B32A32_UINT,
            Item::SeamEntries
            | Item::IlluminationMap
            | Item::LocalResponse
            | Item::NodeIrradiance
            | Item::NodeRadiosity
            | Item::Radiance
            | Item::RadianceSamples
            | Item::RadianceReadback
            | Item::SingleScattering
            | Item::FrontPosition
            | Item::FrontNormal
            | Item::FrontFacet
            | Item::EntryDepth
            | Item::TextureEntry
            | Item::EnvironmentMap => F::R32G32B32A32_SFLOAT,
            Item::GatherEntries => F::R32G32_SFLOAT,
            Item::Texture => F::R8G8B8A8_SRGB,
            Item::ShadowMaps | Item::Depth | Item::BackDepth | Item::SingleDepth => F::D32_SFLOAT,
            Item::Display | Item::DisplaySamples | Item::DisplayReadback => F::R8G8B8A8_UNORM,
        }
    }

    /// Bytes of one element.
    pub const fn bytes(self) -> u64 {
        if let Item::AtlasVertices = self {
            // passes::data::AtlasVertex, asserted there, so that the memory report and the
            // bench's traffic cannot count a size the structure does not have.
            return 112;
        }
        match crate::gpu::resources::format_bytes(self.format()) {
            Some(bytes) => bytes,
            None => panic!("an item's format without a size in gpu::resources::format_bytes"),
        }
    }
}

/// Spherical-harmonic coefficients of the environment transfer per element (eight f16 in an
/// RGBA32UI element).
pub const TRANSFER_COEFFICIENTS_PER_ELEMENT: usize = 8;

/// Transfer elements per atlas texel for `coefficients` coefficients (0 for none).
pub fn transfer_elements(coefficients: usize) -> usize {
    coefficients.div_ceil(TRANSFER_COEFFICIENTS_PER_ELEMENT)
}

/// Kernel elements per covered texel for a `kernel_size` x `kernel_size` kernel: two taps to
/// an element.
pub fn kernel_pairs(kernel_size: u32) -> u32 {
    (kernel_size * kernel_size).div_ceil(2)
}

/// How many elements each item has for one scene.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// Atlas mesh vertices.
    pub atlas_vertices: u64,
    /// Atlas mesh indices.
    pub atlas_indices: u64,
    /// Covered texels.
    pub texels: u64,
    /// Covered texels `dilate` visits.
    pub dilate_texels: u64,
    /// Atlas width x height.
    pub atlas_texels: u64,
    /// Kernel edge.
    pub kernel_size: u32,
    /// Seam taps in use (0 where the blending mode has none).
    pub seam_taps: u64,
    /// Global nodes.
    pub nodes: u64,
    /// Gather entries.
    pub gather_entries: u64,
    /// Global entry pairs of the blending mode's matrix.
    pub global_pairs: u64,
    /// Texture pixels (1 without a texture).
    pub texture_pixels: u64,
    /// Whether the scene has a texture.
    pub textured: bool,
    /// Shadow-map side.
    pub shadow_side: u64,
    /// Shadow-map layers.
    pub shadow_layers: u64,
    /// Output pixels.
    pub pixels: u64,
    /// Samples per output pixel (0 or 1: not multisampled).
    pub samples: u64,
    /// Whether the model has the single-scattering passes.
    pub single: bool,
    /// Samples of the single-scattering passes (their images' pixels).
    pub single_pixels: u64,
    /// Environment transfer elements per atlas texel (0 without an environment light).
    pub transfer_per_texel: u64,
    /// Environment map pixels the surface's reflection reads (0 where it reads none).
    pub environment_pixels: u64,
}

impl Counts {
    /// Elements of `item`. A buffer holds at least one element (empty data is padded).
    pub fn elements(&self, item: Item) -> u64 {
        let n = match item {
            Item::AtlasVertices => self.atlas_vertices,
            Item::AtlasIndices => self.atlas_indices,
            Item::CoveredTexels => self.texels,
            Item::DilateTexels => self.dilate_texels,
            Item::ChartIds | Item::IlluminationMap | Item::LocalResponse => self.atlas_texels,
            Item::Kernels => self.texels * kernel_pairs(self.kernel_size) as u64,
            Item::SeamRows => self.texels + 1,
            Item::SeamEntries => self.seam_taps,
            Item::GatherRows | Item::GlobalRows => self.nodes + 1,
            Item::GatherEntries => self.gather_entries,
            Item::GlobalEntries => self.global_pairs,
            Item::Texture => self.texture_pixels,
            Item::TextureEntry => {
                if self.textured {
                    self.atlas_texels
                } else {
                    0
                }
            }
            Item::NodeIrradiance | Item::NodeRadiosity => self.nodes,
            Item::ShadowMaps => self.shadow_side * self.shadow_side * self.shadow_layers,
            Item::Radiance | Item::Display | Item::RadianceReadback | Item::DisplayReadback => {
                self.pixels
            }
            Item::Depth => self.pixels * self.samples.max(1),
            Item::RadianceSamples | Item::DisplaySamples => {
                if self.samples > 1 {
                    self.pixels * self.samples
                } else {
                    0
                }
            }
            Item::EnvironmentTransfer => self.atlas_texels * self.transfer_per_texel,
            Item::EnvironmentMap => self.environment_pixels,
            Item::EntryDepth => {
                if self.single {
                    self.shadow_side * self.shadow_side * self.shadow_layers
                } else {
                    0
                }
            }
            Item::SingleScattering
            | Item::BackDepth
            | Item::SingleDepth
            | Item::FrontPosition
            | Item::FrontNormal
            | Item::FrontFacet => {
                if self.single {
                    self.single_pixels
                } else {
                    0
                }
            }
        };
        n.max(1)
    }

    /// Bytes of `item`.
    pub fn bytes(&self, item: Item) -> u64 {
        self.elements(item) * item.bytes()
    }

    /// Bytes of several items.
    pub fn sum(&self, items: &[Item]) -> u64 {
        items.iter().map(|&i| self.bytes(i)).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The device's query of multisampled attachments asks for the formats the camera view's
    /// images have.
    #[test]
    fn the_device_asks_for_the_output_formats() {
        let formats = crate::gpu::device::OUTPUT_ATTACHMENTS.map(|(f, _)| f);
        assert_eq!(
            formats,
            [
                Item::RadianceSamples.format(),
                Item::DisplaySamples.format(),
                Item::Depth.format()
            ]
        );
    }

    #[test]
    fn two_taps_to_an_element() {
        assert_eq!(kernel_pairs(1), 1);
        assert_eq!(kernel_pairs(7), 25);
        assert_eq!(kernel_pairs(8), 32);
    }

    #[test]
    fn element_sizes_follow_the_formats() {
        // Every item has a size (a format missing from format_bytes would panic here).
        let total: u64 = Item::ALL.iter().map(|i| i.bytes()).sum();
        assert!(total > 0);
        assert_eq!(Item::Kernels.bytes(), 16);
        assert_eq!(Item::Texture.bytes(), 4);
        assert_eq!(Item::EntryDepth.bytes(), 16);
        assert_eq!(Item::GatherEntries.bytes(), 8);
        assert_eq!(Item::ShadowMaps.bytes(), 4);
        let names: std::collections::BTreeSet<_> = Item::ALL.iter().map(|i| i.name()).collect();
        assert_eq!(names.len(), Item::ALL.len());
    }

    #[test]
    fn counts_give_bytes() {
        let c = Counts {
            texels: 10,
            kernel_size: 7,
            nodes: 3,
            shadow_side: 8,
            shadow_layers: 6,
            ..Counts::default()
        };
        assert_eq!(c.bytes(Item::Kernels), 10 * 25 * 16);
        assert_eq!(c.bytes(Item::GlobalRows), 4 * 4);
        assert_eq!(c.bytes(Item::ShadowMaps), 8 * 8 * 6 * 4);
        assert_eq!(
            c.bytes(Item::SeamEntries),
            16,
            "empty buffers hold one element"
        );
    }
}
