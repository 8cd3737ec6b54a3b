//! `mbtap bridge`: Modbus TCP (and RTU over TCP) in front of serial lines — the lines'
//! masters, the TCP listeners, the metrics endpoint and the monitor, running until a signal.

use std::io::Write;
use std::ops::RangeInclusive;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use tokio::net::TcpListener;
use tokio::sync::mpsc;

use crate::bridge::line::{self, LineOptions, MonitorChunk};
use crate::bridge::metrics::Metrics;
use crate::bridge::metrics::endpoint::{Served, serve_metrics};
use crate::bridge::request::{Route, Routes, ServerOptions};
use crate::bridge::server;
use crate::bridge::shared::LineShared;
use crate::output::EventWriter;
use crate::source::session::Session;
use mbtap_analysis::analyzer::AnalyzerConfig;
use mbtap_analysis::chunk::{Chunk, PortId};
use mbtap_analysis::framer::FramerConfig;
use mbtap_analysis::pairing::PairingConfig;

/// The line's response timeout unless told (`--timeout-ms`), ms: a dead unit's 0x0B reaches a
/// client before its own 1 s timeout (mbpoll's, many SCADAs'). Emulated lines use it too.
pub const DEFAULT_TIMEOUT_MS: u64 = 800;

/// Everything the bridge needs.
#[derive(Debug, Clone)]
pub struct BridgeOptions {
    /// Lines and the units each serves (the first also serves unrouted units when it has `1..=247`).
    pub lines: Vec<(RangeInclusive<u8>, LineOptions)>,
    pub listen: Option<String>,
    pub listen_rtu: Option<String>,
    /// Modbus UDP (MBAP in datagrams), when asked for.
    pub listen_udp: Option<String>,
    pub server: ServerOptions,
    pub queue_per_client: usize,
    pub metrics: Option<String>,
    pub duration: Option<Duration>,
    /// The monitor watches the serial front (`--listen-serial`) instead of the lines: reverse
    /// mode, where the serial bus is the line the user looks at and the back is a TCP device.
    pub monitor_front: bool,
    /// The Modbus/TCP Security listener, when asked for.
    pub tls: crate::bridge::tls::TlsArgs,
    /// `--role` rules, parsed once: the TLS listener's and the broker's (`--mqtt-role`).
    pub roles: Arc<crate::bridge::tls::Roles>,
    /// `--mqtt-writes`: writes from the broker, through the same admission as clients'.
    pub broker_writes: Option<Arc<crate::bridge::broker::BrokerWrites>>,
    /// `--listen-serial`: a serial port on which the bridge is the slave, for a master
    /// already on the line.
    pub listen_serial: Option<crate::bridge::serial_front::SerialFront>,
    /// `--audit`: every request that may change a device, recorded.
    pub audit: Option<Arc<crate::output::audit::Audit>>,
    /// `--web`: the live view's address and who may look.
    pub web: Option<crate::bridge::web::WebOptions>,
}

impl BridgeOptions {
    /// The bridge's fronts before emulated devices (`simulate --listen`): one line answering
    /// every unit from `emulated`, under the bridge's default limits (64 connections, 32
    /// requests waiting per client, idle connections closed after 5 minutes) and its one
    /// admission under `policy` (`simulate --read-only`, `--allow-broadcast`: the bridge's rules).
    #[must_use]
    pub fn emulating(
        emulated: Arc<crate::source::simulate::emulated::Emulated>,
        line: mbtap_analysis::framer::LineSettings,
        mode: mbtap_analysis::analyzer::SerialMode,
        duration: Option<Duration>,
        fronts: EmulatedFronts,
        policy: mbtap_gateway::admit::Policy,
    ) -> Self {
        let EmulatedFronts { listen, listen_rtu, listen_udp, listen_serial } = fronts;
        let line = LineOptions {
            emulated: Some(emulated),
            ..LineOptions::plain("emulated".to_owned(), line, mode, Duration::from_millis(DEFAULT_TIMEOUT_MS))
        };
        Self {
            lines: vec![(1..=247, line)],
            listen,
            listen_rtu,
            listen_udp,
            server: ServerOptions {
                rtu_over_tcp: false,
                policy,
                allow_ips: Vec::new(),
                max_connections: 64,
                idle_timeout: Duration::from_mins(5),
                rate_limit: None,
            },
            queue_per_client: 32,
            metrics: None,
            duration,
            monitor_front: false,
            tls: crate::bridge::tls::TlsArgs::default(),
            roles: Arc::default(),
            broker_writes: None,
            listen_serial,
            audit: None,
            web: None,
        }
    }
}

/// Where emulated devices are served (`simulate --listen…`, `--serial`).
#[derive(Debug, Default)]
pub struct EmulatedFronts {
    pub listen: Option<String>,
    pub listen_rtu: Option<String>,
    pub listen_udp: Option<String>,
    /// A real serial port, on which the devices answer as slaves.
    pub listen_serial: Option<crate::bridge::serial_front::SerialFront>,
}

/// Says when a listener is open on every interface with no `--allow-ip` to say who may connect.
fn open_to_all(err: &mut dyn Write, local: std::net::SocketAddr, allow_ips: &[mbtap_gateway::admit::IpNet]) {
    if local.ip().is_unspecified() && allow_ips.is_empty() {
        let _ =
            writeln!(err, "mbtap: warning: {local} is open on every interface and no --allow-ip says who may connect");
    }
}

/// Runs the bridge until Ctrl-C, SIGTERM or the duration; `writer` gets the monitored traffic.
///
/// # Errors
/// When a listening address cannot be bound (the serial side never fails the bridge: a port
/// that is missing is retried, and clients get exception 0x0A meanwhile).
pub async fn bridge<W: Write>(
    mut opts: BridgeOptions,
    writer: Option<&mut EventWriter<W>>,
    err: &mut dyn Write,
) -> anyhow::Result<()> {
    let (monitor_tx, mut monitor_rx) = mpsc::unbounded_channel::<MonitorChunk>();
    let monitoring = writer.is_some();
    // What the monitor's analyzer is told: the line settings, and which port says what.
    let (mode, settings, pairing);
    let served = {
        let mut routes = Vec::new();
        for (units, line_opts) in &opts.lines {
            // One bound for all of a line's clients together: what --max-connections clients
            // with full queues hold (UDP senders, the broker and the polls included).
            let total = opts.server.max_connections.saturating_mul(opts.queue_per_client);
            let shared = LineShared::new(opts.queue_per_client, total, line_opts.cache.clone());
            let monitor = (monitoring && !opts.monitor_front).then(|| monitor_tx.clone());
            if let Some(emulated) = &line_opts.emulated {
                tokio::spawn(super::emulated::run(Arc::clone(emulated), Arc::clone(&shared)));
            } else {
                tokio::spawn(line::run(line_opts.clone(), Arc::clone(&shared), monitor));
                let _ = writeln!(
                    err,
                    "mbtap: serial line {} at {} {} for units {}–{}",
                    line_opts.port,
                    line_opts.line,
                    line_opts.mode.name(),
                    units.start(),
                    units.end()
                );
            }
            tokio::spawn(super::shared::poll(line_opts.polls.clone(), Arc::clone(&shared)));
            routes.push(Route { units: units.clone(), line: shared });
        }
        let routes = Arc::new(Routes {
            lines: routes,
            server: Metrics::default(),
            audit: opts.audit.clone(),
            clients: opts.web.is_some().then(Arc::default),
        });
        if let Some(web) = &opts.web {
            let listener = super::web::bind(web).await?;
            let _ = writeln!(err, "mbtap: web view at http://{}/ (read-only)", listener.local_addr()?);
            tokio::spawn(super::web::serve(listener, web.clone(), Arc::clone(&routes), std::time::Instant::now()));
        }
        // The admission policy routes by the lines' units, in the order they were given.
        opts.server.policy.routes = routes.iter().map(|r| r.units.clone()).collect();
        if let Some(w) = &opts.broker_writes {
            crate::bridge::broker::start(w, Arc::clone(&routes), Arc::new(opts.server.clone()));
        }
        // One table of connections for every listener: one limit, eviction across them.
        let connections: Arc<server::Connections> = Arc::default();
        for (addr, rtu) in [(&opts.listen, false), (&opts.listen_rtu, true)] {
            let Some(addr) = addr else { continue };
            let addr = crate::io::listen::bind_addr(addr);
            let listener = TcpListener::bind(&addr).await.with_context(|| format!("listening on {addr}"))?;
            let local = listener.local_addr().with_context(|| format!("listening on {addr}"))?;
            let what = if rtu { "RTU over TCP" } else { "Modbus TCP" };
            let _ = writeln!(err, "mbtap: bridge listening on {local} ({what})");
            open_to_all(err, local, &opts.server.allow_ips);
            let server_opts = Arc::new(ServerOptions { rtu_over_tcp: rtu, ..opts.server.clone() });
            tokio::spawn(server::serve(listener, Arc::clone(&routes), server_opts, None, Arc::clone(&connections)));
        }
        if let Some(front) = &opts.listen_serial {
            let _ = writeln!(
                err,
                "mbtap: answering as the slave on {} at {} {} ({})",
                front.port,
                front.line,
                front.mode.name(),
                front.option
            );
            let server_opts = Arc::new(ServerOptions { rtu_over_tcp: false, ..opts.server.clone() });
            let monitor = (monitoring && opts.monitor_front).then(|| monitor_tx.clone());
            tokio::spawn(crate::bridge::serial_front::serve(front.clone(), Arc::clone(&routes), server_opts, monitor));
        }
        if let Some(addr) = &opts.listen_udp {
            let addr = crate::io::listen::bind_addr(addr);
            let socket =
                tokio::net::UdpSocket::bind(&addr).await.with_context(|| format!("--listen-udp: binding {addr}"))?;
            let local = socket.local_addr().with_context(|| format!("--listen-udp: binding {addr}"))?;
            let _ = writeln!(err, "mbtap: bridge listening on {local} (Modbus UDP)");
            open_to_all(err, local, &opts.server.allow_ips);
            let server_opts = Arc::new(ServerOptions { rtu_over_tcp: false, ..opts.server.clone() });
            tokio::spawn(super::udp::serve_udp(socket, Arc::clone(&routes), server_opts));
        }
        if let Some(addr) = &opts.tls.listen_tls {
            // Files are read (and checked) before listening: a bad certificate stops the start.
            let tls = crate::bridge::tls::Tls::start(&opts.tls, Arc::clone(&opts.roles))?;
            let addr = crate::io::listen::bind_addr(addr);
            let listener =
                TcpListener::bind(&addr).await.with_context(|| format!("--listen-tls: listening on {addr}"))?;
            let local = listener.local_addr().with_context(|| format!("--listen-tls: listening on {addr}"))?;
            let _ =
                writeln!(err, "mbtap: bridge listening on {local} (Modbus/TCP Security, TLS with client certificates)");
            // Its own allow-list when given (a TLS port is often opened wider than a plain one).
            let allow_ips = if opts.tls.tls_allow_ip.is_empty() {
                opts.server.allow_ips.clone()
            } else {
                opts.tls.tls_allow_ip.clone()
            };
            let server_opts = Arc::new(ServerOptions { rtu_over_tcp: false, allow_ips, ..opts.server.clone() });
            tokio::spawn(server::serve(
                listener,
                Arc::clone(&routes),
                server_opts,
                Some(tls),
                Arc::clone(&connections),
            ));
        }
        if let Some(front) = opts.listen_serial.as_ref().filter(|_| opts.monitor_front) {
            (mode, settings) = (front.mode, front.line);
            // Port 0 is all the bus carries (other slaves' answers too); port 1 our answers.
            pairing = PairingConfig { response_port: Some(PortId(1)), ..Default::default() };
        } else {
            (mode, settings) = opts.lines.first().map_or(
                (mbtap_analysis::analyzer::SerialMode::Rtu, mbtap_analysis::framer::LineSettings::default()),
                |(_, l)| (l.mode, l.line),
            );
            // The bridge knows who said what: requests on port 0, responses on port 1.
            pairing =
                PairingConfig { request_port: Some(PortId(0)), response_port: Some(PortId(1)), ..Default::default() };
        }
        Served::Lines(routes)
    };
    drop(monitor_tx);
    let served = Arc::new(served);
    if let Some(addr) = &opts.metrics {
        let addr = crate::io::listen::bind_addr(addr);
        let listener = TcpListener::bind(&addr).await.with_context(|| format!("metrics: listening on {addr}"))?;
        let local = listener.local_addr().with_context(|| format!("metrics: listening on {addr}"))?;
        let _ = writeln!(err, "mbtap: metrics at http://{local}/metrics");
        tokio::spawn(serve_metrics(listener, Arc::clone(&served)));
    }
    let _ = err.flush();
    let mut session = writer
        .is_some()
        .then(|| Session::new(AnalyzerConfig { mode, framer: FramerConfig::new(settings, 0), pairing }));
    let mut writer = writer;
    let stop = crate::io::signals::shutdown_signal();
    tokio::pin!(stop);
    let deadline = opts.duration.map(|d| tokio::time::Instant::now() + d);
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    loop {
        tokio::select! {
            () = &mut stop => break,
            () = async { if let Some(d) = deadline { tokio::time::sleep_until(d).await } else { std::future::pending().await } } => break,
            Some((port, t, bytes, whole)) = monitor_rx.recv(), if monitoring => {
                if let (Some(s), Some(w)) = (session.as_mut(), writer.as_deref_mut()) {
                    let chunk = Chunk { port, t, bytes: &bytes };
                    // What the bridge wrote is one frame, shown at once (before its answer).
                    if whole {
                        s.frame(&chunk, w);
                    } else {
                        s.chunk(&chunk, w, err);
                    }
                }
            }
            _ = tick.tick() => {
                if let (Some(s), Some(w)) = (session.as_mut(), writer.as_deref_mut()) {
                    s.tick(crate::io::serial::now(), w);
                    s.flush(w, err);
                }
                for note in served.notes() {
                    let _ = writeln!(err, "mbtap: {note}");
                }
            }
        }
    }
    if let (Some(s), Some(w)) = (session, writer) {
        s.finish(w, err)?;
    }
    Ok(())
}
