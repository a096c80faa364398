//! The roads AutoPlug ships (`roads/*.toml`), built into the program so that a scenario
//! can name one wherever it runs (the dashboard's scenario is built in too).

use crate::file::{self, NamedRoad, RoadFileError};

/// Each shipped road: the name a scenario gives (`track = "handling-circuit"`) and the
/// file's text.
pub const ROADS: &[(&str, &str)] = &[
    (
        "handling-circuit",
        include_str!("../../../roads/handling-circuit.toml"),
    ),
    (
        "braking-straight",
        include_str!("../../../roads/braking-straight.toml"),
    ),
    (
        "country-road",
        include_str!("../../../roads/country-road.toml"),
    ),
];

/// The shipped road called `name`, parsed; `None` when there is none of that name.
pub fn road(name: &str) -> Option<Result<NamedRoad, RoadFileError>> {
    ROADS
        .iter()
        .find(|(shipped, _)| *shipped == name)
        .map(|(shipped, text)| file::parse(text, &format!("roads/{shipped}.toml")))
}

/// The shipped roads' names, for error messages: "a, b, c".
pub fn names() -> String {
    ROADS
        .iter()
        .map(|(name, _)| *name)
        .collect::<Vec<_>>()
        .join(", ")
}
