//! The methods the harness compares: every direction choice ([`Guiding`], paper §2.2–2.4)
//! × every combination of iterations ([`Combine`], paper §2.5) × with and without the
//! world-wide bias correction ρ (paper §2.5).
//!
//! The variants are enumerated through [`clap::ValueEnum::value_variants`], so a mode added to
//! the bake joins the harness without a change here.

use clap::ValueEnum;

use crate::bake::settings::{
    BakeSettings, Budget, Combine, GuideSeed, GuideTarget, GuidedPasses, Guiding, Schedule,
    Transport,
};
use crate::transport::emitters::EmitterSelection;

/// One way of baking: what the bake's `--guiding`, `--combine` and `--bias-correction` say,
/// and the guiding levers (`--mix`, `--schedule`, `--min-split`, `--smooth`, `--min-gain`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Method {
    /// Direction choice.
    pub guiding: Guiding,
    /// Estimator combination.
    pub combine: Combine,
    /// Apply ρ.
    pub rho: bool,
    /// The guiding levers.
    pub levers: Levers,
}

/// The bake's guiding levers, as a method sets them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Levers {
    /// `--mix`: percent of guided packets from the cosine baseline.
    pub mix: u32,
    /// `--schedule`.
    pub schedule: Schedule,
    /// `--min-split`.
    pub min_split: u32,
    /// `--smooth`.
    pub smooth: u32,
    /// `--guided-passes`.
    pub guided_passes: GuidedPasses,
    /// `--min-gain`.
    pub min_gain: u32,
    /// `--flat-below` (`+flat=`).
    pub flat_below: u32,
    /// `--transport`, where the method sets its own (else the ladder's, `guidebake bench
    /// --transport`): so one run compares series and path transport at equal time.
    pub transport: Option<Transport>,
    /// `--emitter-selection`, where the method sets its own (else the ladder's, `guidebake
    /// bench --emitter-selection`): so one run compares emitter selections at equal time.
    pub selection: Option<EmitterSelection>,
    /// `--budget`; `None`: the bake's default for the method's guiding
    /// ([`Budget::default_for`]: the unguided baseline stays uniform).
    pub budget: Option<Budget>,
    /// `--direct-spp` as a percentage of the rung's `--spp` (`+direct=P`), for series
    /// transport; `None`: unset, the lightmap estimates its direct light itself.
    pub direct_percent: Option<u32>,
    /// `--lookup-spp` as a percentage of the rung's `--spp` (`+lookup=P`), for series
    /// transport; `None`: unset, the bake's default
    /// ([`BakeSettings::default_lookup_spp`]).
    pub lookup_percent: Option<u32>,
    /// `--lookup-filter` (`+filter=R`, a radius in texels; 0: none).
    pub lookup_filter: u32,
    /// `--guide-target` (`+target=`).
    pub guide_target: GuideTarget,
    /// `--guide-seed` (`+seed=`).
    pub guide_seed: GuideSeed,
    /// `--target-error` in thousandths (`+stop=20` is 0.02): the stopping rule, the rung's
    /// spp its cap; `None`: off.
    pub stop_permille: Option<u32>,
    /// `--iterations`, where the method sets its own (`+iters=N`; else the ladder's,
    /// `guidebake bench --iterations`).
    pub iterations: Option<u32>,
}

impl Default for Levers {
    fn default() -> Self {
        let d = BakeSettings::default();
        Levers {
            mix: d.mix,
            schedule: d.schedule,
            min_split: d.min_split,
            smooth: d.smooth,
            guided_passes: d.guided_passes,
            min_gain: d.min_gain,
            flat_below: d.flat_below,
            transport: None,
            selection: None,
            budget: None,
            direct_percent: None,
            lookup_percent: None,
            lookup_filter: d.lookup_filter,
            guide_target: d.guide_target,
            guide_seed: d.guide_seed,
            stop_permille: None,
            iterations: None,
        }
    }
}

impl Levers {
    /// The levers before the guiding levers were added: no mixture, an even schedule, splits
    /// at 4 records, α = 25 % (the per-texel frame, which flipped at n.z = −0, is gone).
    pub fn before() -> Levers {
        Levers {
            mix: 0,
            schedule: Schedule::Even,
            min_split: 4,
            smooth: 25,
            guided_passes: GuidedPasses::Every,
            min_gain: 0,
            flat_below: 0,
            transport: None,
            selection: None,
            budget: Some(Budget::Uniform),
            direct_percent: None,
            lookup_percent: None,
            lookup_filter: BakeSettings::default().lookup_filter,
            guide_target: GuideTarget::Radiance,
            guide_seed: GuideSeed::Off,
            stop_permille: None,
            iterations: None,
        }
    }

    /// `+key=value` for every lever that differs from the bake's default.
    fn suffix(&self) -> String {
        let d = Levers::default();
        let mut s = String::new();
        if self.mix != d.mix {
            s += &format!("+mix={}", self.mix);
        }
        if self.schedule != d.schedule {
            s += &format!("+schedule={}", value_name(&self.schedule));
        }
        if self.min_split != d.min_split {
            s += &format!("+split={}", self.min_split);
        }
        if self.smooth != d.smooth {
            s += &format!("+smooth={}", self.smooth);
        }
        if self.guided_passes != d.guided_passes {
            s += &format!("+passes={}", value_name(&self.guided_passes));
        }
        if self.min_gain != d.min_gain {
            s += &format!("+gain={}", self.min_gain);
        }
        if self.flat_below != d.flat_below {
            s += &format!("+flat={}", self.flat_below);
        }
        if let Some(t) = self.transport {
            s += &format!("+transport={}", value_name(&t));
        }
        if let Some(e) = self.selection {
            s += &format!("+select={}", value_name(&e));
        }
        if let Some(b) = self.budget {
            s += &format!("+budget={}", value_name(&b));
        }
        if let Some(p) = self.direct_percent {
            s += &format!("+direct={p}");
        }
        if let Some(p) = self.lookup_percent {
            s += &format!("+lookup={p}");
        }
        if self.lookup_filter != d.lookup_filter {
            s += &format!("+filter={}", self.lookup_filter);
        }
        if self.guide_target != d.guide_target {
            s += &format!("+target={}", value_name(&self.guide_target));
        }
        if let Some(p) = self.stop_permille {
            s += &format!("+stop={p}");
        }
        if self.guide_seed != d.guide_seed {
            s += &format!("+seed={}", value_name(&self.guide_seed));
        }
        if let Some(n) = self.iterations {
            s += &format!("+iters={n}");
        }
        s
    }
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
                        levers: Levers::default(),
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
            levers: Levers::default(),
        }
    }

    /// The bake's defaults.
    pub fn default_bake() -> Method {
        let d = BakeSettings::default();
        Method {
            guiding: d.guiding,
            combine: d.combine,
            rho: d.bias_correction,
            levers: Levers::default(),
        }
    }

    /// Parses a label as [`Self::label`] writes it: `guiding/combine/rho|-` and optional
    /// `+key=value` levers (`mix`, `schedule`, `split`, `smooth`, `passes`, `gain`,
    /// `transport`, `select`, `budget`, `direct`, `lookup`, `filter`, `stop`, `target`, `seed`,
    /// `iters`); the single word `before` stands for every lever as it was before the guiding
    /// levers were added.
    ///
    /// # Errors
    /// A message naming the part that is not understood.
    pub fn parse(label: &str) -> Result<Method, String> {
        let mut parts = label.split('+');
        let head = parts.next().unwrap_or_default();
        let fields: Vec<&str> = head.split('/').collect();
        let [g, c, r] = fields[..] else {
            return Err(format!("method {label:?}: want guiding/combine/rho|-"));
        };
        let guiding = Guiding::from_str(g, true).map_err(|e| format!("{label:?}: {e}"))?;
        let combine = Combine::from_str(c, true).map_err(|e| format!("{label:?}: {e}"))?;
        let rho = match r {
            "rho" => true,
            "-" => false,
            _ => return Err(format!("method {label:?}: rho or -, not {r:?}")),
        };
        let mut levers = Levers::default();
        for part in parts {
            if part == "before" {
                levers = Levers::before();
                continue;
            }
            let (key, value) = part
                .split_once('=')
                .ok_or_else(|| format!("method {label:?}: lever {part:?} is not key=value"))?;
            let number = || {
                value
                    .parse::<u32>()
                    .map_err(|e| format!("method {label:?}: {key}={value}: {e}"))
            };
            match key {
                "mix" => levers.mix = number()?,
                "split" => levers.min_split = number()?,
                "smooth" => levers.smooth = number()?,
                "gain" => levers.min_gain = number()?,
                "flat" => levers.flat_below = number()?,
                "schedule" => {
                    levers.schedule =
                        Schedule::from_str(value, true).map_err(|e| format!("{label:?}: {e}"))?;
                }
                "passes" => {
                    levers.guided_passes = GuidedPasses::from_str(value, true)
                        .map_err(|e| format!("{label:?}: {e}"))?;
                }
                "transport" => {
                    levers.transport = Some(
                        Transport::from_str(value, true).map_err(|e| format!("{label:?}: {e}"))?,
                    );
                }
                "select" => {
                    levers.selection = Some(
                        EmitterSelection::from_str(value, true)
                            .map_err(|e| format!("{label:?}: {e}"))?,
                    );
                }
                "budget" => {
                    levers.budget =
                        Some(Budget::from_str(value, true).map_err(|e| format!("{label:?}: {e}"))?);
                }
                "direct" => levers.direct_percent = Some(number()?),
                "lookup" => levers.lookup_percent = Some(number()?),
                "filter" => levers.lookup_filter = number()?,
                "stop" => levers.stop_permille = Some(number()?),
                "iters" => levers.iterations = Some(number()?),
                "target" => {
                    levers.guide_target = GuideTarget::from_str(value, true)
                        .map_err(|e| format!("{label:?}: {e}"))?;
                }
                "seed" => {
                    levers.guide_seed =
                        GuideSeed::from_str(value, true).map_err(|e| format!("{label:?}: {e}"))?;
                }
                _ => return Err(format!("method {label:?}: unknown lever {key:?}")),
            }
        }
        Ok(Method {
            guiding,
            combine,
            rho,
            levers,
        })
    }

    /// The paper's full method: coherent guiding, Graybill–Deal per texel, ρ.
    pub fn guided_gd_rho() -> Method {
        Method {
            guiding: Guiding::Coherent,
            combine: Combine::Texel,
            rho: true,
            levers: Levers::default(),
        }
    }

    /// A short label: `coherent/texel/rho`, `off/average/-`.
    pub fn label(&self) -> String {
        format!(
            "{}/{}/{}{}",
            value_name(&self.guiding),
            value_name(&self.combine),
            if self.rho { "rho" } else { "-" },
            self.levers.suffix()
        )
    }

    /// The bake settings of this method with `transport` (unless the method sets its own) at
    /// `bounces`; everything else keeps the bake's defaults, so settings added to the bake
    /// need no change here.
    pub fn settings(
        &self,
        spp: u32,
        iterations: u32,
        transport: Transport,
        bounces: u32,
        seed: u32,
    ) -> BakeSettings {
        let transport = self.levers.transport.unwrap_or(transport);
        let percent = |p: Option<u32>| {
            p.filter(|_| transport == Transport::Series)
                .map(|p| (u64::from(spp) * u64::from(p) / 100).min(u64::from(u32::MAX)) as u32)
        };
        let (direct_spp, lookup_spp) = (
            percent(self.levers.direct_percent),
            percent(self.levers.lookup_percent),
        );
        let target_error = self.levers.stop_permille.map(|p| p as f32 / 1000.0);
        BakeSettings {
            spp,
            iterations: self.levers.iterations.unwrap_or(iterations),
            transport,
            bounces,
            guiding: self.guiding,
            combine: self.combine,
            bias_correction: self.rho,
            seed,
            mix: self.levers.mix,
            schedule: self.levers.schedule,
            min_split: self.levers.min_split,
            smooth: self.levers.smooth,
            guided_passes: self.levers.guided_passes,
            min_gain: self.levers.min_gain,
            flat_below: self.levers.flat_below,
            emitter_selection: self.levers.selection.unwrap_or_default(),
            budget: self
                .levers
                .budget
                .unwrap_or(Budget::default_for(self.guiding, target_error)),
            direct_spp,
            lookup_spp,
            lookup_filter: self.levers.lookup_filter,
            guide_target: self.levers.guide_target,
            guide_seed: self.levers.guide_seed,
            target_error,
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

    #[test]
    fn labels_parse_back() {
        for m in Method::all() {
            assert_eq!(Method::parse(&m.label()), Ok(m));
        }
        let m = Method::parse("coherent/texel/rho+before").unwrap();
        assert_eq!(m.levers, Levers::before());
        assert_eq!(Method::parse(&m.label()), Ok(m));
        let m = Method::parse("naive/cluster/-+mix=25+split=16").unwrap();
        assert_eq!((m.levers.mix, m.levers.min_split), (25, 16));
        assert_eq!(Method::parse(&m.label()), Ok(m));
        let m = Method::parse("coherent/cluster/rho+passes=every").unwrap();
        assert_eq!(m.levers.guided_passes, GuidedPasses::Every);
        assert_eq!(m.label(), "coherent/cluster/rho+passes=every");
        assert!(Method::parse("coherent/cluster/rho+passes=some").is_err());
        let m = Method::parse("coherent/cluster/rho+gain=150").unwrap();
        assert_eq!(m.levers.min_gain, 150);
        assert_eq!(m.label(), "coherent/cluster/rho+gain=150");
        assert_eq!(m.settings(256, 4, Transport::Series, 3, 1).min_gain, 150);
        let m = Method::parse("coherent/cluster/rho+transport=path").unwrap();
        assert_eq!(m.label(), "coherent/cluster/rho+transport=path");
        assert_eq!(
            m.settings(256, 4, Transport::Series, 3, 1).transport,
            Transport::Path
        );
        assert!(Method::parse("coherent/cluster/rho+transport=light").is_err());
        let m = Method::parse("coherent/cluster/rho+budget=balanced").unwrap();
        assert_eq!(m.levers.budget, Some(Budget::Balanced));
        assert_eq!(m.label(), "coherent/cluster/rho+budget=balanced");
        assert!(Method::parse("coherent/cluster/rho+budget=most").is_err());
        // Without the lever: the bake's default for the method's guiding; the baseline (and
        // so every reference) stays the uniform unguided bake.
        let budget = |label: &str| {
            Method::parse(label)
                .unwrap()
                .settings(256, 4, Transport::Series, 3, 1)
                .budget
        };
        assert_eq!(budget("coherent/cluster/rho"), Budget::Bounded);
        assert_eq!(budget("coherent/cluster/rho+stop=20"), Budget::Uniform);
        assert_eq!(budget("off/average/-"), Budget::Uniform);
        assert_eq!(
            Method::baseline()
                .settings(256, 4, Transport::Series, 3, 1)
                .budget,
            Budget::Uniform
        );
        assert_eq!(Method::baseline().label(), "off/average/-");
        assert_eq!(
            budget("coherent/cluster/rho+budget=uniform"),
            Budget::Uniform
        );
        let m = Method::parse("coherent/cluster/rho+target=radiance").unwrap();
        assert_eq!(m.label(), "coherent/cluster/rho+target=radiance");
        assert_eq!(
            m.settings(256, 4, Transport::Series, 3, 1).guide_target,
            GuideTarget::Radiance
        );
        assert!(Method::parse("coherent/cluster/rho+target=mean").is_err());
        let m = Method::parse("off/average/-+transport=path+select=tree").unwrap();
        assert_eq!(m.label(), "off/average/-+transport=path+select=tree");
        assert_eq!(
            m.settings(256, 4, Transport::Series, 3, 1)
                .emitter_selection,
            EmitterSelection::Tree
        );
        assert!(Method::parse("off/average/-+select=nearest").is_err());
        assert!(Method::parse("coherent/texel").is_err());
        assert!(Method::parse("coherent/texel/rho+nope=1").is_err());
    }
}
