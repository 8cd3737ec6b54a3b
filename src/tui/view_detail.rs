//! The detail view: one transaction decoded — its frames field by field with the selected
//! field's bytes highlighted in the hex, and the full decode (fields, profile annotations,
//! findings) as `mbtap decode` gives it.

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph, Wrap};

use super::app::{App, Side};
use super::layout::{Field, binary, fields};
use super::model::{Model, Row};
use super::style::{clock, duration, status_style};
use mbtap_proto::FunctionCode;

pub fn draw(frame: &mut Frame<'_>, area: Rect, app: &mut App, model: &Model) {
    let Some(row) = app.selected.and_then(|s| model.row(s)) else {
        frame.render_widget(Paragraph::new("nothing selected").block(Block::bordered()), area);
        return;
    };
    let (side, wire) = match (app.side, row.request.as_deref(), row.response.as_deref()) {
        (Side::Request, Some(r), _) | (Side::Response, Some(r), None) => (Side::Request, r),
        (_, _, Some(r)) => (Side::Response, r),
        (_, None, None) => (app.side, &[][..]),
    };
    let ascii = wire.first() == Some(&b':');
    let bytes = binary(wire);
    // The request's address numbers the response's registers.
    let first = row.request.as_deref().map(binary).and_then(|r| Some(u16::from_be_bytes([*r.get(2)?, *r.get(3)?])));
    let layout = if row.function.is_some() { fields(&bytes, side == Side::Request, ascii, first) } else { Vec::new() };
    app.field = app.field.min(layout.len().saturating_sub(1));
    let hex_lines = u16::try_from(bytes.len().div_ceil(16)).unwrap_or(16).clamp(1, 8);
    let [head, middle, hex] =
        Layout::vertical([Constraint::Length(2), Constraint::Min(3), Constraint::Length(hex_lines + 2)]).areas(area);
    frame.render_widget(Paragraph::new(header(row, model)), head);
    let [left, right] = Layout::horizontal([Constraint::Length(34), Constraint::Min(20)]).areas(middle);
    let which = if side == Side::Request { "request" } else { "response" };
    let field_lines: Vec<Line<'_>> = layout
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let style = if i == app.field { Style::new().add_modifier(Modifier::REVERSED) } else { Style::new() };
            Line::styled(format!("{:<15} {}", f.label, f.value), style)
        })
        .collect();
    frame.render_widget(
        Paragraph::new(field_lines).block(Block::bordered().title(format!(" {which} fields (r: other) "))),
        left,
    );
    frame.render_widget(
        Paragraph::new(decoded(row, model))
            .wrap(Wrap { trim: false })
            .scroll((app.detail_scroll, 0))
            .block(Block::bordered().title(" decoded (PgUp PgDn) ")),
        right,
    );
    let highlight = layout.get(app.field);
    let title = if ascii { format!(" {which} bytes (decoded from ASCII) ") } else { format!(" {which} bytes ") };
    frame.render_widget(Paragraph::new(hex_text(&bytes, highlight)).block(Block::bordered().title(title)), hex);
}

fn header(row: &Row, model: &Model) -> Vec<Line<'static>> {
    let device = row.unit.map_or_else(String::new, |u| match model.device_name(u) {
        Some(d) => format!("unit {u} ({d})"),
        None => format!("unit {u}"),
    });
    let function = row.function.map_or_else(String::new, |f| FunctionCode::from(f & 0x7F).to_string());
    let latency = row.latency_ns.map(|l| format!(" · latency {}", duration(l))).unwrap_or_default();
    vec![
        Line::from(vec![
            Span::raw(format!("{} · {device} · {function} · ", clock(row.t_ns))),
            Span::styled(row.status().replace('_', " "), status_style(row).add_modifier(Modifier::BOLD)),
            Span::raw(latency),
        ]),
        Line::styled(row.summary.clone(), Style::new().fg(Color::Gray)),
    ]
}

/// The transaction as `mbtap decode` shows it, with the unit's profile.
fn decoded(row: &Row, model: &Model) -> Vec<Line<'static>> {
    let text = |wire: &[u8]| {
        if wire.first() == Some(&b':') {
            String::from_utf8_lossy(wire).trim_end().to_owned()
        } else {
            mbtap_analysis::report::format::hex_spaced(wire)
        }
    };
    let lines: Vec<String> =
        [row.request.as_deref(), row.response.as_deref()].into_iter().flatten().map(text).collect();
    if row.function.is_none() {
        return vec![Line::raw("bytes that belong to no frame: noise, a frame cut short, or a wrong line setting")];
    }
    let mut out = Vec::new();
    let mut err = Vec::new();
    let _ = mbtap_analysis::decode::run_with_profiles(
        &lines,
        None,
        mbtap_analysis::decode::Format::Text,
        &model.profiles,
        model.lang,
        &mut out,
        &mut err,
    );
    String::from_utf8_lossy(&out)
        .lines()
        .chain(String::from_utf8_lossy(&err).lines())
        .map(|l| Line::raw(mbtap_analysis::report::format::printable(l).into_owned()))
        .collect()
}

/// The bytes, 16 a line, the highlighted field's reversed.
fn hex_text(bytes: &[u8], highlight: Option<&Field>) -> Vec<Line<'static>> {
    bytes
        .chunks(16)
        .enumerate()
        .map(|(line, chunk)| {
            let spans: Vec<Span<'static>> = chunk
                .iter()
                .enumerate()
                .map(|(j, b)| {
                    let i = line * 16 + j;
                    let on = highlight.is_some_and(|f| f.range.contains(&i));
                    let style = if on { Style::new().fg(Color::Black).bg(Color::Yellow) } else { Style::new() };
                    Span::styled(format!("{b:02X} "), style)
                })
                .collect();
            let mut all = vec![Span::styled(format!("{:04X}  ", line * 16), Style::new().fg(Color::DarkGray))];
            all.extend(spans);
            Line::from(all)
        })
        .collect()
}
