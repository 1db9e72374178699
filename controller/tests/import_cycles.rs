//! No import circle of more than two files in the controller's source.
//!
//! The test reads `controller/src/**/*.rs`, takes every path a file names inside the crate (`use
//! crate::...`, `use super::...`, `use self::...`, a child module's `use child::...`, and inline paths
//! such as `crate::safety::ControlFault` in code), resolves each to the file that defines the item
//! (following the `pub use` re-exports of a module root, `lib.rs` or `mod.rs`, which are the crate's
//! and a folder's facade rather than dependencies of their own code) and fails naming the files and
//! the paths of every strongly connected component of the file graph larger than two files. Comments
//! and string literals are not code, so a doc link or a message naming a module adds no edge.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The largest import circle allowed: two files that name each other (a type and its tests' helper,
/// a folder's root and one of its parts).
const MAX_CIRCLE_FILES: usize = 2;

/// One dependency of a file: the file it names and where.
#[derive(Debug, Clone)]
struct Evidence {
    line: usize,
    path: String,
}

/// A token of the code with comments and literals removed, and its line.
#[derive(Debug, Clone, PartialEq)]
struct Token {
    text: String,
    line: usize,
}

/// One leaf of a `use` tree: its full path as written, whether it ends in `*`, and the name it binds.
#[derive(Debug, Clone)]
struct UseLeaf {
    segments: Vec<String>,
    glob: bool,
    name: Option<String>,
}

/// A file of the crate: its module path (`["cycle", "action"]`), whether it is a module root, its
/// tokens, and its child modules declared with `mod name;`.
struct SourceFile {
    rel: String,
    module: Vec<String>,
    root: bool,
    tokens: Vec<Token>,
}

/// A `use` leaf with its line, the module of its place, and whether it is a top-level `pub use`.
type PlacedUse = (UseLeaf, usize, Vec<String>, bool);
/// An inline path's segments with its line and the module of its place.
type PlacedPath = (Vec<String>, usize, Vec<String>);

/// The module graph: file index to the files it names, with the first place that names each.
type Graph = Vec<BTreeMap<usize, Evidence>>;

/// The code of `text` as tokens: identifiers, `::` and single punctuation characters. Comments, string
/// and character literals are skipped (lifetimes are kept apart from character literals).
fn tokens(text: &str) -> Vec<Token> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut line = 1;
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let next = chars.get(i + 1).copied();
        if c == '\n' {
            line += 1;
            i += 1;
        } else if c.is_whitespace() {
            i += 1;
        } else if c == '/' && next == Some('/') {
            while i < chars.len() && chars[i] != '\n' {
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0usize;
            while i < chars.len() {
                if chars[i] == '/' && chars.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if chars[i] == '*' && chars.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    line += usize::from(chars[i] == '\n');
                    i += 1;
                }
            }
        } else if c == '"' || ((c == 'r' || c == 'b') && raw_string_start(&chars, i).is_some()) {
            i = skip_string(&chars, i, &mut line);
        } else if c == '\'' {
            // A character literal closes within a few characters; a lifetime does not.
            let close = if next == Some('\\') {
                (i + 2..chars.len().min(i + 12)).find(|&j| chars[j] == '\'')
            } else {
                (chars.get(i + 2) == Some(&'\'')).then_some(i + 2)
            };
            match close {
                Some(j) => i = j + 1,
                None => i += 1,
            }
        } else if c.is_alphanumeric() || c == '_' {
            let start = i;
            while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '_') {
                i += 1;
            }
            out.push(Token {
                text: chars[start..i].iter().collect(),
                line,
            });
        } else if c == ':' && next == Some(':') {
            out.push(Token {
                text: "::".into(),
                line,
            });
            i += 2;
        } else {
            out.push(Token {
                text: c.to_string(),
                line,
            });
            i += 1;
        }
    }
    out
}

/// The number of `#` of a raw string (`r"`, `r#"`, `br"`) starting at `i`, if one starts there.
fn raw_string_start(chars: &[char], i: usize) -> Option<usize> {
    let mut j = i;
    if chars.get(j) == Some(&'b') {
        j += 1;
    }
    if chars.get(j) != Some(&'r') {
        return None;
    }
    j += 1;
    let hashes = chars[j..].iter().take_while(|&&c| c == '#').count();
    (chars.get(j + hashes) == Some(&'"')).then_some(hashes)
}

/// The index after the string literal (plain, byte or raw) starting at `i`.
fn skip_string(chars: &[char], i: usize, line: &mut usize) -> usize {
    if let Some(hashes) = raw_string_start(chars, i) {
        let mut j = i + chars[i..].iter().position(|&c| c == '"').unwrap_or(0) + 1;
        while j < chars.len() {
            if chars[j] == '"'
                && chars[j + 1..]
                    .iter()
                    .take(hashes)
                    .filter(|&&c| c == '#')
                    .count()
                    == hashes
            {
                return j + 1 + hashes;
            }
            *line += usize::from(chars[j] == '\n');
            j += 1;
        }
        return j;
    }
    let mut j = i + 1;
    while j < chars.len() && chars[j] != '"' {
        if chars[j] == '\\' {
            j += 1;
        }
        if chars.get(j) == Some(&'\n') {
            *line += 1;
        }
        j += 1;
    }
    j + 1
}

fn is_ident(text: &str) -> bool {
    text.chars()
        .next()
        .is_some_and(|c| c.is_alphabetic() || c == '_')
}

/// Parses the `use` tree at `tokens[*i]` under `prefix` into its leaves; stops after the tree.
fn use_tree(toks: &[Token], i: &mut usize, prefix: Vec<String>, out: &mut Vec<UseLeaf>) {
    let mut segments = prefix;
    while let Some(tok) = toks.get(*i) {
        match tok.text.as_str() {
            "::" => *i += 1,
            "{" => {
                *i += 1;
                while let Some(tok) = toks.get(*i) {
                    match tok.text.as_str() {
                        "}" => {
                            *i += 1;
                            return;
                        }
                        "," => *i += 1,
                        _ => use_tree(toks, i, segments.clone(), out),
                    }
                }
                return;
            }
            "*" => {
                *i += 1;
                out.push(UseLeaf {
                    segments,
                    glob: true,
                    name: None,
                });
                return;
            }
            text if is_ident(text) => {
                segments.push(text.to_string());
                *i += 1;
                if toks.get(*i).is_some_and(|t| t.text == "::") {
                    continue;
                }
                if segments.last().is_some_and(|s| s == "self") {
                    segments.pop();
                }
                let mut name = segments.last().cloned();
                if toks.get(*i).is_some_and(|t| t.text == "as") {
                    name = toks.get(*i + 1).map(|t| t.text.clone());
                    *i += 2;
                }
                out.push(UseLeaf {
                    segments,
                    glob: false,
                    name,
                });
                return;
            }
            _ => return,
        }
    }
}

/// Every `.rs` file under `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry.expect("directory entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// The crate's files under `src` with their module paths.
fn load(src: &Path) -> Vec<SourceFile> {
    rust_files(src)
        .into_iter()
        .map(|path| {
            let rel = path
                .strip_prefix(src)
                .expect("under src")
                .to_string_lossy()
                .replace('\\', "/");
            let mut module: Vec<String> = rel
                .trim_end_matches(".rs")
                .split('/')
                .map(String::from)
                .collect();
            let root = matches!(
                module.last().map(String::as_str),
                Some("lib" | "mod" | "main")
            );
            if root {
                module.pop();
            }
            let text = std::fs::read_to_string(&path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            SourceFile {
                rel,
                module,
                root,
                tokens: tokens(&text),
            }
        })
        .collect()
}

/// A path as written at a place whose module is `here`, made absolute within the crate; `None` for
/// paths outside it (other crates, `std`).
fn absolute(
    segments: &[String],
    here: &[String],
    modules: &BTreeMap<Vec<String>, usize>,
) -> Option<Vec<String>> {
    let first = segments.first()?;
    match first.as_str() {
        "crate" => Some(segments[1..].to_vec()),
        "self" => Some(here.iter().chain(&segments[1..]).cloned().collect()),
        "super" => {
            let ups = segments.iter().take_while(|s| *s == "super").count();
            let base = here.get(..here.len().checked_sub(ups)?)?;
            Some(base.iter().chain(&segments[ups..]).cloned().collect())
        }
        _ => {
            let child: Vec<String> = here.iter().chain(std::iter::once(first)).cloned().collect();
            modules
                .contains_key(&child)
                .then(|| here.iter().chain(segments).cloned().collect())
        }
    }
}

/// The crate's module graph over `files`.
fn graph(files: &[SourceFile]) -> Graph {
    let modules: BTreeMap<Vec<String>, usize> = files
        .iter()
        .enumerate()
        .map(|(i, f)| (f.module.clone(), i))
        .collect();
    // Per file: its uses (leaf, line, module of the place, pub at top level) and inline paths.
    let mut uses: Vec<Vec<PlacedUse>> = Vec::new();
    let mut inline: Vec<Vec<PlacedPath>> = Vec::new();
    for file in files {
        let toks = &file.tokens;
        let (mut file_uses, mut file_inline) = (Vec::new(), Vec::new());
        let mut depth = 0usize;
        // Inline modules (`mod tests { ... }`) open at a brace depth; `super` inside them is relative.
        let mut inline_mods: Vec<(String, usize)> = Vec::new();
        let mut i = 0;
        while i < toks.len() {
            let here: Vec<String> = file
                .module
                .iter()
                .cloned()
                .chain(inline_mods.iter().map(|(n, _)| n.clone()))
                .collect();
            match toks[i].text.as_str() {
                "{" => {
                    depth += 1;
                    i += 1;
                }
                "}" => {
                    if inline_mods.last().is_some_and(|&(_, d)| d == depth) {
                        inline_mods.pop();
                    }
                    depth = depth.saturating_sub(1);
                    i += 1;
                }
                "mod" if toks.get(i + 2).is_some_and(|t| t.text == "{") => {
                    inline_mods.push((toks[i + 1].text.clone(), depth + 1));
                    i += 2;
                }
                "use" => {
                    let public = i > 0
                        && (toks[i - 1].text == "pub"
                            || (toks[i - 1].text == ")" && i >= 4 && toks[i - 4].text == "pub"));
                    let line = toks[i].line;
                    i += 1;
                    let mut leaves = Vec::new();
                    use_tree(toks, &mut i, Vec::new(), &mut leaves);
                    let top = public && inline_mods.is_empty() && depth == 0;
                    file_uses.extend(
                        leaves
                            .into_iter()
                            .map(|leaf| (leaf, line, here.clone(), top)),
                    );
                }
                "crate" | "super" | "self"
                    if toks.get(i + 1).is_some_and(|t| t.text == "::")
                        && (i == 0 || toks[i - 1].text != "::") =>
                {
                    let line = toks[i].line;
                    let mut segments = vec![toks[i].text.clone()];
                    i += 1;
                    while toks.get(i).is_some_and(|t| t.text == "::")
                        && toks.get(i + 1).is_some_and(|t| is_ident(&t.text))
                    {
                        segments.push(toks[i + 1].text.clone());
                        i += 2;
                    }
                    file_inline.push((segments, line, here));
                }
                _ => i += 1,
            }
        }
        uses.push(file_uses);
        inline.push(file_inline);
    }
    // The re-exports of each module root: name to absolute path.
    let reexports: Vec<BTreeMap<String, Vec<String>>> = files
        .iter()
        .zip(&uses)
        .map(|(file, file_uses)| {
            file_uses
                .iter()
                .filter(|(leaf, _, _, top)| *top && file.root && !leaf.glob)
                .filter_map(|(leaf, _, here, _)| {
                    Some((
                        leaf.name.clone()?,
                        absolute(&leaf.segments, here, &modules)?,
                    ))
                })
                .collect()
        })
        .collect();
    let resolve = |abs: &[String]| -> Option<usize> {
        let mut abs = abs.to_vec();
        for _ in 0..16 {
            let (len, &file) = (0..=abs.len())
                .rev()
                .find_map(|n| modules.get(&abs[..n]).map(|f| (n, f)))?;
            match abs.get(len).and_then(|name| reexports[file].get(name)) {
                Some(target) => abs = target.iter().chain(&abs[len + 1..]).cloned().collect(),
                None => return Some(file),
            }
        }
        None
    };
    let mut edges: Graph = vec![BTreeMap::new(); files.len()];
    for (from, file) in files.iter().enumerate() {
        let named = uses[from]
            .iter()
            .filter(|(_, _, _, top)| !(file.root && *top))
            .map(|(leaf, line, here, _)| (leaf.segments.clone(), *line, here.clone()))
            .chain(inline[from].iter().cloned());
        for (segments, line, here) in named {
            let Some(to) = absolute(&segments, &here, &modules).and_then(|abs| resolve(&abs))
            else {
                continue;
            };
            if to != from {
                edges[from].entry(to).or_insert(Evidence {
                    line,
                    path: segments.join("::"),
                });
            }
        }
    }
    edges
}

/// The strongly connected components of `edges` (Tarjan), each sorted.
fn components(edges: &Graph) -> Vec<Vec<usize>> {
    struct State<'a> {
        edges: &'a Graph,
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on_stack: Vec<bool>,
        stack: Vec<usize>,
        next: usize,
        out: Vec<Vec<usize>>,
    }
    fn visit(s: &mut State<'_>, v: usize) {
        s.index[v] = Some(s.next);
        s.low[v] = s.next;
        s.next += 1;
        s.stack.push(v);
        s.on_stack[v] = true;
        for &w in s.edges[v].keys() {
            match s.index[w] {
                None => {
                    visit(s, w);
                    s.low[v] = s.low[v].min(s.low[w]);
                }
                Some(iw) if s.on_stack[w] => s.low[v] = s.low[v].min(iw),
                Some(_) => {}
            }
        }
        if Some(s.low[v]) == s.index[v] {
            let mut component = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack[w] = false;
                component.push(w);
                if w == v {
                    break;
                }
            }
            component.sort_unstable();
            s.out.push(component);
        }
    }
    let n = edges.len();
    let mut s = State {
        edges,
        index: vec![None; n],
        low: vec![0; n],
        on_stack: vec![false; n],
        stack: Vec::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in 0..n {
        if s.index[v].is_none() {
            visit(&mut s, v);
        }
    }
    s.out
}

/// Each import circle of more than [`MAX_CIRCLE_FILES`] files under `src`, as its files and the
/// paths that join them.
fn circles(src: &Path) -> Vec<String> {
    let files = load(src);
    let edges = graph(&files);
    components(&edges)
        .into_iter()
        .filter(|c| c.len() > MAX_CIRCLE_FILES)
        .map(|component| {
            let members: BTreeSet<usize> = component.iter().copied().collect();
            let names: Vec<&str> = component.iter().map(|&f| files[f].rel.as_str()).collect();
            let mut text = format!("{} files: {}", component.len(), names.join(", "));
            for &from in &component {
                for (to, e) in edges[from].iter().filter(|(to, _)| members.contains(to)) {
                    text += &format!(
                        "\n  {}:{} -> {} ({})",
                        files[from].rel, e.line, files[*to].rel, e.path
                    );
                }
            }
            text
        })
        .collect()
}

#[test]
fn controller_has_no_import_circle_of_more_than_two_files() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let found = circles(&src);
    assert!(
        found.is_empty(),
        "import circles in {}:\n{}",
        src.display(),
        found.join("\n")
    );
}

/// Writes `files` (path under src, text) to a fresh crate folder and returns it.
fn fixture(files: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temp dir");
    for (rel, text) in files {
        let path = dir.path().join(rel);
        std::fs::create_dir_all(path.parent().expect("parent")).expect("create folder");
        std::fs::write(path, text).expect("write fixture");
    }
    dir
}

const FIXTURE_LIB: &str = "pub mod a;\npub mod b;\npub mod c;\npub mod f;\npub use a::A;\n";

#[test]
fn a_three_file_circle_through_a_root_reexport_and_an_inline_path_is_named() {
    let dir = fixture(&[
        ("lib.rs", FIXTURE_LIB),
        ("a.rs", "use crate::b::B;\npub struct A;\n"),
        ("b.rs", "pub struct B;\nfn g() -> u32 { crate::c::C }\n"),
        ("c.rs", "use crate::{A, f::F};\npub const C: u32 = 1;\n"),
        ("f/mod.rs", "mod inner;\npub use inner::F;\n"),
        ("f/inner.rs", "pub struct F;\n"),
    ]);
    let found = circles(dir.path());
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(
        found[0].starts_with("3 files: a.rs, b.rs, c.rs"),
        "{}",
        found[0]
    );
    assert!(
        found[0].contains("b.rs:2 -> c.rs (crate::c::C)"),
        "{}",
        found[0]
    );
    assert!(
        found[0].contains("c.rs:1 -> a.rs (crate::A)"),
        "{}",
        found[0]
    );
}

#[test]
fn two_files_naming_each_other_and_paths_in_comments_strings_and_tests_are_allowed() {
    let dir = fixture(&[
        ("lib.rs", FIXTURE_LIB),
        (
            "a.rs",
            "use crate::b::B;\npub struct A;\n#[cfg(test)]\nmod tests {\n    use super::*;\n}\n",
        ),
        ("b.rs", "use super::a::A;\npub struct B;\n"),
        (
            "c.rs",
            "/// Names [`crate::a`] in a doc link.\nconst S: &str = \"crate::b::B\";\nconst R: &str = r#\"crate::a\"#;\n",
        ),
        (
            "f/mod.rs",
            "mod inner;\npub use inner::F;\nfn h() -> char { 'c' }\n",
        ),
        (
            "f/inner.rs",
            "/* crate::c */ pub struct F<'a>(&'a str);\nuse super::super::c;\n",
        ),
    ]);
    assert_eq!(circles(dir.path()), Vec::<String>::new());
    let dir = fixture(&[
        ("lib.rs", FIXTURE_LIB),
        ("a.rs", "pub struct A;\n"),
        ("b.rs", "pub struct B;\n"),
        ("c.rs", "pub const C: u32 = 1;\n"),
        (
            "f/mod.rs",
            "mod inner;\npub use inner::F;\nuse crate::c::C;\n",
        ),
        ("f/inner.rs", "pub struct F;\nuse crate::a::A;\n"),
    ]);
    assert_eq!(circles(dir.path()), Vec::<String>::new());
}
