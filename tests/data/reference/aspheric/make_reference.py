#!/usr/bin/env python3
"""Reference figures for FlareLab's aspheric lenses, by an independent tracer written for this purpose.

It shares no code with FlareLab (Rust): plain Python with mpmath at 40 significant digits. Each surface is
z = c r^2 / (1 + sqrt(1 - (1 + k) c^2 r^2)) + A2 r^2 + A4 r^4 + ... ; a ray meets it at a root of the conic
(quadric) c (x^2 + y^2 + (1 + k) z^2) - 2 z = 0 that lies on the sag branch (the nearer along the travel
when both do; a plain sphere is a whole sphere, the root on the vertex side for the travel, as in
../README.md), then Newton's method on z(t) - sag(r(t)) refines it to 1e-30 mm for the polynomial terms.
Refraction by Snell's law in vector form with the normal from the gradient of z - sag(r); reflection by
the mirror formula. Conventions as in ../README.md (pupil rays, sensor at the paraxial focus, ghosts (i, j)
with the path [0..j, j-1..i, i+1..N-1], clear apertures reported but not applied). A ray that passes outside
an aspheric surface's clear aperture is not traced on (`beyond_asphere`): the polynomial is not the lens
there, and a line may meet it several times.

Run from this folder: python3 make_reference.py  (needs mpmath; writes <lens id>.json next to it).
"""
import json
import os
import sys

import mpmath as mp

mp.mp.dps = 40
HERE = os.path.dirname(os.path.abspath(__file__))
LENSES = os.path.join(HERE, "..", "..", "..", "..", "lenses")
IDS = ["zeiss_master_prime_us5537259", "aspheric_zoom_us5793533"]
RAY_THETAS = [0.0, 5.0, 10.0, 15.0]
RAY_PUPIL = [(0.0, 0.0), (0.0, 0.5), (0.0, 1.0), (0.0, -0.5), (0.0, -1.0), (0.5, 0.5), (0.7, -0.3)]
GHOST_THETAS = [0.0, 5.0, 12.0]
FAN = [-0.6, -0.3, 0.0, 0.3, 0.6]


class Surf:
    def __init__(self, s):
        r = s.get("radius") or 0
        self.c = mp.mpf(0) if r == 0 else 1 / mp.mpf(repr(r))
        self.k = mp.mpf(repr(s.get("conic", 0.0)))
        self.a2 = mp.mpf(repr(s.get("aspheric_r2", 0.0)))
        self.terms = [mp.mpf(repr(a)) for a in s.get("aspheric", [])]
        self.semi = mp.mpf(repr(s["semi_aperture"]))
        self.t = mp.mpf(repr(s["thickness"] or 0.0))
        self.n = mp.mpf(repr(s["nd"]))
        self.stop = s.get("stop", False)

    def sag(self, r2):
        root = 1 - (1 + self.k) * self.c ** 2 * r2
        if root < 0:
            return None
        z = self.c * r2 / (1 + mp.sqrt(root)) + self.a2 * r2
        for i, a in enumerate(self.terms):
            z += a * r2 ** (i + 2)
        return z

    def dsag_dr_over_r(self, r2):
        root = 1 - (1 + self.k) * self.c ** 2 * r2
        if root <= 0:
            return None
        v = self.c / mp.sqrt(root) + 2 * self.a2
        for i, a in enumerate(self.terms):
            v += (2 * i + 4) * a * r2 ** (i + 1)
        return v


def intersect(s, p, d, travel):
    """Distance along d from p (relative to the vertex) to the surface, or None."""
    q = 1 + s.k
    g0 = s.c * (p[0] ** 2 + p[1] ** 2 + q * p[2] ** 2) - 2 * p[2]
    a = s.c * (d[0] ** 2 + d[1] ** 2 + q * d[2] ** 2)
    b = s.c * (p[0] * d[0] + p[1] * d[1] + q * p[2] * d[2]) - d[2]
    roots = []
    if a == 0:
        if b != 0:
            roots = [-g0 / (2 * b)]
    else:
        disc = b * b - a * g0
        if disc >= 0:
            roots = [(-b - mp.sqrt(disc)) / a, (-b + mp.sqrt(disc)) / a]
    if s.k == 0 and s.a2 == 0 and not any(s.terms):
        # A sphere is a whole sphere (the convention of ../README.md): the root on the vertex side for the
        # travel direction, t = (-b - travel sqrt(disc)) / c, even off the hemisphere the sag describes.
        if s.c == 0:
            # A plane is met only by a ray travelling the path's way along z.
            return -p[2] / d[2] if d[2] * travel > 0 else None
        disc = b * b - a * g0
        return None if disc < 0 else (-b - travel * mp.sqrt(disc)) / a
    on_branch = []
    for t in roots:
        x = [p[i] + t * d[i] for i in range(3)]
        conic_only = Surf.__new__(Surf)
        conic_only.c, conic_only.k, conic_only.a2, conic_only.terms = s.c, s.k, mp.mpf(0), []
        sg = conic_only.sag(x[0] ** 2 + x[1] ** 2)
        if sg is not None and abs(x[2] - sg) < mp.mpf("1e-25") * (1 + abs(x[2])):
            on_branch.append(t)
    if on_branch:
        # Along the travel, the first on-branch crossing in the direction of travel along z.
        t = min(on_branch, key=lambda t: travel * (p[2] + t * d[2])) if len(on_branch) > 1 else on_branch[0]
    elif d[2] != 0:
        t = -p[2] / d[2]
    else:
        return None
    if s.a2 == 0 and not any(s.terms):
        return t
    for _ in range(200):
        x = [p[i] + t * d[i] for i in range(3)]
        r2 = x[0] ** 2 + x[1] ** 2
        sg = s.sag(r2)
        m = s.dsag_dr_over_r(r2)
        if sg is None or m is None:
            return None
        f = x[2] - sg
        df = d[2] - m * (x[0] * d[0] + x[1] * d[1])
        if df == 0:
            return None
        step = f / df
        t -= step
        if abs(step) < mp.mpf("1e-32"):
            return t
    return None


def normal(s, x):
    if s.k == 0 and s.a2 == 0 and not any(s.terms):
        # A whole sphere: the gradient of c |x|^2 - 2 z, right on either hemisphere.
        v = [-s.c * x[0], -s.c * x[1], 1 - s.c * x[2]]
        L = mp.sqrt(sum(c * c for c in v))
        return [c / L for c in v]
    r2 = x[0] ** 2 + x[1] ** 2
    m = s.dsag_dr_over_r(r2)
    if m is None:
        return None
    v = [-m * x[0], -m * x[1], mp.mpf(1)]
    L = mp.sqrt(sum(c * c for c in v))
    return [c / L for c in v]


def trace(lens, steps, sensor_z, theta_deg, px, py, pupil):
    """steps: list of (surface, 'refract'|'reflect', travel, n_in, n_out). Returns (landing or None, fail, clipped)."""
    th = mp.radians(mp.mpf(repr(theta_deg)))
    p = [mp.mpf(repr(px)) * pupil[1], mp.mpf(repr(py)) * pupil[1], pupil[0]]
    d = [mp.mpf(0), mp.sin(th), mp.cos(th)]
    z_v = lens["z"]
    clipped = []
    for k, kind, travel, n1, n2 in steps:
        s = lens["surfaces"][k]
        local = [p[0], p[1], p[2] - z_v[k]]
        t = intersect(s, local, d, travel)
        if t is None:
            return None, "miss@%d" % k, clipped
        p = [p[i] + t * d[i] for i in range(3)]
        nrm = normal(s, [p[0], p[1], p[2] - z_v[k]])
        if nrm is None:
            return None, "miss@%d" % k, clipped
        if mp.sqrt(p[0] ** 2 + p[1] ** 2) > s.semi:
            clipped.append(k)
            if not (s.k == 0 and s.a2 == 0 and not any(s.terms)):
                # Beyond an asphere's clear aperture its polynomial is an extrapolation that a line may meet
                # several times: no tracer's answer there is the answer, so such rays are not compared.
                return None, "beyond@%d" % k, clipped
        cos_i = sum(d[i] * nrm[i] for i in range(3))
        if kind == "reflect":
            d = [d[i] - 2 * cos_i * nrm[i] for i in range(3)]
        elif n1 != n2:
            eta = n1 / n2
            root = 1 - eta ** 2 * (1 - cos_i ** 2)
            if root < 0:
                return None, "tir@%d" % k, clipped
            cos_t = mp.sqrt(root) * (1 if cos_i >= 0 else -1)
            d = [eta * d[i] + (cos_t - eta * cos_i) * nrm[i] for i in range(3)]
    if d[2] <= 0:
        return None, "backward@sensor", clipped
    t = (sensor_z - p[2]) / d[2]
    return (p[0] + t * d[0], p[1] + t * d[1]), None, clipped


def media(lens):
    return [mp.mpf(1)] + [s.n for s in lens["surfaces"]]


def image_steps(lens):
    n = media(lens)
    return [(k, "refract", 1, n[k], n[k + 1]) for k in range(len(lens["surfaces"]))]


def ghost_steps(lens, i, j):
    n = media(lens)
    N = len(lens["surfaces"])
    st = [(k, "refract", 1, n[k], n[k + 1]) for k in range(j)]
    st.append((j, "reflect", 1, n[j], n[j]))
    st += [(k, "refract", -1, n[k + 1], n[k]) for k in range(j - 1, i, -1)]
    st.append((i, "reflect", -1, n[i + 1], n[i + 1]))
    st += [(k, "refract", 1, n[k], n[k + 1]) for k in range(i + 1, N)]
    return st


def matmul(a, b):
    return [[a[0][0] * b[0][0] + a[0][1] * b[1][0], a[0][0] * b[0][1] + a[0][1] * b[1][1]],
            [a[1][0] * b[0][0] + a[1][1] * b[1][0], a[1][0] * b[0][1] + a[1][1] * b[1][1]]]


def paraxial(lens, steps, end_z, stop=None):
    """Matrix on (y, n u) from the plane z = 0 to end_z; also the product up to the stop's interaction."""
    m = [[mp.mpf(1), mp.mpf(0)], [mp.mpf(0), mp.mpf(1)]]
    z_now = mp.mpf(0)
    at_stop = None
    for k, kind, travel, n1, n2 in steps:
        s = lens["surfaces"][k]
        zk = lens["z"][k]
        n_here = n1
        m = matmul([[1, abs(zk - z_now) / n_here], [0, 1]], m)
        c = s.c + 2 * s.a2
        if kind == "reflect":
            m = matmul([[1, 0], [2 * travel * n1 * c, 1]], m)
        else:
            m = matmul([[1, 0], [-travel * (n2 - n1) * c, 1]], m)
        z_now = zk
        if stop is not None and k == stop and at_stop is None:
            at_stop = m
    last_n = steps[-1][4] if steps[-1][1] == "refract" else steps[-1][3]
    m = matmul([[1, abs(end_z - z_now) / last_n], [0, 1]], m)
    return m, at_stop


def load(lens_id):
    raw = json.load(open(os.path.join(LENSES, lens_id + ".json")))
    surfaces = [Surf(s) for s in raw["surfaces"]]
    z, acc = [], mp.mpf(0)
    for s in surfaces:
        z.append(acc)
        acc += s.t
    return {"id": lens_id, "surfaces": surfaces, "z": z}


def first_order(lens):
    N = len(lens["surfaces"])
    stop = next(k for k, s in enumerate(lens["surfaces"]) if s.stop)
    z_last = lens["z"][-1]
    m, at_stop = paraxial(lens, image_steps(lens), z_last, stop)
    A, B, C, D = m[0][0], m[0][1], m[1][0], m[1][1]
    efl = -1 / C
    bfd = -A / C
    enp = at_stop[0][1] / at_stop[0][0]
    enp_d = 2 * lens["surfaces"][stop].semi / abs(at_stop[0][0])
    # Stop to last vertex: the image path from just after the stop.
    rear_steps = image_steps(lens)[stop + 1:]
    r = [[mp.mpf(1), mp.mpf(0)], [mp.mpf(0), mp.mpf(1)]]
    z_now = lens["z"][stop]
    for k, kind, travel, n1, n2 in rear_steps:
        r = matmul([[1, abs(lens["z"][k] - z_now) / n1], [0, 1]], r)
        c = lens["surfaces"][k].c + 2 * lens["surfaces"][k].a2
        r = matmul([[1, 0], [-(n2 - n1) * c, 1]], r)
        z_now = lens["z"][k]
    exp = -r[0][1] / r[1][1]
    return {"efl": efl, "bfd": bfd, "enp_dist": enp, "enp_diameter": enp_d, "fno": efl / enp_d,
            "exp_dist": exp, "stop_surface": stop, "total_track": z_last + bfd}


def fl(v):
    return float(v) if v is not None else None


def main():
    for lens_id in IDS:
        lens = load(lens_id)
        fo = first_order(lens)
        sensor = fo["total_track"]
        pupil = (fo["enp_dist"], fo["enp_diameter"] / 2)
        rays = []
        for th in RAY_THETAS:
            for px, py in RAY_PUPIL:
                land, fail, clipped = trace(lens, image_steps(lens), sensor, th, px, py, pupil)
                r = {"theta_deg": th, "px": px, "py": py, "x": fl(land[0]) if land else None,
                     "y": fl(land[1]) if land else None}
                if fail and fail.startswith("beyond@"):
                    r["beyond_asphere"] = int(fail[7:])
                elif fail:
                    r["fails"] = fail
                if clipped:
                    r["vignetted_at_surfaces"] = clipped
                rays.append(r)
        n = media(lens)
        reflecting = [k for k in range(len(lens["surfaces"])) if n[k] != n[k + 1]]
        pairs = [(i, j) for a, i in enumerate(reflecting) for j in reflecting[a + 1:]]
        table = []
        for i, j in pairs:
            steps = ghost_steps(lens, i, j)
            m, _ = paraxial(lens, steps, sensor)
            by = []
            for th in GHOST_THETAS:
                u = mp.tan(mp.radians(th))
                exact, para, fails, clips, beyond = [], [], set(), [], []
                for index, py in enumerate(FAN):
                    land, fail, clipped = trace(lens, steps, sensor, th, 0.0, py, pupil)
                    exact.append(fl(land[1]) if land else None)
                    if fail and fail.startswith("beyond@"):
                        beyond.append(index)
                        clipped = None
                    elif fail:
                        fails.add(fail)
                    clips.append(clipped)
                    y0 = mp.mpf(repr(py)) * pupil[1] - pupil[0] * u
                    para.append(float(m[0][0] * y0 + m[0][1] * u))
                by.append({"theta_deg": th, "exact_y_fan": exact, "paraxial_y_fan": para,
                           "fails": sorted(fails), "clipped_at": clips, "beyond_asphere": beyond})
            table.append({"i": i, "j": j, "by_theta": by})
        out = {"lens": lens_id, "wavelength_nm": 587.5618, "tracer": "make_reference.py (mpmath, 40 digits)",
               "first_order": {k: (fl(v) if k != "stop_surface" else v) for k, v in fo.items()},
               "rays": rays,
               "ghosts": {"pupil_fan_py": FAN, "thetas_deg": GHOST_THETAS, "count": len(pairs), "table": table}}
        with open(os.path.join(HERE, lens_id + ".json"), "w") as f:
            json.dump(out, f, indent=1)
        landed = sum(1 for g in table for b in g["by_theta"] for y in b["exact_y_fan"] if y is not None)
        beyond = sum(len(b["beyond_asphere"]) for g in table for b in g["by_theta"])
        print(lens_id, "rays", len(rays), "(beyond an asphere:", sum("beyond_asphere" in r for r in rays), ") ghosts",
              len(pairs), "ghost rays landed", landed, "beyond an asphere", beyond, file=sys.stderr)


if __name__ == "__main__":
    main()
