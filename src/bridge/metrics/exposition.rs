//! The Prometheus text exposition (format version 0.0.4) of the bridge's [`Metrics`]: a line's
//! families (per unit, the queue, the port, the cache, line time) and the server's
//! (connections, refusals), so that several lines can be told apart by a `line` label while
//! the server's counters are written once.

use std::fmt::Write as _;

use super::{BUCKETS, Metrics};

impl Metrics {
    /// The Prometheus text exposition: the line's families and the server's.
    #[must_use]
    pub fn render(&self) -> String {
        self.render_line() + &self.render_server()
    }

    /// The server's families: connections and refusals, counted once for every listener
    /// whatever line a request would have gone to.
    #[must_use]
    pub fn render_server(&self) -> String {
        self.with(|m| {
            let mut s = String::new();
            let counter = |s: &mut String, name: &str, help: &str| {
                let _ = writeln!(s, "# HELP {name} {help}\n# TYPE {name} counter");
            };
            counter(&mut s, "mbtap_bridge_connections_total", "TCP connections accepted.");
            let _ = writeln!(s, "mbtap_bridge_connections_total {}", m.connections);
            let _ = writeln!(
                s,
                "# HELP mbtap_bridge_connections_open TCP connections open.\n# TYPE mbtap_bridge_connections_open gauge\nmbtap_bridge_connections_open {}",
                m.connections_open
            );
            counter(&mut s, "mbtap_bridge_refused_total", "Connections or requests refused, by reason.");
            for (r, n) in &m.refused {
                let _ = writeln!(s, "mbtap_bridge_refused_total{{reason=\"{r}\"}} {n}");
            }
            counter(
                &mut s,
                "mbtap_bridge_abandoned_total",
                "Requests a client without ids (RTU over TCP, a serial master) gave up on by asking again, or answered after its learnt timeout: their answers withheld.",
            );
            let _ = writeln!(s, "mbtap_bridge_abandoned_total {}", m.abandoned);
            counter(
                &mut s,
                "mbtap_bridge_withheld_sequential_total",
                "Answers withheld from Modbus TCP clients shown to ask one thing at a time (each request right after the last answer) that asked again unanswered: their own timeout had run out.",
            );
            let _ = writeln!(s, "mbtap_bridge_withheld_sequential_total {}", m.withheld_sequential);
            s
        })
    }

    /// One line's families: per unit, the queue, the port, the cache, line time.
    #[must_use]
    pub fn render_line(&self) -> String {
        self.with(|m| {
            let mut s = String::new();
            let counter = |s: &mut String, name: &str, help: &str| {
                let _ = writeln!(s, "# HELP {name} {help}\n# TYPE {name} counter");
            };
            counter(&mut s, "mbtap_bridge_requests_total", "Requests sent on the serial line (retries included).");
            for (u, v) in &m.units {
                let _ = writeln!(s, "mbtap_bridge_requests_total{{unit=\"{u}\"}} {}", v.requests);
            }
            counter(&mut s, "mbtap_bridge_responses_total", "Responses received from slaves.");
            for (u, v) in &m.units {
                let _ = writeln!(s, "mbtap_bridge_responses_total{{unit=\"{u}\"}} {}", v.responses);
            }
            counter(&mut s, "mbtap_bridge_exceptions_total", "Exception responses from slaves, by code.");
            for (u, v) in &m.units {
                for (c, n) in &v.exceptions {
                    let _ = writeln!(s, "mbtap_bridge_exceptions_total{{unit=\"{u}\",code=\"{c}\"}} {n}");
                }
            }
            counter(&mut s, "mbtap_bridge_gateway_exceptions_total", "Exceptions the bridge answered itself (0x0A, 0x0B).");
            for (u, v) in &m.units {
                for (c, n) in &v.gateway_exceptions {
                    let _ = writeln!(s, "mbtap_bridge_gateway_exceptions_total{{unit=\"{u}\",code=\"{c}\"}} {n}");
                }
            }
            counter(&mut s, "mbtap_bridge_timeouts_total", "Requests with no answer in time.");
            for (u, v) in &m.units {
                let _ = writeln!(s, "mbtap_bridge_timeouts_total{{unit=\"{u}\"}} {}", v.timeouts);
            }
            counter(
                &mut s,
                "mbtap_bridge_circuit_open_total",
                "Requests answered 0x0B at once: the unit's circuit breaker was open after consecutive timeouts.",
            );
            for (u, v) in m.units.iter().filter(|(_, v)| v.circuit_open > 0) {
                let _ = writeln!(s, "mbtap_bridge_circuit_open_total{{unit=\"{u}\"}} {}", v.circuit_open);
            }
            let _ = writeln!(
                s,
                "# HELP mbtap_bridge_unit_timeout_seconds The answer timeout in force for the unit (learnt with --timeout auto).\n# TYPE mbtap_bridge_unit_timeout_seconds gauge"
            );
            for (u, v) in &m.units {
                if let Some(t) = v.timeout {
                    let _ = writeln!(s, "mbtap_bridge_unit_timeout_seconds{{unit=\"{u}\"}} {}", t.as_secs_f64());
                }
            }
            counter(&mut s, "mbtap_bridge_timeout_wait_seconds_total", "Line time spent waiting for answers that never came.");
            for (u, v) in &m.units {
                let _ = writeln!(s, "mbtap_bridge_timeout_wait_seconds_total{{unit=\"{u}\"}} {}", v.waited_in_vain.as_secs_f64());
            }
            counter(&mut s, "mbtap_bridge_unit_gap_wait_seconds_total", "Line time kept silent before a unit's requests for its --unit-gap.");
            for (u, v) in m.units.iter().filter(|(_, v)| !v.gap_wait.is_zero()) {
                let _ = writeln!(s, "mbtap_bridge_unit_gap_wait_seconds_total{{unit=\"{u}\"}} {}", v.gap_wait.as_secs_f64());
            }
            counter(&mut s, "mbtap_bridge_collisions_total", "Requests whose echo differed from what was sent: another driver on the line.");
            for (u, v) in &m.units {
                let _ = writeln!(s, "mbtap_bridge_collisions_total{{unit=\"{u}\"}} {}", v.collisions);
            }
            counter(&mut s, "mbtap_bridge_echo_missing_total", "Requests an echoing adapter (--echo on) did not give back.");
            for (u, v) in m.units.iter().filter(|(_, v)| v.echo_missing > 0) {
                let _ = writeln!(s, "mbtap_bridge_echo_missing_total{{unit=\"{u}\"}} {}", v.echo_missing);
            }
            counter(&mut s, "mbtap_bridge_late_answers_total", "Answers that fit another request than the one on the line (late answers after a timeout): dropped.");
            for (u, v) in m.units.iter().filter(|(_, v)| v.late_answers > 0) {
                let _ = writeln!(s, "mbtap_bridge_late_answers_total{{unit=\"{u}\"}} {}", v.late_answers);
            }
            counter(&mut s, "mbtap_bridge_misfit_answers_total", "Answers dropped by the answer check: they do not fit the request awaited (unit, function, length, echoed fields).");
            for (r, n) in &m.misfits {
                let _ = writeln!(s, "mbtap_bridge_misfit_answers_total{{reason=\"{r}\"}} {n}");
            }
            counter(&mut s, "mbtap_bridge_garbage_bytes_total", "Bytes from the line dropped unread: longer than any answer can be.");
            let _ = writeln!(s, "mbtap_bridge_garbage_bytes_total {}", m.garbage_bytes);
            counter(&mut s, "mbtap_bridge_crc_errors_total", "Answers whose CRC or LRC failed.");
            for (u, v) in &m.units {
                let _ = writeln!(s, "mbtap_bridge_crc_errors_total{{unit=\"{u}\"}} {}", v.crc_errors);
            }
            let _ = writeln!(
                s,
                "# HELP mbtap_bridge_latency_seconds Queued to answered.\n# TYPE mbtap_bridge_latency_seconds histogram"
            );
            for (u, v) in &m.units {
                for (b, bound) in v.buckets.iter().zip(BUCKETS) {
                    let _ = writeln!(s, "mbtap_bridge_latency_seconds_bucket{{unit=\"{u}\",le=\"{bound}\"}} {b}");
                }
                let _ = writeln!(s, "mbtap_bridge_latency_seconds_bucket{{unit=\"{u}\",le=\"+Inf\"}} {}", v.latency_count);
                let _ = writeln!(s, "mbtap_bridge_latency_seconds_sum{{unit=\"{u}\"}} {}", v.latency_sum);
                let _ = writeln!(s, "mbtap_bridge_latency_seconds_count{{unit=\"{u}\"}} {}", v.latency_count);
            }
            let _ = writeln!(
                s,
                "# HELP mbtap_bridge_queue_depth Requests waiting for the line.\n# TYPE mbtap_bridge_queue_depth gauge\nmbtap_bridge_queue_depth {}",
                m.queue_depth
            );
            counter(&mut s, "mbtap_bridge_dropped_total", "Queued requests dropped because their client left or gave up on them.");
            let _ = writeln!(s, "mbtap_bridge_dropped_total {}", m.dropped);
            counter(&mut s, "mbtap_bridge_port_reopened_total", "Times the serial port was reopened.");
            let _ = writeln!(s, "mbtap_bridge_port_reopened_total {}", m.reopened);
            counter(&mut s, "mbtap_bridge_cache_hits_total", "Reads answered from the cache (--cache).");
            let _ = writeln!(s, "mbtap_bridge_cache_hits_total {}", m.cache_hits);
            counter(&mut s, "mbtap_bridge_cache_misses_total", "Reads the cache covers that went to the line (missing or stale).");
            let _ = writeln!(s, "mbtap_bridge_cache_misses_total {}", m.cache_misses);
            counter(&mut s, "mbtap_bridge_coalesced_total", "Requests answered with another client's identical read, sent once.");
            let _ = writeln!(s, "mbtap_bridge_coalesced_total {}", m.coalesced);
            counter(&mut s, "mbtap_bridge_line_seconds_total", "Line time used, by class (high: --priority, poll: --poll).");
            for (c, d) in &m.line_time {
                let _ = writeln!(s, "mbtap_bridge_line_seconds_total{{class=\"{c}\"}} {}", d.as_secs_f64());
            }
            s
        })
    }
}
