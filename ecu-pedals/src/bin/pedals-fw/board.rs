//! The pedals ECU's board: a Nucleo-F446RE wired to the bench. The one place that names
//! pins; everything else in the firmware talks to the types below.
//!
//! | Nucleo pin (Arduino / Morpho) | MCU pin | signal | direction | electrical range |
//! |---|---|---|---|---|
//! | D15 / CN10-3 | PB8 | CAN1 RX (AF9) to the transceiver's RXD | in | 3.3 V logic |
//! | D14 / CN10-5 | PB9 | CAN1 TX (AF9) to the transceiver's TXD | out | 3.3 V logic |
//! | A0 / CN8-1 | PA0 | accelerator pedal (ADC1_IN0) | in | 0–3.3 V = 0–100 pedal units |
//! | A1 / CN8-2 | PA1 | brake pedal (ADC1_IN1) | in | 0–3.3 V = 0–100 pedal units |
//! | D5 / CN9-6 | PB4 | accelerator command (TIM3_CH1 PWM, 20 kHz) | out | duty 0–100 % = 0–100 pedal units, 0/3.3 V push-pull |
//! | D4 / CN9-5 | PB5 | brake command (TIM3_CH2 PWM, 20 kHz) | out | duty 0–100 % = 0–100 pedal units, 0/3.3 V push-pull |
//!
//! The transceiver is an external 3.3 V part (e.g. SN65HVD230) on the 120 Ω terminated bus.
//! A pedal is a potentiometer between 3.3 V (CN6-4) and GND, wiper on its pin. A command
//! drives an RC low-pass (e.g. 10 kΩ, 1 µF: 16 Hz corner) where an analog voltage is wanted.
//! Pins avoided: PA2/PA3 (ST-LINK virtual COM port), PA5 (LD2), PA13/PA14 (SWD).
//!
//! Clocks: the ST-LINK's 8 MHz MCO on the Nucleo's HSE input (bypass), PLL to 168 MHz,
//! APB1 42 MHz (CAN1: 500 kbit/s = 84 APB1 cycles per bit).

use ecu_pedals::{Actuators, Sensors, PEDAL_FULL};
use embassy_stm32::adc::{Adc, SampleTime};
use embassy_stm32::can::{self, Can};
use embassy_stm32::gpio::OutputType;
use embassy_stm32::peripherals::{ADC1, CAN1, IWDG, PA0, PA1, TIM3};
use embassy_stm32::rcc::{
    AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllMul, PllPDiv, PllPreDiv, PllQDiv, PllSource,
    Sysclk,
};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm, SimplePwmChannel};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, Config, Peri};

bind_interrupts!(struct Irqs {
    CAN1_TX => can::TxInterruptHandler<CAN1>;
    CAN1_RX0 => can::Rx0InterruptHandler<CAN1>;
    CAN1_RX1 => can::Rx1InterruptHandler<CAN1>;
    CAN1_SCE => can::SceInterruptHandler<CAN1>;
});

/// Frequency of the command PWM outputs.
const PWM_FREQUENCY: Hertz = Hertz(20_000);

/// Full scale of the 12-bit ADC (3.3 V on VDDA/VREF+ of the Nucleo).
const ADC_FULL_SCALE: f32 = 4095.0;

/// Sample time of a pedal reading: 144 ADC cycles, for a potentiometer's source impedance.
const PEDAL_SAMPLE_TIME: SampleTime = SampleTime::CYCLES144;

/// The board's peripherals, as the firmware uses them.
pub struct Board {
    /// CAN1 on PB8/PB9, not yet configured.
    pub can: Can<'static>,
    /// The pedal inputs.
    pub pedals: PedalInputs,
    /// The command outputs, at zero.
    pub commands: CommandOutputs,
    /// The independent watchdog, not yet started.
    pub watchdog: IndependentWatchdog<'static, IWDG>,
}

/// Brings up clocks and peripherals; outputs start at zero.
pub fn init() -> Board {
    let p = embassy_stm32::init(clock_config());

    let can = Can::new(p.CAN1, p.PB8, p.PB9, Irqs);

    let pedals = PedalInputs {
        adc: Adc::new(p.ADC1),
        accelerator: p.PA0,
        brake: p.PA1,
    };

    let pwm = SimplePwm::new(
        p.TIM3,
        Some(PwmPin::new(p.PB4, OutputType::PushPull)),
        Some(PwmPin::new(p.PB5, OutputType::PushPull)),
        None,
        None,
        PWM_FREQUENCY,
        CountingMode::EdgeAlignedUp,
    );
    let channels = pwm.split();
    let mut commands = CommandOutputs {
        accelerator: channels.ch1,
        brake: channels.ch2,
    };
    commands.set(&Actuators::default());
    commands.accelerator.enable();
    commands.brake.enable();

    // Started by the caller once the control loop runs.
    let watchdog = IndependentWatchdog::new(p.IWDG, crate::WATCHDOG_TIMEOUT_US);

    Board {
        can,
        pedals,
        commands,
        watchdog,
    }
}

fn clock_config() -> Config {
    let mut config = Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(8_000_000),
        mode: HseMode::Bypass,
    });
    config.rcc.pll_src = PllSource::HSE;
    config.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV4,   // 2 MHz
        mul: PllMul::MUL168,       // 336 MHz
        divp: Some(PllPDiv::DIV2), // 168 MHz system clock
        divq: Some(PllQDiv::DIV7), // 48 MHz (unused)
        divr: None,
    });
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV4; // 42 MHz: CAN1
    config.rcc.apb2_pre = APBPrescaler::DIV2; // 84 MHz: ADC1 (prescaled to <= 36 MHz)
    config
}

/// The accelerator and brake pedal potentiometers on ADC1.
pub struct PedalInputs {
    adc: Adc<'static, ADC1>,
    accelerator: Peri<'static, PA0>,
    brake: Peri<'static, PA1>,
}

impl PedalInputs {
    /// Reads both pedals: 0–3.3 V is 0–100 pedal units.
    pub fn read(&mut self) -> Sensors {
        let accelerator = self
            .adc
            .blocking_read(&mut self.accelerator, PEDAL_SAMPLE_TIME);
        let brake = self.adc.blocking_read(&mut self.brake, PEDAL_SAMPLE_TIME);
        Sensors {
            accelerator_pedal: pedal_units(accelerator),
            brake_pedal: pedal_units(brake),
        }
    }
}

fn pedal_units(raw: u16) -> f32 {
    f32::from(raw) * (PEDAL_FULL / ADC_FULL_SCALE)
}

/// The accelerator and brake command PWM outputs on TIM3.
pub struct CommandOutputs {
    accelerator: SimplePwmChannel<'static, TIM3>,
    brake: SimplePwmChannel<'static, TIM3>,
}

impl CommandOutputs {
    /// Drives both commands: 0–100 pedal units is 0–100 % duty.
    pub fn set(&mut self, actuators: &Actuators) {
        set_duty(&mut self.accelerator, actuators.accelerator_cmd);
        set_duty(&mut self.brake, actuators.brake_cmd);
    }
}

fn set_duty(channel: &mut SimplePwmChannel<'static, TIM3>, pedal_units: f32) {
    const DENOMINATOR: u32 = 10_000;
    // The logic clamps its commands to 0..100; the clamp here only keeps the register sane.
    let fraction = (pedal_units / PEDAL_FULL).clamp(0.0, 1.0);
    channel.set_duty_cycle_fraction((fraction * DENOMINATOR as f32) as u32, DENOMINATOR);
}
