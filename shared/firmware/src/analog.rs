//! Scaling between the board's electrical signals and the logic's physical units: a 12-bit
//! ADC reading of 0–3.3 V in, a PWM duty cycle of 0–100 % out, both linear over a range
//! each board names once per signal.

/// The largest reading of the 12-bit ADC (3.3 V on the Nucleo's VDDA = VREF+).
pub const ADC_MAX: u16 = 4095;

/// A linear analog input: `at_0v` at 0 V, `at_full_scale` at 3.3 V (the ADC's full scale).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearInput {
    /// Physical value at 0 V.
    pub at_0v: f32,
    /// Physical value at 3.3 V.
    pub at_full_scale: f32,
}

impl LinearInput {
    /// An input spanning `at_0v..at_full_scale` over 0–3.3 V.
    pub const fn new(at_0v: f32, at_full_scale: f32) -> Self {
        Self {
            at_0v,
            at_full_scale,
        }
    }

    /// The physical value of an ADC reading (readings above [`ADC_MAX`] count as full
    /// scale). A reading at a rail gives the range's end, which the logic may treat as
    /// implausible: that is how a broken wire or a shorted sensor reaches it.
    pub fn value(&self, raw: u16) -> f32 {
        let fraction = f32::from(raw.min(ADC_MAX)) / f32::from(ADC_MAX);
        self.at_0v + (self.at_full_scale - self.at_0v) * fraction
    }
}

/// A linear PWM output: `at_0_duty` at 0 % duty, `at_full_duty` at 100 %.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearOutput {
    /// Physical value at 0 % duty.
    pub at_0_duty: f32,
    /// Physical value at 100 % duty.
    pub at_full_duty: f32,
}

impl LinearOutput {
    /// An output spanning `at_0_duty..at_full_duty` over 0–100 % duty.
    pub const fn new(at_0_duty: f32, at_full_duty: f32) -> Self {
        Self {
            at_0_duty,
            at_full_duty,
        }
    }

    /// The duty cycle for a physical value, in parts of [`DUTY_DENOMINATOR`], clamped to
    /// 0–100 % (the logic already limits its commands; the clamp keeps the timer register
    /// sane for any value, NaN included, which gives 0 %).
    pub fn duty(&self, value: f32) -> u32 {
        let fraction = (value - self.at_0_duty) / (self.at_full_duty - self.at_0_duty);
        // `clamp` would keep a NaN.
        let fraction = if fraction.is_nan() {
            0.0
        } else {
            fraction.clamp(0.0, 1.0)
        };
        (fraction * DUTY_DENOMINATOR as f32 + 0.5) as u32
    }
}

/// The resolution of [`LinearOutput::duty`]: duty = value / DUTY_DENOMINATOR.
pub const DUTY_DENOMINATOR: u32 = 10_000;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn input_maps_the_rails_to_the_range_ends() {
        let pedal = LinearInput::new(0.0, 100.0);
        assert_eq!(pedal.value(0), 0.0);
        assert_eq!(pedal.value(ADC_MAX), 100.0);
        assert!((pedal.value(2048) - 50.012).abs() < 1e-3);
    }

    #[test]
    fn input_handles_a_bipolar_range_centred_on_half_supply() {
        let wheel = LinearInput::new(-135.0, 135.0);
        assert_eq!(wheel.value(0), -135.0);
        assert_eq!(wheel.value(ADC_MAX), 135.0);
        assert!(wheel.value(2047).abs() < 0.05);
    }

    #[test]
    fn input_saturates_readings_beyond_twelve_bits() {
        let pedal = LinearInput::new(0.0, 100.0);
        assert_eq!(pedal.value(u16::MAX), 100.0);
    }

    #[test]
    fn output_maps_the_range_onto_the_duty_cycle() {
        let split = LinearOutput::new(-50.0, 50.0);
        assert_eq!(split.duty(-50.0), 0);
        assert_eq!(split.duty(0.0), DUTY_DENOMINATOR / 2);
        assert_eq!(split.duty(50.0), DUTY_DENOMINATOR);
        assert_eq!(split.duty(25.0), 7_500);
    }

    #[test]
    fn output_clamps_out_of_range_and_nan_commands() {
        let fan = LinearOutput::new(0.0, 100.0);
        assert_eq!(fan.duty(-3.0), 0);
        assert_eq!(fan.duty(140.0), DUTY_DENOMINATOR);
        assert_eq!(fan.duty(f32::NAN), 0);
    }

    #[test]
    fn input_and_output_invert_each_other() {
        // A command looped back from a PWM output through an RC filter to an ADC input reads
        // back as itself, to within the ADC's resolution.
        let range = (-135.0, 135.0);
        let out = LinearOutput::new(range.0, range.1);
        let inp = LinearInput::new(range.0, range.1);
        for value in [-135.0, -60.5, 0.0, 12.25, 135.0] {
            let duty = out.duty(value);
            let raw = (duty as f32 / DUTY_DENOMINATOR as f32 * f32::from(ADC_MAX)).round() as u16;
            assert!((inp.value(raw) - value).abs() < 0.1, "{value}");
        }
    }
}
