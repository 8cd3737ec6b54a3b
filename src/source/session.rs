//! One analyzer driver for every live source — `sniff`, `tap`, `demo` and the bridge's
//! `--monitor`: each chunk recorded (when asked) and analyzed, every event going to the one
//! [`EventWriter`] that holds every sink (text or JSON lines, the terminal UI, the health
//! report, the register image, `--learn` drafts, the spy server, MQTT). The sources keep only
//! what touches their world: ports, ptys, the virtual bus, the bridge's channel, timers.

use std::io::Write;

use mbtap_analysis::analyzer::{Analyzer, AnalyzerConfig, Event};
use mbtap_analysis::chunk::{Chunk, Timestamp};

use crate::output::EventWriter;
use crate::source::record::Recorder;

/// The analysis of one live session, and its recording.
pub struct Session {
    analyzer: Analyzer,
    /// The writer's device profiles' vendor lengths were given to the analyzer.
    declared: bool,
    recorder: Option<Recorder>,
    /// Tell the writer (and the recording) what the framer learned of the observer's reads at
    /// the end: for sources read through real ports, where it was learned.
    tell_observers: bool,
}

impl std::fmt::Debug for Session {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Session")
            .field("recording", &self.recorder.is_some())
            .field("tell_observers", &self.tell_observers)
            .finish_non_exhaustive()
    }
}

impl Session {
    #[must_use]
    pub fn new(config: AnalyzerConfig) -> Self {
        Self { analyzer: Analyzer::new(config), declared: false, recorder: None, tell_observers: false }
    }

    /// Every chunk also written to `recorder`.
    #[must_use]
    pub fn recording(mut self, recorder: Option<Recorder>) -> Self {
        self.recorder = recorder;
        self
    }

    /// At the end, what the framer learned of each port's reads goes to the summary and the
    /// recording.
    #[must_use]
    pub fn telling_observers(mut self) -> Self {
        self.tell_observers = true;
        self
    }

    /// The recording, for a source that flushes it itself (a port lost and waited for).
    pub fn recorder(&mut self) -> Option<&mut Recorder> {
        self.recorder.as_mut()
    }

    /// The vendor frame lengths the writer's device profiles declare, given once.
    fn declare<W: Write>(&mut self, writer: &EventWriter<W>) {
        if !self.declared {
            self.declared = true;
            self.analyzer.declare_lengths(&mbtap_analysis::analyzer::declared_lengths(&writer.profiles));
        }
    }

    /// One read: recorded, then analyzed.
    pub fn chunk<W: Write>(&mut self, chunk: &Chunk<'_>, writer: &mut EventWriter<W>, err: &mut dyn Write) {
        self.declare(writer);
        if let Some(r) = self.recorder.as_mut() {
            r.write(u32::from(chunk.port.0), chunk.t, chunk.bytes, err);
        }
        self.analyzer.push(chunk, &mut |e: &Event<'_>| writer.write(e));
    }

    /// A chunk known to be exactly one frame (what the bridge itself wrote), shown at once.
    pub fn frame<W: Write>(&mut self, chunk: &Chunk<'_>, writer: &mut EventWriter<W>) {
        self.declare(writer);
        self.analyzer.push_frame(chunk, &mut |e: &Event<'_>| writer.write(e));
    }

    /// The time is `now` and nothing new came: what the silence decides.
    pub fn tick<W: Write>(&mut self, now: Timestamp, writer: &mut EventWriter<W>) {
        self.analyzer.tick(now, &mut |e: &Event<'_>| writer.write(e));
    }

    /// The recording and the output flushed (at least once a second while live: a killed
    /// process loses at most that).
    pub fn flush<W: Write>(&mut self, writer: &mut EventWriter<W>, err: &mut dyn Write) {
        if let Some(r) = self.recorder.as_mut() {
            r.flush(err);
        }
        let _ = writer.out.flush();
    }

    /// The analysis to its end; then the recording's verdict (the summary is written by the
    /// caller either way, before a failed recording's error reaches the exit status).
    ///
    /// # Errors
    /// The recording could not be completed.
    pub fn finish<W: Write>(mut self, writer: &mut EventWriter<W>, err: &mut dyn Write) -> anyhow::Result<()> {
        self.analyzer.finish(&mut |e: &Event<'_>| writer.write(e));
        if self.tell_observers {
            for (port, estimate) in self.analyzer.observers() {
                writer.observer(port, &estimate);
                if let Some(r) = self.recorder.as_mut() {
                    r.note_observer(port, &estimate, err);
                }
            }
        }
        self.recorder.map_or(Ok(()), |r| r.finish(err))
    }
}
