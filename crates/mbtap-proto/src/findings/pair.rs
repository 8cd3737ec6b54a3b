//! Findings on a request and its response together (MAP v1.1b3 §6: what a response must echo of
//! its request — function, address, quantity, value, byte counts).

use super::Finding;
use crate::data::bit_bytes;
use crate::request::Request;
use crate::response::Response;

pub(super) fn mismatch(out: &mut Vec<Finding>, field: &'static str, request: impl Into<u32>, response: impl Into<u32>) {
    let (request, response) = (request.into(), response.into());
    if request != response {
        out.push(Finding::ResponseMismatch { field, request, response });
    }
}

pub(super) fn len_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// Findings on a response read against the request it answers (MAP v1.1b3 §6: what each
/// response must repeat or carry).
pub fn check_pair(req: &Request<'_>, resp: &Response<'_>, out: &mut Vec<Finding>) {
    mismatch(out, "function", req.function_byte(), resp.function().value());
    match (*req, *resp) {
        (Request::ReadCoils { quantity, .. }, Response::ReadCoils { status })
        | (Request::ReadDiscreteInputs { quantity, .. }, Response::ReadDiscreteInputs { status }) => {
            mismatch(out, "byte count", len_u32(bit_bytes(quantity)), len_u32(status.as_bytes().len()));
        }
        (Request::ReadHoldingRegisters { quantity, .. }, Response::ReadHoldingRegisters { values })
        | (Request::ReadInputRegisters { quantity, .. }, Response::ReadInputRegisters { values })
        | (
            Request::ReadWriteMultipleRegisters { read_quantity: quantity, .. },
            Response::ReadWriteMultipleRegisters { values },
        ) => {
            mismatch(out, "byte count", u32::from(quantity) * 2, len_u32(values.as_bytes().len()));
        }
        (Request::WriteSingleCoil { address: a, value: v }, Response::WriteSingleCoil { address, value })
        | (Request::WriteSingleRegister { address: a, value: v }, Response::WriteSingleRegister { address, value }) => {
            mismatch(out, "address", a, address);
            mismatch(out, "value", v, value);
        }
        (
            Request::WriteMultipleCoils { address: a, quantity: q, .. },
            Response::WriteMultipleCoils { address, quantity },
        )
        | (
            Request::WriteMultipleRegisters { address: a, quantity: q, .. },
            Response::WriteMultipleRegisters { address, quantity },
        ) => {
            mismatch(out, "address", a, address);
            mismatch(out, "quantity", q, quantity);
        }
        (Request::Diagnostics { sub_function: s, data: d }, Response::Diagnostics { sub_function, data }) => {
            mismatch(out, "sub-function", s.value(), sub_function.value());
            // Return Query Data must echo the data (MAP v1.1b3 §6.8.1, sub-function 00).
            if s.value() == 0 && d != data {
                mismatch(out, "echoed data length", len_u32(d.len()), len_u32(data.len()));
                if d.len() == data.len() {
                    out.push(Finding::ResponseMismatch { field: "echoed data", request: 0, response: 1 });
                }
            }
        }
        (
            Request::MaskWriteRegister { address: a, and_mask: am, or_mask: om },
            Response::MaskWriteRegister { address, and_mask, or_mask },
        ) => {
            mismatch(out, "address", a, address);
            mismatch(out, "AND mask", am, and_mask);
            mismatch(out, "OR mask", om, or_mask);
        }
        (Request::WriteFileRecord { records: r }, Response::WriteFileRecord { records }) => {
            mismatch(out, "record data length", len_u32(r.as_bytes().len()), len_u32(records.as_bytes().len()));
        }
        (
            Request::ReadDeviceIdentification { read_code: r, .. },
            Response::ReadDeviceIdentification { read_code, .. },
        ) => {
            mismatch(out, "read device id code", r, read_code);
        }
        _ => {}
    }
}
