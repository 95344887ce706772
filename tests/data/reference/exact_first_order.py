"""Exact first-order data of the lenses in lenses/, in rational arithmetic (Python's fractions).

Independent of FlareLab's Rust code: the (y, n u) ray-transfer matrices of the reference README, multiplied
with no rounding at all, then rounded once to float. Run from the repository root:

    python3 tests/data/reference/exact_first_order.py > tests/data/reference/exact_first_order.json

Why it exists: the ray-optics figures in this folder agree with it to 5e-16 on efl, bfd, total track and
the pupil diameter, but three of their numbers are off: the entrance-pupil position enp_dist by 7e-9 to
1.2e-7 relative, fno by up to 3.5e-8 (it is not exactly their own efl / enp_diameter) and exp_dist by up to
1.4e-7 (ray-optics finds pupils with rays from an object 1e10 mm away and loses digits to cancellation).
The tests check FlareLab's values of those three against this exact computation to 1e-12, and trace the
reference rays from the reference's own pupil numbers, which is how those rays are defined.
"""
import glob
import json
from fractions import Fraction as F


def mul(a, b):
    return [[a[0][0] * b[0][0] + a[0][1] * b[1][0], a[0][0] * b[0][1] + a[0][1] * b[1][1]],
            [a[1][0] * b[0][0] + a[1][1] * b[1][0], a[1][0] * b[0][1] + a[1][1] * b[1][1]]]


def matrix(surfaces, first, last):
    """Matrix from just after surface `first - 1` (at its vertex) through surfaces first..last-1, ending on
    the vertex of surface last-1, in (y, n u)."""
    m = [[F(1), F(0)], [F(0), F(1)]]
    n_prev = F(1) if first == 0 else F(surfaces[first - 1]["nd"])
    for k in range(first, last):
        s = surfaces[k]
        if k > first or first > 0:
            t = F(surfaces[k - 1]["thickness"])
            m = mul([[F(1), t / n_prev], [F(0), F(1)]], m)
        c = F(0) if not s["radius"] else 1 / F(s["radius"])
        n = F(s["nd"])
        m = mul([[F(1), F(0)], [-(n - n_prev) * c, F(1)]], m)
        n_prev = n
    return m


out = {}
for path in sorted(glob.glob("lenses/*.json")):
    lens = json.load(open(path))
    s = lens["surfaces"]
    stop = next(k for k, x in enumerate(s) if x.get("stop"))
    system = matrix(s, 0, len(s))
    front = matrix(s, 0, stop + 1)
    rear = matrix(s, stop + 1, len(s))
    efl = -1 / system[1][0]
    bfd = -system[0][0] / system[1][0]
    enp_dist = front[0][1] / front[0][0]
    enp_diameter = 2 * F(s[stop]["semi_aperture"]) / abs(front[0][0])
    exp_dist = -rear[0][1] / rear[1][1]
    track = sum(F(x["thickness"]) for x in s[:-1]) + bfd
    out[lens["id"]] = {
        "efl": float(efl), "bfd": float(bfd), "enp_dist": float(enp_dist), "enp_diameter": float(enp_diameter),
        "fno": float(efl / enp_diameter), "exp_dist": float(exp_dist), "total_track": float(track),
    }
print(json.dumps(out, indent=1))
