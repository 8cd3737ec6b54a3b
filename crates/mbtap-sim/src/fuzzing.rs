//! Fuzz harness bodies of the simulated devices and the UART model: kept in the library so the
//! `fuzz/` targets stay one-liners and the same bodies run over the seed corpus in `cargo test`
//! (tests/decode/fuzz_corpus.rs).
//!
//! Each function must not panic on any input; a body that asserts a property says so in its
//! `# Panics` — there a panic is the finding.

/// Any request PDU to the simulated built-in devices: an answer or silence, never a panic.
/// The first byte is the unit address, the rest the PDU.
///
/// # Panics
/// When an answer is not a well-formed response: that is the bug the fuzzer is looking for.
pub fn sim(data: &[u8]) {
    use std::sync::{Arc, OnceLock};
    static SLAVES: OnceLock<Vec<crate::Slave>> = OnceLock::new();
    let slaves = SLAVES.get_or_init(|| {
        ["mk4", "mkzp", "display"]
            .into_iter()
            .filter_map(|name| mbtap_device::profile::builtin::get(name).and_then(Result::ok))
            .map(|p| crate::Slave::new(Arc::new(p), 1))
            .collect()
    });
    let Some((&unit, pdu)) = data.split_first() else { return };
    for s in slaves {
        let mut s = s.clone();
        if let Some(answer) = s.handle(unit, pdu) {
            // Whatever the slave says must itself be a well-formed response.
            assert!(mbtap_proto::parse_response(&answer).is_ok(), "unparseable answer {answer:02X?} to {pdu:02X?}");
        }
    }
    // A device emulated from a recording (`simulate --from`): holding 0–9 and coils 0–15 heard.
    let mut values = crate::store::Values::default();
    for a in 0..16u16 {
        values.insert(mbtap_device::profile::Table::Coils, a, a % 2);
        values.insert(mbtap_device::profile::Table::HoldingRegisters, a % 10, a);
    }
    let mut recorded = crate::RecordedDevice::from_image(1, values);
    if let Some(answer) = recorded.handle(unit, pdu) {
        assert!(mbtap_proto::parse_response(&answer).is_ok(), "unparseable answer {answer:02X?} to {pdu:02X?}");
    }
}

/// Any bytes sent at one line setting and heard at another through the UART model: it ends,
/// delivers bytes in time order, and at matching settings delivers exactly what was sent.
/// Byte 0 picks the sender's settings, byte 1 the receiver's; the rest is the frame.
///
/// # Panics
/// When one of those properties fails: that is the bug the fuzzer is looking for.
pub fn uart(data: &[u8]) {
    use crate::bus::LineFrame;
    use crate::uart::UartListener;
    use mbtap_analysis::framer::{LineSettings, Parity};
    const BAUDS: [u32; 8] = [1200, 2400, 9600, 14_400, 19_200, 56_000, 115_200, 256_000];
    let settings = |b: u8| LineSettings {
        baud: BAUDS[usize::from(b & 7)],
        data_bits: if b & 8 == 0 { 8 } else { 7 },
        parity: [Parity::None, Parity::Even, Parity::Odd, Parity::Even][usize::from(b >> 4 & 3)],
        stop_bits: if b & 0x40 == 0 { 1 } else { 2 },
    };
    let [s, r, bytes @ ..] = data else { return };
    let (sender, receiver) = (settings(*s), settings(*r));
    let chars = u64::try_from(bytes.len()).unwrap_or(u64::MAX);
    let frame = LineFrame { end_ns: 1_000_000 + sender.char_ns() * chars, bytes: bytes.to_vec() };
    let heard = UartListener::new(sender, receiver).hear(&frame);
    assert!(heard.windows(2).all(|w| w[0].t_ns < w[1].t_ns), "bytes out of time order");
    if sender == receiver {
        let mask = if sender.data_bits == 7 { 0x7F } else { 0xFF };
        let sent: Vec<u8> = bytes.iter().map(|b| b & mask).collect();
        let got: Vec<u8> = heard.iter().map(|h| h.byte).collect();
        assert_eq!(got, sent, "matching settings must hear what was sent");
        assert!(heard.iter().all(|h| !h.framing_error && !h.parity_error));
    }
}
