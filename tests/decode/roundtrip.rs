//! Round-trip properties over generated PDUs of every function code, both directions:
//! encode → parse → equal, and for arbitrary bytes: parse → encode → the same bytes.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use mbtap_proto::{
    Bits, DeviceObjects, DiagnosticSubFunction, ExceptionCode, FileRecords, FileSubRequests, FunctionCode, MeiType,
    Registers, Request, Response, encode_ascii, encode_rtu, encode_tcp, parse_ascii, parse_request, parse_response,
    parse_rtu, parse_tcp,
};
use proptest::prelude::*;

/// The raw material one generated PDU is built from; the PDU borrows `data` and `objects`.
#[derive(Debug, Clone)]
struct Case {
    kind: u8,
    a: u16,
    b: u16,
    c: u16,
    d: u16,
    x: u8,
    y: u8,
    data: Vec<u8>,
    objects: Vec<u8>,
    object_count: u8,
}

/// Device identification objects: (id, value) pairs laid out as id, length, value.
fn objects() -> impl Strategy<Value = (u8, Vec<u8>)> {
    prop::collection::vec((any::<u8>(), prop::collection::vec(any::<u8>(), 0..20)), 0..6).prop_map(|objs| {
        let mut bytes = Vec::new();
        for (id, v) in &objs {
            bytes.push(*id);
            bytes.push(u8::try_from(v.len()).unwrap());
            bytes.extend_from_slice(v);
        }
        (u8::try_from(objs.len()).unwrap(), bytes)
    })
}

fn case() -> impl Strategy<Value = Case> {
    (any::<u8>(), any::<[u16; 4]>(), any::<u8>(), any::<u8>(), prop::collection::vec(any::<u8>(), 0..=240), objects())
        .prop_map(|(kind, [a, b, c, d], x, y, data, (object_count, objects))| Case {
            kind,
            a,
            b,
            c,
            d,
            x,
            y,
            data,
            objects,
            object_count,
        })
}

/// Function codes with no public layout, for `Other`.
fn unknown_function(x: u8) -> u8 {
    let f = x & 0x7F;
    if matches!(FunctionCode::from(f), FunctionCode::Other(_)) { f } else { 0x41 }
}

/// A MEI type other than Read Device Identification, for `Encapsulated`.
fn raw_mei(x: u8) -> MeiType {
    if x == 0x0E { MeiType::CanopenGeneralReference } else { MeiType::from(x) }
}

/// Sub-functions other than 0 carry one 16-bit field.
fn diag(c: &Case) -> (DiagnosticSubFunction, &[u8]) {
    let sub = DiagnosticSubFunction::from(c.a);
    let data = if c.a == 0 { &c.data[..] } else { &c.data[..c.data.len().min(2)] };
    (sub, data)
}

const REQUEST_KINDS: u8 = 21;
const RESPONSE_KINDS: u8 = 22;

fn build_request(c: &Case) -> Request<'_> {
    let d = &c.data[..];
    match c.kind % REQUEST_KINDS {
        0 => Request::ReadCoils { address: c.a, quantity: c.b },
        1 => Request::ReadDiscreteInputs { address: c.a, quantity: c.b },
        2 => Request::ReadHoldingRegisters { address: c.a, quantity: c.b },
        3 => Request::ReadInputRegisters { address: c.a, quantity: c.b },
        4 => Request::WriteSingleCoil { address: c.a, value: c.b },
        5 => Request::WriteSingleRegister { address: c.a, value: c.b },
        6 => Request::ReadExceptionStatus,
        7 => {
            let (sub_function, data) = diag(c);
            Request::Diagnostics { sub_function, data }
        }
        8 => Request::GetCommEventCounter,
        9 => Request::GetCommEventLog,
        10 => Request::WriteMultipleCoils { address: c.a, quantity: c.b, values: Bits::new(d) },
        11 => Request::WriteMultipleRegisters { address: c.a, quantity: c.b, values: Registers::new(d) },
        12 => Request::ReportServerId,
        13 => Request::ReadFileRecord { sub_requests: FileSubRequests::new(d) },
        14 => Request::WriteFileRecord { records: FileRecords::write_layout(d) },
        15 => Request::MaskWriteRegister { address: c.a, and_mask: c.b, or_mask: c.c },
        16 => Request::ReadWriteMultipleRegisters {
            read_address: c.a,
            read_quantity: c.b,
            write_address: c.c,
            write_quantity: c.d,
            values: Registers::new(d),
        },
        17 => Request::ReadFifoQueue { address: c.a },
        18 => Request::ReadDeviceIdentification { read_code: c.x, object_id: c.y },
        19 => Request::Encapsulated { mei_type: raw_mei(c.x), data: d },
        _ => Request::Other { function: unknown_function(c.x), data: d },
    }
}

fn build_response(c: &Case) -> Response<'_> {
    let d = &c.data[..];
    match c.kind % RESPONSE_KINDS {
        0 => Response::ReadCoils { status: Bits::new(d) },
        1 => Response::ReadDiscreteInputs { status: Bits::new(d) },
        2 => Response::ReadHoldingRegisters { values: Registers::new(d) },
        3 => Response::ReadInputRegisters { values: Registers::new(d) },
        4 => Response::WriteSingleCoil { address: c.a, value: c.b },
        5 => Response::WriteSingleRegister { address: c.a, value: c.b },
        6 => Response::ReadExceptionStatus { status: c.x },
        7 => {
            let (sub_function, data) = diag(c);
            Response::Diagnostics { sub_function, data }
        }
        8 => Response::GetCommEventCounter { status: c.a, event_count: c.b },
        9 => Response::GetCommEventLog { status: c.a, event_count: c.b, message_count: c.c, events: d },
        10 => Response::WriteMultipleCoils { address: c.a, quantity: c.b },
        11 => Response::WriteMultipleRegisters { address: c.a, quantity: c.b },
        12 => Response::ReportServerId { data: d },
        13 => Response::ReadFileRecord { records: FileRecords::read_response_layout(d) },
        14 => Response::WriteFileRecord { records: FileRecords::write_layout(d) },
        15 => Response::MaskWriteRegister { address: c.a, and_mask: c.b, or_mask: c.c },
        16 => Response::ReadWriteMultipleRegisters { values: Registers::new(d) },
        17 => Response::ReadFifoQueue { fifo_count: c.a, values: Registers::new(d) },
        18 => Response::ReadDeviceIdentification {
            read_code: c.x,
            conformity_level: c.y,
            more_follows: c.x.wrapping_mul(3),
            next_object_id: c.y.wrapping_add(1),
            objects: DeviceObjects::from_raw(c.object_count, &c.objects),
        },
        19 => Response::Encapsulated { mei_type: raw_mei(c.x), data: d },
        20 => Response::Exception { function: c.x & 0x7F, code: ExceptionCode::from(c.y) },
        _ => Response::Other { function: unknown_function(c.x), data: d },
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4096))]

    #[test]
    fn request_encode_parse_equal(c in case()) {
        let req = build_request(&c);
        let mut pdu = Vec::new();
        req.encode(&mut pdu).unwrap();
        let (rest, back) = parse_request(&pdu).unwrap();
        prop_assert!(rest.is_empty());
        prop_assert_eq!(back, req);
    }

    #[test]
    fn response_encode_parse_equal(c in case()) {
        let resp = build_response(&c);
        let mut pdu = Vec::new();
        resp.encode(&mut pdu).unwrap();
        let (rest, back) = parse_response(&pdu).unwrap();
        prop_assert!(rest.is_empty());
        prop_assert_eq!(back, resp);
    }

    #[test]
    fn every_generated_kind_keeps_its_function_code(c in case()) {
        let mut pdu = Vec::new();
        build_request(&c).encode(&mut pdu).unwrap();
        prop_assert_eq!(pdu[0], build_request(&c).function_byte());
    }

    #[test]
    fn adus_round_trip(unit in any::<u8>(), tid in any::<u16>(), c in case()) {
        let mut pdu = Vec::new();
        build_response(&c).encode(&mut pdu).unwrap();
        let mut rtu = Vec::new();
        encode_rtu(unit, &pdu, &mut rtu);
        let f = parse_rtu(&rtu).unwrap();
        prop_assert!(f.check_ok());
        prop_assert_eq!((f.unit, f.pdu), (unit, &pdu[..]));

        let mut ascii = Vec::new();
        encode_ascii(unit, &pdu, &mut ascii);
        let f = parse_ascii(&ascii).unwrap();
        prop_assert!(f.check_ok() && f.terminated && !f.lowercase);
        prop_assert_eq!((f.unit(), f.pdu()), (unit, &pdu[..]));

        if pdu.len() <= 253 {
            let mut tcp = Vec::new();
            encode_tcp(tid, unit, &pdu, &mut tcp);
            let f = parse_tcp(&tcp).unwrap();
            prop_assert_eq!((f.header.transaction_id, f.header.unit, f.pdu), (tid, unit, &pdu[..]));
        }
    }

    /// Whatever bytes arrive, a successful parse re-encodes to exactly those bytes.
    #[test]
    fn parse_then_encode_is_identity(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        if let Ok((trailing, req)) = parse_request(&bytes) {
            let mut out = Vec::new();
            req.encode(&mut out).unwrap();
            out.extend_from_slice(trailing);
            prop_assert_eq!(&out, &bytes);
        }
        if let Ok((trailing, resp)) = parse_response(&bytes) {
            let mut out = Vec::new();
            resp.encode(&mut out).unwrap();
            out.extend_from_slice(trailing);
            prop_assert_eq!(&out, &bytes);
        }
    }

    /// The same, with the function byte forced to each public code so every layout is hit.
    #[test]
    fn parse_then_encode_is_identity_per_function(fc in prop::sample::select(vec![
        1u8, 2, 3, 4, 5, 6, 7, 8, 0x0B, 0x0C, 0x0F, 0x10, 0x11, 0x14, 0x15, 0x16, 0x17, 0x18, 0x2B, 0x83, 0x41,
    ]), mei in prop::sample::select(vec![0x0Eu8, 0x0D, 0x99]), rest in prop::collection::vec(any::<u8>(), 0..64)) {
        let mut bytes = vec![fc];
        if fc == 0x2B { bytes.push(mei); }
        bytes.extend_from_slice(&rest);
        if let Ok((t, r)) = parse_request(&bytes) {
            let mut out = Vec::new();
            r.encode(&mut out).unwrap();
            out.extend_from_slice(t);
            prop_assert_eq!(&out, &bytes);
        }
        if let Ok((t, r)) = parse_response(&bytes) {
            let mut out = Vec::new();
            r.encode(&mut out).unwrap();
            out.extend_from_slice(t);
            prop_assert_eq!(&out, &bytes);
        }
    }
}

/// Kinds cover every public function code, both directions (a guard against the generators
/// silently losing a variant).
#[test]
fn generators_cover_every_public_function_code() {
    let blank = Case { kind: 0, a: 1, b: 1, c: 1, d: 1, x: 0x0D, y: 1, data: vec![], objects: vec![], object_count: 0 };
    let mut req_codes: Vec<u8> =
        (0..REQUEST_KINDS).map(|k| build_request(&Case { kind: k, ..blank.clone() }).function_byte()).collect();
    let mut resp_codes: Vec<u8> = (0..RESPONSE_KINDS)
        .map(|k| build_response(&Case { kind: k, ..blank.clone() }).function_byte() & 0x7F)
        .collect();
    req_codes.sort_unstable();
    req_codes.dedup();
    resp_codes.sort_unstable();
    resp_codes.dedup();
    let public = [1u8, 2, 3, 4, 5, 6, 7, 8, 0x0B, 0x0C, 0x0F, 0x10, 0x11, 0x14, 0x15, 0x16, 0x17, 0x18, 0x2B];
    for code in public {
        assert!(req_codes.contains(&code), "request generator misses 0x{code:02X}");
        assert!(resp_codes.contains(&code), "response generator misses 0x{code:02X}");
    }
}
