//! The metrics endpoint (`--metrics ADDR`): `GET /metrics` in the Prometheus text format, every
//! line's families (several lines told apart by a `line` label) and the server's, and the notes
//! the lines keep for the operator's stderr.

use std::fmt::Write as _;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;

use crate::bridge::request::Routes;

/// What the bridge serves, for the metrics endpoint and the notes on stderr.
pub(crate) enum Served {
    Lines(Arc<Routes>),
}

impl Served {
    /// The Prometheus text: one line's families as they are; several lines' series told
    /// apart by a `line` label.
    pub(crate) fn render(&self) -> String {
        let Self::Lines(routes) = self;
        let mut body = String::new();
        for (i, r) in routes.iter().enumerate() {
            let text = r.line.metrics.render_line();
            if routes.len() == 1 {
                body.push_str(&text);
                continue;
            }
            for l in text.lines() {
                if l.starts_with('#') {
                    if i == 0 {
                        body.push_str(l);
                        body.push('\n');
                    }
                } else if let Some((name, rest)) = l.split_once('{') {
                    let _ = writeln!(body, "{name}{{line=\"{i}\",{rest}");
                } else if let Some((name, value)) = l.split_once(' ') {
                    let _ = writeln!(body, "{name}{{line=\"{i}\"}} {value}");
                }
            }
        }
        // Connections and refusals are the server's: once, without a line label.
        body.push_str(&routes.server.render_server());
        if let Some(a) = &routes.audit {
            use std::sync::atomic::Ordering;
            let _ = std::fmt::Write::write_fmt(
                &mut body,
                format_args!(
                    "# HELP mbtap_bridge_audit_records_total Requests that may change a device, handed to the audit.\n\
                     # TYPE mbtap_bridge_audit_records_total counter\nmbtap_bridge_audit_records_total {}\n\
                     # HELP mbtap_bridge_audit_lost_total Audit records that could not be queued or written (a slow or full disk).\n\
                     # TYPE mbtap_bridge_audit_lost_total counter\nmbtap_bridge_audit_lost_total {}\n",
                    a.records.load(Ordering::Relaxed),
                    a.lost.load(Ordering::Relaxed)
                ),
            );
        }
        body
    }

    /// Messages for the operator (a port lost, reopened) since the last call.
    pub(crate) fn notes(&self) -> Vec<String> {
        let Self::Lines(routes) = self;
        routes.iter().filter_map(|r| r.line.metrics.take_note()).collect()
    }
}

/// Serves `GET /metrics` (any path, really) in the Prometheus text format.
/// Scrapes served at once; more are closed unanswered (a scraper needs one).
const METRICS_CONNECTIONS: usize = 8;
/// How long a scrape may take to send its request, and to take the answer.
const METRICS_TIMEOUT: Duration = Duration::from_millis(500);

pub(crate) async fn serve_metrics(listener: TcpListener, served: Arc<Served>) {
    let slots = Arc::new(tokio::sync::Semaphore::new(METRICS_CONNECTIONS));
    loop {
        let Ok((mut stream, _)) = listener.accept().await else {
            // Out of file descriptors (EMFILE) or similar: back off instead of spinning on the
            // error while the Modbus listeners need the CPU and the descriptors.
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        };
        // A flood of scrapes holds at most METRICS_CONNECTIONS descriptors, each briefly.
        let Ok(slot) = Arc::clone(&slots).try_acquire_owned() else {
            drop(stream);
            continue;
        };
        let served = Arc::clone(&served);
        tokio::spawn(async move {
            let _slot = slot;
            let mut req = [0u8; 1024];
            // The request line and headers; the answer does not depend on them.
            let _ = tokio::time::timeout(METRICS_TIMEOUT, stream.read(&mut req)).await;
            let body = served.render();
            let head = format!(
                "HTTP/1.1 200 OK\r\nContent-Type: text/plain; version=0.0.4\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
                body.len()
            );
            let _ = tokio::time::timeout(METRICS_TIMEOUT, async {
                let _ = stream.write_all(head.as_bytes()).await;
                let _ = stream.write_all(body.as_bytes()).await;
                let _ = stream.shutdown().await;
            })
            .await;
        });
    }
}
