"""`hybrid study convergence` on one shape in two triangulations: the ellipsoid of
`tests/mesh/test_two_triangulations.py` (semi-axes 0.15, 0.12, 0.10 m) as a regular file
(an icosphere's 42 and 162 points) and an irregular one (40 and 160 spiral points moved at
random), each the membrane of the inflated scene of `test_convergence_capsule.py`. Each
study refines its file by `mesh.level` toward the smooth surface through the file's points,
and its limit is that surface's; the two surfaces differ between the points, by the
interpolation's error at the file's spacing. So a family's error has two parts: its
studies' (`helpers.limit_allowance`) and its sampling's, estimated over its two files as on
the mesh alone (`helpers.family_errors`: the grid convergence index at order 2).

The metrics are integrals over the body: the largest enclosed volume (`volume_m3`) and its
largest relative change (`volume_rel_change`, a compliance). Measured, the studies' limits
at 42/40, 162/160 and 642/640 points (the last levels 0-2, not run here: 23 s for the
irregular file's study alone):

| | 42 / 40 | 162 / 160 | 642 / 640 |
|---|---|---|---|
| largest volume (L), regular / irregular | 8.034 / 7.951 | 8.042 / 8.028 | 8.044 / 8.041 |
| its gap, and the sum of the estimated errors | 1.03%, 5.8% | 0.18%, 3.5% | 0.04% |
| largest relative change, regular / irregular | 0.06683 / 0.07973 | 0.06707 / 0.07143 | 0.06687 / 0.06822 |
| its gap, and the sum of the estimated errors | 19.3%, 31% | 6.5%, 16% | 2.0% |

The compliance converges with the files more slowly than the volume, and from the irregular
side: the surface through jittered points undulates between them, and a membrane under
pressure reads its curvature, which is further off than its position. The families' own
limits agree: volume 8.045 +- 1.2% and 8.053 +- 2.6% L, compliance 0.0672 +- 1.1% and
0.0687 +- 19%. Those allowances are a few percent of the volume at these small sizes, so the
test's teeth are a 10%-taller ellipsoid (the mesh test tells 3% apart). With each new point
left at its edge's midpoint (no smooth surface), two of the three tests fail: the levels' and
the taller one's.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import ELLIPSOID_AXES_M, family_errors, limit_allowance, write_ellipsoid
from test_convergence_capsule import INFLATION, ORDER_SPACE

from hybrid.studies import convergence

#: the files of each family here: the two coarser resolutions of `helpers.ELLIPSOID_FILES`
FILES = {"regular": (42, 162), "irregular": (40, 160)}
#: each file's levels: 0-3 on the coarser (to 2,562 points), whose study then estimates its
#: limit's error itself (`_limit_error`: the limit without level 0); 0-2 on the finer (as many
#: points), whose three levels fit their order and give no estimate (`helpers.limit_allowance`)
LEVELS = {42: (0, 1, 2, 3), 40: (0, 1, 2, 3), 162: (0, 1, 2), 160: (0, 1, 2)}
METRICS = ("volume_m3", "volume_rel_change")
#: the taller ellipsoid of the last test: 10%, as the studies' allowances at these sizes are a few
#: percent (the mesh alone tells 3% apart: tests/mesh/test_two_triangulations.py)
TALLER = 1.10


def study(folder, kind: str, npoint: int, axes_m=ELLIPSOID_AXES_M) -> dict:
    """The small study of the inflated scene on the file (its LEVELS, two steps, 0.25 s): its
    estimate per metric."""
    folder.mkdir()
    path = write_ellipsoid(folder, kind, npoint, axes_m)
    scene = folder / "ellipsoid.toml"
    scene.write_text(
        INFLATION.replace('name = "capsule_inflation"', f'name = "ellipsoid_{kind}_{npoint}"').replace(
            'path = "capsule.obj"', f'path = "{path.name}"'
        )
    )
    res = convergence.run(
        folder / "cv",
        scene=str(scene),
        metrics=METRICS,
        levels=LEVELS[npoint],
        nstep=2,
        duration_s=0.25,
        repeats=1,  # the values are checked here, not the costs
    )
    assert not res["failures"] and res["spacing_ratio"] == convergence.RATIO_SPACE_FILE
    return res["estimate"]


@pytest.fixture(scope="module")
def studies(tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("two_triangulations")
    out = {kind: [study(root / f"{kind}_{n}", kind, n) for n in counts] for kind, counts in FILES.items()}
    taller = np.array(ELLIPSOID_AXES_M) * [1.0, 1.0, TALLER]
    out["taller"] = [study(root / f"taller_{n}", "irregular", n, taller) for n in FILES["irregular"]]
    return out


def family(estimates: list, k: str) -> dict:
    """A family's errors over its files (`helpers.family_errors`), each file's limit known to its
    study's allowance."""
    return family_errors(
        [e[k]["limit"] for e in estimates],
        [limit_allowance(e[k], convergence.RATIO_SPACE_FILE) for e in estimates],
        ratio=2.0,  # the files' spacing halves: 4 times the points
    )


def test_each_files_study_converges_at_the_membranes_order(studies):
    for kind, counts in (*FILES.items(), ("taller", FILES["irregular"])):
        for n, est in zip(counts, studies[kind]):
            for k in METRICS:
                e = est[k]
                x = e["value_by_level"]
                assert abs(x[1] - x[0]) > 2.0 * abs(x[2] - x[1]) > 0, (kind, n, k, x)  # at least first order
                assert ORDER_SPACE[0] <= e["observed_order_space"] <= ORDER_SPACE[1], (kind, n, k, e)
                # four levels: the study's own estimate; three whose order they fit: none (it would be made up)
                assert (e["limit_error_estimate"] is None) == (len(LEVELS[n]) == 3), (kind, n, k, e)
                assert limit_allowance(e, convergence.RATIO_SPACE_FILE) > 0


def test_the_two_families_limits_agree_within_their_estimated_errors(studies):
    """At both resolutions the two studies' limits are within the sum of their families'
    estimated errors, the gap shrinks from 40 to 160 points, and the families' own limits (over
    their files) agree within theirs."""
    for k in METRICS:
        reg, irr = family(studies["regular"], k), family(studies["irregular"], k)
        gap = [abs(a - b) for a, b in zip(reg["values"], irr["values"])]
        assert all(g <= a + b for g, a, b in zip(gap, reg["sampling"], irr["sampling"])), (k, reg, irr)
        assert gap[1] < gap[0], (k, gap)
        assert abs(reg["limit"] - irr["limit"]) <= reg["limit_error"] + irr["limit_error"], (k, reg, irr)


def test_a_ten_percent_taller_ellipsoid_is_told_apart_by_its_volume(studies):
    """The irregular family on an ellipsoid 10% taller: its largest volume is outside the regular
    family's at 160 points and in the limit."""
    reg, taller = family(studies["regular"], "volume_m3"), family(studies["taller"], "volume_m3")
    assert abs(reg["values"][-1] - taller["values"][-1]) > reg["sampling"][-1] + taller["sampling"][-1]
    assert abs(reg["limit"] - taller["limit"]) > reg["limit_error"] + taller["limit_error"]
