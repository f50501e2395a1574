//! The edge-aware À-Trous wavelet filter (`--denoise atrous`), guided by each texel's world
//! position, normal and variance.
//!
//! The filter is Dammertz et al.'s edge-avoiding À-Trous wavelet transform (HPG 2010) with
//! the variance guidance of SVGF (Schied et al., HPG 2017), applied in atlas space: [`LEVELS`]
//! passes of a 5 × 5 B3-spline kernel whose taps lie 1, 2, … pixels apart. Each tap's weight
//! is the kernel weight times edge-stopping functions that use world space, never UV
//! adjacency alone:
//! - **normal**: `max(0, n_p · n_q)^`[`NORMAL_POWER`] — the two sides of a wall, or the
//!   faces meeting at a geometric edge, do not mix;
//! - **position**: a neighbour farther in world space than its pixel offset allows (another
//!   chart that happens to lie beside this one in the atlas) or off the texel's tangent plane
//!   gets no weight — the filter is chart-aware without knowing the charts;
//! - **luminance**: `exp(−|l_p − l_q| / (`[`LUMINANCE_SIGMA`]` · σ_p))`, σ_p the standard
//!   error of the texel's own estimate (the bake's `rel_std_error` × its luminance; filtered
//!   along with the values, as SVGF does). A texel whose estimate is certain (a dark room that
//!   no light reaches has σ = 0) takes nothing from a brighter neighbour, so light does not
//!   leak under a wall into the dark room even where the floor runs on beneath it.
//!
//! It reads [`ATrous::halo`] pixels around each output, and its directional coefficients are
//! filtered with the irradiance's weights ([`Denoiser::denoise_with`]).

use super::{Denoiser, NoisyTexel, Window};
use guidebake_kernels::estimator::luminance_f32;

/// À-Trous passes of [`ATrous::default`] (taps 1 and 2 pixels apart; chosen by the sweep
/// of docs/bench/denoise/atrous-sweep.md).
pub const LEVELS: u32 = 2;
/// Exponent of the normal weight.
pub const NORMAL_POWER: i32 = 32;
/// Luminance edge-stopping width of [`ATrous::default`], in standard errors (the sweep of
/// docs/denoise.md).
pub const LUMINANCE_SIGMA: f32 = 2.0;
/// The B3-spline kernel of each pass.
const KERNEL: [f32; 5] = [1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0];

/// The edge-aware À-Trous filter of the module docs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ATrous {
    /// Passes (taps 1, 2, …, 2^(levels−1) pixels apart), 1 to 8.
    pub levels: u32,
    /// Luminance edge-stopping width in standard errors.
    pub luminance_sigma: f32,
}

impl Default for ATrous {
    fn default() -> Self {
        Self {
            levels: LEVELS,
            luminance_sigma: LUMINANCE_SIGMA,
        }
    }
}

impl Denoiser for ATrous {
    fn halo(&self) -> u32 {
        // Each pass reaches 2 taps of its step: 2 (1 + 2 + 4 + …).
        2 * ((1 << self.levels.clamp(1, 8)) - 1)
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
        let mut current: Vec<Option<([f32; 3], f32)>> = window
            .texels
            .iter()
            .map(|t| t.map(|t| (t.rgb, t.variance.max(0.0))))
            .collect();
        let mut channels = Extra {
            values: extra.to_vec(),
            count,
        };
        for level in 0..self.levels.clamp(1, 8) {
            (current, channels) = a_trous_pass(
                window,
                &current,
                &channels,
                1 << level,
                self.luminance_sigma,
            );
        }
        let rgb = current.into_iter().map(|c| c.map(|(rgb, _)| rgb)).collect();
        (rgb, channels.values)
    }
}

/// A pixel between passes: irradiance and the variance of its luminance, `None` without a
/// texel.
type Pixel = Option<([f32; 3], f32)>;

/// Channels filtered beside the irradiance with its weights: `count` per pixel.
struct Extra {
    values: Vec<f32>,
    count: usize,
}

/// One À-Trous pass with taps `step` pixels apart: (irradiance, variance) per pixel, and the
/// `extra` channels with the irradiance's weights.
fn a_trous_pass(
    window: &Window,
    values: &[Option<([f32; 3], f32)>],
    extra: &Extra,
    step: usize,
    luminance_sigma: f32,
) -> (Vec<Pixel>, Extra) {
    let (w, h) = (window.width as i64, window.height as i64);
    let mut out = vec![None; values.len()];
    let n = extra.count;
    let mut extra_out = Extra {
        values: extra.values.clone(),
        count: n,
    };
    let mut extra_sum = vec![0.0f64; n];
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let (Some(p), Some((rgb_p, var_p))) = (window.texels[i], values[i]) else {
                continue;
            };
            let l_p = luminance_f32(rgb_p);
            let sigma = luminance_sigma * var_p.sqrt();
            let (mut sum, mut var_sum, mut weight) = ([0.0f64; 3], 0.0f64, 0.0f64);
            extra_sum.fill(0.0);
            for (j, ky) in KERNEL.iter().enumerate() {
                let qy = y + (j as i64 - 2) * step as i64;
                if !(0..h).contains(&qy) {
                    continue;
                }
                for (k, kx) in KERNEL.iter().enumerate() {
                    let qx = x + (k as i64 - 2) * step as i64;
                    if !(0..w).contains(&qx) {
                        continue;
                    }
                    let qi = (qy * w + qx) as usize;
                    let (Some(q), Some((rgb_q, var_q))) = (window.texels[qi], values[qi]) else {
                        continue;
                    };
                    let offset = ((qx - x).pow(2) + (qy - y).pow(2)) as f32;
                    let geometry = geometric_weight(&p, &q, offset.sqrt());
                    if geometry <= 0.0 {
                        continue;
                    }
                    let dl = (luminance_f32(rgb_q) - l_p).abs();
                    let lum = if dl == 0.0 {
                        1.0
                    } else if sigma > 0.0 {
                        (-dl / sigma).exp()
                    } else {
                        0.0
                    };
                    let wgt = f64::from(ky * kx * geometry * lum);
                    if wgt <= 0.0 {
                        continue;
                    }
                    for c in 0..3 {
                        sum[c] += wgt * f64::from(rgb_q[c]);
                    }
                    var_sum += wgt * wgt * f64::from(var_q);
                    weight += wgt;
                    let q_extra = &extra.values[qi * n..(qi + 1) * n];
                    for (e, v) in extra_sum.iter_mut().zip(q_extra) {
                        *e += wgt * f64::from(*v);
                    }
                }
            }
            // The centre tap always has weight > 0, so `weight` > 0.
            let rgb = sum.map(|s| (s / weight) as f32);
            let var = (var_sum / (weight * weight)) as f32;
            out[i] = Some((rgb, var));
            for (o, e) in extra_out.values[i * n..(i + 1) * n]
                .iter_mut()
                .zip(&extra_sum)
            {
                *o = (e / weight) as f32;
            }
        }
    }
    (out, extra_out)
}

/// Normal and position weights of neighbour `q`, `pixels` atlas pixels from `p`.
fn geometric_weight(p: &NoisyTexel, q: &NoisyTexel, pixels: f32) -> f32 {
    let cos = p.normal.dot(q.normal);
    if cos <= 0.0 {
        return 0.0;
    }
    let spacing = p.spacing.max(q.spacing).max(f32::MIN_POSITIVE);
    let d = q.position - p.position;
    // Farther than the pixel offset allows (with slack for stretched charts): another chart.
    if d.length() > spacing * (2.0 * pixels + 1.0) {
        return 0.0;
    }
    let plane = p.normal.dot(d).abs() / spacing;
    cos.powi(NORMAL_POWER) * (-plane).exp()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    use super::super::Noise;

    fn texel(rgb: f32, sd: f32, position: Vec3, normal: Vec3) -> Option<NoisyTexel> {
        Some(NoisyTexel {
            rgb: [rgb; 3],
            variance: sd * sd,
            position,
            normal,
            spacing: 0.1,
        })
    }

    fn rmse(values: &[f32], truth: f32) -> f32 {
        (values.iter().map(|v| (v - truth).powi(2)).sum::<f32>() / values.len() as f32).sqrt()
    }

    #[test]
    fn a_noisy_plane_gets_smoother_and_keeps_its_mean() {
        let (n, truth, sd) = (48usize, 2.0f32, 0.4f32);
        let mut noise = Noise(7);
        let texels = (0..n * n)
            .map(|i| {
                let p = Vec3::new((i % n) as f32 * 0.1, 0.0, (i / n) as f32 * 0.1);
                texel(truth + noise.centred(sd), sd, p, Vec3::Y)
            })
            .collect();
        let window = Window {
            width: n,
            height: n,
            texels,
        };
        let out = ATrous::default().denoise(&window);
        let halo = ATrous::default().halo() as usize;
        let inner = |v: &dyn Fn(usize) -> f32| -> Vec<f32> {
            (halo..n - halo)
                .flat_map(|y| (halo..n - halo).map(move |x| y * n + x))
                .map(v)
                .collect()
        };
        let raw = inner(&|i| window.texels[i].unwrap().rgb[0]);
        let filtered = inner(&|i| out[i].unwrap()[0]);
        let (before, after) = (rmse(&raw, truth), rmse(&filtered, truth));
        assert!(after < before / 3.0, "RMSE {before} → {after}");
        let mean = filtered.iter().sum::<f32>() / filtered.len() as f32;
        assert!((mean - truth).abs() < 0.02, "mean {mean}");
    }

    #[test]
    fn extra_channels_are_filtered_with_the_irradiance_weights() {
        // Two extra channels per pixel: a copy of the red irradiance and its negative times
        // 3 (as a directional coefficient may be). Filtered with the irradiance's weights,
        // they come out as the filtered red (bit for bit: the same sums) and −3 × it (to
        // rounding), and the irradiance is what `denoise` gives.
        let (n, sd) = (24usize, 0.3f32);
        let mut noise = Noise(11);
        let texels: Vec<Option<NoisyTexel>> = (0..n * n)
            .map(|i| {
                let p = Vec3::new((i % n) as f32 * 0.1, 0.0, (i / n) as f32 * 0.1);
                let value = 1.0 + (i % n) as f32 * 0.2 + noise.centred(sd);
                (i % 7 != 3).then(|| texel(value, sd, p, Vec3::Y)).flatten()
            })
            .collect();
        let extra: Vec<f32> = texels
            .iter()
            .flat_map(|t| {
                let red = t.map_or(0.0, |t| t.rgb[0]);
                [red, -3.0 * red]
            })
            .collect();
        let window = Window {
            width: n,
            height: n,
            texels,
        };
        let filter = ATrous::default();
        let (rgb, filtered) = filter.denoise_with(&window, &extra, 2);
        assert_eq!(rgb, filter.denoise(&window));
        let mut changed = 0;
        for (i, value) in rgb.iter().enumerate() {
            match value {
                Some(v) => {
                    assert_eq!(filtered[2 * i].to_bits(), v[0].to_bits(), "pixel {i}");
                    let negative = filtered[2 * i + 1];
                    assert!(
                        (negative + 3.0 * v[0]).abs() <= 1e-6 * v[0].abs(),
                        "pixel {i}"
                    );
                    changed += usize::from(filtered[2 * i] != extra[2 * i]);
                }
                None => assert_eq!(filtered[2 * i..2 * i + 2], extra[2 * i..2 * i + 2]),
            }
        }
        assert!(changed > n * n / 2, "{changed} pixels filtered");
    }

    /// The leak case: a floor that runs on beneath a thin wall (x = 1) from a lit room
    /// (x < 1) into a dark one that no light reaches; in the atlas the two halves are one
    /// chart, side by side, with the wall's two faces (normals ±x) in the rows above.
    #[test]
    fn light_does_not_leak_under_a_thin_wall_into_the_dark_room() {
        let (w, h) = (40usize, 40usize);
        let mut noise = Noise(3);
        let mut texels = vec![None; w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let (px, pz) = (x as f32 * 0.05 + 0.025, y as f32 * 0.05);
                texels[i] = if y < 8 {
                    // The wall's faces: lit side (normal −x) left, dark side (normal +x) right.
                    let lit = x < w / 2;
                    let n = if lit { -Vec3::X } else { Vec3::X };
                    let v = if lit { 3.0 + noise.centred(1.0) } else { 0.0 };
                    texel(v, if lit { 1.0 } else { 0.0 }, Vec3::new(1.0, pz, px), n)
                } else if px < 1.0 {
                    texel(
                        5.0 + noise.centred(2.0),
                        2.0,
                        Vec3::new(px, 0.0, pz),
                        Vec3::Y,
                    )
                } else {
                    texel(0.0, 0.0, Vec3::new(px, 0.0, pz), Vec3::Y)
                };
            }
        }
        let window = Window {
            width: w,
            height: h,
            texels,
        };
        let out = ATrous::default().denoise(&window);
        for y in 0..h {
            for x in w / 2..w {
                let v = out[y * w + x].unwrap();
                assert_eq!(v, [0.0; 3], "dark-room texel ({x}, {y}) took light: {v:?}");
            }
        }
        // And the lit side was filtered.
        let lit: Vec<f32> = (10..h)
            .flat_map(|y| (2..w / 2 - 2).map(move |x| y * w + x))
            .map(|i| out[i].unwrap()[0])
            .collect();
        assert!(rmse(&lit, 5.0) < 2.0 / 2.0, "lit RMSE {}", rmse(&lit, 5.0));
    }

    #[test]
    fn faces_meeting_at_an_edge_and_charts_side_by_side_do_not_mix() {
        // Left half: a floor (normal +y) at 1.0; right half: a wall (normal +x) at 9.0, with
        // positions continuous across the seam (a geometric edge). Bottom rows: a chart of the
        // floor's normal and value 4.0 placed beside the floor in the atlas but 10 m away.
        let (w, h) = (24usize, 24usize);
        let mut texels = vec![None; w * h];
        for y in 0..h {
            for x in 0..w {
                let s = x as f32 * 0.1;
                let t = y as f32 * 0.1;
                texels[y * w + x] = match (x < w / 2, y < h / 2) {
                    (true, true) => texel(1.0, 0.3, Vec3::new(s, 0.0, t), Vec3::Y),
                    (false, true) => texel(9.0, 0.3, Vec3::new(1.2, s - 1.2, t), Vec3::X),
                    (true, false) => texel(1.0, 0.3, Vec3::new(s, 0.0, t), Vec3::Y),
                    (false, false) => texel(4.0, 0.3, Vec3::new(s + 10.0, 0.0, t), Vec3::Y),
                };
            }
        }
        let out = ATrous::default().denoise(&Window {
            width: w,
            height: h,
            texels,
        });
        for y in 0..h {
            for x in 0..w {
                let want = match (x < w / 2, y < h / 2) {
                    (true, _) => 1.0,
                    (false, true) => 9.0,
                    (false, false) => 4.0,
                };
                assert_eq!(out[y * w + x].unwrap()[0], want, "({x}, {y})");
            }
        }
    }
}
