//! A UART listening to the line at settings that may not be the sender's: the sender's
//! characters are turned into the bit stream the wire carries (idle high, a start bit, data bits
//! least significant first, optional parity, stop bits), and a receiver re-samples that stream at
//! its own baud rate and format — so a listener at the wrong baud rate or parity gets the garbage,
//! framing and parity errors a real one would. Pure: times are nanoseconds on the line.
//!
//! The receiver behaves like a 16550-class UART: it waits for the line to go low, checks the
//! start bit half a bit later (a glitch shorter than that is ignored), then samples each bit in
//! its middle. A low stop bit is a framing error; a wrong parity bit a parity error. Bytes with
//! either error are delivered as NUL, as Linux delivers them to a raw-mode port that checks
//! parity without `IGNPAR` or `PARMRK` (termios(3), `INPCK`).

use mbtap_analysis::framer::{LineSettings, Parity};

use super::bus::LineFrame;

/// One character as the listener's UART delivered it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Received {
    /// When its last stop bit was sampled (ns on the line).
    pub t_ns: u64,
    pub byte: u8,
    pub framing_error: bool,
    pub parity_error: bool,
}

/// A receiver listening to a sender: both line settings, and where the receiver is.
#[derive(Debug, Clone)]
pub struct UartListener {
    sender: LineSettings,
    receiver: LineSettings,
    /// The receiver hunts for a start bit from this time on.
    ready_ns: u64,
    /// The low (0) stretches of the frame being heard, in time order.
    lows: Vec<(u64, u64)>,
}

impl UartListener {
    #[must_use]
    pub fn new(sender: LineSettings, receiver: LineSettings) -> Self {
        Self { sender, receiver, ready_ns: 0, lows: Vec::new() }
    }

    /// Hears one frame (the sender's characters back to back, ending at `frame.end_ns`).
    pub fn hear(&mut self, frame: &LineFrame) -> Vec<Received> {
        self.lows.clear();
        let char_ns = self.sender.char_ns();
        let chars = u64::try_from(frame.bytes.len()).unwrap_or(u64::MAX);
        let start = frame.end_ns.saturating_sub(char_ns.saturating_mul(chars));
        for (i, &b) in (0u64..).zip(&frame.bytes) {
            self.add_character(start.saturating_add(char_ns.saturating_mul(i)), b);
        }
        let mut out = Vec::new();
        // Each character takes at least its start bit: bounded by the low stretches.
        while let Some(received) = self.next_character() {
            out.push(received);
        }
        out
    }

    /// The bit levels of one character starting at `at`, as low stretches.
    fn add_character(&mut self, at: u64, byte: u8) {
        let s = self.sender;
        let bit = bit_ns(s);
        let mut bits = Vec::with_capacity(12);
        bits.push(false); // start bit (Serial Line v1.02 §2.5.1: 1 start bit)
        let data = byte & data_mask(s.data_bits);
        for i in 0..s.data_bits {
            bits.push(data >> i & 1 == 1);
        }
        if let Some(p) = parity_bit(s.parity, data) {
            bits.push(p);
        }
        bits.extend(std::iter::repeat_n(true, usize::from(s.stop_bits)));
        for (i, level) in (0u64..).zip(bits) {
            if level {
                continue;
            }
            let from = at.saturating_add(bit.saturating_mul(i));
            let to = from.saturating_add(bit);
            match self.lows.last_mut() {
                Some(last) if last.1 == from => last.1 = to,
                _ => self.lows.push((from, to)),
            }
        }
    }

    fn is_low(&self, t: u64) -> bool {
        let i = self.lows.partition_point(|&(_, to)| to <= t);
        self.lows.get(i).is_some_and(|&(from, _)| from <= t)
    }

    /// The first time at or after `t` the line is low.
    fn next_low(&self, t: u64) -> Option<u64> {
        let i = self.lows.partition_point(|&(_, to)| to <= t);
        self.lows.get(i).map(|&(from, _)| from.max(t))
    }

    fn next_character(&mut self) -> Option<Received> {
        let r = self.receiver;
        let bit = bit_ns(r);
        loop {
            let edge = self.next_low(self.ready_ns)?;
            let mid_start = edge.saturating_add(bit / 2);
            if !self.is_low(mid_start) {
                // A glitch, not a start bit: hunt on.
                self.ready_ns = mid_start;
                continue;
            }
            let sample = |n: u64| !self.is_low(mid_start.saturating_add(bit.saturating_mul(n)));
            let mut data = 0u8;
            for i in 0..r.data_bits {
                if sample(u64::from(i) + 1) {
                    data |= 1 << i;
                }
            }
            let mut next = u64::from(r.data_bits) + 1;
            let parity_error = parity_bit(r.parity, data).is_some_and(|expected| {
                let got = sample(next);
                next += 1;
                got != expected
            });
            let mut framing_error = false;
            for _ in 0..r.stop_bits {
                framing_error |= !sample(next);
                next += 1;
            }
            let last_stop = mid_start.saturating_add(bit.saturating_mul(next - 1));
            // Ready for the next start bit from the middle of the last stop bit on.
            self.ready_ns = last_stop.saturating_add(1);
            let byte = if framing_error || parity_error { 0 } else { data };
            return Some(Received { t_ns: last_stop, byte, framing_error, parity_error });
        }
    }
}

/// How a listener hears the line: byte for byte at the sender's settings, or through a UART
/// at other settings.
#[derive(Debug, Clone)]
pub enum Listener {
    /// The right settings: each byte arrives when its last bit has (character time apart).
    Matched {
        char_ns: u64,
    },
    Mismatched(UartListener),
}

impl Listener {
    /// A listener at `receiver` settings on a line sent at `sender` settings.
    #[must_use]
    pub fn new(sender: LineSettings, receiver: LineSettings) -> Self {
        if sender == receiver {
            Self::Matched { char_ns: sender.char_ns() }
        } else {
            Self::Mismatched(UartListener::new(sender, receiver))
        }
    }

    /// The bytes of `frame` as this listener gets them, each with its arrival time (ns).
    pub fn hear(&mut self, frame: &LineFrame) -> Vec<(u64, u8)> {
        match self {
            Self::Matched { char_ns } => {
                let last = u64::try_from(frame.bytes.len().saturating_sub(1)).unwrap_or(0);
                (0u64..)
                    .zip(&frame.bytes)
                    .map(|(i, &b)| (frame.end_ns.saturating_sub(char_ns.saturating_mul(last - i)), b))
                    .collect()
            }
            Self::Mismatched(uart) => uart.hear(frame).into_iter().map(|r| (r.t_ns, r.byte)).collect(),
        }
    }
}

fn bit_ns(line: LineSettings) -> u64 {
    1_000_000_000 / u64::from(line.baud.max(1))
}

fn data_mask(bits: u8) -> u8 {
    u8::try_from((1u16 << bits.min(8)) - 1).unwrap_or(0xFF)
}

/// The parity bit for `data` (true = 1), or none.
fn parity_bit(parity: Parity, data: u8) -> Option<bool> {
    let odd_ones = data.count_ones() % 2 == 1;
    match parity {
        Parity::None => None,
        // Even parity: the bit makes the count of ones even.
        Parity::Even => Some(odd_ones),
        Parity::Odd => Some(!odd_ones),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(s: &str) -> LineSettings {
        s.parse().unwrap()
    }

    /// An MK4 read of the four voltages (unit 1, 04, 430, 4) with its CRC.
    const READ_VOLTAGES: [u8; 8] = [0x01, 0x04, 0x01, 0xAE, 0x00, 0x04, 0x50, 0x28];

    fn frame(settings: LineSettings) -> LineFrame {
        LineFrame { end_ns: 10_000_000 + settings.char_ns() * 8, bytes: READ_VOLTAGES.to_vec() }
    }

    #[test]
    fn the_right_settings_hear_every_byte_cleanly() {
        for s in ["19200 8E1", "9600 8N2", "115200 8N1", "9600 7E1", "1200 8O1"] {
            let settings = line(s);
            let mut uart = UartListener::new(settings, settings);
            let heard = uart.hear(&frame(settings));
            let mask = data_mask(settings.data_bits);
            let bytes: Vec<u8> = heard.iter().map(|r| r.byte).collect();
            let sent: Vec<u8> = READ_VOLTAGES.iter().map(|b| b & mask).collect();
            assert_eq!(bytes, sent, "{s}");
            assert!(heard.iter().all(|r| !r.framing_error && !r.parity_error), "{s}");
        }
    }

    #[test]
    fn a_bytes_time_is_its_last_stop_bit() {
        let settings = line("19200 8E1");
        let mut uart = UartListener::new(settings, settings);
        let heard = uart.hear(&frame(settings));
        // Middle of the stop bit: 10.5 bit times after the start of the first character.
        let first_start = 10_000_000;
        assert_eq!(heard[0].t_ns, first_start + bit_ns(settings) / 2 + 10 * bit_ns(settings));
    }

    #[test]
    fn the_wrong_parity_gives_parity_errors_and_nul_bytes() {
        let mut uart = UartListener::new(line("19200 8E1"), line("19200 8O1"));
        let heard = uart.hear(&frame(line("19200 8E1")));
        assert_eq!(heard.len(), 8);
        assert!(heard.iter().all(|r| r.parity_error && r.byte == 0));
    }

    #[test]
    fn no_parity_heard_by_an_even_parity_receiver_takes_the_stop_bit_for_parity() {
        // 8N1 sender, 8E1 receiver: the parity sample is the sender's stop bit (1), and the
        // receiver's stop sample falls on the idle line or the next start bit.
        let mut uart = UartListener::new(line("19200 8N1"), line("19200 8E1"));
        let heard = uart.hear(&frame(line("19200 8N1")));
        assert!(heard.iter().any(|r| r.framing_error || r.parity_error));
    }

    #[test]
    fn the_wrong_baud_rate_gives_garbage_and_framing_errors() {
        let sender = line("19200 8E1");
        let mut uart = UartListener::new(sender, line("9600 8E1"));
        let heard = uart.hear(&frame(sender));
        assert!(!heard.is_empty());
        let bytes: Vec<u8> = heard.iter().map(|r| r.byte).collect();
        assert_ne!(bytes, READ_VOLTAGES.to_vec());
        assert!(heard.iter().any(|r| r.framing_error || r.parity_error));
        // Twice the baud rate: a receiver too fast sees more characters than were sent.
        let mut fast = UartListener::new(sender, line("38400 8E1"));
        assert!(fast.hear(&frame(sender)).iter().any(|r| r.framing_error || r.parity_error));
    }

    #[test]
    fn a_matched_listener_gets_each_byte_a_character_apart() {
        let settings = line("19200 8E1");
        let mut listener = Listener::new(settings, settings);
        let heard = listener.hear(&frame(settings));
        assert_eq!(heard.iter().map(|h| h.1).collect::<Vec<_>>(), READ_VOLTAGES);
        assert_eq!(heard[7].0, 10_000_000 + 8 * settings.char_ns());
        assert_eq!(heard[6].0, heard[7].0 - settings.char_ns());
        assert!(matches!(Listener::new(settings, line("9600 8E1")), Listener::Mismatched(_)));
    }

    #[test]
    fn the_receiver_carries_on_across_frames() {
        let settings = line("9600 8N1");
        let mut uart = UartListener::new(settings, settings);
        let first = uart.hear(&frame(settings));
        let later = LineFrame { end_ns: 50_000_000, bytes: vec![0x55, 0xAA] };
        let second = uart.hear(&later);
        assert_eq!(first.len(), 8);
        assert_eq!(second.iter().map(|r| r.byte).collect::<Vec<_>>(), [0x55, 0xAA]);
    }

    #[test]
    fn any_settings_pair_ends_and_delivers_at_most_one_byte_per_start_bit() {
        let settings = ["1200 8N1", "9600 8E1", "19200 8N2", "115200 8N1", "9600 7E1", "256000 8O2"].map(line);
        for &s in &settings {
            for &r in &settings {
                let mut uart = UartListener::new(s, r);
                let heard = uart.hear(&frame(s));
                // A received character spans at least its bits but half of the last stop bit:
                // no more of them than fit in the frame's time (plus one started at its end).
                let frame_ns = 8 * s.char_ns();
                let min_char_ns = (u64::from(r.bits_per_char()) * 2 - 1) * bit_ns(r) / 2;
                assert!(heard.len() as u64 <= frame_ns / min_char_ns + 1, "{s} heard as {r}: {}", heard.len());
                assert!(heard.windows(2).all(|w| w[0].t_ns < w[1].t_ns), "{s} heard as {r}");
            }
        }
    }
}
