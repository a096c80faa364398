//! Vehicle identification numbers: 17 characters (ISO 3779), digits and capital letters
//! but I, O and Q (they read as 1 and 0), with a check digit in position 9 computed as
//! 49 CFR 565.15 prescribes (North America; a VIN from elsewhere may have none, which the
//! fleet would refuse: every vehicle of an AutoPlug fleet carries a checked VIN).
//!
//! The check: each character is transliterated to a number (digits as they are, letters
//! by the table of 565.15(c)), multiplied by the weight of its position, and the sum taken
//! modulo 11; a remainder of 10 is written `X`.
//!
//! `no_std`: an ECU holds its vehicle's VIN and answers it over UDS (DID F190).
#![no_std]
#![deny(missing_docs)]

use core::fmt;

/// Characters in a VIN.
pub const VIN_LEN: usize = 17;
/// The check digit's position (0-based).
pub const CHECK_DIGIT_INDEX: usize = 8;

/// The weights of the 17 positions (49 CFR 565.15(d)); the check digit's own is 0.
const WEIGHTS: [u32; VIN_LEN] = [8, 7, 6, 5, 4, 3, 2, 10, 0, 9, 8, 7, 6, 5, 4, 3, 2];

/// A checked VIN.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Vin([u8; VIN_LEN]);

/// Why a text is not a VIN.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VinError {
    /// Not 17 characters.
    Length(usize),
    /// A character a VIN cannot hold (position from 1, as VINs are read).
    Character {
        /// Position, from 1.
        position: usize,
        /// The character.
        found: char,
    },
    /// The check digit does not match the other 16 characters.
    CheckDigit {
        /// What the other characters give.
        expected: char,
        /// What position 9 holds.
        found: char,
    },
}

impl fmt::Display for VinError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            VinError::Length(n) => write!(f, "a VIN has 17 characters, not {n}"),
            VinError::Character { position, found } => write!(
                f,
                "character {position} of a VIN cannot be '{}' (digits and capital letters but I, O, Q)",
                found.escape_default()
            ),
            VinError::CheckDigit { expected, found } => write!(
                f,
                "the check digit (character 9) is '{found}', the other characters give '{expected}'"
            ),
        }
    }
}

/// The number a character stands for in the check (49 CFR 565.15(c)); `None` if a VIN
/// cannot hold it.
fn value(c: u8) -> Option<u32> {
    Some(match c {
        b'0'..=b'9' => u32::from(c - b'0'),
        b'A' | b'J' => 1,
        b'B' | b'K' | b'S' => 2,
        b'C' | b'L' | b'T' => 3,
        b'D' | b'M' | b'U' => 4,
        b'E' | b'N' | b'V' => 5,
        b'F' | b'W' => 6,
        b'G' | b'P' | b'X' => 7,
        b'H' | b'Y' => 8,
        b'R' | b'Z' => 9,
        _ => return None,
    })
}

/// The check digit of 17 characters that are all valid (the ninth is not counted).
fn check_digit(chars: &[u8; VIN_LEN]) -> u8 {
    let sum: u32 = chars
        .iter()
        .zip(WEIGHTS)
        .map(|(&c, w)| value(c).unwrap_or(0) * w)
        .sum();
    match sum % 11 {
        10 => b'X',
        r => b'0' + r as u8,
    }
}

fn checked_chars(bytes: &[u8]) -> Result<[u8; VIN_LEN], VinError> {
    let chars: [u8; VIN_LEN] = bytes
        .try_into()
        .map_err(|_| VinError::Length(bytes.len()))?;
    for (i, &c) in chars.iter().enumerate() {
        if value(c).is_none() {
            return Err(VinError::Character {
                position: i + 1,
                found: char::from(c),
            });
        }
    }
    Ok(chars)
}

impl Vin {
    /// A VIN from its text (exactly 17 characters: no spaces, capitals only), check digit
    /// verified.
    pub fn parse(text: &str) -> Result<Self, VinError> {
        if text.chars().count() != text.len() {
            // Multi-byte characters: name the first one and its position.
            if let Some((position, found)) = text
                .chars()
                .enumerate()
                .find(|(_, c)| !c.is_ascii())
                .map(|(i, c)| (i + 1, c))
            {
                return Err(VinError::Character { position, found });
            }
        }
        Self::from_bytes(text.as_bytes())
    }

    /// A VIN as an ECU stores it (17 ASCII bytes), check digit verified.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, VinError> {
        let chars = checked_chars(bytes)?;
        let expected = check_digit(&chars);
        let found = chars[CHECK_DIGIT_INDEX];
        if found != expected {
            return Err(VinError::CheckDigit {
                expected: char::from(expected),
                found: char::from(found),
            });
        }
        Ok(Self(chars))
    }

    /// Completes 17 characters whose ninth is a placeholder with their check digit (to
    /// make VINs, e.g. for a simulated fleet).
    pub fn with_check_digit(text: &str) -> Result<Self, VinError> {
        let mut chars = checked_chars(text.as_bytes())?;
        chars[CHECK_DIGIT_INDEX] = check_digit(&chars);
        Ok(Self(chars))
    }

    /// The 17 characters.
    pub fn as_bytes(&self) -> &[u8; VIN_LEN] {
        &self.0
    }

    /// The VIN as text.
    pub fn as_str(&self) -> &str {
        // Only ASCII digits and capitals are ever stored.
        core::str::from_utf8(&self.0).unwrap_or("")
    }

    /// The world manufacturer identifier (characters 1 to 3).
    pub fn wmi(&self) -> &str {
        &self.as_str()[..3]
    }

    /// The serial part (characters 12 to 17).
    pub fn serial(&self) -> &str {
        &self.as_str()[11..]
    }
}

impl fmt::Display for Vin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl fmt::Debug for Vin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Vin({})", self.as_str())
    }
}

impl core::str::FromStr for Vin {
    type Err = VinError;

    fn from_str(text: &str) -> Result<Self, VinError> {
        Self::parse(text)
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use proptest::prelude::*;
    use std::string::ToString;

    #[test]
    fn published_vins_check() {
        // The worked example of the check digit in 49 CFR 565 commentary and references
        // (its remainder is 10: X), and a VIN of all ones (check digit 1).
        for text in ["1M8GDM9AXKP042788", "11111111111111111"] {
            let vin = Vin::parse(text).unwrap();
            assert_eq!(vin.as_str(), text);
            assert_eq!(vin.to_string(), text);
        }
        let vin = Vin::parse("1M8GDM9AXKP042788").unwrap();
        assert_eq!(vin.wmi(), "1M8");
        assert_eq!(vin.serial(), "042788");
    }

    #[test]
    fn each_error_names_what_was_wrong() {
        assert_eq!(Vin::parse("1M8GDM9AXKP04278"), Err(VinError::Length(16)));
        assert_eq!(
            Vin::parse("1M8GDM9AXKP0427O8"),
            Err(VinError::Character {
                position: 16,
                found: 'O'
            })
        );
        assert_eq!(
            Vin::parse("1m8GDM9AXKP042788"),
            Err(VinError::Character {
                position: 2,
                found: 'm'
            })
        );
        assert_eq!(
            Vin::parse("1M8GDM9A9KP042788"),
            Err(VinError::CheckDigit {
                expected: 'X',
                found: '9'
            })
        );
        assert_eq!(
            Vin::parse("1M8GDM9AXKP04278é"),
            Err(VinError::Character {
                position: 17,
                found: 'é'
            })
        );
        let text = Vin::parse("1M8GDM9A9KP042788").unwrap_err().to_string();
        assert!(
            text.contains("check digit") && text.contains("'X'"),
            "{text}"
        );
    }

    #[test]
    fn a_check_digit_is_made_for_a_new_vin() {
        let vin = Vin::with_check_digit("JA3AP00_0TK000001".replace('_', "0").as_str()).unwrap();
        assert!(Vin::parse(vin.as_str()).is_ok());
        assert_eq!(Vin::from_bytes(vin.as_bytes()), Ok(vin));
    }

    proptest! {
        /// Any 17 valid characters completed with their check digit parse back; changing
        /// any one other character (to another that transliterates differently) is caught.
        #[test]
        fn one_changed_character_is_caught(
            chars in proptest::collection::vec(proptest::sample::select(
                b"0123456789ABCDEFGHJKLMNPRSTUVWXYZ".to_vec()), VIN_LEN),
            position in 0usize..VIN_LEN,
            replacement in proptest::sample::select(b"0123456789ABCDEFGHJKLMNPRSTUVWXYZ".to_vec()),
        ) {
            let text: std::string::String = chars.iter().map(|&c| char::from(c)).collect();
            let vin = Vin::with_check_digit(&text).unwrap();
            prop_assert!(Vin::parse(vin.as_str()).is_ok());
            prop_assume!(position != CHECK_DIGIT_INDEX);
            let mut changed = *vin.as_bytes();
            prop_assume!(value(replacement) != value(changed[position]));
            changed[position] = replacement;
            // The weights are all below 11 and 11 is prime: one changed value always
            // changes the sum modulo 11.
            prop_assert!(Vin::from_bytes(&changed).is_err());
        }
    }
}
