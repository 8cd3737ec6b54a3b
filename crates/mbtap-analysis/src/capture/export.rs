//! Wireshark export: the rebuilt frames as pcapng with link type 252
//! (LINKTYPE_WIRESHARK_UPPER_PDU). Each packet starts with exported-PDU tags naming the
//! `mbrtu` dissector and TCP ports that mark direction — client port → 502 for requests,
//! 502 → client port for responses — so plain `tshark -r FILE` decodes every frame as Modbus
//! RTU, and `-o mbrtu.tcp.port:502` also classifies echo-shaped frames as query or response.
//!
//! Two kinds of valid frames are the exception: Wireshark's `mbrtu` dissector refuses address
//! 0 (to avoid mistaking Modbus/TCP for RTU) and frames under 5 bytes (the 4-byte requests of
//! 07, 0B, 0C and 11). Those go out as Modbus/TCP (`mbtcp`: an MBAP header and the PDU, no
//! CRC) — decoded, with unit and function, instead of shown as raw data.
//!
//! Tag layout (Wireshark `epan/exported_pdu.h`): u16 tag, u16 length, value padded to 32 bits,
//! all big-endian; the list ends with tag 0, length 0.

use std::io::{self, Write};

use super::LINKTYPE_WIRESHARK_UPPER_PDU;
use super::writer::PcapNgWriter;
use crate::chunk::Timestamp;
use crate::pairing::Role;
use mbtap_proto::{crc16, encode_tcp, parse_ascii};

const TAG_END: u16 = 0;
const TAG_PROTO_NAME: u16 = 12;
const TAG_PORT_TYPE: u16 = 24;
const TAG_SRC_PORT: u16 = 25;
const TAG_DST_PORT: u16 = 26;
/// Wireshark's `port_type` value for TCP.
const PT_TCP: u32 = 2;
/// The Modbus/TCP port (Modbus Messaging on TCP/IP v1.0b §4.1.1: 502).
pub const SERVER_PORT: u32 = 502;
/// The client side of the made-up connection.
pub const CLIENT_PORT: u32 = 50_200;

fn tag(b: &mut Vec<u8>, t: u16, value: &[u8]) {
    let padded = value.len().div_ceil(4) * 4;
    b.extend_from_slice(&t.to_be_bytes());
    b.extend_from_slice(&u16::try_from(padded).unwrap_or(u16::MAX).to_be_bytes());
    b.extend_from_slice(value);
    b.resize(b.len() + (padded - value.len()), 0);
}

/// Writes frames for Wireshark.
#[derive(Debug)]
pub struct WiresharkExport<W: Write> {
    w: PcapNgWriter<W>,
    packet: Vec<u8>,
    pub frames: u64,
}

impl<W: Write> WiresharkExport<W> {
    /// Starts the file.
    ///
    /// # Errors
    /// I/O errors.
    pub fn new(out: W) -> io::Result<Self> {
        let mut w = PcapNgWriter::new(out)?;
        w.add_interface(
            u16::try_from(LINKTYPE_WIRESHARK_UPPER_PDU).unwrap_or(252),
            "mbtap-export",
            "Modbus RTU frames rebuilt by mbtap",
        )?;
        Ok(Self { w, packet: Vec::with_capacity(300), frames: 0 })
    }

    /// Writes one frame as on the wire. ASCII frames become their RTU equivalent (Wireshark
    /// has no Modbus ASCII dissector): address and PDU with a CRC computed over them — or the
    /// CRC deliberately inverted when the LRC failed, so the frame still shows as damaged.
    ///
    /// # Errors
    /// I/O errors.
    pub fn frame(&mut self, t: Timestamp, bytes: &[u8], role: Role, check_ok: bool) -> io::Result<()> {
        // The frame as RTU bytes.
        let mut rtu = Vec::with_capacity(bytes.len());
        if bytes.first() == Some(&b':') {
            // Not even hex: nothing Wireshark could decode; skip it.
            let Ok(a) = parse_ascii(bytes) else { return Ok(()) };
            rtu.push(a.unit());
            rtu.extend_from_slice(a.pdu());
            let crc = crc16(&rtu);
            rtu.extend_from_slice(&(if check_ok { crc } else { !crc }).to_le_bytes());
        } else {
            rtu.extend_from_slice(bytes);
        }
        // What Wireshark's mbrtu would refuse (see the module doc), when there is a valid PDU.
        let broadcast = check_ok && rtu.len() >= 4 && (rtu[0] == 0 || rtu.len() < 5);
        let p = &mut self.packet;
        p.clear();
        tag(p, TAG_PROTO_NAME, if broadcast { b"mbtcp" } else { b"mbrtu" });
        let ports = match role {
            Role::Request => Some((CLIENT_PORT, SERVER_PORT)),
            Role::Response => Some((SERVER_PORT, CLIENT_PORT)),
            Role::Unknown => None,
        };
        if let Some((src, dst)) = ports {
            tag(p, TAG_PORT_TYPE, &PT_TCP.to_be_bytes());
            tag(p, TAG_SRC_PORT, &src.to_be_bytes());
            tag(p, TAG_DST_PORT, &dst.to_be_bytes());
        }
        tag(p, TAG_END, &[]);
        if broadcast {
            let pdu = &rtu[1..rtu.len() - 2];
            let tid = u16::try_from(self.frames & 0xFFFF).unwrap_or(0);
            encode_tcp(tid, rtu[0], pdu, p);
        } else {
            p.extend_from_slice(&rtu);
        }
        self.frames += 1;
        self.w.write_packet(0, t, &self.packet)
    }

    /// Flushes and returns the writer.
    ///
    /// # Errors
    /// I/O errors.
    pub fn finish(mut self) -> io::Result<W> {
        self.w.flush()?;
        Ok(self.w.into_inner())
    }
}
