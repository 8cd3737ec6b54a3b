//! Corrupt input: truncated frames, bad CRC, bad LRC, bad hex, frames of 256+ bytes, and
//! length fields that lie. Each must give a precise error or a finding — never a panic.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap_proto::{
    AduError, DecodedPdu, DirectionHint, Finding, Mode, PduDecode, PduError, decode_pdu, parse_adu, parse_ascii,
    parse_request, parse_response, parse_rtu, parse_tcp, parse_tcp_frame,
};

/// MK4 §3.3 read request: unit 1, 03, address 0x0065, quantity 3, CRC 15 D4.
const READ_REQ: &[u8] = &[0x01, 0x03, 0x00, 0x65, 0x00, 0x03, 0x15, 0xD4];

#[test]
fn every_truncation_of_a_request_is_reported_not_panicked() {
    let pdu = &READ_REQ[1..6];
    for n in 0..pdu.len() {
        let err = parse_request(&pdu[..n]).unwrap_err();
        if n == 0 {
            assert_eq!(err, PduError::Empty);
        } else {
            assert_eq!(err, PduError::Truncated { function: 3, direction: "request", needed: 5, available: n });
        }
    }
}

#[test]
fn bad_crc_is_decoded_and_flagged() {
    let mut bad = READ_REQ.to_vec();
    bad[7] ^= 0xFF;
    let f = parse_rtu(&bad).unwrap();
    assert!(!f.check_ok());
    assert_eq!(f.crc_computed, 0xD415);
    assert_eq!(f.crc_received, 0x2B15);
}

#[test]
fn bad_lrc_is_decoded_and_flagged() {
    let f = parse_ascii(b":01030065000395\r\n").unwrap();
    assert!(!f.check_ok());
    assert_eq!((f.lrc_received(), f.lrc_computed), (0x95, 0x94));
}

#[test]
fn bad_hex_in_ascii_is_located() {
    assert_eq!(parse_ascii(b":0103006500039X\r\n"), Err(AduError::BadCharacter { position: 14, byte: b'X' }));
    assert_eq!(parse_ascii(b":01 03\r\n"), Err(AduError::BadCharacter { position: 3, byte: b' ' }));
    assert_eq!(parse_ascii(b":0103006\r\n"), Err(AduError::OddDigits { digits: 7 }));
    assert_eq!(parse_ascii(b"0103\r\n"), Err(AduError::MissingStart { found: b'0' }));
}

#[test]
fn rtu_frame_over_256_bytes_is_flagged_and_still_decoded() {
    // Unit 1, 0x41 (user-defined) with 300 data bytes: kept raw, flagged as too long.
    let mut pdu = vec![0x41];
    pdu.extend(std::iter::repeat_n(0xAB, 300));
    let mut wire = Vec::new();
    mbtap_proto::encode_rtu(1, &pdu, &mut wire);
    let adu = parse_adu(&wire, Some(Mode::Rtu)).unwrap();
    assert!(adu.check.ok());
    assert_eq!(adu.findings, vec![Finding::AduTooLong { len: 304, max: 256 }]);
}

#[test]
fn byte_count_larger_than_the_data_is_truncation() {
    // 03 response claiming 0xFA bytes with 2 present.
    assert_eq!(
        parse_response(&[0x03, 0xFA, 0x00, 0x01]),
        Err(PduError::Truncated { function: 3, direction: "response", needed: 252, available: 4 })
    );
}

#[test]
fn byte_count_smaller_than_the_data_leaves_trailing_bytes() {
    let PduDecode::One(DecodedPdu { trailing, findings, .. }) =
        decode_pdu(&[0x03, 0x02, 0x00, 0x01, 0x00, 0x02], DirectionHint::Response)
    else {
        panic!()
    };
    assert_eq!(trailing, &[0x00, 0x02]);
    assert_eq!(findings, vec![Finding::TrailingBytes { count: 2 }]);
}

#[test]
fn byte_count_disagreeing_with_quantity_is_a_finding() {
    // 0x10: address 0, quantity 2, byte count 2 (should be 4), one register.
    let PduDecode::One(DecodedPdu { findings, .. }) =
        decode_pdu(&[0x10, 0x00, 0x00, 0x00, 0x02, 0x02, 0x00, 0x07], DirectionHint::Request)
    else {
        panic!()
    };
    assert_eq!(findings, vec![Finding::ByteCountMismatch { field: "register", byte_count: 2, expected: 4 }]);
}

#[test]
fn quantity_limits_are_findings() {
    let cases: [(&[u8], Finding); 5] = [
        (&[0x01, 0, 0, 0x07, 0xD1], Finding::QuantityOutOfRange { field: "quantity", value: 2001, min: 1, max: 2000 }),
        (&[0x03, 0, 0, 0, 0], Finding::QuantityOutOfRange { field: "quantity", value: 0, min: 1, max: 125 }),
        (&[0x04, 0, 0, 0, 126], Finding::QuantityOutOfRange { field: "quantity", value: 126, min: 1, max: 125 }),
        (&[0x05, 0, 1, 0x12, 0x34], Finding::InvalidCoilValue { value: 0x1234 }),
        (&[0x03, 0xFF, 0xFF, 0, 2], Finding::AddressOverflow { address: 0xFFFF, quantity: 2 }),
    ];
    for (pdu, want) in cases {
        let PduDecode::One(DecodedPdu { findings, .. }) = decode_pdu(pdu, DirectionHint::Request) else { panic!() };
        assert_eq!(findings, vec![want], "{pdu:02X?}");
    }
}

#[test]
fn write_quantity_limits_include_0x17() {
    // 0x17 read 126, write 122 registers, byte count 0.
    let pdu = [0x17, 0, 0, 0, 126, 0, 0, 0, 122, 0];
    let PduDecode::One(DecodedPdu { findings, .. }) = decode_pdu(&pdu, DirectionHint::Request) else { panic!() };
    assert_eq!(
        findings,
        vec![
            Finding::QuantityOutOfRange { field: "quantity", value: 126, min: 1, max: 125 },
            Finding::QuantityOutOfRange { field: "quantity", value: 122, min: 1, max: 121 },
            Finding::ByteCountMismatch { field: "register", byte_count: 0, expected: 244 },
        ]
    );
}

#[test]
fn mbap_length_that_lies() {
    // Transaction 1, protocol 0, length 200, unit 1, PDU 03 00 00 00 01.
    let frame = [0, 1, 0, 0, 0, 200, 1, 3, 0, 0, 0, 1];
    assert_eq!(parse_tcp_frame(&frame), Ok(mbtap_proto::Streaming::Incomplete(206)));
    assert!(matches!(parse_tcp(&frame), Err(AduError::LengthMismatch { .. })));
    let zero = [0, 1, 0, 0, 0, 0, 1];
    assert_eq!(parse_tcp_frame(&zero), Err(AduError::Length(0)));
}

#[test]
fn reserved_and_broadcast_addresses_are_findings() {
    let mut out = Vec::new();
    mbtap_proto::findings::check_unit(0, false, &mut out);
    mbtap_proto::findings::check_unit(248, false, &mut out);
    mbtap_proto::findings::check_unit(0, true, &mut out);
    mbtap_proto::findings::check_unit(247, false, &mut out);
    assert_eq!(
        out,
        vec![Finding::BroadcastAddress, Finding::ReservedAddress { unit: 248 }, Finding::ResponseFromBroadcastAddress]
    );
}
