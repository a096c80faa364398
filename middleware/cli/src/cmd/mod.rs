//! The commands, one module per subcommand: each takes its parsed arguments and writes
//! what it has to say to `out`. [`crate::cli::run`] and [`crate::fleet_cli::run`] only
//! choose the module.
//!
//! | module | command |
//! |---|---|
//! | [`keygen`] | `keygen` |
//! | [`image`] | `image build`, `image inspect` |
//! | [`ecu`] | `ids`, `dtcs`, `flash` and the image's checks before a flash |
//! | [`demo`] | `demo` |
//! | [`replay`] | `replay` |
//! | [`diagnose`] | `diagnose` |
//! | [`gateway`] | `gateway` (the run itself: `autoplug-gateway-app`, the dashboard's too) |
//! | [`dashboard`] | `dashboard` |
//! | [`trips`] | `trips list`, `trips show` |
//! | [`log`] | `log export` |
//! | [`fleet`] | `fleet …` |

use std::path::Path;

use autoplug_gateway::Strictness;

pub(crate) mod dashboard;
pub(crate) mod demo;
pub(crate) mod diagnose;
pub(crate) mod ecu;
pub(crate) mod fleet;
pub(crate) mod gateway;
pub(crate) mod image;
pub(crate) mod keygen;
pub(crate) mod log;
pub(crate) mod replay;
pub(crate) mod trips;

/// `--lenient`: skip malformed lines and count them, or stop at the first.
fn strictness(lenient: bool) -> Strictness {
    if lenient {
        Strictness::Lenient
    } else {
        Strictness::Strict
    }
}

/// Why a log run's report covers only part of the log, if it does.
fn incomplete(log: &Path, run: &autoplug_live::gateway::LogRun) -> Option<String> {
    run.pipeline.incomplete().map(|e| {
        format!(
            "{}: {e} (the report covers the {} frames before it)",
            log.display(),
            run.pipeline.state().counters().frames
        )
    })
}
