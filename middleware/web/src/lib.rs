//! The AutoPlug dashboard's server: the car's decoded signals, live.
//!
//! - [`live`]: the live table the gateway's pipeline publishes into, each signal stamped
//!   with the version that last changed it;
//! - [`history`]: every signal since the session began, in fixed memory (the plots);
//! - [`trace`]: the last frames as they came (the Bus view's trace);
//! - [`server`]: HTTP and WebSocket on a thread of its own (tokio, axum), loopback by
//!   default.
//!
//! # The stream (`GET /api/stream`, WebSocket, JSON text messages)
//!
//! The server sends, in this order:
//! 1. `{"type":"catalog","signals":[{"path":"Vehicle.Speed","name":"VehicleSpeedMsg.VehicleSpeed","unit":"km/h","cycle_ms":10,"labels":[]}, …]}`:
//!    every signal of the CAN catalogue by its COVESA VSS path, with its DBC name, unit,
//!    its message's cycle time and, for an enumeration, the value table as `[raw, label]`
//!    pairs; and every message (`name`, `id`, `dlc`, `cycle_ms`, `senders`);
//! 2. `{"type":"update","version":N,"t":SECONDS,"signals":{PATH: VALUE, …},"bus":{…}}`
//!    with every signal: its value in the unit of the catalogue, `null` while stale (no
//!    valid frame for 3 periods of its message) or never received; `t` is bus time;
//!    `messages` holds each catalogue message's reception by name (`id`, `count`,
//!    `wrong_length`, `invalid`, `period_ms` and `jitter_ms` measured over the last 64
//!    intervals, `last_t` the bus time of the latest frame, the last `data` in hex);
//!    `bus` holds `frames`, `error_frames`, `unknown_frames`, `diagnostic_frames`,
//!    `fd_frames` (CAN FD, which a classic bus leaves aside) and `load_percent` (the last
//!    second's bits on the wire, stuff bits included);
//! 3. then, at most every 50 ms (20 Hz) and only when something changed, an `update` with
//!    only the signals that changed since the last one sent to this client (`messages` and
//!    `bus` only with what changed). A client that reads slowly gets fewer updates with the latest values,
//!    never a backlog.
//!
//!    When ECUs of the virtual car run under GDB servers (`--gdb`), an update carries
//!    `debugger`: `{"ecus":[{"ecu":"cruise","address":"127.0.0.1:3333","attached":true,
//!    "halted":true,"client":"127.0.0.1:50210"}]}`, sent when it changes. While an ECU is
//!    halted the whole car stands still: no other update comes until it runs again.
//!
//! 4. `{"type":"world",…}` messages when the bus is the virtual car's: the simulator's own
//!    view of the car on its road, a channel apart from the signals (see [`world`]).
//!
//! A client may send `{"type":"ping"}` (answered `{"type":"pong"}`); anything else is
//! answered `{"type":"error","error":"…"}` and the stream goes on. `GET /api/catalog` and
//! `GET /api/state` give the first two messages over plain HTTP.
#![deny(missing_docs)]

pub mod api;
pub mod assets;
pub mod connections;
pub mod control;
pub mod fleet;
pub mod history;
pub mod live;
pub mod server;
pub mod trace;
pub mod world;

pub use control::{Action, Answer, Button, Command, Commands, Control, HeldControls, ReplayAction};
pub use fleet::FleetData;
pub use live::{LiveTable, Publisher};
pub use server::{WebConfig, WebServer};
pub use world::WorldChannel;
