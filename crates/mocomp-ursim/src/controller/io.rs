//! The controller's I/O as RTDE serves it: digital outputs set by a client through
//! `*_digital_output_mask` and `*_digital_output` (only the bits in the mask change), digital
//! inputs the world around the controller drives, and the two analog outputs.
//!
//! Bits of `actual_digital_output_bits` and `actual_digital_input_bits` (UR's RTDE guide): 0–7
//! standard, 8–15 configurable, 16–17 tool.

/// A bank of digital outputs a client can set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Bank {
    /// Standard outputs 0–7 (bits 0–7).
    Standard,
    /// Configurable outputs 0–7 (bits 8–15).
    Configurable,
    /// Tool outputs 0–1 (bits 16–17).
    Tool,
}

impl Bank {
    fn index(self) -> usize {
        match self {
            Bank::Standard => 0,
            Bank::Configurable => 1,
            Bank::Tool => 2,
        }
    }

    fn shift(self) -> u32 {
        8 * self.index() as u32
    }

    /// The bank's bits that exist.
    fn width_mask(self) -> u8 {
        match self {
            Bank::Tool => 0b11,
            Bank::Standard | Bank::Configurable => 0xff,
        }
    }
}

/// The I/O state.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Io {
    digital_out: u64,
    digital_in: u64,
    analog_out: [f64; 2],
    /// This package's mask and value per bank (applied together when the package ends: a
    /// recipe may name them in either order).
    pending: [(u8, Option<u8>); 3],
    analog_mask: u8,
    analog_pending: [Option<f64>; 2],
}

impl Io {
    /// A bank's mask from a data package.
    pub fn take_mask(&mut self, bank: Bank, mask: u8) {
        self.pending[bank.index()].0 = mask;
    }

    /// A bank's values from a data package.
    pub fn take_value(&mut self, bank: Bank, value: u8) {
        self.pending[bank.index()].1 = Some(value);
    }

    /// `standard_analog_output_mask`.
    pub fn take_analog_mask(&mut self, mask: u8) {
        self.analog_mask = mask;
    }

    /// `standard_analog_output_0` / `_1`.
    pub fn take_analog(&mut self, channel: usize, value: f64) {
        if let Some(slot) = self.analog_pending.get_mut(channel)
            && value.is_finite()
        {
            *slot = Some(value);
        }
    }

    /// Applies what a data package set: each output in its mask takes the package's value.
    pub fn finish_package(&mut self) {
        for bank in [Bank::Standard, Bank::Configurable, Bank::Tool] {
            let (mask, value) = std::mem::take(&mut self.pending[bank.index()]);
            if let Some(v) = value {
                let mask = u64::from(mask & bank.width_mask()) << bank.shift();
                let v = u64::from(v) << bank.shift();
                self.digital_out = (self.digital_out & !mask) | (v & mask);
            }
        }
        for (ch, pending) in self.analog_pending.iter_mut().enumerate() {
            if let Some(v) = pending.take()
                && self.analog_mask & (1 << ch) != 0
            {
                self.analog_out[ch] = v;
            }
        }
        self.analog_mask = 0;
    }

    /// `actual_digital_output_bits`.
    pub fn digital_outputs(&self) -> u64 {
        self.digital_out
    }

    /// `actual_digital_input_bits`.
    pub fn digital_inputs(&self) -> u64 {
        self.digital_in
    }

    /// Drives digital input `bit` (0–7 standard, 8–15 configurable, 16–17 tool) as the world
    /// around the controller does (a stimulator's trigger line, a button).
    pub fn set_digital_input(&mut self, bit: u32, on: bool) {
        if bit < 18 {
            if on {
                self.digital_in |= 1 << bit;
            } else {
                self.digital_in &= !(1 << bit);
            }
        }
    }

    /// `standard_analog_output0` / `1`.
    pub fn analog_output(&self, channel: usize) -> f64 {
        self.analog_out.get(channel).copied().unwrap_or(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_masked_outputs_change_and_the_order_in_the_package_does_not_matter() {
        let mut io = Io::default();
        io.take_mask(Bank::Standard, 0b1000_0001);
        io.take_value(Bank::Standard, 0b1111_1111);
        io.finish_package();
        assert_eq!(io.digital_outputs(), 0b1000_0001);
        // Value before mask in one package; output 7 off, the others untouched.
        io.take_value(Bank::Standard, 0b0000_0000);
        io.take_mask(Bank::Standard, 0b1000_0000);
        io.finish_package();
        assert_eq!(io.digital_outputs(), 0b0000_0001);
        // A package without the value changes nothing, whatever its mask.
        io.take_mask(Bank::Standard, 0xff);
        io.finish_package();
        assert_eq!(io.digital_outputs(), 0b0000_0001);
        // Configurable 2 is bit 10; the tool has two outputs only.
        io.take_mask(Bank::Configurable, 0b100);
        io.take_value(Bank::Configurable, 0b100);
        io.take_mask(Bank::Tool, 0xff);
        io.take_value(Bank::Tool, 0xff);
        io.finish_package();
        assert_eq!(io.digital_outputs(), 1 | (1 << 10) | (0b11 << 16));
    }

    #[test]
    fn inputs_are_driven_from_outside_and_analog_outputs_follow_their_mask() {
        let mut io = Io::default();
        io.set_digital_input(3, true);
        io.set_digital_input(17, true);
        io.set_digital_input(40, true);
        assert_eq!(io.digital_inputs(), (1 << 3) | (1 << 17));
        io.set_digital_input(3, false);
        assert_eq!(io.digital_inputs(), 1 << 17);
        io.take_analog_mask(0b10);
        io.take_analog(0, 0.5);
        io.take_analog(1, 0.25);
        io.finish_package();
        assert_eq!((io.analog_output(0), io.analog_output(1)), (0.0, 0.25));
    }
}
