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
