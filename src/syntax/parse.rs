//! pest parse tree → AST. Syntax errors become diagnostics that say what was expected.

use super::ast::*;
use crate::diag::{Diagnostic, Span};
use pest::iterators::{Pair, Pairs};
use pest::pratt_parser::{Assoc, Op, PrattParser};
use pest::Parser;
use std::cell::Cell;
use std::sync::OnceLock;

#[derive(pest_derive::Parser)]
#[grammar = "../grammar/pairsum.pest"]
struct Grammar;

/// The deepest nesting a source may have: brackets (`(`, `[`, `{`) and `else if` chains in its
/// text, and levels of its syntax tree (an operator is a level: `a + b + c` is three deep). The
/// parser, the checker and every later stage recurse over the tree, so a deeper input (a fuzzer's
/// `((((…))))` or a sum of thousands of terms) is refused with E0004 rather than overflowing the
/// stack. The stdlib's deepest is 22 levels.
pub const MAX_DEPTH: usize = 128;

/// Parses one source file (`file` is its id in `Sources`).
pub fn parse_file(file: u32, text: &str) -> Result<File, Box<Diagnostic>> {
    if let Some(at) = too_deep_text(text) {
        return Err(Box::new(too_deep(Span::new(file, at, at + 1))));
    }
    let mut pairs = Grammar::parse(Rule::file, text).map_err(|e| Box::new(syntax_error(file, text, e)))?;
    let b = Builder::new(file, 0);
    let root = pairs.next().expect("the file rule always yields one pair");
    let items = root.into_inner().filter(|p| p.as_rule() != Rule::EOI).map(|p| b.item(p)).collect();
    b.finish(File { items })
}

/// Parses one expression that stands at byte `offset` of source file `file` (a case file's
/// initial value): spans point into that file.
pub fn parse_expr(file: u32, offset: usize, text: &str) -> Result<Expr, Box<Diagnostic>> {
    if let Some(at) = too_deep_text(text) {
        return Err(Box::new(too_deep(Span::new(file, offset + at, offset + at + 1))));
    }
    let mut pairs = Grammar::parse(Rule::expr_only, text).map_err(|e| {
        let mut d = syntax_error(file, text, e);
        if let Some((span, _)) = &mut d.primary {
            *span = Span::new(file, span.start as usize + offset, span.end as usize + offset);
        }
        Box::new(d)
    })?;
    let b = Builder::new(file, offset);
    let root = pairs.next().expect("the expr_only rule always yields one pair");
    let e = root.into_inner().find(|p| p.as_rule() == Rule::expr).expect("expr_only holds an expr");
    let e = b.expr(e);
    b.finish(e)
}

fn too_deep(span: Span) -> Diagnostic {
    Diagnostic::error("E0004", format!("nested too deeply: more than {MAX_DEPTH} levels"))
        .at(span, format!("level {} starts here", MAX_DEPTH + 1))
        .help("split the expression with `let` values or helper functions")
}

/// Where the text's nesting first goes deeper than [`MAX_DEPTH`]: brackets, and `else if` chains
/// (each `else if` is a level until its enclosing bracket closes), outside comments and strings.
/// The grammar recurses at each of these, so this bounds the parser's own recursion before it
/// starts; the tree's depth is bounded as it is built.
fn too_deep_text(text: &str) -> Option<usize> {
    let b = text.as_bytes();
    // Per open bracket (and the top level): the `else if` levels opened inside it.
    let mut chains: Vec<usize> = vec![0];
    let mut depth = 0usize;
    let mut k = 0;
    let mut last_word_else = false;
    while k < b.len() {
        let c = b[k];
        if c == b'/' && b.get(k + 1) == Some(&b'/') {
            k = text[k..].find('\n').map_or(b.len(), |n| k + n);
            continue;
        }
        if c == b'/' && b.get(k + 1) == Some(&b'*') {
            k = text[k + 2..].find("*/").map_or(b.len(), |n| k + 2 + n + 2);
            continue;
        }
        if c == b'"' {
            k = text[k + 1..].find(['"', '\n']).map_or(b.len(), |n| k + 1 + n + 1);
            last_word_else = false;
            continue;
        }
        if c.is_ascii_alphanumeric() || c == b'_' {
            let end = b[k..].iter().position(|c| !(c.is_ascii_alphanumeric() || *c == b'_')).map_or(b.len(), |n| k + n);
            let word = &text[k..end];
            if word == "if" && last_word_else {
                *chains.last_mut().expect("the top level") += 1;
                depth += 1;
                if depth > MAX_DEPTH {
                    return Some(k);
                }
            }
            last_word_else = word == "else";
            k = end;
            continue;
        }
        match c {
            b'(' | b'[' | b'{' => {
                chains.push(0);
                depth += 1;
                if depth > MAX_DEPTH {
                    return Some(k);
                }
            }
            b')' | b']' | b'}' if chains.len() > 1 => {
                depth -= 1 + chains.pop().expect("an open bracket");
            }
            _ => {}
        }
        if !c.is_ascii_whitespace() && c != b';' {
            last_word_else = false;
        }
        k += 1;
    }
    None
}

fn syntax_error(file: u32, text: &str, e: pest::error::Error<Rule>) -> Diagnostic {
    let pos = match e.location {
        pest::error::InputLocation::Pos(p) => p,
        pest::error::InputLocation::Span((s, _)) => s,
    };
    // Point at the whole offending token, not just its first byte.
    let rest = &text[pos.min(text.len())..];
    let len = rest
        .char_indices()
        .take_while(|(_, c)| c.is_alphanumeric() || *c == '_')
        .last()
        .map(|(i, c)| i + c.len_utf8())
        .unwrap_or_else(|| rest.chars().next().map(|c| c.len_utf8()).unwrap_or(0));
    let span = Span::new(file, pos, pos + len);
    let found = if rest.is_empty() { "the end of the file".to_string() } else { format!("`{}`", &rest[..len]) };
    let expected = match &e.variant {
        pest::error::ErrorVariant::ParsingError { positives, .. } => describe_expected(positives),
        pest::error::ErrorVariant::CustomError { message } => message.clone(),
    };
    let d = Diagnostic::error("E0001", format!("syntax error: expected {expected}, found {found}"))
        .at(span, format!("expected {expected}"));
    if begins_line_with_paren(text, pos) {
        d.help("a line that begins with `(` starts a new statement; to continue the expression above, end its line with the operator")
    } else {
        d
    }
}

/// Whether `pos` is a `(` with nothing but spaces before it on its line.
fn begins_line_with_paren(text: &str, pos: usize) -> bool {
    let pos = pos.min(text.len());
    let line_start = text[..pos].rfind('\n').map_or(0, |k| k + 1);
    text[pos..].starts_with('(') && text[line_start..pos].trim().is_empty()
}

fn describe_expected(rules: &[Rule]) -> String {
    let mut names: Vec<&str> = rules.iter().map(|r| rule_text(*r)).collect();
    names.sort();
    names.dedup();
    match names.len() {
        0 => "something else".into(),
        1 => names[0].into(),
        _ => {
            let last = names.pop().unwrap_or_default();
            format!("{} or {}", names.join(", "), last)
        }
    }
}

fn rule_text(r: Rule) -> &'static str {
    use Rule::*;
    match r {
        EOI => "the end of the file",
        file => "an item",
        ident | name | callee => "a name",
        side => "`i` or `j`",
        number | number_lit => "a number",
        expr | primary | operand | prefix | neg | not | call | paren | bool_lit | in_group => "an expression",
        or | and | eq | ne | le | ge | lt | gt | add | sub | mul | div | pow | infix => "an operator",
        index | postfix | member => "an operator",
        unit | unit_expr | unit_factor | unit_name | unit_one | unit_none | unit_base => "a unit",
        unit_op => "`*` or `/`",
        unit_power => "an exponent",
        type_spec | shape => "a shape (scalar, vec, symtensor, skewtensor, tensor, bool)",
        block | init_block | finally_block | pair_body | fn_body => "`{`",
        stmt | let_stmt | if_stmt | accum_stmt | assign_stmt | lvalue => "a statement",
        accum_op => "`+=`, `-=`, `min=` or `max=`",
        group_list => "a group name",
        outputs | output => "an output field",
        compensated => "`compensated`",
        rate => "a rate `x' = ...`",
        module_path | string | path_part => "a module path",
        storage => "`field` or `state`",
        item | use_item | group_decl | field_decl | param_decl | const_decl | kernel_select | kernel_def | fn_def
        | pairsum_def | particle_def | integrate_def | timestep_def | require_def => {
            "an item (field, param, pairsum, particle, ...)"
        }
        kernel_entry | kernel_key => "a kernel entry (support, norm1, norm2, norm3, w, dw)",
        on_clause => "`on`",
        from_clause => "`from`",
        K_own => "`own`",
        own_body => "`own body`",
        K_body => "`body`",
        fn_param => "a parameter",
        K_use => "`use`",
        K_group => "`group`",
        K_param => "`param`",
        K_const => "`const`",
        K_kernel => "`kernel`",
        K_fn => "`fn`",
        K_pairsum => "`pairsum`",
        K_particle => "`particle`",
        K_integrate => "`integrate`",
        K_timestep => "`timestep`",
        K_require => "`require`",
        K_on => "`on`",
        K_from => "`from`",
        K_let => "`let`",
        K_if => "`if`",
        K_else => "`else`",
        K_init => "`init`",
        K_finally => "`finally`",
        K_in => "`in`",
        K_acc => "`acc`",
        K_rbrace => "`}`",
        K_rparen => "`)`",
        K_arrow => "`->`",
        K_rbracket => "`]`",
        temp_decl => "`acc`",
        _ => "something else",
    }
}

fn pratt() -> &'static PrattParser<Rule> {
    static P: OnceLock<PrattParser<Rule>> = OnceLock::new();
    P.get_or_init(|| {
        PrattParser::new()
            .op(Op::infix(Rule::or, Assoc::Left))
            .op(Op::infix(Rule::and, Assoc::Left))
            .op(Op::infix(Rule::eq, Assoc::Left) | Op::infix(Rule::ne, Assoc::Left))
            .op(Op::infix(Rule::lt, Assoc::Left)
                | Op::infix(Rule::le, Assoc::Left)
                | Op::infix(Rule::gt, Assoc::Left)
                | Op::infix(Rule::ge, Assoc::Left))
            .op(Op::infix(Rule::add, Assoc::Left) | Op::infix(Rule::sub, Assoc::Left))
            .op(Op::infix(Rule::mul, Assoc::Left) | Op::infix(Rule::div, Assoc::Left))
            .op(Op::prefix(Rule::neg) | Op::prefix(Rule::not))
            .op(Op::infix(Rule::pow, Assoc::Right))
            .op(Op::postfix(Rule::index) | Op::postfix(Rule::member))
    })
}

/// The operators among the children of an `expr` pair (everything but its operands).
fn is_operator(r: Rule) -> bool {
    use Rule::*;
    matches!(r, or | and | eq | ne | le | ge | lt | gt | add | sub | mul | div | pow | neg | not | index | member)
}

fn is_keyword(r: Rule) -> bool {
    use Rule::*;
    matches!(
        r,
        K_use
            | K_group
            | K_param
            | K_const
            | K_kernel
            | K_fn
            | K_pairsum
            | K_particle
            | K_integrate
            | K_timestep
            | K_require
            | K_on
            | K_from
            | K_let
            | K_if
            | K_else
            | K_init
            | K_finally
            | K_in
            | K_acc
            | K_rbrace
            | K_rparen
            | K_arrow
            | K_rbracket
    )
}

/// The children of a pair, keywords left out.
fn kids(p: Pair<Rule>) -> impl Iterator<Item = Pair<Rule>> {
    p.into_inner().filter(|c| !is_keyword(c.as_rule()))
}

struct Builder {
    file: u32,
    /// Where the parsed text starts in the file (an expression inside a case file).
    offset: usize,
    /// The levels of the tree above the node being built.
    depth: Cell<usize>,
    /// Where the tree first went deeper than [`MAX_DEPTH`].
    too_deep: Cell<Option<Span>>,
}

impl Builder {
    fn new(file: u32, offset: usize) -> Builder {
        Builder { file, offset, depth: Cell::new(0), too_deep: Cell::new(None) }
    }

    /// The tree built, or E0004 where it went too deep.
    fn finish<T>(&self, built: T) -> Result<T, Box<Diagnostic>> {
        match self.too_deep.get() {
            Some(span) => Err(Box::new(too_deep(span))),
            None => Ok(built),
        }
    }

    /// Enters `levels` levels of the tree at `span`: false (and E0004 noted) when that is too deep;
    /// otherwise the caller builds, then calls [`Builder::leave`] with the same count.
    fn enter(&self, levels: usize, span: Span) -> bool {
        let d = self.depth.get() + levels;
        if d > MAX_DEPTH {
            if self.too_deep.get().is_none() {
                self.too_deep.set(Some(span));
            }
            return false;
        }
        self.depth.set(d);
        true
    }

    fn leave(&self, levels: usize) {
        self.depth.set(self.depth.get() - levels);
    }

    /// A pair's span without the whitespace and comments pest lets a rule absorb at its end.
    fn span(&self, p: &Pair<Rule>) -> Span {
        let s = p.as_span();
        let start = self.offset + s.start();
        Span::new(self.file, start, start + trimmed_len(p.as_str()))
    }

    fn ident(&self, p: Pair<Rule>) -> Ident {
        Ident { name: p.as_str().to_string(), span: self.span(&p) }
    }

    fn item(&self, p: Pair<Rule>) -> Item {
        let span = self.span(&p);
        match p.as_rule() {
            Rule::use_item => {
                let mut it = kids(p);
                let target = it.next().expect("use has a path");
                let path = match target.as_rule() {
                    Rule::string => UsePath::File(target.as_str().trim_matches('"').to_string()),
                    _ => UsePath::Module(kids(target).map(|i| self.ident(i)).collect()),
                };
                let (mut on, mut from, mut own, mut own_body) = (None, None, false, false);
                for c in it {
                    match c.as_rule() {
                        Rule::on_clause => on = Some(self.groups(c)),
                        Rule::from_clause if self.is_own_body(&c) => own_body = true,
                        Rule::from_clause if self.is_own(&c) => own = true,
                        Rule::from_clause => from = Some(self.groups(c)),
                        _ => {}
                    }
                }
                Item::Use(Use { path, on, from, own, own_body, span })
            }
            Rule::group_decl => Item::Groups(kids(p).map(|i| self.ident(i)).collect()),
            Rule::field_decl => {
                let mut it = kids(p);
                let storage = match it.next().map(|s| s.as_str()) {
                    Some("state") => Storage::State,
                    _ => Storage::Field,
                };
                let name = self.ident(it.next().expect("field name"));
                let ty = self.type_spec(it.next().expect("field type"));
                let init = it.next().map(|e| self.expr(e));
                Item::Field(FieldDecl { storage, name, ty, init, span })
            }
            Rule::param_decl => {
                let mut it = kids(p);
                let name = self.ident(it.next().expect("param name"));
                let ty = self.type_spec(it.next().expect("param type"));
                let default = it.next().map(|e| self.expr(e));
                Item::Param(ParamDecl { name, ty, default, span })
            }
            Rule::const_decl => {
                let mut it = kids(p);
                let name = self.ident(it.next().expect("const name"));
                let value = self.expr(it.next().expect("const value"));
                Item::Const(ConstDecl { name, value, span })
            }
            Rule::kernel_select => Item::KernelSelect(self.ident(kids(p).next().expect("kernel name"))),
            Rule::kernel_def => {
                let mut it = kids(p);
                let name = self.ident(it.next().expect("kernel name"));
                let entries = it.map(|e| self.kernel_entry(e)).collect();
                Item::Kernel(KernelDef { name, entries, span })
            }
            Rule::fn_def => Item::Fn(self.fn_def(p)),
            Rule::pairsum_def => Item::PairSum(self.pairsum(p)),
            Rule::particle_def => {
                let mut def = ParticleDef {
                    name: Ident { name: String::new(), span },
                    on: None,
                    outputs: vec![],
                    body: vec![],
                    span,
                };
                for c in kids(p) {
                    match c.as_rule() {
                        Rule::ident => def.name = self.ident(c),
                        Rule::on_clause => def.on = Some(self.groups(c)),
                        Rule::outputs => def.outputs = self.outputs(c),
                        Rule::block => def.body = self.block(c),
                        _ => {}
                    }
                }
                Item::Particle(def)
            }
            Rule::integrate_def => {
                let mut def = IntegrateDef { on: None, rates: vec![], span };
                for c in kids(p) {
                    match c.as_rule() {
                        Rule::on_clause => def.on = Some(self.groups(c)),
                        Rule::rate => {
                            let rspan = self.span(&c);
                            let mut it = kids(c);
                            let state = self.ident(it.next().expect("rate state"));
                            let rate = self.expr(it.next().expect("rate value"));
                            def.rates.push(Rate { state, rate, span: rspan });
                        }
                        _ => {}
                    }
                }
                Item::Integrate(def)
            }
            Rule::timestep_def => {
                let mut it = kids(p);
                let name = self.ident(it.next().expect("timestep name"));
                let value = self.expr(it.next().expect("timestep value"));
                Item::Timestep(TimestepDef { name, value, span })
            }
            Rule::require_def => {
                let mut it = kids(p);
                let cond = self.expr(it.next().expect("require condition"));
                let why = it.next().expect("require message").as_str().trim_matches('"').to_string();
                Item::Require(RequireDef { cond, why, span })
            }
            r => unreachable!("item rule {r:?}"),
        }
    }

    fn kernel_entry(&self, p: Pair<Rule>) -> KernelEntry {
        let mut it = kids(p);
        let key = it.next().expect("kernel key");
        let key_span = self.span(&key);
        let key = key.as_str().to_string();
        let mut next = it.next().expect("kernel value");
        let mut arg = None;
        if next.as_rule() == Rule::ident {
            arg = Some(self.ident(next));
            next = it.next().expect("kernel value");
        }
        KernelEntry { key, key_span, arg, value: self.expr(next) }
    }

    fn fn_def(&self, p: Pair<Rule>) -> FnDef {
        let span = self.span(&p);
        let mut def = FnDef {
            name: Ident { name: String::new(), span },
            params: vec![],
            ret: None,
            lets: vec![],
            body: Expr { kind: ExprKind::Bool(false), span },
            span,
        };
        for c in kids(p) {
            match c.as_rule() {
                Rule::ident => def.name = self.ident(c),
                Rule::fn_param => {
                    let mut it = kids(c);
                    let name = self.ident(it.next().expect("param name"));
                    let ty = it.next().map(|t| self.type_spec(t));
                    def.params.push(FnParam { name, ty });
                }
                Rule::type_spec => def.ret = Some(self.type_spec(c)),
                Rule::fn_body => {
                    for s in kids(c) {
                        match s.as_rule() {
                            Rule::let_stmt => def.lets.push(self.stmt(s)),
                            _ => def.body = self.expr(s),
                        }
                    }
                }
                _ => {}
            }
        }
        def
    }

    fn pairsum(&self, p: Pair<Rule>) -> PairSumDef {
        let span = self.span(&p);
        let mut def = PairSumDef {
            name: Ident { name: String::new(), span },
            on: None,
            from: None,
            own: false,
            own_body: false,
            outputs: vec![],
            temps: vec![],
            compensated: false,
            init: vec![],
            body: vec![],
            finally: vec![],
            span,
        };
        for c in kids(p) {
            match c.as_rule() {
                Rule::ident => def.name = self.ident(c),
                Rule::on_clause => def.on = Some(self.groups(c)),
                Rule::from_clause if self.is_own_body(&c) => def.own_body = true,
                Rule::from_clause if self.is_own(&c) => def.own = true,
                Rule::from_clause => def.from = Some(self.groups(c)),
                Rule::outputs => def.outputs = self.outputs(c),
                Rule::compensated => def.compensated = true,
                Rule::pair_body => {
                    for s in kids(c) {
                        match s.as_rule() {
                            Rule::temp_decl => {
                                let mut it = kids(s);
                                let name = self.ident(it.next().expect("temp name"));
                                let ty = self.type_spec(it.next().expect("temp type"));
                                def.temps.push(Output { name, ty: Some(ty) });
                            }
                            Rule::init_block => def.init = self.block(kids(s).next().expect("init block")),
                            Rule::finally_block => def.finally = self.block(kids(s).next().expect("finally block")),
                            _ => def.body.push(self.stmt(s)),
                        }
                    }
                }
                _ => {}
            }
        }
        def
    }

    /// `from own` rather than `from a | b`.
    /// `from own body`.
    fn is_own_body(&self, clause: &Pair<Rule>) -> bool {
        clause.clone().into_inner().any(|k| k.as_rule() == Rule::own_body)
    }

    fn is_own(&self, clause: &Pair<Rule>) -> bool {
        clause.clone().into_inner().any(|k| k.as_rule() == Rule::K_own)
    }

    fn groups(&self, clause: Pair<Rule>) -> Vec<Ident> {
        let list = kids(clause).next().expect("group list");
        kids(list).map(|g| self.ident(g)).collect()
    }

    fn outputs(&self, p: Pair<Rule>) -> Vec<Output> {
        kids(p)
            .map(|o| {
                let mut it = kids(o);
                let name = self.ident(it.next().expect("output name"));
                let ty = it.next().map(|t| self.type_spec(t));
                Output { name, ty }
            })
            .collect()
    }

    fn type_spec(&self, p: Pair<Rule>) -> TypeSpec {
        let span = self.span(&p);
        let mut it = kids(p);
        let shape = match it.next().expect("shape").as_str() {
            "scalar" => Shape::Scalar,
            "vec" => Shape::Vec,
            "symtensor" => Shape::SymTensor,
            "skewtensor" => Shape::SkewTensor,
            "tensor" => Shape::Tensor,
            _ => Shape::Bool,
        };
        let unit = it.next().map(|u| self.unit(u));
        TypeSpec { shape, unit, span }
    }

    fn unit(&self, p: Pair<Rule>) -> UnitAnnot {
        let span = self.span(&p);
        let inner = kids(p).next().expect("unit body");
        let expr = match inner.as_rule() {
            Rule::unit_none => UnitExpr::One,
            _ => self.unit_expr(inner),
        };
        UnitAnnot { expr, span }
    }

    fn unit_expr(&self, p: Pair<Rule>) -> UnitExpr {
        // `m * s / kg` nests to the left: one level per operator.
        let levels = 1 + p.clone().into_inner().filter(|c| c.as_rule() == Rule::unit_op).count();
        if !self.enter(levels, self.span(&p)) {
            return UnitExpr::One;
        }
        let out = self.unit_chain(p);
        self.leave(levels);
        out
    }

    fn unit_chain(&self, p: Pair<Rule>) -> UnitExpr {
        let mut it = kids(p);
        let mut acc = self.unit_factor(it.next().expect("unit factor"));
        while let Some(op) = it.next() {
            let rhs = self.unit_factor(it.next().expect("unit factor"));
            acc = match op.as_str() {
                "/" => UnitExpr::Div(Box::new(acc), Box::new(rhs)),
                _ => UnitExpr::Mul(Box::new(acc), Box::new(rhs)),
            };
        }
        acc
    }

    fn unit_factor(&self, p: Pair<Rule>) -> UnitExpr {
        let mut it = kids(p);
        let base_pair = it.next().expect("unit base");
        let base = match base_pair.as_rule() {
            Rule::unit_one => UnitExpr::One,
            Rule::unit_name => UnitExpr::Name(self.ident(base_pair)),
            _ => self.unit_expr(base_pair),
        };
        match it.next() {
            None => base,
            Some(pw) => {
                let span = self.span(&pw);
                let text = pw.as_str().trim_start_matches('(').trim_end_matches(')');
                let (num, den) = match text.split_once('/') {
                    Some((n, d)) => (n.parse().unwrap_or(1), d.parse().unwrap_or(1)),
                    None => (text.parse().unwrap_or(1), 1),
                };
                UnitExpr::Pow(Box::new(base), num, den, span)
            }
        }
    }

    fn block(&self, p: Pair<Rule>) -> Vec<Stmt> {
        if !self.enter(1, self.span(&p)) {
            return vec![];
        }
        let out = kids(p).map(|s| self.stmt(s)).collect();
        self.leave(1);
        out
    }

    fn lvalue(&self, p: Pair<Rule>) -> LValue {
        let mut it = kids(p);
        let name = self.ident(it.next().expect("lvalue name"));
        let side = it.next().map(|ix| {
            let sp = self.span(&ix);
            (side_of(kids(ix).next().expect("side").as_str()), sp)
        });
        LValue { name, side }
    }

    fn stmt(&self, p: Pair<Rule>) -> Stmt {
        let span = self.span(&p);
        match p.as_rule() {
            Rule::let_stmt => {
                let mut name = None;
                let mut ty = None;
                let mut value = None;
                for c in kids(p) {
                    match c.as_rule() {
                        Rule::ident => name = Some(self.ident(c)),
                        Rule::type_spec => ty = Some(self.type_spec(c)),
                        _ => value = Some(self.expr(c)),
                    }
                }
                Stmt::Let { name: name.expect("let name"), ty, value: value.expect("let value"), span }
            }
            Rule::assign_stmt => {
                let mut it = kids(p);
                let target = self.lvalue(it.next().expect("target"));
                let value = self.expr(it.next().expect("value"));
                Stmt::Assign { target, value, span }
            }
            Rule::accum_stmt => {
                let mut it = kids(p);
                let target = self.lvalue(it.next().expect("target"));
                let op = match it.next().expect("op").as_str() {
                    "-=" => AccumOp::Sub,
                    "min=" => AccumOp::Min,
                    "max=" => AccumOp::Max,
                    _ => AccumOp::Add,
                };
                let value = self.expr(it.next().expect("value"));
                Stmt::Accum { target, op, value, span }
            }
            Rule::if_stmt => {
                let mut it = kids(p);
                let cond = self.expr(it.next().expect("condition"));
                let then = self.block(it.next().expect("then block"));
                let otherwise = match it.next() {
                    None => vec![],
                    // `else if`: the next `if` is a level below this one.
                    Some(e) if e.as_rule() == Rule::if_stmt => {
                        if !self.enter(1, self.span(&e)) {
                            return Stmt::If { cond, then, otherwise: vec![], span };
                        }
                        let s = vec![self.stmt(e)];
                        self.leave(1);
                        s
                    }
                    Some(e) => self.block(e),
                };
                Stmt::If { cond, then, otherwise, span }
            }
            r => unreachable!("statement rule {r:?}"),
        }
    }

    fn expr(&self, p: Pair<Rule>) -> Expr {
        // The Pratt parser recurses once per operator, and each operator is a level of the tree.
        let span = self.span(&p);
        let levels = 1 + p.clone().into_inner().filter(|c| is_operator(c.as_rule())).count();
        if !self.enter(levels, span) {
            return Expr { kind: ExprKind::Bool(false), span };
        }
        let out = self.pratt_expr(p);
        self.leave(levels);
        out
    }

    fn pratt_expr(&self, p: Pair<Rule>) -> Expr {
        let inner: Pairs<Rule> = p.into_inner();
        pratt()
            .map_primary(|prim| self.primary(prim))
            .map_prefix(|op, rhs| {
                let span = self.span(&op).to(rhs.span);
                let op = if op.as_rule() == Rule::neg { UnOp::Neg } else { UnOp::Not };
                Expr { kind: ExprKind::Unary(op, Box::new(rhs)), span }
            })
            .map_postfix(|lhs, op| {
                let span = lhs.span.to(self.span(&op));
                match op.as_rule() {
                    Rule::index => {
                        let side_pair = kids(op).next().expect("side");
                        let side_span = self.span(&side_pair);
                        let side = side_of(side_pair.as_str());
                        Expr { kind: ExprKind::Index(Box::new(lhs), side, side_span), span }
                    }
                    _ => {
                        let member = self.ident(kids(op).next().expect("member"));
                        Expr { kind: ExprKind::Member(Box::new(lhs), member), span }
                    }
                }
            })
            .map_infix(|lhs, op, rhs| {
                let span = lhs.span.to(rhs.span);
                let op = match op.as_rule() {
                    Rule::or => BinOp::Or,
                    Rule::and => BinOp::And,
                    Rule::eq => BinOp::Eq,
                    Rule::ne => BinOp::Ne,
                    Rule::lt => BinOp::Lt,
                    Rule::le => BinOp::Le,
                    Rule::gt => BinOp::Gt,
                    Rule::ge => BinOp::Ge,
                    Rule::add => BinOp::Add,
                    Rule::sub => BinOp::Sub,
                    Rule::mul => BinOp::Mul,
                    Rule::div => BinOp::Div,
                    _ => BinOp::Pow,
                };
                Expr { kind: ExprKind::Binary(op, Box::new(lhs), Box::new(rhs)), span }
            })
            .parse(inner)
    }

    fn primary(&self, p: Pair<Rule>) -> Expr {
        let span = self.span(&p);
        let kind = match p.as_rule() {
            Rule::number_lit => {
                let mut it = kids(p);
                let text = it.next().expect("number").as_str();
                let value = text.parse::<f64>().unwrap_or(f64::NAN);
                ExprKind::Number(value, it.next().map(|u| self.unit(u)))
            }
            Rule::bool_lit => ExprKind::Bool(p.as_str() == "true"),
            Rule::in_group => {
                let mut it = kids(p);
                let side = side_of(it.next().expect("side").as_str());
                let groups = kids(it.next().expect("groups")).map(|g| self.ident(g)).collect();
                ExprKind::InGroup(side, groups)
            }
            Rule::call => {
                let mut it = kids(p);
                let name = self.ident(it.next().expect("callee"));
                ExprKind::Call(name, it.map(|a| self.expr(a)).collect())
            }
            Rule::name => ExprKind::Name(self.ident(kids(p).next().expect("ident"))),
            Rule::paren => return self.expr(kids(p).next().expect("inner expression")),
            r => unreachable!("primary rule {r:?}"),
        };
        Expr { kind, span }
    }
}

/// Length of `text` without trailing whitespace and comments.
fn trimmed_len(text: &str) -> usize {
    let mut t = text;
    loop {
        let before = t.len();
        t = t.trim_end();
        if let Some(open) = t.strip_suffix("*/").and_then(|rest| rest.rfind("/*")) {
            t = &t[..open];
        }
        let line_start = t.rfind('\n').map(|k| k + 1).unwrap_or(0);
        if let Some(c) = t[line_start..].find("//") {
            t = &t[..line_start + c];
        }
        if t.len() == before {
            return t.len();
        }
    }
}

fn side_of(s: &str) -> Side {
    if s == "j" {
        Side::J
    } else {
        Side::I
    }
}
