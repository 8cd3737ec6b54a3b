//! Every option that takes a number, of every command, at values no one should give: `inf`,
//! `nan`, `1e300`, `1e-300`, `-1`. Each is refused naming what it expects, or taken — never a
//! panic (exit status 101, "panicked" on standard error). A command that takes the value and
//! runs on is stopped after a moment: what matters is that it did not panic first.

use std::io::Read;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_mbtap");

/// The values tried on each option.
const HOSTILE: [&str; 5] = ["inf", "nan", "1e300", "1e-300", "-1"];

/// A command line that runs with its other arguments valid (every port and file that must
/// not exist does not), and the numeric options to try on it.
fn cases(capture: &str, out: &str) -> Vec<(Vec<String>, Vec<&'static str>)> {
    let v = |args: &[&str]| args.iter().map(|&a| a.to_owned()).collect::<Vec<String>>();
    vec![
        (
            v(&["bridge", "--serial", "/nonexistent/tty", "--listen", "127.0.0.1:0"]),
            vec![
                "--turnaround-ms",
                "--rate-limit",
                "--timeout-ms",
                "--retries",
                "--max-connections",
                "--queue-per-client",
                "--baud",
            ],
        ),
        (
            v(&["bridge", "--reverse", "--serial", "/nonexistent/tty", "--target", "127.0.0.1:9", "--answer-as", "1"]),
            vec!["--turnaround-ms", "--timeout-ms"],
        ),
        (v(&["simulate", "--listen", "127.0.0.1:0", "--duration", "1"]), vec!["--turnaround-ms"]),
        (v(&["demo", "--duration", "1", "--format", "jsonl"]), vec!["--speed"]),
        (v(&["play", capture, "/nonexistent/tty"]), vec!["--speed", "--max-gap"]),
        (v(&["probe", "127.0.0.1:9", "--range", "0-1"]), vec!["--rate", "--timeout-ms", "--unit"]),
        (
            v(&["generate", out, "--transactions", "10", "--force"]),
            vec!["--noise", "--corrupt", "--slow", "--glitch", "--lookalike", "--transactions", "--seed"],
        ),
        (v(&["replay", capture, "--format", "summary"]), vec!["--latency-ms", "--report-every", "--baud"]),
        (v(&["read", "127.0.0.1:9", "holding", "0"]), vec!["--timeout-ms", "--retries", "--unit"]),
    ]
}

/// Runs `args`; its exit status (None: still running after `wait`, then stopped) and stderr.
fn run(args: &[String], wait: Duration) -> (Option<i32>, String) {
    let mut child =
        Command::new(BIN).args(args).stdin(Stdio::null()).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s.code();
        }
        if start.elapsed() > wait {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut err = String::new();
    let _ = child.stderr.take().unwrap().read_to_string(&mut err);
    (status, err)
}

#[test]
fn no_numeric_option_panics_at_any_value() {
    let dir = std::env::temp_dir().join(format!("mbtap-numeric-options-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let capture = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("captures/mk4-doc-examples-rtu.pcapng");
    let mut runs = Vec::new();
    for (base, options) in cases(capture.to_str().unwrap(), dir.join("out.pcapng").to_str().unwrap()) {
        for option in options {
            for value in HOSTILE {
                let mut args = base.clone();
                args.push(format!("{option}={value}"));
                runs.push(args);
            }
        }
    }
    // A few at a time: most are refused at once; the ones that run are stopped after 3 s.
    let mut failures = Vec::new();
    for batch in runs.chunks(8) {
        let handles: Vec<_> = batch
            .iter()
            .cloned()
            .map(|args| std::thread::spawn(move || (run(&args, Duration::from_secs(3)), args)))
            .collect();
        for h in handles {
            let ((status, err), args) = h.join().unwrap();
            if status == Some(101) || err.contains("panicked") {
                failures.push(format!("mbtap {}: {err}", args.join(" ")));
            }
            // The value must reach the option: a command line refused for another reason
            // (an argument the command does not take) would test nothing.
            if err.contains("unexpected argument") {
                failures.push(format!("mbtap {}: not a command line the value reaches: {err}", args.join(" ")));
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
    assert!(failures.is_empty(), "{} failures:\n{}", failures.len(), failures.join("\n"));
}

#[test]
fn a_wait_out_of_range_is_refused_naming_its_range() {
    let args: Vec<String> =
        ["bridge", "--serial", "/nonexistent/tty", "--listen", "127.0.0.1:0", "--turnaround-ms", "1e300"]
            .iter()
            .map(|&a| a.to_owned())
            .collect();
    let (status, err) = run(&args, Duration::from_secs(5));
    assert_eq!(status, Some(2), "{err}");
    assert!(err.contains("--turnaround-ms") && err.contains("0 to 3600000"), "{err}");
}
