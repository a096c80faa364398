//! Why the MCU last reset, from the RCC's reset flags: logged at start-up, so a bench log
//! tells a watchdog reset (the control loop stalled) or a software reset (a panic or a
//! HardFault, see the log before it) from a power cycle.

/// The reset flags of RCC_CSR, as read at start-up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ResetFlags {
    /// LPWRRSTF: illegal entry into a low-power mode.
    pub low_power: bool,
    /// WWDGRSTF: window watchdog.
    pub window_watchdog: bool,
    /// WDGRSTF: independent watchdog.
    pub independent_watchdog: bool,
    /// SFTRSTF: software reset (SYSRESETREQ).
    pub software: bool,
    /// PORRSTF: power-on or power-down reset.
    pub power_on: bool,
    /// BORRSTF: brown-out.
    pub brown_out: bool,
    /// PINRSTF: the NRST pin.
    pub pin: bool,
}

/// The cause of the last reset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
pub enum ResetCause {
    /// Illegal entry into a low-power mode.
    LowPower,
    /// The window watchdog expired.
    WindowWatchdog,
    /// The independent watchdog expired: the control loop stopped feeding it.
    IndependentWatchdog,
    /// Software asked for it: a panic or HardFault (logged before it), or a reset request.
    Software,
    /// Power came up.
    PowerOn,
    /// The supply dipped below the brown-out level.
    BrownOut,
    /// The reset button or a debug probe pulled NRST low.
    Pin,
    /// No flag was set (the flags were cleared and nothing has reset since).
    Unknown,
}

impl ResetCause {
    /// The cause the flags record. Every internal reset also drives NRST low, so the pin
    /// flag comes with the others, and a power-on sets the brown-out flag as well: the most
    /// specific flag wins.
    pub fn from_flags(flags: ResetFlags) -> Self {
        if flags.low_power {
            Self::LowPower
        } else if flags.window_watchdog {
            Self::WindowWatchdog
        } else if flags.independent_watchdog {
            Self::IndependentWatchdog
        } else if flags.software {
            Self::Software
        } else if flags.power_on {
            Self::PowerOn
        } else if flags.brown_out {
            Self::BrownOut
        } else if flags.pin {
            Self::Pin
        } else {
            Self::Unknown
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_watchdog_reset_is_told_from_the_pin_flag_it_also_sets() {
        let flags = ResetFlags {
            independent_watchdog: true,
            pin: true,
            ..ResetFlags::default()
        };
        assert_eq!(
            ResetCause::from_flags(flags),
            ResetCause::IndependentWatchdog
        );
    }

    #[test]
    fn power_on_wins_over_the_brown_out_and_pin_flags_it_sets() {
        let flags = ResetFlags {
            power_on: true,
            brown_out: true,
            pin: true,
            ..ResetFlags::default()
        };
        assert_eq!(ResetCause::from_flags(flags), ResetCause::PowerOn);
    }

    #[test]
    fn a_software_reset_after_a_panic_is_reported_as_such() {
        let flags = ResetFlags {
            software: true,
            pin: true,
            ..ResetFlags::default()
        };
        assert_eq!(ResetCause::from_flags(flags), ResetCause::Software);
    }

    #[test]
    fn the_pin_alone_is_the_reset_button() {
        let flags = ResetFlags {
            pin: true,
            ..ResetFlags::default()
        };
        assert_eq!(ResetCause::from_flags(flags), ResetCause::Pin);
        assert_eq!(
            ResetCause::from_flags(ResetFlags::default()),
            ResetCause::Unknown
        );
    }
}
