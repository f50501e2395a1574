//! The methods the harness compares: every direction choice ([`Guiding`], paper §2.2–2.4)
//! × every combination of iterations ([`Combine`], paper §2.5) × with and without the
//! world-wide bias correction ρ (paper §2.5).
//!
//! The variants are enumerated through [`clap::ValueEnum::value_variants`], so a mode added to
//! the bake joins the harness without a change here.

use clap::ValueEnum;

use crate::bake::settings::{BakeSettings, Combine, Guiding, Transport};

/// One way of baking: what the bake's `--guiding`, `--combine` and `--bias-correction` say.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Method {
    /// Direction choice.
    pub guiding: Guiding,
    /// Estimator combination.
    pub combine: Combine,
    /// Apply ρ.
    pub rho: bool,
}

/// The command-line name of a clap value (`off`, `coherent`, `texel`, …).
pub fn value_name<T: ValueEnum>(v: &T) -> String {
    v.to_possible_value()
        .map_or_else(|| "?".to_owned(), |p| p.get_name().to_owned())
}

/// Serializes a clap value by its command-line name (for `#[serde(serialize_with)]`).
///
/// # Errors
/// The serializer's.
pub fn serialize_value_name<T: ValueEnum, S: serde::Serializer>(
    v: &T,
    s: S,
) -> Result<S::Ok, S::Error> {
    s.serialize_str(&value_name(v))
}

impl Method {
    /// Every method of the bake, baseline first: guiding × combine × (no ρ, ρ).
    pub fn all() -> Vec<Method> {
        let mut out = Vec::new();
        for &guiding in Guiding::value_variants() {
            for &combine in Combine::value_variants() {
                for rho in [false, true] {
                    out.push(Method {
                        guiding,
                        combine,
                        rho,
                    });
                }
            }
        }
        out
    }

    /// The unguided baseline: cosine-weighted gather, plain average, no ρ — an unbiased
    /// Monte Carlo estimate, what a baker without guiding does.
    pub fn baseline() -> Method {
        Method {
            guiding: Guiding::Off,
            combine: Combine::Average,
            rho: false,
        }
    }

    /// The paper's full method: coherent guiding, Graybill–Deal per texel, ρ.
    pub fn guided_gd_rho() -> Method {
        Method {
            guiding: Guiding::Coherent,
            combine: Combine::Texel,
            rho: true,
        }
    }

    /// A short label: `coherent/texel/rho`, `off/average/-`.
    pub fn label(&self) -> String {
        format!(
            "{}/{}/{}",
            value_name(&self.guiding),
            value_name(&self.combine),
            if self.rho { "rho" } else { "-" }
        )
    }

    /// The bake settings of this method with `transport` at `bounces`; everything else keeps
    /// the bake's defaults, so settings added to the bake need no change here.
    // Every field is set today; the update stays so that a new bake setting gets its default.
    #[allow(clippy::needless_update)]
    pub fn settings(
        &self,
        spp: u32,
        iterations: u32,
        transport: Transport,
        bounces: u32,
        seed: u32,
    ) -> BakeSettings {
        BakeSettings {
            spp,
            iterations,
            transport,
            bounces,
            guiding: self.guiding,
            combine: self.combine,
            bias_correction: self.rho,
            seed,
            ..Default::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_variant_appears_once_with_and_without_rho() {
        let all = Method::all();
        let n = Guiding::value_variants().len() * Combine::value_variants().len() * 2;
        assert_eq!(all.len(), n);
        let labels: std::collections::HashSet<String> = all.iter().map(Method::label).collect();
        assert_eq!(labels.len(), n, "labels are distinct");
        assert_eq!(all[0], Method::baseline());
        assert!(all.contains(&Method::guided_gd_rho()));
    }

    #[test]
    fn settings_carry_the_method() {
        let m = Method::guided_gd_rho();
        let s = m.settings(128, 4, Transport::Path, 2, 7);
        assert_eq!(
            (s.spp, s.iterations, s.bounces, s.seed, s.guiding, s.combine),
            (128, 4, 2, 7, Guiding::Coherent, Combine::Texel)
        );
        assert_eq!(s.transport, Transport::Path);
        assert!(s.bias_correction);
        assert!(s.validate().is_ok());
        assert_eq!(m.label(), "coherent/texel/rho");
        assert_eq!(Method::baseline().label(), "off/average/-");
    }
}
