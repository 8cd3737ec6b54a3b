//! The one ending of the analyzing commands (`sniff`, `tap`, `demo`, `replay` and the bridge's
//! `--monitor`). A command builds its source — a [`EventSource`] — and its options; the runner
//! owns the rest: the terminal UI or text/JSON lines on stdout (with the health report and the
//! learned draft when asked), the publishers (spy server, MQTT), and what is said at the end —
//! the summary, where a recording went.

use std::io::{self, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use mbtap_analysis::framer::LineSettings;
use mbtap_device::profile::Profiles;
use mbtap_device::profile::annotate::Lang;

use crate::cli::args::{EventFormatArg, OutputArgs};
use crate::output::{EventWriter, SourceError};
use crate::publish::Publishing;
use crate::tui::source::TuiSource;

/// A source of events: runs into `writer` until it ends or is stopped, and says on `err` what
/// the user should know on the way. Implemented by each source's options.
pub trait EventSource: Send + 'static {
    /// # Errors
    /// [`SourceError::NotStarted`] when the source never began (nothing heard, no summary due);
    /// [`SourceError::Stopped`] when it failed after it had begun.
    fn run<W: Write>(self, writer: &mut EventWriter<W>, err: &mut dyn Write) -> Result<(), SourceError>;
}

/// What kind of input a runner has, said once by the command: it decides how values age, how
/// the UI and stdout keep time, and nothing else asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// A live line (`sniff`, `tap`, the bridge's `--monitor`): values age by the clock, events
    /// reach a pipe as they come.
    Live,
    /// A recording (`replay`): values age by the newest bus time heard, the UI plays it at its
    /// recorded speed, stdout is written in blocks (the file is read as fast as it reads).
    Recording,
    /// The demo's simulated line: it runs in real time on its own clock, so values age by its
    /// bus time and the UI shows it as it comes.
    Simulated,
}

impl Input {
    /// Values age by the host clock (a live line) rather than by the newest bus time heard.
    #[must_use]
    pub const fn ages_by_clock(self) -> bool {
        matches!(self, Self::Live)
    }

    /// The input keeps its own time: the UI offers its speed keys.
    #[must_use]
    pub const fn keeps_own_time(self) -> bool {
        matches!(self, Self::Recording | Self::Simulated)
    }

    /// Events are held to their recorded time before the UI shows them, and stdout takes them
    /// in 64 KiB blocks: the input arrives faster than it happened.
    #[must_use]
    pub const fn arrives_early(self) -> bool {
        matches!(self, Self::Recording)
    }

    /// Once the input has ended, its register image is served until Ctrl-C (`--serve`): a
    /// recording ends in a moment, and its image is what was asked for.
    #[must_use]
    pub const fn serves_after_end(self) -> bool {
        matches!(self, Self::Recording)
    }
}

/// What an analyzing command shows, publishes and says at the end.
#[derive(Debug)]
pub struct Runner {
    /// What the UI's title names: a port, `PORT ⇄ LINK`, a file.
    pub title: String,
    pub format: EventFormatArg,
    /// Loaded once: the output, the UI and the publishers name values by the same profiles.
    pub profiles: Profiles,
    pub lang: Lang,
    /// The line the UI shows until the source says its own.
    pub line: LineSettings,
    /// The report and the draft asked for (`--report`, `--report-every`, `--learn`).
    pub output: Option<OutputArgs>,
    /// What the input is: said once, it decides the UI's pacing and stdout's buffering.
    pub input: Input,
    pub publishing: Publishing,
    /// The recording this session writes: where it went and how much, said at the end.
    pub recording: Option<PathBuf>,
}

impl Runner {
    /// A runner of `input` showing `format` with these profiles, nothing published.
    #[must_use]
    pub fn new(
        title: String,
        input: Input,
        format: EventFormatArg,
        profiles: Profiles,
        lang: Lang,
        line: LineSettings,
    ) -> Self {
        Self {
            title,
            format,
            profiles,
            lang,
            line,
            output: None,
            input,
            publishing: Publishing::default(),
            recording: None,
        }
    }

    /// A runner of `input` as the shared output options say: their profiles (loaded once),
    /// format, language, report and draft, and their publishers started.
    ///
    /// # Errors
    /// A profile that does not load, a publisher that cannot start.
    pub fn from_output(title: String, input: Input, output: OutputArgs, line: LineSettings) -> anyhow::Result<Self> {
        let profiles = crate::config::devices::load_devices(&output.devices)?;
        let publishing = Publishing::start(&output.publish, input.ages_by_clock(), &title, &profiles)?;
        let mut runner = Self::new(title, input, output.format, profiles, output.lang.into(), line);
        runner.publishing = publishing;
        runner.output = Some(output);
        Ok(runner)
    }

    /// Runs `job` into the UI or stdout, then ends: the summary (unless the job never began),
    /// the recording's note, the publishers finished — on every path, the UI's too.
    ///
    /// # Errors
    /// The job's error, or the output's.
    pub fn run(self, job: impl EventSource) -> anyhow::Result<ExitCode> {
        let Self { title, format, profiles, lang, line, output, input, publishing, recording } = self;
        let taps = publishing.taps();
        let ended = if format == EventFormatArg::Tui {
            let ui = TuiSource { profiles, lang, line, pacing: input.keeps_own_time() };
            ui.run(&title, move |writer, err| {
                writer.taps = taps;
                writer.paced = input.arrives_early();
                job.run(writer, err).map_err(SourceError::into_error)
            })
            .map(|_| ())
        } else {
            let shown = Shown { format, profiles, lang, output: output.as_ref(), taps };
            let stdout = io::stdout();
            if input.arrives_early() {
                to_stdout(shown.writer(io::BufWriter::with_capacity(1 << 16, stdout.lock()))?, job)
            } else {
                to_stdout(shown.writer(io::LineWriter::new(stdout.lock()))?, job)
            }
        };
        if let Some(note) = recording.as_deref().and_then(crate::source::record::ended_note) {
            eprintln!("mbtap: {note}");
        }
        if ended.is_ok() && input.serves_after_end() && publishing.spy.is_some() {
            eprintln!("mbtap: the capture is replayed; serving its register image until Ctrl-C");
            crate::runtime()?.block_on(crate::io::signals::shutdown_signal());
        }
        publishing.finish();
        ended.map(|()| ExitCode::SUCCESS)
    }
}

/// How stdout shows events: the pieces of an [`EventWriter`] whatever it writes to.
struct Shown<'a> {
    format: EventFormatArg,
    profiles: Profiles,
    lang: Lang,
    output: Option<&'a OutputArgs>,
    taps: Vec<std::sync::Arc<dyn crate::output::Tap>>,
}

impl Shown<'_> {
    fn writer<W: Write>(self, out: W) -> anyhow::Result<EventWriter<W>> {
        let mut writer = EventWriter::new(out, self.format.into());
        writer.profiles = self.profiles;
        writer.lang = self.lang;
        writer.taps = self.taps;
        if let Some(o) = self.output {
            crate::cli::args::add_reports(&mut writer, o)?;
        }
        Ok(writer)
    }
}

/// Runs `job` into `writer`, then writes the summary (and report, and draft) unless the job
/// never began; the job's error wins over the summary's.
fn to_stdout<W: Write>(mut writer: EventWriter<W>, job: impl EventSource) -> anyhow::Result<()> {
    match job.run(&mut writer, &mut io::stderr()) {
        Ok(()) => writer.finish().map(|_| ()).map_err(Into::into),
        Err(SourceError::NotStarted(e)) => Err(e),
        Err(SourceError::Stopped(e)) => {
            let _ = writer.finish();
            Err(e)
        }
    }
}
