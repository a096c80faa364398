//! The STM32F446RE around the core: flash (the project's simulated NOR flash), SRAM, the
//! device signature, and the peripherals the images use, behind the core's [`Bus`].
//!
//! Peripherals are modelled from RM0390. An access to a peripheral or register no model
//! covers, or to a feature of a modelled peripheral that is not modelled, stops the
//! emulation with a report naming the peripheral, the register offset and the instruction's
//! address: never a silent zero.

pub mod adc;
pub mod can;
pub mod flash_if;
pub mod gpio;
pub mod iwdg;
pub mod rcc;
pub mod timer;

use core::time::Duration;

use autoplug_flash::sim::{FlashError, SimFlash};

use crate::cpu::{Bus, BusError, Size};
use crate::map::{FLASH, FLASH_BASE, FLASH_SIZE, SRAM_SIZE, SRAM_START};

use adc::Adc;
use can::Can;
use flash_if::{FlashEffect, FlashInterface};
use gpio::Port;
use iwdg::Iwdg;
use rcc::{Clocks, Rcc, ResetCause, AHB1, APB1, APB2};
use timer::Timer;

/// An access a model does not cover: what, for the report.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Unmodelled(String);

impl Unmodelled {
    /// A register offset the peripheral's model does not have.
    pub fn register(offset: u32) -> Self {
        Unmodelled(format!("register at offset {offset:#05x}"))
    }

    /// A feature of the peripheral that is not modelled.
    pub fn feature(what: &str) -> Self {
        Unmodelled(format!("{what} is not modelled"))
    }
}

/// Nanoseconds in a second.
const NS_PER_S: u64 = 1_000_000_000;

/// Merges a narrow write into a register: the bytes in `mask` from `value`.
pub fn merge(old: u32, value: u32, mask: u32) -> u32 {
    (old & !mask) | (value & mask)
}

/// Which model answers a peripheral's registers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Model {
    Tim3,
    Tim12,
    Iwdg,
    Can1,
    Pwr,
    Adc,
    /// A GPIO port, by its index (A is 0).
    Gpio(usize),
    Rcc,
    FlashInterface,
}

/// A peripheral of the memory map: its base (each takes 1 KiB), its name, the RCC enable
/// bit that gates its clock (bus and bit) and the model that answers it (`None`: named
/// in reports, not modelled). Reads, writes and the reports of what is not modelled all
/// look here.
struct Peripheral {
    base: u32,
    name: &'static str,
    clock: Option<(usize, u32)>,
    model: Option<Model>,
}

impl Peripheral {
    const fn named(base: u32, name: &'static str) -> Self {
        Self {
            base,
            name,
            clock: None,
            model: None,
        }
    }

    const fn modelled(
        base: u32,
        name: &'static str,
        clock: Option<(usize, u32)>,
        model: Model,
    ) -> Self {
        Self {
            base,
            name,
            clock,
            model: Some(model),
        }
    }
}

/// Bytes of a peripheral's register block.
const PERIPHERAL_SIZE: u32 = 0x400;

/// The peripherals by base address (RM0390 table 1), in address order.
const PERIPHERAL_MAP: &[Peripheral] = &[
    Peripheral::named(0x4000_0000, "TIM2"),
    Peripheral::modelled(0x4000_0400, "TIM3", Some((APB1, 1)), Model::Tim3),
    Peripheral::named(0x4000_0800, "TIM4"),
    Peripheral::named(0x4000_0C00, "TIM5"),
    Peripheral::named(0x4000_1000, "TIM6"),
    Peripheral::named(0x4000_1400, "TIM7"),
    Peripheral::modelled(0x4000_1800, "TIM12", Some((APB1, 6)), Model::Tim12),
    Peripheral::named(0x4000_1C00, "TIM13"),
    Peripheral::named(0x4000_2000, "TIM14"),
    Peripheral::named(0x4000_2800, "RTC"),
    Peripheral::named(0x4000_2C00, "WWDG"),
    Peripheral::modelled(0x4000_3000, "IWDG", None, Model::Iwdg),
    Peripheral::named(0x4000_3800, "SPI2"),
    Peripheral::named(0x4000_3C00, "SPI3"),
    Peripheral::named(0x4000_4000, "SPDIFRX"),
    Peripheral::named(0x4000_4400, "USART2"),
    Peripheral::named(0x4000_4800, "USART3"),
    Peripheral::named(0x4000_4C00, "UART4"),
    Peripheral::named(0x4000_5000, "UART5"),
    Peripheral::named(0x4000_5400, "I2C1"),
    Peripheral::named(0x4000_5800, "I2C2"),
    Peripheral::named(0x4000_5C00, "I2C3"),
    Peripheral::named(0x4000_6000, "FMPI2C1"),
    Peripheral::modelled(0x4000_6400, "CAN1", Some((APB1, 25)), Model::Can1),
    Peripheral::named(0x4000_6800, "CAN2"),
    Peripheral::named(0x4000_6C00, "HDMI-CEC"),
    Peripheral::modelled(0x4000_7000, "PWR", Some((APB1, 28)), Model::Pwr),
    Peripheral::named(0x4000_7400, "DAC"),
    Peripheral::named(0x4001_0000, "TIM1"),
    Peripheral::named(0x4001_0400, "TIM8"),
    Peripheral::named(0x4001_1000, "USART1"),
    Peripheral::named(0x4001_1400, "USART6"),
    Peripheral::modelled(0x4001_2000, "ADC1/2/3", Some((APB2, 8)), Model::Adc),
    Peripheral::named(0x4001_2C00, "SDIO"),
    Peripheral::named(0x4001_3000, "SPI1"),
    Peripheral::named(0x4001_3400, "SPI4"),
    Peripheral::named(0x4001_3800, "SYSCFG"),
    Peripheral::named(0x4001_3C00, "EXTI"),
    Peripheral::named(0x4001_4000, "TIM9"),
    Peripheral::named(0x4001_4400, "TIM10"),
    Peripheral::named(0x4001_4800, "TIM11"),
    Peripheral::named(0x4001_5800, "SAI1"),
    Peripheral::named(0x4001_5C00, "SAI2"),
    Peripheral::modelled(0x4002_0000, "GPIOA", Some((AHB1, 0)), Model::Gpio(0)),
    Peripheral::modelled(0x4002_0400, "GPIOB", Some((AHB1, 1)), Model::Gpio(1)),
    Peripheral::modelled(0x4002_0800, "GPIOC", Some((AHB1, 2)), Model::Gpio(2)),
    Peripheral::modelled(0x4002_0C00, "GPIOD", Some((AHB1, 3)), Model::Gpio(3)),
    Peripheral::modelled(0x4002_1000, "GPIOE", Some((AHB1, 4)), Model::Gpio(4)),
    Peripheral::modelled(0x4002_1400, "GPIOF", Some((AHB1, 5)), Model::Gpio(5)),
    Peripheral::modelled(0x4002_1800, "GPIOG", Some((AHB1, 6)), Model::Gpio(6)),
    Peripheral::modelled(0x4002_1C00, "GPIOH", Some((AHB1, 7)), Model::Gpio(7)),
    Peripheral::named(0x4002_3000, "CRC"),
    Peripheral::modelled(0x4002_3800, "RCC", None, Model::Rcc),
    Peripheral::modelled(0x4002_3C00, "FLASH", None, Model::FlashInterface),
    Peripheral::named(0x4002_4000, "BKPSRAM"),
    Peripheral::named(0x4002_6000, "DMA1"),
    Peripheral::named(0x4002_6400, "DMA2"),
    Peripheral::named(0x4004_0000, "USB OTG HS"),
    Peripheral::named(0x5000_0000, "USB OTG FS"),
    Peripheral::named(0x5005_0000, "DCMI"),
];

/// The peripheral whose register block holds `address`: by [`PERIPHERAL_INDEX`] on the
/// APB and AHB1 buses (every access a firmware makes to its peripherals), by a search
/// of the map above them.
fn peripheral_at(address: u32) -> Option<&'static Peripheral> {
    let offset = address.wrapping_sub(INDEXED.start);
    if offset < INDEXED.end - INDEXED.start {
        return PERIPHERAL_MAP.get(usize::from(
            PERIPHERAL_INDEX[(offset / PERIPHERAL_SIZE) as usize],
        ));
    }
    search_peripheral(address)
}

fn search_peripheral(address: u32) -> Option<&'static Peripheral> {
    let after = PERIPHERAL_MAP.partition_point(|p| p.base <= address);
    let p = PERIPHERAL_MAP.get(after.checked_sub(1)?)?;
    (address - p.base < PERIPHERAL_SIZE).then_some(p)
}

/// The addresses [`PERIPHERAL_INDEX`] covers: APB1, APB2 and AHB1.
const INDEXED: core::ops::Range<u32> = 0x4000_0000..0x4008_0000;

/// For each 1 KiB block of [`INDEXED`], the index of its peripheral in
/// [`PERIPHERAL_MAP`] (`u8::MAX`: none), built from the map at compile time.
const PERIPHERAL_INDEX: [u8; ((INDEXED.end - INDEXED.start) / PERIPHERAL_SIZE) as usize] = {
    let mut index = [u8::MAX; ((INDEXED.end - INDEXED.start) / PERIPHERAL_SIZE) as usize];
    let mut i = 0;
    while i < PERIPHERAL_MAP.len() {
        let base = PERIPHERAL_MAP[i].base;
        assert!(base % PERIPHERAL_SIZE == 0 && i < u8::MAX as usize);
        if base >= INDEXED.start && base < INDEXED.end {
            index[((base - INDEXED.start) / PERIPHERAL_SIZE) as usize] = i as u8;
        }
        i += 1;
    }
    index
};

/// The name of the peripheral at `address`.
pub fn peripheral_name(address: u32) -> &'static str {
    peripheral_at(address).map_or("no peripheral", |p| p.name)
}

/// The interrupt numbers (RM0390 table 38) of the modelled peripherals.
pub mod irq {
    /// FLASH global interrupt.
    pub const FLASH: usize = 4;
    /// ADC1, ADC2, ADC3.
    pub const ADC: usize = 18;
    /// CAN1 TX.
    pub const CAN1_TX: usize = 19;
    /// CAN1 RX0.
    pub const CAN1_RX0: usize = 20;
    /// CAN1 RX1.
    pub const CAN1_RX1: usize = 21;
    /// CAN1 SCE.
    pub const CAN1_SCE: usize = 22;
    /// TIM3.
    pub const TIM3: usize = 29;
    /// TIM8 break and TIM12.
    pub const TIM8_BRK_TIM12: usize = 43;
}

/// What happened during an access that the MCU loop must act on.
#[derive(Clone, Debug, Default)]
pub struct Pending {
    /// Core cycles to stall (the flash was busy).
    pub stall: Duration,
    /// Decoded instructions to forget.
    pub code_changed: Option<core::ops::Range<u32>>,
    /// The simulated flash refused an operation (a power cut).
    pub flash_failed: Option<FlashError>,
}

/// SRAM in pages for snapshots: a page that did not change since the last snapshot is
/// shared with it, so a snapshot costs the pages the firmware wrote.
pub const SNAPSHOT_PAGE: usize = 4096;

/// The chip's state at a moment (a reverse debugger's snapshot): the peripherals copied,
/// SRAM in shared pages, the flash shared while it is unchanged.
#[derive(Clone)]
pub struct ChipSnapshot {
    flash: std::sync::Arc<SimFlash>,
    sram: Vec<std::sync::Arc<[u8]>>,
    uid: [u32; 3],
    rcc: Rcc,
    flash_if: FlashInterface,
    gpio: [Port; 8],
    adc: Adc,
    tim3: Timer,
    tim12: Timer,
    iwdg: Iwdg,
    can1: Can,
    pending: Pending,
    touched: bool,
    clocks: Clocks,
    epoch_ns: u64,
    epoch_cycle: u64,
}

impl ChipSnapshot {
    /// The flash operations done when it was taken (the flash is shared while equal).
    pub fn flash_operations(&self) -> u64 {
        self.flash.operations()
    }

    /// The SRAM pages and the flash, for what the snapshot costs.
    pub fn memories(&self) -> (&[std::sync::Arc<[u8]>], &std::sync::Arc<SimFlash>) {
        (&self.sram, &self.flash)
    }
}

/// The chip around the core.
pub struct Chip {
    /// The main flash.
    pub flash: SimFlash,
    sram: Vec<u8>,
    /// The 96-bit unique ID.
    uid: [u32; 3],
    /// RCC and PWR.
    pub rcc: Rcc,
    /// The flash interface.
    pub flash_if: FlashInterface,
    /// GPIO ports A–H.
    pub gpio: [Port; 8],
    /// ADC1.
    pub adc: Adc,
    /// TIM3.
    pub tim3: Timer,
    /// TIM12.
    pub tim12: Timer,
    /// The independent watchdog.
    pub iwdg: Iwdg,
    /// CAN1.
    pub can1: Can,
    /// Effects for the MCU loop.
    pub pending: Pending,
    /// A peripheral was written: the MCU loop re-reads interrupt lines and event times.
    touched: bool,
    /// The clock rates after the last RCC write.
    clocks: Clocks,
    /// Simulated time at `epoch_cycle` (ns), for LSI-clocked and wall-clock peripherals.
    epoch_ns: u64,
    epoch_cycle: u64,
}

impl Chip {
    /// A chip after a power-on reset, with this flash and unique ID.
    pub fn new(flash: SimFlash, uid: [u32; 3]) -> Self {
        let rcc = Rcc::new(ResetCause::PowerOn, None);
        let clocks = rcc.clocks();
        Chip {
            flash,
            sram: vec![0; SRAM_SIZE as usize],
            uid,
            rcc,
            flash_if: FlashInterface::default(),
            gpio: core::array::from_fn(Port::new),
            adc: Adc::default(),
            tim3: Timer::new(4, false),
            tim12: Timer::new(2, false),
            iwdg: Iwdg::default(),
            can1: Can::default(),
            pending: Pending::default(),
            touched: false,
            clocks,
            epoch_ns: 0,
            epoch_cycle: 0,
        }
    }

    /// The chip after a system reset of `cause` at simulated time `now_ns`: every
    /// peripheral at its reset value, RCC_CSR's flags kept and the cause's added; SRAM keeps
    /// its contents (a reset does not clear it); the world's inputs (pins, ADC volts) stay.
    pub fn reset(&mut self, cause: ResetCause, now_ns: u64) {
        self.rcc = Rcc::new(cause, Some(&self.rcc));
        self.clocks = self.rcc.clocks();
        self.flash_if = FlashInterface::default();
        let inputs = self.adc.inputs();
        self.adc = Adc::default();
        for (channel, volts) in inputs.iter().enumerate() {
            self.adc.set_input(channel, *volts);
        }
        for (i, port) in self.gpio.iter_mut().enumerate() {
            *port = Port::new(i).with_inputs_of(port);
        }
        self.tim3 = Timer::new(4, false);
        self.tim12 = Timer::new(2, false);
        self.iwdg = Iwdg::default();
        self.can1 = Can::default();
        self.pending = Pending::default();
        self.epoch_ns = now_ns;
        self.epoch_cycle = 0;
    }

    /// The chip's state now; `last`, an earlier snapshot, lends the pages and flash that
    /// did not change since.
    pub fn snapshot(&self, last: Option<&ChipSnapshot>) -> ChipSnapshot {
        let flash = match last {
            Some(l) if l.flash.operations() == self.flash.operations() => {
                std::sync::Arc::clone(&l.flash)
            }
            _ => std::sync::Arc::new(self.flash.clone()),
        };
        let sram = self
            .sram
            .chunks(SNAPSHOT_PAGE)
            .enumerate()
            .map(|(i, page)| match last.and_then(|l| l.sram.get(i)) {
                Some(old) if **old == *page => std::sync::Arc::clone(old),
                _ => std::sync::Arc::from(page),
            })
            .collect();
        ChipSnapshot {
            flash,
            sram,
            uid: self.uid,
            rcc: self.rcc.clone(),
            flash_if: self.flash_if.clone(),
            gpio: self.gpio.clone(),
            adc: self.adc.clone(),
            tim3: self.tim3.clone(),
            tim12: self.tim12.clone(),
            iwdg: self.iwdg.clone(),
            can1: self.can1.clone(),
            pending: self.pending.clone(),
            touched: self.touched,
            clocks: self.clocks,
            epoch_ns: self.epoch_ns,
            epoch_cycle: self.epoch_cycle,
        }
    }

    /// Puts the chip back as `snapshot` found it; whether the flash's contents changed.
    pub fn restore(&mut self, snapshot: &ChipSnapshot) -> bool {
        let flash_changed = self.flash.operations() != snapshot.flash.operations();
        if flash_changed {
            self.flash = (*snapshot.flash).clone();
        }
        for (page, saved) in self.sram.chunks_mut(SNAPSHOT_PAGE).zip(&snapshot.sram) {
            page.copy_from_slice(saved);
        }
        self.uid = snapshot.uid;
        self.rcc = snapshot.rcc.clone();
        self.flash_if = snapshot.flash_if.clone();
        self.gpio = snapshot.gpio.clone();
        self.adc = snapshot.adc.clone();
        self.tim3 = snapshot.tim3.clone();
        self.tim12 = snapshot.tim12.clone();
        self.iwdg = snapshot.iwdg.clone();
        self.can1 = snapshot.can1.clone();
        self.pending = snapshot.pending.clone();
        self.touched = snapshot.touched;
        self.clocks = snapshot.clocks;
        self.epoch_ns = snapshot.epoch_ns;
        self.epoch_cycle = snapshot.epoch_cycle;
        flash_changed
    }

    /// The clock rates now.
    pub fn clocks(&self) -> Clocks {
        self.clocks
    }

    /// Simulated nanoseconds at core cycle `cycle`.
    ///
    /// Whole seconds and the rest apart, so both products fit 64 bits: the same result as
    /// one 128-bit product and quotient, which took 3 % of an emulated car's run.
    pub fn ns_at(&self, cycle: u64) -> u64 {
        let hz = self.clocks.hclk;
        let cycles = cycle.saturating_sub(self.epoch_cycle);
        let (seconds, rest) = (cycles / hz, cycles % hz);
        self.epoch_ns + seconds * NS_PER_S + rest * NS_PER_S / hz
    }

    /// The core cycle at simulated nanosecond `ns` (rounded up; split as [`Chip::ns_at`]).
    pub fn cycle_at(&self, ns: u64) -> u64 {
        let hz = self.clocks.hclk;
        let delta = ns.saturating_sub(self.epoch_ns);
        let (seconds, rest) = (delta / NS_PER_S, delta % NS_PER_S);
        self.epoch_cycle + seconds * hz + (rest * hz).div_ceil(NS_PER_S)
    }

    /// Reads SRAM bytes (for a debugger's view: RTT), if all are in SRAM.
    pub fn sram_read(&self, address: u32, buf: &mut [u8]) -> Option<()> {
        let start = address.checked_sub(SRAM_START)? as usize;
        buf.copy_from_slice(self.sram.get(start..start + buf.len())?);
        Some(())
    }

    /// The SRAM word at `address`.
    pub fn sram_word(&self, address: u32) -> Option<u32> {
        let mut bytes = [0u8; 4];
        self.sram_read(address, &mut bytes)?;
        Some(u32::from_le_bytes(bytes))
    }

    /// Writes an SRAM word as a debugger does (RTT's read offset).
    pub fn sram_set_word(&mut self, address: u32, value: u32) {
        if let Some(start) = address.checked_sub(SRAM_START) {
            if let Some(slot) = self.sram.get_mut(start as usize..start as usize + 4) {
                slot.copy_from_slice(&value.to_le_bytes());
            }
        }
    }

    /// Whether a peripheral was written since the last [`Chip::take_touched`].
    pub fn is_touched(&self) -> bool {
        self.touched
    }

    /// Whether a peripheral was written since the last call.
    pub fn take_touched(&mut self) -> bool {
        std::mem::take(&mut self.touched)
    }

    /// The clock tree changed at `now`: re-base time and the timers' clocks.
    fn clocks_changed(&mut self, now: u64) {
        let clocks = self.rcc.clocks();
        if clocks == self.clocks {
            return;
        }
        self.epoch_ns = self.ns_at(now);
        self.epoch_cycle = now;
        self.clocks = clocks;
        let divisor = |timer_hz: u64| (clocks.hclk / timer_hz.max(1)).max(1);
        self.tim3
            .set_clock_divisor(divisor(clocks.apb1_timers()), now);
        self.tim12
            .set_clock_divisor(divisor(clocks.apb1_timers()), now);
    }

    /// The interrupt lines of the modelled peripherals that are high.
    pub fn irq_lines(&self) -> impl Iterator<Item = usize> {
        let can = self.can1.irqs();
        [
            (irq::FLASH, self.flash_if.irq()),
            (irq::ADC, self.adc.irq()),
            (irq::CAN1_TX, can[0]),
            (irq::CAN1_RX0, can[1]),
            (irq::CAN1_RX1, can[2]),
            (irq::CAN1_SCE, can[3]),
            (irq::TIM3, self.tim3.irq()),
            (irq::TIM8_BRK_TIM12, self.tim12.irq()),
        ]
        .into_iter()
        .filter_map(|(n, high)| high.then_some(n))
    }

    /// The next core cycle at which a peripheral sets a flag on its own, if any.
    pub fn next_event(&self) -> Option<u64> {
        let iwdg = self.iwdg.expires().map(|ns| self.cycle_at(ns));
        [
            self.tim3.next_event(),
            self.tim12.next_event(),
            self.adc.next_event(),
            iwdg,
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// Brings the timers' flags up to `now`.
    pub fn sync(&mut self, now: u64) {
        self.tim3.sync(now);
        self.tim12.sync(now);
    }

    fn system_memory(&self, address: u32, size: Size) -> Result<u32, BusError> {
        let offset = address.wrapping_sub(crate::map::UID_BASE);
        let mut bytes = [0u8; 0x14];
        for (i, word) in self.uid.iter().enumerate() {
            bytes[4 * i..4 * i + 4].copy_from_slice(&word.to_le_bytes());
        }
        // The flash size word (0x1FFF_7A22): 512 KiB.
        bytes[0x12..0x14].copy_from_slice(&((FLASH_SIZE / 1024) as u16).to_le_bytes());
        if offset as usize + size as usize <= 0x14 {
            let mut value = [0u8; 4];
            value[..size as usize]
                .copy_from_slice(&bytes[offset as usize..offset as usize + size as usize]);
            return Ok(u32::from_le_bytes(value));
        }
        Err(BusError::Unmodelled(format!(
            "system memory at {address:#010x} (only the unique ID and flash size are modelled)"
        )))
    }

    /// The modelled peripheral at `address`, its clock checked, and the offset into it.
    fn modelled_peripheral(&self, address: u32) -> Result<(Model, u32), Unmodelled> {
        let p = peripheral_at(address)
            .filter(|p| p.model.is_some())
            .ok_or_else(|| Unmodelled(String::from("the peripheral is not modelled")))?;
        if let Some((bus, bit)) = p.clock {
            self.clock_gate(bus, bit, p.name)?;
        }
        Ok((p.model.unwrap_or(Model::Rcc), address - p.base))
    }

    fn peripheral_read(&mut self, address: u32, now: u64) -> Result<u32, Unmodelled> {
        let (model, offset) = self.modelled_peripheral(address)?;
        match model {
            Model::Tim3 => self.tim3.read(offset, now),
            Model::Tim12 => self.tim12.read(offset, now),
            Model::Iwdg => {
                let ns = self.ns_at(now);
                self.iwdg.read(offset, ns)
            }
            Model::Can1 => self.can1.read(offset),
            Model::Pwr => self.rcc.pwr_read(offset),
            Model::Adc => {
                if (0x100..0x300).contains(&offset) {
                    return Err(Unmodelled::feature("ADC2 and ADC3"));
                }
                self.adc.read(offset, now)
            }
            Model::Gpio(port) => self.gpio[port].read(offset),
            Model::Rcc => self.rcc.read(offset),
            Model::FlashInterface => self.flash_if.read(offset),
        }
    }

    /// A peripheral register as a debugger reads it: from a copy of the peripheral where a
    /// read would change it (a timer or the ADC brought up to `now`), so looking changes
    /// nothing the firmware sees.
    fn peripheral_peek(&self, address: u32, now: u64) -> Result<u32, Unmodelled> {
        let (model, offset) = self.modelled_peripheral(address)?;
        match model {
            Model::Tim3 => self.tim3.clone().read(offset, now),
            Model::Tim12 => self.tim12.clone().read(offset, now),
            Model::Iwdg => self.iwdg.clone().read(offset, self.ns_at(now)),
            Model::Can1 => self.can1.read(offset),
            Model::Pwr => self.rcc.pwr_read(offset),
            Model::Adc if (0x100..0x300).contains(&offset) => {
                Err(Unmodelled::feature("ADC2 and ADC3"))
            }
            Model::Adc => self.adc.clone().read(offset, now),
            Model::Gpio(port) => self.gpio[port].read(offset),
            Model::Rcc => self.rcc.read(offset),
            Model::FlashInterface => self.flash_if.read(offset),
        }
    }

    /// Reads memory or a peripheral register as a debugger does (at core cycle `now`),
    /// changing nothing: flash, its alias at 0, SRAM, the device signature and the
    /// modelled peripherals. Elsewhere, and where no model answers, an error.
    pub fn peek(&self, address: u32, size: Size, now: u64) -> Result<u32, BusError> {
        let len = size as u32;
        let narrow = |word: u32, at: u32| {
            let shift = 8 * (at & 3);
            match size {
                Size::Word => word,
                Size::Half => (word >> shift) & 0xFFFF,
                Size::Byte => (word >> shift) & 0xFF,
            }
        };
        if address & (len - 1) != 0 {
            return Err(BusError::Fault);
        }
        if address >= SRAM_START && address - SRAM_START + len <= SRAM_SIZE {
            let mut bytes = [0u8; 4];
            self.sram_read(address, &mut bytes[..len as usize])
                .ok_or(BusError::Fault)?;
            return Ok(u32::from_le_bytes(bytes));
        }
        let flash_address = if address < FLASH_SIZE {
            address + FLASH_BASE
        } else {
            address
        };
        if FLASH.contains(&flash_address) {
            return Ok(narrow(self.flash_word(flash_address & !3), flash_address));
        }
        match address {
            0x4000_0000..=0x5FFF_FFFF => {
                let word = self
                    .peripheral_peek(address & !3, now)
                    .map_err(|e| Self::unmodelled(address, e))?;
                Ok(narrow(word, address))
            }
            0x1FFF_0000..=0x1FFF_FFFF => self.system_memory(address, size),
            _ => Err(BusError::Fault),
        }
    }

    fn peripheral_write(
        &mut self,
        address: u32,
        value: u32,
        mask: u32,
        now: u64,
    ) -> Result<Result<(), BusError>, Unmodelled> {
        let (model, offset) = self.modelled_peripheral(address)?;
        self.touched = true;
        match model {
            Model::Tim3 => self.tim3.write(offset, value, mask, now)?,
            Model::Tim12 => self.tim12.write(offset, value, mask, now)?,
            Model::Iwdg => {
                let ns = self.ns_at(now);
                self.iwdg.write(offset, value, mask, ns)?
            }
            Model::Can1 => self.can1.write(offset, value, mask, now)?,
            Model::Pwr => self.rcc.pwr_write(offset, value, mask)?,
            Model::Adc => {
                if (0x100..0x300).contains(&offset) {
                    return Err(Unmodelled::feature("ADC2 and ADC3"));
                }
                let divisor = (self.clocks.hclk / self.clocks.pclk2.max(1)).max(1);
                self.adc.write(offset, value, mask, now, divisor)?
            }
            Model::Gpio(port) => self.gpio[port].write(offset, value, mask)?,
            Model::Rcc => {
                if let Some((bus, bits)) = self.rcc.write(offset, value, mask)? {
                    self.reset_peripherals(bus, bits);
                }
                self.rcc.settle();
                self.clocks_changed(now);
            }
            Model::FlashInterface => {
                match self.flash_if.write(offset, value, mask, &mut self.flash)? {
                    FlashEffect::BusFault => return Ok(Err(BusError::Fault)),
                    effect => self.flash_effect(effect),
                }
            }
        }
        Ok(Ok(()))
    }

    fn flash_effect(&mut self, effect: FlashEffect) {
        match effect {
            FlashEffect::None | FlashEffect::BusFault => {}
            FlashEffect::Changed { range, busy } => {
                self.pending.stall += busy;
                let code = self.pending.code_changed.take();
                self.pending.code_changed = Some(match code {
                    Some(old) => old.start.min(range.start)..old.end.max(range.end),
                    None => range,
                });
            }
            FlashEffect::Failed(error) => self.pending.flash_failed = Some(error),
        }
    }

    /// Peripherals put in reset through RCC_xxxRSTR return to their reset values.
    fn reset_peripherals(&mut self, bus: usize, bits: u32) {
        let divisor = (self.clocks.hclk / self.clocks.apb1_timers().max(1)).max(1);
        if bus == APB1 {
            if bits & (1 << 1) != 0 {
                self.tim3 = Timer::new(4, false);
                self.tim3.set_clock_divisor(divisor, 0);
            }
            if bits & (1 << 6) != 0 {
                self.tim12 = Timer::new(2, false);
                self.tim12.set_clock_divisor(divisor, 0);
            }
            if bits & (1 << 25) != 0 {
                self.can1 = Can::default();
            }
        }
        if bus == APB2 && bits & (1 << 8) != 0 {
            let inputs = self.adc.inputs();
            self.adc = Adc::default();
            for (channel, volts) in inputs.iter().enumerate() {
                self.adc.set_input(channel, *volts);
            }
        }
        if bus == rcc::AHB1 {
            for (i, port) in self.gpio.iter_mut().enumerate() {
                if bits & (1 << i) != 0 {
                    *port = Port::new(i).with_inputs_of(port);
                }
            }
        }
    }

    /// A peripheral whose clock is off in RCC ignores writes and reads 0 on the chip: a
    /// firmware that does this has a bug, so it is reported rather than ignored.
    fn clock_gate(&self, bus: usize, bit: u32, name: &str) -> Result<(), Unmodelled> {
        if self.rcc.enabled(bus, bit) {
            Ok(())
        } else {
            Err(Unmodelled(format!(
                "{name} is accessed with its clock disabled in RCC (the chip would ignore it)"
            )))
        }
    }

    fn unmodelled(address: u32, what: Unmodelled) -> BusError {
        let name = peripheral_name(address);
        BusError::Unmodelled(format!("{name} at {address:#010x}: {}", what.0))
    }

    #[inline]
    fn flash_word(&self, address: u32) -> u32 {
        self.flash.read_word(address)
    }
}

impl Port {
    /// This port's reset state with the externally driven levels of `other` kept.
    pub fn with_inputs_of(self, other: &Port) -> Port {
        let mut port = self;
        port.copy_inputs(other);
        port
    }
}

impl Bus for Chip {
    #[inline]
    fn read(&mut self, address: u32, size: Size, now: u64) -> Result<u32, BusError> {
        let len = size as u32;
        if address >= SRAM_START && address - SRAM_START + len <= SRAM_SIZE {
            let i = (address - SRAM_START) as usize;
            return Ok(match size {
                Size::Word => u32::from_le_bytes([
                    self.sram[i],
                    self.sram[i + 1],
                    self.sram[i + 2],
                    self.sram[i + 3],
                ]),
                Size::Half => u16::from_le_bytes([self.sram[i], self.sram[i + 1]]) as u32,
                Size::Byte => self.sram[i] as u32,
            });
        }
        let flash_address = if address < FLASH_SIZE {
            address + FLASH_BASE
        } else {
            address
        };
        if FLASH.contains(&flash_address) && flash_address - FLASH_BASE + len <= FLASH_SIZE {
            let word = self.flash_word(flash_address & !3);
            let shift = 8 * (flash_address & 3);
            return Ok(match size {
                Size::Word => word,
                Size::Half => (word >> shift) & 0xFFFF,
                Size::Byte => (word >> shift) & 0xFF,
            });
        }
        match address {
            0x4000_0000..=0x5FFF_FFFF => {
                let word_address = address & !3;
                let shift = 8 * (address & 3);
                let word = self
                    .peripheral_read(word_address, now)
                    .map_err(|e| Self::unmodelled(address, e))?;
                Ok(match size {
                    Size::Word => word,
                    Size::Half => (word >> shift) & 0xFFFF,
                    Size::Byte => (word >> shift) & 0xFF,
                })
            }
            0x1FFF_0000..=0x1FFF_FFFF => self.system_memory(address, size),
            _ => Err(BusError::Fault),
        }
    }

    #[inline]
    fn write(&mut self, address: u32, size: Size, value: u32, now: u64) -> Result<(), BusError> {
        let len = size as u32;
        if address >= SRAM_START && address - SRAM_START + len <= SRAM_SIZE {
            let i = (address - SRAM_START) as usize;
            match size {
                Size::Word => self.sram[i..i + 4].copy_from_slice(&value.to_le_bytes()),
                Size::Half => self.sram[i..i + 2].copy_from_slice(&(value as u16).to_le_bytes()),
                Size::Byte => self.sram[i] = value as u8,
            }
            return Ok(());
        }
        let flash_address = if address < FLASH_SIZE {
            address + FLASH_BASE
        } else {
            address
        };
        if FLASH.contains(&flash_address) {
            let bytes = value.to_le_bytes();
            let effect =
                self.flash_if
                    .program(flash_address, &bytes[..len as usize], &mut self.flash);
            self.touched = true;
            self.flash_effect(effect);
            return Ok(());
        }
        match address {
            0x4000_0000..=0x5FFF_FFFF => {
                let shift = 8 * (address & 3);
                let mask = match size {
                    Size::Word => u32::MAX,
                    Size::Half => 0xFFFF,
                    Size::Byte => 0xFF,
                } << shift;
                self.peripheral_write(address & !3, value << shift, mask, now)
                    .map_err(|e| Self::unmodelled(address, e))?
            }
            _ => Err(BusError::Fault),
        }
    }

    fn yield_requested(&mut self) -> bool {
        self.touched
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_index_finds_what_a_search_of_the_map_finds() {
        for block in (0x3FFF_F000u32..0x5006_0000).step_by(0x100) {
            for address in [block, block + 0xFC] {
                assert_eq!(
                    peripheral_at(address).map(|p| p.base),
                    search_peripheral(address).map(|p| p.base),
                    "{address:#010x}"
                );
            }
        }
    }

    #[test]
    fn one_table_names_every_peripheral_and_routes_the_modelled_ones() {
        assert!(
            PERIPHERAL_MAP
                .windows(2)
                .all(|w| w[0].base + PERIPHERAL_SIZE <= w[1].base),
            "in address order, without overlaps"
        );
        assert_eq!(peripheral_name(0x4000_6404), "CAN1");
        assert_eq!(peripheral_name(0x4002_1C14), "GPIOH");
        assert_eq!(peripheral_name(0x4001_1004), "USART1");
        assert_eq!(peripheral_name(0x4000_2400), "no peripheral");
        assert_eq!(peripheral_name(0x3FFF_FFFC), "no peripheral");
        let modelled: Vec<&str> = PERIPHERAL_MAP
            .iter()
            .filter(|p| p.model.is_some())
            .map(|p| p.name)
            .collect();
        assert_eq!(modelled.len(), 16, "{modelled:?}");
        let chip = Chip::new(SimFlash::new(1), [0; 3]);
        // RCC answers without a clock of its own; GPIOC is gated by its AHB1 bit (off
        // after reset); USART1 is named but not modelled.
        assert!(chip.modelled_peripheral(0x4002_3800).is_ok());
        let gated = chip.modelled_peripheral(0x4002_0800).unwrap_err().0;
        assert!(
            gated.starts_with("GPIOC is accessed with its clock disabled"),
            "{gated}"
        );
        assert!(chip.modelled_peripheral(0x4001_1000).is_err());
    }

    #[test]
    fn cycles_and_nanoseconds_convert_as_one_wide_product_would() {
        let mut chip = Chip::new(SimFlash::new(1), [0; 3]);
        for hz in [16_000_000u64, 168_000_000, 180_000_000] {
            chip.clocks.hclk = hz;
            chip.epoch_ns = 1_234_567;
            chip.epoch_cycle = 777;
            // Hours of simulated time, and the first cycles after the epoch.
            for cycle in [
                777u64,
                778,
                779 + hz,
                3_600 * hz + 12_345,
                u64::from(u32::MAX) * 97,
            ] {
                let wide = (u128::from(cycle - 777) * 1_000_000_000 / u128::from(hz)) as u64;
                assert_eq!(
                    chip.ns_at(cycle),
                    1_234_567 + wide,
                    "{hz} Hz, cycle {cycle}"
                );
            }
            for ns in [1_234_567u64, 1_234_568, 2_000_000_000, 3_600_000_000_123] {
                let wide =
                    (u128::from(ns - 1_234_567) * u128::from(hz)).div_ceil(1_000_000_000) as u64;
                assert_eq!(chip.cycle_at(ns), 777 + wide, "{hz} Hz, {ns} ns");
            }
        }
    }

    #[test]
    fn peripherals_are_named_by_their_base() {
        assert_eq!(peripheral_name(0x4000_6404), "CAN1");
        assert_eq!(peripheral_name(0x4001_2304), "ADC1/2/3");
        assert_eq!(peripheral_name(0x4000_2400), "no peripheral");
    }

    #[test]
    fn the_unique_id_and_flash_size_read_from_system_memory() {
        let mut chip = Chip::new(SimFlash::new(1), [0x11, 0x22, 0x33]);
        assert_eq!(chip.read(0x1FFF_7A10, Size::Word, 0), Ok(0x11));
        assert_eq!(chip.read(0x1FFF_7A18, Size::Word, 0), Ok(0x33));
        assert_eq!(chip.read(0x1FFF_7A22, Size::Half, 0), Ok(512));
        assert!(matches!(
            chip.read(0x1FFF_0000, Size::Word, 0),
            Err(BusError::Unmodelled(_))
        ));
    }

    #[test]
    fn an_unmodelled_peripheral_is_reported_by_name() {
        let mut chip = Chip::new(SimFlash::new(1), [0; 3]);
        match chip.read(0x4001_1004, Size::Word, 0) {
            Err(BusError::Unmodelled(what)) => {
                assert!(what.starts_with("USART1 at 0x40011004"), "{what}")
            }
            other => panic!("{other:?}"),
        }
        match chip.read(0x4000_6400, Size::Word, 0) {
            Err(BusError::Unmodelled(what)) => assert!(what.contains("clock disabled"), "{what}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_flash_is_programmed_through_the_interface_and_stalls_the_core() {
        let mut chip = Chip::new(SimFlash::new(1), [0; 3]);
        let target = 0x0800_8000;
        chip.write(target, Size::Word, 0x1234_5678, 0).unwrap();
        assert_eq!(
            chip.read(target, Size::Word, 0),
            Ok(0xFFFF_FFFF),
            "locked: nothing written"
        );
        assert_ne!(
            chip.read(0x4002_3C0C, Size::Word, 0).unwrap() & (1 << 7),
            0,
            "PGSERR"
        );
        chip.write(0x4002_3C04, Size::Word, 0x4567_0123, 0).unwrap();
        chip.write(0x4002_3C04, Size::Word, 0xCDEF_89AB, 0).unwrap();
        chip.write(0x4002_3C10, Size::Word, 0x201, 0).unwrap(); // PG, PSIZE x32
        chip.write(target, Size::Word, 0x1234_5678, 0).unwrap();
        assert_eq!(chip.read(target, Size::Word, 0), Ok(0x1234_5678));
        assert_eq!(chip.pending.stall, Duration::from_micros(16));
        assert_eq!(chip.pending.code_changed, Some(target..target + 4));
        // A wrong key: a bus error, and locked until reset.
        chip.write(0x4002_3C10, Size::Word, 1 << 31, 0).unwrap();
        assert_eq!(
            chip.write(0x4002_3C04, Size::Word, 0x1111, 0),
            Err(BusError::Fault)
        );
    }
}
