//! What the generated master asks and its slaves answer: one transaction of every kind the
//! generator mixes (reads, writes, exceptions, vendor functions, silence), and the CRC look-alikes
//! and CRC-`00` tails made on purpose.

use super::VENDOR_FC;
use crate::traffic::rng::Rng;
use mbtap_proto::{Request, Response};

/// Makes a register-read answer (`unit 03|04 count data… crc`) a CRC look-alike: its last data
/// byte is chosen so the CRC's high byte is `00`, which makes the frame one byte shorter valid
/// too (CRC-16/MODBUS: for a valid F ending in `00`, F without it checks). Other frames are left
/// as they are.
pub(super) fn make_lookalike(wire: &mut [u8]) {
    if wire.len() >= 7 && matches!(wire[1], 0x03 | 0x04) {
        crc_tail_zero(wire);
    }
}

/// Makes a frame's CRC end in `00` by choosing its last data byte (frames of at least five
/// bytes; CRC-16/MODBUS over one more byte is a bijection of that byte, so one value does).
pub(super) fn crc_tail_zero(wire: &mut [u8]) {
    let n = wire.len();
    if n < 5 {
        return;
    }
    for v in 0..=255u8 {
        wire[n - 3] = v;
        let crc = mbtap_proto::crc16(&wire[..n - 2]).to_le_bytes();
        if crc[1] == 0 {
            wire[n - 2..].copy_from_slice(&crc);
            return;
        }
    }
    // Not reached (one value always does); the frame stays valid whatever happens.
    let crc = mbtap_proto::crc16(&wire[..n - 2]).to_le_bytes();
    wire[n - 2..].copy_from_slice(&crc);
}

/// The vendor request and answer PDUs unit `unit` sends all day: lengths fixed by the unit,
/// contents drawn from `rng`.
pub(super) fn vendor_pdus(unit: u8, rng: &mut Rng) -> (Vec<u8>, Vec<u8>) {
    let (nq, na) = (2 + usize::from(unit % 5), 3 + usize::from(unit.wrapping_mul(7) % 10));
    let mut req = vec![VENDOR_FC];
    req.extend(rng.bytes(nq));
    let mut resp = vec![VENDOR_FC];
    resp.extend(rng.bytes(na));
    (req, resp)
}

/// One transaction of the poll mix: the request PDU and the response PDU (`None`: no answer).
// Encoding into a Vec fails only for data longer than a byte count allows; the mix never
// generates that, so the results are not inspected.
#[allow(unused_must_use)]
pub(super) fn transaction(rng: &mut Rng) -> (Vec<u8>, Option<Vec<u8>>) {
    let addr = u16::try_from(rng.below(400)).unwrap_or(0);
    let mut req = Vec::new();
    let mut resp = Vec::new();
    let kind = rng.below(20);
    let regs = |rng: &mut Rng, n: usize| rng.bytes(n * 2);
    let _ = match kind {
        0..=3 => {
            let q = u16::try_from(rng.range(1, 20)).unwrap_or(1);
            let data = regs(rng, usize::from(q));
            Request::ReadHoldingRegisters { address: addr, quantity: q }.encode(&mut req);
            Response::ReadHoldingRegisters { values: mbtap_proto::Registers::new(&data) }.encode(&mut resp)
        }
        4..=6 => {
            let q = u16::try_from(rng.range(1, 30)).unwrap_or(1);
            let data = regs(rng, usize::from(q));
            Request::ReadInputRegisters { address: addr, quantity: q }.encode(&mut req);
            Response::ReadInputRegisters { values: mbtap_proto::Registers::new(&data) }.encode(&mut resp)
        }
        7 | 8 => {
            let q = u16::try_from(rng.range(1, 40)).unwrap_or(1);
            let data = rng.bytes(mbtap_proto::data::bit_bytes(q));
            if kind == 7 {
                Request::ReadCoils { address: addr, quantity: q }.encode(&mut req);
                Response::ReadCoils { status: mbtap_proto::Bits::new(&data) }.encode(&mut resp)
            } else {
                Request::ReadDiscreteInputs { address: addr, quantity: q }.encode(&mut req);
                Response::ReadDiscreteInputs { status: mbtap_proto::Bits::new(&data) }.encode(&mut resp)
            }
        }
        9 => {
            let value = if rng.chance(0.5) { 0xFF00 } else { 0 };
            Request::WriteSingleCoil { address: addr, value }.encode(&mut req);
            Response::WriteSingleCoil { address: addr, value }.encode(&mut resp)
        }
        10 => {
            let value = u16::try_from(rng.below(65536)).unwrap_or(0);
            Request::WriteSingleRegister { address: addr, value }.encode(&mut req);
            Response::WriteSingleRegister { address: addr, value }.encode(&mut resp)
        }
        11 => {
            let q = u16::try_from(rng.range(1, 20)).unwrap_or(1);
            let data = rng.bytes(mbtap_proto::data::bit_bytes(q));
            Request::WriteMultipleCoils { address: addr, quantity: q, values: mbtap_proto::Bits::new(&data) }
                .encode(&mut req);
            Response::WriteMultipleCoils { address: addr, quantity: q }.encode(&mut resp)
        }
        12 => {
            let q = u16::try_from(rng.range(1, 10)).unwrap_or(1);
            let data = regs(rng, usize::from(q));
            Request::WriteMultipleRegisters { address: addr, quantity: q, values: mbtap_proto::Registers::new(&data) }
                .encode(&mut req);
            Response::WriteMultipleRegisters { address: addr, quantity: q }.encode(&mut resp)
        }
        13 => {
            let (rq, wq) = (u16::try_from(rng.range(1, 8)).unwrap_or(1), u16::try_from(rng.range(1, 8)).unwrap_or(1));
            let w = regs(rng, usize::from(wq));
            let r = regs(rng, usize::from(rq));
            Request::ReadWriteMultipleRegisters {
                read_address: addr,
                read_quantity: rq,
                write_address: addr + 10,
                write_quantity: wq,
                values: mbtap_proto::Registers::new(&w),
            }
            .encode(&mut req);
            Response::ReadWriteMultipleRegisters { values: mbtap_proto::Registers::new(&r) }.encode(&mut resp)
        }
        14 => {
            Request::MaskWriteRegister { address: addr, and_mask: 0xF2F2, or_mask: 0x0025 }.encode(&mut req);
            Response::MaskWriteRegister { address: addr, and_mask: 0xF2F2, or_mask: 0x0025 }.encode(&mut resp)
        }
        15 => {
            let n = usize::try_from(rng.range(0, 5)).unwrap_or(0);
            let data = regs(rng, n);
            Request::ReadFifoQueue { address: addr }.encode(&mut req);
            Response::ReadFifoQueue {
                fifo_count: u16::try_from(n).unwrap_or(0),
                values: mbtap_proto::Registers::new(&data),
            }
            .encode(&mut resp)
        }
        16 => {
            let objs = [0u8, 6, b'M', b'b', b'T', b'a', b'p', b'!', 1, 3, b'M', b'K', b'4'];
            Request::ReadDeviceIdentification { read_code: 1, object_id: 0 }.encode(&mut req);
            Response::ReadDeviceIdentification {
                read_code: 1,
                conformity_level: 1,
                more_follows: 0,
                next_object_id: 0,
                objects: mbtap_proto::DeviceObjects::from_raw(2, &objs),
            }
            .encode(&mut resp)
        }
        17 => match rng.below(5) {
            0 => {
                let echo = rng.bytes(4);
                Request::Diagnostics { sub_function: 0.into(), data: &echo }.encode(&mut req);
                Response::Diagnostics { sub_function: 0.into(), data: &echo }.encode(&mut resp)
            }
            1 => {
                Request::ReportServerId.encode(&mut req);
                Response::ReportServerId { data: &[0x17, 0xFF, b'M', b'K'] }.encode(&mut resp)
            }
            2 => {
                Request::GetCommEventCounter.encode(&mut req);
                Response::GetCommEventCounter { status: 0, event_count: 0x0108 }.encode(&mut resp)
            }
            3 => {
                Request::ReadExceptionStatus.encode(&mut req);
                Response::ReadExceptionStatus { status: 0x6D }.encode(&mut resp)
            }
            _ => {
                Request::Diagnostics { sub_function: 0x0B.into(), data: &[0, 0] }.encode(&mut req);
                Response::Diagnostics { sub_function: 0x0B.into(), data: &[0x01, 0x2C] }.encode(&mut resp)
            }
        },
        18 => {
            // An exception to a read of an address the device does not have.
            Request::ReadHoldingRegisters { address: 9000, quantity: 4 }.encode(&mut req);
            Response::Exception { function: 3, code: mbtap_proto::ExceptionCode::IllegalDataAddress }.encode(&mut resp)
        }
        _ => {
            let (nq, na) = (rng.range(2, 6), rng.range(3, 12));
            let q = rng.bytes(usize::try_from(nq).unwrap_or(2));
            let a = rng.bytes(usize::try_from(na).unwrap_or(3));
            Request::Other { function: VENDOR_FC, data: &q }.encode(&mut req);
            Response::Other { function: VENDOR_FC, data: &a }.encode(&mut resp)
        }
    };
    (req, Some(resp))
}
