//! Reading a Mitsuba 3 XML file into plain elements: the XML parse
//! (roxmltree, positions kept), `<default>` and `-D` parameters with `$name`
//! substitution, `<include>` spliced in place, and `<path>` search folders.
//! What comes out is the list of top-level plugin elements, every attribute
//! already substituted, each element knowing its file, line and column.

use crate::{IoError, Result};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// How deep `<include>` may nest (a file including itself is refused first).
const MAX_INCLUDE_DEPTH: usize = 16;

/// How deep elements may nest (scenes nest a few levels; a hostile file's
/// 200,000 levels would overflow the stack of the recursive reading).
const MAX_ELEMENT_DEPTH: usize = 128;

/// A position in a scene file (1-based line and column).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Loc {
    /// The file.
    pub file: Arc<PathBuf>,
    /// 1-based line.
    pub line: usize,
    /// 1-based column.
    pub column: usize,
}

impl Loc {
    /// An error at this position.
    pub fn error(&self, message: impl Into<String>) -> IoError {
        IoError::At {
            path: self.file.as_ref().clone(),
            line: self.line,
            column: self.column,
            message: message.into(),
        }
    }

    /// `file:line:col` for warnings.
    pub fn describe(&self) -> String {
        format!("{}:{}:{}", self.file.display(), self.line, self.column)
    }
}

/// One XML element, parameters substituted.
#[derive(Debug, Clone, PartialEq)]
pub struct Element {
    /// The tag (`shape`, `float`, `transform`, ...).
    pub tag: String,
    /// Attributes in file order.
    pub attrs: Vec<(String, String)>,
    /// Child elements in file order.
    pub children: Vec<Element>,
    /// Where the element starts.
    pub loc: Loc,
}

impl Element {
    /// The attribute `name`, if present.
    pub fn attr(&self, name: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }

    /// The attribute `name`, or an error naming the element.
    pub fn require(&self, name: &str) -> Result<&str> {
        self.attr(name).ok_or_else(|| {
            self.loc
                .error(format!("<{}> needs the attribute `{name}`", self.tag))
        })
    }

    /// `<tag type="...">` as `tag "type"` for messages.
    pub fn plugin_name(&self) -> String {
        match self.attr("type") {
            Some(t) => format!("{} \"{t}\"", self.tag),
            None => self.tag.clone(),
        }
    }
}

/// A parsed scene: the top-level elements and where relative file names
/// are looked for.
#[derive(Debug, Clone, PartialEq)]
pub struct Document {
    /// The scene's plugin elements (shapes, bsdfs, emitters, sensor, ...).
    pub elements: Vec<Element>,
    /// `<path>` folders, most recent first, then the scene file's folder.
    pub search: Vec<PathBuf>,
}

impl Document {
    /// The first existing file `name` in the search folders (an absolute
    /// name as it is); the name under the scene's folder when none exists,
    /// so the read reports the missing file.
    pub fn resolve(&self, name: &str) -> PathBuf {
        let p = Path::new(name);
        if p.is_absolute() {
            return p.to_path_buf();
        }
        for dir in &self.search {
            let candidate = dir.join(p);
            if candidate.exists() {
                return candidate;
            }
        }
        self.search
            .last()
            .map_or_else(|| p.to_path_buf(), |d| d.join(p))
    }
}

/// Reads the scene file `path` with `defines` (`-D name=value`, which win
/// over the file's `<default>`s).
pub fn read_document(path: &Path, defines: &[(String, String)]) -> Result<Document> {
    let text = crate::files::read_text_file(path)?;
    let base = path
        .parent()
        .unwrap_or_else(|| Path::new("."))
        .to_path_buf();
    parse_document(&text, path, &base, defines)
}

/// Parses scene text held in memory; `name` stands for the file in
/// messages and `base` is the folder relative names resolve against.
pub fn parse_document(
    text: &str,
    name: &Path,
    base: &Path,
    defines: &[(String, String)],
) -> Result<Document> {
    let mut state = State {
        params: defines.iter().cloned().collect(),
        fixed: defines.iter().map(|(k, _)| k.clone()).collect(),
        search: Vec::new(),
        stack: Vec::new(),
    };
    let mut elements = Vec::new();
    state.read_text(text, name, base, &mut elements)?;
    let mut search = state.search;
    search.reverse();
    search.push(base.to_path_buf());
    Ok(Document { elements, search })
}

struct State {
    /// Parameter values: `-D` first, then the first `<default>` of each name.
    params: HashMap<String, String>,
    /// Names given on the command line (a `<default>` does not change them).
    fixed: Vec<String>,
    /// `<path>` folders in file order.
    search: Vec<PathBuf>,
    /// The files being read, outermost first (include cycles).
    stack: Vec<PathBuf>,
}

impl State {
    fn read_text(
        &mut self,
        text: &str,
        name: &Path,
        base: &Path,
        out: &mut Vec<Element>,
    ) -> Result<()> {
        let file = Arc::new(name.to_path_buf());
        if let Some(at) = too_deep(text, MAX_ELEMENT_DEPTH) {
            let lines = Lines::new(text, file);
            return Err(lines.loc(at).error(format!(
                "elements nested deeper than {MAX_ELEMENT_DEPTH} levels"
            )));
        }
        let doc = roxmltree::Document::parse(text).map_err(|e| {
            let pos = e.pos();
            IoError::At {
                path: name.to_path_buf(),
                line: pos.row as usize,
                column: pos.col as usize,
                // roxmltree ends its message with the position, given above.
                message: format!(
                    "not well-formed XML: {}",
                    e.to_string()
                        .trim_end_matches(&format!(" at {}:{}", pos.row, pos.col))
                ),
            }
        })?;
        let root = doc.root_element();
        let lines = Lines::new(text, file);
        let loc = lines.of(&root);
        if root.tag_name().name() != "scene" {
            return Err(loc.error(format!(
                "expected <scene> as the root element, found <{}>",
                root.tag_name().name()
            )));
        }
        self.stack.push(name.to_path_buf());
        // Defaults first, so `$name` works above its `<default>` too.
        for node in root.children().filter(|n| n.is_element()) {
            if node.tag_name().name() == "default" {
                let loc = lines.of(&node);
                let key = attr_of(&node, "name", &loc)?;
                let value = attr_of(&node, "value", &loc)?;
                if !self.fixed.iter().any(|f| f == key) && !self.params.contains_key(key) {
                    self.params.insert(key.to_owned(), value.to_owned());
                }
            }
        }
        for node in root.children().filter(|n| n.is_element()) {
            let loc = lines.of(&node);
            match node.tag_name().name() {
                "default" => {}
                "path" => {
                    let value = self.substitute(attr_of(&node, "value", &loc)?, &loc)?;
                    self.search.push(crate::resolve(base, &value));
                }
                "include" => {
                    let value = self.substitute(attr_of(&node, "filename", &loc)?, &loc)?;
                    self.include(&value, base, &loc, out)?;
                }
                _ => out.push(self.element(&lines, &node, 1)?),
            }
        }
        self.stack.pop();
        Ok(())
    }

    fn include(
        &mut self,
        name: &str,
        base: &Path,
        loc: &Loc,
        out: &mut Vec<Element>,
    ) -> Result<()> {
        let mut search: Vec<PathBuf> = self.search.iter().rev().cloned().collect();
        search.push(base.to_path_buf());
        let doc = Document {
            elements: Vec::new(),
            search,
        };
        let path = doc.resolve(name);
        if self.stack.len() >= MAX_INCLUDE_DEPTH {
            return Err(loc.error(format!(
                "<include> nested deeper than {MAX_INCLUDE_DEPTH} files"
            )));
        }
        if self.stack.iter().any(|p| p == &path) {
            return Err(loc.error(format!("<include> of {} includes itself", path.display())));
        }
        let text = crate::files::read_text_file(&path)
            .map_err(|e| loc.error(format!("<include filename=\"{name}\">: {e}")))?;
        let inner_base = path
            .parent()
            .unwrap_or_else(|| Path::new("."))
            .to_path_buf();
        self.read_text(&text, &path, &inner_base, out)
    }

    fn element(&self, lines: &Lines, node: &roxmltree::Node, depth: usize) -> Result<Element> {
        let loc = lines.of(node);
        if depth > MAX_ELEMENT_DEPTH {
            return Err(loc.error(format!(
                "elements nested deeper than {MAX_ELEMENT_DEPTH} levels"
            )));
        }
        let mut attrs = Vec::new();
        for a in node.attributes() {
            attrs.push((a.name().to_owned(), self.substitute(a.value(), &loc)?));
        }
        let mut children = Vec::new();
        for child in node.children().filter(|n| n.is_element()) {
            children.push(self.element(lines, &child, depth + 1)?);
        }
        Ok(Element {
            tag: node.tag_name().name().to_owned(),
            attrs,
            children,
            loc,
        })
    }

    /// `value` with each `$name` replaced by its parameter; an unknown name
    /// is an error at `loc`.
    fn substitute(&self, value: &str, loc: &Loc) -> Result<String> {
        substitute(value, &self.params).map_err(|name| {
            loc.error(format!(
                "parameter `${name}` has no value: add <default name=\"{name}\" value=\"...\"/> or pass -D {name}=..."
            ))
        })
    }
}

/// The byte offset of the first start tag nested deeper than `max`, by a
/// scan of the tags alone (comments, CDATA, declarations and quoted
/// attribute values skipped), or `None`. roxmltree parses nesting by
/// recursion, so a hostile file's 20,000 levels overflow the stack before
/// any element is seen: this bound comes first.
fn too_deep(text: &str, max: usize) -> Option<usize> {
    let b = text.as_bytes();
    let mut depth = 0usize;
    let mut i = 0;
    while i < b.len() {
        if b[i] != b'<' {
            i += 1;
            continue;
        }
        let rest = &b[i..];
        // Skip to the end of constructs that are not elements.
        let skip_to = |end: &[u8]| {
            rest.windows(end.len())
                .position(|w| w == end)
                .map_or(b.len(), |k| i + k + end.len())
        };
        if rest.starts_with(b"<!--") {
            i = skip_to(b"-->");
        } else if rest.starts_with(b"<![CDATA[") {
            i = skip_to(b"]]>");
        } else if rest.starts_with(b"<?") {
            i = skip_to(b"?>");
        } else if rest.starts_with(b"<!") {
            i = skip_to(b">");
        } else if rest.starts_with(b"</") {
            depth = depth.saturating_sub(1);
            i = skip_to(b">");
        } else {
            // A start tag: find its `>` outside quotes; `/>` closes it.
            let start = i;
            let mut quote = None;
            let mut j = i + 1;
            while j < b.len() {
                match (quote, b[j]) {
                    (None, q @ (b'"' | b'\'')) => quote = Some(q),
                    (Some(q), c) if c == q => quote = None,
                    (None, b'>') => break,
                    _ => {}
                }
                j += 1;
            }
            if j >= b.len() || b[j - 1] != b'/' {
                depth += 1;
                if depth > max {
                    return Some(start);
                }
            }
            i = j + 1;
        }
    }
    None
}

/// `value` with every `$name` (`[A-Za-z_][A-Za-z0-9_]*`) replaced from
/// `params`; `Err(name)` for the first name without a value. A `$` not
/// followed by a name stays as it is.
pub fn substitute(
    value: &str,
    params: &HashMap<String, String>,
) -> std::result::Result<String, String> {
    let mut out = String::with_capacity(value.len());
    let mut rest = value;
    while let Some(i) = rest.find('$') {
        out.push_str(&rest[..i]);
        let after = &rest[i + 1..];
        let len = after
            .char_indices()
            .find(|&(k, c)| !(c == '_' || c.is_ascii_alphabetic() || (k > 0 && c.is_ascii_digit())))
            .map_or(after.len(), |(k, _)| k);
        if len == 0 {
            out.push('$');
            rest = after;
            continue;
        }
        let name = &after[..len];
        match params.get(name) {
            Some(v) => out.push_str(v),
            None => return Err(name.to_owned()),
        }
        rest = &after[len..];
    }
    out.push_str(rest);
    Ok(out)
}

/// The start of each line of a text, to turn byte offsets into positions
/// without rescanning the text for every element.
struct Lines<'t> {
    text: &'t str,
    starts: Vec<usize>,
    file: Arc<PathBuf>,
}

impl<'t> Lines<'t> {
    fn new(text: &'t str, file: Arc<PathBuf>) -> Self {
        let mut starts = vec![0];
        starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
        Self { text, starts, file }
    }

    /// The 1-based line and column (in characters) of byte offset `at`.
    fn loc(&self, at: usize) -> Loc {
        let line = self.starts.partition_point(|&s| s <= at).max(1);
        let start = self.starts[line - 1];
        let column = self
            .text
            .get(start..at)
            .map_or(1, |s| s.chars().count() + 1);
        Loc {
            file: self.file.clone(),
            line,
            column,
        }
    }

    fn of(&self, node: &roxmltree::Node) -> Loc {
        self.loc(node.range().start)
    }
}

fn attr_of<'a>(node: &roxmltree::Node<'a, 'a>, name: &str, loc: &Loc) -> Result<&'a str> {
    node.attribute(name).ok_or_else(|| {
        loc.error(format!(
            "<{}> needs the attribute `{name}`",
            node.tag_name().name()
        ))
    })
}
