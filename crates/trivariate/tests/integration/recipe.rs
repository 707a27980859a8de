//! Modeling recipes (Martin & Cohen §3 operators from JSON): the GRIN lens from its recipe
//! file equals the built-in example, every operator agrees with the library call, and bad
//! recipes are errors naming the file and the JSON path of the field.

use std::path::Path;

use volmorph_trivariate::format::AnyAggregate;
use volmorph_trivariate::{
    GrinLensSpec, Recipe, TrivariateError, build_recipe_file, grin_lens, grin_lens_recipe, rule,
};

const LENS_RECIPE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../docs/nurbs/grin_lens_recipe.json"
);

fn volume(a: AnyAggregate) -> volmorph_trivariate::AggregateVolume {
    match a {
        AnyAggregate::Volume(v) => v,
        _ => panic!("not a volume"),
    }
}

#[test]
fn the_documented_grin_lens_recipe_builds_the_example() {
    let built = volume(build_recipe_file(Path::new(LENS_RECIPE)).unwrap());
    let example = grin_lens(&GrinLensSpec::default()).unwrap();
    assert_eq!(built, example);
    // The file is the recipe the library writes for the default lens.
    let text = std::fs::read_to_string(LENS_RECIPE).unwrap();
    let file = Recipe::from_json_str(&text, "lens").unwrap();
    assert_eq!(file, grin_lens_recipe(&GrinLensSpec::default()).unwrap());
}

#[test]
fn grin_lens_recipes_reproduce_every_lens() {
    for spec in [
        GrinLensSpec::default(),
        GrinLensSpec {
            radius: 2.5,
            thickness: 0.7,
            n0: 1.7,
            gradient: 0.1,
        },
    ] {
        let r = grin_lens_recipe(&spec).unwrap();
        // Through the JSON text and back.
        let r = Recipe::from_json_str(&r.to_json_string().unwrap(), "mem").unwrap();
        assert_eq!(volume(r.build("mem").unwrap()), grin_lens(&spec).unwrap());
    }
}

fn recipe(steps: &str, result: &str) -> String {
    format!(
        r#"{{"format": "volmorph-nurbs-recipe", "version": 1, "steps": [{steps}], "result": "{result}"}}"#
    )
}

fn build(text: &str) -> Result<AnyAggregate, TrivariateError> {
    Recipe::from_json_str(text, "t.json")?.build("t.json")
}

#[test]
fn rule_interpolation_and_attribute_edits_follow_the_operators() {
    // Two aggregate curves ruled into a surface, then extruded: attributes ruled across; the
    // second curve's attribute comes from data at the Greville abscissae.
    let text = recipe(
        r#"
        {"curve": {"name": "a", "degree": 2, "points": [[0,0,0],[1,0.5,0],[2,0,0]]}},
        {"attach": {"name": "a1", "to": "a", "attribute": "t",
                    "spline": {"degree": 2, "values": [0, 0.5, 1]}}},
        {"curve": {"name": "b", "degree": 2, "points": [[0,2,0],[1,2,0],[2,2,0]]}},
        {"attach": {"name": "b1", "to": "b", "attribute": "t",
                    "spline": {"degree": 2, "data": [5, 6, 9]}}},
        {"rule": {"name": "sheet", "from": "a1", "to": "b1"}},
        {"extrude": {"name": "slab", "of": "sheet", "direction": [0, 0, 3]}},
        {"attach": {"name": "slab2", "to": "slab", "attribute": "d",
                    "spline": {"degrees": [1, 1, 1], "counts": [2, 2, 2],
                               "values": [0, 1, 2, 3, 4, 5, 6, 7]}}},
        {"set_attribute": {"name": "slab3", "of": "slab2", "attribute": "d",
                    "spline": {"degree": 0, "counts": [1, 1, 1], "values": [42]}}},
        {"remove_attribute": {"name": "done", "of": "slab3", "attribute": "t"}}
        "#,
        "slab2",
    );
    let slab = volume(build(&text).map_err(|e| e.to_string()).unwrap());
    // `t` on the b side interpolates 5, 6, 9 at the Greville abscissae 0, 0.5, 1 of a
    // quadratic Bézier: its values there are the data.
    let mut v = [0.0];
    for (u, want) in [(0.0, 5.0), (0.5, 6.0), (1.0, 9.0)] {
        slab.attribute_into("t", [u, 1.0, 0.4], &mut v).unwrap();
        assert!((v[0] - want).abs() < 1e-12, "{u}: {}", v[0]);
    }
    // The a side: linear 0 → 1; halfway across the rule, the mean.
    slab.attribute_into("t", [0.5, 0.0, 0.9], &mut v).unwrap();
    assert!((v[0] - 0.5).abs() < 1e-12);
    slab.attribute_into("t", [0.5, 0.5, 0.0], &mut v).unwrap();
    assert!((v[0] - 3.25).abs() < 1e-12);
    // The geometry is the library's rule of the same curves, extruded.
    let p = slab.point([0.5, 0.5, 1.0]).unwrap();
    let a = match build(&recipe(
        r#"{"curve": {"name": "a", "degree": 2, "points": [[0,0,0],[1,0.5,0],[2,0,0]]}}"#,
        "a",
    ))
    .unwrap()
    {
        AnyAggregate::Curve(c) => c,
        _ => unreachable!(),
    };
    let b = match build(&recipe(
        r#"{"curve": {"name": "b", "degree": 2, "points": [[0,2,0],[1,2,0],[2,2,0]]}}"#,
        "b",
    ))
    .unwrap()
    {
        AnyAggregate::Curve(c) => c,
        _ => unreachable!(),
    };
    let sheet: volmorph_trivariate::AggregateSurface = rule::<1, 2>(&a, &b).unwrap();
    let q = sheet.point([0.5, 0.5]).unwrap();
    assert!((p[0] - q[0]).abs() < 1e-12 && (p[1] - q[1]).abs() < 1e-12);
    assert!((p[2] - 3.0).abs() < 1e-12);
    // set_attribute and remove_attribute.
    let text2 = text.replace(r#""result": "slab2""#, r#""result": "done""#);
    let done = volume(build(&text2).unwrap());
    assert!(done.attribute("t").is_none());
    done.attribute_into("d", [0.3, 0.3, 0.3], &mut v).unwrap();
    assert_eq!(v[0], 42.0);
}

/// The error message of a bad recipe.
fn error(text: &str) -> String {
    build(text).unwrap_err().to_string()
}

#[test]
fn errors_name_the_file_and_the_json_path() {
    let line = r#"{"curve": {"name": "p", "degree": 1, "points": [[0,0,0],[1,0,0]]}}"#;
    let cases = [
        // Types and unknown fields, found by the parser.
        (
            recipe(
                r#"{"curve": {"name": "p", "degree": "one", "points": []}}"#,
                "p",
            ),
            "steps[0].curve.degree",
        ),
        (
            recipe(r#"{"curve": {"name": "p", "degre": 1, "points": []}}"#, "p"),
            "steps[0].curve",
        ),
        (recipe(r#"{"twist": {"name": "p"}}"#, "p"), "steps[0]"),
        (
            r#"{"format": "volmorph-nurbs-recipe", "version": 2, "steps": [], "result": "x"}"#
                .to_owned(),
            "t.json: version:",
        ),
        (
            r#"{"format": "other", "version": 1, "steps": [], "result": "x"}"#.to_owned(),
            "t.json: format:",
        ),
        // Meaning, found by the builder.
        (
            recipe(
                &format!(
                    r#"{line}, {{"revolve": {{"name": "d", "of": "p", "axis_point": [0,0,0],
                    "axis_direction": [0,0,1], "angle_degrees": 0}}}}"#
                ),
                "d",
            ),
            "t.json: steps[1].revolve.angle_degrees:",
        ),
        (
            recipe(
                &format!(
                    r#"{line}, {{"revolve": {{"name": "d", "of": "p", "axis_point": [0,0,0],
                    "axis_direction": [0,0,0], "angle_degrees": 90}}}}"#
                ),
                "d",
            ),
            "steps[1].revolve.axis_direction:",
        ),
        (
            recipe(
                &format!(
                    r#"{line}, {{"extrude": {{"name": "s", "of": "q", "direction": [0,0,1]}}}}"#
                ),
                "s",
            ),
            "steps[1].extrude.of: \"q\" is not the name of an earlier step",
        ),
        (
            recipe(&format!(r#"{line}, {line}"#), "p"),
            "steps[1].curve.name: step name \"p\" is used twice",
        ),
        (
            recipe(
                &format!(
                    r#"{line}, {{"attach": {{"name": "a", "to": "p", "attribute": "eta",
                    "spline": {{"degree": 2, "values": [1, 2]}}}}}}"#
                ),
                "a",
            ),
            "steps[1].attach.spline.values:",
        ),
        (
            recipe(
                &format!(
                    r#"{line}, {{"attach": {{"name": "a", "to": "p", "attribute": "eta",
                    "spline": {{"degree": 1, "values": [1, 2], "data": [1, 2]}}}}}}"#
                ),
                "a",
            ),
            "steps[1].attach.spline.values: invalid argument: give exactly one",
        ),
        (
            recipe(
                r#"{"curve": {"name": "p", "degree": 1, "points": [[0,0,0],[0,0,0]]}}"#,
                "p",
            ),
            "steps[0].curve.points: degenerate curve",
        ),
        (recipe(line, "nothing"), "t.json: result:"),
    ];
    for (text, want) in cases {
        let e = error(&text);
        assert!(e.contains(want), "{e:?} lacks {want:?}");
        assert!(e.starts_with("t.json: "), "{e:?}");
    }
    // A volume cannot be lifted.
    let lens = std::fs::read_to_string(LENS_RECIPE)
        .unwrap()
        .replace(r#""result": "lens""#, r#""result": "x""#);
    let lifted = lens.replace(
        "  ],\n  \"result\"",
        ",\n    {\"extrude\": {\"name\": \"x\", \"of\": \"lens\", \"direction\": [1, 0, 0]}}\n  ],\n  \"result\"",
    );
    let e = error(&lifted);
    assert!(e.contains("steps[4].extrude.of:"), "{e}");
    // File errors name the file.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.json");
    std::fs::write(&path, "{").unwrap();
    let e = build_recipe_file(&path).unwrap_err().to_string();
    assert!(e.contains("bad.json"), "{e}");
}
