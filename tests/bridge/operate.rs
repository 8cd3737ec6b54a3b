//! Operating a gateway: pacing per unit (`--unit-gap`), the audit of writes (`--audit`) and the
//! live web view (`--web`), through the bridge in front of `mbtap simulate` on a pseudo-terminal.

use std::time::{Duration, Instant};

use crate::common;

fn dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("mbtap-operate-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Read input register 430 (MAP v1.1b3 §6.4: FC 04, address 01AE, quantity 0001).
const READ_430: [u8; 5] = [0x04, 0x01, 0xAE, 0x00, 0x01];

/// `--unit-gap 1=40` (here from the configuration file, as a deployed bridge has it): twenty
/// reads of unit 1 take at least 0.8 s (nineteen gaps of 40 ms and the exchanges), the time is
/// in the metrics; unit 5 beside it waits for no gap (its counter never appears).
#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn a_units_gap_paces_its_requests_and_no_one_elses() {
    let d = dir("gap");
    let bus = d.join("bus");
    let _sim = common::simulate(&bus, &["--duration", "120"]);
    let config = d.join("bridge.toml");
    std::fs::write(&config, format!("[bridge]\nserial = {:?}\nunit-gap = [\"1=40\"]\n", bus.to_str().unwrap()))
        .unwrap();
    let b =
        common::bridge(&["--config", config.to_str().unwrap(), "--listen", "127.0.0.1:0", "--metrics", "127.0.0.1:0"]);
    let mut s = std::net::TcpStream::connect(b.tcp.as_deref().unwrap()).unwrap();
    for tid in 0..5 {
        assert_eq!(common::call(&mut s, tid, 5, &[0x04, 0x00, 0x00, 0x00, 0x02])[0], 0x04, "unit 5 answers");
    }
    let start = Instant::now();
    for tid in 0..20 {
        assert_eq!(common::call(&mut s, 100 + tid, 1, &READ_430)[0], 0x04, "unit 1 answers");
    }
    let took = start.elapsed();
    assert!(took >= Duration::from_millis(800), "20 reads with a 40 ms gap took {took:?}");
    let m = common::metrics_text(b.metrics.as_deref().unwrap());
    let waited = common::metric(&m, "mbtap_bridge_unit_gap_wait_seconds_total{unit=\"1\"}").unwrap_or(0.0);
    // Each request waits what is left of its 40 ms when it arrives (less when the client is
    // slow to ask again): nineteen gaps count most of 0.76 s.
    assert!(waited >= 0.5, "{waited} s waited for unit 1's gap:\n{m}");
    assert_eq!(common::metric(&m, "mbtap_bridge_unit_gap_wait_seconds_total{unit=\"5\"}"), None, "{m}");
    std::fs::remove_dir_all(&d).ok();
}

/// `--audit FILE`: a write done, a write refused by the bridge (and why), a device's exception —
/// each one JSON line with the client's address; the reads between them leave no line.
#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn the_audit_holds_every_write_and_how_it_ended_and_no_read() {
    let d = dir("audit");
    let bus = d.join("bus");
    let log = d.join("audit.jsonl");
    let _sim = common::simulate(&bus, &["--duration", "120"]);
    let b = common::bridge(&[
        "--serial",
        bus.to_str().unwrap(),
        "--listen",
        "127.0.0.1:0",
        "--allow-function",
        "3",
        "--allow-function",
        "4",
        "--allow-function",
        "6",
        "--audit",
        log.to_str().unwrap(),
        "--metrics",
        "127.0.0.1:0",
    ]);
    let mut s = std::net::TcpStream::connect(b.tcp.as_deref().unwrap()).unwrap();
    let me = s.local_addr().unwrap().to_string();
    // MAP v1.1b3 §6.6: write single register 100 = 5 (the MK4 takes it).
    assert_eq!(common::call(&mut s, 1, 1, &[0x06, 0x00, 0x64, 0x00, 0x05]), [0x06, 0x00, 0x64, 0x00, 0x05]);
    assert_eq!(common::call(&mut s, 2, 1, &READ_430)[0], 0x04);
    // §6.12: write multiple registers 100–101: not an allowed function, refused with 01.
    assert_eq!(common::call(&mut s, 3, 1, &[0x10, 0x00, 0x64, 0x00, 0x01, 0x02, 0x00, 0x07]), [0x90, 0x01]);
    // §6.6 to 9999, which the MK4 does not have: its exception 02.
    assert_eq!(common::call(&mut s, 4, 1, &[0x06, 0x27, 0x0F, 0x00, 0x01]), [0x86, 0x02]);
    assert_eq!(common::call(&mut s, 5, 1, &READ_430)[0], 0x04);
    // The writer syncs each batch: the lines are there once the metrics count them.
    let start = Instant::now();
    let lines: Vec<serde_json::Value> = loop {
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        let lines: Vec<serde_json::Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        if lines.len() >= 3 || start.elapsed() > Duration::from_secs(5) {
            break lines;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(lines.len(), 3, "three writes, no read: {lines:#?}");
    for l in &lines {
        assert_eq!(l["client"]["address"], me.as_str(), "{l}");
        assert_eq!(l["client"]["transport"], "tcp", "{l}");
        assert_eq!(l["unit"], 1, "{l}");
        assert!(l["time"].as_str().unwrap().ends_with('Z'), "{l}");
    }
    assert_eq!((lines[0]["function"].as_u64(), lines[0]["address"].as_u64()), (Some(6), Some(100)));
    assert_eq!(lines[0]["values"], serde_json::json!([5]));
    assert_eq!(lines[0]["outcome"], "done");
    assert_eq!(lines[1]["function"], 16);
    assert!(lines[1]["outcome"].as_str().unwrap().starts_with("refused: "), "{}", lines[1]);
    assert_eq!(lines[2]["outcome"], "exception 02");
    let m = common::metrics_text(b.metrics.as_deref().unwrap());
    assert_eq!(common::metric(&m, "mbtap_bridge_audit_records_total"), Some(3.0), "{m}");
    assert_eq!(common::metric(&m, "mbtap_bridge_audit_lost_total"), Some(0.0), "{m}");
    std::fs::remove_dir_all(&d).ok();
}

/// A full disk (`/dev/full`: every write fails with ENOSPC) never holds a write back: the client
/// gets its answer, what could not be recorded is counted and said.
#[test]
#[ignore = "drives real pseudo-terminals; .ci/run runs this with --ignored"]
fn a_full_disk_loses_audit_lines_counted_and_said_never_a_request() {
    let d = dir("audit-full");
    let bus = d.join("bus");
    let _sim = common::simulate(&bus, &["--duration", "120"]);
    let b = common::bridge(&[
        "--serial",
        bus.to_str().unwrap(),
        "--listen",
        "127.0.0.1:0",
        "--audit",
        "/dev/full",
        "--metrics",
        "127.0.0.1:0",
    ]);
    let mut s = std::net::TcpStream::connect(b.tcp.as_deref().unwrap()).unwrap();
    for tid in 0..3 {
        assert_eq!(common::call(&mut s, tid, 1, &[0x06, 0x00, 0x64, 0x00, 0x05])[0], 0x06, "answered");
    }
    let start = Instant::now();
    let lost = loop {
        let m = common::metrics_text(b.metrics.as_deref().unwrap());
        let lost = common::metric(&m, "mbtap_bridge_audit_lost_total").unwrap_or(0.0);
        if lost >= 3.0 || start.elapsed() > Duration::from_secs(5) {
            break lost;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!((lost - 3.0).abs() < f64::EPSILON, "{lost}");
    let said = b.log.lock().unwrap().join("\n");
    assert!(said.contains("--audit /dev/full: cannot write") && said.contains("lost"), "{said}");
    std::fs::remove_dir_all(&d).ok();
}

/// GET a path of the web view; the body.
fn get(addr: &str, path: &str) -> String {
    use std::io::{Read, Write};
    // A connection the view closes unanswered (all its slots taken) reads as nothing.
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    let _ = write!(s, "GET {path} HTTP/1.1\r\nHost: x\r\n\r\n");
    let mut text = String::new();
    let _ = s.read_to_string(&mut text);
    text.split_once("\r\n\r\n").map(|(_, b)| b.to_owned()).unwrap_or_default()
}

/// The page as headless Chromium renders it after its script ran for `ms` of virtual time.
fn rendered(url: &str, ms: u32) -> String {
    let browser = ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|b| std::process::Command::new(b).arg("--version").output().is_ok_and(|o| o.status.success()))
        .expect("chromium must be installed for this test");
    // `timeout`: a page that never settles fails the test instead of hanging it.
    let out = std::process::Command::new("timeout")
        .args(["60", browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"])
        .arg(format!("--virtual-time-budget={ms}"))
        .args(["--dump-dom", url])
        .output()
        .unwrap();
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A field of a unit as the page shows it (`data-unit="1" data-field="requests"`).
fn shown(dom: &str, unit: u8, field: &str) -> Option<String> {
    let key = format!("data-unit=\"{unit}\" data-field=\"{field}\">");
    let at = dom.find(&key)? + key.len();
    Some(dom[at..].split('<').next()?.to_owned())
}

/// `--web`: headless Chromium opens the page; unit 1's request count on it is `/api/state`'s,
/// and after more traffic both show the new count; the page took several updates from its
/// event stream. The page fetches nothing from elsewhere, and refuses to write.
#[test]
#[ignore = "needs chromium and real pseudo-terminals; .ci/run installs it and runs this with --ignored"]
fn the_web_view_shows_what_the_api_says_and_follows_the_traffic() {
    let d = dir("web");
    let bus = d.join("bus");
    let _sim = common::simulate(&bus, &["--duration", "120"]);
    let b = common::bridge(&["--serial", bus.to_str().unwrap(), "--listen", "127.0.0.1:0", "--web", "127.0.0.1:0"]);
    let web = b.web.clone().unwrap();
    let mut s = std::net::TcpStream::connect(b.tcp.as_deref().unwrap()).unwrap();
    for round in 0..2u16 {
        for tid in 0..(3 + round * 4) {
            assert_eq!(common::call(&mut s, tid, 1, &READ_430)[0], 0x04);
        }
        let api: serde_json::Value = serde_json::from_str(&get(&web, "/api/state")).unwrap();
        let unit = api["lines"][0]["units"].as_array().unwrap().iter().find(|u| u["unit"] == 1).unwrap().clone();
        // Three updates from the event stream, then the page stops following (`?updates=3`).
        let dom = rendered(&format!("http://{web}/?updates=3"), 5000);
        assert_eq!(shown(&dom, 1, "requests"), Some(unit["requests"].to_string()), "round {round}: {unit}\n{dom}");
        assert_eq!(shown(&dom, 1, "answers"), Some(unit["answers"].to_string()));
        let updates: u32 = dom.split("data-updates=\"").nth(1).unwrap().split('"').next().unwrap().parse().unwrap();
        assert!(updates >= 2, "the page updated {updates} times from its event stream");
        assert!(dom.contains("data-client=\"127.0.0.1:"), "the client is listed");
    }
    let page = get(&web, "/");
    // Nothing fetched from elsewhere: no link, source, stylesheet import or URL but the SVG
    // namespace's name (an identifier, never fetched).
    for outside in ["<link", "src=", "url(", "@import", "https://"] {
        assert!(!page.contains(outside), "the page names {outside}");
    }
    assert_eq!(page.matches("http://").count(), page.matches("http://www.w3.org/2000/svg").count());
    let mut post = std::net::TcpStream::connect(&web).unwrap();
    std::io::Write::write_all(&mut post, b"POST /api/state HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\n\r\n").unwrap();
    let mut answer = String::new();
    std::io::Read::read_to_string(&mut post, &mut answer).unwrap();
    assert!(answer.starts_with("HTTP/1.1 405"), "{answer}");
    std::fs::remove_dir_all(&d).ok();
}

/// A web view on an address that is not loopback, without `--web-allow-ip`, is refused at start
/// with what to give; with one, it starts.
#[test]
fn a_web_view_open_beyond_loopback_needs_an_allow_list() {
    let out = std::process::Command::new(common::BIN)
        .args([
            "bridge",
            "--serial",
            "/dev/null-none",
            "--listen",
            "127.0.0.1:0",
            "--web",
            "0.0.0.0:0",
            "--duration",
            "1",
        ])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && said.contains("--web-allow-ip"), "{said}");
    let out = std::process::Command::new(common::BIN)
        .args(["bridge", "--serial", "/dev/null-none", "--listen", "127.0.0.1:0", "--web", "0.0.0.0:0"])
        .args(["--web-allow-ip", "127.0.0.1", "--duration", "1"])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && said.contains("web view at http://0.0.0.0:"), "{said}");
}

/// The view is bounded like every other front: 32 connections that say nothing hold every
/// slot, the next one is closed unanswered (counted), and once the silent ones time out (5 s
/// for a request head) the view answers again.
#[test]
fn the_web_views_connections_are_bounded_and_silent_ones_time_out() {
    use std::io::{Read, Write};
    let b = common::bridge(&[
        "--serial",
        "/dev/null-none",
        "--listen",
        "127.0.0.1:0",
        "--web",
        "127.0.0.1:0",
        "--metrics",
        "127.0.0.1:0",
        "--duration",
        "30",
    ]);
    let web = b.web.clone().unwrap();
    let silent: Vec<std::net::TcpStream> = (0..32).map(|_| std::net::TcpStream::connect(&web).unwrap()).collect();
    std::thread::sleep(Duration::from_millis(300));
    let mut extra = std::net::TcpStream::connect(&web).unwrap();
    extra.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
    let _ = extra.write_all(b"GET /api/state HTTP/1.1\r\n\r\n");
    let mut got = Vec::new();
    let _ = extra.read_to_end(&mut got);
    assert!(got.is_empty(), "past 32 connections: closed unanswered, got {}", String::from_utf8_lossy(&got));
    let m = common::metrics_text(b.metrics.as_deref().unwrap());
    assert!(common::metric(&m, "mbtap_bridge_refused_total{reason=\"web_connections\"}").unwrap_or(0.0) >= 1.0, "{m}");
    let start = Instant::now();
    loop {
        assert!(start.elapsed() < Duration::from_secs(15), "the view never answered again");
        std::thread::sleep(Duration::from_millis(500));
        if get(&web, "/api/state").starts_with('{') {
            break;
        }
    }
    drop(silent);
}
