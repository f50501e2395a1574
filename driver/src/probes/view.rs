//! What `render --probes` draws over the lit scene: every probe as a small white sphere
//! shaded by its own SH (a diffuse white ball at the probe: E(n)/π), and, with `--sphere`, a
//! grey test sphere lit from the probes interpolated at its centre ([`super::field`]) as an
//! engine lights a dynamic object — to check by eye that it matches the lightmapped floor
//! around it (docs/probes.md, "Seeing the probes").

use std::collections::HashMap;

use glam::Vec3;

use super::field::{ProbeField, key};
use super::sh::Sh9;
use crate::render::Overlay;

/// The test sphere's albedo (an 18 % grey card would be darker than most floors; 0.5 is
/// the albedo of the scenes' usual grey).
pub const SPHERE_ALBEDO: f32 = 0.5;

/// A sphere and the SH that lights it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Ball {
    centre: Vec3,
    radius: f32,
    sh: Sh9,
    albedo: f32,
}

impl Ball {
    fn hit(&self, org: Vec3, dir: Vec3, tmax: f32) -> Option<(f32, Vec3)> {
        let oc = org - self.centre;
        let b = oc.dot(dir);
        let c = oc.length_squared() - self.radius * self.radius;
        let disc = b * b - c;
        if disc < 0.0 {
            return None;
        }
        let root = disc.sqrt();
        let t = if -b - root > 0.0 {
            -b - root
        } else {
            -b + root
        };
        if !(t > 0.0 && t < tmax) {
            return None;
        }
        let n = (org + dir * t - self.centre) / self.radius;
        let e = self.sh.irradiance(n).max(Vec3::ZERO);
        Some((t, e * (self.albedo / std::f32::consts::PI)))
    }
}

/// The probes as spheres in a uniform grid (each sphere in every cell its box touches), and
/// the test sphere.
pub struct ProbeOverlay {
    balls: Vec<Ball>,
    cell: f32,
    cells: HashMap<[i32; 3], Vec<u32>>,
    lo: Vec3,
    hi: Vec3,
    sphere: Option<Ball>,
}

impl ProbeOverlay {
    /// The probes of `field` drawn at `radius` (0: not drawn), and a test sphere at
    /// `sphere` (centre, radius) lit by the field there.
    #[must_use]
    pub fn new(field: &ProbeField, radius: f32, sphere: Option<(Vec3, f32)>) -> Self {
        let balls: Vec<Ball> = if radius > 0.0 {
            field
                .probes()
                .iter()
                .map(|p| Ball {
                    centre: p.position,
                    radius,
                    sh: p.sh,
                    albedo: 1.0,
                })
                .collect()
        } else {
            Vec::new()
        };
        let cell = (4.0 * radius).max(1e-6);
        let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for (i, b) in balls.iter().enumerate() {
            let a = key(b.centre - b.radius, cell);
            let z = key(b.centre + b.radius, cell);
            for x in a[0]..=z[0] {
                for y in a[1]..=z[1] {
                    for w in a[2]..=z[2] {
                        cells.entry([x, y, w]).or_default().push(i as u32);
                    }
                }
            }
            lo = lo.min(b.centre - b.radius);
            hi = hi.max(b.centre + b.radius);
        }
        let sphere = sphere.and_then(|(centre, r)| {
            Some(Ball {
                centre,
                radius: r,
                sh: field.at(centre)?,
                albedo: SPHERE_ALBEDO,
            })
        });
        Self {
            balls,
            cell,
            cells,
            lo,
            hi,
            sphere,
        }
    }

    /// The nearest probe sphere along the ray before `tmax`: the grid's cells walked in
    /// order (Amanatides & Woo), stopping at the first cell that holds a hit nearer than
    /// its far side.
    fn nearest_probe(&self, org: Vec3, dir: Vec3, tmax: f32) -> Option<(f32, Vec3)> {
        if self.balls.is_empty() {
            return None;
        }
        // The ray's stretch inside the probes' box.
        let inv = dir.recip();
        let t0 = (self.lo - org) * inv;
        let t1 = (self.hi - org) * inv;
        let enter = t0.min(t1).max_element().max(0.0);
        let leave = t0.max(t1).min_element().min(tmax);
        if enter > leave || enter.is_nan() || leave.is_nan() {
            return None;
        }
        let start = org + dir * enter;
        let mut at = key(start, self.cell);
        let step = [dir.x, dir.y, dir.z].map(|d| if d > 0.0 { 1 } else { -1 });
        let next_edge = |a: usize, c: i32| {
            let edge = (c + i32::from(step[a] > 0)) as f32 * self.cell;
            let (o, d) = (org[a], dir[a]);
            if d == 0.0 {
                f32::INFINITY
            } else {
                (edge - o) / d
            }
        };
        let mut t_next = [
            next_edge(0, at[0]),
            next_edge(1, at[1]),
            next_edge(2, at[2]),
        ];
        let delta = [dir.x, dir.y, dir.z].map(|d| {
            if d == 0.0 {
                f32::INFINITY
            } else {
                self.cell / d.abs()
            }
        });
        let mut best: Option<(f32, Vec3)> = None;
        loop {
            if let Some(ids) = self.cells.get(&at) {
                for &i in ids {
                    let limit = best.map_or(tmax, |b| b.0);
                    if let Some(h) = self.balls[i as usize].hit(org, dir, limit) {
                        best = Some(h);
                    }
                }
            }
            let axis = (0..3)
                .min_by(|&a, &b| t_next[a].total_cmp(&t_next[b]))
                .unwrap_or(0);
            let far = t_next[axis];
            if best.is_some_and(|b| b.0 <= far) || far > leave {
                return best;
            }
            at[axis] += step[axis];
            t_next[axis] += delta[axis];
        }
    }
}

impl Overlay for ProbeOverlay {
    fn hit(&self, org: Vec3, dir: Vec3, tmax: f32) -> Option<(f32, Vec3)> {
        let probe = self.nearest_probe(org, dir, tmax);
        let limit = probe.map_or(tmax, |p| p.0);
        self.sphere.and_then(|s| s.hit(org, dir, limit)).or(probe)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::probes::file::ProbeRecord;

    fn lit(value: f32) -> Sh9 {
        let mut sh = Sh9::default();
        sh.c[0] = Vec3::splat(value * (4.0 * std::f32::consts::PI).sqrt());
        sh
    }

    /// The grid walk finds the same nearest sphere as testing every one, for rays in many
    /// directions through a lattice of probes.
    #[test]
    fn the_grid_walk_finds_the_nearest_probe_sphere() {
        let mut probes = Vec::new();
        for x in 0..6 {
            for y in 0..4 {
                for z in 0..5 {
                    probes.push(ProbeRecord {
                        position: Vec3::new(x as f32, y as f32 * 1.3, z as f32 * 0.7),
                        spacing: 1.0,
                        relative_error: 0.0,
                        sh: lit(1.0 + x as f32),
                    });
                }
            }
        }
        let field = ProbeField::new(probes);
        let overlay = ProbeOverlay::new(&field, 0.2, None);
        let org = Vec3::new(-3.0, 2.1, -2.5);
        let mut hits = 0;
        for i in 0..400 {
            let target = Vec3::new((i % 20) as f32 * 0.3, (i / 20) as f32 * 0.25, 1.7);
            let dir = (target - org).normalize();
            let brute = overlay
                .balls
                .iter()
                .filter_map(|b| b.hit(org, dir, f32::INFINITY))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let walked = overlay.hit(org, dir, f32::INFINITY);
            assert_eq!(walked.map(|h| h.0), brute.map(|h| h.0), "ray {i}");
            hits += usize::from(walked.is_some());
        }
        assert!(hits > 50, "{hits}");
    }

    /// A sphere under constant radiance L with albedo a shows a·L everywhere it is seen.
    #[test]
    fn the_test_sphere_is_lit_by_the_field() {
        let probes = vec![ProbeRecord {
            position: Vec3::ZERO,
            spacing: 4.0,
            relative_error: 0.0,
            sh: lit(2.0),
        }];
        let field = ProbeField::new(probes);
        let overlay = ProbeOverlay::new(&field, 0.0, Some((Vec3::new(0.5, 0.0, 0.0), 0.25)));
        let (t, radiance) = overlay
            .hit(Vec3::new(0.5, 0.0, -5.0), Vec3::Z, f32::INFINITY)
            .unwrap();
        assert!((t - 4.75).abs() < 1e-4);
        assert!(
            (radiance.x - SPHERE_ALBEDO * 2.0).abs() < 1e-3,
            "{radiance}"
        );
        assert!(
            overlay
                .hit(Vec3::new(0.5, 0.0, -5.0), Vec3::Z, 4.0)
                .is_none()
        );
    }
}
