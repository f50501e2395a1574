//! `texels`: the texel file — the contract between whatever laid out the lightmap and the
//! bake (docs/ARCHITECTURE.md). Field-by-field layout: `docs/texel-format.md`.
//!
//! The paper (Silvennoinen & Sloan 2019, §2.1) bakes texels grouped into clusters of nearby
//! texels with similar normals; the bake therefore streams **tiles** of up to 32×32 texels
//! and clusters inside a tile. This module owns the file: a streaming [`TexelWriter`] that
//! never holds more than one tile, and a validating, zero-copy [`TexelFile`] reader over a
//! memory map.
//!
//! Records are **array of structures**, one 64-byte [`TexelRecord`] per texel (a cache line):
//! every consumer of a texel reads nearly all of it together — clustering reads position and
//! normal, ray generation reads position, normal and both footprint axes, the output writer
//! reads page and pixel — so SoA would touch four streams where AoS touches one line.
//!
//! ## Memory-map invariant
//! [`TexelFile`] is the only owner of texel-file maps in the driver. **The file must not be
//! modified or truncated by anyone while it is mapped**: validation happens once, on open,
//! and everything after trusts it. Writers never write in place: they write `NAME.tmp-PID`
//! and rename over `NAME` on success, so a reader holding the old inode is unaffected.

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3};

mod error;
mod format;
mod reader;
mod writer;

pub use error::{FileKind, TexelFileError, what_file_is};
pub use format::*;
use format::{align_up, check_tile, check_tile_texels, check_triangles};
pub use reader::TexelFile;
pub use writer::{TexelWriter, TileRect};

#[cfg(test)]
mod tests {
    use super::*;
    use guidebake_kernels::testing::Pcg32;

    pub(crate) fn random_texel(rng: &mut Pcg32, page: u32, x: u16, y: u16) -> TexelRecord {
        let mut v = || {
            [
                rng.next_f32() * 20.0 - 10.0,
                rng.next_f32() * 20.0 - 10.0,
                rng.next_f32() * 20.0 - 10.0,
            ]
        };
        let p = v();
        let n = Vec3::from(v()).normalize_or(Vec3::Z).to_array();
        TexelRecord {
            position: p,
            normal: n,
            dpdu: v(),
            dpdv: v(),
            page,
            pixel: [x, y],
            triangle: 7,
            flags: FLAG_VALID,
        }
    }

    #[test]
    fn round_trip_is_identical() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.texels");
        let pages = [
            PageRecord {
                width: 70,
                height: 40,
            },
            PageRecord {
                width: 32,
                height: 32,
            },
        ];
        let mut triangles = vec![TriangleRecord::unmapped(SEEN_FRONT); 8];
        triangles[7] = TriangleRecord::lightmapped(
            1,
            [Vec2::ZERO, Vec2::new(32.0, 0.0), Vec2::new(0.0, 32.0)],
            SEEN_BACK,
        );
        let mut w = TexelWriter::create(&path, &pages, &triangles, 4.0).unwrap();
        let mut rng = Pcg32::new(5, 1);
        let mut all = Vec::new();
        for (page, tx, ty, tw, th) in [
            (0u32, 64u32, 32u32, 6u32, 8u32),
            (0, 0, 0, 32, 32),
            (1, 0, 0, 32, 32),
        ] {
            let mut tile = Vec::new();
            for y in ty..ty + th {
                for x in tx..tx + tw {
                    if !rng.next_u32().is_multiple_of(3) {
                        tile.push(random_texel(&mut rng, page, x as u16, y as u16));
                    }
                }
            }
            w.push_tile(
                TileRect {
                    page,
                    x: tx,
                    y: ty,
                    width: tw,
                    height: th,
                },
                &tile,
            )
            .unwrap();
            all.push(tile);
        }
        let h = w.finish().unwrap();
        let f = TexelFile::open(&path).unwrap();
        assert_eq!(*f.header(), h);
        assert_eq!(f.pages(), pages);
        assert_eq!(f.triangles(), triangles);
        assert_eq!(f.tiles().len(), 3);
        for (i, tile) in all.iter().enumerate() {
            assert_eq!(f.tile_texels(i), tile.as_slice());
        }
        assert_eq!(f.texels().len(), all.iter().map(Vec::len).sum::<usize>());
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            1,
            "temporary files left behind"
        );
    }

    #[test]
    fn writer_rejects_bad_texels_and_leaves_no_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.texels");
        let mut w = TexelWriter::create(
            &path,
            &[PageRecord {
                width: 8,
                height: 8,
            }],
            &[],
            0.0,
        )
        .unwrap();
        let mut rng = Pcg32::new(1, 1);
        let mut t = random_texel(&mut rng, 0, 1, 1);
        t.normal = [0.0; 3];
        let e = w
            .push_tile(
                TileRect {
                    page: 0,
                    x: 0,
                    y: 0,
                    width: 8,
                    height: 8,
                },
                &[t],
            )
            .unwrap_err();
        assert!(e.to_string().contains("normal"), "{e}");
        drop(w);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    /// Resident bytes of the mappings of `path` in this process (`/proc/self/smaps`).
    #[cfg(target_os = "linux")]
    fn resident_bytes_of(path: &Path) -> u64 {
        let smaps = std::fs::read_to_string("/proc/self/smaps").unwrap();
        let name = path.to_str().unwrap();
        let mut ours = false;
        let mut kib = 0;
        for line in smaps.lines() {
            let header = line.split_whitespace().next().is_some_and(|range| {
                range.contains('-') && range.chars().all(|c| c.is_ascii_hexdigit() || c == '-')
            });
            if header {
                ours = line.ends_with(name);
            } else if ours && let Some(v) = line.strip_prefix("Rss:") {
                kib += v
                    .trim()
                    .trim_end_matches("kB")
                    .trim()
                    .parse::<u64>()
                    .unwrap();
            }
        }
        kib * 1024
    }

    /// A streaming bake reads a texel file tile by tile and releases each tile behind it; the
    /// file's resident pages must not grow with the file (docs/farm.md, "Resident memory after
    /// the release fix").
    /// With a release margin smaller than the folios a fault maps, about half of the file
    /// stayed resident.
    #[cfg(target_os = "linux")]
    #[test]
    fn reading_tile_by_tile_and_releasing_keeps_the_file_out_of_memory() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.texels");
        let side = 1024u32;
        let pages = [PageRecord {
            width: side,
            height: side,
        }];
        // 1024 tiles of 32 × 32 texels: a 64 MiB file.
        let mut triangles = vec![TriangleRecord::unmapped(SEEN_FRONT); 8];
        triangles[7] = TriangleRecord::lightmapped(0, [Vec2::ZERO; 3], SEEN_FRONT);
        let mut w = TexelWriter::create(&path, &pages, &triangles, 1.0).unwrap();
        let mut rng = Pcg32::new(9, 1);
        let mut tile = Vec::with_capacity(1024);
        for ty in (0..side).step_by(32) {
            for tx in (0..side).step_by(32) {
                tile.clear();
                for y in ty..ty + 32 {
                    for x in tx..tx + 32 {
                        tile.push(random_texel(&mut rng, 0, x as u16, y as u16));
                    }
                }
                let rect = TileRect {
                    page: 0,
                    x: tx,
                    y: ty,
                    width: 32,
                    height: 32,
                };
                w.push_tile(rect, &tile).unwrap();
            }
        }
        w.finish().unwrap();
        let f = TexelFile::open(&path).unwrap();
        let mut peak = resident_bytes_of(&path);
        let mut sum = 0.0f32;
        for i in 0..f.tiles().len() {
            sum += f.tile_texels(i).iter().map(|t| t.position[0]).sum::<f32>();
            f.release_tile(i);
            if i % 64 == 0 {
                peak = peak.max(resident_bytes_of(&path));
            }
        }
        assert!(sum.is_finite());
        let left = resident_bytes_of(&path);
        let file = std::fs::metadata(&path).unwrap().len();
        // At most the folios around the tile being read (2 × RELEASE_MARGIN) and the tile table.
        let bound = 3 * super::reader::RELEASE_MARGIN + 64 * 1024;
        assert!(
            peak <= bound && left <= bound,
            "{peak} bytes resident at the peak, {left} at the end, of a {file}-byte file (bound {bound})"
        );
    }
}
