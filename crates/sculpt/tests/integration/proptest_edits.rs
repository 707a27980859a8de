//! Property test: any sequence of dabs and strokes keeps the sculpted mesh a closed,
//! consistently oriented 2-manifold, and undoing the sequence restores the document.

use std::sync::Arc;

use glam::{DQuat, DVec3};
use proptest::prelude::*;
use volmorph_mesh::shapes::{cuboid, icosphere};
use volmorph_sculpt::{Edit, Op, Pose, SculptDocument, SculptOptions, Tool};

#[derive(Debug, Clone)]
struct Step {
    sphere: bool,
    op: u8,
    dir: [f64; 3],
    radius: f64,
    axis: [f64; 3],
    angle: f64,
    scale: f64,
    stroke: Option<[f64; 3]>,
}

fn step() -> impl Strategy<Value = Step> {
    (
        any::<bool>(),
        0u8..3,
        prop::array::uniform3(-1.0f64..1.0),
        0.5f64..1.3,
        prop::array::uniform3(-1.0f64..1.0),
        0.0f64..6.3,
        0.5f64..1.6,
        prop::option::weighted(0.3, prop::array::uniform3(-0.5f64..0.5)),
    )
        .prop_map(
            |(sphere, op, dir, radius, axis, angle, scale, stroke)| Step {
                sphere,
                op,
                dir,
                radius,
                axis,
                angle,
                scale,
                stroke,
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn random_strokes_keep_a_closed_manifold(steps in prop::collection::vec(step(), 1..7)) {
        let base = icosphere(3, 1.0, DVec3::ZERO).unwrap();
        let sphere = Arc::new(Tool::new(&icosphere(2, 0.3, DVec3::ZERO).unwrap()).unwrap());
        let cube = Arc::new(Tool::new(&cuboid(DVec3::splat(-0.22), DVec3::splat(0.22)).unwrap()).unwrap());
        let mut doc = SculptDocument::around(&base, 32, 8.0, SculptOptions::default()).unwrap();
        let original = doc.clone();
        let mut records = Vec::new();
        for s in &steps {
            let dir = DVec3::from(s.dir).normalize_or(DVec3::X);
            let axis = DVec3::from(s.axis).normalize_or(DVec3::Z);
            let pose = Pose {
                translation: dir * s.radius,
                rotation: DQuat::from_axis_angle(axis, s.angle),
                scale: s.scale,
            };
            let mut poses = vec![pose];
            if let Some(d) = s.stroke {
                poses.push(Pose { translation: pose.translation + DVec3::from(d), ..pose });
            }
            let op = [Op::Add, Op::Subtract, Op::Intersect][s.op as usize];
            let tool = if s.sphere { sphere.clone() } else { cube.clone() };
            let rec = doc.apply(&Edit::Tool { tool, op, poses, step: None }).unwrap();
            let mesh = doc.mesh().unwrap();
            let report = mesh.validate();
            if mesh.face_count() > 0 {
                prop_assert!(report.is_closed_manifold(), "after {:?}:\n{}", s, report);
            }
            records.push(rec);
        }
        for rec in records.iter().rev() {
            doc.undo(rec).unwrap();
        }
        prop_assert!(doc.same_state(&original));
    }
}
