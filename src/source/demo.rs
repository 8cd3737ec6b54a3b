//! `mbtap demo`: the whole job with no hardware — simulated MK4, Display and MKZP-0.4 on a
//! virtual line ([`mbtap_sim::bus`]), polled by a built-in master, heard by the same analyzer
//! `sniff` uses and shown annotated by their profiles, in real time.

use std::io::Write;
use std::sync::Arc;
use std::time::Duration;

use crate::io::serial::now;
use crate::output::EventWriter;
use crate::source::session::Session;
use mbtap_analysis::analyzer::AnalyzerConfig;
use mbtap_analysis::chunk::{Chunk, PortId, Timestamp};
use mbtap_analysis::framer::{FramerConfig, LineSettings};
use mbtap_sim::Slave;
use mbtap_sim::bus::VirtualBus;
use mbtap_sim::uart::Listener;

/// Demo settings.
#[derive(Debug, Clone, Default)]
pub struct DemoOptions {
    /// Line time to run for.
    pub duration: Option<Duration>,
    pub faults: Vec<mbtap_sim::bus::Fault>,
    /// Line time per wall-clock time; 0 runs without waiting.
    pub speed: f64,
    /// The listener's UART settings, when not the line's.
    pub heard_at: Option<LineSettings>,
    /// Where to record what the listener hears (pcapng).
    pub record: Option<std::path::PathBuf>,
}

/// Runs the demo until Ctrl-C or the duration; the writer's profiles are set to the devices.
///
/// # Errors
/// When a built-in profile does not load (a build defect) or the output cannot be written.
pub async fn demo<W: Write>(opts: DemoOptions, writer: &mut EventWriter<W>) -> anyhow::Result<()> {
    let duration = opts.duration;
    let line = LineSettings::default();
    let mut slaves = Vec::new();
    for (address, profile) in mbtap_sim::demo_profiles()? {
        writer.profiles.insert(address, profile.clone());
        slaves.push(Slave::new(Arc::new(profile), address));
    }
    let mut bus = VirtualBus::new(slaves, line);
    bus.faults = opts.faults;
    let heard_at = opts.heard_at.unwrap_or(line);
    let mut listener = Listener::new(line, heard_at);
    let recorder = match &opts.record {
        Some(path) => Some(crate::source::record::Recorder::create(
            path,
            // What the listener hears, described as the reader reads it back (its settings).
            &[(
                "demo",
                &mbtap_analysis::line_args::LineOverrides::describe(
                    mbtap_analysis::analyzer::SerialMode::Rtu,
                    heard_at,
                    0,
                ),
            )],
        )?),
        None => None,
    };
    let mut session =
        Session::new(AnalyzerConfig { framer: FramerConfig::new(heard_at, 0), ..AnalyzerConfig::default() })
            .recording(recorder);
    let start = tokio::time::Instant::now();
    let start_t = now();
    let mut stop = Box::pin(crate::io::signals::shutdown_signal());
    'run: loop {
        for frame in bus.next_transaction() {
            let at = Duration::from_nanos(frame.end_ns);
            if duration.is_some_and(|d| at >= d) {
                break 'run;
            }
            if let Some(feed) = writer.tui.clone() {
                // The UI sets the pace (space pauses, s changes the speed).
                while let Some(wait) = feed.due_in(frame.end_ns) {
                    tokio::select! {
                        () = &mut stop => break 'run,
                        () = tokio::time::sleep(wait) => {}
                    }
                }
            } else if opts.speed > 0.0 {
                tokio::select! {
                    () = &mut stop => break 'run,
                    () = tokio::time::sleep_until(start + at.div_f64(opts.speed)) => {}
                }
            }
            let heard: Vec<u8> = listener.hear(&frame).into_iter().map(|(_, b)| b).collect();
            let t = Timestamp(start_t.0.saturating_add(frame.end_ns));
            session.chunk(&Chunk { port: PortId(0), t, bytes: &heard }, writer, &mut std::io::sink());
            // The frame's end is only certain after the line stays quiet: let the framer see it.
            session.tick(Timestamp(t.0.saturating_add(2_000_000)), writer);
            session.flush(writer, &mut std::io::sink());
        }
        if let Some(e) = writer.error.take() {
            return Err(e.into());
        }
    }
    session.finish(writer, &mut std::io::sink())
}
