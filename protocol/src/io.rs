//! Digital inputs of a robot controller as the hardware-state message carries them: one bit mask,
//! `HwStateBody::digital_inputs`, laid out as a UR controller's RTDE output
//! `actual_digital_input_bits` (UINT64):
//!
//! | bits | inputs | name here |
//! | --- | --- | --- |
//! | 0-7 | standard inputs | `DI0`-`DI7` |
//! | 8-15 | configurable inputs | `CI0`-`CI7` |
//! | 16-17 | tool inputs | `TI0`-`TI1` |
//!
//! A touch-trigger probe is wired to one of them; `ips serve --trigger DI0` names it.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A bank of digital inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum InputBank {
    /// Standard inputs DI0-7, bits 0-7.
    Standard,
    /// Configurable inputs CI0-7, bits 8-15.
    Configurable,
    /// Tool inputs TI0-1, bits 16-17.
    Tool,
}

impl InputBank {
    fn prefix(self) -> &'static str {
        match self {
            InputBank::Standard => "DI",
            InputBank::Configurable => "CI",
            InputBank::Tool => "TI",
        }
    }

    /// The bank's first bit and how many inputs it has.
    fn layout(self) -> (u8, u8) {
        match self {
            InputBank::Standard => (0, 8),
            InputBank::Configurable => (8, 8),
            InputBank::Tool => (16, 2),
        }
    }
}

/// One digital input, e.g. `DI0`, `CI3`, `TI1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct DigitalInput {
    bank: InputBank,
    index: u8,
}

impl DigitalInput {
    /// Standard input DI0, where sim-robot wires its trigger probe unless told otherwise.
    pub const DI0: DigitalInput = DigitalInput {
        bank: InputBank::Standard,
        index: 0,
    };

    /// The input `index` of `bank`, if the bank has it.
    pub fn new(bank: InputBank, index: u8) -> Option<Self> {
        (index < bank.layout().1).then_some(Self { bank, index })
    }

    pub fn bank(self) -> InputBank {
        self.bank
    }

    /// Its bit in `digital_inputs` (0-17).
    pub fn bit(self) -> u8 {
        self.bank.layout().0 + self.index
    }

    /// Its mask in `digital_inputs`.
    pub fn mask(self) -> u64 {
        1 << self.bit()
    }

    /// Whether the input is high in the bit mask `digital_inputs`.
    pub fn is_high(self, digital_inputs: u64) -> bool {
        digital_inputs & self.mask() != 0
    }
}

impl fmt::Display for DigitalInput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}{}", self.bank.prefix(), self.index)
    }
}

/// Why a name is not a digital input.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{0}' is not a digital input: expected DI0-DI7, CI0-CI7 or TI0-TI1")]
pub struct NotAnInput(pub String);

impl FromStr for DigitalInput {
    type Err = NotAnInput;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        let refused = || NotAnInput(name.to_owned());
        let upper = name.trim().to_ascii_uppercase();
        let bank = [
            InputBank::Standard,
            InputBank::Configurable,
            InputBank::Tool,
        ]
        .into_iter()
        .find(|bank| upper.starts_with(bank.prefix()))
        .ok_or_else(refused)?;
        let digits = &upper[bank.prefix().len()..];
        // One digit only: "DI00" or "DI+1" are typos, not inputs.
        if digits.len() != 1 {
            return Err(refused());
        }
        let index = digits.parse::<u8>().map_err(|_| refused())?;
        DigitalInput::new(bank, index).ok_or_else(refused)
    }
}

impl Serialize for DigitalInput {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for DigitalInput {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let name = String::deserialize(deserializer)?;
        name.parse().map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_map_to_the_ur_bit_layout_and_back() {
        for (name, bit) in [("DI0", 0), ("DI7", 7), ("CI0", 8), ("CI3", 11), ("TI1", 17)] {
            let input: DigitalInput = name.parse().unwrap();
            assert_eq!(input.bit(), bit, "{name}");
            assert_eq!(input.to_string(), name);
        }
        assert_eq!("ti0".parse::<DigitalInput>().unwrap().bit(), 16);
        assert!(DigitalInput::DI0.is_high(0b1));
        assert!(!DigitalInput::DI0.is_high(0b10));
    }

    #[test]
    fn anything_else_is_refused_with_the_names_that_exist() {
        for bad in ["XYZ", "DI8", "TI2", "CI", "DI00", "DI-1", "", "D0"] {
            let error = bad.parse::<DigitalInput>().unwrap_err();
            assert!(error.to_string().contains("DI0-DI7"), "{bad}: {error}");
        }
    }

    #[test]
    fn serialises_as_its_name() {
        let json = serde_json::to_string(&DigitalInput::DI0).unwrap();
        assert_eq!(json, "\"DI0\"");
        assert!(serde_json::from_str::<DigitalInput>("\"TI7\"").is_err());
    }
}
