//! Items resolved against a profile: a name to its table and addresses, a range without a table
//! to the one table where the profile documents it, and ranges widened so that a multi-register
//! value (u32, f32, string, date) is always read whole.
//!
//! Names match case-insensitively, in English or the document's language, with or without a
//! trailing explanation in parentheses (`Level 2 set point` finds
//! `Level 2 set point (pump 1 on)` when only one name shortens to it). A name that matches
//! nothing gets the closest name as a suggestion.

use super::items::{Item, What};
use super::{QueryError, is_bits};
use crate::profile::{Profile, Table};

/// An item with its table and addresses fixed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Target {
    pub item: Item,
    pub table: Table,
    pub first: u16,
    /// Inclusive.
    pub last: u16,
}

impl Target {
    /// Registers or points the target covers.
    #[must_use]
    pub fn count(&self) -> u32 {
        u32::from(self.last) - u32::from(self.first) + 1
    }
}

/// The name without a trailing ` (…)`, lower-cased.
fn short(name: &str) -> String {
    let n = name.trim();
    let n = match n.rfind(" (") {
        Some(i) if n.ends_with(')') => &n[..i],
        _ => n,
    };
    n.to_lowercase()
}

/// Levenshtein distance over chars, for "did you mean" (register names here, profile names in
/// the binary). Bounded work: names are short.
#[must_use]
pub fn distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = if ca == cb { prev } else { 1 + prev.min(row[j]).min(cur) };
            prev = cur;
        }
    }
    row[b.len()]
}

/// The shortest of `names` holding every word of `want` (two words at least; a word of three
/// letters or more may be the start of the name's word: `volt` in `volts`), if one does.
fn by_words<'p>(want: &str, names: impl Iterator<Item = &'p str>) -> Option<String> {
    let words: Vec<&str> = want.split(|c: char| !c.is_alphanumeric()).filter(|w| !w.is_empty()).collect();
    if words.len() < 2 {
        return None;
    }
    names
        .filter(|en| {
            let lower = en.to_lowercase();
            let has: Vec<&str> = lower.split(|c: char| !c.is_alphanumeric()).filter(|w| !w.is_empty()).collect();
            words.iter().all(|w| has.iter().any(|h| h == w || (w.chars().count() >= 3 && h.starts_with(w))))
        })
        .min_by_key(|en| en.chars().count())
        .map(str::to_owned)
}

/// Every value's first address with its names: (table, first, names to match).
fn named_values(p: &Profile) -> impl Iterator<Item = (Table, u16, &str, Option<&str>)> {
    p.tables.iter().flat_map(move |(&table, slots)| {
        slots.iter().filter(|(_, s)| s.part == 0).map(move |(&a, s)| {
            let ru = p.defs[s.def].name_ru.as_deref().filter(|r| !r.contains("{n}"));
            (table, a, s.name.as_str(), ru)
        })
    })
}

fn find_name(item: &Item, name: &str, p: &Profile) -> Result<(Table, u16), QueryError> {
    let want = name.trim().to_lowercase();
    let in_table = |t: Table| item.table.is_none_or(|want| want == t);
    let exact: Vec<(Table, u16)> = named_values(p)
        .filter(|&(t, _, en, ru)| {
            in_table(t) && (en.to_lowercase() == want || ru.is_some_and(|r| r.to_lowercase() == want))
        })
        .map(|(t, a, ..)| (t, a))
        .collect();
    let found = if exact.is_empty() {
        named_values(p)
            .filter(|&(t, _, en, ru)| in_table(t) && (short(en) == want || ru.is_some_and(|r| short(r) == want)))
            .map(|(t, a, ..)| (t, a))
            .collect()
    } else {
        exact
    };
    match found.as_slice() {
        [one] => Ok(*one),
        [] => {
            // Only names of about the same length can be close enough: the edit distance is at
            // least the difference in length, and skipping the rest keeps a long garbage name
            // from costing its length times every name in the profile.
            let limit = want.chars().count() / 3 + 2;
            let near = |n: &str| n.chars().count().abs_diff(want.chars().count()) <= limit;
            // A name holding every word typed comes first ("Phase 1 volts" → "Phase 1 line to
            // neutral volts", not the closer-spelled "Phase 1 power"): users shorten names by
            // leaving words out far more often than they misspell them.
            let suggestion = by_words(&want, named_values(p).filter(|&(t, ..)| in_table(t)).map(|(_, _, en, _)| en))
                .or_else(|| {
                    named_values(p)
                        .filter(|&(t, ..)| in_table(t))
                        .filter_map(|(_, _, en, _)| {
                            let (full, cut) = (en.to_lowercase(), short(en));
                            let d = [full, cut].iter().filter(|n| near(n)).map(|n| distance(&want, n)).min()?;
                            Some((d, en))
                        })
                        .min_by_key(|&(d, _)| d)
                        .filter(|&(d, _)| d <= limit)
                        .map(|(_, en)| en.to_owned())
                });
            Err(QueryError::UnknownName { item: item.text.clone(), profile: p.meta.name.clone(), suggestion })
        }
        many => {
            let mut tables: Vec<&str> = many.iter().map(|(t, _)| t.name()).collect();
            tables.dedup();
            if tables.len() > 1 {
                Err(QueryError::AmbiguousName {
                    item: item.text.clone(),
                    name: name.to_owned(),
                    tables: tables.join(", "),
                })
            } else {
                Err(QueryError::Syntax {
                    item: item.text.clone(),
                    problem: format!("{} values share this name; give the address instead", many.len()),
                })
            }
        }
    }
}

/// The one table where `p` documents any of `first..=last`.
fn table_of_range(item: &Item, first: u16, last: u16, p: Option<&Profile>) -> Result<Table, QueryError> {
    let need = |why: &str| QueryError::TableNeeded { item: item.text.clone(), why: why.to_owned() };
    let Some(p) = p else { return Err(need("there is no device profile to look the address up in")) };
    let tables: Vec<Table> =
        p.tables.iter().filter(|(_, slots)| slots.range(first..=last).next().is_some()).map(|(&t, _)| t).collect();
    match tables.as_slice() {
        [one] => Ok(*one),
        [] => Err(need(&format!("no address in it is in the {} profile", p.meta.name))),
        many => Err(need(&format!(
            "the {} profile documents it in {}",
            p.meta.name,
            many.iter().map(|t| t.name()).collect::<Vec<_>>().join(" and ")
        ))),
    }
}

/// Resolves one item. See the module documentation.
pub fn resolve(item: &Item, p: Option<&Profile>) -> Result<Target, QueryError> {
    let (table, mut first, mut last) = match &item.what {
        What::Name(name) => {
            let Some(p) = p else { return Err(QueryError::NameWithoutProfile { item: item.text.clone() }) };
            let (table, first) = find_name(item, name, p)?;
            (table, first, first)
        }
        &What::Range { first, last } => {
            let table = match item.table {
                Some(t) => t,
                None => table_of_range(item, first, last, p)?,
            };
            (table, first, last)
        }
    };
    // Whole values: back to the first register of the value `first` is in, on to the last
    // register of the value `last` is in.
    if let Some(p) = p.filter(|_| !is_bits(table)) {
        if let Some((slot, _)) = p.slot(table, first) {
            first = slot.first;
        }
        if let Some((slot, def)) = p.slot(table, last) {
            last = last.max(slot.first.saturating_add(def.width.saturating_sub(1)));
        }
    }
    Ok(Target { item: item.clone(), table, first, last })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::super::items::parse_item;
    use super::*;

    fn mk4() -> Profile {
        crate::profile::builtin::get("mk4").unwrap().unwrap()
    }

    fn target(text: &str) -> Result<Target, QueryError> {
        resolve(&parse_item(text, None).unwrap(), Some(&mk4()))
    }

    #[test]
    fn names_in_either_language_and_without_their_explanation() {
        let t = target("phase a (l1) voltage").unwrap();
        assert_eq!((t.table, t.first, t.last), (Table::InputRegisters, 430, 430));
        let t = target("Level 2 set point").unwrap();
        assert_eq!((t.table, t.first), (Table::HoldingRegisters, 105));
        let t = target("Режим работы").unwrap();
        assert_eq!((t.table, t.first), (Table::HoldingRegisters, 101));
    }

    #[test]
    fn a_typo_gets_the_closest_name() {
        let e = target("Operating mdoe").unwrap_err();
        assert!(e.to_string().contains("did you mean \"Operating mode\""), "{e}");
    }

    #[test]
    fn a_name_shortened_by_leaving_words_out_is_suggested_whole() {
        let sdm = crate::profile::builtin::get("sdm630").unwrap().unwrap();
        let e = resolve(&parse_item("Phase 1 volts", None).unwrap(), Some(&sdm)).unwrap_err();
        assert!(e.to_string().contains("did you mean \"Phase 1 line to neutral volts\""), "{e}");
        // A misspelling still finds the name by its spelling.
        let e = resolve(&parse_item("Total kwhh", None).unwrap(), Some(&sdm)).unwrap_err();
        assert!(e.to_string().contains("did you mean \"Total kWh\""), "{e}");
    }

    #[test]
    fn a_range_takes_its_table_from_the_profile_when_only_one_has_it() {
        let t = target("430..433").unwrap();
        assert_eq!(t.table, Table::InputRegisters);
        let e = resolve(&parse_item("430..433", None).unwrap(), None).unwrap_err();
        assert!(matches!(e, QueryError::TableNeeded { .. }), "{e}");
        let t = resolve(&parse_item("holding 7", None).unwrap(), None).unwrap();
        assert_eq!((t.table, t.first, t.last), (Table::HoldingRegisters, 7, 7));
    }

    #[test]
    fn distance_counts_edits() {
        assert_eq!(distance("mode", "mdoe"), 2);
        assert_eq!(distance("", "abc"), 3);
        assert_eq!(distance("voltage", "voltage"), 0);
    }
}
