//! The `autoplug` command: argument parsing and the output of each command, over the
//! library crates that do the work (`autoplug-tester`, `autoplug-transport`,
//! `autoplug-image-tool`, `autoplug-live`, `autoplug-dashboard`, `autoplug-fleet`,
//! `autoplug-fleet-sim`).
//!
//! | module | what |
//! |---|---|
//! | [`cli`] | the `autoplug` command's arguments and its commands |
//! | [`fleet_cli`] | `autoplug fleet`: the fleet service, campaigns, queries, the simulated fleet |
//! | `cmd` | the commands, one module per subcommand (`cmd::fleet::…` for the fleet's) |
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod cli;
mod cmd;
pub mod fleet_cli;
