//! Splitting a list of frames (or queries, or areas) over processes: shard `i/N` takes the items whose
//! position in the list is ≡ i (mod N). Every stage that loops over frames uses the same rule, so the
//! outputs of N shards together are exactly those of one process.

use std::str::FromStr;

/// `--shard i/N`: the items whose position in their list is ≡ `index` (mod `count`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// This shard, 0-based, below `count`.
    pub index: u32,
    /// Number of shards (≥ 1).
    pub count: u32,
}

/// Why a shard specification was refused; the message quotes the text given.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShardError {
    #[error("expected I/N (e.g. 0/4), got {0:?}")]
    NotIOverN(String),
    #[error("shard index {0:?} is not a non-negative integer")]
    Index(String),
    #[error("shard count {0:?} is not a positive integer")]
    Count(String),
    #[error("shard count must be at least 1")]
    Zero,
    #[error("shard index must be below the count (0..{count}), got {index}/{count}")]
    IndexTooLarge { index: u32, count: u32 },
}

impl Default for Shard {
    /// All items (0/1).
    fn default() -> Self {
        Shard { index: 0, count: 1 }
    }
}

impl Shard {
    /// Whether the item at `position` (0-based) belongs to this shard.
    pub fn contains(&self, position: usize) -> bool {
        position % self.count as usize == self.index as usize
    }
}

impl FromStr for Shard {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Self, ShardError> {
        let (i, n) = s.split_once('/').ok_or_else(|| ShardError::NotIOverN(s.to_string()))?;
        let index: u32 = i.trim().parse().map_err(|_| ShardError::Index(i.to_string()))?;
        let count: u32 = n.trim().parse().map_err(|_| ShardError::Count(n.to_string()))?;
        if count == 0 {
            return Err(ShardError::Zero);
        }
        if index >= count {
            return Err(ShardError::IndexTooLarge { index, count });
        }
        Ok(Shard { index, count })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_validates() {
        assert_eq!("1/4".parse::<Shard>().unwrap(), Shard { index: 1, count: 4 });
        assert_eq!(" 0 / 1 ".parse::<Shard>().unwrap(), Shard::default());
        assert!("4/4".parse::<Shard>().unwrap_err().to_string().contains("below the count"));
        assert!("0/0".parse::<Shard>().unwrap_err().to_string().contains("at least 1"));
        assert!("x".parse::<Shard>().unwrap_err().to_string().contains("expected I/N"));
        assert!("-1/3".parse::<Shard>().is_err());
        assert!("a/2".parse::<Shard>().unwrap_err().to_string().contains("\"a\""));
    }

    #[test]
    fn shards_partition_the_items() {
        let mut hits = [0; 23];
        for index in 0..4 {
            let s = Shard { index, count: 4 };
            for (i, h) in hits.iter_mut().enumerate() {
                *h += s.contains(i) as u32;
            }
        }
        assert!(hits.iter().all(|&h| h == 1));
    }

    #[test]
    fn display_round_trips() {
        let s = Shard { index: 2, count: 5 };
        assert_eq!(s.to_string().parse::<Shard>().unwrap(), s);
    }
}
