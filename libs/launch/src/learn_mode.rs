//! `learn = "first" | "online"`: where the object's affordance gradient comes from, and the arguments it gives the estimator and the planner.
//!
//! - `first` (the default): as the processes' own arguments say: a learning phase, or an AG
//!   file (`--reuse`, `--load`, `--learn-if-missing`).
//! - `online`: an object never pushed before. No learning phase and no AG file: the task's
//!   first circling gives the estimator the object's border, from which it builds the
//!   contact prior (a push through the centroid translates the object along the push, an
//!   offset one turns it by its lever arm about the border's centroid), and it learns on
//!   from every push of the task while the planner places the object on each set it
//!   publishes. The plan gives every `agp-estimator` `--learn-online --from-prior` (in
//!   place of `--reuse`) and every `agp-planner` `--from-prior` (in place of
//!   `--learn-if-missing`); an estimator told `--load` or `--perceive-only`, or a file
//!   with no `agp-estimator`, is refused.

use crate::ProcessConfig;

/// Where the object's affordance gradient comes from (`learn` in a launch file).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LearnMode {
    /// As the processes' arguments say: learned first, or loaded (the default).
    #[default]
    First,
    /// Learned online from the task's own pushes, from the contact prior of the first
    /// circling: an object never pushed before.
    Online,
}

impl LearnMode {
    /// The word a launch file uses.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::First => "first",
            Self::Online => "online",
        }
    }

    /// The mode a launch file's `learn` names; `None` for any other word.
    pub fn from_word(word: &str) -> Option<Self> {
        match word {
            "first" => Some(Self::First),
            "online" => Some(Self::Online),
            _ => None,
        }
    }
}

/// Why `learn = "online"` cannot run these processes: the process and the reason.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct LearnConflict {
    pub process: Option<String>,
    pub reason: String,
}

fn exec_is(p: &ProcessConfig, name: &str) -> bool {
    p.exec.file_name().is_some_and(|n| n == name)
}

/// Gives the processes the arguments `mode` asks for (nothing for `first`), or says why it
/// cannot.
pub(crate) fn apply(mode: LearnMode, processes: &mut [ProcessConfig]) -> Vec<LearnConflict> {
    let mut conflicts = Vec::new();
    if mode == LearnMode::First {
        return conflicts;
    }
    let mut estimators = 0;
    for p in processes.iter_mut() {
        if exec_is(p, "agp-estimator") {
            estimators += 1;
            for refused in ["--load", "--perceive-only"] {
                if p.args
                    .iter()
                    .any(|a| a == refused || a.starts_with(&format!("{refused}=")))
                {
                    conflicts.push(LearnConflict {
                        process: Some(p.name.clone()),
                        reason: format!(
                            "`learn = \"online\"` starts from no AG file and learns, but the estimator is told `{refused}`; remove it"
                        ),
                    });
                }
            }
            p.args.retain(|a| a != "--reuse");
            for flag in ["--learn-online", "--from-prior"] {
                if !p.args.iter().any(|a| a == flag) {
                    p.args.push(flag.to_owned());
                }
            }
        } else if exec_is(p, "agp-planner") {
            p.args.retain(|a| a != "--learn-if-missing");
            if !p.args.iter().any(|a| a == "--from-prior") {
                p.args.push("--from-prior".to_owned());
            }
        }
    }
    if estimators == 0 {
        conflicts.push(LearnConflict {
            process: None,
            reason: "`learn = \"online\"` needs an `agp-estimator` process to learn the gradient"
                .to_owned(),
        });
    }
    conflicts
}

#[cfg(test)]
mod tests {
    use super::*;

    fn process(name: &str, exec: &str, args: &[&str]) -> ProcessConfig {
        ProcessConfig {
            name: name.to_owned(),
            exec: std::path::PathBuf::from("/bin").join(exec),
            args: args.iter().map(|a| (*a).to_owned()).collect(),
            env: Default::default(),
            restart: crate::RestartConfig {
                policy: crate::RestartPolicy::Never,
                max_restarts: 0,
                backoff: std::time::Duration::ZERO,
            },
            ends_run: false,
            stop_grace: std::time::Duration::from_secs(1),
            line: 1,
        }
    }

    #[test]
    fn online_learning_gives_the_estimator_and_the_planner_their_flags_in_place_of_the_files() {
        let mut ps = vec![
            process("physics", "agp-physics", &[]),
            process("estimator", "agp-estimator", &["--reuse"]),
            process(
                "planner",
                "agp-planner",
                &["--mode", "place", "--learn-if-missing"],
            ),
        ];
        assert_eq!(apply(LearnMode::Online, &mut ps), vec![]);
        assert!(ps[0].args.is_empty());
        assert_eq!(ps[1].args, ["--learn-online", "--from-prior"]);
        assert_eq!(ps[2].args, ["--mode", "place", "--from-prior"]);
    }

    #[test]
    fn learning_first_changes_no_argument() {
        let mut ps = vec![process("estimator", "agp-estimator", &["--reuse"])];
        assert_eq!(apply(LearnMode::First, &mut ps), vec![]);
        assert_eq!(ps[0].args, ["--reuse"]);
    }

    #[test]
    fn online_learning_refuses_an_estimator_told_to_load_and_a_file_without_one() {
        let mut ps = vec![process("est", "agp-estimator", &["--load", "x.ag"])];
        let c = apply(LearnMode::Online, &mut ps);
        assert_eq!(c.len(), 1);
        assert_eq!(c[0].process.as_deref(), Some("est"));
        assert!(c[0].reason.contains("--load"), "{}", c[0].reason);
        let mut ps = vec![process("physics", "agp-physics", &[])];
        let c = apply(LearnMode::Online, &mut ps);
        assert_eq!(c.len(), 1);
        assert!(c[0].reason.contains("agp-estimator"), "{}", c[0].reason);
    }

    #[test]
    fn the_words_of_the_modes_parse_back() {
        for m in [LearnMode::First, LearnMode::Online] {
            assert_eq!(LearnMode::from_word(m.as_str()), Some(m));
        }
        assert_eq!(LearnMode::from_word("later"), None);
    }
}
