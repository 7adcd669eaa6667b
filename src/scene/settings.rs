//! The preprocessing settings a user gives (the scene file's `[settings]`, the command
//! line's flags) instead of derived ones, and their validation. The derivation of the rest is
//! the preprocessing's (`preprocess::settings`).

use super::desc::SettingsDesc;
use serde::{Deserialize, Serialize};

/// Values given by the user instead of derived ones.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SettingsOverrides {
    /// Texel edge, mm.
    pub texel_mm: Option<f64>,
    /// Kernel edge, texels.
    pub kernel_size: Option<u32>,
    /// Node spacing, mm.
    pub node_spacing_mm: Option<f64>,
    /// Pruning tolerance (fraction).
    pub prune_tolerance: Option<f64>,
    /// Random walks per node and channel (`model = "volume"`).
    pub walk_paths: Option<u32>,
    /// Whether the walks are made once for any lamp (`model = "volume"` under lamps,
    /// [`crate::preprocess::mix`]) rather than along the scene's lamps.
    pub lamp_independent: Option<bool>,
}

impl SettingsOverrides {
    /// These, and `below`'s where these leave a setting out (the command line's over the
    /// scene file's).
    pub fn or(self, below: SettingsOverrides) -> SettingsOverrides {
        SettingsOverrides {
            texel_mm: self.texel_mm.or(below.texel_mm),
            kernel_size: self.kernel_size.or(below.kernel_size),
            node_spacing_mm: self.node_spacing_mm.or(below.node_spacing_mm),
            prune_tolerance: self.prune_tolerance.or(below.prune_tolerance),
            walk_paths: self.walk_paths.or(below.walk_paths),
            lamp_independent: self.lamp_independent.or(below.lamp_independent),
        }
    }
}

/// Validates user-given values.
pub fn validate(o: &SettingsOverrides) -> anyhow::Result<()> {
    if let Some(h) = o.texel_mm {
        anyhow::ensure!(
            h.is_finite() && h > 0.0,
            "texel size {h} mm must be a finite positive length"
        );
    }
    if let Some(k) = o.kernel_size {
        anyhow::ensure!(
            k % 2 == 1 && (1..=31).contains(&k),
            "kernel size {k} must be odd and between 1 and 31"
        );
    }
    if let Some(s) = o.node_spacing_mm {
        anyhow::ensure!(
            s.is_finite() && s > 0.0,
            "node spacing {s} mm must be a finite positive length"
        );
    }
    if let Some(t) = o.prune_tolerance {
        anyhow::ensure!(
            (0.0..0.5).contains(&t),
            "pruning tolerance {t} must lie in [0, 0.5)"
        );
    }
    if let Some(n) = o.walk_paths {
        anyhow::ensure!(
            (16..=1 << 20).contains(&n),
            "walks per node {n} must lie between 16 and 1048576"
        );
    }
    Ok(())
}

// The scene file's `[settings]` and the overrides it gives.
impl From<SettingsDesc> for SettingsOverrides {
    fn from(d: SettingsDesc) -> Self {
        Self {
            texel_mm: d.texel_mm,
            kernel_size: d.kernel,
            node_spacing_mm: d.node_spacing_mm,
            prune_tolerance: d.prune,
            walk_paths: d.walk_paths,
            lamp_independent: d.lamp_independent,
        }
    }
}

impl From<SettingsOverrides> for SettingsDesc {
    fn from(o: SettingsOverrides) -> Self {
        Self {
            texel_mm: o.texel_mm,
            kernel: o.kernel_size,
            node_spacing_mm: o.node_spacing_mm,
            prune: o.prune_tolerance,
            walk_paths: o.walk_paths,
            lamp_independent: o.lamp_independent,
        }
    }
}
