//! Which tiles a run bakes: `--shard i/n` and `--resume`.
//!
//! Shard `i` of `n` owns the tiles whose index is `i` modulo `n`: interleaving spreads the
//! expensive parts of a world (tiles are stored in a spatially coherent order, so a contiguous
//! range could hold all of one dense building) evenly over the shards. Tiles already in the
//! journal are skipped on resume. The order within a run is ascending tile index, which keeps
//! the texel file's pages streaming forward.

use std::collections::HashSet;
use std::fmt;
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

    /// Whether this shard owns `tile`.
    pub fn owns(&self, tile: u32) -> bool {
        tile % self.count == self.index
    }
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

/// The tiles this run bakes, ascending: those `shard` owns, minus those already `done`.
pub fn tiles_to_bake(tile_count: u32, shard: Shard, done: &HashSet<u32>) -> Vec<u32> {
    (0..tile_count)
        .filter(|&t| shard.owns(t) && !done.contains(&t))
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

    #[test]
    fn shards_partition_the_tiles() {
        let mut seen = vec![0u32; 100];
        for index in 0..3 {
            for t in tiles_to_bake(100, Shard { index, count: 3 }, &HashSet::new()) {
                seen[t as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n == 1));
    }

    #[test]
    fn resume_skips_journalled_tiles() {
        let done: HashSet<u32> = [0, 2, 5].into_iter().collect();
        assert_eq!(tiles_to_bake(7, Shard::WHOLE, &done), [1, 3, 4, 6]);
    }
}
