//! The integration tests, one module per file of `tests/`, built as one test binary: each
//! binary links the whole library and its dependencies, and 32 of them took about 6 minutes
//! of a clean `cargo test`'s CPU time where one takes about 1.5. `cargo test --test
//! integration reuse::` runs one file's tests.

mod animation;
mod antialiasing;
mod architecture;
mod cancel;
mod caustics;
mod cgroup_limits;
mod cli;
mod coverage;
mod embree;
mod emission;
mod error_control;
mod farm;
mod fuzz_scenes;
mod glossy_light;
mod gltf_lights;
mod hard_scene;
mod hostile_loaders;
mod hostile_numbers;
mod interior_scene;
mod library;
mod light_tracing;
mod light_transport;
mod materials;
mod memory_limits;
mod night_scene;
mod outputs;
mod pixel_identity;
mod real_lens;
mod region;
mod render;
mod reuse;
mod scene_assets;
mod scene_files;
mod scratch;
mod shadows;
