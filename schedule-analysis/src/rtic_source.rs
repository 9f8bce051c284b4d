//! Reads an RTIC 2 application from its source with `syn`: the tasks (name, priority, hardware binding or
//! software), the shared and local resources each one uses, `idle`, and the dispatchers — so the analysed task
//! list is the firmware's own and cannot drift from it.
//!
//! Understood: `#[rtic::app(...)] mod app { ... }` (or `#[app]`), `#[shared]`/`#[local]` structs with `#[lock_free]`
//! fields, `#[init]`, `#[idle(...)]`, `#[task(binds = .., priority = .., shared = [..], local = [..])]` on `fn` and
//! `async fn`, the same inside `extern "Rust" { ... }` blocks, and `#[cfg(...)]` on tasks and resources
//! (`feature = ".."`, `not`, `all`, `any`; any other predicate counts as true).

use std::fmt;

use proc_macro2::{Delimiter, Span, TokenStream, TokenTree};
use syn::punctuated::Punctuated;
use syn::{Attribute, Item, Meta, Token};

/// The application as the analysis needs it.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct RticApp {
    /// The `device = ...` path.
    pub device: Option<String>,
    /// Interrupts lent to the software-task dispatchers.
    pub dispatchers: Vec<String>,
    /// Fields of the `#[shared]` struct.
    pub shared: Vec<SharedResource>,
    /// Fields of the `#[local]` struct.
    pub local: Vec<String>,
    /// `idle`, if the app has one (priority 0).
    pub idle: Option<RticTask>,
    /// Every `#[task]`, in source order.
    pub tasks: Vec<RticTask>,
}

/// A field of the `#[shared]` struct.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SharedResource {
    /// Field name.
    pub name: String,
    /// `#[lock_free]`: all users run at one priority and never lock, so it cannot block.
    pub lock_free: bool,
    /// `#[cfg(...)]` attributes, as written.
    pub cfg: Vec<String>,
}

/// How a task is started.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RticTaskKind {
    /// Bound to an interrupt (`binds = USB_LP_CAN_RX0`).
    Hardware {
        /// The interrupt.
        binds: String,
    },
    /// A software task, run by the dispatcher of its priority.
    Software,
    /// The `idle` loop.
    Idle,
}

/// One task.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RticTask {
    /// Function name.
    pub name: String,
    /// Hardware, software or idle.
    pub kind: RticTaskKind,
    /// Priority (RTIC's default 1; 0 for idle).
    pub priority: u8,
    /// Shared resources it may lock.
    pub shared: Vec<String>,
    /// Local resources it owns.
    pub local: Vec<String>,
    /// Declared `async`.
    pub is_async: bool,
    /// `#[cfg(...)]` attributes, as written.
    pub cfg: Vec<String>,
    /// Line of the function name in the source.
    pub line: usize,
}

/// Source that is not an RTIC app this reader understands.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SourceError {
    /// 1-based line (0 when unknown).
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for SourceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line > 0 {
            write!(f, "line {}: {}", self.line, self.message)
        } else {
            f.write_str(&self.message)
        }
    }
}

impl std::error::Error for SourceError {}

fn err(span: Span, message: impl Into<String>) -> SourceError {
    SourceError {
        line: span.start().line,
        message: message.into(),
    }
}

/// Parses the RTIC app in `source` (all tasks, whatever their `cfg`).
pub fn parse_app(source: &str) -> Result<RticApp, SourceError> {
    let file =
        syn::parse_file(source).map_err(|e| err(e.span(), format!("not valid Rust: {e}")))?;
    let Some((attr, items)) = find_app(&file.items) else {
        return Err(SourceError {
            line: 0,
            message: "no `#[rtic::app]` module found".into(),
        });
    };
    let mut app = RticApp::default();
    read_app_args(attr, &mut app)?;
    for item in items {
        match item {
            Item::Struct(s) if has_attr(&s.attrs, "shared") => {
                for field in &s.fields {
                    let Some(ident) = &field.ident else { continue };
                    app.shared.push(SharedResource {
                        name: ident.to_string(),
                        lock_free: has_attr(&field.attrs, "lock_free"),
                        cfg: cfgs(&field.attrs),
                    });
                }
            }
            Item::Struct(s) if has_attr(&s.attrs, "local") => {
                app.local.extend(
                    s.fields
                        .iter()
                        .filter_map(|f| f.ident.as_ref().map(|i| i.to_string())),
                );
            }
            Item::Fn(f) => read_fn(&f.attrs, &f.sig, &mut app)?,
            Item::ForeignMod(block) => {
                for foreign in &block.items {
                    match foreign {
                        syn::ForeignItem::Fn(f) => read_fn(&f.attrs, &f.sig, &mut app)?,
                        syn::ForeignItem::Verbatim(tokens) => {
                            // `async fn` declarations inside `extern` blocks are not Rust syntax syn models;
                            // RTIC accepts them, so read them as a function with an empty body.
                            let text = tokens.to_string();
                            let text = text.trim_end().strip_suffix(';').unwrap_or(&text);
                            let Ok(f) = syn::parse_str::<syn::ItemFn>(&format!("{text} {{}}"))
                            else {
                                continue;
                            };
                            let before = app.tasks.len();
                            read_fn(&f.attrs, &f.sig, &mut app)?;
                            // The re-parse lost the position; take the line from the original tokens.
                            let line = tokens
                                .clone()
                                .into_iter()
                                .next()
                                .map_or(0, |t| t.span().start().line);
                            for task in app.tasks.iter_mut().skip(before) {
                                task.line = line;
                            }
                        }
                        _ => {}
                    }
                }
            }
            _ => {}
        }
    }
    check(&app)?;
    Ok(app)
}

impl RticApp {
    /// The app as built with `features` enabled: tasks and resources whose `cfg` is false are dropped.
    pub fn with_features(&self, features: &[&str]) -> RticApp {
        let on = |cfg: &[String]| cfg.iter().all(|c| cfg_holds(c, features));
        RticApp {
            device: self.device.clone(),
            dispatchers: self.dispatchers.clone(),
            shared: self.shared.iter().filter(|r| on(&r.cfg)).cloned().collect(),
            local: self.local.clone(),
            idle: self.idle.clone().filter(|t| on(&t.cfg)),
            tasks: self.tasks.iter().filter(|t| on(&t.cfg)).cloned().collect(),
        }
    }

    /// The task called `name`.
    pub fn task(&self, name: &str) -> Option<&RticTask> {
        self.tasks.iter().find(|t| t.name == name)
    }

    /// Whether `resource` is `#[lock_free]`.
    pub fn is_lock_free(&self, resource: &str) -> bool {
        self.shared
            .iter()
            .any(|r| r.name == resource && r.lock_free)
    }
}

fn find_app(items: &[Item]) -> Option<(&Attribute, &[Item])> {
    for item in items {
        if let Item::Mod(m) = item {
            let Some((_, content)) = &m.content else {
                continue;
            };
            if let Some(attr) = m.attrs.iter().find(|a| is_app_attr(a)) {
                return Some((attr, content));
            }
            if let Some(found) = find_app(content) {
                return Some(found);
            }
        }
    }
    None
}

fn is_app_attr(attr: &Attribute) -> bool {
    let segments: Vec<String> = attr
        .path()
        .segments
        .iter()
        .map(|s| s.ident.to_string())
        .collect();
    matches!(segments.as_slice(), [one] if one == "app")
        || matches!(segments.as_slice(), [a, b] if a == "rtic" && b == "app")
}

fn has_attr(attrs: &[Attribute], name: &str) -> bool {
    attrs.iter().any(|a| a.path().is_ident(name))
}

fn cfgs(attrs: &[Attribute]) -> Vec<String> {
    attrs
        .iter()
        .filter(|a| a.path().is_ident("cfg"))
        .filter_map(|a| match &a.meta {
            Meta::List(list) => Some(list.tokens.to_string()),
            _ => None,
        })
        .collect()
}

/// Splits a token stream at its top-level commas. Brackets are token groups already; angle brackets are not, so
/// their depth is tracked (a `local = [buf: Vec<u8, 4> = ..]` entry stays one entry). The `>` of `->` and `=>`
/// closes nothing.
fn split_commas(tokens: TokenStream) -> Vec<Vec<TokenTree>> {
    let mut parts = vec![Vec::new()];
    let mut depth = 0usize;
    let mut previous_joint = None;
    for tree in tokens {
        let mut joint = None;
        if let TokenTree::Punct(p) = &tree {
            match p.as_char() {
                ',' if depth == 0 => {
                    parts.push(Vec::new());
                    previous_joint = None;
                    continue;
                }
                '<' => depth += 1,
                '>' if !matches!(previous_joint, Some('-') | Some('=')) => {
                    depth = depth.saturating_sub(1)
                }
                _ => {}
            }
            if p.spacing() == proc_macro2::Spacing::Joint {
                joint = Some(p.as_char());
            }
        }
        previous_joint = joint;
        if let Some(last) = parts.last_mut() {
            last.push(tree);
        }
    }
    parts.retain(|p| !p.is_empty());
    parts
}

/// `key = value` pairs of an attribute's arguments, values as raw tokens.
fn key_values(tokens: TokenStream) -> Result<Vec<(String, Span, Vec<TokenTree>)>, SourceError> {
    let mut out = Vec::new();
    for part in split_commas(tokens) {
        let mut it = part.into_iter();
        let Some(TokenTree::Ident(key)) = it.next() else {
            return Err(SourceError {
                line: 0,
                message: "attribute argument is not `key = value`".into(),
            });
        };
        match it.next() {
            Some(TokenTree::Punct(p)) if p.as_char() == '=' => {}
            _ => return Err(err(key.span(), format!("`{key}` must be followed by `=`"))),
        }
        out.push((key.to_string(), key.span(), it.collect()));
    }
    Ok(out)
}

fn tokens_text(tokens: &[TokenTree]) -> String {
    tokens
        .iter()
        .map(|t| t.to_string())
        .collect::<Vec<_>>()
        .join("")
        .replace(' ', "")
}

/// The first identifier of each comma-separated item in a `[...]` group (skipping a leading `&`).
fn bracket_names(tokens: &[TokenTree], key: &str, span: Span) -> Result<Vec<String>, SourceError> {
    let [TokenTree::Group(group)] = tokens else {
        return Err(err(span, format!("`{key}` must be a list in brackets")));
    };
    if group.delimiter() != Delimiter::Bracket {
        return Err(err(span, format!("`{key}` must be a list in brackets")));
    }
    let mut names = Vec::new();
    for item in split_commas(group.stream()) {
        let name = item.iter().find_map(|t| match t {
            TokenTree::Ident(i) => Some(i.to_string()),
            _ => None,
        });
        match name {
            Some(n) => names.push(n),
            None => return Err(err(span, format!("an entry of `{key}` has no name"))),
        }
    }
    Ok(names)
}

fn read_app_args(attr: &Attribute, app: &mut RticApp) -> Result<(), SourceError> {
    let Meta::List(list) = &attr.meta else {
        return Ok(());
    };
    for (key, span, value) in key_values(list.tokens.clone())? {
        match key.as_str() {
            "device" => app.device = Some(tokens_text(&value)),
            "dispatchers" => app.dispatchers = bracket_names(&value, "dispatchers", span)?,
            _ => {}
        }
    }
    Ok(())
}

fn read_fn(
    attrs: &[Attribute],
    sig: &syn::Signature,
    app: &mut RticApp,
) -> Result<(), SourceError> {
    let name = sig.ident.to_string();
    let line = sig.ident.span().start().line;
    let is_async = sig.asyncness.is_some();
    for attr in attrs {
        let kind = if attr.path().is_ident("task") {
            Some(false)
        } else if attr.path().is_ident("idle") {
            Some(true)
        } else {
            None
        };
        let Some(is_idle) = kind else { continue };
        let mut task = RticTask {
            name: name.clone(),
            kind: if is_idle {
                RticTaskKind::Idle
            } else {
                RticTaskKind::Software
            },
            priority: if is_idle { 0 } else { 1 },
            shared: Vec::new(),
            local: Vec::new(),
            is_async,
            cfg: cfgs(attrs),
            line,
        };
        if let Meta::List(list) = &attr.meta {
            for (key, span, value) in key_values(list.tokens.clone())? {
                match key.as_str() {
                    "binds" if !is_idle => {
                        task.kind = RticTaskKind::Hardware {
                            binds: tokens_text(&value),
                        }
                    }
                    "priority" if !is_idle => {
                        let text = tokens_text(&value);
                        task.priority = text.parse().map_err(|_| {
                            err(
                                span,
                                format!(
                                    "task `{name}`: priority `{text}` is not an integer 0..=255"
                                ),
                            )
                        })?;
                    }
                    "shared" => task.shared = bracket_names(&value, "shared", span)?,
                    "local" => task.local = bracket_names(&value, "local", span)?,
                    _ => {}
                }
            }
        }
        if is_idle {
            app.idle = Some(task);
        } else {
            if app
                .tasks
                .iter()
                .any(|t| t.name == task.name && t.cfg == task.cfg)
            {
                return Err(err(
                    sig.ident.span(),
                    format!("task `{name}` is declared twice"),
                ));
            }
            app.tasks.push(task);
        }
    }
    Ok(())
}

fn check(app: &RticApp) -> Result<(), SourceError> {
    for task in app.tasks.iter().chain(app.idle.iter()) {
        for resource in &task.shared {
            if !app.shared.iter().any(|r| &r.name == resource) {
                return Err(SourceError {
                    line: task.line,
                    message: format!(
                        "task `{}` uses `{resource}`, which is not a field of the #[shared] struct",
                        task.name
                    ),
                });
            }
        }
    }
    Ok(())
}

/// Evaluates one `cfg(...)` predicate (as written between the parentheses) with `features` enabled.
pub fn cfg_holds(predicate: &str, features: &[&str]) -> bool {
    match syn::parse_str::<Meta>(predicate) {
        Ok(meta) => eval_cfg(&meta, features),
        Err(_) => true,
    }
}

fn eval_cfg(meta: &Meta, features: &[&str]) -> bool {
    match meta {
        Meta::NameValue(nv) if nv.path.is_ident("feature") => match &nv.value {
            syn::Expr::Lit(syn::ExprLit {
                lit: syn::Lit::Str(s),
                ..
            }) => features.contains(&s.value().as_str()),
            _ => true,
        },
        Meta::List(list) => {
            let nested = list.parse_args_with(Punctuated::<Meta, Token![,]>::parse_terminated);
            let Ok(nested) = nested else { return true };
            if list.path.is_ident("not") {
                !nested.first().is_some_and(|m| eval_cfg(m, features))
            } else if list.path.is_ident("all") {
                nested.iter().all(|m| eval_cfg(m, features))
            } else if list.path.is_ident("any") {
                nested.iter().any(|m| eval_cfg(m, features))
            } else {
                true
            }
        }
        _ => true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cfg_predicates() {
        assert!(cfg_holds("feature = \"qemu\"", &["qemu"]));
        assert!(!cfg_holds("feature = \"qemu\"", &[]));
        assert!(cfg_holds("not(feature = \"qemu\")", &[]));
        assert!(cfg_holds(
            "all(feature = \"a\", not(feature = \"b\"))",
            &["a"]
        ));
        assert!(!cfg_holds("any(feature = \"a\", feature = \"b\")", &[]));
        assert!(cfg_holds("target_os = \"none\"", &[]));
    }
}
