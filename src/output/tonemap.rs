//! The tone curves from linear radiance (times the exposure) to the display's linear values,
//! before the sRGB encoding: the plain clip, Khronos PBR Neutral and AgX. `glsl/display.glsl`
//! has the same curves; `tests/suite/render.rs` holds the two to one 8-bit step.

use serde::{Deserialize, Serialize};

/// A tone curve (`[output] tonemap`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ToneMap {
    /// Values above 1 clip: exact below, harsh at highlights.
    #[default]
    Srgb,
    /// Khronos PBR Neutral: base colours kept up to 0.76, highlights compressed towards white
    /// with a little desaturation.
    Neutral,
    /// AgX (Troy Sobotka's; the minimal fit of its contrast curve): a filmic curve over about
    /// 16.5 stops, highlights desaturating to white.
    Agx,
}

impl ToneMap {
    /// Every curve, in the panel's order.
    pub const ALL: [ToneMap; 3] = [ToneMap::Srgb, ToneMap::Neutral, ToneMap::Agx];

    /// Its name in scene files and the viewer's script.
    pub fn name(self) -> &'static str {
        match self {
            ToneMap::Srgb => "srgb",
            ToneMap::Neutral => "neutral",
            ToneMap::Agx => "agx",
        }
    }

    /// The curve called `name`.
    pub fn parse(name: &str) -> Option<ToneMap> {
        ToneMap::ALL.into_iter().find(|t| t.name() == name)
    }

    /// The specialisation constant that selects it in the composite.
    pub fn constant(self) -> u32 {
        self as u32
    }

    /// The display's linear value of radiance `c` (already times the exposure), in [0, 1].
    pub fn apply(self, c: [f32; 3]) -> [f32; 3] {
        let c = c.map(|v| v.max(0.0));
        match self {
            ToneMap::Srgb => c.map(|v| v.min(1.0)),
            ToneMap::Neutral => neutral(c),
            ToneMap::Agx => agx(c),
        }
    }
}

/// Khronos PBR Neutral (the reference implementation of the Khronos 3D Commerce group).
fn neutral(mut c: [f32; 3]) -> [f32; 3] {
    const START: f32 = 0.8 - 0.04;
    const DESATURATION: f32 = 0.15;
    let x = c[0].min(c[1]).min(c[2]);
    let offset = if x < 0.08 { x - 6.25 * x * x } else { 0.04 };
    c = c.map(|v| v - offset);
    let peak = c[0].max(c[1]).max(c[2]);
    if peak < START {
        return c.map(|v| v.clamp(0.0, 1.0));
    }
    let d = 1.0 - START;
    let new_peak = 1.0 - d * d / (peak + d - START);
    c = c.map(|v| v * new_peak / peak);
    let g = 1.0 - 1.0 / (DESATURATION * (peak - new_peak) + 1.0);
    c.map(|v| (v * (1.0 - g) + new_peak * g).clamp(0.0, 1.0))
}

/// AgX: into its working space, log2 over [-12.47, 4.03] stops, the contrast curve (a
/// sixth-degree fit), back out and to linear (the curve's output is encoded with a 2.2 gamma).
fn agx(c: [f32; 3]) -> [f32; 3] {
    const INSET: [[f32; 3]; 3] = [
        [0.842_479_1, 0.042_328_24, 0.042_375_654],
        [0.078_433_6, 0.878_468_6, 0.078_433_6],
        [0.079_223_745, 0.079_166_13, 0.879_143],
    ];
    const OUTSET: [[f32; 3]; 3] = [
        [1.196_879, -0.052_896_85, -0.052_971_635],
        [-0.098_020_88, 1.151_903_1, -0.098_043_45],
        [-0.099_029_74, -0.098_961_18, 1.151_073_7],
    ];
    const MIN_EV: f32 = -12.473_93;
    const MAX_EV: f32 = 4.026_069;
    // Column-major, as GLSL's mat3 * vec3.
    let mul = |m: &[[f32; 3]; 3], v: [f32; 3]| {
        [0, 1, 2].map(|r| m[0][r] * v[0] + m[1][r] * v[1] + m[2][r] * v[2])
    };
    let v = mul(&INSET, c).map(|x| {
        let e = x.max(1e-10).log2().clamp(MIN_EV, MAX_EV);
        let x = (e - MIN_EV) / (MAX_EV - MIN_EV);
        let (x2, x4) = (x * x, x * x * x * x);
        15.5 * x4 * x2 - 40.14 * x4 * x + 31.96 * x4 - 6.868 * x2 * x + 0.4298 * x2 + 0.1191 * x
            - 0.00232
    });
    mul(&OUTSET, v).map(|x| x.max(0.0).powf(2.2).min(1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each curve is monotonic in grey, black at black, and (but the clip) keeps a value well
    /// above 1 below white while the clip does not; names round-trip.
    #[test]
    fn curves_rise_from_black_and_names_round_trip() {
        for t in ToneMap::ALL {
            assert_eq!(ToneMap::parse(t.name()), Some(t));
            let mut last = -1.0;
            for k in 0..200 {
                let x = 0.001 * 1.06f32.powi(k);
                let y = t.apply([x; 3])[1];
                assert!(y >= last - 1e-6, "{t:?} falls at {x}: {y} after {last}");
                last = y;
            }
            assert!(t.apply([0.0; 3])[0] < 0.01, "{t:?} at black");
        }
        assert_eq!(ToneMap::Srgb.apply([4.0; 3]), [1.0; 3]);
        for t in [ToneMap::Neutral, ToneMap::Agx] {
            let y = t.apply([4.0; 3])[0];
            assert!(y > 0.8 && y < 1.0, "{t:?} at 4: {y}");
        }
        // Neutral keeps a mid base colour as it is (up to its small toe offset of 0.04).
        let c = ToneMap::Neutral.apply([0.5, 0.3, 0.2]);
        assert!(
            (c[0] - 0.46).abs() < 1e-6 && (c[2] - 0.16).abs() < 1e-6,
            "{c:?}"
        );
    }
}
