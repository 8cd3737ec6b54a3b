//! How the views write and colour the figures they share (times, durations, function names,
//! a row's status): a leaf every view and the frame's renderer take from, so the views and the
//! renderer that calls them never import each other.

use ratatui::style::{Color, Style};

pub use mbtap_analysis::report::format::clock_ms as clock;

/// A duration for a narrow column: `850µs`, `12.3ms`, `1.25s`, `3m05s`.
#[must_use]
pub fn duration(ns: u64) -> String {
    match ns {
        0..1_000_000 => format!("{}µs", ns / 1000),
        1_000_000..100_000_000 => format!("{}.{}ms", ns / 1_000_000, ns / 100_000 % 10),
        100_000_000..1_000_000_000 => format!("{}ms", ns / 1_000_000),
        1_000_000_000..60_000_000_000 => format!("{}.{:02}s", ns / 1_000_000_000, ns / 10_000_000 % 100),
        _ => format!("{}m{:02}s", ns / 60_000_000_000, ns / 1_000_000_000 % 60),
    }
}

/// A function's name short enough for a table column.
#[must_use]
pub fn short_function(fc: u8) -> String {
    let base = fc & 0x7F;
    let name = match base {
        0x01 => "Read Coils",
        0x02 => "Read Inputs",
        0x03 => "Read Holding",
        0x04 => "Read Input",
        0x05 => "Write Coil",
        0x06 => "Write Reg",
        0x07 => "Exc Status",
        0x08 => "Diagnostics",
        0x0F => "Write Coils",
        0x10 => "Write Regs",
        0x11 => "Server Id",
        0x16 => "Mask Write",
        0x17 => "R/W Regs",
        0x2B => "Encapsulated",
        _ => mbtap_proto::FunctionCode::from(base).label(),
    };
    format!("{fc:02X} {name}")
}

/// The style of a row's status.
#[must_use]
pub fn status_style(row: &super::model::Row) -> Style {
    use super::model::RowKind;
    use mbtap_analysis::pairing::Outcome;
    match row.kind {
        RowKind::Transaction(Outcome::Ok | Outcome::Broadcast) if row.is_error() => Style::new().fg(Color::Yellow),
        RowKind::Transaction(Outcome::Ok | Outcome::Broadcast) => Style::new(),
        RowKind::Transaction(Outcome::Exception(_)) => Style::new().fg(Color::Yellow),
        RowKind::Transaction(Outcome::NoResponse) => Style::new().fg(Color::Red),
        RowKind::Transaction(Outcome::BadResponse) | RowKind::Noise => Style::new().fg(Color::Magenta),
        RowKind::Transaction(Outcome::Orphan | Outcome::WrongUnit(_)) => Style::new().fg(Color::Cyan),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_fit_a_narrow_column() {
        assert_eq!(duration(850_000), "850µs");
        assert_eq!(duration(12_345_678), "12.3ms");
        assert_eq!(duration(250_000_000), "250ms");
        assert_eq!(duration(1_250_000_000), "1.25s");
        assert_eq!(duration(185_000_000_000), "3m05s");
        assert_eq!(clock(3_723_004_000_000), "01:02:03.004");
    }
}
