//! Denoising the lightmap at page-writing time (`--denoise atrous|oidn`).
//!
//! `finish` hands a denoiser one [`Window`] per tile — the tile and a halo of
//! [`Denoiser::halo`] pixels around it, read from the merged results of the tiles around it —
//! and keeps the filtered values of the tile's own texels. Memory stays bounded (a page is
//! never held whole), and every output texel is a function of the merged results alone, so a
//! denoised bake is the same bytes for any shard split.
//!
//! Two denoisers:
//! - [`ATrous`] (`atrous`): the edge-aware À-Trous filter guided by world position, normal and
//!   variance ([`atrous`]);
//! - `Oidn` (`oidn`, with the cargo feature `oidn`): Intel Open Image Denoise's `RTLightmap`
//!   network, run per island of a window (a chart's texels that lie there) on an image whose
//!   other pixels are filled from that island alone ([`islands`]), so no texel takes light from
//!   another chart or from padding. `scripts/oidn/fetch.sh` gets the library.

pub mod atrous;
pub mod islands;
#[cfg(feature = "oidn")]
pub mod oidn;

use glam::Vec3;

pub use atrous::{ATrous, LEVELS, LUMINANCE_SIGMA, NORMAL_POWER};
#[cfg(feature = "oidn")]
pub use oidn::{Oidn, OidnError};

/// Whether this build has the `oidn` denoiser.
pub const OIDN_BUILT_IN: bool = cfg!(feature = "oidn");

/// What a build without the `oidn` feature says when asked for `--denoise oidn`.
pub const OIDN_MISSING: &str = "--denoise oidn needs Intel Open Image Denoise, which this build of guidebake lacks: run scripts/oidn/fetch.sh (it downloads the library and prints the environment to build with), then build with `--features oidn` (e.g. cargo build --release -p guidebake --features oidn)";

/// One baked texel as a denoiser sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoisyTexel {
    /// Irradiance, linear RGB.
    pub rgb: [f32; 3],
    /// Variance of the luminance estimate (squared standard error).
    pub variance: f32,
    /// World position.
    pub position: Vec3,
    /// Unit normal of the side the texel describes.
    pub normal: Vec3,
    /// World size of one texel step (the larger footprint axis).
    pub spacing: f32,
}

/// A rectangle of an atlas page: a tile with its halo. Pixels without a baked texel are
/// `None` (empty atlas, padding, texels inside geometry, or off the page).
#[derive(Clone, Debug, PartialEq)]
pub struct Window {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major texels.
    pub texels: Vec<Option<NoisyTexel>>,
}

/// A lightmap denoiser: filters a window's irradiance. Implementations must be deterministic
/// (the same window gives the same bits) and may read `halo()` pixels around each output.
pub trait Denoiser: Sync {
    /// Pixels around a tile the filter reads.
    fn halo(&self) -> u32;
    /// The filtered irradiance of every pixel of `window` (`None` where it has no texel).
    /// Only pixels at least `halo()` pixels inside the window need be exact.
    fn denoise(&self, window: &Window) -> Vec<Option<[f32; 3]>>;

    /// [`Self::denoise`], and `extra` channels — `count` per pixel of the window, row-major
    /// (e.g. the directional coefficients) — filtered alike. The default leaves them as they
    /// are.
    fn denoise_with(
        &self,
        window: &Window,
        extra: &[f32],
        count: usize,
    ) -> (Vec<Option<[f32; 3]>>, Vec<f32>) {
        let _ = count;
        (self.denoise(window), extra.to_vec())
    }
}

/// A tiny xorshift for the denoisers' tests: noise uniform in [0, 1) (`next`) or of zero mean
/// and a given standard deviation (`centred`), the same sequence on every run.
#[cfg(test)]
pub(crate) struct Noise(pub(crate) u64);

#[cfg(test)]
impl Noise {
    pub(crate) fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform noise of zero mean and standard deviation `sd`.
    pub(crate) fn centred(&mut self, sd: f32) -> f32 {
        (self.next() - 0.5) * sd * 12f32.sqrt()
    }
}
