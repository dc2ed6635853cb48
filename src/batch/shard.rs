//! This worker's share of the work on a render farm.
//!
//! A [`Shard`] `I/N` is worker `I` (0-based) of `N`; it takes the items (frames, tiles) whose
//! position `i` in the list has `i % N == I`: round-robin, so neighbouring frames, which tend to
//! cost the same, go to different workers and every worker finishes at about the same time.
//!
//! The shard comes from the command line ([`Shard::parse`]) or from the scheduler's environment
//! ([`Shard::from_env`]):
//!
//! - **Slurm job arrays** (`sbatch --array=0-9`): every task gets `SLURM_ARRAY_TASK_ID` (its
//!   array index), `SLURM_ARRAY_TASK_MIN` and `SLURM_ARRAY_TASK_MAX` (the lowest and highest
//!   index), `SLURM_ARRAY_TASK_COUNT` (the number of tasks) and `SLURM_ARRAY_TASK_STEP` (the step
//!   of `--array=1-7:2`; 1 when absent). The shard is `(ID - MIN) / STEP` of `COUNT`. A `%`
//!   throttle (`--array=0-99%10`) only limits how many tasks run at once and changes none of
//!   these. An array that is not one evenly stepped range (`--array=1,3,7`, `--array=0-3,10`)
//!   has `(MAX - MIN) / STEP + 1 != COUNT`; its tasks cannot tell their position from their ID,
//!   so it is refused.
//! - **Kubernetes Indexed Jobs** (`completionMode: Indexed`): the control plane gives every pod
//!   its completion index (0 to `spec.completions - 1`) in `JOB_COMPLETION_INDEX` (the value of
//!   the pod annotation `batch.kubernetes.io/job-completion-index`). The number of completions
//!   is not exposed to the pod, so the manifest passes it as `DOFRAY_SHARD_COUNT`.
//!
//! When both are set, Slurm wins: `sbatch` passes the submitting shell's environment on to the
//! job (`--export=ALL` by default), so a job array submitted from inside a Kubernetes pod still
//! carries that pod's `JOB_COMPLETION_INDEX`, while the `SLURM_ARRAY_*` variables are set by
//! Slurm for the task itself. Variables set to an empty string count as unset.

use std::fmt;
use std::str::FromStr;

use serde::Serialize;

use crate::error_kind::{ErrorKind, HasKind};

/// Slurm: the task's array index.
pub const SLURM_ARRAY_TASK_ID: &str = "SLURM_ARRAY_TASK_ID";
/// Slurm: the lowest array index.
pub const SLURM_ARRAY_TASK_MIN: &str = "SLURM_ARRAY_TASK_MIN";
/// Slurm: the highest array index.
pub const SLURM_ARRAY_TASK_MAX: &str = "SLURM_ARRAY_TASK_MAX";
/// Slurm: the number of tasks in the array.
pub const SLURM_ARRAY_TASK_COUNT: &str = "SLURM_ARRAY_TASK_COUNT";
/// Slurm: the array's index step.
pub const SLURM_ARRAY_TASK_STEP: &str = "SLURM_ARRAY_TASK_STEP";
/// Kubernetes: the pod's completion index in an Indexed Job.
pub const JOB_COMPLETION_INDEX: &str = "JOB_COMPLETION_INDEX";
/// dofray: the number of workers, for schedulers that do not say it (Kubernetes).
pub const DOFRAY_SHARD_COUNT: &str = "DOFRAY_SHARD_COUNT";

/// A shard that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShardError {
    /// Text that is not `I/N`.
    #[error(
        "cannot read the shard `{text}`: expected `I/N`, this worker's index I (counting from 0) \
         and the number of workers N, as in `0/4`"
    )]
    Syntax {
        /// The text given.
        text: String,
    },
    /// A shard count of 0.
    #[error("the shard `{index}/0` has no workers; the count N in `I/N` must be at least 1")]
    ZeroCount {
        /// The index given.
        index: u32,
    },
    /// An index not below the count.
    #[error(
        "the shard `{index}/{count}` does not exist; indices count from 0, so the shards of \
         {count} workers are `0/{count}` to `{}/{count}`",
        count - 1
    )]
    IndexTooLarge {
        /// The index given.
        index: u32,
        /// The count given (at least 1).
        count: u32,
    },
    /// An environment variable that is not the number it should be.
    #[error("the environment variable {variable} is `{value}`, but it must be {expected}")]
    Malformed {
        /// The variable.
        variable: &'static str,
        /// Its value.
        value: String,
        /// What it must be.
        expected: &'static str,
    },
    /// A Slurm array task whose environment lacks a variable the shard needs.
    #[error(
        "{SLURM_ARRAY_TASK_ID} is set but {variable} is not, so this task's share of the work is \
         unknown; pass --shard I/N"
    )]
    SlurmMissing {
        /// The missing variable.
        variable: &'static str,
    },
    /// A Slurm job array's variables without the task's own index (unset or empty): every
    /// task would render everything.
    #[error(
        "{variable} is set (a Slurm job array) but {SLURM_ARRAY_TASK_ID} is {state}, so this \
         task's share of the work is unknown; pass --shard I/N"
    )]
    SlurmIdMissing {
        /// The array variable that was seen.
        variable: &'static str,
        /// `"empty"` or `"not set"`.
        state: &'static str,
    },
    /// A Slurm array that is not one evenly stepped range.
    #[error(
        "this Slurm job array is not one contiguous range ({SLURM_ARRAY_TASK_MIN}={min}, \
         {SLURM_ARRAY_TASK_MAX}={max}, {SLURM_ARRAY_TASK_STEP}={step}, but \
         {SLURM_ARRAY_TASK_COUNT}={count}), so a task cannot tell its share from its index; \
         submit a contiguous array such as `--array=0-{}`, or pass --shard I/N",
        count.saturating_sub(1)
    )]
    SlurmSparse {
        /// `SLURM_ARRAY_TASK_MIN`.
        min: u32,
        /// `SLURM_ARRAY_TASK_MAX`.
        max: u32,
        /// `SLURM_ARRAY_TASK_STEP`.
        step: u32,
        /// `SLURM_ARRAY_TASK_COUNT`.
        count: u32,
    },
    /// A Slurm task ID that is not one of the array's indices.
    #[error(
        "{SLURM_ARRAY_TASK_ID}={id} is not one of this job array's indices \
         ({SLURM_ARRAY_TASK_MIN}={min} to {SLURM_ARRAY_TASK_MAX}={max} in steps of \
         {SLURM_ARRAY_TASK_STEP}={step}); pass --shard I/N"
    )]
    SlurmOutside {
        /// `SLURM_ARRAY_TASK_ID`.
        id: u32,
        /// `SLURM_ARRAY_TASK_MIN`.
        min: u32,
        /// `SLURM_ARRAY_TASK_MAX`.
        max: u32,
        /// `SLURM_ARRAY_TASK_STEP`.
        step: u32,
    },
    /// A Kubernetes completion index without the number of completions.
    #[error(
        "{JOB_COMPLETION_INDEX} is set (a Kubernetes Indexed Job) but {DOFRAY_SHARD_COUNT} is \
         not; Kubernetes does not tell a pod how many completions its Job has, so set \
         {DOFRAY_SHARD_COUNT} in the pod template to the Job's `spec.completions`"
    )]
    KubernetesCountMissing,
    /// `DOFRAY_SHARD_COUNT` without a completion index.
    #[error(
        "{DOFRAY_SHARD_COUNT} is set but {JOB_COMPLETION_INDEX} is not; run the pods as a \
         Kubernetes Job with `completionMode: Indexed`, or pass --shard I/N"
    )]
    KubernetesIndexMissing,
    /// A Kubernetes completion index not below `DOFRAY_SHARD_COUNT`.
    #[error(
        "{JOB_COMPLETION_INDEX} is {index}, but {DOFRAY_SHARD_COUNT} is {count}, so there is no \
         such shard; set {DOFRAY_SHARD_COUNT} to the Job's `spec.completions`"
    )]
    KubernetesOutside {
        /// `JOB_COMPLETION_INDEX`.
        index: u32,
        /// `DOFRAY_SHARD_COUNT`.
        count: u32,
    },
}

/// Where a shard read from the environment came from, for messages and `--json`.
///
/// Serialised as `{"scheduler": "slurm", "task_id": 3}` or
/// `{"scheduler": "kubernetes", "completion_index": 3}`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(tag = "scheduler", rename_all = "lowercase")]
pub enum ShardSource {
    /// A Slurm job array task.
    Slurm {
        /// Its `SLURM_ARRAY_TASK_ID` (not the shard index when the array does not start at 0
        /// or has a step).
        task_id: u32,
    },
    /// A pod of a Kubernetes Indexed Job.
    Kubernetes {
        /// Its `JOB_COMPLETION_INDEX`.
        completion_index: u32,
    },
}

impl ShardSource {
    /// The environment variable that identifies the worker.
    pub fn variable(&self) -> &'static str {
        match self {
            ShardSource::Slurm { .. } => SLURM_ARRAY_TASK_ID,
            ShardSource::Kubernetes { .. } => JOB_COMPLETION_INDEX,
        }
    }
}

impl fmt::Display for ShardSource {
    /// `Slurm array task 3 (SLURM_ARRAY_TASK_ID)`, `Kubernetes completion index 3
    /// (JOB_COMPLETION_INDEX)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ShardSource::Slurm { task_id } => {
                write!(f, "Slurm array task {task_id} ({})", self.variable())
            }
            ShardSource::Kubernetes { completion_index } => {
                write!(
                    f,
                    "Kubernetes completion index {completion_index} ({})",
                    self.variable()
                )
            }
        }
    }
}

/// Worker `index` (0-based) of `count`: see the module documentation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub struct Shard {
    /// This worker's index, below `count`.
    pub index: u32,
    /// The number of workers, at least 1.
    pub count: u32,
}

impl Shard {
    /// The whole work: one worker, `0/1`.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Worker `index` of `count`, checked: `count >= 1` and `index < count`.
    pub fn new(index: u32, count: u32) -> Result<Shard, ShardError> {
        if count == 0 {
            return Err(ShardError::ZeroCount { index });
        }
        if index >= count {
            return Err(ShardError::IndexTooLarge { index, count });
        }
        Ok(Shard { index, count })
    }

    /// Parses `I/N` (white space around the numbers is ignored), as [`Shard::new`] checks it.
    pub fn parse(text: &str) -> Result<Shard, ShardError> {
        let syntax = || ShardError::Syntax {
            text: text.to_string(),
        };
        let (index, count) = text.split_once('/').ok_or_else(syntax)?;
        let number = |s: &str| {
            let s = s.trim();
            if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
                return Err(syntax());
            }
            s.parse::<u32>().map_err(|_| syntax())
        };
        Shard::new(number(index)?, number(count)?)
    }

    /// The positions this worker takes of a list of `len` items: `index`, `index + count`, ...
    pub fn indices(&self, len: usize) -> impl Iterator<Item = usize> + use<> {
        (self.index as usize..len).step_by(self.count.max(1) as usize)
    }

    /// This worker's items: those at positions `i` with `i % count == index`, in order.
    ///
    /// ```
    /// use dofray::batch::Shard;
    /// let frames = [1, 2, 3, 4, 5, 6, 7];
    /// assert_eq!(Shard::parse("1/3").unwrap().pick(&frames), vec![2, 5]);
    /// ```
    pub fn pick<T: Clone>(&self, items: &[T]) -> Vec<T> {
        self.indices(items.len())
            .map(|i| items[i].clone())
            .collect()
    }

    /// The shard the scheduler assigned this process, read through `get` (pass
    /// `|k| std::env::var(k).ok()`): `Ok(None)` when neither a Slurm job array nor a Kubernetes
    /// Indexed Job is seen; an error when the variables are malformed, inconsistent or
    /// incomplete (see the module documentation).
    pub fn from_env(
        get: impl Fn(&str) -> Option<String>,
    ) -> Result<Option<(Shard, ShardSource)>, ShardError> {
        let raw_id = get(SLURM_ARRAY_TASK_ID);
        let get = |name: &str| get(name).filter(|v| !v.trim().is_empty());
        if let Some(id) = get(SLURM_ARRAY_TASK_ID) {
            return slurm(&get, &id).map(Some);
        }
        // The array's other variables without the task's index: refused, not read as "no
        // array" (every task would then render every frame).
        let array_variable = [
            SLURM_ARRAY_TASK_MIN,
            SLURM_ARRAY_TASK_MAX,
            SLURM_ARRAY_TASK_COUNT,
            SLURM_ARRAY_TASK_STEP,
        ]
        .into_iter()
        .find(|v| get(v).is_some());
        if let Some(variable) = array_variable {
            let state = if raw_id.is_some() { "empty" } else { "not set" };
            return Err(ShardError::SlurmIdMissing { variable, state });
        }
        match (get(JOB_COMPLETION_INDEX), get(DOFRAY_SHARD_COUNT)) {
            (None, None) => Ok(None),
            (None, Some(_)) => Err(ShardError::KubernetesIndexMissing),
            (Some(_), None) => Err(ShardError::KubernetesCountMissing),
            (Some(index), Some(count)) => {
                let index = number(JOB_COMPLETION_INDEX, &index)?;
                let count = positive(DOFRAY_SHARD_COUNT, &count)?;
                if index >= count {
                    return Err(ShardError::KubernetesOutside { index, count });
                }
                let source = ShardSource::Kubernetes {
                    completion_index: index,
                };
                Ok(Some((Shard { index, count }, source)))
            }
        }
    }
}

/// The shard of a Slurm array task whose `SLURM_ARRAY_TASK_ID` is `id`.
fn slurm(
    get: &impl Fn(&str) -> Option<String>,
    id: &str,
) -> Result<(Shard, ShardSource), ShardError> {
    let id = number(SLURM_ARRAY_TASK_ID, id)?;
    let required =
        |variable: &'static str| get(variable).ok_or(ShardError::SlurmMissing { variable });
    let min = number(SLURM_ARRAY_TASK_MIN, &required(SLURM_ARRAY_TASK_MIN)?)?;
    let max = number(SLURM_ARRAY_TASK_MAX, &required(SLURM_ARRAY_TASK_MAX)?)?;
    let count = positive(SLURM_ARRAY_TASK_COUNT, &required(SLURM_ARRAY_TASK_COUNT)?)?;
    let step = match get(SLURM_ARRAY_TASK_STEP) {
        Some(step) => positive(SLURM_ARRAY_TASK_STEP, &step)?,
        None => 1,
    };
    let outside = ShardError::SlurmOutside { id, min, max, step };
    let span = max.checked_sub(min).ok_or(outside.clone())?;
    if u64::from(span / step) + 1 != u64::from(count) {
        return Err(ShardError::SlurmSparse {
            min,
            max,
            step,
            count,
        });
    }
    if id < min || id > max || (id - min) % step != 0 {
        return Err(outside);
    }
    let shard = Shard {
        index: (id - min) / step,
        count,
    };
    Ok((shard, ShardSource::Slurm { task_id: id }))
}

/// An environment variable's value as a number from 0 to `u32::MAX`.
fn number(variable: &'static str, value: &str) -> Result<u32, ShardError> {
    let trimmed = value.trim();
    // `parse` alone would take a leading `+`.
    let digits = trimmed.bytes().all(|b| b.is_ascii_digit());
    match trimmed.parse::<u32>() {
        Ok(n) if digits => Ok(n),
        _ => Err(ShardError::Malformed {
            variable,
            value: value.to_string(),
            expected: "a whole number from 0 to 4294967295",
        }),
    }
}

/// An environment variable's value as a number from 1 to `u32::MAX`.
fn positive(variable: &'static str, value: &str) -> Result<u32, ShardError> {
    match number(variable, value) {
        Ok(0) | Err(_) => Err(ShardError::Malformed {
            variable,
            value: value.to_string(),
            expected: "a whole number from 1 to 4294967295",
        }),
        Ok(n) => Ok(n),
    }
}

impl fmt::Display for Shard {
    /// `I/N`, as [`Shard::parse`] reads it.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = ShardError;

    /// [`Shard::parse`].
    fn from_str(text: &str) -> Result<Shard, ShardError> {
        Shard::parse(text)
    }
}

impl HasKind for ShardError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Usage
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;

    /// `from_env` over the given variables.
    fn env(vars: &[(&str, &str)]) -> Result<Option<(Shard, ShardSource)>, ShardError> {
        let map: HashMap<String, String> = vars
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        Shard::from_env(|k| map.get(k).cloned())
    }

    /// The Slurm variables of task `id` of an array from `min` to `max` in `step`s of `count`
    /// tasks.
    fn slurm_vars(
        id: &str,
        min: &str,
        max: &str,
        step: &str,
        count: &str,
    ) -> Vec<(&'static str, String)> {
        vec![
            (SLURM_ARRAY_TASK_ID, id.into()),
            (SLURM_ARRAY_TASK_MIN, min.into()),
            (SLURM_ARRAY_TASK_MAX, max.into()),
            (SLURM_ARRAY_TASK_STEP, step.into()),
            (SLURM_ARRAY_TASK_COUNT, count.into()),
        ]
    }

    fn slurm_env(
        id: &str,
        min: &str,
        max: &str,
        step: &str,
        count: &str,
    ) -> Result<Option<(Shard, ShardSource)>, ShardError> {
        let vars = slurm_vars(id, min, max, step, count);
        let vars: Vec<(&str, &str)> = vars.iter().map(|(k, v)| (*k, v.as_str())).collect();
        env(&vars)
    }

    fn shard(index: u32, count: u32) -> Shard {
        Shard { index, count }
    }

    #[test]
    fn an_array_without_its_task_id_is_refused() {
        // Empty, blank or missing SLURM_ARRAY_TASK_ID while the array's other variables are
        // set: every task would otherwise render every frame.
        for id in ["", "  "] {
            assert_eq!(
                slurm_env(id, "0", "9", "1", "10"),
                Err(ShardError::SlurmIdMissing {
                    variable: SLURM_ARRAY_TASK_MIN,
                    state: "empty"
                })
            );
        }
        assert_eq!(
            env(&[(SLURM_ARRAY_TASK_COUNT, "4")]),
            Err(ShardError::SlurmIdMissing {
                variable: SLURM_ARRAY_TASK_COUNT,
                state: "not set"
            })
        );
        // No Slurm array variables at all (or only empty ones): no shard.
        assert_eq!(env(&[]), Ok(None));
        assert_eq!(
            env(&[(SLURM_ARRAY_TASK_ID, ""), (SLURM_ARRAY_TASK_MIN, "")]),
            Ok(None)
        );
    }

    #[test]
    fn parse_and_display_round_trip() {
        assert_eq!(Shard::parse("0/1"), Ok(Shard::ALL));
        assert_eq!(Shard::parse("3/8"), Ok(shard(3, 8)));
        assert_eq!(Shard::parse(" 3 / 8 "), Ok(shard(3, 8)));
        assert_eq!("7/8".parse::<Shard>(), Ok(shard(7, 8)));
        assert_eq!(shard(3, 8).to_string(), "3/8");
        for text in ["0/1", "5/6", "4294967294/4294967295"] {
            assert_eq!(Shard::parse(text).unwrap().to_string(), text);
        }
    }

    #[test]
    fn parse_refuses_what_is_not_a_shard() {
        for text in [
            "",
            "3",
            "3/",
            "/8",
            "a/8",
            "3/b",
            "3/8/9",
            "-1/8",
            "3/-8",
            "+3/8",
            "1.0/2",
            "3 8",
            "4294967296/4294967297",
        ] {
            assert_eq!(
                Shard::parse(text),
                Err(ShardError::Syntax { text: text.into() }),
                "{text:?}"
            );
        }
        assert_eq!(Shard::parse("0/0"), Err(ShardError::ZeroCount { index: 0 }));
        assert_eq!(
            Shard::parse("8/8"),
            Err(ShardError::IndexTooLarge { index: 8, count: 8 })
        );
        assert_eq!(
            Shard::parse("9/8"),
            Err(ShardError::IndexTooLarge { index: 9, count: 8 })
        );
        assert_eq!(
            Shard::parse("8/8").unwrap_err().to_string(),
            "the shard `8/8` does not exist; indices count from 0, so the shards of 8 workers are \
             `0/8` to `7/8`"
        );
        assert_eq!(
            Shard::parse("1-4").unwrap_err().to_string(),
            "cannot read the shard `1-4`: expected `I/N`, this worker's index I (counting from 0) \
             and the number of workers N, as in `0/4`"
        );
    }

    #[test]
    fn pick_is_round_robin() {
        let items: Vec<i64> = (1..=10).collect();
        assert_eq!(shard(0, 3).pick(&items), vec![1, 4, 7, 10]);
        assert_eq!(shard(1, 3).pick(&items), vec![2, 5, 8]);
        assert_eq!(shard(2, 3).pick(&items), vec![3, 6, 9]);
        assert_eq!(Shard::ALL.pick(&items), items);
        assert_eq!(
            shard(4, 5).pick(&[1, 2, 3]),
            Vec::<i32>::new(),
            "more workers than items"
        );
        assert_eq!(shard(0, 2).pick::<u8>(&[]), Vec::<u8>::new());
        assert_eq!(shard(2, 3).indices(10).collect::<Vec<_>>(), vec![2, 5, 8]);
    }

    #[test]
    fn the_shards_partition_the_items() {
        let items: Vec<usize> = (0..101).collect();
        for count in 1..=12 {
            let mut all: Vec<usize> = (0..count)
                .flat_map(|i| shard(i, count).pick(&items))
                .collect();
            let sizes: Vec<usize> = (0..count)
                .map(|i| shard(i, count).pick(&items).len())
                .collect();
            all.sort();
            assert_eq!(all, items, "count {count}: every item exactly once");
            let (lo, hi) = (sizes.iter().min().unwrap(), sizes.iter().max().unwrap());
            assert!(hi - lo <= 1, "count {count}: balanced, {sizes:?}");
        }
    }

    #[test]
    fn no_scheduler_is_none() {
        assert_eq!(env(&[]), Ok(None));
        assert_eq!(env(&[("SLURM_JOB_ID", "12"), ("HOME", "/root")]), Ok(None));
        assert_eq!(
            env(&[(SLURM_ARRAY_TASK_ID, ""), (JOB_COMPLETION_INDEX, " ")]),
            Ok(None)
        );
    }

    #[test]
    fn slurm_contiguous_array() {
        // sbatch --array=0-9: task 3.
        let got = slurm_env("3", "0", "9", "1", "10").unwrap().unwrap();
        assert_eq!(got, (shard(3, 10), ShardSource::Slurm { task_id: 3 }));
        // sbatch --array=1-16%4 (the throttle changes nothing): task 1 is the first shard.
        assert_eq!(
            slurm_env("1", "1", "16", "1", "16").unwrap().unwrap().0,
            shard(0, 16)
        );
        assert_eq!(
            slurm_env("16", "1", "16", "1", "16").unwrap().unwrap().0,
            shard(15, 16)
        );
        // A one-task array.
        assert_eq!(
            slurm_env("5", "5", "5", "1", "1").unwrap().unwrap().0,
            shard(0, 1)
        );
    }

    #[test]
    fn slurm_stepped_array() {
        // sbatch --array=1-7:2: tasks 1, 3, 5, 7.
        for (id, index) in [("1", 0), ("3", 1), ("5", 2), ("7", 3)] {
            let got = slurm_env(id, "1", "7", "2", "4").unwrap().unwrap();
            assert_eq!(got.0, shard(index, 4), "task {id}");
        }
        // sbatch --array=0-15:4 (0, 4, 8, 12): MAX is the highest index, 12.
        assert_eq!(
            slurm_env("8", "0", "12", "4", "4").unwrap().unwrap().0,
            shard(2, 4)
        );
    }

    #[test]
    fn slurm_step_defaults_to_one() {
        let got = env(&[
            (SLURM_ARRAY_TASK_ID, "12"),
            (SLURM_ARRAY_TASK_MIN, "10"),
            (SLURM_ARRAY_TASK_MAX, "13"),
            (SLURM_ARRAY_TASK_COUNT, "4"),
        ]);
        assert_eq!(
            got,
            Ok(Some((shard(2, 4), ShardSource::Slurm { task_id: 12 })))
        );
    }

    #[test]
    fn slurm_sparse_arrays_are_refused() {
        // sbatch --array=1,3,7: Slurm reports MIN 1, MAX 7, COUNT 3.
        let err = slurm_env("3", "1", "7", "1", "3").unwrap_err();
        assert_eq!(
            err,
            ShardError::SlurmSparse {
                min: 1,
                max: 7,
                step: 1,
                count: 3
            }
        );
        let text = err.to_string();
        assert!(
            text.contains("`--array=0-2`") && text.contains("--shard I/N"),
            "{text}"
        );
        assert!(text.contains("SLURM_ARRAY_TASK_COUNT=3"), "{text}");
        // sbatch --array=1-7:2,20: five tasks from 1 to 20.
        assert!(matches!(
            slurm_env("20", "1", "20", "2", "5"),
            Err(ShardError::SlurmSparse { .. })
        ));
    }

    #[test]
    fn slurm_inconsistent_ids_are_refused() {
        let outside = |id| ShardError::SlurmOutside {
            id,
            min: 1,
            max: 7,
            step: 2,
        };
        for (id, why) in [
            (4, "between two indices"),
            (0, "below MIN"),
            (9, "above MAX"),
        ] {
            let got = slurm_env(&id.to_string(), "1", "7", "2", "4");
            assert_eq!(got, Err(outside(id)), "{why}");
        }
        assert_eq!(
            slurm_env("3", "5", "1", "1", "1"),
            Err(ShardError::SlurmOutside {
                id: 3,
                min: 5,
                max: 1,
                step: 1
            }),
            "MAX below MIN"
        );
    }

    #[test]
    fn slurm_missing_variables_are_named() {
        for missing in [
            SLURM_ARRAY_TASK_MIN,
            SLURM_ARRAY_TASK_MAX,
            SLURM_ARRAY_TASK_COUNT,
        ] {
            let vars = slurm_vars("3", "0", "9", "1", "10");
            let vars: Vec<(&str, &str)> = vars
                .iter()
                .filter(|(k, _)| *k != missing)
                .map(|(k, v)| (*k, v.as_str()))
                .collect();
            let err = env(&vars).unwrap_err();
            assert_eq!(err, ShardError::SlurmMissing { variable: missing });
            assert!(
                err.to_string()
                    .starts_with(&format!("SLURM_ARRAY_TASK_ID is set but {missing} is not"))
            );
        }
    }

    /// Asserts that `got` is a `Malformed` error naming `variable` and `value`.
    #[track_caller]
    fn assert_malformed(
        got: Result<Option<(Shard, ShardSource)>, ShardError>,
        variable: &str,
        value: &str,
    ) {
        match got {
            Err(ShardError::Malformed {
                variable: v,
                value: val,
                ..
            }) => {
                assert_eq!((v, val.as_str()), (variable, value));
            }
            other => panic!("{variable}={value}: {other:?}"),
        }
    }

    #[test]
    fn malformed_numbers_name_the_variable_and_value() {
        use {SLURM_ARRAY_TASK_COUNT as COUNT, SLURM_ARRAY_TASK_ID as ID};
        use {SLURM_ARRAY_TASK_MAX as MAX, SLURM_ARRAY_TASK_MIN as MIN};
        assert_malformed(slurm_env("three", "0", "9", "1", "10"), ID, "three");
        assert_malformed(slurm_env("3", "-1", "9", "1", "10"), MIN, "-1");
        assert_malformed(slurm_env("3", "0", "9x", "1", "10"), MAX, "9x");
        let step_0 = slurm_env("3", "0", "9", "0", "10");
        assert_malformed(step_0, SLURM_ARRAY_TASK_STEP, "0");
        assert_malformed(slurm_env("3", "0", "9", "1", "0"), COUNT, "0");
        let huge = "99999999999";
        assert_malformed(slurm_env("3", "0", "9", "1", huge), COUNT, huge);
        let k8s = |index, count| env(&[(JOB_COMPLETION_INDEX, index), (DOFRAY_SHARD_COUNT, count)]);
        assert_malformed(k8s("1.5", "4"), JOB_COMPLETION_INDEX, "1.5");
        assert_malformed(k8s("1", "four"), DOFRAY_SHARD_COUNT, "four");
        assert_malformed(k8s("1", "0"), DOFRAY_SHARD_COUNT, "0");
        assert_malformed(k8s("+1", "2"), JOB_COMPLETION_INDEX, "+1");
        assert_eq!(
            slurm_env("x", "0", "9", "1", "10").unwrap_err().to_string(),
            "the environment variable SLURM_ARRAY_TASK_ID is `x`, but it must be a whole number \
             from 0 to 4294967295"
        );
    }

    #[test]
    fn values_are_trimmed() {
        let got = slurm_env(" 3\n", "0", "9", "1", "10").unwrap().unwrap();
        assert_eq!(got.0, shard(3, 10));
    }

    #[test]
    fn kubernetes_indexed_job() {
        let got = env(&[(JOB_COMPLETION_INDEX, "2"), (DOFRAY_SHARD_COUNT, "5")]);
        assert_eq!(
            got,
            Ok(Some((
                shard(2, 5),
                ShardSource::Kubernetes {
                    completion_index: 2
                }
            )))
        );
        assert_eq!(
            env(&[(JOB_COMPLETION_INDEX, "0"), (DOFRAY_SHARD_COUNT, "1")])
                .unwrap()
                .unwrap()
                .0,
            Shard::ALL
        );
    }

    #[test]
    fn kubernetes_needs_both_variables() {
        let err = env(&[(JOB_COMPLETION_INDEX, "2")]).unwrap_err();
        assert_eq!(err, ShardError::KubernetesCountMissing);
        assert!(err.to_string().contains("set DOFRAY_SHARD_COUNT"), "{err}");
        let err = env(&[(DOFRAY_SHARD_COUNT, "5")]).unwrap_err();
        assert_eq!(err, ShardError::KubernetesIndexMissing);
        assert!(err.to_string().contains("completionMode: Indexed"), "{err}");
        assert_eq!(
            env(&[(JOB_COMPLETION_INDEX, "5"), (DOFRAY_SHARD_COUNT, "5")]),
            Err(ShardError::KubernetesOutside { index: 5, count: 5 })
        );
    }

    #[test]
    fn slurm_wins_over_kubernetes() {
        let mut vars = slurm_vars("4", "0", "9", "1", "10");
        vars.push((JOB_COMPLETION_INDEX, "1".into()));
        let vars: Vec<(&str, &str)> = vars.iter().map(|(k, v)| (*k, v.as_str())).collect();
        assert_eq!(
            env(&vars),
            Ok(Some((shard(4, 10), ShardSource::Slurm { task_id: 4 })))
        );
        // Even an incomplete Kubernetes setup does not matter under Slurm.
        let got = env(&[
            (SLURM_ARRAY_TASK_ID, "0"),
            (SLURM_ARRAY_TASK_MIN, "0"),
            (SLURM_ARRAY_TASK_MAX, "1"),
            (SLURM_ARRAY_TASK_COUNT, "2"),
            (DOFRAY_SHARD_COUNT, "7"),
        ]);
        assert_eq!(got.unwrap().unwrap().0, shard(0, 2));
    }

    #[test]
    fn sources_for_messages_and_json() {
        let slurm = ShardSource::Slurm { task_id: 3 };
        let k8s = ShardSource::Kubernetes {
            completion_index: 3,
        };
        assert_eq!(
            slurm.to_string(),
            "Slurm array task 3 (SLURM_ARRAY_TASK_ID)"
        );
        assert_eq!(
            k8s.to_string(),
            "Kubernetes completion index 3 (JOB_COMPLETION_INDEX)"
        );
        assert_eq!(
            serde_json::to_value(slurm).unwrap(),
            serde_json::json!({"scheduler": "slurm", "task_id": 3})
        );
        assert_eq!(
            serde_json::to_value(k8s).unwrap(),
            serde_json::json!({"scheduler": "kubernetes", "completion_index": 3})
        );
        assert_eq!(
            serde_json::to_value(shard(1, 4)).unwrap(),
            serde_json::json!({"index": 1, "count": 4})
        );
    }
}
