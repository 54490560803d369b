//! Reads source files and follows `use`: each module is loaded once, the prelude first.
//! `use a::b` from a file in directory D looks for `D/a/b.sph`, then `<stdlib>/a/b.sph`.

use crate::diag::{Diagnostic, Sources, Span};
use crate::syntax::ast::{self, Ident};
use crate::syntax::ast::{File, Item, UsePath};
use crate::syntax::parse_file;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

mod embedded {
    include!(concat!(env!("OUT_DIR"), "/stdlib_files.rs"));
}

/// Where the stdlib comes from: a directory on disk (so edits show without a rebuild), or the copy
/// embedded in the binary.
#[derive(Clone, Debug)]
pub enum Stdlib {
    Dir(PathBuf),
    Embedded,
}

impl Stdlib {
    /// The file of a stdlib module named as a case or `use` names it: `models::elastic_solid` →
    /// `models/elastic_solid.sph`.
    pub fn file_of(name: &str) -> String {
        name.replace("::", "/") + ".sph"
    }

    /// Every stdlib module by its name (`models::elastic_solid`).
    pub fn module_names(&self) -> Vec<String> {
        self.modules().iter().map(|m| m.trim_end_matches(".sph").replace('/', "::")).collect()
    }

    /// `$PAIRSUM_STDLIB`, else the source tree's `stdlib/` when it exists, else the embedded copy.
    pub fn locate() -> Stdlib {
        if let Some(dir) = &crate::config::env().stdlib {
            return Stdlib::Dir(dir.clone());
        }
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("stdlib");
        if dir.join("prelude.sph").is_file() {
            Stdlib::Dir(dir)
        } else {
            Stdlib::Embedded
        }
    }

    fn read(&self, rel: &str) -> Option<(String, String)> {
        match self {
            Stdlib::Dir(d) => {
                // Only a regular file: a name such as `use "/dev/zero"` must not read forever.
                let p = d.join(rel);
                if !p.is_file() {
                    return None;
                }
                let text = std::fs::read_to_string(&p).ok()?;
                Some((key_of(&p), text))
            }
            Stdlib::Embedded => embedded::STDLIB_FILES
                .iter()
                .find(|(r, _)| *r == rel)
                .map(|(r, t)| (format!("<stdlib>/{r}"), t.to_string())),
        }
    }

    fn display(&self, rel: &str) -> String {
        match self {
            Stdlib::Dir(d) => display_path(&d.join(rel)),
            Stdlib::Embedded => format!("<stdlib>/{rel}"),
        }
    }

    /// Every stdlib module path (`solid/jaumann.sph`).
    pub fn modules(&self) -> Vec<String> {
        match self {
            Stdlib::Embedded => embedded::STDLIB_FILES.iter().map(|(r, _)| r.to_string()).collect(),
            Stdlib::Dir(d) => {
                let mut out = vec![];
                walk(d, d, &mut out);
                out.sort();
                out
            }
        }
    }
}

fn walk(dir: &Path, root: &Path, out: &mut Vec<String>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for p in entries.flatten().map(|e| e.path()) {
        if p.is_dir() {
            walk(&p, root, out);
        } else if p.extension().is_some_and(|e| e == "sph") {
            if let Ok(rel) = p.strip_prefix(root) {
                out.push(rel.to_string_lossy().replace('\\', "/"));
            }
        }
    }
}

fn key_of(p: &Path) -> String {
    p.canonicalize().unwrap_or_else(|_| p.to_path_buf()).to_string_lossy().into_owned()
}

/// A path as the user would like to read it: relative to the working directory when inside it.
pub fn display_path(p: &Path) -> String {
    let canon = p.canonicalize().unwrap_or_else(|_| p.to_path_buf());
    if let Ok(cwd) = std::env::current_dir().and_then(|c| c.canonicalize()) {
        if let Ok(rel) = canon.strip_prefix(&cwd) {
            return rel.to_string_lossy().into_owned();
        }
    }
    p.to_string_lossy().into_owned()
}

/// One parsed module.
pub struct Module {
    pub file: u32,
    pub ast: File,
    /// Whether the user named it (rather than it being reached through `use` or the prelude).
    pub root: bool,
    /// The modules it uses, with the groups it restricts them to.
    pub uses: Vec<UseEdge>,
}

/// `use m on G from S`, resolved: m's index among the loaded modules.
pub struct UseEdge {
    pub target: usize,
    pub on: Option<Vec<Ident>>,
    pub from: Option<Vec<Ident>>,
    pub own: bool,
    pub own_body: bool,
    /// The `use` as written, for diagnostics.
    pub span: Span,
}

pub struct Loader<'s> {
    pub sources: &'s mut Sources,
    stdlib: Stdlib,
    /// Modules by identity; `None`: read but did not parse.
    seen: HashMap<String, Option<usize>>,
    pub modules: Vec<Module>,
    pub diags: Vec<Diagnostic>,
}

/// Where a module was found: its identity, its name for messages, its text, and its directory.
struct Found {
    key: String,
    name: String,
    text: String,
    dir: Option<PathBuf>,
}

impl<'s> Loader<'s> {
    pub fn new(sources: &'s mut Sources, stdlib: Stdlib) -> Loader<'s> {
        let mut l = Loader { sources, stdlib, seen: HashMap::new(), modules: vec![], diags: vec![] };
        let _ = l.load_stdlib_module("prelude.sph", None, false);
        l
    }

    /// Loads a file the user named.
    pub fn load_path(&mut self, path: &Path) {
        match std::fs::read_to_string(path) {
            Ok(text) => {
                let found = Found {
                    key: key_of(path),
                    name: display_path(path),
                    text,
                    dir: path.parent().map(Path::to_path_buf),
                };
                let _ = self.add(found, true);
            }
            Err(e) => self.diags.push(Diagnostic::error("E0002", format!("cannot read `{}`: {e}", path.display()))),
        }
    }

    /// Loads source text that has no file (tests, case files' inline models); `use` is resolved
    /// against `dir` and the stdlib.
    pub fn load_text(&mut self, name: &str, text: &str, dir: Option<PathBuf>) {
        let found = Found { key: format!("<text>/{name}"), name: name.to_string(), text: text.to_string(), dir };
        let _ = self.add(found, true);
    }

    /// Loads a stdlib module by its relative path (`solid/jaumann.sph`).
    pub fn load_stdlib_module(&mut self, rel: &str, from: Option<Span>, root: bool) -> Option<usize> {
        match self.stdlib.read(rel) {
            Some((key, text)) => {
                let dir = match &self.stdlib {
                    Stdlib::Dir(d) => d.join(rel).parent().map(Path::to_path_buf),
                    Stdlib::Embedded => None,
                };
                let name = self.stdlib.display(rel);
                self.add(Found { key, name, text, dir }, root)
            }
            None => {
                let mut d = Diagnostic::error("E0003", format!("cannot find stdlib module `{rel}`"));
                if let Some(span) = from {
                    d = d.at(span, "imported here");
                }
                self.diags.push(d);
                None
            }
        }
    }

    /// Loads a module once; its index among the modules (`None` if it does not parse).
    fn add(&mut self, found: Found, root: bool) -> Option<usize> {
        if let Some(known) = self.seen.get(&found.key) {
            if let (true, Some(k)) = (root, known) {
                self.modules[*k].root = true;
            }
            return *known;
        }
        self.seen.insert(found.key.clone(), None);
        let file = self.sources.add(found.name, found.text.clone());
        match parse_file(file, &found.text) {
            Ok(ast) => {
                let uses: Vec<_> = ast
                    .items
                    .iter()
                    .filter_map(|i| match i {
                        Item::Use(u) => Some(u.clone()),
                        _ => None,
                    })
                    .collect();
                let index = self.modules.len();
                self.modules.push(Module { file, ast, root, uses: vec![] });
                self.seen.insert(found.key, Some(index));
                let mut first_use: HashMap<usize, ast::Use> = HashMap::new();
                for u in uses {
                    if let Some(target) = self.resolve_use(&u.path, u.span, found.dir.as_deref()) {
                        match first_use.get(&target) {
                            Some(first) if own_restriction(first) != own_restriction(&u) => {
                                self.diags.push(used_twice(first, &u));
                            }
                            Some(_) => {}
                            None => {
                                first_use.insert(target, u.clone());
                            }
                        }
                        self.modules[index].uses.push(UseEdge {
                            target,
                            on: u.on,
                            from: u.from,
                            own: u.own,
                            own_body: u.own_body,
                            span: u.span,
                        });
                    }
                }
                Some(index)
            }
            Err(d) => {
                self.diags.push(*d);
                None
            }
        }
    }

    fn resolve_use(&mut self, path: &UsePath, span: Span, dir: Option<&Path>) -> Option<usize> {
        let rel = match path {
            UsePath::Module(parts) => parts.iter().map(|p| p.name.as_str()).collect::<Vec<_>>().join("/") + ".sph",
            UsePath::File(f) => f.clone(),
        };
        let mut looked = vec![];
        if let Some(dir) = dir {
            let p = dir.join(&rel);
            if p.is_file() {
                let text = std::fs::read_to_string(&p).unwrap_or_default();
                let found =
                    Found { key: key_of(&p), name: display_path(&p), text, dir: p.parent().map(Path::to_path_buf) };
                return self.add(found, false);
            }
            looked.push(display_path(&p));
        }
        if self.stdlib.read(&rel).is_some() {
            return self.load_stdlib_module(&rel, Some(span), false);
        }
        looked.push(self.stdlib.display(&rel));
        let shown = use_name(path);
        let mut d = Diagnostic::error("E0003", format!("cannot find module `{shown}`"))
            .at(span, "no such module")
            .note(format!("looked for {}", looked.join(" and ")));
        let stem = rel.rsplit('/').next().unwrap_or(&rel).to_string();
        let names = self.stdlib.module_names();
        let candidates: Vec<&str> = names.iter().map(String::as_str).collect();
        if let Some(best) = crate::diag::closest(&shown, candidates.iter().copied()) {
            d = d.help(format!("did you mean `use {best}`?"));
        } else if let Some(m) = names.iter().find(|n| n.ends_with(stem.trim_end_matches(".sph"))) {
            d = d.help(format!("the stdlib has `use {m}`"));
        }
        self.diags.push(d);
        None
    }
}

/// Whether a `use` keeps its module's pair sums to particle i's own group and to its own body.
fn own_restriction(u: &ast::Use) -> (bool, bool) {
    (u.own, u.own_body)
}

/// E0111: one module used twice by one file, once `from own` (or `from own body`) and once not.
/// The groups pair (`on A` beside `on B from S` keeps S to B), but `own` holds for a module's
/// equations on every group or on none.
fn used_twice(first: &ast::Use, second: &ast::Use) -> Diagnostic {
    Diagnostic::error("E0111", format!("`{}` is used twice, once `from own` and once not", use_name(&second.path)))
        .at(second.span, "used again")
        .also(first.span, "first used here")
        .note(
            "`from own` and `from own body` hold for all of a module's equations or for none; write the \
             equations you want on one group in a module of their own",
        )
}

/// A `use`'s module as written: `a::b`, or the file's path.
fn use_name(path: &UsePath) -> String {
    match path {
        UsePath::Module(parts) => parts.iter().map(|p| p.name.as_str()).collect::<Vec<_>>().join("::"),
        UsePath::File(f) => f.clone(),
    }
}
