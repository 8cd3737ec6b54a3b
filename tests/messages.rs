//! Error messages say what went wrong once, and name the thing (issue 16).
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

/// "reading the capture: reading the capture: Is a directory (os error 21): Is a directory
/// (os error 21)" — each part said once now.
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

/// `scan adir` said "opening adir at 1200 8E1".
#[test]
fn scanning_a_directory_says_it_is_one() {
    let dir = std::env::temp_dir();
    let e = stderr_of(&["scan", dir.to_str().unwrap()]);
    assert!(e.contains("is a directory"), "{e}");
    assert!(!e.contains("1200 8E1"), "{e}");
}
