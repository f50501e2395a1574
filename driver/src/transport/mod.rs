//! Light transport for the final gather (DESIGN.md, "The bake", light transport).
//!
//! Surfaces are two-sided Lambertian. Analytic lights (sun, point, spot, sphere) are
//! connected explicitly by next-event estimation with shadow rays ([`lights`]); the final
//! gather itself sees the sky, emissive triangles and indirect light — and that is what the
//! guide learns (paper §2.2). The two never overlap: a gather ray that misses sees the sky
//! without the sun, so no light is counted twice.

pub mod lights;
pub mod sky;
