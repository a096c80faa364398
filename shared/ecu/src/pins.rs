//! A board's signals as data: which Nucleo-F446RE pin carries each sensor and actuator,
//! its ADC or timer channel, and the scaling between its electrical signal (a 12-bit ADC
//! reading of 0–3.3 V in, a PWM duty cycle of 0–100 % out, a logic level) and the logic's
//! physical units. Each ECU crate's `pins` module declares its board with these; the
//! firmware's board module wires them to the HAL and the virtual car's emulated ECUs drive
//! the same pins from the vehicle model, so a scale or a pin is named once.

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

/// A pin of the STM32F446: its port (`b'A'`..`b'H'`) and number (0..15).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Pin {
    /// The GPIO port's letter.
    pub port: u8,
    /// The pin's number within its port.
    pub number: u8,
}

impl Pin {
    /// Port A's pin `number`.
    pub const fn a(number: u8) -> Self {
        Self { port: b'A', number }
    }
    /// Port B's pin `number`.
    pub const fn b(number: u8) -> Self {
        Self { port: b'B', number }
    }
    /// Port C's pin `number`.
    pub const fn c(number: u8) -> Self {
        Self { port: b'C', number }
    }
    /// The port's index from port A (0 for A).
    pub const fn port_index(&self) -> usize {
        (self.port - b'A') as usize
    }
}

impl core::fmt::Display for Pin {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "P{}{}", self.port as char, self.number)
    }
}

/// An analog input on ADC1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnalogIn {
    /// The pin.
    pub pin: Pin,
    /// Its ADC1 channel (ADC1_INx).
    pub adc_channel: u8,
    /// Volts to physical units.
    pub scale: LinearInput,
}

impl AnalogIn {
    /// The voltage at the pin for a physical value (clamped to the ADC's 0–3.3 V): what
    /// the bench's signal source puts on it.
    pub fn volts(&self, value: f32) -> f32 {
        let s = &self.scale;
        let fraction = (value - s.at_0v) / (s.at_full_scale - s.at_0v);
        let fraction = if fraction.is_nan() {
            0.0
        } else {
            fraction.clamp(0.0, 1.0)
        };
        fraction * FULL_SCALE_V
    }
}

/// A PWM output on a TIM3 channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PwmOut {
    /// The pin.
    pub pin: Pin,
    /// Its TIM3 channel, 1..=4.
    pub tim3_channel: u8,
    /// Physical units to duty cycle.
    pub scale: LinearOutput,
}

impl PwmOut {
    /// The physical value a duty cycle (0.0..=1.0) stands for: what the bench reads.
    pub fn value(&self, duty: f32) -> f32 {
        let s = &self.scale;
        s.at_0_duty + (s.at_full_duty - s.at_0_duty) * duty.clamp(0.0, 1.0)
    }
}

/// The internal resistor of a digital input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pull {
    /// Pull-up: a switch closes the pin to GND (reads low when closed).
    Up,
    /// Pull-down: the line is driven high for a 1.
    Down,
}

/// A digital input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DigitalIn {
    /// The pin.
    pub pin: Pin,
    /// Its internal resistor, which says what an open (undriven) pin reads.
    pub pull: Pull,
}

/// A push-pull digital output (high = on, or a 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DigitalOut {
    /// The pin.
    pub pin: Pin,
}

/// One signal of a board, for listing and checking a board's pins as a whole.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Signal {
    /// An analog input.
    Analog(AnalogIn),
    /// A PWM output.
    Pwm(PwmOut),
    /// A digital input.
    Input(DigitalIn),
    /// A digital output.
    Output(DigitalOut),
}

impl Signal {
    /// The pin it uses.
    pub fn pin(&self) -> Pin {
        match self {
            Signal::Analog(s) => s.pin,
            Signal::Pwm(s) => s.pin,
            Signal::Input(s) => s.pin,
            Signal::Output(s) => s.pin,
        }
    }

    /// Whether it is an input of the MCU.
    pub fn is_input(&self) -> bool {
        matches!(self, Signal::Analog(_) | Signal::Input(_))
    }
}

/// The ADC's full scale on the Nucleo (VDDA = VREF+ = 3.3 V).
pub const FULL_SCALE_V: f32 = 3.3;

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::ToString;

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

    #[test]
    fn analog_volts_invert_the_scale_and_clamp_to_the_rails() {
        let speed = AnalogIn {
            pin: Pin::a(0),
            adc_channel: 0,
            scale: LinearInput::new(0.0, 255.0),
        };
        assert_eq!(speed.volts(0.0), 0.0);
        assert!((speed.volts(127.5) - 1.65).abs() < 1e-6);
        assert_eq!(speed.volts(300.0), FULL_SCALE_V);
        assert_eq!(speed.volts(-1.0), 0.0);
        assert_eq!(speed.volts(f32::NAN), 0.0);
        let raw = (speed.volts(100.0) / FULL_SCALE_V * f32::from(ADC_MAX)).round() as u16;
        assert!((speed.scale.value(raw) - 100.0).abs() < 0.05);
    }

    #[test]
    fn pwm_value_inverts_the_duty() {
        let split = PwmOut {
            pin: Pin::b(4),
            tim3_channel: 1,
            scale: LinearOutput::new(-50.0, 50.0),
        };
        assert_eq!(split.value(0.5), 0.0);
        assert_eq!(split.value(1.0), 50.0);
        assert_eq!(split.value(2.0), 50.0);
        let duty = split.scale.duty(-20.0) as f32 / DUTY_DENOMINATOR as f32;
        assert!((split.value(duty) + 20.0).abs() < 0.01);
        assert_eq!(Pin::c(9).to_string(), "PC9");
    }
}
