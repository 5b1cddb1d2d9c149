//! How a run ended, and the exit status of `agp up` that says so.

/// The exit statuses of `agp up` (its `--help` lists them).
pub(crate) mod exit {
    /// The run ended as asked (its `ends_run` process finished, or `agp down`), and its
    /// task, if it had one, succeeded.
    pub(crate) const OK: u8 = 0;
    /// The run ended in error: a process failed past its restart policy or could not be
    /// started, every process exited with none marked `ends_run`, the verdict could not be
    /// judged or written, or files of the instance remain; or nothing could start (the
    /// instance is held, its leftovers cannot be removed).
    pub(crate) const ERROR: u8 = 1;
    /// The launch file or the environment is invalid: nothing was started.
    pub(crate) const INVALID: u8 = 2;
    /// The run ended by itself and the judge says the task failed (`NOT placed`, the
    /// path's end not reached).
    pub(crate) const TASK_FAILED: u8 = 3;
    /// Stopped by signal N (SIGINT, SIGTERM, ...): 128 + N, as a shell reports it.
    pub(crate) const SIGNAL_BASE: u8 = 128;
}

/// Why a run ended.
#[derive(Debug)]
pub(crate) enum RunEnd {
    /// A process marked `ends_run` exited with status 0.
    Finished { process: String },
    /// The supervisor got a stop signal.
    Signal(i32),
    /// A process failed past its restart policy, or could not be started.
    Failed { process: String, why: String },
    /// Nothing runs any more and nothing ended the run.
    AllExited,
    /// `agp down` asked for it.
    Down,
}

impl RunEnd {
    /// The exit status of `agp up` for a run that ended so: `errors` when something went
    /// wrong after the run (the verdict or the cleaning), `task_failed` when the judge said
    /// the task failed. A stop signal says how the run ended whatever the rest; an error
    /// outranks a verdict; a run stopped by `agp down` has no verdict to answer for.
    pub(crate) fn exit_code(&self, errors: bool, task_failed: bool) -> u8 {
        match self {
            Self::Signal(s) => {
                u8::try_from(i32::from(exit::SIGNAL_BASE) + s).unwrap_or(exit::ERROR)
            }
            Self::Failed { .. } | Self::AllExited => exit::ERROR,
            Self::Finished { .. } | Self::Down if errors => exit::ERROR,
            Self::Finished { .. } if task_failed => exit::TASK_FAILED,
            Self::Finished { .. } | Self::Down => exit::OK,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_finished_run_whose_task_failed_exits_non_zero_and_an_error_outranks_it() {
        let finished = RunEnd::Finished {
            process: "planner".to_owned(),
        };
        assert_eq!(finished.exit_code(false, false), exit::OK);
        assert_eq!(finished.exit_code(false, true), exit::TASK_FAILED);
        assert_eq!(finished.exit_code(true, true), exit::ERROR);
        assert_eq!(RunEnd::Down.exit_code(true, false), exit::ERROR);
        assert_eq!(RunEnd::Down.exit_code(false, true), exit::OK);
        let failed = RunEnd::Failed {
            process: "physics".to_owned(),
            why: "crashed".to_owned(),
        };
        assert_eq!(failed.exit_code(false, false), exit::ERROR);
        assert_eq!(RunEnd::AllExited.exit_code(false, false), exit::ERROR);
        assert_eq!(RunEnd::Signal(libc::SIGTERM).exit_code(true, true), 143);
        assert_eq!(RunEnd::Signal(libc::SIGPIPE).exit_code(false, false), 141);
        let codes = [exit::OK, exit::ERROR, exit::INVALID, exit::TASK_FAILED];
        assert!(codes.iter().all(|c| *c < exit::SIGNAL_BASE));
        let mut distinct = codes.to_vec();
        distinct.dedup();
        assert_eq!(distinct.len(), codes.len(), "distinct exit statuses");
    }
}
