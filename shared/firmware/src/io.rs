//! The board-side building blocks every ECU's board module uses: analog inputs on ADC1 and
//! PWM outputs on a general-purpose timer, each with the [`analog`](crate::analog) scaling
//! of its signal. Which pin is which signal stays in each ECU's board module.

use embassy_stm32::adc::{Adc, AnyAdcChannel, SampleTime};
use embassy_stm32::peripherals::ADC1;
use embassy_stm32::timer::simple_pwm::SimplePwmChannel;
use embassy_stm32::timer::GeneralInstance4Channel;

use crate::analog::{LinearInput, LinearOutput, DUTY_DENOMINATOR};

/// Sample time of every analog reading: 144 ADC cycles (about 7 µs at 21 MHz), long
/// enough for a potentiometer's or an RC filter's source impedance of some 10 kΩ.
pub const SAMPLE_TIME: SampleTime = SampleTime::CYCLES144;

/// Frequency of every PWM output: above hearing, and an RC low-pass of 16 Hz (10 kΩ, 1 µF)
/// turns it into a steady voltage where an analog one is wanted.
pub const PWM_FREQUENCY_HZ: u32 = 20_000;

/// An analog input pin of ADC1 (`pin.degrade_adc()`): one type for every pin, so that
/// [`read_analog`] is one function in the image rather than one per pin.
pub type AnalogPin = AnyAdcChannel<'static, ADC1>;

/// Reads one analog input on ADC1 and scales it.
pub fn read_analog(adc: &mut Adc<'static, ADC1>, pin: &mut AnalogPin, scale: &LinearInput) -> f32 {
    scale.value(adc.blocking_read(pin, SAMPLE_TIME))
}

/// One PWM output channel with the scaling of its signal.
pub struct PwmOutput<T: GeneralInstance4Channel> {
    channel: SimplePwmChannel<'static, T>,
    scale: LinearOutput,
}

impl<T: GeneralInstance4Channel> PwmOutput<T> {
    /// Sets the channel to `initial` (the actuator's safe value), then enables it.
    pub fn new(channel: SimplePwmChannel<'static, T>, scale: LinearOutput, initial: f32) -> Self {
        let mut output = Self { channel, scale };
        output.set(initial);
        output.channel.enable();
        output
    }

    /// Drives the output to `value`, in the signal's physical unit.
    pub fn set(&mut self, value: f32) {
        self.channel
            .set_duty_cycle_fraction(self.scale.duty(value), DUTY_DENOMINATOR);
    }
}
