//! The traffic view: a row per transaction or noise burst — time, Δt, unit and device,
//! function, status, latency and the annotated values — coloured by status.

use ratatui::Frame;
use ratatui::layout::{Constraint, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::widgets::{Block, Cell, Row, Table};

use super::app::App;
use super::model::{Model, RowKind};
use super::style::{clock, duration, short_function, status_style};

pub fn draw(frame: &mut Frame<'_>, area: Rect, app: &mut App, model: &Model) {
    let height = usize::from(area.height.saturating_sub(3)).max(1);
    // Below 100 columns the values need the room more than Δt does.
    let wide = area.width >= 100;
    let selected = app.selected_index();
    let total = app.visible().len();
    if let Some(i) = selected {
        if i < app.traffic_offset {
            app.traffic_offset = i;
        } else if i >= app.traffic_offset + height {
            app.traffic_offset = i + 1 - height;
        }
    }
    app.traffic_offset = app.traffic_offset.min(total.saturating_sub(height));
    // The status column as wide as the longest status shown (`ok gap <t3.5` whole, not cut to
    // `<t3.`), between 6 and 20 columns.
    let mut status_width = 6u16;
    let rows: Vec<Row<'_>> = app
        .visible()
        .iter()
        .enumerate()
        .skip(app.traffic_offset)
        .take(height)
        .filter_map(|(i, &seq)| model.row(seq).map(|r| (i, r)))
        .map(|(i, r)| {
            let device = r.unit.map_or_else(String::new, |u| {
                model.device_name(u).map_or_else(|| format!("{u:>3}"), |d| format!("{u:>3} {d}"))
            });
            let function = r.function.map_or_else(String::new, short_function);
            let mut status = r.label();
            if r.timing.gap_inside {
                status.push_str(" gap");
            }
            if r.timing.short_gap {
                status.push_str(" <t3.5");
            }
            if r.timing.two_lengths {
                status.push_str(" len?");
            }
            status_width = status_width.max(u16::try_from(status.chars().count()).unwrap_or(20).min(20));
            let style =
                if Some(i) == selected { status_style(r).add_modifier(Modifier::REVERSED) } else { status_style(r) };
            let mut cells = vec![Cell::from(clock(r.t_ns))];
            if wide {
                cells.push(Cell::from(r.delta_ns.map(duration).unwrap_or_default()));
            }
            cells.extend([
                Cell::from(device),
                Cell::from(function),
                Cell::from(status),
                Cell::from(r.latency_ns.map(duration).unwrap_or_default()),
                Cell::from(if r.kind == RowKind::Noise {
                    hex_preview(r.response.as_deref())
                } else {
                    r.summary.clone()
                }),
            ]);
            Row::new(cells).style(style)
        })
        .collect();
    let names: &[&str] = if wide {
        &["time", "Δt", "unit", "function", "status", "latency", "values"]
    } else {
        &["time", "unit", "function", "status", "latency", "values"]
    };
    let header = Row::new(names.to_vec()).style(Style::new().fg(Color::Cyan).add_modifier(Modifier::BOLD));
    let mut widths = vec![Constraint::Length(12)];
    if wide {
        widths.push(Constraint::Length(6));
    }
    widths.extend([
        Constraint::Length(11),
        Constraint::Length(15),
        Constraint::Length(status_width),
        Constraint::Length(7),
        Constraint::Min(10),
    ]);
    let title = if app.follow { " traffic (following) " } else { " traffic " };
    let table = Table::new(rows, widths).header(header).block(Block::bordered().title(title)).column_spacing(1);
    frame.render_widget(table, area);
}

/// Noise in hex, a few bytes of it.
fn hex_preview(bytes: Option<&[u8]>) -> String {
    let bytes = bytes.unwrap_or_default();
    let mut s = mbtap_analysis::report::format::hex_spaced(bytes.get(..24).unwrap_or(bytes));
    if bytes.len() > 24 {
        s.push_str(" …");
    }
    s
}
