//! The integration tests, one binary: lavapipe with the Khronos validation layer on (any
//! validation message fails the test that made it), the `translucent` executable run as a user
//! would, and the library's stages against independent references. One binary links once and
//! keeps both cores busy from the first test to the last; each test opens its own device and
//! folders. Run one file's tests with `cargo test --release --test suite viewer::`.

mod common;

mod accuracy;
mod careless;
mod cli;
mod device;
mod environment;
mod estimate;
mod fuzz;
mod gpu_passes;
mod hostile;
mod preprocess;
mod render;
mod robustness;
mod single;
mod stability;
mod truth;
mod truth_accuracy;
mod viewer;
