//! What a bake is asked to do: the options of `guidebake bake`, and the identity that lets
//! `--resume` and `merge` refuse results of a different bake.

use std::collections::BTreeMap;
use std::fmt;

use crate::hash::fnv1a64;
use crate::transport::emitters::EmitterSelection;
pub use crate::transport::settings::{EmitterSampling, Transport};

/// Whether a bake writes directional coefficients (`--directional`). A setting, so it lives
/// here; [`super::directional`], which computes the coefficients, re-exports it and imports
/// this module, not the other way round.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum Directional {
    /// Irradiance only (the default).
    #[default]
    None,
    /// L1 spherical harmonics of the incident radiance, world space
    /// (four RGB layers: SH0, SH1x, SH1y, SH1z).
    ShL1,
}

impl std::fmt::Display for Directional {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Directional::None => "none",
            Directional::ShL1 => "sh-l1",
        })
    }
}

/// How gather directions are chosen (docs/ARCHITECTURE.md, "Comparators").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum Guiding {
    /// Unguided cosine-weighted gather from presorted packets: the baseline.
    Off,
    /// The learned guide, warped one sample at a time from unsorted points, single rays.
    Naive,
    /// Presorted packets, rotated per texel, warped 8-wide and traced as packets (paper §2.4).
    Coherent,
    /// The comparator of the HWRTL baker and Unreal's first-bounce guiding: a 16×16-bin
    /// density per 8×8-texel square, sampled per lane, traced as packets.
    Grid,
}

/// How a texel's iterations are combined (paper §2.5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum Combine {
    /// Every sample counts the same.
    Average,
    /// Graybill–Deal per texel: iterations weighted by the inverse variance of their means.
    Texel,
    /// Müller et al.'s production scheme: one weight per iteration for the whole world, ∝ 1 /
    /// the mean over all texels of that iteration's variance; unbiased, needs no ρ. The
    /// iterations' batches are kept in a file and combined in the final pass.
    Global,
    /// Weights from the cluster: each iteration's weight ∝ its sample count over the
    /// cluster's pooled relative variance of that iteration (the sum over the cluster's
    /// texels of each texel's per-sample variance in the iteration over the sum of their
    /// squared means). The guide's quality is a property of the cluster, which 64 texels'
    /// samples estimate far better than one texel's; a firefly still lowers its own
    /// iteration's weight, so use it with ρ. The default: against 16× references level with
    /// `global` by RMSE at equal CPU time, ahead by relative MSE on four of the six runs and
    /// level on the other two (docs/estimator.md, "The default: cluster weights + ρ"), and it
    /// needs no batch file.
    Cluster,
}

impl Combine {
    /// Whether the combination's mean needs the world-wide correction ρ (paper §2.5): the
    /// per-texel and per-cluster weights are estimated from the samples they weigh, which
    /// biases the mean; the plain average and the global weights are unbiased (and ρ is 1
    /// for the average). What `--bias-correction auto` picks.
    pub fn wants_rho(self) -> bool {
        matches!(self, Combine::Texel | Combine::Cluster)
    }
}

/// Which series passes sample a learned guide (docs/bake.md, "The direct pass").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum GuidedPasses {
    /// The last pass only, the lightmap; the passes before it, whose results only feed the
    /// next pass's lookups, gather with cosine sampling. The default: at 256 spp on the three
    /// converted scenes the lightmap's RMSE is the same to three digits as with every pass
    /// guided and its relative MSE within 4 %, for a third of guiding's cost
    /// (docs/BENCHMARKS.md, "Guiding the last pass").
    #[default]
    Last,
    /// Every gather pass.
    Every,
}

/// How a bake's samples are split over its learning iterations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum Schedule {
    /// The same number of packets in every iteration (the remainder to the last).
    Even,
    /// Each iteration twice the previous one's packets, the last at least half the budget
    /// (Müller et al. 2017): the guide the most samples use learned from the most records.
    Doubling,
}

/// How the last pass of a series bake spends its samples over the texels (`--budget`, module
/// [`super::budget`]): every texel the same, or by the error the previous passes measured;
/// and the direct pass its later iterations' samples, by the error each tile's earlier ones
/// measured ([`super::budget::tile_factors`]).
/// [`Budget::Bounded`] by default for a guided bake: less relative MSE at equal time on every
/// scene and rung measured, the MSE the uniform budget's ([`Budget::default_for`];
/// docs/budget.md, "The spatial budget").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum Budget {
    /// `--spp` samples at every texel.
    Uniform,
    /// n ∝ σ / √(μ·μ̄): between the two below.
    Balanced,
    /// n ∝ σ: least squared error (MSE), more samples where the light is bright and noisy.
    Mse,
    /// n ∝ σ / √(μ² + ε), ε = 10⁻²·μ̄²: least relative squared error.
    Relative,
    /// n ∝ σ·√(1/(μ² + ε) + λ/μ̄²): least relative squared error whose predicted squared error
    /// (MSE) is no more than the uniform budget's, λ the smallest that keeps it there.
    Bounded,
}

impl Budget {
    /// The budget a bake gets unless it asks for one: [`Budget::Bounded`] for a guided bake;
    /// [`Budget::Uniform`] for an unguided one — the plain Monte Carlo bake guiding is
    /// measured against — and for one with a `--target-error`, whose stopping rule spends the
    /// samples by each cluster's own error within the `--spp` cap.
    pub fn default_for(guiding: Guiding, target_error: Option<f32>) -> Budget {
        if guiding == Guiding::Off || target_error.is_some() {
            Budget::Uniform
        } else {
            Budget::Bounded
        }
    }
}

/// What a cluster's guide learns from its records (`--guide-target`, docs/guiding-levers.md,
/// "The guide's target"): the density ∝ `E[L]` over the cluster's texels (the paper's), or
/// ∝ `√E[L²]`, which minimises their summed variance (variance-aware guiding, Rath et al.
/// 2020; [`guidebake_kernels::guide::GuideParams::second_moment`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum GuideTarget {
    /// The incident radiance (flux `L/q`): the paper's target.
    Radiance,
    /// The square root of its second moment (records `L²/q`): 1.00–1.23× less relative MSE
    /// at equal time on the three converted scenes, never behind by more than the noise
    /// (docs/guiding-levers.md).
    #[default]
    SecondMoment,
}

/// Whether the last pass's first iteration samples a guide seeded by the pass before it
/// (`--guide-seed`; docs/guiding-levers.md, "The seed guide").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum GuideSeed {
    /// The pass before the last keeps, per cluster, a coarse histogram of what its gather
    /// samples brought back over the primary sample square (one cell in each texel's result);
    /// the last pass builds its clusters' first guide from it, so no iteration of the
    /// lightmap is unguided. The default: 1.02–1.03× (Cornell box), 1.07× (ajar) and
    /// 1.19–1.23× (bidir) less relative MSE at equal samples, no measurable CPU
    /// (docs/guiding-levers.md).
    #[default]
    Previous,
    /// Every guided pass's first iteration gathers with cosine points (the paper's).
    Off,
}

/// The series transport's pass 0: each texel's direct light alone, by next-event estimation
/// (no gather rays), which pass 1's gather hits read as the previous pass's total instead of
/// tracing a shadow ray each (docs/bake.md, "The direct pass").
pub const DIRECT_PASS: u32 = 0;

/// The work directory's layout and the passes' meaning; a new value makes older work
/// directories another bake ([`BakeSettings::bake_id`]). 2: series bakes start with
/// [`DIRECT_PASS`]; 3: the lightmap takes its direct light from it
/// ([`BakeSettings::lightmap_borrows_direct`]); 4: the pass before the last keeps the seed
/// of the last pass's guides ([`BakeSettings::guide_seed`]); 5: a guide learns from every
/// iteration of its cluster since the last cosine one, not the last iteration alone.
const BAKE_FORMAT: u32 = 5;

/// The bake's settings; everything that changes its bits is part of [`Self::bake_id`].
#[derive(Clone, Copy, PartialEq)]
pub struct BakeSettings {
    /// Final-gather rays per texel, all learning iterations together.
    pub spp: u32,
    /// Learning iterations K (iteration 0 is unguided unless the pass before kept a guide
    /// seed). 3 by default since the seed guides the first iteration (docs/guiding-levers.md, "The
    /// records a guide learns from, and three iterations").
    pub iterations: u32,
    /// Direction choice.
    pub guiding: Guiding,
    /// Estimator combination.
    pub combine: Combine,
    /// Apply the world-wide bias correction ρ.
    pub bias_correction: bool,
    /// Seed of every random number.
    pub seed: u32,
    /// Light transport at the gather hits.
    pub transport: Transport,
    /// Bounces of light after the gather hit: 1 = emission and direct light at the hit
    /// only; `series` runs this many passes, `path` paths of at most this many vertices.
    pub bounces: u32,
    /// Percent of the cosine baseline in the defensive mixture every guided iteration
    /// samples, `c + (1 − c)·q` on the primary sample square: folded into the guide
    /// ([`guidebake_kernels::guide::GuideParams::uniform`]), so the guided density is
    /// never below `c` and every sample is weighted with the mixture's density.
    pub mix: u32,
    /// How the samples are split over the iterations.
    pub schedule: Schedule,
    /// A guide node splits only if it holds at least this many records.
    pub min_split: u32,
    /// The guide's smoothing α (paper §2.3) in percent: each child's share of its parent
    /// pulled toward a quarter by this much (the paper's filter: a prior toward the parent).
    pub smooth: u32,
    /// A cluster keeps sampling its guide only while the guide shows, on the records of the
    /// iteration that sampled it, at least this gain in percent: the stratified cosine
    /// points' variance per sample over its own (`--min-gain`; 0: always guide). Below it
    /// the cluster gathers with cosine points for its remaining iterations
    /// ([`GatherCounters`]'s `iterations_unguided_no_gain`). 25 by the benchmark
    /// (docs/BENCHMARKS.md, "Guiding only where it pays"): only a guide 4× worse than cosine
    /// points stops; at 150 the bake lost a third to a half of guiding's gain at equal time.
    ///
    /// [`GatherCounters`]: crate::bake::gather::GatherCounters
    pub min_gain: u32,
    /// A cluster of the last pass whose light the pass before measured as flat — a pooled
    /// relative per-sample variance of its cosine samples below this many thousandths —
    /// gathers that pass with cosine points alone, as one set of all its iterations' samples:
    /// no seed, no learned guide (`--flat-below`; 0: guide every cluster). Stratified cosine
    /// points integrate a constant sky exactly and broad light better than a guide learned
    /// from a few hundred records (docs/guiding-on-levels.md).
    /// Judged from the pass that keeps the guide seeds, so only where the last pass reads them
    /// ([`Self::reads_guide_seeds`]); counted as [`GatherCounters`]'s `clusters_flat`.
    ///
    /// [`GatherCounters`]: crate::bake::gather::GatherCounters
    pub flat_below: u32,
    /// How emissive triangles are found.
    pub emitters: EmitterSampling,
    /// How next-event estimation picks an emitter.
    pub emitter_selection: EmitterSelection,
    /// Directional coefficients kept beside the irradiance (`--directional`).
    pub directional: Directional,
    /// Which series passes sample a learned guide (`--guided-passes`).
    pub guided_passes: GuidedPasses,
    /// How the last pass of a series bake of 2 or more bounces spreads its samples over the
    /// texels (`--budget`). The default settings' is the guided bake's, [`Budget::Bounded`];
    /// [`Budget::default_for`] is what the command line picks for other guiding.
    pub budget: Budget,
    /// Next-event samples per texel of series transport's direct pass (`--direct-spp`;
    /// `None`: `--spp`), whose estimate the lightmap takes as its texels' direct light
    /// ([`Self::lightmap_borrows_direct`]).
    pub direct_spp: Option<u32>,
    /// Gather rays per texel of the series passes between the direct pass and the last,
    /// whose results only feed the next pass's lookups (`--lookup-spp`; `None`:
    /// [`Self::default_lookup_spp`], a quarter of `--spp`).
    pub lookup_spp: Option<u32>,
    /// Radius in texels of the lookups' filter (`--lookup-filter`; 0: none): the gathered
    /// light of a series pass that feeds the next pass's lookups is averaged over the texels
    /// around each that lie on the same surface and agree within their noise, before the next
    /// pass reads it ([`crate::transport::lookup_filter`]). No effect under path transport.
    pub lookup_filter: u32,
    /// What the learned guides learn (`--guide-target`).
    pub guide_target: GuideTarget,
    /// The stopping rule (`--target-error`; `None`: every texel takes every iteration): the
    /// relative error a texel's estimate may stop at, `--spp` (and `--direct-spp`,
    /// `--lookup-spp`) the cap. After each iteration from the second to the last but one, a
    /// gather cluster (a tile of the direct pass) whose texels' error, measured between its
    /// iterations, is within it skips its remaining iterations, or takes only the samples it
    /// still needs in the next one; decided from its own samples, so the bits do not depend
    /// on threads, shards or resumes ([`crate::bake::stopping`]).
    pub target_error: Option<f32>,
    /// Whether the last pass's first iteration samples a guide seeded by the pass before it
    /// (`--guide-seed`; [`Self::writes_guide_seeds`], [`Self::reads_guide_seeds`]).
    pub guide_seed: GuideSeed,
}

/// The settings as their identity's text ([`BakeSettings::identity`]), so that `{:?}` shows
/// what the identity hashes.
impl fmt::Debug for BakeSettings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.identity())
    }
}

/// The default [`BakeSettings::flat_below`], in thousandths: a relative variance per sample
/// of 1. Chosen at equal CPU time against the unguided bake on the three converted rooms and
/// both levels, 64–256 spp, where 1 000 was level with 100 or ahead by relative MSE and MSE
/// everywhere (docs/guiding-on-levels.md, "One set where the light is flat").
pub const DEFAULT_FLAT_BELOW: u32 = 1000;

/// Most learning iterations a bake may ask for.
pub const MAX_ITERATIONS: usize = 16;

/// Most bounces a bake may ask for.
pub const MAX_BOUNCES: u32 = 64;

/// The lookups' filter radius of the default settings, in texels (`--lookup-filter`).
/// Chosen by relative MSE against path references at equal samples: 2 and 3 are within 3 %
/// of each other, 1 gives up most of the gain on the ajar room (docs/estimator.md, "The
/// lookups: filtered, a quarter of the rays").
pub const DEFAULT_LOOKUP_FILTER: u32 = 2;

/// Most texels a lookups' filter may reach on each side ([`BakeSettings::lookup_filter`]).
pub const MAX_LOOKUP_FILTER: u32 = 8;

/// The share of `--spp` the lookup passes take by default: one in this many
/// ([`BakeSettings::default_lookup_spp`]).
pub const LOOKUP_SHARE: u32 = 4;

impl Default for BakeSettings {
    fn default() -> Self {
        Self {
            spp: 256,
            iterations: 3,
            guiding: Guiding::Coherent,
            combine: Combine::Cluster,
            bias_correction: Combine::Cluster.wants_rho(),
            seed: 0,
            transport: Transport::Series,
            bounces: 3,
            mix: 25,
            schedule: Schedule::Doubling,
            min_split: 64,
            smooth: 10,
            min_gain: 25,
            flat_below: DEFAULT_FLAT_BELOW,
            emitters: EmitterSampling::default(),
            emitter_selection: EmitterSelection::default(),
            directional: Directional::None,
            guided_passes: GuidedPasses::default(),
            budget: Budget::default_for(Guiding::Coherent, None),
            direct_spp: None,
            lookup_spp: None,
            lookup_filter: DEFAULT_LOOKUP_FILTER,
            guide_target: GuideTarget::default(),
            target_error: None,
            guide_seed: GuideSeed::default(),
        }
    }
}

/// Why settings were refused.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct SettingsError(String);

impl SettingsError {
    /// An error with this message (which names the option at fault).
    pub fn new(message: String) -> Self {
        Self(message)
    }
}

impl BakeSettings {
    /// Checks the settings a user can get wrong.
    ///
    /// # Errors
    /// [`SettingsError`] saying which option is out of range and why.
    pub fn validate(&self) -> Result<(), SettingsError> {
        if self.iterations == 0 || self.iterations as usize > MAX_ITERATIONS {
            return Err(SettingsError(format!(
                "--iterations {}: between 1 and {MAX_ITERATIONS} learning iterations",
                self.iterations
            )));
        }
        let spp_passes = (self.first_pass()..=self.last_pass()).filter(|&p| !self.feeds_lookups(p));
        self.check_per_iteration("--spp", self.spp, spp_passes)?;
        if self.mix > 100 {
            return Err(SettingsError(format!(
                "--mix {}: a percentage of the packets, between 0 and 100",
                self.mix
            )));
        }
        if self.smooth > 100 {
            return Err(SettingsError(format!(
                "--smooth {}: a percentage, between 0 and 100",
                self.smooth
            )));
        }
        if self.min_split < 1 {
            return Err(SettingsError(format!(
                "--min-split {}: at least 1 record",
                self.min_split
            )));
        }
        if !(1..=MAX_BOUNCES).contains(&self.bounces) {
            return Err(SettingsError(format!(
                "--bounces {}: between 1 and {MAX_BOUNCES}",
                self.bounces
            )));
        }
        if let Some(n) = self.direct_spp {
            self.validate_direct_spp(n)?;
        }
        if let Some(n) = self.lookup_spp {
            if self.transport != Transport::Series {
                return Err(SettingsError(format!(
                    "--lookup-spp {n}: the passes before the last are series transport's \
                     (--transport series)"
                )));
            }
            self.check_per_iteration("--lookup-spp", n, self.lookup_passes())?;
        }
        if self.lookup_filter > MAX_LOOKUP_FILTER {
            return Err(SettingsError(format!(
                "--lookup-filter {}: a radius in texels, at most {MAX_LOOKUP_FILTER}",
                self.lookup_filter
            )));
        }
        if let Some(t) = self.target_error {
            if !(t > 0.0 && t < 1.0) {
                return Err(SettingsError(format!(
                    "--target-error {t}: a relative standard error per texel, above 0 and \
                     below 1 (0.02 is 2 %)"
                )));
            }
            if self.combine == Combine::Global {
                return Err(SettingsError(format!(
                    "--target-error {t}: --combine global weighs every texel's iterations alike, \
                     which a texel that stopped early did not take; use --combine cluster"
                )));
            }
            if self.iterations < 3 {
                return Err(SettingsError(format!(
                    "--target-error {t}: a texel stops after its second iteration at the \
                     earliest and before its last, so give at least 3 (--iterations {}; 8 stops \
                     at every doubling of the samples)",
                    self.iterations
                )));
            }
        }
        Ok(())
    }

    /// `option`'s `n` samples per texel, split over the iterations of the passes that take
    /// them (`passes`; one where a pass bakes in one set, [`Self::needs_iterations`]), must
    /// give each iteration at least one packet of 8 and at most 2^20.
    fn check_per_iteration(
        &self,
        option: &str,
        n: u32,
        passes: impl Iterator<Item = u32>,
    ) -> Result<(), SettingsError> {
        let iterations = self.iterations_of(passes);
        let per_iteration = n / iterations;
        if (8..=1 << 20).contains(&per_iteration) {
            return Ok(());
        }
        let s = if iterations == 1 { "" } else { "s" };
        let fix = if per_iteration < 8 {
            let fewer = n / 8;
            let more = 8 * iterations;
            match fewer {
                0 => format!("{option} {more} would take it"),
                _ => format!(
                    "{option} {more} would take it, or --iterations {fewer} (fewer learning iterations)"
                ),
            }
        } else {
            format!("--iterations {} would take it", n.div_ceil(1 << 20))
        };
        Err(SettingsError(format!(
            "{option} {n} over {iterations} iteration{s} leaves {per_iteration} per iteration: \
             give at least 8 (one packet) and at most 2^20 per iteration; {fix}"
        )))
    }

    /// `--direct-spp N` needs a direct pass (series transport), a packet per iteration and
    /// no more than 2^20 per iteration, and a lightmap that takes its direct light from that
    /// pass ([`Self::lightmap_borrows_direct`]).
    fn validate_direct_spp(&self, n: u32) -> Result<(), SettingsError> {
        let refuse = |why: &str| Err(SettingsError(format!("--direct-spp {n}: {why}")));
        if self.transport != Transport::Series {
            return refuse("the direct pass is series transport's (--transport series)");
        }
        self.check_per_iteration("--direct-spp", n, [DIRECT_PASS].into_iter())?;
        if !self.lightmap_borrows_direct() {
            return refuse(
                "with --directional sh-l1 or --combine global the lightmap estimates its \
                 direct light in its own last pass, weighted against its gather",
            );
        }
        Ok(())
    }

    /// The bake's first pass: [`DIRECT_PASS`] for series transport, which starts with the
    /// direct light alone, else 1. A bake runs passes `first_pass()..=last_pass()`.
    pub fn first_pass(&self) -> u32 {
        match self.transport {
            Transport::Series => DIRECT_PASS,
            Transport::Path => 1,
        }
    }

    /// The bake's last pass, the lightmap: `bounces` for series transport (pass b carries
    /// light through b reflections), 1 for path tracing.
    pub fn last_pass(&self) -> u32 {
        match self.transport {
            Transport::Series => self.bounces,
            Transport::Path => 1,
        }
    }

    /// Whether pass `pass`'s texels leave out their own next-event estimate: the series
    /// passes after the direct pass. Their total is the direct pass's plus their gathered
    /// light, so their gathers trace no shadow ray at the texel: for the passes before the
    /// last the two are added when the next pass's image is built, for the last (the
    /// lightmap) by the finish ([`Self::lightmap_borrows_direct`]).
    pub fn borrows_direct(&self, pass: u32) -> bool {
        self.feeds_lookups(pass)
            || (self.transport == Transport::Series
                && pass == self.last_pass()
                && self.lightmap_borrows_direct())
    }

    /// Whether pass `pass` is a series pass between the direct pass and the last, whose
    /// results only feed the next pass's lookups.
    pub fn feeds_lookups(&self, pass: u32) -> bool {
        self.transport == Transport::Series && pass > DIRECT_PASS && pass < self.last_pass()
    }

    /// The passes whose results only feed the next pass's lookups ([`Self::feeds_lookups`]):
    /// those that take `--lookup-spp`.
    fn lookup_passes(&self) -> impl Iterator<Item = u32> + '_ {
        (self.first_pass()..=self.last_pass()).filter(|&pass| self.feeds_lookups(pass))
    }

    /// Whether pass `pass` keeps the seed of the last pass's guides in its results
    /// ([`GuideSeed::Previous`]): the gather pass right before a guided last pass of series
    /// transport. Its clusters are the last pass's (the same texels, clustered alike).
    pub fn writes_guide_seeds(&self, pass: u32) -> bool {
        self.guide_seed == GuideSeed::Previous
            && matches!(self.guiding, Guiding::Coherent | Guiding::Naive)
            && self.feeds_lookups(pass)
            && pass + 1 == self.last_pass()
    }

    /// Whether pass `pass` seeds its clusters' first guide from the pass before it
    /// ([`Self::writes_guide_seeds`]).
    pub fn reads_guide_seeds(&self, pass: u32) -> bool {
        pass > 0 && self.writes_guide_seeds(pass - 1)
    }

    /// Whether the lightmap takes its texels' direct light from the direct pass (series
    /// transport): the finish adds that pass's estimate to the last pass's gathered light.
    /// Not when the last pass keeps directional coefficients (`--directional sh-l1`: the
    /// direct pass projects none) or its batches for the global weights (`--combine global`):
    /// there its texels estimate the direct light again, weighted against their gather (MIS).
    /// Taking it from the direct pass was 1.08–1.18× as efficient by relative MSE and
    /// 1.07–1.27× by MSE at equal time (docs/estimator.md, "The lightmap's direct light").
    pub fn lightmap_borrows_direct(&self) -> bool {
        self.transport == Transport::Series
            && self.directional == Directional::None
            && self.combine != Combine::Global
    }

    /// Next-event samples per texel of the direct pass in iteration `k`: the gather's
    /// ([`Self::samples_in_iteration`]), scaled by `--direct-spp` over `--spp` in whole packets
    /// (at least one) when it is set.
    pub fn direct_samples_in_iteration(&self, k: u32) -> u32 {
        let n = self.samples_in_iteration(k);
        match self.direct_spp {
            None => n,
            Some(direct) => {
                let packets = f64::from(n / 8) * f64::from(direct) / f64::from(self.spp);
                (packets.round() as u32).max(1) * 8
            }
        }
    }

    /// The settings pass `pass` bakes with: these, with `--guiding off` for a pass
    /// [`GuidedPasses`] leaves unguided (a pass before the last under
    /// [`GuidedPasses::Last`]) and `--lookup-spp` rays for a gather pass before the last.
    ///
    /// A pass that learns nothing from its iterations bakes in one
    /// ([`Self::needs_iterations`]).
    pub fn for_pass(&self, pass: u32) -> BakeSettings {
        let mut settings = self.learning_of(pass);
        if self.feeds_lookups(pass) {
            settings.spp = self.lookup_spp.unwrap_or_else(|| self.default_lookup_spp());
        }
        settings
    }

    /// Pass `pass`'s guiding and iterations, the rest these settings: [`Self::for_pass`]
    /// without the lookup passes' rays.
    fn learning_of(&self, pass: u32) -> BakeSettings {
        let guided = match self.guided_passes {
            GuidedPasses::Last => pass == self.last_pass(),
            GuidedPasses::Every => true,
        };
        let mut settings = BakeSettings {
            guiding: if guided { self.guiding } else { Guiding::Off },
            ..*self
        };
        if !settings.needs_iterations(pass) {
            settings.iterations = 1;
        }
        settings
    }

    /// The most iterations any of `passes` splits its samples into ([`Self::for_pass`]); 1
    /// where there is no such pass.
    fn iterations_of(&self, passes: impl Iterator<Item = u32>) -> u32 {
        passes
            .map(|pass| self.learning_of(pass).iterations)
            .max()
            .unwrap_or(1)
    }

    /// Whether pass `pass`, baked with these settings, needs its samples split into
    /// `--iterations`: a guided pass learns from them, the stopping rule measures its error
    /// between them, global weights keep them, and the direct pass's budget spends its later
    /// ones by the earlier ones' error. A pass that needs none of that gathers each texel's
    /// samples as one presorted set: a set rotated afresh per iteration is stratified only
    /// within itself: the unguided bake's four sets a pass held 1.11–1.50× the relative MSE of
    /// one set at equal samples (docs/sampling.md, "One set, not four").
    pub fn needs_iterations(&self, pass: u32) -> bool {
        let direct_budget = self.transport == Transport::Series
            && pass == DIRECT_PASS
            && self.budget != Budget::Uniform;
        self.guiding != Guiding::Off
            || self.target_error.is_some()
            || self.combine == Combine::Global
            || direct_budget
    }

    /// Gather rays per texel of the lookup passes without `--lookup-spp`: a
    /// [`LOOKUP_SHARE`]th of `--spp`, but at least a packet per iteration they bake in (one
    /// packet where they bake in one set, [`Self::needs_iterations`]) and at most `--spp`.
    /// With their lookups filtered ([`Self::lookup_filter`]) a quarter of the rays cost 1–3 %
    /// of relative MSE against all of them, for 0.57–0.69× the bake's time (256²,
    /// docs/estimator.md, "The lookups: filtered, a quarter of the rays").
    pub fn default_lookup_spp(&self) -> u32 {
        let iterations = self.iterations_of(self.lookup_passes());
        (self.spp / LOOKUP_SHARE).max(8 * iterations).min(self.spp)
    }

    /// Whether the image pass `pass`'s results leave for the next pass is filtered
    /// ([`Self::lookup_filter`]): a gather pass that feeds the next pass's lookups.
    pub fn filters_lookups(&self, pass: u32) -> bool {
        self.lookup_filter > 0 && self.feeds_lookups(pass)
    }

    /// How many passes stream the world: [`Self::first_pass`]`..=`[`Self::last_pass`].
    pub fn pass_count(&self) -> u32 {
        self.last_pass() + 1 - self.first_pass()
    }

    /// Gather rays per texel in iteration `k`, in whole packets of 8.
    ///
    /// `even`: the budget split evenly, the remainder going to the last iteration (which
    /// learns from the best guide). `doubling`: from the last iteration backwards, each takes
    /// half of what is left (rounded up) while leaving one packet to every earlier one, and
    /// iteration 0 takes the rest: 32 packets over 4 iterations are 4, 4, 8, 16.
    pub fn samples_in_iteration(&self, k: u32) -> u32 {
        let packets = self.spp / 8;
        let n = self.iterations;
        match self.schedule {
            Schedule::Even => {
                let base = packets / n;
                let extra = if k + 1 == n { packets % n } else { 0 };
                (base + extra) * 8
            }
            Schedule::Doubling => {
                let mut left = packets;
                for j in (1..n).rev() {
                    let take = left.div_ceil(2).min(left.saturating_sub(j)).max(1);
                    if j == k {
                        return take * 8;
                    }
                    left -= take.min(left);
                }
                left * 8
            }
        }
    }

    /// The cosine baseline's share of the defensive mixture: `--mix` as a fraction.
    pub fn uniform_share(&self) -> f32 {
        self.mix as f32 / 100.0
    }

    /// Identity of a bake of `texel_file_id` with these settings (and [`BAKE_FORMAT`]: work
    /// left by a bake of another layout is not resumed). A bake passes the identity of
    /// everything else that changes its bits here too: the texel file, the scene's geometry,
    /// lights and materials ([`super::run`]).
    pub fn bake_id(&self, texel_file_id: u64) -> u64 {
        let identity = self.identity();
        fnv1a64(format!("{identity} {texel_file_id:016x} format {BAKE_FORMAT}").as_bytes())
    }

    /// The text a bake's identity ([`Self::bake_id`]) and the bench's reference keys hash:
    /// every setting by its field name, `BakeSettings { spp: 256, iterations: 3, … }`, in
    /// the fields' order, each value as its `Debug` (a number, an enum's variant name), with
    /// the settings added after bakes existed written only where they differ from what those
    /// bakes did, so those bakes keep their identity: `budget` only when it is not
    /// [`Budget::Uniform`], `direct_spp` and `lookup_spp` only when they are set,
    /// `lookup_filter` only for [`Transport::Series`], `guide_target` only when it is not
    /// [`GuideTarget::Radiance`], `target_error` only when it is set, `guide_seed` only when
    /// it is [`GuideSeed::Off`], and `flat_below` only when it is set and can act (a guided
    /// series bake whose last pass reads guide seeds). The destructuring names every field
    /// (no `..`), so a field added to the settings does not compile until it is written here;
    /// a test changes each field alone and checks that the identity changes.
    #[must_use]
    pub fn identity(&self) -> String {
        let BakeSettings {
            spp,
            iterations,
            guiding,
            combine,
            bias_correction,
            seed,
            transport,
            bounces,
            mix,
            schedule,
            min_split,
            smooth,
            min_gain,
            flat_below,
            emitters,
            emitter_selection,
            directional,
            guided_passes,
            budget,
            direct_spp,
            lookup_spp,
            lookup_filter,
            guide_target,
            target_error,
            guide_seed,
        } = self;
        let mut fields: Vec<(&str, String)> = vec![
            ("spp", format!("{spp:?}")),
            ("iterations", format!("{iterations:?}")),
            ("guiding", format!("{guiding:?}")),
            ("combine", format!("{combine:?}")),
            ("bias_correction", format!("{bias_correction:?}")),
            ("seed", format!("{seed:?}")),
            ("transport", format!("{transport:?}")),
            ("bounces", format!("{bounces:?}")),
            ("mix", format!("{mix:?}")),
            ("schedule", format!("{schedule:?}")),
            ("min_split", format!("{min_split:?}")),
            ("smooth", format!("{smooth:?}")),
            ("min_gain", format!("{min_gain:?}")),
            ("emitters", format!("{emitters:?}")),
            ("emitter_selection", format!("{emitter_selection:?}")),
            ("directional", format!("{directional:?}")),
            ("guided_passes", format!("{guided_passes:?}")),
        ];
        if *budget != Budget::Uniform {
            fields.push(("budget", format!("{budget:?}")));
        }
        if let Some(direct_spp) = direct_spp {
            fields.push(("direct_spp", format!("{direct_spp:?}")));
        }
        if let Some(lookup_spp) = lookup_spp {
            fields.push(("lookup_spp", format!("{lookup_spp:?}")));
        }
        if *transport == Transport::Series {
            fields.push(("lookup_filter", format!("{lookup_filter:?}")));
        }
        if *guide_target != GuideTarget::Radiance {
            fields.push(("guide_target", format!("{guide_target:?}")));
        }
        if let Some(target_error) = target_error {
            fields.push(("target_error", format!("{target_error:?}")));
        }
        if *guide_seed == GuideSeed::Off {
            fields.push(("guide_seed", format!("{guide_seed:?}")));
        }
        // Judged only where the last pass reads the guide seeds.
        if *flat_below != 0 && self.reads_guide_seeds(self.last_pass()) {
            fields.push(("flat_below", format!("{flat_below:?}")));
        }
        let fields: Vec<String> = fields.iter().map(|(k, v)| format!("{k}: {v}")).collect();
        format!("BakeSettings {{ {} }}", fields.join(", "))
    }

    /// The settings by the `guidebake bake` options that set them (`--spp` → `256`), every
    /// field once: what a work directory's manifest records, so `--resume` names each setting
    /// that differs ([`super::workdir`]). `--direct-spp` and `--lookup-spp` not given read
    /// `default`; `--bias-correction` reads `on` or `off` as the bake applies it.
    #[must_use]
    pub fn options(&self) -> BTreeMap<String, String> {
        fn name<T: clap::ValueEnum + fmt::Debug>(v: &T) -> String {
            v.to_possible_value()
                .map_or_else(|| format!("{v:?}"), |p| p.get_name().to_owned())
        }
        let BakeSettings {
            spp,
            iterations,
            guiding,
            combine,
            bias_correction,
            seed,
            transport,
            bounces,
            mix,
            schedule,
            min_split,
            smooth,
            min_gain,
            flat_below,
            emitters,
            emitter_selection,
            directional,
            guided_passes,
            budget,
            direct_spp,
            lookup_spp,
            lookup_filter,
            guide_target,
            target_error,
            guide_seed,
        } = self;
        let or_default =
            |v: &Option<u32>| v.map_or_else(|| "default".to_owned(), |n| n.to_string());
        [
            ("--spp", spp.to_string()),
            ("--iterations", iterations.to_string()),
            ("--guiding", name(guiding)),
            ("--combine", name(combine)),
            (
                "--bias-correction",
                if *bias_correction { "on" } else { "off" }.to_owned(),
            ),
            ("--seed", seed.to_string()),
            ("--transport", name(transport)),
            ("--bounces", bounces.to_string()),
            ("--mix", mix.to_string()),
            ("--schedule", name(schedule)),
            ("--min-split", min_split.to_string()),
            ("--smooth", smooth.to_string()),
            ("--min-gain", min_gain.to_string()),
            ("--flat-below", flat_below.to_string()),
            ("--emitters", name(emitters)),
            ("--emitter-selection", name(emitter_selection)),
            ("--directional", name(directional)),
            ("--guided-passes", name(guided_passes)),
            ("--budget", name(budget)),
            ("--direct-spp", or_default(direct_spp)),
            ("--lookup-spp", or_default(lookup_spp)),
            ("--lookup-filter", lookup_filter.to_string()),
            ("--guide-target", name(guide_target)),
            (
                "--target-error",
                target_error.map_or_else(|| "none".to_owned(), |e| e.to_string()),
            ),
            ("--guide-seed", name(guide_seed)),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_owned(), v))
        .collect()
    }
}

impl fmt::Display for Guiding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Guiding::Off => "off",
            Guiding::Naive => "naive",
            Guiding::Coherent => "coherent",
            Guiding::Grid => "grid",
        })
    }
}

impl fmt::Display for Combine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Combine::Average => "average",
            Combine::Texel => "texel",
            Combine::Global => "global",
            Combine::Cluster => "cluster",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pass_that_learns_nothing_from_its_iterations_bakes_in_one() {
        let iterations = |s: &BakeSettings| -> Vec<u32> {
            (s.first_pass()..=s.last_pass())
                .map(|p| s.for_pass(p).iterations)
                .collect()
        };
        // The default: the direct pass's budget spends its later iterations by the earlier
        // ones, the lookup passes learn nothing, the last pass is guided.
        let d = BakeSettings::default();
        assert_eq!(iterations(&d), [3, 1, 1, 3]);
        // Unguided: every pass one set; with a uniform budget the direct pass too.
        let off = BakeSettings {
            guiding: Guiding::Off,
            budget: Budget::default_for(Guiding::Off, None),
            combine: Combine::Average,
            ..d
        };
        assert_eq!(iterations(&off), [1, 1, 1, 1]);
        // So a packet per texel is all an unguided bake needs, where the guided bake needs
        // one per iteration of its direct and last passes.
        assert!(BakeSettings { spp: 8, ..off }.validate().is_ok());
        let err = BakeSettings { spp: 16, ..d }
            .validate()
            .unwrap_err()
            .to_string();
        assert!(err.contains("--spp 16 over 3 iterations"), "{err}");
        assert_eq!(
            iterations(&BakeSettings {
                transport: Transport::Path,
                ..off
            }),
            [1]
        );
        // Every guided pass learns; the stopping rule and global weights need the iterations
        // of every pass.
        let every = BakeSettings {
            guided_passes: GuidedPasses::Every,
            ..d
        };
        assert_eq!(iterations(&every), [3, 3, 3, 3]);
        for s in [
            BakeSettings {
                target_error: Some(0.02),
                ..off
            },
            BakeSettings {
                combine: Combine::Global,
                ..off
            },
        ] {
            assert_eq!(iterations(&s), [3, 3, 3, 3]);
        }
    }

    #[test]
    fn the_budget_is_split_in_whole_packets() {
        let s = BakeSettings {
            spp: 200,
            iterations: 3,
            schedule: Schedule::Even,
            ..Default::default()
        };
        let per: Vec<u32> = (0..3).map(|k| s.samples_in_iteration(k)).collect();
        assert_eq!(per, [64, 64, 72]);
        assert!(per.iter().all(|n| n % 8 == 0));
        assert!(s.validate().is_ok());
    }

    #[test]
    fn doubling_gives_the_last_iteration_half() {
        let s = BakeSettings {
            spp: 256,
            iterations: 4,
            schedule: Schedule::Doubling,
            ..Default::default()
        };
        let per: Vec<u32> = (0..4).map(|k| s.samples_in_iteration(k)).collect();
        assert_eq!(per, [32, 32, 64, 128]);
        for (spp, iterations) in [(32, 4), (128, 16), (8, 1), (200, 3), (4096, 7)] {
            let s = BakeSettings {
                spp,
                iterations,
                schedule: Schedule::Doubling,
                ..Default::default()
            };
            let per: Vec<u32> = (0..iterations).map(|k| s.samples_in_iteration(k)).collect();
            assert_eq!(per.iter().sum::<u32>(), spp / 8 * 8, "{per:?}");
            assert!(per.iter().all(|&n| n >= 8 && n % 8 == 0), "{per:?}");
            if spp / 8 >= 1 << (iterations - 1) {
                assert!(2 * per[per.len() - 1] >= spp / 8 * 8, "{per:?}");
            }
        }
    }

    #[test]
    fn the_direct_pass_takes_direct_spp_in_whole_packets_split_as_the_gather_is() {
        let s = BakeSettings {
            spp: 256,
            iterations: 4,
            ..Default::default()
        };
        let per = |s: &BakeSettings| (0..4).map(|k| s.direct_samples_in_iteration(k)).collect();
        let gather: Vec<u32> = (0..4).map(|k| s.samples_in_iteration(k)).collect();
        assert_eq!(per(&s), gather, "unset: the gather's");
        assert!(s.lightmap_borrows_direct() && s.borrows_direct(3) && s.borrows_direct(2));
        assert!(!s.borrows_direct(DIRECT_PASS));
        let twice = BakeSettings {
            direct_spp: Some(512),
            ..s
        };
        assert_eq!(per(&twice), vec![64, 64, 128, 256]);
        assert!(twice.validate().is_ok());
        for own in [
            BakeSettings {
                directional: Directional::ShL1,
                ..s
            },
            BakeSettings {
                combine: Combine::Global,
                ..s
            },
        ] {
            assert!(!own.lightmap_borrows_direct() && !own.borrows_direct(3));
            assert!(own.borrows_direct(2));
        }
        let path = BakeSettings {
            transport: Transport::Path,
            ..s
        };
        assert!(!path.lightmap_borrows_direct() && !path.borrows_direct(1));
        let odd = BakeSettings {
            direct_spp: Some(100),
            ..s
        };
        let odd: Vec<u32> = per(&odd);
        assert!(odd.iter().all(|&n| n >= 8 && n % 8 == 0), "{odd:?}");
        assert_eq!(odd.iter().sum::<u32>(), 104, "{odd:?}: 2, 2, 3, 6 packets");
    }

    #[test]
    fn lookup_spp_is_the_gather_of_the_passes_between_the_direct_pass_and_the_last() {
        let s = BakeSettings {
            lookup_spp: Some(64),
            ..Default::default()
        };
        assert!(s.validate().is_ok());
        let spp: Vec<u32> = (0..=3).map(|pass| s.for_pass(pass).spp).collect();
        assert_eq!(
            spp,
            [256, 64, 64, 256],
            "pass 0 and the lightmap keep --spp"
        );
        // A lookup pass learns nothing from iterations: its 64 rays are one set.
        assert_eq!(s.for_pass(1).iterations, 1);
        assert_eq!(s.for_pass(1).samples_in_iteration(0), 64);
        let path = BakeSettings {
            transport: Transport::Path,
            ..s
        };
        let err = path.validate().unwrap_err().to_string();
        assert!(
            err.contains("--lookup-spp 64") && err.contains("series"),
            "{err}"
        );
        // Baked in one set, a lookup pass needs one packet; guided, a packet per iteration.
        let few = BakeSettings {
            lookup_spp: Some(16),
            ..s
        };
        assert!(few.validate().is_ok());
        let guided = BakeSettings {
            guided_passes: GuidedPasses::Every,
            ..few
        };
        let err = guided.validate().unwrap_err().to_string();
        assert!(
            err.contains("--lookup-spp 16 over 3 iterations") && err.contains("at least 8"),
            "{err}"
        );
        let err = BakeSettings {
            lookup_spp: Some(4),
            ..s
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("--lookup-spp 4 over 1 iteration leaves 4"),
            "{err}"
        );
        assert!(format!("{s:?}").contains("lookup_spp: 64"));
        assert!(!format!("{:?}", BakeSettings::default()).contains("lookup_spp"));
        let wide = BakeSettings {
            lookup_filter: MAX_LOOKUP_FILTER + 1,
            ..BakeSettings::default()
        };
        let err = wide.validate().unwrap_err().to_string();
        assert!(err.contains("--lookup-filter 9"), "{err}");
        let d = BakeSettings::default();
        assert!(
            d.filters_lookups(1) && d.filters_lookups(2),
            "the lookup passes"
        );
        assert!(
            !d.filters_lookups(0) && !d.filters_lookups(3),
            "the direct pass, the lightmap"
        );
        let off = BakeSettings {
            lookup_filter: 0,
            ..d
        };
        assert!(!off.filters_lookups(1));
    }

    #[test]
    fn direct_spp_is_refused_where_the_lightmap_cannot_take_the_direct_pass() {
        let with = |direct_spp: u32, s: BakeSettings| {
            BakeSettings {
                direct_spp: Some(direct_spp),
                ..s
            }
            .validate()
            .map_err(|e| e.to_string())
        };
        let d = BakeSettings::default();
        for (s, n, why) in [
            (
                BakeSettings {
                    transport: Transport::Path,
                    ..d
                },
                256,
                "--transport series",
            ),
            (d, 16, "at least 8"),
            (
                BakeSettings {
                    directional: Directional::ShL1,
                    ..d
                },
                256,
                "--directional sh-l1",
            ),
            (
                BakeSettings {
                    combine: Combine::Global,
                    ..d
                },
                256,
                "--combine global",
            ),
        ] {
            let err = with(n, s).unwrap_err();
            assert!(
                err.contains(&format!("--direct-spp {n}")) && err.contains(why),
                "{err}"
            );
        }
        assert!(with(32, d).is_ok());
        assert!(
            format!(
                "{:?}",
                BakeSettings {
                    direct_spp: Some(32),
                    ..d
                }
            )
            .contains("direct_spp: 32")
        );
    }

    #[test]
    fn bad_settings_say_which_option() {
        let zero = BakeSettings {
            spp: 0,
            ..Default::default()
        };
        assert!(zero.validate().unwrap_err().to_string().contains("--spp 0"));
        let none = BakeSettings {
            iterations: 0,
            ..Default::default()
        };
        assert!(
            none.validate()
                .unwrap_err()
                .to_string()
                .contains("--iterations 0")
        );
        let bounces = BakeSettings {
            bounces: 0,
            ..Default::default()
        };
        assert!(
            bounces
                .validate()
                .unwrap_err()
                .to_string()
                .contains("--bounces 0")
        );
    }

    #[test]
    fn a_guided_bake_gets_the_bounded_budget_unless_it_stops_by_its_error() {
        for guiding in [Guiding::Naive, Guiding::Coherent, Guiding::Grid] {
            assert_eq!(Budget::default_for(guiding, None), Budget::Bounded);
            assert_eq!(Budget::default_for(guiding, Some(0.02)), Budget::Uniform);
        }
        assert_eq!(Budget::default_for(Guiding::Off, None), Budget::Uniform);
        assert_eq!(BakeSettings::default().budget, Budget::Bounded);
    }

    #[test]
    fn a_uniform_budget_and_the_radiance_target_keep_the_identity_bakes_had_before_them() {
        // The guide's target of the bakes before it: their identity and the bench's keys.
        // Path transport has no lookups, so its identity (the bench's references) keeps no
        // filter; series names its filter, which every series bake has had since it came.
        let d = BakeSettings {
            guide_target: GuideTarget::Radiance,
            budget: Budget::Uniform,
            transport: Transport::Path,
            iterations: 4,
            ..BakeSettings::default()
        };
        assert_eq!(
            format!("{d:?}"),
            "BakeSettings { spp: 256, iterations: 4, guiding: Coherent, combine: Cluster, \
             bias_correction: true, seed: 0, transport: Path, bounces: 3, mix: 25, \
             schedule: Doubling, min_split: 64, smooth: 10, min_gain: 25, emitters: Mis, \
             emitter_selection: Local, directional: None, guided_passes: Last }"
        );
        let d = BakeSettings {
            transport: Transport::Series,
            ..d
        };
        assert!(
            format!("{d:?}").ends_with("guided_passes: Last, lookup_filter: 2, flat_below: 1000 }")
        );
        // Guiding every cluster, as series bakes did before `--flat-below`: their identity.
        let d = BakeSettings { flat_below: 0, ..d };
        assert!(format!("{d:?}").ends_with("guided_passes: Last, lookup_filter: 2 }"));
        let unfiltered = BakeSettings {
            lookup_filter: 0,
            ..d
        };
        assert_ne!(unfiltered.bake_id(1), d.bake_id(1));
        let balanced = BakeSettings {
            budget: Budget::Balanced,
            ..d
        };
        assert!(
            format!("{balanced:?}")
                .ends_with("guided_passes: Last, budget: Balanced, lookup_filter: 2 }")
        );
        assert_ne!(balanced.bake_id(1), d.bake_id(1));
        // The default learns the second moment: another bake than the radiance target's.
        let second = BakeSettings {
            budget: Budget::Uniform,
            flat_below: 0,
            ..BakeSettings::default()
        };
        assert_eq!(
            BakeSettings::default().guide_target,
            GuideTarget::SecondMoment
        );
        assert!(
            format!("{second:?}")
                .ends_with("guided_passes: Last, lookup_filter: 2, guide_target: SecondMoment }")
        );
        assert_ne!(second.bake_id(1), d.bake_id(1));
        // And spends its last pass's samples by the bounded budget: another bake again.
        let bounded = BakeSettings {
            flat_below: 0,
            ..BakeSettings::default()
        };
        assert_eq!(bounded.budget, Budget::Bounded);
        assert!(
            format!("{bounded:?}")
                .ends_with("budget: Bounded, lookup_filter: 2, guide_target: SecondMoment }")
        );
        // And leaves the clusters whose light is flat unguided: another bake again.
        assert!(
            format!("{:?}", BakeSettings::default())
                .ends_with("guide_target: SecondMoment, flat_below: 1000 }")
        );
        assert_ne!(BakeSettings::default().bake_id(1), bounded.bake_id(1));
        assert_ne!(bounded.bake_id(1), second.bake_id(1));
        // The stopping rule, set, is another bake too.
        let stopping = BakeSettings {
            target_error: Some(0.02),
            ..second
        };
        assert!(
            format!("{stopping:?}").ends_with("guide_target: SecondMoment, target_error: 0.02 }")
        );
        assert_ne!(stopping.bake_id(1), second.bake_id(1));
    }

    #[test]
    fn a_target_error_is_a_fraction_with_iterations_to_stop_between() {
        let with = |target_error: f32, iterations: u32, combine: Combine| {
            BakeSettings {
                target_error: Some(target_error),
                iterations,
                spp: 1024,
                combine,
                ..BakeSettings::default()
            }
            .validate()
            .map_err(|e| e.to_string())
        };
        assert_eq!(with(0.02, 8, Combine::Cluster), Ok(()));
        for bad in [0.0, -0.1, 1.0, f32::NAN, f32::INFINITY] {
            let e = with(bad, 8, Combine::Cluster).unwrap_err();
            assert!(e.starts_with(&format!("--target-error {bad}: ")), "{e}");
        }
        let e = with(0.02, 2, Combine::Cluster).unwrap_err();
        assert!(e.contains("at least 3 (--iterations 2"), "{e}");
        let e = with(0.02, 8, Combine::Global).unwrap_err();
        assert!(e.contains("--combine global"), "{e}");
    }

    #[test]
    fn the_pass_before_a_guided_last_pass_seeds_its_guides() {
        let d = BakeSettings::default();
        let passes = |s: &BakeSettings, f: fn(&BakeSettings, u32) -> bool| {
            (0..=s.last_pass() + 1)
                .filter(|&p| f(s, p))
                .collect::<Vec<_>>()
        };
        assert_eq!(passes(&d, BakeSettings::writes_guide_seeds), [2]);
        assert_eq!(passes(&d, BakeSettings::reads_guide_seeds), [3]);
        let two = BakeSettings { bounces: 2, ..d };
        assert_eq!(passes(&two, BakeSettings::writes_guide_seeds), [1]);
        assert_eq!(passes(&two, BakeSettings::reads_guide_seeds), [2]);
        // No gather pass before the lightmap (one bounce, path transport), no guide to seed
        // (unguided, the grid comparator), or the seed switched off.
        for s in [
            BakeSettings { bounces: 1, ..d },
            BakeSettings {
                transport: Transport::Path,
                ..d
            },
            BakeSettings {
                guiding: Guiding::Off,
                ..d
            },
            BakeSettings {
                guiding: Guiding::Grid,
                ..d
            },
            BakeSettings {
                guide_seed: GuideSeed::Off,
                ..d
            },
        ] {
            assert!(
                passes(&s, BakeSettings::writes_guide_seeds).is_empty(),
                "{s:?}"
            );
            assert!(
                passes(&s, BakeSettings::reads_guide_seeds).is_empty(),
                "{s:?}"
            );
        }
        // Switched off, the seed is part of the bake's identity.
        let off = BakeSettings {
            guide_seed: GuideSeed::Off,
            ..d
        };
        assert_ne!(d.bake_id(7), off.bake_id(7));
    }

    #[test]
    fn only_the_guided_passes_sample_a_guide() {
        let last = BakeSettings::default();
        assert_eq!(last.guided_passes, GuidedPasses::Last);
        assert_eq!((last.first_pass(), last.last_pass()), (DIRECT_PASS, 3));
        for pass in 0..3 {
            assert_eq!(last.for_pass(pass).guiding, Guiding::Off, "pass {pass}");
        }
        assert_eq!(last.for_pass(3), last);
        let every = BakeSettings {
            guided_passes: GuidedPasses::Every,
            ..last
        };
        // Guided, the lookup passes take a quarter of the rays (at least a packet per iteration).
        let lookup = BakeSettings { spp: 64, ..every };
        assert_eq!(every.for_pass(0), every);
        assert!((1..=2).all(|pass| every.for_pass(pass) == lookup));
        assert_eq!(every.for_pass(3), every);
        let few = |spp| BakeSettings { spp, ..every }.default_lookup_spp();
        assert_eq!((few(1024), few(64), few(16)), (256, 24, 16));
        // Unguided, the lookup passes bake in one set: a packet is their floor.
        let few = |spp| BakeSettings { spp, ..last }.default_lookup_spp();
        assert_eq!((few(1024), few(64), few(16)), (256, 16, 8));
        let set = BakeSettings {
            lookup_spp: Some(128),
            ..every
        };
        assert_eq!(set.for_pass(1).spp, 128);
        let path = BakeSettings {
            transport: Transport::Path,
            ..last
        };
        assert_eq!((path.first_pass(), path.last_pass()), (1, 1));
        assert_eq!(path.for_pass(1), path, "path's one pass is its last");
        assert!(!path.borrows_direct(1));
        assert!((1..=3).all(|pass| last.borrows_direct(pass)));
        assert!(!last.borrows_direct(0));
    }

    #[test]
    fn every_setting_is_named_by_its_option() {
        let a = BakeSettings::default();
        let options = a.options();
        assert_eq!(options.len(), 25, "{options:?}");
        assert_eq!(options["--flat-below"], "1000");
        assert_eq!(options["--spp"], "256");
        assert_eq!(options["--guiding"], "coherent");
        assert_eq!(options["--direct-spp"], "default");
        let b = BakeSettings {
            spp: 64,
            seed: 3,
            ..a
        };
        let differ: Vec<_> = b
            .options()
            .into_iter()
            .filter(|(k, v)| options[k] != *v)
            .map(|(k, _)| k)
            .collect();
        assert_eq!(differ, ["--seed", "--spp"]);
    }

    #[test]
    fn bake_ids_differ_when_the_bits_would() {
        let a = BakeSettings::default();
        let b = BakeSettings { seed: 1, ..a };
        assert_ne!(a.bake_id(7), b.bake_id(7));
        assert_ne!(a.bake_id(7), a.bake_id(8));
        assert_eq!(a.bake_id(7), a.bake_id(7));
    }
    /// The default settings with each field changed alone, by name: every field of
    /// [`BakeSettings`] once (the literal below has no `..`, so a new field must be added here).
    fn each_field_changed() -> Vec<(&'static str, BakeSettings)> {
        let d = BakeSettings::default();
        let BakeSettings {
            spp,
            iterations,
            guiding,
            combine,
            bias_correction,
            seed,
            transport,
            bounces,
            mix,
            schedule,
            min_split,
            smooth,
            min_gain,
            flat_below,
            emitters,
            emitter_selection,
            directional,
            guided_passes,
            budget,
            direct_spp,
            lookup_spp,
            lookup_filter,
            guide_target,
            target_error,
            guide_seed,
        } = d;
        let all = BakeSettings {
            spp,
            iterations,
            guiding,
            combine,
            bias_correction,
            seed,
            transport,
            bounces,
            mix,
            schedule,
            min_split,
            smooth,
            min_gain,
            flat_below,
            emitters,
            emitter_selection,
            directional,
            guided_passes,
            budget,
            direct_spp,
            lookup_spp,
            lookup_filter,
            guide_target,
            target_error,
            guide_seed,
        };
        assert!(all == d);
        vec![
            ("spp", BakeSettings { spp: 512, ..d }),
            ("iterations", BakeSettings { iterations: 4, ..d }),
            (
                "guiding",
                BakeSettings {
                    guiding: Guiding::Naive,
                    ..d
                },
            ),
            (
                "combine",
                BakeSettings {
                    combine: Combine::Texel,
                    ..d
                },
            ),
            (
                "bias_correction",
                BakeSettings {
                    bias_correction: false,
                    ..d
                },
            ),
            ("seed", BakeSettings { seed: 1, ..d }),
            (
                "transport",
                BakeSettings {
                    transport: Transport::Path,
                    ..d
                },
            ),
            ("bounces", BakeSettings { bounces: 2, ..d }),
            ("mix", BakeSettings { mix: 50, ..d }),
            (
                "schedule",
                BakeSettings {
                    schedule: Schedule::Even,
                    ..d
                },
            ),
            ("min_split", BakeSettings { min_split: 32, ..d }),
            ("smooth", BakeSettings { smooth: 20, ..d }),
            ("min_gain", BakeSettings { min_gain: 0, ..d }),
            ("flat_below", BakeSettings { flat_below: 0, ..d }),
            (
                "emitters",
                BakeSettings {
                    emitters: EmitterSampling::Nee,
                    ..d
                },
            ),
            (
                "emitter_selection",
                BakeSettings {
                    emitter_selection: EmitterSelection::Tree,
                    ..d
                },
            ),
            (
                "directional",
                BakeSettings {
                    directional: Directional::ShL1,
                    ..d
                },
            ),
            (
                "guided_passes",
                BakeSettings {
                    guided_passes: GuidedPasses::Every,
                    ..d
                },
            ),
            (
                "budget",
                BakeSettings {
                    budget: Budget::Uniform,
                    ..d
                },
            ),
            (
                "direct_spp",
                BakeSettings {
                    direct_spp: Some(64),
                    ..d
                },
            ),
            (
                "lookup_spp",
                BakeSettings {
                    lookup_spp: Some(32),
                    ..d
                },
            ),
            (
                "lookup_filter",
                BakeSettings {
                    lookup_filter: 0,
                    ..d
                },
            ),
            (
                "guide_target",
                BakeSettings {
                    guide_target: GuideTarget::Radiance,
                    ..d
                },
            ),
            (
                "target_error",
                BakeSettings {
                    target_error: Some(0.05),
                    ..d
                },
            ),
            (
                "guide_seed",
                BakeSettings {
                    guide_seed: GuideSeed::Off,
                    ..d
                },
            ),
        ]
    }

    /// The identities the settings had when they were the hash of a hand-written `Debug`:
    /// work directories, shard files and the bench's references of those bakes stay theirs.
    #[test]
    fn the_identity_of_every_setting_is_the_one_bakes_had() {
        let pinned = [
            ("default", 0x98a6_0b68_ec38_c057),
            ("spp", 0xaa0e_9a7d_f0ef_eda4),
            ("iterations", 0x2922_eb9f_6122_f25a),
            ("guiding", 0xa186_781b_9bb1_e572),
            ("combine", 0x77e5_0370_d7f6_0789),
            ("bias_correction", 0xde1a_7ceb_ab8c_4986),
            ("seed", 0x309a_770a_f5cc_6496),
            ("transport", 0xb775_da2b_9b1e_2604),
            ("bounces", 0x04da_eeed_77af_6f5c),
            ("mix", 0x4eb3_f699_9bc2_8877),
            ("schedule", 0x2e25_d9a1_78c5_9db9),
            ("min_split", 0xa223_77a3_5c16_6a78),
            ("smooth", 0x9c57_2eb4_efc6_5638),
            ("min_gain", 0xe3a6_3c75_9013_e34a),
            ("flat_below", 0xd52e_bdad_5f95_fc1d),
            ("emitters", 0x7e7e_cdbd_e3a6_ed46),
            ("emitter_selection", 0xf266_6a01_c2d5_d456),
            ("directional", 0x53eb_104d_5586_c071),
            ("guided_passes", 0x1aaa_9b08_05cf_c308),
            ("budget", 0x1972_ef6f_1f02_75f1),
            ("direct_spp", 0x37da_c720_3eb7_b650),
            ("lookup_spp", 0x523e_9842_455f_0bf4),
            ("lookup_filter", 0x60ac_1cd4_c9fb_3031),
            ("guide_target", 0x49ae_5342_d38e_4a81),
            ("target_error", 0xe6dc_987a_0800_8910),
            ("guide_seed", 0x43b1_ec4c_5239_4336),
        ];
        let mut settings = vec![("default", BakeSettings::default())];
        settings.extend(each_field_changed());
        assert_eq!(settings.len(), pinned.len());
        for ((name, s), (pinned_name, id)) in settings.into_iter().zip(pinned) {
            assert_eq!(name, pinned_name);
            assert_eq!(s.bake_id(0x0123_4567_89ab_cdef), id, "{name}: {s:?}");
        }
    }

    /// A setting left out of the identity would let `--resume` and `merge` take another
    /// bake's results: each field changed alone changes it.
    #[test]
    fn changing_any_setting_changes_the_identity() {
        let d = BakeSettings::default();
        let changed = each_field_changed();
        for (name, s) in &changed {
            assert_ne!(s.bake_id(7), d.bake_id(7), "{name} is not in the identity");
        }
        let mut ids: Vec<u64> = changed.iter().map(|(_, s)| s.bake_id(7)).collect();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), changed.len());
    }
}
