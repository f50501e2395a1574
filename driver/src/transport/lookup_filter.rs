//! The lookups' filter (docs/estimator.md, "The lookups: filtered, a quarter of the rays"):
//! before a series pass's gathered light becomes the next pass's lookups ([`super::series`]),
//! each texel's value is replaced by a weighted mean over the texels around it on its page
//! that lie on the same surface and agree with it within their noise.
//!
//! The next pass reads these values only through its gather rays, each of which averages the
//! four texels around its hit, and sums many of them: what it needs from a texel is the
//! irradiance of the surface around it, not that texel's own noisy estimate. A texel's
//! gathered light is a Monte Carlo estimate whose noise is independent of its neighbours',
//! while indirect light changes slowly over a surface, so averaging a few texels takes most of
//! the noise for little bias (the final-gather argument of photon mapping and irradiance
//! caching; the paper's §1 production setting reads the previous bounce the same way). Only
//! the **gathered** light is filtered: the direct light the pass borrowed from the direct
//! pass, with its shadow edges, is added back unfiltered ([`filter_page`]).
//!
//! The pair of texels at offsets ±d from texel i counts with the weight
//! `exp(−d²/2s²) · n₊ · n₋`, d the distance in texels on the page, s = 0.75 × the radius, and
//! `n = exp(−(Lᵢ − Lⱼ)²/2(σᵢ² + σⱼ²))` for each of the two, L the gathered luminance and σ its
//! standard error (the pass's relative standard error × L): texels whose values differ by more
//! than their noise explains — a real change of the light — barely mix. The window is
//! mirror-symmetric (a texel counts only with its mirror), so a light that changes linearly
//! keeps its value at the texel where the window is cut; with a plain mean the texels along a
//! room's corner came out low (a mean t of −0.28 standard errors over 240 texels,
//! `tests/surfaces.rs`). Texels on another surface never count: normals more than
//! [`NORMAL_COS`] apart, more than [`PLANE_TEXELS`] of a texel off texel i's plane, or farther
//! in the world than the window reaches (a chart that lies close in the atlas but elsewhere in
//! the world).

use glam::Vec3;

use crate::transport::emitters::luminance;

/// Normals of two texels that count toward each other agree at least this much (cosine:
/// about 18°).
pub const NORMAL_COS: f32 = 0.95;

/// A texel counts toward texel i only within this many of texel i's sizes of its plane.
pub const PLANE_TEXELS: f32 = 0.5;

/// What the filter knows of one baked texel: where it lies and how noisy its gathered light is.
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct Surfel {
    /// World position of the texel centre.
    pub position: [f32; 3],
    /// Unit normal.
    pub normal: [f32; 3],
    /// World length of the texel (the longer footprint axis).
    pub size: f32,
    /// Standard error of its gathered luminance.
    pub sigma: f32,
    /// Its gathered light, RGB, as the pass left it.
    pub gathered: [f32; 3],
    /// 1 for a baked texel, 0 for none.
    pub baked: f32,
}

impl Surfel {
    /// A baked texel at `position` with `normal`, a footprint of `size`, and its gathered
    /// light with relative standard error `rel_std_error` (0 when unknown: it then mixes only
    /// with neighbours of exactly its value). Non-finite inputs give no surfel.
    pub fn new(
        position: Vec3,
        normal: Vec3,
        size: f32,
        gathered: [f32; 3],
        rel_std_error: f32,
    ) -> Option<Self> {
        let sigma = rel_std_error.max(0.0) * luminance(Vec3::from(gathered)).abs();
        let finite = rel_std_error.is_finite()
            && position.is_finite()
            && normal.is_finite()
            && size.is_finite()
            && sigma.is_finite()
            && gathered.iter().all(|c| c.is_finite());
        finite.then_some(Self {
            position: position.to_array(),
            normal: normal.normalize_or_zero().to_array(),
            size,
            sigma,
            gathered,
            baked: 1.0,
        })
    }

    fn is_baked(&self) -> bool {
        self.baked == 1.0
    }
}

/// Texel i's filtered gathered light: the weighted mean over the surfels of `page`
/// (`width` × `height`, row-major) within `radius` texels of (`x`, `y`) that pass the surface
/// tests, over a **mirror-symmetric** window: the texel at offset d counts only if the one at
/// −d does, with the same weight (its spatial weight times both texels' noise weights). A
/// light that changes linearly over the surface then keeps its value at the texel even where
/// the window is cut — beside another surface, at a chart's edge — where a plain mean would
/// pull it toward the side that has texels (the light rising into a corner). Texel i itself
/// always counts with weight 1.
fn filtered(
    page: &[Surfel],
    (width, height): (usize, usize),
    (x, y): (usize, usize),
    radius: usize,
) -> Vec3 {
    let me = page[y * width + x];
    filtered_at(&me, (x, y), (width, height), radius, |nx, ny| {
        page[ny * width + nx]
    })
}

/// [`filtered`] of texel `me` at (`x`, `y`) on a page of `width` × `height`, its neighbours
/// given by `at(column, row)` (called on the page only; a surfel that is not baked where no
/// texel is): the pass image's build reads them through its cell table
/// (`transport/pass_image.rs`), the same arithmetic in the same order.
pub fn filtered_at(
    me: &Surfel,
    (x, y): (usize, usize),
    (width, height): (usize, usize),
    radius: usize,
    at: impl Fn(usize, usize) -> Surfel,
) -> Vec3 {
    let (p, n) = (Vec3::from(me.position), Vec3::from(me.normal));
    let lum = luminance(Vec3::from(me.gathered));
    let spread = 0.75 * radius as f32;
    let reach = 1.5 * (radius as f32 + 1.0) * me.size;
    // The texel at offset (dx, dy), with its noise weight, if it passes the surface tests.
    let tap = |dx: isize, dy: isize| -> Option<(Vec3, f32)> {
        let (nx, ny) = (x.checked_add_signed(dx)?, y.checked_add_signed(dy)?);
        if nx >= width || ny >= height {
            return None;
        }
        let other = at(nx, ny);
        if !other.is_baked() || Vec3::from(other.normal).dot(n) < NORMAL_COS {
            return None;
        }
        let offset = Vec3::from(other.position) - p;
        if offset.dot(n).abs() > PLANE_TEXELS * me.size || offset.length() > reach {
            return None;
        }
        let diff = luminance(Vec3::from(other.gathered)) - lum;
        let noise = me.sigma * me.sigma + other.sigma * other.sigma;
        let w = if noise > 0.0 {
            (-diff * diff / (2.0 * noise)).exp()
        } else if diff == 0.0 {
            1.0
        } else {
            0.0
        };
        Some((Vec3::from(other.gathered), w))
    };
    let r = radius as isize;
    let (mut sum, mut weight) = (Vec3::from(me.gathered), 1.0f32);
    // Each pair {d, −d} once: the half-plane dy > 0, and dy = 0 with dx > 0.
    for dy in 0..=r {
        for dx in -r..=r {
            if dy == 0 && dx <= 0 {
                continue;
            }
            let (Some((a, wa)), Some((b, wb))) = (tap(dx, dy), tap(-dx, -dy)) else {
                continue;
            };
            let d2 = (dx * dx + dy * dy) as f32;
            let w = (-d2 / (2.0 * spread * spread)).exp() * wa * wb;
            sum += (a + b) * w;
            weight += 2.0 * w;
        }
    }
    sum / weight
}

/// Filters one page: for every baked pixel `i` of `surfels` (the page's texels, row-major),
/// calls `set(i, change)` with [`filtered`]'s value less the texel's own gathered light; the
/// pass image adds it to both its layers, so the direct light stays as it was. Pixels without
/// a surfel are left alone. Depends on nothing but the page, so the same bits come out
/// whatever baked the pass.
pub fn filter_page(
    surfels: &[Surfel],
    (width, height): (usize, usize),
    radius: u32,
    mut set: impl FnMut(usize, Vec3),
) {
    if radius == 0 {
        return;
    }
    for y in 0..height {
        for x in 0..width {
            if surfels[y * width + x].is_baked() {
                let f = filtered(surfels, (width, height), (x, y), radius as usize);
                set(
                    y * width + x,
                    f - Vec3::from(surfels[y * width + x].gathered),
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w` × `h` page of texels on the plane z = 0, one unit apart, with gathered light
    /// `value(x, y)` and standard error `sigma`.
    fn plane(w: usize, h: usize, sigma: f32, value: impl Fn(usize, usize) -> f32) -> Vec<Surfel> {
        (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let v = value(x, y);
                Surfel {
                    position: [x as f32, y as f32, 0.0],
                    normal: [0.0, 0.0, 1.0],
                    size: 1.0,
                    sigma,
                    gathered: [v; 3],
                    baked: 1.0,
                }
            })
            .collect()
    }

    fn run(page: &[Surfel], w: usize, h: usize, radius: u32) -> Vec<Vec3> {
        let mut out: Vec<Vec3> = page.iter().map(|s| Vec3::from(s.gathered)).collect();
        filter_page(page, (w, h), radius, |i, change| out[i] += change);
        out
    }

    #[test]
    fn a_constant_and_a_linear_ramp_come_out_as_they_went_in() {
        let page = plane(9, 9, 0.5, |_, _| 3.0);
        for v in run(&page, 9, 9, 2) {
            assert!((v - Vec3::splat(3.0)).abs().max_element() < 1e-5, "{v}");
        }
        // A ramp of 0.1 a texel under noise 1 keeps its values everywhere, at the page's
        // edges too, where the window is cut (a one-sided mean would pull them inwards)...
        let page = plane(9, 9, 1.0, |x, y| 1.0 + 0.1 * x as f32 + 0.05 * y as f32);
        let out = run(&page, 9, 9, 2);
        for y in 0..9 {
            for x in 0..9 {
                let want = 1.0 + 0.1 * x as f32 + 0.05 * y as f32;
                let got = out[y * 9 + x].x;
                assert!((got - want).abs() < 1e-4, "({x}, {y}): {got}");
            }
        }
        // ... and where another surface cuts it: a wall's corner, the light rising towards it.
        let mut page = plane(9, 4, 1.0, |x, _| 1.0 + 0.2 * x as f32);
        for s in page.iter_mut().filter(|s| s.position[0] >= 6.0) {
            s.normal = [1.0, 0.0, 0.0];
        }
        let out = run(&page, 9, 4, 2);
        for y in 0..4 {
            let got = out[y * 9 + 5].x;
            assert!((got - 2.0).abs() < 1e-4, "row {y}: {got}");
        }
        // A single row: the texels of its ends have no mirror, and keep their values.
        let page = plane(5, 1, 1.0, |x, _| 1.0 + 0.1 * x as f32);
        let out = run(&page, 5, 1, 2);
        assert!(
            out.iter()
                .all(|v| v.is_finite() && v.x >= 1.0 && v.x <= 1.4)
        );
    }

    #[test]
    fn noise_falls_by_about_the_texels_it_averages() {
        // Independent noise of deviation 0.1 on 1: the 5×5 window's Gaussian weights average
        // about 2π(1.5)² ≈ 14 texels, and the noise term gives a texel far from its
        // neighbours less of them: the variance falls about 4× inside the page.
        let mut state = 12345u32;
        let mut noise = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        let values: Vec<f32> = (0..64 * 64)
            .map(|_| 1.0 + 0.1 * 12f32.sqrt() * noise())
            .collect();
        let page = plane(64, 64, 0.1, |x, y| values[y * 64 + x]);
        let out = run(&page, 64, 64, 2);
        let var = |f: &dyn Fn(usize) -> f32| {
            let inner: Vec<f32> = (0..64 * 64)
                .filter(|i| (2..62).contains(&(i % 64)) && (2..62).contains(&(i / 64)))
                .map(f)
                .collect();
            let mean = inner.iter().sum::<f32>() / inner.len() as f32;
            inner.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / inner.len() as f32
        };
        let (before, after) = (var(&|i| values[i]), var(&|i| out[i].x));
        assert!(after < before / 3.0, "variance {before} → {after}");
        assert!(
            after > before / 20.0,
            "variance {before} → {after}: more than the window"
        );
    }

    #[test]
    fn another_surface_a_step_and_unbaked_pixels_do_not_mix() {
        // Left half at 1, right half at 10 with noise 0.1: a real step, kept.
        let page = plane(8, 4, 0.1, |x, _| if x < 4 { 1.0 } else { 10.0 });
        let out = run(&page, 8, 4, 2);
        for (i, v) in out.iter().enumerate() {
            let want = if i % 8 < 4 { 1.0 } else { 10.0 };
            assert!((v.x - want).abs() < 1e-3, "pixel {i}: {v}");
        }
        // The same values as one noisy surface (σ = 20): they mix.
        let page = plane(8, 4, 20.0, |x, _| if x < 4 { 1.0 } else { 10.0 });
        assert!(run(&page, 8, 4, 2)[3].x > 2.0);
        // Right half turned 90° (a wall meeting the floor), lifted off the plane, or far away
        // in the world though beside it in the atlas, or not baked: no mixing at any noise.
        for change in 0..4 {
            let mut page = plane(8, 4, 20.0, |x, _| if x < 4 { 1.0 } else { 10.0 });
            for s in page.iter_mut().filter(|s| s.position[0] >= 4.0) {
                match change {
                    0 => s.normal = [1.0, 0.0, 0.0],
                    1 => s.position[2] = 0.8,
                    2 => s.position[0] += 100.0,
                    _ => *s = Surfel::default(),
                }
            }
            let out = run(&page, 8, 4, 2);
            for y in 0..4 {
                for x in 0..4 {
                    assert!(
                        (out[y * 8 + x].x - 1.0).abs() < 1e-5,
                        "change {change}, ({x}, {y})"
                    );
                }
            }
        }
    }

    #[test]
    fn radius_zero_and_bad_input_leave_every_value() {
        let page = plane(4, 4, 1.0, |x, y| (x + y) as f32);
        let out = run(&page, 4, 4, 0);
        assert!(out.iter().zip(&page).all(|(v, s)| v.x == s.gathered[0]));
        let ok = Surfel::new(Vec3::ZERO, Vec3::Z, 1.0, [1.0; 3], 0.1).unwrap();
        assert!((ok.sigma - 0.1).abs() < 1e-6 && ok.is_baked());
        assert!(Surfel::new(Vec3::NAN, Vec3::Z, 1.0, [1.0; 3], 0.1).is_none());
        assert!(Surfel::new(Vec3::ZERO, Vec3::Z, 1.0, [f32::INFINITY; 3], 0.1).is_none());
        assert!(Surfel::new(Vec3::ZERO, Vec3::Z, 1.0, [1.0; 3], f32::NAN).is_none());
        // A surfel without noise mixes only with its equals: the ramp stays.
        let page = plane(5, 1, 0.0, |x, _| x as f32);
        let out = run(&page, 5, 1, 2);
        assert!(out.iter().enumerate().all(|(i, v)| v.x == i as f32));
    }
}
