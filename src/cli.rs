//! Command-line definitions (clap). Parsing only; `main` dispatches.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

use mbtap_core::framer::LineSettings;

/// mbtap — a Modbus RTU/ASCII bus analyzer: sniff, decode, record, replay, bridge.
#[derive(Debug, Parser)]
#[command(name = "mbtap", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

/// Framing of the frames given to `decode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    Rtu,
    Ascii,
    Tcp,
}

/// Output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    /// Human-readable text.
    Text,
    /// One JSON object per line.
    Jsonl,
}

/// Language of names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LangArg {
    /// English.
    En,
    /// The document's original (Russian) names.
    Ru,
}

impl From<LangArg> for mbtap_core::profile::annotate::Lang {
    fn from(l: LangArg) -> Self {
        match l {
            LangArg::En => Self::En,
            LangArg::Ru => Self::Ru,
        }
    }
}

/// Serial mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SerialModeArg {
    Rtu,
    Ascii,
}

/// Parity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ParityArg {
    None,
    Even,
    Odd,
}

/// Output of analyzer commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum EventFormatArg {
    /// One line per frame, noise burst and transaction.
    Text,
    /// One JSON object per line (`event`: frame, noise, transaction, warning, summary).
    Jsonl,
    /// Only the summary at the end.
    Summary,
    /// The terminal UI: traffic, detail, devices and registers views (needs a terminal).
    Tui,
}

/// Line settings (each one overrides what a capture file stores).
#[derive(Debug, Clone, Args)]
pub struct LineArgs {
    /// RTU or ASCII framing [default: rtu, or what the capture says].
    #[arg(long, value_enum)]
    pub mode: Option<SerialModeArg>,
    /// Baud rate [default: 19200, or what the capture says].
    #[arg(long)]
    pub baud: Option<u32>,
    /// Parity [default: even, as the serial-line spec says].
    #[arg(long, value_enum)]
    pub parity: Option<ParityArg>,
    /// Stop bits (1 or 2) [default: 1].
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=2))]
    pub stop_bits: Option<u8>,
    /// Data bits (7 or 8) [default: 8 for RTU, 7 for ASCII].
    #[arg(long, value_parser = clap::value_parser!(u8).range(7..=8))]
    pub data_bits: Option<u8>,
    /// How late the adapter may deliver a byte, in ms (FTDI default latency timer: 16).
    /// Timing gaps shorter than this are not trusted. [default: live ports: the adapter's
    /// latency timer, at least 1 ms; captures: what they were recorded with; else 0]
    #[arg(long)]
    pub latency_ms: Option<f64>,
}

/// How the generator's bytes reach the reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ObserveArg {
    /// One read per byte, exact timestamps.
    PerByte,
    /// One packet per frame, as gap-cutting sniffers write captures.
    PerFrame,
    /// 16550 UART FIFO: 14-byte trigger, 4-character timeout.
    Fifo,
    /// USB adapter, 1 ms latency timer.
    Usb1,
    /// USB adapter, 16 ms latency timer (FTDI default).
    Usb16,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Explain Modbus frames given as hex (RTU, TCP) or ASCII (`:...`).
    ///
    /// Frames come as arguments, or one per line on stdin when there are none. Spaces, `0x`
    /// prefixes and separators (, ; - _ |) are tolerated. A request followed by its response is
    /// shown as one transaction.
    ///
    /// Exit status: 0 every frame decoded and passed its check; 1 a check failed or a PDU does
    /// not fit its function code; 2 some input is not a frame at all.
    #[command(
        after_help = "Examples:\n  mbtap decode \"01 03 06 00 00 00 00 01 90 20 89\"\n  mbtap decode ':01030065000394'\n  mbtap decode 010300650003 15D4 0103060000000001902089\n  echo 0183030131 | mbtap decode --format jsonl"
    )]
    Decode {
        /// Frames, one per argument (read from stdin, one per line, when none are given).
        frames: Vec<String>,
        /// Framing; detected per frame when not given (':' = ASCII, valid CRC = RTU, consistent MBAP = TCP).
        #[arg(long, value_enum)]
        mode: Option<ModeArg>,
        /// Output format.
        #[arg(long, value_enum, default_value_t = FormatArg::Text)]
        format: FormatArg,
        /// Annotate unit UNIT's values with a profile: `UNIT=NAME` (built-in, see `profiles
        /// list`) or `UNIT=FILE.toml` (repeatable).
        #[arg(long = "device", value_name = "UNIT=PROFILE")]
        devices: Vec<String>,
        /// Language of register names in annotations.
        #[arg(long, value_enum, default_value_t = LangArg::En)]
        lang: LangArg,
    },
    /// Replay a line capture (pcap/pcapng, link type 147) through the analyzer.
    ///
    /// Each packet is one chunk as a serial read delivered it, with its timestamp; frames are
    /// rebuilt, paired and shown exactly as a live session would have.
    Replay {
        /// The capture file.
        file: PathBuf,
        /// Write the register image (latest value of every unit/table/address seen, when, and
        /// from which transaction) to this file: `.json` for JSON, anything else CSV.
        #[arg(long)]
        image: Option<PathBuf>,
        #[command(flatten)]
        line: LineArgs,
        #[command(flatten)]
        output: OutputArgs,
    },
    /// Write a synthetic line capture with known content (for training, tests and benchmarks).
    Generate {
        /// Output pcapng file.
        out: PathBuf,
        /// Transactions to generate.
        #[arg(long, default_value_t = 1000)]
        transactions: usize,
        /// Random seed (the same seed gives the same file).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[command(flatten)]
        line: LineArgs,
        /// How the bytes are read.
        #[arg(long, value_enum, default_value_t = ObserveArg::PerByte)]
        observe: ObserveArg,
        /// Probability of a noise burst before a transaction.
        #[arg(long, default_value_t = 0.02)]
        noise: f64,
        /// Probability that a frame has a corrupted byte.
        #[arg(long, default_value_t = 0.02)]
        corrupt: f64,
        /// Probability that a response pauses inside (a slow slave).
        #[arg(long, default_value_t = 0.02)]
        slow: f64,
        /// Instead of random traffic, send these frames (one per line, hex or `:ASCII`, as
        /// `decode` reads them) back to back with a 5 ms turnaround, one read per byte.
        #[arg(long)]
        frames: Option<PathBuf>,
    },
    /// Export the rebuilt frames for Wireshark (pcapng, link type 252, `mbrtu` dissector).
    ///
    /// `tshark -r OUT` decodes every frame as Modbus RTU with no configuration; add
    /// `-o mbrtu.tcp.port:502` to have echo-shaped frames (05, 06, 08, 16) classified as query
    /// or response from the direction mbtap worked out.
    Export {
        /// The line capture to read.
        file: PathBuf,
        /// The Wireshark file to write.
        #[arg(short, long)]
        out: PathBuf,
        #[command(flatten)]
        line: LineArgs,
    },
    /// Listen to a live serial port: rebuild, pair and show every frame.
    ///
    /// Stops on Ctrl-C or SIGTERM (or after --duration) and prints a summary. With --record,
    /// every read is written to a pcapng line capture (flushed each second) that `replay`
    /// shows exactly as this session did.
    Sniff {
        /// The serial port (e.g. /dev/ttyUSB0).
        port: String,
        #[command(flatten)]
        line: LineArgs,
        #[command(flatten)]
        output: OutputArgs,
        /// Record every read to this pcapng file.
        #[arg(long)]
        record: Option<PathBuf>,
        /// Stop after this many seconds.
        #[arg(long)]
        duration: Option<f64>,
    },
    /// Play a line capture into a serial port with its recorded timing.
    Play {
        /// The capture to play.
        file: PathBuf,
        /// The serial port to write to.
        port: String,
        #[command(flatten)]
        line: LineArgs,
        /// Speed factor (2 = twice as fast).
        #[arg(long, default_value_t = 1.0)]
        speed: f64,
    },
    /// Tap a port used by an application on this computer: relay through a pseudo-terminal.
    ///
    /// mbtap opens PORT and offers a pseudo-terminal at --link for the application (a SCADA,
    /// a configuration tool) to open instead; bytes are relayed untouched both ways and both
    /// directions are analysed with the direction known.
    Tap {
        /// The real serial port.
        port: String,
        /// Where to create the pseudo-terminal link for the application.
        #[arg(long)]
        link: PathBuf,
        #[command(flatten)]
        line: LineArgs,
        #[command(flatten)]
        output: OutputArgs,
        /// Record both directions to this pcapng file.
        #[arg(long)]
        record: Option<PathBuf>,
        /// Stop after this many seconds.
        #[arg(long)]
        duration: Option<f64>,
    },
    /// The whole job with no hardware: simulated MK4, Display and MKZP-0.4 polled on a virtual
    /// line, heard and shown annotated as `sniff` would.
    Demo {
        /// Output format [default: tui on a terminal, text otherwise].
        #[arg(long, value_enum)]
        format: Option<EventFormatArg>,
        /// Language of register names in annotations.
        #[arg(long, value_enum, default_value_t = LangArg::En)]
        lang: LangArg,
        /// Stop after this many seconds (of line time).
        #[arg(long)]
        duration: Option<f64>,
        /// Inject a fault into every fourth transaction, faults taking turns (repeatable).
        #[arg(long = "fault", value_enum)]
        faults: Vec<FaultArg>,
        /// Line time per wall-clock time: 1 is real time, 10 ten times faster, 0 as fast as it goes.
        #[arg(long, default_value_t = 1.0)]
        speed: f64,
        /// Listen through a UART at these settings instead of the line's 19200 8E1 ("9600 8N1"):
        /// what a sniffer set up wrong gets.
        #[arg(long, value_name = "SETTINGS")]
        heard_at: Option<LineSettings>,
    },
    /// Simulated devices on a pseudo-terminal: point a Modbus master (or mbtap) at --link.
    Simulate {
        /// Where to create the pseudo-terminal link for the master.
        #[arg(long, default_value = "/tmp/mbtap-bus")]
        link: PathBuf,
        /// A simulated slave, `NAME@ADDRESS` (repeatable; default: mk4@1 display@5 mkzp@17).
        #[arg(long = "device", value_name = "NAME@ADDRESS")]
        devices: Vec<String>,
        #[command(flatten)]
        line: LineArgs,
        /// Stop after this many seconds.
        #[arg(long)]
        duration: Option<f64>,
        /// A slave's time from the end of a request to its answer, ms.
        #[arg(long, default_value_t = 3.0)]
        turnaround_ms: f64,
        /// Take the line's time when answering: requests end when their characters would
        /// have crossed the line, answers leave at the character rate.
        #[arg(long)]
        paced: bool,
        /// Play the master too: poll the devices and put the whole line on the pseudo-terminal,
        /// paced at the line's character rate, for a listener (`mbtap sniff LINK`).
        #[arg(long)]
        poll: bool,
        /// With --poll: inject a fault into every fourth transaction (repeatable).
        #[arg(long = "fault", value_enum, requires = "poll")]
        faults: Vec<FaultArg>,
        /// With --poll: the listener's UART settings when they are not the line's ("9600 8N1").
        #[arg(long, value_name = "SETTINGS", requires = "poll", conflicts_with = "follow_baud")]
        heard_at: Option<LineSettings>,
        /// With --poll: hear the line at the baud rate the listener set on the pseudo-terminal
        /// (as `mbtap scan` reopens it at each rate). A pty keeps the baud rate and odd parity
        /// of its termios but not the character size or parity enable, so only the rate follows.
        #[arg(long, requires = "poll")]
        follow_baud: bool,
    },
    /// Modbus TCP clients to serial devices: a TCP server in front of a serial master.
    #[command(args_override_self = true)]
    Bridge(Box<BridgeArgs>),
    /// Print a commented sample configuration for `bridge --config`.
    GenerateConfig,
    /// Find a live bus's line settings: try baud rates, parities, character sizes and both
    /// modes, and rank them by the valid frames they give.
    ///
    /// Given a file instead of a port — a capture (pcap/pcapng) or a raw dump of received
    /// bytes — it tells the mode and character size from the stored bytes (their baud rate
    /// and parity can no longer be changed: a wrong receiver's lost bits are gone).
    Scan {
        /// The serial port, or a file of stored bytes.
        port: String,
        /// Only these baud rates (repeatable; default: 1200 to 256000).
        #[arg(long = "baud")]
        bauds: Vec<u32>,
        /// How long to listen at each setting, ms.
        #[arg(long, default_value_t = 600)]
        dwell_ms: u64,
    },
    /// A bus health report from a capture: per unit and per bus, and findings with evidence.
    Report {
        /// The capture file (pcap or pcapng, as `sniff --record` writes).
        file: PathBuf,
        #[command(flatten)]
        line: LineArgs,
        /// Output format.
        #[arg(long, value_enum, default_value_t = ReportFormatArg::Text)]
        format: ReportFormatArg,
        /// Check unit UNIT's values against a profile: `UNIT=NAME` or `UNIT=FILE.toml` (repeatable).
        #[arg(long = "device", value_name = "UNIT=PROFILE")]
        devices: Vec<String>,
    },
    /// Device profiles: check a profile file, or show what it defines.
    #[command(subcommand)]
    Profiles(ProfilesCommand),
}

/// What `sniff`, `tap` and `replay` show, and how.
#[derive(Debug, Args)]
pub struct OutputArgs {
    /// Output format.
    #[arg(long, value_enum, default_value_t = EventFormatArg::Text)]
    pub format: EventFormatArg,
    /// Annotate unit UNIT's values with a profile: `UNIT=NAME` or `UNIT=FILE.toml` (repeatable).
    #[arg(long = "device", value_name = "UNIT=PROFILE")]
    pub devices: Vec<String>,
    /// Language of register names in annotations.
    #[arg(long, value_enum, default_value_t = LangArg::En)]
    pub lang: LangArg,
    /// End (end of file, Ctrl-C or --duration) with the bus health report, as `mbtap report`
    /// gives it.
    #[arg(long)]
    pub report: bool,
    /// Also give the report so far every SECONDS of bus time, while it runs (implies --report).
    #[arg(long, value_name = "SECONDS")]
    pub report_every: Option<f64>,
}

/// `mbtap bridge …` (boxed: by far the largest command).
#[derive(Debug, Args)]
pub struct BridgeArgs {
    /// Read settings from this TOML file ([bridge] table; the command line wins).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// The serial port of the line (all units; see --route for several lines).
    #[arg(long)]
    pub serial: Option<String>,
    #[command(flatten)]
    pub line: LineArgs,
    /// Modbus TCP (MBAP) listening address, e.g. 0.0.0.0:502 (port 0 picks a free port).
    #[arg(long, value_name = "ADDR:PORT")]
    pub listen: Option<String>,
    /// Raw RTU frames over TCP on this address too (or instead).
    #[arg(long, value_name = "ADDR:PORT")]
    pub listen_rtu: Option<String>,
    /// Units FIRST-LAST on another serial port (repeatable): --route 11-20=/dev/ttyUSB1.
    #[arg(long = "route", value_name = "UNITS=PORT")]
    pub routes: Vec<String>,
    /// Response timeout per request, ms; then retries, then exception 0x0B.
    #[arg(long, default_value_t = 1000)]
    pub timeout_ms: u64,
    /// Retries after a timeout or a failed CRC.
    #[arg(long, default_value_t = 0)]
    pub retries: u32,
    /// Extra quiet time after t3.5 before the next request, ms.
    #[arg(long, default_value_t = 0.0)]
    pub turnaround_ms: f64,
    /// Answer broadcast writes (unit 0) at once instead of not at all.
    #[arg(long)]
    pub broadcast_reply: bool,
    /// Refuse writes (exception 0x01); they never reach the line.
    #[arg(long)]
    pub read_only: bool,
    /// Only these function codes pass (repeatable; 3 or 0x03).
    #[arg(long = "allow-function", value_name = "CODE")]
    pub allow_functions: Vec<String>,
    /// Only these clients may connect (repeatable; 10.0.0.5 or 10.0.0.0/24).
    #[arg(long = "allow-ip", value_name = "NET")]
    pub allow_ips: Vec<String>,
    /// Connections open at once; more are refused.
    #[arg(long, default_value_t = 64)]
    pub max_connections: usize,
    /// Close a connection silent this long, s.
    #[arg(long, default_value_t = 300.0)]
    pub idle_timeout: f64,
    /// Requests per second per connection; above it exception 0x06 (busy).
    #[arg(long)]
    pub rate_limit: Option<f64>,
    /// Requests a client may have waiting; more get exception 0x06.
    #[arg(long, default_value_t = 32)]
    pub queue_per_client: usize,
    /// TCP unit id → serial address (repeatable): --map-unit 10=1.
    #[arg(long = "map-unit", value_name = "TCP=SERIAL")]
    pub unit_map: Vec<String>,
    /// Serve Prometheus metrics on this address (GET /metrics).
    #[arg(long, value_name = "ADDR:PORT")]
    pub metrics: Option<String>,
    /// Reverse: answer as serial slaves (--answer-as) and forward to the Modbus TCP server
    /// --target, so an RTU master reaches TCP devices.
    #[arg(long, requires = "target")]
    pub reverse: bool,
    /// Reverse mode: the Modbus TCP server to forward to.
    #[arg(long, value_name = "HOST:PORT")]
    pub target: Option<String>,
    /// Reverse mode: serial addresses to answer as, e.g. 1,5,10-20 (default: all).
    #[arg(long, value_name = "UNITS")]
    pub answer_as: Option<String>,
    /// Show the bridged traffic: text, jsonl or tui.
    #[arg(long, value_enum)]
    pub monitor: Option<EventFormatArg>,
    /// Annotate unit UNIT's values in the monitor: `UNIT=NAME` or `UNIT=FILE.toml`.
    #[arg(long = "device", value_name = "UNIT=PROFILE")]
    pub devices: Vec<String>,
    /// Stop after this many seconds.
    #[arg(long)]
    pub duration: Option<f64>,
}

/// Output of `report`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ReportFormatArg {
    Text,
    /// One JSON document with a top-level `findings` list.
    Json,
    /// A self-contained HTML page with plots (latency, errors over time, availability).
    Html,
}

/// A fault to inject on the simulated line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FaultArg {
    /// A flipped bit in a response: bad CRC.
    Corrupt,
    /// A burst of random bytes on the idle line.
    Noise,
    /// A slave pausing in the middle of its answer (gap inside a frame).
    SlowSlave,
    /// A slave that does not answer (the master times out).
    SilentSlave,
    /// A second device on the first unit's address answering with it.
    Collision,
    /// A master polling again before t3.5 of silence.
    FastMaster,
    /// A second master sending its own request while the first one's answer is due.
    SecondMaster,
    /// The MK4's running pump trips on overcurrent; its alarm log records it.
    PumpTrip,
    /// All of the above, taking turns.
    All,
}

/// `mbtap profiles …`
#[derive(Debug, Subcommand)]
pub enum ProfilesCommand {
    /// List the built-in profiles.
    List,
    /// Load a profile file and report the first problem with file:line:column, or a summary.
    Check { file: PathBuf },
    /// Print every address a profile (a built-in name or a file) defines, per table.
    Show { profile: String },
}
