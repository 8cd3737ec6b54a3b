//! `mbtap watch`: the same reads as `read`, again every interval — a live table on a terminal,
//! JSON lines (each with the time of its cycle) in a pipe.

use std::io::{IsTerminal as _, Write as _};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Context as _;

use crate::master::{MasterArgs, MasterFormat, exec, link::Link, show};

/// Broker writes carried out between two rounds of reads (`--mqtt-writes`): polling goes on
/// under a flood of sets.
const WRITES_PER_ROUND: usize = 4;

/// Read values again and again: a live table on a terminal, JSON lines in a pipe.
///
/// Example: `mbtap watch /dev/ttyUSB0 --device mk4 --interval 1s 430..433 "Operating mode"`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub master: MasterArgs,
    /// What to read, as for `mbtap read`.
    #[arg(required = true, value_name = "ITEM")]
    pub items: Vec<String>,
    /// Time from the start of one round of reads to the next: `1s`, `250ms`, `2` (seconds).
    /// A round that takes longer starts the next at once.
    #[arg(long, default_value = "1s", value_parser = parse_interval)]
    pub interval: Duration,
    /// Stop after this many rounds [default: until Ctrl-C].
    #[arg(long)]
    pub count: Option<u64>,
    #[command(flatten)]
    pub mqtt: crate::publish::mqtt::MqttArgs,
}

/// Between 1 ms and a day.
fn parse_interval(s: &str) -> Result<Duration, String> {
    mbtap_analysis::duration::parse_duration(s, Duration::from_millis(1), Duration::from_hours(24))
}

pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let m = &args.master;
    let profile = m.profile()?;
    let unit = m.unit(profile.as_ref());
    let (targets, plan) = super::read::prepare(&args.items, profile.as_ref())?;
    let timeout = Duration::from_millis(m.timeout_ms);
    let mut link = Link::new(&m.target, &m.line, timeout, m.retries)?;
    let format = m.format();
    let live = format == MasterFormat::Text && std::io::stdout().is_terminal();
    let profiles: mbtap_device::profile::Profiles = profile.iter().map(|p| (unit, p.clone())).collect();
    // No health figures: watch hears only its own answers, not the bus.
    // Writes the broker asks for (`--mqtt-writes`) arrive here and are done between rounds.
    let (asks_tx, asks) = std::sync::mpsc::sync_channel(crate::publish::outbox::COMMANDS_WAITING);
    let mqtt = crate::publish::mqtt::Mqtt::start_with(&args.mqtt, &m.target, profiles, false, Some(asks_tx))?;
    let rt = crate::cmd::runtime()?;
    let mut any_failed = false;
    rt.block_on(async {
        let stop = crate::io::signals::shutdown_signal();
        tokio::pin!(stop);
        let mut round = 0u64;
        let mut next = tokio::time::Instant::now();
        while args.count.is_none_or(|c| round < c) {
            round += 1;
            if let Some(mq) = &mqtt {
                // At most WRITES_PER_ROUND writes between two rounds, so polling goes on under a
                // flood of sets; a stop asked for is honoured between two writes.
                let mut stopped = false;
                for ask in asks.try_iter().take(WRITES_PER_ROUND) {
                    // The stop signal looked at without waiting (polled first, then given up).
                    tokio::select! {
                        biased;
                        () = &mut stop => stopped = true,
                        () = std::future::ready(()) => {}
                    }
                    if stopped {
                        break;
                    }
                    let outcome = crate::master::remote::apply(&mut link, unit, &ask, profile.as_ref()).await;
                    mq.write_result(&ask, &outcome, crate::io::serial::now().0);
                }
                if stopped {
                    break;
                }
            }
            let started = Instant::now();
            let t_ns = crate::io::serial::now().0;
            let (rows, failures) = exec::read_all(&mut link, unit, &targets, &plan, profile.as_ref()).await;
            any_failed |= !failures.is_empty();
            if let Some(mq) = &mqtt {
                mq.rows(rows.clone(), t_ns);
            }
            let took = started.elapsed();
            let mut out = std::io::stdout().lock();
            if live {
                // Redraw in place: home, clear, then the table.
                write!(out, "\x1b[H\x1b[2J")?;
                writeln!(
                    out,
                    "mbtap watch {} unit {unit} — round {round}, {:.1} ms, every {:?} (Ctrl-C stops)\n",
                    link.describe(),
                    took.as_secs_f64() * 1e3,
                    args.interval
                )?;
            } else if format == MasterFormat::Text {
                writeln!(out, "# round {round}, {:.1} ms", took.as_secs_f64() * 1e3)?;
            }
            let round_ms = (took.as_secs_f64() * 1e6).round() / 1e3;
            let extra = [("t_ns", t_ns.into()), ("round", round.into()), ("round_ms", round_ms.into())];
            show::print(format, &rows, &failures, &extra, &mut out)?;
            drop(out);
            next += args.interval;
            let now = tokio::time::Instant::now();
            if next < now {
                next = now;
            }
            tokio::select! {
                () = &mut stop => break,
                () = tokio::time::sleep_until(next) => {}
            }
        }
        anyhow::Ok(())
    })
    .context("writing the values")?;
    if let Some(mq) = &mqtt {
        mq.finish();
    }
    Ok(if any_failed { ExitCode::FAILURE } else { ExitCode::SUCCESS })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intervals_in_the_units_people_write() {
        assert_eq!(parse_interval("1s"), Ok(Duration::from_secs(1)));
        assert_eq!(parse_interval("250ms"), Ok(Duration::from_millis(250)));
        assert_eq!(parse_interval("1.5"), Ok(Duration::from_millis(1500)));
        assert!(parse_interval("0").is_err());
        assert!(parse_interval("soon").is_err());
    }
}
