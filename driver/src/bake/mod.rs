//! The streaming bake (docs/ARCHITECTURE.md, "The bake, as data flows"; paper §2): tiles stream from the texel file
//! through per-worker buffers to one writer, in memory that does not grow with the world.
//!
//! This module holds the machinery that does not depend on light transport: which tiles a
//! run bakes ([`shard`]), and the bounded worker/writer [`pipeline`] that commits finished
//! tiles to the [result file and journal](crate::output).

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
