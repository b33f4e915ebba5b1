#!/usr/bin/env python3
"""Writes the SVG test parts of host/cli/tests/integration/svg_import.rs with svgwrite, a Python SVG library,
and each part's JSON twin: its exact area (mm²), centroid (mm, y up, as the reader gives it)
and hole count, computed here from the shapes' formulas (not from the SVG).

The files are committed, so tests and CI need no Python; to change them:

    pip install svgwrite && python3 host/cli/tests/integration/data/svg/make.py

  circle-hole.svg     40 x 20 mm rect, a <circle> hole (r 5) drawn on top; width/height in mm
  rounded-inch.svg    2 x 1 in rounded rect (rx 0.1 in) with viewBox in hundredths of an inch
  evenodd-pt.svg      one <path>: a disc drawn with two arcs and a square inside it,
                      fill-rule evenodd, sizes in pt, inside a rotated and translated group
  css-ellipse.svg     an <ellipse> with an elliptic hole as a second element, the hole's fill
                      set by a CSS class, width/height in cm
  unitless.svg        a <polygon> triangle with no width/height: user units read as mm (a note)
"""

import json
import math
import os

import svgwrite

HERE = os.path.dirname(os.path.abspath(__file__))


def write(name, drawing, area, centroid, holes):
    drawing.saveas(os.path.join(HERE, name + ".svg"), pretty=True)
    twin = {"area_mm2": area, "centroid_mm": centroid, "holes": holes}
    with open(os.path.join(HERE, name + ".json"), "w") as f:
        json.dump(twin, f, indent=2)
        f.write("\n")


def combine(parts):
    """Area and centroid of (area, cx, cy) pieces (negative area: a hole)."""
    a = sum(p[0] for p in parts)
    return a, [sum(p[0] * p[1] for p in parts) / a, sum(p[0] * p[2] for p in parts) / a]


def circle_hole():
    d = svgwrite.Drawing(size=("40mm", "20mm"), viewBox="0 0 40 20")
    d.add(d.rect((0, 0), (40, 20), fill="black"))
    d.add(d.circle((10, 8), 5, fill="white"))
    a, c = combine([(800.0, 20.0, -10.0), (-math.pi * 25.0, 10.0, -8.0)])
    write("circle-hole", d, a, c, 1)


def rounded_inch():
    d = svgwrite.Drawing(size=("2in", "1in"), viewBox="0 0 200 100")
    d.add(d.rect((0, 0), (200, 100), rx=10, ry=10))
    w, h, r = 50.8, 25.4, 2.54
    a = w * h - (4.0 - math.pi) * r * r
    write("rounded-inch", d, a, [w / 2, -h / 2], 0)


def evenodd_pt():
    # 1 user unit = 1 pt (viewBox = size in pt); a disc of radius 36 pt about (0, 0) and a
    # 24 pt square hole centred at (6, 0), the group turned by 30° about the origin and moved.
    d = svgwrite.Drawing(size=("144pt", "144pt"), viewBox="0 0 144 144")
    g = d.g(transform="translate(72 72) rotate(30)")
    p = d.path(d="M -36 0 A 36 36 0 0 1 36 0 A 36 36 0 0 1 -36 0 Z "
                 "M -6 -12 H 18 V 12 H -6 Z", fill_rule="evenodd")
    g.add(p)
    d.add(g)
    pt = 25.4 / 72.0
    r, s = 36 * pt, 24 * pt
    a, c = combine([(math.pi * r * r, 0.0, 0.0), (-s * s, 6 * pt, 0.0)])
    # Turn the local centroid by 30° (SVG: clockwise on screen, y down), move by (72, 72) pt,
    # then flip y.
    t = math.radians(30)
    x, y = c[0] * math.cos(t) - c[1] * math.sin(t), c[0] * math.sin(t) + c[1] * math.cos(t)
    write("evenodd-pt", d, a, [72 * pt + x, -(72 * pt + y)], 1)


def css_ellipse():
    # 1 user unit = 1 mm (10 cm over 100 units); the hole is a second element, filled by CSS.
    d = svgwrite.Drawing(size=("10cm", "5cm"), viewBox="0 0 100 50")
    d.defs.add(d.style(".hole { fill: #fff; }"))
    d.add(d.ellipse((50, 25), (40, 20)))
    d.add(d.ellipse((35, 25), (10, 5), class_="hole"))
    a, c = combine([(math.pi * 800.0, 50.0, -25.0), (-math.pi * 50.0, 35.0, -25.0)])
    write("css-ellipse", d, a, c, 1)


def unitless():
    d = svgwrite.Drawing()
    d.attribs.pop("width", None)
    d.attribs.pop("height", None)
    d.add(d.polygon([(0, 0), (30, 0), (0, 20)]))
    write("unitless", d, 300.0, [10.0, -20.0 / 3.0], 0)


if __name__ == "__main__":
    circle_hole()
    rounded_inch()
    evenodd_pt()
    css_ellipse()
    unitless()
