//! What a probe found, said: the present runs of each table, the text a user reads, and the
//! skeleton profile to start a device's profile from.

use super::Probe;
use mbtap_device::profile::Table;
use std::fmt::Write as _;

impl Probe {
    /// The present addresses of `table` as runs `(first, last)`.
    #[must_use]
    pub fn runs(&self, table: Table) -> Vec<(u16, u16)> {
        let mut out: Vec<(u16, u16)> = Vec::new();
        for &a in self.found.get(&table).map(|f| f.present.keys()).into_iter().flatten() {
            match out.last_mut() {
                Some((_, last)) if u32::from(*last) + 1 == u32::from(a) => *last = a,
                _ => out.push((a, a)),
            }
        }
        out
    }

    /// A summary for people.
    #[must_use]
    pub fn text(&self) -> String {
        let mut s = String::new();
        for (table, f) in &self.found {
            if f.unsupported {
                let _ = writeln!(s, "{}: not supported (exception 01)", table.name());
                continue;
            }
            let runs: Vec<String> = self
                .runs(*table)
                .iter()
                .map(|&(a, b)| if a == b { a.to_string() } else { format!("{a}..{b}") })
                .collect();
            let _ = writeln!(
                s,
                "{}: {} address(es) answer{}{}",
                table.name(),
                f.present.len(),
                if runs.is_empty() { String::new() } else { format!(": {}", runs.join(", ")) },
                match (f.max_block, f.refused_block) {
                    (Some(m), Some(r)) => format!(" ({m} per read accepted, {r} refused)"),
                    (Some(m), None) => format!(" ({m} per read accepted)"),
                    _ => String::new(),
                }
            );
        }
        let _ = writeln!(s, "{} read request(s), nothing written", self.requests);
        if self.assumed_absent > 0 {
            let _ = writeln!(
                s,
                "{} address(es) inside absent stretches were stepped over unread (a lone present address among them would be missed)",
                self.assumed_absent
            );
        }
        if let Some(why) = &self.stopped {
            let _ = writeln!(s, "stopped early: {why}");
        }
        s
    }

    /// A skeleton profile: every address that answered, named `reg_<table>_<address>`, with the
    /// value it gave as a comment; runs of 16 or more as one `addresses` entry.
    #[must_use]
    pub fn skeleton(&self, unit: u8, target: &str) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "# Skeleton by `mbtap probe` of unit {unit} at {} — read only; names are placeholders.",
            mbtap_device::profile::escape::comment(target)
        );
        if let Some(why) = &self.stopped {
            let _ = writeln!(s, "# The probe stopped early: {}", mbtap_device::profile::escape::comment(why));
        }
        let _ = writeln!(
            s,
            "\n[profile]\nname = \"probed-unit-{unit}\"\ndevice = \"unit {unit} (probed by mbtap)\"\ndefault_address = {unit}"
        );
        let functions: Vec<&str> = self
            .found
            .iter()
            .filter(|(_, f)| !f.present.is_empty())
            .map(|(t, _)| match t {
                Table::Coils => "1",
                Table::DiscreteInputs => "2",
                Table::HoldingRegisters => "3",
                Table::InputRegisters => "4",
            })
            .collect();
        let _ = writeln!(s, "functions = [{}]", functions.join(", "));
        for (table, f) in &self.found {
            for (a, b) in self.runs(*table) {
                if b - a >= 15 {
                    let _ = writeln!(
                        s,
                        "\n# {} addresses answered\n[[{}]]\naddresses = [{a}, {b}]\nname = \"reg_{}_{a}+{{n}}\"",
                        u32::from(b) - u32::from(a) + 1,
                        table.name(),
                        table.word()
                    );
                    continue;
                }
                for addr in a..=b {
                    let v = f.present.get(&addr).copied().unwrap_or(0);
                    let _ = writeln!(
                        s,
                        "\n# read {v} (0x{v:04X})\n[[{}]]\naddress = {addr}\nname = \"reg_{}_{addr}\"",
                        table.name(),
                        table.word()
                    );
                }
            }
        }
        s
    }
}
