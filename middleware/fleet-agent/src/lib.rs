//! The car's side of the AutoPlug fleet (the manufacturer's side is `autoplug-fleet`):
//!
//! - [`vehicle`]: the campaign agent, sans-IO: an offer checked against what the car
//!   runs, the driver's consent, the update when the car is parked, and the reports;
//! - [`link`]: the gateway's link that runs it, over MQTT (`autoplug_fleet::mqtt`) and the
//!   car's tester, with the outbox that keeps each report until its receipt.
//!
//! A crate apart so that the fleet service links neither the gateway nor the tester.

pub mod link;
pub mod vehicle;
