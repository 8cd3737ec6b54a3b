//! `learn --confirm`: a capture holding one poll of an ABB B23 (the built-in profile, served
//! moving by `simulate`), learned, then the device asked again through a proxy that logs every
//! request on the wire: the registers one sample left undecided are settled by the extra reads,
//! and the wire shows nothing but reads, of the master's own blocks, no faster than --rate.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::common::{self, BIN};

/// The B23's blocks a logger reads once (MAP v1.1b3 §6.3, function 03): voltages to apparent
/// powers 5B00h–5B2Bh (u32 and i32 pairs, ABB 2CMC485003M0201), frequency 5B2Ch, power factors
/// 5B3Ah–5B3Dh.
const BLOCKS: [(u16, u16); 3] = [(0x5B00, 0x2C), (0x5B2C, 1), (0x5B3A, 4)];

/// Each request's arrival and function code, as the proxy saw it.
type WireLog = Arc<Mutex<Vec<(Instant, u8)>>>;

/// A proxy between `learn` and the device that logs each request's arrival and function code
/// (MBAP, Modbus Messaging on TCP/IP v1.0b §3.1.3: 7-byte header whose length counts the unit
/// and the PDU).
fn logging_proxy(upstream: String) -> (String, WireLog) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let log = Arc::new(Mutex::new(Vec::new()));
    let sink = Arc::clone(&log);
    std::thread::spawn(move || {
        for client in listener.incoming() {
            let Ok(mut client) = client else { return };
            let mut server = TcpStream::connect(&upstream).unwrap();
            let (mut back_from, mut back_to) = (server.try_clone().unwrap(), client.try_clone().unwrap());
            std::thread::spawn(move || std::io::copy(&mut back_from, &mut back_to));
            let sink = Arc::clone(&sink);
            std::thread::spawn(move || {
                let mut head = [0u8; 7];
                while client.read_exact(&mut head).is_ok() {
                    let mut rest = vec![0u8; usize::from(u16::from_be_bytes([head[4], head[5]])).saturating_sub(1)];
                    if client.read_exact(&mut rest).is_err() {
                        return;
                    }
                    sink.lock().unwrap().push((Instant::now(), rest.first().copied().unwrap_or(0)));
                    if server.write_all(&head).and_then(|()| server.write_all(&rest)).is_err() {
                        return;
                    }
                }
            });
        }
    });
    (addr, log)
}

fn crc(data: &[u8]) -> [u8; 2] {
    let mut frame = Vec::new();
    mbtap_proto::encode_rtu(data[0], &data[1..], &mut frame);
    [frame[frame.len() - 2], frame[frame.len() - 1]]
}

/// The registers `learn` drafted: address → (type, width).
fn drafted(json: &[u8]) -> std::collections::BTreeMap<u64, (String, u64)> {
    let report: serde_json::Value = serde_json::from_slice(json).unwrap();
    report["units"][0]["registers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            (r["address"].as_u64().unwrap(), (r["type"].as_str().unwrap().to_owned(), r["width"].as_u64().unwrap()))
        })
        .collect()
}

/// A capture of one poll of each of [`BLOCKS`] from the device at `device`, as a logger's
/// capture holds it (RTU frames made into a pcapng by `generate`).
fn one_poll(device: &str, dir: &std::path::Path) -> std::path::PathBuf {
    let mut s = TcpStream::connect(device).unwrap();
    let mut frames = String::new();
    for (tid, (first, quantity)) in (1..).zip(BLOCKS) {
        let [a, b] = first.to_be_bytes();
        let [q, r] = quantity.to_be_bytes();
        let pdu = [0x03, a, b, q, r];
        let answer = common::call(&mut s, tid, 1, &pdu);
        for body in [[&[1u8][..], &pdu].concat(), [&[1u8][..], &answer].concat()] {
            let line: Vec<String> = body.iter().chain(&crc(&body)).map(|b| format!("{b:02x}")).collect();
            frames.push_str(&(line.join(" ") + "\n"));
        }
    }
    std::fs::write(dir.join("poll.txt"), frames).unwrap();
    let capture = dir.join("poll.pcapng");
    let made = Command::new(BIN)
        .args(["generate", capture.to_str().unwrap(), "--frames", dir.join("poll.txt").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(made.status.success(), "{}", String::from_utf8_lossy(&made.stderr));
    capture
}

#[test]
fn confirm_settles_what_one_poll_left_undecided_with_reads_only_within_the_rate() {
    let dir = std::env::temp_dir().join(format!("mbtap-learn-confirm-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (_sim, device, _, _) =
        common::simulate_listening(&["--device", "b23@1", "--listen", "127.0.0.1:0", "--duration", "120"]);
    let capture = one_poll(&device, &dir);
    let passive = Command::new(BIN).args(["learn", capture.to_str().unwrap(), "--format", "json"]).output().unwrap();
    let before = drafted(&passive.stdout);
    // One sample: the L1 voltage's pair (0x0000 0x08FC-ish) is two registers, undecided.
    assert_ne!(before.get(&0x5B00).map(|(t, _)| t.as_str()), Some("u32 high word first"), "{before:?}");

    let (proxy, log) = logging_proxy(device);
    let rate = 10.0;
    let confirmed = Command::new(BIN)
        .args(["learn", capture.to_str().unwrap(), "--format", "json", "--confirm", &proxy])
        .args(["--rate", "10", "--confirm-for", "20s"])
        .output()
        .unwrap();
    std::fs::remove_dir_all(&dir).ok();
    let said = String::from_utf8_lossy(&confirmed.stderr);
    assert!(confirmed.status.success(), "{said}");
    let after = drafted(&confirmed.stdout);
    // Settled: the voltages (u32, 0.1 V) and the rest of the block as pairs from its start.
    // (A current that only rose over the few seconds asked may be called a counter: the series
    // cannot say otherwise; its width and word order are what is settled.)
    for a in [0x5B00u64, 0x5B02, 0x5B04, 0x5B0C] {
        let (kind, width) = after.get(&a).unwrap_or_else(|| panic!("{a:#x}: {after:?}\n{said}"));
        assert!(
            kind.starts_with("u32") && kind.ends_with("high word first") && *width == 2,
            "{a:#x}: {after:?}\n{said}"
        );
    }
    assert!(said.contains("asked") && said.contains("→ u32 high word first"), "{said}");
    // The wire: reads only (03), of the three blocks, as many as said, never faster than --rate.
    let log = log.lock().unwrap().clone();
    assert!(log.len() >= 3 && log.iter().all(|&(_, fc)| fc == 0x03), "{log:?}");
    assert!(said.contains(&format!("asked {} reads", log.len())), "{said}");
    let gap = Duration::from_secs_f64(1.0 / rate);
    for w in log.windows(2) {
        // A millisecond of slack for the proxy's own thread hand-off.
        assert!(w[1].0 - w[0].0 + Duration::from_millis(1) >= gap, "two reads {:?} apart", w[1].0 - w[0].0);
    }
}

/// A device that refuses what the master read (here an MK4, which has no register at 5B00h:
/// exception 02) ends the asking at its first refusal, said; nothing is asked again.
#[test]
fn a_device_that_refuses_ends_the_confirming_said() {
    let dir = std::env::temp_dir().join(format!("mbtap-learn-refused-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (_b23, b23, _, _) =
        common::simulate_listening(&["--device", "b23@1", "--listen", "127.0.0.1:0", "--duration", "60"]);
    let capture = one_poll(&b23, &dir);
    let (_mk4, mk4, _, _) =
        common::simulate_listening(&["--device", "mk4@1", "--listen", "127.0.0.1:0", "--duration", "60"]);
    let (proxy, log) = logging_proxy(mk4);
    let out = Command::new(BIN)
        .args(["learn", capture.to_str().unwrap(), "--format", "json", "--confirm", &proxy, "--rate", "10"])
        .output()
        .unwrap();
    std::fs::remove_dir_all(&dir).ok();
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{said}");
    assert!(said.contains("refused with exception 02; asked nothing more") && said.contains("asked 1 reads"), "{said}");
    assert_eq!(log.lock().unwrap().len(), 1);
}
