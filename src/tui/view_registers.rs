//! The registers view: one unit's register image — address, name, scaled value, when it last
//! changed, and a sparkline of its recent values.

use ratatui::Frame;
use ratatui::layout::{Constraint, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::widgets::{Block, Cell, Paragraph, Row, Table};

use super::app::App;
use super::model::Model;
use super::registers::sparkline;
use super::style::clock;
use mbtap_device::profile::Table as RegTable;

pub fn draw(frame: &mut Frame<'_>, area: Rect, app: &mut App, model: &Model) {
    let Some(unit) = app.register_unit(model) else {
        let text = "no register values seen yet (they come from answered reads and writes)";
        frame.render_widget(Paragraph::new(text).block(Block::bordered().title(" registers ")), area);
        return;
    };
    let height = usize::from(area.height.saturating_sub(3)).max(1);
    let count = model.registers.of(unit).count();
    app.register_offset = app.register_offset.min(count.saturating_sub(height));
    let rows: Vec<Row<'_>> = model
        .registers
        .of(unit)
        .skip(app.register_offset)
        .take(height)
        .map(|(table, address, r)| {
            let kind = match table {
                RegTable::Coils => "C",
                RegTable::DiscreteInputs => "DI",
                RegTable::HoldingRegisters => "HR",
                RegTable::InputRegisters => "IR",
            };
            let spark = if r.numeric { sparkline(&r.history, 16) } else { String::new() };
            Row::new(vec![
                Cell::from(kind),
                Cell::from(address.to_string()),
                Cell::from(r.name.clone().unwrap_or_default()),
                Cell::from(r.text.clone()),
                Cell::from(clock(r.changed_ns)),
                Cell::from(spark),
            ])
        })
        .collect();
    let header = Row::new(["", "addr", "name", "value", "changed", "history"])
        .style(Style::new().fg(Color::Cyan).add_modifier(Modifier::BOLD));
    let widths = [
        Constraint::Length(2),
        Constraint::Length(5),
        Constraint::Fill(3),
        Constraint::Fill(2),
        Constraint::Length(12),
        Constraint::Length(16),
    ];
    let device = model.device_name(unit).map(|d| format!(" {d}")).unwrap_or_default();
    let title = format!(" registers of unit {unit}{device} ({count}; ← → other units) ");
    frame.render_widget(Table::new(rows, widths).header(header).block(Block::bordered().title(title)), area);
}
