//! Scaling between the board's electrical signals and the logic's physical units: the types
//! live with the boards' pin declarations (`autoplug_ecu::pins`), which the virtual car
//! reads too; the firmware's I/O takes them from here.

pub use autoplug_ecu::pins::{LinearInput, LinearOutput, ADC_MAX, DUTY_DENOMINATOR};
