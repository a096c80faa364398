//! `autoplug fleet …`: one module per subcommand, over the fleet's store and broker.
//!
//! | module | command |
//! |---|---|
//! | [`serve`] | `fleet serve` |
//! | [`simulate`] | `fleet simulate` |
//! | [`recall`] | `fleet recall` |
//! | [`evidence`] | `fleet evidence` |
//! | [`vehicle`] | `fleet vehicle` |
//! | [`campaign`] | `fleet campaign create`, `status`, `pause`, `resume` |
//! | [`broker`] | `fleet broker init`, `add` |

use autoplug_fleet::FleetStore;

use crate::fleet_cli::DbArgs;

pub(crate) mod broker;
pub(crate) mod campaign;
pub(crate) mod evidence;
pub(crate) mod recall;
pub(crate) mod serve;
pub(crate) mod simulate;
pub(crate) mod vehicle;

/// The fleet database `--db` names.
fn open(db: &DbArgs) -> Result<FleetStore, String> {
    FleetStore::open(&db.db).map_err(|e| e.to_string())
}

/// What `--json` prints.
fn json(value: &impl serde::Serialize) -> Result<String, String> {
    serde_json::to_string_pretty(value).map_err(|e| e.to_string())
}

/// The fleet commands' error for output that cannot be written.
fn io(e: std::io::Error) -> String {
    format!("cannot write the output: {e}")
}

pub use autoplug_fleet::mqtt::runtime as mqtt_runtime;
