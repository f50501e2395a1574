//! # guidebake (driver)
//!
//! The std half of guidebake: scenes in, memory-mapped texel files, the streaming guided
//! bake, EXR lightmaps out, and the benchmark harness. The SIMD kernels live in
//! [`guidebake_kernels`]; this crate feeds them.
//!
//! | module | what |
//! |---|---|
//! | [`texels`] | the texel file: streaming writer, validating memory-mapped reader |
//! | [`scene`] | glTF / OBJ scenes, lights, sky |
//! | [`bake`] | the streaming bake: shards, resume, the bounded tile pipeline |
//! | [`demo`] | the bundled default scene: a room lit through a door ajar |
//! | [`bvh`] | obvhs build, flattened into the kernels' node layout; robust ray origins |
//! | [`prepare`] | lightmap UV rasterization into texel tiles |
//! | [`prepare::facing`] | which side of a two-sided surface its texels describe (used by `prepare`) |
//! | [`synth`] | procedural worlds of any size, streamed |
//! | [`output`] | result file, journal of finished tiles, ρ, EXR pages |
//! | [`atomic`] | files that appear complete or not at all (temporary name, sync, rename) |
//! | [`hash`] | FNV-1a and the word hash: checksums, identities, fingerprints |
//! | [`preview`] | PNG figures and tone-mapped previews |
//! | [`render`] | a picture of the lit scene: eye rays shaded from the baked lightmap |
//! | [`transport`] | the world a gather ray meets ([`transport::world`]) and light transport: next-event estimation, series lookups, path sampling |
//! | [`bench`] | the run-time-against-error harness and the Figure-5 overhead |
//! | [`cmd`] | the `guidebake` subcommands |
#![deny(unsafe_op_in_unsafe_fn)]

pub mod atomic;
pub mod bake;
pub mod bench;
pub mod bvh;
pub mod cmd;
pub mod demo;
pub mod hash;
pub mod output;
pub mod prepare;
pub mod preview;
pub mod probes;
pub mod render;
pub mod scene;
pub mod synth;
#[doc(hidden)]
pub mod test_support;
pub mod texels;
pub mod transport;
pub mod view;
