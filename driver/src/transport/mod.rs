//! Light transport for the final gather (docs/bake.md): one home
//! for how light reaches a texel.
//!
//! Surfaces are two-sided Lambertian. Lights are of two kinds: analytic lights (sun, point,
//! spot, sphere: [`lights`]) and emissive triangles ([`emitters`]), which emit from their
//! front face. Both are connected explicitly by next-event estimation with shadow rays
//! ([`direct`]) at the texel and at every gather hit or path vertex. Emitters can also be hit
//! by the rays the bake traces anyway; the two estimates are combined by multiple importance
//! sampling (power heuristic), so every light path counts once. A gather ray that misses sees
//! the sky without the sun, so the sun is never counted twice.
//!
//! What leaves a gather hit depends on the transport (`--transport`, [`path`]): in `series`
//! mode emission (MIS-weighted) plus albedo/π × (direct light + the previous pass's indirect
//! irradiance, looked up in its lightmap: [`series`]); in `path` mode the path continues
//! from the hit with cosine-weighted directions, next-event estimation and MIS at every
//! vertex and Russian roulette. What a gather sample contains, and so what the guide learns
//! from (paper §2.2), is documented in [`path`]. Random numbers beyond the gather's Sobol
//! point come from [`rng`].

pub mod alias;
pub mod direct;
pub mod emitters;
pub mod light_tree;
pub mod lights;
pub mod lookup_filter;
pub mod pass_image;
pub mod path;
pub mod rng;
pub mod series;
pub mod settings;
pub mod sh_l1;
pub mod sky;
pub mod world;
