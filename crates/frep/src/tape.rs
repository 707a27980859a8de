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
        let mut class_of: Vec<Class> = Vec::with_capacity(n);
        for (i, node) in nodes.iter().enumerate() {
            let d = match *node {
                Node::Input(a) => 1u8 << a.min(2),
                Node::Const(_) => 0,
                _ => args(node).fold(0u8, |m, a| m | dep_of[a as usize]),
            };
            dep_of.push(d);
            // Compact evaluation pays off for costly operations and what is computed from
            // their compact results; cheap operations of raw inputs run on every lane
            // (expanding their results would cost as much as computing them).
            let allowed = Class::of(d);
            let class = if allowed != Class::Full
                && (costly(node) || args(node).any(|a| class_of[a as usize] != Class::Full))
            {
                allowed
            } else {
                Class::Full
            };
            class_of.push(class);
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

    /// Evaluate on a block of whole grid rows: lane `r · row_len + i` is point `i` of row
    /// `r`, where the x coordinate depends only on `i` (every row holds the same x values)
    /// and y and z only on `r` (constant along each row). Each instruction is evaluated
    /// only on the lanes its inputs distinguish: once if it depends on no input, once per
    /// row position if only on x, once per row if not on x, and at every lane otherwise.
    /// Every value is the one [`Tape::eval_batch`] gives (each operation is a pure function
    /// of its arguments), bit for bit.
    ///
    /// The caller guarantees the row structure; `row_len` must be in `1..=LANES` and divide
    /// the length (otherwise this falls back to [`Tape::eval_batch_with`]).
    pub(crate) fn eval_rows_with(
        &self,
        row_len: usize,
        x: &[f64],
        y: &[f64],
        z: &[f64],
        out: &mut [f64],
        scratch: &mut BatchScratch,
    ) {
        rows_kernel(self, row_len, x, y, z, out, scratch);
    }

    /// Body of [`Tape::eval_rows_with`], inlined into each compiled variant of
    /// [`rows_kernel`].
    #[inline(always)]
    fn eval_rows_inner(
        &self,
        row_len: usize,
        x: &[f64],
        y: &[f64],
        z: &[f64],
        out: &mut [f64],
        scratch: &mut BatchScratch,
    ) {
        let n = x.len().min(y.len()).min(z.len()).min(out.len());
        if row_len == 0 || row_len > LANES || !n.is_multiple_of(row_len) {
            self.eval_batch_inner(x, y, z, out, scratch);
            return;
        }
        if scratch.regs.len() < self.regs {
            scratch.regs.resize(self.regs, [0.0; LANES]);
        }
        if scratch.class.len() < self.regs {
            scratch.class.resize(self.regs, Class::Full);
        }
        let block = (LANES / row_len) * row_len;
        let mut start = 0;
        while start < n {
            let end = (start + block).min(n);
            let xs = [&x[start..end], &y[start..end], &z[start..end]];
            self.eval_rows_block(row_len, xs, scratch, &mut out[start..end]);
            start = end;
        }
    }

    #[inline(always)]
    fn eval_rows_block(
        &self,
        row_len: usize,
        xs: [&[f64]; 3],
        scratch: &mut BatchScratch,
        out: &mut [f64],
    ) {
        let n = out.len();
        let rows = n / row_len;
        let BatchScratch { regs, class, tmp } = scratch;
        // Row heads: the y and z of every row, and the x of one row.
        let mut heads = [[0.0f64; LANES]; 2];
        for (r, chunk) in xs[1].chunks_exact(row_len).enumerate() {
            heads[0][r] = chunk[0];
        }
        for (r, chunk) in xs[2].chunks_exact(row_len).enumerate() {
            heads[1][r] = chunk[0];
        }
        let compact = Compact {
            row_len,
            rows,
            n,
            x: &xs[0][..row_len],
            y: &heads[0][..rows],
            z: &heads[1][..rows],
            full: xs,
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
        match self.output {
            Arg::Reg(r) => compact.expand(&regs[r as usize], class[r as usize], out),
            Arg::Imm(v) => out.fill(v),
            Arg::Input(k) => out.copy_from_slice(xs[usize::from(k)]),
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

/// Whether a node's operation is costly enough to evaluate on as few lanes as possible.
fn costly(n: &Node) -> bool {
    match *n {
        Node::Unary(op, _) => !matches!(
            op,
            UnaryOp::Neg
                | UnaryOp::Abs
                | UnaryOp::Square
                | UnaryOp::Floor
                | UnaryOp::Ceil
                | UnaryOp::Sign
                | UnaryOp::Not
        ),
        Node::Binary(op, _, _) => matches!(
            op,
            BinaryOp::Div
                | BinaryOp::Pow
                | BinaryOp::Atan2
                | BinaryOp::RUnion
                | BinaryOp::RIntersection
        ),
        Node::Voxel(..) => true,
        _ => false,
    }
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

/// Shapes of a row-structured block.
struct Compact<'a> {
    row_len: usize,
    rows: usize,
    n: usize,
    x: &'a [f64],
    y: &'a [f64],
    z: &'a [f64],
    full: [&'a [f64]; 3],
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

    /// Operand `a` of an instruction of class `c`, expanded into `tmp` if its register is
    /// stored more compactly than `c` needs.
    #[inline(always)]
    fn src<'b>(&'b self, a: Arg, c: Class, ctx: Ctx<'b>, tmp: &'b mut Vec<f64>) -> Src<'b> {
        let (lo, hi, o, class) = ctx;
        match a {
            Arg::Imm(v) => Src::C(v),
            Arg::Input(k) => match (c, k) {
                (Class::Full, _) => Src::S(self.full[usize::from(k)]),
                (_, 0) => Src::S(self.x),
                (_, 1) => Src::S(self.y),
                _ => Src::S(self.z),
            },
            Arg::Reg(r) => {
                let reg: &'b [f64; LANES] = if r < o {
                    &lo[r as usize]
                } else {
                    &hi[(r - o - 1) as usize]
                };
                let rc = class[r as usize];
                if rc == c {
                    Src::S(&reg[..self.len(c)])
                } else if rc == Class::Const {
                    Src::C(reg[0])
                } else if rc == Class::Full {
                    self.compact(&reg[..self.n], c, tmp)
                } else {
                    tmp.resize(self.n, 0.0);
                    self.expand(reg, rc, tmp);
                    if c == Class::Full {
                        Src::S(&tmp[..])
                    } else {
                        // Not produced by compilation (a compact instruction's register
                        // arguments are full, constant or of its own class), but total.
                        let mut t2 = std::mem::take(tmp);
                        let v = self.compact_owned(&mut t2, c);
                        *tmp = t2;
                        v.map_or(Src::S(&tmp[..self.len(c)]), Src::C)
                    }
                }
            }
        }
    }

    /// The lanes of class `c` of full-lane values `full` (gathered into `tmp` for rows).
    fn compact<'b>(&self, full: &'b [f64], c: Class, tmp: &'b mut Vec<f64>) -> Src<'b> {
        match c {
            Class::Const => Src::C(full[0]),
            Class::X => Src::S(&full[..self.row_len]),
            Class::Full => Src::S(full),
            Class::Rows => {
                tmp.clear();
                tmp.extend(full.iter().step_by(self.row_len).take(self.rows));
                Src::S(&tmp[..])
            }
        }
    }

    /// Compact full-lane values in place to the lanes of class `c` (`Some` for a constant).
    fn compact_owned(&self, v: &mut [f64], c: Class) -> Option<f64> {
        match c {
            Class::Const => Some(v[0]),
            Class::X | Class::Full => None,
            Class::Rows => {
                for r in 0..self.rows {
                    v[r] = v[r * self.row_len];
                }
                None
            }
        }
    }

    /// Write the full-lane values of a register stored with class `c` into `out`.
    fn expand(&self, reg: &[f64; LANES], c: Class, out: &mut [f64]) {
        match c {
            Class::Const => out.fill(reg[0]),
            Class::X => {
                for row in out.chunks_exact_mut(self.row_len) {
                    row.copy_from_slice(&reg[..self.row_len]);
                }
            }
            Class::Rows => {
                for (row, &v) in out.chunks_exact_mut(self.row_len).zip(&reg[..self.rows]) {
                    row.fill(v);
                }
            }
            Class::Full => out.copy_from_slice(&reg[..self.n]),
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
    /// Number of `min`/`max`/`select` nodes decided over the last box.
    #[must_use]
    pub fn pruned(&self) -> usize {
        self.pruned
    }
}

/// A block operand: a slice of `n` values or a constant.
#[derive(Clone, Copy)]
enum Src<'a> {
    S(&'a [f64]),
    C(f64),
}

impl Src<'_> {
    #[inline(always)]
    fn at(&self, i: usize) -> f64 {
        match *self {
            Src::S(s) => s[i],
            Src::C(c) => c,
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
    row_len: usize,
    x: &[f64],
    y: &[f64],
    z: &[f64],
    out: &mut [f64],
    scratch: &mut BatchScratch,
) {
    tape.eval_rows_inner(row_len, x, y, z, out, scratch);
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
    }
}

#[inline(always)]
fn map2(o: &mut [f64], a: Src<'_>, b: Src<'_>, f: impl Fn(f64, f64) -> f64) {
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
        for row_len in [1, 3, 7, 16, 37, LANES] {
            let rows = 700 / row_len + 1;
            let n = rows * row_len;
            let (mut xs, mut ys, mut zs) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            for r in 0..rows {
                for i in 0..row_len {
                    let l = r * row_len + i;
                    xs[l] = -1.5 + 0.37 * i as f64;
                    ys[l] = if r % 5 == 0 {
                        0.0
                    } else {
                        0.9 - 0.11 * r as f64
                    };
                    zs[l] = if r % 5 == 0 {
                        0.0
                    } else {
                        0.3 - 0.4 * (r % 3) as f64
                    };
                }
            }
            let mut a = vec![0.0; n];
            let mut b = vec![0.0; n];
            let mut sc = BatchScratch::default();
            t.eval_batch_with(&xs, &ys, &zs, &mut a, &mut sc);
            t.eval_rows_with(row_len, &xs, &ys, &zs, &mut b, &mut sc);
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
