//! Spy mode: a read-only Modbus TCP server (tokio-modbus's) answering from the register image
//! the sniffer builds — per unit, per table, the latest value heard. It runs on its own thread
//! and runtime, so a slow or hostile client never delays the analysis; the analysing thread
//! only takes a short lock to update the image. Refusals are counted per exception code.

use std::fmt::Write as _;
use std::future::Ready;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context as _;
use mbtap_analysis::analyzer::Event;
use mbtap_device::profile::Table;
use mbtap_device::profile::image::{ILLEGAL_FUNCTION, RegisterImage};
use tokio_modbus::server::tcp::Server;

use super::expiring::{Connections, Expiring};
use tokio_modbus::{ExceptionCode, Request, Response, SlaveRequest};

/// The image, its clock, and what the server did.
#[derive(Debug)]
pub struct Spy {
    image: Mutex<Image>,
    max_age_ns: Option<u64>,
    live: bool,
    pub addr: SocketAddr,
    answered: AtomicU64,
    /// Connections open now, and those refused because [`MAX_CLIENTS`] were.
    open: std::sync::atomic::AtomicUsize,
    refused_connections: AtomicU64,
    /// Idle connections closed to make room, and failed accepts.
    evicted: AtomicU64,
    accept_errors: AtomicU64,
    /// Refusals by exception code (index = code, 0..=15).
    refused: [AtomicU64; 16],
}

#[derive(Debug, Default)]
struct Image {
    values: RegisterImage,
    /// The newest bus time heard (the clock of a replay).
    latest_ns: u64,
}

impl crate::output::Tap for Spy {
    fn event(&self, e: &Event<'_>) {
        let t = crate::output::event_time(e);
        // A poisoned lock means a panic elsewhere; serving stops being worth more than analysing.
        if let Ok(mut img) = self.image.lock() {
            img.latest_ns = img.latest_ns.max(t);
            crate::output::update_image(&mut img.values, e);
        }
    }
}

fn bits(v: &[u16]) -> Vec<bool> {
    v.iter().map(|&b| b != 0).collect()
}

impl Spy {
    /// Binds `addr` and serves on a thread of its own.
    pub fn start(addr: &str, max_age: Option<Duration>, live: bool) -> anyhow::Result<Arc<Self>> {
        let listener = std::net::TcpListener::bind(crate::io::listen::bind_addr(addr))
            .with_context(|| format!("--serve {addr}: cannot listen there"))?;
        listener.set_nonblocking(true).context("--serve: setting the socket non-blocking")?;
        let bound = listener.local_addr().context("--serve: the bound address")?;
        let spy = Arc::new(Self {
            image: Mutex::new(Image::default()),
            max_age_ns: max_age.map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)),
            live,
            addr: bound,
            answered: AtomicU64::new(0),
            open: std::sync::atomic::AtomicUsize::new(0),
            refused_connections: AtomicU64::new(0),
            evicted: AtomicU64::new(0),
            accept_errors: AtomicU64::new(0),
            refused: std::array::from_fn(|_| AtomicU64::new(0)),
        });
        let server_spy = Arc::clone(&spy);
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().context("--serve: a runtime")?;
        std::thread::Builder::new()
            .name("spy-server".into())
            .spawn(move || {
                rt.block_on(async move {
                    let listener = match tokio::net::TcpListener::from_std(listener) {
                        Ok(l) => l,
                        Err(e) => {
                            eprintln!("mbtap: --serve: {e}");
                            return;
                        }
                    };
                    let server = Server::new(listener);
                    let table = Arc::new(Connections::default());
                    let on_connected = |stream, peer| {
                        let (spy, table) = (Arc::clone(&server_spy), Arc::clone(&table));
                        async move {
                            // When MAX_CLIENTS are open, a socket that never asked or the
                            // idlest gives its place (the bridge's rule); only when all are busy
                            // is the newcomer closed at once, counted.
                            if spy.open.fetch_add(1, Ordering::SeqCst) >= MAX_CLIENTS {
                                if table.evict_idlest(tokio::time::Instant::now()) {
                                    spy.evicted.fetch_add(1, Ordering::Relaxed);
                                } else {
                                    spy.open.fetch_sub(1, Ordering::SeqCst);
                                    spy.refused_connections.fetch_add(1, Ordering::Relaxed);
                                    return Ok(None);
                                }
                            }
                            let _ = peer;
                            let stream = Expiring::new(stream, IDLE_TIMEOUT, table.open());
                            std::io::Result::Ok(Some((Service { spy: Arc::clone(&spy) }, stream)))
                        }
                    };
                    // A client that breaks its connection ends only that connection. An accept
                    // error (out of file descriptors) ends tokio-modbus's loop: it is said once
                    // per spell, counted, and serving starts again (a process that lives on
                    // must not stop serving for good).
                    let mut said = false;
                    loop {
                        match server.serve(&on_connected, |_err| {}).await {
                            Ok(()) => break,
                            Err(e) => {
                                server_spy.accept_errors.fetch_add(1, Ordering::Relaxed);
                                if !said {
                                    eprintln!("mbtap: --serve: accepting a connection failed: {e}; serving on");
                                    said = true;
                                }
                                tokio::time::sleep(Duration::from_millis(100)).await;
                            }
                        }
                    }
                });
            })
            .context("--serve: starting the server thread")?;
        eprintln!(
            "mbtap: spy server listening on {bound} (Modbus TCP, read-only: answers from what is heard on the line)"
        );
        Ok(spy)
    }

    fn now_ns(&self, img: &Image) -> u64 {
        if self.live { crate::io::serial::now().0 } else { img.latest_ns }
    }

    /// The answer to one request.
    fn answer(&self, unit: u8, request: &Request<'_>) -> Result<Response, ExceptionCode> {
        let read = |table, address, quantity| -> Result<Vec<u16>, u8> {
            let img = self.image.lock().map_err(|_| mbtap_device::profile::image::GATEWAY_TARGET_FAILED)?;
            img.values.serve_read(unit, table, address, quantity, self.now_ns(&img), self.max_age_ns)
        };
        let r = match *request {
            Request::ReadCoils(a, q) => read(Table::Coils, a, q).map(|v| Response::ReadCoils(bits(&v))),
            Request::ReadDiscreteInputs(a, q) => {
                read(Table::DiscreteInputs, a, q).map(|v| Response::ReadDiscreteInputs(bits(&v)))
            }
            Request::ReadHoldingRegisters(a, q) => {
                read(Table::HoldingRegisters, a, q).map(Response::ReadHoldingRegisters)
            }
            Request::ReadInputRegisters(a, q) => read(Table::InputRegisters, a, q).map(Response::ReadInputRegisters),
            // Writes and everything else: the spy sends nothing on the line, so it cannot do them.
            _ => Err(ILLEGAL_FUNCTION),
        };
        match r {
            Ok(resp) => {
                self.answered.fetch_add(1, Ordering::Relaxed);
                Ok(resp)
            }
            Err(code) => {
                if let Some(c) = self.refused.get(usize::from(code)) {
                    c.fetch_add(1, Ordering::Relaxed);
                }
                Err(ExceptionCode::new(code))
            }
        }
    }

    /// `spy server: 12 answered, 3 refused (02: 1, 0B: 2)`.
    #[must_use]
    pub fn summary(&self) -> String {
        let refused: Vec<(usize, u64)> = self
            .refused
            .iter()
            .enumerate()
            .map(|(c, n)| (c, n.load(Ordering::Relaxed)))
            .filter(|&(_, n)| n > 0)
            .collect();
        let total: u64 = refused.iter().map(|(_, n)| n).sum();
        let overflowed = self.image.lock().map_or(0, |i| i.values.overflowed);
        let mut full = if overflowed > 0 {
            format!("; image full: {overflowed} values of new addresses not kept")
        } else {
            String::new()
        };
        let turned_away = self.refused_connections.load(Ordering::Relaxed);
        if turned_away > 0 {
            let _ = write!(full, "; {turned_away} connections refused ({MAX_CLIENTS} open at most)");
        }
        let evicted = self.evicted.load(Ordering::Relaxed);
        if evicted > 0 {
            let _ = write!(full, "; {evicted} idle connections closed to make room");
        }
        let accept_errors = self.accept_errors.load(Ordering::Relaxed);
        if accept_errors > 0 {
            let _ = write!(full, "; {accept_errors} failed accepts");
        }
        let detail = refused.iter().map(|(c, n)| format!("{c:02X}: {n}")).collect::<Vec<_>>().join(", ");
        format!(
            "spy server on {}: {} answered, {total} refused{}{full}",
            self.addr,
            self.answered.load(Ordering::Relaxed),
            if detail.is_empty() { String::new() } else { format!(" ({detail})") }
        )
    }
}

/// Connections the spy server holds open at once.
const MAX_CLIENTS: usize = 64;
/// A connection silent this long is closed (the bridge's default `--idle-timeout`).
const IDLE_TIMEOUT: Duration = Duration::from_mins(5);

/// One connection's service; its end frees the connection's place.
struct Service {
    spy: Arc<Spy>,
}

impl Drop for Service {
    fn drop(&mut self) {
        self.spy.open.fetch_sub(1, Ordering::SeqCst);
    }
}

impl tokio_modbus::server::Service for Service {
    type Request = SlaveRequest<'static>;
    type Response = Response;
    type Exception = ExceptionCode;
    type Future = Ready<Result<Response, ExceptionCode>>;

    fn call(&self, req: Self::Request) -> Self::Future {
        std::future::ready(self.spy.answer(req.slave, &req.request))
    }
}
