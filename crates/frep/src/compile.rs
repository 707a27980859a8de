//! From a parsed [`Program`] to a [`Shape`]: symbolic execution of the model.
//!
//! Every variable holds a graph node (or an array of nodes), so running the statements once
//! builds the expression graph of the whole model; library calls expand into nodes
//! ([`crate::library`]) and calls of other objects are inlined.
//!
//! **Control flow.**
//! * An `if` or `while` whose condition is a constant (it depends only on numbers and model
//!   parameters, as loop counters do) is decided at compile time: the branch not taken
//!   leaves no trace, and a loop is unrolled, up to [`MAX_ITERATIONS`] iterations in all
//!   (more is an error naming the loop: it would not terminate).
//! * **Fallback for data-dependent control flow** (a condition depending on the point):
//!   both branches of an `if` are compiled and every variable either assigns is merged with
//!   a `select(cond, then, else)` node — a variable assigned in one branch only is NaN where
//!   the other branch is taken. A data-dependent `while` is unrolled
//!   [`MAX_DEPENDENT_ITERATIONS`] times with an *active* mask (`active ∧ cond` after every
//!   pass) guarding each update; points still looping after the last pass evaluate to NaN,
//!   and the loop is recorded in the shape ([`crate::Shape::unfinished_loops`]) with its
//!   still-running mask, so grid sampling and ray casting (every volume, mesh, picture and
//!   animation) fail with the loop's line and column ([`crate::FrepError::LoopBudget`])
//!   instead of returning NaN silently. The pass budget
//!   is [`MAX_DEPENDENT_ITERATIONS`]; a loop that needs more at the sampled points must be
//!   rewritten (for example with a closed form, or a loop counter bound known at compile
//!   time, which unrolls up to [`MAX_ITERATIONS`]).
//! * Array indices are 1-based; a constant index out of range is an error, a data-dependent
//!   index is compiled into a chain of selects over the elements (NaN when out of range).
//!
//! The model's parameter array (the second formal parameter, `a[k]`) is bound to constants:
//! [`CompileOptions::params`] (defaults 0), so parameters fold into the graph.
//!
//! **Sampled volumes.** `vmVolume("file", x, level [, "linear" | "cubic" [, outside]])` is
//! the defining function `f(x) = s(x) − level` of a volume file (any format volmorph reads):
//! `s` interpolates the voxels at the physical point `x` (the volume's full geometry,
//! direction matrix included) trilinearly, or with the interpolating cubic B-spline, and is
//! the constant `outside` (default: the smallest voxel value) beyond the volume — so voxels
//! brighter than `level` are solid. `level` may be any expression (a parameter `a[k]`, a
//! function of `x`); `outside` is a number known at compile time. It is an ordinary node of
//! the graph: point, batch, interval (from a min–max pyramid of the voxels) and gradient
//! evaluation all work, and mappings apply to it like to any model (see [`crate::voxel`]).
//! The file name is relative to [`CompileOptions::data_dir`] (the model file's folder; see
//! [`compile_file`]) and must resolve, after symbolic links, inside it unless
//! [`CompileOptions::allow_external_data`] or the process-wide default of
//! `volmorph-volume-io` (the command line's `--allow-external-data`) allows otherwise. The
//! volume counts against the memory budget.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::error::{FrepError, Pos};
use crate::lang::{BinOp, Expr, Object, Program, Stmt, UnOp};
use crate::library::{self, Value};
use crate::ops::{BinaryOp, UnaryOp};
use crate::shape::{Builder, Id, MAX_NODES, Shape};
use crate::voxel::{self, VoxelKernel};

/// Largest total number of loop iterations unrolled at compile time.
pub const MAX_ITERATIONS: usize = 100_000;

/// Passes a data-dependent `while` loop is unrolled (points still looping get NaN).
pub const MAX_DEPENDENT_ITERATIONS: usize = 64;

/// Deepest chain of object calls (recursion is refused anyway; this bounds long chains).
pub const MAX_CALL_DEPTH: usize = 64;

/// Options of [`compile`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CompileOptions {
    /// Values of the model's parameter array, by 1-based index (`params[&1]` is `a[1]`).
    /// Missing entries are 0.
    pub params: HashMap<usize, f64>,
    /// Name of the object to compile; `None` for the last object of the program.
    pub object: Option<String>,
    /// The folder data files named by the model (`vmVolume`) are relative to and must stay
    /// in: the model file's folder ([`compile_file`] sets it). `None` refuses `vmVolume`.
    pub data_dir: Option<PathBuf>,
    /// Accept data files that resolve outside [`data_dir`](Self::data_dir). They are also
    /// accepted when `volmorph-volume-io`'s process-wide default allows external data (the
    /// command line's `--allow-external-data`).
    pub allow_external_data: bool,
}

impl CompileOptions {
    /// Parse one parameter override `aN=VALUE` (`N` ≥ 1, the 1-based index of the model's
    /// parameter array `a[N]`; `VALUE` a finite number; spaces around either are ignored)
    /// into the key and value of [`CompileOptions::params`].
    ///
    /// ```
    /// use volmorph_frep::CompileOptions;
    /// assert_eq!(CompileOptions::parse_param("a2 = 0.5").unwrap(), (2, 0.5));
    /// assert!(CompileOptions::parse_param("a0=1").is_err());
    /// ```
    ///
    /// # Errors
    /// [`FrepError::InvalidArgument`] naming `text` when there is no `=`, the name is not
    /// `a1`, `a2`, …, or the value is not a finite number.
    pub fn parse_param(text: &str) -> Result<(usize, f64), FrepError> {
        let bad = |why: &str| FrepError::InvalidArgument(format!("parameter {text}: {why}"));
        let Some((k, v)) = text.split_once('=') else {
            return Err(bad("expected aN=VALUE, e.g. a1=0.5"));
        };
        let idx: usize = k
            .trim()
            .strip_prefix('a')
            .and_then(|n| n.parse().ok())
            .filter(|&n: &usize| n >= 1)
            .ok_or_else(|| bad("the name must be a1, a2, …"))?;
        let val: f64 = v
            .trim()
            .parse()
            .map_err(|_| bad(&format!("{:?} is not a number", v.trim())))?;
        if !val.is_finite() {
            return Err(bad("the value must be finite"));
        }
        Ok((idx, val))
    }
}

/// Parse and compile model source text.
///
/// # Errors
/// As [`crate::lang::parse`] and [`compile`].
pub fn compile_source(src: &str, options: &CompileOptions) -> Result<Shape, FrepError> {
    let program = crate::lang::parse(src)?;
    compile(&program, options)
}

/// Read and compile a model file: [`compile_source`] with [`CompileOptions::data_dir`] set
/// to the file's folder (unless `options` sets it).
///
/// # Errors
/// [`FrepError::InFile`] naming `path` around the error of reading (a missing file, a
/// file over [`crate::lang::MAX_SOURCE_BYTES`], text that is not UTF-8) or of
/// [`compile_source`].
pub fn compile_file(path: &Path, options: &CompileOptions) -> Result<Shape, FrepError> {
    let in_file = |e: FrepError| FrepError::InFile {
        path: path.display().to_string(),
        source: Box::new(e),
    };
    let bytes = read_bounded(path).map_err(in_file)?;
    let src = String::from_utf8(bytes).map_err(|_| {
        in_file(FrepError::InvalidArgument(
            "the model is not UTF-8 text".into(),
        ))
    })?;
    let mut options = options.clone();
    if options.data_dir.is_none() {
        options.data_dir = Some(path.parent().unwrap_or(Path::new("")).to_path_buf());
    }
    compile_source(&src, &options).map_err(in_file)
}

/// The bytes of a model or specification file of at most [`crate::lang::MAX_SOURCE_BYTES`].
pub(crate) fn read_bounded(path: &Path) -> Result<Vec<u8>, FrepError> {
    use std::io::Read;
    let file = volmorph_io::open_regular(path)?;
    let mut bytes = Vec::new();
    file.take(crate::lang::MAX_SOURCE_BYTES as u64 + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| volmorph_io::IoError::os(path, e))?;
    if bytes.len() > crate::lang::MAX_SOURCE_BYTES {
        return Err(FrepError::InvalidArgument(format!(
            "the file is larger than the {} bytes accepted",
            crate::lang::MAX_SOURCE_BYTES
        )));
    }
    Ok(bytes)
}

/// Compile the model object of `program` into a shape `f(x, y, z)`.
///
/// The object's first formal parameter (`x[3]`; sizes 1–3 are accepted) is bound to the
/// coordinates, the second (if any) to the parameter array.
///
/// # Errors
/// [`FrepError::Compile`] with the position of the offending construct: an undefined
/// variable, an unknown function, a wrong number or kind of arguments, an index out of
/// range, recursion, a constant loop exceeding [`MAX_ITERATIONS`], a graph beyond
/// [`MAX_NODES`], or an object that never assigns its result.
pub fn compile(program: &Program, options: &CompileOptions) -> Result<Shape, FrepError> {
    let obj = match &options.object {
        Some(name) => program
            .objects
            .iter()
            .find(|o| &o.name == name)
            .ok_or_else(|| {
                FrepError::compile(Pos { line: 1, col: 1 }, format!("no object named `{name}`"))
            })?,
        None => program.objects.last().ok_or_else(|| {
            FrepError::compile(Pos { line: 1, col: 1 }, "the program has no object")
        })?,
    };
    let mut b = Builder::new();
    let inputs = b.inputs();
    let mut args = Vec::new();
    for (k, (pname, size)) in obj.params.iter().enumerate() {
        let v = match k {
            0 => {
                if *size > 3 {
                    return Err(FrepError::compile(
                        obj.pos,
                        format!("the point array `{pname}[{size}]` has more than 3 coordinates"),
                    ));
                }
                Value::Array(inputs[..*size].to_vec())
            }
            _ => Value::Array(
                (1..=*size)
                    .map(|i| b.constant(options.params.get(&i).copied().unwrap_or(0.0)))
                    .collect(),
            ),
        };
        args.push(v);
    }
    if let Some(&i) = options
        .params
        .keys()
        .find(|&&i| i == 0 || obj.params.get(1).is_none_or(|(_, n)| i > *n))
    {
        let declared = obj.params.get(1).map_or(0, |p| p.1);
        return Err(FrepError::compile(
            obj.pos,
            format!(
                "parameter a{i} is outside the model's parameter array (it declares {declared})"
            ),
        ));
    }
    let mut ctx = Ctx {
        program,
        options,
        b: &mut b,
        stack: Vec::new(),
        iterations: 0,
        bools: Default::default(),
        pending: Vec::new(),
        unfinished: Vec::new(),
    };
    let root = ctx.object(obj, args, obj.pos)?;
    let loops = ctx
        .unfinished
        .iter()
        .map(|&(pos, active)| crate::shape::LoopGuard {
            pos,
            passes: MAX_DEPENDENT_ITERATIONS,
            active: b.finish(active),
        })
        .collect();
    Ok(b.finish(root).with_loops(loops))
}

struct Ctx<'a> {
    program: &'a Program,
    options: &'a CompileOptions,
    b: &'a mut Builder,
    stack: Vec<String>,
    iterations: usize,
    /// Nodes known to be booleans (results of comparisons and logic).
    bools: std::collections::HashSet<Id>,
    /// In-place updates of point arrays by transformation calls, applied after the
    /// expression that made them.
    pending: Vec<(String, Value)>,
    /// Data-dependent loops unrolled to the pass budget, with their still-running masks.
    unfinished: Vec<(Pos, Id)>,
}

type Env = HashMap<String, Value>;

impl Ctx<'_> {
    fn object(&mut self, obj: &Object, args: Vec<Value>, call_pos: Pos) -> Result<Id, FrepError> {
        if self.stack.contains(&obj.name) {
            return Err(FrepError::compile(
                call_pos,
                format!(
                    "recursive call of `{}` (call chain {} → {})",
                    obj.name,
                    self.stack.join(" → "),
                    obj.name
                ),
            ));
        }
        if self.stack.len() >= MAX_CALL_DEPTH {
            return Err(FrepError::compile(
                call_pos,
                format!("object calls nested deeper than {MAX_CALL_DEPTH}"),
            ));
        }
        self.stack.push(obj.name.clone());
        let mut env: Env = HashMap::new();
        for ((pname, _), v) in obj.params.iter().zip(args) {
            env.insert(pname.clone(), v);
        }
        self.block(&obj.body, &mut env)?;
        self.stack.pop();
        match env.get(&obj.name) {
            Some(Value::Scalar(id)) => Ok(*id),
            Some(Value::Array(_)) => Err(FrepError::compile(
                obj.pos,
                format!("object `{}` assigns an array to its result", obj.name),
            )),
            None => Err(FrepError::compile(
                obj.pos,
                format!(
                    "object `{}` never assigns its result (`{} = …;`)",
                    obj.name, obj.name
                ),
            )),
        }
    }

    fn check_size(&self, pos: Pos) -> Result<(), FrepError> {
        if self.b.len() > MAX_NODES {
            return Err(FrepError::compile(
                pos,
                format!("the model grows beyond {MAX_NODES} operations"),
            ));
        }
        Ok(())
    }

    fn block(&mut self, stmts: &[Stmt], env: &mut Env) -> Result<(), FrepError> {
        for s in stmts {
            self.stmt(s, env)?;
        }
        Ok(())
    }

    fn stmt(&mut self, s: &Stmt, env: &mut Env) -> Result<(), FrepError> {
        match s {
            Stmt::Array(decls) => {
                for (name, n, _) in decls {
                    let z = self.b.constant(0.0);
                    env.insert(name.clone(), Value::Array(vec![z; *n]));
                }
            }
            Stmt::Assign {
                name,
                index,
                value,
                pos,
            } => {
                let v = self.expr(value, env)?;
                self.flush(env);
                match index {
                    None => {
                        if let (Some(Value::Array(old)), Value::Array(new)) = (env.get(name), &v)
                            && old.len() != new.len()
                        {
                            return Err(FrepError::compile(
                                *pos,
                                format!(
                                    "array `{name}` has {} elements, the value assigned has {}",
                                    old.len(),
                                    new.len()
                                ),
                            ));
                        }
                        env.insert(name.clone(), v);
                    }
                    Some(ix) => {
                        let Value::Scalar(v) = v else {
                            return Err(FrepError::compile(
                                value.pos(),
                                format!("cannot store an array in an element of `{name}`"),
                            ));
                        };
                        let i = self.scalar(ix, env)?;
                        let Some(Value::Array(mut a)) = env.get(name).cloned() else {
                            return Err(FrepError::compile(
                                *pos,
                                format!(
                                    "`{name}` is not an array (declare it with `array {name}[n];`)"
                                ),
                            ));
                        };
                        if let Some(k) = self.b.const_value(i) {
                            let k = self.const_index(k, a.len(), name, ix.pos())?;
                            a[k] = v;
                        } else {
                            for (k, e) in a.iter_mut().enumerate() {
                                let kc = self.b.constant((k + 1) as f64);
                                let hit = self.b.binary(BinaryOp::Eq, i, kc);
                                *e = self.b.select(hit, v, *e);
                            }
                        }
                        env.insert(name.clone(), Value::Array(a));
                    }
                }
                self.check_size(*pos)?;
            }
            Stmt::Call(e) => {
                let _ = self.expr(e, env)?;
                self.flush(env);
                self.check_size(e.pos())?;
            }
            Stmt::If {
                cond,
                then,
                otherwise,
                pos,
            } => {
                let c = self.condition(cond, env)?;
                self.flush(env);
                match self.b.const_value(c) {
                    Some(v) if !v.is_nan() => {
                        self.block(if v != 0.0 { then } else { otherwise }, env)?;
                    }
                    _ => {
                        let mut e1 = env.clone();
                        let mut e2 = env.clone();
                        self.block(then, &mut e1)?;
                        self.block(otherwise, &mut e2)?;
                        *env = self.merge(c, &e1, &e2, *pos)?;
                    }
                }
                self.check_size(*pos)?;
            }
            Stmt::While { cond, body, pos } => self.while_loop(cond, body, *pos, env)?,
        }
        Ok(())
    }

    fn const_index(&self, k: f64, len: usize, name: &str, pos: Pos) -> Result<usize, FrepError> {
        if k.fract() == 0.0 && k >= 1.0 && k <= len as f64 {
            Ok(k as usize - 1)
        } else {
            Err(FrepError::compile(
                pos,
                format!("index {k} is outside `{name}[1..{len}]` (indices start at 1)"),
            ))
        }
    }

    /// Merge two environments after a data-dependent branch.
    fn merge(&mut self, c: Id, e1: &Env, e2: &Env, pos: Pos) -> Result<Env, FrepError> {
        let mut out = Env::new();
        let nan = self.b.constant(f64::NAN);
        let mut names: Vec<&String> = e1.keys().chain(e2.keys()).collect();
        names.sort();
        names.dedup();
        for name in names {
            let v = match (e1.get(name), e2.get(name)) {
                (Some(Value::Scalar(a)), Some(Value::Scalar(b))) => {
                    Value::Scalar(self.b.select(c, *a, *b))
                }
                (Some(Value::Array(a)), Some(Value::Array(b))) if a.len() == b.len() => {
                    Value::Array(
                        a.iter()
                            .zip(b)
                            .map(|(&x, &y)| self.b.select(c, x, y))
                            .collect(),
                    )
                }
                (Some(Value::Scalar(a)), None) => Value::Scalar(self.b.select(c, *a, nan)),
                (None, Some(Value::Scalar(b))) => Value::Scalar(self.b.select(c, nan, *b)),
                (Some(Value::Array(a)), None) => {
                    Value::Array(a.iter().map(|&x| self.b.select(c, x, nan)).collect())
                }
                (None, Some(Value::Array(b))) => {
                    Value::Array(b.iter().map(|&y| self.b.select(c, nan, y)).collect())
                }
                _ => {
                    return Err(FrepError::compile(
                        pos,
                        format!(
                            "`{name}` is a number in one branch and an array (or an array of another size) in the other"
                        ),
                    ));
                }
            };
            out.insert(name.clone(), v);
        }
        Ok(out)
    }

    fn while_loop(
        &mut self,
        cond: &Expr,
        body: &[Stmt],
        pos: Pos,
        env: &mut Env,
    ) -> Result<(), FrepError> {
        loop {
            let c = self.condition(cond, env)?;
            match self.b.const_value(c) {
                Some(v) if !v.is_nan() => {
                    if v == 0.0 {
                        return Ok(());
                    }
                    self.iterations += 1;
                    if self.iterations > MAX_ITERATIONS {
                        return Err(FrepError::compile(
                            pos,
                            format!(
                                "loop does not end: more than {MAX_ITERATIONS} iterations at compile time"
                            ),
                        ));
                    }
                    self.block(body, env)?;
                    self.check_size(pos)?;
                }
                _ => return self.dependent_loop(c, cond, body, pos, env),
            }
        }
    }

    /// Masked unrolling of a loop whose condition depends on the point.
    fn dependent_loop(
        &mut self,
        first: Id,
        cond: &Expr,
        body: &[Stmt],
        pos: Pos,
        env: &mut Env,
    ) -> Result<(), FrepError> {
        let mut active = first;
        for _ in 0..MAX_DEPENDENT_ITERATIONS {
            // Unrolled passes share the compile-time iteration budget, so nested
            // data-dependent loops cannot multiply into a hang.
            self.iterations += 1;
            if self.iterations > MAX_ITERATIONS {
                return Err(FrepError::compile(
                    pos,
                    format!("loops unroll into more than {MAX_ITERATIONS} passes at compile time"),
                ));
            }
            let mut next = env.clone();
            self.block(body, &mut next)?;
            *env = self.merge(active, &next, env, pos)?;
            self.check_size(pos)?;
            let c = self.condition(cond, env)?;
            active = self.b.binary(BinaryOp::And, active, c);
            self.mark_bool(active);
            if self.b.const_value(active) == Some(0.0) {
                return Ok(());
            }
        }
        // Points still looping: NaN, and the loop is recorded so that a sampler that meets
        // those points names it.
        self.unfinished.push((pos, active));
        let mut poisoned = env.clone();
        let nan = self.b.constant(f64::NAN);
        for v in poisoned.values_mut() {
            match v {
                Value::Scalar(s) => *s = nan,
                Value::Array(a) => a.iter_mut().for_each(|e| *e = nan),
            }
        }
        *env = self.merge(active, &poisoned, env, pos)?;
        Ok(())
    }

    fn condition(&mut self, e: &Expr, env: &Env) -> Result<Id, FrepError> {
        self.scalar(e, env)
    }

    fn flush(&mut self, env: &mut Env) {
        for (name, v) in self.pending.drain(..) {
            env.insert(name, v);
        }
    }

    fn scalar(&mut self, e: &Expr, env: &Env) -> Result<Id, FrepError> {
        match self.expr(e, env)? {
            Value::Scalar(id) => Ok(id),
            Value::Array(a) => Err(FrepError::compile(
                e.pos(),
                format!(
                    "expected a number, found an array of {} (index it: `name[i]`)",
                    a.len()
                ),
            )),
        }
    }

    fn expr(&mut self, e: &Expr, env: &Env) -> Result<Value, FrepError> {
        Ok(match e {
            Expr::Num(v, _) => Value::Scalar(self.b.constant(*v)),
            Expr::Str(_, pos) => {
                return Err(FrepError::compile(
                    *pos,
                    "a string is accepted only as a file or option name of a function, as in \
                     vmVolume(\"head.nii.gz\", x, level)",
                ));
            }
            Expr::Var(name, pos) => env
                .get(name)
                .cloned()
                .ok_or_else(|| FrepError::compile(*pos, format!("undefined variable `{name}`")))?,
            Expr::Index(name, ix, pos) => {
                let Some(v) = env.get(name).cloned() else {
                    return Err(FrepError::compile(
                        *pos,
                        format!("undefined array `{name}`"),
                    ));
                };
                let Value::Array(a) = v else {
                    return Err(FrepError::compile(
                        *pos,
                        format!("`{name}` is a number, not an array"),
                    ));
                };
                let i = self.scalar(ix, env)?;
                if let Some(k) = self.b.const_value(i) {
                    Value::Scalar(a[self.const_index(k, a.len(), name, ix.pos())?])
                } else {
                    let mut v = self.b.constant(f64::NAN);
                    for (k, &el) in a.iter().enumerate().rev() {
                        let kc = self.b.constant((k + 1) as f64);
                        let hit = self.b.binary(BinaryOp::Eq, i, kc);
                        v = self.b.select(hit, el, v);
                    }
                    Value::Scalar(v)
                }
            }
            Expr::Array(items, _) => {
                let mut out = Vec::with_capacity(items.len());
                for it in items {
                    out.push(self.scalar(it, env)?);
                }
                Value::Array(out)
            }
            Expr::Call(name, args, pos) => self.call(name, args, *pos, env)?,
            Expr::Unary(op, a, _) => {
                let v = self.scalar(a, env)?;
                Value::Scalar(match op {
                    UnOp::Neg => self.b.neg(v),
                    UnOp::Not if self.bools.contains(&v) => {
                        let r = self.b.unary(UnaryOp::Not, v);
                        self.mark_bool(r)
                    }
                    UnOp::Not => self.b.neg(v),
                })
            }
            Expr::Binary(op, l, r, pos) => {
                let a = self.scalar(l, env)?;
                let b = self.scalar(r, env)?;
                Value::Scalar(self.binary(*op, a, b, *pos)?)
            }
        })
    }

    /// Whether `id` is a condition, for deciding between logic and R-functions; constants
    /// 0 and 1 count as conditions next to one.
    fn is_bool(&self, id: Id, other: Id) -> bool {
        self.bools.contains(&id)
            || (self.bools.contains(&other)
                && matches!(self.b.const_value(id), Some(v) if v == 0.0 || v == 1.0))
    }

    fn mark_bool(&mut self, id: Id) -> Id {
        if self.b.const_value(id).is_none() {
            self.bools.insert(id);
        }
        id
    }

    fn binary(&mut self, op: BinOp, a: Id, c: Id, pos: Pos) -> Result<Id, FrepError> {
        let (ba, bc) = (self.is_bool(a, c), self.is_bool(c, a));
        if matches!(op, BinOp::Union | BinOp::Intersection) && ba != bc {
            return Err(FrepError::compile(
                pos,
                format!(
                    "`{}` combines a condition with a number",
                    if op == BinOp::Union { "|" } else { "&" }
                ),
            ));
        }
        let b = &mut *self.b;
        let r = match op {
            BinOp::Add => b.add(a, c),
            BinOp::Sub => b.sub(a, c),
            BinOp::Mul => b.mul(a, c),
            BinOp::Div => b.div(a, c),
            BinOp::Pow => b.binary(BinaryOp::Pow, a, c),
            BinOp::Union if ba => {
                let r = b.binary(BinaryOp::Or, a, c);
                return Ok(self.mark_bool(r));
            }
            BinOp::Intersection if ba => {
                let r = b.binary(BinaryOp::And, a, c);
                return Ok(self.mark_bool(r));
            }
            BinOp::Union => b.union(a, c),
            BinOp::Intersection => b.intersection(a, c),
            BinOp::Subtraction | BinOp::Product => {
                if ba || bc {
                    return Err(FrepError::compile(
                        pos,
                        "set operations `\\` and `@` apply to shapes, not conditions",
                    ));
                }
                if op == BinOp::Subtraction {
                    b.subtraction(a, c)
                } else {
                    b.intersection(a, c)
                }
            }
            BinOp::Lt | BinOp::Gt | BinOp::Le | BinOp::Ge | BinOp::Eq | BinOp::Ne => {
                let r = match op {
                    BinOp::Lt => b.binary(BinaryOp::Lt, a, c),
                    BinOp::Gt => b.binary(BinaryOp::Lt, c, a),
                    BinOp::Le => b.binary(BinaryOp::Le, a, c),
                    BinOp::Ge => b.binary(BinaryOp::Le, c, a),
                    BinOp::Eq => b.binary(BinaryOp::Eq, a, c),
                    _ => b.binary(BinaryOp::Ne, a, c),
                };
                return Ok(self.mark_bool(r));
            }
        };
        Ok(r)
    }

    fn call(&mut self, name: &str, args: &[Expr], pos: Pos, env: &Env) -> Result<Value, FrepError> {
        if name.eq_ignore_ascii_case("vmVolume") {
            return self.vm_volume(args, pos, env);
        }
        // Built-in math functions.
        if let Some((op, arity)) = math_function(name) {
            let ok = match arity {
                Arity::Exactly(n) => args.len() == n,
                Arity::AtLeast(n) => args.len() >= n,
            };
            if !ok {
                let want = match arity {
                    Arity::Exactly(n) => format!("{n}"),
                    Arity::AtLeast(n) => format!("at least {n}"),
                };
                return Err(FrepError::compile(
                    pos,
                    format!("`{name}` takes {want} argument(s), got {}", args.len()),
                ));
            }
            let mut vals = Vec::with_capacity(args.len());
            for a in args {
                vals.push(self.scalar(a, env)?);
            }
            let r = match op {
                Math::Unary(u) => self.b.unary(u, vals[0]),
                Math::Binary(bop) => {
                    let mut acc = vals[0];
                    for &v in &vals[1..] {
                        acc = self.b.binary(bop, acc, v);
                    }
                    acc
                }
            };
            return Ok(Value::Scalar(r));
        }
        if let Some(lib) = library::canonical(name) {
            let mut vals = Vec::with_capacity(args.len());
            for a in args {
                vals.push(self.expr(a, env)?);
            }
            let res = library::call(self.b, lib, &vals).map_err(|m| FrepError::compile(pos, m))?;
            if let Some(p) = res.new_point {
                match args.first() {
                    Some(Expr::Var(var, _)) => {
                        // Transformations change their point array in place.
                        let mut p = p;
                        if let Some(Value::Array(old)) = env.get(var)
                            && old.len() > p.len()
                        {
                            p.extend_from_slice(&old[p.len()..]);
                        }
                        self.pending.push((var.clone(), Value::Array(p)));
                    }
                    _ => {
                        return Err(FrepError::compile(
                            pos,
                            format!(
                                "the first argument of `{name}` must be an array variable (it is changed in place)"
                            ),
                        ));
                    }
                }
            }
            return Ok(Value::Scalar(res.value));
        }
        if let Some(obj) = self.program.objects.iter().find(|o| o.name == name) {
            if args.len() != obj.params.len() {
                return Err(FrepError::compile(
                    pos,
                    format!(
                        "object `{name}` takes {} arguments, got {}",
                        obj.params.len(),
                        args.len()
                    ),
                ));
            }
            let mut vals = Vec::with_capacity(args.len());
            for (a, (pname, size)) in args.iter().zip(&obj.params) {
                let v = self.expr(a, env)?;
                let n = match &v {
                    Value::Scalar(_) => 1,
                    Value::Array(a) => a.len(),
                };
                if n < *size {
                    return Err(FrepError::compile(
                        a.pos(),
                        format!("argument `{pname}` of `{name}` needs {size} values, got {n}"),
                    ));
                }
                vals.push(v);
            }
            return Ok(Value::Scalar(self.object(obj, vals, pos)?));
        }
        let hint = if name.starts_with("hf") {
            format!(
                " (the library has: {})",
                library::library_names().join(", ")
            )
        } else {
            String::new()
        };
        Err(FrepError::compile(
            pos,
            format!("unknown function `{name}`{hint}"),
        ))
    }
}

impl Ctx<'_> {
    /// `vmVolume("file", x, level [, kernel [, outside]])` (see the module docs).
    fn vm_volume(&mut self, args: &[Expr], pos: Pos, env: &Env) -> Result<Value, FrepError> {
        const USAGE: &str = "vmVolume(\"file\", x, level [, \"linear\" | \"cubic\" [, outside]])";
        if !(3..=5).contains(&args.len()) {
            return Err(FrepError::compile(
                pos,
                format!(
                    "`vmVolume` takes 3 to 5 arguments, got {}: {USAGE}",
                    args.len()
                ),
            ));
        }
        let Expr::Str(name, npos) = &args[0] else {
            return Err(FrepError::compile(
                args[0].pos(),
                format!(
                    "the first argument of `vmVolume` is the file name in double quotes: {USAGE}"
                ),
            ));
        };
        let x = match self.expr(&args[1], env)? {
            Value::Array(a) if a.len() >= 3 => [a[0], a[1], a[2]],
            _ => {
                return Err(FrepError::compile(
                    args[1].pos(),
                    format!("the second argument of `vmVolume` is the point array x[3]: {USAGE}"),
                ));
            }
        };
        let level = self.scalar(&args[2], env)?;
        let kernel = match args.get(3) {
            None => VoxelKernel::Linear,
            Some(Expr::Str(k, kpos)) => {
                VoxelKernel::parse(k).map_err(|e| FrepError::compile(*kpos, e.to_string()))?
            }
            Some(e) => {
                return Err(FrepError::compile(
                    e.pos(),
                    format!("the interpolation of `vmVolume` is \"linear\" or \"cubic\": {USAGE}"),
                ));
            }
        };
        let outside = match args.get(4) {
            None => None,
            Some(e) => {
                let id = self.scalar(e, env)?;
                match self.b.const_value(id) {
                    Some(v) if v.is_finite() => Some(v),
                    _ => {
                        return Err(FrepError::compile(
                            e.pos(),
                            "the value outside the volume must be a finite number known at \
                             compile time",
                        ));
                    }
                }
            }
        };
        let Some(dir) = &self.options.data_dir else {
            return Err(FrepError::compile(
                *npos,
                format!(
                    "`vmVolume` cannot find \"{name}\": the model has no folder (compile it \
                     from its file)"
                ),
            ));
        };
        let allow = self.options.allow_external_data
            || volmorph_volume_io::ReadOptions::default().allow_external_data;
        let path = volmorph_io::resolve_in_folder(dir, name, allow)
            .map_err(|e| FrepError::compile(*npos, format!("vmVolume: {e}")))?;
        let field = voxel::load(&path, kernel, outside)
            .map_err(|e| FrepError::compile(*npos, format!("vmVolume \"{name}\": {e}")))?;
        // Continuous voxel index u = M (x − origin).
        let (m, o) = field.index_map();
        let u = [0, 1, 2].map(|r| {
            let mut acc = self.b.constant(0.0);
            for (c, &xc) in x.iter().enumerate() {
                let k = m.col(c)[r];
                if k == 0.0 {
                    continue;
                }
                let d = self.b.add_c(xc, -o[c]);
                let t = self.b.mul_c(d, k);
                acc = self.b.add(acc, t);
            }
            acc
        });
        let s = self.b.voxel(&field, [0; 3], u);
        Ok(Value::Scalar(self.b.sub(s, level)))
    }
}

#[derive(Clone, Copy)]
enum Math {
    Unary(UnaryOp),
    Binary(BinaryOp),
}

#[derive(Clone, Copy)]
enum Arity {
    Exactly(usize),
    AtLeast(usize),
}

fn math_function(name: &str) -> Option<(Math, Arity)> {
    use Arity::{AtLeast, Exactly};
    let u = |op| Some((Math::Unary(op), Exactly(1)));
    match name {
        "sqrt" => u(UnaryOp::Sqrt),
        "exp" => u(UnaryOp::Exp),
        "log" | "ln" => u(UnaryOp::Ln),
        "logd" | "log10" => u(UnaryOp::Log10),
        "sin" => u(UnaryOp::Sin),
        "cos" => u(UnaryOp::Cos),
        "tan" => u(UnaryOp::Tan),
        "asin" | "arcsin" => u(UnaryOp::Asin),
        "acos" | "arccos" => u(UnaryOp::Acos),
        "atan" | "arctan" => u(UnaryOp::Atan),
        "sinh" => u(UnaryOp::Sinh),
        "cosh" => u(UnaryOp::Cosh),
        "tanh" => u(UnaryOp::Tanh),
        "abs" => u(UnaryOp::Abs),
        "sign" => u(UnaryOp::Sign),
        "floor" => u(UnaryOp::Floor),
        "ceil" => u(UnaryOp::Ceil),
        "sqr" => u(UnaryOp::Square),
        "max" => Some((Math::Binary(BinaryOp::Max), AtLeast(2))),
        "min" => Some((Math::Binary(BinaryOp::Min), AtLeast(2))),
        "pow" => Some((Math::Binary(BinaryOp::Pow), Exactly(2))),
        "atan2" => Some((Math::Binary(BinaryOp::Atan2), Exactly(2))),
        _ => None,
    }
}
