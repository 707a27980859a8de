//! A sculpting job reports one step per phase, can be cancelled, and gives with progress the
//! same mesh as without.

use glam::DVec3;
use volmorph_mesh::shapes::icosphere;
use volmorph_sculpt::{
    Job, Op, Pose, SculptError, SculptOptions, SmoothRegion, ToolEdit, run_job, run_job_with,
};
use volmorph_testkit::progress;

#[test]
fn job_reports_phases_and_cancels() {
    let base = icosphere(3, 1.0, DVec3::ZERO).unwrap();
    let tool = icosphere(2, 0.4, DVec3::ZERO).unwrap();
    let job = Job {
        tool: Some(ToolEdit {
            mesh: &tool,
            op: Op::Subtract,
            poses: vec![Pose::at(DVec3::new(0.9, 0.0, 0.0))],
            step: None,
        }),
        smooth: Some(SmoothRegion {
            min: DVec3::new(-1.2, -1.2, 0.5),
            max: DVec3::new(1.2, 1.2, 1.2),
            kernel: 1,
        }),
        grid_points: 32,
        options: SculptOptions::default(),
    };
    let plain = run_job(&base, &job).unwrap();
    let with = progress::check(|p| run_job_with(&base, &job, p));
    assert_eq!(plain.mesh, with.mesh);
    assert_eq!(plain.crossings, with.crossings);
    assert_eq!(progress::total_steps(|p| run_job_with(&base, &job, p)), 5);
    let e = progress::cancelled(|p| run_job_with(&base, &job, p), 1, 5);
    assert!(matches!(e, SculptError::Cancelled(_)), "{e}");
}
