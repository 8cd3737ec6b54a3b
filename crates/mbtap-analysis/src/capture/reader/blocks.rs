//! The blocks of the two formats: a pcap record, the pcapng blocks (section header, interface
//! description with its link type, description and comments, enhanced and simple packets), each
//! with its length checked before it is read.

use super::{CaptureReader, MAX_DESCRIPTION, MAX_INTERFACES, Next};
use crate::capture::clock::Clock;
use crate::capture::format::{
    EPB, FormatError, IDB, ISB, Interface, SHB, SPB, Step, parse_block, parse_epb, parse_idb, parse_isb,
    parse_pcap_record, parse_shb_endian, parse_spb, ticks_to_ns,
};
use nom::number::Endianness;
use std::io::Read;

impl<R: Read> CaptureReader<R> {
    pub(super) fn pcap_step(&mut self, endian: Endianness, nanos: bool) -> Result<Next, FormatError> {
        loop {
            match parse_pcap_record(&self.buf[self.start..self.end], endian)? {
                Step::Item(r, used) => {
                    let frac = if nanos { u64::from(r.ts_frac) } else { u64::from(r.ts_frac) * 1000 };
                    let t = u64::from(r.ts_sec) * 1_000_000_000 + frac;
                    let at = self.start + 16;
                    let len = r.data.len();
                    self.consume(used);
                    return Ok(self.packet(0, t, at, len));
                }
                Step::NeedMore(n) => {
                    if !self.need(n).map_err(|_| FormatError::Short { what: "pcap record" })? {
                        return Ok(self.truncated());
                    }
                }
            }
        }
    }

    pub(super) fn pcapng_step(&mut self) -> Result<Next, FormatError> {
        loop {
            let input = &self.buf[self.start..self.end];
            // A section header carries its own byte order.
            if input.len() >= 4 && u32::from_le_bytes([input[0], input[1], input[2], input[3]]) == SHB {
                match parse_shb_endian(input)? {
                    Step::Item(e, _) => {
                        self.endian = e;
                        self.interfaces.clear();
                        self.warned_linktype.clear();
                        self.clocks.clear();
                    }
                    Step::NeedMore(n) => {
                        if !self.need(n).map_err(|_| FormatError::Short { what: "section header" })? {
                            return Ok(self.truncated());
                        }
                        continue;
                    }
                }
            }
            let input = &self.buf[self.start..self.end];
            match parse_block(input, self.endian)? {
                Step::NeedMore(n) => {
                    if !self.need(n).map_err(|_| FormatError::Short { what: "block" })? {
                        return Ok(self.truncated());
                    }
                }
                Step::Item(block, used) => {
                    let body_at = self.start + 8;
                    let next = match block.block_type {
                        IDB => {
                            let iface = parse_idb(block.body, self.endian)?;
                            self.consume(used);
                            return Ok(self.add_interface(iface));
                        }
                        EPB | SPB => {
                            let p = if block.block_type == EPB {
                                parse_epb(block.body, self.endian)?
                            } else {
                                parse_spb(block.body, self.endian)?
                            };
                            let data_at = body_at + if block.block_type == EPB { 20 } else { 4 };
                            let len = p.data.len();
                            let iface = self.interfaces.get(p.interface as usize);
                            let t = match (p.ticks, iface) {
                                (Some(ticks), Some(i)) => ticks_to_ns(ticks, i.ticks_per_sec),
                                _ => self.clocks.get(p.interface as usize).and_then(|(c, _)| c.last_raw()).unwrap_or(0),
                            };
                            if iface.is_none() {
                                let id = p.interface;
                                self.consume(used);
                                self.undescribed_packets += 1;
                                if self.undescribed_packets > 1 {
                                    return Ok(Next::Continue);
                                }
                                return Ok(Next::Warning(format!(
                                    "packet at offset {} names interface {id}, which was never described: skipped (further ones are counted)",
                                    self.offset - used as u64
                                )));
                            }
                            let interface = p.interface;
                            self.consume(used);
                            self.packet(interface, t, data_at, len)
                        }
                        ISB => {
                            // A damaged statistics block costs nothing but its comment.
                            if let Ok((iface, comments)) = parse_isb(block.body, self.endian) {
                                self.note_observer(iface, &comments);
                            }
                            self.consume(used);
                            Next::Continue
                        }
                        // Section headers were handled above; name resolution, custom and
                        // unknown blocks carry nothing for us.
                        _ => {
                            self.consume(used);
                            Next::Continue
                        }
                    };
                    return Ok(next);
                }
            }
        }
    }

    pub(super) fn add_interface(&mut self, mut iface: Interface) -> Next {
        if self.interfaces.len() >= MAX_INTERFACES {
            // Memory must not follow a flood of descriptions; one more is said, not kept.
            self.dropped_interfaces += 1;
            if self.dropped_interfaces == 1 {
                return Next::Warning(format!(
                    "more than {MAX_INTERFACES} interfaces described (at offset {}): the rest are not kept and their packets are skipped",
                    self.offset
                ));
            }
            return Next::Continue;
        }
        for text in [&mut iface.name, &mut iface.description].into_iter().flatten() {
            if text.len() > MAX_DESCRIPTION {
                let mut cut = MAX_DESCRIPTION;
                while !text.is_char_boundary(cut) {
                    cut -= 1;
                }
                text.truncate(cut);
            }
        }
        let id = u32::try_from(self.interfaces.len()).unwrap_or(u32::MAX);
        self.interfaces.push(iface.clone());
        self.warned_linktype.push(false);
        self.clocks.push((Clock::default(), 0));
        Next::Interface(id, Box::new(iface))
    }

    /// Keeps the latency a recording session learned for `iface`, from its comments.
    pub(super) fn note_observer(&mut self, iface: u32, comments: &[String]) {
        let learned = comments
            .iter()
            .filter_map(|c| c.strip_prefix("mbtap observer "))
            .flat_map(str::split_whitespace)
            .find_map(|w| w.strip_prefix("latency_ns=").and_then(|v| v.parse::<u64>().ok()));
        if let Some(ns) = learned {
            self.recorded_latency.retain(|(i, _)| *i != iface);
            if self.recorded_latency.len() < MAX_INTERFACES {
                self.recorded_latency.push((iface, ns));
            }
        }
    }
}
