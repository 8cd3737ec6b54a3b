//! Running the terminal UI over a source: the source produces events on its own thread into
//! an [`EventWriter`] that feeds the UI's model, until the user quits. Shared by `replay`,
//! `sniff`, `tap`, `demo` and `bridge --monitor tui`.

use std::io::{self, IsTerminal, Write};
use std::process::ExitCode;

use crate::output::{EventFormat, EventWriter};

/// What the terminal UI needs to know about a source.
#[derive(Debug)]
pub struct TuiSource {
    pub profiles: mbtap_device::profile::Profiles,
    pub lang: mbtap_device::profile::annotate::Lang,
    pub line: mbtap_analysis::framer::LineSettings,
    /// Recorded or simulated input the UI may pace; live input it can only freeze.
    pub pacing: bool,
}

impl TuiSource {
    /// Runs `produce` on its own thread, feeding the UI, until the user quits.
    pub fn run<F>(self, source: &str, produce: F) -> anyhow::Result<ExitCode>
    where
        F: FnOnce(&mut EventWriter<io::Sink>, &mut dyn Write) -> anyhow::Result<()> + Send + 'static,
    {
        use super::terminal::{NoticeWriter, Shared, run};
        anyhow::ensure!(
            io::stdout().is_terminal(),
            "the terminal UI needs a terminal on stdout; use --format text or jsonl in pipes"
        );
        let model = super::Model::new(self.profiles.clone(), self.lang, self.line, super::model::DEFAULT_SCROLLBACK);
        let shared = Shared::new(model);
        let feeder = std::sync::Arc::clone(&shared);
        let (profiles, lang) = (self.profiles, self.lang);
        run(&shared, source, self.pacing, move || {
            let mut writer = EventWriter::new(io::sink(), EventFormat::Summary);
            writer.profiles = profiles;
            writer.lang = lang;
            writer.tui = Some(std::sync::Arc::clone(&feeder) as std::sync::Arc<dyn crate::output::UiFeed>);
            let mut notices = NoticeWriter::new(feeder);
            produce(&mut writer, &mut notices)
        })?;
        Ok(ExitCode::SUCCESS)
    }
}
