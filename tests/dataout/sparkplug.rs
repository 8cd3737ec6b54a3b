//! Sparkplug B and store-and-forward against a real Mosquitto and a Sparkplug host outside this
//! project: a subscriber decoding every payload with the specification's own `sparkplug_b.proto`
//! (pysparkplug's compiled copy, `tests/interop/sparkplug_host.py`). Births with bdSeq, data by
//! exception with a seq that counts without a gap, DDEATH when a simulated unit loses power and
//! DBIRTH when it is back, rebirth on NCMD, the NDEATH will on kill -9; a broker
//! stopped for 30 s (every value measured meanwhile arrives, historical, in order, with its
//! timestamp) and mbtap restarted while it is away. Needs mosquitto, python3, paho-mqtt and
//! pysparkplug: `#[ignore]`d in a plain `cargo test`, run by `.ci/run`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // tests may fail loudly

use std::io::{BufRead, BufReader};
use std::net::TcpListener;
use std::os::unix::fs::PermissionsExt as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::common;
use common::{BIN, Kill, wait_port};

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("mbtap-sparkplug-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

fn now_ms() -> u64 {
    u64::try_from(std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_millis()).unwrap()
}

/// A Mosquitto broker on `port` that keeps sessions across a restart (persistence in `d`, which
/// the broker's own user must be able to write) and queues QoS 0 messages for a persistent
/// subscriber that is away: the host must not miss what is forwarded while it reconnects.
fn broker(d: &Path, port: u16) -> Child {
    let store = d.join("broker");
    std::fs::create_dir_all(&store).unwrap();
    std::fs::set_permissions(&store, std::fs::Permissions::from_mode(0o777)).unwrap();
    let conf = d.join("mosquitto.conf");
    std::fs::write(
        &conf,
        format!(
            "listener {port} 127.0.0.1\nallow_anonymous true\npersistence true\npersistence_location {}/\nautosave_interval 1\nqueue_qos0_messages true\nmax_queued_messages 100000\n",
            store.display()
        ),
    )
    .unwrap();
    let mosquitto = if Path::new("/usr/sbin/mosquitto").exists() { "/usr/sbin/mosquitto" } else { "mosquitto" };
    let child = Command::new(mosquitto)
        .arg("-c")
        .arg(&conf)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("mosquitto must be installed for this test");
    wait_port(port);
    child
}

/// Stops a process with SIGTERM (a broker saves its sessions, mbtap ends cleanly) and waits.
fn terminate(mut child: Child) {
    let _ = Command::new("kill").args(["-TERM", &child.id().to_string()]).status();
    let _ = child.wait();
}

/// The Sparkplug host: every message it received, decoded.
struct Host {
    _child: Kill,
    got: Arc<Mutex<Vec<serde_json::Value>>>,
}

impl Host {
    fn start(port: u16) -> Self {
        let mut child = Command::new("python3")
            .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/interop/sparkplug_host.py"))
            .args(["listen", &port.to_string()])
            .stdout(Stdio::piped())
            .spawn()
            .expect("python3 must be installed for this test");
        let out = child.stdout.take().unwrap();
        let got = Arc::new(Mutex::new(Vec::new()));
        let sink = Arc::clone(&got);
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for l in BufReader::new(out).lines().map_while(Result::ok) {
                let v: serde_json::Value = serde_json::from_str(&l).unwrap();
                if v.get("ready").is_some() {
                    let _ = ready_tx.send(());
                } else {
                    sink.lock().unwrap().push(v);
                }
            }
        });
        ready_rx.recv_timeout(Duration::from_secs(30)).expect("the host never subscribed");
        Self { _child: Kill(child), got }
    }

    fn got(&self) -> Vec<serde_json::Value> {
        self.got.lock().unwrap().clone()
    }

    /// Waits (bounded: a hang guard, not a timing assertion) until `pred` holds.
    fn wait_for(&self, what: &str, limit: Duration, pred: impl Fn(&[serde_json::Value]) -> bool) {
        let start = Instant::now();
        while !pred(&self.got()) {
            assert!(start.elapsed() < limit, "never got {what}: {:#?}", kinds(&self.got()));
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

/// The message type of a Sparkplug topic (`spBv1.0/G/NBIRTH/N…` → `NBIRTH`), and its device.
fn kind(m: &serde_json::Value) -> (&str, Option<&str>) {
    let topic = m["topic"].as_str().unwrap();
    if topic.starts_with("spBv1.0/STATE/") {
        return ("STATE", None);
    }
    let mut parts = topic.split('/');
    let k = parts.nth(2).unwrap();
    (k, parts.nth(1))
}

fn kinds(got: &[serde_json::Value]) -> Vec<String> {
    got.iter().map(|m| format!("{:?} seq {}", kind(m), m["payload"]["seq"])).collect()
}

fn seq(m: &serde_json::Value) -> Option<u64> {
    m["payload"]["seq"].as_str().and_then(|s| s.parse().ok())
}

fn bd_seq(m: &serde_json::Value) -> u64 {
    let metric = m["payload"]["metrics"].as_array().unwrap().iter().find(|x| x["name"] == "bdSeq").unwrap();
    metric["long_value"].as_str().unwrap().parse().unwrap()
}

fn is(m: &serde_json::Value, k: &str, device: Option<&str>) -> bool {
    kind(m) == (k, device)
}

/// Every message from an NBIRTH on: seq 0 at the NBIRTH, then one more each (mod 256); NDEATH
/// carries none.
fn assert_seq_counts(got: &[serde_json::Value]) {
    let mut expect: Option<u64> = None;
    for m in got {
        assert!(m.get("error").is_none(), "the specification's schema refused a payload: {m}");
        match kind(m).0 {
            // Commands and the host's state are the host's, not the node's.
            "NCMD" | "DCMD" | "STATE" => {}
            "NDEATH" => assert_eq!(seq(m), None, "{m}"),
            "NBIRTH" => {
                assert_eq!(seq(m), Some(0), "{m}");
                expect = Some(1);
            }
            _ => {
                if let Some(e) = expect {
                    assert_eq!(seq(m), Some(e), "a gap in seq at {}: {:#?}", m["topic"], kinds(got));
                }
                expect = seq(m).map(|s| (s + 1) % 256);
            }
        }
    }
}

fn spawn_demo(port: u16, extra: &[&str]) -> Child {
    Command::new(BIN)
        .args(["demo", "--format", "summary", "--mqtt", &format!("mqtt://127.0.0.1:{port}")])
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

#[test]
#[ignore = "needs mosquitto, python3 and pysparkplug; .ci/run installs them and runs this with --ignored"]
fn births_data_deaths_rebirth_and_the_will_as_a_host_sees_them() {
    let d = dir("node");
    let port = free_port();
    let _broker = Kill(broker(&d, port));
    let host = Host::start(port);
    // Twice the line's speed: the last unit (the MKZP, 17) loses power 20–40 s into each minute
    // of bus time, 10–20 s of the clock.
    let mut mbtap = spawn_demo(
        port,
        &["--speed", "2", "--duration", "600", "--fault", "unit-outage", "--sparkplug", "plant/station"],
    );
    mbtap.drain();
    let mkzp = Some("mkzp-17");
    host.wait_for("the MKZP's death", Duration::from_mins(1), |g| g.iter().any(|m| is(m, "DDEATH", mkzp)));
    host.wait_for("the MKZP's birth after its death", Duration::from_mins(1), |g| {
        let death = g.iter().position(|m| is(m, "DDEATH", mkzp)).unwrap();
        g[death..].iter().any(|m| is(m, "DBIRTH", mkzp))
    });
    let got = host.got();
    let nbirth = got.iter().find(|m| is(m, "NBIRTH", None)).unwrap();
    let names: Vec<&str> =
        nbirth["payload"]["metrics"].as_array().unwrap().iter().map(|m| m["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["bdSeq", "Node Control/Rebirth"]);
    // A DBIRTH declares each metric's datatype, and its engineering unit where it has one.
    let dbirth = got.iter().find(|m| is(m, "DBIRTH", Some("mk4-1"))).unwrap();
    let volts =
        dbirth["payload"]["metrics"].as_array().unwrap().iter().find(|m| m["name"] == "Phase A (L1) voltage").unwrap();
    assert_eq!(volts["datatype"], 10, "Double: {volts}");
    assert_eq!(volts["properties"]["keys"][0], "engUnit");
    assert_eq!(volts["properties"]["values"][0]["string_value"], "V");
    // Data by exception: a DDATA carries only what changed, never the whole device.
    let ddata = got.iter().find(|m| is(m, "DDATA", Some("mk4-1"))).unwrap();
    assert!(
        ddata["payload"]["metrics"].as_array().unwrap().len() < dbirth["payload"]["metrics"].as_array().unwrap().len()
    );

    // Rebirth on the host's command: NBIRTH (seq 0) and a DBIRTH per live device.
    let before = host.got().len();
    let cmd = Command::new("python3")
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/interop/sparkplug_host.py"))
        .args(["rebirth", &port.to_string(), "plant", "station"])
        .status()
        .unwrap();
    assert!(cmd.success());
    host.wait_for("the rebirth", Duration::from_secs(30), |g| g[before..].iter().any(|m| is(m, "NBIRTH", None)));
    host.wait_for("the DBIRTHs after the rebirth", Duration::from_secs(30), |g| {
        let at = before + g[before..].iter().position(|m| is(m, "NBIRTH", None)).unwrap();
        g[at..].iter().any(|m| is(m, "DBIRTH", Some("mk4-1")))
    });

    // kill -9: the broker publishes the will, the NDEATH with the session's bdSeq.
    mbtap.kill().unwrap();
    let _ = mbtap.wait();
    host.wait_for("the NDEATH will", Duration::from_secs(30), |g| g.iter().any(|m| is(m, "NDEATH", None)));
    let got = host.got();
    let ndeath = got.iter().find(|m| is(m, "NDEATH", None)).unwrap();
    assert_eq!(bd_seq(ndeath), bd_seq(nbirth), "the will's bdSeq is its session's");
    assert_seq_counts(&got);
}

/// What `spawn_demo` needs of a child: its stderr read on (or the pipe fills and it stalls).
trait DrainStderr {
    fn drain(&mut self);
    fn stderr_lines(&mut self) -> Arc<Mutex<Vec<String>>>;
}

impl DrainStderr for Child {
    fn drain(&mut self) {
        let _ = self.stderr_lines();
    }

    fn stderr_lines(&mut self) -> Arc<Mutex<Vec<String>>> {
        let lines = Arc::new(Mutex::new(Vec::new()));
        if let Some(err) = self.stderr.take() {
            let sink = Arc::clone(&lines);
            std::thread::spawn(move || {
                for l in BufReader::new(err).lines().map_while(Result::ok) {
                    sink.lock().unwrap().push(l);
                }
            });
        }
        lines
    }
}

/// Historical metrics of the messages after the last NBIRTH: (timestamp, arrival index).
fn historical(got: &[serde_json::Value]) -> Vec<u64> {
    let mut out = Vec::new();
    for m in got {
        if kind(m).0 != "DDATA" {
            continue;
        }
        for x in m["payload"]["metrics"].as_array().unwrap() {
            if x["is_historical"] == true {
                out.push(x["timestamp"].as_str().unwrap().parse::<u64>().unwrap());
            }
        }
    }
    out
}

/// The largest step between consecutive times, and whether they never go back.
fn steps(ts: &[u64]) -> (u64, bool) {
    let max = ts.windows(2).map(|w| w[1].saturating_sub(w[0])).max().unwrap_or(0);
    (max, ts.windows(2).all(|w| w[1] >= w[0]))
}

#[test]
#[ignore = "needs mosquitto, python3 and pysparkplug; .ci/run installs them and runs this with --ignored"]
fn a_broker_away_for_30_s_loses_nothing_measured_meanwhile() {
    let d = dir("outage");
    let port = free_port();
    let b = broker(&d, port);
    let host = Host::start(port);
    let buffer = d.join("held");
    let mut mbtap = spawn_demo(
        port,
        &[
            "--speed",
            "1",
            "--duration",
            "600",
            "--sparkplug",
            "plant/station",
            "--mqtt-buffer",
            buffer.to_str().unwrap(),
        ],
    );
    let err = mbtap.stderr_lines();
    let _mbtap = Kill(mbtap);
    host.wait_for("data", Duration::from_secs(30), |g| g.iter().any(|m| is(m, "DDATA", Some("mk4-1"))));
    let first_birth = bd_seq(host.got().iter().find(|m| is(m, "NBIRTH", None)).unwrap());
    let stopped = now_ms();
    terminate(b);
    std::thread::sleep(Duration::from_secs(30));
    let back = now_ms();
    let _b = Kill(broker(&d, port));
    host.wait_for("live data after the held data", Duration::from_mins(1), |g| {
        let Some(at) = g.iter().rposition(|m| is(m, "NBIRTH", None)) else { return false };
        !historical(&g[at..]).is_empty()
            && g[at..].iter().any(|m| {
                is(m, "DDATA", Some("mk4-1"))
                    && m["payload"]["metrics"].as_array().unwrap().iter().all(|x| x.get("is_historical").is_none())
            })
    });
    let got = host.got();
    let at = got.iter().rposition(|m| is(m, "NBIRTH", None)).unwrap();
    assert_eq!(bd_seq(&got[at]), first_birth + 1, "a new session, the next bdSeq");
    let held = historical(&got[at..]);
    let (max_step, in_order) = steps(&held);
    assert!(in_order, "held values forwarded in the order they were measured");
    // The demo polls every unit about every 1.2 s: the held values cover the outage with no
    // hole longer than a few polls, from its start to its end.
    assert!(held[0] <= stopped + 3_000, "the first held value {} ms after the broker stopped", held[0] - stopped);
    assert!(
        *held.last().unwrap() + 3_000 >= back,
        "the last held value {} ms before it was back",
        back - held.last().unwrap()
    );
    assert!(max_step <= 3_000, "a hole of {max_step} ms in the held values");
    assert_seq_counts(&got[at..]);
    let said = err.lock().unwrap().join("\n");
    assert!(said.contains("forwarding what was held"), "{said}");
}

#[test]
#[ignore = "needs mosquitto, python3 and pysparkplug; .ci/run installs them and runs this with --ignored"]
fn held_messages_survive_a_restart_of_mbtap() {
    let d = dir("restart");
    let port = free_port();
    let b = broker(&d, port);
    let host = Host::start(port);
    let buffer = d.join("held");
    let args = [
        "--speed",
        "1",
        "--duration",
        "600",
        "--sparkplug",
        "plant/station",
        "--mqtt-buffer",
        buffer.to_str().unwrap(),
    ];
    let mut first = spawn_demo(port, &args);
    let err = first.stderr_lines();
    host.wait_for("data", Duration::from_secs(30), |g| g.iter().any(|m| is(m, "DDATA", Some("mk4-1"))));
    let stopped = now_ms();
    terminate(b);
    std::thread::sleep(Duration::from_secs(6));
    let first_end = now_ms();
    terminate(first);
    let said = err.lock().unwrap().join("\n");
    assert!(said.contains("held on disk for the next run"), "{said}");
    let mut second = spawn_demo(port, &args);
    second.drain();
    let _second = Kill(second);
    std::thread::sleep(Duration::from_secs(2));
    let _b = Kill(broker(&d, port));
    host.wait_for("the first run's held values", Duration::from_mins(1), |g| {
        historical(g).iter().any(|&t| t >= first_end - 2_000 && t <= first_end)
    });
    let held = historical(&host.got());
    assert!(held.iter().any(|&t| t >= stopped && t <= stopped + 3_000), "the start of the first run's outage");
    assert_seq_counts(&host.got()[host.got().iter().rposition(|m| is(m, "NBIRTH", None)).unwrap()..]);
}

/// A DCMD from the host reaches the simulated MK4 through the profile (a scaled set
/// point by its published name) and the value comes back as DDATA; one out of the profile's
/// range is refused and never written.
#[test]
#[ignore = "needs mosquitto, python3 and pysparkplug; .ci/run installs them and runs this with --ignored"]
fn a_dcmd_write_reaches_the_device_and_comes_back_as_data() {
    let d = dir("dcmd");
    let port = free_port();
    let _broker = Kill(broker(&d, port));
    let host = Host::start(port);
    let bus = d.join("bus");
    let _sim = common::simulate(&bus, &["--duration", "120"]);
    let mut watch = Command::new(BIN)
        .args(["watch", bus.to_str().unwrap(), "--device", "mk4", "--interval", "200ms", "--count", "300"])
        .args(["--format", "jsonl", "--mqtt", &format!("mqtt://127.0.0.1:{port}")])
        .args(["--sparkplug", "plant/watch", "--mqtt-writes", "holding:102..105"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let err = watch.stderr_lines();
    let _watch = Kill(watch);
    host.wait_for("the MK4's birth", Duration::from_secs(30), |g| g.iter().any(|m| is(m, "DBIRTH", Some("mk4-1"))));
    let dcmd = |metric: &str, value: &str| {
        let ok = Command::new("python3")
            .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/interop/sparkplug_host.py"))
            .args(["dcmd", &port.to_string(), "plant", "watch", "mk4-1", metric, value])
            .status()
            .unwrap();
        assert!(ok.success());
    };
    dcmd("Level 2 set point (pump 1 on)", "3.5");
    dcmd("Working pumps", "7");
    host.wait_for("the new set point as data", Duration::from_secs(30), |g| {
        g.iter().any(|m| {
            is(m, "DDATA", Some("mk4-1"))
                && m["payload"]["metrics"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|x| x["name"] == "Level 2 set point (pump 1 on)" && x["double_value"].as_f64() == Some(3.5))
        })
    });
    let start = Instant::now();
    while !err.lock().unwrap().iter().any(|l| l.contains("write refused")) {
        assert!(start.elapsed() < Duration::from_secs(30), "{:#?}", err.lock().unwrap());
        std::thread::sleep(Duration::from_millis(100));
    }
    let said = err.lock().unwrap().join("\n");
    assert!(said.contains("outside the documented range"), "{said}");
    // Never written: no DDATA ever carries 7 working pumps.
    assert!(!host.got().iter().any(|m| {
        m["payload"]["metrics"]
            .as_array()
            .is_some_and(|ms| ms.iter().any(|x| x["name"] == "Working pumps" && x["long_value"].as_str() == Some("7")))
    }));
}

/// Rumqttc refuses packets over 10 KiB by default and drops the
/// connection over one; a DBIRTH declaring a busy device's metrics is bigger, so the node fell
/// into a loop of reconnects and births and sent almost no data. A generated line (every read of
/// another range: the births grow with every new register) is replayed whole into the broker.
#[test]
#[ignore = "needs mosquitto, python3 and pysparkplug; .ci/run installs them and runs this with --ignored"]
fn a_dbirth_over_10_kib_goes_out_whole_on_one_connection() {
    let d = dir("big-birth");
    let capture = d.join("line.pcapng");
    let g = Command::new(BIN).args(["generate", capture.to_str().unwrap(), "--transactions", "2000"]).output().unwrap();
    assert!(g.status.success());
    let port = free_port();
    let _broker = Kill(broker(&d, port));
    let host = Host::start(port);
    let out = Command::new(BIN)
        .args(["replay", capture.to_str().unwrap(), "--format", "summary"])
        .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}"), "--sparkplug", "plant/replay"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert_eq!(err.matches("mqtt: connected").count(), 1, "one session, no reconnects: {err}");
    assert!(err.contains(", 0 dropped"), "{err}");
    host.wait_for("the end", Duration::from_secs(30), |g| g.iter().any(|m| is(m, "NDEATH", None)));
    let got = host.got();
    let biggest = got
        .iter()
        .filter(|m| kind(m).0 == "DBIRTH")
        .map(|m| m["payload"]["metrics"].as_array().unwrap().len())
        .max()
        .unwrap();
    assert!(biggest > 200, "a birth of {biggest} metrics: not the big one this test is about");
    for unit in ["unit-1", "unit-5", "unit-17", "unit-247"] {
        assert!(got.iter().any(|m| is(m, "DDATA", Some(unit))), "no data from {unit}: {:#?}", kinds(&got));
    }
    assert_seq_counts(&got);
}

/// Says the primary host `id` is online or offline (a retained STATE, Sparkplug 3.0 JSON).
fn host_state(port: u16, id: &str, online: bool) {
    let ok = Command::new("python3")
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/interop/sparkplug_host.py"))
        .args(["state", &port.to_string(), id, if online { "online" } else { "offline" }])
        .status()
        .unwrap();
    assert!(ok.success());
}

/// With `--sparkplug-host`, the node is not born until its primary host's STATE says
/// online; what it measures meanwhile arrives after the births as historical data; when the host
/// goes offline it holds again, and when it is back it is born again with the session's bdSeq.
#[test]
#[ignore = "needs mosquitto, python3 and pysparkplug; .ci/run installs them and runs this with --ignored"]
fn the_node_waits_for_its_primary_host() {
    let d = dir("host");
    let port = free_port();
    let _broker = Kill(broker(&d, port));
    let host = Host::start(port);
    host_state(port, "scada", false);
    let mut mbtap = spawn_demo(
        port,
        &["--speed", "1", "--duration", "600", "--sparkplug", "plant/station", "--sparkplug-host", "scada"],
    );
    mbtap.drain();
    let _mbtap = Kill(mbtap);
    let waiting_from = now_ms();
    std::thread::sleep(Duration::from_secs(4));
    let node_messages = |g: &[serde_json::Value]| g.iter().filter(|m| kind(m).0 != "STATE").count();
    assert_eq!(node_messages(&host.got()), 0, "born before its host: {:#?}", kinds(&host.got()));
    host_state(port, "scada", true);
    host.wait_for("births, then what was measured meanwhile", Duration::from_secs(30), |g| {
        g.iter().any(|m| is(m, "NBIRTH", None)) && historical(g).iter().any(|&t| t <= waiting_from + 2_000)
    });
    let first_births = host.got().iter().filter(|m| is(m, "NBIRTH", None)).count();
    host_state(port, "scada", false);
    std::thread::sleep(Duration::from_secs(3));
    let away_from = now_ms();
    std::thread::sleep(Duration::from_secs(2));
    host_state(port, "scada", true);
    host.wait_for("born again, and the away time's values", Duration::from_secs(30), |g| {
        g.iter().filter(|m| is(m, "NBIRTH", None)).count() > first_births
            && historical(g).iter().any(|&t| t >= away_from && t <= away_from + 2_000)
    });
    let got = host.got();
    let births: Vec<u64> = got.iter().filter(|m| is(m, "NBIRTH", None)).map(bd_seq).collect();
    assert!(births.windows(2).all(|w| w[0] == w[1]), "one MQTT session, one bdSeq: {births:?}");
    assert_seq_counts(&got[got.iter().rposition(|m| is(m, "NBIRTH", None)).unwrap()..]);
}
