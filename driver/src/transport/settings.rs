//! The settings the light transport reads (`--transport`, `--emitters`): options of
//! `guidebake bake` ([`crate::bake::settings::BakeSettings`] holds them and re-exports
//! them), defined here, below both the bake and the transport, so that [`super::path`] and
//! [`super::direct`] import nothing of the bake.

use std::fmt;

/// How the radiance a gather ray brings back from its hit is computed (docs/bake.md, light
/// transport).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum Transport {
    /// The paper's production setting: pass b gathers, at each hit, emission + albedo/π ×
    /// (direct light connected explicitly + the indirect irradiance of pass b−1 looked up in
    /// the previous pass's lightmap). Pass 0 (the direct pass) bakes the direct light alone, then
    /// `--bounces B` gather passes stream the world.
    Series,
    /// Unidirectional path tracing from the gather hit, next-event estimation at every
    /// vertex and Russian roulette: the unbiased reference, one pass.
    Path,
}

/// How emissive triangles light a shading point (`crate::transport::direct`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum EmitterSampling {
    /// Next-event estimation and the rays that hit them, weighted by the power heuristic.
    #[default]
    Mis,
    /// Next-event estimation alone; emission that rays hit is not counted.
    Nee,
    /// Only rays that happen to hit them (the bake before emitters were lights).
    Hits,
}

impl fmt::Display for Transport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Transport::Series => "series",
            Transport::Path => "path",
        })
    }
}

impl fmt::Display for EmitterSampling {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            EmitterSampling::Mis => "mis",
            EmitterSampling::Nee => "nee",
            EmitterSampling::Hits => "hits",
        })
    }
}
