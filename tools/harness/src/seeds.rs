//! Which seeds a benchmark runs, which of them this shard runs, the spread of a figure
//! over them, and the parts of a run gathered for a merge ([`gather`]).
//!
//! Seeds 1 to 10 are the tuning seeds: every constant of the planners and the learner was
//! chosen on them. Seeds 11-30 and 100-109 informed design choices later (README, Seeds):
//! they are no longer held out. Reported figures use seeds from [`FIRST_REPORTED_SEED`]
//! on, which no constant and no choice saw. `--seed S` runs one seed, the old way (tests
//! and quick looks).

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use anyhow::Context;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value, json};

/// The first seed of the reported figures: nothing was tuned or chosen on it or after it
/// (100 until issue 32: seeds 100-109 then had informed design choices).
pub const FIRST_REPORTED_SEED: u64 = 200;

/// The seeds of every benchmark: `--seeds N` from `--first-seed`, or `--seed S` alone,
/// and `--shard I/N` to run a share of them.
#[derive(Debug, Clone, clap::Args)]
pub struct SeedArgs {
    /// How many seeds to run, from `--first-seed` on. Figures are reported with their
    /// mean and spread over the seeds, and per seed in the JSON (`seeds`, `per_seed`).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: u64,
    /// The first seed. Seeds 1-10 are the ones the constants were tuned on; the default
    /// starts the seeds the README reports, which no constant or choice saw.
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
    /// ` (shard I/N of seeds ...)` when this run is a shard, else nothing: what a run's
    /// first line says after its own seeds.
    pub fn shard_note(&self) -> String {
        self.shard
            .map(|s| format!(" (shard {s} of seeds {})", seed_list(&self.all())))
            .unwrap_or_default()
    }

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

/// A part a merge refuses, in one line: which part (its index among the parts given; none
/// when the fault is of the parts together) and what is wrong. `agp bench merge` puts the
/// part's file name in its place.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}{what}", part.map(|p| format!("part {}: ", p + 1)).unwrap_or_default())]
pub struct MergePartError {
    /// Index of the faulty part in the parts given.
    pub part: Option<usize>,
    /// What is wrong, lowercase, no trailing period.
    pub what: String,
}

impl MergePartError {
    fn of(part: usize, what: String) -> Self {
        Self {
            part: Some(part),
            what,
        }
    }
}

/// The parts of one run, checked: every seed of the run, and each seed's document in seed
/// order with the part it came from.
#[derive(Debug, Clone)]
pub struct SeedParts {
    /// Every seed of the run, ascending.
    pub seeds: Vec<u64>,
    /// (seed, index of its part, its one-seed document), ascending by seed.
    pub per_seed: Vec<(u64, usize, Value)>,
}

impl SeedParts {
    /// The one-seed documents, in seed order.
    pub fn docs(&self) -> impl Iterator<Item = &Value> {
        self.per_seed.iter().map(|(_, _, d)| d)
    }
}

/// The seed list a document names: `seeds`, else its one `seed`.
fn declared_seeds(doc: &Value) -> Option<Vec<u64>> {
    match doc.get("seeds") {
        Some(list) => list.as_array()?.iter().map(Value::as_u64).collect(),
        None => doc.get("seed").and_then(Value::as_u64).map(|s| vec![s]),
    }
}

/// Gathers the parts of one run of `benchmark` for a merge: documents of disjoint seed
/// sets, each a whole run, a shard's partial run (`shard`, `seeds` of the whole run,
/// `per_seed` its own) or a one-seed document without `per_seed`. Refuses a part of
/// another benchmark, a part whose `signature` (what must be alike in every seed of one
/// run: scenario, planners, episodes..., computed on each one-seed document) differs from
/// the first's, a seed twice, and, when any part is a shard, parts of different runs
/// (another seed list) or a seed of the run that no part holds.
pub fn gather(
    parts: &[Value],
    benchmark: &str,
    signature: impl Fn(&Value) -> Value,
) -> Result<SeedParts, MergePartError> {
    if parts.is_empty() {
        return Err(MergePartError {
            part: None,
            what: "no part to merge".into(),
        });
    }
    let mut per_seed: Vec<(u64, usize, Value)> = Vec::new();
    let mut run_seeds: Option<(usize, Vec<u64>)> = None;
    let mut any_shard = false;
    let mut first_signature: Option<Value> = None;
    for (i, part) in parts.iter().enumerate() {
        let kind = part.get("benchmark").and_then(Value::as_str);
        if kind != Some(benchmark) {
            return Err(MergePartError::of(
                i,
                match kind {
                    Some(k) => format!("a `{k}` result, not `{benchmark}`"),
                    None => format!(
                        "not a benchmark result (no `benchmark` field; `{benchmark}` expected)"
                    ),
                },
            ));
        }
        let declared = declared_seeds(part)
            .ok_or_else(|| MergePartError::of(i, "no `seeds` list or `seed`".into()))?;
        let shard = match part.get("shard") {
            None | Some(Value::Null) => None,
            Some(v) => Some(
                v.as_str()
                    .and_then(|s| s.parse::<Shard>().ok())
                    .ok_or_else(|| MergePartError::of(i, format!("`shard` {v} is not I/N")))?,
            ),
        };
        any_shard |= shard.is_some();
        let own: Vec<Value> = match part.get("per_seed") {
            Some(list) => list
                .as_array()
                .ok_or_else(|| MergePartError::of(i, "`per_seed` is not a list".into()))?
                .clone(),
            None => vec![part.clone()],
        };
        if own.is_empty() {
            return Err(MergePartError::of(i, "`per_seed` is empty".into()));
        }
        match &run_seeds {
            Some((_, seeds)) if shard.is_some() && *seeds != declared => {
                return Err(MergePartError::of(
                    i,
                    format!(
                        "a part of another run: seeds {}, not {} as the other parts",
                        seed_list(&declared),
                        seed_list(seeds)
                    ),
                ));
            }
            None if shard.is_some() => run_seeds = Some((i, declared.clone())),
            _ => {}
        }
        for doc in own {
            let seed = doc.get("seed").and_then(Value::as_u64).ok_or_else(|| {
                MergePartError::of(i, "an entry of `per_seed` has no `seed`".into())
            })?;
            if !declared.contains(&seed) {
                return Err(MergePartError::of(
                    i,
                    format!(
                        "seed {seed} is not among its run's seeds {}",
                        seed_list(&declared)
                    ),
                ));
            }
            let sig = signature(&doc);
            match &first_signature {
                None => first_signature = Some(sig),
                Some(first) if *first != sig => {
                    return Err(MergePartError::of(
                        i,
                        format!(
                            "seed {seed} is of another run than the first part's seeds: {}",
                            differences(&sig, first)
                        ),
                    ));
                }
                Some(_) => {}
            }
            if let Some((_, other, _)) = per_seed.iter().find(|(s, _, _)| *s == seed) {
                let other = *other;
                return Err(MergePartError::of(
                    i,
                    if other == i {
                        format!("seed {seed} is there twice")
                    } else {
                        format!("seed {seed} is also in part {}", other + 1)
                    },
                ));
            }
            per_seed.push((seed, i, doc));
        }
    }
    per_seed.sort_by_key(|(s, _, _)| *s);
    let mut seeds: Vec<u64> = per_seed.iter().map(|(s, _, _)| *s).collect();
    if any_shard {
        let (_, mut declared) = run_seeds.unwrap_or_default();
        declared.sort_unstable();
        // A one-seed part beside shards must be of the same run.
        if let Some(&(s, i, _)) = per_seed.iter().find(|(s, _, _)| !declared.contains(s)) {
            return Err(MergePartError::of(
                i,
                format!(
                    "seed {s} is not among the run's seeds {}",
                    seed_list(&declared)
                ),
            ));
        }
        if let Some(missing) = declared.iter().find(|s| !seeds.contains(s)) {
            return Err(MergePartError {
                part: None,
                what: format!(
                    "seed {missing} of the run (seeds {}) is in no part: a shard is missing",
                    seed_list(&declared)
                ),
            });
        }
        seeds = declared;
    }
    Ok(SeedParts { seeds, per_seed })
}

/// What differs between two signatures: "`scenario` is \"lshape\", not \"triangle\"", for
/// each differing key of two objects.
fn differences(sig: &Value, first: &Value) -> String {
    match (sig.as_object(), first.as_object()) {
        (Some(a), Some(b)) => a
            .iter()
            .filter(|(k, v)| b.get(*k) != Some(*v))
            .map(|(k, v)| {
                format!(
                    "`{k}` is {v}, not {}",
                    b.get(k)
                        .map_or_else(|| "absent".to_owned(), Value::to_string)
                )
            })
            .chain(
                b.keys()
                    .filter(|k| !a.contains_key(*k))
                    .map(|k| format!("`{k}` is absent")),
            )
            .collect::<Vec<_>>()
            .join("; "),
        _ => format!("{sig}, not {first}"),
    }
}

/// The mean of the finite `values`; NaN when none is.
pub fn mean_of(values: &[f64]) -> f64 {
    Spread::of(values).map_or(f64::NAN, |s| s.mean)
}

/// What a benchmark document says of its seeds: its one-seed documents (`per_seed`), every
/// seed of the run (`seeds`, a shard's whole run included) and the seeds this document
/// holds itself (each `per_seed` entry's `seed`).
pub struct SeedLists<'a> {
    pub docs: Vec<&'a Value>,
    pub all: Vec<u64>,
    pub own: Vec<u64>,
    /// `I/N` when the document is a shard's.
    pub shard: Option<&'a str>,
}

impl<'a> SeedLists<'a> {
    pub fn of(doc: &'a Value) -> Self {
        let docs: Vec<&Value> = doc["per_seed"]
            .as_array()
            .map(|a| a.iter().collect())
            .unwrap_or_default();
        let all = doc["seeds"]
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_u64).collect())
            .unwrap_or_default();
        let own = docs.iter().filter_map(|d| d["seed"].as_u64()).collect();
        Self {
            docs,
            all,
            own,
            shard: doc["shard"].as_str(),
        }
    }

    /// `seed 100`, `seeds 100-104`, and ` (shard I/N of seeds ...)` for a shard's document:
    /// what a printed table says it covers.
    pub fn describe(&self) -> String {
        format!(
            "{} {}{}",
            if self.own.len() == 1 { "seed" } else { "seeds" },
            seed_list(&self.own),
            self.shard
                .map(|s| format!(" (shard {s} of seeds {})", seed_list(&self.all)))
                .unwrap_or_default()
        )
    }
}

/// The parts of a run (or of its shard) over `all_seeds`, from the one-seed documents of
/// the seeds it ran, checked as a merge checks its parts: what a benchmark assembles its
/// document from.
pub fn run_parts(
    docs: &[Value],
    benchmark: &str,
    signature: impl Fn(&Value) -> Value,
    all_seeds: Vec<u64>,
) -> Result<SeedParts, MergePartError> {
    Ok(SeedParts {
        seeds: all_seeds,
        ..gather(docs, benchmark, signature)?
    })
}

/// `100-104`, or `100, 102` when not a run of consecutive seeds.
pub fn seed_list(seeds: &[u64]) -> String {
    let consecutive = seeds.windows(2).all(|w| w[1] == w[0].wrapping_add(1));
    match (seeds.first(), seeds.last()) {
        (Some(a), Some(b)) if seeds.len() > 2 && consecutive => format!("{a}-{b}"),
        _ => seeds
            .iter()
            .map(u64::to_string)
            .collect::<Vec<_>>()
            .join(", "),
    }
}

/// The number at `path` in `doc`; NaN when absent or null (a figure a seed had none of).
pub fn number_at(doc: &Value, path: &[&str]) -> f64 {
    path.iter()
        .try_fold(doc, |v, k| v.get(*k))
        .and_then(Value::as_f64)
        .unwrap_or(f64::NAN)
}

/// The [`Spread`] of a figure over the seeds' documents, as JSON (null when no seed has it).
pub fn spread_at<'a>(docs: impl IntoIterator<Item = &'a Value>, path: &[&str]) -> Value {
    let values: Vec<f64> = docs.into_iter().map(|d| number_at(d, path)).collect();
    Spread::of(&values).map_or(Value::Null, |s| json!(s))
}

/// A number, or JSON null when it is not finite (a median of no values).
pub fn finite_or_null(v: f64) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

/// Adds what every merged document carries: `seeds` (every seed of the run), `per_seed` (the
/// one-seed documents in seed order), and `shard` when the document is a shard's part.
pub fn add_seed_fields(doc: &mut Map<String, Value>, parts: &SeedParts, shard: Option<Shard>) {
    doc.insert("seeds".into(), json!(parts.seeds));
    doc.insert(
        "per_seed".into(),
        Value::Array(parts.docs().cloned().collect()),
    );
    if let Some(shard) = shard {
        doc.insert("shard".into(), json!(shard.to_string()));
    }
}

/// Closes a document a benchmark assembled from its seeds' documents: `seeds`,
/// `per_seed`, the shard, and `wall_time_s`, the longest seed's (the seeds run side by
/// side).
pub fn finish_seed_doc(
    mut doc: Map<String, Value>,
    parts: &SeedParts,
    shard: Option<Shard>,
) -> Value {
    add_seed_fields(&mut doc, parts, shard);
    let wall = parts
        .docs()
        .map(|d| number_at(d, &["wall_time_s"]))
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    doc.insert("wall_time_s".into(), json!(wall));
    Value::Object(doc)
}

/// A benchmark's `merge`: the parts gathered and checked ([`gather`]), assembled by the
/// benchmark's own `assemble` (the one its runs use), `wall_time_s` the longest part's.
pub fn merge_parts(
    parts: &[Value],
    benchmark: &str,
    signature: impl Fn(&Value) -> Value,
    assemble: impl Fn(&SeedParts, Option<Shard>) -> Value,
) -> Result<Value, MergePartError> {
    let gathered = gather(parts, benchmark, signature)?;
    let mut doc = assemble(&gathered, None);
    doc["wall_time_s"] = json!(longest_wall_time(parts));
    Ok(doc)
}

/// The wall time of merged parts: the longest part's (shards run side by side), s.
pub fn longest_wall_time(parts: &[Value]) -> f64 {
    parts
        .iter()
        .map(|p| number_at(p, &["wall_time_s"]))
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
}

/// Writes `value` as pretty JSON (and a final newline) to `path`, naming the file when it
/// cannot.
pub(crate) fn write_json(path: &Path, value: &impl Serialize) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(value).context("cannot serialise the result")?;
    std::fs::write(path, text + "\n").with_context(|| format!("cannot write `{}`", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_runs_five_held_out_seeds_from_200() {
        assert_eq!(SeedArgs::default().all(), vec![200, 201, 202, 203, 204]);
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

    fn doc(seeds: &[u64], mine: &[u64], shard: Option<&str>) -> Value {
        let mut d = json!({
            "benchmark": "place",
            "seed": mine[0],
            "seeds": seeds,
            "per_seed": mine.iter().map(|s| json!({"benchmark": "place", "seed": s, "scenario": "triangle"})).collect::<Vec<_>>(),
        });
        if let Some(shard) = shard {
            d["shard"] = json!(shard);
        }
        d
    }

    fn scenario(d: &Value) -> Value {
        json!({ "scenario": d["scenario"] })
    }

    #[test]
    fn gathered_shards_give_every_seed_once_in_order() {
        let all = [100, 101, 102];
        let parts = [
            doc(&all, &[102], Some("2/2")),
            doc(&all, &[100, 101], Some("1/2")),
        ];
        let g = gather(&parts, "place", scenario).unwrap();
        assert_eq!(g.seeds, all);
        let order: Vec<(u64, usize)> = g.per_seed.iter().map(|(s, p, _)| (*s, *p)).collect();
        assert_eq!(order, [(100, 1), (101, 1), (102, 0)]);
    }

    #[test]
    fn a_seed_twice_a_missing_shard_and_another_run_are_refused_naming_the_part() {
        let all = [100, 101, 102];
        let twice = gather(
            &[
                doc(&all, &[100, 101], Some("1/2")),
                doc(&all, &[101, 102], Some("2/2")),
            ],
            "place",
            scenario,
        )
        .unwrap_err();
        assert_eq!(twice.part, Some(1));
        assert!(twice.what.contains("seed 101 is also in part 1"), "{twice}");
        let missing =
            gather(&[doc(&all, &[100, 101], Some("1/2"))], "place", scenario).unwrap_err();
        assert_eq!(missing.part, None);
        assert!(missing.what.contains("seed 102"), "{missing}");
        let other = gather(
            &[
                doc(&all, &[100, 101], Some("1/2")),
                doc(&[100, 101, 102, 103], &[102, 103], Some("2/2")),
            ],
            "place",
            scenario,
        )
        .unwrap_err();
        assert_eq!(other.part, Some(1));
        assert!(other.what.contains("another run"), "{other}");
        let mut lshape = doc(&[103], &[103], None);
        lshape["per_seed"][0]["scenario"] = json!("lshape");
        let unlike = gather(&[doc(&[100], &[100], None), lshape], "place", scenario).unwrap_err();
        assert_eq!(unlike.part, Some(1));
        assert!(
            unlike
                .what
                .contains(r#"`scenario` is "lshape", not "triangle""#),
            "{unlike}"
        );
    }

    #[test]
    fn one_seed_documents_without_per_seed_merge_as_their_union() {
        let one = |s: u64| json!({"benchmark": "place", "seed": s, "scenario": "triangle"});
        let g = gather(&[one(7), one(3)], "place", scenario).unwrap();
        assert_eq!(g.seeds, [3, 7]);
        assert_eq!(seed_list(&[100, 101, 102]), "100-102");
        assert_eq!(seed_list(&[3, 7]), "3, 7");
    }

    #[test]
    fn the_first_seed_help_names_the_reported_seed_as_its_default_and_no_other_number() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            seeds: SeedArgs,
        }
        let help = <Cli as clap::CommandFactory>::command()
            .render_long_help()
            .to_string();
        let first_seed = help
            .split("--first-seed <FIRST_SEED>")
            .nth(1)
            .and_then(|rest| rest.split("--seed <SEED>").next())
            .expect("the help has a --first-seed entry followed by --seed");
        assert!(
            first_seed.contains(&format!("[default: {FIRST_REPORTED_SEED}]")),
            "{first_seed}"
        );
        assert!(!first_seed.contains("100"), "{first_seed}");
    }
}
