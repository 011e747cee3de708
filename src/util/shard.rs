//! Splitting a list of frames (or queries, or areas) over processes: shard `i/N` takes the items whose
//! position in the list is ≡ i (mod N). Every stage that loops over frames uses the same rule, so the
//! outputs of N shards together are exactly those of one process.
//!
//! On a cluster the shard comes from the scheduler ([`Shard::from_scheduler`]): a Slurm job array
//! (`SLURM_ARRAY_TASK_ID` with `SLURM_ARRAY_TASK_COUNT`, or with `SLURM_ARRAY_TASK_MIN`/`MAX`/`STEP`)
//! or a Kubernetes Indexed Job (`JOB_COMPLETION_INDEX`). With `auto/N` the task id itself is the index
//! and N the count: the form for arrays submitted as `0-(N-1)` and resubmitted in part (`--array=3,7`
//! for the failed tasks only), and for Kubernetes, which does not export the completion count.

use std::str::FromStr;

/// `--shard i/N`: the items whose position in their list is ≡ `index` (mod `count`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Shard {
    /// This shard, 0-based, below `count`.
    pub index: u32,
    /// Number of shards (≥ 1).
    pub count: u32,
}

/// Why a shard specification was refused; the message quotes the text given.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShardError {
    /// Not of the form `I/N` (the text given).
    #[error("expected I/N (e.g. 0/4), got {0:?}")]
    NotIOverN(String),
    /// `I` is not a non-negative integer (the text given).
    #[error("shard index {0:?} is not a non-negative integer")]
    Index(String),
    /// `N` is not a positive integer (the text given).
    #[error("shard count {0:?} is not a positive integer")]
    Count(String),
    /// `N` is 0.
    #[error("shard count must be at least 1")]
    Zero,
    /// `I` is not below `N`.
    #[error("shard index must be below the count (0..{count}), got {index}/{count}")]
    IndexTooLarge {
        /// The index given.
        index: u32,
        /// The count given.
        count: u32,
    },
    #[error(
        "--shard auto found no scheduler task index: set by a Slurm job array (SLURM_ARRAY_TASK_ID) or a \
         Kubernetes Indexed Job (JOB_COMPLETION_INDEX)"
    )]
    /// `--shard auto` outside a Slurm job array or Kubernetes Indexed Job.
    NoScheduler,
    /// A scheduler variable that is not a non-negative integer.
    #[error("{name}={value:?} is not a non-negative integer")]
    BadVariable {
        /// The environment variable.
        name: &'static str,
        /// Its value.
        value: String,
    },
    #[error(
        "JOB_COMPLETION_INDEX is set but Kubernetes does not export the number of completions: give it \
         as --shard auto/N"
    )]
    /// A Kubernetes Indexed Job without `--shard auto/N`: the count is not exported.
    CountUnknown,
    /// A shard error in the values a scheduler set.
    #[error("{source} (from {scheduler})")]
    FromScheduler {
        /// The scheduler.
        scheduler: Scheduler,
        /// What is wrong with its values.
        source: Box<ShardError>,
    },
    /// A part holds another number of items than its shard should.
    #[error("shard {index}/{count} holds {found} item(s); of {total} it should hold {expected}")]
    PartLength {
        /// The shard's index.
        index: u32,
        /// The shard count.
        count: u32,
        /// Items in all shards.
        total: usize,
        /// Items the shard should hold.
        expected: usize,
        /// Items it holds.
        found: usize,
    },
    /// Not every shard given exactly once.
    #[error("{found} part(s) for {count} shards; every shard 0..{count} must be given once")]
    PartCount {
        /// The shard count.
        count: u32,
        /// Parts given.
        found: usize,
    },
}

/// The directory, inside a report's output directory, that holds the parts shards write of it:
/// `<out>/parts/<i>-of-<N>/` (see [`Shard::part_dir_name`]).
pub use crate::layout::PARTS_DIR;
/// The file that makes a directory `parts/<i>-of-<N>/` a shard's part of a report (its `kind` says
/// which report); `insgen merge` combines such parts instead of copying them.
pub const PART_MARKER: &str = "part.json";

/// Where a shard taken from the environment came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scheduler {
    /// A Slurm job array.
    Slurm,
    /// A Kubernetes Indexed Job.
    Kubernetes,
}

impl std::fmt::Display for Scheduler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Scheduler::Slurm => "Slurm job array",
            Scheduler::Kubernetes => "Kubernetes Indexed Job",
        })
    }
}

/// `--shard`: a fixed `I/N`, or `auto` / `auto/N` (the index, and the count when the scheduler has
/// one, from the environment when the command starts).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShardSpec {
    /// `I/N`: this shard.
    Fixed(Shard),
    /// `auto` or `auto/N`: the shard from the scheduler's environment.
    Auto {
        /// `N` when given (needed under Kubernetes).
        count: Option<u32>,
    },
}

impl FromStr for ShardSpec {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Self, ShardError> {
        let t = s.trim();
        if t == "auto" {
            return Ok(ShardSpec::Auto { count: None });
        }
        if let Some(n) = t.strip_prefix("auto/") {
            return match n.trim().parse::<u32>() {
                Ok(0) => Err(ShardError::Zero),
                Ok(count) => Ok(ShardSpec::Auto { count: Some(count) }),
                Err(_) => Err(ShardError::Count(n.to_string())),
            };
        }
        s.parse().map(ShardSpec::Fixed)
    }
}

impl ShardSpec {
    /// The shard to run, and the scheduler it came from (`None` for a fixed one); `env` reads one
    /// environment variable (e.g. `|k| std::env::var(k).ok()`).
    pub fn resolve(
        &self,
        env: impl Fn(&str) -> Option<String>,
    ) -> Result<(Shard, Option<Scheduler>), ShardError> {
        match *self {
            ShardSpec::Fixed(s) => Ok((s, None)),
            ShardSpec::Auto { count } => Shard::from_scheduler(env, count).map(|(s, from)| (s, Some(from))),
        }
    }
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

    /// Whether this is the whole list (one shard).
    pub fn is_whole(&self) -> bool {
        self.count == 1
    }

    /// How many of `total` items this shard holds.
    pub fn len_of(&self, total: usize) -> usize {
        let (i, n) = (self.index as usize, self.count as usize);
        if total > i {
            (total - i).div_ceil(n)
        } else {
            0
        }
    }

    /// `<i>-of-<N>`: the name of this shard's part directory under [`PARTS_DIR`].
    pub fn part_dir_name(&self) -> String {
        format!("{}-of-{}", self.index, self.count)
    }

    /// The shard a part directory name (`<i>-of-<N>`) stands for.
    pub fn from_part_dir_name(name: &str) -> Option<Shard> {
        let (i, n) = name.split_once("-of-")?;
        let all_digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
        if !all_digits(i) || !all_digits(n) {
            return None;
        }
        format!("{i}/{n}").parse().ok()
    }

    /// The shard of this task of a job array, read with `env`.
    ///
    /// Without `count` (Slurm only): index `(ID − MIN) / STEP` of `COUNT` tasks (or
    /// `(MAX − MIN) / STEP + 1` when COUNT is absent), so `--array=0-3` and `--array=1-4` both give
    /// shards 0/4 … 3/4. With `count`: the task id itself (`SLURM_ARRAY_TASK_ID` or
    /// `JOB_COMPLETION_INDEX`) is the index, so a partial resubmission keeps each task's shard.
    pub fn from_scheduler(
        env: impl Fn(&str) -> Option<String>,
        count: Option<u32>,
    ) -> Result<(Shard, Scheduler), ShardError> {
        let var = |name: &'static str| -> Result<Option<u32>, ShardError> {
            match env(name) {
                None => Ok(None),
                Some(v) if v.trim().is_empty() => Ok(None),
                Some(v) => v.trim().parse().map(Some).map_err(|_| ShardError::BadVariable { name, value: v }),
            }
        };
        let checked = |index: u32, count: u32, scheduler: Scheduler| {
            let shard = if count == 0 {
                Err(ShardError::Zero)
            } else if index >= count {
                Err(ShardError::IndexTooLarge { index, count })
            } else {
                Ok(Shard { index, count })
            };
            shard
                .map(|s| (s, scheduler))
                .map_err(|e| ShardError::FromScheduler { scheduler, source: Box::new(e) })
        };
        if let (Some(id), Some(n)) = (var("SLURM_ARRAY_TASK_ID")?, count) {
            return checked(id, n, Scheduler::Slurm);
        }
        if let Some(id) = var("SLURM_ARRAY_TASK_ID")? {
            let min = var("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let step = var("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
            let index = id.checked_sub(min).map(|d| d / step).ok_or(ShardError::FromScheduler {
                scheduler: Scheduler::Slurm,
                source: Box::new(ShardError::BadVariable {
                    name: "SLURM_ARRAY_TASK_ID",
                    value: id.to_string(),
                }),
            })?;
            let from_env = match (var("SLURM_ARRAY_TASK_COUNT")?, var("SLURM_ARRAY_TASK_MAX")?) {
                (Some(n), _) => Some(n),
                (None, Some(max)) => Some(max.saturating_sub(min) / step + 1),
                (None, None) => None,
            };
            let n = from_env.ok_or(ShardError::FromScheduler {
                scheduler: Scheduler::Slurm,
                source: Box::new(ShardError::Count("SLURM_ARRAY_TASK_COUNT unset".into())),
            })?;
            return checked(index, n, Scheduler::Slurm);
        }
        if let Some(index) = var("JOB_COMPLETION_INDEX")? {
            return checked(index, count.ok_or(ShardError::CountUnknown)?, Scheduler::Kubernetes);
        }
        Err(ShardError::NoScheduler)
    }
}

/// The one list back from its shards' lists: `parts[k]` holds, in order, the items of shard `k/N`
/// (N = `parts.len()`) of a list of `total`, and the item at position p comes from shard p mod N at
/// p div N. Groups of lines (a query's lines, one per cost) interleave as items.
///
/// # Errors
/// [`ShardError::PartLength`] when a part does not hold its share of `total`; [`ShardError::PartCount`]
/// when there are no parts.
pub fn interleave<T>(parts: Vec<Vec<T>>, total: usize) -> Result<Vec<T>, ShardError> {
    let count = u32::try_from(parts.len())
        .map_err(|_| ShardError::PartCount { count: u32::MAX, found: parts.len() })?;
    if count == 0 {
        return Err(ShardError::PartCount { count, found: 0 });
    }
    for (k, p) in parts.iter().enumerate() {
        let shard = Shard { index: k as u32, count };
        let expected = shard.len_of(total);
        if p.len() != expected {
            return Err(ShardError::PartLength {
                index: shard.index,
                count,
                total,
                expected,
                found: p.len(),
            });
        }
    }
    let mut iters: Vec<std::vec::IntoIter<T>> = parts.into_iter().map(Vec::into_iter).collect();
    let n = iters.len();
    let mut out = Vec::with_capacity(total);
    for p in 0..total {
        // Each part's length was checked above: part p mod N holds an item for every such p.
        out.push(iters[p % n].next().expect("part lengths checked"));
    }
    Ok(out)
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

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| vars.iter().find(|(n, _)| *n == k).map(|(_, v)| v.to_string())
    }

    #[test]
    fn slurm_arrays_from_zero_or_one_give_the_same_shards() {
        // --array=0-3: Slurm sets ID, COUNT, MIN, MAX (and STEP).
        let zero =
            [("SLURM_ARRAY_TASK_ID", "2"), ("SLURM_ARRAY_TASK_MIN", "0"), ("SLURM_ARRAY_TASK_MAX", "3")];
        let one =
            [("SLURM_ARRAY_TASK_ID", "3"), ("SLURM_ARRAY_TASK_MIN", "1"), ("SLURM_ARRAY_TASK_COUNT", "4")];
        for vars in [&zero[..], &one[..]] {
            assert_eq!(
                Shard::from_scheduler(env(vars), None).unwrap(),
                (Shard { index: 2, count: 4 }, Scheduler::Slurm)
            );
        }
        // --array=0-6:2 → tasks 0,2,4,6 → shards 0..4.
        let step = [
            ("SLURM_ARRAY_TASK_ID", "6"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
            ("SLURM_ARRAY_TASK_MAX", "6"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
        ];
        assert_eq!(Shard::from_scheduler(env(&step), None).unwrap().0, Shard { index: 3, count: 4 });
        // auto/N: a resubmission of the failed tasks (--array=3,7 of 0-7) keeps each task's shard.
        let again =
            [("SLURM_ARRAY_TASK_ID", "7"), ("SLURM_ARRAY_TASK_MIN", "3"), ("SLURM_ARRAY_TASK_COUNT", "2")];
        assert_eq!(Shard::from_scheduler(env(&again), Some(8)).unwrap().0, Shard { index: 7, count: 8 });
    }

    #[test]
    fn kubernetes_needs_the_count_and_errors_name_the_variable() {
        let k8s = [("JOB_COMPLETION_INDEX", "1")];
        assert_eq!(Shard::from_scheduler(env(&k8s), None).unwrap_err(), ShardError::CountUnknown);
        assert_eq!(
            "auto/3".parse::<ShardSpec>().unwrap().resolve(env(&k8s)).unwrap(),
            (Shard { index: 1, count: 3 }, Some(Scheduler::Kubernetes))
        );
        let e = "auto/1".parse::<ShardSpec>().unwrap().resolve(env(&k8s)).unwrap_err().to_string();
        assert!(e.contains("below the count") && e.contains("Kubernetes"), "{e}");
        let bad = [("SLURM_ARRAY_TASK_ID", "x")];
        assert!(Shard::from_scheduler(env(&bad), None)
            .unwrap_err()
            .to_string()
            .contains("SLURM_ARRAY_TASK_ID"));
        assert_eq!(Shard::from_scheduler(env(&[]), None).unwrap_err(), ShardError::NoScheduler);
        assert_eq!("auto/0".parse::<ShardSpec>().unwrap_err(), ShardError::Zero);
        assert_eq!(
            "1/2".parse::<ShardSpec>().unwrap().resolve(env(&k8s)).unwrap(),
            (Shard { index: 1, count: 2 }, None)
        );
    }

    #[test]
    fn lengths_part_names_and_interleaving_invert_the_split() {
        let total = 11;
        for count in 1..=5u32 {
            let parts: Vec<Vec<usize>> = (0..count)
                .map(|index| (0..total).filter(|&p| Shard { index, count }.contains(p)).collect())
                .collect();
            for (k, p) in parts.iter().enumerate() {
                assert_eq!(Shard { index: k as u32, count }.len_of(total), p.len());
            }
            assert_eq!(interleave(parts, total).unwrap(), (0..total).collect::<Vec<_>>());
        }
        assert_eq!(Shard { index: 4, count: 6 }.len_of(3), 0);
        let s = Shard { index: 2, count: 7 };
        assert_eq!(s.part_dir_name(), "2-of-7");
        assert_eq!(Shard::from_part_dir_name("2-of-7"), Some(s));
        for bad in ["7-of-7", "a-of-2", "1of2", "-1-of-2", "1-of-", "1-of-2x"] {
            assert_eq!(Shard::from_part_dir_name(bad), None, "{bad}");
        }
        let e = interleave(vec![vec![0, 2], vec![1]], 4).unwrap_err();
        assert_eq!(e, ShardError::PartLength { index: 1, count: 2, total: 4, expected: 2, found: 1 });
        assert!(matches!(interleave(Vec::<Vec<u8>>::new(), 0), Err(ShardError::PartCount { .. })));
    }

    #[test]
    fn display_round_trips() {
        let s = Shard { index: 2, count: 5 };
        assert_eq!(s.to_string().parse::<Shard>().unwrap(), s);
    }
}
