//! Models in the HyperFun language: library definitions, R-function identities and sign
//! conventions, control flow, errors with locations, and grid sampling equal to pointwise
//! evaluation. The model texts are small snippets written for these tests in the styles of
//! real HyperFun files (object form with library calls; machine-exported assignment form).

use glam::{DMat3, DVec3};
use volmorph_frep::grid::{box_geometry, sample, sample_naive};
use volmorph_frep::{CompileOptions, FrepError, Pos, Tape, compile_source};
use volmorph_volume::Geometry;

fn tape(src: &str) -> Tape {
    match compile_source(src, &CompileOptions::default()) {
        Ok(s) => Tape::new(&s),
        Err(e) => panic!("{e}"),
    }
}

fn err(src: &str) -> FrepError {
    compile_source(src, &CompileOptions::default()).expect_err("must fail")
}

const CSG: &str = "my_model(x[3], a[1])
{
  array center[3];
  array corner[3];
  center = [0, 0, 0];
  ball = hfSphere(x, center, 5);
  corner = [-4, -4, -4];
  box = hfBlock(x, corner, 8, 8, 8);
  my_model = box \\ ball;
}";

/// Assignment form, as exported by machines: SSA temporaries and plain math.
const EXPORTED: &str = "my_model(x[3], a[1])
{
  t0 = x[1];
  t1 = (t0*t0);
  t2 = x[2];
  t3 = (t2*t2);
  t4 = (t1+t3);
  t5 = sqrt(t4);
  t6 = 0.75;
  t7 = (t5-t6);
  t8 = x[3];
  t9 = abs(t8);
  t10 = 0.25;
  t11 = (t9-t10);
  t12 = max(t7,t11);
  t13 = (t5-0.3);
  t14 = (0.0-t13);
  t15 = max(t12,t14);
  my_model = -(t15);
}";

fn r_int(a: f64, b: f64) -> f64 {
    a + b - (a * a + b * b).sqrt()
}

#[test]
fn csg_model_follows_the_r_functions() {
    let t = tape(CSG);
    for p in [
        DVec3::ZERO,
        DVec3::new(3.9, 3.9, 3.9),
        DVec3::new(4.5, 0.0, 0.0),
        DVec3::new(1.0, -2.0, 3.0),
    ] {
        let ball = 25.0 - p.length_squared();
        let slab = |v: f64| (v + 4.0) * (4.0 - v);
        let bx = r_int(r_int(slab(p.x), slab(p.y)), slab(p.z));
        let want = r_int(bx, -ball);
        assert!((t.eval(p) - want).abs() < 1e-9 * want.abs().max(1.0), "{p}");
    }
    // Corners of the box are in the solid, the centre (inside the ball) is not.
    assert!(t.eval(DVec3::splat(3.9)) > 0.0);
    assert!(t.eval(DVec3::ZERO) < 0.0);
    assert!(t.eval(DVec3::splat(4.1)) < 0.0);
}

#[test]
fn exported_assignment_form_evaluates() {
    let t = tape(EXPORTED);
    let f = |p: DVec3| {
        let r = (p.x * p.x + p.y * p.y).sqrt();
        -((r - 0.75).max(p.z.abs() - 0.25).max(-(r - 0.3)))
    };
    for p in [
        DVec3::new(0.5, 0.1, 0.0),
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(0.9, 0.0, 0.1),
    ] {
        assert_eq!(t.eval(p), f(p));
    }
    // Deduplication: repeated sub-expressions share nodes.
    assert!(t.len() < 18, "{}", t.len());
}

#[test]
fn r_function_identities_and_signs() {
    let t = tape(
        "m(x[3], a[1]) { u = x[1] | x[2]; i = x[1] & x[2]; s = x[1] \\ x[2]; n = ~x[1]; p = x[1] @ x[2]; m = u * 1000000 + i * 10000 + s * 100 + n + p * 0; }",
    );
    let u = tape("m(x[3], a[1]) { m = x[1] | x[2]; }");
    let i = tape("m(x[3], a[1]) { m = x[1] & x[2]; }");
    let s = tape("m(x[3], a[1]) { m = x[1] \\ x[2]; }");
    let n = tape("m(x[3], a[1]) { m = ~x[1]; }");
    let _ = t;
    for a in [-2.0, -0.5, 0.0, 0.5, 3.0] {
        for b in [-1.5, -0.25, 0.0, 0.75, 2.0] {
            let p = DVec3::new(a, b, 0.0);
            let (fu, fi, fs) = (u.eval(p), i.eval(p), s.eval(p));
            assert!((fu - (a + b + (a * a + b * b).sqrt())).abs() < 1e-12);
            assert!((fi - r_int(a, b)).abs() < 1e-12);
            assert!((fs - r_int(a, -b)).abs() < 1e-12);
            assert_eq!(n.eval(p), -a);
            // Signs: union inside iff either is, intersection iff both, subtraction iff
            // the first is and the second is not.
            assert_eq!(fu >= 0.0, a >= 0.0 || b >= 0.0, "union {a} {b}");
            assert_eq!(fi >= 0.0, a >= 0.0 && b >= 0.0, "intersection {a} {b}");
            assert_eq!(fs >= 0.0, a >= 0.0 && -b >= 0.0, "subtraction {a} {b}");
            // De Morgan holds exactly for R-functions: ~(~f1 | ~f2) = f1 & f2.
            assert!((-((-a) + (-b) + (a * a + b * b).sqrt()) - fi).abs() < 1e-12);
        }
    }
}

#[test]
fn library_primitives_follow_their_definitions() {
    let p = DVec3::new(0.3, -0.4, 0.5);
    let cases: Vec<(&str, f64)> = vec![
        (
            "c = [0.1, 0.2, -0.1]; m = hfSphere(x, c, 1.5);",
            2.25 - (0.2f64.powi(2) + 0.6f64.powi(2) + 0.6f64.powi(2)),
        ),
        (
            "c = [0, 0, 0]; m = hfEllipsoid(x, c, 1, 2, 0.5);",
            1.0 - 0.09 - 0.04 - 1.0,
        ),
        (
            "c = [0, 0, 0]; m = hfCylinderX(x, c, 1);",
            1.0 - 0.16 - 0.25,
        ),
        (
            "c = [0, 0, 0]; m = hfCylinderZ(x, c, 1);",
            1.0 - 0.09 - 0.16,
        ),
        (
            "c = [0, 0, 0]; m = hfConeY(x, c, 2);",
            0.16 - 0.0225 - 0.0625,
        ),
        (
            "c = [0, 0, 0]; m = hfEllCylY(x, c, 1, 2);",
            1.0 - 0.0625 - 0.09,
        ),
        (
            "c = [0, 0, 0]; m = hfTorusZ(x, c, 1, 0.3);",
            0.09 - 0.25 - (0.5f64 - 1.0).powi(2),
        ),
        (
            "c = [0, 0, 0]; m = hfSuperell(x, c, 1, 1, 1, 1, 1);",
            1.0 - 0.09 - 0.16 - 0.25,
        ),
        (
            "m = hfBlendUni(x[1], x[2], 1, 1, 1);",
            0.3 - 0.4 + 0.5 + 1.0 / (1.0 + 0.09 + 0.16),
        ),
        (
            "m = hfBlendInt(x[1], x[2], 1, 1, 1);",
            0.3 - 0.4 - 0.5 + 1.0 / (1.0 + 0.09 + 0.16),
        ),
        (
            "x0 = [0]; y0 = [0]; z0 = [0]; aa = [2]; bb = [3]; m = hfBlobby(x, x0, y0, z0, aa, bb, 1);",
            3.0 * (-2.0f64 * 0.5).exp() - 1.0,
        ),
        (
            "x0 = [0]; y0 = [0]; z0 = [0]; bb = [2]; d = [2]; m = hfMetaball(x, x0, y0, z0, bb, d, 0.5);",
            1.5 * 2.0 * (1.0 - 0.5f64.sqrt() / 2.0).powi(2) - 0.5,
        ),
        (
            "x0 = [0]; y0 = [0]; z0 = [0]; d = [1]; m = hfSoft(x, x0, y0, z0, d, 0.1);",
            1.0 - 22.0 * 0.5 / 9.0 + 17.0 * 0.25 / 9.0 - 4.0 * 0.125 / 9.0 - 0.1,
        ),
        (
            "v = [0, 0, 0]; s = [1]; m = hfConvPoint(x, v, s, 0.2);",
            1.0 / (1.5f64 * 1.5) - 0.2,
        ),
        (
            "dummy = hfShift3D(x, 0.3, 0, 0); c = [0, 0, 0]; m = hfSphere(x, c, 1);",
            1.0 - 0.16 - 0.25,
        ),
        (
            "dummy = hfScale3D(x, 2, 2, 2); c = [0, 0, 0]; m = hfSphere(x, c, 1);",
            1.0 - 0.5 / 4.0,
        ),
        (
            "dummy = hfRotate3DZ(x, 1.5707963267948966); m = x[1];",
            -0.4,
        ),
        ("dummy = hfRotate3DX(x, 1.5707963267948966); m = x[2];", 0.5),
        (
            "dummy = hfRotate3DY(x, 1.5707963267948966); m = x[1];",
            -0.5,
        ),
        (
            "c = [0, 0, 0]; dummy = hfStretch3D(x, c, 2, 1, 1); m = x[1];",
            0.15,
        ),
        (
            "dummy = hfTwistZ(x, 0, 1, 0, 3.141592653589793); m = x[1];",
            0.3 * (0.5f64 * std::f64::consts::PI).cos()
                - 0.4 * (0.5f64 * std::f64::consts::PI).sin(),
        ),
        ("dummy = hfTaperX(x, 0, 1, 1, 2); m = x[2];", -0.4 / 1.3),
        ("dummy = hfTaperX(x, 1, 2, 0.5, 2); m = x[3];", 1.0),
        (
            "b = [0, 0, -1]; e = [0, 0, 1]; s = [1]; m = hfConvLine(x, b, e, s, 0);",
            conv_line_numeric(p, 1.0),
        ),
        (
            // The polyline (0,0,−1) → (0,0,−0.3) → (0,0,1): the same segment in two pieces.
            "v = [0, 0, -1, 0, 0, -0.3, 0, 0, 1]; s = [1, 1]; m = hfConvCurve(x, v, s, 0.25);",
            conv_line_numeric(p, 1.0) - 0.25,
        ),
    ];
    for (body, want) in cases {
        let src = format!("m(x[3], a[1]) {{ array c[3]; {body} }}");
        let v = tape(&src).eval(p);
        assert!(
            (v - want).abs() < 1e-9 * want.abs().max(1.0),
            "{body}: {v} vs {want}"
        );
    }
    // Block: the R-intersection of its three slabs.
    let b = tape("m(x[3], a[1]) { array v[3]; v = [0, 0, 0]; m = hfBlock(x, v, 1, 2, 3); }");
    let q = DVec3::new(0.5, 0.5, 1.0);
    let want = r_int(r_int(0.5 * 0.5, 0.5 * 1.5), 1.0 * 2.0);
    assert!((b.eval(q) - want).abs() < 1e-12);
}

/// `∫₀^θ dφ / (1 + S²|x − c − r·(u cos φ + v sin φ)|²)²` by Simpson with many intervals.
fn conv_arc_numeric(x: DVec3, c: DVec3, r: f64, theta_deg: f64, u: DVec3, v: DVec3, s: f64) -> f64 {
    let n = 20_000;
    let th = theta_deg.to_radians();
    let h = th / f64::from(n);
    let mut sum = 0.0;
    for i in 0..=n {
        let ph = f64::from(i) * h;
        let q = c + r * (u * ph.cos() + v * ph.sin());
        let w = if i == 0 || i == n {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        };
        sum += w / (1.0 + s * s * (x - q).length_squared()).powi(2);
    }
    sum * h / 3.0
}

#[test]
fn conv_arc_is_the_integral_over_the_arc() {
    let x = DVec3::new(0.3, 0.5, -0.2);
    // (θ, axis, angle, world directions of the local x and y axes).
    let cases = [
        (120.0_f64, "0, 0, 1", 0.0, DVec3::X, DVec3::Y),
        (270.0, "0, 0, 1", 0.0, DVec3::X, DVec3::Y),
        (400.0, "0, 0, 1", 0.0, DVec3::X, DVec3::Y),
        // The arc's plane turned by +90° about x: local y goes to world z.
        (200.0, "1, 0, 0", 90.0, DVec3::X, DVec3::Z),
    ];
    let c = DVec3::new(0.1, -0.2, 0.05);
    for (th, axis, angle, u, v) in cases {
        let src = format!(
            "m(x[3], a[1]) {{ array c[3], r[1], t[1], ax[3], an[1], s[1];
               c = [0.1, -0.2, 0.05]; r = [0.8]; t = [{th}]; ax = [{axis}]; an = [{angle}];
               s = [1.5]; m = hfConvArc(x, c, r, t, ax, an, s, 0.1); }}"
        );
        let t = tape(&src);
        let want = conv_arc_numeric(x, c, 0.8, th.min(360.0), u, v, 1.5) - 0.1;
        let got = t.eval(x);
        assert!(
            (got - want).abs() < 1e-5,
            "θ = {th}, axis {axis}: {got} vs {want}"
        );
        // Gradients are the tape's: compare with differences.
        let (gv, g) = t.gradient(x);
        assert_eq!(gv, got);
        let h = 1e-6;
        let fd = (t.eval(x + DVec3::X * h) - t.eval(x - DVec3::X * h)) / (2.0 * h);
        assert!((fd - g.x).abs() < 1e-5, "{fd} vs {}", g.x);
    }
}

/// `∬_T dA / (1 + S²r²)²` by the centroid rule on `n²` congruent sub-triangles.
fn conv_triangle_numeric(x: DVec3, t: [DVec3; 3], s: f64, n: u32) -> f64 {
    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
    let area = 0.5 * e1.cross(e2).length() / f64::from(n * n);
    let k = |p: DVec3| 1.0 / (1.0 + s * s * (x - p).length_squared()).powi(2);
    let nf = f64::from(n);
    let mut sum = 0.0;
    for i in 0..n {
        for j in 0..n - i {
            let (a, b) = (f64::from(i), f64::from(j));
            sum += k(t[0] + e1 * ((a + 1.0 / 3.0) / nf) + e2 * ((b + 1.0 / 3.0) / nf));
            if i + j + 1 < n {
                sum += k(t[0] + e1 * ((a + 2.0 / 3.0) / nf) + e2 * ((b + 2.0 / 3.0) / nf));
            }
        }
    }
    sum * area
}

#[test]
fn conv_triangle_mesh_and_noise_follow_their_definitions() {
    let x = DVec3::new(1.0, -0.5, 0.3);
    let t = [
        DVec3::ZERO,
        DVec3::new(1.2, 0.1, 0.0),
        DVec3::new(0.3, 0.9, 0.2),
    ];
    // Every labelling of the corners gives the same value (the longest edge is found).
    for (order, s) in [
        ([0, 1, 2], 1.0),
        ([1, 2, 0], 2.0),
        ([2, 0, 1], 0.7),
        ([0, 2, 1], 1.3),
    ] {
        let v: Vec<String> = order
            .iter()
            .flat_map(|&i: &usize| t[i].to_array())
            .map(|c| c.to_string())
            .collect();
        let src = format!(
            "m(x[3], a[1]) {{ array v[9], s[1]; v = [{}]; s = [{s}]; m = hfConvTriangle(x, v, s, 0.05); }}",
            v.join(", ")
        );
        let got = tape(&src).eval(x);
        let want = s * s * s * conv_triangle_numeric(x, t, s, 300) - 0.05;
        assert!(
            (got - want).abs() < 1e-5 * want.abs().max(1.0),
            "S = {s}: {got} vs {want}"
        );
    }
    // A mesh of two triangles sharing an edge is the sum of the two triangles.
    let quad = [
        DVec3::ZERO,
        DVec3::new(1.0, 0.0, 0.0),
        DVec3::new(1.0, 1.0, 0.1),
        DVec3::new(0.0, 1.0, 0.0),
    ];
    let mesh = tape(
        "m(x[3], a[1]) { array v[12], tri[6], s[2];
           v = [0, 0, 0, 1, 0, 0, 1, 1, 0.1, 0, 1, 0]; tri = [1, 2, 3, 1, 3, 4]; s = [1, 1];
           m = hfConvMesh(x, v, tri, s, 0.2); }",
    );
    let want = conv_triangle_numeric(x, [quad[0], quad[1], quad[2]], 1.0, 300)
        + conv_triangle_numeric(x, [quad[0], quad[2], quad[3]], 1.0, 300)
        - 0.2;
    assert!(
        (mesh.eval(x) - want).abs() < 1e-5,
        "{} vs {want}",
        mesh.eval(x)
    );
    // hfFMapBlob: f − Σ f0/(1 + r²/σ²), the blob with σ ≤ 1e-6 ignored.
    let blob = tape(
        "m(x[3], a[1]) { array x0[2], y0[2], z0[2], f0[2], sg[2];
           x0 = [1, 0]; y0 = [0, 0]; z0 = [0, 0]; f0 = [0.5, 9]; sg = [2, 0];
           m = hfFMapBlob(x, 0.3, x0, y0, z0, f0, sg); }",
    );
    let r2 = (x - DVec3::X).length_squared();
    assert!((blob.eval(x) - (0.3 - 0.5 / (1.0 + r2 / 4.0))).abs() < 1e-12);
    // Space maps by handles: the point seen by the primitive after the in-place mapping.
    let (src, dst, fr) = (DVec3::new(0.8, -0.4, 0.2), DVec3::new(1.1, -0.5, 0.4), 1.5);
    let delta = dst - src;
    let l = (x - dst) / (fr * (DVec3::ONE + delta.abs()));
    let rho = l.length();
    let cubic = x - delta * ((1.0 - rho).powi(3) / (1.0 + rho));
    let expo = x - delta * (-rho * rho).exp();
    assert!(rho <= 1.0);
    for (name, moved) in [("hfSpaceMapCubic", cubic), ("hfSpaceMapExp", expo)] {
        for (k, want) in moved.to_array().into_iter().enumerate() {
            let t = tape(&format!(
                "m(x[3], a[1]) {{ array s[3], d[3], b[3]; s = [0.8, -0.4, 0.2]; d = [1.1, -0.5, 0.4];
                   b = [1.5, 1.5, 1.5]; dummy = {name}(x, s, d, b); m = x[{}]; }}",
                k + 1
            ));
            assert!((t.eval(x) - want).abs() < 1e-12, "{name} axis {k}");
        }
    }
    // Beyond the cubic map's support nothing moves.
    let far = tape(
        "m(x[3], a[1]) { array s[3], d[3], b[3]; s = [0, 0, 0]; d = [0.1, 0, 0]; b = [0.1, 0.1, 0.1];
           dummy = hfSpaceMapCubic(x, s, d, b); m = x[1]; }",
    );
    assert_eq!(far.eval(x), x.x);
    // Library names are case-insensitive, as in HyperFun.
    let upper = tape("m(x[3], a[1]) { m = HFNOISEG(x, 0.8, 3, 0.5); }");
    // hfNoiseG at a hand-checked point.
    let noise = tape("m(x[3], a[1]) { m = hfNoiseG(x, 0.8, 3, 0.5); }");
    let (a, f, ph) = (0.8f64, 3.0f64, 0.5f64);
    let sn = [(f * x.x).sin(), (f * x.y).sin(), (f * x.z).sin()];
    let ser = |k: usize, c: f64, prev: f64| a * sn[k] + a / 1.17 * (f * c / 1.35 + ph * prev).sin();
    let want = ser(0, x.x, sn[2]) * ser(1, x.y, sn[0]) * ser(2, x.z, sn[1]);
    assert!((noise.eval(x) - want).abs() < 1e-12);
    assert_eq!(upper.eval(x), noise.eval(x));
}

/// ∫ 1/(1 + S²r²)² along the segment (0,0,−1)→(0,0,1), by Simpson with many intervals.
fn conv_line_numeric(p: DVec3, s: f64) -> f64 {
    let n = 20_000;
    let h = 2.0 / f64::from(n);
    let mut sum = 0.0;
    for i in 0..=n {
        let q = DVec3::new(0.0, 0.0, -1.0 + h * f64::from(i));
        let r2 = (p - q).length_squared();
        let w = if i == 0 || i == n {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        };
        sum += w / (1.0 + s * s * r2).powi(2);
    }
    sum * h / 3.0
}

#[test]
fn control_flow_constant_and_data_dependent() {
    // A counting loop is unrolled; constant ifs leave no trace.
    let t = tape(
        "m(x[3], a[1]) { s = 0; i = 1; while i <= 10 loop s = s + i * x[1]; i = i + 1; endloop; if s > 1000 then m = 1; else m = s; endif; }",
    );
    assert_eq!(t.eval(DVec3::new(2.0, 0.0, 0.0)), 110.0);
    assert!(t.len() <= 21, "{}", t.len());
    // A data-dependent if is a select.
    let t = tape("m(x[3], a[1]) { if x[1] > 0 & x[2] > 0 then m = 1; else m = -1; endif; }");
    assert_eq!(t.eval(DVec3::new(1.0, 1.0, 0.0)), 1.0);
    assert_eq!(t.eval(DVec3::new(1.0, -1.0, 0.0)), -1.0);
    // A data-dependent loop: halve until below 1 (ends within the unroll limit).
    let t = tape(
        "m(x[3], a[1]) { v = abs(x[1]); n = 0; while v >= 1 loop v = v / 2; n = n + 1; endloop; m = n; }",
    );
    for (x, n) in [(0.5, 0.0), (1.0, 1.0), (5.0, 3.0), (1000.0, 10.0)] {
        assert_eq!(t.eval(DVec3::new(x, 0.0, 0.0)), n, "{x}");
    }
    // Points needing more passes than the unroll limit are NaN, not wrong.
    assert!(t.eval(DVec3::new(1e300, 0.0, 0.0)).is_nan());
    // Data-dependent array index.
    let t = tape("m(x[3], a[1]) { array v[3]; v = [10, 20, 30]; m = v[x[1]]; }");
    assert_eq!(t.eval(DVec3::new(2.0, 0.0, 0.0)), 20.0);
    assert!(t.eval(DVec3::new(4.0, 0.0, 0.0)).is_nan());
    // Parameters and objects calling objects.
    let src = "ball(x[3], r[1]) { ball = r[1]^2 - x[1]^2 - x[2]^2 - x[3]^2; }
               m(x[3], a[2]) { m = ball(x, a) | ball(x, [a[2]]); }";
    let opts = CompileOptions {
        params: [(1, 1.0), (2, 0.5)].into(),
        ..Default::default()
    };
    let t = Tape::new(&compile_source(src, &opts).unwrap());
    let (f1, f2): (f64, f64) = (1.0 - 0.25, 0.25 - 0.25);
    assert!(
        (t.eval(DVec3::new(0.5, 0.0, 0.0)) - (f1 + f2 + (f1 * f1 + f2 * f2).sqrt())).abs() < 1e-12
    );
}

#[test]
fn bad_models_give_located_errors() {
    let cases: Vec<(&str, &str, u32)> = vec![
        (
            "m(x[3], a[1]) {\n  m = 1 +;\n}",
            "expected an expression",
            2,
        ),
        (
            "m(x[3], a[1]) {\n  m = hfSphere(x, 1);\n}",
            "takes 3 arguments",
            2,
        ),
        (
            "m(x[3], a[1]) {\n  m = hfConvCurve(x, 1, 2);\n}",
            "takes 4 arguments",
            2,
        ),
        (
            "m(x[3], a[1]) {\n  array v[6];\n  m = hfConvCurve(x, v, v, 0);\n}",
            "`vect` needs 3 values per point",
            3,
        ),
        (
            "m(x[3], a[1]) {\n  array c[3];\n  m = hfConvArc(x, c, c, c, c, c, c, c);\n}",
            "argument 8 (`T`) of `hfConvArc` must be a number",
            3,
        ),
        (
            "m(x[3], a[1]) {\n  array c[3], s[2];\n  m = hfConvArc(x, c, c, c, c, c, s, 0);\n}",
            "2 arcs",
            3,
        ),
        (
            "m(x[3], a[1]) {\n  array s[4];\n  m = hfSpaceMapExp(x, s, s, s);\n}",
            "3 values per handle",
            3,
        ),
        (
            "m(x[3], a[1]) {\n  array s[2], z[3];\n  m = hfFMapBlob(x, 1, s, s, z, z, z);\n}",
            "3 blobs",
            3,
        ),
        (
            "m(x[3], a[1]) {\n  m = hfNoiseG(x, 1, 2);\n}",
            "takes 4 arguments",
            2,
        ),
        (
            "m(x[3], a[1]) {\n  array v[9], s[2];\n  m = hfConvTriangle(x, v, s, 0);\n}",
            "9 values per triangle",
            3,
        ),
        (
            "m(x[3], a[1]) {\n  array v[9], t[3], s[1];\n  t = [1, 2, 4];\n  m = hfConvMesh(x, v, t, s, 0);\n}",
            "vertex number 4 of triangle 1",
            4,
        ),
        (
            "m(x[3], a[1]) {\n  array v[9], t[3], s[1];\n  t = [1, 2, x[1]];\n  m = hfConvMesh(x, v, t, s, 0);\n}",
            "must be constants",
            4,
        ),
        (
            "m(x[3], a[1]) {\n  m = hfNothing(x);\n}",
            "unknown function `hfNothing`",
            2,
        ),
        (
            "m(x[3], a[1]) {\n  m = frobnicate(x[1]);\n}",
            "unknown function",
            2,
        ),
        (
            "m(x[3], a[1]) {\n  m = sqrt(1, 2);\n}",
            "takes 1 argument",
            2,
        ),
        (
            "m(x[3], a[1]) {\n  m = y + 1;\n}",
            "undefined variable `y`",
            2,
        ),
        ("m(x[3], a[1]) {\n  m = x[4];\n}", "outside `x[1..3]`", 2),
        (
            "m(x[3], a[1]) {\n  array c[3];\n  m = hfSphere(x, 1, 2);\n}",
            "must be an array",
            3,
        ),
        (
            "f(x[3], a[1]) { f = g(x, a); }\ng(x[3], a[1]) { g = f(x, a); }\nm(x[3], a[1]) {\n  m = f(x, a);\n}",
            "recursive call",
            2,
        ),
        (
            "m(x[3], a[1]) {\n  i = 0;\n  while 1 > 0 loop i = i + 1; endloop;\n  m = i;\n}",
            "loop does not end",
            3,
        ),
        (
            "m(x[3], a[1]) {\n  t = 1;\n}",
            "never assigns its result",
            1,
        ),
        ("m(x[3], a[1]) {\n  m = x;\n}", "assigns an array", 1),
        (
            "m(x[3], a[1]) {\n  m = (x[1] > 0) | 2;\n}",
            "combines a condition with a number",
            2,
        ),
    ];
    for (src, msg, line) in cases {
        let e = err(src);
        assert!(e.to_string().contains(msg), "{src}\n→ {e}");
        assert_eq!(e.pos().map(|p: Pos| p.line), Some(line), "{src}\n→ {e}");
    }
    // Nested data-dependent loops with empty bodies must not hang.
    let nested = format!(
        "m(x[3], a[1]) {{ {} m = 1; }}",
        "while x[1] > 0 loop ".repeat(6) + &"endloop; ".repeat(6)
    );
    let t0 = std::time::Instant::now();
    let e = err(&nested);
    assert!(e.to_string().contains("passes"), "{e}");
    assert!(t0.elapsed().as_secs() < 20);
    // Parameters outside the declared array.
    let e = compile_source(
        "m(x[3], a[1]) { m = a[1]; }",
        &CompileOptions {
            params: [(2, 1.0)].into(),
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("a2"), "{e}");
}

/// Grids large enough that regions are cut many times, specialised tapes are shared
/// between regions and leaves are evaluated row-structured on rows of every length: still
/// bit-for-bit the point-by-point values (the smooth blend of two balls, a union of many
/// boxes, a twisted bar).
#[test]
fn large_grid_sampling_equals_pointwise_evaluation() {
    let models = [
        "m(x[3], a[1]) { dx1 = x[1] - 0.45; dx2 = x[1] + 0.45;
            a1 = sqrt(dx1*dx1 + x[2]*x[2] + x[3]*x[3]) - 0.7;
            b1 = sqrt(dx2*dx2 + x[2]*x[2] + x[3]*x[3]) - 0.7;
            k = 0.25; h = max(k - abs(a1 - b1), 0.0) / k;
            f = min(a1, b1) - h*h*h*k/6.0; m = -f; }",
        "m(x[3], a[1]) { f = 1.0e9; i = 0;
            while i < 9 loop c = cos(0.7*i); s = sin(0.7*i);
              u = abs(c*x[1] + s*x[2] - 0.9) - 0.1; v = abs(c*x[2] - s*x[1]) - 0.08;
              f = min(f, max(max(u, v), abs(x[3]) - 0.2)); i = i + 1; endloop;
            m = -f; }",
        "m(x[3], a[1]) { ct = cos(1.2*x[3]); st = sin(1.2*x[3]);
            f = max(abs(x[1]*ct + x[2]*st) - 0.35, abs(x[2]*ct - x[1]*st) - 0.35);
            m = -max(f, abs(x[3]) - 1.1); }",
    ];
    for src in models {
        let t = tape(src);
        for dims in [[97, 61, 45], [300, 9, 11]] {
            let g = box_geometry(DVec3::splat(-1.6), DVec3::splat(1.6), dims).unwrap();
            let fast = sample(&t, &g).unwrap();
            let slow = sample_naive(&t, &g).unwrap();
            let same = fast
                .data()
                .iter()
                .zip(slow.data())
                .filter(|(a, b)| a.to_bits() == b.to_bits())
                .count();
            assert_eq!(same, slow.data().len(), "{dims:?}: {src}");
        }
    }
}

#[test]
fn grid_sampling_equals_pointwise_evaluation() {
    let models = [
        CSG,
        EXPORTED,
        "m(x[3], a[1]) { g = sin(3*x[1])*cos(3*x[2]) + sin(3*x[2])*cos(3*x[3]) + sin(3*x[3])*cos(3*x[1]); m = -max(g, sqrt(x[1]^2+x[2]^2+x[3]^2) - 1.4); }",
    ];
    let rot = DMat3::from_rotation_z(0.3) * DMat3::from_rotation_x(-0.7);
    for (n, src) in models.iter().enumerate() {
        let t = tape(src);
        let scale = if n == 0 { 6.0 } else { 1.6 };
        let g1 = box_geometry(DVec3::splat(-scale), DVec3::splat(scale), [37, 29, 23]).unwrap();
        let g2 = Geometry::new([31, 17, 40])
            .with_origin(DVec3::new(-scale, -0.5 * scale, -scale))
            .with_spacing(DVec3::splat(scale / 15.0))
            .with_direction(rot);
        for g in [g1, g2] {
            let fast = sample(&t, &g).unwrap();
            let slow = sample_naive(&t, &g).unwrap();
            assert!(
                fast.data()
                    .iter()
                    .zip(slow.data())
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
            // Spot-check against the point evaluator at the physical voxel centre.
            let p = g.index_to_physical(DVec3::new(5.0, 7.0, 3.0));
            let v = fast.get(5, 7, 3).unwrap();
            assert!((f64::from(v) - t.eval(p)).abs() <= 1e-6 * t.eval(p).abs().max(1.0));
        }
    }
    assert!(box_geometry(DVec3::ONE, DVec3::ZERO, [4, 4, 4]).is_err());
    assert!(box_geometry(DVec3::ZERO, DVec3::ONE, [1, 4, 4]).is_err());
}
