//! The real `mbtap bridge` refuses to start on settings that would fail open or make no sense,
//! Naming where each came from: nothing here opens a port or a socket.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::process::{Command, Output};

fn bridge(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .env("MBTAP_CONFIG", "/nonexistent/mbtap-config.toml")
        .arg("bridge")
        .args(["--serial", "/nonexistent/ttyUSB-test", "--listen", "127.0.0.1:0", "--duration", "0"])
        .args(args)
        .output()
        .unwrap()
}

fn config(name: &str, text: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("mbtap-bridge-config-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let f = dir.join("bridge.toml");
    std::fs::write(&f, text).unwrap();
    f
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn zero_connections_queue_or_timeout_are_refused_on_the_command_line() {
    for (opt, key) in [
        ("--max-connections", "max-connections"),
        ("--queue-per-client", "queue-per-client"),
        ("--timeout-ms", "timeout-ms"),
    ] {
        let o = bridge(&[opt, "0"]);
        assert_eq!(o.status.code(), Some(2), "{opt}: {}", stderr(&o));
        assert!(stderr(&o).contains(&format!("--{key} 0: expected 1 or more")), "{}", stderr(&o));
    }
}

/// `timeout-ms = -5` in a file is refused naming the file, the key and the value (never clap's
/// `unexpected argument '-5' found`).
#[test]
fn nonsense_in_the_file_names_the_file_the_key_and_the_value() {
    let f = config("negative", "[bridge]\ntimeout-ms = -5\n");
    let o = bridge(&["--config", f.to_str().unwrap()]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains(f.to_str().unwrap()) && e.contains("timeout-ms") && e.contains("-5"), "{e}");
    assert!(!e.contains("unexpected argument"), "{e}");
    let f = config("zero", "[bridge]\nmax-connections = 0\n");
    let e = stderr(&bridge(&["--config", f.to_str().unwrap()]));
    assert!(e.contains(&format!("{}: max-connections = 0: expected 1 or more", f.display())), "{e}");
}

/// `allow-ip = []` opened the bridge to everyone.
#[test]
fn an_empty_allow_list_in_the_file_refuses_to_start() {
    for key in ["allow-ip", "allow-function"] {
        let f = config(key, &format!("[bridge]\n{key} = []\n"));
        let o = bridge(&["--config", f.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains(&format!("{key} = []")), "{}", stderr(&o));
    }
}

/// With no such serial port the bridge says so at once (and once a minute), not only "listening"
/// while every client gets "gateway path unavailable" with no word why.
#[test]
fn a_missing_serial_port_is_said_at_start() {
    let o = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .env("MBTAP_CONFIG", "/nonexistent/mbtap-config.toml")
        .args(["bridge", "--serial", "/nonexistent/ttyUSB-test", "--listen", "127.0.0.1:0", "--duration", "1s"])
        .output()
        .unwrap();
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("serial port /nonexistent/ttyUSB-test: cannot open it") && err.contains("0x0A"), "{err}");
}

/// `sniff` on a missing port says only the error: no empty summary on stdout beside it.
#[test]
fn sniff_on_a_missing_port_says_only_the_error() {
    let o = Command::new(env!("CARGO_BIN_EXE_mbtap"))
        .args(["sniff", "/nonexistent/ttyUSB-test", "--duration", "1"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(o.stdout.is_empty(), "{}", String::from_utf8_lossy(&o.stdout));
    assert!(stderr(&o).contains("/nonexistent/ttyUSB-test"), "{}", stderr(&o));
}

/// `--link-type` (a capture's link type) and "or what the capture says" appear only in the help of
/// commands that read a capture.
#[test]
fn help_lists_only_options_that_apply() {
    let help = |cmd: &str| {
        let o = Command::new(env!("CARGO_BIN_EXE_mbtap")).args([cmd, "--help"]).output().unwrap();
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    for live in ["simulate", "bridge", "sniff", "tap", "read"] {
        let h = help(live);
        assert!(!h.contains("--link-type") && !h.contains("what the capture says"), "{live}:\n{h}");
    }
    for capture in ["replay", "report", "export"] {
        assert!(help(capture).contains("--link-type"), "{capture}");
    }
}

/// With `--role` rules and `--mqtt-writes` but no `--mqtt-role`, anyone who could
/// publish on the broker wrote under the plain listeners' rules. The bridge refuses to start.
#[test]
fn mqtt_writes_with_roles_need_an_mqtt_role() {
    let o =
        bridge(&["--mqtt", "mqtt://127.0.0.1:9", "--monitor", "jsonl", "--mqtt-writes", "--role", "viewer=read-only"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--mqtt-role"), "{}", stderr(&o));
}
