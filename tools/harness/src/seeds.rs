//! Which seeds a benchmark runs, which of them this shard runs, and the spread of a figure
//! over them.
//!
//! Seeds 1 to 10 are the tuning seeds: every constant of the planners and the learner was
//! chosen on them. Reported figures use seeds from [`FIRST_REPORTED_SEED`] on, which no
//! constant saw. `--seed S` runs one seed, the old way (tests and quick looks).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// The first seed of the reported figures: nothing was tuned on it or after it.
pub const FIRST_REPORTED_SEED: u64 = 100;

/// The seeds of every benchmark: `--seeds N` from `--first-seed`, or `--seed S` alone,
/// and `--shard I/N` to run a share of them.
#[derive(Debug, Clone, clap::Args)]
pub struct SeedArgs {
    /// How many seeds to run, from `--first-seed` on. Figures are reported with their
    /// mean and spread over the seeds, and per seed in the JSON (`seeds`, `per_seed`).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: u64,
    /// The first seed. Seeds 1-10 are the ones the constants were tuned on; the default,
    /// 100, starts the held-out seeds the README reports.
    #[arg(long, default_value_t = FIRST_REPORTED_SEED)]
    pub first_seed: u64,
    /// Run this one seed only (instead of `--seeds`/`--first-seed`).
    #[arg(long, conflicts_with_all = ["seeds", "first_seed"])]
    pub seed: Option<u64>,
    /// Run only the I-th of N equal shares of the seeds (I from 1 to N) and write a
    /// partial JSON; `agp bench merge` combines the partials into the full result.
    #[arg(long, value_name = "I/N")]
    pub shard: Option<Shard>,
}

impl Default for SeedArgs {
    fn default() -> Self {
        Self {
            seeds: 5,
            first_seed: FIRST_REPORTED_SEED,
            seed: None,
            shard: None,
        }
    }
}

impl SeedArgs {
    /// One seed, no shard.
    pub fn one(seed: u64) -> Self {
        Self {
            seed: Some(seed),
            ..Self::default()
        }
    }

    /// Every seed of the run, in order (all shards together).
    pub fn all(&self) -> Vec<u64> {
        match self.seed {
            Some(s) => vec![s],
            None => (0..self.seeds)
                .map(|k| self.first_seed.wrapping_add(k))
                .collect(),
        }
    }

    /// The seeds this run works: all of them, or this shard's share.
    pub fn mine(&self) -> Vec<u64> {
        let all = self.all();
        match self.shard {
            None => all,
            Some(shard) => shard.pick(&all),
        }
    }
}

/// `--shard I/N`: the I-th (1-based) of N shares.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    pub index: u64,
    pub count: u64,
}

impl Shard {
    /// The share of `items` this shard runs: contiguous blocks, the first ones one longer
    /// when N does not divide the count, so the shards in order give back `items`.
    pub fn pick<T: Clone>(&self, items: &[T]) -> Vec<T> {
        let n = items.len() as u64;
        let (base, extra) = (n / self.count, n % self.count);
        let i = self.index - 1;
        let start = i * base + i.min(extra);
        let len = base + u64::from(i < extra);
        items[start as usize..(start + len) as usize].to_vec()
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || format!("`{s}` is not a shard: write I/N, I from 1 to N (e.g. 2/4)");
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let index: u64 = i.trim().parse().map_err(|_| bad())?;
        let count: u64 = n.trim().parse().map_err(|_| bad())?;
        if count == 0 || index == 0 || index > count {
            return Err(bad());
        }
        Ok(Self { index, count })
    }
}

/// A figure over seeds: its mean, its range and a 95 % interval of the mean (Student's t;
/// equal to the mean for one seed). Non-finite values (a run that had no figure) are left
/// out and counted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Spread {
    pub mean: f64,
    pub min: f64,
    pub max: f64,
    pub ci95_low: f64,
    pub ci95_high: f64,
    /// Values the figure is over.
    pub n: usize,
    /// Values left out because they were not finite.
    pub missing: usize,
}

impl Spread {
    /// The spread of `values`; `None` when none is finite.
    pub fn of(values: &[f64]) -> Option<Self> {
        let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
        let n = finite.len();
        if n == 0 {
            return None;
        }
        let mean = finite.iter().sum::<f64>() / n as f64;
        let min = finite.iter().copied().fold(f64::INFINITY, f64::min);
        let max = finite.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let half = if n > 1 {
            let var = finite.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
            student_t95(n - 1) * (var / n as f64).sqrt()
        } else {
            0.0
        };
        Some(Self {
            mean,
            min,
            max,
            ci95_low: mean - half,
            ci95_high: mean + half,
            n,
            missing: values.len() - n,
        })
    }

    /// `mean (min-max)` with `decimals` decimals, for the human tables.
    pub fn show(&self, decimals: usize) -> String {
        if self.n == 1 {
            return format!("{:.*}", decimals, self.mean);
        }
        format!(
            "{:.*} ({:.*}-{:.*})",
            decimals, self.mean, decimals, self.min, decimals, self.max
        )
    }
}

/// The two-sided 95 % quantile of Student's t with `dof` degrees of freedom.
fn student_t95(dof: usize) -> f64 {
    const TABLE: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    match dof {
        0 => f64::NAN,
        d if d <= TABLE.len() => TABLE[d - 1],
        _ => 1.96,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_runs_five_held_out_seeds_from_100() {
        assert_eq!(SeedArgs::default().all(), vec![100, 101, 102, 103, 104]);
        assert_eq!(SeedArgs::one(7).mine(), vec![7]);
    }

    #[test]
    fn the_shards_in_order_give_back_every_seed_once() {
        let args = SeedArgs {
            seeds: 22,
            ..SeedArgs::default()
        };
        let all = args.all();
        let mut joined = Vec::new();
        for index in 1..=4 {
            let shard = Shard { index, count: 4 };
            let part = SeedArgs {
                shard: Some(shard),
                ..args.clone()
            }
            .mine();
            assert!((5..=6).contains(&part.len()), "{shard}: {part:?}");
            joined.extend(part);
        }
        assert_eq!(joined, all);
    }

    #[test]
    fn a_shard_reads_as_i_of_n_and_refuses_the_rest() {
        assert_eq!("2/4".parse(), Ok(Shard { index: 2, count: 4 }));
        for bad in ["0/4", "5/4", "1/0", "2", "a/b", "-1/3"] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
    }

    #[test]
    fn the_spread_of_known_values_matches_the_hand_computed_interval() {
        // 1..=5: mean 3, sample sd sqrt(2.5); t(4) = 2.776.
        let s = Spread::of(&[1.0, 2.0, 3.0, 4.0, 5.0, f64::NAN]).unwrap();
        assert_eq!(
            (s.mean, s.min, s.max, s.n, s.missing),
            (3.0, 1.0, 5.0, 5, 1)
        );
        let half = 2.776 * (2.5f64 / 5.0).sqrt();
        assert!((s.ci95_high - 3.0 - half).abs() < 1e-12);
        assert!((3.0 - s.ci95_low - half).abs() < 1e-12);
        assert_eq!(Spread::of(&[f64::NAN]), None);
        let one = Spread::of(&[2.5]).unwrap();
        assert_eq!((one.ci95_low, one.ci95_high), (2.5, 2.5));
    }
}
