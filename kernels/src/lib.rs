//! # guidebake-kernels
//!
//! `#![no_std]` SIMD kernels for guided lightmap baking, after Silvennoinen & Sloan,
//! *Ray Guiding for Production Lightmap Baking*, SIGGRAPH Asia 2019 Technical Briefs
//! (DOI 10.1145/3355088.3365167). One module per concept of the paper:
//!
//! | module | concept | paper |
//! |---|---|---|
//! | [`sobol`] | Sobol points, Cranley–Patterson rotation | §2.4 |
//! | [`presort`] | presorted coherent packets of 8 | §2.4, Figure 3 |
//! | [`mapping`] | square ↔ cosine-weighted hemisphere, tangent frames | §2.2 |
//! | [`guide`] | learned directional quadtree and its smoothing filter | §2.2–2.3 |
//! | [`warp`] | hierarchical sample warping, scalar and 8-wide | §2.4 |
//! | [`packet`] | `Ray8` / `Hit8` packets | §2.4 |
//! | [`traverse`] | 8-wide packet BVH traversal, scalar reference | §2.4 |
//! | [`estimator`] | Welford batches, Graybill–Deal, bias correction ρ | §2.5 |
//! | [`cluster`] | texel clustering | §2.1 |
//!
//! Every 8-wide kernel has a scalar reference beside it, and the two are tested against each
//! other in every build (with and without AVX2). Hot paths never allocate and never return
//! `Result`; preconditions are `debug_assert!`s whose release behaviour is documented.
//!
//! Feature `alloc` adds convenience constructors returning `Vec`s.
#![no_std]
#![deny(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]

#[cfg(feature = "alloc")]
extern crate alloc;
#[cfg(test)]
extern crate std;

pub mod cluster;
pub mod estimator;
pub mod guide;
pub mod mapping;
pub mod packet;
pub mod presort;
pub mod sobol;
pub mod traverse;
pub mod warp;

#[cfg(any(test, feature = "testing"))]
#[doc(hidden)]
pub mod testing;
