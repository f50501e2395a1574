//! Scene sources beyond glTF: OBJ + MTL, the TOML scene file with sun and skies.

use glam::{Vec2, Vec3};
use guidebake::scene::{Scene, SceneError, Sky};

#[test]
fn obj_with_mtl_loads_materials_and_uvs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("m.mtl"),
        "newmtl wall\nKd 0.5 0.25 0.125\nnewmtl lamp\nKd 0 0 0\nKe 4 4 2\n",
    )
    .unwrap();
    std::fs::write(
        d.join("q.obj"),
        "mtllib m.mtl\no wall\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
         usemtl wall\nf 1/1 2/2 3/3 4/4\n\
         o lamp\nv 0 2 0\nv 1 2 0\nv 0 2 1\nusemtl lamp\nf 5 6 7\n",
    )
    .unwrap();
    let s = Scene::load(&d.join("q.obj")).unwrap();
    assert_eq!(s.meshes.len(), 2);
    assert_eq!(s.triangles.len(), 3, "the quad is triangulated");
    let wall = s.triangle_material(0);
    assert_eq!(wall.albedo, Vec3::new(0.5, 0.25, 0.125));
    assert_eq!(s.triangle_material(2).emission, Vec3::new(4.0, 4.0, 2.0));
    assert_eq!(s.triangles[0].lightmap_uv.unwrap()[0], Vec2::ZERO);
    assert_eq!(s.meshes_without_lightmap_uvs(), ["lamp"]);
    // No normals in the file: the geometric normal (+Z for the wall's winding).
    assert_eq!(s.triangles[0].normals, [Vec3::Z; 3]);
}

fn obj_triangle(d: &std::path::Path) {
    std::fs::write(
        d.join("t.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 0 -1\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n",
    )
    .unwrap();
}

#[test]
fn scene_file_adds_sun_and_constant_sky() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    obj_triangle(d);
    std::fs::write(
        d.join("s.toml"),
        "geometry = \"t.obj\"\n[sky]\nconstant = [0.1, 0.2, 0.3]\n[sun]\ndirection = [0, 2, 0]\nangular_radius_deg = 0.5\nirradiance = [3, 2, 1]\n",
    )
    .unwrap();
    let s = Scene::load(&d.join("s.toml")).unwrap();
    assert_eq!(s.sky, Sky::Constant(Vec3::new(0.1, 0.2, 0.3)));
    let sun = s.sun.unwrap();
    assert_eq!(sun.direction, Vec3::Y);
    assert!((sun.angular_radius - 0.5f32.to_radians()).abs() < 1e-7);
    assert_eq!(sun.irradiance, Vec3::new(3.0, 2.0, 1.0));
}

#[test]
fn scene_file_adds_sphere_lights_and_rejects_bad_ones() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    obj_triangle(d);
    let light = |radius: &str| {
        format!(
            "geometry = \"t.obj\"\n[[sphere_light]]\ncenter = [0, 1, 0]\nradius = {radius}\nradiance = [5, 4, 3]\n[[sphere_light]]\ncenter = [1, 1, 0]\nradius = 0.5\nradiance = [1, 1, 1]\n"
        )
    };
    std::fs::write(d.join("s.toml"), light("0.25")).unwrap();
    let s = Scene::load(&d.join("s.toml")).unwrap();
    assert_eq!(s.lights.len(), 2);
    assert_eq!(
        s.lights[0],
        guidebake::scene::SceneLight::Sphere {
            center: Vec3::Y,
            radius: 0.25,
            radiance: Vec3::new(5.0, 4.0, 3.0),
        }
    );
    for bad in ["0", "-1", "nan"] {
        std::fs::write(d.join("s.toml"), light(bad)).unwrap();
        let err = Scene::load(&d.join("s.toml")).unwrap_err().to_string();
        assert!(
            err.contains("s.toml") && err.contains("sphere_light radius"),
            "{bad}: {err}"
        );
    }
}

#[test]
fn scene_file_loads_an_equirect_exr_and_rejects_bad_ones() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    obj_triangle(d);
    exr::prelude::write_rgba_file(d.join("sky.exr"), 8, 4, |x, y| {
        (x as f32, y as f32, 1.0, 1.0)
    })
    .unwrap();
    std::fs::write(
        d.join("s.toml"),
        "geometry = \"t.obj\"\n[sky]\nequirect = \"sky.exr\"\n",
    )
    .unwrap();
    let s = Scene::load(&d.join("s.toml")).unwrap();
    let Sky::Equirect {
        width,
        height,
        pixels,
        ..
    } = &s.sky
    else {
        panic!("{:?}", s.sky)
    };
    assert_eq!((*width, *height), (8, 4));
    assert_eq!(pixels[2 * 8 + 5], Vec3::new(5.0, 2.0, 1.0));

    exr::prelude::write_rgba_file(d.join("nan.exr"), 2, 2, |x, _| {
        (if x == 1 { f32::NAN } else { 0.0 }, 0.0, 0.0, 1.0)
    })
    .unwrap();
    std::fs::write(
        d.join("n.toml"),
        "geometry = \"t.obj\"\n[sky]\nequirect = \"nan.exr\"\n",
    )
    .unwrap();
    let e = Scene::load(&d.join("n.toml")).unwrap_err();
    assert!(
        matches!(e, SceneError::Sky { .. }) && e.to_string().contains("pixel (1, 0)"),
        "{e}"
    );

    std::fs::write(
        d.join("both.toml"),
        "geometry = \"t.obj\"\n[sky]\nequirect = \"sky.exr\"\nconstant = [1, 1, 1]\n",
    )
    .unwrap();
    let e = Scene::load(&d.join("both.toml")).unwrap_err();
    assert!(e.to_string().contains("exactly one"), "{e}");

    std::fs::write(
        d.join("typo.toml"),
        "geometry = \"t.obj\"\n[sun]\ndirection = [0, 1, 0]\n",
    )
    .unwrap();
    let e = Scene::load(&d.join("typo.toml")).unwrap_err();
    assert!(
        matches!(e, SceneError::SceneFile { .. }) && e.to_string().contains("typo.toml"),
        "{e}"
    );
}
