//! translucent: interactive rendering of translucent objects after Lensch et al., "Interactive
//! Rendering of Translucent Objects" (2002), on Vulkan.
//!
//! The modules follow the data: [`scene`] (input) -> [`physics`] (dipole, materials) ->
//! [`graph`] (render graph) with [`passes`] on the [`gpu`] backend -> [`output`] (files).
//! [`renderer`] assembles the graph for a scene; [`cli`] is the command line.

#![warn(missing_docs)]
// Per-channel numeric code indexes several parallel arrays by channel; iterator rewrites of
// those loops read worse.
#![allow(clippy::needless_range_loop)]

pub mod bench;
pub mod chart;
pub mod cli;
pub mod environment;
pub mod geometry;
pub mod gpu;
pub mod graph;
pub mod input;
pub mod layout;
pub mod metrics;
pub mod numeric;
pub mod output;
pub mod passes;
pub mod physics;
pub mod pipeline;
pub mod preprocess;
pub mod reference;
pub mod renderer;
pub mod scene;
pub mod truth;
pub mod viewer;
