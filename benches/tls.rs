//! Modbus/TCP Security's cost: one bridge with a plain and a TLS listener in front
//! of `mbtap simulate`, certificates made with the openssl CLI, the read answered from the
//! bridge's cache (so the serial line's time is not in the figures). Measures a request's round
//! trip over the plain listener and over TLS on an established session (p50 / p99, one client
//! back to back), and full handshakes per second (connect, TLS with client certificate, one
//! request, close) from one client thread.
//!
//! Run: `cargo bench --bench tls` (about 20 s; needs openssl). Figures go to BENCHMARKS.md.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::cast_precision_loss)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio_rustls::rustls;
use tokio_rustls::rustls::pki_types::pem::PemObject as _;
use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName};

mod support;
use support::{Kill, percentile};

const BIN: &str = env!("CARGO_BIN_EXE_mbtap");
/// Read input registers 430–433 of unit 1 (MAP v1.1b3 §6.4), in an MBAP frame (transaction
/// id patched per request).
const FRAME: [u8; 12] = [0, 0, 0, 0, 0, 6, 1, 0x04, 0x01, 0xAE, 0x00, 0x04];

fn openssl(d: &Path, args: &[&str]) {
    let o = Command::new("openssl").args(args).current_dir(d).output().expect("openssl");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

fn certificates() -> PathBuf {
    let d = std::env::temp_dir().join(format!("mbtap-bench-tls-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    openssl(
        &d,
        &[
            "req",
            "-x509",
            "-newkey",
            "ec",
            "-pkeyopt",
            "ec_paramgen_curve:P-256",
            "-nodes",
            "-keyout",
            "ca.key",
            "-out",
            "ca.pem",
            "-days",
            "2",
            "-subj",
            "/CN=bench CA",
        ],
    );
    for (name, ext) in
        [("server", "subjectAltName=IP:127.0.0.1\n"), ("client", "1.3.6.1.4.1.50316.802.1=ASN1:UTF8String:operator\n")]
    {
        openssl(
            &d,
            &[
                "req",
                "-newkey",
                "ec",
                "-pkeyopt",
                "ec_paramgen_curve:P-256",
                "-nodes",
                "-keyout",
                &format!("{name}.key"),
                "-out",
                &format!("{name}.csr"),
                "-subj",
                &format!("/CN={name}"),
            ],
        );
        std::fs::write(d.join(format!("{name}.ext")), ext).unwrap();
        openssl(
            &d,
            &[
                "x509",
                "-req",
                "-in",
                &format!("{name}.csr"),
                "-CA",
                "ca.pem",
                "-CAkey",
                "ca.key",
                "-CAcreateserial",
                "-out",
                &format!("{name}.pem"),
                "-days",
                "2",
                "-extfile",
                &format!("{name}.ext"),
            ],
        );
    }
    d
}

fn client_config(d: &Path) -> Arc<rustls::ClientConfig> {
    let mut roots = rustls::RootCertStore::empty();
    for c in CertificateDer::pem_file_iter(d.join("ca.pem")).unwrap() {
        roots.add(c.unwrap()).unwrap();
    }
    let chain: Vec<_> = CertificateDer::pem_file_iter(d.join("client.pem")).unwrap().map(Result::unwrap).collect();
    let key = PrivateKeyDer::from_pem_file(d.join("client.key")).unwrap();
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    Arc::new(
        rustls::ClientConfig::builder_with_provider(provider)
            .with_safe_default_protocol_versions()
            .unwrap()
            .with_root_certificates(roots)
            .with_client_auth_cert(chain, key)
            .unwrap(),
    )
}

fn round_trips<S: Read + Write>(s: &mut S, n: usize) -> Vec<f64> {
    let mut out = Vec::with_capacity(n);
    let mut answer = [0u8; 7 + 10];
    for i in 0..n {
        let mut f = FRAME;
        f[..2].copy_from_slice(&u16::try_from(i % 60000).unwrap().to_be_bytes());
        let t = Instant::now();
        s.write_all(&f).unwrap();
        s.flush().unwrap();
        s.read_exact(&mut answer).unwrap();
        out.push(t.elapsed().as_secs_f64() * 1e3);
    }
    out
}

fn main() {
    let d = certificates();
    let bus = d.join("bus");
    let _sim = support::simulate(&bus, &["--turnaround-ms", "0", "--baud", "115200"]);
    let f = |n: &str| d.join(n).to_str().unwrap().to_owned();
    let mut child = Command::new(BIN)
        .args([
            "bridge",
            "--serial",
            bus.to_str().unwrap(),
            "--baud",
            "115200",
            "--listen",
            "127.0.0.1:0",
            "--listen-tls",
            "127.0.0.1:0",
        ])
        .args([
            "--cert",
            &f("server.pem"),
            "--key",
            &f("server.key"),
            "--client-ca",
            &f("ca.pem"),
            "--role",
            "operator=read-only",
        ])
        .args(["--max-connections", "1000"])
        // Answered from memory after the first read: what is measured is the bridge and TLS,
        // not the serial line.
        .args(["--cache", "1:input:430-433=3600s"])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let (mut plain, mut tls) = (None, None);
    while plain.is_none() || tls.is_none() {
        let l = lines.next().unwrap().unwrap();
        if let Some(rest) = l.strip_prefix("mbtap: bridge listening on ") {
            let a = rest.split_whitespace().next().unwrap().to_owned();
            if rest.contains("TLS") { tls = Some(a) } else { plain = Some(a) }
        }
    }
    std::thread::spawn(move || for _ in lines {});
    let _bridge = Kill(child);
    let (plain, tls) = (plain.unwrap(), tls.unwrap());
    let config = client_config(&d);
    let n = 3000;

    let mut s = TcpStream::connect(&plain).unwrap();
    s.set_nodelay(true).unwrap();
    round_trips(&mut s, 200);
    let mut p = round_trips(&mut s, n);

    let tcp = TcpStream::connect(&tls).unwrap();
    tcp.set_nodelay(true).unwrap();
    let conn = rustls::ClientConnection::new(Arc::clone(&config), ServerName::try_from("127.0.0.1").unwrap()).unwrap();
    let mut ts = rustls::StreamOwned::new(conn, tcp);
    round_trips(&mut ts, 200);
    let mut t = round_trips(&mut ts, n);
    let (p50, t50) = (percentile(&mut p, 0.5), percentile(&mut t, 0.5));
    println!(
        "round trip, {n} requests: plain p50 {p50:.3} ms p99 {:.3} ms; TLS p50 {t50:.3} ms p99 {:.3} ms; TLS adds {:.3} ms at p50",
        percentile(&mut p, 0.99),
        percentile(&mut t, 0.99),
        t50 - p50
    );

    let until = Instant::now() + Duration::from_secs(5);
    let mut handshakes = 0u32;
    let start = Instant::now();
    while Instant::now() < until {
        let tcp = TcpStream::connect(&tls).unwrap();
        let conn =
            rustls::ClientConnection::new(Arc::clone(&config), ServerName::try_from("127.0.0.1").unwrap()).unwrap();
        let mut ts = rustls::StreamOwned::new(conn, tcp);
        // One request proves the session is up (TLS 1.3 reports a refused client late).
        round_trips(&mut ts, 1);
        handshakes += 1;
    }
    println!(
        "full handshakes (ECDSA P-256, client certificate, TLS 1.3) + one cached request: {:.0}/s from one client thread",
        f64::from(handshakes) / start.elapsed().as_secs_f64()
    );
}
