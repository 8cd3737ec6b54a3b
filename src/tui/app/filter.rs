//! Which rows the traffic view shows: the filter a user types (unit, function, errors only),
//! matched against each row and described in the status line.

use crate::tui::model::Row;

/// Which rows the traffic view shows.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Filter {
    pub unit: Option<u8>,
    pub function: Option<u8>,
    pub errors_only: bool,
    /// Case-insensitive text looked for in the device name, status and summary.
    pub text: String,
}

impl Filter {
    #[must_use]
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }

    /// Whether `row` passes; `device` is its unit's device name.
    #[must_use]
    pub fn matches(&self, row: &Row, device: Option<&str>) -> bool {
        if self.unit.is_some() && row.unit != self.unit {
            return false;
        }
        if self.function.is_some() && row.function.map(|f| f & 0x7F) != self.function {
            return false;
        }
        if self.errors_only && !row.is_error() {
            return false;
        }
        if !self.text.is_empty() {
            let needle = self.text.to_lowercase();
            let hay =
                format!("{} {} {} {}", device.unwrap_or(""), row.status(), row.label(), row.summary).to_lowercase();
            if !hay.contains(&needle) {
                return false;
            }
        }
        true
    }

    /// The filter in a few words for the status line.
    #[must_use]
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        if let Some(u) = self.unit {
            parts.push(format!("unit {u}"));
        }
        if let Some(f) = self.function {
            parts.push(format!("fn 0x{f:02X}"));
        }
        if self.errors_only {
            parts.push("errors only".into());
        }
        if !self.text.is_empty() {
            parts.push(format!("\"{}\"", self.text));
        }
        parts.join(", ")
    }
}
