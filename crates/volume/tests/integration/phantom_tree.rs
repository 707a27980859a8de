//! The tree phantom (True 1992 Figs. 13–14): one connected solid that forks into
//! `TREE_LIMBS` limbs and `TREE_LIMBS · TREE_TWIGS_PER_LIMB` twigs.

use std::collections::VecDeque;

use volmorph_volume::phantom::{self, ISO_VALUE, Phantom, TREE_LIMBS, TREE_TWIGS_PER_LIMB};

/// Connected components (6-connectivity) of the voxels where `inside(i, j, k)` holds, on an
/// `n0 × n1 × n2` grid.
fn components(dims: [usize; 3], inside: impl Fn(usize, usize, usize) -> bool) -> usize {
    let [nx, ny, nz] = dims;
    let mut seen = vec![false; nx * ny * nz];
    let at = |i: usize, j: usize, k: usize| i + nx * (j + ny * k);
    let mut count = 0;
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                if seen[at(i, j, k)] || !inside(i, j, k) {
                    continue;
                }
                count += 1;
                let mut queue = VecDeque::from([(i, j, k)]);
                seen[at(i, j, k)] = true;
                while let Some((a, b, c)) = queue.pop_front() {
                    let mut visit = |x: usize, y: usize, z: usize| {
                        if x < nx && y < ny && z < nz && !seen[at(x, y, z)] && inside(x, y, z) {
                            seen[at(x, y, z)] = true;
                            queue.push_back((x, y, z));
                        }
                    };
                    visit(a + 1, b, c);
                    visit(a.wrapping_sub(1), b, c);
                    visit(a, b + 1, c);
                    visit(a, b.wrapping_sub(1), c);
                    visit(a, b, c + 1);
                    visit(a, b, c.wrapping_sub(1));
                }
            }
        }
    }
    count
}

#[test]
fn the_tree_is_one_component_with_the_expected_branch_count() {
    for n in [30, 64] {
        let dims = [n; 3];
        let vol = phantom::density(Phantom::Tree, dims).unwrap();
        let g = *vol.geometry();
        let solid = |i, j, k| vol[[i, j, k]] >= ISO_VALUE;
        assert_eq!(components(dims, solid), 1, "{n}³: the tree falls apart");
        // Horizontal cuts: the limbs between heights 0.0 and 0.15, the twigs between 0.4
        // and 0.6, the trunk below the fork.
        let slice = |z: f64| {
            let k = g.physical_to_index(glam::DVec3::new(0.0, 0.0, z)).z.round() as usize;
            components([n, n, 1], |i, j, _| vol[[i, j, k]] >= ISO_VALUE)
        };
        assert_eq!(slice(-0.5), 1, "{n}³ trunk");
        assert_eq!(slice(0.08), TREE_LIMBS, "{n}³ limbs");
        assert_eq!(slice(0.5), TREE_LIMBS * TREE_TWIGS_PER_LIMB, "{n}³ twigs");
        assert!(vol[[0, 0, 0]] == 0 && vol[[n - 1, n - 1, n - 1]] == 0);
    }
    let (lo, hi) = Phantom::Tree.bounding_box();
    assert!(
        lo.min_element() >= -phantom::MODEL_EXTENT && hi.max_element() <= phantom::MODEL_EXTENT
    );
    assert_eq!("tree".parse::<Phantom>(), Ok(Phantom::Tree));
}
