//! The AutoPlug middleware on the host: signing and inspecting firmware images, reading
//! ECU identification and flashing ECUs over CAN with UDS (ISO 14229) on ISO-TP
//! (ISO 15765-2), the tester counterpart of `autoplug-uds`.
//!
//! | module | what |
//! |---|---|
//! | [`tester`] | the sans-IO UDS client: request/response with "response pending", functional requests, TesterPresent; the flash job and the identification job |
//! | [`transport`] | real-time transports behind one trait: socketcand over TCP, Linux SocketCAN; `--via` URLs |
//! | [`driver`] | runs a job over a transport with the wall clock |
//! | [`image_tool`] | key files, building an image from a raw binary or an ELF file, inspecting one |
//! | [`names`] | NRC and service names (ISO 14229-1), ECU names of the command line |
//! | [`live`] | live frame sources for the gateway: the in-process virtual car, socketcand, SocketCAN; the `--bus` URL |
//! | [`gateway`] | the gateway's commands: `gateway` on a live bus, `replay` and `diagnose` on a log, `trips`, `log export` |
//! | [`bus_tester`] | the gateway as a tester on a live bus (`--transmit`): identification into the inventory, trouble codes every minute |
//! | [`fleet_link`] | the gateway's link to the fleet: inventory and trips out, campaigns in (the agent against MQTT and the tester) |
//! | [`fleet_sim`] | `autoplug fleet simulate`: a planned fleet of virtual cars, each with its gateway and MQTT session, driven headless |
//! | [`watch`] | what the gateway does with every frame: diagnostics, trips into the store, the status line |
//! | [`cli`] | the `autoplug` command |
//!
//! Everything that talks to ECUs is sans-IO: it takes frames and the current time and
//! gives frames, so the same code runs against in-process ECUs on a simulated bus (the
//! tests of this crate, the virtual car) and against a real bus.
//!
//! ```
//! use autoplug_can::Node;
//! use autoplug_middleware::tester::{FlashConfig, FlashJob, Job};
//! use autoplug_middleware::DEV_SECURITY_SECRET;
//! use autoplug_ecu::Instant;
//!
//! let image = vec![0u8; 1024]; // a signed image file in practice
//! let mut job = FlashJob::new(FlashConfig::new(Node::Cruise, image, DEV_SECURITY_SECRET)).unwrap();
//! job.poll(Instant::ZERO);
//! // The sequence starts with a TesterPresent and the functional extended session.
//! let first = job.poll_transmit(Instant::ZERO).unwrap();
//! assert_eq!((first.id(), &first.data()[..3]), (0x7DF, &[0x02, 0x3E, 0x80][..]));
//! job.confirm_transmit(Instant::ZERO);
//! let second = job.poll_transmit(Instant::ZERO).unwrap();
//! assert_eq!((second.id(), &second.data()[..3]), (0x7DF, &[0x02, 0x10, 0x03][..]));
//! ```
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod bus_tester;
pub mod cli;
pub mod dashboard;
pub mod demo;
pub mod driver;
pub mod driving;
pub mod fleet_cli;
pub mod fleet_link;
pub mod fleet_page;
pub mod fleet_sim;
pub mod gateway;
pub mod image_tool;
pub mod live;
pub mod names;
pub mod on_car;
pub mod replay;
pub mod session;
pub mod tester;
pub mod transport;
pub mod watch;

/// The SecurityAccess secret of the AutoPlug ECUs in development: the key for a seed is
/// `autoplug_uds::security::key_for(secret, node, seed)`, and the ECU side
/// (`DiagNode::new(node, secret, now)`) is built with this same value, so a development
/// tester unlocks every development ECU.
///
/// It is public, so it protects nothing: a production bench must replace it, on the
/// ECUs and here (`autoplug flash --secret-file FILE`), with a secret of its own.
pub use autoplug_uds::DEV_SECURITY_SECRET;
