//! The devices view: per unit — requests, answers, exceptions by code, check errors, timeouts,
//! latency p50 / p99 / max, polling period, last seen — and the bus load and error rate.

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::widgets::{Block, Cell, Paragraph, Row, Table};

use super::app::App;
use super::model::Model;
use super::style::{clock, duration};

pub fn draw(frame: &mut Frame<'_>, area: Rect, app: &App, model: &Model) {
    // The table takes what its units need (a header, borders, a row each), the findings the
    // rest, wrapped (six of ten findings, cut at the right, under a mostly empty
    // devices pane).
    let units = u16::try_from(model.devices.len().saturating_sub(app.device_offset)).unwrap_or(u16::MAX);
    let [bus, table, findings] =
        Layout::vertical([Constraint::Length(1), Constraint::Max(units.max(1).saturating_add(3)), Constraint::Min(3)])
            .areas(area);
    let lines: Vec<ratatui::text::Line<'_>> = if app.findings.is_empty() {
        vec![ratatui::text::Line::styled("none — the bus looks healthy", Style::new().fg(Color::Green))]
    } else {
        app.findings
            .iter()
            .map(|f| {
                let who = f.unit.map_or_else(|| "bus".to_owned(), |u| format!("unit {u}"));
                ratatui::text::Line::from(vec![
                    ratatui::text::Span::styled(format!("{} ", f.kind), Style::new().fg(Color::Red)),
                    ratatui::text::Span::raw(format!("{who} ×{}: {}", f.count, f.summary)),
                ])
            })
            .collect()
    };
    let title = format!(" findings ({}; mbtap report for the evidence) ", app.findings.len());
    frame.render_widget(
        Paragraph::new(lines).wrap(ratatui::widgets::Wrap { trim: true }).block(Block::bordered().title(title)),
        findings,
    );
    let b = &model.bus;
    let pct = |v: Option<f64>| v.map_or_else(|| "–".to_owned(), |v| format!("{v:.1} %"));
    let line = format!(
        " bus {}: load {} · errors {} of {} transactions ({}) · {} frames, {} failed checks, {} noise bursts",
        model.line,
        pct(b.load_percent()),
        b.errors,
        b.transactions,
        pct(b.error_percent()),
        b.frames,
        b.bad_frames,
        b.noise_events
    );
    frame.render_widget(Paragraph::new(line), bus);
    let rows: Vec<Row<'_>> = model
        .devices
        .iter()
        .skip(app.device_offset)
        .map(|(unit, d)| {
            let exceptions = if d.exceptions.is_empty() {
                "0".to_owned()
            } else {
                d.exceptions.iter().map(|(c, n)| format!("{c:02X}×{n}")).collect::<Vec<_>>().join(" ")
            };
            let ms = |v: Option<u64>| v.map_or_else(|| "–".to_owned(), duration);
            let style = if d.timeouts > 0 && d.ok == 0 {
                Style::new().fg(Color::Red)
            } else if d.timeouts + d.bad_responses + d.exceptions_total() > 0 {
                Style::new().fg(Color::Yellow)
            } else {
                Style::new()
            };
            Row::new(vec![
                Cell::from(format!("{unit:>3}")),
                Cell::from(model.device_name(*unit).unwrap_or("").to_owned()),
                Cell::from(d.requests.to_string()),
                Cell::from(d.ok.to_string()),
                Cell::from(exceptions),
                Cell::from(d.bad_responses.to_string()),
                Cell::from(d.timeouts.to_string()),
                Cell::from(ms(d.latency_percentile(50))),
                Cell::from(ms(d.latency_percentile(99))),
                Cell::from(ms((d.max_latency_ns > 0).then_some(d.max_latency_ns))),
                Cell::from(ms(d.poll_period_ns)),
                Cell::from(clock(d.last_seen_ns).get(..8).unwrap_or_default().to_owned()),
            ])
            .style(style)
        })
        .collect();
    let header =
        Row::new(["unit", "device", "req", "ok", "exc", "crc", "t/o", "p50", "p99", "max", "period", "last seen"])
            .style(Style::new().fg(Color::Cyan).add_modifier(Modifier::BOLD));
    let widths = [
        Constraint::Length(4),
        Constraint::Length(7),
        Constraint::Length(5),
        Constraint::Length(5),
        Constraint::Length(6),
        Constraint::Length(4),
        Constraint::Length(4),
        Constraint::Length(6),
        Constraint::Length(6),
        Constraint::Length(6),
        Constraint::Length(6),
        Constraint::Min(8),
    ];
    frame.render_widget(
        Table::new(rows, widths).header(header).block(Block::bordered().title(" devices ")).column_spacing(1),
        table,
    );
}
