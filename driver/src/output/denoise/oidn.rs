//! Intel Open Image Denoise's `RTLightmap` filter as a chart-aware [`Denoiser`]
//! (`--denoise oidn`, cargo feature `oidn`; `scripts/oidn/fetch.sh` gets the library).
//!
//! OIDN is an image network: run on an atlas as it stands it mixes neighbouring charts and
//! the padding between them. Here it runs per island of each window ([`super::islands`]):
//! the island on its bounding box plus [`MARGIN`] pixels, every other pixel filled from the
//! island's own texels by dilation, and only the island's texels taken back. Islands of
//! fewer than [`MIN_ISLAND`] texels are left as baked.
//!
//! - **Irradiance**: `RTLightmap` in HDR mode on linear RGB. The filter takes no albedo or
//!   normal auxiliary images (OIDN documents `color`, `output` and `directional` for it; the
//!   auxiliaries belong to the `RT` filter), and an island image needs none: its texels lie on
//!   one smooth surface.
//! - **Certainty**: the output is held within [`CLAMP_SIGMAS`] standard errors of the texel's
//!   own estimate. A texel whose estimate is certain (σ = 0, e.g. a room no light reaches, its
//!   floor one chart with the lit room's under a thin wall) keeps its value exactly; the
//!   network, which sees no variance, would otherwise carry the lit side's light over the
//!   edge.
//! - **Directional coefficients** (`--directional sh-l1`), as OIDN documents for directional
//!   lightmaps: L0 as HDR colour, each L1 layer normalised by `√3 · L0` per channel (into
//!   [−1, 1]) and filtered with `directional` set, then multiplied back by `√3` × the
//!   filtered L0. A texel whose irradiance is certain keeps its coefficients.
//! - **Determinism**: each worker thread has its own OIDN CPU device with one thread
//!   (`numThreads = 1`, no affinity), and a window's result depends on that window alone, so a
//!   page is the same bytes at any thread count on one machine and library. OIDN itself
//!   promises no more than that: its CPU kernels are chosen per instruction set, so another
//!   CPU or OIDN version may round differently.
//! - **Errors**: the library's errors (a missing CPU device library, out of memory) come back
//!   as [`OidnError`]; a window whose filtering fails, or any output that is not finite,
//!   keeps the texels' own estimates (never a NaN in a page).

use std::ffi::{CStr, c_char};
use std::sync::Mutex;

use oidn::sys;

use super::islands::{IslandImage, Islands};
use super::{Denoiser, NoisyTexel, Window};
use guidebake_kernels::estimator::luminance_f32;

/// Pixels of a tile's halo: how much of its surroundings the network sees.
pub const HALO: u32 = 16;
/// Pixels each island image reaches past the island's bounding box.
pub const MARGIN: usize = 4;
/// Island images are rounded up to this many pixels a side (fewer distinct sizes, fewer
/// re-commits of the filter).
pub const ROUND: usize = 16;
/// How many standard errors the output may move from the texel's estimate.
pub const CLAMP_SIGMAS: f32 = 3.0;
/// Islands of fewer texels are left as baked: on a level's tiny charts the network, seeing
/// mostly the dilated fill, raised the error (docs/denoise.md).
pub const MIN_ISLAND: usize = 32;
/// `|L1| ≤ √3 · L0` for non-negative radiance in this SH basis (`Y1 / Y0`).
const L1_BOUND: f32 = 1.732_050_8;

/// A failure of the OIDN library.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("Intel Open Image Denoise: {0}")]
pub struct OidnError(pub String);

/// One OIDN CPU device with its two `RTLightmap` filters (HDR and directional).
struct Engine {
    device: sys::OIDNDevice,
    hdr: sys::OIDNFilter,
    directional: sys::OIDNFilter,
}

// The handles are used by one thread at a time (taken from and returned to the pool).
unsafe impl Send for Engine {}

impl Engine {
    fn new() -> Result<Self, OidnError> {
        // SAFETY: plain OIDN calls on handles created here; names are NUL-terminated.
        unsafe {
            let device = sys::oidnNewDevice(sys::OIDNDeviceType_OIDN_DEVICE_TYPE_CPU);
            if device.is_null() {
                return Err(OidnError(
                    "no CPU device (is libOpenImageDenoise_device_cpu beside libOpenImageDenoise?)"
                        .into(),
                ));
            }
            sys::oidnSetDeviceInt(device, c"numThreads".as_ptr(), 1);
            sys::oidnSetDeviceBool(device, c"setAffinity".as_ptr(), false);
            sys::oidnCommitDevice(device);
            let mut engine = Self {
                device,
                hdr: std::ptr::null_mut(),
                directional: std::ptr::null_mut(),
            };
            engine.check("creating the CPU device")?;
            engine.hdr = engine.filter(false)?;
            engine.directional = engine.filter(true)?;
            Ok(engine)
        }
    }

    /// A new `RTLightmap` filter, directional or HDR.
    unsafe fn filter(&self, directional: bool) -> Result<sys::OIDNFilter, OidnError> {
        // SAFETY: the device is live.
        let filter = unsafe { sys::oidnNewFilter(self.device, c"RTLightmap".as_ptr()) };
        self.check("creating the RTLightmap filter")?;
        if filter.is_null() {
            return Err(OidnError("the RTLightmap filter is missing".into()));
        }
        // SAFETY: the filter is live.
        unsafe { sys::oidnSetFilterBool(filter, c"directional".as_ptr(), directional) };
        Ok(filter)
    }

    /// The device's pending error, if any, said with `doing`.
    fn check(&self, doing: &str) -> Result<(), OidnError> {
        let mut message: *const c_char = std::ptr::null();
        // SAFETY: the device is live; OIDN owns the message until the next call.
        let code = unsafe { sys::oidnGetDeviceError(self.device, &mut message) };
        if code == sys::OIDNError_OIDN_ERROR_NONE {
            return Ok(());
        }
        let text = if message.is_null() {
            format!("error {code}")
        } else {
            // SAFETY: a NUL-terminated string from OIDN.
            unsafe { CStr::from_ptr(message) }
                .to_string_lossy()
                .into_owned()
        };
        Err(OidnError(format!("{doing}: {text}")))
    }

    /// Filters `image` (RGB, `width` × `height`) in place.
    fn run(
        &mut self,
        directional: bool,
        image: &mut [f32],
        width: usize,
        height: usize,
    ) -> Result<(), OidnError> {
        assert_eq!(image.len(), 3 * width * height, "image size");
        let filter = if directional {
            self.directional
        } else {
            self.hdr
        };
        let input = image.to_vec();
        // SAFETY: both images hold 3 × width × height floats and outlive the execution,
        // which is synchronous; the filter is live and used by this thread alone.
        unsafe {
            let float3 = sys::OIDNFormat_OIDN_FORMAT_FLOAT3;
            let color = input.as_ptr().cast_mut().cast();
            let output = image.as_mut_ptr().cast();
            sys::oidnSetSharedFilterImage(
                filter,
                c"color".as_ptr(),
                color,
                float3,
                width,
                height,
                0,
                0,
                0,
            );
            sys::oidnSetSharedFilterImage(
                filter,
                c"output".as_ptr(),
                output,
                float3,
                width,
                height,
                0,
                0,
                0,
            );
            sys::oidnCommitFilter(filter);
            sys::oidnExecuteFilter(filter);
        }
        self.check("filtering")
    }
}

impl Drop for Engine {
    fn drop(&mut self) {
        // SAFETY: handles created by this engine, released once.
        unsafe {
            for filter in [self.hdr, self.directional] {
                if !filter.is_null() {
                    sys::oidnReleaseFilter(filter);
                }
            }
            sys::oidnReleaseDevice(self.device);
        }
    }
}

/// A window's filtered irradiance (per pixel, `None` without a texel) and extra channels.
pub type Filtered = (Vec<Option<[f32; 3]>>, Vec<f32>);

/// The chart-aware OIDN denoiser of the module docs.
pub struct Oidn {
    /// Idle engines; a thread takes one (or makes one) per window.
    pool: Mutex<Vec<Engine>>,
    /// How many standard errors the output may move from the estimate.
    pub clamp_sigmas: f32,
    /// Islands of fewer texels are left as baked.
    pub min_island: usize,
}

impl Oidn {
    /// A denoiser whose first engine is made now, so a missing or broken library is an
    /// error before any page is written.
    ///
    /// # Errors
    /// [`OidnError`] when OIDN cannot make a CPU device or an `RTLightmap` filter.
    pub fn new() -> Result<Self, OidnError> {
        Ok(Self {
            pool: Mutex::new(vec![Engine::new()?]),
            clamp_sigmas: CLAMP_SIGMAS,
            min_island: MIN_ISLAND,
        })
    }

    /// Runs `work` with an engine from the pool.
    fn with_engine<T>(&self, work: impl FnOnce(&mut Engine) -> T) -> Result<T, OidnError> {
        let taken = self.pool.lock().unwrap_or_else(|e| e.into_inner()).pop();
        let mut engine = match taken {
            Some(engine) => engine,
            None => Engine::new()?,
        };
        let result = work(&mut engine);
        self.pool
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(engine);
        Ok(result)
    }

    /// The filtered irradiance and (with `count` = 12) directional coefficients of every
    /// island of `window` of at least `min_island` texels; the rest as they were.
    ///
    /// # Errors
    /// [`OidnError`] from the library.
    pub fn try_denoise_with(
        &self,
        window: &Window,
        extra: &[f32],
        count: usize,
    ) -> Result<Filtered, OidnError> {
        let mut rgb: Vec<Option<[f32; 3]>> =
            window.texels.iter().map(|t| t.map(|t| t.rgb)).collect();
        let mut out_extra = extra.to_vec();
        let islands = Islands::of(window);
        let directional = count == 12 && extra.len() == 12 * window.texels.len();
        self.with_engine(|engine| -> Result<(), OidnError> {
            // Every island, those in the halo too: a window clipped at the page's edge holds its
            // tile off centre, so which pixels are the tile's is not known here.
            for island in 0..islands.boxes.len() {
                let image = IslandImage::new(&islands, window.width, island, MARGIN, ROUND);
                if image.own.iter().filter(|own| **own).count() < self.min_island {
                    continue;
                }
                let texel = |i: usize| window.texels[i].expect("island pixels hold texels");
                let filtered = filter_layer(engine, &image, false, |i| texel(i).rgb)?;
                for (at, i) in image.own_pixels() {
                    rgb[i] = Some(held(&texel(i), pixel(&filtered, at), self.clamp_sigmas));
                }
                if directional {
                    let sh = filter_directional(engine, &image, extra)?;
                    for (at, i) in image.own_pixels() {
                        if texel(i).variance > 0.0 {
                            let values = sh.iter().flat_map(|layer| pixel(layer, at));
                            copy_finite(&mut out_extra[12 * i..12 * (i + 1)], values);
                        }
                    }
                }
            }
            Ok(())
        })??;
        Ok((rgb, out_extra))
    }
}

/// Pixel `at` of an RGB image.
fn pixel(image: &[f32], at: usize) -> [f32; 3] {
    [image[3 * at], image[3 * at + 1], image[3 * at + 2]]
}

/// One layer of an island image, filtered.
fn filter_layer(
    engine: &mut Engine,
    image: &IslandImage,
    directional: bool,
    value: impl Fn(usize) -> [f32; 3],
) -> Result<Vec<f32>, OidnError> {
    let mut layer = image.layer(value);
    engine.run(directional, &mut layer, image.width, image.height)?;
    Ok(layer)
}

/// The four SH layers of an island image, filtered as OIDN documents for directional
/// lightmaps: L0 as HDR, each L1 layer normalised by `√3 · L0` and filtered as directional,
/// then scaled back by the filtered L0.
fn filter_directional(
    engine: &mut Engine,
    image: &IslandImage,
    extra: &[f32],
) -> Result<[Vec<f32>; 4], OidnError> {
    let coefficient = |i: usize, layer: usize| -> [f32; 3] {
        std::array::from_fn(|c| extra[12 * i + 3 * layer + c])
    };
    let l0 = filter_layer(engine, image, false, |i| coefficient(i, 0))?;
    let mut layers = [l0.clone(), Vec::new(), Vec::new(), Vec::new()];
    for (axis, slot) in layers.iter_mut().enumerate().skip(1) {
        let normalised = |i: usize| -> [f32; 3] {
            let (l0, l1) = (coefficient(i, 0), coefficient(i, axis));
            std::array::from_fn(|c| {
                let bound = L1_BOUND * l0[c];
                if bound > 0.0 {
                    (l1[c] / bound).clamp(-1.0, 1.0)
                } else {
                    0.0
                }
            })
        };
        let mut filtered = filter_layer(engine, image, true, normalised)?;
        for (v, l0) in filtered.iter_mut().zip(&l0) {
            *v *= L1_BOUND * l0.max(0.0);
        }
        *slot = filtered;
    }
    Ok(layers)
}

/// `filtered` held within `sigmas` standard errors of the texel's estimate, non-negative,
/// and the estimate itself where the filter gave something not finite.
fn held(texel: &NoisyTexel, filtered: [f32; 3], sigmas: f32) -> [f32; 3] {
    if !filtered.iter().all(|v| v.is_finite()) {
        return texel.rgb;
    }
    // The luminance's standard error, spread over the channels in proportion to each.
    let sd = texel.variance.max(0.0).sqrt();
    let luminance = luminance_f32(texel.rgb);
    std::array::from_fn(|c| {
        let own = texel.rgb[c];
        let share = if luminance > 0.0 {
            (own / luminance).abs()
        } else {
            1.0
        };
        // An infinite `sigmas` holds nothing (∞ · 0 would be NaN where σ = 0).
        let reach = if sigmas.is_finite() {
            sigmas * sd * share
        } else {
            f32::INFINITY
        };
        if reach.is_nan() {
            return own;
        }
        filtered[c].clamp(own - reach, own + reach).max(0.0)
    })
}

/// `values` into `out` where every one is finite; else `out` is left as it is.
fn copy_finite(out: &mut [f32], values: impl Iterator<Item = f32>) {
    let values: Vec<f32> = values.collect();
    if values.len() == out.len() && values.iter().all(|v| v.is_finite()) {
        out.copy_from_slice(&values);
    }
}

impl Denoiser for Oidn {
    fn halo(&self) -> u32 {
        HALO
    }

    fn denoise(&self, window: &Window) -> Vec<Option<[f32; 3]>> {
        self.denoise_with(window, &[], 0).0
    }

    fn denoise_with(
        &self,
        window: &Window,
        extra: &[f32],
        count: usize,
    ) -> (Vec<Option<[f32; 3]>>, Vec<f32>) {
        // A failure here (the library worked when `new` made the first engine) leaves the
        // window as baked: the page is still written, with no NaN in it.
        self.try_denoise_with(window, extra, count)
            .unwrap_or_else(|e| {
                eprintln!("guidebake: warning: a window was left undenoised: {e}");
                (
                    window.texels.iter().map(|t| t.map(|t| t.rgb)).collect(),
                    extra.to_vec(),
                )
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    use super::super::Noise;

    /// Edge of the charts of [`atlas`] and the padding between them.
    const CHART: usize = 8;
    const PADDING: usize = 2;
    const PITCH: usize = CHART + PADDING;

    /// The true irradiance of chart `k` of [`atlas`]: bright and dark in a checkerboard.
    fn truth(k: usize) -> f32 {
        if (k + k / 8).is_multiple_of(2) {
            50.0
        } else {
            0.5
        }
    }

    /// An 80 × 80 window of 8 × 8 small charts (8 × 8 texels, 2 pixels of padding), each a
    /// patch of floor 10 m from the next, lit bright or dark ([`truth`]) with noise of
    /// relative standard deviation 0.5. `keep(k)` picks the charts present.
    fn atlas(keep: impl Fn(usize) -> bool) -> Window {
        let n = 8 * PITCH;
        let mut noise = Noise(17);
        let texels = (0..n * n)
            .map(|i| {
                let (x, y) = (i % n, i / n);
                let sample = noise.next();
                let (cx, cy) = (x / PITCH, y / PITCH);
                let k = cy * 8 + cx;
                if x % PITCH >= CHART || y % PITCH >= CHART || !keep(k) {
                    return None;
                }
                let value = truth(k) * (1.0 + (sample - 0.5) * 3f32.sqrt());
                let sd = 0.5 * truth(k);
                Some(NoisyTexel {
                    rgb: [value; 3],
                    variance: sd * sd,
                    position: Vec3::new(
                        10.0 * k as f32 + (x % PITCH) as f32 * 0.1,
                        0.0,
                        (y % PITCH) as f32 * 0.1,
                    ),
                    normal: Vec3::Y,
                    spacing: 0.1,
                })
            })
            .collect();
        Window {
            width: n,
            height: n,
            texels,
        }
    }

    fn chart_of(i: usize) -> usize {
        let n = 8 * PITCH;
        (i / n / PITCH) * 8 + (i % n) / PITCH
    }

    #[test]
    fn each_small_chart_is_denoised_as_if_it_were_alone_in_the_atlas() {
        let oidn = Oidn::new().unwrap();
        let window = atlas(|_| true);
        let together = oidn.try_denoise_with(&window, &[], 0).unwrap().0;
        let n = window.width;
        let (mut before, mut after, mut compared) = (0.0f64, 0.0f64, 0);
        for k in 0..64 {
            let alone = oidn.try_denoise_with(&atlas(|c| c == k), &[], 0).unwrap().0;
            for i in (0..n * n).filter(|&i| chart_of(i) == k && window.texels[i].is_some()) {
                // Bit for bit: neither the bright charts around a dark one nor the padding
                // reach it.
                assert_eq!(together[i], alone[i], "chart {k}, pixel {i}");
                let t = f64::from(truth(k));
                before += (f64::from(window.texels[i].unwrap().rgb[0]) / t - 1.0).powi(2);
                after += (f64::from(together[i].unwrap()[0]) / t - 1.0).powi(2);
                compared += 1;
            }
        }
        assert_eq!(compared, 64 * CHART * CHART);
        // And the filter did its work: the relative error fell.
        assert!(
            after < before / 2.0,
            "relative squared error {before} → {after}"
        );
    }

    #[test]
    fn islands_below_the_least_size_are_left_as_baked() {
        let oidn = Oidn {
            min_island: CHART * CHART + 1,
            ..Oidn::new().unwrap()
        };
        let window = atlas(|_| true);
        let out = oidn.try_denoise_with(&window, &[], 0).unwrap().0;
        let raw: Vec<_> = window.texels.iter().map(|t| t.map(|t| t.rgb)).collect();
        assert_eq!(out, raw);
    }

    #[test]
    fn a_certain_texel_keeps_its_value_beside_a_lit_one() {
        // One floor chart running from a lit room (x < 16, noisy) under a thin wall into a
        // dark room that no light reaches (σ = 0): the dark half stays exactly 0.
        let n = 48;
        let mut noise = Noise(5);
        let texels = (0..n * n)
            .map(|i| {
                let (x, y) = (i % n, i / n);
                let lit = x < 24;
                let value = if lit {
                    5.0 + 4.0 * (noise.next() - 0.5)
                } else {
                    0.0
                };
                Some(NoisyTexel {
                    rgb: [value; 3],
                    variance: if lit { 1.5 } else { 0.0 },
                    position: Vec3::new(x as f32 * 0.1, 0.0, y as f32 * 0.1),
                    normal: Vec3::Y,
                    spacing: 0.1,
                })
            })
            .collect();
        let window = Window {
            width: n,
            height: n,
            texels,
        };
        let out = Oidn::new()
            .unwrap()
            .try_denoise_with(&window, &[], 0)
            .unwrap()
            .0;
        for i in (0..n * n).filter(|i| i % n >= 24) {
            assert_eq!(out[i], Some([0.0; 3]), "dark texel {i}");
        }
    }

    #[test]
    fn any_thread_count_gives_the_same_bits() {
        let windows: Vec<Window> = (0..6).map(|k| atlas(move |c| c % 6 != k)).collect();
        let run = |threads: usize| {
            let oidn = Oidn::new().unwrap();
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                use rayon::prelude::*;
                windows
                    .par_iter()
                    .map(|w| oidn.try_denoise_with(w, &[], 0).unwrap().0)
                    .collect::<Vec<_>>()
            })
        };
        assert_eq!(run(1), run(2));
    }

    #[test]
    fn directional_coefficients_keep_their_direction_and_follow_the_filtered_l0() {
        // Every texel's L1 points along +x at half its bound (√3/2 · L0) with a noisy L0:
        // the filtered coefficients still do, and L0 is smoother.
        let window = atlas(|_| true);
        let mut noise = Noise(9);
        let extra: Vec<f32> = window
            .texels
            .iter()
            .flat_map(|t| {
                let l0 = t.map_or(0.0, |t| t.rgb[0] * (0.8 + 0.4 * noise.next()));
                let l1x = 0.5 * L1_BOUND * l0;
                [l0, l0, l0, l1x, l1x, l1x, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            })
            .collect();
        let (_, out) = Oidn::new()
            .unwrap()
            .try_denoise_with(&window, &extra, 12)
            .unwrap();
        let mut changed = 0;
        for (i, t) in window.texels.iter().enumerate() {
            let (c, e) = (&out[12 * i..12 * (i + 1)], &extra[12 * i..12 * (i + 1)]);
            if t.is_none() {
                assert_eq!(c, e);
                continue;
            }
            changed += usize::from(c[0] != e[0]);
            if c[0] > 0.0 {
                let ratio = c[3] / (L1_BOUND * c[0]);
                assert!((ratio - 0.5).abs() < 0.1, "texel {i}: L1x / bound {ratio}");
                assert!(
                    c[6].abs() <= 0.1 * L1_BOUND * c[0],
                    "texel {i}: L1y {}",
                    c[6]
                );
            }
        }
        assert!(changed > 500, "{changed} texels' L0 filtered");
    }
}
