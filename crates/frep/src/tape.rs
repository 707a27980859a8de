//! The compiled evaluator: a [`Shape`] flattened into a register-allocated instruction list
//! (a *tape*), evaluated at points, on batches of points, over boxes (intervals) and with
//! gradients — four evaluators over one instruction list, whose agreement the shared
//! conformance suite checks.
//!
//! Design (after the tape/interval/simplification architecture of fidget):
//! * the graph is already deduplicated and topologically sorted, so the tape is the graph's
//!   non-leaf nodes in order; constants and coordinates become immediate operands;
//! * registers are reused once a value's last use has passed (linear scan), so even long
//!   models need few registers and a batch's working set stays in cache;
//! * batch evaluation runs each instruction over a whole block of [`LANES`] points before
//!   the next instruction, in plain loops over slices that the compiler vectorises;
//! * interval evaluation over a box records which side every `min`, `max` and `select`
//!   takes there ([`Choice`]); [`Tape::simplify`] drops the sides that cannot matter, giving
//!   a shorter tape that is **exactly** equal to the full one everywhere in the box (a pruned
//!   side never decides the value and is never NaN there). Grid sampling and ray casting
//!   evaluate such specialised tapes.

use glam::DVec3;
use multiversion::multiversion;

use crate::ops::{self, BinaryOp, Choice, Dual, Interval, UnaryOp};
use crate::shape::{Id, Node, Shape, VoxelOp};

/// Points per batch block: each instruction runs over this many points at a time.
pub const LANES: usize = 256;

/// An operand of an instruction.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Arg {
    Reg(u32),
    Imm(f64),
    Input(u8),
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Instr {
    Unary(UnaryOp, u32, Arg),
    Binary(BinaryOp, u32, Arg, Arg),
    Select(u32, Arg, Arg, Arg),
    /// A sample of the shape's field `op.field` at the index `(a, b, c)`.
    Voxel(VoxelOp, u32, Arg, Arg, Arg),
}

/// A compiled defining function. Cheap to clone (the graph is shared); evaluation methods
/// take `&self` and keep their scratch space in the caller's evaluator or on the stack, so
/// one tape serves many threads.
#[derive(Debug, Clone)]
pub struct Tape {
    shape: Shape,
    instrs: Vec<Instr>,
    regs: usize,
    output: Arg,
    /// Number of `min`, `max` and `select` instructions (what specialisation can prune).
    choices: usize,
    /// Per instruction, the lanes row-structured evaluation computes it on.
    classes: Vec<Class>,
}

impl Tape {
    /// Compile `shape`: register allocation by linear scan over the graph.
    #[must_use]
    pub fn new(shape: &Shape) -> Tape {
        let nodes = shape.nodes();
        let n = nodes.len();
        let mut last_use = vec![0usize; n];
        for (i, node) in nodes.iter().enumerate() {
            for a in args(node) {
                last_use[a as usize] = i;
            }
        }
        let root = shape.root() as usize;
        last_use[root] = usize::MAX;
        let mut arg_of: Vec<Arg> = Vec::with_capacity(n);
        let mut free: Vec<u32> = Vec::new();
        let mut regs = 0u32;
        let mut instrs = Vec::new();
        let mut classes = Vec::new();
        let mut dep_of: Vec<u8> = Vec::with_capacity(n);
        for (i, node) in nodes.iter().enumerate() {
            let d = match *node {
                Node::Input(a) => 1u8 << a.min(2),
                Node::Const(_) => 0,
                _ => args(node).fold(0u8, |m, a| m | dep_of[a as usize]),
            };
            dep_of.push(d);
            // Every operation runs on the fewest lanes its inputs distinguish; an operation
            // combining compact values of different classes reads them broadcast.
            let class = Class::of(d);
            let leaf = match *node {
                Node::Input(a) => Some(Arg::Input(a.min(2))),
                Node::Const(b) => Some(Arg::Imm(f64::from_bits(b))),
                _ => None,
            };
            if let Some(a) = leaf {
                arg_of.push(a);
                continue;
            }
            let out = free.pop().unwrap_or_else(|| {
                regs += 1;
                regs - 1
            });
            let g = |a: Id| arg_of[a as usize];
            classes.push(class);
            instrs.push(match *node {
                Node::Unary(op, a) => Instr::Unary(op, out, g(a)),
                Node::Binary(op, a, b) => Instr::Binary(op, out, g(a), g(b)),
                Node::Select(c, a, b) => Instr::Select(out, g(c), g(a), g(b)),
                Node::Voxel(op, a, b, c) => Instr::Voxel(op, out, g(a), g(b), g(c)),
                Node::Input(_) | Node::Const(_) => unreachable_leaf(),
            });
            // Free the arguments whose last use is this instruction (after the output was
            // allocated, so an output never aliases an argument).
            let mut done: [Option<u32>; 3] = [None; 3];
            for (k, a) in args(node).enumerate() {
                if last_use[a as usize] == i
                    && let Arg::Reg(r) = arg_of[a as usize]
                    && !done.contains(&Some(r))
                {
                    free.push(r);
                    done[k] = Some(r);
                }
            }
            arg_of.push(Arg::Reg(out));
        }
        let choices = instrs
            .iter()
            .filter(|i| {
                matches!(
                    i,
                    Instr::Binary(BinaryOp::Min | BinaryOp::Max, ..) | Instr::Select(..)
                )
            })
            .count();
        Tape {
            shape: shape.clone(),
            output: arg_of[root],
            instrs,
            regs: regs as usize,
            choices,
            classes,
        }
    }

    /// The graph this tape was compiled from.
    #[must_use]
    pub fn shape(&self) -> &Shape {
        &self.shape
    }

    /// Number of instructions (non-leaf graph nodes).
    #[must_use]
    pub fn len(&self) -> usize {
        self.instrs.len()
    }

    /// Whether the function is a constant or a bare coordinate (no instruction).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.instrs.is_empty()
    }

    /// Number of `min`, `max` and `select` instructions: `0` means [`Tape::simplify`] can
    /// never shorten this tape.
    #[must_use]
    pub fn choice_count(&self) -> usize {
        self.choices
    }

    /// Number of registers a batch or point evaluation needs.
    #[must_use]
    pub fn register_count(&self) -> usize {
        self.regs
    }

    /// The value `f(p)`.
    #[must_use]
    pub fn eval(&self, p: DVec3) -> f64 {
        let mut regs = vec![0.0; self.regs];
        self.eval_with(p, &mut regs)
    }

    /// The value `f(p)` using `regs` as scratch (resized as needed), for loops that evaluate
    /// many points without allocating.
    pub fn eval_with(&self, p: DVec3, regs: &mut Vec<f64>) -> f64 {
        if regs.len() < self.regs {
            regs.resize(self.regs, 0.0);
        }
        let pa = p.to_array();
        let get = |a: Arg, regs: &[f64]| match a {
            Arg::Reg(r) => regs[r as usize],
            Arg::Imm(v) => v,
            Arg::Input(k) => pa[usize::from(k)],
        };
        for ins in &self.instrs {
            match *ins {
                Instr::Unary(op, o, a) => regs[o as usize] = ops::unary(op, get(a, regs)),
                Instr::Binary(op, o, a, b) => {
                    regs[o as usize] = ops::binary(op, get(a, regs), get(b, regs));
                }
                Instr::Select(o, c, a, b) => {
                    regs[o as usize] = ops::select(get(c, regs), get(a, regs), get(b, regs));
                }
                Instr::Voxel(op, o, a, b, c) => {
                    let u = [get(a, regs), get(b, regs), get(c, regs)];
                    regs[o as usize] = self.shape.fields()[op.field as usize].eval(op.order, u);
                }
            }
        }
        get(self.output, regs)
    }

    /// The value and gradient `(f(p), ∇f(p))` by forward-mode differentiation. The value is
    /// bit-for-bit [`Tape::eval`]'s.
    #[must_use]
    pub fn gradient(&self, p: DVec3) -> (f64, DVec3) {
        let mut regs = vec![Dual::constant(0.0); self.regs];
        self.gradient_with(p, &mut regs)
    }

    /// [`Tape::gradient`] with caller-provided scratch.
    pub fn gradient_with(&self, p: DVec3, regs: &mut Vec<Dual>) -> (f64, DVec3) {
        if regs.len() < self.regs {
            regs.resize(self.regs, Dual::constant(0.0));
        }
        let inputs = [
            Dual {
                v: p.x,
                d: DVec3::X,
            },
            Dual {
                v: p.y,
                d: DVec3::Y,
            },
            Dual {
                v: p.z,
                d: DVec3::Z,
            },
        ];
        let get = |a: Arg, regs: &[Dual]| match a {
            Arg::Reg(r) => regs[r as usize],
            Arg::Imm(v) => Dual::constant(v),
            Arg::Input(k) => inputs[usize::from(k)],
        };
        for ins in &self.instrs {
            match *ins {
                Instr::Unary(op, o, a) => regs[o as usize] = ops::unary_dual(op, get(a, regs)),
                Instr::Binary(op, o, a, b) => {
                    regs[o as usize] = ops::binary_dual(op, get(a, regs), get(b, regs));
                }
                Instr::Select(o, c, a, b) => {
                    regs[o as usize] = ops::select_dual(get(c, regs), get(a, regs), get(b, regs));
                }
                Instr::Voxel(op, o, a, b, c) => {
                    let (a, b, c) = (get(a, regs), get(b, regs), get(c, regs));
                    let (v, g) = self.shape.fields()[op.field as usize]
                        .eval_with_gradient(op.order, [a.v, b.v, c.v]);
                    regs[o as usize] = Dual {
                        v,
                        d: a.d * g[0] + b.d * g[1] + c.d * g[2],
                    };
                }
            }
        }
        let r = get(self.output, regs);
        (r.v, r.d)
    }

    /// Evaluate at the points `(x[i], y[i], z[i])` into `out[i]`, block by block.
    ///
    /// # Panics
    /// Never; the slices are truncated to the shortest length.
    pub fn eval_batch(&self, x: &[f64], y: &[f64], z: &[f64], out: &mut [f64]) {
        let mut scratch = BatchScratch::default();
        self.eval_batch_with(x, y, z, out, &mut scratch);
    }

    /// [`Tape::eval_batch`] with caller-provided scratch registers.
    pub fn eval_batch_with(
        &self,
        x: &[f64],
        y: &[f64],
        z: &[f64],
        out: &mut [f64],
        scratch: &mut BatchScratch,
    ) {
        batch_kernel(self, x, y, z, out, scratch);
    }

    /// Body of [`Tape::eval_batch_with`], inlined into each compiled variant of
    /// [`batch_kernel`].
    #[inline(always)]
    fn eval_batch_inner(
        &self,
        x: &[f64],
        y: &[f64],
        z: &[f64],
        out: &mut [f64],
        scratch: &mut BatchScratch,
    ) {
        let n = x.len().min(y.len()).min(z.len()).min(out.len());
        if scratch.regs.len() < self.regs {
            scratch.regs.resize(self.regs, [0.0; LANES]);
        }
        let mut start = 0;
        while start < n {
            let end = (start + LANES).min(n);
            let xs = [&x[start..end], &y[start..end], &z[start..end]];
            self.eval_block(xs, &mut scratch.regs, &mut out[start..end]);
            start = end;
        }
    }

    #[inline(always)]
    fn eval_block(&self, xs: [&[f64]; 3], regs: &mut [[f64; LANES]], out: &mut [f64]) {
        let n = out.len();
        for ins in &self.instrs {
            match *ins {
                Instr::Unary(op, o, a) => {
                    let (dst, lo, hi) = split(regs, o as usize);
                    let a = src(a, lo, hi, o, xs, n);
                    unary_block(op, &mut dst[..n], a);
                }
                Instr::Binary(op, o, a, b) => {
                    let (dst, lo, hi) = split(regs, o as usize);
                    let a = src(a, lo, hi, o, xs, n);
                    let b = src(b, lo, hi, o, xs, n);
                    binary_block(op, &mut dst[..n], a, b);
                }
                Instr::Select(o, c, a, b) => {
                    let (dst, lo, hi) = split(regs, o as usize);
                    let c = src(c, lo, hi, o, xs, n);
                    let a = src(a, lo, hi, o, xs, n);
                    let b = src(b, lo, hi, o, xs, n);
                    for (i, d) in dst[..n].iter_mut().enumerate() {
                        *d = ops::select(c.at(i), a.at(i), b.at(i));
                    }
                }
                Instr::Voxel(op, o, a, b, c) => {
                    let (dst, lo, hi) = split(regs, o as usize);
                    let a = src(a, lo, hi, o, xs, n);
                    let b = src(b, lo, hi, o, xs, n);
                    let c = src(c, lo, hi, o, xs, n);
                    let field = &self.shape.fields()[op.field as usize];
                    for (i, d) in dst[..n].iter_mut().enumerate() {
                        *d = field.eval(op.order, [a.at(i), b.at(i), c.at(i)]);
                    }
                }
            }
        }
        match self.output {
            Arg::Reg(r) => out.copy_from_slice(&regs[r as usize][..n]),
            Arg::Imm(v) => out.fill(v),
            Arg::Input(k) => out.copy_from_slice(xs[usize::from(k)]),
        }
    }

    /// Evaluate on whole grid rows given compactly: point `(i, r)` — lane `r · x.len() + i`
    /// of `out` — is `(x[i], y[r], z[r])`, for `r < out.len() / x.len()` (the slices are
    /// truncated to the shortest). This is the layout of a grid whose x coordinate depends
    /// only on the column and y and z only on the row. Each instruction is evaluated only
    /// on the lanes its inputs distinguish: once if it depends on no input, once per
    /// column if only on x, once per row if not on x, and at every lane otherwise (reading
    /// compact arguments broadcast). Every value is the one [`Tape::eval_batch`] gives on
    /// the expanded points (each operation is a pure function of its arguments), bit for
    /// bit.
    pub(crate) fn eval_rows_with(
        &self,
        x: &[f64],
        y: &[f64],
        z: &[f64],
        out: &mut [f64],
        scratch: &mut BatchScratch,
    ) {
        rows_kernel(self, x, y, z, out, scratch);
    }

    /// Body of [`Tape::eval_rows_with`], inlined into each compiled variant of
    /// [`rows_kernel`].
    #[inline(always)]
    fn eval_rows_inner(
        &self,
        x: &[f64],
        y: &[f64],
        z: &[f64],
        out: &mut [f64],
        scratch: &mut BatchScratch,
    ) {
        let row_len = x.len();
        if row_len == 0 {
            return;
        }
        let rows = y.len().min(z.len()).min(out.len() / row_len);
        if scratch.regs.len() < self.regs {
            scratch.regs.resize(self.regs, [0.0; LANES]);
        }
        if scratch.class.len() < self.regs {
            scratch.class.resize(self.regs, Class::Full);
        }
        // Rows longer than a block are cut into segments, each a block of one row.
        let seg = row_len.min(LANES);
        let per_block = LANES / seg;
        for s0 in (0..row_len).step_by(seg) {
            let s1 = (s0 + seg).min(row_len);
            let xs = &x[s0..s1];
            let mut r0 = 0;
            while r0 < rows {
                let r1 = (r0 + per_block).min(rows);
                if s1 - s0 == row_len {
                    let o = &mut out[r0 * row_len..r1 * row_len];
                    self.eval_rows_block(xs, &y[r0..r1], &z[r0..r1], scratch, o);
                } else {
                    let o = &mut out[r0 * row_len + s0..r0 * row_len + s1];
                    self.eval_rows_block(xs, &y[r0..r1], &z[r0..r1], scratch, o);
                }
                r0 = r1;
            }
        }
    }

    #[inline(always)]
    fn eval_rows_block(
        &self,
        x: &[f64],
        y: &[f64],
        z: &[f64],
        scratch: &mut BatchScratch,
        out: &mut [f64],
    ) {
        let row_len = x.len();
        let rows = out.len() / row_len;
        let n = rows * row_len;
        let BatchScratch { regs, class, tmp } = scratch;
        let compact = Compact {
            row_len,
            rows,
            n,
            x,
            y: &y[..rows],
            z: &z[..rows],
        };
        for (ins, &c) in self.instrs.iter().zip(&self.classes) {
            let (o, m) = match *ins {
                Instr::Unary(_, o, _)
                | Instr::Binary(_, o, _, _)
                | Instr::Select(o, _, _, _)
                | Instr::Voxel(_, o, _, _, _) => (o, compact.len(c)),
            };
            let (dst, lo, hi) = split(regs, o as usize);
            let [t0, t1, t2] = tmp;
            let ctx = (lo, hi, o, &class[..]);
            match *ins {
                Instr::Unary(op, _, a) => {
                    let a = compact.src(a, c, ctx, t0);
                    unary_block(op, &mut dst[..m], a);
                }
                Instr::Binary(op, _, a, b) => {
                    let a = compact.src(a, c, ctx, t0);
                    let b = compact.src(b, c, ctx, t1);
                    binary_block(op, &mut dst[..m], a, b);
                }
                Instr::Select(_, cc, a, b) => {
                    let cc = compact.src(cc, c, ctx, t0);
                    let a = compact.src(a, c, ctx, t1);
                    let b = compact.src(b, c, ctx, t2);
                    for (i, d) in dst[..m].iter_mut().enumerate() {
                        *d = ops::select(cc.at(i), a.at(i), b.at(i));
                    }
                }
                Instr::Voxel(op, _, a, b, cc) => {
                    let a = compact.src(a, c, ctx, t0);
                    let b = compact.src(b, c, ctx, t1);
                    let cc = compact.src(cc, c, ctx, t2);
                    let field = &self.shape.fields()[op.field as usize];
                    for (i, d) in dst[..m].iter_mut().enumerate() {
                        *d = field.eval(op.order, [a.at(i), b.at(i), cc.at(i)]);
                    }
                }
            }
            class[o as usize] = c;
        }
        let out = &mut out[..n];
        match self.output {
            Arg::Reg(r) => compact.expand(&regs[r as usize], class[r as usize], out),
            Arg::Imm(v) => out.fill(v),
            Arg::Input(0) => compact.expand(compact.x, Class::X, out),
            Arg::Input(1) => compact.expand(compact.y, Class::Rows, out),
            Arg::Input(_) => compact.expand(compact.z, Class::Rows, out),
        }
    }

    /// An enclosure of `f` over the box `[lo, hi]` (every point value lies in it, NaN only
    /// if the `nan` flag is set).
    #[must_use]
    pub fn interval(&self, lo: DVec3, hi: DVec3) -> Interval {
        let mut s = IntervalScratch::default();
        self.interval_with(lo, hi, &mut s)
    }

    /// [`Tape::interval`] with scratch; afterwards `scratch` holds the [`Choice`] of every
    /// graph node over the box, for [`Tape::simplify`].
    pub fn interval_with(&self, lo: DVec3, hi: DVec3, s: &mut IntervalScratch) -> Interval {
        let nodes = self.shape.nodes();
        s.values.clear();
        s.choices.clear();
        s.pruned = 0;
        let box_ = [
            Interval::new(lo.x, hi.x),
            Interval::new(lo.y, hi.y),
            Interval::new(lo.z, hi.z),
        ];
        for node in nodes {
            let v = &s.values;
            let (iv, ch) = match *node {
                Node::Input(a) => (box_[usize::from(a.min(2))], Choice::Both),
                Node::Const(b) => (Interval::point(f64::from_bits(b)), Choice::Both),
                Node::Unary(op, a) => (ops::unary_interval(op, v[a as usize]), Choice::Both),
                Node::Binary(op, a, b) => {
                    let (ia, ib) = (v[a as usize], v[b as usize]);
                    let ch = ops::min_max_choice(op, ia, ib);
                    (ops::binary_interval(op, ia, ib), ch)
                }
                Node::Select(c, a, b) => {
                    ops::select_interval(v[c as usize], v[a as usize], v[b as usize])
                }
                Node::Voxel(op, a, b, c) => (
                    self.shape.fields()[op.field as usize]
                        .bound(op.order, [v[a as usize], v[b as usize], v[c as usize]]),
                    Choice::Both,
                ),
            };
            if ch != Choice::Both {
                s.pruned += 1;
            }
            s.values.push(iv);
            s.choices.push(ch);
        }
        s.values[self.shape.root() as usize]
    }

    /// The tape specialised to the box of the last [`Tape::interval_with`] call on `s`:
    /// `min`/`max`/`select` sides that cannot decide the value there are removed, and what
    /// only they used is dropped. Equal to `self` at every point of that box (bit for bit).
    /// Returns `None` when nothing can be pruned (use `self`).
    #[must_use]
    pub fn simplify(&self, s: &IntervalScratch) -> Option<Tape> {
        if s.pruned == 0 || s.choices.len() != self.shape.len() {
            return None;
        }
        let shape = simplify_shape(&self.shape, &s.choices);
        Some(Tape::new(&shape))
    }
}

fn unreachable_leaf() -> Instr {
    // Leaves were handled before; a harmless placeholder keeps this total.
    Instr::Unary(UnaryOp::Neg, 0, Arg::Imm(f64::NAN))
}

/// Arguments of a node.
fn args(n: &Node) -> impl Iterator<Item = Id> {
    let (a, k): ([Id; 3], usize) = match *n {
        Node::Unary(_, a) => ([a, 0, 0], 1),
        Node::Binary(_, a, b) => ([a, b, 0], 2),
        Node::Select(c, a, b) | Node::Voxel(_, c, a, b) => ([c, a, b], 3),
        _ => ([0; 3], 0),
    };
    a.into_iter().take(k)
}

/// The shape with the recorded choices applied (pruned sides replaced by the kept one).
fn simplify_shape(shape: &Shape, choices: &[Choice]) -> Shape {
    let nodes = shape.nodes();
    let mut rep: Vec<Id> = Vec::with_capacity(nodes.len());
    let mut out: Vec<Node> = Vec::with_capacity(nodes.len());
    for (i, n) in nodes.iter().enumerate() {
        let r = |a: Id| rep[a as usize];
        let (node, alias) = match (*n, choices[i]) {
            (Node::Binary(BinaryOp::Min | BinaryOp::Max, a, _), Choice::First)
            | (Node::Select(_, a, _), Choice::First) => (None, Some(r(a))),
            (Node::Binary(BinaryOp::Min | BinaryOp::Max, _, b), Choice::Second)
            | (Node::Select(_, _, b), Choice::Second) => (None, Some(r(b))),
            (Node::Unary(op, a), _) => (Some(Node::Unary(op, r(a))), None),
            (Node::Binary(op, a, b), _) => (Some(Node::Binary(op, r(a), r(b))), None),
            (Node::Select(c, a, b), _) => (Some(Node::Select(r(c), r(a), r(b))), None),
            (Node::Voxel(op, a, b, c), _) => (Some(Node::Voxel(op, r(a), r(b), r(c))), None),
            (leaf, _) => (Some(leaf), None),
        };
        // Fold operations whose arguments became constants (a pruned `max(…, 0)` makes
        // everything computed from it constant); the values are those evaluation would give.
        let konst = |a: Id| out[a as usize].as_const();
        let (node, alias) = match node {
            Some(Node::Unary(op, a)) if konst(a).is_some() => (
                Some(Node::Const(const_bits(ops::unary(
                    op,
                    konst(a).unwrap_or(0.0),
                )))),
                alias,
            ),
            Some(Node::Binary(op, a, b)) if konst(a).is_some() && konst(b).is_some() => (
                Some(Node::Const(const_bits(ops::binary(
                    op,
                    konst(a).unwrap_or(0.0),
                    konst(b).unwrap_or(0.0),
                )))),
                alias,
            ),
            Some(Node::Voxel(op, a, b, c))
                if konst(a).is_some() && konst(b).is_some() && konst(c).is_some() =>
            {
                let u = [a, b, c].map(|i| konst(i).unwrap_or(0.0));
                let v = shape.fields()[op.field as usize].eval(op.order, u);
                (Some(Node::Const(const_bits(v))), alias)
            }
            Some(Node::Select(c, a, b)) if konst(c).is_some_and(|v| !v.is_nan()) => {
                if konst(c).is_some_and(|v| v != 0.0) {
                    (None, Some(a))
                } else {
                    (None, Some(b))
                }
            }
            other => (other, alias),
        };
        // Identities that hold bit for bit for every x (NaN included): x − (+0) = x,
        // x·1 = 1·x = x, x/1 = x. A pruned `max(…, 0)` leaves such operations behind (the
        // smooth-minimum blends: `min(a, b) − h³k/6` with `h` folded to 0).
        let is_bits = |a: Id, v: f64| {
            out.get(a as usize)
                .and_then(Node::as_const)
                .is_some_and(|c| c.to_bits() == v.to_bits())
        };
        let (node, alias) = match node {
            Some(Node::Binary(BinaryOp::Sub, a, b)) if is_bits(b, 0.0) => (None, Some(a)),
            Some(Node::Binary(BinaryOp::Mul | BinaryOp::Div, a, b)) if is_bits(b, 1.0) => {
                (None, Some(a))
            }
            Some(Node::Binary(BinaryOp::Mul, a, b)) if is_bits(a, 1.0) => (None, Some(b)),
            other => (other, alias),
        };
        match (node, alias) {
            (_, Some(a)) => {
                // Keep indices aligned with a dead placeholder.
                out.push(Node::Const(0));
                rep.push(a);
            }
            (Some(nd), None) => {
                out.push(nd);
                rep.push(i as Id);
            }
            (None, None) => {
                out.push(Node::Const(0));
                rep.push(i as Id);
            }
        }
    }
    let root = rep[shape.root() as usize];
    Shape::compact(&out, root, shape.fields())
}

/// Bit pattern of a folded constant (NaNs canonicalised, as the builder does).
fn const_bits(v: f64) -> u64 {
    if v.is_nan() { f64::NAN } else { v }.to_bits()
}

/// Scratch registers of batch evaluation (reuse one per thread).
#[derive(Debug, Clone, Default)]
pub struct BatchScratch {
    regs: Vec<[f64; LANES]>,
    /// Layout of every register in row-structured evaluation.
    class: Vec<Class>,
    /// Expanded operands of row-structured evaluation.
    tmp: [Vec<f64>; 3],
}

/// Which lanes of a row-structured block an instruction is evaluated on (by the inputs it
/// depends on).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Class {
    /// No input: one value (lane 0).
    Const,
    /// Only x: one row's worth (`row_len` values).
    X,
    /// Not x: one value per row (`rows` values).
    Rows,
    /// Every lane.
    Full,
}

impl Class {
    fn of(deps: u8) -> Class {
        match deps {
            0 => Class::Const,
            1 => Class::X,
            d if d & 1 == 0 => Class::Rows,
            _ => Class::Full,
        }
    }
}

type Ctx<'a> = (&'a Regs, &'a Regs, u32, &'a [Class]);

/// Shapes of a row-structured block: `rows` rows of `row_len` points, the x coordinate of
/// every column and the y and z coordinates of every row.
struct Compact<'a> {
    row_len: usize,
    rows: usize,
    n: usize,
    x: &'a [f64],
    y: &'a [f64],
    z: &'a [f64],
}

impl Compact<'_> {
    fn len(&self, c: Class) -> usize {
        match c {
            Class::Const => 1,
            Class::X => self.row_len,
            Class::Rows => self.rows,
            Class::Full => self.n,
        }
    }

    /// Values of class `rc` (stored compactly in `v`) as an operand of an instruction of
    /// class `c`: as they are when the classes agree, broadcast for a full-lane
    /// instruction, compacted through `tmp` otherwise (not produced by compilation — an
    /// instruction's arguments depend on no input it does not — but total).
    #[inline(always)]
    fn view<'b>(&self, v: &'b [f64], rc: Class, c: Class, tmp: &'b mut Vec<f64>) -> Src<'b> {
        match (rc, c) {
            (Class::Const, _) => Src::C(v[0]),
            (rc, c) if rc == c => Src::S(&v[..self.len(c)]),
            (Class::X, Class::Full) => Src::X(&v[..self.row_len]),
            (Class::Rows, Class::Full) => Src::R(&v[..self.rows], self.row_len),
            (rc, c) => {
                tmp.resize(self.n, 0.0);
                self.expand(v, rc, tmp);
                match c {
                    Class::Const => Src::C(tmp[0]),
                    Class::X => Src::S(&tmp[..self.row_len]),
                    Class::Full => Src::S(&tmp[..]),
                    Class::Rows => {
                        for r in 0..self.rows {
                            tmp[r] = tmp[r * self.row_len];
                        }
                        Src::S(&tmp[..self.rows])
                    }
                }
            }
        }
    }

    /// Operand `a` of an instruction of class `c`.
    #[inline(always)]
    fn src<'b>(&'b self, a: Arg, c: Class, ctx: Ctx<'b>, tmp: &'b mut Vec<f64>) -> Src<'b> {
        let (lo, hi, o, class) = ctx;
        match a {
            Arg::Imm(v) => Src::C(v),
            Arg::Input(0) => self.view(self.x, Class::X, c, tmp),
            Arg::Input(1) => self.view(self.y, Class::Rows, c, tmp),
            Arg::Input(_) => self.view(self.z, Class::Rows, c, tmp),
            Arg::Reg(r) => {
                let reg: &'b [f64; LANES] = if r < o {
                    &lo[r as usize]
                } else {
                    &hi[(r - o - 1) as usize]
                };
                self.view(reg, class[r as usize], c, tmp)
            }
        }
    }

    /// Write the full-lane values of values stored with class `c` into `out`.
    fn expand(&self, v: &[f64], c: Class, out: &mut [f64]) {
        match c {
            Class::Const => out.fill(v[0]),
            Class::X => {
                for row in out.chunks_exact_mut(self.row_len) {
                    row.copy_from_slice(&v[..self.row_len]);
                }
            }
            Class::Rows => {
                for (row, &v) in out.chunks_exact_mut(self.row_len).zip(&v[..self.rows]) {
                    row.fill(v);
                }
            }
            Class::Full => out.copy_from_slice(&v[..self.n]),
        }
    }
}

/// Scratch space of interval evaluation: one interval and one [`Choice`] per graph node.
#[derive(Debug, Clone, Default)]
pub struct IntervalScratch {
    values: Vec<Interval>,
    choices: Vec<Choice>,
    pruned: usize,
}

impl IntervalScratch {
    /// Append the [`Choice`] of every graph node over the last box to `key`, one byte each:
    /// two boxes with the same key give the same [`Tape::simplify`] result.
    pub(crate) fn choice_key(&self, key: &mut Vec<u8>) {
        key.extend(self.choices.iter().map(|&c| c as u8));
    }

    /// Number of `min`/`max`/`select` nodes decided over the last box.
    #[must_use]
    pub fn pruned(&self) -> usize {
        self.pruned
    }
}

/// A block operand: a slice of `n` values, a constant, or compact values read broadcast
/// over a row-structured block.
#[derive(Clone, Copy)]
enum Src<'a> {
    S(&'a [f64]),
    C(f64),
    /// One value per column: lane `l` reads `s[l % s.len()]`.
    X(&'a [f64]),
    /// One value per row of the given length: lane `l` reads `s[l / len]`.
    R(&'a [f64], usize),
}

impl<'a> Src<'a> {
    #[inline(always)]
    fn at(&self, i: usize) -> f64 {
        match *self {
            Src::S(s) => s[i],
            Src::C(c) => c,
            Src::X(s) => s[i % s.len()],
            Src::R(s, len) => s[i / len],
        }
    }

    /// Row length of a broadcast operand.
    #[inline(always)]
    fn row_len(&self) -> Option<usize> {
        match *self {
            Src::X(s) => Some(s.len()),
            Src::R(_, len) => Some(len),
            Src::S(_) | Src::C(_) => None,
        }
    }

    /// Row `r` (of length `len`) of the operand, as a slice or a constant.
    #[inline(always)]
    fn row(&self, r: usize, len: usize) -> Src<'a> {
        match *self {
            Src::S(s) => Src::S(&s[r * len..(r + 1) * len]),
            Src::C(c) => Src::C(c),
            Src::X(s) => Src::S(s),
            Src::R(s, _) => Src::C(s[r]),
        }
    }
}

type Regs = [[f64; LANES]];

/// The output register mutably, and the registers before and after it shared.
fn split(regs: &mut Regs, o: usize) -> (&mut [f64; LANES], &Regs, &Regs) {
    let (lo, rest) = regs.split_at_mut(o);
    let (dst, hi) = rest.split_at_mut(1);
    (&mut dst[0], lo, hi)
}

#[inline(always)]
fn src<'a>(a: Arg, lo: &'a Regs, hi: &'a Regs, o: u32, xs: [&'a [f64]; 3], n: usize) -> Src<'a> {
    match a {
        Arg::Reg(r) if r < o => Src::S(&lo[r as usize][..n]),
        Arg::Reg(r) => Src::S(&hi[(r - o - 1) as usize][..n]),
        Arg::Imm(v) => Src::C(v),
        Arg::Input(k) => Src::S(xs[usize::from(k)]),
    }
}

/// [`Tape::eval_batch_with`], compiled for the baseline target and for x86-64 with AVX2 and
/// FMA (four lanes per vector operation), chosen at run time. The two give the same values
/// bit for bit: every operation is the same IEEE operation or the same library call, and no
/// multiply-add is contracted.
#[multiversion(targets("x86_64+avx2+fma"))]
fn batch_kernel(
    tape: &Tape,
    x: &[f64],
    y: &[f64],
    z: &[f64],
    out: &mut [f64],
    scratch: &mut BatchScratch,
) {
    tape.eval_batch_inner(x, y, z, out, scratch);
}

/// [`Tape::eval_rows_with`], compiled like [`batch_kernel`].
#[multiversion(targets("x86_64+avx2+fma"))]
fn rows_kernel(
    tape: &Tape,
    x: &[f64],
    y: &[f64],
    z: &[f64],
    out: &mut [f64],
    scratch: &mut BatchScratch,
) {
    tape.eval_rows_inner(x, y, z, out, scratch);
}

#[inline(always)]
fn map1(o: &mut [f64], a: Src<'_>, f: impl Fn(f64) -> f64) {
    match a {
        Src::S(a) => {
            for (o, &a) in o.iter_mut().zip(a) {
                *o = f(a);
            }
        }
        Src::C(c) => o.fill(f(c)),
        // Not produced by compilation (an operation of one compact value is compact).
        Src::X(_) | Src::R(..) => {
            for (i, o) in o.iter_mut().enumerate() {
                *o = f(a.at(i));
            }
        }
    }
}

#[inline(always)]
fn map2(o: &mut [f64], a: Src<'_>, b: Src<'_>, f: impl Fn(f64, f64) -> f64) {
    if let Some(len) = a.row_len().or(b.row_len()) {
        // A broadcast operand: row by row, each row a slice or a constant.
        for (r, o) in o.chunks_exact_mut(len).enumerate() {
            map2_flat(o, a.row(r, len), b.row(r, len), &f);
        }
    } else {
        map2_flat(o, a, b, f);
    }
}

#[inline(always)]
fn map2_flat(o: &mut [f64], a: Src<'_>, b: Src<'_>, f: impl Fn(f64, f64) -> f64) {
    match (a, b) {
        (Src::S(a), Src::S(b)) => {
            for ((o, &a), &b) in o.iter_mut().zip(a).zip(b) {
                *o = f(a, b);
            }
        }
        (Src::S(a), Src::C(b)) => {
            for (o, &a) in o.iter_mut().zip(a) {
                *o = f(a, b);
            }
        }
        (Src::C(a), Src::S(b)) => {
            for (o, &b) in o.iter_mut().zip(b) {
                *o = f(a, b);
            }
        }
        (Src::C(a), Src::C(b)) => o.fill(f(a, b)),
        (a, b) => {
            for (i, o) in o.iter_mut().enumerate() {
                *o = f(a.at(i), b.at(i));
            }
        }
    }
}

macro_rules! unary_arms {
    ($op:expr, $o:expr, $a:expr, [$($k:ident),*]) => {
        match $op {
            $(UnaryOp::$k => map1($o, $a, |v| ops::unary(UnaryOp::$k, v)),)*
            UnaryOp::PowI(n) => map1($o, $a, |v| ops::unary(UnaryOp::PowI(n), v)),
        }
    };
}

macro_rules! binary_arms {
    ($op:expr, $o:expr, $a:expr, $b:expr, [$($k:ident),*]) => {
        match $op {
            $(BinaryOp::$k => map2($o, $a, $b, |x, y| ops::binary(BinaryOp::$k, x, y)),)*
        }
    };
}

#[inline(always)]
fn unary_block(op: UnaryOp, o: &mut [f64], a: Src<'_>) {
    // Sine and cosine: the branch-free kernel when the whole block is in its range (the
    // same values `ops::sin`/`ops::cos` give there), so the loop vectorises.
    if let (UnaryOp::Sin | UnaryOp::Cos, Src::S(s)) = (op, a)
        && s.iter()
            .fold(true, |ok, v| ok & (v.abs() <= ops::TRIG_FAST_LIMIT))
    {
        if op == UnaryOp::Sin {
            map1(o, a, ops::sin_reduced);
        } else {
            map1(o, a, ops::cos_reduced);
        }
        return;
    }
    unary_arms!(
        op,
        o,
        a,
        [
            Neg, Abs, Sqrt, Square, Exp, Ln, Log10, Sin, Cos, Tan, Asin, Acos, Atan, Sinh, Cosh,
            Tanh, Floor, Ceil, Sign, Not
        ]
    );
}

#[inline(always)]
fn binary_block(op: BinaryOp, o: &mut [f64], a: Src<'_>, b: Src<'_>) {
    binary_arms!(
        op,
        o,
        a,
        b,
        [
            Add,
            Sub,
            Mul,
            Div,
            Min,
            Max,
            Pow,
            Atan2,
            Lt,
            Le,
            Eq,
            Ne,
            And,
            Or,
            RUnion,
            RIntersection
        ]
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::Builder;

    #[test]
    fn registers_are_reused() {
        // A long chain needs two registers however long it is.
        let s = Shape::build(|b, [x, y, _]| {
            let mut acc = b.add(x, y);
            for k in 0..100 {
                let c = b.constant(f64::from(k));
                let t = b.mul(acc, c);
                acc = b.unary(UnaryOp::Sin, t);
            }
            acc
        });
        let t = Tape::new(&s);
        assert!(t.register_count() <= 3, "{}", t.register_count());
        let p = DVec3::new(0.3, 0.2, 0.0);
        assert_eq!(t.eval(p), s.eval_reference(p.to_array()));
    }

    #[test]
    fn row_structured_evaluation_equals_batch_evaluation() {
        // Operations of every class: constant-only, x-only, y/z-only and mixed, costly and
        // cheap, a select, and special values (division by zero, NaN from sqrt).
        let s = Shape::build(|b: &mut Builder, [x, y, z]| {
            let two = b.constant(2.0);
            let k = b.unary(UnaryOp::Sin, two);
            let x3 = b.mul(x, k);
            let sx = b.unary(UnaryOp::Sin, x3);
            let cy = b.unary(UnaryOp::Cos, y);
            let yz = b.add(y, z);
            let dyz = b.binary(BinaryOp::Div, cy, yz);
            let e = b.unary(UnaryOp::Exp, dyz);
            let p = b.mul(sx, e);
            let q = b.unary(UnaryOp::Sqrt, z);
            let c = b.binary(BinaryOp::Lt, sx, cy);
            let sel = b.select(c, p, q);
            let xx = b.mul(x, x);
            let m = b.binary(BinaryOp::Max, sel, xx);
            let w = b.add(m, cy);
            b.add(w, q)
        });
        let t = Tape::new(&s);
        for row_len in [1, 3, 7, 16, 37, LANES, LANES + 44, 3 * LANES] {
            let rows = (700 / row_len + 1).max(6);
            let n = rows * row_len;
            let cx: Vec<f64> = (0..row_len).map(|i| -1.5 + 0.37 * i as f64).collect();
            let cy: Vec<f64> = (0..rows)
                .map(|r| {
                    if r % 5 == 0 {
                        0.0
                    } else {
                        0.9 - 0.11 * r as f64
                    }
                })
                .collect();
            let cz: Vec<f64> = (0..rows)
                .map(|r| {
                    if r % 5 == 0 {
                        0.0
                    } else {
                        0.3 - 0.4 * (r % 3) as f64
                    }
                })
                .collect();
            let (mut xs, mut ys, mut zs) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            for r in 0..rows {
                for (i, &x) in cx.iter().enumerate() {
                    let l = r * row_len + i;
                    (xs[l], ys[l], zs[l]) = (x, cy[r], cz[r]);
                }
            }
            let mut a = vec![0.0; n];
            let mut b = vec![0.0; n];
            let mut sc = BatchScratch::default();
            t.eval_batch_with(&xs, &ys, &zs, &mut a, &mut sc);
            t.eval_rows_with(&cx, &cy, &cz, &mut b, &mut sc);
            for l in 0..n {
                assert_eq!(
                    a[l].to_bits(),
                    b[l].to_bits(),
                    "row_len {row_len}, lane {l}"
                );
                let p = DVec3::new(xs[l], ys[l], zs[l]);
                assert_eq!(t.eval(p).to_bits(), b[l].to_bits());
            }
            assert!(b.iter().any(|v| v.is_nan()) && b.iter().any(|v| v.is_finite()));
        }
    }

    #[test]
    fn simplify_is_exact_inside_the_box() {
        let s = Shape::build(|b: &mut Builder, [x, y, z]| {
            let a = b.add_c(x, -1.0);
            let c = b.mul(y, z);
            let m = b.binary(BinaryOp::Min, a, c);
            let n = b.binary(BinaryOp::Max, m, y);
            b.unary(UnaryOp::Sin, n)
        });
        let t = Tape::new(&s);
        let mut sc = IntervalScratch::default();
        let (lo, hi) = (DVec3::new(-1.0, 2.0, 3.0), DVec3::new(-0.5, 3.0, 4.0));
        let _ = t.interval_with(lo, hi, &mut sc);
        let small = t.simplify(&sc).expect("min is decided");
        assert!(small.len() < t.len());
        for i in 0..50 {
            let f = f64::from(i) / 49.0;
            let p = lo + (hi - lo) * DVec3::new(f, 1.0 - f, f * f);
            assert_eq!(small.eval(p).to_bits(), t.eval(p).to_bits());
        }
    }

    #[test]
    fn simplify_drops_bit_exact_identities_left_by_pruning() {
        // The polynomial smooth minimum of two balls (`s3_blend`): far from the blend,
        // `h = max(k − |a − b|, 0)/k` folds to 0 and `min(a, b) − h³k/6` to `min(a, b)`.
        let src = "m(x[3], a[1]) {
            dx1 = x[1] - 0.45; dx2 = x[1] + 0.45;
            a1 = sqrt(dx1*dx1 + x[2]*x[2] + x[3]*x[3]) - 0.7;
            b1 = sqrt(dx2*dx2 + x[2]*x[2] + x[3]*x[3]) - 0.7;
            k = 0.25; h = max(k - abs(a1 - b1), 0.0) / k;
            f = min(a1, b1) - h*h*h*k/6.0; m = -f; }";
        let t = Tape::new(&crate::compile_source(src, &Default::default()).unwrap());
        let mut sc = IntervalScratch::default();
        let (lo, hi) = (DVec3::new(0.9, -0.2, -0.2), DVec3::new(1.2, 0.2, 0.2));
        let _ = t.interval_with(lo, hi, &mut sc);
        let small = t.simplify(&sc).expect("the blend is decided");
        // −(sqrt(dx1² + y² + z²) − 0.7): 8 operations, no `− 0` left.
        assert!(
            !small.shape().nodes().iter().any(|n| matches!(
                n,
                Node::Binary(BinaryOp::Sub, _, c) if small.shape().nodes()[*c as usize].as_const() == Some(0.0)
            )),
            "{:?}",
            small.shape().nodes()
        );
        for i in 0..50 {
            let f = f64::from(i) / 49.0;
            let p = lo + (hi - lo) * DVec3::new(f, 1.0 - f, f * f);
            assert_eq!(small.eval(p).to_bits(), t.eval(p).to_bits());
        }
        // Signed zeros: x − (−0) is not x (−0 − −0 = +0), so it must stay.
        let s = Shape::build(|b: &mut Builder, [x, _, _]| {
            let nz = b.constant(-0.0);
            let m = b.binary(BinaryOp::Max, x, nz);
            let d = b.binary(BinaryOp::Sub, x, m);
            b.binary(BinaryOp::Min, d, x)
        });
        let t = Tape::new(&s);
        let _ = t.interval_with(DVec3::splat(-2.0), DVec3::splat(-1.0), &mut sc);
        if let Some(small) = t.simplify(&sc) {
            let p = DVec3::splat(-1.5);
            assert_eq!(small.eval(p).to_bits(), t.eval(p).to_bits());
        }
    }
}
