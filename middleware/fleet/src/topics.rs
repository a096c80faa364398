//! The fleet's MQTT topics, named once. A vehicle publishes under its own VIN and reads
//! only its own commands (the broker's ACL enforces both: `broker/acl`); images are
//! retained under their SHA-256, readable by every vehicle.
//!
//! ```text
//! autoplug/v1/vehicles/{VIN}/report/inventory   vehicle → fleet, QoS 1
//! autoplug/v1/vehicles/{VIN}/report/trip        vehicle → fleet, QoS 1
//! autoplug/v1/vehicles/{VIN}/report/campaign    vehicle → fleet, QoS 1
//! autoplug/v1/vehicles/{VIN}/command/campaign   fleet → vehicle, QoS 1 (persistent session)
//! autoplug/v1/vehicles/{VIN}/command/receipt    fleet → vehicle, QoS 1: a report stored (or refused)
//! autoplug/v1/images/{sha256}                   fleet → vehicles, QoS 1, retained
//! ```

use autoplug_vin::Vin;

/// Every topic of the fleet starts with this (a version, so a later protocol can run beside).
pub const PREFIX: &str = "autoplug/v1";

/// The fleet services' subscription to every vehicle's reports: a shared subscription
/// (MQTT 5, and Mosquitto for 3.1.1 clients too), so several stateless services split the
/// reports between them and each report is stored by one.
pub const REPORTS_SHARED: &str = "$share/autoplug-fleet/autoplug/v1/vehicles/+/report/#";

/// The shared subscription of the fleet services in `group` (services of one group split
/// the reports; each group gets all of them).
pub fn reports_shared(group: &str) -> String {
    format!("$share/{group}/{REPORTS}")
}

/// The same without sharing (a broker without shared subscriptions, one service).
pub const REPORTS: &str = "autoplug/v1/vehicles/+/report/#";

/// What a vehicle reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ReportKind {
    /// Its inventory (when it changed).
    Inventory,
    /// A trip that ended, with its verdicts and trouble codes.
    Trip,
    /// How a campaign went on it.
    Campaign,
}

impl ReportKind {
    /// Every kind.
    pub const ALL: [ReportKind; 3] = [
        ReportKind::Inventory,
        ReportKind::Trip,
        ReportKind::Campaign,
    ];

    /// Its topic segment.
    pub fn name(self) -> &'static str {
        match self {
            ReportKind::Inventory => "inventory",
            ReportKind::Trip => "trip",
            ReportKind::Campaign => "campaign",
        }
    }
}

/// Where `vin` publishes a report of `kind`.
pub fn report(vin: &Vin, kind: ReportKind) -> String {
    format!("{PREFIX}/vehicles/{vin}/report/{}", kind.name())
}

/// Where the fleet sends `vin` its campaign instructions.
pub fn command(vin: &Vin) -> String {
    format!("{PREFIX}/vehicles/{vin}/command/campaign")
}

/// Where the fleet tells `vin` that one of its reports is stored (or refused for good):
/// the vehicle keeps each report until then ([`crate::outbox`]).
pub fn receipt(vin: &Vin) -> String {
    format!("{PREFIX}/vehicles/{vin}/command/receipt")
}

/// Where an image is retained, by its SHA-256 (lower-case hex).
pub fn image(sha256_hex: &str) -> String {
    format!("{PREFIX}/images/{sha256_hex}")
}

/// The vehicle and the kind of a report topic; an error naming what is wrong otherwise.
pub fn parse_report(topic: &str) -> Result<(Vin, ReportKind), String> {
    let bad = || format!("topic \"{}\" is not a vehicle report", cut(topic));
    let rest = topic
        .strip_prefix(PREFIX)
        .and_then(|t| t.strip_prefix("/vehicles/"))
        .ok_or_else(bad)?;
    let mut parts = rest.split('/');
    let (Some(vin), Some("report"), Some(kind), None) =
        (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Err(bad());
    };
    let vin = Vin::parse(vin).map_err(|e| format!("topic \"{}\": {e}", cut(topic)))?;
    let kind = ReportKind::ALL
        .into_iter()
        .find(|k| k.name() == kind)
        .ok_or_else(|| format!("topic \"{}\": no report kind \"{}\"", cut(topic), cut(kind)))?;
    Ok((vin, kind))
}

fn cut(text: &str) -> String {
    text.chars().take(120).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_topics_round_trip_and_bad_ones_are_named() {
        let vin = Vin::parse("JA3AP47H0YF000042").unwrap();
        for kind in ReportKind::ALL {
            assert_eq!(parse_report(&report(&vin, kind)), Ok((vin, kind)));
        }
        assert_eq!(
            command(&vin),
            "autoplug/v1/vehicles/JA3AP47H0YF000042/command/campaign"
        );
        assert!(
            parse_report("autoplug/v1/vehicles/JA3AP47H0YF000042/report/x")
                .unwrap_err()
                .contains("no report kind \"x\"")
        );
        assert!(
            parse_report("autoplug/v1/vehicles/JA3AP47H1YF000042/report/trip")
                .unwrap_err()
                .contains("check digit")
        );
        assert!(
            parse_report("autoplug/v1/vehicles/JA3AP47H0YF000042/report/trip/more")
                .unwrap_err()
                .contains("not a vehicle report")
        );
        assert!(parse_report("other/JA3AP47H0YF000042").is_err());
    }
}
