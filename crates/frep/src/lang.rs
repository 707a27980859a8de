//! The model language: a hand-written lexer and recursive-descent parser for HyperFun
//! programs.
//!
//! # Grammar
//!
//! ```text
//! program  := object+
//! object   := IDENT '(' param (',' param)* ')' '{' stmt* '}'
//! param    := IDENT ('[' NUMBER ']')?          -- x[3]: coordinates; a[k]: parameters
//! stmt     := 'array' decl (',' decl)* ';'     -- decl := IDENT '[' NUMBER ']'
//!           | lvalue '=' expr ';'
//!           | IDENT '(' args ')' ';'            -- a transformation called for its effect
//!           | 'if' expr 'then' stmt* ('else' stmt*)? 'endif' ';'?
//!           | 'while' expr 'loop' stmt* 'endloop' ';'?
//! lvalue   := IDENT ('[' expr ']')?
//! expr     := and  (('|' | 'or' | '||') and)*              -- union / logical or
//! and      := rel  (('&' | '\' | '@' | 'and' | '&&') rel)*  -- intersection, subtraction,
//!                                                             Cartesian product / logical and
//! rel      := sum  (('<' | '>' | '<=' | '>=' | '=' | '==' | '/=' | '!=' | '<>') sum)?
//! sum      := prod (('+' | '-') prod)*
//! prod     := unary (('*' | '/') unary)*
//! unary    := ('-' | '+' | '~' | '!' | 'not') unary | power
//! power    := primary ('^' unary)?                          -- right-associative, binds
//!                                                             tighter than unary minus
//! primary  := NUMBER | STRING | IDENT | IDENT '[' expr ']' | IDENT '(' args? ')'
//!           | '[' expr (',' expr)* ']' | '(' expr ')'
//! ```
//!
//! A `STRING` is text between double quotes on one line (`\"` and `\\` escape a quote and a
//! backslash); it is accepted only where a function takes a name, as the file of
//! `vmVolume("head.nii.gz", x, level)`.
//!
//! Keywords are case-insensitive; identifiers are case-sensitive. Comments run from `--` or
//! `//` to the end of the line, or between `/*` and `*/`. Array indices are 1-based. An
//! object's value is the value last assigned to its own name.
//!
//! Limits that keep hostile input harmless: sources over [`MAX_SOURCE_BYTES`] and nesting
//! deeper than [`MAX_DEPTH`] are refused with an error (no stack overflow). The depth counts
//! parentheses, blocks and chains of binary operators alike (an expression tree's height), so
//! a sum of more than about [`MAX_DEPTH`] terms must be split into several assignments.

use crate::error::{FrepError, Pos};

/// Largest model source accepted (16 MiB).
pub const MAX_SOURCE_BYTES: usize = 16 << 20;

/// Deepest nesting of expressions and blocks accepted.
pub const MAX_DEPTH: usize = 200;

/// A whole program: one or more objects. The model is the **last** object; earlier objects
/// can be called from later ones like functions.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    /// Objects in source order.
    pub objects: Vec<Object>,
}

/// An object definition `name(x[3], a[k]) { … }`.
#[derive(Debug, Clone, PartialEq)]
pub struct Object {
    /// Object name; the body assigns the result to it.
    pub name: String,
    /// Formal parameters with their declared array sizes (`1` for a scalar without `[…]`).
    pub params: Vec<(String, usize)>,
    /// Statements.
    pub body: Vec<Stmt>,
    /// Position of the name.
    pub pos: Pos,
}

/// A statement.
#[derive(Debug, Clone, PartialEq)]
pub enum Stmt {
    /// `array a[n], b[m];`
    Array(Vec<(String, usize, Pos)>),
    /// `name = expr;` or `name[index] = expr;`.
    Assign {
        /// Target variable.
        name: String,
        /// Element index for `name[index] = …`.
        index: Option<Expr>,
        /// Value.
        value: Expr,
        /// Position of the target.
        pos: Pos,
    },
    /// A call evaluated for its effect on its array arguments (`hfShift3D(x, 1, 0, 0);`).
    Call(Expr),
    /// `if cond then … else … endif`.
    If {
        /// Condition (true when non-zero).
        cond: Expr,
        /// Statements when true.
        then: Vec<Stmt>,
        /// Statements when false.
        otherwise: Vec<Stmt>,
        /// Position of `if`.
        pos: Pos,
    },
    /// `while cond loop … endloop`.
    While {
        /// Condition checked before every iteration.
        cond: Expr,
        /// Loop body.
        body: Vec<Stmt>,
        /// Position of `while`.
        pos: Pos,
    },
}

/// Binary operators of the language.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    /// `+`
    Add,
    /// `-`
    Sub,
    /// `*`
    Mul,
    /// `/`
    Div,
    /// `^`
    Pow,
    /// `|` (R-union on numbers, logical or on conditions), also `or`, `||`.
    Union,
    /// `&` (R-intersection / logical and), also `and`, `&&`.
    Intersection,
    /// `\` (R-subtraction).
    Subtraction,
    /// `@` (Cartesian product: R-intersection of the cylindrical extensions).
    Product,
    /// `<`
    Lt,
    /// `>`
    Gt,
    /// `<=`
    Le,
    /// `>=`
    Ge,
    /// `=` or `==` inside an expression.
    Eq,
    /// `/=`, `!=` or `<>`.
    Ne,
}

/// Unary operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnOp {
    /// `-x`
    Neg,
    /// `~x` (R-negation / logical not), also `!`, `not`.
    Not,
}

/// An expression.
#[derive(Debug, Clone, PartialEq)]
pub enum Expr {
    /// A number.
    Num(f64, Pos),
    /// A string literal (a file or option name; see the grammar).
    Str(String, Pos),
    /// A variable.
    Var(String, Pos),
    /// `name[index]` (1-based).
    Index(String, Box<Expr>, Pos),
    /// `[e1, e2, …]`.
    Array(Vec<Expr>, Pos),
    /// `name(args)`.
    Call(String, Vec<Expr>, Pos),
    /// Unary operation.
    Unary(UnOp, Box<Expr>, Pos),
    /// Binary operation.
    Binary(BinOp, Box<Expr>, Box<Expr>, Pos),
}

impl Expr {
    /// Source position of the expression.
    #[must_use]
    pub fn pos(&self) -> Pos {
        match self {
            Expr::Num(_, p)
            | Expr::Str(_, p)
            | Expr::Var(_, p)
            | Expr::Index(_, _, p)
            | Expr::Array(_, p)
            | Expr::Call(_, _, p)
            | Expr::Unary(_, _, p)
            | Expr::Binary(_, _, _, p) => *p,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Str(String),
    Ident(String),
    Punct(&'static str),
    Eof,
}

const PUNCTS: [&str; 29] = [
    "<=", ">=", "/=", "!=", "<>", "==", "&&", "||", "(", ")", "[", "]", "{", "}", ",", ";", "=",
    "+", "-", "*", "/", "^", "|", "&", "\\", "~", "@", "<", ">",
];

fn lex(src: &str) -> Result<Vec<(Tok, Pos)>, FrepError> {
    let chars: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let (mut i, mut line, mut col) = (0usize, 1u32, 1u32);
    let advance = |i: &mut usize, line: &mut u32, col: &mut u32, c: char| {
        *i += 1;
        if c == '\n' {
            *line += 1;
            *col = 1;
        } else {
            *col += 1;
        }
    };
    while i < chars.len() {
        let c = chars[i];
        let pos = Pos { line, col };
        let next = chars.get(i + 1).copied();
        if c.is_whitespace() {
            advance(&mut i, &mut line, &mut col, c);
            continue;
        }
        if (c == '-' && next == Some('-')) || (c == '/' && next == Some('/')) {
            while i < chars.len() && chars[i] != '\n' {
                {
                    let ch = chars[i];
                    advance(&mut i, &mut line, &mut col, ch);
                }
            }
            continue;
        }
        if c == '/' && next == Some('*') {
            advance(&mut i, &mut line, &mut col, '/');
            advance(&mut i, &mut line, &mut col, '*');
            loop {
                if i >= chars.len() {
                    return Err(FrepError::syntax(pos, "comment `/*` is never closed"));
                }
                if chars[i] == '*' && chars.get(i + 1) == Some(&'/') {
                    advance(&mut i, &mut line, &mut col, '*');
                    advance(&mut i, &mut line, &mut col, '/');
                    break;
                }
                {
                    let ch = chars[i];
                    advance(&mut i, &mut line, &mut col, ch);
                }
            }
            continue;
        }
        if c.is_ascii_digit() || (c == '.' && next.is_some_and(|d| d.is_ascii_digit())) {
            let start = i;
            while i < chars.len() && (chars[i].is_ascii_digit() || chars[i] == '.') {
                {
                    let ch = chars[i];
                    advance(&mut i, &mut line, &mut col, ch);
                }
            }
            if i < chars.len() && (chars[i] == 'e' || chars[i] == 'E') {
                let mut j = i + 1;
                if j < chars.len() && (chars[j] == '+' || chars[j] == '-') {
                    j += 1;
                }
                if j < chars.len() && chars[j].is_ascii_digit() {
                    while i < j {
                        {
                            let ch = chars[i];
                            advance(&mut i, &mut line, &mut col, ch);
                        }
                    }
                    while i < chars.len() && chars[i].is_ascii_digit() {
                        {
                            let ch = chars[i];
                            advance(&mut i, &mut line, &mut col, ch);
                        }
                    }
                }
            }
            let text: String = chars[start..i].iter().collect();
            let v: f64 = text
                .parse()
                .map_err(|_| FrepError::syntax(pos, format!("malformed number `{text}`")))?;
            out.push((Tok::Num(v), pos));
            continue;
        }
        if c == '"' {
            advance(&mut i, &mut line, &mut col, c);
            let mut text = String::new();
            loop {
                match chars.get(i).copied() {
                    None | Some('\n') => {
                        return Err(FrepError::syntax(pos, "string is not closed on its line"));
                    }
                    Some('"') => {
                        advance(&mut i, &mut line, &mut col, '"');
                        break;
                    }
                    Some('\\') if matches!(chars.get(i + 1), Some('"' | '\\')) => {
                        advance(&mut i, &mut line, &mut col, '\\');
                        let ch = chars[i];
                        text.push(ch);
                        advance(&mut i, &mut line, &mut col, ch);
                    }
                    Some(ch) => {
                        text.push(ch);
                        advance(&mut i, &mut line, &mut col, ch);
                    }
                }
            }
            out.push((Tok::Str(text), pos));
            continue;
        }
        if c.is_alphabetic() || c == '_' {
            let start = i;
            while i < chars.len() && (chars[i].is_alphanumeric() || chars[i] == '_') {
                {
                    let ch = chars[i];
                    advance(&mut i, &mut line, &mut col, ch);
                }
            }
            out.push((Tok::Ident(chars[start..i].iter().collect()), pos));
            continue;
        }
        let mut matched = None;
        for p in PUNCTS {
            let pc: Vec<char> = p.chars().collect();
            if chars[i..].starts_with(&pc) {
                matched = Some(p);
                break;
            }
        }
        let Some(p) = matched else {
            return Err(FrepError::syntax(
                pos,
                format!("unexpected character `{c}`"),
            ));
        };
        for ch in p.chars() {
            advance(&mut i, &mut line, &mut col, ch);
        }
        out.push((Tok::Punct(p), pos));
    }
    out.push((Tok::Eof, Pos { line, col }));
    Ok(out)
}

/// Parse a program.
///
/// # Errors
/// [`FrepError::Syntax`] with the line and column of the first problem: an unexpected
/// character or token, a missing `;`, `)`, `endif`…, a malformed number, an unclosed
/// comment, nesting deeper than [`MAX_DEPTH`], a source over [`MAX_SOURCE_BYTES`], or no
/// object at all.
pub fn parse(src: &str) -> Result<Program, FrepError> {
    if src.len() > MAX_SOURCE_BYTES {
        return Err(FrepError::syntax(
            Pos { line: 1, col: 1 },
            format!(
                "model source is {} bytes, more than the {MAX_SOURCE_BYTES} accepted",
                src.len()
            ),
        ));
    }
    let toks = lex(src)?;
    let mut p = Parser {
        toks,
        i: 0,
        depth: 0,
    };
    let mut objects = Vec::new();
    while !matches!(p.peek(), Tok::Eof) {
        objects.push(p.object()?);
    }
    if objects.is_empty() {
        return Err(FrepError::syntax(
            p.pos(),
            "the model has no object (expected `name(x[3], a[1]) { … }`)",
        ));
    }
    Ok(Program { objects })
}

struct Parser {
    toks: Vec<(Tok, Pos)>,
    i: usize,
    depth: usize,
}

fn describe(t: &Tok) -> String {
    match t {
        Tok::Num(v) => format!("number {}", volmorph_io::Num(*v)),
        Tok::Str(t) => format!("string \"{t}\""),
        Tok::Ident(s) => format!("`{s}`"),
        Tok::Punct(p) => format!("`{p}`"),
        Tok::Eof => "end of file".into(),
    }
}

fn is_keyword(s: &str, kw: &str) -> bool {
    s.eq_ignore_ascii_case(kw)
}

const KEYWORDS: [&str; 11] = [
    "array", "if", "then", "else", "endif", "while", "loop", "endloop", "and", "or", "not",
];

impl Parser {
    fn peek(&self) -> &Tok {
        &self.toks[self.i.min(self.toks.len() - 1)].0
    }

    fn pos(&self) -> Pos {
        self.toks[self.i.min(self.toks.len() - 1)].1
    }

    fn bump(&mut self) -> (Tok, Pos) {
        let t = self.toks[self.i.min(self.toks.len() - 1)].clone();
        if self.i < self.toks.len() - 1 {
            self.i += 1;
        }
        t
    }

    fn is_punct(&self, p: &str) -> bool {
        matches!(self.peek(), Tok::Punct(q) if *q == p)
    }

    fn is_kw(&self, kw: &str) -> bool {
        matches!(self.peek(), Tok::Ident(s) if is_keyword(s, kw))
    }

    fn eat_punct(&mut self, p: &str) -> bool {
        if self.is_punct(p) {
            self.bump();
            true
        } else {
            false
        }
    }

    fn expect_punct(&mut self, p: &str, what: &str) -> Result<Pos, FrepError> {
        if self.is_punct(p) {
            Ok(self.bump().1)
        } else {
            Err(FrepError::syntax(
                self.pos(),
                format!("expected `{p}` {what}, found {}", describe(self.peek())),
            ))
        }
    }

    fn expect_kw(&mut self, kw: &str, what: &str) -> Result<(), FrepError> {
        if self.is_kw(kw) {
            self.bump();
            Ok(())
        } else {
            Err(FrepError::syntax(
                self.pos(),
                format!("expected `{kw}` {what}, found {}", describe(self.peek())),
            ))
        }
    }

    fn ident(&mut self, what: &str) -> Result<(String, Pos), FrepError> {
        match self.peek().clone() {
            Tok::Ident(s) if !KEYWORDS.iter().any(|k| is_keyword(&s, k)) => {
                let p = self.bump().1;
                Ok((s, p))
            }
            t => Err(FrepError::syntax(
                self.pos(),
                format!("expected {what}, found {}", describe(&t)),
            )),
        }
    }

    fn size(&mut self) -> Result<usize, FrepError> {
        let pos = self.pos();
        match self.bump().0 {
            Tok::Num(v) if v >= 1.0 && v.fract() == 0.0 && v <= 1e6 => Ok(v as usize),
            t => Err(FrepError::syntax(
                pos,
                format!(
                    "expected an array size (a whole number from 1 to 1000000), found {}",
                    describe(&t)
                ),
            )),
        }
    }

    fn enter(&mut self) -> Result<(), FrepError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(FrepError::syntax(
                self.pos(),
                format!("nesting deeper than {MAX_DEPTH} levels"),
            ));
        }
        Ok(())
    }

    fn object(&mut self) -> Result<Object, FrepError> {
        let (name, pos) = self.ident("an object name")?;
        self.expect_punct("(", "after the object name")?;
        let mut params = Vec::new();
        loop {
            let (p, _) = self.ident("a parameter name")?;
            let size = if self.eat_punct("[") {
                let s = self.size()?;
                self.expect_punct("]", "after the array size")?;
                s
            } else {
                1
            };
            params.push((p, size));
            if !self.eat_punct(",") {
                break;
            }
        }
        self.expect_punct(")", "after the parameters")?;
        self.expect_punct("{", "to open the object body")?;
        let body = self.block(&["}"])?;
        self.expect_punct("}", "to close the object body")?;
        Ok(Object {
            name,
            params,
            body,
            pos,
        })
    }

    /// Statements up to (not including) one of the terminators (keywords or `}`).
    fn block(&mut self, ends: &[&str]) -> Result<Vec<Stmt>, FrepError> {
        self.enter()?;
        let mut out = Vec::new();
        loop {
            let end = match self.peek() {
                Tok::Eof => true,
                Tok::Punct(p) => *p == "}" || ends.contains(p),
                Tok::Ident(s) => ends.iter().any(|e| is_keyword(s, e)),
                Tok::Num(_) | Tok::Str(_) => false,
            };
            if end {
                break;
            }
            out.push(self.stmt()?);
        }
        self.depth -= 1;
        Ok(out)
    }

    fn stmt(&mut self) -> Result<Stmt, FrepError> {
        let pos = self.pos();
        if self.is_kw("array") {
            self.bump();
            let mut decls = Vec::new();
            loop {
                let (n, p) = self.ident("an array name")?;
                self.expect_punct("[", "after the array name")?;
                let s = self.size()?;
                self.expect_punct("]", "after the array size")?;
                decls.push((n, s, p));
                if !self.eat_punct(",") {
                    break;
                }
            }
            self.expect_punct(";", "after the array declaration")?;
            return Ok(Stmt::Array(decls));
        }
        if self.is_kw("if") {
            self.bump();
            let cond = self.expr()?;
            self.expect_kw("then", "after the `if` condition")?;
            let then = self.block(&["else", "endif"])?;
            let otherwise = if self.is_kw("else") {
                self.bump();
                self.block(&["endif"])?
            } else {
                Vec::new()
            };
            self.expect_kw("endif", &format!("to close the `if` at {pos}"))?;
            self.eat_punct(";");
            return Ok(Stmt::If {
                cond,
                then,
                otherwise,
                pos,
            });
        }
        if self.is_kw("while") {
            self.bump();
            let cond = self.expr()?;
            self.expect_kw("loop", "after the `while` condition")?;
            let body = self.block(&["endloop"])?;
            self.expect_kw("endloop", &format!("to close the `while` at {pos}"))?;
            self.eat_punct(";");
            return Ok(Stmt::While { cond, body, pos });
        }
        let (name, npos) = self.ident("a statement")?;
        if self.is_punct("(") {
            let call = self.call_rest(name, npos)?;
            self.expect_punct(";", "after the call")?;
            return Ok(Stmt::Call(call));
        }
        let index = if self.eat_punct("[") {
            let e = self.expr()?;
            self.expect_punct("]", "after the index")?;
            Some(e)
        } else {
            None
        };
        self.expect_punct("=", &format!("after `{name}` (an assignment)"))?;
        let value = self.expr()?;
        self.expect_punct(";", "after the assignment")?;
        Ok(Stmt::Assign {
            name,
            index,
            value,
            pos: npos,
        })
    }

    fn expr(&mut self) -> Result<Expr, FrepError> {
        self.enter()?;
        let r = self.or_expr();
        self.depth -= 1;
        r
    }

    fn or_expr(&mut self) -> Result<Expr, FrepError> {
        let mut l = self.and_expr()?;
        let mark = self.depth;
        loop {
            let pos = self.pos();
            if self.eat_punct("|") || self.eat_punct("||") || self.eat_kw("or") {
                self.enter()?;
                let r = self.and_expr()?;
                l = Expr::Binary(BinOp::Union, Box::new(l), Box::new(r), pos);
            } else {
                self.depth = mark;
                return Ok(l);
            }
        }
    }

    fn eat_kw(&mut self, kw: &str) -> bool {
        if self.is_kw(kw) {
            self.bump();
            true
        } else {
            false
        }
    }

    fn and_expr(&mut self) -> Result<Expr, FrepError> {
        let mut l = self.rel_expr()?;
        let mark = self.depth;
        loop {
            let pos = self.pos();
            let op = if self.eat_punct("&") || self.eat_punct("&&") || self.eat_kw("and") {
                BinOp::Intersection
            } else if self.eat_punct("\\") {
                BinOp::Subtraction
            } else if self.eat_punct("@") {
                BinOp::Product
            } else {
                self.depth = mark;
                return Ok(l);
            };
            self.enter()?;
            let r = self.rel_expr()?;
            l = Expr::Binary(op, Box::new(l), Box::new(r), pos);
        }
    }

    fn rel_expr(&mut self) -> Result<Expr, FrepError> {
        let l = self.sum()?;
        let pos = self.pos();
        let op = match self.peek() {
            Tok::Punct("<") => BinOp::Lt,
            Tok::Punct(">") => BinOp::Gt,
            Tok::Punct("<=") => BinOp::Le,
            Tok::Punct(">=") => BinOp::Ge,
            Tok::Punct("=") | Tok::Punct("==") => BinOp::Eq,
            Tok::Punct("/=") | Tok::Punct("!=") | Tok::Punct("<>") => BinOp::Ne,
            _ => return Ok(l),
        };
        self.bump();
        let r = self.sum()?;
        Ok(Expr::Binary(op, Box::new(l), Box::new(r), pos))
    }

    fn sum(&mut self) -> Result<Expr, FrepError> {
        let mut l = self.prod()?;
        let mark = self.depth;
        loop {
            let pos = self.pos();
            let op = if self.eat_punct("+") {
                BinOp::Add
            } else if self.eat_punct("-") {
                BinOp::Sub
            } else {
                self.depth = mark;
                return Ok(l);
            };
            self.enter()?;
            let r = self.prod()?;
            l = Expr::Binary(op, Box::new(l), Box::new(r), pos);
        }
    }

    fn prod(&mut self) -> Result<Expr, FrepError> {
        let mut l = self.unary()?;
        let mark = self.depth;
        loop {
            let pos = self.pos();
            let op = if self.eat_punct("*") {
                BinOp::Mul
            } else if self.eat_punct("/") {
                BinOp::Div
            } else {
                self.depth = mark;
                return Ok(l);
            };
            self.enter()?;
            let r = self.unary()?;
            l = Expr::Binary(op, Box::new(l), Box::new(r), pos);
        }
    }

    fn unary(&mut self) -> Result<Expr, FrepError> {
        self.enter()?;
        let pos = self.pos();
        let r = if self.eat_punct("-") {
            self.unary()
                .map(|e| Expr::Unary(UnOp::Neg, Box::new(e), pos))
        } else if self.eat_punct("+") {
            self.unary()
        } else if self.eat_punct("~") || self.eat_punct("!") || self.eat_kw("not") {
            self.unary()
                .map(|e| Expr::Unary(UnOp::Not, Box::new(e), pos))
        } else {
            self.power()
        };
        self.depth -= 1;
        r
    }

    fn power(&mut self) -> Result<Expr, FrepError> {
        let base = self.primary()?;
        let pos = self.pos();
        if self.eat_punct("^") {
            let e = self.unary()?;
            return Ok(Expr::Binary(BinOp::Pow, Box::new(base), Box::new(e), pos));
        }
        Ok(base)
    }

    fn call_rest(&mut self, name: String, pos: Pos) -> Result<Expr, FrepError> {
        self.expect_punct("(", "")?;
        let mut args = Vec::new();
        if !self.is_punct(")") {
            loop {
                args.push(self.expr()?);
                if !self.eat_punct(",") {
                    break;
                }
            }
        }
        self.expect_punct(")", &format!("to close the call of `{name}`"))?;
        Ok(Expr::Call(name, args, pos))
    }

    fn primary(&mut self) -> Result<Expr, FrepError> {
        let pos = self.pos();
        match self.peek().clone() {
            Tok::Num(v) => {
                self.bump();
                Ok(Expr::Num(v, pos))
            }
            Tok::Str(t) => {
                self.bump();
                Ok(Expr::Str(t, pos))
            }
            Tok::Punct("(") => {
                self.bump();
                let e = self.expr()?;
                self.expect_punct(")", "to close the parenthesis")?;
                Ok(e)
            }
            Tok::Punct("[") => {
                self.bump();
                let mut items = vec![self.expr()?];
                while self.eat_punct(",") {
                    items.push(self.expr()?);
                }
                self.expect_punct("]", "to close the array")?;
                Ok(Expr::Array(items, pos))
            }
            Tok::Ident(_) => {
                let (name, pos) = self.ident("an expression")?;
                if self.is_punct("(") {
                    return self.call_rest(name, pos);
                }
                if self.eat_punct("[") {
                    let e = self.expr()?;
                    self.expect_punct("]", "after the index")?;
                    return Ok(Expr::Index(name, Box::new(e), pos));
                }
                Ok(Expr::Var(name, pos))
            }
            t => Err(FrepError::syntax(
                pos,
                format!("expected an expression, found {}", describe(&t)),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_object_form() {
        let p = parse(
            "-- a comment\nm(x[3], a[1]) {\n array c[3];\n c = [0, 0, 0];\n s = hfSphere(x, c, 1.5e0);\n if s > 0 then t = 1; else t = -2; endif;\n m = s | -x[1]^2;\n}",
        )
        .unwrap();
        assert_eq!(p.objects.len(), 1);
        let o = &p.objects[0];
        assert_eq!(o.name, "m");
        assert_eq!(o.params, vec![("x".into(), 3), ("a".into(), 1)]);
        assert_eq!(o.body.len(), 5);
        // -x[1]^2 is -(x[1]^2).
        let Stmt::Assign { value, .. } = &o.body[4] else {
            panic!()
        };
        let Expr::Binary(BinOp::Union, _, r, _) = value else {
            panic!("{value:?}")
        };
        assert!(
            matches!(**r, Expr::Unary(UnOp::Neg, ref e, _) if matches!(**e, Expr::Binary(BinOp::Pow, ..)))
        );
    }

    #[test]
    fn errors_have_positions() {
        let e = parse("m(x[3]) {\n  m = 1 +;\n}").unwrap_err();
        assert_eq!(e.pos(), Some(Pos { line: 2, col: 10 }), "{e}");
        let e = parse("m(x[3]) {\n  m = 1\n}").unwrap_err();
        assert!(e.to_string().contains("expected `;`"), "{e}");
        assert_eq!(e.pos().unwrap().line, 3);
        let e = parse("m(x[3]) { if x[1] > 0 then m = 1; }").unwrap_err();
        assert!(e.to_string().contains("endif"), "{e}");
        let e = parse("m(x[3]) { m = 1 $ 2; }").unwrap_err();
        assert!(e.to_string().contains("unexpected character `$`"), "{e}");
        assert!(parse("").is_err());
        assert!(parse("/* open").is_err());
        let deep = format!(
            "m(x[3]) {{ m = {}1{}; }}",
            "(".repeat(5000),
            ")".repeat(5000)
        );
        assert!(parse(&deep).unwrap_err().to_string().contains("nesting"));
        let deep = format!("m(x[3]) {{ m = {}1; }}", "~ ".repeat(5000));
        assert!(parse(&deep).is_err());
        // Long operator chains count as depth too (the compiler recurses on them).
        let long = format!("m(x[3]) {{ m = 1{}; }}", " + x[1]".repeat(5000));
        assert!(parse(&long).unwrap_err().to_string().contains("nesting"));
        let ok = format!("m(x[3]) {{ m = 1{}; }}", " * x[2] + x[1]".repeat(60));
        assert!(parse(&ok).is_ok());
        assert!(parse(&deep).is_err());
    }
}
