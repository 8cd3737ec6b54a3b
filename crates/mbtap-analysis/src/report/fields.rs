//! The decoded fields of a request or response as a list of named values: one description
//! that both the text and the JSON renderers draw from, so they never disagree.

use mbtap_proto::data::device_object_name;
use mbtap_proto::{Bits, DeviceObjects, FileRecords, FileSubRequests, Registers, Request, Response};

/// A decoded value.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Value<'a> {
    Num(u32),
    /// A 16-bit field best read in hex (masks, status words).
    Hex(u16),
    Name(&'static str),
    Bytes(&'a [u8]),
    /// Registers, with their addresses when the request is known.
    Registers {
        start: Option<u16>,
        values: Registers<'a>,
    },
    /// Bits, with their addresses and how many count when the request is known.
    Bits {
        start: Option<u16>,
        count: Option<u16>,
        bits: Bits<'a>,
    },
    /// A list of records, each a list of fields.
    Records(Vec<Vec<Field<'a>>>),
    Text(String),
}

/// A named decoded value; `key` is snake_case, for JSON and text alike.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field<'a> {
    pub key: &'static str,
    pub value: Value<'a>,
}

fn f<'a>(key: &'static str, value: Value<'a>) -> Field<'a> {
    Field { key, value }
}

fn num(key: &'static str, v: impl Into<u32>) -> Field<'static> {
    f(key, Value::Num(v.into()))
}

fn count(key: &'static str, n: usize) -> Field<'static> {
    num(key, u32::try_from(n).unwrap_or(u32::MAX))
}

fn coil_state(value: u16) -> Value<'static> {
    match value {
        0xFF00 => Value::Name("ON"),
        0x0000 => Value::Name("OFF"),
        _ => Value::Name("invalid"),
    }
}

fn sub_requests(s: FileSubRequests<'_>) -> Value<'static> {
    Value::Records(
        s.iter()
            .map(|r| {
                vec![
                    num("reference_type", r.reference_type),
                    num("file_number", r.file_number),
                    num("record_number", r.record_number),
                    num("record_length", r.record_length),
                ]
            })
            .collect(),
    )
}

fn records(r: FileRecords<'_>) -> Value<'_> {
    Value::Records(
        r.iter()
            .map(|rec| {
                let mut v = vec![num("reference_type", rec.reference_type)];
                if let Some(n) = rec.file_number {
                    v.push(num("file_number", n));
                }
                if let Some(n) = rec.record_number {
                    v.push(num("record_number", n));
                }
                v.push(f("data", Value::Registers { start: None, values: rec.data }));
                v
            })
            .collect(),
    )
}

fn objects(o: DeviceObjects<'_>) -> Value<'_> {
    Value::Records(
        o.iter()
            .map(|obj| {
                vec![
                    num("id", obj.id),
                    f("name", Value::Name(device_object_name(obj.id))),
                    f("value", Value::Text(String::from_utf8_lossy(obj.value).into_owned())),
                ]
            })
            .collect(),
    )
}

/// The fields of a request.
#[must_use]
pub fn request_fields<'a>(req: &Request<'a>) -> Vec<Field<'a>> {
    match *req {
        Request::ReadCoils { address, quantity }
        | Request::ReadDiscreteInputs { address, quantity }
        | Request::ReadHoldingRegisters { address, quantity }
        | Request::ReadInputRegisters { address, quantity } => vec![num("address", address), num("quantity", quantity)],
        Request::WriteSingleCoil { address, value } => {
            vec![num("address", address), f("value", Value::Hex(value)), f("state", coil_state(value))]
        }
        Request::WriteSingleRegister { address, value } => vec![num("address", address), num("value", value)],
        Request::ReadExceptionStatus
        | Request::GetCommEventCounter
        | Request::GetCommEventLog
        | Request::ReportServerId => vec![],
        Request::Diagnostics { sub_function, data } => diagnostics(sub_function, data),
        Request::WriteMultipleCoils { address, quantity, values } => vec![
            num("address", address),
            num("quantity", quantity),
            count("byte_count", values.as_bytes().len()),
            f("coils", Value::Bits { start: Some(address), count: Some(quantity), bits: values }),
        ],
        Request::WriteMultipleRegisters { address, quantity, values } => vec![
            num("address", address),
            num("quantity", quantity),
            count("byte_count", values.as_bytes().len()),
            f("registers", Value::Registers { start: Some(address), values }),
        ],
        Request::ReadFileRecord { sub_requests: s } => {
            vec![count("byte_count", s.as_bytes().len()), f("sub_requests", sub_requests(s))]
        }
        Request::WriteFileRecord { records: r } => {
            vec![count("byte_count", r.as_bytes().len()), f("records", records(r))]
        }
        Request::MaskWriteRegister { address, and_mask, or_mask } => {
            vec![num("address", address), f("and_mask", Value::Hex(and_mask)), f("or_mask", Value::Hex(or_mask))]
        }
        Request::ReadWriteMultipleRegisters { read_address, read_quantity, write_address, write_quantity, values } => {
            vec![
                num("read_address", read_address),
                num("read_quantity", read_quantity),
                num("write_address", write_address),
                num("write_quantity", write_quantity),
                count("byte_count", values.as_bytes().len()),
                f("registers", Value::Registers { start: Some(write_address), values }),
            ]
        }
        Request::ReadFifoQueue { address } => vec![num("fifo_address", address)],
        Request::ReadDeviceIdentification { read_code, object_id } => {
            vec![num("mei_type", 0x0E_u8), num("read_code", read_code), num("object_id", object_id)]
        }
        Request::Encapsulated { mei_type, data } => encapsulated(mei_type, data),
        Request::Other { data, .. } => vec![f("data", Value::Bytes(data))],
    }
}

fn diagnostics(sub_function: mbtap_proto::DiagnosticSubFunction, data: &[u8]) -> Vec<Field<'_>> {
    let mut v = vec![num("sub_function", sub_function.value())];
    if let Some(name) = sub_function.name() {
        v.push(f("sub_function_name", Value::Name(name)));
    }
    v.push(f("data", Value::Bytes(data)));
    v
}

fn encapsulated(mei_type: mbtap_proto::MeiType, data: &[u8]) -> Vec<Field<'_>> {
    let mut v = vec![num("mei_type", mei_type.value())];
    if let Some(name) = mei_type.name() {
        v.push(f("mei_name", Value::Name(name)));
    }
    v.push(f("data", Value::Bytes(data)));
    v
}

/// The fields of a response; `request` (when paired) supplies addresses and bit counts.
#[must_use]
pub fn response_fields<'a>(resp: &Response<'a>, request: Option<&Request<'_>>) -> Vec<Field<'a>> {
    let (start, quantity) = match request {
        Some(
            Request::ReadCoils { address, quantity }
            | Request::ReadDiscreteInputs { address, quantity }
            | Request::ReadHoldingRegisters { address, quantity }
            | Request::ReadInputRegisters { address, quantity }
            | Request::ReadWriteMultipleRegisters { read_address: address, read_quantity: quantity, .. },
        ) => (Some(*address), Some(*quantity)),
        Some(Request::ReadFifoQueue { address }) => (Some(*address), None),
        _ => (None, None),
    };
    match *resp {
        Response::ReadCoils { status } => vec![
            count("byte_count", status.as_bytes().len()),
            f("coils", Value::Bits { start, count: quantity, bits: status }),
        ],
        Response::ReadDiscreteInputs { status } => vec![
            count("byte_count", status.as_bytes().len()),
            f("inputs", Value::Bits { start, count: quantity, bits: status }),
        ],
        Response::ReadHoldingRegisters { values }
        | Response::ReadInputRegisters { values }
        | Response::ReadWriteMultipleRegisters { values } => {
            vec![count("byte_count", values.as_bytes().len()), f("registers", Value::Registers { start, values })]
        }
        Response::WriteSingleCoil { address, value } => {
            vec![num("address", address), f("value", Value::Hex(value)), f("state", coil_state(value))]
        }
        Response::WriteSingleRegister { address, value } => vec![num("address", address), num("value", value)],
        Response::ReadExceptionStatus { status } => vec![f("status", Value::Hex(u16::from(status)))],
        Response::Diagnostics { sub_function, data } => diagnostics(sub_function, data),
        Response::GetCommEventCounter { status, event_count } => {
            vec![f("status", Value::Hex(status)), num("event_count", event_count)]
        }
        Response::GetCommEventLog { status, event_count, message_count, events } => vec![
            f("status", Value::Hex(status)),
            num("event_count", event_count),
            num("message_count", message_count),
            f("events", Value::Bytes(events)),
        ],
        Response::WriteMultipleCoils { address, quantity } | Response::WriteMultipleRegisters { address, quantity } => {
            vec![num("address", address), num("quantity", quantity)]
        }
        Response::ReportServerId { data } => vec![count("byte_count", data.len()), f("data", Value::Bytes(data))],
        Response::ReadFileRecord { records: r } | Response::WriteFileRecord { records: r } => {
            vec![count("byte_count", r.as_bytes().len()), f("records", records(r))]
        }
        Response::MaskWriteRegister { address, and_mask, or_mask } => {
            vec![num("address", address), f("and_mask", Value::Hex(and_mask)), f("or_mask", Value::Hex(or_mask))]
        }
        Response::ReadFifoQueue { fifo_count, values } => {
            vec![num("fifo_count", fifo_count), f("registers", Value::Registers { start: None, values })]
        }
        Response::ReadDeviceIdentification {
            read_code,
            conformity_level,
            more_follows,
            next_object_id,
            objects: o,
        } => {
            vec![
                num("mei_type", 0x0E_u8),
                num("read_code", read_code),
                f("conformity_level", Value::Hex(u16::from(conformity_level))),
                f("more_follows", Value::Hex(u16::from(more_follows))),
                num("next_object_id", next_object_id),
                num("number_of_objects", o.count()),
                f("objects", objects(o)),
            ]
        }
        Response::Encapsulated { mei_type, data } => encapsulated(mei_type, data),
        Response::Exception { code, .. } => {
            vec![
                num("exception_code", code.value()),
                f("exception", Value::Name(code.name().unwrap_or("Unknown exception"))),
            ]
        }
        Response::Other { data, .. } => vec![f("data", Value::Bytes(data))],
    }
}
