//! How many single-scattering samples a frame takes: the `front`, `thickness` and `single`
//! passes' image size against the output's.

use super::Scene;

/// Image pixels per single-scattering sample along each side for `scene`, and why: the
/// scene's `[output] single_downsample` when set, else 1 (a sample per pixel). Fewer samples
/// make the pass quicker, and the composite's upsample follows the depth so that
/// another surface's samples (at a silhouette, or an ear in front of the head) do not mix in;
/// but single scattering steps at the mesh's edges and near the light's terminator from one
/// pixel to the next, which fewer samples blur, so the default keeps every pixel.
pub fn downsample(scene: &Scene) -> (u32, String) {
    let k = factor(scene);
    let why = if scene.single_downsample.is_some() {
        format!("single scattering at one sample per {k}x{k} pixels: given")
    } else {
        "single scattering at every pixel ([output] single_downsample = 2 takes one sample per 2x2 pixels: the pass is quicker, its steps at the mesh's edges blurred)".to_string()
    };
    (k, why)
}

/// [`downsample`]'s factor alone.
pub fn factor(scene: &Scene) -> u32 {
    scene.single_downsample.unwrap_or(1)
}

/// The single-scattering images' size for `scene` (its output at [`downsample`]'s factor).
pub fn size(scene: &Scene) -> (u32, u32) {
    downsampled(scene.width, scene.height, factor(scene))
}

/// The single-scattering images' size for an image of `width` x `height` at `downsample`.
pub fn downsampled(width: u32, height: u32, downsample: u32) -> (u32, u32) {
    let k = downsample.max(1);
    (width.div_ceil(k), height.div_ceil(k))
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::scene::tests::from_text as scene;

    /// One sample per pixel unless the scene asks for fewer; the images' size rounds up.
    #[test]
    fn the_downsample_is_the_scenes_or_one() {
        assert_eq!(
            downsample(&scene("[output]\nwidth = 64\nheight = 64\n")).0,
            1
        );
        let given = scene("[output]\nwidth = 64\nheight = 64\nsingle_downsample = 3\n");
        assert_eq!(
            downsample(&given),
            (
                3,
                "single scattering at one sample per 3x3 pixels: given".to_string()
            )
        );
        assert_eq!(downsampled(255, 64, 2), (128, 32));
        assert_eq!(downsampled(255, 64, 1), (255, 64));
    }
}
