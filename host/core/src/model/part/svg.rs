//! SVG parts through `usvg` (the resvg project's tree): every shape (`<rect>` with rounded
//! corners, `<circle>`, `<ellipse>`, `<polygon>`, `<polyline>`, `<path>` with arcs and
//! Béziers), `<use>`, CSS and `transform`s are resolved by usvg into paths of straight, quadratic
//! and cubic segments in the document's pixels. Those are flattened here to chords at most the
//! chord tolerance (mm, as DXF arcs: [`super::ImportOptions::chord_mm`]) from the curve, with
//! vertices on the curve.
//!
//! Units: the root's `width`/`height` in `mm`, `cm`, `in`, `pt`, `pc` or `px` (96 px per inch,
//! as CSS) give the drawing's physical size and usvg maps the `viewBox` onto it. A file that
//! states no physical unit (no `width`/`height`, plain numbers or percentages) is read with one
//! user unit (or unitless pixel) = 1 mm, with a note saying so. SVG's y-down axis is flipped so
//! the part looks as drawn.
//!
//! Holes: within one element the fill rule decides (`nonzero`, the default, or `evenodd`; an
//! element without fill is read as `evenodd`): a sub-path whose inside is unfilled while its
//! outside is filled is a hole; one whose inside and outside are both filled (a same-direction
//! loop under `nonzero`) draws nothing and is dropped with a note. Across elements, the
//! largest filled region is the outline and every other element drawn inside it is a hole (the
//! way parts are drawn: a plate, then its holes on top); one outside it is a second outline,
//! refused. usvg works in `f32`: vertices carry about 7 significant digits.

use usvg::tiny_skia_path::{PathSegment, Point};

use super::{Part, PartError, inside, signed_area, svg_non_finite};

/// mm per CSS pixel (96 px = 1 in = 25.4 mm).
pub(crate) const MM_PER_PX: f64 = 25.4 / 96.0;
/// Deepest curve subdivision: 2¹⁶ chords per segment at most.
const MAX_DEPTH: u32 = 16;

/// A ring of one element, with what the fill rule makes of it.
struct Loop {
    ring: Vec<[f64; 2]>,
    /// Which element (usvg path) it comes from.
    element: usize,
    /// Its inside is filled and its outside is not: an outer boundary.
    outer: bool,
}

/// Reads an SVG part; returns it and the notes for the user.
pub fn read(text: &str, name: &str, chord_mm: f64) -> Result<(Part, Vec<String>), PartError> {
    let doc = roxmltree::Document::parse(text)?;
    check_finite(&doc)?;
    let mut notes = Vec::new();
    let mm_per_px = match stated_unit(&doc) {
        Some(_) => MM_PER_PX,
        None => {
            notes.push(
                "the SVG states no physical size (width/height in mm, cm, in, pt or px): one user \
                 unit is read as 1 mm"
                    .to_string(),
            );
            1.0
        }
    };
    let opt = usvg::Options::default();
    let tree = usvg::Tree::from_xmltree(&doc, &opt).map_err(|e| PartError::SvgAttribute {
        element: "svg".into(),
        attribute: "(document)",
        message: e.to_string(),
    })?;
    let mut paths = Vec::new();
    collect(tree.root(), &mut paths);
    let tol_px = chord_mm / mm_per_px;
    let mut loops = Vec::new();
    let mut names = Vec::new();
    for (k, path) in paths.iter().enumerate() {
        let id = path.id();
        names.push(if id.is_empty() {
            format!("shape {k}")
        } else {
            format!("shape {k} (id {id:?})")
        });
        let rings = flatten(path, tol_px, mm_per_px);
        let evenodd = path.fill().is_none_or(|f| f.rule() == usvg::FillRule::EvenOdd);
        let dropped = classify(rings, k, evenodd, &mut loops);
        if dropped > 0 {
            notes.push(format!(
                "{}: {dropped} sub-path(s) inside a filled region of the same element draw \
                 nothing (nonzero fill rule, same direction) and are ignored",
                names[k]
            ));
        }
    }
    assemble(name, loops, &names).map(|p| (p, notes))
}

/// Every path of the tree, in document order (groups entered, their transforms kept).
fn collect<'a>(g: &'a usvg::Group, out: &mut Vec<&'a usvg::Path>) {
    for node in g.children() {
        match node {
            usvg::Node::Group(g) => collect(g, out),
            usvg::Node::Path(p) => out.push(p),
            _ => {}
        }
    }
}

/// The physical unit of the root's width or height, if it states one.
fn stated_unit(doc: &roxmltree::Document<'_>) -> Option<&'static str> {
    let root = doc.root_element();
    ["width", "height"].iter().find_map(|a| {
        let v = root.attribute(*a)?.trim();
        ["mm", "cm", "in", "pt", "pc", "px"].into_iter().find(|u| v.ends_with(u))
    })
}

/// NaN or infinity in a coordinate list is named as written (usvg would drop the element).
fn check_finite(doc: &roxmltree::Document<'_>) -> Result<(), PartError> {
    for node in doc.descendants().filter(|n| n.is_element()) {
        for attribute in ["points", "d"] {
            if let Some(token) = node.attribute(attribute).and_then(svg_non_finite) {
                let element = node.tag_name().name().to_string();
                return Err(PartError::SvgNotFinite { element, attribute, token });
            }
        }
    }
    Ok(())
}

/// The sub-paths of a path as rings in mm (y up), curves flattened to `tol_px`.
fn flatten(path: &usvg::Path, tol_px: f64, mm_per_px: f64) -> Vec<Vec<[f64; 2]>> {
    let Some(data) = path.data().clone().transform(path.abs_transform()) else {
        return Vec::new();
    };
    let mut rings = Vec::new();
    let mut cur: Vec<[f64; 2]> = Vec::new();
    let mut last = Point::zero();
    for seg in data.segments() {
        match seg {
            PathSegment::MoveTo(p) => {
                rings.push(std::mem::take(&mut cur));
                cur.push(xy(p));
                last = p;
            }
            PathSegment::LineTo(p) => {
                cur.push(xy(p));
                last = p;
            }
            PathSegment::QuadTo(c, p) => {
                // The quadratic as a cubic: control points 2/3 of the way to c.
                let c1 = [
                    last.x as f64 + 2.0 / 3.0 * (c.x - last.x) as f64,
                    last.y as f64 + 2.0 / 3.0 * (c.y - last.y) as f64,
                ];
                let c2 = [
                    p.x as f64 + 2.0 / 3.0 * (c.x - p.x) as f64,
                    p.y as f64 + 2.0 / 3.0 * (c.y - p.y) as f64,
                ];
                cubic([xy(last), c1, c2, xy(p)], tol_px, 0, &mut cur);
                last = p;
            }
            PathSegment::CubicTo(c1, c2, p) => {
                cubic([xy(last), xy(c1), xy(c2), xy(p)], tol_px, 0, &mut cur);
                last = p;
            }
            PathSegment::Close => rings.push(std::mem::take(&mut cur)),
        }
    }
    rings.push(cur);
    rings
        .into_iter()
        .map(|r| {
            clean(r, tol_px * 1e-6)
                .into_iter()
                .map(|[x, y]| [x * mm_per_px, -y * mm_per_px])
                .collect()
        })
        .filter(|r: &Vec<[f64; 2]>| r.len() >= 3)
        .collect()
}

fn xy(p: Point) -> [f64; 2] {
    [p.x as f64, p.y as f64]
}

/// Appends the cubic's points after its start: chords where the control points lie within
/// `tol` of the chord (the curve lies in their hull, so within `tol` of it too).
fn cubic(b: [[f64; 2]; 4], tol: f64, depth: u32, out: &mut Vec<[f64; 2]>) {
    let dist_to_chord = |p| crate::model::geometry::segment_foot(p, b[0], b[3]).1;
    let flat = dist_to_chord(b[1]).max(dist_to_chord(b[2])) <= tol;
    if flat || depth >= MAX_DEPTH {
        out.push(b[3]);
        return;
    }
    let mid = |p: [f64; 2], q: [f64; 2]| [(p[0] + q[0]) / 2.0, (p[1] + q[1]) / 2.0];
    let (p01, p12, p23) = (mid(b[0], b[1]), mid(b[1], b[2]), mid(b[2], b[3]));
    let (p012, p123) = (mid(p01, p12), mid(p12, p23));
    let m = mid(p012, p123);
    cubic([b[0], p01, p012, m], tol, depth + 1, out);
    cubic([m, p123, p23, b[3]], tol, depth + 1, out);
}

/// Drops repeated vertices (within `eps`), including a closing one equal to the start.
fn clean(ring: Vec<[f64; 2]>, eps: f64) -> Vec<[f64; 2]> {
    let same = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() <= eps && (a[1] - b[1]).abs() <= eps;
    let mut out: Vec<[f64; 2]> = Vec::with_capacity(ring.len());
    for p in ring {
        if out.last().is_none_or(|&q| !same(p, q)) {
            out.push(p);
        }
    }
    while out.len() > 1 && same(out[0], out[out.len() - 1]) {
        out.pop();
    }
    out
}

/// Sorts one element's rings by the fill rule into outer boundaries and holes (pushed to
/// `loops`); returns how many draw nothing.
fn classify(
    rings: Vec<Vec<[f64; 2]>>,
    element: usize,
    evenodd: bool,
    loops: &mut Vec<Loop>,
) -> usize {
    let wind = |r: &Vec<[f64; 2]>| if signed_area(r) > 0.0 { 1i32 } else { -1 };
    let mut dropped = 0;
    for (i, ring) in rings.iter().enumerate() {
        // The fill just outside ring i: the rings containing it, by the rule.
        let (mut count, mut winding) = (0i32, 0i32);
        for (j, other) in rings.iter().enumerate() {
            if j != i && inside(ring[0], other) {
                count += 1;
                winding += wind(other);
            }
        }
        let filled = |c: i32, w: i32| if evenodd { c % 2 == 1 } else { w != 0 };
        let outside = filled(count, winding);
        let within = filled(count + 1, winding + wind(ring));
        if outside == within {
            dropped += 1;
        } else {
            loops.push(Loop { ring: ring.clone(), element, outer: within });
        }
    }
    dropped
}

/// The part: the largest outer boundary is the outline; every other loop inside it a hole.
fn assemble(name: &str, mut loops: Vec<Loop>, names: &[String]) -> Result<Part, PartError> {
    let Some(outer) = (0..loops.len()).filter(|&i| loops[i].outer).max_by(|&a, &b| {
        signed_area(&loops[a].ring).abs().total_cmp(&signed_area(&loops[b].ring).abs())
    }) else {
        return Err(PartError::NoShape);
    };
    let outline = loops.remove(outer);
    let apart: Vec<usize> = loops
        .iter()
        .filter(|l| !l.ring.iter().any(|&p| inside(p, &outline.ring)))
        .map(|l| l.element)
        .collect();
    if !apart.is_empty() {
        let count = apart.len() + 1;
        let mut elements = vec![outline.element];
        for e in apart {
            if !elements.contains(&e) {
                elements.push(e);
            }
        }
        return Err(PartError::SvgSeparateOutlines {
            count,
            names: elements.iter().map(|&e| names[e].as_str()).collect::<Vec<_>>().join(", "),
        });
    }
    Part::new(name.to_string(), outline.ring, loops.into_iter().map(|l| l.ring).collect())
}
