//! A part of a sweep split over machines (`--part K/N`, or the index a batch scheduler
//! gives its task: Slurm's `SLURM_ARRAY_TASK_ID`, a Kubernetes Indexed Job's
//! `JOB_COMPLETION_INDEX`). Part K of N flies the flights whose index is K − 1 modulo N:
//! every N-th flight, so that cells that cost more (a larger swarm, a longer flight) are
//! spread over the parts. Pure.

use std::fmt;

/// Part `k` of `n` (from 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Part {
    /// Which part, from 1.
    pub k: u64,
    /// Of how many.
    pub n: u64,
}

impl Part {
    /// The whole sweep.
    pub const WHOLE: Self = Self { k: 1, n: 1 };

    /// Whether flight `index` is this part's.
    pub fn has(self, index: u64) -> bool {
        index % self.n == self.k - 1
    }

    /// `K/N` as given to `--part`.
    ///
    /// # Errors
    /// Not two whole numbers with 1 ≤ K ≤ N, named.
    pub fn parse(text: &str) -> Result<Self, String> {
        let bad = || format!("--part wants K/N with 1 <= K <= N (part 2 of 3: 2/3), got `{text}`");
        let (k, n) = text.split_once('/').ok_or_else(bad)?;
        let (k, n): (u64, u64) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if k == 0 || k > n {
            return Err(bad());
        }
        Ok(Self { k, n })
    }

    /// The part a batch scheduler's task is, when no `--part` was given: `count` parts
    /// (`--parts N`), the task's index from `SLURM_ARRAY_TASK_ID` (counted from
    /// `SLURM_ARRAY_TASK_MIN`, 0 when unset) or `JOB_COMPLETION_INDEX` (from 0), looked up
    /// through `var`.
    ///
    /// # Errors
    /// Neither variable set, a value that is not a whole number, or an index outside the
    /// `count` parts; named.
    pub fn from_scheduler(
        count: u64,
        var: impl Fn(&str) -> Option<String>,
    ) -> Result<Self, String> {
        let number = |name: &str, v: &str| -> Result<u64, String> {
            v.trim()
                .parse()
                .map_err(|_| format!("{name}={v} is not a whole number"))
        };
        let index = if let Some(v) = var("SLURM_ARRAY_TASK_ID") {
            let id = number("SLURM_ARRAY_TASK_ID", &v)?;
            let min = match var("SLURM_ARRAY_TASK_MIN") {
                Some(m) => number("SLURM_ARRAY_TASK_MIN", &m)?,
                None => 0,
            };
            id.checked_sub(min).ok_or_else(|| {
                format!("SLURM_ARRAY_TASK_ID={id} is below SLURM_ARRAY_TASK_MIN={min}")
            })?
        } else if let Some(v) = var("JOB_COMPLETION_INDEX") {
            number("JOB_COMPLETION_INDEX", &v)?
        } else {
            return Err(
                "--parts needs the task's index: give --part K/N, or run as a Slurm array task \
                 (SLURM_ARRAY_TASK_ID) or a Kubernetes Indexed Job (JOB_COMPLETION_INDEX)"
                    .to_owned(),
            );
        };
        if count == 0 || index >= count {
            return Err(format!(
                "the task's index {index} (from 0) is not one of the {count} parts"
            ));
        }
        Ok(Self {
            k: index + 1,
            n: count,
        })
    }
}

impl fmt::Display for Part {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.k, self.n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_parts_of_a_split_take_every_flight_once() {
        let parts: Vec<Part> = (1..=3)
            .map(|k| Part::parse(&format!("{k}/3")).unwrap())
            .collect();
        for i in 0..100 {
            assert_eq!(parts.iter().filter(|p| p.has(i)).count(), 1, "flight {i}");
        }
        assert!(parts[1].has(4) && parts[0].has(0) && parts[2].has(2));
        assert!(Part::WHOLE.has(12_345));
        assert_eq!(parts[1].to_string(), "2/3");
    }

    #[test]
    fn a_malformed_part_is_refused_by_what_it_wants() {
        for text in ["0/3", "4/3", "3", "a/b", "1/0", "-1/3"] {
            let e = Part::parse(text).unwrap_err();
            assert!(e.contains("1 <= K <= N") && e.contains(text), "{text}: {e}");
        }
    }

    #[test]
    fn a_scheduler_task_gives_its_part_from_its_index() {
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            move |name: &str| {
                pairs
                    .iter()
                    .find(|(k, _)| *k == name)
                    .map(|(_, v)| (*v).to_owned())
            }
        };
        // Slurm arrays may start at 1 (`--array=1-4`): the index counts from the minimum.
        let p = Part::from_scheduler(
            4,
            env(&[("SLURM_ARRAY_TASK_ID", "3"), ("SLURM_ARRAY_TASK_MIN", "1")]),
        );
        assert_eq!(p.unwrap(), Part { k: 3, n: 4 });
        let p = Part::from_scheduler(4, env(&[("SLURM_ARRAY_TASK_ID", "0")]));
        assert_eq!(p.unwrap(), Part { k: 1, n: 4 });
        let p = Part::from_scheduler(4, env(&[("JOB_COMPLETION_INDEX", "3")]));
        assert_eq!(p.unwrap(), Part { k: 4, n: 4 });
        let e = Part::from_scheduler(4, env(&[("JOB_COMPLETION_INDEX", "4")])).unwrap_err();
        assert!(
            e.contains("index 4 (from 0) is not one of the 4 parts"),
            "{e}"
        );
        let e = Part::from_scheduler(4, env(&[("SLURM_ARRAY_TASK_ID", "x")])).unwrap_err();
        assert!(
            e.contains("SLURM_ARRAY_TASK_ID=x is not a whole number"),
            "{e}"
        );
        let e = Part::from_scheduler(4, env(&[])).unwrap_err();
        assert!(e.contains("JOB_COMPLETION_INDEX"), "{e}");
    }
}
