//! Helpers shared by the tests that drive the real binary on pseudo-terminals.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::process::Child;
use std::time::{Duration, Instant};

/// The binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_mbtap");

/// A child process killed and reaped when the test ends, pass or fail.
pub struct Kill(pub Child);

impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Waits (up to 10 s) for a path to appear: a pty link, a recording.
pub fn wait_for(path: &std::path::Path) {
    let start = Instant::now();
    while !path.exists() {
        assert!(start.elapsed() < Duration::from_secs(10), "{} never appeared", path.display());
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Starts `mbtap simulate` (the MK4, Display and MKZP-0.4 on a pseudo-terminal) linked at
/// `link`, with `args` after the link and its stderr dropped; waits for the link.
pub fn simulate(link: &std::path::Path, args: &[&str]) -> Kill {
    // A link left by an earlier run would be taken for this one's.
    let _ = std::fs::remove_file(link);
    let sim = Kill(
        std::process::Command::new(BIN)
            .args(["simulate", "--link", link.to_str().unwrap()])
            .args(args)
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    wait_for(link);
    sim
}

/// `mbtap replay` of the MK4 document's examples (`captures/mk4-doc-examples-rtu.pcapng`)
/// serving what it heard (`--serve` on a free port, `--max-age AGE`), once the replay is done:
/// the process and the address it listens on.
pub fn spy_replay(max_age: &str) -> (Kill, String) {
    use std::io::BufRead;
    let capture = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("captures/mk4-doc-examples-rtu.pcapng");
    let mut child = std::process::Command::new(BIN)
        .args(["replay", capture.to_str().unwrap(), "--format", "summary", "--serve", "127.0.0.1:0"])
        .args(["--max-age", max_age])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = std::io::BufReader::new(child.stderr.take().unwrap()).lines();
    let addr = loop {
        let l = err.next().expect("replay ended before serving").unwrap();
        if let Some(rest) = l.strip_prefix("mbtap: spy server listening on ") {
            break rest.split_whitespace().next().unwrap().to_owned();
        }
    };
    // Served once the replay is done.
    loop {
        let l = err.next().expect("replay ended").unwrap();
        if l.contains("serving its register image") {
            break;
        }
    }
    // Keep draining stderr so the server never blocks on a full pipe.
    std::thread::spawn(move || for _ in err {});
    (Kill(child), addr)
}

/// A running `mbtap bridge`: the addresses it said it listens on, and what it wrote on stderr
/// after that.
pub struct Bridge {
    pub child: Kill,
    /// Modbus TCP, RTU over TCP, Modbus/TCP Security, metrics (`ADDR:PORT`), as asked for.
    pub tcp: Option<String>,
    pub rtu: Option<String>,
    pub tls: Option<String>,
    pub udp: Option<String>,
    pub metrics: Option<String>,
    /// `--web`: the live view's address.
    pub web: Option<String>,
    pub log: std::sync::Arc<std::sync::Mutex<Vec<String>>>,
}

/// Starts `mbtap bridge ARGS` and waits until every listener the arguments ask for is up.
pub fn bridge(args: &[&str]) -> Bridge {
    use std::io::{BufRead, BufReader};
    let mut child =
        std::process::Command::new(BIN).arg("bridge").args(args).stderr(std::process::Stdio::piped()).spawn().unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let wants = |flag: &str| args.contains(&flag);
    let (mut tcp, mut rtu, mut tls, mut udp, mut metrics, mut web) = (None, None, None, None, None, None);
    while (wants("--listen") && tcp.is_none())
        || (wants("--web") && web.is_none())
        || (wants("--listen-udp") && udp.is_none())
        || (wants("--listen-rtu") && rtu.is_none())
        || (wants("--listen-tls") && tls.is_none())
        || (wants("--metrics") && metrics.is_none())
    {
        let l = lines.next().expect("the bridge ended before listening").unwrap();
        if let Some(rest) = l.strip_prefix("mbtap: bridge listening on ") {
            let addr = Some(rest.split_whitespace().next().unwrap().to_owned());
            if rest.contains("(Modbus TCP)") {
                tcp = addr;
            } else if rest.contains("TLS") {
                tls = addr;
            } else if rest.contains("(Modbus UDP)") {
                udp = addr;
            } else {
                rtu = addr;
            }
        } else if let Some(rest) = l.strip_prefix("mbtap: metrics at http://") {
            metrics = Some(rest.trim_end_matches("/metrics").to_owned());
        } else if let Some(rest) = l.strip_prefix("mbtap: web view at http://") {
            web = Some(rest.split('/').next().unwrap().to_owned());
        }
    }
    let log = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let sink = std::sync::Arc::clone(&log);
    std::thread::spawn(move || {
        for l in lines.map_while(Result::ok) {
            sink.lock().unwrap().push(l);
        }
    });
    Bridge { child: Kill(child), tcp, rtu, tls, udp, metrics, web, log }
}

/// GET /metrics.
pub fn metrics_text(addr: &str) -> String {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.write_all(b"GET /metrics HTTP/1.0\r\n\r\n").unwrap();
    let mut out = String::new();
    s.read_to_string(&mut out).unwrap();
    out
}

/// The value of the series that starts `series ` (`name{labels}`); a series not there yet
/// (per-unit series appear with the unit's first request) is `None`.
pub fn metric(text: &str, series: &str) -> Option<f64> {
    text.lines().find_map(|l| l.strip_prefix(series)?.strip_prefix(' ')?.trim().parse().ok())
}

/// A pair of linked pseudo-terminals (socat), `a` and `b` in `dir`.
pub fn socat_pair(dir: &std::path::Path) -> (Kill, std::path::PathBuf, std::path::PathBuf) {
    let (a, b) = (dir.join("a"), dir.join("b"));
    let k = Kill(
        std::process::Command::new("socat")
            .args([format!("pty,raw,echo=0,link={}", a.display()), format!("pty,raw,echo=0,link={}", b.display())])
            .spawn()
            .expect("socat must be installed for this test"),
    );
    wait_for(&a);
    wait_for(&b);
    (k, a, b)
}

/// A counter's value (0 when the series is not there yet).
pub fn counter(addr: &str, series: &str) -> u64 {
    let text = metrics_text(addr);
    text.lines().find_map(|l| l.strip_prefix(series)?.strip_prefix(' ')?.trim().parse().ok()).unwrap_or(0)
}

/// Waits (up to 20 s) until something listens on loopback `port`: a broker, a Python server.
pub fn wait_port(port: u16) {
    let start = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(start.elapsed() < Duration::from_secs(20), "nothing ever listened on port {port}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// One Modbus TCP request (MBAP, Modbus Messaging on TCP/IP v1.0b §3.1.3); the answer's PDU.
pub fn call(s: &mut std::net::TcpStream, tid: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut f = vec![0u8; 7];
    f[..2].copy_from_slice(&tid.to_be_bytes());
    f[4..6].copy_from_slice(&u16::try_from(pdu.len() + 1).unwrap().to_be_bytes());
    f[6] = unit;
    f.extend_from_slice(pdu);
    std::io::Write::write_all(s, &f).unwrap();
    let mut head = [0u8; 7];
    std::io::Read::read_exact(s, &mut head).unwrap();
    assert_eq!(head[..2], tid.to_be_bytes(), "each client gets its own transaction id back");
    let mut answer = vec![0u8; usize::from(u16::from_be_bytes([head[4], head[5]])) - 1];
    std::io::Read::read_exact(s, &mut answer).unwrap();
    answer
}

/// `mbtap simulate ARGS` serving on a free Modbus TCP port (the caller's `--listen 127.0.0.1:0`
/// among `args`): the process, the address it listens on, what it said before listening, and
/// what it says after (gathered as it comes).
pub fn simulate_listening(args: &[&str]) -> (Kill, String, String, std::sync::Arc<std::sync::Mutex<String>>) {
    use std::io::BufRead;
    let mut child = std::process::Command::new(BIN)
        .arg("simulate")
        .args(args)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(child.stderr.take().unwrap()).lines();
    let mut before = String::new();
    let addr = loop {
        let l = lines.next().expect("simulate ended before listening").unwrap();
        if let Some(rest) = l.strip_prefix("mbtap: bridge listening on ") {
            break rest.split_whitespace().next().unwrap().to_owned();
        }
        before.push_str(&l);
        before.push('\n');
    };
    let after = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
    let sink = std::sync::Arc::clone(&after);
    std::thread::spawn(move || {
        for l in lines.map_while(Result::ok) {
            sink.lock().unwrap().push_str(&(l + "\n"));
        }
    });
    (Kill(child), addr, before, after)
}

/// The energy meter's vendor sheet (`tests/fixtures/sheets/energy-meter-modicon.csv`: f32 volts at
/// input register 0, watts at 12, …) imported into `dir/meter.toml`, as a user would.
pub fn imported_meter(dir: &std::path::Path) -> std::path::PathBuf {
    let sheet = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sheets/energy-meter-modicon.csv");
    let meter = dir.join("meter.toml");
    let _ = std::fs::remove_file(&meter);
    let out = std::process::Command::new(BIN)
        .args(["profiles", "import", sheet.to_str().unwrap(), "-o", meter.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    meter
}
