//! Handle files that cannot be read name the file and what is wrong, through the readers a
//! user's file goes through (`HandleSet::read`, `read_point_list`).

use volmorph_handles::handles::{HandleSet, read_point_list};

/// A malformed handle JSON file was reported as "lattice JSON".
#[test]
fn handle_json_parse_error_labelled_lattice_json() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.json");
    std::fs::write(&path, "{\"points\": [ {\"source\": [1, 2, 3], ").unwrap();
    let e = HandleSet::read(&path).unwrap_err().to_string();
    assert!(e.contains("h.json") && e.contains("handle JSON"), "{e}");
    assert!(!e.contains("lattice"), "{e}");
}

/// An error about a whole handle file (its version) said "line 0".
#[test]
fn handle_error_reports_line_0() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v.json");
    std::fs::write(&path, r#"{"version": 7, "points": []}"#).unwrap();
    let e = HandleSet::read(&path).unwrap_err().to_string();
    assert!(e.contains("v.json") && e.contains("version 7"), "{e}");
    assert!(!e.contains("line 0"), "{e}");
    // A text handle file's error names the line it is on (counted from 1).
    let text = dir.path().join("h.txt");
    std::fs::write(&text, "# sources → targets\n1 2 3 4 5 6\n1 2 x 4 5 6\n").unwrap();
    let e = HandleSet::read(&text).unwrap_err().to_string();
    assert!(e.contains("h.txt") && e.contains("line 3"), "{e}");
    let points = dir.path().join("p.txt");
    std::fs::write(&points, "1 2 3\n4 5\n").unwrap();
    let e = read_point_list(&points).unwrap_err().to_string();
    assert!(e.contains("p.txt") && e.contains("line 2"), "{e}");
}
