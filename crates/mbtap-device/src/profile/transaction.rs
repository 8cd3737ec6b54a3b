//! Annotating a whole transaction: which table and addresses a request names, and the values
//! its response (for reads) or its request (for writes) carries.

use super::annotate::{Annotation, annotate_bits, annotate_registers};
use super::format::Table;
use super::model::Profile;
use mbtap_proto::{Request, Response};

fn bits(bytes: &[u8], count: u16) -> Vec<bool> {
    mbtap_proto::Bits::new(bytes).iter(usize::from(count)).collect()
}

/// Annotations for `request` answered by `response` (or unanswered, for writes).
#[must_use]
pub fn annotate_transaction(p: &Profile, request: &Request<'_>, response: Option<&Response<'_>>) -> Vec<Annotation> {
    match (*request, response.copied()) {
        (Request::ReadCoils { address, quantity }, Some(Response::ReadCoils { status })) => {
            annotate_bits(p, Table::Coils, address, &bits(status.as_bytes(), quantity), false)
        }
        (Request::ReadDiscreteInputs { address, quantity }, Some(Response::ReadDiscreteInputs { status })) => {
            annotate_bits(p, Table::DiscreteInputs, address, &bits(status.as_bytes(), quantity), false)
        }
        (Request::ReadHoldingRegisters { address, .. }, Some(Response::ReadHoldingRegisters { values })) => {
            annotate_registers(p, Table::HoldingRegisters, address, &values.iter().collect::<Vec<_>>(), false)
        }
        (Request::ReadInputRegisters { address, .. }, Some(Response::ReadInputRegisters { values })) => {
            annotate_registers(p, Table::InputRegisters, address, &values.iter().collect::<Vec<_>>(), false)
        }
        (Request::WriteSingleCoil { address, value }, _) => {
            annotate_bits(p, Table::Coils, address, &[value == 0xFF00], true)
        }
        (Request::WriteSingleRegister { address, value }, _) => {
            annotate_registers(p, Table::HoldingRegisters, address, &[value], true)
        }
        (Request::WriteMultipleCoils { address, quantity, values }, _) => {
            annotate_bits(p, Table::Coils, address, &bits(values.as_bytes(), quantity), true)
        }
        (Request::WriteMultipleRegisters { address, values, .. }, _) => {
            annotate_registers(p, Table::HoldingRegisters, address, &values.iter().collect::<Vec<_>>(), true)
        }
        (Request::ReadWriteMultipleRegisters { read_address, write_address, values, .. }, resp) => {
            let mut out =
                annotate_registers(p, Table::HoldingRegisters, write_address, &values.iter().collect::<Vec<_>>(), true);
            if let Some(Response::ReadWriteMultipleRegisters { values: read }) = resp {
                out.extend(annotate_registers(
                    p,
                    Table::HoldingRegisters,
                    read_address,
                    &read.iter().collect::<Vec<_>>(),
                    false,
                ));
            }
            out
        }
        _ => Vec::new(),
    }
}

/// Annotations for a transaction given as its PDUs (what pairing reports:
/// `Transaction::request_pdu`, `response_pdu`).
#[must_use]
pub fn annotate_pdus(p: &Profile, request_pdu: &[u8], response_pdu: Option<&[u8]>) -> Vec<Annotation> {
    let Ok(([], req)) = mbtap_proto::parse_request(request_pdu) else { return Vec::new() };
    let resp = match response_pdu.map(mbtap_proto::parse_response) {
        Some(Ok(([], r))) => Some(r),
        _ => None,
    };
    annotate_transaction(p, &req, resp.as_ref())
}
