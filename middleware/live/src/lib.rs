//! The AutoPlug gateway at work on a bus or a log: where frames come from, what the gateway
//! does with each, and the report's demonstrations.
//!
//! | module | what |
//! |---|---|
//! | [`sources`] | live frame sources: the in-process virtual car, socketcand, SocketCAN; the `--bus` URL |
//! | [`watch`] | what the gateway does with every frame: diagnostics, trips into the store, the status line |
//! | [`gateway`] | the gateway's runs: on a live bus, `replay` and `diagnose` on a log, the tables they print |
//! | [`replay`] | a recording replayed at a chosen speed, paused and stepped (the dashboard's replay desk) |
//! | [`driving`] | the driver's desk: the controls a person at the dashboard holds, applied to the virtual car |
//! | [`on_car`] | the in-process virtual car as a tester's bus, on the car's simulated time |
//! | [`demo`] | the report's demonstrations: flash a faulty ECU, see the diagnosis, flash the fix |
//!
//! Everything that talks to ECUs is sans-IO (the `autoplug-tester` jobs): the same code runs
//! against in-process ECUs on a simulated bus and against a real bus.
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod demo;
pub mod driving;
pub mod gateway;
pub mod on_car;
pub mod replay;
pub mod sources;
pub mod watch;
