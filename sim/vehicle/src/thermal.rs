//! Cabin air temperature: one thermal mass exchanging heat with the ambient air, the sun
//! and the HVAC air stream.
//!
//! `C·dT/dt = G_amb·(T_amb − T) + Q_sun + fan·G_hvac·(T_outlet − T)`
//!
//! The fan blows air conditioned to a fixed outlet temperature (the A/C evaporator's),
//! and its power scales the air flow. So with the fan off the cabin drifts to
//! `T_amb + Q_sun/G_amb`; at full fan it is pulled strongly towards the outlet
//! temperature. The catalogue has one command (fan power), so the HVAC only cools: the
//! cabin ECU's PID drives the fan from the cabin temperature error.

use crate::params::CabinParams;
use crate::rng::SplitMix64;

#[derive(Clone, Debug)]
pub(crate) struct Cabin {
    temp_c: f64,
    sensor_c: f64,
    rng: SplitMix64,
}

impl Cabin {
    pub(crate) fn new(temp_c: f64, seed: u64) -> Self {
        Self {
            temp_c,
            sensor_c: temp_c,
            rng: SplitMix64::new(seed),
        }
    }

    /// Advances by `dt` with fan power `fan` (0..=1).
    pub(crate) fn step(
        &mut self,
        p: &CabinParams,
        ambient_c: f64,
        sun_load_w: f64,
        fan: f64,
        dt: f64,
    ) {
        // Backward Euler: unconditionally stable and exact at equilibrium.
        let hvac_conductance = fan * p.hvac_conductance_w_per_k;
        let capacity_rate = p.heat_capacity_j_per_k / dt;
        self.temp_c = (capacity_rate * self.temp_c
            + p.ambient_conductance_w_per_k * ambient_c
            + sun_load_w
            + hvac_conductance * p.hvac_outlet_temp_c)
            / (capacity_rate + p.ambient_conductance_w_per_k + hvac_conductance);
        self.sensor_c = self.temp_c + p.sensor_noise_std_k * self.rng.next_standard_normal();
    }

    pub(crate) fn temp_c(&self) -> f64 {
        self.temp_c
    }

    pub(crate) fn sensor_c(&self) -> f64 {
        self.sensor_c
    }
}

/// Temperature the cabin settles at with a constant fan power, °C.
pub fn cabin_equilibrium_c(p: &CabinParams, ambient_c: f64, sun_load_w: f64, fan: f64) -> f64 {
    let hvac_conductance = fan * p.hvac_conductance_w_per_k;
    (p.ambient_conductance_w_per_k * ambient_c
        + sun_load_w
        + hvac_conductance * p.hvac_outlet_temp_c)
        / (p.ambient_conductance_w_per_k + hvac_conductance)
}
