//! Error messages say what went wrong once, and name the thing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::process::Command;

fn stderr_of(args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .env("MBTAP_CONFIG", "/nonexistent/mbtap-config.toml")
        .args(args)
        .output()
        .unwrap();
    assert_ne!(o.status.code(), Some(0), "{args:?} should fail");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Each part of a capture error is said once (never "reading the capture: reading the capture: Is a
/// directory (os error 21): Is a directory (os error 21)").
#[test]
fn a_capture_error_is_said_once() {
    let dir = std::env::temp_dir();
    let e = stderr_of(&["replay", dir.to_str().unwrap()]);
    assert_eq!(e.matches("reading the capture").count(), 1, "{e}");
    assert_eq!(e.matches("Is a directory").count(), 1, "{e}");
    let not_a_capture = std::env::temp_dir().join(format!("mbtap-not-a-capture-{}", std::process::id()));
    std::fs::write(&not_a_capture, "root:x:0:0:root:/root:/bin/bash\n").unwrap();
    let e = stderr_of(&["replay", not_a_capture.to_str().unwrap()]);
    assert_eq!(e.matches("not a pcap or pcapng file").count(), 1, "{e}");
}

/// `scan adir` says it is a directory (not "opening adir at 1200 8E1").
#[test]
fn scanning_a_directory_says_it_is_one() {
    let dir = std::env::temp_dir();
    let e = stderr_of(&["scan", dir.to_str().unwrap()]);
    assert!(e.contains("is a directory"), "{e}");
    assert!(!e.contains("1200 8E1"), "{e}");
}

/// A classic pcap file (microseconds, little-endian) with link type `dlt` of `records`:
/// (ts_sec, ts_usec, bytes) each.
fn pcap_records(dlt: u32, records: &[(u32, u32, &[u8])]) -> std::path::PathBuf {
    // Tests run at once in one process: each file its own name.
    static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let mut f = Vec::new();
    // magic, version 2.4, thiszone, sigfigs, snaplen, network
    f.extend_from_slice(&0xA1B2_C3D4u32.to_le_bytes());
    f.extend_from_slice(&2u16.to_le_bytes());
    f.extend_from_slice(&4u16.to_le_bytes());
    f.extend_from_slice(&[0; 8]);
    f.extend_from_slice(&65_535u32.to_le_bytes());
    f.extend_from_slice(&dlt.to_le_bytes());
    for &(sec, usec, frame) in records {
        let len = u32::try_from(frame.len()).unwrap();
        // ts_sec, ts_usec, incl_len, orig_len, bytes
        f.extend_from_slice(&sec.to_le_bytes());
        f.extend_from_slice(&usec.to_le_bytes());
        f.extend_from_slice(&len.to_le_bytes());
        f.extend_from_slice(&len.to_le_bytes());
        f.extend_from_slice(frame);
    }
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!("mbtap-dlt{dlt}-{}-{n}.pcap", std::process::id()));
    std::fs::write(&path, f).unwrap();
    path
}

/// [`pcap_records`] of `frames` 20 ms apart.
fn pcap(dlt: u32, frames: &[&[u8]]) -> std::path::PathBuf {
    let records: Vec<(u32, u32, &[u8])> =
        frames.iter().enumerate().map(|(i, f)| (1_700_000_000, u32::try_from(i).unwrap() * 20_000, *f)).collect();
    pcap_records(dlt, &records)
}

/// Unit 1, read 3 holding registers from 101, and its answer (MK4 document §3.3).
const REQUEST: &[u8] = &[0x01, 0x03, 0x00, 0x65, 0x00, 0x03, 0x15, 0xD4];
const ANSWER: &[u8] = &[0x01, 0x03, 0x06, 0x00, 0x00, 0x00, 0x00, 0x01, 0x90, 0x20, 0x89];

fn replay(path: &std::path::Path, extra: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .env("MBTAP_CONFIG", "/nonexistent/mbtap-config.toml")
        .args(["replay", path.to_str().unwrap(), "--format", "jsonl"])
        .args(extra)
        .output()
        .unwrap()
}

/// Link types 148–162 (the other user DLTs other sniffers use) are read, and an unknown link type
/// is an error, never skipped silently with exit 0.
#[test]
fn user_link_types_are_read_and_an_unknown_one_is_an_error() {
    let p = pcap(150, &[REQUEST, ANSWER]);
    let o = replay(&p, &[]);
    assert_eq!(o.status.code(), Some(0));
    assert_eq!(String::from_utf8_lossy(&o.stdout).matches("\"event\":\"frame\"").count(), 2);
    let p = pcap(1, &[REQUEST, ANSWER]);
    let o = replay(&p, &[]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("link type 1") && e.contains("--link-type 1"), "{e}");
    let o = replay(&p, &["--link-type", "1"]);
    assert_eq!(o.status.code(), Some(0));
    assert_eq!(String::from_utf8_lossy(&o.stdout).matches("\"event\":\"frame\"").count(), 2);
}

/// `--baud 0` is refused on the command line.
#[test]
fn a_zero_baud_rate_is_refused_on_the_command_line() {
    let e = stderr_of(&["generate", "/tmp/never-written.pcapng", "--baud", "0"]);
    assert!(e.contains("--baud") && e.contains('0'), "{e}");
}

/// One flipped bit in one record's length field (a megabyte claimed) costs that record: the reader
/// skips to the next readable record and reads on (never "the file ends in the middle of a block …
/// its last 128 877 bytes are ignored" with 4 of 299 transactions kept).
#[test]
fn a_damaged_length_field_costs_one_record_not_the_rest_of_the_file() {
    let frames: Vec<&[u8]> = (0..30).map(|i| if i % 2 == 0 { REQUEST } else { ANSWER }).collect();
    let p = pcap(147, &frames);
    let mut bytes = std::fs::read(&p).unwrap();
    // The 5th record's incl_len (record header: ts_sec, ts_usec, incl_len, orig_len).
    let fifth = 24 + 2 * (16 + REQUEST.len()) + 2 * (16 + ANSWER.len());
    bytes[fifth + 8 + 2] ^= 0x10;
    let damaged = std::env::temp_dir().join(format!("mbtap-damaged-len-{}.pcap", std::process::id()));
    std::fs::write(&damaged, bytes).unwrap();
    let o = replay(&damaged, &[]);
    assert_eq!(o.status.code(), Some(0));
    let frames_read = String::from_utf8_lossy(&o.stdout).matches("\"event\":\"frame\"").count();
    assert!(frames_read >= 28, "{frames_read} of 30 frames read");
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("damaged length")
            || String::from_utf8_lossy(&o.stderr).contains("damaged length")
    );
}

/// An ASCII capture replayed as RTU is not just "16 bytes of noise": the hint says what the bytes
/// look like; and a capture without stored settings says which settings it was read at.
#[test]
fn a_capture_says_which_settings_it_assumed_and_what_its_bytes_look_like() {
    // Unit 1, read 3 holding registers from 101, twice (MK4 document §3.1).
    let p = pcap(147, &[b":01030065000394\r\n", b":01030065000394\r\n"]);
    // In JSON lines the warnings are `warning` events on stdout.
    let said = |o: &std::process::Output| {
        format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
    };
    let o = replay(&p, &[]);
    let e = said(&o);
    assert!(e.contains("stores no line settings") && e.contains("19200 8E1"), "{e}");
    assert!(e.contains("look like Modbus ASCII") && e.contains("--mode ascii"), "{e}");
    let o = replay(&p, &["--mode", "ascii", "--baud", "9600"]);
    let e = said(&o);
    assert!(!e.contains("stores no line settings") && !e.contains("look like"), "{e}");
    assert_eq!(String::from_utf8_lossy(&o.stdout).matches("\"check_ok\":true").count(), 2);
}

/// Binary garbage holds ':' and LF as often as anything else, so it is never told "the bytes look
/// like Modbus ASCII": only bytes that are mostly hex digits between ':' and CR LF earn that hint;
/// garbage gets the neutral "mbtap scan" one.
#[test]
fn binary_garbage_is_not_called_modbus_ascii() {
    // Every byte value 0..=250 in turn, so ':' (0x3A) and LF (0x0A) both occur.
    let garbage: Vec<u8> = (0..2000u32).map(|i| u8::try_from(i % 251).unwrap()).collect();
    let p = pcap(147, &[&garbage]);
    let o = replay(&p, &[]);
    let e = format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(!e.contains("look like Modbus ASCII"), "{e}");
    assert!(e.contains("no valid frame in the capture") && e.contains("mbtap scan"), "{e}");
}

/// A classic pcap (microseconds) of `n` polls: REQUEST at k·100 ms, ANSWER 20 ms later, with
/// `bit` of the seconds flipped in the request of poll `bad` (1 700 000 000 s has bit 11
/// clear: +2 048 s; bit 12 set: −4 096 s).
fn polls_with_one_flipped_second(n: u32, bad: u32, bit: u32) -> std::path::PathBuf {
    let mut records = Vec::new();
    for k in 0..n {
        for (frame, after_us) in [(REQUEST, 0), (ANSWER, 20_000)] {
            let us = u64::from(k) * 100_000 + after_us;
            let mut sec = 1_700_000_000 + u32::try_from(us / 1_000_000).unwrap();
            if k == bad && after_us == 0 {
                sec ^= 1 << bit;
            }
            records.push((sec, u32::try_from(us % 1_000_000).unwrap(), frame));
        }
    }
    pcap_records(147, &records)
}

/// One flipped bit in one timestamp does not hold every later packet at that value (which would
/// make every later answer "less than t3.5 after the request", 357 findings in this file): the lone
/// jump is one warning with its offset, and timing after it is the file's own. The one packet whose
/// true time is unknown may still cost one finding. The amounts said are from the packet before (80
/// ms before the bad request).
#[test]
fn one_flipped_timestamp_bit_does_not_spoil_the_timing_after_it() {
    for (bit, said) in [(11, "2048.080 s ahead of"), (12, "4095.920 s behind")] {
        let p = polls_with_one_flipped_second(300, 40, bit);
        let o = Command::new(env!("CARGO_BIN_EXE_mbtap"))
            .env("MBTAP_CONFIG", "/nonexistent/mbtap-config.toml")
            .args(["report", p.to_str().unwrap(), "--baud", "19200", "--format", "json"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("a lone bad timestamp") && err.contains(said), "{err}");
        let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let timing: u64 = report["findings"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|f| f["kind"] == "fast_answer" || f["kind"] == "fast_master")
            .map(|f| f["count"].as_u64().unwrap())
            .sum();
        assert!(timing <= 1, "bit {bit}: {timing} timing findings\n{report}\n{err}");
        let _ = std::fs::remove_file(&p);
    }
}

/// Long work shows progress on a terminal and never on a pipe. `script` (util-linux,
/// Essential in Debian) gives the real binary a pseudo-terminal for stderr; the threshold of
/// one second is set to 0 so the first read draws the line. The line is cleared before the
/// warnings print (`\r ESC [K`), so they never land on it.
#[test]
fn progress_is_drawn_on_a_terminal_and_never_on_a_pipe() {
    let p = polls_with_one_flipped_second(50, 10, 11);
    let bin = env!("CARGO_BIN_EXE_mbtap");
    let cmd = format!("{bin} report {} --format json > /dev/null", p.display());
    let o = Command::new("script")
        .args(["-q", "-c", &cmd, "/dev/null"])
        .env("MBTAP_PROGRESS_AFTER_MS", "0")
        .env("MBTAP_CONFIG", "/nonexistent/mbtap-config.toml")
        .output()
        .expect("script (util-linux) runs");
    let tty = String::from_utf8_lossy(&o.stdout);
    assert!(tty.contains("\r\x1b[Kmbtap: reading ") && tty.contains("s left"), "{tty:?}");
    assert!(tty.contains("\r\x1b[Kmbtap: warning: "), "the line is cleared before a warning: {tty:?}");
    // The same on a pipe: no progress line, no control sequences.
    let o = Command::new(bin)
        .args(["report", p.to_str().unwrap(), "--format", "json"])
        .env("MBTAP_PROGRESS_AFTER_MS", "0")
        .env("MBTAP_CONFIG", "/nonexistent/mbtap-config.toml")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!err.contains("reading ") && !err.contains('\x1b'), "{err:?}");
    let _ = std::fs::remove_file(&p);
}
