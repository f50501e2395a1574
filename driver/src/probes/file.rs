//! The probe file an engine reads (positions and L2 SH, little-endian, versioned, checked on
//! open; byte for byte in docs/probes.md, "The probe file"), and the volume form: the coarse
//! grid's probes as EXR images of 3D-texture slices, one image per SH band.

use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, LineOrder,
    SmallVec, WritableImage,
};
use glam::Vec3;

use super::placement::CoarseGrid;
use super::sh::{BAND, COEFFICIENTS, Sh9};
use crate::hash::{fnv1a64, fnv1a64_more};
use crate::output::exr_pages::LightmapIdentity;

/// The file's first eight bytes.
pub const MAGIC: [u8; 8] = *b"GBPROBES";
/// The format version this guidebake writes and reads.
pub const VERSION: u32 = 1;
/// Bytes of the header.
pub const HEADER_BYTES: usize = 64;
/// Bytes of one probe record.
pub const RECORD_BYTES: usize = 128;

/// Header flag: the SH were de-ringed.
pub const FLAG_DERINGED: u32 = 1;
/// Header flag: hits read paths (`--probe-transport path`), not the lightmap.
pub const FLAG_PATH: u32 = 2;
/// Header flag: the probes were guided.
pub const FLAG_GUIDED: u32 = 4;

/// What the header says besides the count.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProbeHeader {
    /// [`FLAG_DERINGED`] | [`FLAG_PATH`] | [`FLAG_GUIDED`].
    pub flags: u32,
    /// Gather samples per probe.
    pub spp: u32,
    /// The finest lattice spacing D.
    pub fine_spacing: f32,
    /// The coarse spacing, the volume's.
    pub coarse_spacing: f32,
    /// The seed.
    pub seed: u32,
}

/// One probe as the file holds it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProbeRecord {
    /// Where it is.
    pub position: Vec3,
    /// The reach of its weight in interpolation (docs/probes.md).
    pub spacing: f32,
    /// The relative standard error of its band-0 luminance.
    pub relative_error: f32,
    /// Incident radiance, L2 (the convention of [`super::sh`]).
    pub sh: Sh9,
}

impl ProbeRecord {
    pub(super) fn to_bytes(self) -> [u8; RECORD_BYTES] {
        let mut words = [0f32; RECORD_BYTES / 4];
        words[..3].copy_from_slice(&self.position.to_array());
        words[3] = self.spacing;
        words[4] = self.relative_error;
        for (k, c) in self.sh.c.iter().enumerate() {
            words[5 + 3 * k..8 + 3 * k].copy_from_slice(&c.to_array());
        }
        let mut out = [0u8; RECORD_BYTES];
        for (o, w) in out.chunks_exact_mut(4).zip(words) {
            o.copy_from_slice(&w.to_le_bytes());
        }
        out
    }

    pub(super) fn from_bytes(b: &[u8]) -> Self {
        let w = |i: usize| f32::from_le_bytes(b[4 * i..4 * i + 4].try_into().unwrap_or([0; 4]));
        let mut sh = Sh9::default();
        for (k, c) in sh.c.iter_mut().enumerate() {
            *c = Vec3::new(w(5 + 3 * k), w(6 + 3 * k), w(7 + 3 * k));
        }
        Self {
            position: Vec3::new(w(0), w(1), w(2)),
            spacing: w(3),
            relative_error: w(4),
            sh,
        }
    }
}

fn header_bytes(h: &ProbeHeader, count: u64, records_hash: u64) -> [u8; HEADER_BYTES] {
    let mut b = [0u8; HEADER_BYTES];
    b[..8].copy_from_slice(&MAGIC);
    b[8..12].copy_from_slice(&VERSION.to_le_bytes());
    b[12..16].copy_from_slice(&(RECORD_BYTES as u32).to_le_bytes());
    b[16..24].copy_from_slice(&count.to_le_bytes());
    b[24..28].copy_from_slice(&h.flags.to_le_bytes());
    b[28..32].copy_from_slice(&h.spp.to_le_bytes());
    b[32..36].copy_from_slice(&h.fine_spacing.to_le_bytes());
    b[36..40].copy_from_slice(&h.coarse_spacing.to_le_bytes());
    b[40..44].copy_from_slice(&h.seed.to_le_bytes());
    b[48..56].copy_from_slice(&records_hash.to_le_bytes());
    let own = fnv1a64(&b[..56]);
    b[56..64].copy_from_slice(&own.to_le_bytes());
    b
}

/// Writes a probe file as its records arrive (in file order), under a temporary name: the
/// header, whose count and checksum are known only at the end, is written last.
pub struct ProbeWriter {
    path: PathBuf,
    tmp: PathBuf,
    file: std::io::BufWriter<std::fs::File>,
    header: ProbeHeader,
    count: u64,
    hash: u64,
}

impl ProbeWriter {
    /// Starts `path`'s temporary file.
    ///
    /// # Errors
    /// A message naming the file.
    pub fn create(path: &Path, header: ProbeHeader) -> Result<Self, String> {
        let tmp = crate::atomic::temporary_name(path);
        let fail =
            |e: std::io::Error| format!("{}: cannot write the probe file: {e}", path.display());
        let mut file = std::io::BufWriter::new(std::fs::File::create(&tmp).map_err(fail)?);
        file.write_all(&[0u8; HEADER_BYTES]).map_err(fail)?;
        Ok(Self {
            path: path.to_owned(),
            tmp,
            file,
            header,
            count: 0,
            hash: fnv1a64(&[]),
        })
    }

    /// Appends one record.
    ///
    /// # Errors
    /// A message naming the file.
    pub fn push(&mut self, record: &ProbeRecord) -> Result<(), String> {
        let bytes = record.to_bytes();
        self.hash = fnv1a64_more(self.hash, &bytes);
        self.count += 1;
        self.file
            .write_all(&bytes)
            .map_err(|e| format!("{}: cannot write the probe file: {e}", self.path.display()))
    }

    /// Writes the header, syncs and renames into place.
    ///
    /// # Errors
    /// A message naming the file; the temporary file is removed.
    pub fn finish(self) -> Result<(), String> {
        let Self {
            path,
            tmp,
            file,
            header,
            count,
            hash,
        } = self;
        let result = (|| -> std::io::Result<()> {
            let mut f = file
                .into_inner()
                .map_err(std::io::IntoInnerError::into_error)?;
            f.seek(SeekFrom::Start(0))?;
            f.write_all(&header_bytes(&header, count, hash))?;
            f.sync_all()?;
            std::fs::rename(&tmp, &path)
        })();
        result.map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            format!("{}: cannot write the probe file: {e}", path.display())
        })
    }

    /// Removes the temporary file (the bake stopped).
    pub fn abandon(self) {
        let _ = std::fs::remove_file(&self.tmp);
    }
}

/// A probe file read back and checked.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeFile {
    /// The header's settings.
    pub header: ProbeHeader,
    /// The probes, in file order.
    pub probes: Vec<ProbeRecord>,
}

impl ProbeFile {
    /// Reads and checks `path`: magic, version, record size, length, both checksums, and
    /// every value finite (spacing positive, error non-negative).
    ///
    /// # Errors
    /// A message naming the file and what is wrong with it.
    pub fn open(path: &Path) -> Result<Self, String> {
        let bad = |what: String| format!("{}: not a usable probe file: {what}", path.display());
        let bytes = std::fs::read(path)
            .map_err(|e| format!("{}: cannot read the probe file: {e}", path.display()))?;
        if bytes.len() < HEADER_BYTES || bytes[..8] != MAGIC {
            return Err(bad(
                "it does not start with GBPROBES (is it a probe file?)".into()
            ));
        }
        let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap_or([0; 4]));
        let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().unwrap_or([0; 8]));
        let f32_at = |o: usize| f32::from_bits(u32_at(o));
        if u64_at(56) != fnv1a64(&bytes[..56]) {
            return Err(bad("its header checksum does not match (damaged)".into()));
        }
        let version = u32_at(8);
        if version != VERSION {
            return Err(bad(format!(
                "format version {version}; this guidebake reads version {VERSION}"
            )));
        }
        if u32_at(12) as usize != RECORD_BYTES {
            return Err(bad(format!(
                "records of {} bytes, not {RECORD_BYTES}",
                u32_at(12)
            )));
        }
        let count = u64_at(16);
        let want = count
            .checked_mul(RECORD_BYTES as u64)
            .and_then(|n| n.checked_add(HEADER_BYTES as u64));
        if want != Some(bytes.len() as u64) {
            return Err(bad(format!(
                "{} bytes for {count} probes (truncated or padded)",
                bytes.len()
            )));
        }
        let body = &bytes[HEADER_BYTES..];
        if fnv1a64_more(fnv1a64(&[]), body) != u64_at(48) {
            return Err(bad("its records' checksum does not match (damaged)".into()));
        }
        let probes: Vec<ProbeRecord> = body
            .chunks_exact(RECORD_BYTES)
            .map(ProbeRecord::from_bytes)
            .collect();
        if let Some(i) = probes.iter().position(|p| {
            !(p.position.is_finite()
                && p.spacing.is_finite()
                && p.spacing > 0.0
                && p.relative_error.is_finite()
                && p.relative_error >= 0.0
                && p.sh.is_finite())
        }) {
            return Err(bad(format!(
                "probe {i} holds a value that is not finite or out of range"
            )));
        }
        Ok(Self {
            header: ProbeHeader {
                flags: u32_at(24),
                spp: u32_at(28),
                fine_spacing: f32_at(32),
                coarse_spacing: f32_at(36),
                seed: u32_at(40),
            },
            probes,
        })
    }
}

/// The volume's image of SH band `band` beside `out` (`OUT.volume-l0.exr`, `-l1`, `-l2`).
#[must_use]
pub fn volume_path(out: &Path, band: usize) -> PathBuf {
    let mut name = out.as_os_str().to_owned();
    name.push(format!(".volume-l{band}.exr"));
    PathBuf::from(name)
}

/// The coarse grid's SH, one per grid point (x fastest, then y, then z): `placed`, the SH of
/// the probes at its points ([`super::placement::PlacedProbe::coarse_point`]), and the points inside geometry
/// filled from their neighbours — the mean of the filled neighbours among the six, ring by
/// ring, as a lightmap is dilated — so trilinear interpolation never reads the inside of a
/// wall.
#[must_use]
pub fn coarse_values(grid: &CoarseGrid, placed: &[([u32; 3], Sh9)]) -> Vec<Sh9> {
    let [nx, ny, nz] = grid.points.map(|n| n as usize);
    let index = |x: usize, y: usize, z: usize| x + nx * (y + ny * z);
    let mut values: Vec<Option<Sh9>> = vec![None; grid.len()];
    for (at, s) in placed {
        let [x, y, z] = at.map(|v| v as usize);
        if x < nx && y < ny && z < nz {
            values[index(x, y, z)] = Some(*s);
        }
    }
    loop {
        let mut next = values.clone();
        let mut changed = false;
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    if values[index(x, y, z)].is_some() {
                        continue;
                    }
                    let mut sum = Sh9::default();
                    let mut n = 0;
                    let around = [
                        (x.wrapping_sub(1), y, z),
                        (x + 1, y, z),
                        (x, y.wrapping_sub(1), z),
                        (x, y + 1, z),
                        (x, y, z.wrapping_sub(1)),
                        (x, y, z + 1),
                    ];
                    for (a, b, c) in around {
                        if a < nx
                            && b < ny
                            && c < nz
                            && let Some(v) = values[index(a, b, c)]
                        {
                            sum = sum.plus(&v);
                            n += 1;
                        }
                    }
                    if n > 0 {
                        next[index(x, y, z)] = Some(sum.scaled(1.0 / n as f32));
                        changed = true;
                    }
                }
            }
        }
        values = next;
        if !changed {
            break;
        }
    }
    values.into_iter().map(Option::unwrap_or_default).collect()
}

/// Writes the volume: for each SH band an EXR of `nx` × (`ny` · `nz`) pixels, slice z below
/// slice z − 1, channels `SH{k}.R`, `.G`, `.B` for the band's coefficients k, and the grid
/// (origin, spacing, points) in the `guidebake` header attribute. Each image is published
/// whole (temporary name, rename).
///
/// # Errors
/// A message naming the file.
pub fn write_volume(out: &Path, grid: &CoarseGrid, values: &[Sh9]) -> Result<Vec<PathBuf>, String> {
    let [nx, ny, nz] = grid.points.map(|n| n as usize);
    let mut written = Vec::new();
    for band in 0..3 {
        let path = volume_path(out, band);
        let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
        for k in (0..COEFFICIENTS).filter(|&k| BAND[k] == band) {
            for (c, name) in ["R", "G", "B"].into_iter().enumerate() {
                let plane: Vec<f32> = values.iter().map(|v| v.c[k][c]).collect();
                channels.push(AnyChannel::new(
                    format!("SH{k}.{name}").as_str(),
                    FlatSamples::F32(plane),
                ));
            }
        }
        let mut attributes = LayerAttributes::named(format!("sh-band-{band}").as_str());
        LightmapIdentity::default()
            .with(
                "what",
                "guidebake light probe volume: L2 SH of incident radiance",
            )
            .with(
                "origin",
                &format!("{} {} {}", grid.origin.x, grid.origin.y, grid.origin.z),
            )
            .with("spacing", &grid.spacing().to_string())
            .with("points", &format!("{nx} {ny} {nz}"))
            .with(
                "layout",
                "x along the width; y down the rows of a slice; slice z below slice z-1",
            )
            .write_into(&mut attributes);
        let layer = Layer::new(
            (nx, ny * nz),
            attributes,
            Encoding {
                line_order: LineOrder::Increasing,
                ..Encoding::SMALL_FAST_LOSSLESS
            },
            AnyChannels::sort(channels),
        );
        let tmp = crate::atomic::temporary_name(&path);
        let result = Image::from_layer(layer)
            .write()
            .to_file(&tmp)
            .map_err(|e| e.to_string())
            .and_then(|()| std::fs::rename(&tmp, &path).map_err(|e| e.to_string()));
        if let Err(e) = result {
            let _ = std::fs::remove_file(&tmp);
            for p in &written {
                let _ = std::fs::remove_file(p);
            }
            return Err(format!(
                "{}: cannot write the probe volume: {e}",
                path.display()
            ));
        }
        written.push(path);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::probes::placement::PlacedProbe;

    fn record(i: usize) -> ProbeRecord {
        let mut sh = Sh9::default();
        for (k, c) in sh.c.iter_mut().enumerate() {
            *c = Vec3::new(i as f32, k as f32, -0.5 * k as f32);
        }
        ProbeRecord {
            position: Vec3::new(i as f32, 1e6, -3.0),
            spacing: 0.25,
            relative_error: 0.01 * i as f32,
            sh,
        }
    }

    fn written(dir: &Path, n: usize) -> PathBuf {
        let path = dir.join("level.probes");
        let header = ProbeHeader {
            flags: FLAG_GUIDED,
            spp: 256,
            fine_spacing: 0.25,
            coarse_spacing: 1.0,
            seed: 7,
        };
        let mut w = ProbeWriter::create(&path, header).unwrap();
        for i in 0..n {
            w.push(&record(i)).unwrap();
        }
        w.finish().unwrap();
        path
    }

    /// What is written is read back as it was; every kind of damage is refused with a
    /// message naming the file and what is wrong; no temporary file is left.
    #[test]
    fn a_probe_file_reads_back_and_damage_is_named() {
        let dir = std::env::temp_dir().join(format!("gb-probefile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = written(&dir, 5);
        let file = ProbeFile::open(&path).unwrap();
        assert_eq!(file.probes, (0..5).map(record).collect::<Vec<_>>());
        assert_eq!(file.header.flags, FLAG_GUIDED);
        assert_eq!(file.header.seed, 7);
        assert_eq!(
            std::fs::read(&path).unwrap().len(),
            HEADER_BYTES + 5 * RECORD_BYTES
        );
        assert_eq!(
            std::fs::read_dir(&dir).unwrap().count(),
            1,
            "a temporary file is left"
        );
        let bytes = std::fs::read(&path).unwrap();
        let damaged = |f: &dyn Fn(&mut Vec<u8>), says: &str| {
            let mut b = bytes.clone();
            f(&mut b);
            std::fs::write(&path, &b).unwrap();
            let e = ProbeFile::open(&path).unwrap_err();
            assert!(
                e.starts_with(&path.display().to_string()) && e.contains(says),
                "{e}"
            );
        };
        damaged(&|b| b[0] = b'X', "GBPROBES");
        damaged(&|b| b[200] ^= 1, "records' checksum");
        damaged(&|b| b[20] ^= 1, "header checksum");
        damaged(&|b| b.truncate(b.len() - 3), "truncated");
        damaged(&|b| b.truncate(10), "GBPROBES");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The volume's points inside geometry are filled from their neighbours, ring by ring:
    /// a grid with one probe takes its value everywhere.
    #[test]
    fn the_coarse_grid_is_filled_where_probes_are_missing() {
        let grid = CoarseGrid {
            origin: Vec3::ZERO,
            fine: 0.25,
            points: [3, 2, 2],
        };
        let probe = PlacedProbe {
            position: Vec3::ZERO,
            spacing: 1.0,
            cluster: [0; 3],
            lattice: Some([4, 0, 4]),
        };
        let mut sh = Sh9::default();
        sh.c[0] = Vec3::splat(2.0);
        let point = probe.coarse_point().unwrap();
        assert_eq!(point, [1, 0, 1]);
        let values = coarse_values(&grid, &[(point, sh)]);
        assert_eq!(values.len(), 12);
        assert!(values.iter().all(|v| v.c[0] == Vec3::splat(2.0)));
    }
}
