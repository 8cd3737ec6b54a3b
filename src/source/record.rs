//! `--record FILE` for `sniff` and `tap`: every read to a pcapng line capture, flushed at least
//! once a second whatever the traffic. A recording that fails (a full disk, a pulled stick)
//! stops recording, says so once — naming the file — and leaves the analysis and the relay
//! running; the command's exit status still reports it.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::Context;
use mbtap_analysis::capture::PcapNgWriter;
use mbtap_analysis::chunk::Timestamp;

/// A recording in progress, or one that failed.
#[derive(Debug)]
pub struct Recorder {
    path: PathBuf,
    writer: Option<PcapNgWriter<BufWriter<std::fs::File>>>,
    /// What made the recording stop, kept for the exit status.
    failed: Option<String>,
}

impl Recorder {
    /// Creates `path` with one serial interface per `(name, description)`.
    ///
    /// # Errors
    /// The file cannot be created or its header written (at start, nothing is lost yet).
    pub fn create(path: &Path, interfaces: &[(&str, &str)]) -> anyhow::Result<Self> {
        // A recording grows while the line is heard: written in place (what was heard before a
        // crash stays), but never through a link planted at its name.
        let file = {
            use std::os::unix::fs::OpenOptionsExt as _;
            std::fs::OpenOptions::new()
                .write(true)
                .create(true)
                .truncate(true)
                .custom_flags(nix::fcntl::OFlag::O_NOFOLLOW.bits())
                .open(path)
                .with_context(|| format!("creating {} (a symbolic link there is not followed)", path.display()))?
        };
        let mut w = PcapNgWriter::new(BufWriter::new(file)).with_context(|| format!("writing {}", path.display()))?;
        for (name, description) in interfaces {
            w.add_serial_interface(name, description).with_context(|| format!("writing {}", path.display()))?;
        }
        Ok(Self { path: path.to_owned(), writer: Some(w), failed: None })
    }

    /// Records one read; on failure stops recording and says so on `err`.
    pub fn write(&mut self, port: u32, t: Timestamp, bytes: &[u8], err: &mut dyn Write) {
        if let Some(w) = self.writer.as_mut()
            && let Err(e) = w.write_packet(port, t, bytes)
        {
            self.fail(&e, err);
        }
    }

    /// Pushes what is buffered to the file; on failure stops recording and says so.
    pub fn flush(&mut self, err: &mut dyn Write) {
        if let Some(w) = self.writer.as_mut()
            && let Err(e) = w.flush()
        {
            self.fail(&e, err);
        }
    }

    fn fail(&mut self, e: &std::io::Error, err: &mut dyn Write) {
        let message = format!("recording to {} failed: {e}", self.path.display());
        let _ = writeln!(err, "mbtap: {message}; recording stopped, the analysis goes on");
        self.writer = None;
        self.failed = Some(message);
    }

    /// Writes what the framer learned about a port's reads into the recording (an interface
    /// statistics block's comment, `mbtap observer latency_ns=…`): known only at the end, read
    /// back by `replay` and shown beside what the replay learns.
    pub fn note_observer(
        &mut self,
        port: mbtap_analysis::chunk::PortId,
        e: &mbtap_analysis::framer::ObserverEstimate,
        err: &mut dyn Write,
    ) {
        let Some(learned) = e.learned_latency_ns else { return };
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        let comment = format!(
            "mbtap observer latency_ns={learned} split_frames={} reads={} read_bytes={} longest_read={}",
            e.split_frames, e.reads, e.read_bytes, e.longest_read
        );
        if let Some(w) = self.writer.as_mut()
            && let Err(x) = w.write_statistics_comment(u32::from(port.0), Timestamp(now), &comment)
        {
            self.fail(&x, err);
        }
    }

    /// Flushes and closes; the error if the recording failed at any time.
    ///
    /// # Errors
    /// The recording failed (the message names the file).
    pub fn finish(mut self, err: &mut dyn Write) -> anyhow::Result<()> {
        self.flush(err);
        match self.failed {
            Some(message) => anyhow::bail!("{message} (what came before it is in the file)"),
            None => Ok(()),
        }
    }
}

/// Valid frames seen while reading a capture back.
struct ValidFrames(u64);

impl mbtap_analysis::analyzer::Sink for ValidFrames {
    fn event(&mut self, e: &mbtap_analysis::analyzer::Event<'_>) {
        if let mbtap_analysis::analyzer::Event::Frame { frame, .. } = e
            && frame.check_ok
        {
            self.0 += 1;
        }
    }

    fn warning(&mut self, _: &str) {}
}

/// Recordings up to this size are read back for their frame count as a session ends (a few
/// hundredths of a second at replay's speed); a longer one is said by its size alone.
const COUNT_UP_TO: u64 = 64 << 20;

/// What a session that recorded says as it ends, whichever way it ends (the terminal UI's `q`
/// too): where the file is and what it holds.
#[must_use]
pub fn ended_note(path: &Path) -> Option<String> {
    let len = std::fs::metadata(path).ok()?.len();
    let frames = (len <= COUNT_UP_TO)
        .then(|| {
            let file = std::fs::File::open(path).ok()?;
            let mut count = ValidFrames(0);
            let overrides = mbtap_analysis::line_args::LineOverrides::default();
            mbtap_analysis::replay::replay_into(std::io::BufReader::new(file), overrides, &mut count).ok()?;
            Some(format!("{} valid frames, ", count.0))
        })
        .flatten()
        .unwrap_or_default();
    Some(format!(
        "recorded to {} ({frames}{len} bytes); play it back with: mbtap replay {}",
        path.display(),
        path.display()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `--record` session ending said nothing of its file. It says where, how many
    /// valid frames (as a replay counts them: the Display's examples are 8) and how big.
    #[test]
    fn a_recording_is_said_with_its_frames_when_it_ends() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("captures/display-examples-rtu.pcapng");
        let note = ended_note(&path).unwrap();
        assert!(note.contains("(8 valid frames, ") && note.contains("mbtap replay "), "{note}");
        assert_eq!(ended_note(Path::new("/nonexistent/x.pcapng")), None);
    }

    /// A full disk stops the recording, not `sniff` or `tap`, and the message names the file.
    #[test]
    fn a_full_disk_stops_the_recording_not_the_caller_and_names_the_file() {
        // /dev/full accepts the open and fails every write with ENOSPC, as a full disk does.
        let mut r = match Recorder::create(Path::new("/dev/full"), &[("p", "19200 8E1")]) {
            Ok(r) => r,
            // The header is buffered; if this system's /dev/full refused even that, the failure
            // at start is named too.
            Err(e) => {
                assert!(e.to_string().contains("/dev/full"), "{e}");
                return;
            }
        };
        let mut err = Vec::new();
        for i in 0..10_000u64 {
            r.write(0, Timestamp(i), &[0x01, 0x03, 0x00, 0x00], &mut err);
        }
        r.flush(&mut err);
        let said = String::from_utf8_lossy(&err).into_owned();
        assert_eq!(said.matches("recording to /dev/full failed").count(), 1, "said once: {said}");
        let e = r.finish(&mut err).unwrap_err().to_string();
        assert!(e.contains("/dev/full"), "{e}");
    }

    /// What the framer learned about a port's reads goes into the file, for replay to read back;
    /// nothing is written before anything is learned.
    #[test]
    fn the_learned_latency_is_written_at_the_end_of_the_recording() {
        let path = std::env::temp_dir().join(format!("mbtap-observer-{}.pcapng", std::process::id()));
        let mut r = Recorder::create(&path, &[("p", "mbtap rtu 9600 8E1 latency_ns=0")]).unwrap();
        let mut err = Vec::new();
        r.write(0, Timestamp(5), &[0x01, 0x03, 0x00, 0x00], &mut err);
        let mut e = mbtap_analysis::framer::ObserverEstimate::default();
        r.note_observer(mbtap_analysis::chunk::PortId(0), &e, &mut err);
        e.learned_latency_ns = Some(15_900_000);
        r.note_observer(mbtap_analysis::chunk::PortId(0), &e, &mut err);
        r.finish(&mut err).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        let mut reader = mbtap_analysis::capture::CaptureReader::new(&bytes[..]);
        while reader.next_item().unwrap().is_some() {}
        assert_eq!(reader.recorded_latency, [(0, 15_900_000)]);
        let blocks = String::from_utf8_lossy(&bytes).matches("mbtap observer").count();
        assert_eq!(blocks, 1, "one comment, none before anything was learned");
    }
}
