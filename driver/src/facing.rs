//! Which side of a two-sided surface its lightmap texels describe.
//!
//! The scenes are two-sided Lambertian (docs/bake.md), but a lightmap texel
//! stores one irradiance, gathered over one hemisphere. Scene files do not say which side
//! matters: the converted Bitterli scenes have no normals and arbitrary winding, so a wall's
//! geometric normal may point out of the room, where its texels would gather nothing and
//! series transport would look up black where light bounces. [`facing_sides`] decides per
//! triangle: from a few points on it, 32 fixed cosine-distributed rays on each side; the side
//! whose rays escape the scene markedly less often (by [`MARGIN`] rays) is the side its
//! texels face. Ties keep the winding's side, so open scenes (a ground under a sky, a thin
//! wall) keep their normals. Emission is unaffected: it stays front-facing by winding.

use glam::Vec3;
use guidebake_kernels::mapping::{orthonormal_basis, sample_cosine_hemisphere};
use guidebake_kernels::packet::{Ray, offset_origin, triangle_extent};
use guidebake_kernels::traverse::{WideRef, intersect1};

use crate::bvh::{Bvh, BvhError, Preset};
use crate::scene::Scene;

/// Escaping rays (of 32) by which the back side must beat the front to be chosen.
pub const MARGIN: u32 = 4;

/// Points on a triangle (barycentric weights of the second and third vertices).
const POINTS: [[f32; 2]; 4] = [[1.0 / 3.0, 1.0 / 3.0], [0.6, 0.2], [0.2, 0.6], [0.2, 0.2]];

/// For every triangle of `scene`, whether its texels face against its winding (`true`:
/// flip the normal). Triangles without lightmap UVs are never flipped (they have no texels).
///
/// # Errors
/// [`BvhError`] when the scene's BVH cannot be built (a non-finite vertex).
pub fn facing_sides(scene: &Scene) -> Result<Vec<bool>, BvhError> {
    let corners = scene.triangle_positions();
    // Rays per triangle: 8 from each point, on both sides.
    let rays = (POINTS.len() * 8 * 2 * corners.len()) as f64;
    let bvh = Bvh::build(&corners, Preset::for_rays(corners.len(), rays))?;
    let view = bvh.wide();
    Ok(scene
        .triangles
        .iter()
        .zip(&corners)
        .map(|(t, c)| {
            if t.lightmap_uv.is_none() {
                return false;
            }
            let n = t.geometric_normal();
            escaping(&view, c, -n) + MARGIN <= escaping(&view, c, n)
        })
        .collect())
}

/// Rays from points of triangle `c` over the hemisphere around `n` that hit nothing.
fn escaping(bvh: &WideRef<'_>, c: &[Vec3; 3], n: Vec3) -> u32 {
    let (tangent, bitangent) = orthonormal_basis(n);
    let mut misses = 0;
    for [b1, b2] in POINTS {
        let p = c[0] * (1.0 - b1 - b2) + c[1] * b1 + c[2] * b2;
        let origin = offset_origin(p, n, triangle_extent(p, c));
        for i in 0..8 {
            let u = [((i % 4) as f32 + 0.5) / 4.0, ((i / 4) as f32 + 0.5) / 2.0];
            let d = sample_cosine_hemisphere(u);
            let dir = tangent * d.x + bitangent * d.y + n * d.z;
            let ray = Ray::new(origin, dir, 0.0, f32::INFINITY);
            misses += u32::from(intersect1(bvh, &ray).is_none());
        }
    }
    misses
}

#[cfg(test)]
mod tests {
    use glam::Vec2;

    use super::*;
    use crate::scene::{Material, Sky, Triangle};

    /// The 2 m cube's faces, wound to face out of the box, plus a 40 m ground beside it facing
    /// up; all with lightmap UVs.
    fn scene() -> Scene {
        let (o, s) = (Vec3::splat(-1.0), 2.0);
        let (x, y, z) = (Vec3::X * s, Vec3::Y * s, Vec3::Z * s);
        let mut quads = vec![
            (o, y, x),
            (o + z, x, y),
            (o, z, y),
            (o + x, y, z),
            (o, x, z),
            (o + y, z, x),
        ];
        quads.push((Vec3::new(10.0, -20.0, -3.0), Vec3::X * 40.0, Vec3::Y * 40.0));
        let tri = |p: [Vec3; 3]| Triangle {
            positions: p,
            normals: [Vec3::ZERO; 3],
            lightmap_uv: Some([Vec2::ZERO, Vec2::X, Vec2::Y]),
            texture_uv: None,
            colour: None,
            mesh: 0,
            material: 0,
        };
        let triangles: Vec<Triangle> = quads
            .iter()
            .flat_map(|&(c, u, v)| [tri([c, c + u, c + u + v]), tri([c, c + u + v, c + v])])
            .collect();
        Scene {
            sky: Sky::Constant(Vec3::ONE),
            ..Scene::of_triangles(
                "facing",
                triangles,
                vec![Material {
                    name: "m".into(),
                    base_color_texture: None,
                    albedo: Vec3::splat(0.5),
                    emission: Vec3::ZERO,
                }],
            )
        }
    }

    #[test]
    fn a_closed_room_wound_outwards_is_seen_from_inside_and_open_ground_keeps_its_side() {
        let s = scene();
        for (i, t) in s.triangles.iter().take(12).enumerate() {
            assert!(
                t.geometric_normal().dot(-t.positions[0]) < 0.0,
                "face {i} faces out"
            );
        }
        let flip = facing_sides(&s).unwrap();
        assert!(
            flip[..12].iter().all(|&f| f),
            "the box's faces turn inwards: {flip:?}"
        );
        assert!(!flip[12] && !flip[13], "the ground keeps facing the sky");
    }
}
