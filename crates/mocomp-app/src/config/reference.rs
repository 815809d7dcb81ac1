//! The configuration's reference for the book (`mocomp config reference`): every section and key
//! of the commented template ([`crate::config::template::TEMPLATE`], which a test holds to the schema's
//! defaults) as Markdown tables, key, default and meaning. Generated, never written by hand, so
//! it cannot drift from what the program reads.
//!
//! The template's layout, which this reads line by line: `[section]  # what it is`; `key = value
//! # meaning`; an optional key commented out, `# key = example  # meaning`; a meaning continued
//! on the lines below it, indented past column 30; any other comment is a note of its section.

use crate::AppError;
use crate::config::template::TEMPLATE;

/// One key of a section.
#[derive(Debug, Clone, PartialEq)]
struct Key {
    name: String,
    /// The default as written, or an example for an optional key.
    value: String,
    optional: bool,
    meaning: String,
}

/// One section: `[name]` (empty: the top level), what it is, its keys and notes.
#[derive(Debug, Clone, Default, PartialEq)]
struct Section {
    name: String,
    about: String,
    keys: Vec<Key>,
    notes: Vec<String>,
}

/// A meaning's continuation: a comment indented past the values' column.
const CONTINUATION_INDENT: usize = 20;

/// `text` split at its first `#` outside a string: the part before, and the comment after.
fn split_comment(text: &str) -> (&str, Option<&str>) {
    let mut in_string = false;
    for (i, c) in text.char_indices() {
        match c {
            '"' => in_string = !in_string,
            '#' if !in_string => return (text[..i].trim_end(), Some(text[i + 1..].trim())),
            _ => {}
        }
    }
    (text.trim_end(), None)
}

/// `name = value` when `value` is a TOML value.
fn key_value(text: &str) -> Option<(String, String)> {
    let (name, value) = text.split_once('=')?;
    let name = name.trim();
    let value = value.trim();
    let valid = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        && format!("v = {value}").parse::<toml::Table>().is_ok();
    valid.then(|| (name.to_string(), value.to_string()))
}

/// `[name]`'s name.
fn header(text: &str) -> Option<&str> {
    let t = text.trim();
    t.strip_prefix('[')?.strip_suffix(']')
}

/// What a line of the template holds.
enum Item {
    Section(Section),
    Key(Key),
}

/// A `[section]` header or a `key = value` line (`optional`: commented out), with its meaning.
fn item(code: &str, meaning: Option<&str>, optional: bool) -> Option<Item> {
    let meaning = meaning.unwrap_or_default().to_string();
    if let Some(name) = header(code) {
        return Some(Item::Section(Section {
            name: name.to_string(),
            about: meaning,
            ..Section::default()
        }));
    }
    key_value(code).map(|(name, value)| {
        Item::Key(Key {
            name,
            value,
            optional,
            meaning,
        })
    })
}

/// The template's sections, in its order.
fn sections(template: &str) -> Vec<Section> {
    let mut out = vec![Section::default()];
    // Where a continued comment goes: the last key's meaning, else the section's note.
    let mut last_key = false;
    for line in template.lines() {
        let indent = line.len() - line.trim_start().len();
        let t = line.trim();
        let Some(section) = out.last_mut() else {
            break;
        };
        if t.is_empty() {
            last_key = false;
            continue;
        }
        if let Some(comment) = t.strip_prefix('#') {
            let comment = comment.trim();
            if indent >= CONTINUATION_INDENT && last_key {
                if let Some(k) = section.keys.last_mut() {
                    k.meaning = format!("{} {comment}", k.meaning).trim().to_string();
                }
                continue;
            }
            let (code, meaning) = split_comment(comment);
            match item(code, meaning, true) {
                Some(Item::Section(s)) => {
                    // A table left out by default (`# [head.landmarks]`): its keys follow,
                    // commented.
                    out.push(s);
                    last_key = false;
                }
                Some(Item::Key(k)) => {
                    section.keys.push(k);
                    last_key = true;
                }
                None => {
                    section.notes.push(comment.to_string());
                    last_key = false;
                }
            }
            continue;
        }
        let (code, meaning) = split_comment(t);
        match item(code, meaning, false) {
            Some(Item::Section(s)) => {
                out.push(s);
                last_key = false;
            }
            Some(Item::Key(k)) => {
                section.keys.push(k);
                last_key = true;
            }
            None => {}
        }
    }
    out
}

/// A table cell: no line break, no unescaped bar.
fn cell(text: &str) -> String {
    text.replace('|', "\\|")
}

/// The reference as Markdown.
pub fn markdown() -> Result<String, AppError> {
    // The template is the program's own: refuse to document one that does not parse.
    TEMPLATE
        .parse::<toml::Table>()
        .map_err(|e| AppError::failed("the configuration template", e))?;
    let mut o = String::from(
        "# Configuration reference\n\n\
         Every key of the one configuration that `run`, `demo`, `calibrate collect`, \
         `teach-goal`, `register` and the other commands read with `--config FILE`. Generated \
         from the program's own template (`mocomp config reference`), which a test holds to \
         the schema's defaults; `mocomp config print` prints it as a file with comments. A file \
         needs only the keys it changes; a file with none is the built-in simulated world. \
         Units: metres, seconds, radians; poses are UR pose vectors `[x, y, z, rx, ry, rz]`. \
         Unknown keys and values out of range are refused, naming the key (exit 2).\n",
    );
    for s in sections(TEMPLATE) {
        let title = if s.name.is_empty() {
            "The top level".to_string()
        } else {
            format!("`[{}]`", s.name)
        };
        o.push_str(&format!("\n## {title}\n\n"));
        if !s.about.is_empty() {
            o.push_str(&format!("{}\n\n", s.about));
        }
        if !s.keys.is_empty() {
            o.push_str("| key | default | what it is |\n|---|---|---|\n");
            for k in &s.keys {
                let value = if k.optional {
                    format!("none (e.g. `{}`)", cell(&k.value))
                } else {
                    format!("`{}`", cell(&k.value))
                };
                o.push_str(&format!(
                    "| `{}` | {value} | {} |\n",
                    k.name,
                    cell(&k.meaning)
                ));
            }
        }
        if !s.notes.is_empty() {
            o.push_str(&format!("\n{}\n", s.notes.join(" ")));
        }
    }
    Ok(o)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use crate::config::{Config, flatten, same_value};

    #[test]
    fn every_key_the_program_reads_by_default_is_in_the_reference_with_its_default() {
        let secs = sections(TEMPLATE);
        let text = toml::to_string(&Config::default()).unwrap();
        let defaults: toml::Table = text.parse().unwrap();
        let mut all = Vec::new();
        flatten("", &defaults, &mut all);
        assert!(all.len() > 150, "{}", all.len());
        for (path, ours) in all {
            let (section, key) = path.rsplit_once('.').unwrap_or(("", &path));
            let s = secs
                .iter()
                .find(|s| s.name == section)
                .unwrap_or_else(|| panic!("no section [{section}] for {path}"));
            let k = s
                .keys
                .iter()
                .find(|k| k.name == key)
                .unwrap_or_else(|| panic!("{path} is not in the reference"));
            // The default as the reference states it is the program's.
            let theirs: toml::Table = format!("v = {}", k.value).parse().unwrap();
            if !k.optional {
                assert!(
                    same_value(&theirs["v"], &ours),
                    "{path}: reference {} against the default {ours}",
                    k.value
                );
            }
        }
    }

    #[test]
    fn a_continued_meaning_stays_with_its_key_and_an_optional_key_is_marked() {
        let secs = sections(
            "[a]                # the a's\n\
             x = 1              # first half\n\
             \x20                                  # second half\n\
             # y = \"e\"        # optional\n\
             # kind = \"nods\": start_s = 1.0  (a note)\n",
        );
        let a = &secs[1];
        assert_eq!(a.name, "a");
        assert_eq!(a.about, "the a's");
        assert_eq!(a.keys[0].meaning, "first half second half");
        assert!(!a.keys[0].optional);
        assert_eq!((a.keys[1].name.as_str(), a.keys[1].optional), ("y", true));
        assert_eq!(a.keys.len(), 2, "{:?}", a.keys);
        assert_eq!(a.notes.len(), 1);
    }
}
