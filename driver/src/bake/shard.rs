//! Which tiles a run bakes: `--shard i/n` and `--resume`.
//!
//! Shard `i` of `n` owns one contiguous run of tiles in file order, the runs balanced by
//! texel count ([`Split`]): tile `t` belongs to the shard whose `1/n` of the world's texels
//! holds the tile's middle texel. Tiles are stored in a spatially coherent order (`synth`:
//! city cells row by row; `prepare`: Morton order within each page), so a shard is one region
//! of the world, walked as an unsharded bake walks it, and it reads and writes one stretch of
//! the texel file and of its result file. The earlier assignment, tile index modulo `n`,
//! spread every shard over the whole world; measured side by side, contiguous shards baked a
//! 10^7-texel city 7% faster and a 10^8-texel one as fast, with the same load balance
//! (docs/farm.md, "Locality"). Tiles already in the journal are skipped on resume. The order
//! within a run is ascending tile index, which keeps the texel file's pages streaming forward.

use std::collections::HashSet;
use std::fmt;
use std::ops::Range;
use std::str::FromStr;

/// `--shard i/n`: this run bakes shard `index` of `count` (0-based).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// Which shard, `0..count`.
    pub index: u32,
    /// How many shards the world is split into, ≥ 1.
    pub count: u32,
}

impl Shard {
    /// The whole world in one run.
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// Why a `--shard` value was refused.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
#[error("--shard {text:?}: {why} (expected i/n with 0 <= i < n, e.g. 0/4)")]
pub struct ShardParseError {
    text: String,
    why: &'static str,
}

impl FromStr for Shard {
    type Err = ShardParseError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = |why| ShardParseError {
            text: s.to_owned(),
            why,
        };
        let (i, n) = s.split_once('/').ok_or_else(|| err("no '/'"))?;
        let index: u32 = i
            .trim()
            .parse()
            .map_err(|_| err("i is not a whole number"))?;
        let count: u32 = n
            .trim()
            .parse()
            .map_err(|_| err("n is not a whole number"))?;
        if count == 0 {
            return Err(err("n must be at least 1"));
        }
        if index >= count {
            return Err(err("i must be less than n"));
        }
        Ok(Shard { index, count })
    }
}

/// How a world's tiles are split into shards: which shard owns each tile.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Split {
    /// The owner of every tile, non-decreasing in tile index (each shard's tiles are one
    /// run); one per tile, whatever the shard count.
    owners: Vec<u32>,
}

impl Split {
    /// Splits tiles of `texel_counts` texels (in file order) into `count` contiguous runs of
    /// about equal texel count: tile `t`, with `p` texels before it and `c` in it, goes to
    /// shard `⌊count · (p + c/2) / total⌋` (the shard holding its middle texel), so every
    /// shard's texels are within one tile of `total / count`.
    pub fn new(texel_counts: impl Iterator<Item = u32> + Clone, count: u32) -> Self {
        let count = u128::from(count.max(1));
        let total: u128 = texel_counts.clone().map(u128::from).sum();
        let mut before = 0u128;
        let owners = texel_counts
            .map(|c| {
                let middle = 2 * before + u128::from(c);
                before += u128::from(c);
                if total == 0 {
                    0
                } else {
                    (count * middle / (2 * total)).min(count - 1) as u32
                }
            })
            .collect();
        Split { owners }
    }

    /// The tiles shard `index` owns.
    pub fn tiles(&self, index: u32) -> Range<u32> {
        let start = self.owners.partition_point(|&s| s < index);
        let end = self.owners.partition_point(|&s| s <= index);
        start as u32..end as u32
    }

    /// The shard that owns `tile`.
    pub fn owner(&self, tile: u32) -> usize {
        self.owners[tile as usize] as usize
    }
}

/// The tiles this run bakes, ascending: those `shard` owns in a world of tiles of
/// `texel_counts` texels ([`Split`]), minus those already `done`.
pub fn tiles_to_bake(
    texel_counts: impl Iterator<Item = u32> + Clone,
    shard: Shard,
    done: &HashSet<u32>,
) -> Vec<u32> {
    Split::new(texel_counts, shard.count)
        .tiles(shard.index)
        .filter(|t| !done.contains(t))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_refuses_shard_values() {
        assert_eq!("2/5".parse::<Shard>(), Ok(Shard { index: 2, count: 5 }));
        for bad in ["3/2", "2/2", "1/0", "x/2", "1", "-1/2", "1/2/3"] {
            let err = bad.parse::<Shard>().unwrap_err().to_string();
            assert!(
                err.contains(bad) && err.contains("expected i/n"),
                "{bad}: {err}"
            );
        }
    }

    /// Tile sizes like a `prepare`d atlas's: mostly full tiles, some partial ones.
    fn texel_counts(tiles: u32) -> Vec<u32> {
        (0..tiles)
            .map(|t| match t.wrapping_mul(2_654_435_761) % 7 {
                0 => 1 + t % 300,
                _ => 1024,
            })
            .collect()
    }

    #[test]
    fn shards_are_contiguous_runs_that_partition_the_tiles() {
        for (tiles, count) in [
            (100, 3),
            (1000, 10),
            (7, 7),
            (5, 9),
            (1, 4),
            (0, 3),
            (977, 1),
        ] {
            let counts = texel_counts(tiles);
            let split = Split::new(counts.iter().copied(), count);
            let mut next = 0;
            for index in 0..count {
                let run = split.tiles(index);
                assert_eq!(run.start, next, "{tiles} tiles, shard {index}/{count}");
                for t in run.clone() {
                    assert_eq!(split.owner(t), index as usize);
                }
                let shard = Shard { index, count };
                let baked = tiles_to_bake(counts.iter().copied(), shard, &HashSet::new());
                assert_eq!(baked, run.clone().collect::<Vec<_>>());
                next = run.end;
            }
            assert_eq!(next, tiles, "{tiles} tiles in {count} shards");
        }
    }

    #[test]
    fn shards_hold_equal_texels_within_one_tile() {
        let counts = texel_counts(5000);
        let total: u64 = counts.iter().map(|&c| u64::from(c)).sum();
        for count in [2, 3, 10, 64, 1000] {
            let split = Split::new(counts.iter().copied(), count);
            for index in 0..count {
                let texels: u64 = split
                    .tiles(index)
                    .map(|t| u64::from(counts[t as usize]))
                    .sum();
                let fair = total as f64 / f64::from(count);
                assert!(
                    (texels as f64 - fair).abs() <= 1024.0,
                    "shard {index}/{count}: {texels} texels, fair share {fair}"
                );
            }
        }
    }

    #[test]
    fn a_split_does_not_overflow_on_huge_worlds() {
        let counts = std::iter::repeat_n(u32::MAX, 1 << 12);
        let split = Split::new(counts, u32::MAX);
        assert_eq!(split.tiles(0), 0..0);
        assert_eq!(split.owner(0), (u32::MAX / (1 << 13)) as usize);
        assert_eq!(split.tiles(u32::MAX - 1), 4096..4096);
        assert_eq!(
            split.owner(4095),
            (u64::from(u32::MAX) * 8191 / 8192) as usize
        );
    }

    #[test]
    fn resume_skips_journalled_tiles() {
        let done: HashSet<u32> = [0, 2, 5].into_iter().collect();
        assert_eq!(
            tiles_to_bake(std::iter::repeat_n(10, 7), Shard::WHOLE, &done),
            [1, 3, 4, 6]
        );
        let second = Shard { index: 1, count: 2 };
        assert_eq!(
            tiles_to_bake(std::iter::repeat_n(10, 8), second, &done),
            [4, 6, 7]
        );
    }
}
