//! AutoPlug's dashboard behind the web server (`autoplug dashboard`, `autoplug gateway
//! --web`): the session that owns the car, its gateway and tester, the driver's desk and the
//! replay desk, and answers the web dashboard's requests; the data folder and its firmware
//! library; the fleet view read from the fleet's database.
//!
//! | module | what |
//! |---|---|
//! | [`dashboard`] | `autoplug dashboard`: the data folder (trips, recordings, images) and what runs on it |
//! | [`debuggers`] | what the page shows of the GDB servers on emulated ECUs, watched beside the stalled session |
//! | [`session`] | the dashboard's session: live state out, the user's actions (flash, clear, drive, replay) in |
//! | [`fleet_page`] | the dashboard's fleet view: the fleet's database, read off the session's thread |
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod dashboard;
pub mod debuggers;
pub mod fleet_page;
pub mod session;
