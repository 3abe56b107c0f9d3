//! Generated documentation stays current: docs/pipeline-reference.md is the output of
//! `lamina plugins --markdown`. Run with `LAMINA_UPDATE_DOCS=1` to rewrite it.

use std::path::Path;
use std::process::Command;

#[test]
fn pipeline_reference_is_current() {
    let out = Command::new(env!("CARGO_BIN_EXE_lamina"))
        .args(["plugins", "--markdown"])
        .output()
        .expect("lamina runs");
    assert!(out.status.success());
    let generated = String::from_utf8(out.stdout).expect("utf-8");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/pipeline-reference.md");
    if std::env::var_os("LAMINA_UPDATE_DOCS").is_some() {
        std::fs::write(&path, &generated).expect("write");
        return;
    }
    let current = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        current == generated,
        "docs/pipeline-reference.md is out of date: run `LAMINA_UPDATE_DOCS=1 cargo test --test integration docs::`"
    );
}

/// ARCHITECTURE.md names every stage the program ships where it describes the crate
/// that holds it, in backticks as a pipeline writes it: a stage added without a word
/// there fails here.
#[test]
fn the_architecture_names_every_built_in_stage() {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("ARCHITECTURE.md"))
        .expect("ARCHITECTURE.md");
    let out = Command::new(env!("CARGO_BIN_EXE_lamina"))
        .arg("plugins")
        .output()
        .expect("lamina runs");
    assert!(out.status.success());
    // `kind:` headings, then a line per stage: two spaces, its name, its summary. The
    // machine profiles listed after them are no stages.
    let listing = String::from_utf8(out.stdout).expect("utf-8");
    let mut kind = "";
    let mut names = Vec::new();
    for line in listing.lines() {
        if let Some(k) = line.strip_suffix(':').filter(|k| !k.starts_with(' ')) {
            kind = if k.contains(' ') { "" } else { k };
        } else if let Some(rest) = line
            .strip_prefix("  ")
            .filter(|r| !r.starts_with(' ') && !kind.is_empty())
        {
            let name = rest.split_whitespace().next().unwrap_or_default();
            names.push((kind.to_string(), name.to_string()));
        }
    }
    assert!(names.len() > 40, "{names:?}");
    let missing: Vec<String> = names
        .iter()
        .filter(|(_, name)| !text.contains(&format!("`{name}`")))
        .map(|(kind, name)| format!("{kind}:{name}"))
        .collect();
    assert!(
        missing.is_empty(),
        "ARCHITECTURE.md does not name {}",
        missing.join(", ")
    );
}

/// Where a call sets a diagnostic's code: the index of the code among its arguments.
fn code_argument(callee: &str) -> Option<usize> {
    match callee {
        "Warning::new" => Some(0),
        "Diagnostic::warning" | "warn" | "note" => Some(1),
        "Diagnostic::new" => Some(2),
        _ => None,
    }
}

/// The codes the shipped code sets, read with syn from every call that sets one
/// (outside tests): a string literal, or a `const` of the same file.
#[derive(Default)]
struct Codes {
    consts: std::collections::HashMap<String, String>,
    /// (file, code) where the code is a literal or a constant; `None` for any other
    /// expression (a code passed on).
    found: Vec<(String, Option<String>)>,
    file: String,
}

impl Codes {
    fn argument(&mut self, callee: &str, args: &syn::punctuated::Punctuated<syn::Expr, syn::Token![,]>) {
        let Some(arg) = code_argument(callee).and_then(|i| args.iter().nth(i)) else {
            return;
        };
        let code = match arg {
            syn::Expr::Lit(syn::ExprLit {
                lit: syn::Lit::Str(s),
                ..
            }) => Some(s.value()),
            syn::Expr::Path(p) => p
                .path
                .get_ident()
                .and_then(|i| self.consts.get(&i.to_string()).cloned()),
            _ => None,
        };
        self.found.push((self.file.clone(), code));
    }
}

impl<'ast> syn::visit::Visit<'ast> for Codes {
    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        if !crate::code_shape::is_test(&m.attrs) {
            syn::visit::visit_item_mod(self, m);
        }
    }

    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        if !crate::code_shape::is_test(&f.attrs) {
            syn::visit::visit_item_fn(self, f);
        }
    }

    fn visit_expr_call(&mut self, call: &'ast syn::ExprCall) {
        if let syn::Expr::Path(p) = &*call.func {
            let segments: Vec<String> = p.path.segments.iter().map(|s| s.ident.to_string()).collect();
            let callee = segments[segments.len().saturating_sub(2)..].join("::");
            self.argument(&callee, &call.args);
        }
        syn::visit::visit_expr_call(self, call);
    }

    fn visit_expr_method_call(&mut self, call: &'ast syn::ExprMethodCall) {
        self.argument(&call.method.to_string(), &call.args);
        syn::visit::visit_expr_method_call(self, call);
    }
}

/// Every diagnostic code a built-in stage sets is kebab-case and listed in
/// docs/formats.md, where tools built on the JSON plan look codes up; a stage that
/// says something new without a code, or with a code nobody documented, fails here.
#[test]
fn every_diagnostic_code_is_documented() {
    let formats =
        std::fs::read_to_string(crate::support::root().join("docs/formats.md")).expect("docs/formats.md");
    let mut codes = Codes::default();
    for path in crate::code_shape::source_files() {
        let text = std::fs::read_to_string(&path).expect("source");
        let file = syn::parse_file(&text).expect("Rust");
        codes.consts.clear();
        for item in &file.items {
            if let syn::Item::Const(c) = item
                && let syn::Expr::Lit(syn::ExprLit {
                    lit: syn::Lit::Str(s),
                    ..
                }) = &*c.expr
            {
                codes.consts.insert(c.ident.to_string(), s.value());
            }
        }
        codes.file = path.display().to_string();
        syn::visit::Visit::visit_file(&mut codes, &file);
    }
    let literal: Vec<&(String, Option<String>)> = codes.found.iter().filter(|(_, c)| c.is_some()).collect();
    assert!(literal.len() >= 15, "{:?}", codes.found);
    let wrong: Vec<String> = literal
        .iter()
        .filter_map(|(file, code)| {
            let code = code.as_deref()?;
            let documented = formats.contains(&format!("| `{code}` |"));
            (!lamina_core::diagnostic::is_code(code) || !documented).then(|| format!("{file}: `{code}`"))
        })
        .collect();
    assert!(
        wrong.is_empty(),
        "codes that are not kebab-case or not in the table of docs/formats.md: {}",
        wrong.join(", ")
    );
}
