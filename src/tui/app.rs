//! The UI's state — which view, which row, the filter, the search being typed — and what each
//! key does to it. Pure: keys in, state and [`Action`]s out; the terminal loop carries the
//! actions out (quit, export, pacing), the views render the state.

use std::collections::VecDeque;

use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};

use super::model::Model;

mod filter;
pub use filter::Filter;

/// The views.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum View {
    Traffic,
    Detail,
    Devices,
    Registers,
}

/// Replay pace: line time per wall-clock time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Speed {
    Paused,
    Times(f64),
    /// As fast as it goes.
    Max,
}

impl Speed {
    /// The next step of the `s` key: paused → 1× → 10× → max → paused.
    #[must_use]
    pub fn next(self) -> Self {
        match self {
            Self::Paused => Self::Times(1.0),
            Self::Times(x) if x < 10.0 => Self::Times(10.0),
            Self::Times(_) => Self::Max,
            Self::Max => Self::Paused,
        }
    }

    #[must_use]
    pub fn label(self) -> String {
        match self {
            Self::Paused => "paused".into(),
            Self::Times(x) => format!("{x}×"),
            Self::Max => "max".into(),
        }
    }
}

/// What the terminal loop must do after a key.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    None,
    Quit,
    /// Write what the filter shows to a file.
    ExportJsonl,
    ExportPcapng,
    /// The pace changed (replay and demo only).
    Speed,
}

/// Which frame of the selected transaction the detail view's hex shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    Request,
    Response,
}

/// The UI state.
#[derive(Debug)]
pub struct App {
    pub view: View,
    /// Selected row (its sequence number).
    pub selected: Option<u64>,
    /// Keep the newest row selected.
    pub follow: bool,
    pub filter: Filter,
    /// A search being typed after `/`.
    pub input: Option<String>,
    pub help: bool,
    /// Live input: the newest row shown while frozen (`space`); rows after it wait.
    pub frozen_at: Option<u64>,
    pub speed: Speed,
    /// Whether the source can be paced (replay, demo) or only frozen (live).
    pub pacing: bool,
    pub side: Side,
    /// Selected field in the detail view's hex.
    pub field: usize,
    /// Lines scrolled in the detail view's decode.
    pub detail_scroll: u16,
    pub register_unit: Option<u8>,
    pub register_offset: usize,
    pub device_offset: usize,
    /// First visible row drawn in the traffic view (kept so the selection moves, not the page).
    pub traffic_offset: usize,
    /// A message for the status line (export done, nothing to export).
    pub message: Option<String>,
    visible: Visible,
    /// Lines a page moves (set by the renderer from the terminal height).
    pub page: usize,
    /// The health findings shown in the devices view, and the row count they were made at
    /// (recomputed at most every 20 draws — about a second — when rows arrived).
    pub findings: Vec<mbtap_analysis::health::Finding>,
    pub findings_rows: Option<u64>,
    pub draws: u64,
}

/// Sequence numbers of the rows that pass the filter, kept up to date incrementally: the
/// filter runs once per new row, not once per row per frame.
#[derive(Debug, Default)]
struct Visible {
    filter: Filter,
    seqs: VecDeque<u64>,
    /// Next row to look at.
    scanned: u64,
}

impl App {
    #[must_use]
    pub fn new(pacing: bool) -> Self {
        Self {
            view: View::Traffic,
            selected: None,
            follow: true,
            filter: Filter::default(),
            input: None,
            help: false,
            frozen_at: None,
            speed: Speed::Times(1.0),
            pacing,
            side: Side::Response,
            field: 0,
            detail_scroll: 0,
            register_unit: None,
            register_offset: 0,
            device_offset: 0,
            traffic_offset: 0,
            message: None,
            visible: Visible::default(),
            page: 10,
            findings: Vec::new(),
            findings_rows: None,
            draws: 0,
        }
    }

    /// Brings the visible list up to date with the model and the filter.
    pub fn refresh(&mut self, model: &Model) {
        if self.visible.filter != self.filter {
            self.visible = Visible { filter: self.filter.clone(), ..Visible::default() };
        }
        let first = model.rows.front().map_or(0, |r| r.seq);
        while self.visible.seqs.front().is_some_and(|&s| s < first) {
            self.visible.seqs.pop_front();
        }
        let limit = self.frozen_at.map_or(u64::MAX, |f| f + 1);
        let start = self.visible.scanned.max(first);
        let skip = usize::try_from(start - first).unwrap_or(usize::MAX);
        for row in model.rows.iter().skip(skip).take_while(|r| r.seq < limit) {
            if self.filter.matches(row, row.unit.and_then(|u| model.device_name(u))) {
                self.visible.seqs.push_back(row.seq);
            }
            self.visible.scanned = row.seq + 1;
        }
        if self.follow || self.selected.is_none_or(|s| s < first) {
            self.selected = self.visible.seqs.back().copied();
        }
    }

    /// The rows that pass the filter, oldest first (sequence numbers).
    #[must_use]
    pub fn visible(&self) -> &VecDeque<u64> {
        &self.visible.seqs
    }

    /// Index of the selected row among the visible ones.
    #[must_use]
    pub fn selected_index(&self) -> Option<usize> {
        let s = self.selected?;
        let v = &self.visible.seqs;
        let i = v.partition_point(|&x| x < s);
        (i < v.len()).then_some(i)
    }

    fn move_selection(&mut self, delta: isize) {
        let n = self.visible.seqs.len();
        if n == 0 {
            return;
        }
        let current = self.selected_index().unwrap_or(n - 1);
        let target = current.saturating_add_signed(delta).min(n - 1);
        self.selected = self.visible.seqs.get(target).copied();
        self.follow = target == n - 1 && delta > 0;
        self.field = 0;
    }

    /// Handles one key; `model` gives the units and functions to cycle through.
    pub fn key(&mut self, key: KeyEvent, model: &Model) -> Action {
        self.message = None;
        if key.modifiers.contains(KeyModifiers::CONTROL) && key.code == KeyCode::Char('c') {
            return Action::Quit;
        }
        if let Some(text) = self.input.as_mut() {
            match key.code {
                KeyCode::Enter => {
                    self.filter.text = self.input.take().unwrap_or_default();
                }
                KeyCode::Esc => self.input = None,
                KeyCode::Backspace => {
                    text.pop();
                }
                KeyCode::Char(c) => text.push(c),
                _ => {}
            }
            return Action::None;
        }
        if self.help {
            // Any key closes the help; q still quits.
            self.help = false;
            return if key.code == KeyCode::Char('q') { Action::Quit } else { Action::None };
        }
        let page = isize::try_from(self.page.max(1)).unwrap_or(10);
        match key.code {
            KeyCode::Char('q') => return Action::Quit,
            KeyCode::Char('?') => self.help = true,
            KeyCode::Char('1') => self.view = View::Traffic,
            KeyCode::Char('2') => self.view = View::Devices,
            KeyCode::Char('3') => self.view = View::Registers,
            KeyCode::Tab => {
                self.view = match self.view {
                    View::Traffic | View::Detail => View::Devices,
                    View::Devices => View::Registers,
                    View::Registers => View::Traffic,
                };
            }
            KeyCode::Enter if self.view == View::Traffic && self.selected.is_some() => {
                self.view = View::Detail;
                self.field = 0;
                self.detail_scroll = 0;
            }
            KeyCode::Esc | KeyCode::Backspace if self.view == View::Detail => self.view = View::Traffic,
            KeyCode::Esc if !self.filter.is_empty() => self.filter = Filter::default(),
            KeyCode::Up | KeyCode::Char('k') => self.up(1, model),
            KeyCode::Down | KeyCode::Char('j') => self.down(1, model),
            KeyCode::PageUp if self.view == View::Detail => {
                self.detail_scroll = self.detail_scroll.saturating_sub(u16::try_from(page).unwrap_or(10));
            }
            KeyCode::PageDown if self.view == View::Detail => {
                self.detail_scroll = self.detail_scroll.saturating_add(u16::try_from(page).unwrap_or(10));
            }
            KeyCode::PageUp => self.up(page, model),
            KeyCode::PageDown => self.down(page, model),
            KeyCode::Home | KeyCode::Char('g') => self.up(isize::MAX / 2, model),
            KeyCode::End | KeyCode::Char('G') => {
                self.down(isize::MAX / 2, model);
                self.follow = true;
            }
            KeyCode::Left | KeyCode::Char('h') if self.view == View::Registers => {
                self.cycle_register_unit(model, false);
            }
            KeyCode::Right | KeyCode::Char('l') if self.view == View::Registers => {
                self.cycle_register_unit(model, true);
            }
            KeyCode::Char('r') if self.view == View::Detail => {
                self.side = if self.side == Side::Request { Side::Response } else { Side::Request };
                self.field = 0;
            }
            KeyCode::Char('u') => {
                self.filter.unit = cycle(self.filter.unit, &model.devices.keys().copied().collect::<Vec<_>>());
            }
            KeyCode::Char('f') => self.filter.function = cycle(self.filter.function, &functions(model)),
            KeyCode::Char('e') => self.filter.errors_only = !self.filter.errors_only,
            KeyCode::Char('/') => self.input = Some(self.filter.text.clone()),
            KeyCode::Char('c') => self.filter = Filter::default(),
            KeyCode::Char(' ') => return self.pause(model),
            KeyCode::Char('s') if self.pacing => {
                self.speed = self.speed.next();
                return Action::Speed;
            }
            KeyCode::Char('x') => return Action::ExportJsonl,
            KeyCode::Char('w') => return Action::ExportPcapng,
            _ => {}
        }
        Action::None
    }

    fn pause(&mut self, model: &Model) -> Action {
        if self.pacing {
            self.speed = if self.speed == Speed::Paused { Speed::Times(1.0) } else { Speed::Paused };
            return Action::Speed;
        }
        self.frozen_at = match self.frozen_at {
            Some(_) => None,
            None => Some(model.total_rows().saturating_sub(1)),
        };
        Action::None
    }

    fn up(&mut self, n: isize, model: &Model) {
        match self.view {
            View::Traffic => self.move_selection(-n),
            View::Detail => self.field = self.field.saturating_sub(n.unsigned_abs()),
            View::Devices => self.device_offset = self.device_offset.saturating_sub(n.unsigned_abs()),
            View::Registers => self.register_offset = self.register_offset.saturating_sub(n.unsigned_abs()),
        }
        let _ = model;
    }

    fn down(&mut self, n: isize, model: &Model) {
        match self.view {
            View::Traffic => self.move_selection(n),
            View::Detail => self.field = self.field.saturating_add(n.unsigned_abs()),
            View::Devices => {
                self.device_offset =
                    self.device_offset.saturating_add(n.unsigned_abs()).min(model.devices.len().saturating_sub(1));
            }
            View::Registers => {
                let count = self.register_unit.map_or(0, |u| model.registers.of(u).count());
                self.register_offset =
                    self.register_offset.saturating_add(n.unsigned_abs()).min(count.saturating_sub(1));
            }
        }
    }

    fn cycle_register_unit(&mut self, model: &Model, forward: bool) {
        let mut units = model.registers.units();
        if !forward {
            units.reverse();
        }
        self.register_unit = match self.register_unit(model).and_then(|u| units.iter().position(|&x| x == u)) {
            Some(i) => units.get(i + 1).or(units.first()).copied(),
            None => units.first().copied(),
        };
        self.register_offset = 0;
    }

    /// The unit the registers view shows: the chosen one, else the selected row's, else the first.
    #[must_use]
    pub fn register_unit(&self, model: &Model) -> Option<u8> {
        self.register_unit
            .or_else(|| self.selected.and_then(|s| model.row(s)).and_then(|r| r.unit))
            .filter(|u| model.registers.of(*u).next().is_some())
            .or_else(|| model.registers.units().first().copied())
    }
}

/// Functions seen on the bus (exception bit cleared), in order.
fn functions(model: &Model) -> Vec<u8> {
    let mut f: Vec<u8> = model.rows.iter().filter_map(|r| r.function.map(|f| f & 0x7F)).collect();
    f.sort_unstable();
    f.dedup();
    f
}

/// None → first → … → last → None.
fn cycle(current: Option<u8>, all: &[u8]) -> Option<u8> {
    match current.and_then(|c| all.iter().position(|&x| x == c)) {
        None => all.first().copied(),
        Some(i) => all.get(i + 1).copied(),
    }
}
