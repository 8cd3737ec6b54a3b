//! `learn --confirm TARGET`: the blocks whose registers one or two samples decided
//! ([`mbtap_analysis::learn::confirm::plan`]) read again from the device through the master's
//! link — reads only (03/04), of blocks the master on the line read itself, paced at `--rate`,
//! for at most `--confirm-for` — and fed to the learner as more samples. A device that does not
//! answer, is busy (06) or refuses (an exception) ends it, said: nothing is retried into it.

use std::time::{Duration, Instant};

use mbtap_analysis::learn::Learner;
use mbtap_analysis::learn::confirm::{Ask, READS_EACH, plan, registers, settled, undecided};

use super::link::Link;

/// What `--confirm` was given.
#[derive(Debug, Clone)]
pub struct ConfirmOptions {
    pub target: String,
    pub line: crate::cli::args::SerialLineArgs,
    /// Requests per second, at most.
    pub rate: f64,
    /// How long it may ask, at most.
    pub limit: Duration,
    pub timeout: Duration,
}

/// Asks, feeds the answers to `learner`, and returns what to say: what was asked, what it
/// settled, and why it ended.
///
/// # Errors
/// The target cannot be reached at all (a link that cannot be made).
pub async fn confirm(learner: &mut Learner, opts: &ConfirmOptions) -> anyhow::Result<String> {
    use std::fmt::Write as _;
    let mut said = String::new();
    let mut link = Link::new(&opts.target, &opts.line, opts.timeout, 0)?;
    let gap = Duration::from_secs_f64(1.0 / opts.rate);
    let started = Instant::now();
    // The capture's time goes on after its last poll: the new samples follow it.
    let t0 = learner
        .units
        .values()
        .flat_map(|u| u.blocks.values().map(|b| b.last_t_ns))
        .max()
        .unwrap_or(0)
        .saturating_add(1_000_000_000);
    let units: Vec<u8> = learner.units.keys().copied().collect();
    let mut last_sent: Option<Instant> = None;
    for unit in units {
        let Some(u) = learner.units.get(&unit) else { continue };
        let asks = plan(u);
        let before = undecided(u);
        if asks.is_empty() {
            let _ = writeln!(said, "unit {unit}: nothing to confirm (every register decided by a series)");
            continue;
        }
        let (mut sent, mut answered) = (0u64, 0u64);
        let mut ended = None;
        'rounds: for _ in 0..READS_EACH {
            for ask in &asks {
                if started.elapsed() >= opts.limit {
                    ended = Some(format!("--confirm-for {:?} reached", opts.limit));
                    break 'rounds;
                }
                // Paced from the end of the last exchange: however late a request reaches the
                // wire, the next one follows it by at least the rate's interval.
                if let Some(t) = last_sent {
                    tokio::time::sleep(gap.saturating_sub(t.elapsed())).await;
                }
                sent += 1;
                let asked = link.ask(unit, ask.pdu()).await;
                last_sent = Some(Instant::now());
                match asked {
                    Ok(answer) if answer.first().is_some_and(|f| f & 0x80 == 0) && !answer.is_empty() => {
                        answered += 1;
                        let t = t0.saturating_add(u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX));
                        learner.observe(unit, &ask.pdu(), &answer, t);
                    }
                    Ok(answer) => {
                        ended = Some(refusal(*ask, &answer));
                        break 'rounds;
                    }
                    Err(why) => {
                        ended = Some(format!("{why}: asked nothing more"));
                        break 'rounds;
                    }
                }
            }
        }
        let (changed, still) = settled(&before, learner, unit);
        let _ = writeln!(
            said,
            "unit {unit}: asked {sent} reads of {} block(s) ({}) in {:.1} s at up to {} requests/s, {answered} answered; \
             of {} registers decided by few samples, {} still are (confidence at most {}){}",
            asks.len(),
            asks.iter().copied().map(describe).collect::<Vec<_>>().join(", "),
            started.elapsed().as_secs_f64(),
            opts.rate,
            registers(&before),
            still,
            mbtap_analysis::learn::few_samples::FEW,
            ended.map(|e| format!("; ended: {e}")).unwrap_or_default()
        );
        for line in changed {
            let _ = writeln!(said, "  {line}");
        }
    }
    Ok(said)
}

fn describe(a: Ask) -> String {
    format!("{} {}..{}", a.table.name(), a.first, u32::from(a.first) + u32::from(a.quantity) - 1)
}

/// Why an answer that is no read's ends the asking: the device's exception (06 busy: it has
/// other work; anything else: it refuses what its own master reads), or silence.
fn refusal(ask: Ask, answer: &[u8]) -> String {
    match answer {
        [f, 0x06, ..] if f & 0x80 != 0 => {
            format!("{}: the device is busy (exception 06); asked nothing more", describe(ask))
        }
        [f, code, ..] if f & 0x80 != 0 => {
            format!("{}: the device refused with exception {code:02X}; asked nothing more", describe(ask))
        }
        _ => format!("{}: no answer (a broadcast or a silent device); asked nothing more", describe(ask)),
    }
}
