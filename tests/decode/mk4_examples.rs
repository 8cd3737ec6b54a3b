//! Every RTU and ASCII example frame of the MK4 protocol document
//! (`shared/seeds/000_5832448cb8234b66.txt`, sections 3.1 to 4), as named, field-annotated
//! constants. Each must pass its check, decode to the values the document states, and
//! re-encode to exactly the same bytes.
//!
//! The document leaves the check of three examples as "xx xx" (§3.4 read of input registers
//! 400–402, and the §4 exception response); those constants carry the CRC/LRC we computed,
//! marked `computed, document says xx xx`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap_proto::{
    Bits, DecodedPdu, DirectionHint, ExceptionCode, Pdu, PduDecode, Request, Response, decode_pdu, encode_ascii,
    encode_rtu, parse_ascii, parse_rtu,
};

// ---- §3.1 Read Coils (01): 8 coils from 000 -------------------------------------------------
const RTU_READ_COILS_8_FROM_0_REQ: &[u8] = &[
    0x01, // address
    0x01, // function: Read Coils
    0x00, 0x00, // start address 000
    0x00, 0x08, // quantity 8
    0x3D, 0xCC, // CRC (low byte first)
];
const RTU_READ_COILS_8_FROM_0_RESP: &[u8] = &[
    0x01, // address
    0x01, // function
    0x01, // byte count
    0x02, // coils 007..000 = 0000_0010: coil 001 (motor M2) on
    0xD0, 0x49, // CRC
];
const ASCII_READ_COILS_8_FROM_0_REQ: &[u8] = b":010100000008F6\r\n"; // ':' 01 01 0000 0008 LRC F6 CRLF
const ASCII_READ_COILS_8_FROM_0_RESP: &[u8] = b":01010102FB\r\n"; // ':' 01 01 01 02 LRC FB CRLF

// ---- §3.1 Read Coils (01): one coil at 003 (agitator) ---------------------------------------
const RTU_READ_COIL_3_REQ: &[u8] = &[
    0x01, // address
    0x01, // function
    0x00, 0x03, // start address 003
    0x00, 0x01, // quantity 1
    0x0D, 0xCA, // CRC
];
const RTU_READ_COIL_3_RESP: &[u8] = &[
    0x01, // address
    0x01, // function
    0x01, // byte count
    0x00, // coil 003 off
    0x51, 0x88, // CRC
];
const ASCII_READ_COIL_3_REQ: &[u8] = b":010100030001FA\r\n";
const ASCII_READ_COIL_3_RESP: &[u8] = b":01010100FD\r\n";

// ---- §3.1 Write Single Coil (05): coil 003 on; the response echoes ---------------------------
const RTU_WRITE_COIL_3_ON: &[u8] = &[
    0x01, // address
    0x05, // function: Write Single Coil
    0x00, 0x03, // output address 003
    0xFF, 0x00, // value FF00 = on
    0x7C, 0x3A, // CRC
];
const ASCII_WRITE_COIL_3_ON: &[u8] = b":01050003FF00F8\r\n";

// ---- §3.2 Read Discrete Inputs (02): 3 inputs from 053 ---------------------------------------
const RTU_READ_INPUTS_3_FROM_53_REQ: &[u8] = &[
    0x01, // address
    0x02, // function: Read Discrete Inputs
    0x00, 0x35, // start address 053
    0x00, 0x03, // quantity 3
    0x28, 0x05, // CRC
];
const RTU_READ_INPUTS_3_FROM_53_RESP: &[u8] = &[
    0x01, // address
    0x02, // function
    0x01, // byte count
    0x02, // inputs 055..053 = 010: input 054 closed
    0x20, 0x49, // CRC
];
const ASCII_READ_INPUTS_3_FROM_53_REQ: &[u8] = b":010200350003C5\r\n";
const ASCII_READ_INPUTS_3_FROM_53_RESP: &[u8] = b":01020102FA\r\n";

// ---- §3.2 Read Discrete Inputs (02): 8 inputs from 050 ---------------------------------------
const RTU_READ_INPUTS_8_FROM_50_REQ: &[u8] = &[
    0x01, 0x02, // address, function
    0x00, 0x32, // start address 050
    0x00, 0x08, // quantity 8
    0xD8, 0x03, // CRC
];
const RTU_READ_INPUTS_8_FROM_50_RESP: &[u8] = &[
    0x01, 0x02, // address, function
    0x01, // byte count
    0x10, // inputs 057..050 = 0001_0000: input 054 closed
    0xA0, 0x44, // CRC
];
const ASCII_READ_INPUTS_8_FROM_50_REQ: &[u8] = b":010200320008C3\r\n";
const ASCII_READ_INPUTS_8_FROM_50_RESP: &[u8] = b":01020110EC\r\n";

// ---- §3.2 Read Discrete Inputs (02): 16 inputs from 050 --------------------------------------
const RTU_READ_INPUTS_16_FROM_50_REQ: &[u8] = &[
    0x01, 0x02, // address, function
    0x00, 0x32, // start address 050
    0x00, 0x10, // quantity 16
    0xD8, 0x09, // CRC
];
const RTU_READ_INPUTS_16_FROM_50_RESP: &[u8] = &[
    0x01, 0x02, // address, function
    0x02, // byte count
    0x10, // inputs 057..050
    0x40, // inputs 065..058 = 0100_0000: input 064 closed
    0xB5, 0x88, // CRC
];
const ASCII_READ_INPUTS_16_FROM_50_REQ: &[u8] = b":010200320010BB\r\n";
const ASCII_READ_INPUTS_16_FROM_50_RESP: &[u8] = b":0102021040AB\r\n";

// ---- §3.3 Read Holding Registers (03): 3 registers from 101 ----------------------------------
const RTU_READ_HOLDING_3_FROM_101_REQ: &[u8] = &[
    0x01, // address
    0x03, // function: Read Holding Registers
    0x00, 0x65, // start address 101
    0x00, 0x03, // quantity 3
    0x15, 0xD4, // CRC
];
const RTU_READ_HOLDING_3_FROM_101_RESP: &[u8] = &[
    0x01, 0x03, // address, function
    0x06, // byte count
    0x00, 0x00, // register 101 = 0
    0x00, 0x00, // register 102 = 0
    0x01, 0x90, // register 103 = 400
    0x20, 0x89, // CRC
];
const ASCII_READ_HOLDING_3_FROM_101_REQ: &[u8] = b":01030065000394\r\n";
const ASCII_READ_HOLDING_3_FROM_101_RESP: &[u8] = b":0103060000000001906 5\r\n";

// ---- §3.3 Write Single Register (06): register 108 = 10; the response echoes -----------------
const RTU_WRITE_REGISTER_108: &[u8] = &[
    0x01, // address
    0x06, // function: Write Single Register
    0x00, 0x6C, // register address 108
    0x00, 0x0A, // value 10
    0xC9, 0xD0, // CRC
];
const ASCII_WRITE_REGISTER_108: &[u8] = b":0106006C000A83\r\n";

// ---- §3.3 Write Multiple Registers (10): 5 registers from 101 = 0, 0, 400, 300, 10 ----------
const RTU_WRITE_5_FROM_101_REQ: &[u8] = &[
    0x01, // address
    0x10, // function: Write Multiple Registers
    0x00, 0x65, // start address 101
    0x00, 0x05, // quantity 5
    0x0A, // byte count 10
    0x00, 0x00, // 101 = 0
    0x00, 0x00, // 102 = 0
    0x01, 0x90, // 103 = 400
    0x01, 0x2C, // 104 = 300
    0x00, 0x0A, // 105 = 10
    0xE5, 0x63, // CRC
];
const RTU_WRITE_5_FROM_101_RESP: &[u8] = &[
    0x01, 0x10, // address, function
    0x00, 0x65, // start address 101
    0x00, 0x05, // quantity 5
    0x10, 0x15, // CRC
];
const ASCII_WRITE_5_FROM_101_REQ: &[u8] = b":0110006500050A000000000190012C000AB3\r\n";
const ASCII_WRITE_5_FROM_101_RESP: &[u8] = b":01100065000585\r\n";

// ---- §3.4 Read Input Registers (04): 3 registers from 400 = 2, 0, 4 --------------------------
const RTU_READ_INPUT_3_FROM_400_REQ: &[u8] = &[
    0x01, 0x04, // address, function: Read Input Registers
    0x01, 0x90, // start address 400
    0x00, 0x03, // quantity 3
    0xB1, 0xDA, // CRC computed, document says xx xx
];
const RTU_READ_INPUT_3_FROM_400_RESP: &[u8] = &[
    0x01, 0x04, // address, function
    0x06, // byte count
    0x00, 0x02, // 400 = 2
    0x00, 0x00, // 401 = 0
    0x00, 0x04, // 402 = 4
    0x18, 0x90, // CRC computed, document says xx xx
];
const ASCII_READ_INPUT_3_FROM_400_REQ: &[u8] = b":010401900003 67\r\n"; // LRC computed, document says xx xx
const ASCII_READ_INPUT_3_FROM_400_RESP: &[u8] = b":010406000200000004 EF\r\n"; // LRC computed, document says xx xx

// ---- §4 Exceptions: 6 registers from 18 → exception 03 ---------------------------------------
const RTU_EXCEPTION_REQ: &[u8] = &[
    0x01, 0x03, // address, function
    0x00, 0x12, // start address 18
    0x00, 0x06, // quantity 6
    0x65, 0xCD, // CRC
];
const RTU_EXCEPTION_RESP: &[u8] = &[
    0x01, // address
    0x83, // function 03 | 0x80
    0x03, // exception 03: illegal data value
    0x01, 0x31, // CRC computed, document says XX XX
];

/// Strips the spaces some constants keep to show where the LRC starts.
fn ascii(chars: &[u8]) -> Vec<u8> {
    chars.iter().copied().filter(|&c| c != b' ').collect()
}

/// Parses a frame (RTU or ASCII), asserts its check and that it re-encodes byte-exact, and
/// returns (unit, PDU).
fn frame(wire: &[u8]) -> (u8, Vec<u8>) {
    if wire.first() == Some(&b':') {
        let wire = ascii(wire);
        let f = parse_ascii(&wire).unwrap();
        assert!(f.check_ok(), "LRC of {:?}", String::from_utf8_lossy(&wire));
        let mut again = Vec::new();
        encode_ascii(f.unit(), f.pdu(), &mut again);
        assert_eq!(again, wire);
        (f.unit(), f.pdu().to_vec())
    } else {
        let f = parse_rtu(wire).unwrap();
        assert!(f.check_ok(), "CRC of {wire:02X?}");
        let mut again = Vec::new();
        encode_rtu(f.unit, f.pdu, &mut again);
        assert_eq!(again, wire);
        (f.unit, f.pdu.to_vec())
    }
}

fn request(pdu: &[u8]) -> Request<'_> {
    match decode_pdu(pdu, DirectionHint::Request) {
        PduDecode::One(DecodedPdu { pdu: Pdu::Request(r), trailing: [], findings }) if findings.is_empty() => r,
        other => panic!("{other:?}"),
    }
}

fn response(pdu: &[u8]) -> Response<'_> {
    match decode_pdu(pdu, DirectionHint::Response) {
        PduDecode::One(DecodedPdu { pdu: Pdu::Response(r), trailing: [], findings }) if findings.is_empty() => r,
        other => panic!("{other:?}"),
    }
}

fn registers(r: &Response<'_>) -> Vec<u16> {
    match r {
        Response::ReadHoldingRegisters { values } | Response::ReadInputRegisters { values } => values.iter().collect(),
        other => panic!("{other:?}"),
    }
}

#[test]
fn read_coils_8_from_0() {
    for (req, resp) in [
        (RTU_READ_COILS_8_FROM_0_REQ, RTU_READ_COILS_8_FROM_0_RESP),
        (ASCII_READ_COILS_8_FROM_0_REQ, ASCII_READ_COILS_8_FROM_0_RESP),
    ] {
        let (unit, pdu) = frame(req);
        assert_eq!(unit, 1);
        assert_eq!(request(&pdu), Request::ReadCoils { address: 0, quantity: 8 });
        let (_, pdu) = frame(resp);
        let Response::ReadCoils { status } = response(&pdu) else { panic!() };
        assert_eq!(status.iter(8).collect::<Vec<_>>(), [false, true, false, false, false, false, false, false]);
    }
}

#[test]
fn read_coil_3() {
    for (req, resp) in [(RTU_READ_COIL_3_REQ, RTU_READ_COIL_3_RESP), (ASCII_READ_COIL_3_REQ, ASCII_READ_COIL_3_RESP)] {
        let (_, pdu) = frame(req);
        assert_eq!(request(&pdu), Request::ReadCoils { address: 3, quantity: 1 });
        let (_, pdu) = frame(resp);
        assert_eq!(response(&pdu), Response::ReadCoils { status: Bits::new(&[0x00]) });
    }
}

#[test]
fn write_coil_3_on_echoes() {
    for wire in [RTU_WRITE_COIL_3_ON, ASCII_WRITE_COIL_3_ON] {
        let (_, pdu) = frame(wire);
        assert_eq!(request(&pdu), Request::WriteSingleCoil { address: 3, value: 0xFF00 });
        assert_eq!(response(&pdu), Response::WriteSingleCoil { address: 3, value: 0xFF00 });
        assert!(matches!(decode_pdu(&pdu, DirectionHint::Unknown), PduDecode::Either { .. }));
    }
}

#[test]
fn read_discrete_inputs() {
    type Case<'a> = (&'a [u8], &'a [u8], u16, u16, &'a [u8]);
    let cases: [Case<'_>; 6] = [
        (RTU_READ_INPUTS_3_FROM_53_REQ, RTU_READ_INPUTS_3_FROM_53_RESP, 53, 3, &[0x02]),
        (ASCII_READ_INPUTS_3_FROM_53_REQ, ASCII_READ_INPUTS_3_FROM_53_RESP, 53, 3, &[0x02]),
        (RTU_READ_INPUTS_8_FROM_50_REQ, RTU_READ_INPUTS_8_FROM_50_RESP, 50, 8, &[0x10]),
        (ASCII_READ_INPUTS_8_FROM_50_REQ, ASCII_READ_INPUTS_8_FROM_50_RESP, 50, 8, &[0x10]),
        (RTU_READ_INPUTS_16_FROM_50_REQ, RTU_READ_INPUTS_16_FROM_50_RESP, 50, 16, &[0x10, 0x40]),
        (ASCII_READ_INPUTS_16_FROM_50_REQ, ASCII_READ_INPUTS_16_FROM_50_RESP, 50, 16, &[0x10, 0x40]),
    ];
    for (req, resp, address, quantity, status) in cases {
        let (_, pdu) = frame(req);
        assert_eq!(request(&pdu), Request::ReadDiscreteInputs { address, quantity });
        let (_, pdu) = frame(resp);
        assert_eq!(response(&pdu), Response::ReadDiscreteInputs { status: Bits::new(status) });
    }
}

#[test]
fn read_holding_3_from_101() {
    for (req, resp) in [
        (RTU_READ_HOLDING_3_FROM_101_REQ, RTU_READ_HOLDING_3_FROM_101_RESP),
        (ASCII_READ_HOLDING_3_FROM_101_REQ, ASCII_READ_HOLDING_3_FROM_101_RESP),
    ] {
        let (_, pdu) = frame(req);
        assert_eq!(request(&pdu), Request::ReadHoldingRegisters { address: 101, quantity: 3 });
        let (_, pdu) = frame(resp);
        assert_eq!(registers(&response(&pdu)), [0, 0, 400]);
    }
}

#[test]
fn write_register_108_echoes() {
    for wire in [RTU_WRITE_REGISTER_108, ASCII_WRITE_REGISTER_108] {
        let (_, pdu) = frame(wire);
        assert_eq!(request(&pdu), Request::WriteSingleRegister { address: 108, value: 10 });
        assert_eq!(response(&pdu), Response::WriteSingleRegister { address: 108, value: 10 });
    }
}

#[test]
fn write_5_from_101() {
    for (req, resp) in [
        (RTU_WRITE_5_FROM_101_REQ, RTU_WRITE_5_FROM_101_RESP),
        (ASCII_WRITE_5_FROM_101_REQ, ASCII_WRITE_5_FROM_101_RESP),
    ] {
        let (_, pdu) = frame(req);
        let Request::WriteMultipleRegisters { address: 101, quantity: 5, values } = request(&pdu) else { panic!() };
        assert_eq!(values.iter().collect::<Vec<_>>(), [0, 0, 400, 300, 10]);
        let (_, pdu) = frame(resp);
        assert_eq!(response(&pdu), Response::WriteMultipleRegisters { address: 101, quantity: 5 });
    }
}

#[test]
fn read_input_3_from_400() {
    for (req, resp) in [
        (RTU_READ_INPUT_3_FROM_400_REQ, RTU_READ_INPUT_3_FROM_400_RESP),
        (ASCII_READ_INPUT_3_FROM_400_REQ, ASCII_READ_INPUT_3_FROM_400_RESP),
    ] {
        let (_, pdu) = frame(req);
        assert_eq!(request(&pdu), Request::ReadInputRegisters { address: 400, quantity: 3 });
        let (_, pdu) = frame(resp);
        assert_eq!(registers(&response(&pdu)), [2, 0, 4]);
    }
}

#[test]
fn exception_illegal_data_value() {
    let (_, pdu) = frame(RTU_EXCEPTION_REQ);
    assert_eq!(request(&pdu), Request::ReadHoldingRegisters { address: 18, quantity: 6 });
    let (_, pdu) = frame(RTU_EXCEPTION_RESP);
    assert_eq!(response(&pdu), Response::Exception { function: 3, code: ExceptionCode::IllegalDataValue });
    assert!(matches!(
        decode_pdu(&pdu, DirectionHint::Unknown),
        PduDecode::One(DecodedPdu { pdu: Pdu::Response(_), .. })
    ));
}

/// A single flipped bit anywhere in any example must fail its check.
#[test]
fn every_single_bit_flip_fails_the_check() {
    let rtu: [&[u8]; 5] = [
        RTU_READ_COILS_8_FROM_0_REQ,
        RTU_READ_HOLDING_3_FROM_101_RESP,
        RTU_WRITE_5_FROM_101_REQ,
        RTU_EXCEPTION_RESP,
        RTU_READ_INPUT_3_FROM_400_RESP,
    ];
    for wire in rtu {
        for bit in 0..wire.len() * 8 {
            let mut bad = wire.to_vec();
            bad[bit / 8] ^= 1 << (bit % 8);
            assert!(!parse_rtu(&bad).unwrap().check_ok(), "{bad:02X?}");
        }
    }
}
