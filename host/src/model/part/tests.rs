use super::*;

fn json(s: &str) -> Result<Part, PartError> {
    Part::from_json(s, "t")
}

#[test]
fn json_part_is_normalised_to_ccw_outline_and_cw_holes() {
    let p = json(
        r#"{"name": "plate", "outline": [[0,0],[0,10],[10,10],[10,0]],
            "holes": [[[2,2],[4,2],[4,4],[2,4]]]}"#,
    )
    .unwrap();
    assert_eq!(p.name, "plate");
    assert!(signed_area(&p.outline) > 0.0);
    assert!(signed_area(&p.holes[0]) < 0.0);
    assert_eq!(p.area(), 96.0);
    // Name defaults to the file stem; closing vertex dropped.
    let p = json(r#"{"outline": [[0,0],[1,0],[0,1],[0,0]]}"#).unwrap();
    assert_eq!((p.name.as_str(), p.outline.len()), ("t", 3));
}

#[test]
fn validation_errors_name_the_problem_and_vertex() {
    let e = json(r#"{"outline": [[0,0],[1,0]]}"#).unwrap_err();
    assert!(matches!(e, PartError::TooFewVertices { ring: Ring::Outline, count: 2 }), "{e}");
    let e = json(r#"{"outline": [[0,0],[1,0],[2,0]]}"#).unwrap_err();
    assert!(matches!(e, PartError::ZeroArea { ring: Ring::Outline }), "{e}");
    // Bow tie: edge 0 (0,0)-(2,2) crosses edge 2 (2,0)-(0,2).
    let e = json(r#"{"outline": [[0,0],[2,2],[2,0],[0,2]]}"#).unwrap_err();
    assert!(matches!(e, PartError::SelfIntersection { a: 0, b: 2, .. }), "{e}");
    assert_eq!(
        e.to_string(),
        "outline: self-intersection, edge from vertex 0 crosses edge from vertex 2"
    );
    let e = json(r#"{"outline": [[0,0],[1,0],[1,1],[0,1]], "holes": [[[5,5],[6,5],[6,6]]]}"#)
        .unwrap_err();
    assert!(matches!(e, PartError::HoleOutside { hole: 0, index: 0 }), "{e}");
    let e = json(r#"{"outline": [[0,0],[4,0],[4,4],[0,4]], "holes": [[[1,1],[5,1],[5,2],[1,2]]]}"#)
        .unwrap_err();
    assert!(matches!(e, PartError::HoleOutside { hole: 0, .. }), "{e}");
    let e = json(
        r#"{"outline": [[0,0],[9,0],[9,9],[0,9]],
            "holes": [[[1,1],[4,1],[4,4],[1,4]], [[3,3],[6,3],[6,6],[3,6]]]}"#,
    )
    .unwrap_err();
    assert!(matches!(e, PartError::HolesOverlap { a: 0, b: 1, .. }), "{e}");
    let e = json(
        r#"{"outline": [[0,0],[9,0],[9,9],[0,9]],
            "holes": [[[1,1],[8,1],[8,8],[1,8]], [[3,3],[6,3],[6,6],[3,6]]]}"#,
    )
    .unwrap_err();
    assert!(matches!(e, PartError::HolesOverlap { a: 1, b: 0, .. }), "{e}");
    let e = json(r#"{"outline": [[0,0],[1e9,0],[0,1]]}"#).unwrap_err();
    assert!(matches!(e, PartError::TooLarge { index: 1, .. }), "{e}");
    let e = json(r#"{"outline": [[0,0],[1e-5,0],[0,1e-5]]}"#).unwrap_err();
    assert!(matches!(e, PartError::TooSmall { .. }), "{e}");
    let e = json(r#"{"outline": [[0,0],[1,0],[1,0],[0,1]]}"#).unwrap_err();
    assert!(matches!(e, PartError::DuplicateVertex { index: 2, .. }), "{e}");
    // Spike folding back on itself.
    let e = json(r#"{"outline": [[0,0],[4,0],[4,4],[4,2],[0,4]]}"#).unwrap_err();
    assert!(matches!(e, PartError::SelfIntersection { .. }), "{e}");
    assert!(matches!(json("{\"outline\": 3}").unwrap_err(), PartError::Json(_)));
}

#[test]
fn non_finite_values_are_rejected() {
    let e =
        Part::new("x".into(), vec![[0.0, 0.0], [1.0, f64::NAN], [0.0, 1.0]], vec![]).unwrap_err();
    assert!(matches!(e, PartError::NotFinite { ring: Ring::Outline, index: 1, .. }), "{e}");
    let e = Part::new(
        "x".into(),
        vec![[0.0, 0.0], [3.0, 0.0], [0.0, 3.0]],
        vec![vec![[0.5, 0.5], [f64::INFINITY, 0.5], [0.5, 1.0]]],
    )
    .unwrap_err();
    assert!(matches!(e, PartError::NotFinite { ring: Ring::Hole(0), index: 1, .. }), "{e}");
}

#[test]
fn svg_polygon_and_path_with_hole_and_transform() {
    let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100">
      <g transform="translate(10 20)">
        <path d="M 0 0 h 40 v 30 H 0 Z M 5 5 L 5 10 L 10 10 L 10 5 Z"/>
      </g>
    </svg>"#;
    let p = Part::from_svg(svg, "bracket").unwrap();
    assert_eq!(p.name, "bracket");
    assert_eq!(p.outline.len(), 4);
    assert_eq!(p.holes.len(), 1);
    assert_eq!(p.area(), 1200.0 - 25.0);
    // y flipped, translated.
    assert!(p.outline.contains(&[10.0, -20.0]) && p.outline.contains(&[50.0, -50.0]));
    let svg = r#"<svg xmlns="http://www.w3.org/2000/svg"><polygon points="0,0 10,0 5,8"/></svg>"#;
    assert_eq!(Part::from_svg(svg, "t").unwrap().area(), 40.0);
    let curve = r#"<svg xmlns="http://www.w3.org/2000/svg"><path d="M0 0 C 1 1 2 2 3 0 Z"/></svg>"#;
    assert!(matches!(Part::from_svg(curve, "c").unwrap_err(), PartError::Curve { path: 0 }));
    let empty = r#"<svg xmlns="http://www.w3.org/2000/svg"><circle r="3"/></svg>"#;
    assert!(matches!(Part::from_svg(empty, "c").unwrap_err(), PartError::NoShape));
    assert!(matches!(Part::from_svg("<svg", "c").unwrap_err(), PartError::Xml(_)));
}

#[test]
fn json_nan_names_the_token_place_and_key() {
    let e = json("{\"name\": \"t\", \"outline\": [[0, 0], [NaN, 1], [1, 1]]}").unwrap_err();
    let m = e.to_string();
    assert!(
        m.contains("`NaN`")
            && m.contains("line 1 column")
            && m.contains("\"outline\"")
            && m.contains("no NaN or Infinity"),
        "{m}"
    );
    let e = json("{\"outline\": [[0, 0],\n [1, -Infinity], [1, 1]]}").unwrap_err().to_string();
    assert!(e.contains("`-Infinity`") && e.contains("line 2"), "{e}");
    // Other syntax errors keep serde's message.
    assert!(matches!(json("{\"outline\": [[0, 0], [x, 1]]}").unwrap_err(), PartError::Json(_)));
}

#[test]
fn svg_nan_and_separate_outlines_are_named() {
    let nan = r#"<svg xmlns="http://www.w3.org/2000/svg"><polygon points="0,0 NaN,0 5,8"/></svg>"#;
    let e = Part::from_svg(nan, "t").unwrap_err().to_string();
    assert!(
        e.contains("`NaN`") && e.contains("points") && e.contains("not a finite number"),
        "{e}"
    );
    let two = r#"<svg xmlns="http://www.w3.org/2000/svg"><path d="M0 0 L10 0 L10 10 Z"/>
        <path d="M20 0 L40 0 L40 10 Z"/></svg>"#;
    let e = Part::from_svg(two, "t").unwrap_err().to_string();
    assert!(
        e.contains("2 separate outlines") && e.contains("<path> 1") && e.contains("<path> 0"),
        "{e}"
    );
}
