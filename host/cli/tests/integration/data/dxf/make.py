#!/usr/bin/env python3
"""Writes the DXF test parts of host/cli/tests/integration/dxf_import.rs with ezdxf, a real CAD library.

The generated .dxf files (and the JSON twin of the arc part) are committed, so the tests and
CI need no Python; run this again (pip install ezdxf) only to change them:

    python3 host/cli/tests/integration/data/dxf/make.py

Each file tests one thing of `Part::load` for DXF (docs/analyze.md, "DXF parts"):
  rectangle.dxf   closed LWPOLYLINE, mm               twin examples/parts/rectangle.json
  l-shape.dxf     six LINEs, shuffled and some reversed, unitless ($INSUNITS 0)
                                                      twin examples/parts/l-shape.json
  hole-arc.dxf    LWPOLYLINE with a bulge (semicircular top edge) and a CIRCLE hole
                                                      twin hole-arc.json (arcs at 1024 chords)
  arc-chain.dxf   the same outline as LINE + ARC entities, the hole as a CIRCLE (twin hole-arc.json)
  inch.dxf        closed LWPOLYLINE 1.6 x 0.4 in ($INSUNITS 1): 40.64 x 10.16 mm
  layers.dxf      layer PART: the rectangle; layer FIXTURE: a 100 x 80 frame elsewhere
  open.dxf        LINE chain with a 2 mm gap                  (error: open chain)
  spline.dxf      a closed SPLINE                             (error: spline)
  disjoint.dxf    two closed LWPOLYLINEs apart                (error: separate outlines)
  miles.dxf       the rectangle in miles ($INSUNITS 3)        (error: unsupported units)
  cad-dims.dxf    hole-arc's part on layer PART (LWPOLYLINE + CIRCLE) as CAD exports it: linear
                  and radial DIMENSIONs on DIMS, centre lines (LINEs) on CENTER, TEXT and MTEXT
                  on NOTES, a HATCH of the part on HATCH    (twin hole-arc.json; one note)
  cad-title.dxf   cad-dims plus an A4 title block (frame and cells, LINEs) on layer TITLE
                                                      (error without --layer; --layer PART: twin)
  block.dxf       the part as a block (its entities on layer "0"), inserted on layer PART turned
                  by 30 degrees at (100, 50) (twin hole-arc.json, turned: same area), and a
                  second INSERT at scale 2 on layer BIG    (--layer BIG: 4x the area)
"""

import json
import math
import os

import ezdxf

HERE = os.path.dirname(os.path.abspath(__file__))
MM, INCH, MILES, UNITLESS = 4, 1, 3, 0


def new(units):
    doc = ezdxf.new("R2010")
    doc.header["$INSUNITS"] = units
    return doc, doc.modelspace()


def save(doc, name):
    doc.saveas(os.path.join(HERE, name))


def rectangle():
    doc, msp = new(MM)
    msp.add_lwpolyline([(0, 0), (40, 0), (40, 10), (0, 10)], close=True)
    save(doc, "rectangle.dxf")


def l_shape():
    doc, msp = new(UNITLESS)
    pts = [(0, 0), (40, 0), (40, 12), (12, 12), (12, 30), (0, 30)]
    edges = [(pts[i], pts[(i + 1) % 6]) for i in range(6)]
    # Out of order, every other edge reversed: the importer must join them end to end.
    for k in [3, 0, 5, 1, 4, 2]:
        a, b = edges[k]
        msp.add_line(b, a) if k % 2 else msp.add_line(a, b)
    save(doc, "l-shape.dxf")


# The arc part: 50 x 20 rectangle with a semicircular top (centre (25, 20), r 25), and a
# circular hole of radius 6 at (25, 18).
HOLE_C, HOLE_R = (25.0, 18.0), 6.0


def hole_arc():
    doc, msp = new(MM)
    # Bulge 1 = a half circle, counter-clockwise from (50, 20) to (0, 20).
    msp.add_lwpolyline(
        [(0, 0, 0, 0, 0), (50, 0, 0, 0, 0), (50, 20, 0, 0, 1.0), (0, 20, 0, 0, 0)],
        format="xyseb",
        close=True,
    )
    msp.add_circle(HOLE_C, HOLE_R)
    save(doc, "hole-arc.dxf")


def arc_chain():
    doc, msp = new(MM)
    msp.add_line((0, 20), (0, 0))
    msp.add_arc((25, 20), 25, 0, 180)
    msp.add_line((50, 0), (50, 20))
    msp.add_line((0, 0), (50, 0))
    msp.add_circle(HOLE_C, HOLE_R)
    save(doc, "arc-chain.dxf")


def hole_arc_twin():
    n = 1024
    top = [(25 + 25 * math.cos(math.pi * k / n), 20 + 25 * math.sin(math.pi * k / n))
           for k in range(1, n)]
    outline = [(0, 0), (50, 0), (50, 20)] + top + [(0, 20)]
    hole = [(HOLE_C[0] + HOLE_R * math.cos(2 * math.pi * k / n),
             HOLE_C[1] + HOLE_R * math.sin(2 * math.pi * k / n)) for k in range(n)]
    r = lambda ring: [[round(x, 6), round(y, 6)] for x, y in ring]
    with open(os.path.join(HERE, "hole-arc.json"), "w") as f:
        json.dump({"name": "hole-arc", "outline": r(outline), "holes": [r(hole)]}, f)
        f.write("\n")


def inch():
    doc, msp = new(INCH)
    msp.add_lwpolyline([(0, 0), (1.6, 0), (1.6, 0.4), (0, 0.4)], close=True)
    save(doc, "inch.dxf")


def layers():
    doc, msp = new(MM)
    doc.layers.add("PART")
    doc.layers.add("FIXTURE")
    msp.add_lwpolyline([(0, 0), (40, 0), (40, 10), (0, 10)], close=True,
                       dxfattribs={"layer": "PART"})
    msp.add_lwpolyline([(100, 0), (200, 0), (200, 80), (100, 80)], close=True,
                       dxfattribs={"layer": "FIXTURE"})
    save(doc, "layers.dxf")


def open_chain():
    doc, msp = new(MM)
    msp.add_line((0, 0), (40, 0))
    msp.add_line((40, 0), (40, 10))
    msp.add_line((40, 10), (0, 10))
    msp.add_line((0, 10), (0, 2))  # 2 mm short of (0, 0)
    save(doc, "open.dxf")


def spline():
    doc, msp = new(MM)
    msp.add_spline([(0, 0), (20, 5), (40, 0), (20, 20)]).closed = True
    save(doc, "spline.dxf")


def disjoint():
    doc, msp = new(MM)
    msp.add_lwpolyline([(0, 0), (40, 0), (40, 10), (0, 10)], close=True)
    msp.add_lwpolyline([(60, 0), (80, 0), (80, 10), (60, 10)], close=True)
    save(doc, "disjoint.dxf")


def miles():
    doc, msp = new(MILES)
    msp.add_lwpolyline([(0, 0), (40, 0), (40, 10), (0, 10)], close=True)
    save(doc, "miles.dxf")


def part_on(msp, layer):
    """hole-arc's part on one layer."""
    msp.add_lwpolyline(
        [(0, 0, 0, 0, 0), (50, 0, 0, 0, 0), (50, 20, 0, 0, 1.0), (0, 20, 0, 0, 0)],
        format="xyseb", close=True, dxfattribs={"layer": layer})
    msp.add_circle(HOLE_C, HOLE_R, dxfattribs={"layer": layer})


def annotate(doc, msp):
    for name in ["PART", "DIMS", "CENTER", "NOTES", "HATCH"]:
        doc.layers.add(name)
    part_on(msp, "PART")
    msp.add_linear_dim(base=(25, -10), p1=(0, 0), p2=(50, 0),
                       dxfattribs={"layer": "DIMS"}).render()
    msp.add_linear_dim(base=(60, 10), p1=(50, 0), p2=(50, 20), angle=90,
                       dxfattribs={"layer": "DIMS"}).render()
    msp.add_radius_dim(center=HOLE_C, radius=HOLE_R, angle=45,
                       dxfattribs={"layer": "DIMS"}).render()
    for a, b in [((25, -5), (25, 50)), ((-5, 18), (55, 18))]:
        msp.add_line(a, b, dxfattribs={"layer": "CENTER", "linetype": "CENTER"})
    msp.add_text("PART 7", dxfattribs={"layer": "NOTES", "height": 3}).set_placement((0, 55))
    msp.add_mtext("material: steel\\Pthickness 2 mm", dxfattribs={"layer": "NOTES"}).set_location((0, 65))
    hatch = msp.add_hatch(dxfattribs={"layer": "HATCH"})
    hatch.paths.add_polyline_path([(0, 0), (50, 0), (50, 20), (0, 20)], is_closed=True)


def cad_dims():
    doc, msp = new(MM)
    annotate(doc, msp)
    save(doc, "cad-dims.dxf")


def cad_title():
    doc, msp = new(MM)
    annotate(doc, msp)
    doc.layers.add("TITLE")
    t = {"layer": "TITLE"}
    # A4 landscape frame around the part, and a title block of four cells at its lower right.
    x0, y0, x1, y1 = -40, -60, 257, 150
    for a, b in [((x0, y0), (x1, y0)), ((x1, y0), (x1, y1)), ((x1, y1), (x0, y1)),
                 ((x0, y1), (x0, y0))]:
        msp.add_line(a, b, dxfattribs=t)
    bx, by = 157, -60
    for a, b in [((bx, by), (bx, by + 30)), ((bx, by + 30), (x1, by + 30)),
                 ((bx, by + 15), (x1, by + 15)), ((bx + 50, by), (bx + 50, by + 30))]:
        msp.add_line(a, b, dxfattribs=t)
    msp.add_text("CHLADNI TEST PART", dxfattribs={"layer": "TITLE", "height": 4}).set_placement((bx + 2, by + 20))
    save(doc, "cad-title.dxf")


def block():
    doc, msp = new(MM)
    doc.layers.add("PART")
    doc.layers.add("BIG")
    blk = doc.blocks.new(name="HOLEARC", base_point=(25, 10))
    part_on(blk, "0")
    msp.add_blockref("HOLEARC", (100, 50), dxfattribs={"layer": "PART", "rotation": 30})
    msp.add_blockref("HOLEARC", (300, 50), dxfattribs={"layer": "BIG", "xscale": 2, "yscale": 2})
    save(doc, "block.dxf")


if __name__ == "__main__":
    for make in [rectangle, l_shape, hole_arc, arc_chain, hole_arc_twin, inch, layers,
                 open_chain, spline, disjoint, miles, cad_dims, cad_title, block]:
        make()
