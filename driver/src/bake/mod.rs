//! The streaming bake (docs/ARCHITECTURE.md, "The bake, as data flows"; paper §2): tiles stream from the texel file
//! through per-worker buffers to one writer, in memory that does not grow with the world.
//!
//! It stands on the light transport and the world a ray meets ([`crate::transport`], a layer
//! below; docs/ARCHITECTURE.md, "Layers"): the guided gather of a tile ([`gather`]), where
//! the samples go ([`budget`], [`stopping`]), which tiles a run bakes ([`shard`]), the
//! bounded worker/writer [`pipeline`] that commits finished tiles to the
//! [result file and journal](crate::output), the passes of a run ([`run`]) and the finish
//! that writes the pages ([`finish`]); its options and identity are in [`settings`].

pub mod budget;
pub mod directional;
pub mod error;
pub mod finish;
pub mod gather;
pub mod grid;
pub mod pipeline;
pub mod run;
pub mod settings;
pub mod shard;
pub mod stopping;
pub mod workdir;
