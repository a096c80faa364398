//! The Nucleo-F446RE's clock tree, the same on every ECU: the ST-LINK's 8 MHz MCO on the
//! HSE input (bypass, Nucleo solder bridges as shipped), PLL to 168 MHz, APB1 at 42 MHz
//! (CAN1: 500 kbit/s is 84 APB1 cycles per bit) and APB2 at 84 MHz (ADC1, prescaled by the
//! HAL to at most 36 MHz; TIM1/TIM8 at 168 MHz, TIM2–5 at 84 MHz).

use embassy_stm32::rcc::{
    AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllMul, PllPDiv, PllPreDiv, PllQDiv, PllSource,
    Sysclk,
};
use embassy_stm32::time::Hertz;
use embassy_stm32::{Config, Peripherals};

/// APB1's clock (CAN1's), as [`config`] sets it up: 168 MHz / 4.
pub const APB1_HZ: u32 = 42_000_000;

/// The HAL configuration with the clock tree above.
pub fn config() -> Config {
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
    config.rcc.apb2_pre = APBPrescaler::DIV2; // 84 MHz: ADC1
    config
}

/// Brings up the clocks and the HAL, and hands out the peripherals.
pub fn init() -> Peripherals {
    embassy_stm32::init(config())
}
