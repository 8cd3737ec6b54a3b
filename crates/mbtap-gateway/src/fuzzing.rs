//! Fuzz harness body for the gateway core, kept in the library so the `fuzz/` target stays a
//! one-liner and the same body runs over the seed corpus in `cargo test`.

use std::collections::BTreeMap;
use std::time::Duration;

use mbtap_proto::serial_line::LineSettings;
use mbtap_proto::serial_line::SerialMode;

use crate::timeouts::{TimeoutMode, Timeouts};
use crate::transaction::{EchoMode, MasterConfig, SerialMaster, Step};

/// Any bytes as a serial line's behaviour: the first byte picks the mode, the echo and the
/// retries, the second the request; then chunks of `[length, milliseconds later, bytes…]` are
/// what the line delivers. The machine must end (an answer, or 0x0B after its retries) and never
/// panic, whatever arrives.
///
/// # Panics
/// When the machine runs on without end, lets time run backwards, or ends without an outcome:
/// the point of this harness.
pub fn transaction(data: &[u8]) {
    let (&setup, rest) = data.split_first().unwrap_or((&0, &[]));
    let (&pick, mut script) = rest.split_first().unwrap_or((&0, &[]));
    let config = MasterConfig {
        line: LineSettings::default(),
        mode: if setup & 1 == 0 { SerialMode::Rtu } else { SerialMode::Ascii },
        echo: match setup >> 1 & 3 {
            0 => EchoMode::Auto,
            1 => EchoMode::On,
            _ => EchoMode::Off,
        },
        retries: u32::from(setup >> 3 & 3),
        turnaround: Duration::ZERO,
        broadcast_reply: setup & 0x20 != 0,
        latency: Duration::from_millis(u64::from(setup >> 6)),
        monitored: true,
    };
    let mut master =
        SerialMaster::new(config, Timeouts::new(Duration::from_millis(50), TimeoutMode::Auto, BTreeMap::new()));
    // Read holding 0–1, write one register, or a vendor code; unit 1, or a broadcast.
    let pdus: [&[u8]; 3] = [&[0x03, 0, 0, 0, 2], &[0x06, 0, 1, 0, 3], &[0x41, 1, 2]];
    let unit = u8::from(pick & 0x80 == 0);
    for round in 0..2 {
        let pdu = pdus[usize::from(pick) % pdus.len()];
        let (mut t, mut step) = master.transaction(unit, pdu);
        let mut now = Duration::from_secs(round);
        let mut steps = 0u32;
        loop {
            steps += 1;
            assert!(steps < 100_000, "the transaction never ends");
            step = match step {
                Step::Send(_) => t.sent(now, false),
                Step::PauseUntil(at) => {
                    assert!(at >= now, "time runs backwards");
                    now = at;
                    t.tick(now)
                }
                Step::WaitUntil(at) => {
                    if let [len, ms, tail @ ..] = script {
                        let n = usize::from(*len).min(tail.len());
                        let (bytes, next) = tail.split_at(n);
                        script = next;
                        now += Duration::from_millis(u64::from(*ms));
                        if now >= at { t.tick(now.max(at)) } else { t.bytes(now, bytes) }
                    } else {
                        now = now.max(at);
                        t.tick(now)
                    }
                }
                Step::Done => break,
            };
        }
        let _ = t.take_notes();
        assert!(t.outcome().is_some(), "done without an outcome");
    }
}

/// Any bytes as what a networked line delivers: the first byte picks the transport — even, a
/// Modbus TCP device's stream ([`crate::tcp_device`]); odd, a Telnet/RFC 2217 server's
/// ([`mbtap_proto::rfc2217`]) — the rest arrives in reads of 1 to 16 bytes. Neither may panic, nor
/// buffer without bound, nor make more line bytes than it received. The same bytes as a request
/// go through the audit's reading of it ([`crate::audit::change`]).
///
/// # Panics
/// When one of those is broken: the point of this harness.
pub fn transports(data: &[u8]) {
    let (&pick, rest) = data.split_first().unwrap_or((&0, &[]));
    // The audit reads any request a client sends: whatever the bytes, a bounded record.
    if let Some(c) = crate::audit::change(rest) {
        assert!(c.values.len() <= crate::audit::MAX_VALUES, "{} values", c.values.len());
    }
    let reads = rest.chunks(usize::from(pick >> 4) + 1);
    if pick % 2 == 0 {
        const READ_ONE: [u8; 5] = [0x03, 0x00, 0x00, 0x00, 0x01];
        let mut device = crate::tcp_device::TcpDevice::seeded(u64::from(pick));
        let _ = device.request(1, &READ_ONE);
        for read in reads {
            match device.bytes(read).0 {
                crate::tcp_device::Heard::Answer { unit, pdu } => {
                    // The one answer check held: only an answer that fits reaches a client.
                    assert_eq!(crate::answer::check(1, &READ_ONE, unit, &pdu), Ok(()), "{pdu:02X?}");
                    let _ = device.request(1, &READ_ONE);
                }
                crate::tcp_device::Heard::Broken => {
                    device.reset();
                    let _ = device.request(1, &READ_ONE);
                }
                crate::tcp_device::Heard::More => {}
            }
        }
    } else {
        // The spec's default line: 19200 8E1 (Serial Line v1.02 §2.5.1, §3.3.1).
        let mut telnet = mbtap_proto::rfc2217::Telnet::new(mbtap_proto::serial_line::LineSettings::default());
        let (mut data, mut reply) = (Vec::new(), Vec::new());
        for read in reads {
            telnet.feed(read, &mut data, &mut reply);
        }
        assert!(data.len() <= rest.len(), "{} line bytes from {} received", data.len(), rest.len());
        // At most the settings (4 subnegotiations) and one refusal per option value.
        assert!(reply.len() <= 64 + 3 * 256, "{} bytes of answers", reply.len());
    }
}

/// Any bytes as one asker's requests and answers in time: the first byte picks ids or none;
/// then each byte is an event — its top bit a request (the next number) or an answer (to a
/// request still numbered, picked by the low bits), the rest milliseconds since the last event.
/// The rule must never deliver an answer to a request its asker gave up on, nor an answer to a
/// client without ids after a later request, and keeps bounded state.
///
/// # Panics
/// When an answer reaches a request given up: the point of this harness.
pub fn lifetime(data: &[u8]) {
    use crate::lifetime::{Fate, Ids, Lifetime};
    let (&kind, script) = data.split_first().unwrap_or((&0, &[]));
    let ids = if kind & 1 == 0 { Ids::Has } else { Ids::None };
    let mut l = Lifetime::new(ids);
    let (mut next, mut now) = (0u64, Duration::ZERO);
    let mut open: Vec<u64> = Vec::new();
    for &b in script {
        now += Duration::from_millis(u64::from(b & 0x3F) * 7);
        if b & 0x80 != 0 || open.is_empty() {
            let seq = next;
            next += 1;
            if let Some(below) = l.asked(seq, now) {
                assert!(below <= seq, "gave up on requests not yet asked");
                open.retain(|&s| s >= below);
            }
            open.push(seq);
            if open.len() > 64 {
                open.remove(0);
            }
        } else {
            let i = usize::from(b & 0x3F) % open.len();
            let seq = open.remove(i);
            let fate = l.answer(seq, now);
            if l.given_up(seq) {
                assert_eq!(fate, Fate::Withhold, "request {seq} was given up");
            }
            if ids == Ids::None && seq + 1 < next {
                assert_eq!(fate, Fate::Withhold, "a later request came: {seq} answered to a client without ids");
            }
        }
    }
}
