//! Draws the UI: a title line with the views and the source's state, the current view, a
//! status line (filter, search being typed, messages, key hints), and the help overlay.

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Clear, Paragraph};

use super::app::{App, View};
use super::model::Model;

/// Every key, for the help overlay (and the README).
pub const KEYS: &[(&str, &str)] = &[
    ("1 2 3, Tab", "traffic, devices, registers view"),
    ("↑ ↓ j k", "move (traffic: row; detail: field)"),
    ("PgUp PgDn", "move a page (detail: scroll the decode)"),
    ("g Home / G End", "first / newest row (G follows new rows)"),
    ("Enter", "detail of the selected transaction"),
    ("r", "detail: request / response hex"),
    ("Esc", "back; clear the filter"),
    ("u", "filter: next unit"),
    ("f", "filter: next function"),
    ("e", "filter: errors only"),
    ("/", "search text (Enter applies, Esc cancels)"),
    ("c", "clear the filter"),
    ("space", "pause / resume (live: freeze the view)"),
    ("s", "replay speed: paused, 1×, 10×, max"),
    ("← →", "registers: other unit"),
    ("x / w", "export the filtered rows: JSON lines / pcapng"),
    ("?", "this help"),
    ("q, Ctrl-C", "quit"),
];

/// Draws everything; `source` names what is shown (`demo`, a port, a file).
pub fn draw(frame: &mut Frame<'_>, app: &mut App, model: &Model, source: &str) {
    app.refresh(model);
    app.draws += 1;
    let stale = app.findings_rows != Some(model.total_rows());
    if app.view == View::Devices && stale && (app.findings_rows.is_none() || app.draws.is_multiple_of(20)) {
        app.findings = model.health.report().findings;
        app.findings_rows = Some(model.total_rows());
    }
    let [title, body, status] =
        Layout::vertical([Constraint::Length(1), Constraint::Min(3), Constraint::Length(1)]).areas(frame.area());
    app.page = usize::from(body.height.saturating_sub(2)).max(1);
    title_line(frame, title, app, model, source);
    match app.view {
        View::Traffic => super::view_traffic::draw(frame, body, app, model),
        View::Detail => super::view_detail::draw(frame, body, app, model),
        View::Devices => super::view_devices::draw(frame, body, app, model),
        View::Registers => super::view_registers::draw(frame, body, app, model),
    }
    status_line(frame, status, app, model);
    if app.help {
        help(frame, body);
    }
}

fn title_line(frame: &mut Frame<'_>, area: Rect, app: &App, model: &Model, source: &str) {
    let tab = |n: &str, name: &str, on: bool| {
        let style = if on {
            Style::new().fg(Color::Black).bg(Color::Cyan).add_modifier(Modifier::BOLD)
        } else {
            Style::new().fg(Color::Cyan)
        };
        Span::styled(format!(" {n} {name} "), style)
    };
    let state = if let Some(done) = &model.finished {
        done.clone()
    } else if app.pacing {
        app.speed.label()
    } else if app.frozen_at.is_some() {
        "frozen".to_owned()
    } else {
        "live".to_owned()
    };
    let line = Line::from(vec![
        Span::styled("mbtap ", Style::new().add_modifier(Modifier::BOLD)),
        tab("1", "Traffic", matches!(app.view, View::Traffic | View::Detail)),
        tab("2", "Devices", app.view == View::Devices),
        tab("3", "Registers", app.view == View::Registers),
        Span::raw(format!(" {source} · {state} · {} rows", model.total_rows())),
    ]);
    frame.render_widget(Paragraph::new(line), area);
}

fn status_line(frame: &mut Frame<'_>, area: Rect, app: &App, model: &Model) {
    let line = if let Some(text) = &app.input {
        Line::from(vec![Span::styled("search: ", Style::new().fg(Color::Yellow)), Span::raw(format!("{text}▏"))])
    } else {
        let mut spans = Vec::new();
        if !app.filter.is_empty() {
            spans.push(Span::styled(format!("filter: {} ", app.filter.describe()), Style::new().fg(Color::Yellow)));
            spans.push(Span::raw(format!("({} shown) ", app.visible().len())));
        }
        if model.dropped > 0 {
            spans.push(Span::raw(format!("{} oldest dropped (scroll-back {}) ", model.dropped, model.capacity)));
        }
        if let Some(n) = &model.notice {
            spans.push(Span::styled(format!("{n} "), Style::new().fg(Color::Magenta)));
        }
        if let Some(m) = &app.message {
            spans.push(Span::styled(format!("{m} "), Style::new().fg(Color::Green)));
        }
        spans.push(Span::styled("? help  q quit", Style::new().fg(Color::DarkGray)));
        Line::from(spans)
    };
    frame.render_widget(Paragraph::new(line), area);
}

fn help(frame: &mut Frame<'_>, area: Rect) {
    let height = u16::try_from(KEYS.len()).unwrap_or(u16::MAX).saturating_add(2).min(area.height);
    let width = 66.min(area.width);
    let x = area.x + (area.width - width) / 2;
    let y = area.y + (area.height - height) / 2;
    let popup = Rect { x, y, width, height };
    let lines: Vec<Line<'_>> = KEYS
        .iter()
        .map(|(k, what)| {
            Line::from(vec![Span::styled(format!("{k:>15}  "), Style::new().fg(Color::Cyan)), Span::raw(*what)])
        })
        .collect();
    frame.render_widget(Clear, popup);
    frame.render_widget(Paragraph::new(lines).block(Block::bordered().title(" keys (any key closes) ")), popup);
}

pub use mbtap_core::report::format::clock_ms as clock;

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
        _ => mbtap_core::proto::FunctionCode::from(base).label(),
    };
    format!("{fc:02X} {name}")
}

/// The style of a row's status.
#[must_use]
pub fn status_style(row: &super::model::Row) -> Style {
    use super::model::RowKind;
    use mbtap_core::pairing::Outcome;
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
