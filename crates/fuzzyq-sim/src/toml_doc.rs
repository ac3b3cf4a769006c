//! Reading TOML documents with positions: every error names its line, arrays longer than
//! their fields are refused, and messages stay on one line. Configurations, arenas and
//! policies learned from samples are read through [`TomlDoc`].

use serde::Serialize;
use serde::de::DeserializeOwned;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

use crate::error::ConfigError;

/// The longest message fuzzyq quotes from a TOML error (a value quoted in it may be long).
const MAX_MESSAGE_CHARS: usize = 240;

/// `text` on one line (line breaks become spaces) and at most [`MAX_MESSAGE_CHARS`] long.
pub(crate) fn one_line(text: &str) -> String {
    let mut out = String::with_capacity(text.len().min(MAX_MESSAGE_CHARS + 3));
    for (i, c) in text.trim().chars().enumerate() {
        if i == MAX_MESSAGE_CHARS {
            out.push_str("...");
            break;
        }
        out.push(if c.is_control() { ' ' } else { c });
    }
    out
}

/// An error reading a TOML document: what is wrong, the field (a dotted path:
/// `env.mass`, `obstacle[1]`) and the line, when known. Displayed on one line:
/// `env.mass: invalid type: string "a", expected f64 (line 7)`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct TomlError {
    /// The field, if known.
    pub field: Option<String>,
    /// The line (from 1), if known.
    pub line: Option<usize>,
    /// What is wrong (one line).
    pub message: String,
}

impl TomlError {
    /// Whether the error is in the top-level table `key` (or is that table).
    pub(crate) fn within(&self, key: &str) -> bool {
        self.field.as_deref().is_some_and(|f| {
            f.strip_prefix(key)
                .is_some_and(|rest| rest.is_empty() || rest.starts_with(['.', '[']))
        })
    }
}

impl std::fmt::Display for TomlError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if let Some(field) = &self.field {
            write!(f, "{field}: ")?;
        }
        f.write_str(&self.message)?;
        if let Some(line) = self.line {
            write!(f, " (line {line})")?;
        }
        Ok(())
    }
}

impl From<TomlError> for ConfigError {
    fn from(e: TomlError) -> Self {
        Self::Parse(e.to_string())
    }
}

/// The line (from 1) of byte `offset` of `text`.
pub(crate) fn line_at(text: &str, offset: usize) -> usize {
    let end = offset.min(text.len());
    1 + text.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
}

/// A TOML key as written in a dotted path: bare if it can be, else quoted.
fn key_text(key: &str) -> String {
    if !key.is_empty()
        && key
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        key.to_string()
    } else {
        format!("{key:?}")
    }
}

fn contains(span: &std::ops::Range<usize>, offset: usize) -> bool {
    span.contains(&offset) || (span.is_empty() && span.start == offset)
}

/// A parsed TOML document that keeps the position of every key and value, so that errors
/// name the line and the field; shared by configurations, arenas and the TOML of policy
/// files.
pub(crate) struct TomlDoc<'i> {
    text: &'i str,
    pub(crate) root: Spanned<DeTable<'i>>,
}

impl<'i> TomlDoc<'i> {
    /// Parses `text` (syntax only).
    pub(crate) fn parse(text: &'i str) -> Result<Self, TomlError> {
        match DeTable::parse(text) {
            Ok(root) => Ok(Self { text, root }),
            Err(e) => {
                let offset = e.span().map_or(text.len(), |s| s.start);
                let line = line_at(text, offset);
                let mut message = one_line(e.message());
                if offset >= text.trim_end().len() {
                    message.push_str(" at the end of the text (truncated?)");
                }
                // A syntax error names the key of its line, when the line has one.
                let field = text
                    .lines()
                    .nth(line - 1)
                    .and_then(|l| l.split_once('='))
                    .map(|(k, _)| k.trim())
                    .filter(|k| {
                        !k.is_empty()
                            && k.len() <= 64
                            && k.chars()
                                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
                    })
                    .map(str::to_string);
                Err(TomlError {
                    field,
                    line: Some(line),
                    message,
                })
            }
        }
    }

    /// The top-level table `key`, if the document has it.
    pub(crate) fn table(&self, key: &str) -> Option<&DeTable<'i>> {
        match self.root.get_ref().get(key)?.get_ref() {
            DeValue::Table(t) => Some(t),
            _ => None,
        }
    }

    /// Reads the whole document as `T`.
    pub(crate) fn deserialize<T: DeserializeOwned + Serialize>(&self) -> Result<T, TomlError> {
        self.deserialize_table(self.root.clone())
    }

    /// Reads `table` (part of this document) as `T`: errors name the field and its line, and
    /// an array longer than `T` reads (`x = [-6, 0, 6]` for two numbers; toml would drop the
    /// rest silently) is refused.
    pub(crate) fn deserialize_table<T: DeserializeOwned + Serialize>(
        &self,
        table: Spanned<DeTable<'i>>,
    ) -> Result<T, TomlError> {
        let value = T::deserialize(toml::de::Deserializer::from(table.clone()))
            .map_err(|e| self.error(&e))?;
        // What was read, written back: an array of the text longer than its counterpart
        // lost values.
        let mut path = self
            .node_at(table.span().start)
            .filter(|(_, v)| v.span() == table.span())
            .map(|(p, _)| p)
            .unwrap_or_default();
        if let Ok(toml::Value::Table(read)) = toml::Value::try_from(&value)
            && let Some(e) = self.extra_values(table.get_ref(), &read, &mut path)
        {
            return Err(e);
        }
        Ok(value)
    }

    fn error(&self, e: &toml::de::Error) -> TomlError {
        let message = one_line(e.message());
        // An error of the whole document (a missing top-level field) has no line.
        let whole = e
            .span()
            .is_some_and(|s| s == self.root.span() || s.start == s.end);
        let Some(mut offset) = e.span().filter(|_| !whole).map(|s| s.start) else {
            return TomlError {
                field: None,
                line: None,
                message,
            };
        };
        let mut field = None;
        if let Some((path, v)) = self.node_at(offset) {
            field = Some(path.join("."));
            // A table (or an element of an array of tables, whose errors toml places on the
            // array) that serde read without positions: look for what the message quotes in
            // it, then in the tables around it.
            if matches!(v.get_ref(), DeValue::Table(_)) {
                let mut outer = path.clone();
                while !outer.is_empty() {
                    let joined = outer.join(".");
                    if let Some((_, v)) = self.value_of(&joined)
                        && let Some((inner, at)) = Self::within_table(v, &outer, e.message())
                    {
                        (field, offset) = (Some(inner.join(".")), at);
                        break;
                    }
                    let last = outer.pop().unwrap_or_default();
                    if let Some((key, _)) = last.rsplit_once('[') {
                        outer.push(key.to_string());
                    }
                }
            }
        }
        TomlError {
            field,
            line: Some(line_at(self.text, offset)),
            message,
        }
    }

    fn extra_values(
        &self,
        text: &DeTable<'i>,
        read: &toml::Table,
        path: &mut Vec<String>,
    ) -> Option<TomlError> {
        for (k, v) in text.iter() {
            let key: &str = k.get_ref().as_ref();
            if let Some(r) = read.get(key) {
                path.push(key_text(key));
                let e = self.extra_values_in(v, r, path);
                path.pop();
                if e.is_some() {
                    return e;
                }
            }
        }
        None
    }

    fn extra_values_in(
        &self,
        text: &Spanned<DeValue<'i>>,
        read: &toml::Value,
        path: &mut Vec<String>,
    ) -> Option<TomlError> {
        match (text.get_ref(), read) {
            (DeValue::Table(t), toml::Value::Table(r)) => self.extra_values(t, r, path),
            (DeValue::Array(t), toml::Value::Array(r)) => {
                if t.len() > r.len() {
                    let span = text.span();
                    let written = self.text.get(span.clone()).unwrap_or_default();
                    let shown = if written.len() <= 80 && !written.contains('\n') {
                        format!(" ({written})")
                    } else {
                        String::new()
                    };
                    return Some(TomlError {
                        field: Some(path.join(".")),
                        line: Some(line_at(self.text, t[r.len()].span().start)),
                        message: format!("has {} values{shown}, expected {}", t.len(), r.len()),
                    });
                }
                for (i, (t, r)) in t.iter().zip(r).enumerate() {
                    let last = path.pop().unwrap_or_default();
                    path.push(format!("{last}[{i}]"));
                    let e = self.extra_values_in(t, r, path);
                    path.pop();
                    path.push(last);
                    if e.is_some() {
                        return e;
                    }
                }
                None
            }
            _ => None,
        }
    }

    /// The first NaN of the document, as an error naming its field and line (no fuzzyq
    /// file holds one: a NaN is damage).
    pub(crate) fn find_nan(&self) -> Option<TomlError> {
        fn walk_value(
            text: &str,
            v: &Spanned<DeValue<'_>>,
            path: &mut Vec<String>,
        ) -> Option<TomlError> {
            match v.get_ref() {
                DeValue::Table(t) => walk(text, t, path),
                DeValue::Array(a) => a.iter().enumerate().find_map(|(i, e)| {
                    let last = path.pop().unwrap_or_default();
                    path.push(format!("{last}[{i}]"));
                    let found = walk_value(text, e, path);
                    path.pop();
                    path.push(last);
                    found
                }),
                DeValue::Float(f) if f.as_str().trim_start_matches(['+', '-']) == "nan" => {
                    Some(TomlError {
                        field: Some(path.join(".")),
                        line: Some(line_at(text, v.span().start)),
                        message: "value is NaN".into(),
                    })
                }
                _ => None,
            }
        }
        fn walk(text: &str, t: &DeTable<'_>, path: &mut Vec<String>) -> Option<TomlError> {
            t.iter().find_map(|(k, v)| {
                path.push(key_text(k.get_ref()));
                let found = walk_value(text, v, path);
                path.pop();
                found
            })
        }
        walk(self.text, self.root.get_ref(), &mut Vec::new())
    }

    /// The path (dotted segments) and value of the innermost key or value at byte `offset`.
    fn node_at(&self, offset: usize) -> Option<(Vec<String>, &Spanned<DeValue<'i>>)> {
        type Best<'a, 'i> = Option<(Vec<String>, &'a Spanned<DeValue<'i>>)>;
        fn walk<'a, 'i>(
            table: &'a DeTable<'i>,
            offset: usize,
            path: &mut Vec<String>,
            best: &mut Best<'a, 'i>,
        ) {
            for (k, v) in table.iter() {
                path.push(key_text(k.get_ref()));
                walk_value(v, offset, contains(&k.span(), offset), path, best);
                path.pop();
            }
        }
        fn walk_value<'a, 'i>(
            v: &'a Spanned<DeValue<'i>>,
            offset: usize,
            on_key: bool,
            path: &mut Vec<String>,
            best: &mut Best<'a, 'i>,
        ) {
            if (on_key || contains(&v.span(), offset))
                && best.as_ref().is_none_or(|(b, _)| b.len() <= path.len())
            {
                *best = Some((path.clone(), v));
            }
            match v.get_ref() {
                DeValue::Table(t) => walk(t, offset, path, best),
                DeValue::Array(a) => {
                    for (i, e) in a.iter().enumerate() {
                        let last = path.pop().unwrap_or_default();
                        path.push(format!("{last}[{i}]"));
                        walk_value(e, offset, false, path, best);
                        path.pop();
                        path.push(last);
                    }
                }
                _ => {}
            }
        }
        let mut best = None;
        walk(self.root.get_ref(), offset, &mut Vec::new(), &mut best);
        best
    }

    /// The first key or value under `v` (a table) that `hit` accepts, with its path (from
    /// `path`) and the offset of its key or value.
    fn find_under(
        v: &Spanned<DeValue<'i>>,
        path: &mut Vec<String>,
        hit: &dyn Fn(Option<&str>, &DeValue<'i>) -> bool,
    ) -> Option<(Vec<String>, usize)> {
        match v.get_ref() {
            DeValue::Table(t) => t.iter().find_map(|(k, v)| {
                path.push(key_text(k.get_ref()));
                let found = if hit(Some(k.get_ref()), v.get_ref()) {
                    Some((path.clone(), k.span().start))
                } else {
                    Self::find_under(v, path, hit)
                };
                path.pop();
                found
            }),
            DeValue::Array(a) => a.iter().enumerate().find_map(|(i, e)| {
                let last = path.pop().unwrap_or_default();
                path.push(format!("{last}[{i}]"));
                let found = if hit(None, e.get_ref()) {
                    Some((path.clone(), e.span().start))
                } else {
                    Self::find_under(e, path, hit)
                };
                path.pop();
                path.push(last);
                found
            }),
            _ => None,
        }
    }

    /// The error of a table that serde read from a copy without positions (an internally
    /// tagged enum such as `[env.friction]`): the key or value in it that the message quotes
    /// (`unknown field `x``, `invalid type: string "a"`, `invalid length 3`), if any.
    fn within_table(
        v: &Spanned<DeValue<'i>>,
        path: &[String],
        message: &str,
    ) -> Option<(Vec<String>, usize)> {
        let quoted = |before: &str, open: char, close: char| {
            let rest = &message[message.find(before)? + before.len()..];
            let rest = rest.strip_prefix(open)?;
            Some(rest[..rest.find(close)?].to_string())
        };
        let find = |hit: &dyn Fn(Option<&str>, &DeValue<'i>) -> bool| {
            Self::find_under(v, &mut path.to_vec(), hit)
        };
        for what in ["unknown field ", "duplicate field "] {
            if let Some(name) = quoted(what, '`', '`') {
                return find(&|k, _| k == Some(name.as_str()));
            }
        }
        if let Some(name) = quoted("unknown variant ", '`', '`') {
            return find(&|_, v| v.as_str() == Some(name.as_str()));
        }
        if let Some(n) = message
            .strip_prefix("invalid length ")
            .and_then(|r| r.split(',').next())
            .and_then(|n| n.parse::<usize>().ok())
        {
            return find(&|_, v| matches!(v, DeValue::Array(a) if a.len() == n));
        }
        let unexpected = message
            .strip_prefix("invalid type: ")
            .or_else(|| message.strip_prefix("invalid value: "))?;
        if let Some(text) = unexpected.strip_prefix("string ") {
            return find(&|_, v| {
                v.as_str()
                    .is_some_and(|s| text.starts_with(&format!("{s:?}")))
            });
        }
        let (kind, rest) = unexpected.split_once(" `")?;
        let written = rest.split('`').next()?;
        let kind = kind.to_string();
        find(&|_, v| match v {
            DeValue::Integer(i) => {
                kind == "integer" && i.as_str().replace('_', "") == written.trim_start_matches('+')
            }
            DeValue::Float(f) => {
                kind == "floating point"
                    && f.as_str().replace('_', "").parse::<f64>().ok()
                        == written.parse::<f64>().ok()
            }
            DeValue::Boolean(b) => kind == "boolean" && b.to_string() == written,
            _ => false,
        })
    }

    /// The line of the key or value at `field` (`env.mass`, `obstacle[1]`, `grid.cores[2]`),
    /// if the document has it.
    pub(crate) fn line_of(&self, field: &str) -> Option<usize> {
        self.value_of(field)
            .map(|(span, _)| line_at(self.text, span.start))
    }

    /// The value at `field` (as for [`line_of`](Self::line_of)) with the span of its key (of
    /// itself for an array element).
    fn value_of(&self, field: &str) -> Option<(std::ops::Range<usize>, &Spanned<DeValue<'i>>)> {
        let mut value: Option<&Spanned<DeValue<'i>>> = None;
        let mut table = self.root.get_ref();
        let mut span = None;
        for part in field.split('.') {
            let (key, indices) = part.split_once('[').unwrap_or((part, ""));
            if let Some(v) = value {
                let DeValue::Table(t) = v.get_ref() else {
                    return None;
                };
                table = t;
            }
            let (k, v) = table.get_key_value(key)?;
            span = Some(k.span());
            let mut v = v;
            if !indices.is_empty() {
                for index in indices.split('[') {
                    let i: usize = index.trim_end_matches(']').parse().ok()?;
                    let DeValue::Array(a) = v.get_ref() else {
                        return None;
                    };
                    v = a.get(i)?;
                    span = Some(v.span());
                }
            }
            value = Some(v);
        }
        Some((span?, value?))
    }

    /// `e` with the line of its field appended to its reason, trying the field under each
    /// of `prefixes` (`"env."` for a field named `arena.x` in a configuration).
    pub(crate) fn locate(&self, e: ConfigError, prefixes: &[&str]) -> ConfigError {
        match e {
            ConfigError::Invalid { field, reason } => {
                let line = prefixes
                    .iter()
                    .find_map(|p| self.line_of(&format!("{p}{field}")));
                let reason = one_line(&reason);
                ConfigError::Invalid {
                    reason: match line {
                        Some(line) => format!("{reason} (line {line})"),
                        None => reason,
                    },
                    field: one_line(&field),
                }
            }
            ConfigError::Parse(m) => ConfigError::Parse(one_line(&m)),
        }
    }
}
