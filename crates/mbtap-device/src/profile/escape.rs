//! Writing strings that came from outside (profile names, sheet file names, register names,
//! units) into the files other tools read, so that they stay *values* there.
//!
//! Three readers matter and each has its own trap:
//! - **YAML 1.1** (PyYAML and libyaml: Home Assistant, ESPHome). A comment ends at any line break
//!   the reader knows — `\n`, `\r`, and also U+0085, U+2028 and U+2029 (YAML 1.1 §5.4, "line break
//!   characters") — so text after one becomes configuration. A plain scalar is *typed* by the
//!   1.1 resolver: `yes`/`off` are booleans, `1:20` a base-60 integer, `1_000` an integer,
//!   `2001-12-14` a date, `<<` a merge key and `=` a value key (YAML 1.1 type repository). So every
//!   string is written plain only when it starts with a letter, holds only letters, digits and a
//!   few punctuation marks no resolver reads, and is not one of the boolean/null words; any other
//!   string is double-quoted with every non-printable and every line-break character escaped
//!   (`\N`, `\L`, `\P`, `\uXXXX`; YAML 1.1 §5.7).
//! - **TOML 1.0** basic strings: `"` and `\` escaped, control characters as `\uXXXX`.
//! - **Spreadsheets** reading CSV: a cell starting `=`, `+`, `-`, `@`, tab or CR is a formula
//!   (OWASP "CSV injection"); such a cell that is not a number gets a leading `'`.
//!
//! Comments (YAML and TOML) keep only printable ASCII and letters or digits of any script; anything
//! else is written as `\u{XXXX}`, so no reader can see a line end inside one.

use std::fmt::Write as _;

use serde_json::Value;

/// A TOML basic string (TOML 1.0 "Basic strings"): quotes, backslashes and control characters
/// escaped.
#[must_use]
pub fn toml_str(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => {
                let _ = write!(out, "\\u{:04X}", u32::from(c));
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// Text safe inside a one-line comment of YAML or TOML: printable ASCII and letters/digits of
/// any script as they are, everything else (controls, line and paragraph separators, format
/// characters) as `\u{XXXX}`.
#[must_use]
pub fn comment(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        if c == ' ' || c.is_ascii_graphic() || (!c.is_ascii() && c.is_alphanumeric()) {
            out.push(c);
        } else {
            let _ = write!(out, "\\u{{{:04X}}}", u32::from(c));
        }
    }
    out
}

/// Words a YAML 1.1 resolver reads as a boolean or null when plain (YAML 1.1 `bool` and `null`
/// types), compared without case.
const YAML11_WORDS: [&str; 13] =
    ["y", "n", "yes", "no", "true", "false", "on", "off", "null", "nan", "inf", "nil", "none"];

/// Whether `s` can be written as a plain YAML scalar and still be read back as this string by
/// a YAML 1.1 or 1.2 reader.
fn plain_ok(s: &str) -> bool {
    let Some(first) = s.chars().next() else { return false };
    if !first.is_ascii_alphabetic() || s.ends_with(' ') {
        return false;
    }
    if YAML11_WORDS.iter().any(|w| w.eq_ignore_ascii_case(s)) {
        return false;
    }
    // No `:`, `#`, quotes, brackets, `&`/`*`/`!`/`|`/`>`/`%`/`@`/backtick, no double spaces
    // (kept as they are, but folded by some emitters).
    s.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, ' ' | '_' | '-' | '.' | '/' | '(' | ')'))
        && !s.contains("  ")
}

/// A YAML double-quoted scalar (YAML 1.1 §5.7 escapes): every character outside printable ASCII
/// that a reader could take as a break or refuse is escaped.
fn yaml_quoted(s: &str, out: &mut String) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            '\u{85}' => out.push_str("\\N"),
            '\u{2028}' => out.push_str("\\L"),
            '\u{2029}' => out.push_str("\\P"),
            c if c == ' ' || c.is_ascii_graphic() || (!c.is_ascii() && c.is_alphanumeric()) => out.push(c),
            c => {
                let n = u32::from(c);
                if n <= 0xFFFF {
                    let _ = write!(out, "\\u{n:04X}");
                } else {
                    let _ = write!(out, "\\U{n:08X}");
                }
            }
        }
    }
    out.push('"');
}

/// A string as a YAML scalar: plain when nothing can misread it, double-quoted otherwise.
#[must_use]
pub fn yaml_str(s: &str) -> String {
    if plain_ok(s) {
        return s.to_owned();
    }
    let mut out = String::with_capacity(s.len() + 2);
    yaml_quoted(s, &mut out);
    out
}

/// A number as YAML reads it in 1.1 and 1.2: floats always with a point and never in exponent
/// form (YAML 1.1's float needs the point; `1e-5` would be a string there).
fn yaml_number(n: &serde_json::Number) -> String {
    if let Some(f) = n.as_f64().filter(|_| n.is_f64()) {
        if f.is_nan() {
            return ".nan".into();
        }
        if f.is_infinite() {
            return if f > 0.0 { ".inf".into() } else { "-.inf".into() };
        }
        let s = format!("{f}");
        return if s.contains('.') { s } else { s + ".0" };
    }
    n.to_string()
}

fn scalar(v: &Value) -> Option<String> {
    match v {
        Value::Null => Some("null".into()),
        Value::Bool(b) => Some(b.to_string()),
        Value::Number(n) => Some(yaml_number(n)),
        Value::String(s) => Some(yaml_str(s)),
        Value::Array(a) if a.is_empty() => Some("[]".into()),
        Value::Object(m) if m.is_empty() => Some("{}".into()),
        _ => None,
    }
}

/// `v` as a block-style YAML document (mappings in their insertion order, sequences as `- `
/// items at the parent's indent), every string through [`yaml_str`].
#[must_use]
pub fn yaml_doc(v: &Value) -> String {
    let mut out = String::new();
    block(v, 0, &mut out);
    out
}

fn block(v: &Value, indent: usize, out: &mut String) {
    match v {
        Value::Object(m) if !m.is_empty() => {
            for (k, val) in m {
                pad(out, indent);
                entry(k, val, indent, out);
            }
        }
        Value::Array(a) if !a.is_empty() => {
            for item in a {
                pad(out, indent);
                out.push_str("- ");
                match scalar(item) {
                    Some(s) => {
                        out.push_str(&s);
                        out.push('\n');
                    }
                    None => block(item, indent + 2, out),
                }
            }
        }
        other => {
            out.push_str(&scalar(other).unwrap_or_default());
            out.push('\n');
        }
    }
}

fn entry(k: &str, val: &Value, indent: usize, out: &mut String) {
    out.push_str(&yaml_str(k));
    out.push(':');
    if let Some(s) = scalar(val) {
        out.push(' ');
        out.push_str(&s);
        out.push('\n');
        return;
    }
    out.push('\n');
    match val {
        Value::Array(_) => block(val, indent, out),
        _ => block(val, indent + 2, out),
    }
}

fn pad(out: &mut String, indent: usize) {
    // The first key of a mapping inside a sequence item follows its `- ` on the same line.
    if out.ends_with("- ") {
        return;
    }
    out.extend(std::iter::repeat_n(' ', indent));
}

/// A CSV cell (RFC 4180 quoting) that a spreadsheet will not run: text starting with `=`, `+`,
/// `-`, `@`, tab or CR, unless it is a number, gets a leading `'`.
#[must_use]
pub fn csv_cell(s: &str) -> String {
    let risky = s.starts_with(['=', '+', '-', '@', '\t', '\r']) && s.parse::<f64>().is_err();
    let mut out = String::with_capacity(s.len() + 3);
    out.push('"');
    if risky {
        out.push('\'');
    }
    out.push_str(&s.replace('"', "\"\""));
    out.push('"');
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// Names a YAML 1.1 resolver would type (the hostile probes' list), each must be quoted.
    const TYPED_WHEN_PLAIN: [&str; 12] =
        ["yes", "No", "ON", "off", "1:20", "12:30:00", "1_000", "2001-12-14", "<<", "=", "~", ".inf"];

    #[test]
    fn names_a_yaml_1_1_reader_would_type_are_quoted() {
        for s in TYPED_WHEN_PLAIN {
            let y = yaml_str(s);
            assert!(y.starts_with('"'), "{s} → {y}");
        }
        assert_eq!(yaml_str("Voltage L1 (avg)"), "Voltage L1 (avg)");
    }

    #[test]
    fn line_separators_are_escaped_never_written_raw() {
        let hostile = "x\u{2028}shell_command:\u{85}  evil: rm -rf /\u{b}";
        let y = yaml_str(hostile);
        assert_eq!(y, "\"x\\Lshell_command:\\N  evil: rm -rf /\\u000B\"");
        let c = comment(hostile);
        assert!(c.chars().all(|c| c == ' ' || c.is_ascii_graphic()), "{c}");
        assert_eq!(comment("Zähler 3"), "Zähler 3");
    }

    #[test]
    fn a_document_reads_back_as_the_data_it_was_made_from() {
        let v = json!({ "modbus": [{ "name": "a: b", "n": 1, "k": 0.00001, "sensors": [{ "name": "yes" }, { "x": [] }], "e": {} }] });
        let text = yaml_doc(&v);
        let back: serde_json::Value = serde_norway::from_str(&text).expect("YAML");
        assert_eq!(back["modbus"][0]["name"], "a: b");
        assert_eq!(back["modbus"][0]["sensors"][0]["name"], "yes");
        assert!((back["modbus"][0]["k"].as_f64().expect("float") - 0.00001).abs() < 1e-12, "{text}");
        assert!(text.contains("k: 0.00001"), "{text}");
    }

    #[test]
    fn csv_formulas_are_neutralised_and_numbers_kept() {
        assert_eq!(csv_cell("=HYPERLINK(\"x\")"), "\"'=HYPERLINK(\"\"x\"\")\"");
        assert_eq!(csv_cell("@SUM(A1)"), "\"'@SUM(A1)\"");
        assert_eq!(csv_cell("-12.5"), "\"-12.5\"");
        assert_eq!(csv_cell("Voltage"), "\"Voltage\"");
    }
}
