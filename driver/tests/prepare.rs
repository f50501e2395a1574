//! `prepare` on every scene in `../shared/scenes`: covered-texel counts against the atlas
//! sizes of scenes/README.md, and every texel on its triangle.

use std::path::PathBuf;

use guidebake::prepare::{Layout, PrepareOptions, Resolution, prepare};
use guidebake::scene::Scene;
use guidebake::test_support::assert_texels_on_triangles;
use guidebake::texels::{FLAG_PARTIAL, TexelFile};

fn scenes_dir() -> Option<PathBuf> {
    guidebake::test_support::shared_scenes_dir()
}

/// Total UV area and UV perimeter of the scene's triangles, in page pixels.
fn pixel_area_and_perimeter(scene: &Scene, f: &TexelFile) -> (f64, f64) {
    let (mut area, mut perim) = (0.0f64, 0.0f64);
    for (t, record) in scene.triangles.iter().zip(f.triangles()) {
        let Some((_, q)) = record.pixel_uv() else {
            continue;
        };
        assert!(t.lightmap_uv.is_some(), "a triangle without UVs got some");
        area += f64::from(0.5 * (q[1] - q[0]).perp_dot(q[2] - q[0]).abs());
        perim += f64::from(q[0].distance(q[1]) + q[1].distance(q[2]) + q[2].distance(q[0]));
    }
    (area, perim)
}

/// Converted Bitterli scenes at their atlas sizes. Every texel centre inside a UV triangle is
/// covered, so the centre-covered count C estimates the total UV area A in pixels; a centre
/// count differs from the area only along chart borders, by at most half a pixel per unit of
/// border length. The sum of all triangle perimeters P bounds the border length from above,
/// so |C − A| ≤ P/2. The conservative pass adds only texels overlapping a border, so
/// partial ≤ P + 4·triangles (each unit of border touches at most ~1 new texel, plus the
/// corners).
#[test]
fn converted_scenes_have_expected_covered_texels() {
    let Some(dir) = scenes_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    for (name, w, h) in [
        ("bitterli_cornell_box", 1073, 932),
        ("bitterli_veach_bidir", 816, 1128),
        ("bitterli_veach_ajar_no_teapots", 977, 976),
    ] {
        let scene = Scene::load(&dir.join(format!("converted/{name}.glb"))).unwrap();
        let out = tmp.path().join(format!("{name}.texels"));
        let opts = PrepareOptions {
            resolution: Resolution::Size(w, h),
            layout: Layout::Auto,
        };
        let report = prepare(&scene, &out, opts).unwrap();
        assert!(
            !report.per_mesh_layout,
            "{name}: the shared xatlas atlas must be respected"
        );
        let f = TexelFile::open(&out).unwrap();
        assert_eq!(f.header().texel_count, report.texels);
        let partial = f
            .texels()
            .iter()
            .filter(|t| t.flags & FLAG_PARTIAL != 0)
            .count() as f64;
        let centre = report.texels as f64 - partial;
        let (area, perim) = pixel_area_and_perimeter(&scene, &f);
        println!(
            "{name}: {} texels, centre {centre}, partial {partial}, UV area {area:.0} px, perimeter {perim:.0} px, fill {:.3}",
            report.texels,
            area / f64::from(w * h)
        );
        assert!(
            (centre - area).abs() <= perim / 2.0,
            "{name}: centre-covered {centre} vs UV area {area}"
        );
        assert!(
            partial <= perim + 4.0 * scene.triangles.len() as f64,
            "{name}: {partial} partial texels"
        );
        // xatlas fills well over half of its atlas; a layout bug would not.
        assert!(
            centre > 0.5 * f64::from(w * h),
            "{name}: only {centre} of {w}x{h} covered"
        );
        assert_texels_on_triangles(&scene, &f);
    }
}

/// The vinc3r Cornell box: every mesh has its own 0..1 UVs, so meshes must be packed
/// without overlap; meshes without TEXCOORD_1 are reported by name.
#[test]
fn vinc3r_meshes_are_packed_and_missing_uvs_reported() {
    let Some(dir) = scenes_dir() else { return };
    let p =
        dir.join("vinc3r_cornellbox/BJS-2.80-Eevee-gltf/assets/cornellBox-2.80-Eevee-gltf.gltf");
    let scene = Scene::load(&p).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("v.texels");
    let opts = PrepareOptions {
        resolution: Resolution::Size(1024, 1024),
        layout: Layout::Auto,
    };
    let report = prepare(&scene, &out, opts).unwrap();
    assert!(report.per_mesh_layout);
    assert_eq!(report.pages, [(1024, 1024)]);
    assert!(
        report
            .meshes_without_lightmap_uvs
            .iter()
            .any(|m| m == "lamp.000")
    );
    let f = TexelFile::open(&out).unwrap();
    // Meshes occupy disjoint pixel squares: each texel's mesh's cell contains its pixel.
    let mut owner = vec![u32::MAX; 1024 * 1024];
    for x in f.texels() {
        let mesh = scene.triangles[x.triangle as usize].mesh;
        let o = &mut owner[x.pixel[1] as usize * 1024 + x.pixel[0] as usize];
        assert_eq!(*o, u32::MAX, "pixel {:?} written twice", x.pixel);
        *o = mesh;
    }
    let (area, perim) = pixel_area_and_perimeter(&scene, &f);
    let partial = f
        .texels()
        .iter()
        .filter(|t| t.flags & FLAG_PARTIAL != 0)
        .count() as f64;
    let centre = report.texels as f64 - partial;
    assert!(
        (centre - area).abs() <= perim / 2.0,
        "centre-covered {centre} vs UV area {area}"
    );
    assert_texels_on_triangles(&scene, &f);
}

/// A texel density doubles the texel count about fourfold.
#[test]
fn texels_per_unit_scales_quadratically() {
    let Some(dir) = scenes_dir() else { return };
    let scene = Scene::load(&dir.join("converted/bitterli_cornell_box.glb")).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let count = |d: f32| {
        let out = tmp.path().join(format!("c{d}.texels"));
        let opts = PrepareOptions {
            resolution: Resolution::TexelsPerUnit(d),
            layout: Layout::Auto,
        };
        prepare(&scene, &out, opts).unwrap().texels as f64
    };
    let (a, b) = (count(20.0), count(40.0));
    assert!((b / a - 4.0).abs() < 0.4, "{a} -> {b}");
}
