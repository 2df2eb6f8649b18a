//! Warnings said once per kind: many places with the same problem (48
//! meshes each with zero-area triangles) become one line with a count and
//! the first few names, not one line each.

use std::collections::HashMap;
use std::path::Path;

/// How many places a summary names before "and N more".
const NAMES_SHOWN: usize = 3;

/// Adds `message` to `warnings`, one line per place: the line of `key`
/// (which `warned` indexes) when there is one and lacks the message, else
/// a new line `first(key)` with `message` after it.
pub(crate) fn warn_at(
    warnings: &mut Vec<String>,
    warned: &mut HashMap<String, usize>,
    key: String,
    message: &str,
    first: impl FnOnce(&str) -> String,
) {
    match warned.get(&key) {
        Some(&i) => {
            let w = &mut warnings[i];
            if !w.contains(message) {
                w.push_str("; ");
                w.push_str(message);
            }
        }
        None => {
            warnings.push(format!("{}{message}", first(&key)));
            warned.insert(key, warnings.len() - 1);
        }
    }
}

/// The loader's own warnings with exact repeats folded into one line
/// ("... (N times)"), then the validation warnings `(place, message)` one
/// line per kind: messages that differ only in their numbers are one kind.
pub(crate) fn summarize(
    loader: Vec<String>,
    file: &Path,
    issues: Vec<(String, String)>,
) -> Vec<String> {
    let mut out: Vec<(String, usize)> = Vec::new();
    for w in loader {
        match out.iter_mut().find(|(seen, _)| *seen == w) {
            Some((_, n)) => *n += 1,
            None => out.push((w, 1)),
        }
    }
    let mut lines: Vec<String> = out
        .into_iter()
        .map(|(w, n)| if n > 1 { format!("{w} ({n} times)") } else { w })
        .collect();
    let mut kinds: Vec<(String, Vec<(String, String)>)> = Vec::new();
    for (place, message) in issues {
        let key = mask_numbers(&message);
        match kinds.iter_mut().find(|(k, _)| *k == key) {
            Some((_, group)) => group.push((place, message)),
            None => kinds.push((key, vec![(place, message)])),
        }
    }
    let file = file.display();
    for (_, group) in kinds {
        let [(place, message)] = group.as_slice() else {
            lines.push(summary_line(&file.to_string(), &group));
            continue;
        };
        lines.push(format!("{file}: {place}: {message}"));
    }
    lines
}

/// One line for `group` (two or more places, one kind). Where every
/// message is a count followed by words ("3 zero-area triangle(s) ..."),
/// the counts are summed; otherwise the first place and its message are
/// said as they are. Then how many places, and the first few.
fn summary_line(file: &str, group: &[(String, String)]) -> String {
    let leading_count = |m: &str| -> Option<u64> {
        match numbers(m).as_slice() {
            [(range, n)] if range.start == 0 => n.parse().ok(),
            _ => None,
        }
    };
    let counts: Option<Vec<u64>> = group.iter().map(|(_, m)| leading_count(m)).collect();
    let (first_place, first) = &group[0];
    let (head, rest) = match counts {
        Some(counts) => {
            let total = counts.iter().fold(0u64, |a, &c| a.saturating_add(c));
            let words = first.trim_start_matches(|c: char| c.is_ascii_digit());
            (format!("{total}{words}"), group)
        }
        None => (format!("{first_place}: {first}"), &group[1..]),
    };
    let shown: Vec<&str> = rest
        .iter()
        .take(NAMES_SHOWN)
        .map(|(p, _)| p.as_str())
        .collect();
    let more = rest.len().saturating_sub(NAMES_SHOWN);
    let names = if more > 0 {
        format!("{} and {more} more", shown.join(", "))
    } else {
        shown.join(", ")
    };
    if rest.len() == group.len() {
        format!("{file}: {head} (in {} places: {names})", group.len())
    } else {
        let places = if rest.len() == 1 { "place" } else { "places" };
        let n = rest.len();
        format!("{file}: {head}; the same in {n} more {places} ({names})")
    }
}

/// The runs of ASCII digits in `s`, with their byte ranges.
fn numbers(s: &str) -> Vec<(std::ops::Range<usize>, &str)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, c) in s.char_indices().chain(std::iter::once((s.len(), ' '))) {
        match (c.is_ascii_digit(), start) {
            (true, None) => start = Some(i),
            (false, Some(a)) => {
                out.push((a..i, &s[a..i]));
                start = None;
            }
            _ => {}
        }
    }
    out
}

/// `s` with every run of digits replaced by `#`: the kind of a message.
fn mask_numbers(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut last = 0;
    for (range, _) in numbers(s) {
        out.push_str(&s[last..range.start]);
        out.push('#');
        last = range.end;
    }
    out.push_str(&s[last..]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn issue(place: &str, message: &str) -> (String, String) {
        (place.to_string(), message.to_string())
    }

    #[test]
    fn many_places_of_one_kind_are_one_line_with_the_total() {
        let issues = (0..48)
            .map(|i| {
                issue(
                    &format!("meshes[{i}]"),
                    &format!("{} zero-area triangle(s) will not be drawn", i % 3 + 1),
                )
            })
            .collect();
        let lines = summarize(Vec::new(), Path::new("m.obj"), issues);
        assert_eq!(
            lines,
            [
                "m.obj: 96 zero-area triangle(s) will not be drawn (in 48 places: meshes[0], meshes[1], meshes[2] and 45 more)"
            ]
        );
    }

    #[test]
    fn kinds_stay_apart_in_order_and_a_single_place_reads_as_before() {
        let lines = summarize(
            vec![
                "a.png: not found".into(),
                "a.png: not found".into(),
                "b".into(),
            ],
            Path::new("s.toml"),
            vec![
                issue("objects[0]", "material 7 has no name"),
                issue("meshes[1]", "2 zero-area triangle(s) will not be drawn"),
                issue("objects[4]", "material 9 has no name"),
            ],
        );
        assert_eq!(
            lines,
            [
                "a.png: not found (2 times)",
                "b",
                "s.toml: objects[0]: material 7 has no name; the same in 1 more place (objects[4])",
                "s.toml: meshes[1]: 2 zero-area triangle(s) will not be drawn",
            ]
        );
    }

    #[test]
    fn messages_that_are_not_counts_keep_the_first_place_and_name_the_rest() {
        let lines = summarize(
            Vec::new(),
            Path::new("s.toml"),
            vec![
                issue("lights[0]", "cone 30 wider than 20"),
                issue("lights[1]", "cone 40 wider than 20"),
            ],
        );
        assert_eq!(
            lines,
            ["s.toml: lights[0]: cone 30 wider than 20; the same in 1 more place (lights[1])"]
        );
    }
}
