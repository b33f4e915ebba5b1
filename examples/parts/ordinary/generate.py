#!/usr/bin/env python3
"""Writes the ten ordinary parts of examples/parts/ordinary/ (the plan table in docs/plan.md,
"Ordinary parts on the solver's plates").

Python standard library only; run from anywhere: `python3 examples/parts/ordinary/generate.py`.
Real dimensions in mm, y up, as `chladni part` reads them (docs/part.md). Round features are
polygons with a chord error under 0.05 mm. `flips` says whether the part lands on either face
when dropped: a flat stamping or a bar does; a part with a hub, a bent tab or a bead on one face
rests on the other.
"""

import json
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))


def circle(cx, cy, r, start_deg=0.0, end_deg=360.0, n=None):
    """Points of an arc (counter-clockwise from start to end), the end point included unless
    the arc is a full circle."""
    span = end_deg - start_deg
    if n is None:
        # Chord error r(1 - cos(dθ/2)) ≤ 0.05 mm.
        step = 2.0 * math.acos(max(-1.0, 1.0 - 0.05 / r)) if r > 0.05 else math.pi / 2
        n = max(6, int(math.ceil(abs(math.radians(span)) / step)))
    full = abs(abs(span) - 360.0) < 1e-9
    count = n if full else n + 1
    return [
        (cx + r * math.cos(math.radians(start_deg + span * k / n)),
         cy + r * math.sin(math.radians(start_deg + span * k / n)))
        for k in range(count)
    ]


def hole(cx, cy, d):
    """A round hole of diameter d (the reader fixes the winding)."""
    return circle(cx, cy, d / 2.0)


def slot(x0, x1, y, w):
    """A straight slot from x0 to x1 (centres of the end radii) at height y, width w."""
    r = w / 2.0
    return circle(x1, y, r, -90, 90) + circle(x0, y, r, 90, 270)


def hex_key():
    """5 mm hex key (ISO 2936), lying flat: long arm 85 mm, short arm 30 mm, bend radius 5 mm
    inside; the outline seen from above is the bar's 5 mm across-flats width."""
    w, long_arm, short_arm, ri = 5.0, 85.0, 30.0, 5.0
    ro = ri + w
    pts = [(long_arm, 0.0), (long_arm, w)]
    # Inner corner: arc of radius ri centred at (w + ri, w + ri), from the long arm's top
    # edge to the short arm's inner edge.
    pts += circle(w + ri, w + ri, ri, 270, 180)
    pts += [(w, short_arm), (0.0, short_arm)]
    # Outer corner: radius ro centred at the same point, from the short arm's outer edge down
    # to the long arm's bottom edge.
    pts += circle(w + ri, w + ri, ro, 180, 270)
    return {"name": "hex key 5 mm", "outline": dedupe(pts), "flips": True}


def corner_bracket():
    """Flat corner bracket 60 × 40 mm, 15 mm wide, three 5 mm holes (two on the long arm)."""
    outline = [(0, 0), (60, 0), (60, 15), (15, 15), (15, 40), (0, 40)]
    holes = [hole(30, 7.5, 5), hole(50, 7.5, 5), hole(7.5, 30, 5)]
    return {"name": "corner bracket", "outline": outline, "holes": holes, "flips": True}


def slotted_strap():
    """Mending strap 70 × 20 mm, corners rounded 3 mm: a 6 mm hole near one end, a 6 mm wide
    slot 14 mm long near the other, and a 4 mm hole off the centre line."""
    outline = rounded_rect(0, 0, 70, 20, 3)
    holes = [hole(9, 10, 6), slot(48, 62, 10, 6), hole(30, 6, 4)]
    return {"name": "slotted strap", "outline": outline, "holes": holes, "flips": True}


def u_channel():
    """End view of a 10 mm cut of unequal-leg aluminium U-channel: 40 mm wide, legs 30 and
    20 mm, 3 mm walls. It lies on the cut face, so either face."""
    t = 3.0
    outline = [(0, 0), (40, 0), (40, 20), (40 - t, 20), (40 - t, t), (t, t), (t, 30), (0, 30)]
    return {"name": "U-channel", "outline": outline, "flips": True}


def spring_clip():
    """Flat spring clip: a C of outer radius 15 mm, 3 mm wire-width, opening 60° wide, with a
    14 mm straight tail. The tail's end is bent up, so it rests on one face."""
    ro, ri = 15.0, 12.0
    # The C runs from 30° to 330°, the tail leaves tangentially from the 330° end.
    outer = circle(0, 0, ro, 30, 330)
    inner = list(reversed(circle(0, 0, ri, 30, 330)))
    a = math.radians(330)
    tx, ty = math.cos(a + math.pi / 2), math.sin(a + math.pi / 2)  # tangent (CCW)
    end_o = (ro * math.cos(a), ro * math.sin(a))
    end_i = (ri * math.cos(a), ri * math.sin(a))
    tail = [
        (end_o[0] + 14 * tx, end_o[1] + 14 * ty),
        (end_i[0] + 14 * tx, end_i[1] + 14 * ty),
    ]
    pts = outer + tail + inner
    return {"name": "spring clip", "outline": dedupe(pts), "flips": False}


def house_key():
    """Cylinder-lock key: a 24 mm round bow with a 4 mm ring hole, a 28 mm blade 8 mm wide,
    five cuts on one edge."""
    bow = circle(12, 0, 12, 20, 340)
    # The blade leaves the bow at x = 23.3; tip at x = 55.
    cuts = [(27, 0.0), (31, 1.5), (35, 0.5), (39, 2.5), (43, 1.0), (47, 2.0)]
    top = 4.0
    pts = list(bow)
    pts += [(23.5, -top), (51, -top), (55, -1.5)]
    # Bitting along the bottom edge, from the tip back to the bow (depth into the blade).
    pts += [(55, top - 1.0)]
    for x, depth in reversed(cuts):
        pts += [(x + 2, top - depth), (x, top - depth)]
    pts += [(23.5, top)]
    holes = [hole(6, 0, 4)]
    return {"name": "house key", "outline": dedupe(pts), "holes": holes, "flips": True}


def keyed_gear():
    """Spur gear, 12 teeth, module 3 (tip radius 19.5, root 14.25 mm), 10 mm bore with a
    3 × 1.5 mm keyway. The hub stands 4 mm proud on one face, so it rests on the other."""
    z, tip, root = 12, 19.5, 14.25
    pitch = 360.0 / z
    pts = []
    for k in range(z):
        c = k * pitch
        # Root land, flank, tip land, flank (straight-flank approximation of the involute).
        pts += circle(0, 0, root, c - 0.5 * pitch, c - 0.25 * pitch, n=3)[:-1]
        pts += circle(0, 0, tip, c - 0.12 * pitch, c + 0.12 * pitch, n=3)
        pts += circle(0, 0, root, c + 0.25 * pitch, c + 0.5 * pitch, n=3)[1:-1]
    # Bore with a keyway at +y.
    r, kw, kd = 5.0, 3.0, 1.5
    half = math.degrees(math.asin(kw / 2 / r))
    bore = circle(0, 0, r, 90 + half, 450 - half)
    bore += [(kw / 2, math.sqrt(r * r - kw * kw / 4)), (kw / 2, r + kd), (-kw / 2, r + kd),
             (-kw / 2, math.sqrt(r * r - kw * kw / 4))]
    return {"name": "gear with keyed bore", "outline": dedupe(pts), "holes": [dedupe(bore)],
            "flips": False}


def tee_plate():
    """Flat T plate: bar 60 × 15 mm, stem 35 mm long 15 mm wide, 22 mm from the left end;
    four 6 mm holes."""
    outline = [(0, 35), (22, 35), (22, 0), (37, 0), (37, 35), (60, 35), (60, 50), (0, 50)]
    holes = [hole(8, 42.5, 6), hole(52, 42.5, 6), hole(29.5, 42.5, 6), hole(29.5, 10, 6)]
    return {"name": "tee plate", "outline": outline, "holes": holes, "flips": True}


def lever():
    """Crank lever: 50 mm between a 20 mm boss (8 mm bore) and a 12 mm end (5 mm bore),
    tapered web; a bead pressed into one face, so it rests on the other."""
    # CCW: the small end's half circle, the web's top edge, the boss's half circle, the
    # web's bottom edge (the closing segment).
    small = circle(50, 0, 6, -90, 90)
    big = circle(0, 0, 10, 90, 270)
    return {"name": "crank lever", "outline": dedupe(small + big),
            "holes": [hole(0, 0, 8), hole(50, 0, 5)], "flips": False}


def gusset():
    """Right-triangle gusset 50 × 35 mm with a 10 mm chamfer at the right angle's far corner
    and three 5 mm holes."""
    outline = [(0, 0), (50, 0), (50, 8), (8, 35), (0, 35)]
    holes = [hole(8, 8, 5), hole(34, 7, 5), hole(7, 25, 5)]
    return {"name": "gusset", "outline": outline, "holes": holes, "flips": True}


def rounded_rect(x0, y0, x1, y1, r):
    """A rectangle with corners rounded to r (CCW)."""
    return (circle(x1 - r, y0 + r, r, -90, 0) + circle(x1 - r, y1 - r, r, 0, 90)
            + circle(x0 + r, y1 - r, r, 90, 180) + circle(x0 + r, y0 + r, r, 180, 270))


def dedupe(pts):
    """Drops consecutive duplicate points (and a closing repeat of the first)."""
    out = []
    for p in pts:
        if not out or math.dist(out[-1], p) > 1e-6:
            out.append(p)
    if len(out) > 1 and math.dist(out[0], out[-1]) < 1e-6:
        out.pop()
    return out


def rounded(ring):
    return [[round(x, 3), round(y, 3)] for x, y in ring]


PARTS = {
    "hex-key.json": hex_key,
    "corner-bracket.json": corner_bracket,
    "slotted-strap.json": slotted_strap,
    "u-channel.json": u_channel,
    "spring-clip.json": spring_clip,
    "house-key.json": house_key,
    "keyed-gear.json": keyed_gear,
    "tee-plate.json": tee_plate,
    "crank-lever.json": lever,
    "gusset.json": gusset,
}


def main():
    for name, make in PARTS.items():
        p = make()
        out = {"name": p["name"], "outline": rounded(p["outline"])}
        if p.get("holes"):
            out["holes"] = [rounded(h) for h in p["holes"]]
        out["flips"] = p["flips"]
        with open(os.path.join(HERE, name), "w", encoding="utf-8") as f:
            json.dump(out, f, separators=(",", ":"))
            f.write("\n")


if __name__ == "__main__":
    main()
