//! How many single-scattering samples a frame takes: the `front`, `thickness` and `single`
//! passes' image size against the output's.

use super::build::MAX_SINGLE_DOWNSAMPLE;
use super::Scene;

/// Single-scattering samples across the object (its bounding sphere's diameter on screen)
/// that the derived sample rate keeps at least.
pub const MIN_SAMPLES_ACROSS: f64 = 96.0;

/// Image pixels per single-scattering sample along each side for `scene`, and why: the
/// scene's `[output] single_downsample` when set; else the largest factor (at most
/// `MAX_SINGLE_DOWNSAMPLE`, the most a scene may give) at which the object still spans
/// [`MIN_SAMPLES_ACROSS`] samples: 1 (a sample per pixel) where it spans fewer than twice
/// that many pixels.
/// Single scattering is smooth over the surface but at its edges and near the light's
/// terminator, where it steps from one pixel to the next; the composite's upsample follows the
/// depth, so that another surface's samples (at a silhouette, or an ear in front of the head)
/// do not mix in, and what fewer samples blur is a sample's width along those steps: at a
/// fixed number of samples across the object, the same small share of it at any resolution.
pub fn downsample(scene: &Scene) -> (u32, String) {
    if let Some(k) = scene.single_downsample {
        return (
            k,
            format!("single scattering at one sample per {k}x{k} pixels: given"),
        );
    }
    let across = pixels_across(scene);
    let k = ((across / MIN_SAMPLES_ACROSS).floor() as u32).clamp(1, MAX_SINGLE_DOWNSAMPLE);
    if k > 1 {
        (
            k,
            format!(
                "single scattering at one sample per {k}x{k} pixels: the object spans {across:.0} pixels, {:.0} samples (at least {MIN_SAMPLES_ACROSS:.0}; [output] single_downsample = 1 samples every pixel)",
                across / k as f64
            ),
        )
    } else {
        (
            1,
            format!(
                "single scattering at every pixel: the object spans {across:.0} pixels (one sample per 2x2 from {:.0})",
                2.0 * MIN_SAMPLES_ACROSS
            ),
        )
    }
}

/// Pixels the object spans on screen: its bounding sphere's diameter over the pixel size at
/// its centre, at most the image's longer side (an object that fills the view, or a camera
/// inside the sphere, spans the image).
pub fn pixels_across(scene: &Scene) -> f64 {
    let (_, radius) = scene.bounds();
    let image = scene.width.max(scene.height) as f64;
    (2.0 * radius as f64 / scene.pixel_mm()).min(image)
}

/// [`downsample`]'s factor alone.
pub fn factor(scene: &Scene) -> u32 {
    downsample(scene).0
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

    /// The scene's own factor where it gives one; the images' size rounds up.
    #[test]
    fn a_given_downsample_is_kept() {
        let given = scene("[output]\nwidth = 64\nheight = 64\nsingle_downsample = 3\n");
        assert_eq!(
            downsample(&given),
            (
                3,
                "single scattering at one sample per 3x3 pixels: given".to_string()
            )
        );
        let one = scene("[output]\nwidth = 1024\nheight = 1024\nsingle_downsample = 1\n");
        assert_eq!(factor(&one), 1);
        assert_eq!(downsampled(255, 64, 2), (128, 32));
        assert_eq!(downsampled(255, 64, 1), (255, 64));
    }

    /// Derived: a sample per pixel on a small object, one per 2x2 pixels from
    /// MIN_SAMPLES_ACROSS samples across at that rate, one per 3x3 from as many at that rate,
    /// at the image heights where the object's span crosses those; the span follows the
    /// height, and the factor stops at the largest a scene may give.
    #[test]
    fn the_derived_downsample_follows_the_objects_size_on_screen() {
        let at = |h: u32| scene(&format!("[output]\nwidth = {h}\nheight = {h}\n"));
        let small = at(64);
        let per_pixel = pixels_across(&small) / 64.0;
        assert!((pixels_across(&at(640)) / 640.0 - per_pixel).abs() < 1e-9 * per_pixel);
        for k in 2..=3u32 {
            let threshold = (k as f64 * MIN_SAMPLES_ACROSS / per_pixel).ceil() as u32;
            assert_eq!(
                factor(&at(threshold - 1)),
                k - 1,
                "{}",
                downsample(&at(threshold - 1)).1
            );
            assert_eq!(
                factor(&at(threshold)),
                k,
                "{}",
                downsample(&at(threshold)).1
            );
            assert!(downsample(&at(threshold)).1.contains(&format!("{k}x{k}")));
            assert_eq!(
                size(&at(threshold + 1)),
                downsampled(threshold + 1, threshold + 1, k)
            );
        }
        let huge = ((MAX_SINGLE_DOWNSAMPLE + 2) as f64 * MIN_SAMPLES_ACROSS / per_pixel) as u32;
        assert_eq!(factor(&at(huge)), MAX_SINGLE_DOWNSAMPLE);
        // Seen from close by, the bounding sphere spans more than the image: the object spans
        // the image, too few pixels for fewer samples.
        let close = scene(
            "[camera]\nposition = [0.0, 24.0, 30.0]\ntarget = [0.0, 24.0, 0.0]\n[output]\nwidth = 100\nheight = 100\n",
        );
        let (_, radius) = close.bounds();
        assert!(2.0 * radius as f64 / close.pixel_mm() > 2.0 * MIN_SAMPLES_ACROSS);
        assert_eq!(pixels_across(&close), 100.0);
        assert_eq!(factor(&close), 1);
    }
}
