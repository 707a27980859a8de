//! Painting one ray with another: the Boolean operations of McPhail's ray painting
//! (Algorithm 3.2) for one solid material and empty space.
//!
//! Each ray of the base and of the edit holds clean crossings (sorted, alternately entering
//! and leaving, so they bound disjoint solid intervals). The two lists are merged in depth
//! order; the result keeps a crossing wherever the combined material changes, so every edit
//! interval is kept and the base crossings inside it disappear, as in the thesis. Crossings
//! of the two rays at the same depth are handled together: the result changes there at most
//! once, so coincident surfaces leave no zero-width sliver or gap (the thesis orders such
//! pairs to the same effect).

use crate::peel::Crossing;

/// A Boolean edit of the solid by a tool.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Op {
    /// Union: the tool's volume becomes solid (painting with material).
    Add,
    /// Difference: the tool's volume becomes empty (painting with "empty" material).
    Subtract,
    /// Intersection: only the solid inside the tool remains.
    Intersect,
}

impl Op {
    #[inline]
    fn apply(self, base: bool, tool: bool) -> bool {
        match self {
            Op::Add => base || tool,
            Op::Subtract => base && !tool,
            Op::Intersect => base && tool,
        }
    }
}

/// Push to `out` the clean crossings of `base` combined with `tool` by `op`. Both inputs must
/// be clean rays (sorted, alternating, starting with an entering crossing). Normals of the
/// tool are turned around where its surface bounds the result from the other side (the walls
/// of a subtracted cavity face into it).
pub fn combine(base: &[Crossing], tool: &[Crossing], op: Op, out: &mut Vec<Crossing>) {
    let (mut i, mut j) = (0, 0);
    let (mut in_b, mut in_t) = (false, false);
    let flip_tool = op == Op::Subtract;
    while i < base.len() || j < tool.len() {
        let d = match (base.get(i), tool.get(j)) {
            (Some(b), Some(t)) => b.depth.min(t.depth),
            (Some(b), None) => b.depth,
            (None, Some(t)) => t.depth,
            (None, None) => unreachable!(),
        };
        let before = op.apply(in_b, in_t);
        let eb = base.get(i).filter(|b| b.depth == d).copied();
        let et = tool.get(j).filter(|t| t.depth == d).copied();
        if eb.is_some() {
            in_b = !in_b;
            i += 1;
        }
        if et.is_some() {
            in_t = !in_t;
            j += 1;
        }
        let after = op.apply(in_b, in_t);
        if before == after {
            continue;
        }
        // The event whose own change points the same way as the result's.
        let from_tool = et.map(|t| {
            if flip_tool {
                Crossing {
                    depth: t.depth,
                    normal: t.normal.map(|x| -x),
                    entering: !t.entering,
                }
            } else {
                t
            }
        });
        let pick = [eb, from_tool]
            .into_iter()
            .flatten()
            .find(|c| c.entering == after)
            .or(eb)
            .or(from_tool);
        if let Some(c) = pick {
            out.push(Crossing {
                depth: d,
                normal: c.normal,
                entering: after,
            });
        }
    }
}

/// `true` when `ray` is clean: depths strictly increasing and finite, crossings alternately
/// entering and leaving starting with an entering one, and an even count.
#[must_use]
pub fn is_clean(ray: &[Crossing]) -> bool {
    ray.len().is_multiple_of(2)
        && ray
            .iter()
            .enumerate()
            .all(|(k, c)| c.entering == (k % 2 == 0) && c.depth.is_finite())
        && ray.windows(2).all(|w| w[0].depth < w[1].depth)
}

/// Whether the point at `depth` on a clean ray is solid: an odd number of crossings at or
/// before it (intervals are closed at the entering end, open at the leaving end).
#[inline]
#[must_use]
pub fn inside_at(ray: &[Crossing], depth: f64) -> bool {
    ray.partition_point(|c| c.depth <= depth) % 2 == 1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(ds: &[f64]) -> Vec<Crossing> {
        ds.iter()
            .enumerate()
            .map(|(k, &d)| Crossing {
                depth: d,
                normal: [if k % 2 == 0 { -1.0 } else { 1.0 }, 0.0, 0.0],
                entering: k % 2 == 0,
            })
            .collect()
    }

    fn depths(r: &[Crossing]) -> Vec<f64> {
        r.iter().map(|c| c.depth).collect()
    }

    fn run(b: &[f64], t: &[f64], op: Op) -> Vec<Crossing> {
        let mut out = Vec::new();
        combine(&ray(b), &ray(t), op, &mut out);
        assert!(is_clean(&out), "{op:?} of {b:?} and {t:?} gave {out:?}");
        out
    }

    /// The result agrees point by point with the Boolean of the two inputs.
    #[test]
    fn combine_agrees_with_pointwise_booleans() {
        let cases: [(&[f64], &[f64]); 6] = [
            (&[0.0, 4.0, 6.0, 9.0], &[2.0, 7.0]),
            (&[0.0, 4.0], &[4.0, 6.0]),
            (&[0.0, 4.0], &[0.0, 4.0]),
            (&[1.0, 2.0, 3.0, 4.0], &[0.0, 5.0]),
            (&[], &[1.0, 2.0]),
            (&[1.0, 3.0], &[]),
        ];
        for (b, t) in cases {
            for op in [Op::Add, Op::Subtract, Op::Intersect] {
                let out = run(b, t, op);
                for k in 0..=200 {
                    let x = -0.5 + k as f64 * 0.05;
                    let expect = op.apply(inside_at(&ray(b), x), inside_at(&ray(t), x));
                    assert_eq!(inside_at(&out, x), expect, "{op:?} {b:?} {t:?} at {x}");
                }
            }
        }
    }

    #[test]
    fn touching_intervals_merge_and_cavity_walls_face_inwards() {
        assert_eq!(depths(&run(&[0.0, 4.0], &[4.0, 6.0], Op::Add)), [0.0, 6.0]);
        assert!(run(&[0.0, 4.0], &[0.0, 4.0], Op::Subtract).is_empty());
        let cut = run(&[0.0, 10.0], &[3.0, 5.0], Op::Subtract);
        assert_eq!(depths(&cut), [0.0, 3.0, 5.0, 10.0]);
        // The cavity's near wall is the tool's entering face, now a leaving crossing whose
        // outward normal points along the ray (+x), and the far wall the reverse.
        assert_eq!(cut[1].normal[0], 1.0);
        assert!(!cut[1].entering);
        assert_eq!(cut[2].normal[0], -1.0);
        assert!(cut[2].entering);
    }
}
