//! The code's shape, read from its source with syn: no function over 150 lines outside
//! tests, no file of the engine (core) over 600 lines, and no import circle through more
//! than two files of a crate. A long function hides its phases, a long file its modules,
//! and a circle of imports makes a set of files one module that can only be read whole.
//!
//! An import is what a file's `use` items and paths name, resolved through the crate's
//! modules, `use` aliases and glob imports to the file that defines the item. A re-export
//! (`pub use`) that the file does not itself mention is not an import of that file: a
//! `lib.rs` that lists a crate's API depends on nothing it lists.

use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::path::{Path, PathBuf};

use syn::visit::Visit;

use crate::support::root;

/// Longest function body, in lines from `fn` to the closing brace.
const MAX_FUNCTION_LINES: usize = 150;
/// Longest file of the engine.
const MAX_CORE_FILE_LINES: usize = 600;
/// Most files one import circle may pass through (a module and its child may use each
/// other).
const MAX_CIRCLE_FILES: usize = 2;

/// Every crate root of the workspace's shipped code: each member's `src/lib.rs` and
/// `src/main.rs`. Test fixtures are tests.
fn crate_roots() -> Vec<PathBuf> {
    let root = root();
    let manifest: toml::Table =
        toml::from_str(&std::fs::read_to_string(root.join("Cargo.toml")).expect("Cargo.toml"))
            .expect("Cargo.toml is TOML");
    let members = manifest["workspace"]["members"]
        .as_array()
        .expect("workspace.members");
    let mut dirs = vec![root.to_path_buf()];
    for member in members {
        let member = member.as_str().expect("a member is a path");
        if member.starts_with("tests/") {
            continue;
        }
        match member.strip_suffix("/*") {
            Some(parent) => {
                for entry in std::fs::read_dir(root.join(parent)).expect(parent) {
                    let dir = entry.expect("entry").path();
                    if dir.join("Cargo.toml").exists() {
                        dirs.push(dir);
                    }
                }
            }
            None => dirs.push(root.join(member)),
        }
    }
    let mut roots: Vec<PathBuf> = dirs
        .iter()
        .flat_map(|d| [d.join("src/lib.rs"), d.join("src/main.rs")])
        .filter(|p| p.exists())
        .collect();
    roots.sort();
    roots
}

/// Whether attributes mark test-only code: `#[test]` or `#[cfg(test)]`.
pub(crate) fn is_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("test")
            || (a.path().is_ident("cfg")
                && a.parse_args::<syn::Meta>()
                    .is_ok_and(|m| m.path().is_ident("test")))
    })
}

/// One `use` leaf: the name it brings into scope and the path it names.
#[derive(Debug)]
struct Use {
    alias: String,
    path: Vec<String>,
    glob: bool,
    public: bool,
}

fn flatten_use(tree: &syn::UseTree, prefix: &mut Vec<String>, public: bool, out: &mut Vec<Use>) {
    match tree {
        syn::UseTree::Path(p) => {
            prefix.push(p.ident.to_string());
            flatten_use(&p.tree, prefix, public, out);
            prefix.pop();
        }
        syn::UseTree::Name(n) => {
            let name = n.ident.to_string();
            let (alias, path) = if name == "self" {
                (prefix.last().cloned().unwrap_or_default(), prefix.clone())
            } else {
                (name.clone(), [prefix.as_slice(), &[name]].concat())
            };
            out.push(Use {
                alias,
                path,
                glob: false,
                public,
            });
        }
        syn::UseTree::Rename(r) => {
            let name = r.ident.to_string();
            let path = if name == "self" {
                prefix.clone()
            } else {
                [prefix.as_slice(), &[name]].concat()
            };
            out.push(Use {
                alias: r.rename.to_string(),
                path,
                glob: false,
                public,
            });
        }
        syn::UseTree::Glob(_) => out.push(Use {
            alias: String::new(),
            path: prefix.clone(),
            glob: true,
            public,
        }),
        syn::UseTree::Group(g) => {
            for t in &g.items {
                flatten_use(t, prefix, public, out);
            }
        }
    }
}

/// A module of a crate: the file it is written in, what it defines and imports, and the
/// paths its code names.
#[derive(Default)]
struct Module {
    file: usize,
    children: HashSet<String>,
    defs: HashSet<String>,
    uses: Vec<Use>,
    paths: Vec<Vec<String>>,
}

/// Collects the paths and identifiers that code names, outside `use` items, nested
/// modules and tests.
#[derive(Default)]
struct Names {
    paths: Vec<Vec<String>>,
    idents: HashSet<String>,
}

impl<'ast> Visit<'ast> for Names {
    fn visit_item_use(&mut self, _: &'ast syn::ItemUse) {}
    fn visit_item_mod(&mut self, _: &'ast syn::ItemMod) {}
    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        if !is_test(&f.attrs) {
            syn::visit::visit_item_fn(self, f);
        }
    }
    fn visit_path(&mut self, p: &'ast syn::Path) {
        let segments: Vec<String> = p.segments.iter().map(|s| s.ident.to_string()).collect();
        self.idents.extend(segments.iter().cloned());
        self.paths.push(segments);
        syn::visit::visit_path(self, p);
    }
    fn visit_macro(&mut self, m: &'ast syn::Macro) {
        // A macro's tokens are not parsed: its identifiers still name what it uses
        // (`format!("{}", Layer::EMPTY)` or a `vec![Kind::A]`).
        let mut tokens: Vec<String> = Vec::new();
        collect_idents(m.tokens.clone(), &mut tokens);
        for (i, token) in tokens.iter().enumerate() {
            self.paths.push(tokens[i..(i + 2).min(tokens.len())].to_vec());
            self.paths.push(vec![token.clone()]);
        }
        self.idents.extend(tokens);
        syn::visit::visit_macro(self, m);
    }
}

fn collect_idents(tokens: proc_macro2::TokenStream, out: &mut Vec<String>) {
    for t in tokens {
        match t {
            proc_macro2::TokenTree::Ident(i) => out.push(i.to_string()),
            proc_macro2::TokenTree::Group(g) => collect_idents(g.stream(), out),
            _ => {}
        }
    }
}

/// A crate read whole: its files and its modules by path.
struct CrateSource {
    files: Vec<PathBuf>,
    /// Identifiers each file's code names (outside `use` items).
    idents: Vec<HashSet<String>>,
    modules: HashMap<Vec<String>, Module>,
    /// Names looked up in modules' scopes, by module and name.
    looked_up: RefCell<HashMap<(Vec<String>, String), Lookup>>,
}

/// What a name in a module's scope was found to be: `None` for nothing of the crate.
type Lookup = Option<Target>;

/// What a path names inside the crate.
#[derive(Debug, Clone)]
enum Target {
    Module(Vec<String>),
    /// An item, by the file that defines it.
    Item(usize),
}

impl CrateSource {
    fn read(root: &Path) -> CrateSource {
        let mut krate = CrateSource {
            files: Vec::new(),
            idents: Vec::new(),
            modules: HashMap::new(),
            looked_up: RefCell::new(HashMap::new()),
        };
        let ast = parse(root);
        krate.files.push(root.to_path_buf());
        krate.idents.push(HashSet::new());
        krate.add_module(Vec::new(), 0, root, true, &ast.items);
        krate
    }

    fn add_module(
        &mut self,
        path: Vec<String>,
        file: usize,
        file_path: &Path,
        owns_dir: bool,
        items: &[syn::Item],
    ) {
        let mut module = Module {
            file,
            ..Module::default()
        };
        let mut names = Names::default();
        for item in items {
            match item {
                syn::Item::Mod(m) if is_test(&m.attrs) => {}
                syn::Item::Mod(m) => {
                    let name = m.ident.to_string();
                    module.children.insert(name.clone());
                    let child = [path.as_slice(), std::slice::from_ref(&name)].concat();
                    match &m.content {
                        Some((_, inner)) => self.add_module(child, file, file_path, false, inner),
                        None => {
                            let dir = if owns_dir {
                                file_path.parent().expect("a file's folder").to_path_buf()
                            } else {
                                file_path.with_extension("")
                            };
                            let candidates = [dir.join(format!("{name}.rs")), dir.join(&name).join("mod.rs")];
                            let Some(child_path) = candidates.iter().find(|p| p.exists()) else {
                                panic!("{}: `mod {name}` has no file", file_path.display())
                            };
                            let ast = parse(child_path);
                            let index = self.files.len();
                            self.files.push(child_path.clone());
                            self.idents.push(HashSet::new());
                            let owns = child_path.ends_with("mod.rs");
                            self.add_module(child, index, &child_path.clone(), owns, &ast.items);
                        }
                    }
                }
                syn::Item::Use(u) => {
                    let public = !matches!(u.vis, syn::Visibility::Inherited);
                    flatten_use(&u.tree, &mut Vec::new(), public, &mut module.uses);
                }
                other => {
                    if let Some(name) = defined_name(other) {
                        module.defs.insert(name);
                    }
                    if !item_is_test(other) {
                        names.visit_item(other);
                    }
                }
            }
        }
        module.paths = names.paths;
        self.idents[file].extend(names.idents);
        self.modules.insert(path, module);
    }

    /// The file that defines what `path` names, seen from module `from`; `None` for what
    /// lies outside the crate.
    fn resolve(&self, from: &[String], path: &[String]) -> Option<usize> {
        match self.resolve_path(from, path)? {
            Target::Module(m) => self.modules.get(&m).map(|m| m.file),
            Target::Item(file) => Some(file),
        }
    }

    /// [`Self::resolve`] for a path in code: an item, never a module (a bare name
    /// that finds a module is a local variable of the same name).
    fn resolve_item(&self, from: &[String], path: &[String]) -> Option<usize> {
        match self.resolve_path(from, path)? {
            Target::Item(file) => Some(file),
            Target::Module(_) => None,
        }
    }

    /// What `path` names, seen from module `from`: a module of the crate, or the file of
    /// an item (a path that goes on past an item, to a variant or an associated item,
    /// names that item).
    fn resolve_path(&self, from: &[String], path: &[String]) -> Option<Target> {
        let (first, rest) = path.split_first()?;
        let mut module: Vec<String> = from.to_vec();
        let mut target = match first.as_str() {
            "crate" => Target::Module(Vec::new()),
            "self" => Target::Module(module),
            "super" => {
                module.pop()?;
                Target::Module(module)
            }
            name => self.lookup(from, name)?,
        };
        for name in rest {
            target = match target {
                Target::Module(m) if name == "super" => {
                    let mut m = m;
                    m.pop()?;
                    Target::Module(m)
                }
                Target::Module(m) => self.lookup(&m, name)?,
                item @ Target::Item(_) => return Some(item),
            };
        }
        Some(target)
    }

    /// What `name` is in the scope of `module`: a child module, an item it defines, or
    /// what a `use` (or a glob of this crate's) brings in. Remembered, and `None` while
    /// it is being looked up, since glob imports may run in circles.
    fn lookup(&self, module: &[String], name: &str) -> Option<Target> {
        let key = (module.to_vec(), name.to_string());
        if let Some(known) = self.looked_up.borrow().get(&key) {
            return known.clone();
        }
        self.looked_up.borrow_mut().insert(key.clone(), None);
        let found = self.find(module, name);
        self.looked_up.borrow_mut().insert(key, found.clone());
        found
    }

    fn find(&self, module: &[String], name: &str) -> Option<Target> {
        let m = self.modules.get(module)?;
        if m.children.contains(name) {
            return Some(Target::Module([module, &[name.to_string()]].concat()));
        }
        if m.defs.contains(name) {
            return Some(Target::Item(m.file));
        }
        if let Some(u) = m.uses.iter().find(|u| !u.glob && u.alias == name) {
            return self.resolve_path(module, &u.path);
        }
        m.uses
            .iter()
            .filter(|u| u.glob)
            .find_map(|u| match self.resolve_path(module, &u.path)? {
                Target::Module(g) => self.lookup(&g, name),
                Target::Item(_) => None,
            })
    }

    /// Each file's imports: the files it takes names from, and the names.
    fn imports(&self) -> BTreeMap<(usize, usize), BTreeSet<String>> {
        let mut edges: BTreeMap<(usize, usize), BTreeSet<String>> = BTreeMap::new();
        for (path, module) in &self.modules {
            let mentioned = &self.idents[module.file];
            let mut add = |target: Option<usize>, name: &str| {
                if let Some(t) = target.filter(|&t| t != module.file) {
                    edges
                        .entry((module.file, t))
                        .or_default()
                        .insert(name.to_string());
                }
            };
            for u in &module.uses {
                if u.glob {
                    for name in mentioned {
                        let target = [u.path.as_slice(), std::slice::from_ref(name)].concat();
                        add(self.resolve_item(path, &target), name);
                    }
                } else if !u.public || mentioned.contains(&u.alias) {
                    add(self.resolve(path, &u.path), &u.alias);
                }
            }
            for p in &module.paths {
                add(self.resolve_item(path, p), &p.join("::"));
            }
        }
        edges
    }
}

fn parse(path: &Path) -> syn::File {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    syn::parse_file(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn item_is_test(item: &syn::Item) -> bool {
    match item {
        syn::Item::Fn(f) => is_test(&f.attrs),
        syn::Item::Impl(i) => is_test(&i.attrs),
        syn::Item::Struct(s) => is_test(&s.attrs),
        syn::Item::Const(c) => is_test(&c.attrs),
        _ => false,
    }
}

fn defined_name(item: &syn::Item) -> Option<String> {
    let ident = match item {
        syn::Item::Fn(i) => &i.sig.ident,
        syn::Item::Struct(i) => &i.ident,
        syn::Item::Enum(i) => &i.ident,
        syn::Item::Trait(i) => &i.ident,
        syn::Item::TraitAlias(i) => &i.ident,
        syn::Item::Type(i) => &i.ident,
        syn::Item::Const(i) => &i.ident,
        syn::Item::Static(i) => &i.ident,
        syn::Item::Union(i) => &i.ident,
        syn::Item::Macro(i) => i.ident.as_ref()?,
        _ => return None,
    };
    Some(ident.to_string())
}

/// The strongly connected components of a graph of `n` nodes (Tarjan).
fn circles(n: usize, edges: &BTreeMap<(usize, usize), BTreeSet<String>>) -> Vec<Vec<usize>> {
    struct Tarjan<'a> {
        next: Vec<Vec<usize>>,
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on_stack: Vec<bool>,
        stack: Vec<usize>,
        counter: usize,
        out: &'a mut Vec<Vec<usize>>,
    }
    impl Tarjan<'_> {
        fn visit(&mut self, v: usize) {
            self.index[v] = Some(self.counter);
            self.low[v] = self.counter;
            self.counter += 1;
            self.stack.push(v);
            self.on_stack[v] = true;
            for w in self.next[v].clone() {
                match self.index[w] {
                    None => {
                        self.visit(w);
                        self.low[v] = self.low[v].min(self.low[w]);
                    }
                    Some(i) if self.on_stack[w] => self.low[v] = self.low[v].min(i),
                    Some(_) => {}
                }
            }
            if Some(self.low[v]) == self.index[v] {
                let mut component = Vec::new();
                while let Some(w) = self.stack.pop() {
                    self.on_stack[w] = false;
                    component.push(w);
                    if w == v {
                        break;
                    }
                }
                if component.len() > 1 {
                    component.sort();
                    self.out.push(component);
                }
            }
        }
    }
    let mut next = vec![Vec::new(); n];
    for &(a, b) in edges.keys() {
        next[a].push(b);
    }
    let mut out = Vec::new();
    let mut t = Tarjan {
        next,
        index: vec![None; n],
        low: vec![0; n],
        on_stack: vec![false; n],
        stack: Vec::new(),
        counter: 0,
        out: &mut out,
    };
    for v in 0..n {
        if t.index[v].is_none() {
            t.visit(v);
        }
    }
    out
}

/// The line count of every function outside tests.
#[derive(Default)]
struct Functions {
    long: Vec<(usize, String)>,
}

impl<'ast> Visit<'ast> for Functions {
    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        if !is_test(&m.attrs) {
            syn::visit::visit_item_mod(self, m);
        }
    }
    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        if !is_test(&f.attrs) {
            self.measure(
                &f.sig.ident,
                f.sig.fn_token.span,
                f.block.brace_token.span.close(),
            );
            syn::visit::visit_item_fn(self, f);
        }
    }
    fn visit_impl_item_fn(&mut self, f: &'ast syn::ImplItemFn) {
        self.measure(
            &f.sig.ident,
            f.sig.fn_token.span,
            f.block.brace_token.span.close(),
        );
        syn::visit::visit_impl_item_fn(self, f);
    }
    fn visit_trait_item_fn(&mut self, f: &'ast syn::TraitItemFn) {
        if let Some(block) = &f.default {
            self.measure(&f.sig.ident, f.sig.fn_token.span, block.brace_token.span.close());
        }
        syn::visit::visit_trait_item_fn(self, f);
    }
}

impl Functions {
    fn measure(&mut self, name: &syn::Ident, start: proc_macro2::Span, end: proc_macro2::Span) {
        let lines = end.end().line - start.start().line + 1;
        if lines > MAX_FUNCTION_LINES {
            self.long
                .push((lines, format!("{name} (line {})", start.start().line)));
        }
    }
}

/// Every `.rs` file under the crate roots' `src` folders.
pub(crate) fn source_files() -> Vec<PathBuf> {
    let mut files = Vec::new();
    for krate in crate_roots() {
        let src = krate.parent().expect("src/").to_path_buf();
        let mut stack = vec![src];
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).expect("a source folder") {
                let p = entry.expect("entry").path();
                if p.is_dir() {
                    stack.push(p);
                } else if p.extension().is_some_and(|e| e == "rs") && !files.contains(&p) {
                    files.push(p);
                }
            }
        }
    }
    files.sort();
    files
}

#[test]
fn no_function_is_over_150_lines_outside_tests() {
    let root = root();
    let files = source_files();
    assert!(files.len() > 100, "found {} source files", files.len());
    let mut long = Vec::new();
    for file in files {
        let mut functions = Functions::default();
        functions.visit_file(&parse(&file));
        for (lines, name) in functions.long {
            long.push(format!(
                "{} lines: {} {name}",
                lines,
                file.strip_prefix(root).unwrap_or(&file).display()
            ));
        }
    }
    long.sort();
    assert!(
        long.is_empty(),
        "functions over {MAX_FUNCTION_LINES} lines:\n{}",
        long.join("\n")
    );
}

#[test]
fn no_file_of_the_engine_is_over_600_lines() {
    let root = root();
    let mut long = Vec::new();
    for file in source_files()
        .into_iter()
        .filter(|f| f.starts_with(root.join("core")))
    {
        let lines = std::fs::read_to_string(&file).expect("source").lines().count();
        if lines > MAX_CORE_FILE_LINES {
            long.push(format!("{lines} lines: {}", file.display()));
        }
    }
    assert!(
        long.is_empty(),
        "core files over {MAX_CORE_FILE_LINES} lines:\n{}",
        long.join("\n")
    );
}

#[test]
fn no_import_circle_passes_through_more_than_two_files() {
    let root = root();
    let mut found = Vec::new();
    let mut edges_seen = 0;
    for krate in crate_roots() {
        let source = CrateSource::read(&krate);
        let edges = source.imports();
        edges_seen += edges.len();
        let name = |i: usize| {
            source.files[i]
                .strip_prefix(root)
                .unwrap_or(&source.files[i])
                .display()
                .to_string()
        };
        for circle in circles(source.files.len(), &edges) {
            if circle.len() <= MAX_CIRCLE_FILES {
                continue;
            }
            let mut text = format!(
                "{} files: {}",
                circle.len(),
                circle.iter().map(|&i| name(i)).collect::<Vec<_>>().join(", ")
            );
            for (&(a, b), names) in &edges {
                if circle.contains(&a) && circle.contains(&b) {
                    let names: Vec<&str> = names.iter().map(String::as_str).take(6).collect();
                    text.push_str(&format!("\n    {} -> {}: {}", name(a), name(b), names.join(", ")));
                }
            }
            found.push(text);
        }
    }
    assert!(edges_seen > 200, "found only {edges_seen} imports between files");
    assert!(
        found.is_empty(),
        "import circles through more than {MAX_CIRCLE_FILES} files:\n{}",
        found.join("\n")
    );
}

/// The reader finds circles where there are some: a crate written for the purpose, with
/// a circle of three files through an alias, a glob import and a path in code, and
/// re-exports that close no circle.
#[test]
fn the_import_reader_finds_a_circle_through_aliases_globs_and_paths() {
    let dir = tempfile::tempdir().expect("temp dir");
    let src = dir.path().join("src");
    std::fs::create_dir_all(src.join("b")).expect("src/b");
    let write = |p: &str, text: &str| std::fs::write(src.join(p), text).expect("write");
    write("lib.rs", "mod a;\nmod b;\npub use a::A;\npub use b::{B, c::C};\n");
    write("a.rs", "use crate::b::B as Bee;\npub struct A(pub Bee);\n");
    write(
        "b/mod.rs",
        "pub mod c;\nuse c::*;\npub struct B;\nfn f() -> C { C }\n",
    );
    write(
        "b/c.rs",
        "pub struct C;\nfn g() { let _ = crate::a::A(crate::b::B); }\n",
    );
    let source = CrateSource::read(&src.join("lib.rs"));
    let edges = source.imports();
    let name = |i: usize| {
        source.files[i]
            .strip_prefix(&src)
            .expect("in src")
            .display()
            .to_string()
    };
    let named: BTreeSet<(String, String)> = edges.keys().map(|&(a, b)| (name(a), name(b))).collect();
    let expect: BTreeSet<(String, String)> = [
        ("a.rs", "b/mod.rs"),
        ("b/mod.rs", "b/c.rs"),
        ("b/c.rs", "a.rs"),
        ("b/c.rs", "b/mod.rs"),
    ]
    .iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect();
    assert_eq!(named, expect);
    let found = circles(source.files.len(), &edges);
    assert_eq!(found.len(), 1);
    assert_eq!(found[0].len(), 3);
}

/// The length reader counts a function from `fn` to its closing brace, in impls and
/// traits too, and leaves tests out.
#[test]
fn the_length_reader_counts_functions_outside_tests() {
    // `fn` line, body, closing brace: one line over the limit, and one at it.
    let body = "    let _ = 1;\n".repeat(MAX_FUNCTION_LINES - 1);
    let long = format!("fn long() {{\n{body}}}\n");
    let at_limit = format!(
        "fn short() {{\n{}}}\n",
        "    let _ = 1;\n".repeat(MAX_FUNCTION_LINES - 2)
    );
    let text = format!(
        "{long}{at_limit}\
         struct S;\nimpl S {{\n    {}\n}}\n\
         trait T {{\n    {}\n}}\n\
         #[test]\n{}\
         #[cfg(test)]\nmod tests {{\n{}}}\n",
        long.replace("fn long", "fn method"),
        long.replace("fn long", "fn provided"),
        long.replace("fn long", "fn a_test"),
        long.replace("fn long", "fn in_tests"),
    );
    let mut functions = Functions::default();
    functions.visit_file(&syn::parse_file(&text).expect("Rust"));
    let names: Vec<&str> = functions
        .long
        .iter()
        .map(|(lines, name)| {
            assert_eq!(*lines, MAX_FUNCTION_LINES + 1, "{name}");
            name.split(' ').next().expect("a name")
        })
        .collect();
    assert_eq!(names, ["long", "method", "provided"]);
}
