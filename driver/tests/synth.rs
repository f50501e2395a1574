//! `synth` writes a texel file whose texels lie on the triangles of the scene it writes,
//! and that scene loads through `Scene::load` (the `.toml` with sun and sky).

use glam::Vec3;
use guidebake::scene::{Scene, Sky};
use guidebake::synth::synth;
use guidebake::texels::TexelFile;

mod cli;

#[test]
fn synth_texels_lie_on_the_written_scene() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("city.texels");
    let r = synth(300_000, &out).unwrap();
    assert!(
        (r.texels as f64 / 300_000.0 - 1.0).abs() < 0.02,
        "{}",
        r.texels
    );
    let f = TexelFile::open(&out).unwrap();
    assert_eq!(f.header().texel_count, r.texels);
    let scene = Scene::load(&r.scene).unwrap();
    assert_eq!(scene.triangles.len() as u32, f.header().triangle_count);
    assert!(scene.sun.is_some());
    assert!(matches!(scene.sky, Sky::Constant(_)));
    for (i, x) in f.texels().iter().enumerate() {
        let t = &scene.triangles[x.triangle as usize];
        let [a, b, c] = t.positions;
        let p = Vec3::from(x.position);
        let n = (b - a).cross(c - a);
        let area2 = n.length_squared();
        let l1 = (p - a).cross(c - a).dot(n) / area2;
        let l2 = (b - a).cross(p - a).dot(n) / area2;
        assert!(
            (p - a).dot(n.normalize()).abs() < 1e-4,
            "texel {i} off its plane"
        );
        assert!(
            l1 >= -1e-4 && l2 >= -1e-4 && 1.0 - l1 - l2 >= -1e-4,
            "texel {i}: {l1} {l2}"
        );
        assert!(
            Vec3::from(x.normal).dot(n.normalize()) > 0.9999,
            "texel {i} normal"
        );
        // The triangle table holds the triangle's lightmap UVs, which map onto the texel's
        // pixel, and the scene's own UVs say the same.
        let (page, q) = f.triangles()[x.triangle as usize].pixel_uv().unwrap();
        assert_eq!(page, x.page);
        let size = glam::Vec2::splat(f.pages()[0].width as f32);
        let from_scene = t.lightmap_uv.unwrap().map(|v| v * size);
        assert!(
            q.iter()
                .zip(&from_scene)
                .all(|(a, b)| a.distance(*b) < 1e-3),
            "texel {i}"
        );
        let px = q[0] * (1.0 - l1 - l2) + q[1] * l1 + q[2] * l2;
        assert_eq!(
            px.floor().as_uvec2().to_array(),
            [u32::from(x.pixel[0]), u32::from(x.pixel[1])],
            "texel {i}"
        );
    }
}

#[test]
fn synth_rejects_impossible_counts_without_leaving_files() {
    let dir = tempfile::tempdir().unwrap();
    let e = synth(10, &dir.path().join("x.texels")).unwrap_err();
    assert!(e.to_string().contains("--texels 10"), "{e}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// `synth` then `inspect --json --texel`: the dump equals the file's records; an id out of
/// range is an error naming the file.
#[test]
fn cli_synth_then_inspect_json() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("c.texels");
    let run = |args: &[&str]| cli::run(args);
    let o = run(&["synth", "--texels", "20000", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = run(&[
        "inspect",
        out.to_str().unwrap(),
        "--json",
        "--texel",
        "0",
        "--texel",
        "1234",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let f = TexelFile::open(&out).unwrap();
    assert_eq!(v["texel_count"], f.header().texel_count);
    assert_eq!(v["tile_count"], f.header().tile_count);
    for (k, id) in [0usize, 1234].into_iter().enumerate() {
        let t = &f.texels()[id];
        let pos: Vec<f32> = serde_json::from_value(v["texels"][k]["position"].clone()).unwrap();
        let nrm: Vec<f32> = serde_json::from_value(v["texels"][k]["normal"].clone()).unwrap();
        assert_eq!(pos, t.position);
        assert_eq!(nrm, t.normal);
    }
    let o = run(&["inspect", out.to_str().unwrap(), "--texel", "99999999"]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("c.texels: texel 99999999 is out of range"),
        "{err}"
    );
}

/// The world grows with N at a fixed texel density, and its geometry with it: 16×
/// the texels is 25× the cells (5× the grid edge) at about the same texels per metre (within
/// 25%: box heights, so wall areas, vary from cell to cell), and one triangle per 32 texels.
#[test]
fn synth_grows_the_world_not_the_density() {
    let dir = tempfile::tempdir().unwrap();
    let small = synth(150_000, &dir.path().join("small.texels")).unwrap();
    let large = synth(2_400_000, &dir.path().join("large.texels")).unwrap();
    assert_eq!((small.grid, large.grid), (2, 10), "{small:?} {large:?}");
    let ratio = large.texels_per_unit / small.texels_per_unit;
    assert!((ratio - 1.0).abs() < 0.25, "density ratio {ratio}");
    for r in [&small, &large] {
        assert_eq!(u64::from(r.triangles), r.texels / 32, "{r:?}");
    }
}
