//! The edge of the UI: the real terminal (raw mode, alternate screen, restored on quit, error,
//! panic and signals), the key loop, pacing of recorded input, and exports of what the filter
//! shows. The producer (sniffer, replay, demo) runs on its own thread and feeds the shared
//! model through [`crate::output::EventWriter`].

use std::io::Write;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use anyhow::Context;
use ratatui::crossterm::event::{self, Event as TermEvent, KeyEventKind};

use super::app::{Action, App, Speed};
use super::model::{Model, Row, RowKind};

/// What the producer and the UI share.
#[derive(Debug)]
pub struct Shared {
    pub model: Mutex<Model>,
    pub speed: Mutex<Speed>,
    /// The producer's pacing of recorded input (one producer per UI).
    pacer: Mutex<Pacer>,
}

impl crate::output::UiFeed for Shared {
    fn event(&self, e: &mbtap_analysis::analyzer::Event<'_>, paced: bool) {
        if paced {
            // Wait (the producer's thread) until the event is due; a stop ends all waiting.
            let t = crate::output::event_time(e);
            while !crate::io::signals::stop_requested() {
                match self.due_in(t) {
                    None => break,
                    Some(d) => std::thread::sleep(d),
                }
            }
        }
        self.model().event(e);
    }

    fn settings(&self, line: mbtap_analysis::framer::LineSettings) {
        self.model().line = line;
    }

    fn due_in(&self, t_ns: u64) -> Option<Duration> {
        let speed = self.speed();
        self.pacer.lock().unwrap_or_else(PoisonError::into_inner).delay(t_ns, speed, Instant::now())
    }
}

impl Shared {
    #[must_use]
    pub fn new(model: Model) -> Arc<Self> {
        Arc::new(Self {
            model: Mutex::new(model),
            speed: Mutex::new(Speed::Times(1.0)),
            pacer: Mutex::new(Pacer::default()),
        })
    }

    /// The model, even if a producer panicked while holding it (the UI must still restore
    /// the terminal and show what it has).
    pub fn model(&self) -> std::sync::MutexGuard<'_, Model> {
        self.model.lock().unwrap_or_else(PoisonError::into_inner)
    }

    #[must_use]
    pub fn speed(&self) -> Speed {
        *self.speed.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// The producer's messages (what it would print on stderr), shown on the status line: the
/// terminal belongs to the UI. A message arrives in pieces (`writeln!` writes each formatted
/// part apart): the line is shown once it is whole (the status line showed only the
/// last piece of one, a stray `)`).
#[derive(Debug)]
pub struct NoticeWriter {
    shared: Arc<Shared>,
    /// The start of a line whose end has not come yet (bounded: a line longer is cut).
    partial: String,
}

/// The longest part of a line kept while waiting for its end.
const NOTICE_MAX: usize = 4096;

impl NoticeWriter {
    #[must_use]
    pub fn new(shared: Arc<Shared>) -> Self {
        Self { shared, partial: String::new() }
    }
}

impl Write for NoticeWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let text = String::from_utf8_lossy(buf);
        let mut last = None;
        for c in text.chars() {
            if c == '\n' {
                let line = std::mem::take(&mut self.partial);
                if !line.trim().is_empty() {
                    last = Some(line);
                }
            } else if self.partial.len() < NOTICE_MAX {
                self.partial.push(c);
            }
        }
        if let Some(line) = last {
            self.shared.model().notice = Some(line.trim().trim_start_matches("mbtap: ").to_owned());
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod notice_tests {
    use super::*;

    /// The status line began with a stray `)` — the last piece `writeln!` wrote of
    /// "sniffing PORT at … (reads trusted to …)" taken for the whole message.
    #[test]
    fn a_message_written_in_pieces_is_shown_whole() {
        let line = mbtap_analysis::framer::LineSettings {
            baud: 19_200,
            data_bits: 8,
            parity: mbtap_analysis::framer::Parity::Even,
            stop_bits: 1,
        };
        let model = super::super::model::Model::new(
            mbtap_device::profile::Profiles::new(),
            mbtap_device::profile::annotate::Lang::En,
            line,
            100,
        );
        let shared = Shared::new(model);
        let mut w = NoticeWriter::new(shared.clone());
        let (port, line, trust) = ("/dev/ttyUSB0", "19200 8E1", "reads trusted to 1000 µs");
        let _ = writeln!(w, "mbtap: sniffing {port} at {line} ({trust})");
        assert_eq!(
            shared.model().notice.as_deref(),
            Some("sniffing /dev/ttyUSB0 at 19200 8E1 (reads trusted to 1000 µs)")
        );
    }
}

/// Paces recorded input: when the event at line time `t` may be shown at the chosen speed.
/// Pure: the caller passes the wall-clock time.
#[derive(Debug, Clone, Default)]
pub struct Pacer {
    anchor: Option<(Instant, u64, u64)>,
}

/// The longest single wait, so a change of speed is noticed promptly.
const STEP: Duration = Duration::from_millis(50);

impl Pacer {
    /// `None`: go now. `Some(d)`: wait `d` and ask again.
    pub fn delay(&mut self, t_ns: u64, speed: Speed, now: Instant) -> Option<Duration> {
        let times = match speed {
            Speed::Paused => {
                self.anchor = None;
                return Some(STEP);
            }
            Speed::Max => {
                self.anchor = None;
                return None;
            }
            Speed::Times(x) => x,
        };
        // Speed as thousandths, so a change of speed re-anchors.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let milli = (times * 1000.0).clamp(1.0, 1e12) as u64;
        let &mut (wall, line, m) = self.anchor.get_or_insert((now, t_ns, milli));
        if m != milli || t_ns < line {
            self.anchor = Some((now, t_ns, milli));
            return None;
        }
        let due = wall + Duration::from_nanos((t_ns - line).saturating_mul(1000) / milli);
        let wait = due.saturating_duration_since(now);
        (!wait.is_zero()).then(|| wait.min(STEP))
    }
}

/// Runs the UI on this thread until `q` (or a signal); `producer` runs on its own thread and
/// feeds `shared`. Returns the producer's error, if it had one.
///
/// # Errors
/// When the terminal cannot be set up, or the producer failed.
pub fn run<F>(shared: &Arc<Shared>, source: &str, pacing: bool, producer: F) -> anyhow::Result<()>
where
    F: FnOnce() -> anyhow::Result<()> + Send + 'static,
{
    let feeder = Arc::clone(shared);
    let handle = std::thread::Builder::new()
        .name("mbtap-producer".into())
        .spawn(move || {
            let result = producer();
            let mut model = feeder.model();
            model.finished = Some(match &result {
                Ok(()) => "input ended".to_owned(),
                Err(e) => format!("stopped: {e:#}"),
            });
            result
        })
        .context("starting the producer thread")?;
    // ratatui::init restores the terminal on panic too (its panic hook).
    let mut terminal = ratatui::init();
    let ui = ui_loop(&mut terminal, shared, source, pacing);
    ratatui::restore();
    crate::io::signals::request_stop();
    let produced = handle.join().unwrap_or_else(|_| Err(anyhow::anyhow!("the producer thread panicked")));
    ui?;
    produced
}

fn ui_loop(terminal: &mut ratatui::DefaultTerminal, shared: &Shared, source: &str, pacing: bool) -> anyhow::Result<()> {
    let mut app = App::new(pacing);
    loop {
        {
            let model = shared.model();
            terminal.draw(|f| super::render::draw(f, &mut app, &model, source)).context("drawing the terminal")?;
        }
        if crate::io::signals::signalled() {
            return Ok(());
        }
        // Redraw at most every 50 ms: smooth, and cheap on a busy bus.
        if !event::poll(Duration::from_millis(50)).context("reading the terminal")? {
            continue;
        }
        let TermEvent::Key(key) = event::read().context("reading the terminal")? else { continue };
        if key.kind != KeyEventKind::Press {
            continue;
        }
        let action = {
            let model = shared.model();
            app.key(key, &model)
        };
        match action {
            Action::None => {}
            Action::Quit => return Ok(()),
            Action::Speed => *shared.speed.lock().unwrap_or_else(PoisonError::into_inner) = app.speed,
            Action::ExportJsonl | Action::ExportPcapng => {
                let model = shared.model();
                let shown = app.visible().len();
                let rows: Vec<&Row> = app.visible().iter().filter_map(|&s| model.row(s)).collect();
                let pcap = action == Action::ExportPcapng;
                app.message = Some(match export(&rows, &model, pcap) {
                    Ok((path, n)) => export_said(&path, n, shown),
                    Err(e) => format!("export failed: {e:#}"),
                });
            }
        }
    }
}

/// What an export says: every row shown, or how many of them and why the rest are not (a row
/// the model has let go of — the oldest, when memory is full — can still be on screen but can
/// no longer be written, so "exported 26 rows" beside "(27 shown)" says why).
fn export_said(path: &str, exported: usize, shown: usize) -> String {
    if exported >= shown {
        format!("exported all {exported} rows shown to {path}")
    } else {
        format!(
            "exported {exported} of the {shown} rows shown to {path}: the {} oldest were already dropped from memory",
            shown - exported
        )
    }
}

/// Writes `rows` to a new file in the working directory; its name and the count.
fn export(rows: &[&Row], model: &Model, pcap: bool) -> anyhow::Result<(String, usize)> {
    let stamp = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let stem = format!("mbtap-export-{stamp}");
    let (path, file) = create_unique(std::path::Path::new("."), &stem, if pcap { "pcapng" } else { "jsonl" })
        .with_context(|| format!("creating {stem}.* in the working directory"))?;
    let path = path.strip_prefix(".").unwrap_or(&path).display().to_string();
    let mut out = std::io::BufWriter::new(file);
    if pcap {
        write_pcapng(rows, model, &mut out).with_context(|| format!("writing {path}"))?;
    } else {
        for r in rows {
            writeln!(out, "{}", row_json(r, model)).with_context(|| format!("writing {path}"))?;
        }
    }
    out.flush().with_context(|| format!("writing {path}"))?;
    Ok((path, rows.len()))
}

/// Creates `dir/stem.ext`, or `stem-2.ext`, `stem-3.ext`… if taken: two exports in the same
/// second get two files, and an existing file is never truncated (`create_new`).
fn create_unique(dir: &std::path::Path, stem: &str, ext: &str) -> std::io::Result<(std::path::PathBuf, std::fs::File)> {
    for n in 1..=1000u32 {
        let name = if n == 1 { format!("{stem}.{ext}") } else { format!("{stem}-{n}.{ext}") };
        let path = dir.join(name);
        match std::fs::OpenOptions::new().write(true).create_new(true).open(&path) {
            Ok(file) => return Ok((path, file)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(e),
        }
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::AlreadyExists,
        format!("{stem}.{ext} and 999 numbered names are taken"),
    ))
}

fn hex(b: Option<&[u8]>) -> Option<String> {
    b.map(mbtap_analysis::report::format::hex_compact)
}

/// One exported row (the same keys as `sniff --format jsonl` transactions and noise).
#[must_use]
pub fn row_json(r: &Row, model: &Model) -> serde_json::Value {
    match r.kind {
        RowKind::Noise => serde_json::json!({
            "event": "noise", "t_ns": r.t_ns, "hex": hex(r.response.as_deref()),
        }),
        RowKind::Transaction(outcome) => serde_json::json!({
            "event": "transaction",
            "t_ns": r.t_ns,
            "unit": r.unit,
            "device": r.unit.and_then(|u| model.device_name(u)),
            "function": r.function,
            "outcome": outcome.name(),
            "latency_ns": r.latency_ns,
            "request_hex": hex(r.request.as_deref()),
            "response_hex": hex(r.response.as_deref()),
            "summary": r.summary,
        }),
    }
}

/// The rows' frames as a capture `mbtap replay` reads back (line settings in the interface).
fn write_pcapng(rows: &[&Row], model: &Model, out: &mut dyn Write) -> std::io::Result<()> {
    let mut w = mbtap_analysis::capture::writer::PcapNgWriter::new(out)?;
    let description =
        mbtap_analysis::line_args::LineOverrides::describe(mbtap_analysis::analyzer::SerialMode::Rtu, model.line, 0);
    let port = w.add_serial_interface("export", &description)?;
    for r in rows {
        let mut t = r.t_ns;
        for frame in [r.request.as_deref(), r.response.as_deref()].into_iter().flatten() {
            let end = t.saturating_add(model.line.char_ns().saturating_mul(frame.len() as u64));
            w.write_packet(port, mbtap_analysis::chunk::Timestamp(end), frame)?;
            t = end.saturating_add(r.latency_ns.unwrap_or(0));
        }
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// "(27 shown)" and "exported 26 rows" with nothing said of the difference.
    #[test]
    fn an_export_says_what_it_left_out_and_why() {
        assert_eq!(export_said("x.jsonl", 27, 27), "exported all 27 rows shown to x.jsonl");
        let said = export_said("x.jsonl", 26, 27);
        assert!(said.contains("26 of the 27") && said.contains("1 oldest were already dropped"), "{said}");
    }

    #[test]
    fn the_pacer_follows_line_time_at_the_chosen_speed() {
        let start = Instant::now();
        let mut p = Pacer::default();
        assert_eq!(p.delay(1_000_000_000, Speed::Times(1.0), start), None, "the first event anchors");
        // 30 ms of line time later, at 1×: 30 ms to wait; at 10× (re-anchored): goes now, then 3 ms.
        assert_eq!(p.delay(1_030_000_000, Speed::Times(1.0), start), Some(Duration::from_millis(30)));
        assert_eq!(p.delay(1_030_000_000, Speed::Times(10.0), start), None);
        assert_eq!(p.delay(1_060_000_000, Speed::Times(10.0), start), Some(Duration::from_millis(3)));
        // Long waits come in steps so a change of speed is seen.
        assert_eq!(p.delay(9_000_000_000, Speed::Times(10.0), start), Some(STEP));
        assert_eq!(p.delay(9_000_000_000, Speed::Paused, start), Some(STEP));
        assert_eq!(p.delay(9_000_000_000, Speed::Max, start), None);
    }

    /// Exports within the same second overwrote each other (same name,
    /// `File::create` truncating).
    #[test]
    fn exports_in_the_same_second_get_their_own_files_and_never_truncate() {
        let dir = std::env::temp_dir().join(format!("mbtap-export-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("mbtap-export-7.jsonl"), "kept\n").unwrap();
        let (a, _) = create_unique(&dir, "mbtap-export-7", "jsonl").unwrap();
        let (b, _) = create_unique(&dir, "mbtap-export-7", "jsonl").unwrap();
        assert_eq!(a, dir.join("mbtap-export-7-2.jsonl"));
        assert_eq!(b, dir.join("mbtap-export-7-3.jsonl"));
        assert_eq!(std::fs::read_to_string(dir.join("mbtap-export-7.jsonl")).unwrap(), "kept\n");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
