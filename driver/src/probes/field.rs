//! Probes interpolated at any point, as an engine lights a dynamic object from them
//! (docs/probes.md, "Interpolating the probes"): each probe weighs the tent of its own
//! spacing along each axis, Π max(0, 1 − |x − p| / s), and the weights are normalised. On a
//! full regular lattice that is trilinear interpolation; across the adaptive lattice's levels
//! the coarse probes fade where the fine ones stand; where probes inside geometry were not
//! placed the others share their weight. A point no probe reaches takes the nearest probe.

use std::collections::HashMap;

use glam::Vec3;

use super::file::ProbeRecord;
use super::sh::Sh9;

/// Probes indexed for interpolation.
pub struct ProbeField {
    probes: Vec<ProbeRecord>,
    cell: f32,
    cells: HashMap<[i32; 3], Vec<u32>>,
}

impl ProbeField {
    /// Indexes `probes` in cells as wide as the widest spacing (so a point's probes lie in its
    /// cell and the 26 around it).
    #[must_use]
    pub fn new(probes: Vec<ProbeRecord>) -> Self {
        let cell = probes
            .iter()
            .map(|p| p.spacing)
            .fold(0.0f32, f32::max)
            .max(1e-6);
        let mut cells: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
        for (i, p) in probes.iter().enumerate() {
            cells
                .entry(key(p.position, cell))
                .or_default()
                .push(i as u32);
        }
        Self {
            probes,
            cell,
            cells,
        }
    }

    /// The probes, in file order.
    #[must_use]
    pub fn probes(&self) -> &[ProbeRecord] {
        &self.probes
    }

    /// The SH at `x` (module docs); `None` without probes.
    #[must_use]
    pub fn at(&self, x: Vec3) -> Option<Sh9> {
        let [cx, cy, cz] = key(x, self.cell);
        let mut sum = Sh9::default();
        let mut total = 0.0f32;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(ids) = self.cells.get(&[cx + dx, cy + dy, cz + dz]) else {
                        continue;
                    };
                    for &i in ids {
                        let p = &self.probes[i as usize];
                        let d = (x - p.position).abs() / p.spacing;
                        let w = (1.0 - d).max(Vec3::ZERO);
                        let w = w.x * w.y * w.z;
                        if w > 0.0 {
                            sum = sum.plus(&p.sh.scaled(w));
                            total += w;
                        }
                    }
                }
            }
        }
        if total > 0.0 {
            return Some(sum.scaled(1.0 / total));
        }
        self.probes
            .iter()
            .min_by(|a, b| {
                a.position
                    .distance_squared(x)
                    .total_cmp(&b.position.distance_squared(x))
            })
            .map(|p| p.sh)
    }
}

/// The cell of side `cell` that holds `p`, in a uniform grid from the origin (also the
/// drawn probes' grid, [`super::view`]).
pub(crate) fn key(p: Vec3, cell: f32) -> [i32; 3] {
    let k = (p / cell).floor();
    [k.x as i32, k.y as i32, k.z as i32]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn probe(position: Vec3, spacing: f32, value: f32) -> ProbeRecord {
        let mut sh = Sh9::default();
        sh.c[0] = Vec3::splat(value);
        ProbeRecord {
            position,
            spacing,
            relative_error: 0.0,
            sh,
        }
    }

    /// On a regular lattice the field is trilinear: a linear function of position is
    /// reproduced exactly between the probes; beyond every probe's reach the nearest answers.
    #[test]
    fn a_regular_lattice_interpolates_trilinearly() {
        let mut probes = Vec::new();
        for x in 0..3 {
            for y in 0..3 {
                for z in 0..3 {
                    let p = Vec3::new(x as f32, y as f32, z as f32) * 2.0;
                    probes.push(probe(p, 2.0, 1.0 + p.x + 2.0 * p.y - p.z));
                }
            }
        }
        let field = ProbeField::new(probes);
        for x in [
            Vec3::new(0.3, 1.7, 2.2),
            Vec3::new(3.9, 0.1, 0.5),
            Vec3::splat(2.0),
        ] {
            let got = field.at(x).unwrap().c[0].x;
            let want = 1.0 + x.x + 2.0 * x.y - x.z;
            assert!((got - want).abs() < 1e-4, "{x}: {got} vs {want}");
        }
        let far = field.at(Vec3::new(40.0, 0.0, 0.0)).unwrap().c[0].x;
        assert_eq!(far, 1.0 + 4.0);
    }

    /// A missing probe (one inside geometry) hands its weight to the others: the field stays
    /// a weighted mean of the probes, never darker than the darkest.
    #[test]
    fn a_missing_probe_leaves_a_normalised_mean() {
        let probes = vec![
            probe(Vec3::ZERO, 1.0, 2.0),
            probe(Vec3::X, 1.0, 4.0),
            probe(Vec3::Y, 1.0, 4.0),
        ];
        let field = ProbeField::new(probes);
        let v = field.at(Vec3::new(0.5, 0.5, 0.0)).unwrap().c[0].x;
        assert!((v - (2.0 + 4.0 + 4.0) / 3.0).abs() < 1e-5, "{v}");
    }
}
