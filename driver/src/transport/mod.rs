//! Light transport for the final gather (DESIGN.md, "The bake", light transport).
//!
//! Surfaces are two-sided Lambertian. Analytic lights (sun, point, spot, sphere) are
//! connected explicitly by next-event estimation with shadow rays ([`lights`]); the final
//! gather itself sees the sky, emissive triangles and indirect light — and that is what the
//! guide learns (paper §2.2). The two never overlap: a gather ray that misses sees the sky
//! without the sun, so no light is counted twice.
//!
//! What leaves a gather hit depends on the transport (`--transport`): in `series` mode
//! emission plus albedo/π × (direct light + the previous pass's indirect irradiance, looked
//! up in its lightmap: [`series`]); in `path` mode the path continues from the hit with
//! cosine-weighted directions, next-event estimation at every vertex and Russian roulette
//! ([`crate::bake::world::World::hit_radiance`]). Random numbers beyond the gather's Sobol
//! point come from [`rng`].

pub mod alias;
pub mod light_tree;
pub mod lights;
pub mod rng;
pub mod series;
pub mod sky;
