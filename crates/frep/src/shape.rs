//! Defining functions as deduplicated expression graphs: [`Builder`] (hash-consing,
//! constant folding) and the immutable [`Shape`] it produces, with the R-function set
//! operations and blends of HyperFun.
//!
//! A shape's value at a point is its defining function `f(x, y, z)`; the solid is where
//! **`f ≥ 0`** (the F-rep convention, Savchenko–Pasko Eq. 3), the surface where `f = 0`.

use std::collections::HashMap;
use std::sync::Arc;

use crate::ops::{self, BinaryOp, UnaryOp};
use crate::voxel::VoxelField;

/// Index of a node in a [`Builder`] or [`Shape`].
pub type Id = u32;

/// Largest number of nodes a builder accepts; a model or mapping that would grow its graph
/// beyond this (an over-long unrolled loop, say) is refused.
pub const MAX_NODES: usize = 1 << 21;

/// One node of an expression graph. Arguments are indices of earlier nodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Node {
    /// Coordinate `0 = x`, `1 = y`, `2 = z` of the evaluation point.
    Input(u8),
    /// A constant, stored as its bit pattern (NaNs canonicalised).
    Const(u64),
    /// A unary operation.
    Unary(UnaryOp, Id),
    /// A binary operation.
    Binary(BinaryOp, Id, Id),
    /// `select(c, a, b)`: `a` where `c ≠ 0`, else `b` (NaN where `c` is NaN).
    Select(Id, Id, Id),
    /// A sample of a [`VoxelField`] of the shape ([`Shape::fields`]) at the continuous voxel
    /// index given by the three arguments (see [`crate::voxel`]).
    Voxel(VoxelOp, Id, Id, Id),
}

/// What a [`Node::Voxel`] samples: field `field` of the shape's (or builder's) field table,
/// differentiated `order[a]` times along index axis `a` (`[0, 0, 0]`: the value).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct VoxelOp {
    /// Index into the field table.
    pub field: u32,
    /// Derivative order per index axis.
    pub order: [u8; 3],
}

impl Node {
    /// The constant value, if this node is a constant.
    #[must_use]
    pub fn as_const(&self) -> Option<f64> {
        match *self {
            Node::Const(b) => Some(f64::from_bits(b)),
            _ => None,
        }
    }
}

/// Builds expression graphs with structural sharing: an operation applied to the same
/// arguments twice gives the same node, and operations on constants are folded.
#[derive(Debug, Clone, Default)]
pub struct Builder {
    nodes: Vec<Node>,
    index: HashMap<Node, Id>,
    fields: Vec<Arc<VoxelField>>,
}

fn commutative(op: BinaryOp) -> bool {
    matches!(
        op,
        BinaryOp::Add
            | BinaryOp::Mul
            | BinaryOp::Min
            | BinaryOp::Max
            | BinaryOp::Eq
            | BinaryOp::Ne
            | BinaryOp::And
            | BinaryOp::Or
            | BinaryOp::RUnion
            | BinaryOp::RIntersection
    )
}

impl Builder {
    /// An empty builder.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of nodes so far.
    #[must_use]
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether no node was made yet.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The node `id` (`None` if out of range).
    #[must_use]
    pub fn node(&self, id: Id) -> Option<Node> {
        self.nodes.get(id as usize).copied()
    }

    /// The constant value of node `id`, if it is a constant.
    #[must_use]
    pub fn const_value(&self, id: Id) -> Option<f64> {
        self.node(id).and_then(|n| n.as_const())
    }

    fn intern(&mut self, n: Node) -> Id {
        if let Some(&id) = self.index.get(&n) {
            return id;
        }
        let id = self.nodes.len() as Id;
        self.nodes.push(n);
        self.index.insert(n, id);
        id
    }

    /// The coordinate `axis` (0 = x, 1 = y, 2 = z; larger values are clamped to z).
    pub fn input(&mut self, axis: u8) -> Id {
        self.intern(Node::Input(axis.min(2)))
    }

    /// The three coordinates `[x, y, z]`.
    pub fn inputs(&mut self) -> [Id; 3] {
        [self.input(0), self.input(1), self.input(2)]
    }

    /// A constant.
    pub fn constant(&mut self, v: f64) -> Id {
        let v = if v.is_nan() { f64::NAN } else { v };
        self.intern(Node::Const(v.to_bits()))
    }

    /// A unary operation (folded when `a` is constant).
    pub fn unary(&mut self, op: UnaryOp, a: Id) -> Id {
        if let Some(v) = self.const_value(a) {
            return self.constant(ops::unary(op, v));
        }
        if op == UnaryOp::Neg
            && let Some(Node::Unary(UnaryOp::Neg, inner)) = self.node(a)
        {
            return inner;
        }
        if op == UnaryOp::PowI(1) {
            return a;
        }
        if op == UnaryOp::PowI(2) {
            return self.intern(Node::Unary(UnaryOp::Square, a));
        }
        self.intern(Node::Unary(op, a))
    }

    /// A binary operation (folded when both arguments are constants; `x + 0`, `x − 0`,
    /// `x · 1`, `x / 1`, `min(x, x)`, `max(x, x)` simplified; constant integer powers become
    /// [`UnaryOp::PowI`]).
    pub fn binary(&mut self, op: BinaryOp, a: Id, b: Id) -> Id {
        let (ca, cb) = (self.const_value(a), self.const_value(b));
        if let (Some(x), Some(y)) = (ca, cb) {
            return self.constant(ops::binary(op, x, y));
        }
        let is = |c: Option<f64>, v: f64| c.is_some_and(|c| c == v);
        match op {
            BinaryOp::Add if is(ca, 0.0) => return b,
            BinaryOp::Add | BinaryOp::Sub if is(cb, 0.0) => return a,
            BinaryOp::Mul if is(ca, 1.0) => return b,
            BinaryOp::Mul | BinaryOp::Div if is(cb, 1.0) => return a,
            BinaryOp::Sub if ca.is_some_and(|z| z == 0.0 && z.is_sign_negative()) => {
                return self.unary(UnaryOp::Neg, b);
            }
            BinaryOp::Pow => {
                if let Some(e) = cb
                    && e.fract() == 0.0
                    && e.abs() <= 64.0
                {
                    return self.unary(UnaryOp::PowI(e as i32), a);
                }
            }
            _ => {}
        }
        if a == b && matches!(op, BinaryOp::Min | BinaryOp::Max) {
            return a;
        }
        if a == b && op == BinaryOp::Mul {
            return self.intern(Node::Unary(UnaryOp::Square, a));
        }
        let (a, b) = if commutative(op) && b < a {
            (b, a)
        } else {
            (a, b)
        };
        self.intern(Node::Binary(op, a, b))
    }

    /// `select(c, a, b)` (folded when `c` is constant and not NaN, or when `a == b` and `c`
    /// is a comparison of non-NaN constants… kept otherwise).
    pub fn select(&mut self, c: Id, a: Id, b: Id) -> Id {
        if let Some(v) = self.const_value(c)
            && !v.is_nan()
        {
            return if v != 0.0 { a } else { b };
        }
        self.intern(Node::Select(c, a, b))
    }

    /// A sample of `field` (derivative `order` per index axis) at the continuous voxel index
    /// `u` (see [`crate::voxel`]); zero when an order exceeds the kernel's degree, folded to
    /// a constant when `u` is.
    pub fn voxel(&mut self, field: &Arc<VoxelField>, order: [u8; 3], u: [Id; 3]) -> Id {
        if order.iter().any(|&o| o > field.kernel().degree()) {
            return self.constant(0.0);
        }
        if let [Some(a), Some(b), Some(c)] = u.map(|i| self.const_value(i)) {
            return self.constant(field.eval(order, [a, b, c]));
        }
        let f = self.field_index(field);
        self.intern(Node::Voxel(VoxelOp { field: f, order }, u[0], u[1], u[2]))
    }

    /// The index of `field` in this builder's table (added if new; fields are the same when
    /// they are the same object).
    fn field_index(&mut self, field: &Arc<VoxelField>) -> u32 {
        if let Some(i) = self.fields.iter().position(|f| Arc::ptr_eq(f, field)) {
            return i as u32;
        }
        self.fields.push(Arc::clone(field));
        (self.fields.len() - 1) as u32
    }

    /// `a + b`.
    pub fn add(&mut self, a: Id, b: Id) -> Id {
        self.binary(BinaryOp::Add, a, b)
    }
    /// `a − b`.
    pub fn sub(&mut self, a: Id, b: Id) -> Id {
        self.binary(BinaryOp::Sub, a, b)
    }
    /// `a · b`.
    pub fn mul(&mut self, a: Id, b: Id) -> Id {
        self.binary(BinaryOp::Mul, a, b)
    }
    /// `a / b`.
    pub fn div(&mut self, a: Id, b: Id) -> Id {
        self.binary(BinaryOp::Div, a, b)
    }
    /// `−a`.
    pub fn neg(&mut self, a: Id) -> Id {
        self.unary(UnaryOp::Neg, a)
    }
    /// `a²`.
    pub fn square(&mut self, a: Id) -> Id {
        self.unary(UnaryOp::Square, a)
    }
    /// `√a`.
    pub fn sqrt(&mut self, a: Id) -> Id {
        self.unary(UnaryOp::Sqrt, a)
    }
    /// `a · c` for a constant `c`.
    pub fn mul_c(&mut self, a: Id, c: f64) -> Id {
        let c = self.constant(c);
        self.mul(a, c)
    }
    /// `a + c` for a constant `c`.
    pub fn add_c(&mut self, a: Id, c: f64) -> Id {
        let c = self.constant(c);
        self.add(a, c)
    }

    /// R-function union `f1 + f2 + √(f1² + f2²)` (HyperFun `|`): `≥ 0` exactly where either
    /// argument is `≥ 0`, smooth away from the points where both vanish. One node
    /// ([`BinaryOp::RUnion`]), so its enclosure over a box is exact up to rounding.
    pub fn union(&mut self, a: Id, b: Id) -> Id {
        self.binary(BinaryOp::RUnion, a, b)
    }

    /// R-function intersection `f1 + f2 − √(f1² + f2²)` (HyperFun `&`), one node
    /// ([`BinaryOp::RIntersection`]).
    pub fn intersection(&mut self, a: Id, b: Id) -> Id {
        self.binary(BinaryOp::RIntersection, a, b)
    }

    /// R-function subtraction `f1 \ f2 = f1 & (−f2)` (HyperFun `\`).
    pub fn subtraction(&mut self, a: Id, b: Id) -> Id {
        let nb = self.neg(b);
        self.intersection(a, nb)
    }

    /// `√(a² + b²)`.
    pub fn norm2(&mut self, a: Id, b: Id) -> Id {
        let a2 = self.square(a);
        let b2 = self.square(b);
        let s = self.add(a2, b2);
        self.sqrt(s)
    }

    /// Blending displacement `a0 / (1 + (f1/a1)² + (f2/a2)²)` of HyperFun's blends.
    pub fn blend_displacement(&mut self, f1: Id, f2: Id, a0: Id, a1: Id, a2: Id) -> Id {
        let q1 = self.div(f1, a1);
        let q1 = self.square(q1);
        let q2 = self.div(f2, a2);
        let q2 = self.square(q2);
        let one = self.constant(1.0);
        let s = self.add(one, q1);
        let s = self.add(s, q2);
        self.div(a0, s)
    }

    /// Re-create the graph of `shape` in this builder with its coordinates replaced by the
    /// nodes `inputs` (function composition `f(inputs)`); returns the new root.
    pub fn import(&mut self, shape: &Shape, inputs: [Id; 3]) -> Id {
        let mut map: Vec<Id> = Vec::with_capacity(shape.nodes.len());
        let fields = shape.fields.clone();
        for n in shape.nodes.iter() {
            let id = match *n {
                Node::Input(a) => inputs[usize::from(a.min(2))],
                Node::Const(b) => self.constant(f64::from_bits(b)),
                Node::Unary(op, a) => self.unary(op, map[a as usize]),
                Node::Binary(op, a, b) => self.binary(op, map[a as usize], map[b as usize]),
                Node::Select(c, a, b) => {
                    self.select(map[c as usize], map[a as usize], map[b as usize])
                }
                Node::Voxel(op, a, b, c) => self.voxel(
                    &fields[op.field as usize],
                    op.order,
                    [map[a as usize], map[b as usize], map[c as usize]],
                ),
            };
            map.push(id);
        }
        map[shape.root as usize]
    }

    /// Symbolic gradient `[∂f/∂x, ∂f/∂y, ∂f/∂z]` of node `id` as new nodes, following the
    /// same rules as [`ops::unary_dual`] / [`ops::binary_dual`] (so its values agree with the
    /// forward-mode gradient).
    pub fn gradient(&mut self, id: Id) -> [Id; 3] {
        let mut memo: HashMap<Id, [Id; 3]> = HashMap::new();
        let mut order = Vec::new();
        // Post-order over the nodes reachable from `id` (ids are topologically sorted).
        let mut seen = vec![false; id as usize + 1];
        seen[id as usize] = true;
        for i in (0..=id).rev() {
            if !seen[i as usize] {
                continue;
            }
            order.push(i);
            let args: Vec<Id> = match self.nodes[i as usize] {
                Node::Unary(_, a) => vec![a],
                Node::Binary(_, a, b) => vec![a, b],
                Node::Select(c, a, b) | Node::Voxel(_, c, a, b) => vec![c, a, b],
                _ => vec![],
            };
            for a in args {
                seen[a as usize] = true;
            }
        }
        order.reverse();
        let zero = self.constant(0.0);
        for i in order {
            let g = match self.nodes[i as usize] {
                Node::Input(a) => {
                    let one = self.constant(1.0);
                    let mut g = [zero; 3];
                    g[usize::from(a.min(2))] = one;
                    g
                }
                Node::Const(_) => [zero; 3],
                Node::Unary(op, a) => {
                    let ga = memo[&a];
                    let s = self.unary_slope(op, a, i);
                    ga.map(|d| self.mul(s, d))
                }
                Node::Binary(op, a, b) => {
                    let (ga, gb) = (memo[&a], memo[&b]);
                    self.binary_gradient(op, a, b, i, ga, gb)
                }
                Node::Select(c, a, b) => {
                    let (ga, gb) = (memo[&a], memo[&b]);
                    [0, 1, 2].map(|k| self.select(c, ga[k], gb[k]))
                }
                Node::Voxel(op, a, b, c) => {
                    // Chain rule through the index arguments: Σ_k ∂s/∂u_k · ∇u_k.
                    let field = Arc::clone(&self.fields[op.field as usize]);
                    let args = [a, b, c];
                    let mut g = [zero; 3];
                    for (k, &arg) in args.iter().enumerate() {
                        let mut order = op.order;
                        order[k] = order[k].saturating_add(1);
                        let partial = self.voxel(&field, order, args);
                        let ga = memo[&arg];
                        for (gd, &gad) in g.iter_mut().zip(&ga) {
                            let t = self.mul(partial, gad);
                            *gd = self.add(*gd, t);
                        }
                    }
                    g
                }
            };
            memo.insert(i, g);
        }
        memo[&id]
    }

    /// `d op(a) / d a` as a node (`v` is the node of `op(a)` itself).
    fn unary_slope(&mut self, op: UnaryOp, a: Id, v: Id) -> Id {
        let one = self.constant(1.0);
        match op {
            UnaryOp::Neg => self.constant(-1.0),
            UnaryOp::Abs => {
                let zero = self.constant(0.0);
                let neg = self.binary(BinaryOp::Lt, a, zero);
                let m1 = self.constant(-1.0);
                self.select(neg, m1, one)
            }
            UnaryOp::Sqrt => {
                let h = self.constant(0.5);
                self.div(h, v)
            }
            UnaryOp::Square => self.mul_c(a, 2.0),
            UnaryOp::Exp => v,
            UnaryOp::Ln => self.div(one, a),
            UnaryOp::Log10 => {
                let d = self.mul_c(a, std::f64::consts::LN_10);
                self.div(one, d)
            }
            UnaryOp::Sin => self.unary(UnaryOp::Cos, a),
            UnaryOp::Cos => {
                let s = self.unary(UnaryOp::Sin, a);
                self.neg(s)
            }
            UnaryOp::Tan => {
                let v2 = self.square(v);
                self.add(one, v2)
            }
            UnaryOp::Asin | UnaryOp::Acos => {
                let a2 = self.square(a);
                let d = self.sub(one, a2);
                let d = self.sqrt(d);
                let s = self.div(one, d);
                if op == UnaryOp::Acos { self.neg(s) } else { s }
            }
            UnaryOp::Atan => {
                let a2 = self.square(a);
                let d = self.add(one, a2);
                self.div(one, d)
            }
            UnaryOp::Sinh => self.unary(UnaryOp::Cosh, a),
            UnaryOp::Cosh => self.unary(UnaryOp::Sinh, a),
            UnaryOp::Tanh => {
                let v2 = self.square(v);
                self.sub(one, v2)
            }
            UnaryOp::Floor | UnaryOp::Ceil | UnaryOp::Sign | UnaryOp::Not => self.constant(0.0),
            UnaryOp::PowI(n) => {
                if n == 0 {
                    self.constant(0.0)
                } else {
                    let p = self.unary(UnaryOp::PowI(n - 1), a);
                    self.mul_c(p, f64::from(n))
                }
            }
        }
    }

    fn binary_gradient(
        &mut self,
        op: BinaryOp,
        a: Id,
        b: Id,
        v: Id,
        ga: [Id; 3],
        gb: [Id; 3],
    ) -> [Id; 3] {
        let zero = self.constant(0.0);
        match op {
            BinaryOp::Add => [0, 1, 2].map(|k| self.add(ga[k], gb[k])),
            BinaryOp::Sub => [0, 1, 2].map(|k| self.sub(ga[k], gb[k])),
            BinaryOp::Mul => [0, 1, 2].map(|k| {
                let l = self.mul(ga[k], b);
                let r = self.mul(gb[k], a);
                self.add(l, r)
            }),
            BinaryOp::Div => {
                let b2 = self.square(b);
                [0, 1, 2].map(|k| {
                    let l = self.mul(ga[k], b);
                    let r = self.mul(gb[k], a);
                    let n = self.sub(l, r);
                    self.div(n, b2)
                })
            }
            BinaryOp::Min | BinaryOp::Max => {
                // min picks `a` where a < b, max where b < a (as `ops::binary_dual`).
                let c = if op == BinaryOp::Min {
                    self.binary(BinaryOp::Lt, a, b)
                } else {
                    self.binary(BinaryOp::Lt, b, a)
                };
                [0, 1, 2].map(|k| self.select(c, ga[k], gb[k]))
            }
            BinaryOp::Pow => {
                let one = self.constant(1.0);
                let bm1 = self.sub(b, one);
                let p = self.binary(BinaryOp::Pow, a, bm1);
                let s = self.mul(b, p);
                let ln = self.unary(UnaryOp::Ln, a);
                let t = self.mul(v, ln);
                [0, 1, 2].map(|k| {
                    let l = self.mul(ga[k], s);
                    if gb[k] == zero {
                        l
                    } else {
                        let r = self.mul(gb[k], t);
                        self.add(l, r)
                    }
                })
            }
            BinaryOp::Atan2 => {
                let a2 = self.square(a);
                let b2 = self.square(b);
                let d = self.add(a2, b2);
                [0, 1, 2].map(|k| {
                    let l = self.mul(ga[k], b);
                    let r = self.mul(gb[k], a);
                    let n = self.sub(l, r);
                    self.div(n, d)
                })
            }
            BinaryOp::RUnion | BinaryOp::RIntersection => {
                // ∂/∂a = 1 ± a/r, ∂/∂b = 1 ± b/r, r = √(a² + b²).
                let r = self.norm2(a, b);
                let one = self.constant(1.0);
                let (qa, qb) = (self.div(a, r), self.div(b, r));
                let (sa, sb) = if op == BinaryOp::RUnion {
                    (self.add(one, qa), self.add(one, qb))
                } else {
                    (self.sub(one, qa), self.sub(one, qb))
                };
                [0, 1, 2].map(|k| {
                    let l = self.mul(ga[k], sa);
                    let r = self.mul(gb[k], sb);
                    self.add(l, r)
                })
            }
            _ => [zero; 3],
        }
    }

    /// Freeze the graph below `root` into a [`Shape`] (unreachable nodes dropped).
    /// [`Shape::unfinished_loops`] is empty; the compiler attaches its loops.
    #[must_use]
    pub fn finish(&self, root: Id) -> Shape {
        Shape::compact(&self.nodes, root, &self.fields)
    }
}

/// An immutable defining function `f(x, y, z)`: a topologically sorted, deduplicated graph
/// of [`Node`]s with one root. Cheap to clone (shared storage).
///
/// The solid is `{p : f(p) ≥ 0}`. Build shapes by compiling a model
/// ([`crate::compile`](mod@crate::compile)), with a [`Builder`], or from other shapes with the operations of
/// [`crate::mapping`].
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    nodes: Arc<[Node]>,
    root: Id,
    loops: Arc<[LoopGuard]>,
    fields: Arc<[Arc<VoxelField>]>,
}

/// A data-dependent `while` loop that was unrolled to its pass budget without ending at
/// every point: where [`LoopGuard::active`] is non-zero the loop was still running after
/// [`LoopGuard::passes`] passes, and the shape's value there is NaN. Samplers use it to
/// name the loop instead of returning NaN silently.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopGuard {
    /// Position of the `while` in the model text.
    pub pos: crate::error::Pos,
    /// Passes unrolled ([`crate::compile::MAX_DEPENDENT_ITERATIONS`]).
    pub passes: usize,
    /// Non-zero where the loop had not ended after the last pass.
    pub active: Shape,
}

impl Shape {
    /// The nodes reachable from `root`, renumbered in order (arguments must precede their
    /// users).
    pub(crate) fn compact(nodes: &[Node], root: Id, fields: &[Arc<VoxelField>]) -> Shape {
        let n = (root as usize + 1).min(nodes.len());
        let mut live = vec![false; n];
        if n > 0 {
            live[n - 1] = true;
        }
        for i in (0..n).rev() {
            if !live[i] {
                continue;
            }
            match nodes[i] {
                Node::Unary(_, a) => live[a as usize] = true,
                Node::Binary(_, a, b) => {
                    live[a as usize] = true;
                    live[b as usize] = true;
                }
                Node::Select(c, a, b) | Node::Voxel(_, c, a, b) => {
                    live[c as usize] = true;
                    live[a as usize] = true;
                    live[b as usize] = true;
                }
                _ => {}
            }
        }
        let mut map = vec![0 as Id; n];
        let mut out = Vec::new();
        // Fields referenced by live nodes, renumbered in order of first use.
        let mut field_map: Vec<Option<u32>> = vec![None; fields.len()];
        let mut kept: Vec<Arc<VoxelField>> = Vec::new();
        for i in 0..n {
            if !live[i] {
                continue;
            }
            map[i] = out.len() as Id;
            let m = |a: Id| map[a as usize];
            out.push(match nodes[i] {
                Node::Unary(op, a) => Node::Unary(op, m(a)),
                Node::Binary(op, a, b) => Node::Binary(op, m(a), m(b)),
                Node::Select(c, a, b) => Node::Select(m(c), m(a), m(b)),
                Node::Voxel(op, a, b, c) => {
                    let f = op.field as usize;
                    let idx = *field_map[f].get_or_insert_with(|| {
                        kept.push(Arc::clone(&fields[f]));
                        (kept.len() - 1) as u32
                    });
                    Node::Voxel(
                        VoxelOp {
                            field: idx,
                            order: op.order,
                        },
                        m(a),
                        m(b),
                        m(c),
                    )
                }
                other => other,
            });
        }
        if out.is_empty() {
            out.push(Node::Const(f64::NAN.to_bits()));
        }
        let root = (out.len() - 1) as Id;
        Shape {
            nodes: out.into(),
            root,
            loops: Arc::from(Vec::new()),
            fields: kept.into(),
        }
    }

    /// The sampled volumes the shape's [`Node::Voxel`] nodes read, by index.
    #[must_use]
    pub fn fields(&self) -> &[Arc<VoxelField>] {
        &self.fields
    }

    /// The data-dependent loops of a compiled model that may not have ended within their
    /// pass budget at some points (empty for shapes built otherwise).
    #[must_use]
    pub fn unfinished_loops(&self) -> &[LoopGuard] {
        &self.loops
    }

    /// This shape with `loops` attached (see [`Shape::unfinished_loops`]).
    pub(crate) fn with_loops(mut self, loops: Vec<LoopGuard>) -> Shape {
        self.loops = loops.into();
        self
    }

    /// The constant shape `f ≡ v`.
    #[must_use]
    pub fn constant(v: f64) -> Shape {
        let mut b = Builder::new();
        let c = b.constant(v);
        b.finish(c)
    }

    /// Build a shape with a closure that receives a builder and the coordinate nodes
    /// `[x, y, z]` and returns the root.
    #[must_use]
    pub fn build(f: impl FnOnce(&mut Builder, [Id; 3]) -> Id) -> Shape {
        let mut b = Builder::new();
        let x = b.inputs();
        let r = f(&mut b, x);
        b.finish(r)
    }

    /// The nodes, topologically sorted; the root is the last one.
    #[must_use]
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// Index of the root node (always the last).
    #[must_use]
    pub fn root(&self) -> Id {
        self.root
    }

    /// Number of nodes.
    #[must_use]
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Always `false`: a shape has at least its root.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Evaluate by walking the graph (reference evaluator, one allocation per call; the
    /// compiled [`Tape`](crate::Tape) is the fast path and must agree with this).
    #[must_use]
    pub fn eval_reference(&self, p: [f64; 3]) -> f64 {
        let mut v = Vec::with_capacity(self.nodes.len());
        for n in self.nodes.iter() {
            let x = match *n {
                Node::Input(a) => p[usize::from(a.min(2))],
                Node::Const(b) => f64::from_bits(b),
                Node::Unary(op, a) => ops::unary(op, v[a as usize]),
                Node::Binary(op, a, b) => ops::binary(op, v[a as usize], v[b as usize]),
                Node::Select(c, a, b) => ops::select(v[c as usize], v[a as usize], v[b as usize]),
                Node::Voxel(op, a, b, c) => self.fields[op.field as usize]
                    .eval(op.order, [v[a as usize], v[b as usize], v[c as usize]]),
            };
            v.push(x);
        }
        v[self.root as usize]
    }

    /// Apply `f` to the defining functions of `self` and `other` in one graph:
    /// `f(builder, self_root, other_root)`.
    #[must_use]
    pub fn combine(&self, other: &Shape, f: impl FnOnce(&mut Builder, Id, Id) -> Id) -> Shape {
        let mut b = Builder::new();
        let x = b.inputs();
        let r1 = b.import(self, x);
        let r2 = b.import(other, x);
        let r = f(&mut b, r1, r2);
        b.finish(r)
    }

    /// Apply `f` to this shape's defining function: `f(builder, root, [x, y, z])`.
    #[must_use]
    pub fn map(&self, f: impl FnOnce(&mut Builder, Id, [Id; 3]) -> Id) -> Shape {
        let mut b = Builder::new();
        let x = b.inputs();
        let r = b.import(self, x);
        let out = f(&mut b, r, x);
        b.finish(out)
    }

    /// R-function union (`|`).
    #[must_use]
    pub fn union(&self, o: &Shape) -> Shape {
        self.combine(o, Builder::union)
    }

    /// R-function intersection (`&`).
    #[must_use]
    pub fn intersection(&self, o: &Shape) -> Shape {
        self.combine(o, Builder::intersection)
    }

    /// R-function subtraction (`\`).
    #[must_use]
    pub fn subtraction(&self, o: &Shape) -> Shape {
        self.combine(o, Builder::subtraction)
    }

    /// Complement `−f` (`~`).
    #[must_use]
    pub fn complement(&self) -> Shape {
        self.map(|b, r, _| b.neg(r))
    }
}
