#!/usr/bin/env python3
"""Reference figures for FlareLab's toroidal (anamorphic) surfaces, by an independent tracer written for this purpose.

It shares no code with FlareLab (Rust) and no formula for the toroid: plain Python with mpmath at 50 significant
digits, the toroid written as the implicit surface

    G(x, y, z) = 2 (z_y(y) - z) + c_x (z^2 + x^2 - z_y(y)^2) = 0,

Zemax's TOROIDAL (the y-z profile z_y(y) = c y^2 / (1 + sqrt(1 - (1 + k) c^2 y^2)) + A4 y^4 + ... swept about an
axis parallel to y at the radius of rotation R = 1 / c_x from the vertex: (R - z)^2 + x^2 = (R - z_y)^2 divided
by R), met by Newton's method on G along the ray from the vertex plane, on the vertex side (1 - c_x z > 0), its
normal the gradient of G. Spheres and planes: the whole sphere, the root on the vertex side for the direction of
travel (the convention of ../README.md). Refraction by Snell's law in vector form, reflection by the mirror
formula, indices nd (the d-line). Rays start at explicit points with explicit directions (no pupil), follow the
image path or a ghost (i, j) (path [0..j, j-1..i, i+1..N-1]) and end on the sensor plane, which sits half way
between the paraxial foci of the x-z and the y-z sections, found by this script's own paraxial trace of each
section (y-nu, vertex curvatures of that section). Clear apertures are reported; a ray that passes outside a
toroid's clear aperture is not compared (`beyond`): the surface is not the lens there.

Run from this folder: python3 make_reference.py  (needs mpmath; writes toroidal_test_lens_reference.json).
"""
import json
import os

import mpmath as mp

mp.mp.dps = 50
HERE = os.path.dirname(os.path.abspath(__file__))
LENS = os.path.join(HERE, "toroidal_test_lens.json")
OUT = os.path.join(HERE, "toroidal_test_lens_reference.json")


def num(v):
    return mp.mpf(repr(float(v)))


class Surf:
    def __init__(self, s):
        r = s.get("radius") or 0
        self.c = mp.mpf(0) if r == 0 else 1 / num(r)
        self.k = num(s.get("conic", 0.0))
        self.terms = [num(a) for a in s.get("aspheric", [])]
        self.toroid = "radius_x" in s
        rx = s.get("radius_x") or 0
        self.cx = mp.mpf(0) if rx == 0 else 1 / num(rx)
        self.semi = num(s["semi_aperture"])
        self.t = num(s.get("thickness") or 0.0)
        self.n = num(s["nd"])
        self.stop = s.get("stop", False)
        self.sphere = not self.toroid and self.k == 0 and not any(self.terms)

    def zy(self, y):
        """The y-z profile and its derivative."""
        y2 = y * y
        root = 1 - (1 + self.k) * self.c ** 2 * y2
        if root <= 0:
            return None
        z = self.c * y2 / (1 + mp.sqrt(root))
        dz = self.c * y / mp.sqrt(root)
        for i, a in enumerate(self.terms):
            z += a * y ** (2 * i + 4)
            dz += (2 * i + 4) * a * y ** (2 * i + 3)
        return z, dz

    def g(self, x, y, z):
        """G and its gradient."""
        zy = self.zy(y)
        if zy is None:
            return None
        zy, dzy = zy
        val = 2 * (zy - z) + self.cx * (z * z + x * x - zy * zy)
        grad = [2 * self.cx * x, 2 * dzy * (1 - self.cx * zy), 2 * (self.cx * z - 1)]
        return val, grad


def intersect(s, p, d, travel):
    if s.sphere:
        if s.c == 0:
            return -p[2] / d[2] if d[2] != 0 else None
        # c |p + t d|^2 - 2 (p_z + t d_z) = 0
        a = s.c
        b = s.c * sum(p[i] * d[i] for i in range(3)) - d[2]
        g0 = s.c * sum(v * v for v in p) - 2 * p[2]
        disc = b * b - a * g0
        if disc < 0:
            return None
        return (-b - travel * mp.sqrt(disc)) / a
    if d[2] == 0:
        return None
    t = -p[2] / d[2]
    for _ in range(200):
        x = [p[i] + t * d[i] for i in range(3)]
        r = s.g(*x)
        if r is None:
            return None
        val, grad = r
        dg = sum(grad[i] * d[i] for i in range(3))
        if dg == 0:
            return None
        step = val / dg
        t -= step
        if abs(step) < mp.mpf("1e-40"):
            x = [p[i] + t * d[i] for i in range(3)]
            return t if 1 - s.cx * x[2] > 0 else None
    return None


def normal(s, x):
    if s.sphere:
        v = [-s.c * x[0], -s.c * x[1], 1 - s.c * x[2]]
    else:
        r = s.g(*x)
        if r is None:
            return None
        v = [-g for g in r[1]]
    L = mp.sqrt(sum(c * c for c in v))
    return [c / L for c in v]


def load():
    raw = json.load(open(LENS))
    surfaces = [Surf(s) for s in raw["surfaces"]]
    z, acc = [], mp.mpf(0)
    for s in surfaces:
        z.append(acc)
        acc += s.t
    return {"surfaces": surfaces, "z": z}


def media(lens):
    return [mp.mpf(1)] + [s.n for s in lens["surfaces"]]


def steps_of(lens, path):
    n = media(lens)
    N = len(lens["surfaces"])
    if path == "image":
        return [(k, "refract", 1, n[k], n[k + 1]) for k in range(N)]
    i, j = path
    st = [(k, "refract", 1, n[k], n[k + 1]) for k in range(j)]
    st.append((j, "reflect", 1, n[j], n[j]))
    st += [(k, "refract", -1, n[k + 1], n[k]) for k in range(j - 1, i, -1)]
    st.append((i, "reflect", -1, n[i + 1], n[i + 1]))
    st += [(k, "refract", 1, n[k], n[k + 1]) for k in range(i + 1, N)]
    return st


def trace(lens, steps, sensor_z, start, direction):
    p = [num(v) for v in start]
    d = [num(v) for v in direction]
    L = mp.sqrt(sum(c * c for c in d))
    d = [c / L for c in d]
    clipped = []
    for k, kind, travel, n1, n2 in steps:
        s = lens["surfaces"][k]
        zk = lens["z"][k]
        t = intersect(s, [p[0], p[1], p[2] - zk], d, travel)
        if t is None:
            return {"status": "missed", "surface": k, "clipped_at": clipped}
        p = [p[i] + t * d[i] for i in range(3)]
        nrm = normal(s, [p[0], p[1], p[2] - zk])
        if nrm is None:
            return {"status": "missed", "surface": k, "clipped_at": clipped}
        if mp.sqrt(p[0] ** 2 + p[1] ** 2) > s.semi:
            clipped.append(k)
            if not s.sphere:
                return {"status": "beyond", "surface": k, "clipped_at": clipped}
        cos_i = sum(d[i] * nrm[i] for i in range(3))
        if kind == "reflect":
            d = [d[i] - 2 * cos_i * nrm[i] for i in range(3)]
        elif n1 != n2:
            eta = n1 / n2
            root = 1 - eta ** 2 * (1 - cos_i ** 2)
            if root < 0:
                return {"status": "tir", "surface": k, "clipped_at": clipped}
            cos_t = mp.sqrt(root) * (1 if cos_i >= 0 else -1)
            d = [eta * d[i] + (cos_t - eta * cos_i) * nrm[i] for i in range(3)]
    if d[2] <= 0:
        return {"status": "backward", "clipped_at": clipped}
    t = (sensor_z - p[2]) / d[2]
    q = [p[i] + t * d[i] for i in range(3)]
    return {"status": "ok", "point_mm": [float(v) for v in q], "direction": [float(v) for v in d],
            "clipped_at": clipped}


def section_focus(lens, section):
    """Paraxial y-nu trace of a ray parallel to the axis in one section: EFL and focus z (from the first vertex)."""
    n = media(lens)
    y, nu = mp.mpf(1), mp.mpf(0)
    surfaces = lens["surfaces"]
    for k, s in enumerate(surfaces):
        if section == "x" and s.toroid:
            c = s.cx
        else:
            c = s.c  # the conic and the r^4.. terms do not act near the axis
        nu = nu - y * (n[k + 1] - n[k]) * c
        if k + 1 < len(surfaces):
            y = y + s.t * nu / n[k + 1]
    efl = -1 / nu  # image space is air
    bfd = -y / nu
    return efl, lens["z"][-1] + bfd


def ghost_ellipse(lens, path, section):
    """The stop's image through a ghost path in one section, from this script's own paraxial trace: heights y and
    slopes u = dy/dz measured along +z whatever the direction of travel, so that a translation is y += (z' - z) u
    (signed), a refraction n2 u' = n1 u - (n2 - n1) c y and a reflection u' = -u - 2 c y (c the section's vertex
    curvature). Returns (centre per unit slope, semi-axis) on the sensor: the ray through the stop's centre at its
    first crossing, and the ray through its rim."""
    surfaces = lens["surfaces"]
    stop = next(k for k, s in enumerate(surfaces) if s.stop)

    def run(y0, u0):
        y, u, z = y0, u0, mp.mpf(0)
        at_stop = None
        for k, kind, travel, n1, n2 in steps_of(lens, path):
            s = surfaces[k]
            y = y + (lens["z"][k] - z) * u
            z = lens["z"][k]
            c = s.cx if (section == "x" and s.toroid) else s.c
            if kind == "reflect":
                u = -u - 2 * c * y
            else:
                u = (n1 * u - (n2 - n1) * c * y) / n2
            if k == stop and at_stop is None:
                at_stop = y
        return y + (lens["sensor_z"] - z) * u, at_stop

    # Heights are linear in (y0, u): read the matrices off unit rays.
    f_a, a_a = run(mp.mpf(1), mp.mpf(0))
    f_b, a_b = run(mp.mpf(0), mp.mpf(1))
    k = f_b - f_a * a_b / a_a
    return k, abs(f_a / a_a) * surfaces[stop].semi


def main():
    lens = load()
    N = len(lens["surfaces"])
    efl_x, focus_x = section_focus(lens, "x")
    efl_y, focus_y = section_focus(lens, "y")
    sensor_z = (focus_x + focus_y) / 2
    lens["sensor_z"] = sensor_z
    starts = [(0.0, 0.0), (3.0, 0.0), (0.0, 3.0), (-4.0, 2.5), (5.5, -5.0), (2.0, 7.0), (-7.5, -1.5), (6.0, 6.0)]
    dirs = [(0.0, 0.0, 1.0), (0.08, 0.0, 1.0), (0.0, -0.1, 1.0), (0.05, 0.12, 1.0), (-0.15, 0.07, 1.0)]
    rays = []
    reflecting = [k for k in range(N) if media(lens)[k] != media(lens)[k + 1]]
    paths = ["image"] + [[i, j] for a, i in enumerate(reflecting) for j in reflecting[a + 1:]]
    for path in paths:
        steps = steps_of(lens, path)
        chosen = [(s, d) for s in starts for d in dirs] if path == "image" else \
            [(starts[(m * 3 + len(rays)) % len(starts)], dirs[m % len(dirs)]) for m in range(8)]
        for (x, y), d in chosen:
            start = [x, y, -15.0]
            r = trace(lens, steps, sensor_z, start, d)
            r.update({"path": path, "start_mm": start, "dir": list(d)})
            rays.append(r)
    ellipses = []
    for path in paths[1:]:
        e = {"i": path[0], "j": path[1]}
        for section in ("x", "y"):
            k, r = ghost_ellipse(lens, path, section)
            e[section] = {"centre_per_slope": float(k), "semi_axis_mm": float(r)}
        ellipses.append(e)
    out = {
        "ghost_ellipses": ellipses,
        "about": "made by make_reference.py (mpmath, 50 digits, implicit toroid); see its docstring",
        "lens": "toroidal_test_lens.json",
        "wavelength_nm": 587.5618,
        "sections": {"x": {"efl_mm": float(efl_x), "focus_z_mm": float(focus_x)},
                     "y": {"efl_mm": float(efl_y), "focus_z_mm": float(focus_y)}},
        "sensor_z_mm": float(sensor_z),
        "rays": rays,
    }
    with open(OUT, "w") as f:
        json.dump(out, f, indent=1)
    counts = {}
    for r in rays:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    print(len(rays), "rays", counts, "sensor", float(sensor_z))


main()
