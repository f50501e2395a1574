//! The work directory of a probe bake, `LEVEL.probes.bake/` (docs/probes.md, "Stopping and
//! resuming"): a manifest that says which bake it holds ([`ProbeManifest`]: the settings by
//! option, the texel file, the scene, the lights and the lightmap read), and one file per
//! finished batch of clusters, each published whole (temporary name, sync, rename). A bake
//! stopped at any moment — Ctrl-C, a kill, a crash — keeps every batch it finished;
//! `--resume` checks the manifest and bakes only the missing batches. The probe file is
//! assembled from the batches in file order only once all are there, so nothing at the
//! final path ever looks complete before it is.
//!
//! A shard (`--shard K/N`, docs/probes.md, "Shards") bakes its own contiguous run of batches
//! ([`owned`]) into `LEVEL.probes.shard-K-of-N/` and stops there; `--merge` reads the batches
//! from every shard's directory ([`open_merge`]) and assembles the same file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::file::{ProbeRecord, RECORD_BYTES};
use super::gather::GatherCount;
use crate::bake::shard::Shard;
use crate::bake::workdir::BakeRecord;
use crate::hash::{fnv1a64, fnv1a64_more};

/// A batch file's first eight bytes.
const BATCH_MAGIC: [u8; 8] = *b"GBPRBTCH";
/// Bytes of a batch file's header: magic, probe bake id, batch index, record count, the
/// five counts of [`GatherCount`], the checksum of the rest.
const BATCH_HEADER_BYTES: usize = 8 + 8 + 8 + 8 + 5 * 8 + 8;

/// The manifest of a probe bake's work directory: what `--resume` checks before trusting it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProbeManifest {
    /// The texel file baked (for messages).
    pub texels: PathBuf,
    /// The bake's identity, hex: a hash of `record` (but its version) and the counts, what
    /// the batch files are stamped with.
    pub probe_id: String,
    /// Probes placed.
    pub probes: u64,
    /// Clusters.
    pub clusters: u64,
    /// Batches of clusters, one file each when done.
    pub batches: u64,
    /// The shard this directory holds, `[K, N]` (`None`: the whole bake).
    pub shard: Option<[u32; 2]>,
    /// Everything that changes the probes' bits, by name, so that `--resume` of a different
    /// bake names what differs.
    pub record: BakeRecord,
}

impl ProbeManifest {
    /// The manifest of a bake (or of shard `shard` of one) of `record` over `texels`,
    /// placing `probes` probes in `clusters` clusters and `batches` batches. The identity is
    /// the bake's, the same in every shard.
    #[must_use]
    pub fn new(
        texels: &Path,
        record: BakeRecord,
        (probes, clusters, batches): (u64, u64, u64),
        shard: Option<Shard>,
    ) -> Self {
        Self {
            texels: texels.to_owned(),
            probe_id: format!("{:016x}", record_id(&record, probes, clusters, batches)),
            probes,
            clusters,
            batches,
            shard: shard.map(|s| [s.index, s.count]),
            record,
        }
    }

    fn id(&self) -> u64 {
        u64::from_str_radix(&self.probe_id, 16).unwrap_or(0)
    }
}

/// The identity of a probe bake: every field of `record` but the guidebake version, and the
/// placement's counts.
fn record_id(record: &BakeRecord, probes: u64, clusters: u64, batches: u64) -> u64 {
    let BakeRecord {
        options,
        texels,
        geometry,
        materials,
        lighting,
        lights,
        version: _,
    } = record;
    let text = format!(
        "{options:?} {texels} {geometry} {materials} {lighting} {lights:?} {probes} {clusters} {batches}"
    );
    fnv1a64(text.as_bytes())
}

/// What one finished batch holds: its probes' records in file order and what its gather
/// counted.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Batch {
    /// The records, as the probe file will hold them.
    pub records: Vec<ProbeRecord>,
    /// Rays and samples.
    pub count: GatherCount,
}

/// The work directory of the probe file `out`: `OUT.bake/`, or `OUT.shard-K-of-N/` for
/// shard K of N.
#[must_use]
pub fn work_dir(out: &Path, shard: Option<Shard>) -> PathBuf {
    let mut name = out.as_os_str().to_owned();
    match shard {
        None => name.push(".bake"),
        Some(s) => name.push(format!(".shard-{}-of-{}", s.index, s.count)),
    }
    PathBuf::from(name)
}

/// The batches shard `shard` of `batches` bakes (all of them for `None`): one contiguous run
/// in file order, the runs' lengths differing by at most one.
#[must_use]
pub fn owned(shard: Option<Shard>, batches: usize) -> std::ops::Range<usize> {
    let Some(shard) = shard else {
        return 0..batches;
    };
    let at = |k: u32| batches * k as usize / shard.count.max(1) as usize;
    at(shard.index)..at(shard.index + 1)
}

/// `DIR1, DIR2, …`, for messages.
#[must_use]
pub fn list(dirs: &[PathBuf]) -> String {
    dirs.iter()
        .map(|d| d.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// An open work directory (for a merge, the shards' directories, read only).
pub struct ProbeWork {
    dirs: Vec<PathBuf>,
    id: u64,
}

/// Opens the work directory `dir` for the bake `manifest` describes: creates it (with its
/// manifest, appearing whole) when there is none; with `resume`, continues the one there if
/// its manifest is this bake's. Refused, with a message naming the directory: one there
/// without `resume` (nothing of it is touched), one of a different bake (each difference
/// named), one whose manifest cannot be read.
///
/// # Errors
/// The message.
pub fn open(dir: &Path, manifest: &ProbeManifest, resume: bool) -> Result<ProbeWork, String> {
    let work = ProbeWork {
        dirs: vec![dir.to_owned()],
        id: manifest.id(),
    };
    if !dir.exists() {
        create(dir, manifest)?;
        return Ok(work);
    }
    if !resume {
        return Err(format!(
            "{}: a previous probe bake's work is here; pass --resume to continue it, or delete the directory to start over",
            dir.display()
        ));
    }
    let found =
        read_manifest(dir).map_err(|e| format!("{e}; delete {} to start over", dir.display()))?;
    if found.probe_id != manifest.probe_id {
        return Err(format!(
            "{}: --resume of a different probe bake{}; delete {} to start over",
            dir.display(),
            what_differs(&found, manifest),
            dir.display()
        ));
    }
    work.remove_scratch();
    Ok(work)
}

/// The shards' directories `dirs`, read only, for a merge of the bake `manifest` describes:
/// each must be a shard of this bake (each difference named), all of one count N, every shard
/// 0 … N − 1 given once.
///
/// # Errors
/// A message naming the directory (or the shard) at fault.
pub fn open_merge(dirs: &[PathBuf], manifest: &ProbeManifest) -> Result<ProbeWork, String> {
    let mut seen: Vec<[u32; 2]> = Vec::new();
    for dir in dirs {
        if !dir.is_dir() {
            return Err(format!(
                "{}: no such shard work directory (each --shard K/N run writes OUT.shard-K-of-N)",
                dir.display()
            ));
        }
        let found = read_manifest(dir)?;
        if found.probe_id != manifest.probe_id {
            return Err(format!(
                "{}: --merge of a shard of a different probe bake{}",
                dir.display(),
                what_differs(&found, manifest)
            ));
        }
        let Some([k, n]) = found.shard else {
            return Err(format!(
                "{}: not a shard's work directory (a whole bake's: finish it with --resume)",
                dir.display()
            ));
        };
        if let Some([_, m]) = seen.first().filter(|[_, m]| *m != n) {
            return Err(format!(
                "{}: shard {k}/{n}, but the shards before it are of {m}",
                dir.display()
            ));
        }
        if seen.contains(&[k, n]) {
            return Err(format!("{}: shard {k}/{n} is given twice", dir.display()));
        }
        seen.push([k, n]);
    }
    let n = seen.first().map_or(1, |[_, n]| *n);
    if let Some(k) = (0..n).find(|k| !seen.contains(&[*k, n])) {
        return Err(format!(
            "shard {k}/{n} is missing: give every shard's work directory (OUT.shard-K-of-{n})"
        ));
    }
    Ok(ProbeWork {
        dirs: dirs.to_vec(),
        id: manifest.id(),
    })
}

/// `: --spp was 256, now 64; …`, or why the identities differ when no field says.
fn what_differs(found: &ProbeManifest, now: &ProbeManifest) -> String {
    let mut differences = now
        .record
        .differences(&found.record, &found.texels, &now.texels);
    if differences.is_empty() && found.probes != now.probes {
        differences.push(format!(
            "{} probes were placed, now {}",
            found.probes, now.probes
        ));
    }
    if differences.is_empty() {
        " (other settings, texel file, scene or lightmap)".to_owned()
    } else {
        format!(": {}", differences.join("; "))
    }
}

fn manifest_path(dir: &Path) -> PathBuf {
    dir.join("manifest.json")
}

fn read_manifest(dir: &Path) -> Result<ProbeManifest, String> {
    let path = manifest_path(dir);
    let text = std::fs::read_to_string(&path).map_err(|e| {
        format!(
            "{}: cannot read the probe bake's manifest: {e}",
            path.display()
        )
    })?;
    serde_json::from_str(&text)
        .map_err(|e| format!("{}: not a probe bake's manifest ({e})", path.display()))
}

/// The directory appears with its manifest or not at all: made under a temporary name and
/// renamed.
fn create(dir: &Path, manifest: &ProbeManifest) -> Result<(), String> {
    let fail = |e: std::io::Error| {
        format!(
            "{}: cannot create the probe bake's work directory: {e}",
            dir.display()
        )
    };
    let staging = crate::atomic::temporary_name(dir);
    let _ = std::fs::remove_dir_all(&staging);
    std::fs::create_dir_all(&staging).map_err(fail)?;
    let json = serde_json::to_string_pretty(manifest).map_err(|e| e.to_string())?;
    let result = crate::atomic::write(&manifest_path(&staging), json)
        .and_then(|()| std::fs::rename(&staging, dir));
    if let Err(e) = result {
        let _ = std::fs::remove_dir_all(&staging);
        return Err(fail(e));
    }
    Ok(())
}

/// Removes the work directory `dir` once its probe file, volume and stats are written. It
/// is renamed out of the way first, so a stop during the removal leaves no half-deleted work
/// directory for `--resume` to refuse.
///
/// # Errors
/// A message naming the directory.
pub fn retire(dir: &Path) -> Result<(), String> {
    let retired = crate::atomic::temporary_name(dir);
    let _ = std::fs::remove_dir_all(&retired);
    std::fs::rename(dir, &retired)
        .and_then(|()| std::fs::remove_dir_all(&retired))
        .map_err(|e| {
            format!(
                "{}: cannot remove the finished probe bake's work directory: {e}",
                dir.display()
            )
        })
}

impl ProbeWork {
    /// The directory (for a merge, the first shard's).
    #[must_use]
    pub fn dir(&self) -> &Path {
        &self.dirs[0]
    }

    /// Batch `batch`'s file in `dir`.
    fn batch_in(dir: &Path, batch: usize) -> PathBuf {
        dir.join(format!("batch-{batch:06}.bin"))
    }

    /// Where batch `batch` is: the first of the directories that has it (the work
    /// directory's own path when none has).
    fn batch_path(&self, batch: usize) -> PathBuf {
        self.dirs
            .iter()
            .map(|d| Self::batch_in(d, batch))
            .find(|p| p.exists())
            .unwrap_or_else(|| Self::batch_in(self.dir(), batch))
    }

    /// Temporary files a stopped write left (`.NAME.tmp-PID`): never a finished batch.
    fn remove_scratch(&self) {
        let Ok(entries) = std::fs::read_dir(self.dir()) else {
            return;
        };
        for entry in entries.flatten() {
            if entry.file_name().to_string_lossy().starts_with('.') {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }

    /// Publishes batch `batch` whole.
    ///
    /// # Errors
    /// A message naming the file.
    pub fn write(&self, batch: usize, done: &Batch) -> Result<(), String> {
        let path = Self::batch_in(self.dir(), batch);
        crate::atomic::write(&path, batch_bytes(self.id, batch, done))
            .map_err(|e| format!("{}: cannot write the probe batch: {e}", path.display()))
    }

    /// Batch `batch` as a finished run wrote it, if it is there and whole: its stamp, index,
    /// checksum, and its probes at `positions`. A damaged one is reported on stderr and
    /// baked again.
    #[must_use]
    pub fn read(&self, batch: usize, positions: &[glam::Vec3]) -> Option<Batch> {
        let path = self.batch_path(batch);
        let bytes = std::fs::read(&path).ok()?;
        let parsed = parse_batch(&bytes, self.id, batch).filter(|b| {
            b.records.len() == positions.len()
                && b.records
                    .iter()
                    .zip(positions)
                    .all(|(r, p)| r.position == *p)
        });
        if parsed.is_none() {
            eprintln!(
                "guidebake: warning: {}: damaged or not this bake's; baking the batch again",
                path.display()
            );
        }
        parsed
    }
}

fn counts(c: &GatherCount) -> [u64; 5] {
    [
        c.gather_rays,
        c.shadow_rays,
        c.path_rays,
        c.lightmap_reads,
        c.rejected,
    ]
}

fn batch_bytes(id: u64, batch: usize, done: &Batch) -> Vec<u8> {
    let mut b = Vec::with_capacity(BATCH_HEADER_BYTES + done.records.len() * RECORD_BYTES);
    b.extend_from_slice(&BATCH_MAGIC);
    for word in [id, batch as u64, done.records.len() as u64]
        .into_iter()
        .chain(counts(&done.count))
    {
        b.extend_from_slice(&word.to_le_bytes());
    }
    let head = b.len();
    b.extend_from_slice(&[0; 8]);
    for r in &done.records {
        b.extend_from_slice(&r.to_bytes());
    }
    let sum = fnv1a64_more(fnv1a64(&b[..head]), &b[head + 8..]);
    b[head..head + 8].copy_from_slice(&sum.to_le_bytes());
    b
}

fn parse_batch(bytes: &[u8], id: u64, batch: usize) -> Option<Batch> {
    if bytes.len() < BATCH_HEADER_BYTES || bytes[..8] != BATCH_MAGIC {
        return None;
    }
    let word =
        |i: usize| u64::from_le_bytes(bytes[8 + 8 * i..16 + 8 * i].try_into().unwrap_or([0; 8]));
    let head = BATCH_HEADER_BYTES - 8;
    let body = &bytes[BATCH_HEADER_BYTES..];
    let sum = fnv1a64_more(fnv1a64(&bytes[..head]), body);
    let n = usize::try_from(word(2)).ok()?;
    if word(0) != id
        || word(1) != batch as u64
        || word(8) != sum
        || n.checked_mul(RECORD_BYTES) != Some(body.len())
    {
        return None;
    }
    Some(Batch {
        records: body
            .chunks_exact(RECORD_BYTES)
            .map(ProbeRecord::from_bytes)
            .collect(),
        count: GatherCount {
            gather_rays: word(3),
            shadow_rays: word(4),
            path_rays: word(5),
            lightmap_reads: word(6),
            rejected: word(7),
        },
    })
}

/// The options of a probe bake, by the `probes` options that set them: what
/// [`ProbeManifest`] records besides the texel file, scene and lights.
#[must_use]
pub fn options(
    settings: &super::ProbeSettings,
    lightmap: &str,
    batch_clusters: usize,
) -> BTreeMap<String, String> {
    let on_off = |b: bool| if b { "on" } else { "off" }.to_owned();
    let p = &settings.placement;
    let g = &settings.gather;
    let points = p.points.iter().fold(fnv1a64(&[]), |h, v| {
        v.to_array()
            .iter()
            .fold(h, |h, x| fnv1a64_more(h, &x.to_le_bytes()))
    });
    [
        (
            "--spacing",
            p.spacing.map_or("auto".into(), |d| d.to_string()),
        ),
        (
            "--points",
            format!("{} points, {points:016x}", p.points.len()),
        ),
        (
            "--placement",
            if p.lattice { "lattice" } else { "points" }.into(),
        ),
        (
            "--refine",
            if p.refine_light { "light" } else { "geometry" }.into(),
        ),
        ("--spp", g.spp.to_string()),
        ("--iterations", g.iterations.to_string()),
        ("--guiding", on_off(g.guiding)),
        ("--transport", g.transport.name().to_owned()),
        ("--bounces", settings.bounces.to_string()),
        ("--seed", g.seed.to_string()),
        ("--dering", on_off(settings.dering)),
        ("--volume", on_off(settings.volume)),
        ("--lightmap", lightmap.to_owned()),
        ("--batch-clusters", batch_clusters.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_owned(), v))
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shards' runs of batches are contiguous, in order, cover every batch once, and
    /// differ in length by at most one; the whole bake owns them all.
    #[test]
    fn the_shards_split_the_batches_into_contiguous_runs() {
        for batches in 0..20 {
            assert_eq!(owned(None, batches), 0..batches);
            for count in 1..6 {
                let runs: Vec<_> = (0..count)
                    .map(|index| owned(Some(Shard { index, count }), batches))
                    .collect();
                assert_eq!(runs[0].start, 0);
                assert_eq!(runs[runs.len() - 1].end, batches);
                assert!(runs.windows(2).all(|w| w[0].end == w[1].start));
                let lengths = runs.iter().map(ExactSizeIterator::len);
                let (lo, hi) = (lengths.clone().min().unwrap(), lengths.max().unwrap());
                assert!(hi - lo <= 1, "{batches} batches in {count}: {runs:?}");
            }
        }
    }

    /// A batch reads back as written; a flipped byte, another bake's stamp or another index
    /// is not taken.
    #[test]
    fn a_batch_reads_back_and_damage_is_refused() {
        let mut done = Batch::default();
        for i in 0..3 {
            let mut r = ProbeRecord {
                position: glam::Vec3::new(i as f32, 1.0, 2.0),
                spacing: 0.5,
                relative_error: 0.1,
                ..ProbeRecord::default()
            };
            r.sh.c[0] = glam::Vec3::splat(i as f32);
            done.records.push(r);
        }
        done.count.gather_rays = 77;
        done.count.rejected = 2;
        let bytes = batch_bytes(9, 4, &done);
        assert_eq!(parse_batch(&bytes, 9, 4), Some(done));
        assert_eq!(parse_batch(&bytes, 8, 4), None);
        assert_eq!(parse_batch(&bytes, 9, 3), None);
        let mut flipped = bytes.clone();
        flipped[BATCH_HEADER_BYTES + 5] ^= 1;
        assert_eq!(parse_batch(&flipped, 9, 4), None);
        assert_eq!(parse_batch(&bytes[..bytes.len() - 1], 9, 4), None);
    }
}
