//! The bridge's options made into what it runs with, one small named step each: the serial
//! port named by `--serial-match`, the `--allow-function` codes, reverse mode's line and front,
//! the cache rules and polls, and the direction control the ports must be able to do.

use anyhow::Context as _;

/// `--serial-match VID:PID[:SERIAL]` as the port name `usb:VID:PID[:SERIAL]`, else `--serial`.
pub(super) fn usb_serial(serial: Option<String>, serial_match: Option<String>) -> anyhow::Result<Option<String>> {
    let Some(m) = serial_match else { return Ok(serial) };
    let spec = format!("usb:{m}");
    anyhow::ensure!(
        crate::io::serial::UsbMatch::parse(&spec).is_some(),
        "--serial-match {m:?}: expected VID:PID or VID:PID:SERIAL in hex, e.g. 0403:6001"
    );
    Ok(Some(spec))
}

/// `--allow-function` codes (None: not given, every function passes admission's other rules).
pub(super) fn allow_function_codes(values: &[String]) -> anyhow::Result<Option<Vec<u8>>> {
    if values.is_empty() {
        return Ok(None);
    }
    let codes = values.iter().map(|f| {
        mbtap_gateway::parse::parse_function_code(f)
            .with_context(|| format!("--allow-function {f:?}: expected a function code, 3 or 0x03"))
    });
    codes.collect::<anyhow::Result<Vec<u8>>>().map(Some)
}

/// Reverse mode is the serial front on `--serial` with the TCP target as its line: the
/// (line, serial front) pair it makes, or the pair given.
pub(super) fn reverse_front(
    reverse: bool,
    serial: Option<String>,
    listen_serial: Option<String>,
    target: Option<String>,
    target_rtu: Option<String>,
) -> anyhow::Result<(Option<String>, Option<String>)> {
    if !reverse {
        return Ok((serial, listen_serial));
    }
    let port = serial.context("--reverse needs --serial PORT: the line to answer on")?;
    let back = match (target, target_rtu) {
        (Some(t), _) => format!("tcp://{t}"),
        (None, Some(t)) => format!("rtu-over-tcp://{t}"),
        (None, None) => anyhow::bail!(
            "--reverse needs --target HOST:PORT (a Modbus TCP server) or --target-rtu HOST:PORT (RTU over TCP)"
        ),
    };
    Ok((Some(back), Some(port)))
}

/// `--cache` rules and `--poll` ranges; what the bridge polls it answers from memory too.
pub(super) fn caches(
    cache: &[String],
    poll: &[String],
) -> anyhow::Result<(Vec<mbtap_gateway::cache::Rule>, Vec<mbtap_gateway::cache::Poll>)> {
    let polls = poll.iter().map(|r| mbtap_gateway::cache::parse_poll(r)).collect::<Result<Vec<_>, _>>()?;
    let mut rules = cache.iter().map(|r| mbtap_gateway::cache::parse_rule(r)).collect::<Result<Vec<_>, _>>()?;
    rules.extend(polls.iter().map(|p| p.rule.clone()));
    Ok((rules, polls))
}

/// Direction control the ports cannot do is refused now, never a silent fallback: `--rs485` on
/// a port reached over the network, or one that refuses the mode.
pub(super) fn check_rs485<'a>(
    rs485: &crate::io::rs485::Rs485Args,
    ports: impl Iterator<Item = &'a str>,
) -> anyhow::Result<()> {
    if rs485.rs485 == crate::io::rs485::Rs485Mode::Off {
        return Ok(());
    }
    for port in ports {
        anyhow::ensure!(
            !crate::io::stream::Transport::of(port).networked(),
            "--rs485 {:?}: {port} is reached over the network, where the serial server drives the line; leave --rs485 out for it",
            rs485.rs485
        );
        rs485.prepare(&crate::io::serial::resolve_port(port).with_context(|| format!("--serial {port}"))?)?;
    }
    Ok(())
}
