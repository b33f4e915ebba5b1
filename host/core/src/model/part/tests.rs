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
    // An outline alone, without the object around it, is named as what it is.
    let e = json("[[0, 0], [10, 0], [0, 10]]").unwrap_err();
    assert!(matches!(e, PartError::NotAnObject("an array")), "{e}");
    assert!(e.to_string().contains("a part file is one JSON object"), "{e}");
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
    let empty = r#"<svg xmlns="http://www.w3.org/2000/svg"><circle r="0"/></svg>"#;
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
        e.contains("2 separate outlines") && e.contains("shape 1") && e.contains("shape 0"),
        "{e}"
    );
}

/// A circle of radius r flattened at tolerance t has chords of sagitta ≤ t: its area lies
/// between the inscribed polygon's bound π r² (1 − 2t/r) and π r².
fn circle_area_ok(area: f64, r: f64, t: f64) -> bool {
    let full = std::f64::consts::PI * r * r;
    area <= full * (1.0 + 1e-6) && area >= full * (1.0 - 2.0 * t / r)
}

#[test]
fn svg_circle_hole_curves_and_units() {
    // The issue's case: a <circle> drawn on a rectangle is its hole.
    let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="40mm" height="20mm" viewBox="0 0 40 20">
      <rect width="40" height="20"/><circle cx="10" cy="10" r="5" fill="white"/></svg>"#;
    let (p, notes) = svg::read(svg, "plate", 0.01).unwrap();
    assert!(notes.is_empty(), "{notes:?}");
    assert_eq!(p.holes.len(), 1);
    let hole = -signed_area(&p.holes[0]);
    assert!(circle_area_ok(hole, 5.0, 0.01), "{hole}");
    // 2 in across with a viewBox: 50.8 mm, not 2 viewBox units.
    let inch = r#"<svg xmlns="http://www.w3.org/2000/svg" width="2in" height="1in" viewBox="0 0 2 1">
      <rect width="2" height="1"/></svg>"#;
    let (p, _) = svg::read(inch, "i", 0.05).unwrap();
    assert!((p.area() - 50.8 * 25.4).abs() < 1e-2, "{}", p.area());
    // pt and px: 72 pt = 96 px = 1 in.
    for (w, h) in [("72pt", "72pt"), ("96px", "96px"), ("2.54cm", "25.4mm")] {
        let s = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 10 10"><rect width="10" height="10"/></svg>"#
        );
        let (p, _) = svg::read(&s, "u", 0.05).unwrap();
        assert!((p.area() - 25.4 * 25.4).abs() < 1e-2, "{w}: {}", p.area());
    }
    // No unit: a note, and user units read as mm.
    let bare =
        r#"<svg xmlns="http://www.w3.org/2000/svg"><ellipse cx="0" cy="0" rx="20" ry="10"/></svg>"#;
    let (p, notes) = svg::read(bare, "e", 0.05).unwrap();
    assert!(notes.len() == 1 && notes[0].contains("no physical size"), "{notes:?}");
    let full = std::f64::consts::PI * 200.0;
    assert!(p.area() < full && p.area() > full * (1.0 - 2.0 * 0.05 / 10.0), "{}", p.area());
}

#[test]
fn svg_fill_rule_decides_holes() {
    // Two same-direction squares: nonzero fills the inner one (no hole), evenodd makes a hole.
    let d = "M0 0 H30 V30 H0 Z M10 10 H20 V20 H10 Z";
    let nonzero = format!(r#"<svg xmlns="http://www.w3.org/2000/svg"><path d="{d}"/></svg>"#);
    let (p, notes) = svg::read(&nonzero, "n", 0.05).unwrap();
    assert!(p.holes.is_empty() && notes.iter().any(|n| n.contains("draw nothing")), "{notes:?}");
    let evenodd = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg"><path fill-rule="evenodd" d="{d}"/></svg>"#
    );
    let (p, _) = svg::read(&evenodd, "e", 0.05).unwrap();
    assert_eq!(p.holes.len(), 1);
    assert!((p.area() - 800.0).abs() < 1e-3);
    // Opposite direction under nonzero: a hole. CSS sets the rule too.
    let css = r#"<svg xmlns="http://www.w3.org/2000/svg"><style>path { fill-rule: evenodd }</style>
      <path d="M0 0 H30 V30 H0 Z M10 10 H20 V20 H10 Z"/></svg>"#;
    assert_eq!(svg::read(css, "c", 0.05).unwrap().0.holes.len(), 1);
    let opposite = r#"<svg xmlns="http://www.w3.org/2000/svg"><path d="M0 0 H30 V30 H0 Z M10 10 V20 H20 V10 Z"/></svg>"#;
    assert_eq!(svg::read(opposite, "o", 0.05).unwrap().0.holes.len(), 1);
}

#[test]
fn svg_rounded_rect_and_arc_path_flatten_within_the_tolerance() {
    // A 40 × 20 rect with 5 mm corners: area 800 − (4 − π)·25.
    let rr = r#"<svg xmlns="http://www.w3.org/2000/svg" width="40mm" height="20mm" viewBox="0 0 40 20"><rect width="40" height="20" rx="5"/></svg>"#;
    let want = 800.0 - (4.0 - std::f64::consts::PI) * 25.0;
    for t in [0.05, 0.005] {
        let a = svg::read(rr, "r", t).unwrap().0.area();
        assert!(a <= want + 1e-3 && a > want - 4.0 * 40.0 * t, "{t}: {a} vs {want}");
    }
    // A half disc drawn with an arc command.
    let arc =
        r#"<svg xmlns="http://www.w3.org/2000/svg"><path d="M -10 0 A 10 10 0 0 1 10 0 Z"/></svg>"#;
    let a = svg::read(arc, "a", 0.01).unwrap().0.area();
    assert!(circle_area_ok(2.0 * a, 10.0, 0.01), "{a}");
}
