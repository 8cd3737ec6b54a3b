//! The items of a `read`/`write`/`watch` command line, as typed: an optional table word, then a
//! register name or an address or inclusive range, then (for writes) `=VALUE`.
//!
//! Contract of [`parse_items`]: every token becomes exactly one item or the first error, which
//! names the token; a table word alone (`holding 50..60`, two tokens) applies to the token
//! after it. Nothing here knows a profile: names are resolved by [`super::resolve`].

use super::{QueryError, table_word};
use crate::profile::Table;

/// What an item names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum What {
    /// Addresses `first..=last` (one address: `first == last`).
    Range { first: u16, last: u16 },
    /// A register or point name, as typed.
    Name(String),
}

/// One item.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Item {
    /// The item as the user wrote it (for messages and output labels).
    pub text: String,
    pub table: Option<Table>,
    pub what: What,
    /// The text after `=`, for writes.
    pub value: Option<String>,
}

fn number(s: &str) -> Option<u16> {
    let s = s.trim();
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(hex) => u16::from_str_radix(hex, 16).ok(),
        None => s.parse().ok(),
    }
}

fn looks_numeric(s: &str) -> bool {
    s.trim().starts_with(|c: char| c.is_ascii_digit())
}

/// Parses one item (without a separate table word).
pub fn parse_item(token: &str, table: Option<Table>) -> Result<Item, QueryError> {
    let syntax = |problem: &str| QueryError::Syntax { item: token.to_owned(), problem: problem.to_owned() };
    let (head, value) = match token.split_once('=') {
        Some((h, v)) => (h, Some(v.trim().to_owned())),
        None => (token, None),
    };
    // `holding:50..60` and `holding 50..60` in one token.
    let (table, head) = match head.trim().split_once([':', ' ']).and_then(|(w, rest)| Some((table_word(w)?, rest))) {
        Some((t, rest)) if table.is_none() => (Some(t), rest.trim()),
        Some(_) => return Err(syntax("two table words")),
        None => (table, head.trim()),
    };
    if head.is_empty() {
        return Err(syntax("nothing to read: give a name, an address or a range FIRST..LAST"));
    }
    let what = if looks_numeric(head) {
        let (a, b) = head.split_once("..").map_or((head, head), |(a, b)| (a, b.trim_start_matches('=')));
        let first = number(a).ok_or_else(|| syntax("an address is a number 0..=65535 (decimal or 0x hex)"))?;
        let last = number(b).ok_or_else(|| syntax("a range is FIRST..LAST, both 0..=65535, LAST included"))?;
        if last < first {
            return Err(syntax("a range's LAST is below its FIRST"));
        }
        What::Range { first, last }
    } else {
        What::Name(head.to_owned())
    };
    Ok(Item { text: token.trim().to_owned(), table, what, value })
}

/// Parses the items of a command line. See the module documentation for the contract.
pub fn parse_items<S: AsRef<str>>(tokens: &[S]) -> Result<Vec<Item>, QueryError> {
    let mut out = Vec::with_capacity(tokens.len());
    let mut pending: Option<(Table, &str)> = None;
    for t in tokens {
        let t = t.as_ref();
        if let Some(table) = table_word(t.trim()) {
            if let Some((_, word)) = pending {
                return Err(QueryError::Syntax {
                    item: word.to_owned(),
                    problem: format!("a table word must be followed by an address or a name, not by {t:?}"),
                });
            }
            pending = Some((table, t));
            continue;
        }
        let mut item = parse_item(t, pending.map(|(table, _)| table))?;
        if let Some((_, word)) = pending.take() {
            // The label says what was asked: `holding 50..60`, not `50..60`.
            item.text = format!("{} {}", word.trim(), item.text);
        }
        out.push(item);
    }
    if let Some((_, word)) = pending {
        return Err(QueryError::Syntax {
            item: word.to_owned(),
            problem: "a table word must be followed by an address or a range".to_owned(),
        });
    }
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn table_word_applies_to_the_next_token_only() {
        let items = parse_items(&["holding", "50..60", "430"]).unwrap();
        assert_eq!(items[0].table, Some(Table::HoldingRegisters));
        assert_eq!(items[0].what, What::Range { first: 50, last: 60 });
        assert_eq!(items[0].text, "holding 50..60");
        assert_eq!(items[1].table, None);
        assert_eq!(items[1].what, What::Range { first: 430, last: 430 });
    }

    #[test]
    fn names_values_and_one_token_tables() {
        let items = parse_items(&["Level 2 set point=1.50", "input:0x1AE", "coils 3=on"]).unwrap();
        assert_eq!(items[0].what, What::Name("Level 2 set point".into()));
        assert_eq!(items[0].value.as_deref(), Some("1.50"));
        assert_eq!(items[1].table, Some(Table::InputRegisters));
        assert_eq!(items[1].what, What::Range { first: 430, last: 430 });
        assert_eq!(items[2].table, Some(Table::Coils));
        assert_eq!(items[2].value.as_deref(), Some("on"));
    }

    #[test]
    fn errors_name_the_token() {
        let e = parse_items(&["433..430"]).unwrap_err();
        assert!(e.to_string().contains("\"433..430\""), "{e}");
        assert!(parse_items(&["holding"]).is_err());
        assert!(parse_items(&["70000"]).is_err());
        assert!(parse_items(&["holding", "input", "1"]).is_err());
    }
}
