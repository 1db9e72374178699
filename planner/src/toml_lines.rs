//! Lines and fields of TOML text, for configuration errors that name the file, the line and the field
//! (the machine file, the simulator's scenario, the controller config).
//!
//! Fields are dotted paths through tables and array entries by index (`cycle.actions.2.start.x_m`).

use gateway_core::range::Limits;
use toml::de::{DeTable, DeValue};

/// `Ok` if `v` is finite and within `limits` (the workspace's one finite-and-range check,
/// [`gateway_core::range`]); otherwise `(field, reason)`, the form the file validators return before
/// [`line_of_field`] adds the line: `must be finite and in [0, 20], got -2`.
///
/// # Errors
/// `field` and the rule `v` breaks, with `v`.
pub fn check_field(field: &str, v: f64, limits: Limits) -> Result<(), (String, String)> {
    limits
        .check(v)
        .map_err(|e| (field.to_owned(), format!("{e}, got {v}")))
}

/// As [`check_field`] with the bounds and the value in exponent form (`[5e6, 5e7], got 1e308`), for
/// quantities that span many decades (pressures, flows, masses).
///
/// # Errors
/// As [`check_field`].
pub fn check_field_exp(field: &str, v: f64, limits: Limits) -> Result<(), (String, String)> {
    limits
        .check(v)
        .map_err(|e| (field.to_owned(), format!("{e:e}, got {v:e}")))
}

/// The 1-based line of byte `offset` in `text` (a parser span's start).
#[must_use]
pub fn line_of_offset(text: &str, offset: usize) -> usize {
    text.get(..offset.min(text.len()))
        .map_or(0, |s| s.bytes().filter(|&b| b == b'\n').count())
        + 1
}

/// The 1-based line of the dotted field `path` (`soil_regions.1.x_min_m`, array entries by index) in
/// TOML `text`: the line of its key, or, for a value the file leaves at its default, of the deepest
/// table on the path that the file has. `None` if the text is not TOML or has no part of the path.
#[must_use]
pub fn line_of_field(text: &str, path: &str) -> Option<usize> {
    let doc = DeTable::parse(text).ok()?;
    let mut table: &DeTable<'_> = doc.get_ref();
    let mut value: Option<&DeValue<'_>> = None;
    let mut found: Option<usize> = None;
    for segment in path.split('.') {
        let next = match value {
            None => table
                .iter()
                .find(|(k, _)| k.get_ref().as_ref() == segment)
                .map(|(k, v)| (k.span().start, v)),
            Some(DeValue::Array(items)) => segment
                .parse::<usize>()
                .ok()
                .and_then(|i| items.get(i))
                .map(|v| (v.span().start, v)),
            Some(_) => None,
        };
        let Some((offset, v)) = next else { break };
        found = Some(offset);
        match v.get_ref() {
            DeValue::Table(t) => {
                table = t;
                value = None;
            }
            other => value = Some(other),
        }
    }
    found.map(|o| line_of_offset(text, o))
}

/// The dotted field whose key or value covers byte `offset` of TOML `text` (the deepest one), for
/// parse errors whose message does not name it. `None` for text that is not TOML (its syntax error's
/// message names the place) or an offset outside every field.
#[must_use]
pub fn field_at_offset(text: &str, offset: usize) -> Option<String> {
    // Spans of tables opened by a `[header]` cover the header only, so every table and array is
    // searched, not only the ones whose span holds the offset.
    fn walk(value: &DeValue<'_>, offset: usize, path: &mut Vec<String>) -> bool {
        let mut visit = |name: String,
                         key_span: Option<std::ops::Range<usize>>,
                         v: &toml::Spanned<DeValue<'_>>| {
            let hit = key_span.is_some_and(|s| s.contains(&offset)) || v.span().contains(&offset);
            path.push(name);
            if walk(v.get_ref(), offset, path) || hit {
                return true;
            }
            path.pop();
            false
        };
        match value {
            DeValue::Table(t) => t
                .iter()
                .any(|(k, v)| visit(k.get_ref().to_string(), Some(k.span()), v)),
            DeValue::Array(items) => items
                .iter()
                .enumerate()
                .any(|(i, v)| visit(i.to_string(), None, v)),
            _ => false,
        }
    }
    let doc = DeTable::parse(text).ok()?;
    let mut path = Vec::new();
    walk(&DeValue::Table(doc.into_inner()), offset, &mut path);
    (!path.is_empty()).then(|| path.join("."))
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "\
top = 1

[a]
x = 2.0 # note
[a.b]
y = \"s\"

[[r]]
x_min_m = 0.0

[[r]]
x_min_m = 1.0
nested = { z = 3 }
";

    #[test]
    fn lines_count_from_one() {
        assert_eq!(line_of_offset(TEXT, 0), 1);
        assert_eq!(line_of_offset(TEXT, TEXT.find("[a]").unwrap()), 3);
        assert_eq!(line_of_offset(TEXT, usize::MAX), TEXT.lines().count() + 1);
    }

    #[test]
    fn fields_are_found_on_their_key_line() {
        assert_eq!(line_of_field(TEXT, "top"), Some(1));
        assert_eq!(line_of_field(TEXT, "a.x"), Some(4));
        assert_eq!(line_of_field(TEXT, "a.b.y"), Some(6));
    }

    #[test]
    fn array_entries_are_found_by_index() {
        assert_eq!(line_of_field(TEXT, "r.0.x_min_m"), Some(9));
        assert_eq!(line_of_field(TEXT, "r.1.x_min_m"), Some(12));
        assert_eq!(line_of_field(TEXT, "r.1.nested.z"), Some(13));
    }

    #[test]
    fn a_default_value_points_at_the_deepest_table_the_file_has() {
        assert_eq!(line_of_field(TEXT, "a.b.missing"), Some(5));
        assert_eq!(line_of_field(TEXT, "a.missing.deeper"), Some(3));
        assert_eq!(line_of_field(TEXT, "r.5.x_min_m"), Some(8));
        assert_eq!(line_of_field(TEXT, "missing.key"), None);
        assert_eq!(line_of_field("not = = toml", "not"), None);
    }

    #[test]
    fn the_field_at_an_offset_is_the_deepest_one() {
        assert_eq!(
            field_at_offset(TEXT, TEXT.find("2.0").unwrap()).as_deref(),
            Some("a.x")
        );
        let z = TEXT.find("z = 3").unwrap() + 4;
        assert_eq!(field_at_offset(TEXT, z).as_deref(), Some("r.1.nested.z"));
        assert_eq!(field_at_offset("not = = toml", 0), None);
    }
}
